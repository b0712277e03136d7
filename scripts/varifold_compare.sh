#!/usr/bin/env bash
# Times pykeops (CPU, float64) against fshape-varifold on the same inputs in
# one run: the data attachment between the two fsaverage5 pial hemispheres
# with thickness, value and both gradients. Installs pykeops in
# target/python-venv; builds fshape in release.
# Usage: scripts/varifold_compare.sh [REPS]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
py="$("$here/python-env.sh")"
"$(dirname "$py")/pip" install --quiet pykeops==2.3 >&2
(cd "$here/.." && cargo build --release --quiet -p fshape-varifold --example varifold_timing)
"$py" "$here/varifold_compare.py" "$@"
