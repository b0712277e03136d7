#!/usr/bin/env bash
# The atlas over MPI (fshape-cli's `mpi` feature), checked end to end:
#   1. installs Open MPI and libclang if missing (scripts/mpi-deps.sh);
#   2. builds `fshape` with --features mpi (the dev profile, which optimises
#      every numeric crate: it reuses the test build's artifacts, where a
#      release build of the whole tree took about 7 minutes of CI);
#   3. makes a small population (the atlas-spheres demo's: an ellipsoid
#      shot by seeded random momenta) and runs the atlas on one process,
#      then under mpirun on 1, 2 and 3 processes: the template, every
#      subject's momenta and the PCA must be the same bytes;
#   4. kills one process of a 2-process run midway: mpirun must end the
#      run within a bounded time with an error, and `--resume` on 3
#      processes must finish on the same bytes as the single process;
#   5. `fshape batch` under mpirun (rows dealt to 3 processes) gives every
#      row the bytes of one process, and a bad row fails alone.
# Usage: scripts/mpi-test.sh [WORKDIR]   (exit status 0 when all hold)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$here/.."
work="${1:-$root/target/mpi-test}"

"$here/mpi-deps.sh"

echo "== building fshape with --features mpi"
(cd "$root" && cargo build --quiet -p fshape-cli --features mpi)
fshape="$root/target/debug/fshape"
# Open MPI refuses root and more processes than cores unless told.
mpi=(mpirun --allow-run-as-root --oversubscribe --bind-to none)

rm -rf "$work"
mkdir -p "$work"
cd "$work"
"$fshape" demo atlas-spheres --max-iterations 1 --out inputs > /dev/null 2>&1
in="inputs/atlas-spheres"
head -n 7 "$in/subjects/subjects.csv" > "$in/subjects/six.csv"
sed 's/^max_iterations = .*/max_iterations = 12/' "$in/atlas/config.toml" > config.toml
args=(atlas --subjects "$in/subjects/six.csv" --template "$in/template_start.ply" --config config.toml)

same() {
    for f in template.ply momenta.csv pca.csv subject_003/p0.csv; do
        cmp -s "one/$f" "$1/$f" || { echo "FAIL: $1/$f differs from one process's"; exit 1; }
    done
}

seconds() { date +%s.%N; }
echo "== one process"
t0=$(seconds)
"$fshape" "${args[@]}" --out one > one.log 2>&1
echo "   $(awk "BEGIN { printf \"%.1f\", $(seconds) - $t0 }") s"
for r in 1 2 3; do
    echo "== mpirun -n $r"
    t0=$(seconds)
    "${mpi[@]}" -n "$r" "$fshape" "${args[@]}" --out "mpi$r" > "mpi$r.log" 2>&1
    same "mpi$r"
    echo "   the same bytes as one process ($(awk "BEGIN { printf \"%.1f\", $(seconds) - $t0 }") s)"
done

# Accepted iterations in a checkpoint, finished stages included.
iterations() {
    "$fshape" checkpoint "$1" 2> /dev/null | python3 -c 'import json, sys; c = json.load(sys.stdin); print(c["iterations"] + c["iterations_done"])' 2> /dev/null || echo 0
}

echo "== a process killed midway"
"${mpi[@]}" -n 2 "$fshape" "${args[@]}" --out killed > killed.log 2>&1 &
runner=$!
# Wait for the checkpoint of the third iteration, then kill process 1.
for _ in $(seq 600); do
    if [ -f killed/checkpoint.bin ] && [ "$(iterations killed/checkpoint.bin)" -ge 3 ]; then
        break
    fi
    sleep 0.1
done
victim=""
for pid in $(pgrep -f "fshape atlas.*--out killed" || true); do
    if tr '\0' '\n' < "/proc/$pid/environ" 2> /dev/null | grep -qx 'OMPI_COMM_WORLD_RANK=1'; then
        victim=$pid
    fi
done
[ -n "$victim" ] || { echo "FAIL: no process 1 to kill (the run ended too soon?)"; cat killed.log; exit 1; }
echo "   killing process 1 after $(iterations killed/checkpoint.bin) iterations"
kill -9 "$victim"
start=$(date +%s)
status=0
for _ in $(seq 600); do
    kill -0 "$runner" 2> /dev/null || break
    sleep 0.1
done
if kill -0 "$runner" 2> /dev/null; then
    kill -9 "$runner" || true
    echo "FAIL: mpirun still running 60 s after process 1 was killed"
    exit 1
fi
wait "$runner" || status=$?
[ "$status" -ne 0 ] || { echo "FAIL: the killed run exited 0"; exit 1; }
echo "   mpirun ended with status $status within $(($(date +%s) - start)) s:"
grep -iE "signal|killed|exited|abort" killed.log | head -3 | sed 's/^/   | /'
[ ! -f killed/template.ply ] || { echo "FAIL: a killed run wrote outputs"; exit 1; }
echo "== resumed on 3 processes"
"${mpi[@]}" -n 3 "$fshape" "${args[@]}" --out killed --resume > resumed.log 2>&1
same killed
echo "   the same bytes as one process"
echo "== fshape batch under mpirun: rows dealt to 3 processes"
{
    echo "source,target,name"
    for i in 00 01 02 03; do echo "$in/template_start.ply,$in/subjects/subject_$i.ply,s$i"; done
    echo "$in/template_start.ply,$in/subjects/absent.ply,bad"
} > pairs.csv
sed 's/^max_iterations = .*/max_iterations = 8/' config.toml > batch.toml
batch=(batch pairs.csv --config batch.toml --times 0,1)
"$fshape" "${batch[@]}" --out batch_one > batch_one.log 2>&1 && { echo "FAIL: the bad row did not fail"; exit 1; }
"${mpi[@]}" -n 3 "$fshape" "${batch[@]}" --out batch_mpi > batch_mpi.log 2>&1 && { echo "FAIL: the bad row did not fail under mpirun"; exit 1; }
for i in 00 01 02 03; do
    cmp -s "batch_one/s$i/p0.csv" "batch_mpi/s$i/p0.csv" || { echo "FAIL: row s$i differs under mpirun"; exit 1; }
done
grep -q '"done": 4' batch_mpi/index.json && grep -q '"failed": 1' batch_mpi/index.json \
    || { echo "FAIL: the index under mpirun"; cat batch_mpi/index.json; exit 1; }
echo "   the same rows as one process; the bad row failed alone"
echo "mpi-test: 5 passed, 0 failed"
