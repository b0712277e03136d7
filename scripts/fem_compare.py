"""Times libigl's massmatrix(FULL) + cotmatrix against fshape-fem's P1 mass +
stiffness assembly on the same meshes, in one run, and prints the ratios.

Both sides start from raw vertex and face arrays already in memory, so
building the sparsity pattern counts on both sides. fshape's numeric
refactorisation + solve of D_1 (fixed pattern) is reported separately.
Run with scripts/fem_compare.sh (it installs libigl and builds fshape).
"""
import json
import subprocess
import sys
import time
from pathlib import Path

import igl
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
TIMING = ROOT / "target" / "release" / "examples" / "fem_timing"
MESHES = [
    ("icosphere level 5", "ico:5"),
    ("fsaverage5 pial (real)", "data/fsaverage5/lh.pial.thick.ply.gz"),
    ("icosphere level 6", "ico:6"),
    ("pycortex S1 pial (real)", "data/pycortex_S1/lh.pia.ply.gz"),
    ("icosphere level 8", "ico:8"),
]


def read_binary_ply(path):
    """Reads the binary PLY fshape writes: double vertex properties (x y z, and
    `signal` when present), faces `uchar 3, int ×3`."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    nv = next(int(l.split()[2]) for l in header if l.startswith("element vertex"))
    nf = next(int(l.split()[2]) for l in header if l.startswith("element face"))
    start = next(k for k, l in enumerate(header) if l.startswith("element vertex"))
    nprop = 0
    for line in header[start + 1:]:
        if not line.startswith("property double"):
            break
        nprop += 1
    V = np.frombuffer(data, dtype="<f8", count=nprop * nv, offset=end).reshape(nv, nprop)[:, :3].copy()
    face = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    F = np.frombuffer(data, dtype=face, count=nf, offset=end + 8 * nprop * nv)
    assert (F["n"] == 3).all() and F["i"].min() >= 0 and F["i"].max() < nv, "not an fshape binary PLY"
    F = F["i"].astype(np.int64)
    return V, F


def median_ms(f, reps):
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        f()
        times.append((time.perf_counter() - t) * 1e3)
    return float(np.median(times))


def main():
    reps = int(sys.argv[1]) if len(sys.argv) > 1 else 7
    out_dir = ROOT / "target" / "bench-meshes"
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, mesh in MESHES:
        ply = out_dir / (mesh.replace("/", "_").replace(":", "") + ".ply")
        ours = json.loads(subprocess.run(
            [str(TIMING), mesh, "--reps", str(reps), "--export", str(ply)],
            check=True, capture_output=True, text=True, cwd=ROOT).stdout)
        V, F = read_binary_ply(ply)
        igl_ms = median_ms(lambda: (igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_FULL), igl.cotmatrix(V, F)), reps)
        rows.append((name, ours, igl_ms))
        print(f"{name}: ours {ours['assembly_ms']:.1f} ms, libigl {igl_ms:.1f} ms", file=sys.stderr)
    print(f"Median of {reps} runs each; {rows[0][1]['threads']} threads for fshape; libigl {igl.__version__ if hasattr(igl, '__version__') else ''}.")
    print()
    print("| mesh | vertices | triangles | libigl massmatrix+cotmatrix (ms) | fshape mass+stiffness from raw arrays (ms) | ratio fshape/libigl | fshape values on a fixed pattern (ms) | fshape D1 refactor+solve (ms) |")
    print("|---|---|---|---|---|---|---|---|")
    for name, o, g in rows:
        print(f"| {name} | {o['n_vertices']} | {o['n_cells']} | {g:.1f} | {o['assembly_ms']:.1f} | {o['assembly_ms'] / g:.2f} | {o['assembly_fixed_pattern_ms']:.1f} | {o['refactor_solve_ms']:.1f} |")


if __name__ == "__main__":
    main()
