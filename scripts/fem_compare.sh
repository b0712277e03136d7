#!/usr/bin/env bash
# Times libigl against fshape-fem on the same meshes in one run (installs
# libigl, numpy and scipy in target/python-venv; builds fshape in release).
# Usage: scripts/fem_compare.sh [REPS]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
py="$("$here/python-env.sh")"
(cd "$here/.." && cargo build --release --quiet -p fshape-fem --example fem_timing)
"$py" "$here/fem_compare.py" "$@"
