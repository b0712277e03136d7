"""Times fshape-varifold against a pykeops (CPU, float64) formulation of the
same sums in one run and prints a Markdown table with the ratios.

Task: one matching iteration's data attachment between the fsaverage5 left
pial surface X (20480 triangles, thickness) and the right one Y (thickness):
A(X, Y) = <X,X> - 2<X,Y> + <Y,Y> with k_p Gaussian exp(-u/(2 sigma^2)),
k_f Gaussian of width sigma_f, k_t unoriented Gaussian exp(-2(1-s^2)/sigma_t^2),
and its gradients in the vertex positions and thickness values of X. <Y,Y>
is computed once, untimed, on both sides. The pykeops side computes the cell
features in numpy, the per-cell sums (value and the analytic feature
derivatives, the same formula fshape uses) in two KeOps reductions, and the
chain rule back to the vertices in numpy. Its A and gradients are checked
against fshape's exact ones. Run with scripts/varifold_compare.sh.
"""
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from pykeops.numpy import LazyTensor

ROOT = Path(__file__).resolve().parent.parent
TIMING = ROOT / "target" / "release" / "examples" / "varifold_timing"
SIGMA_F, SIGMA_T = 0.5, 0.5


def load(work, name):
    pts = np.fromfile(work / f"{name}_points.bin", dtype="<f8").reshape(-1, 3)
    faces = np.fromfile(work / f"{name}_faces.bin", dtype="<u4").reshape(-1, 3).astype(np.int64)
    sig = np.fromfile(work / f"{name}_signal.bin", dtype="<f8")
    return pts, faces, sig


def features(pts, faces, sig):
    p0, p1, p2 = pts[faces[:, 0]], pts[faces[:, 1]], pts[faces[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    n = 0.5 * np.cross(e1, e2)
    r = np.linalg.norm(n, axis=1)
    u = n / r[:, None]
    return (p0 + p1 + p2) / 3.0, u, sig[faces].mean(1), r, (e1, e2)


def sums(x, y, sigma):
    """Per cell i of x: [s0, gc (3), gu (3), gf] summed over the cells of y."""
    (cx, ux, fx, _, _), (cy, uy, fy, ry, _) = x, y
    a, b, c = 1.0 / (2 * sigma**2), 1.0 / (2 * SIGMA_F**2), 2.0 / SIGMA_T**2
    ci, cj = LazyTensor(cx[:, None, :]), LazyTensor(cy[None, :, :])
    ui, uj = LazyTensor(ux[:, None, :]), LazyTensor(uy[None, :, :])
    fi, fj = LazyTensor(fx[:, None, None]), LazyTensor(fy[None, :, None])
    rj = LazyTensor(ry[None, :, None])
    d = ci - cj
    kp = (-a * (d**2).sum(-1)).exp()
    df = fi - fj
    kf = (-b * df**2).exp()
    s = (ui * uj).sum(-1)
    kt = (c * (s**2 - 1.0)).exp()
    s0 = rj * kp * kf * kt
    gc = (-2.0 * a) * s0 * d
    gu = (rj * kp * kf * (2.0 * c) * s * kt) * uj
    gf = (-2.0 * b) * s0 * df
    return s0.concat(gc).concat(gu).concat(gf).sum(1, backend="CPU")


def inner_and_grad(x, y, sigma):
    out = sums(x, y, sigma)
    r = x[3]
    return float((r * out[:, 0]).sum()), out[:, 0], r[:, None] * out[:, 1:4], r[:, None] * out[:, 4:7], r * out[:, 7]


def pull_back(pts, faces, x, g_r, g_c, g_u, g_f):
    _, u, _, r, (e1, e2) = x
    ug = (u * g_u).sum(1)
    gn = g_r[:, None] * u + (g_u - ug[:, None] * u) / r[:, None]
    d1 = 0.5 * np.cross(e2, gn)
    d2 = 0.5 * np.cross(gn, e1)
    d0 = -d1 - d2
    gx = np.zeros_like(pts)
    gfv = np.zeros(len(pts))
    for corner, dk in ((0, d0), (1, d1), (2, d2)):
        idx = faces[:, corner]
        for k in range(3):
            gx[:, k] += np.bincount(idx, weights=dk[:, k] + g_c[:, k] / 3.0, minlength=len(pts))
        gfv += np.bincount(idx, weights=g_f / 3.0, minlength=len(pts))
    return gx, gfv


def keops_attachment(xmesh, yfeat, yy, sigma):
    pts, faces, sig = xmesh
    x = features(pts, faces, sig)
    xx, r_xx, c_xx, u_xx, f_xx = inner_and_grad(x, x, sigma)
    xy, r_xy, c_xy, u_xy, f_xy = inner_and_grad(x, yfeat, sigma)
    g = [2 * p - 2 * q for p, q in ((r_xx, r_xy), (c_xx, c_xy), (u_xx, u_xy), (f_xx, f_xy))]
    gx, gf = pull_back(pts, faces, x, *g)
    return xx - 2 * xy + yy, gx, gf


def median_s(f, reps):
    f()  # warm up: KeOps compiles its kernels on first use
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), out


def main():
    reps = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    work = ROOT / "target" / "bench-varifold"
    rows = []
    for sigma in (5.0, 10.0, 20.0):
        ours = json.loads(subprocess.run(
            [str(TIMING), repr(sigma), repr(SIGMA_F), repr(SIGMA_T), "--reps", str(reps),
             "--tol", "1e-6", "--tol", "1e-9", "--export", str(work)],
            check=True, capture_output=True, text=True).stdout)
        xmesh, ymesh = load(work, "x"), load(work, "y")
        yfeat = features(*ymesh)
        yy = inner_and_grad(yfeat, yfeat, sigma)[0]
        keops_s, (a, gx, gf) = median_s(lambda: keops_attachment(xmesh, yfeat, yy, sigma), reps)
        a_ours = float(np.fromfile(work / "ours_a.bin", dtype="<f8")[0])
        gx_ours = np.fromfile(work / "ours_gx.bin", dtype="<f8").reshape(-1, 3)
        gf_ours = np.fromfile(work / "ours_gf.bin", dtype="<f8")
        agree = (abs(a - a_ours) / abs(a), float(np.abs(gx - gx_ours).max() / np.abs(gx).max()),
                 float(np.abs(gf - gf_ours).max() / np.abs(gf).max()))
        rows.append((sigma, keops_s * 1e3, ours, agree))
        print(f"sigma={sigma}: keops {keops_s*1e3:.1f} ms, ours {ours['exact_ms']:.1f} ms, agreement {agree}", file=sys.stderr)
    print(f"Median of {reps} runs each (after one warm-up run for KeOps); fshape uses {rows[0][2]['threads']} threads; "
          f"pykeops CPU backend, float64. A + dA/dx + dA/df, 20480 x 20480 cells, sigma_f = {SIGMA_F}, sigma_t = {SIGMA_T}.")
    print()
    print("| sigma (mm) | pykeops (ms) | fshape exact (ms) | ratio | fshape tau=1e-6 (ms) | ratio | rel. err. A | fshape tau=1e-9 (ms) | ratio | rel. err. A | exact vs pykeops: A, dA/dx, dA/df |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for sigma, k, o, agree in rows:
        t6, t9 = o["truncated"]
        print(f"| {sigma:g} | {k:.0f} | {o['exact_ms']:.0f} | {o['exact_ms']/k:.2f} | {t6['ms']:.0f} | {t6['ms']/k:.2f} | {t6['rel_err_a']:.1e} "
              f"| {t9['ms']:.0f} | {t9['ms']/k:.2f} | {t9['rel_err_a']:.1e} | {agree[0]:.0e}, {agree[1]:.0e}, {agree[2]:.0e} |")


if __name__ == "__main__":
    main()
