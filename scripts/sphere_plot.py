"""Plots target/sphere_geodesics.csv (written by fshape-validate's
sphere_plots example) as docs/sphere_geodesics.png. Run scripts/sphere_plot.sh."""
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

ROOT = Path(__file__).resolve().parent.parent
rows = list(csv.DictReader(open(ROOT / "target" / "sphere_geodesics.csv")))
fig, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
for s in range(3):
    rs = [r for r in rows if int(r["setting"]) == s]
    t = [float(r["t"]) for r in rs]
    disc = [r for r in rs if r["discrete_r"]]
    for row, (name, key) in enumerate([("r_t", "r"), ("f_t", "f")]):
        ax = axes[row][s]
        ax.plot(t, [float(r[f"ode_{key}"]) for r in rs], "b-", label="ODE, χ with 2π (derived)")
        ax.plot(t, [float(r[f"paper_{key}"]) for r in rs], "r--", label="ODE, the paper's 4π")
        ax.plot([float(r["t"]) for r in disc], [float(r[f"discrete_{key}"]) for r in disc], "ko", ms=4,
                label="discrete shooting, 2562 vertices, lumped L²")
        ax.set_title(f"{name}: ρ0 = {rs[0]['rho0']}, p^f = {rs[0]['pf']}")
        ax.set_xlabel("t")
        if row == 0 and s == 0:
            ax.legend(fontsize=8)
fig.suptitle("Sphere geodesics (σ = 0.3, γ_V = 1, γ_f = 5)")
out = ROOT / "docs" / "sphere_geodesics.png"
fig.savefig(out, dpi=90)
print(f"wrote {out}")
