"""Aligns every subject of an `fshape atlas` folder made with [prealign], as
the atlas saw it (its summary's matrix applied), once more onto the
estimated template, as a second round of generalised Procrustes would;
prints the rotation (degrees) and translation (% of the diagonal) of that
second alignment. Usage: python realign.py DEMO_DIR
(e.g. demo-output/stats-spheres, from `fshape demo stats-spheres`)."""
import json
import sys

import numpy as np

import fshape

root = sys.argv[1]
summary = json.load(open(f"{root}/atlas/summary.json"))
template = fshape.read_mesh(f"{root}/atlas/template.ply")
tables = fshape.Config.read(f"{root}/atlas/config.toml").to_dict()
tables["optimizer"]["max_iterations"] = 0  # the alignment only
diag = np.linalg.norm(template.points.max(0) - template.points.min(0))
worst = [0.0, 0.0]
for subject in summary["subjects"]:
    shape = fshape.read_mesh(subject["file"])
    m = np.array(subject["prealign"]["matrix"]).reshape(4, 4)
    aligned = fshape.FShape(shape.points @ m[:3, :3].T + m[:3, 3], shape.cells, shape.signal)
    a = fshape.match(aligned, template, tables)["alignment"]
    shift = 100 * np.linalg.norm(a["translation"]) / diag
    worst = [max(worst[0], a["rotation_degrees"]), max(worst[1], shift)]
    print(f"{subject['directory']}: {a['rotation_degrees']:.3f} degrees, {shift:.4f} % of the diagonal")
print(f"largest: {worst[0]:.3f} degrees, {worst[1]:.4f} % of the diagonal")
