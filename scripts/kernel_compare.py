"""Times fshape-kernels against pykeops (CPU, float64) on the same inputs in
one run and prints a Markdown table with the ratios.

Inputs: N = M points from real cortical surfaces (conte69 32k midthickness;
pycortex S1 pial for 10^5), weights b_j in R^3 drawn uniformly in [0, 1]
with a fixed seed, Gaussian widths sigma = f x the bounding-box diagonal.
out_i = sum_j exp(-|x_i - x_j|^2 / (2 sigma^2)) b_j. fshape's exact sum is
checked against pykeops' (relative difference), its truncated and its
mixed-precision sums against its f64 exact one (max_i |err_i| /
max_i |exact_i|). KeOps writes
exp(-u / s^2); we pass it 1/(2 sigma^2) explicitly, so both compute the
same kernel. Run with scripts/kernel_compare.sh.
"""
import gzip
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from pykeops.numpy import LazyTensor

ROOT = Path(__file__).resolve().parent.parent
TIMING = ROOT / "target" / "release" / "examples" / "kernel_timing"


def read_ascii_ply(path):
    with gzip.open(path, "rt") as fh:
        lines = fh.read().splitlines()
    end = lines.index("end_header")
    nv = next(int(l.split()[2]) for l in lines[:end] if l.startswith("element vertex"))
    return np.array([[float(t) for t in l.split()[:3]] for l in lines[end + 1:end + 1 + nv]])


def keops_conv(x, b, sigma):
    a = np.array([1.0 / (2.0 * sigma * sigma)])
    xi, xj, bj = LazyTensor(x[:, None, :]), LazyTensor(x[None, :, :]), LazyTensor(b[None, :, :])
    return ((-LazyTensor(a[None, None, :]) * ((xi - xj) ** 2).sum(-1)).exp() * bj).sum(1, backend="CPU")


def median_s(f, reps):
    f()  # warm up: KeOps compiles its kernel on first use
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), out


def main():
    reps = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    conte = read_ascii_ply(ROOT / "data/conte69_32k/lh.midthickness.ply.gz")
    pycortex = read_ascii_ply(ROOT / "data/pycortex_S1/lh.pia.ply.gz")
    rng = np.random.default_rng(0)
    cases = []
    for n in (1_000, 10_000):
        cases.append((f"conte69 subset {n}", conte[np.sort(rng.choice(len(conte), n, replace=False))], (0.01, 0.05, 0.2)))
    cases.append(("conte69 32492", conte, (0.01, 0.05, 0.2)))
    cases.append(("pycortex S1 subset 100000", pycortex[np.sort(rng.choice(len(pycortex), 100_000, replace=False))], (0.05,)))
    work = ROOT / "target" / "bench-kernels"
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, x, factors in cases:
        x = np.ascontiguousarray(x)
        b = rng.random((len(x), 3))
        diam = float(np.linalg.norm(x.max(0) - x.min(0)))
        inp, outp = work / "points.bin", work / "exact.bin"
        np.hstack([x, b]).astype("<f8").tofile(inp)
        for f in factors:
            sigma = f * diam
            ours = json.loads(subprocess.run(
                [str(TIMING), str(inp), repr(sigma), "--reps", str(reps), "--tol", "1e-6", "--tol", "1e-9", "--out", str(outp)],
                check=True, capture_output=True, text=True).stdout)
            keops_s, keops_out = median_s(lambda: keops_conv(x, b, sigma), reps)
            exact = np.fromfile(outp, dtype="<f8").reshape(-1, 3)
            agree = float(np.abs(exact - keops_out).max() / np.abs(keops_out).max())
            rows.append((name, len(x), f, keops_s * 1e3, ours, agree))
            print(f"{name} f={f}: keops {keops_s*1e3:.1f} ms, ours {ours['exact_ms']:.1f} ms", file=sys.stderr)
    print(f"Median of {reps} runs each (after one warm-up run for KeOps); fshape uses {rows[0][4]['threads']} threads; pykeops CPU backend, float64.")
    print()
    print("| points | N = M | sigma / diameter | pykeops (ms) | fshape exact (ms) | ratio | fshape tau=1e-6 (ms) | ratio | rel. error | fshape tau=1e-9 (ms) | ratio | rel. error | exact vs pykeops |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, n, f, k, o, agree in rows:
        t6, t9 = o["truncated"]
        print(f"| {name} | {n} | {f} | {k:.1f} | {o['exact_ms']:.1f} | {o['exact_ms']/k:.2f} | {t6['ms']:.1f} | {t6['ms']/k:.2f} | {t6['rel_err']:.1e} | {t9['ms']:.1f} | {t9['ms']/k:.2f} | {t9['rel_err']:.1e} | {agree:.1e} |")
    print()
    print("Mixed precision (Precision::MixedF32: pair terms in f32, sums and results in f64), same runs; rel. error against fshape's f64 exact sum:")
    print()
    print("| points | N = M | sigma / diameter | pykeops (ms) | fshape exact, mixed (ms) | ratio | rel. error | fshape tau=1e-6, mixed (ms) | ratio | rel. error |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, n, f, k, o, agree in rows:
        t6 = o["truncated"][0]
        print(f"| {name} | {n} | {f} | {k:.1f} | {o['mixed_ms']:.1f} | {o['mixed_ms']/k:.3f} | {o['mixed_rel_err']:.1e} | {t6['mixed_ms']:.1f} | {t6['mixed_ms']/k:.3f} | {t6['mixed_rel_err']:.1e} |")


if __name__ == "__main__":
    main()
