#!/usr/bin/env bash
# Remakes fshape-mesh/tests/data/nibabel with nibabel, in a venv of its own
# (scripts/python-venv.sh makes it). The files are committed: the Rust
# tests need no Python. Run this only to change the fixtures.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=$(bash scripts/python-venv.sh)
out=fshape-mesh/tests/data/nibabel
rm -f "$out"/*.gii "$out"/*.csv "$out"/lh.* "$out"/*.mgh "$out"/*.mgz "$out"/*.nii
"$venv/bin/python" scripts/make-nibabel-fixtures.py "$out"
