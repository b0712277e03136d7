"""Move a coarse solution's momenta to a finer template two ways, for docs/guide/src/experiments.md (“a deep stage on the coarse sphere”).

A diagnostic, not part of the test suite. Needs numpy and scipy:

    python docs/guide/src/experiments/transfer_by_velocity.py COARSE.ply FINE.ply P0.csv PF.csv OUT WIDTH [WIDTH ...]

COARSE and FINE are the two templates (binary little-endian PLY as fshape
writes them, triangles), P0.csv and PF.csv the coarse solution's momenta
(`fshape match` writes them), WIDTH the deformation kernel's Gaussian
widths (exp(-u/(2 sigma^2)), weights 1). Writes into OUT:

- p0_density.csv, pf_density.csv: what `resolution::prolongate` does, the
  coarse densities p/m interpolated linearly at each fine vertex's closest
  point on COARSE (found here by dense sampling) times the fine lumped
  areas;
- p0_fit.csv: the fine p_0 whose velocity field at the fine vertices is
  the coarse one's, (K_ff + lambda * mean(m) * diag(1/m)) q = K_fc p_0 with
  lambda = 1e-6 (a dense solve: a few thousand fine vertices at most).

and prints each one's energy p^T K p and the relative error of its
velocity field at the fine vertices. Shoot them with `fshape shoot FINE
--momentum ... --signal-momentum pf_density.csv --config shoot.toml` and
compare with `fshape distance` / `fshape quality`.
"""
import os
import sys

import numpy as np
from scipy.spatial import cKDTree

from plyio import lumped_areas, read_ply


def main():
    if len(sys.argv) < 7:
        sys.exit(__doc__)
    coarse, fine, p0_path, pf_path, out = sys.argv[1:6]
    widths = [float(w) for w in sys.argv[6:]]
    xc, _, fc = read_ply(coarse)
    xf, _, ff = read_ply(fine)
    p0 = np.loadtxt(p0_path, delimiter=",", skiprows=1)
    pf = np.loadtxt(pf_path, skiprows=1)
    mc, mf = lumped_areas(xc, fc), lumped_areas(xf, ff)
    # Closest points on the coarse mesh: the nearest of a dense
    # barycentric sampling (24 subdivisions per edge).
    n = 24
    pts, bary, tris = [], [], []
    for i in range(n + 1):
        for j in range(n + 1 - i):
            a, b = i / n, j / n
            c = 1 - a - b
            pts.append(a * xc[fc[:, 0]] + b * xc[fc[:, 1]] + c * xc[fc[:, 2]])
            bary.append(np.tile([a, b, c], (len(fc), 1)))
            tris.append(np.arange(len(fc)))
    idx = cKDTree(np.vstack(pts)).query(xf)[1]
    tri = fc[np.concatenate(tris)[idx]]
    w = np.vstack(bary)[idx]

    def interp(v):
        return w[:, 0:1] * v[tri[:, 0]] + w[:, 1:2] * v[tri[:, 1]] + w[:, 2:3] * v[tri[:, 2]]

    def kernel(a, b):
        d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
        return sum(np.exp(-d2 / (2 * s * s)) for s in widths)

    q_density = interp(p0 / mc[:, None]) * mf[:, None]
    qf_density = interp((pf / mc)[:, None])[:, 0] * mf
    kff = kernel(xf, xf)
    v = kernel(xf, xc) @ p0
    q_fit = np.linalg.solve(kff + 1e-6 * mf.mean() * np.diag(1 / mf), v)
    print(f"coarse: energy {np.einsum('ij,ij', p0, kernel(xc, xc) @ p0):.4f}")
    for name, q in [("density", q_density), ("fit", q_fit)]:
        err = np.linalg.norm(kff @ q - v) / np.linalg.norm(v)
        print(f"{name}: energy {np.einsum('ij,ij', q, kff @ q):.4f}, velocity error {err:.2e} (relative)")
    os.makedirs(out, exist_ok=True)
    for name, q in [("p0_density.csv", q_density), ("p0_fit.csv", q_fit)]:
        np.savetxt(os.path.join(out, name), q, delimiter=",", header="p_x,p_y,p_z", comments="")
    np.savetxt(os.path.join(out, "pf_density.csv"), qf_density, header="pf", comments="")


if __name__ == "__main__":
    main()
