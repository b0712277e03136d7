"""Split a registration's signal error into a smooth part and an oscillating part.

Diagnostic of docs/guide/src/experiments.md (“a deep stage on the coarse sphere”), not part of the test suite.
Needs numpy and scipy:

    python docs/guide/src/experiments/signal_error_parts.py TARGET.ply RESULT.ply [RESULT.ply ...]

TARGET and RESULT are binary little-endian PLY files as fshape writes them
(x, y, z, signal as doubles; triangles). For every target vertex the
result's signal is read at the nearest of a dense sampling of the result
(8 subdivisions per triangle edge, linear interpolation), and
e = f_result - g_target. Printed, as percentages of the target signal's
range, with lumped-area weights at the target's vertices:

- rms: the whole error (close to `fshape quality`'s, which uses exact
  closest points on area samples);
- slope, offset: the least-squares fit f ≈ slope·g + offset (slope < 1: the
  signal was fitted with a smaller amplitude than the target's);
- smooth part: e after 20 steps of lazy averaging over the target's mesh
  neighbours (v ← v/2 + mean of the neighbours/2, a diffusion length of a
  few edges, about 5 % of the bunny's diagonal);
- oscillating part: e minus its smooth part.
"""
import sys

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from plyio import lumped_areas, read_ply


def dense(x, s, f, n=8):
    pts, sig = [], []
    for i in range(n + 1):
        for j in range(n + 1 - i):
            a, b = i / n, j / n
            c = 1 - a - b
            pts.append(a * x[f[:, 0]] + b * x[f[:, 1]] + c * x[f[:, 2]])
            sig.append(a * s[f[:, 0]] + b * s[f[:, 1]] + c * s[f[:, 2]])
    return np.vstack(pts), np.concatenate(sig)


def smooth(v, t, steps=20):
    i = np.concatenate([t[:, 0], t[:, 1], t[:, 2], t[:, 1], t[:, 2], t[:, 0]])
    j = np.concatenate([t[:, 1], t[:, 2], t[:, 0], t[:, 0], t[:, 1], t[:, 2]])
    w = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(len(v), len(v)))
    w.data[:] = 1.0
    p = sp.diags(1.0 / np.asarray(w.sum(1)).ravel()) @ w
    for _ in range(steps):
        v = 0.5 * v + 0.5 * (p @ v)
    return v


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    y, g, t = read_ply(sys.argv[1])
    if g is None:
        sys.exit(f"{sys.argv[1]}: no signal")
    m = lumped_areas(y, t)
    m = m / m.sum()
    r = g.max() - g.min()
    rms = lambda e: 100 * np.sqrt((m * e * e).sum()) / r
    for path in sys.argv[2:]:
        x, s, f = read_ply(path)
        if s is None:
            sys.exit(f"{path}: no signal")
        pts, sig = dense(x, s, f)
        fx = sig[cKDTree(pts).query(y)[1]]
        e = fx - g
        w = np.sqrt(m)
        slope, offset = np.linalg.lstsq(np.c_[g * w, w], fx * w, rcond=None)[0]
        es = smooth(e, t)
        print(
            f"{path}: rms {rms(e):.2f}%, slope {slope:.3f}, offset {offset:+.3f}, "
            f"smooth part {rms(es):.2f}%, oscillating part {rms(e - es):.2f}%"
        )


if __name__ == "__main__":
    main()
