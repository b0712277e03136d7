#!/usr/bin/env bash
# Makes (once) the Python venv the Python package's tests and the nibabel
# fixtures use, and prints its path. Everything comes from PyPI, pinned.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=${FSHAPE_VENV:-target/venv}
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c "import nibabel, numpy, pytest, maturin, mypy" 2>/dev/null; then
    python3 -m venv "$venv" >&2
    "$venv/bin/pip" install --quiet --upgrade pip >&2
    "$venv/bin/pip" install --quiet -r scripts/python-requirements.txt >&2
fi
cd "$venv" && pwd
