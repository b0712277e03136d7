#!/usr/bin/env bash
# Times pykeops (CPU, float64) against fshape-kernels on the same inputs in
# one run. Installs pykeops in target/python-venv; builds fshape in release.
# Usage: scripts/kernel_compare.sh [REPS]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
py="$("$here/python-env.sh")"
"$(dirname "$py")/pip" install --quiet pykeops==2.3 >&2
(cd "$here/.." && cargo build --release --quiet -p fshape-kernels --example kernel_timing)
"$py" "$here/kernel_compare.py" "$@"
