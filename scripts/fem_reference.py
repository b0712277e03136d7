"""Reference values for fshape-fem from libigl, an independent implementation.

Writes fshape-fem/tests/reference/:
  bunny_qslim_fem.csv.gz  every stored entry (i >= j) of libigl's
                          massmatrix(FULL), massmatrix(BARYCENTRIC) and
                          -cotmatrix on data/stanford_bunny/bunny_qslim_2581v.ply.gz
  cortex_fem.json         quadratic forms f^T M f and -f^T L f on
                          data/fsaverage5/lh.pial.thick.ply.gz for fixed signals

Run with scripts/fem_reference.sh (it installs libigl, numpy and scipy).
The meshes are read here from the repository's ASCII PLY files with a plain
parser, so fshape's own readers take no part in the reference.
"""
import gzip
import json
import sys
from pathlib import Path

import igl
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "fshape-fem" / "tests" / "reference"


def read_ascii_ply(path):
    with gzip.open(path, "rt") as fh:
        lines = fh.read().splitlines()
    end = lines.index("end_header")
    header = lines[:end]
    nv = next(int(l.split()[2]) for l in header if l.startswith("element vertex"))
    nf = next(int(l.split()[2]) for l in header if l.startswith("element face"))
    body = lines[end + 1:]
    V = np.array([[float(t) for t in l.split()[:3]] for l in body[:nv]], dtype=np.float64)
    F = np.array([[int(t) for t in l.split()[1:4]] for l in body[nv:nv + nf]], dtype=np.int64)
    return V, F


def signals(V):
    """Deterministic smooth signals of the coordinates (also computed in the Rust test)."""
    ptp = V.max(0) - V.min(0)
    return {
        "ones": np.ones(len(V)),
        "x": V[:, 0] / ptp[0],
        "wave": np.sin(3.0 * V[:, 0] / ptp[0]) + V[:, 1] / ptp[1],
    }


def matrices(V, F):
    M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_FULL).tocsc()
    B = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_BARYCENTRIC).tocsc()
    K = (-igl.cotmatrix(V, F)).tocsc()
    return M, B, K


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    V, F = read_ascii_ply(ROOT / "data/stanford_bunny/bunny_qslim_2581v.ply.gz")
    M, B, K = matrices(V, F)
    rows = {}
    for name, A in (("mass_full", M), ("mass_barycentric", B), ("stiffness", K)):
        C = A.tocoo()
        for i, j, v in zip(C.row, C.col, C.data):
            if i >= j:
                rows.setdefault((int(i), int(j)), {})[name] = float(v)
    with gzip.GzipFile(OUT / "bunny_qslim_fem.csv.gz", "wb", mtime=0) as gz:
        gz.write(b"row,col,mass_full,mass_barycentric,stiffness\n")
        for (i, j) in sorted(rows):
            r = rows[(i, j)]
            vals = [repr(r.get(k, 0.0)) for k in ("mass_full", "mass_barycentric", "stiffness")]
            gz.write(f"{i},{j},{','.join(vals)}\n".encode())

    V, F = read_ascii_ply(ROOT / "data/fsaverage5/lh.pial.thick.ply.gz")
    M, B, K = matrices(V, F)
    out = {"mesh": "data/fsaverage5/lh.pial.thick.ply.gz", "libigl": "2.6.3",
           "n_vertices": int(len(V)), "n_faces": int(len(F)), "forms": {}}
    for name, f in signals(V).items():
        out["forms"][name] = {
            "mass_full": float(f @ (M @ f)),
            "mass_barycentric": float(f @ (B @ f)),
            "stiffness": float(f @ (K @ f)),
        }
    (OUT / "cortex_fem.json").write_text(json.dumps(out, indent=1) + "\n")
    print("wrote", OUT, file=sys.stderr)


if __name__ == "__main__":
    main()
