"""The fshape Python package against the library's own answers: the CLI's
output for the same inputs, nibabel for the file formats, and facts that
hold whatever the implementation (round trips, shapes, error messages)."""

import json
import os
import subprocess
import threading
import warnings
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

import fshape

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "data"
NIBABEL = ROOT / "fshape-mesh" / "tests" / "data" / "nibabel"


def cli(*args):
    """Runs the fshape program (FSHAPE_BIN, else the debug build)."""
    exe = os.environ.get("FSHAPE_BIN", str(ROOT / "target" / "debug" / "fshape"))
    out = subprocess.run([exe, *map(str, args)], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout


def sphere_pair():
    """An icosahedron (12 vertices) carrying z, and a stretched copy carrying z + x/2."""
    t = (1 + 5**0.5) / 2
    base = fshape.FShape(
        np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]) / np.sqrt(1 + t * t),
        [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
         [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    p = base.points
    src = fshape.FShape(0.5 * p, base.cells, p[:, 2])
    tgt = fshape.FShape(0.5 * p * [1.3, 1.0, 0.8], base.cells, p[:, 2] + 0.5 * p[:, 0])
    return src, tgt


CONFIG = {
    "model": {"norm": "h1", "length": 0.2, "gamma_w": 400.0},
    "deformation": {"widths": [0.4, 0.2]},
    "integrator": {"steps": 5},
    "attachment": {"kernel_geom": "gaussian:0.1", "kernel_signal": "gaussian:0.5"},
    "optimizer": {"max_iterations": 10},
    "stage": [{"kernel_geom": "gaussian:0.3"}, {"kernel_geom": "gaussian:0.1"}],
}


def test_numpy_round_trip_keeps_every_value_and_dtype():
    rng = np.random.default_rng(7)
    points = rng.normal(size=(12, 3))
    cells = np.array([[0, 1, 2], [2, 3, 4], [5, 6, 7], [8, 9, 10], [9, 10, 11]], dtype=np.int32)
    signal = rng.normal(size=12)
    s = fshape.FShape(points, cells, signal)
    assert np.array_equal(s.points, points) and s.points.dtype == np.float64
    assert np.array_equal(s.cells, cells) and s.cells.dtype == np.int64
    assert np.array_equal(s.signal, signal)
    assert (s.dim, s.kind, s.n_vertices, s.n_cells) == (3, "triangle", 12, 5)
    assert fshape.FShape(s.points, s.cells, s.signal) == s
    curve = fshape.FShape([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], [[0, 1], [1, 2]])
    assert (curve.kind, curve.signal, curve.total_volume()) == ("segment", None, 2.0)


def test_bad_input_raises_fshape_error_naming_the_problem():
    with pytest.raises(fshape.FShapeError, match="vertex 2 has a NaN"):
        fshape.FShape([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]], [[0, 1, 2]])
    with pytest.raises(fshape.FShapeError, match="cell 0 uses vertex 3, but there are only 3"):
        fshape.FShape([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
    with pytest.raises(fshape.FShapeError, match="negative index -1"):
        fshape.FShape([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, -1]])
    with pytest.raises(fshape.FShapeError, match="4 columns"):
        fshape.FShape([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2, 3]])
    # A bad file is an InputError that names it and, for text, its line.
    with pytest.raises(fshape.InputError, match=r"ply_no_magic.ply: line 1") as e:
        fshape.read_mesh(ROOT / "fshape-mesh" / "tests" / "malformed" / "ply_no_magic.ply")
    assert e.value.path.endswith("ply_no_magic.ply") and e.value.line == 1
    with pytest.raises(fshape.InputError, match="gii_truncated_zlib.shape.gii: line 3") as e:
        fshape.read_signal(ROOT / "fshape-mesh" / "tests" / "malformed" / "gii_truncated_zlib.shape.gii")
    assert e.value.path.endswith("gii_truncated_zlib.shape.gii") and e.value.line == 3
    with pytest.raises(fshape.InputError) as e:
        fshape.FShape([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
    assert (e.value.path, e.value.line) == (None, None)
    # The configuration's errors are a ConfigError; all are FShapeError
    # (a ValueError).
    src, tgt = sphere_pair()
    with pytest.raises(fshape.ConfigError, match="modle: unknown field"):
        fshape.match(src, tgt, {**CONFIG, "modle": {}})
    with pytest.raises(fshape.ConfigError, match="model.gamma_w"):
        fshape.match(src, tgt, {**CONFIG, "model": {"gamma_w": -1.0}})
    for kind in (fshape.InputError, fshape.ConfigError, fshape.CheckpointError, fshape.DivergenceError):
        assert issubclass(kind, fshape.FShapeError) and issubclass(kind, ValueError)
        assert not issubclass(kind, fshape.InputError) or kind is fshape.InputError
    with pytest.raises(fshape.FShapeError, match="unknown kernel|gaussian"):
        fshape.attachment(src, tgt, "gauss:0.1", "binet")


def test_a_config_comes_from_tables_toml_text_or_a_file_and_text_is_never_guessed(tmp_path):
    from_tables = fshape.Config(CONFIG)
    text = from_tables.to_toml()
    from_text = fshape.Config.from_toml(text)
    (tmp_path / "c.toml").write_text(text)
    from_file = fshape.Config.read(tmp_path / "c.toml")
    assert from_text.to_dict() == from_tables.to_dict() == from_file.to_dict()
    assert from_tables.to_dict()["deformation"]["widths"] == CONFIG["deformation"]["widths"]
    src, tgt = sphere_pair()
    runs = [fshape.match(src, tgt, c) for c in (from_tables, CONFIG, tmp_path / "c.toml", str(tmp_path / "c.toml"))]
    assert all(np.array_equal(r["p0"], runs[0]["p0"]) for r in runs)
    # A string is a path: TOML text passed as one is refused with the way to pass it.
    with pytest.raises(fshape.FShapeError, match=r"no file .*Config\.from_toml"):
        fshape.match(src, tgt, text)
    with pytest.raises(fshape.FShapeError, match="line 2"):
        fshape.Config.from_toml("[model]\ngamma_w = \n")
    with pytest.raises(fshape.FShapeError, match="missing.toml"):
        fshape.Config.read(tmp_path / "missing.toml")


def test_validation_reports_warnings_with_their_place():
    s = fshape.FShape([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]], [[0, 1, 2]])
    v = s.validate()
    assert v["errors"] == []
    codes = {w["code"]: w["message"] for w in v["warnings"]}
    assert "unused_vertex" in codes and "3" in codes["unused_vertex"]


def test_the_attachment_equals_the_cli_distance_on_the_shipped_cortex(tmp_path):
    lh = fshape.read_mesh(DATA / "fsaverage5" / "lh.pial.thick.ply.gz")
    rh = fshape.read_mesh(DATA / "fsaverage5" / "rh.pial.ply.gz")
    _, thick = fshape.read_signal(DATA / "fsaverage5" / "rh.thick.csv.gz")
    target = rh.with_signal(thick)
    kernels = ("gaussian:10", "gaussian-unoriented:0.5", "gaussian:0.5")
    mine = fshape.attachment(lh, target, *kernels)
    theirs = json.loads(cli("distance", DATA / "fsaverage5" / "lh.pial.thick.ply.gz",
                            DATA / "fsaverage5" / "rh.pial.ply.gz", "--target-signal",
                            DATA / "fsaverage5" / "rh.thick.csv.gz", "--kernel-geom", kernels[0],
                            "--kernel-grass", kernels[1], "--kernel-signal", kernels[2], "--json"))
    for k in ("value", "xx", "xy", "yy"):
        assert mine[k] == theirs[k], k


def test_the_attachment_gradient_matches_central_differences():
    src, tgt = sphere_pair()
    kernels = ("gaussian:0.2", "binet", "gaussian:0.5")
    value, gp, gf = fshape.attachment_grad(src, tgt, *kernels)
    assert gp.shape == (12, 3) and gf.shape == (12,)
    assert value == fshape.attachment(src, tgt, *kernels)
    h = 1e-6
    for v, c in [(0, 0), (5, 2), (9, 1)]:
        plus, minus = src.points.copy(), src.points.copy()
        plus[v, c] += h
        minus[v, c] -= h
        a = lambda p: fshape.attachment(fshape.FShape(p, src.cells, src.signal), tgt, *kernels)["value"]  # noqa: E731
        assert abs((a(plus) - a(minus)) / (2 * h) - gp[v, c]) < 1e-6 * max(1.0, abs(gp[v, c]))
    f = src.signal.copy()
    f[3] += h
    up = fshape.attachment(src.with_signal(f), tgt, *kernels)["value"]
    f[3] -= 2 * h
    down = fshape.attachment(src.with_signal(f), tgt, *kernels)["value"]
    assert abs((up - down) / (2 * h) - gf[3]) < 1e-6 * max(1.0, abs(gf[3]))


def test_several_maps_per_vertex_are_n_by_k_arrays_compared_with_a_width_each(tmp_path):
    src, tgt = sphere_pair()
    x = src.points[:, 0]
    two = src.with_signal(np.column_stack([src.signal, x]))
    assert two.n_channels == 2 and src.n_channels == 1 and two.signal.shape == (12, 2)
    assert np.array_equal(two.signal[:, 0], src.signal) and "2 signal channels" in repr(two)
    # A second map that is the same constant on both sides changes no bit.
    const = lambda s: s.with_signal(np.column_stack([s.signal, np.full(s.n_vertices, 2.5)]))  # noqa: E731
    assert fshape.attachment(src, tgt, "gaussian:0.2", "binet", "gaussian:0.5") == fshape.attachment(
        const(src), const(tgt), "gaussian:0.2", "binet", "gaussian:0.5,0.1")
    # A change in the second map alone is seen, with the gradient of both maps.
    kernels = ("gaussian:0.2", "binet", "gaussian:0.5,0.3")
    moved = two.with_signal(two.signal + [0.0, 0.3])
    value, _, gf = fshape.attachment_grad(two, moved, *kernels)
    assert value["value"] > 0 and gf.shape == (12, 2)
    h = 1e-6
    for v, c in [(4, 0), (7, 1)]:
        up, down = two.signal.copy(), two.signal.copy()
        up[v, c] += h
        down[v, c] -= h
        a = lambda f: fshape.attachment(two.with_signal(f), moved, *kernels)["value"]  # noqa: E731
        assert abs((a(up) - a(down)) / (2 * h) - gf[v, c]) < 1e-6 * max(1.0, abs(gf[v, c]))
    # The norm sums over the maps; maps against another count are refused.
    both = fshape.signal_norm(src, "l2") + fshape.signal_norm(src.with_signal(x), "l2")
    assert fshape.signal_norm(two, "l2") == pytest.approx(both, rel=1e-12)
    with pytest.raises(fshape.FShapeError, match="channels"):
        fshape.attachment(two, src, "gaussian:0.2", "binet", "gaussian:0.5")
    # A registration of two maps: each channel's error falls, the results
    # are n × k.
    two_tgt = tgt.with_signal(np.column_stack([tgt.signal, tgt.points[:, 0] + 0.2]))
    widths = {**CONFIG, "attachment": {"kernel_geom": "gaussian:0.1", "kernel_signal": "gaussian:0.5,0.5"}}
    r = fshape.match(two, two_tgt, widths)
    assert r.matched.n_channels == 2 and r.pf.shape == (12, 2)
    assert r.geodesic["signals"].shape[1:] == (12, 2)
    for c in range(2):
        assert r.quality["channels"][c]["signal_rms"] < r.initial_quality["channels"][c]["signal_rms"]
    # Its momenta shot again with the weights it used end where it ended.
    shot = fshape.shoot(two, r.p0, r.config, pf=r.pf)
    assert np.allclose(shot.signals[-1], r.geodesic["signals"][-1], rtol=1e-9, atol=1e-12)
    with pytest.raises(fshape.FShapeError, match=r"pf: shape \[12\]"):
        fshape.shoot(two, r.p0, r.config, pf=np.zeros(12))
    # Its report: a scene per map, each map's error.
    fshape.report(tmp_path / "report.html", two, two_tgt, r)
    page = (tmp_path / "report.html").read_text()
    assert "signal channel 2 of 2" in page and "channel 2: signal error" in page


def test_signal_norms_of_a_constant_signal_are_the_area():
    src, _ = sphere_pair()
    one = src.with_signal(np.ones(src.n_vertices))
    area = src.total_volume()
    for norm in ("l2-lumped", "l2", "h1"):
        assert fshape.signal_norm(one, norm, length=0.3) == pytest.approx(area, rel=1e-12)
    # H1 adds length^2 times the Dirichlet energy of a varying signal.
    assert fshape.signal_norm(src, "h1", 1.0) > fshape.signal_norm(src, "l2")


def test_a_small_match_equals_the_cli_on_the_same_inputs_and_config(tmp_path):
    src, tgt = sphere_pair()
    fshape.write_mesh(tmp_path / "src.ply", src)
    fshape.write_mesh(tmp_path / "tgt.ply", tgt)
    lines = [
        '[model]\nnorm = "h1"\nlength = 0.2\ngamma_w = 400.0',
        "[deformation]\nwidths = [0.4, 0.2]",
        "[integrator]\nsteps = 5",
        '[attachment]\nkernel_geom = "gaussian:0.1"\nkernel_signal = "gaussian:0.5"',
        "[optimizer]\nmax_iterations = 10",
        '[schedule]\nkernel_geom = ["gaussian:0.3", "gaussian:0.1"]',
    ]
    (tmp_path / "match.toml").write_text("\n".join(lines) + "\n")
    cli("match", tmp_path / "src.ply", tmp_path / "tgt.ply", "--config", tmp_path / "match.toml",
        "--out", tmp_path / "run")
    events = []
    result = fshape.match(src, tgt, CONFIG, progress=events.append)
    # The same optimisation: the same momenta to the last bit, the same end.
    p0 = np.loadtxt(tmp_path / "run" / "p0.csv", delimiter=",", skiprows=1)
    pf = np.loadtxt(tmp_path / "run" / "pf.csv", delimiter=",", skiprows=1)
    assert np.array_equal(result.p0, p0) and np.array_equal(result.pf, pf)
    end = fshape.read_mesh(tmp_path / "run" / "state_004.ply")
    assert np.array_equal(result.matched.points, end.points)
    assert np.array_equal(result.geodesic["points"][-1], end.points)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert result.energies["value"] == summary["final_value"]
    assert result.quality["mean_distance"] == summary["quality"]["mean_distance"]
    assert result.quality["mean_distance"] < result.initial_quality["mean_distance"]
    # The progress callback saw both stages and every iteration.
    assert [e["stage"] for e in events if e["event"] == "stage"] == [0, 1]
    assert sum(e["event"] == "iteration" for e in events) == result.iterations
    g = result.geodesic
    assert g.points.shape == (5, 12, 3) and g.signals.shape == (5, 12)
    # The weights it used shoot the momenta to the same end.
    shot = fshape.shoot(src, result.p0, result.config, pf=result.pf)
    assert np.array_equal(shot.points[-1], end.points)


def test_a_correspondence_follows_the_stated_rules_and_carries_as_the_cli_transfers(tmp_path):
    # One triangle; onto points at barycentric (0.6, 0.3, 0.1), (0.2, 0.4, 0.4)
    # and one 2 above (0.2, 0.2, 0.6).
    tri = fshape.FShape([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    onto = fshape.FShape([[0.3, 0.1, 0], [0.4, 0.4, 0], [0.2, 0.6, 2]], [[0, 1, 2]])
    c = fshape.Correspondence(tri, onto)
    assert len(c) == 3 and np.allclose(c.distances, [0, 0, 2])
    values, counts = c.map([np.nan, 10.0, 20.0], max_distance=1.0)
    # Corner 0 has no value: 0.4 of the weight is left at the first point
    # (NaN), 0.8 at the second: (0.4 * 10 + 0.4 * 20) / 0.8.
    assert np.isnan(values[0]) and values[1] == pytest.approx(15.0) and np.isnan(values[2])
    assert counts == {"vertices": 3, "beyond": 1, "missing": 1}
    assert c.map([1.0, 10.0, 20.0])[0][2] == pytest.approx(0.2 + 2.0 + 12.0)
    labels = c.labels(np.array([7, 3, 4]), max_distance=1.0)
    assert labels.dtype == np.int32 and labels.tolist() == [7, 3, -1]
    with pytest.raises(fshape.FShapeError, match="3 vertices"):
        c.map([1.0, 2.0])
    with pytest.raises(fshape.FShapeError, match="outside int32"):
        c.labels([1, 2, 2**40])

    # Through a registration: the result's matched and target shapes carry
    # a map as `fshape transfer` carries it from the run's folder.
    src, tgt = sphere_pair()
    fshape.write_mesh(tmp_path / "src.ply", src)
    fshape.write_mesh(tmp_path / "tgt.ply", tgt)
    (tmp_path / "match.toml").write_text(
        '[model]\nnorm = "h1"\nlength = 0.2\ngamma_w = 400.0\n[deformation]\nwidths = [0.4, 0.2]\n'
        '[integrator]\nsteps = 5\n[attachment]\nkernel_geom = "gaussian:0.1"\nkernel_signal = "gaussian:0.5"\n'
        '[optimizer]\nmax_iterations = 10\n[schedule]\nkernel_geom = ["gaussian:0.3", "gaussian:0.1"]\n'
    )
    cli("match", tmp_path / "src.ply", tmp_path / "tgt.ply", "--config", tmp_path / "match.toml",
        "--out", tmp_path / "run")
    result = fshape.match(src, tgt, CONFIG)
    thickness = np.sin(3 * src.points[:, 0]) + src.points[:, 1]
    thickness[src.points[:, 2] > 0.4] = np.nan
    fshape.write_signal(tmp_path / "thickness.csv", thickness, name="thickness")
    cli("transfer", tmp_path / "run", tmp_path / "thickness.csv", tmp_path / "on_target.csv", "--max-distance", "1")
    on_target, _ = fshape.Correspondence(result.matched, result.target).map(thickness, max_distance=1.0)
    cli_values = np.genfromtxt(tmp_path / "on_target.csv", delimiter=",", skip_header=1)
    assert np.allclose(on_target, cli_values, rtol=0, atol=1e-12, equal_nan=True)
    assert np.isnan(on_target).any() and np.isfinite(on_target).sum() > 6


def test_prealignment_brings_a_turned_shifted_copy_back_and_agrees_with_the_cli(tmp_path):
    # The bunny (geometry only) turned by 120 degrees about a tilted axis and shifted:
    # a rigid [prealign] undoes it before a short registration.
    bunny = fshape.read_mesh(DATA / "stanford_bunny" / "bunny_qslim_2581v.ply.gz")
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    a = np.radians(120.0)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    r = np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k
    moved = fshape.FShape(bunny.points @ r.T + [0.05, -0.02, 0.1], bunny.cells, bunny.signal)
    diag = np.linalg.norm(bunny.points.max(0) - bunny.points.min(0))
    w = 0.05 * diag
    config = {
        "model": {"gamma_w": 100.0},
        "deformation": {"widths": [2 * w]},
        "attachment": {"kernel_geom": f"gaussian:{w}", "kernel_grass": "binet"},
        "optimizer": {"max_iterations": 2},
        "prealign": {"kind": "rigid"},
    }
    result = fshape.match(moved, bunny, config)
    al = result.alignment
    assert al["kind"] == "rigid" and al["moving"] == "source"
    t = np.array(al["matrix"])
    # T undoes the motion: T(R x + b) = x, so T's linear part is R^T.
    assert np.allclose(t[:3, :3], r.T, atol=0.02), t
    back = moved.points @ t[:3, :3].T + t[:3, 3]
    assert np.abs(back - bunny.points).max() < 0.01 * diag
    assert al["attachment_after"] < 1e-3 * al["attachment_before"]
    # The program finds the same map, and says so in summary.json.
    fshape.write_mesh(tmp_path / "moved.ply", moved)
    (tmp_path / "c.toml").write_text(fshape.Config(config).to_toml())
    cli("match", tmp_path / "moved.ply", DATA / "stanford_bunny" / "bunny_qslim_2581v.ply.gz",
        "--config", tmp_path / "c.toml", "--out", tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["prealign"]["matrix"] == al["matrix"]


def test_the_callback_ends_a_run_with_its_result_so_far_and_its_exceptions_propagate():
    src, tgt = sphere_pair()
    whole = fshape.match(src, tgt, CONFIG)
    assert whole.stopped is False
    # True at the third iteration: the run ends there and returns where it got.
    early = fshape.match(src, tgt, CONFIG, progress=stop_at(3))
    assert early.stopped is True and early.iterations == 3
    assert early.p0.shape == whole.p0.shape and early.matched.points.shape == src.points.shape
    assert early.energies["value"] > whole.energies["value"]
    # True at the first event: the start, zero momenta.
    start = fshape.match(src, tgt, CONFIG, progress=lambda e: True)
    assert start.stopped is True and start.iterations == 0
    assert not start.p0.any() and np.array_equal(start.matched.points, src.points)

    def boom(event):
        raise RuntimeError("from the callback")

    with pytest.raises(RuntimeError, match="from the callback"):
        fshape.match(src, tgt, CONFIG, progress=boom)


def stop_at(n):
    """A progress callback that stops the run at its n-th iteration."""
    seen = []

    def callback(event):
        seen.append(event["event"] == "iteration")
        return sum(seen) == n and seen[-1]

    return callback


def test_a_match_stopped_anywhere_resumes_from_its_checkpoint_to_the_same_bits(tmp_path):
    src, tgt = sphere_pair()
    whole = fshape.match(src, tgt, CONFIG)
    assert whole.iterations > 4
    path = tmp_path / "run.ckpt"
    stopped = fshape.match(src, tgt, CONFIG, progress=stop_at(4), checkpoint=path)
    assert stopped.stopped is True and stopped.iterations == 4
    assert path.exists()
    events = []
    resumed = fshape.match(src, tgt, CONFIG, progress=events.append, checkpoint=path)
    # It went on from the fourth iteration, not from the start.
    assert sum(e["event"] == "iteration" for e in events) == whole.iterations - 4
    assert resumed.iterations == whole.iterations
    assert np.array_equal(resumed.p0, whole.p0) and np.array_equal(resumed.pf, whole.pf)
    assert np.array_equal(resumed.matched.points, whole.matched.points)
    # Once finished, the same call returns the result without iterating.
    events.clear()
    again = fshape.match(src, tgt, CONFIG, progress=events.append, checkpoint=path)
    assert not any(e["event"] == "iteration" for e in events)
    assert np.array_equal(again.p0, whole.p0)
    # A checkpoint of other inputs, or a damaged one, is refused, naming the file.
    with pytest.raises(fshape.CheckpointError, match=r"run\.ckpt: .*other inputs"):
        fshape.match(src, src, CONFIG, checkpoint=path)
    path.write_bytes(path.read_bytes()[:40])
    with pytest.raises(fshape.CheckpointError, match=r"run\.ckpt: the checkpoint is damaged or truncated"):
        fshape.match(src, tgt, CONFIG, checkpoint=path)


def test_the_gil_is_released_while_the_library_computes():
    # The cortex's attachment takes seconds. While a thread computes it,
    # this thread keeps running Python: it ticks every millisecond. Were
    # the GIL held, it could not tick at all until the computation ended.
    lh = fshape.read_mesh(DATA / "fsaverage5" / "lh.pial.thick.ply.gz")
    rh = fshape.read_mesh(DATA / "fsaverage5" / "rh.pial.ply.gz")
    worker = threading.Thread(target=fshape.attachment, args=(lh, rh, "gaussian:10", "binet"))
    ticks = 0
    worker.start()
    while worker.is_alive():
        ticks += 1
        worker.join(0.001)
    assert ticks > 50


def test_shooting_with_zero_momenta_stays_put_and_bad_lengths_are_refused():
    src, _ = sphere_pair()
    config = {"model": {"normalize": False}, "deformation": {"widths": [0.3]}, "integrator": {"steps": 4}}
    g = fshape.shoot(src, np.zeros((12, 3)), config)
    assert g.points.shape == (5, 12, 3)
    assert np.array_equal(g.points[-1], src.points)
    with pytest.raises(fshape.FShapeError, match="p0: shape"):
        fshape.shoot(src, np.zeros((11, 3)), config)
    with pytest.raises(fshape.FShapeError, match="normalize"):
        fshape.shoot(src, np.zeros((12, 3)), {"deformation": {"widths": [0.3]}})
    # Momenta far too large for four steps: the Hamiltonian drifts.
    with pytest.raises(fshape.DivergenceError, match="shooting diverged"):
        fshape.shoot(src, 1e4 * np.random.default_rng(0).normal(size=(12, 3)), config)


def test_transport_carries_momenta_there_and_back():
    src, _ = sphere_pair()
    rng = np.random.default_rng(3)
    p0, pf = 0.1 * rng.normal(size=(12, 3)), 0.1 * rng.normal(size=12)
    beta, beta_f = rng.normal(size=(12, 3)), rng.normal(size=12)
    scale = np.linalg.norm(np.concatenate([beta.ravel(), beta_f]))
    errors = []
    for steps in [20, 40]:
        config = {"model": {"normalize": False, "gamma_f": 0.5}, "deformation": {"widths": [0.6]},
                  "integrator": {"steps": steps}}
        there, there_f = fshape.transport(src, p0, config, beta, pf=pf, beta_f=beta_f)
        assert there.shape == (12, 3) and there_f.shape == (12,)
        home, home_f = fshape.transport(src, p0, config, there, pf=pf, beta_f=there_f, back=True)
        moved = np.linalg.norm(np.concatenate([(there - beta).ravel(), there_f - beta_f])) / scale
        errors.append(np.linalg.norm(np.concatenate([(home - beta).ravel(), home_f - beta_f])) / scale)
        # The momenta move on the way (63 % measured) and come back.
        assert moved > 0.3, moved
    # First order in the step (1.1 % at 20 steps, 0.56 % at 40 measured).
    assert errors[1] < 0.015 and errors[1] < 0.6 * errors[0], errors
    with pytest.raises(fshape.FShapeError, match="beta: shape"):
        fshape.transport(src, p0, config, beta[:5], pf=pf)
    with pytest.raises(fshape.FShapeError, match="second-order integrator"):
        fshape.transport(src, p0, {**config, "integrator": {"scheme": "euler", "steps": 20}}, beta)


def test_an_atlas_of_three_subjects_brings_its_template_closer():
    src, tgt = sphere_pair()
    mid = fshape.FShape(0.5 * (src.points + tgt.points), src.cells, 0.5 * (src.signal + tgt.signal))
    config = {**CONFIG, "optimizer": {"max_iterations": 6}}
    del config["stage"]
    far = fshape.FShape(src.points * [0.8, 1.1, 1.2], src.cells, src.signal - 0.3)
    r = fshape.atlas([src, tgt, far], config, template=mid)
    assert isinstance(r.template, fshape.FShape) and len(r.subjects) == 3
    assert r.stages[0]["iterations"][-1]["value"] < r.stages[0]["initial"]["value"]
    assert all(s.p0.shape == (12, 3) for s in r.subjects)
    after = sum(s.energies["attachment"] for s in r.subjects)
    before = sum(s.initial_attachment for s in r.subjects)
    assert 0 < after < 0.5 * before


def test_a_regression_fits_its_visits_and_equals_the_cli(tmp_path):
    src, tgt = sphere_pair()
    mid = fshape.FShape(0.5 * (src.points + tgt.points), src.cells, 0.5 * (src.signal + tgt.signal))
    visits = [src, tgt, mid]
    ages = [30.0, 32.0, 31.0]
    for name, v in zip(["a", "b", "c"], visits):
        fshape.write_mesh(tmp_path / f"{name}.ply", v)
    (tmp_path / "visits.csv").write_text("age,mesh\n30,a.ply\n32,b.ply\n31,c.ply\n")
    lines = [
        '[model]\nnorm = "h1"\nlength = 0.2\ngamma_w = 400.0',
        "[deformation]\nwidths = [0.4, 0.2]",
        "[integrator]\nsteps = 5",
        '[attachment]\nkernel_geom = "gaussian:0.1"\nkernel_signal = "gaussian:0.5"',
        "[optimizer]\nmax_iterations = 10",
        '[[stage]]\nkernel_geom = "gaussian:0.3"\n[[stage]]\nkernel_geom = "gaussian:0.1"',
    ]
    (tmp_path / "regress.toml").write_text("\n".join(lines) + "\n")
    cli("regress", "--visits", tmp_path / "visits.csv", "--config", tmp_path / "regress.toml", "--out", tmp_path / "run")
    r = fshape.regress(visits, ages, CONFIG)
    assert (r.t0, r.span) == (30.0, 2.0) and list(r.times) == [0.0, 1.0, 0.5]
    # The same optimisation as the program's, to the last bit.
    p0 = np.loadtxt(tmp_path / "run" / "p0.csv", delimiter=",", skiprows=1)
    assert np.array_equal(r.p0, p0)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert r.energies["value"] == summary["final_value"]
    # Each later visit is closer to its fit than to the baseline.
    for q, q0 in zip(r.quality[1:], r.initial_quality[1:]):
        assert q["mean_distance"] < 0.5 * q0["mean_distance"]
    assert len(r.fitted) == 3 and r.rates["normal_velocity"].shape == (12,) and r.rates["signal_rate"].shape == (12,)
    g = r.geodesic
    assert list(g.times) == [30.0, 30.5, 31.0, 31.5, 32.0] and g.points.shape == (5, 12, 3)
    assert np.allclose(g.points[-1], r.fitted[1].points) and np.allclose(g.points[2], r.fitted[2].points)
    with pytest.raises(fshape.FShapeError, match="3 visits but 2 ages"):
        fshape.regress(visits, ages[:2], CONFIG)
    with pytest.raises(fshape.FShapeError, match="ages_out: 29"):
        fshape.regress(visits, ages, CONFIG, ages_out=[29.0])


def test_an_atlas_of_subjects_with_two_maps_gives_a_template_of_two_maps():
    src, tgt = sphere_pair()
    two = [s.with_signal(np.column_stack([s.signal, s.points[:, 1] - 0.1 * i])) for i, s in enumerate([src, tgt])]
    config = {**CONFIG, "attachment": {"kernel_geom": "gaussian:0.1", "kernel_signal": "gaussian:0.5,0.5"},
              "optimizer": {"max_iterations": 6}}
    del config["stage"]
    r = fshape.atlas(two, config)
    assert r.template.n_channels == 2 and r.template.signal.shape == (12, 2)
    for s in r.subjects:
        assert s.pf.shape == (12, 2) and s.matched.n_channels == 2
        assert s.geodesic["signals"].shape[1:] == (12, 2)
        assert len(s.quality["channels"]) == 2
    with pytest.raises(fshape.FShapeError, match="and subject 1 carries 1"):
        fshape.atlas([two[0], tgt], config)
    # Stats test each map: `signal_2` beside `signal`, by name too.
    four = two + [s.with_signal(s.signal + [0.1, 0.3]) for s in two]
    r4 = fshape.atlas(four, {**config, "optimizer": {"max_iterations": 2}})
    st = fshape.stats(r4, {"group": ["a", "a", "b", "b"]}, "group", permutations=24)
    assert {"signal", "signal_2", "area"} <= set(st.maps)
    one = fshape.stats(r4, {"group": ["a", "a", "b", "b"]}, "group", maps=["signal_2"], permutations=24)
    assert list(one.maps) == ["signal_2"]
    assert np.array_equal(one.maps["signal_2"]["statistic"], st.maps["signal_2"]["statistic"])


def test_an_atlas_stopped_anywhere_resumes_from_its_checkpoint_to_the_same_bits(tmp_path):
    src, tgt = sphere_pair()
    config = {**CONFIG, "optimizer": {"max_iterations": 4}}
    whole = fshape.atlas([src, tgt], config)
    path = tmp_path / "atlas.ckpt"
    with pytest.raises(fshape.FShapeError, match="resumes it") as e:
        fshape.atlas([src, tgt], config, progress=stop_at(3), checkpoint=path)
    # A stop asked for is no bad input: the base class itself.
    assert type(e.value) is fshape.FShapeError
    resumed = fshape.atlas([src, tgt], config, checkpoint=path)
    assert resumed.iterations == whole.iterations > 3
    assert np.array_equal(resumed.template.points, whole.template.points)
    assert np.array_equal(resumed.template.signal, whole.template.signal)
    assert all(np.array_equal(a["p0"], b["p0"]) for a, b in zip(resumed["subjects"], whole["subjects"]))


@pytest.mark.parametrize("encoding", ["ascii", "base64", "gzip-base64"])
@pytest.mark.parametrize("big_endian", [False, True])
@pytest.mark.parametrize("column_major", [False, True])
def test_nibabel_reads_the_gifti_fshape_writes(tmp_path, encoding, big_endian, column_major):
    src, _ = sphere_pair()
    path = tmp_path / "s.surf.gii"
    fshape.write_mesh(path, src, gifti_encoding=encoding, big_endian=big_endian, column_major=column_major)
    g = nib.load(path)
    assert g.darrays[0].endian == (nib.gifti.util.gifti_endian_codes.code["big" if big_endian else "little"])
    assert np.array_equal(g.agg_data("pointset"), src.points.astype(np.float32))
    assert np.array_equal(g.agg_data("triangle"), src.cells)
    assert np.array_equal(g.agg_data("shape"), src.signal.astype(np.float32))
    fshape.write_signal(tmp_path / "f.shape.gii", src.signal, name="thickness")
    d = nib.load(tmp_path / "f.shape.gii").darrays[0]
    assert d.meta["Name"] == "thickness" and np.array_equal(d.data, src.signal.astype(np.float32))


def test_the_default_gifti_encodings_are_gzip_base64_and_ascii(tmp_path):
    src, _ = sphere_pair()
    fshape.write_mesh(tmp_path / "b.gii", src)
    fshape.write_mesh(tmp_path / "a.gii", src, ascii=True)
    assert 'Encoding="GZipBase64Binary"' in (tmp_path / "b.gii").read_text()
    assert 'Encoding="ASCII"' in (tmp_path / "a.gii").read_text()
    with pytest.raises(fshape.FShapeError, match="unknown output format"):
        fshape.write_mesh(tmp_path / "s.ply", src, big_endian=True)
    assert not (tmp_path / "s.ply").exists()


def test_nibabel_reads_the_freesurfer_files_fshape_writes(tmp_path):
    src, _ = sphere_pair()
    fshape.write_mesh(tmp_path / "lh.pial", src)
    p, f = nib.freesurfer.read_geometry(tmp_path / "lh.pial")
    assert np.array_equal(p, src.points.astype(np.float32)) and np.array_equal(f, src.cells)
    fshape.write_signal(tmp_path / "lh.thickness", src.signal, faces=src.n_cells)
    assert np.array_equal(nib.freesurfer.read_morph_data(tmp_path / "lh.thickness"), src.signal.astype(np.float32))
    for ext in ("mgh", "mgz"):
        fshape.write_signal(tmp_path / f"t.{ext}", src.signal)
        data = np.asarray(nib.load(tmp_path / f"t.{ext}").dataobj).ravel()
        assert np.array_equal(data, src.signal.astype(np.float32))


def test_the_nibabel_fixtures_read_back_through_the_package():
    points = np.loadtxt(NIBABEL / "expected_points.csv", delimiter=",", skiprows=1)
    thickness = np.loadtxt(NIBABEL / "expected_thickness.csv", skiprows=1)
    s = fshape.read_mesh(NIBABEL / "surf_bigendian_gzipbase64.surf.gii", signal_name="thickness")
    assert np.array_equal(s.points, points) and np.array_equal(s.signal, thickness)
    assert np.array_equal(fshape.read_signal(NIBABEL / "lh.thickness")[1], thickness)


def test_every_gifti_file_of_nibabel_s_tests_reads_as_nibabel_reads_it():
    """nibabel's own GIfTI test files (in its wheel): the surfaces and signals
    it reads, fshape reads to the same arrays; a file nibabel reads whose
    triangles are not a valid mesh gets fshape's validation error; a signal
    file of several arrays is refused by name."""
    folder = Path(nib.__file__).parent / "gifti" / "tests" / "data"
    files = sorted(folder.glob("*.gii*"))
    assert len(files) >= 10, files
    seen = {"surface": 0, "signal": 0, "invalid": 0, "several": 0}
    for f in files:
        arrays = nib.load(f).darrays
        intents = [nib.nifti1.intent_codes.label[d.intent] for d in arrays]
        if "pointset" in intents and "triangle" in intents:
            points = arrays[intents.index("pointset")].data.astype(np.float64)
            cells = arrays[intents.index("triangle")].data.astype(np.int64)
            if cells.max() < len(points):
                s = fshape.read_mesh(f)
                assert np.array_equal(s.points, points) and np.array_equal(s.cells, cells), f
                seen["surface"] += 1
            else:
                with pytest.raises(fshape.FShapeError, match="index_out_of_range"):
                    fshape.read_mesh(f)
                seen["invalid"] += 1
        elif len(arrays) == 1:
            name, values = fshape.read_signal(f)
            assert np.array_equal(values, arrays[0].data.astype(np.float64).ravel()), f
            seen["signal"] += 1
        else:
            with pytest.raises(fshape.FShapeError, match="name the data array after the file"):
                fshape.read_signal(f)
            # Each is read by its number from 1 after the file.
            for i in (0, len(arrays) - 1) if all(a.data.ndim == 1 for a in arrays) else ():
                _, values = fshape.read_signal(f"{f}:{i + 1}")
                assert np.array_equal(values, arrays[i].data.astype(np.float64).ravel()), (f, i)
            seen["several"] += 1
    # The folder as nibabel 5.4 ships it: external, bz2 and gz surfaces,
    # GIFTI_ENDIAN_LITTLE, labels, shapes and a time series.
    assert seen == {"surface": 4, "signal": 4, "invalid": 2, "several": 1}, seen


def test_stats_on_an_atlas_gives_the_cli_s_maps_and_names_a_bad_column(tmp_path):
    # A small two-group atlas by the program (the stats-spheres demo's
    # inputs, a few iterations), read back as `fshape.atlas` returns one.
    cli("demo", "stats-spheres", "--quick", "--subjects", "4", "--max-iterations", "5",
        "--permutations", "100", "--out", tmp_path)
    root = tmp_path / "stats-spheres"
    summary = json.loads((root / "atlas" / "summary.json").read_text())
    atlas = {
        "template": fshape.read_mesh(root / "atlas" / "template.ply"),
        "subjects": [
            {
                "p0": np.loadtxt(root / "atlas" / s["directory"] / "p0.csv", delimiter=",", skiprows=1),
                "matched": fshape.read_mesh(root / "atlas" / s["directory"] / "matched.ply"),
            }
            for s in summary["subjects"]
        ],
    }
    groups = [line.split(",")[1] for line in (root / "covariates.csv").read_text().splitlines()[1:]]
    cli("stats", root / "atlas", "--covariates", root / "covariates.csv", "--contrast", "group",
        "--permutations", "100", "--tfce", "--out", tmp_path / "cli")
    r = fshape.stats(atlas, {"group": groups}, "group", permutations=100, tfce=True)
    assert r["design"]["columns"] == ["intercept", "group[effect]"]
    for name in ["signal", "momentum", "displacement", "area"]:
        m = r["maps"][name]
        _, t = fshape.read_signal(tmp_path / "cli" / f"{name}_t.gii")
        # GIfTI stores single precision.
        assert np.allclose(m["statistic"], t, rtol=1e-6, atol=1e-6)
        for key in ["p_fwe", "tfce_p_fwe"]:
            _, p = fshape.read_signal(tmp_path / "cli" / f"{name}_{key}.gii")
            # p-values are multiples of 1/100, exact in single precision to 1e-8.
            assert np.allclose(m[key], p, rtol=0, atol=1e-7)
        assert m["kind"] == "t" and tuple(m["dof"]) == (1, 6)
    with pytest.raises(fshape.FShapeError, match="column `site`.*single group"):
        fshape.stats(atlas, {"group": groups, "site": ["a"] * 8}, "group", permutations=10)
    with pytest.raises(fshape.FShapeError, match="3 values for 8 subjects"):
        fshape.stats(atlas, {"group": groups[:3]}, "group", permutations=10)


def test_report_writes_one_self_contained_page_of_the_registration(tmp_path):
    src, tgt = sphere_pair()
    r = fshape.match(src, tgt, {**CONFIG, "optimizer": {"max_iterations": 3}})
    path = tmp_path / "report.html"
    fshape.report(path, src, tgt, r)
    page = path.read_text()
    assert "<canvas id=\"view\">" in page and "default-src 'none'" in page
    assert "src=\"http" not in page and "<link" not in page
    data = json.loads(page.split('id="fshape-data">', 1)[1].split("</script>", 1)[0])
    # Every node of the geodesic, and the target beside it.
    assert len(data["scenes"][0]["mesh"]["frames"]) == len(r["geodesic"]["times"])
    assert len(data["scenes"][0]["companion"]["frames"]) == 1
    assert "How close it came" in page
    with pytest.raises(fshape.FShapeError, match="geodesic has 12 vertices"):
        fshape.report(path, fshape.FShape(src.points[:4], [[0, 1, 2], [1, 2, 3]]), tgt, r)
    # The report reads the result's typed record, not its attributes: a
    # dict with the same keys is refused.
    with pytest.raises(TypeError, match="MatchResult"):
        fshape.report(path, src, tgt, {key: r[key] for key in r.keys()})


def test_results_are_read_only_classes_that_still_index_by_their_keys():
    src, tgt = sphere_pair()
    r = fshape.match(src, tgt, {**CONFIG, "optimizer": {"max_iterations": 2}})
    assert type(r) is fshape.MatchResult and type(r.geodesic) is fshape.Geodesic
    assert r.keys()[:3] == ["stopped", "p0", "pf"] and "matched" in r and "p1" not in r
    assert r["matched"] is r.matched and r.geodesic["points"] is r.geodesic.points
    with pytest.raises(KeyError, match="p1.*a MatchResult has stopped, p0"):
        r["p1"]
    with pytest.raises(AttributeError):
        r.p0 = None
    assert repr(r).startswith("MatchResult(stopped, p0, pf,")
    # A read-only mapping of its attributes, as the dicts were.
    assert len(r) == 15 and list(r) == r.keys() and dict(r)["p0"] is r.p0 and 1 not in r
    assert r.get("p1", 3) == 3 and r.get("p0") is r.p0 and dict(r.items()) == dict(r)
    shot = fshape.shoot(src, r.p0, r.config, pf=r.pf)
    assert type(shot) is fshape.Geodesic and shot.points.shape == (6, 12, 3)
    config = {key: value for key, value in CONFIG.items() if key != "stage"}
    config["optimizer"] = {"max_iterations": 1}
    atlas = fshape.atlas([src, tgt, src], config)
    assert type(atlas) is fshape.AtlasResult and all(type(s) is fshape.SubjectResult for s in atlas.subjects)
    st = fshape.stats(atlas, {"group": ["a", "b", "a"]}, "group", maps=["area"], permutations=4)
    assert type(st) is fshape.StatsResult and type(st.maps["area"]) is fshape.MapTest
    assert st.maps["area"].statistic.shape == (12,) and st.maps["area"].kind == "t"


def test_the_older_schedule_arrays_read_with_a_deprecation_warning(tmp_path):
    arrays = {**{k: v for k, v in CONFIG.items() if k != "stage"},
              "schedule": {"kernel_geom": ["gaussian:0.3", "gaussian:0.1"]}}
    with pytest.warns(DeprecationWarning, match=r"\[schedule\]: its arrays are the older form"):
        old = fshape.Config(arrays)
    (tmp_path / "old.toml").write_text(old.to_toml())
    with pytest.warns(DeprecationWarning, match="older form"):
        fshape.Config.read(tmp_path / "old.toml")
    # The tables say the same schedule, and read without a warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = fshape.Config(CONFIG)
    assert new.to_dict()["stage"][1]["kernel_geom"] == old.to_dict()["schedule"]["kernel_geom"][1]


def test_a_mask_travels_with_the_shape_and_a_masked_match_reads_no_masked_value(tmp_path):
    src, tgt = sphere_pair()
    cap = src.points[:, 2] > 0.3
    mask = np.where(cap, 0.0, 1.0)
    filled = lambda s, v: np.where(cap, v, s.signal)
    masked = fshape.FShape(src.points, src.cells, filled(src, np.nan), mask)
    assert np.array_equal(masked.mask, mask) and np.isnan(masked.signal[cap]).all()
    assert "mask" in repr(masked)
    # with_signal keeps the mask and stores NaN under it, whatever is given there.
    again = masked.with_signal(filled(src, 1e300))
    assert np.array_equal(again.mask, mask) and np.isnan(again.signal[cap]).all()
    with pytest.raises(fshape.FShapeError, match="vertex"):
        fshape.FShape(src.points, src.cells, np.where(cap, src.signal, np.nan), mask)
    # Nothing masked is read: the same bits with NaN, 0 or 1e300 under the masks.
    config = dict(CONFIG, optimizer={"max_iterations": 4}, stage=[{"kernel_geom": "gaussian:0.1"}])
    runs = []
    for v in (np.nan, 0.0, 1e300):
        s = fshape.FShape(src.points, src.cells, filled(src, v), mask)
        t = fshape.FShape(tgt.points, tgt.cells, np.where(cap, v, tgt.signal), mask)
        runs.append(fshape.match(s, t, config))
    for r in runs[1:]:
        assert r["energies"]["value"] == runs[0]["energies"]["value"]
        assert np.array_equal(r["p0"], runs[0]["p0"]) and np.array_equal(r["pf"], runs[0]["pf"])
    assert np.all(runs[0]["pf"][cap] == 0.0)
    assert np.array_equal(runs[0]["matched"].mask, mask)
    # HCP's thickness as shipped: NaN on the medial wall, accepted when asked.
    thickness = DATA / "conte69_32k" / "lh.thickness.csv.gz"
    with pytest.raises(fshape.FShapeError, match="allow-missing"):
        fshape.read_signal(thickness)
    _, values = fshape.read_signal(thickness, allow_missing=True)
    assert values.shape == (32492,) and np.isnan(values).sum() == 3221


def test_freesurfer_labels_read_and_write_as_nibabel_reads_them(tmp_path):
    rng = np.random.default_rng(3)
    vertices = np.sort(rng.choice(500, size=120, replace=False))
    points = rng.normal(scale=40.0, size=(120, 3)).round(3)
    values = rng.random(120)
    # As FreeSurfer writes a label (its fixed formats); nibabel and fshape
    # read the same arrays, and the mask is the label's vertices.
    lines = ["#!ascii label  , from subject bert vox2ras=TkReg", str(len(vertices))]
    lines += [f"{v}  {p[0]:.3f}  {p[1]:.3f}  {p[2]:.3f} {x:.10f}" for v, p, x in zip(vertices, points, values)]
    (tmp_path / "lh.cortex.label").write_text("\n".join(lines) + "\n")
    nv, ns = nib.freesurfer.read_label(tmp_path / "lh.cortex.label", read_scalars=True)
    fv, fp, fs = fshape.read_label(tmp_path / "lh.cortex.label")
    assert np.array_equal(fv, nv) and np.array_equal(fs, ns) and np.array_equal(fp, points)
    m = fshape.read_mask(tmp_path / "lh.cortex.label", 500)
    assert np.array_equal(m, np.isin(np.arange(500), nv).astype(float))
    with pytest.raises(fshape.FShapeError, match="vertex"):
        fshape.read_mask(tmp_path / "lh.cortex.label", int(vertices.max()))
    # What fshape writes, nibabel reads back.
    fshape.write_label(tmp_path / "out.label", vertices, points, values, subject="bert")
    wv, ws = nib.freesurfer.read_label(tmp_path / "out.label", read_scalars=True)
    assert np.array_equal(wv, vertices) and np.array_equal(ws, values)


def test_parcellations_read_as_nibabel_writes_them_become_masks_and_write_as_it_reads_them(tmp_path):
    rng = np.random.default_rng(5)
    n = 400
    names = ["unknown", "precentral", "postcentral", "insula", "cuneus"]
    ctab = np.column_stack([rng.integers(0, 256, size=(5, 3)), np.zeros(5, int)]).astype(np.int32)
    keys = rng.integers(-1, 5, size=n).astype(np.int32)
    nib.freesurfer.write_annot(tmp_path / "lh.aparc.annot", keys, ctab, names)
    nk, nctab, nnames = nib.freesurfer.read_annot(tmp_path / "lh.aparc.annot")
    fk, regions = fshape.read_parcellation(tmp_path / "lh.aparc.annot")
    assert np.array_equal(fk, nk) and [r[1] for r in regions] == [x.decode() for x in nnames]
    assert np.allclose([r[2][:3] for r in regions], nctab[:, :3] / 255.0)
    mask = fshape.read_mask(f"{tmp_path / 'lh.aparc.annot'}:insula,cuneus", n)
    assert np.array_equal(mask, np.isin(nk, [3, 4]).astype(float))
    # A GIfTI label array with its table, as HCP writes its parcellations.
    table = nib.gifti.GiftiLabelTable()
    for key, name in [(0, "???"), (11, "V1"), (12, "V2")]:
        label = nib.gifti.GiftiLabel(key, *rng.random(3), 1.0)
        label.label = name
        table.labels.append(label)
    gkeys = rng.choice([0, 11, 12], size=n).astype(np.int32)
    darray = nib.gifti.GiftiDataArray(gkeys, intent="NIFTI_INTENT_LABEL", datatype="NIFTI_TYPE_INT32")
    nib.save(nib.gifti.GiftiImage(labeltable=table, darrays=[darray]), tmp_path / "lh.visual.label.gii")
    fk, regions = fshape.read_parcellation(tmp_path / "lh.visual.label.gii")
    assert np.array_equal(fk, nib.load(tmp_path / "lh.visual.label.gii").darrays[0].data)
    assert {k: name for k, name, _ in regions} == nib.load(tmp_path / "lh.visual.label.gii").labeltable.get_labels_as_dict()
    with pytest.raises(fshape.FShapeError, match="no region named `V3`"):
        fshape.read_mask(f"{tmp_path / 'lh.visual.label.gii'}:V3", n)
    # Written by fshape, nibabel reads the label file to its keys, names
    # and colours; the annotation's vertices in no region (-1) as `???`
    # (key 0 is free in the annotation shifted by 100).
    fshape.write_parcellation(tmp_path / "again.label.gii", fk, regions)
    again = nib.load(tmp_path / "again.label.gii")
    assert again.darrays[0].intent == nib.nifti1.intent_codes.code["NIFTI_INTENT_LABEL"]
    assert np.array_equal(again.darrays[0].data, fk) and again.darrays[0].data.dtype == np.int32
    assert again.labeltable.get_labels_as_dict() == {k: name for k, name, _ in regions}
    assert all(np.allclose(label.rgba, r[2]) for label, r in zip(again.labeltable.labels, regions))
    fk, regions = fshape.read_parcellation(tmp_path / "lh.aparc.annot")
    shifted = [(k + 100, name, rgba) for k, name, rgba in regions]
    fshape.write_parcellation(tmp_path / "aparc.label.gii", np.where(fk >= 0, fk + 100, -1), shifted)
    g = nib.load(tmp_path / "aparc.label.gii")
    assert np.array_equal(g.darrays[0].data, np.where(nk >= 0, nk + 100, 0))
    assert g.labeltable.get_labels_as_dict() == {0: "???", **{k: name for k, name, _ in shifted}}
    with pytest.raises(fshape.InputError, match="vertex 0 has the key 5"):
        fshape.write_parcellation(tmp_path / "bad.label.gii", np.full(n, 5), regions)


def test_cifti_maps_read_as_nibabel_reads_them_and_write_back_keeping_the_rest(tmp_path):
    rng = np.random.default_rng(7)
    ax = nib.cifti2.cifti2_axes
    # fs_LR-like: each cortex without its "medial wall", plus voxels.
    n = 300
    left = np.sort(rng.choice(n, size=260, replace=False))
    right = np.sort(rng.choice(n, size=250, replace=False))
    voxels = rng.integers(0, 5, size=(7, 3))
    brain = (ax.BrainModelAxis.from_surface(left, n, "CortexLeft")
             + ax.BrainModelAxis.from_surface(right, n, "CortexRight")
             + ax.BrainModelAxis("brain_stem", voxel=voxels, affine=np.eye(4), volume_shape=(5, 5, 5)))
    data = rng.normal(size=(3, len(brain))).astype(np.float32)
    img = nib.Cifti2Image(data, header=(ax.ScalarAxis(["thickness", "myelin", "curvature"]), brain))
    img.nifti_header.set_intent("ConnDenseScalar")
    img.to_filename(tmp_path / "maps.dscalar.nii")
    expected = np.full(n, np.nan)
    expected[right] = data[1, len(left):len(left) + len(right)]
    name, got = fshape.read_cifti(tmp_path / "maps.dscalar.nii", "CORTEX_RIGHT", n, map="myelin")
    assert name == "myelin" and np.array_equal(got, expected, equal_nan=True)
    _, got = fshape.read_signal(f"{tmp_path / 'maps.dscalar.nii'}:CORTEX_RIGHT:2", allow_missing=True)
    assert np.array_equal(got, expected, equal_nan=True)
    with pytest.raises(fshape.FShapeError, match="expected 301, found 300"):
        fshape.read_cifti(tmp_path / "maps.dscalar.nii", "CORTEX_LEFT", n + 1, map="myelin")
    # Written back: nibabel reads the new left thickness, and everything
    # else (the other maps, the right cortex, the voxels, the axes) as before.
    new = rng.normal(size=n)
    fshape.write_cifti(tmp_path / "out.dscalar.nii", tmp_path / "maps.dscalar.nii", "CORTEX_LEFT", new, map="thickness")
    out = nib.load(tmp_path / "out.dscalar.nii")
    want = data.copy()
    want[0, :len(left)] = new[left].astype(np.float32)
    assert np.array_equal(out.get_fdata(dtype=np.float32), want)
    assert out.header.get_axis(0) == img.header.get_axis(0) and out.header.get_axis(1) == brain


def test_cifti_label_files_read_as_nibabel_reads_them(tmp_path):
    rng = np.random.default_rng(11)
    ax = nib.cifti2.cifti2_axes
    n = 300
    left = np.sort(rng.choice(n, size=260, replace=False))
    brain = ax.BrainModelAxis.from_surface(left, n, "CortexLeft")
    tables = [{0: ("???", (0.0, 0.0, 0.0, 0.0)), 1001: ("V1_ROI", (0.5, 0.25, 1.0, 1.0)),
               1002: ("V2_ROI", (0.25, 1.0, 0.5, 1.0))},
              {0: ("???", (0.0, 0.0, 0.0, 0.0)), 3: ("dorsal", (1.0, 0.5, 0.0, 1.0))}]
    keys = np.vstack([rng.choice([0, 1001, 1002], size=len(left)), rng.choice([0, 3], size=len(left))])
    img = nib.Cifti2Image(keys.astype(np.float32), header=(ax.LabelAxis(["areas", "streams"], tables), brain))
    img.nifti_header.set_intent("ConnDenseLabel")
    img.to_filename(tmp_path / "parcels.dlabel.nii")
    got, regions = fshape.read_parcellation(f"{tmp_path / 'parcels.dlabel.nii'}:CORTEX_LEFT:areas")
    # nibabel's keys on the structure's vertices, the ??? key (0) off it.
    label_axis = nib.load(tmp_path / "parcels.dlabel.nii").header.get_axis(0)
    expected = np.zeros(n, dtype=np.int64)
    expected[left] = keys[0]
    assert np.array_equal(got, expected)
    assert {k: (name, tuple(rgba)) for k, name, rgba in regions} == label_axis.label[0]
    # As a mask of regions, and never as a map.
    mask = fshape.read_mask(f"{tmp_path / 'parcels.dlabel.nii'}:CORTEX_LEFT:areas:V1_ROI", n)
    assert np.array_equal(mask, (expected == 1001).astype(float))
    with pytest.raises(fshape.InputError, match="holds region keys"):
        fshape.read_signal(f"{tmp_path / 'parcels.dlabel.nii'}:CORTEX_LEFT:streams", allow_missing=True)
