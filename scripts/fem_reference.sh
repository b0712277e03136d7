#!/usr/bin/env bash
# Regenerates fshape-fem/tests/reference/ from libigl (installs what it needs).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
py="$("$here/python-env.sh")"
"$py" "$here/fem_reference.py"
