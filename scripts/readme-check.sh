#!/usr/bin/env bash
# Every command of the README's ```sh blocks, run as a newcomer would (in
# a scratch folder beside the repository's data), with the program built
# by cargo test (debug) standing for target/release/fshape. Not run here:
# cargo's own commands (CI builds and tests the workspace itself), pip
# (scripts/python-test.sh installs the package), mdbook (the guide's own
# step), and the "Your data" block, whose files are the reader's.
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
if [ -z "${FSHAPE_BIN:-}" ]; then
    # The binary `cargo test --workspace` builds (nothing to do after it):
    # `cargo build -p fshape-cli` alone unifies other features (fshape-mesh
    # without test-support) and would rebuild every crate.
    cargo test --workspace --no-run --quiet
    FSHAPE_BIN="$repo/target/debug/fshape"
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
ln -s "$repo/data" "$work/data"
python3 - "$repo/README.md" > "$work/commands.sh" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
skip_block = "## Your data"
sections = re.split(r"(?m)^## ", text)
lines = []
for sec in sections:
    if sec.startswith(skip_block[3:]):
        continue
    for block in re.findall(r"```sh\n(.*?)```", sec, re.S):
        cmd = ""
        for line in block.split("\n"):
            line = line.split("  #")[0].rstrip() if not line.lstrip().startswith("#") else ""
            if not line:
                continue
            cmd += line[:-1] + " " if line.endswith("\\") else line
            if not line.endswith("\\"):
                lines.append(cmd.strip())
                cmd = ""
for c in lines:
    if c.split()[0] in ("cargo", "pip", "mdbook"):
        print(f"# not run here: {c}")
    else:
        print(c)
PY
sed -i "s#target/release/fshape#$FSHAPE_BIN#g" "$work/commands.sh"
cat "$work/commands.sh"
(cd "$work" && bash -euo pipefail commands.sh > output.txt 2>&1) || { cat "$work/output.txt"; echo "a README command failed"; exit 1; }
echo "every README command ran"
