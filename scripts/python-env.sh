#!/usr/bin/env bash
# Creates (once) the Python environment the comparison scripts use, with
# pinned packages from PyPI, and prints the interpreter's path.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
venv="$here/../target/python-venv"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv" >&2
  "$venv/bin/pip" install --quiet --upgrade pip >&2
  "$venv/bin/pip" install --quiet libigl==2.6.3 numpy==2.4.6 scipy==1.17.1 >&2
fi
echo "$venv/bin/python"
