#!/usr/bin/env bash
# The HTML reports as a colleague opens them: a registration's (of one map and of two), an atlas's,
# a regression's and a batch's report.html made by the fshape program (debug build unless
# FSHAPE_BIN names one), each opened in headless Chromium (Debian's
# package, installed if missing) by scripts/report-check.mjs through
# playwright-core (npm, installed under target/report-check): no console
# error, no network request, the 3-D canvas draws and its time slider
# moves the picture; hostile names (markup, quotes, `<!--<script>`) show
# as text and run nothing under the page's hash-only script policy.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v chromium >/dev/null; then
    echo "installing Debian's chromium"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
fi
check=target/report-check
mkdir -p "$check"
if [ ! -d "$check/node_modules/playwright-core" ]; then
    (cd "$check" && npm install --silent --no-audit --no-fund playwright-core@1.57.0 >/dev/null)
fi
cp scripts/report-check.mjs "$check/"
if [ -z "${FSHAPE_BIN:-}" ]; then
    # The binary `cargo test --workspace` builds (nothing to do after it):
    # `cargo build -p fshape-cli` alone unifies other features (fshape-mesh
    # without test-support) and would rebuild every crate.
    cargo test --workspace --no-run --quiet
    FSHAPE_BIN="$PWD/target/debug/fshape"
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# A registration (a digit, planar) and an atlas (ellipsoids, in space).
"$FSHAPE_BIN" demo digits --ratios 100 --max-iterations 2 --out "$work" >/dev/null 2>&1
"$FSHAPE_BIN" demo stats-spheres --quick --subjects 3 --max-iterations 3 --permutations 50 --out "$work" >/dev/null 2>&1
# A batch of two pairs and a row that fails.
mkdir -p "$work/batch"
cp "$work/digits/source.ply" "$work/digits/target.ply" "$work/batch/"
sed -e 's/^max_iterations = [0-9]*$/max_iterations = 2/' -e '/^max_iterations = \[/d' "$work/digits/ratio_100/config.toml" > "$work/batch/config.toml"
# Names a hostile colleague could choose: markup, quotes, `&`, and
# `<!--<script>` (which swallows a script element's end if only `</` is
# escaped). Each must show as text and run nothing (window.pwned unset).
img='<img src=x onerror=window.pwned=1>'
cp "$work/digits/source.ply" "$work/batch/$img.ply"
cat > "$work/batch/pairs.csv" <<'TABLE'
source,target,name
source.ply,target.ply,forth
target.ply,source.ply,back
source.ply,missing.ply,broken
<img src=x onerror=window.pwned=1>.ply,target.ply,"x<!--<script>&""'"
source.ply,target.ply,<script>window.pwned=2</script>
TABLE
"$FSHAPE_BIN" batch "$work/batch/pairs.csv" --config "$work/batch/config.toml" --out "$work/batch/out" >/dev/null 2>&1 || true
# A registration of two maps (the digit's signal and its opposite): a scene
# per map, the second drawn from the first's geometry.
for side in source target; do
    "$FSHAPE_BIN" convert "$work/digits/$side.ply" "$work/batch/$side.ascii.ply" --ascii
    awk '/^element vertex/ { n = $3 } /^end_header/ { h = NR; print "map" > a; print "map" > b; next }
         h && NR <= h + n { print $NF > a; print -$NF > b }' \
        a="$work/batch/$side.1.csv" b="$work/batch/$side.2.csv" "$work/batch/$side.ascii.ply"
done
"$FSHAPE_BIN" match "$work/batch/source.ply" "$work/batch/target.ply" \
    --signal "$work/batch/source.1.csv" --signal "$work/batch/source.2.csv" \
    --target-signal "$work/batch/target.1.csv" --target-signal "$work/batch/target.2.csv" \
    --config "$work/batch/config.toml" --out "$work/two_maps" >/dev/null 2>&1
# A regression of the digit's two shapes as one subject's visits, the
# subject named as hostilely as the batch's row.
cat > "$work/batch/visits.csv" <<'TABLE'
subject,age,mesh
"x<!--<script>&""'",60,source.ply
"x<!--<script>&""'",62.5,target.ply
TABLE
"$FSHAPE_BIN" regress --visits "$work/batch/visits.csv" --config "$work/batch/config.toml" --out "$work/regress" >/dev/null 2>&1
node "$check/report-check.mjs" \
    "$work/digits/ratio_100/report.html" \
    "$work/regress/x<!--<script>&\"'/report.html::x<!--<script>&\"'" \
    "$work/two_maps/report.html" \
    "$work/stats-spheres/atlas/report.html" \
    "$work/batch/out/report.html::x<!--<script>&\"'" \
    "$work/batch/out/report.html::<script>window.pwned=2</script>" \
    "$work/batch/out/forth/report.html" \
    "$work/batch/out/x<!--<script>&\"'/report.html::$img"
echo "reports checked"
