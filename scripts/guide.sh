#!/usr/bin/env bash
# Builds the user guide (docs/guide, mdBook; installed from crates.io
# under target/tools if missing) into target/guide and checks every link
# of every page (scripts/guide-check.py).
set -euo pipefail
cd "$(dirname "$0")/.."
mdbook=target/tools/bin/mdbook
if ! [ -x "$mdbook" ]; then
    cargo install --quiet mdbook --version 0.4.52 --no-default-features --features search --locked --root target/tools
fi
"$mdbook" build docs/guide 2>&1 | grep -v "INFO" || true
test -s target/guide/index.html
python3 scripts/guide-check.py target/guide | grep -v "^web link"
