#!/usr/bin/env bash
# The Python package as a user gets it: `pip install ./fshape-py` into the
# project's venv (scripts/python-venv.sh), its stub checked against the
# compiled module (stubtest), then its tests (pytest) and the
# the guide's example (docs/guide/src/python.md), run as written. The tests compare with the fshape
# program, built here in debug (cargo test's build) unless FSHAPE_BIN names one.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=$(bash scripts/python-venv.sh)
export PYO3_PYTHON="$venv/bin/python"
# Build in the workspace's target directory and its dev profile (which
# optimises every numeric crate, fshape-py/Cargo.toml repeats it): pip and
# clippy then reuse the third-party crates `cargo test --workspace` built
# (the fshape crates are built again: without fshape-mesh's test-support
# feature they are other artifacts), where a release build of the whole
# tree in a directory of its own took about 15 minutes of CI. A user's
# `pip install ./fshape-py` builds the release profile.
export CARGO_TARGET_DIR="$PWD/target"
export MATURIN_PEP517_ARGS="--profile dev"
echo "== fshape-py: rustfmt and clippy"
cargo fmt --manifest-path fshape-py/Cargo.toml --check
cargo clippy --manifest-path fshape-py/Cargo.toml -- -D warnings
echo "== fshape-py: pip install ./fshape-py"
"$venv/bin/pip" install --quiet --force-reinstall --no-deps ./fshape-py
# The binary `cargo test --workspace` builds (nothing to do after it):
# `cargo build -p fshape-cli` alone unifies other features (fshape-mesh
# without test-support) and would rebuild every crate.
cargo test --workspace --no-run --quiet
export FSHAPE_BIN="${FSHAPE_BIN:-$PWD/target/debug/fshape}"
echo "== fshape-py: the stub (python/fshape/__init__.pyi) against the installed package (mypy's stubtest, no allow-list)"
(cd fshape-py && "$venv/bin/python" -m mypy.stubtest fshape --ignore-disjoint-bases)
echo "== fshape-py: pytest"
"$venv/bin/python" -m pytest -q fshape-py/tests
echo "== the guide's Python example"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$venv/bin/python" - "$tmp/example.py" <<'PY'
import re, sys
text = open("docs/guide/src/python.md").read()
block = text.split("<!-- python-example", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
open(sys.argv[1], "w").write(block)
PY
(cd "$tmp" && ln -s "$OLDPWD/data" data && "$venv/bin/python" example.py)
test -s "$tmp/matched.surf.gii"
# The README's few lines too.
"$venv/bin/python" - "$tmp/readme.py" <<'PY'
import re, sys
block = re.findall(r"```python\n(.*?)```", open("README.md").read(), re.S)[0]
open(sys.argv[1], "w").write(block)
PY
(cd "$tmp" && "$venv/bin/python" readme.py)
echo "the guide's Python example ran"
