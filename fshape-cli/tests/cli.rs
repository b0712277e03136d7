//! The `fshape` program end to end: exit codes, JSON, conversions.

use std::path::PathBuf;
use std::process::{Command, Output};

fn fshape(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fshape")).args(args).output().expect("the binary runs")
}

fn repo(rel: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join(rel).display().to_string()
}

fn tmp(name: &str) -> PathBuf {
    // Under target/tmp (cargo's scratch space for integration tests), not
    // the system's temporary directory, which would keep every run's files.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("fshape-cli-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn json(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("valid JSON")
}

#[test]
fn info_json_on_the_shipped_cortex() {
    let v = json(&fshape(&["info", &repo("data/fsaverage5/lh.pial.thick.ply.gz"), "--json"]));
    assert_eq!(v["n_vertices"], 10242);
    assert_eq!(v["n_cells"], 20480);
    assert_eq!(v["closed"], true);
    assert_eq!(v["errors"].as_array().unwrap().len(), 0);
    assert_eq!(v["warnings"].as_array().unwrap().len(), 0);
    // data/README.md: thickness from −0.0028 to 4.66 mm.
    let (lo, hi) = (v["signal"]["min"].as_f64().unwrap(), v["signal"]["max"].as_f64().unwrap());
    assert!((-0.0029..-0.0027).contains(&lo) && (4.65..4.66).contains(&hi), "{lo} {hi}");
}

#[test]
fn info_reports_the_full_bunny_warnings() {
    let v = json(&fshape(&["info", &repo("data/stanford_bunny/bun_zipper.ply.gz"), "--json"]));
    let warnings = v["warnings"].as_array().unwrap();
    let unused = warnings.iter().find(|w| w["code"] == "unused_vertex").unwrap();
    assert_eq!(unused["count"], 1113);
    assert_eq!(v["boundary_loops"], 5);
    assert_eq!(v["signal"], serde_json::Value::Null, "confidence/intensity are not a signal");
}

#[test]
fn bad_input_exits_1_naming_file_and_line() {
    let bad = repo("fshape-mesh/tests/malformed/ply_non_numeric.ply");
    let out = fshape(&["info", &bad]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("ply_non_numeric.ply") && err.contains("line 12"), "{err}");
    let missing = fshape(&["info", "no/such/file.ply"]);
    assert_eq!(missing.status.code(), Some(1));
}

#[test]
fn usage_errors_exit_2() {
    assert_eq!(fshape(&["info"]).status.code(), Some(2));
    assert_eq!(fshape(&["frobnicate"]).status.code(), Some(2));
    assert_eq!(fshape(&["info", "x.ply", "--bogus"]).status.code(), Some(2));
}

#[test]
fn the_command_list_is_one_short_line_per_command_and_each_command_explains_itself() {
    // `fshape --help` lists the commands one line each, as cargo's does;
    // the paragraph is `fshape COMMAND --help`'s.
    let o = fshape(&["--help"]);
    assert!(o.status.success());
    let help = String::from_utf8(o.stdout).unwrap();
    let list: Vec<&str> =
        help.lines().skip_while(|l| *l != "Commands:").skip(1).take_while(|l| !l.trim().is_empty()).collect();
    assert!(list.len() >= 15, "{help}");
    for line in &list {
        assert!(line.chars().count() <= 80, "a long line in the command list: {line}");
    }
    let long = String::from_utf8(fshape(&["match", "--help"]).stdout).unwrap();
    assert!(long.contains("--resume") && long.contains("bit for bit"), "{long}");
}

#[test]
fn convert_attaches_a_csv_signal_and_round_trips() {
    let out = tmp("rh.vtk");
    let r = fshape(&[
        "convert",
        &repo("data/fsaverage5/rh.pial.ply.gz"),
        out.to_str().unwrap(),
        "--signal",
        &repo("data/fsaverage5/rh.thick.csv.gz"),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let v = json(&fshape(&["info", out.to_str().unwrap(), "--json"]));
    assert_eq!(v["n_vertices"], 10242);
    assert!(v["signal"]["max"].as_f64().unwrap() > 4.0, "thickness in mm");
    // A signal of the wrong length is refused and nothing is written.
    let bad_out = tmp("bunny.ply");
    let r = fshape(&[
        "convert",
        &repo("data/stanford_bunny/bunny_qslim_2581v.ply.gz"),
        bad_out.to_str().unwrap(),
        "--signal",
        &repo("data/fsaverage5/rh.thick.csv.gz"),
    ]);
    assert_eq!(r.status.code(), Some(1));
    // Read as a stream, the table stops at its first value past the mesh.
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("line 2583: the signal goes on past the mesh's 2581 vertices (value 2582 is here)"), "{err}");
    assert!(!bad_out.exists());
}

#[test]
fn convert_repairs_the_dirty_bunny() {
    let out = tmp("res4.ply");
    let r =
        fshape(&["convert", &repo("data/stanford_bunny/bun_zipper_res4.ply.gz"), out.to_str().unwrap(), "--repair"]);
    assert!(r.status.success());
    let v = json(&fshape(&["info", out.to_str().unwrap(), "--json"]));
    // data/README.md: 948 faces, 40 of them duplicates.
    assert_eq!(v["n_cells"], 948 - 40);
    let codes: Vec<&str> = v["warnings"].as_array().unwrap().iter().map(|w| w["code"].as_str().unwrap()).collect();
    assert!(!codes.contains(&"duplicate_cell"), "{codes:?}");
}

#[test]
fn unwritable_output_exits_1_and_leaves_nothing() {
    let dir = tmp("no-such-dir").join("sub");
    let out = dir.join("x.ply");
    let r = fshape(&["convert", &repo("data/stanford_bunny/bun_zipper_res4.ply.gz"), out.to_str().unwrap()]);
    assert_eq!(r.status.code(), Some(1));
    assert!(!dir.exists());
}

#[test]
fn fem_summary_and_matrix_market_export() {
    let mesh = repo("data/stanford_bunny/bun_zipper_res4.ply.gz");
    let out = tmp("d.mtx");
    // The lumped L2 matrix: diagonal, trace = total area.
    let v = json(&fshape(&["fem", &mesh, "--norm", "l2-lumped", "--json", "--out", out.to_str().unwrap()]));
    assert_eq!(v["n"], 453);
    assert_eq!(v["nnz"], 453);
    let (trace, area) = (v["trace"].as_f64().unwrap(), v["total_area"].as_f64().unwrap());
    assert!((trace - area).abs() <= 1e-12 * area);
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("%%MatrixMarket matrix coordinate real symmetric"));
    let size = lines.find(|l| !l.starts_with('%')).unwrap();
    assert_eq!(size, "453 453 453");
    let sum: f64 = lines.map(|l| l.split(' ').nth(2).unwrap().parse::<f64>().unwrap()).sum();
    assert!((sum - area).abs() <= 1e-12 * area);
    // P1 mass: trace = half the area for triangles (diagonal A/6 per corner).
    let v = json(&fshape(&["fem", &mesh, "--norm", "l2", "--json"]));
    assert!((v["trace"].as_f64().unwrap() - area / 2.0).abs() <= 1e-12 * area);
    // A bad norm name or length is a clear error.
    // An unknown norm is a usage error naming the flag and the choices.
    let r = fshape(&["fem", &mesh, "--norm", "h2"]);
    assert_eq!(r.status.code(), Some(2));
    let e = String::from_utf8_lossy(&r.stderr);
    assert!(e.contains("'h2'") && e.contains("--norm") && e.contains("l2-lumped"), "{e}");
    let r = fshape(&["fem", &mesh, "--norm", "h1", "--length=-1"]);
    assert_eq!(r.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&r.stderr).contains("length scale must be positive"));
}

/// A one-triangle ASCII PLY lifted to height z.
fn triangle_at(name: &str, z: f64) -> String {
    let p = tmp(name);
    let text = format!(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 {z}\n1 0 {z}\n0 1 {z}\n3 0 1 2\n"
    );
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

#[test]
fn distance_between_two_parallel_triangles_is_the_hand_computed_value() {
    // Two triangles of area r = 1/2 with equal normals, centres 1 apart: with
    // σ = 1 and currents, ⟨X,X⟩ = ⟨Y,Y⟩ = r², ⟨X,Y⟩ = r² e^{−1/2}, so
    // A = 2r²(1 − e^{−1/2}).
    let (a, b) = (triangle_at("t0.ply", 0.0), triangle_at("t1.ply", 1.0));
    let v = json(&fshape(&["distance", &a, &b, "--kernel-geom", "gaussian:1", "--kernel-grass", "linear", "--json"]));
    let expected = 0.5 * (1.0 - (-0.5f64).exp());
    assert!((v["value"].as_f64().unwrap() - expected).abs() < 1e-15, "{v}");
    assert!((v["xy"].as_f64().unwrap() - 0.25 * (-0.5f64).exp()).abs() < 1e-15, "{v}");
}

#[test]
fn distance_between_the_shipped_hemispheres_with_thickness() {
    let (lh, rh) = (repo("data/fsaverage5/lh.pial.thick.ply.gz"), repo("data/fsaverage5/rh.pial.ply.gz"));
    let thick = repo("data/fsaverage5/rh.thick.csv.gz");
    let kernels = ["--kernel-geom", "gaussian:20", "--kernel-signal", "gaussian:0.5", "--kernel-grass", "binet"];
    let run = |extra: &[&str]| {
        let mut args = vec!["distance"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&kernels);
        args.extend(["--tolerance", "1e-6", "--json"]);
        json(&fshape(&args))
    };
    let v = run(&[&lh, &rh, "--target-signal", &thick]);
    let (a, xx, xy, yy) = ["value", "xx", "xy", "yy"].map(|k| v[k].as_f64().unwrap()).into();
    assert!(a > 0.0 && (a - (xx - 2.0 * xy + yy)).abs() <= 1e-12 * (xx + yy), "{v}");
    // Swapping source and target swaps the self terms and keeps A.
    let w = run(&[&rh, &lh, "--source-signal", &thick]);
    assert!((w["value"].as_f64().unwrap() - a).abs() <= 1e-12 * (xx + yy), "{v} vs {w}");
    assert!((w["xx"].as_f64().unwrap() - yy).abs() <= 1e-12 * yy);
    // Against itself: 0.
    let z = run(&[&lh, &lh]);
    assert!(z["value"].as_f64().unwrap().abs() <= 1e-12 * xx, "{z}");
}

#[test]
fn distance_on_the_full_bunny_warns_about_its_unused_vertices() {
    let full = repo("data/stanford_bunny/bun_zipper.ply.gz");
    let coarse = repo("data/stanford_bunny/bun_zipper_res4.ply.gz");
    let out = fshape(&[
        "distance",
        &full,
        &coarse,
        "--kernel-geom",
        "gaussian:0.005",
        "--kernel-grass",
        "gaussian-unoriented:0.5",
        "--tolerance",
        "1e-6",
        "--json",
    ]);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(err.contains("1113 unused vertices"), "{err}");
    let v = json(&out);
    assert_eq!(v["source_cells"], 69451);
    assert!(v["value"].as_f64().unwrap() > 0.0, "{v}");
}

#[test]
fn distance_refuses_bad_kernels_naming_them() {
    let lh = repo("data/fsaverage5/lh.pial.thick.ply.gz");
    let bunny = repo("data/stanford_bunny/bun_zipper_res4.ply.gz");
    for (args, needle) in [
        (vec!["--kernel-geom", "gaussian:0", "--kernel-grass", "binet"], "position kernel width"),
        (vec!["--kernel-geom", "gauss:1", "--kernel-grass", "binet"], "gauss:1"),
        (vec!["--kernel-geom", "gaussian:1", "--kernel-grass", "wavy"], "wavy"),
        (vec!["--kernel-geom", "gaussian:1", "--kernel-grass", "gaussian-oriented:-1"], "direction kernel width"),
        (vec!["--kernel-geom", "gaussian:1", "--kernel-grass", "binet", "--kernel-signal", "gaussian:1"], "no signal"),
        (vec!["--kernel-geom", "gaussian:1", "--kernel-grass", "binet", "--tolerance", "2"], "tolerance"),
    ] {
        let mut all = vec!["distance", lh.as_str(), bunny.as_str()];
        all.extend(args);
        let out = fshape(&all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{all:?}: {err}");
        assert!(err.contains(needle), "{all:?}: {err}");
    }
    // A missing required flag is a usage error.
    assert_eq!(fshape(&["distance", &lh, &bunny, "--kernel-geom", "gaussian:1"]).status.code(), Some(2));
}

#[test]
fn an_error_names_its_place_once() {
    // A signal CSV with a missing value on its third data line (file line 4).
    let csv = tmp("nan.csv");
    std::fs::write(&csv, "thickness\n1.0\n2.0\nnan\n").unwrap();
    let mesh = triangle_at("nan_mesh.ply", 0.0);
    let out = fshape(&["info", &mesh, "--signal", &csv.display().to_string()]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("nan.csv") && err.contains("line 4"), "{err}");
    assert_eq!(err.matches("line 4").count(), 1, "the cause is repeated: {err}");
}

/// A level-2 icosphere with a smooth signal written to a temporary PLY,
/// random momenta CSVs, and a config; returns their paths.
fn shoot_inputs(tag: &str) -> (String, String, String, String) {
    use fshape_mesh::io::{Encoding, write_mesh};
    let sphere = fshape_mesh::generate::icosphere(2, 1.0);
    let f: Vec<f64> = sphere.points().chunks_exact(3).map(|p| p[0] + 0.5 * p[2]).collect();
    let sphere = sphere.with_signal(Some(f)).unwrap();
    let mesh = tmp(&format!("{tag}_sphere.ply"));
    write_mesh(&mesh, &sphere, Encoding::Ascii).unwrap();
    let mut rng = fshape_mesh::generate::SplitMix64(3);
    let mut p = String::from("p_x,p_y,p_z\n");
    let mut pf = String::from("pf\n");
    for _ in 0..sphere.n_vertices() {
        p.push_str(&format!("{},{},{}\n", rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), rng.range(-0.3, 0.3)));
        pf.push_str(&format!("{}\n", rng.range(-0.3, 0.3)));
    }
    let (pp, pfp, cfg) = (tmp(&format!("{tag}_p.csv")), tmp(&format!("{tag}_pf.csv")), tmp(&format!("{tag}.toml")));
    std::fs::write(&pp, p).unwrap();
    std::fs::write(&pfp, pf).unwrap();
    std::fs::write(
        &cfg,
        "[model]\nnorm = \"h1\"\nlength = 0.5\nnormalize = false\ngamma_f = 1.0\n[deformation]\nwidths = [0.5]\n[integrator]\nsteps = 8\n",
    )
    .unwrap();
    let s = |p: PathBuf| p.display().to_string();
    (s(mesh), s(pp), s(pfp), s(cfg))
}

#[test]
fn shoot_writes_states_a_collection_and_a_summary_that_read_back() {
    use fshape_mesh::io::{ReadOptions, read_mesh};
    let (mesh, p, pf, cfg) = shoot_inputs("ok");
    let out = tmp("shoot_out");
    let o = fshape(&[
        "shoot",
        &mesh,
        "--momentum",
        &p,
        "--signal-momentum",
        &pf,
        "--config",
        &cfg,
        "--out",
        &out.display().to_string(),
        "--times",
        "0,0.5,1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let template = read_mesh(mesh.as_ref(), &ReadOptions::default()).unwrap();
    // The library's own shooting, for the end state.
    let model = fshape_match::Config::read(cfg.as_ref()).unwrap().model().unwrap();
    let p0 = fshape_mesh::io::csv::read_vectors(p.as_ref(), 3).unwrap();
    let pfv = fshape_mesh::io::csv::read_signal(pf.as_ref(), false).unwrap().values;
    let traj = fshape_shoot::Problem::new(&template, model).unwrap().shoot(&p0, &pfv).unwrap();
    for ext in ["vtk", "ply"] {
        let start = read_mesh(&out.join(format!("state_000.{ext}")), &ReadOptions::default()).unwrap();
        assert_eq!(start.cells(), template.cells());
        let end = read_mesh(&out.join(format!("state_002.{ext}")), &ReadOptions::default()).unwrap();
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(u, v)| (u - v).abs() < 1e-6 * (1.0 + v.abs()));
        assert!(close(start.points(), template.points()) && close(start.signal().unwrap(), template.signal().unwrap()));
        assert!(close(end.points(), traj.points(8)) && close(end.signal().unwrap(), traj.signal(8)), "{ext}");
        assert!(!close(end.points(), template.points()), "the shape did move");
    }
    let pvd = std::fs::read_to_string(out.join("trajectory.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 3);
    assert!(pvd.contains("timestep=\"0.5\" part=\"0\" file=\"state_001.vtk\""));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["hamiltonian"].as_array().unwrap().len(), 9);
    assert!(summary["hamiltonian_drift"].as_f64().unwrap() < 1e-4, "{summary}");
}

#[test]
fn shoot_refuses_bad_input_and_writes_nothing() {
    let (mesh, p, _, cfg) = shoot_inputs("bad");
    let short = tmp("short_p.csv");
    std::fs::write(&short, "p_x,p_y,p_z\n1,2,3\n").unwrap();
    let bad_cfg = tmp("unknown_key.toml");
    std::fs::write(&bad_cfg, "[deformation]\nwidths = [0.5]\nsteps = 3\n").unwrap();
    let (short, bad_cfg) = (short.display().to_string(), bad_cfg.display().to_string());
    for (i, (args, needle)) in [
        (vec!["--momentum", short.as_str(), "--config", cfg.as_str()], "short_p.csv"),
        (vec!["--momentum", p.as_str(), "--config", bad_cfg.as_str()], "steps"),
        (vec!["--momentum", p.as_str(), "--config", cfg.as_str(), "--times", "0,2"], "--times"),
    ]
    .into_iter()
    .enumerate()
    {
        let out = tmp(&format!("refused_{i}"));
        let mut all = vec!["shoot", mesh.as_str(), "--out"];
        let o = out.display().to_string();
        all.push(&o);
        all.extend(args);
        let r = fshape(&all);
        let err = String::from_utf8_lossy(&r.stderr);
        // A value out of range is a usage error (clap's, exit 2); bad files are bad input (1).
        let code = if needle == "--times" { 2 } else { 1 };
        assert_eq!(r.status.code(), Some(code), "{all:?}: {err}");
        assert!(err.contains(needle), "{all:?}: {err}");
        assert!(!out.exists(), "{all:?}: output written despite the error");
    }
}

#[test]
fn shoot_reports_divergence_and_zero_steps_and_writes_nothing() {
    let (mesh, _, _, cfg) = shoot_inputs("diverge");
    // The issue's case: momenta of 1e6 on a small sphere.
    let huge = tmp("huge_p.csv");
    let sphere = fshape_mesh::generate::icosphere(2, 1.0);
    let mut text = String::from("p_x,p_y,p_z\n");
    for p in sphere.points().chunks_exact(3) {
        text.push_str(&format!("{},{},{}\n", 1e6 * p[0], -1e6 * p[1], 1e6 * p[2]));
    }
    std::fs::write(&huge, text).unwrap();
    let zero_steps = tmp("zero_steps.toml");
    std::fs::write(&zero_steps, "[deformation]\nwidths = [0.5]\n[integrator]\nsteps = 0\n").unwrap();
    for (i, (momenta, config, needles)) in [
        (huge.display().to_string(), cfg.clone(), vec!["diverged", "reduce the momenta or add time steps"]),
        (huge.display().to_string(), zero_steps.display().to_string(), vec!["integrator.steps", "at least 1"]),
    ]
    .into_iter()
    .enumerate()
    {
        let out = tmp(&format!("diverge_{i}"));
        let o = out.display().to_string();
        let r = fshape(&["shoot", &mesh, "--momentum", &momenta, "--config", &config, "--out", &o]);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(1), "{err}");
        assert!(needles.iter().all(|n| err.contains(n)), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "output written despite the error");
    }
}

#[test]
fn a_checkpoint_cut_short_is_refused_naming_the_file_and_the_array() {
    let (s, t, c) = match_inputs("match_cut", 8);
    let out = tmp("match_cut_out");
    let o = out.display().to_string();
    let r = fshape(&["match", &s, &t, "--config", &c, "--out", &o, "--stop-after", "3"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let path = out.join("checkpoint.bin");
    let mut ck = fshape_match::Checkpoint::read(&path).unwrap();
    let x = &mut ck.current.as_mut().unwrap().state.x;
    let n = x.len();
    x.truncate(n / 2);
    let bytes = ck.to_bytes().unwrap();
    // Also bytes cut short.
    for (case, contents) in [("short arrays", bytes.clone()), ("short file", bytes[..bytes.len() / 3].to_vec())] {
        std::fs::write(&path, contents).unwrap();
        let r = fshape(&["match", &s, &t, "--config", &c, "--out", &o, "--resume"]);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(1), "{case}: {err}");
        assert!(!err.contains("panicked"), "{case}: {err}");
        assert!(err.contains(&path.display().to_string()), "{case}: {err}");
        let what = if case == "short arrays" {
            format!("current.state.x has {} values", n / 2)
        } else {
            "damaged or truncated".to_string()
        };
        assert!(err.contains(&what), "{case}: {err}");
        assert!(!out.join("summary.json").exists());
    }
}

/// A level-2 sphere and a stretched, re-textured copy as PLY files, and a
/// two-stage matching config; returns their paths.
fn match_inputs(tag: &str, max_iterations: usize) -> (String, String, String) {
    use fshape_mesh::io::{Encoding, write_mesh};
    let sphere = fshape_mesh::generate::icosphere(2, 0.5);
    let f: Vec<f64> = sphere.points().chunks_exact(3).map(|p| p[2]).collect();
    let source = sphere.clone().with_signal(Some(f)).unwrap();
    let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [1.3 * p[0], p[1], 0.8 * p[2]]).collect();
    let g: Vec<f64> = sphere.points().chunks_exact(3).map(|p| p[2] + 0.5 * p[0]).collect();
    let target = sphere.with_points(pts).unwrap().with_signal(Some(g)).unwrap();
    let (s, t, c) = (tmp(&format!("{tag}_src.ply")), tmp(&format!("{tag}_tgt.ply")), tmp(&format!("{tag}.toml")));
    write_mesh(&s, &source, Encoding::Binary).unwrap();
    write_mesh(&t, &target, Encoding::Binary).unwrap();
    std::fs::write(
        &c,
        format!(
            "[model]\nnorm = \"h1\"\nlength = 0.2\ngamma_w = 400.0\n[deformation]\nwidths = [0.4, 0.2]\n\
             [integrator]\nsteps = 5\n[attachment]\nkernel_geom = \"gaussian:0.1\"\nkernel_signal = \"gaussian:0.5\"\n\
             [optimizer]\nmax_iterations = {max_iterations}\n[schedule]\nkernel_geom = [\"gaussian:0.3\", \"gaussian:0.1\"]\n"
        ),
    )
    .unwrap();
    let p = |p: PathBuf| p.display().to_string();
    (p(s), p(t), p(c))
}

#[test]
fn match_writes_a_geodesic_momenta_and_a_summary_and_decreases_the_data_term() {
    use fshape_mesh::io::{ReadOptions, read_mesh};
    let (s, t, c) = match_inputs("match_ok", 15);
    let out = tmp("match_out");
    let o = fshape(&["match", &s, &t, "--config", &c, "--out", &out.display().to_string()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The configuration's older [schedule] arrays read, with a warning
    // naming the file; the configuration the run writes is in tables.
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains(&format!("warning: {c}: [schedule]: its arrays are the older form")), "{stderr}");
    let shoot = std::fs::read_to_string(out.join("shoot.toml")).unwrap();
    assert!(shoot.contains("[[stage]]") && !shoot.contains("[schedule]"), "{shoot}");
    // Writing the outputs is said on the run's clock, after the last stage.
    let (last, writing) = (stderr.rfind("stage 2/2").unwrap(), stderr.find("outputs writing").unwrap());
    assert!(last < writing && stderr[..writing].ends_with(" s] "), "{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let stages = summary["stages"].as_array().unwrap();
    assert_eq!(stages.len(), 2);
    assert_eq!(stages[1]["kernel_geom"], "gaussian:0.1");
    // Within each stage J decreases at every iteration, and the data term
    // of the last stage falls well below its start.
    for st in stages {
        let values: Vec<f64> =
            st["iterations"].as_array().unwrap().iter().map(|i| i["value"].as_f64().unwrap()).collect();
        assert!(values.windows(2).all(|w| w[1] <= w[0]), "{values:?}");
    }
    let (a0, a1) =
        (stages[1]["initial"]["attachment"].as_f64().unwrap(), summary["final_attachment"].as_f64().unwrap());
    let first = stages[0]["initial"]["attachment"].as_f64().unwrap();
    // (J falls within each stage; A alone may rise as H falls.)
    assert!(a1 < 0.2 * first, "attachment {first} -> {a0} -> {a1}");
    assert!(summary["geodesic_distance"].as_f64().unwrap() > 0.0);
    // The end state reads back, and the match quality says it is closer to
    // the target than the template was, in shape and in signal, and the
    // same as the end state's own quality.
    let target = read_mesh(t.as_ref(), &ReadOptions::default()).unwrap();
    let end = read_mesh(&out.join("state_004.ply"), &ReadOptions::default()).unwrap();
    let (q, q0) = (&summary["quality"], &summary["quality_before"]);
    let num = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap();
    assert!(num(q, "mean_distance") < 0.5 * num(q0, "mean_distance"), "{q} against {q0}");
    assert!(num(q, "signal_rms") < num(q0, "signal_rms"), "{q} against {q0}");
    let own = fshape_match::quality(&end, &target).unwrap();
    assert!((own.mean_distance - num(q, "mean_distance")).abs() < 1e-9, "{own:?}");
    // `fshape quality` on the written end state says the same, field by field.
    let o = fshape(&["quality", &out.join("state_004.ply").display().to_string(), &t, "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cli = json(&o);
    for k in [
        "mean_distance",
        "p95_distance",
        "target_within_1pct",
        "signal_rms",
        "signal_p99",
        "signal_rms_within_1pct",
        "signal_rms_beyond_1pct",
        "signal_roughness",
        "signal_rms_on_shape",
        "signal_rms_on_shape_beyond_1pct",
        "shape_beyond_1pct",
        "signal_roughness_beyond_1pct",
        "shape_past_boundary",
        "signal_rms_past_boundary",
        "signal_roughness_past_boundary",
    ] {
        // A part of the signal error with no area is null on both sides.
        if q[k].is_null() {
            assert!(cli[k].is_null(), "{k}: {cli} against {q}");
            continue;
        }
        assert!((num(&cli, k) - num(q, k)).abs() < 1e-9 * (1.0 + num(q, k).abs()), "{k}: {cli} against {q}");
    }
    let p0 = fshape_mesh::io::csv::read_vectors(&out.join("p0.csv"), 3).unwrap();
    assert_eq!(p0.len(), 3 * target.n_vertices());
    // The match's momenta shot again with the shoot.toml it wrote (the
    // weights its model used) end where the match ended.
    let again = tmp("match_out_shot");
    let file = |f: &str| out.join(f).display().to_string();
    let o = fshape(&[
        "shoot",
        &s,
        "--momentum",
        &file("p0.csv"),
        "--signal-momentum",
        &file("pf.csv"),
        "--config",
        &file("shoot.toml"),
        "--out",
        &again.display().to_string(),
        "--times",
        "1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let shot = read_mesh(&again.join("state_000.ply"), &ReadOptions::default()).unwrap();
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(u, v)| (u - v).abs() < 1e-9 * (1.0 + v.abs()));
    assert!(close(shot.points(), end.points()) && close(shot.signal().unwrap(), end.signal().unwrap()));
    // The match's own config (normalised weights) is refused by shoot, saying why.
    let o =
        fshape(&["shoot", &s, "--momentum", &file("p0.csv"), "--config", &c, "--out", &again.display().to_string()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("normalize = false"));
    for f in ["momenta.vtk", "energy.svg", "energy.png", "trajectory.pvd", "checkpoint.bin"] {
        assert!(out.join(f).exists(), "{f}");
    }
    // The renders are PNG images that differ from frame to frame and end
    // close to the target's.
    let png = |f: &str| std::fs::read(out.join(f)).unwrap();
    for f in ["render_000.png", "render_004.png", "target.png"] {
        assert!(png(f).starts_with(b"\x89PNG\r\n\x1a\n"), "{f}");
    }
    assert_ne!(png("render_000.png"), png("render_004.png"));
    // The energy curve: a 720×420 PNG with white background, black curve and
    // axes, and text (the embedded font draws grey anti-aliased edges).
    let dec = png::Decoder::new(std::io::Cursor::new(png("energy.png")));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (720, 420));
    let px: Vec<&[u8]> = buf[..info.buffer_size()].chunks_exact(3).collect();
    let count = |f: &dyn Fn(&[u8]) -> bool| px.iter().filter(|p| f(p)).count();
    assert!(count(&|p| p == [255, 255, 255]) > px.len() / 2);
    assert!(count(&|p| p == [0, 0, 0]) > 500);
    assert!(count(&|p| p[0] == p[1] && p[1] == p[2] && p[0] > 40 && p[0] < 215) > 200, "no anti-aliased text");
    // The energy's curve and its legend swatch in blue, γ_W·A's in red,
    // two pixels wide: the legend's swatches show their colours in rows
    // next to each other.
    let rows_with = |c: [u8; 3]| {
        (0..info.height as usize)
            .filter(|y| (600..700).any(|x| px[y * info.width as usize + x] == c))
            .collect::<Vec<usize>>()
    };
    for c in [[0, 0, 255], [255, 0, 0]] {
        let rows = rows_with(c);
        assert!(rows.windows(2).any(|w| w[1] == w[0] + 1), "{c:?}: {rows:?}");
    }
}

#[test]
fn an_interrupted_match_resumes_to_the_same_result_bit_for_bit() {
    let (s, t, c) = match_inputs("match_resume", 8);
    let (whole, parts) = (tmp("match_whole"), tmp("match_parts"));
    let run = |out: &PathBuf, extra: &[&str]| {
        let o = fshape(&[&["match", &s, &t, "--config", &c, "--out", &out.display().to_string()], extra].concat());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run(&whole, &[]);
    // Interrupted twice (once inside the first stage, once inside the
    // second), resumed each time.
    run(&parts, &["--stop-after", "5"]);
    assert!(!parts.join("summary.json").exists(), "no result before the end");
    // `fshape checkpoint` tells where the binary checkpoint stands.
    let o = fshape(&["checkpoint", &parts.join("checkpoint.bin").display().to_string()]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["format"], fshape_match::CHECKPOINT_FORMAT);
    let done = v["iterations_done"].as_u64().unwrap() + v["iterations"].as_u64().unwrap();
    assert_eq!(done, 5, "{v}");
    run(&parts, &["--resume", "--stop-after", "6"]);
    run(&parts, &["--resume"]);
    for f in ["p0.csv", "pf.csv", "state_004.ply", "state_002.vtk", "momenta.vtk", "render_004.png"] {
        assert_eq!(std::fs::read(whole.join(f)).unwrap(), std::fs::read(parts.join(f)).unwrap(), "{f}");
    }
    let stages = |d: &PathBuf| {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap()).unwrap();
        v["stages"].clone()
    };
    assert_eq!(stages(&whole), stages(&parts), "every iteration's energies");
    // Resuming a finished run writes the same results again (e.g. after a
    // change of --view or --times), without iterating.
    std::fs::remove_file(whole.join("p0.csv")).unwrap();
    let seconds = |f: &PathBuf| -> f64 {
        if f.extension().is_some_and(|e| e == "bin") {
            return fshape_match::Checkpoint::read(f).unwrap().seconds;
        }
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(f).unwrap()).unwrap();
        v["seconds"].as_f64().unwrap()
    };
    // The checkpoint carries the wall time so far, and the summary of the
    // resumed run counts it.
    let before = seconds(&whole.join("checkpoint.bin"));
    assert!(before > 0.0);
    run(&whole, &["--resume"]);
    assert!(seconds(&whole.join("summary.json")) >= before);
    assert_eq!(std::fs::read(whole.join("p0.csv")).unwrap(), std::fs::read(parts.join("p0.csv")).unwrap());
    assert_eq!(stages(&whole), stages(&parts));
    // A checkpoint of other inputs is refused by name.
    std::fs::write(&c, std::fs::read_to_string(&c).unwrap().replace("gamma_w = 400.0", "gamma_w = 5.0")).unwrap();
    let o = fshape(&["match", &s, &t, "--config", &c, "--out", &parts.display().to_string(), "--resume"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("checkpoint.bin: the checkpoint was written for other inputs"));
}

#[test]
fn match_runs_coarse_stages_on_stage_templates() {
    use fshape_mesh::io::{Encoding, write_mesh};
    let (s, t, c) = match_inputs("match_multires", 4);
    let coarse = fshape_mesh::generate::icosphere(1, 0.5);
    let f: Vec<f64> = coarse.points().chunks_exact(3).map(|p| p[2]).collect();
    let coarse_path = tmp("match_multires_coarse.ply");
    write_mesh(&coarse_path, &coarse.with_signal(Some(f)).unwrap(), Encoding::Binary).unwrap();
    let coarse_path = coarse_path.display().to_string();
    let out = tmp("match_multires_out");
    let o = out.display().to_string();
    let r = fshape(&["match", &s, &t, "--config", &c, "--out", &o, "--stage-templates", &coarse_path]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["stages"].as_array().unwrap().len(), 2);
    let q = |k: &str| summary[k]["mean_distance"].as_f64().unwrap();
    assert!(q("quality") < q("quality_before"), "{summary}");
    // One template per stage before the last, or a clear error.
    let r = fshape(&[
        "match",
        &s,
        &t,
        "--config",
        &c,
        "--out",
        &o,
        "--stage-templates",
        &format!("{coarse_path},{coarse_path}"),
    ]);
    assert_eq!(r.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&r.stderr)
            .contains("--stage-templates: 2 meshes for a schedule of 2 stages: give one per stage before the last (1)"),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
}

#[test]
fn match_takes_the_view_as_azimuth_comma_elevation_negative_included() {
    let (s, t, c) = match_inputs("match_view", 1);
    let ok = tmp("match_view_ok");
    let o = fshape(&[
        "match",
        &s,
        &t,
        "--config",
        &c,
        "--out",
        &ok.display().to_string(),
        "--view",
        "-90,0",
        "--stop-after",
        "0",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for bad in ["30", "1,2,3", "nan,0"] {
        let out = tmp("match_view_bad");
        let o = fshape(&["match", &s, &t, "--config", &c, "--out", &out.display().to_string(), "--view", bad]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains("view"), "--view {bad}: {err}");
        assert!(!out.exists() || std::fs::read_dir(&out).unwrap().next().is_none(), "--view {bad} wrote files");
    }
}

#[test]
fn demo_cortex_runs_both_models_on_the_hemispheres_it_is_given() {
    // Stand-ins for fsaverage5 (coarse spheres in mm, the right one at
    // x > 0), so the demo's wiring runs in a second: mirroring, the
    // thickness CSV, the coarse templates undone from the icosahedral
    // subdivision, one config per model, four stages each.
    use fshape_mesh::io::{Encoding, ReadOptions, read_mesh, write_mesh};
    let data = tmp("cortex_data");
    let fs5 = data.join("fsaverage5");
    std::fs::create_dir_all(&fs5).unwrap();
    let sphere = fshape_mesh::generate::icosphere(2, 30.0);
    let left: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [p[0] - 35.0, p[1], p[2]]).collect();
    let right: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [1.1 * p[0] + 36.0, p[1], p[2]]).collect();
    let thick = |pts: &[f64], a: f64| -> Vec<f64> { pts.chunks_exact(3).map(|p| 2.5 + a * p[2] / 30.0).collect() };
    let lh = sphere.clone().with_points(left.clone()).unwrap().with_signal(Some(thick(&left, 0.5))).unwrap();
    let rh = sphere.clone().with_points(right.clone()).unwrap();
    write_mesh(&fs5.join("lh.pial.thick.ply.gz"), &lh, Encoding::Binary).unwrap();
    write_mesh(&fs5.join("rh.pial.ply.gz"), &rh, Encoding::Binary).unwrap();
    fshape_mesh::io::csv::write_signal(&fs5.join("rh.thick.csv.gz"), "thickness", &thick(&right, -0.5)).unwrap();
    let out = tmp("cortex_out");
    let args = ["demo", "cortex", "--data", &data.display().to_string(), "--out", &out.display().to_string()];
    let o = fshape(&[&args[..], &["--max-iterations", "2"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let target = read_mesh(&out.join("cortex/target.ply"), &ReadOptions::default()).unwrap();
    assert!(target.points().chunks_exact(3).all(|p| p[0] < 0.0), "mirrored to x < 0");
    // The first 42 and 12 vertices of the 162-vertex sphere, with their thickness.
    for (file, n) in [("source_coarse1.ply", 42), ("source_coarse2.ply", 12)] {
        let coarse = read_mesh(&out.join("cortex").join(file), &ReadOptions::default()).unwrap();
        assert_eq!((coarse.n_vertices(), coarse.n_cells()), (n, 2 * n - 4), "{file}");
        assert_eq!(coarse.points(), &left[..3 * n]);
        assert_eq!(coarse.signal().unwrap(), &thick(&left, 0.5)[..n]);
    }
    for model in ["tangential", "metamorphosis"] {
        let dir = out.join("cortex").join(model);
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
        assert_eq!(summary["stages"].as_array().unwrap().len(), 4, "{model}");
        assert!(summary["final_value"].as_f64().unwrap() < summary["stages"][0]["initial"]["value"].as_f64().unwrap());
        assert!(std::fs::read_to_string(dir.join("config.toml")).unwrap().contains(&format!("kind = \"{model}\"")));
    }
    // A thickness file of the wrong length is refused by name.
    fshape_mesh::io::csv::write_signal(&fs5.join("rh.thick.csv.gz"), "thickness", &[2.0; 5]).unwrap();
    let o = fshape(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("rh.thick.csv.gz") && err.contains("5 values"), "{err}");
}

#[test]
fn demo_bunny_quick_runs_three_stages_on_the_coarse_sphere_with_their_convergence_test() {
    let out = tmp("bunny_quick_out");
    let o = fshape(&["demo", "bunny", "--quick", "--max-iterations", "1", "--out", &out.display().to_string()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for norm in ["h1", "l2-lumped"] {
        let dir = out.join("bunny-quick").join(norm);
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
        let stages = summary["stages"].as_array().unwrap();
        assert_eq!(stages.len(), 3, "{norm}");
        // At most 4, 4 and 6 iterations (times --max-iterations), each
        // stage stopped by a rule the summary names.
        for (s, limit) in stages.iter().zip([4, 4, 6]) {
            assert!(s["iterations"].as_array().unwrap().len() <= limit, "{norm}: {s}");
            assert!(["Decrease", "Iterations", "Gradient"].contains(&s["stop"].as_str().unwrap()), "{norm}: {s}");
        }
        // The full demo's first three stages: the third is the deep one.
        // (Written as [[stage]] tables, which read with no warning.)
        let written = fshape_match::Config::read(&dir.join("config.toml")).unwrap();
        assert!(written.stage.is_some() && written.warnings().is_empty(), "{norm}");
        let specs = written.schedule().unwrap();
        let decrease: Vec<(f64, usize)> = specs.iter().map(|s| s.decrease).collect();
        assert_eq!(decrease, [(0.005, 5), (0.005, 5), (0.002, 10)], "{norm}");
        assert_eq!(specs.iter().map(|s| s.max_iterations).collect::<Vec<_>>(), [4, 4, 6], "{norm}");
        let config = std::fs::read_to_string(dir.join("config.toml")).unwrap();
        for line in [
            "memory = 30",
            "momentum_metric = \"energy\"",
            // The demo's own γ_f, not the default (demo::BUNNY_GAMMA_F).
            "gamma_f = 0.01\n",
        ] {
            assert!(config.contains(line), "{norm}: no {line:?} in\n{config}");
        }
        let template = fshape_mesh::io::read_mesh(&out.join("bunny-quick/source.ply"), &Default::default()).unwrap();
        assert_eq!(template.n_vertices(), 642);
    }
    // Both end states and the target from below (the paper's view of the
    // holes), each a picture of a few thousand pixels.
    for name in ["h1", "l2-lumped", "target"] {
        let (pixels, _) = painted(&out.join("bunny-quick").join(format!("below_{name}.png")));
        assert!(pixels.len() > 1000, "{name}: {} pixels", pixels.len());
    }
    let o = fshape(&["demo", "cortex", "--quick", "--out", &out.display().to_string()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--quick"), "{err}");
}

/// Three subjects (stretched spheres with signals, written as PLY), a list
/// file naming the last two, and an atlas configuration.
fn atlas_inputs(tag: &str) -> (Vec<String>, String, String) {
    use fshape_mesh::io::{Encoding, write_mesh};
    let mut files = Vec::new();
    for i in 0..3 {
        let s = fshape_mesh::generate::icosphere(2, 1.0);
        let a = 1.0 + 0.2 * i as f64;
        let pts: Vec<f64> =
            s.points().chunks_exact(3).flat_map(|p| [0.5 * a * p[0], 0.5 * p[1], 0.5 * p[2] / a]).collect();
        let f: Vec<f64> = pts.chunks_exact(3).map(|p| p[2] + 0.3 * i as f64 * p[0]).collect();
        let path = tmp(&format!("{tag}_subject{i}.ply"));
        write_mesh(&path, &s.with_points(pts).unwrap().with_signal(Some(f)).unwrap(), Encoding::Binary).unwrap();
        files.push(path.display().to_string());
    }
    let list = tmp(&format!("{tag}_list.csv"));
    let name = |f: &str| PathBuf::from(f).file_name().unwrap().to_string_lossy().to_string();
    std::fs::write(&list, format!("# subjects\n{}\n{}\n", name(&files[1]), name(&files[2]))).unwrap();
    let config = tmp(&format!("{tag}.toml"));
    std::fs::write(
        &config,
        "[model]\nnorm = \"h1\"\nlength = 0.2\n[deformation]\nwidths = [0.4, 0.2]\n[integrator]\nsteps = 5\n\
         [attachment]\nkernel_geom = \"gaussian:0.1\"\nkernel_signal = \"gaussian:0.5\"\n\
         [optimizer]\nmax_iterations = 6\n",
    )
    .unwrap();
    (files, list.display().to_string(), config.display().to_string())
}

#[test]
fn atlas_writes_a_template_every_subjects_momenta_and_resumes_bit_for_bit() {
    let (files, list, config) = atlas_inputs("atlas");
    let (whole, parts) = (tmp("atlas_whole"), tmp("atlas_parts"));
    let run = |out: &PathBuf, extra: &[&str]| {
        let out = out.display().to_string();
        let args =
            [&["atlas", files[0].as_str(), "--subjects", &list, "--config", &config, "--out", &out], extra].concat();
        let o = fshape(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        o
    };
    let o = run(&whole, &[]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("atlas of 3 subjects"));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(whole.join("summary.json")).unwrap()).unwrap();
    let subjects = summary["subjects"].as_array().unwrap();
    // The list's subjects first, then the positional one.
    assert_eq!(subjects.len(), 3);
    assert!(subjects[0]["file"].as_str().unwrap().ends_with("atlas_subject1.ply"));
    assert!(subjects[2]["file"].as_str().unwrap().ends_with("atlas_subject0.ply"));
    // Each subject is closer to the template shot onto it than to the
    // template itself, and J fell.
    for s in subjects {
        let q = |k: &str| s[k]["mean_distance"].as_f64().unwrap();
        assert!(q("quality") < q("template_quality"), "{s}");
        // The first subject is the initial template: it starts at A = 0,
        // where the share removed is undefined (null).
        let (a, a0) = (s["attachment"].as_f64().unwrap(), s["attachment_start"].as_f64().unwrap());
        if a0 == 0.0 {
            assert!(s["attachment_fall"].is_null(), "{s}");
            continue;
        }
        let fall = s["attachment_fall"].as_f64().unwrap();
        assert!(fall > 0.0 && (fall - (1.0 - a / a0)).abs() < 1e-12, "{s}");
    }
    let min = subjects.iter().filter_map(|s| s["attachment_fall"].as_f64()).fold(f64::INFINITY, f64::min);
    assert_eq!(summary["min_attachment_fall"].as_f64().unwrap(), min);
    let stage = &summary["stages"][0];
    let last = stage["iterations"].as_array().unwrap().last().unwrap()["value"].as_f64().unwrap();
    assert!(last < stage["initial"]["value"].as_f64().unwrap());
    // momenta.csv: a header and one row per subject, the subject's index,
    // then 3 values per vertex of p_0 and one of p^f.
    let table = std::fs::read_to_string(whole.join("momenta.csv")).unwrap();
    let rows: Vec<&str> = table.lines().collect();
    assert_eq!(rows.len(), 4);
    assert!(rows.iter().all(|r| r.split(',').count() == 1 + 4 * 162), "{}", &rows[0][..80]);
    for f in [
        "template.ply",
        "template.vtk",
        "template.png",
        "template_start.png",
        "subjects.png",
        "energy.png",
        "subject_002/matched.ply",
        "modes.png",
        "mode_1_minus2sd.ply",
        "mode_2_plus2sd.ply",
    ] {
        assert!(whole.join(f).exists(), "{f}");
    }
    // Three subjects: two principal modes, their scores one row per subject.
    let modes = summary["modes"].as_array().unwrap();
    assert_eq!(modes.len(), 2);
    let share: f64 = modes.iter().map(|m| m["share"].as_f64().unwrap()).sum();
    assert!((share - 1.0).abs() < 1e-9, "{modes:?}");
    let pca = std::fs::read_to_string(whole.join("pca.csv")).unwrap();
    assert_eq!(pca.lines().next().unwrap(), "subject,mode_1,mode_2");
    assert_eq!(pca.lines().count(), 4);
    // A map on the template carried onto a subject (its folder), and the
    // atlas folder itself refused with the way to name a subject.
    let template = fshape_mesh::io::read_mesh(&whole.join("template.ply"), &Default::default()).unwrap();
    let heights: Vec<f64> = template.points().chunks_exact(3).map(|p| p[2]).collect();
    fshape_mesh::io::csv::write_signal(&tmp("atlas_height.csv"), "height", &heights).unwrap();
    let (height, onto) =
        (tmp("atlas_height.csv").display().to_string(), tmp("atlas_height_1.csv").display().to_string());
    let v = json(&fshape(&["transfer", &whole.join("subject_001").display().to_string(), &height, &onto, "--json"]));
    assert_eq!((v["vertices"].as_u64(), v["missing"].as_u64()), (Some(162), Some(0)), "{v}");
    let o = fshape(&["transfer", &whole.display().to_string(), &height, &onto]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("give one subject's folder"), "{o:?}");
    // The page written from memory is the one `fshape report` builds from
    // the files.
    let page = std::fs::read_to_string(whole.join("report.html")).unwrap();
    assert!(page.contains("mode 2 (±2 standard deviations)") && page.contains("subject 2: the template shot onto it"));
    std::fs::remove_file(whole.join("report.html")).unwrap();
    assert!(fshape(&["report", &whole.display().to_string()]).status.success());
    assert_eq!(std::fs::read_to_string(whole.join("report.html")).unwrap(), page);
    // Stopped after 2 iterations and resumed: the same template, bit for bit.
    run(&parts, &["--stop-after", "2"]);
    assert!(!parts.join("template.ply").exists());
    run(&parts, &["--resume"]);
    for f in ["template.ply", "momenta.csv", "subject_001/p0.csv"] {
        assert_eq!(std::fs::read(whole.join(f)).unwrap(), std::fs::read(parts.join(f)).unwrap(), "{f}");
    }
}

#[test]
fn atlas_runs_its_first_stage_on_a_coarser_template() {
    let (files, list, config) = atlas_inputs("atlas_levels");
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(&config, format!("{text}[schedule]\nkernel_geom = [\"gaussian:0.15\", \"gaussian:0.1\"]\n"))
        .unwrap();
    // The initial template a sphere (its signal the subjects' mean), the
    // first stage on the same sphere at level 1.
    let (fine, coarse) = (tmp("atlas_levels_fine.ply"), tmp("atlas_levels_coarse.ply"));
    for (path, level) in [(&fine, 2), (&coarse, 1)] {
        let sphere = fshape_mesh::generate::icosphere(level, 0.5);
        fshape_mesh::io::write_mesh(path, &sphere, fshape_mesh::io::Encoding::Binary).unwrap();
    }
    let out = tmp("atlas_levels_out");
    let fine = fine.display().to_string();
    let args = |templates: &str| {
        [
            "atlas",
            files[0].as_str(),
            "--subjects",
            &list,
            "--config",
            &config,
            "--out",
            &out.display().to_string(),
            "--template",
            &fine,
            "--stage-templates",
            templates,
        ]
        .map(String::from)
    };
    let coarse = coarse.display().to_string();
    let o = fshape(&args(&coarse).each_ref().map(String::as_str));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let stages = summary["stages"].as_array().unwrap();
    assert_eq!(stages.len(), 2);
    // The template is the initial one's (162 vertices), and the second
    // stage starts below where the first did.
    let template =
        fshape_mesh::io::read_mesh(&out.join("template.ply"), &fshape_mesh::io::ReadOptions::default()).unwrap();
    assert_eq!(template.n_vertices(), 162);
    let value = |s: &serde_json::Value| s["initial"]["value"].as_f64().unwrap();
    assert!(value(&stages[1]) < value(&stages[0]), "{stages:?}");
    // One stage template per stage before the last.
    let o = fshape(&args(&format!("{coarse},{coarse}")).each_ref().map(String::as_str));
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--stage-templates: 2 meshes for a schedule of 2 stages: give one per stage before the last (1)"),
        "{err}"
    );
}

#[test]
fn atlas_refuses_a_bad_list_line_naming_the_file_and_line() {
    let (files, list, config) = atlas_inputs("atlas_bad");
    std::fs::write(&list, "a.ply\nb.ply,b.csv,m.csv,extra\n").unwrap();
    let o = fshape(&[
        "atlas",
        &files[0],
        "--subjects",
        &list,
        "--config",
        &config,
        "--out",
        &tmp("atlas_bad_out").display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("atlas_bad_list.csv:2"), "{err}");
    // No subjects at all.
    let o = fshape(&["atlas", "--config", &config, "--out", &tmp("atlas_none").display().to_string()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no subjects"));
}

#[test]
fn demo_atlas_digits_reads_the_population_and_writes_an_atlas() {
    // Two of the shipped 3s, a few iterations: the wiring (the digits on
    // one square, the template from their mean image, fshape atlas).
    let out = tmp("atlas_digits_out");
    let o = fshape(&[
        "demo",
        "atlas-digits",
        "--subjects",
        "2",
        "--max-iterations",
        "1",
        "--out",
        &out.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dir = out.join("atlas-digits");
    let list = std::fs::read_to_string(dir.join("subjects/subjects.csv")).unwrap();
    assert_eq!(list.lines().filter(|l| !l.starts_with('#')).count(), 2);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("atlas/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["subjects"].as_array().unwrap().len(), 2);
    assert_eq!(summary["stages"].as_array().unwrap().len(), 2);
    // Both digits on one square, which the template keeps; each carries a
    // digit (values up to 0.6), not a blank square.
    use fshape_mesh::io::{ReadOptions, read_mesh};
    let read = |p: &str| read_mesh(&dir.join(p), &ReadOptions::default()).unwrap();
    let (a, b) = (read("subjects/mnist5k_1500_label3.ply"), read("subjects/mnist5k_1501_label3.ply"));
    let template = read("atlas/template.ply");
    assert_eq!((a.points(), a.cells()), (b.points(), b.cells()));
    assert_eq!((template.n_vertices(), template.cells()), (a.n_vertices(), a.cells()));
    for s in [&a, &b] {
        assert!(s.signal().unwrap().iter().any(|v| *v > 0.3), "a digit, not a blank square");
    }
    assert!(summary["min_attachment_fall"].as_f64().unwrap() > 0.0);
}

#[test]
fn demo_atlas_spheres_reports_the_template_against_the_truth() {
    let out = tmp("atlas_spheres_out");
    let o = fshape(&["demo", "atlas-spheres", "--max-iterations", "2", "--out", &out.display().to_string()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("the template against the truth"));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("atlas-spheres/truth.json")).unwrap()).unwrap();
    let num = |k: &str| report[k].as_f64().unwrap();
    // Six iterations already bring the sphere closer to the ellipsoid.
    assert!(num("truth_distance") < num("truth_distance_start"), "{report}");
    assert!((num("bound") - num("bias") - num("residual")).abs() < 1e-15);
    for f in ["truth.png", "estimate.png", "truth.ply", "atlas/template.ply", "subjects/subject_09.ply"] {
        assert!(out.join("atlas-spheres").join(f).exists(), "{f}");
    }
}

/// A batch table in a directory of its own: three sphere-to-ellipsoid
/// pairs (one with a signal CSV), a pair whose target does not exist and a
/// line with too few fields; and a fast configuration.
/// The small registration the batch and masked-population tests run on
/// spheres of radius 0.5: one deformation width, `iterations` at most.
fn sphere_config(iterations: usize) -> String {
    format!(
        "[model]\nnorm = \"h1\"\nlength = 0.2\n[deformation]\nwidths = [0.4]\n[integrator]\nsteps = 5\n\
         [attachment]\nkernel_geom = \"gaussian:0.1\"\nkernel_signal = \"gaussian:0.5\"\n\
         [optimizer]\nmax_iterations = {iterations}\n"
    )
}

fn batch_inputs(tag: &str) -> (PathBuf, String) {
    use fshape_mesh::io::{Encoding, write_mesh};
    let dir = tmp(tag);
    std::fs::create_dir_all(&dir).unwrap();
    let sphere = fshape_mesh::generate::icosphere(2, 0.5);
    let n = sphere.n_vertices();
    write_mesh(&dir.join("sphere.ply"), &sphere.clone().with_signal(Some(vec![0.0; n])).unwrap(), Encoding::Binary)
        .unwrap();
    for i in 0..3 {
        let a = 1.1 + 0.1 * i as f64;
        let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [a * p[0], p[1], p[2] / a]).collect();
        let f: Vec<f64> = pts.chunks_exact(3).map(|p| p[2] + 0.2 * i as f64).collect();
        let s = sphere.clone().with_points(pts).unwrap().with_signal(Some(f.clone())).unwrap();
        write_mesh(&dir.join(format!("ellipsoid{i}.ply")), &s, Encoding::Binary).unwrap();
        let csv: String = std::iter::once("signal\n".to_string()).chain(f.iter().map(|v| format!("{v}\n"))).collect();
        std::fs::write(dir.join(format!("signal{i}.csv")), csv).unwrap();
    }
    std::fs::write(
        dir.join("pairs.csv"),
        "# three pairs, a missing target, a short line\n\
         source,target,target_signal,name\n\
         sphere.ply,ellipsoid0.ply,,first\n\
         sphere.ply,ellipsoid1.ply,signal1.csv,\n\
         sphere.ply,missing.ply,,lost\n\
         sphere.ply\n\
         sphere.ply,ellipsoid2.ply,,third\n",
    )
    .unwrap();
    let config = dir.join("match.toml");
    std::fs::write(&config, sphere_config(6)).unwrap();
    (dir, config.display().to_string())
}

#[test]
fn pre_alignment_and_setup_report_on_the_runs_clock_before_the_stages() {
    let (dir, config) = batch_inputs("setup_lines");
    let with_prealign = dir.join("prealign.toml");
    std::fs::write(&with_prealign, std::fs::read_to_string(&config).unwrap() + "\n[prealign]\nkind = \"rigid\"\n")
        .unwrap();
    let path = |name: &str| dir.join(name).display().to_string();
    let args = ["match", &path("sphere.ply"), &path("ellipsoid0.ply"), "--config", &path("prealign.toml")];
    let o = fshape(&[&args[..], &["--out", &path("run"), "--stop-after", "1"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    let lines: Vec<&str> = err.lines().collect();
    let at = |what: &str| lines.iter().position(|l| l.contains(what)).unwrap_or_else(|| panic!("no `{what}` in {err}"));
    let (begins, ends, stage) =
        (at("setup pre-alignment (rigid) begins"), at("setup pre-alignment: rotation"), at("stage 1/1"));
    assert!(begins < ends && ends < stage, "{err}");
    // On the run's clock: "[    0.1 s] setup ...", as the stages' lines.
    for k in [begins, ends, stage] {
        let clock = lines[k].trim_start_matches('[').split(" s]").next().unwrap().trim();
        assert!(clock.parse::<f64>().is_ok_and(|t| t >= 0.0), "{}", lines[k]);
    }
    // The iteration lines weigh the attachment by the model's γ_W, which
    // the setup makes known.
    let iteration = lines[at("iteration 1:")];
    assert!(iteration.contains("γ_W·A ") && !iteration.contains("NaN"), "{iteration}");
}

#[test]
fn batch_gives_every_row_the_same_result_in_every_mode_and_a_bad_row_fails_alone() {
    let (dir, config) = batch_inputs("batch");
    let pairs = dir.join("pairs.csv").display().to_string();
    let batch = |out: &str, extra: &[&str], env: &[(&str, &str)]| {
        let args = [&["batch", pairs.as_str(), "--config", &config, "--out", out, "--times", "0,1"], extra].concat();
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_fshape"));
        cmd.args(&args);
        for (k, v) in env {
            cmd.env(k, v);
        }
        cmd.output().expect("the binary runs")
    };
    let out = |name: &str| dir.join(name).display().to_string();
    // In sequence: the two bad rows fail, the others finish; exit status 1.
    let o = batch(&out("seq"), &[], &[]);
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("seq/index.json")).unwrap()).unwrap();
    let rows = index["rows"].as_array().unwrap();
    let status: Vec<&str> = rows.iter().map(|r| r["status"].as_str().unwrap()).collect();
    assert_eq!(status, ["done", "done", "failed", "failed", "done"]);
    let names: Vec<&str> = rows.iter().map(|r| r["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["first", "row_002", "lost", "row_004", "third"]);
    let error = |k: usize| rows[k]["error"].as_str().unwrap().to_string();
    assert!(error(2).contains("missing.ply"), "{}", error(2));
    assert!(error(3).contains("pairs.csv:6") && error(3).contains("expected 4 fields"), "{}", error(3));
    for r in rows.iter().filter(|r| r["status"] == "done") {
        let d = r["mean_distance"].as_f64().unwrap();
        assert!(d > 0.0 && d < 0.05 && r["value"].as_f64().unwrap() > 0.0, "{r}");
    }
    // The signal CSV was read: that row's target signal is the CSV's.
    assert!(rows[1]["signal_rms"].as_f64().is_some());
    let csv = std::fs::read_to_string(dir.join("seq/index.csv")).unwrap();
    assert_eq!(csv.lines().count(), 6);
    assert!(csv.lines().nth(3).unwrap().contains(",failed,"));
    // Two rows at once, and a job array of two tasks (the second from
    // Slurm's variables, numbered from 1), then the index alone.
    let o = batch(&out("jobs"), &["--jobs", "2"], &[]);
    assert_eq!(o.status.code(), Some(1));
    let o = batch(&out("array"), &["--shard", "0/2"], &[]);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "rows 1, 3 and 5: {err}");
    assert!(err.contains("1 of this shard's 3 rows failed"), "{err}");
    // The reason once, not repeated by each layer of the error.
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
    let slurm = [("SLURM_ARRAY_TASK_ID", "2"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_COUNT", "2")];
    let o = batch(&out("array"), &[], &slurm);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "rows 2 and 4: {err}");
    assert!(err.contains("(1/2)") && err.contains("1 of this shard's 2 rows failed"), "{err}");
    assert!(batch(&out("array"), &["--index-only"], &[]).status.success());
    let again: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("array/index.json")).unwrap()).unwrap();
    assert_eq!((again["done"].as_u64(), again["failed"].as_u64()), (Some(3), Some(2)));
    for name in ["first", "row_002", "third"] {
        let a = std::fs::read(dir.join("seq").join(name).join("p0.csv")).unwrap();
        assert_eq!(a, std::fs::read(dir.join("jobs").join(name).join("p0.csv")).unwrap(), "{name}");
        assert_eq!(a, std::fs::read(dir.join("array").join(name).join("p0.csv")).unwrap(), "{name}");
    }
    // A row stopped midway resumes; finished rows are kept as they are.
    let stopped = dir.join("resumed/third").display().to_string();
    let src = dir.join("sphere.ply").display().to_string();
    let tgt = dir.join("ellipsoid2.ply").display().to_string();
    let o =
        fshape(&["match", &src, &tgt, "--config", &config, "--out", &stopped, "--stop-after", "2", "--times", "0,1"]);
    assert!(o.status.success() && !dir.join("resumed/third/summary.json").exists());
    batch(&out("resumed"), &[], &[]);
    let third = std::fs::read(dir.join("resumed/third/p0.csv")).unwrap();
    assert_eq!(third, std::fs::read(dir.join("seq/third/p0.csv")).unwrap());
    let o = batch(&out("seq"), &[], &[]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("1 to run"), "{}", String::from_utf8_lossy(&o.stderr));
    // A damaged summary: the index says so, naming it, and the row runs
    // again (to the same result).
    let first = dir.join("seq/first");
    std::fs::write(first.join("summary.json"), "{\"source\": ").unwrap();
    assert!(batch(&out("seq"), &["--index-only"], &[]).status.success());
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("seq/index.json")).unwrap()).unwrap();
    let row = &index["rows"][0];
    assert_eq!(row["status"], "failed", "{row}");
    let why = row["error"].as_str().unwrap();
    assert!(why.contains("summary.json: not JSON"), "{why}");
    let o = batch(&out("seq"), &[], &[]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("2 to run"), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(first.join("p0.csv")).unwrap(), std::fs::read(dir.join("jobs/first/p0.csv")).unwrap());
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("seq/index.json")).unwrap()).unwrap();
    assert_eq!(index["rows"][0]["status"], "done");
    // The page written from the index in memory is the one `fshape report`
    // builds from the files.
    let page = std::fs::read_to_string(dir.join("seq/report.html")).unwrap();
    assert!(fshape(&["report", &out("seq")]).status.success());
    assert_eq!(std::fs::read_to_string(dir.join("seq/report.html")).unwrap(), page);
}

#[test]
fn batch_refuses_a_bad_table_and_a_bad_shard() {
    let (dir, config) = batch_inputs("batch_bad");
    let pairs = dir.join("pairs.csv");
    let out = dir.join("out").display().to_string();
    let run = |extra: &[&str]| {
        fshape(&[&["batch", pairs.to_str().unwrap(), "--config", &config, "--out", &out], extra].concat())
    };
    for shard in ["2/2", "x/2", "1"] {
        let o = run(&["--shard", shard]);
        assert_eq!(o.status.code(), Some(2), "a usage error");
        assert!(String::from_utf8_lossy(&o.stderr).contains("--shard"), "{shard}");
    }
    std::fs::write(&pairs, "source,target,weight\na.ply,b.ply,1\n").unwrap();
    let o = run(&[]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("pairs.csv:1: unknown column `weight`"));
    std::fs::write(&pairs, "# nothing\n").unwrap();
    assert!(String::from_utf8_lossy(&run(&[]).stderr).contains("no header"));
    // Two rows of one name, and a name that is a path: those rows fail.
    std::fs::write(&pairs, "source,target,name\na.ply,b.ply,x\nc.ply,d.ply,x\ne.ply,f.ply,../up\n").unwrap();
    assert!(run(&["--index-only"]).status.success());
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/index.json")).unwrap()).unwrap();
    let rows = index["rows"].as_array().unwrap();
    assert_eq!(rows[0]["status"], "pending");
    assert!(rows[1]["error"].as_str().unwrap().contains("name `x` is also line 2's"), "{}", rows[1]);
    assert!(rows[2]["error"].as_str().unwrap().contains("not a plain directory name"), "{}", rows[2]);
}

#[test]
fn info_convert_match_and_atlas_take_gifti_and_freesurfer_files() {
    use fshape_mesh::io::{self, Encoding, ReadOptions, read_mesh, write_mesh};
    let (s, t, c) = match_inputs("neuro", 6);
    let dir = tmp("neuro_files");
    std::fs::create_dir_all(&dir).unwrap();
    let source = read_mesh(s.as_ref(), &ReadOptions::default()).unwrap();
    let target = read_mesh(t.as_ref(), &ReadOptions::default()).unwrap();
    // The source as FreeSurfer keeps it: a surface and a curv file; the
    // target as GIfTI, its signal a SHAPE array beside the geometry.
    write_mesh(&dir.join("lh.pial"), &source, Encoding::Binary).unwrap();
    io::write_signal(&dir.join("lh.thickness"), "thickness", source.signal().unwrap(), source.n_cells()).unwrap();
    write_mesh(&dir.join("target.surf.gii"), &target, Encoding::Binary).unwrap();
    io::write_signal(&dir.join("target.shape.gii"), "thickness", target.signal().unwrap(), 0).unwrap();
    io::write_signal(&dir.join("target.mgz"), "thickness", target.signal().unwrap(), 0).unwrap();
    let p = |name: &str| dir.join(name).display().to_string();

    let v = json(&fshape(&["info", &p("lh.pial"), "--signal", &p("lh.thickness"), "--json"]));
    assert_eq!((v["n_vertices"].as_u64(), v["closed"].as_bool()), (Some(162), Some(true)));
    let f32_min = source.signal().unwrap().iter().map(|&v| f64::from(v as f32)).fold(f64::INFINITY, f64::min);
    assert_eq!(v["signal"]["min"].as_f64().unwrap(), f32_min);
    let v = json(&fshape(&["info", &p("target.surf.gii"), "--json"]));
    assert!(v["signal"].is_object(), "the GIfTI surface's SHAPE array is its signal");
    let v = json(&fshape(&["info", &p("target.surf.gii"), "--signal", &p("target.mgz"), "--json"]));
    assert!(v["signal"].is_object());

    // Conversions both ways, by the output's name.
    let o = fshape(&["convert", &p("target.surf.gii"), &p("target.vtk")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = fshape(&["convert", &s, &p("rh.white")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let white = read_mesh(&dir.join("rh.white"), &ReadOptions::default()).unwrap();
    assert_eq!(std::fs::read(dir.join("rh.white")).unwrap()[..3], [0xff, 0xff, 0xfe]);
    assert_eq!(white.cells(), source.cells());
    let o = fshape(&["convert", &p("lh.pial"), &p("lh.gii"), "--signal", &p("lh.thickness")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let gii = read_mesh(&dir.join("lh.gii"), &ReadOptions::default()).unwrap();
    assert_eq!(gii.signal().unwrap().len(), 162);

    // A registration from the FreeSurfer pair to the GIfTI pair reaches
    // its target as the PLY one does (the same numbers to f32 rounding).
    let out = dir.join("match");
    let o = fshape(&[
        "match",
        &p("lh.pial"),
        &p("target.surf.gii"),
        "--signal",
        &p("lh.thickness"),
        "--target-signal",
        &p("target.shape.gii"),
        "--config",
        &c,
        "--out",
        &out.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let first = summary["stages"][0]["initial"]["attachment"].as_f64().unwrap();
    assert!(summary["final_attachment"].as_f64().unwrap() < 0.5 * first, "{summary}");

    // An atlas of subjects given as FreeSurfer and GIfTI files.
    let list = dir.join("subjects.csv");
    std::fs::write(&list, "lh.pial,lh.thickness\ntarget.surf.gii,target.mgz\n").unwrap();
    let out = dir.join("atlas");
    let o = fshape(&[
        "atlas",
        "--subjects",
        &list.display().to_string(),
        "--config",
        &c,
        "--out",
        &out.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("template.ply").exists());
    // A mesh given where a signal belongs is refused, saying what it is.
    let o = fshape(&["info", &p("lh.pial"), "--signal", &p("rh.white")]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("this is a mesh"), "{}", String::from_utf8_lossy(&o.stderr));
}

/// A closed curve of `n` points: an ellipse of half-axes (a, b), in R² or
/// lifted into R³ (z = c·cos θ + d·sin θ); written as OBJ (which carries no
/// signal) with its signal `sin θ + e·cos θ` as a CSV column.
fn curve_files(tag: &str, dim: usize, (a, b, c, d, e): (f64, f64, f64, f64, f64)) -> (String, String) {
    use fshape_mesh::io::{self, Encoding, write_mesh};
    let n = 48;
    let theta: Vec<f64> = (0..n).map(|k| std::f64::consts::TAU * k as f64 / n as f64).collect();
    let points: Vec<f64> = theta
        .iter()
        .flat_map(|t| {
            let p = [a * t.cos(), b * t.sin(), c * t.cos() + d * t.sin()];
            p[..dim].to_vec()
        })
        .collect();
    let signal: Vec<f64> = theta.iter().map(|t| t.sin() + e * t.cos()).collect();
    let (mesh, csv) = (tmp(&format!("{tag}.obj")), tmp(&format!("{tag}.csv")));
    write_mesh(&mesh, &fshape_mesh::generate::polyline(dim, points, true).unwrap(), Encoding::Binary).unwrap();
    io::write_signal(&csv, "f", &signal, 0).unwrap();
    (mesh.display().to_string(), csv.display().to_string())
}

#[test]
fn match_registers_curves_in_the_plane_and_in_space_given_signal_files() {
    let config = tmp("curves.toml");
    std::fs::write(
        &config,
        "[model]\nnorm = \"h1\"\nlength = 0.3\n[deformation]\nwidths = [0.8]\n[integrator]\nsteps = 5\n\
         [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:0.5\"\n[optimizer]\nmax_iterations = 40\n",
    )
    .unwrap();
    let config = config.display().to_string();
    for dim in [2, 3] {
        let (s, sf) = curve_files(&format!("curve{dim}_src"), dim, (1.0, 1.0, 0.3, 0.0, 0.0));
        let (t, tf) = curve_files(&format!("curve{dim}_tgt"), dim, (1.4, 0.8, 0.3, 0.2, 0.5));
        let out = tmp(&format!("curve{dim}_run"));
        let args = ["match", &s, &t, "--source-signal", &sf, "--target-signal", &tf, "--config", &config, "--out"];
        let o = fshape(&[&args[..], &[&out.display().to_string()]].concat());
        assert!(o.status.success(), "{dim}-D: {}", String::from_utf8_lossy(&o.stderr));
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
        let (q0, q) = (&summary["quality_before"], &summary["quality"]);
        let num = |q: &serde_json::Value, k: &str| q[k].as_f64().unwrap();
        // The ellipse is reached: the mean distance and the signal error
        // fall below a twentieth of where they started (seen: 1/200 and
        // less, the stage ending on its gradient test).
        assert!(num(q, "mean_distance") < 0.05 * num(q0, "mean_distance"), "{dim}-D: {q0} -> {q}");
        assert!(num(q, "signal_rms") < 0.05 * num(q0, "signal_rms"), "{dim}-D: {q0} -> {q}");
        // Without the target's signal the error names the target's file.
        let o = fshape(&[
            "match",
            &s,
            &t,
            "--source-signal",
            &sf,
            "--config",
            &config,
            "--out",
            &out.display().to_string(),
        ]);
        assert_eq!(o.status.code(), Some(1));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(&format!("{t}: the target has no signal")), "{err}");
    }
}

#[test]
fn match_registers_a_flat_square_with_an_image_like_signal() {
    use fshape_mesh::io::{Encoding, write_mesh};
    // A flat square of side 2 (as the digits) carrying a bump; the target
    // carries the bump moved: the signal must follow, the square stays.
    let square = fshape_mesh::generate::square(300, 3);
    let bump = |cx: f64| -> Vec<f64> {
        square.points().chunks_exact(2).map(|p| (-((p[0] - cx).powi(2) + p[1].powi(2)) / 0.18).exp()).collect()
    };
    let (s, t) = (tmp("flat_src.ply"), tmp("flat_tgt.ply"));
    write_mesh(&s, &square.clone().with_signal(Some(bump(-0.3))).unwrap(), Encoding::Binary).unwrap();
    write_mesh(&t, &square.clone().with_signal(Some(bump(0.3))).unwrap(), Encoding::Binary).unwrap();
    let config = tmp("flat.toml");
    std::fs::write(
        &config,
        "[model]\nnorm = \"h1\"\nlength = 0.2\n[deformation]\nwidths = [0.5]\n[integrator]\nsteps = 5\n\
         [attachment]\nkernel_geom = \"gaussian:0.2\"\nkernel_signal = \"gaussian:0.3\"\n[optimizer]\nmax_iterations = 40\n",
    )
    .unwrap();
    let out = tmp("flat_run");
    let o = fshape(&[
        "match",
        &s.display().to_string(),
        &t.display().to_string(),
        "--config",
        &config.display().to_string(),
        "--out",
        &out.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let (q0, q) = (&summary["quality_before"], &summary["quality"]);
    let num = |q: &serde_json::Value, k: &str| q[k].as_f64().unwrap();
    // The bump moves (seen: 29.9 % of the range to 0.5 %).
    assert!(num(q, "signal_rms") < 0.1 * num(q0, "signal_rms"), "{q0} -> {q}");
    // The square stays a square: its boundary within 2 % of the diagonal.
    assert!(num(q, "max_distance") < 0.02, "{q}");
}

/// A one-triangle ASCII PLY at x offset `dx` carrying the signal `f`.
fn signal_triangle(name: &str, dx: f64, f: [f64; 3]) -> String {
    let p = tmp(name);
    let text = format!(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
         property float signal\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
         {dx} 0 0 {}\n{} 0 0 {}\n{dx} 1 0 {}\n3 0 1 2\n",
        f[0],
        dx + 1.0,
        f[1],
        f[2]
    );
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// The RGB pixels of a PNG that `fshape render` wrote: (columns of the
/// non-white ones, their distinct colours).
fn painted(path: &std::path::Path) -> (Vec<usize>, std::collections::BTreeSet<[u8; 3]>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height, info.color_type), (512, 512, png::ColorType::Rgb));
    let (mut columns, mut colours) = (Vec::new(), std::collections::BTreeSet::new());
    for (i, px) in buf[..info.buffer_size()].chunks_exact(3).enumerate() {
        if px != [255, 255, 255] {
            columns.push(i % 512);
            colours.insert([px[0], px[1], px[2]]);
        }
    }
    (columns, colours)
}

#[test]
fn render_draws_meshes_from_one_camera_in_one_colour_range_and_refuses_bad_requests() {
    // Two unit triangles side by side in the plane z = 0, one with the
    // signal 0, 1, 2 at its corners, one constant at 2; seen from above.
    let a = signal_triangle("render_a.ply", 0.0, [0.0, 1.0, 2.0]);
    let (b, b4) = (signal_triangle("render_b.ply", 2.0, [2.0; 3]), signal_triangle("render_b4.ply", 2.0, [4.0; 3]));
    let (pa, pb) = (tmp("render_a.png"), tmp("render_b.png"));
    let outs = format!("{},{}", pa.display(), pb.display());
    let render = |meshes: &[&str], extra: &[&str]| {
        let mut args = vec!["render"];
        args.extend_from_slice(meshes);
        args.extend_from_slice(&["--out", &outs, "--view", "0,90"]);
        args.extend_from_slice(extra);
        let r = fshape(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        (painted(&pa), painted(&pb))
    };
    let ((ca, colours_a), (cb, colours_b)) = render(&[&a, &b], &[]);
    // Framed together: the first triangle in the left part of its picture,
    // the second in the right part of its own.
    assert!(!ca.is_empty() && !cb.is_empty());
    assert!(ca.iter().max() < cb.iter().min(), "columns {:?} and {:?}", ca.iter().max(), cb.iter().min());
    assert!(colours_a.len() > 20 && colours_b.len() == 1, "{} {colours_b:?}", colours_a.len());
    // One colour range for both: with the constant raised to 4 it is still
    // the top of the map, and the first triangle's colours move down.
    let ((_, colours_a4), (_, colours_b4)) = render(&[&a, &b4], &[]);
    assert_eq!(colours_b4, colours_b);
    assert_ne!(colours_a4, colours_a);
    // A range far above both signals paints both in the map's bottom colour.
    let ((_, low_a), (_, low_b)) = render(&[&a, &b], &["--range", "10,20"]);
    assert!(low_a.len() == 1 && low_a == low_b && low_b != colours_b, "{low_a:?} {low_b:?}");

    // Refusals, each naming its argument, with nothing written.
    let fresh = tmp("render_fresh.png");
    let fresh_s = fresh.display().to_string();
    let other = tmp("render_other.png").display().to_string();
    let pair = format!("{fresh_s},{other}");
    for (args, says) in [
        (vec!["render", &a, &b, "--out", &fresh_s], "--out"),
        (vec!["render", &a, "--out", "picture.jpg"], "png"),
        (vec!["render", &a, &b, "--out", &pair, "--range", "2,1"], "--range"),
        (vec!["render", &a, &b, "--out", &pair, "--range", "nan,1"], "--range"),
        (vec!["render", &a, "no/such/mesh.ply", "--out", &pair], "no/such/mesh.ply"),
        (vec!["render", &a, &b, "--out", &pair, "--view", "30"], "view"),
    ] {
        let r = fshape(&args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success() && err.contains(says), "{args:?}: {err}");
        assert!(!fresh.exists(), "{args:?} wrote {fresh_s}");
    }
}

#[test]
fn match_with_stderr_in_a_file_logs_a_line_per_iteration_and_quiet_logs_none() {
    let (s, t, c) = match_inputs("match_log", 6);
    let out = tmp("match_log_out");
    let log = tmp("match_log.txt");
    let status = Command::new(env!("CARGO_BIN_EXE_fshape"))
        .args(["match", &s, &t, "--config", &c, "--out", &out.display().to_string()])
        .stderr(std::fs::File::create(&log).unwrap())
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(&log).unwrap();
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let stages = summary["stages"].as_array().unwrap();
    let iterations: usize = stages.iter().map(|s| s["iterations"].as_array().unwrap().len()).sum();
    let lines: Vec<&str> = text.lines().filter(|l| l.contains("] stage ") && l.contains(": J ")).collect();
    assert_eq!(lines.len(), iterations, "{text}");
    assert!(iterations > stages.len(), "{text}");
    // Each names its stage, the elapsed time, J and its parts.
    assert!(lines[0].starts_with("[") && lines[0].contains(" s] stage 1/2 (gaussian:0.3) iteration 1: J "), "{text}");
    assert!(lines.iter().all(|l| l.contains("= H ") && l.contains("γ_W·A") && l.contains("evaluations")), "{text}");
    assert_eq!(text.lines().filter(|l| l.contains(" starts, at most ")).count(), stages.len(), "{text}");
    // --quiet: the result only.
    let o =
        fshape(&["match", &s, &t, "--config", &c, "--out", &tmp("match_log_quiet").display().to_string(), "--quiet"]);
    assert!(o.status.success());
    assert!(!String::from_utf8_lossy(&o.stderr).contains(" iteration "), "{}", String::from_utf8_lossy(&o.stderr));
    // The result in a few short lines: before -> after.
    let result = String::from_utf8_lossy(&o.stdout);
    assert_eq!(result.lines().count(), 5, "{result}");
    assert!(
        result.contains("mean distance ") && result.contains("signal error ") && result.contains(" -> "),
        "{result}"
    );
    assert!(result.lines().all(|l| l.chars().count() < 200), "{result}");
}

/// `fshape demo stats-spheres --quick` (8 ellipsoids per group, 162
/// vertices), run once for the tests that read its atlas and statistics.
fn stats_spheres() -> &'static PathBuf {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let out = tmp("stats_spheres_out");
        let o = fshape(&[
            "demo",
            "stats-spheres",
            "--quick",
            "--subjects",
            "8",
            "--permutations",
            "1000",
            "--out",
            &out.display().to_string(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        out.join("stats-spheres")
    })
}

#[test]
fn demo_stats_spheres_finds_each_effect_at_its_place() {
    // Two groups of randomly turned and moved ellipsoids; the second has
    // a bump at one place and a signal rise at another. After the atlas
    // (rigid pre-alignment) and the permutation tests, the maps of the
    // geometry find the bump and the signal map finds the rise, each
    // within the stated distance, by the maximum statistic and by TFCE.
    let dir = stats_spheres();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    let count = |map: &str, test: &str, place: &str| truth[map][test][place].as_u64().unwrap();
    for test in ["max_t", "tfce"] {
        // Nothing found where the groups do not differ.
        for map in ["signal", "momentum", "displacement", "area"] {
            assert_eq!(count(map, test, "elsewhere"), 0, "{map} {test}: {truth}");
        }
        // The bump by the geometry's maps, the rise by the signal's, and
        // neither map sees the other effect.
        assert!(count("displacement", test, "near_geometry_effect") > 0, "{test}: {truth}");
        assert_eq!(count("displacement", test, "near_signal_effect"), 0, "{test}: {truth}");
        assert!(count("momentum", test, "near_geometry_effect") > 0, "{test}: {truth}");
        assert!(count("signal", test, "near_signal_effect") > 0, "{test}: {truth}");
        assert_eq!(count("signal", test, "near_geometry_effect"), 0, "{test}: {truth}");
    }
    let width = truth["width"].as_f64().unwrap();
    assert!(truth["displacement"]["peak_distance_to_geometry_effect"].as_f64().unwrap() < width, "{truth}");
    assert!(truth["signal"]["peak_distance_to_signal_effect"].as_f64().unwrap() < width, "{truth}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("stats/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["design"]["columns"], serde_json::json!(["intercept", "group[effect]"]));
    // The bump is outward and the signal rises in the second group.
    let peak =
        |map: &str| summary["maps"].as_array().unwrap().iter().find(|m| m["map"] == map).unwrap()["peak"].clone();
    assert!(peak("displacement")["statistic"].as_f64().unwrap() > 0.0);
    assert!(peak("signal")["statistic"].as_f64().unwrap() > 0.0);
    assert!(summary["multivariate"]["p"].as_f64().unwrap() < 0.05, "{summary}");
    for f in [
        "signal_t.gii",
        "signal_p_fwe.gii",
        "signal_tfce_p_fwe.gii",
        "displacement_t.ply",
        "area.png",
        "multivariate.csv",
    ] {
        assert!(dir.join("stats").join(f).exists(), "{f}");
    }
}

#[test]
fn stats_gives_the_same_bits_for_a_seed_and_refuses_bad_tables_naming_the_cell() {
    let dir = stats_spheres();
    let atlas = dir.join("atlas").display().to_string();
    let run = |table: &str, contrast: &str, out: &str| {
        let path = tmp(&format!("{out}.csv"));
        std::fs::write(&path, table).unwrap();
        let out = tmp(out);
        let o = fshape(&[
            "stats",
            &atlas,
            "--covariates",
            &path.display().to_string(),
            "--contrast",
            contrast,
            "--permutations",
            "200",
            "--maps",
            "signal,area",
            "--out",
            &out.display().to_string(),
        ]);
        (o, out)
    };
    // The demo's own table, with an age column; twice, the same bits.
    let good: String = std::fs::read_to_string(dir.join("covariates.csv"))
        .unwrap()
        .lines()
        .enumerate()
        .map(|(k, l)| if k == 0 { format!("{l},age\n") } else { format!("{l},{}\n", 20 + k) })
        .collect();
    let (a, out_a) = run(&good, "group", "stats_a");
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    let (b, out_b) = run(&good, "group", "stats_b");
    assert!(b.status.success());
    for f in ["signal_t.gii", "signal_p_fwe.gii", "area_p.gii"] {
        assert_eq!(std::fs::read(out_a.join(f)).unwrap(), std::fs::read(out_b.join(f)).unwrap(), "{f}");
    }
    assert!(!out_a.join("momentum_t.gii").exists(), "--maps chooses the maps");
    let stdout = String::from_utf8_lossy(&a.stdout);
    assert!(stdout.contains("signal") && stdout.contains("p_FWE"), "{stdout}");
    // Bad tables and contrasts: exit 1, the file, line and column named.
    let first_row = good.lines().nth(1).unwrap().to_string();
    let cases: Vec<(String, &str, Vec<&str>)> = vec![
        (good.replace(&format!("{first_row}\n"), ""), "group", vec!["subject 0", "no row"]),
        (good.replacen(",21\n", ",twenty\n", 1), "group", vec!["line 2", "column `age`", "`twenty` is not a number"]),
        (
            good.lines()
                .map(|l| if l.starts_with("subject") { format!("{l},site\n") } else { format!("{l},a\n") })
                .collect(),
            "group",
            vec!["column `site`", "single group"],
        ),
        (good.clone(), "height", vec!["contrast `height`", "neither a design column"]),
    ];
    for (k, (table, contrast, says)) in cases.iter().enumerate() {
        let (o, out) = run(table, contrast, &format!("stats_bad_{k}"));
        assert_eq!(o.status.code(), Some(1), "case {k}");
        let err = String::from_utf8_lossy(&o.stderr);
        for s in says {
            assert!(err.contains(s), "case {k}: `{s}` not in {err}");
        }
        assert!(!out.exists(), "case {k}: nothing written");
    }
}

#[test]
fn match_writes_a_self_contained_report_that_fshape_report_writes_again() {
    use base64::Engine;
    use std::io::Read;
    let (s, t, c) = match_inputs("report", 3);
    let out = tmp("report_out");
    let o = fshape(&["match", &s, &t, "--config", &c, "--out", &out.display().to_string()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("report.html"), "the console names the report: {stdout}");
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    // Nothing from the network: no external script, style, image or font.
    for pattern in ["src=\"http", "href=\"http", "url(http", "@import", "<link"] {
        assert!(!page.contains(pattern), "{pattern}");
    }
    assert!(page.contains("default-src 'none'"), "a policy that forbids loading anything");
    // The data: every state of the geodesic, as the PLY files hold it
    // (float32), and the target.
    let start = page.find("id=\"fshape-data\">").unwrap() + "id=\"fshape-data\">".len();
    let json = &page[start..start + page[start..].find("</script>").unwrap()];
    let data: serde_json::Value = serde_json::from_str(json).unwrap();
    let scene = &data["scenes"][0];
    let frames = scene["mesh"]["frames"].as_array().unwrap();
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(frames.len(), 5, "the five times of --times");
    let unpack = |b64: &str| -> Vec<f32> {
        let gz = base64::engine::general_purpose::STANDARD.decode(b64).unwrap();
        let mut bytes = Vec::new();
        flate2::read::GzDecoder::new(&gz[..]).read_to_end(&mut bytes).unwrap();
        bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
    };
    use fshape_mesh::io::{ReadOptions, read_mesh};
    let last = read_mesh(&out.join("state_004.ply"), &ReadOptions::default()).unwrap();
    let shown = unpack(frames[4].as_str().unwrap());
    assert_eq!(shown.len(), last.points().len());
    for (a, b) in shown.iter().zip(last.points()) {
        assert_eq!(*a, *b as f32);
    }
    assert!(scene["companion"]["frames"].as_array().unwrap().len() == 1, "the target");
    assert!(summary["files"].as_array().unwrap().iter().any(|f| f == "report.html"));
    // `fshape report` writes the same page again.
    std::fs::remove_file(out.join("report.html")).unwrap();
    let again = fshape(&["report", &out.display().to_string()]);
    assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
    assert_eq!(std::fs::read_to_string(out.join("report.html")).unwrap(), page);
    // A folder that is not an output is refused by name.
    let bad = fshape(&["report", &tmp("no_such_run").display().to_string()]);
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("not an fshape match, atlas or batch folder"));
}

#[test]
fn hcp_thickness_as_shipped_is_read_with_its_medial_wall_masked() {
    let (mesh, thick) = (repo("data/conte69_32k/lh.midthickness.ply.gz"), repo("data/conte69_32k/lh.thickness.csv.gz"));
    // As shipped, NaN on the medial wall: refused, saying how to accept it.
    let o = fshape(&["info", &mesh, "--signal", &thick]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--allow-missing"), "{}", String::from_utf8_lossy(&o.stderr));
    // With --allow-missing: the 3 221 wall vertices are masked, the signal summary is the cortex's.
    let v = json(&fshape(&["info", &mesh, "--signal", &thick, "--allow-missing", "--json"]));
    assert_eq!((v["mask"]["masked"].as_u64(), v["mask"]["unmasked"].as_u64()), (Some(3221), Some(32492 - 3221)));
    assert!(v["signal"]["min"].as_f64().unwrap() > 1.0, "{v}");
    // The same wall as a FreeSurfer label of the cortex: the label's vertices count, the rest is masked.
    let text = String::from_utf8(
        std::io::Read::bytes(flate2::read::GzDecoder::new(std::fs::File::open(&thick).unwrap()))
            .collect::<Result<Vec<u8>, _>>()
            .unwrap(),
    )
    .unwrap();
    let cortex: Vec<usize> =
        text.lines().skip(1).enumerate().filter(|(_, l)| l.trim() != "nan").map(|(k, _)| k).collect();
    let mut label = format!("#!ascii label  , from subject conte69 vox2ras=TkReg\n{}\n", cortex.len());
    for v in &cortex {
        label.push_str(&format!("{v} 0 0 0 0\n"));
    }
    let path = tmp("lh.cortex.label");
    std::fs::write(&path, label).unwrap();
    let w = json(&fshape(&[
        "info",
        &mesh,
        "--signal",
        &thick,
        "--allow-missing",
        "--mask",
        path.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(w["mask"], v["mask"]);
    // A masked shape against itself: no signal error, the wall left out.
    let q = json(&fshape(&[
        "quality",
        &mesh,
        &mesh,
        "--signal",
        &thick,
        "--target-signal",
        &thick,
        "--allow-missing",
        "--json",
    ]));
    // (closest points found to rounding: 1e-16 of the range)
    assert!(q["signal_rms"].as_f64().unwrap() < 1e-12, "{q}");
}

#[test]
fn a_masked_population_goes_through_atlas_stats_and_batch_with_its_wall_left_out() {
    use fshape_mesh::io::{Encoding, ReadOptions, read_mesh, write_mesh};
    // Four ellipsoids on one mesh, a cap z > 0.3 as their medial wall:
    // the first two carry NaN there in a signal file (--allow-missing),
    // the last two a signal of their own and a mask column.
    let dir = tmp("masked_population");
    std::fs::create_dir_all(&dir).unwrap();
    let sphere = fshape_mesh::generate::icosphere(2, 0.5);
    let n = sphere.n_vertices();
    let wall: Vec<bool> = sphere.points().chunks_exact(3).map(|p| p[2] > 0.3).collect();
    let walled = wall.iter().filter(|w| **w).count();
    let column = |name: &str, values: &mut dyn Iterator<Item = f64>| -> String {
        std::iter::once(format!("{name}\n")).chain(values.map(|v| format!("{v}\n"))).collect()
    };
    let mut list = String::new();
    for i in 0..4 {
        let a = 1.0 + 0.1 * i as f64;
        let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [a * p[0], p[1], p[2] / a]).collect();
        let f: Vec<f64> = pts.chunks_exact(3).map(|p| p[0] + 0.2 * f64::from(i / 2)).collect();
        let mesh = sphere.clone().with_points(pts).unwrap();
        if i < 2 {
            write_mesh(&dir.join(format!("s{i}.ply")), &mesh, Encoding::Binary).unwrap();
            let mut nan = f.iter().zip(&wall).map(|(f, w)| if *w { f64::NAN } else { *f });
            std::fs::write(dir.join(format!("s{i}.csv")), column("thickness", &mut nan)).unwrap();
            list.push_str(&format!("s{i}.ply,s{i}.csv\n"));
        } else {
            write_mesh(&dir.join(format!("s{i}.ply")), &mesh.with_signal(Some(f)).unwrap(), Encoding::Binary).unwrap();
            let mut mask = wall.iter().map(|w| if *w { 0.0 } else { 1.0 });
            std::fs::write(dir.join(format!("m{i}.csv")), column("mask", &mut mask)).unwrap();
            list.push_str(&format!("s{i}.ply,,m{i}.csv\n"));
        }
    }
    std::fs::write(dir.join("list.csv"), list).unwrap();
    let config = dir.join("atlas.toml");
    std::fs::write(&config, sphere_config(4)).unwrap();
    let s = |p: PathBuf| p.display().to_string();
    let (list, config, atlas) = (s(dir.join("list.csv")), s(config), s(dir.join("atlas")));
    let template = s(dir.join("s0.ply"));
    let run = |args: &[&str]| {
        let o = fshape(args);
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        o
    };
    // NaN without --allow-missing: refused, naming the file.
    let o = fshape(&["atlas", "--subjects", &list, "--config", &config, "--out", &atlas]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("s0.csv") && err.contains("--allow-missing"), "{err}");
    // The template (the first subject's mesh, no signal) takes the mean
    // signal and the wall as its mask; the matched states keep it.
    run(&[
        "atlas",
        "--subjects",
        &list,
        "--template",
        &template,
        "--allow-missing",
        "--config",
        &config,
        "--out",
        &atlas,
    ]);
    let read = |p: PathBuf| read_mesh(&p, &ReadOptions::default()).unwrap();
    let t = read(dir.join("atlas/template.ply"));
    let masked: Vec<bool> = t.mask().unwrap().iter().map(|m| *m == 0.0).collect();
    assert_eq!(masked, wall);
    assert!(read(dir.join("atlas/subject_003/matched.ply")).mask().is_some());
    // Stats: the wall is outside every test, NaN in the maps.
    let covariates = dir.join("covariates.csv");
    std::fs::write(&covariates, "subject,group\n0,a\n1,a\n2,b\n3,b\n").unwrap();
    let out = dir.join("stats");
    run(&[
        "stats",
        &atlas,
        "--covariates",
        &s(covariates),
        "--contrast",
        "group",
        "--permutations",
        "24",
        "--maps",
        "signal,area",
        "--out",
        &s(out.clone()),
    ]);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["masked_vertices"].as_u64(), Some(walled as u64));
    for map in ["signal", "area"] {
        let stat = read(out.join(format!("{map}_t.ply")));
        let f = stat.signal().unwrap();
        assert!((0..n).all(|v| f[v].is_nan() == wall[v]), "{map}: NaN exactly on the wall");
    }
    // A batch row with mask columns registers with both walls masked; a
    // mask of the wrong length fails its row alone, naming the file.
    std::fs::write(
        dir.join("pairs.csv"),
        "source,target,source_signal,target_mask,name\n\
         s0.ply,s3.ply,s0.csv,m3.csv,masked\n\
         s0.ply,s3.ply,s0.csv,list.csv,short\n",
    )
    .unwrap();
    let batch = dir.join("batch");
    let o = fshape(&[
        "batch",
        &s(dir.join("pairs.csv")),
        "--config",
        &config,
        "--allow-missing",
        "--out",
        &s(batch.clone()),
    ]);
    assert!(!o.status.success());
    let end = std::fs::read_dir(batch.join("masked")).unwrap().filter_map(|e| e.ok()).map(|e| e.path()).find(|p| {
        p.file_name().unwrap().to_string_lossy().starts_with("state_") && p.extension().is_some_and(|e| e == "ply")
    });
    let end = read(end.expect("a state PLY"));
    assert_eq!(end.mask().unwrap().iter().map(|m| *m == 0.0).collect::<Vec<_>>(), wall);
    // The run keeps both walls (matched.ply, target.ply): a map of ones
    // carried either way comes from outside the giving side's wall only,
    // so the receiving wall, far from it, gets no value.
    let ones = dir.join("ones.csv");
    std::fs::write(&ones, column("ones", &mut std::iter::repeat_n(1.0, n))).unwrap();
    for onto in ["target", "source"] {
        let out = dir.join(format!("ones_on_{onto}.csv"));
        let v = json(&fshape(&[
            "transfer",
            &s(batch.join("masked")),
            &s(ones.clone()),
            &s(out.clone()),
            "--onto",
            onto,
            "--json",
        ]));
        assert_eq!((v["masked"].as_u64(), v["run_mask"].as_bool()), (Some(walled as u64), Some(true)), "{onto}: {v}");
        let got = fshape_mesh::io::read_signal_for(&out, Some(n), true).unwrap().values;
        let deep: Vec<bool> = sphere.points().chunks_exact(3).map(|p| p[2] > 0.4).collect();
        assert!((0..n).all(|v| !deep[v] || got[v].is_nan()), "{onto}: a value deep in the wall");
        let clear: Vec<bool> = sphere.points().chunks_exact(3).map(|p| p[2] < 0.2).collect();
        assert!((0..n).all(|v| !clear[v] || (got[v] - 1.0).abs() < 1e-12), "{onto}: away from the wall, every value");
    }
    let error = std::fs::read_to_string(batch.join("short/error.txt")).unwrap();
    assert!(error.contains("list.csv"), "{error}");
}

#[test]
fn info_takes_a_cifti_map_and_a_parcellation_s_regions_named_after_the_file() {
    // nibabel's files (fshape-mesh/tests/data/nibabel): a 12-vertex
    // surface, a dscalar whose CORTEX_LEFT leaves vertices 5 and 10 out,
    // and an annotation of three regions.
    let nib = |name: &str| repo(&format!("fshape-mesh/tests/data/nibabel/{name}"));
    let surface = nib("surf_base64.surf.gii");
    let signal = format!("{}:CORTEX_LEFT:myelin", nib("maps.dscalar.nii"));
    let v = json(&fshape(&["info", &surface, "--signal", &signal, "--allow-missing", "--json"]));
    assert_eq!(v["mask"]["masked"], 2, "{v}");
    let o = fshape(&["info", &surface, "--signal", &signal]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(1) && err.contains("is NaN") && err.contains("--allow-missing"), "{err}");
    let o = fshape(&["info", &surface, "--signal", &nib("maps.dscalar.nii")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("name the surface structure after the file") && err.contains("CORTEX_RIGHT"), "{err}");
    let mask = format!("{}:insula", nib("lh.parcels.annot"));
    let v = json(&fshape(&["info", &surface, "--mask", &mask, "--json"]));
    assert_eq!(v["mask"]["masked"], 9, "three of the twelve vertices are the insula: {v}");
}

#[test]
fn transfer_carries_maps_parcellations_and_labels_onto_the_target_and_back() {
    use fshape_mesh::io::{self, ReadOptions, parcellation::Parcellation, parcellation::Region, read_mesh};
    let (s, t, c) = match_inputs("transfer", 15);
    let run = tmp("transfer_run");
    let r = fshape(&["match", &s, &t, "--config", &c, "--out", &run.display().to_string(), "--times", "0,0.5"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // matched.ply is the end of the geodesic even when --times leaves t = 1 out.
    let source = read_mesh(s.as_ref(), &ReadOptions::default()).unwrap();
    let matched = read_mesh(&run.join("matched.ply"), &ReadOptions::default()).unwrap();
    assert_eq!(matched.n_vertices(), source.n_vertices());
    let n = source.n_vertices();
    let file = |name: &str| tmp(name).display().to_string();
    let run = run.display().to_string();

    // A map with a cap of missing values (z > 0.3 on the radius-0.5 sphere),
    // carried onto the target and back: the same values, up to twice the
    // interpolation error of a smooth map on cells of about 0.15 (h² ≈ 0.02
    // times its second derivatives, about 9), the cap still missing.
    let f = |p: &[f64]| if p[2] > 0.3 { f64::NAN } else { (3.0 * p[0]).sin() + p[1] };
    let values: Vec<f64> = (0..n).map(|v| f(source.point(v))).collect();
    io::csv::write_signal(tmp("transfer_map.csv").as_ref(), "thickness", &values).unwrap();
    let there = json(&fshape(&[
        "transfer",
        &run,
        &file("transfer_map.csv"),
        &file("transfer_on_target.gii"),
        "--max-distance",
        "1",
        "--json",
    ]));
    assert_eq!((there["kind"].as_str(), there["beyond"].as_u64()), (Some("map"), Some(0)), "{there}");
    assert!(there["missing"].as_u64().unwrap() > 0, "the cap is missing on the target: {there}");
    let back = json(&fshape(&[
        "transfer",
        &run,
        &file("transfer_on_target.gii"),
        &file("transfer_back.csv"),
        "--onto",
        "source",
        "--max-distance",
        "1",
        "--json",
    ]));
    assert_eq!(back["vertices"].as_u64(), Some(n as u64));
    let got = io::read_signal_for(tmp("transfer_back.csv").as_ref(), Some(n), true).unwrap().values;
    assert_eq!(got.len(), n);
    let mut worst: f64 = 0.0;
    for v in 0..n {
        let z = source.point(v)[2];
        if z < 0.2 {
            assert!(got[v].is_finite(), "vertex {v} at z = {z} lost its value");
            worst = worst.max((got[v] - values[v]).abs());
        } else if z > 0.4 {
            assert!(got[v].is_nan(), "vertex {v} at z = {z} in the missing cap got {}", got[v]);
        }
    }
    assert!(worst < 0.1, "round trip error {worst}");

    // A parcellation (.annot): two regions and vertices in none, there and
    // back; most vertices come back to their region, all keys and names kept.
    let region = |p: &[f64]| {
        if p[0] > 0.05 {
            0
        } else if p[1] > 0.0 {
            1
        } else {
            -1
        }
    };
    let parcels = Parcellation {
        keys: (0..n).map(|v| region(source.point(v))).collect(),
        regions: vec![
            Region { key: 0, name: "east".into(), rgba: [1.0, 0.0, 0.0, 1.0] },
            Region { key: 1, name: "north".into(), rgba: [0.0, 0.0, 1.0, 1.0] },
        ],
    };
    std::fs::write(tmp("lh.transfer.annot"), io::freesurfer::annot_bytes(&parcels).unwrap()).unwrap();
    for (from, to, onto) in
        [("lh.transfer.annot", "lh.on_target.annot", "target"), ("lh.on_target.annot", "lh.back.annot", "source")]
    {
        let o = fshape(&["transfer", &run, &file(from), &file(to), "--onto", onto, "--max-distance", "1"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(String::from_utf8_lossy(&o.stdout).contains("a parcellation onto the"), "{o:?}");
    }
    // As a GIfTI label file: the same regions vertex by vertex, the
    // vertices in none as the table's `???`.
    let o =
        fshape(&["transfer", &run, &file("lh.transfer.annot"), &file("on_target.label.gii"), "--max-distance", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (gii, annot) = (
        io::read_parcellation(&tmp("on_target.label.gii")).unwrap(),
        io::read_parcellation(&tmp("lh.on_target.annot")).unwrap(),
    );
    assert_eq!(gii.keys.len(), annot.keys.len());
    assert!(annot.keys.contains(&-1));
    for (g, a) in gii.keys.iter().zip(&annot.keys) {
        assert_eq!(gii.name(*g), Some(annot.name(*a).unwrap_or("???")));
    }
    let back = io::read_parcellation(&tmp("lh.back.annot")).unwrap();
    assert_eq!(back.regions.iter().map(|r| r.name.as_str()).collect::<Vec<_>>(), ["east", "north"]);
    let same = back.keys.iter().zip(&parcels.keys).filter(|(a, b)| a == b).count();
    assert!(same * 10 >= n * 9, "{same} of {n} vertices back in their region");
    assert!([-1, 0, 1].iter().all(|k| back.keys.contains(k)));

    // A FreeSurfer label onto the target: a .label of the target's vertices.
    let label = io::label::Label {
        vertices: (0..n).filter(|&v| source.point(v)[2] < -0.2).collect(),
        points: vec![],
        values: vec![],
    };
    let label = io::label::Label {
        points: vec![0.0; 3 * label.vertices.len()],
        values: vec![0.0; label.vertices.len()],
        ..label
    };
    io::label::write_label(&tmp("lh.bottom.label"), &label, "test").unwrap();
    let v = json(&fshape(&["transfer", &run, &file("lh.bottom.label"), &file("lh.bottom_on_target.label"), "--json"]));
    assert_eq!(v["kind"], "label");
    let carried = io::label::read_label(&tmp("lh.bottom_on_target.label")).unwrap();
    let target = read_mesh(t.as_ref(), &ReadOptions::default()).unwrap();
    assert!(carried.vertices.iter().all(|&u| target.point(u)[2] < -0.05), "{:?}", carried.vertices);
    assert!(
        carried.vertices.len() * 2 > label.vertices.len(),
        "{} of {}",
        carried.vertices.len(),
        label.vertices.len()
    );

    // A mask on the source: only the label's vertices carry their values.
    let o = fshape(&[
        "transfer",
        &run,
        &file("transfer_map.csv"),
        &file("transfer_masked.csv"),
        "--mask",
        &file("lh.bottom.label"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got = io::read_signal_for(tmp("transfer_masked.csv").as_ref(), Some(target.n_vertices()), true).unwrap().values;
    for (u, g) in got.iter().enumerate() {
        let z = target.point(u)[2];
        assert!(
            if z > -0.1 {
                g.is_nan()
            } else if z < -0.35 {
                g.is_finite()
            } else {
                true
            },
            "vertex {u} at z = {z}: {g}"
        );
    }

    // A registration that masked its source keeps the mask in matched.ply:
    // the masked vertices carry nothing, as with the same mask given by
    // --mask (the same file), unless --no-run-mask (the same file as no
    // mask at all).
    let masked_run = tmp("transfer_masked_run");
    std::fs::create_dir_all(&masked_run).unwrap();
    std::fs::copy(tmp("transfer_run").join("target.ply"), masked_run.join("target.ply")).unwrap();
    let wall: Vec<f64> = (0..n).map(|v| if source.point(v)[2] < -0.2 { 1.0 } else { 0.0 }).collect();
    let walled = matched.clone().with_mask(Some(wall.clone())).unwrap();
    io::write_mesh(&masked_run.join("matched.ply"), &walled, io::Encoding::Binary).unwrap();
    let masked_run = masked_run.display().to_string();
    let v =
        json(&fshape(&["transfer", &masked_run, &file("transfer_map.csv"), &file("transfer_walled.csv"), "--json"]));
    let walls = wall.iter().filter(|w| **w == 0.0).count();
    assert_eq!((v["masked"].as_u64(), v["run_mask"].as_bool()), (Some(walls as u64), Some(true)), "{v}");
    assert_eq!(std::fs::read(tmp("transfer_walled.csv")).unwrap(), std::fs::read(tmp("transfer_masked.csv")).unwrap());
    let map = file("transfer_map.csv");
    for (dir, extra, out) in
        [(&run, None, "transfer_plain.csv"), (&masked_run, Some("--no-run-mask"), "transfer_unwalled.csv")]
    {
        let out = file(out);
        let args: Vec<&str> = ["transfer", dir.as_str(), &map, &out].into_iter().chain(extra).collect();
        assert!(fshape(&args).status.success(), "{args:?}");
    }
    assert_eq!(std::fs::read(tmp("transfer_unwalled.csv")).unwrap(), std::fs::read(tmp("transfer_plain.csv")).unwrap());

    // A limit of 0: no vertex lies exactly on the other surface.
    let v = json(&fshape(&[
        "transfer",
        &run,
        &file("transfer_map.csv"),
        &file("transfer_none.csv"),
        "--max-distance",
        "0%",
        "--json",
    ]));
    assert_eq!(v["beyond"], v["vertices"], "{v}");

    // Refusals, naming the problem, with nothing written.
    io::csv::write_signal(tmp("transfer_short.csv").as_ref(), "thickness", &values[..5]).unwrap();
    let wide: Vec<f64> = (0..n).map(|v| if v == 7 { 5.0 } else { 1.0 }).collect();
    io::csv::write_signal(tmp("transfer_wide.csv").as_ref(), "mask", &wide).unwrap();
    for (args, says) in [
        (vec![run.clone(), file("transfer_map.csv"), file("transfer_x.annot")], "a map is written as a signal file"),
        (
            vec![run.clone(), file("transfer_map.csv"), file("transfer_x.dscalar.nii")],
            "a map is written as a signal file",
        ),
        (
            vec![
                run.clone(),
                file("transfer_map.csv"),
                file("transfer_x.csv"),
                "--mask".into(),
                file("transfer_wide.csv"),
            ],
            "a mask's weights are in [0, 1]",
        ),
        (
            vec![run.clone(), file("lh.transfer.annot"), file("transfer_x.gii")],
            "written as .annot (FreeSurfer), .label.gii",
        ),
        (vec![run.clone(), file("transfer_short.csv"), file("transfer_x.csv")], "values for a surface of"),
        (
            vec![run.clone(), file("transfer_map.csv"), file("transfer_x.csv"), "--max-distance=-1".into()],
            "--max-distance",
        ),
        (vec![repo("data"), file("transfer_map.csv"), file("transfer_x.csv")], "no matched.ply here"),
    ] {
        let args: Vec<&str> = std::iter::once("transfer").chain(args.iter().map(String::as_str)).collect();
        let o = fshape(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.code() == Some(1) && err.contains(says), "{args:?}: {err}");
    }
    for f in ["transfer_x.annot", "transfer_x.gii", "transfer_x.csv", "transfer_x.dscalar.nii"] {
        assert!(!tmp(f).exists(), "{f}");
    }
}

/// A structure of a CIFTI-2 label file (HCP's parcellations) is carried as
/// a parcellation, keys and table: through a registration that ended on
/// its target (nibabel's icosahedron onto itself) every key comes back,
/// the medial wall's `???` included.
#[test]
fn transfer_carries_a_cifti_label_file_as_a_parcellation() {
    use fshape_mesh::io;
    let run = tmp("transfer_dlabel_run");
    std::fs::create_dir_all(&run).unwrap();
    let nibabel = |name: &str| repo(&format!("fshape-mesh/tests/data/nibabel/{name}"));
    let ico = io::read_mesh(nibabel("lh.icosahedron").as_ref(), &io::ReadOptions::default()).unwrap();
    for name in ["matched.ply", "target.ply"] {
        io::write_mesh(&run.join(name), &ico, io::Encoding::Binary).unwrap();
    }
    let (run, out) = (run.display().to_string(), tmp("transfer_dlabel.label.gii").display().to_string());
    let input = format!("{}:CORTEX_LEFT:parcels", nibabel("parcels.dlabel.nii"));
    let v = json(&fshape(&["transfer", &run, &input, &out, "--json"]));
    assert_eq!((v["kind"].as_str(), v["vertices"].as_u64()), (Some("parcellation"), Some(12)), "{v}");
    let carried = io::read_parcellation(out.as_ref()).unwrap();
    let given = io::read_parcellation(input.as_ref()).unwrap();
    assert_eq!(carried.keys, given.keys);
    assert_eq!(carried.regions, given.regions);
    // Keys are never averaged: no map file is written from them.
    let o = fshape(&["transfer", &run, &input, &tmp("transfer_dlabel_x.func.gii").display().to_string()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(1) && err.contains("written as .annot (FreeSurfer), .label.gii"), "{err}");
}

/// FSHAPE_SIMD caps the kernel sums' instruction set: a registration gives
/// the same bits on every instruction set this machine has (the sums hold
/// their lanes in fixed blocks and round each fused multiply-add once), and
/// a value that is not understood is refused before any work.
#[test]
fn every_instruction_set_gives_the_same_registration_bits() {
    let (s, t, c) = match_inputs("simd", 8);
    let mut runs = Vec::new();
    for cap in ["auto", "avx2", "scalar"] {
        let out = tmp(&format!("simd_{cap}"));
        let o = Command::new(env!("CARGO_BIN_EXE_fshape"))
            .args(["match", &s, &t, "--config", &c, "--out", &out.display().to_string()])
            .env("FSHAPE_SIMD", cap)
            .output()
            .unwrap();
        assert!(o.status.success(), "{cap}: {}", String::from_utf8_lossy(&o.stderr));
        let read = |name: &str| std::fs::read(out.join(name)).unwrap();
        let summary: serde_json::Value = serde_json::from_slice(&read("summary.json")).unwrap();
        runs.push((cap, read("p0.csv"), read("pf.csv"), summary["final_value"].as_f64().unwrap()));
    }
    for r in &runs[1..] {
        assert!(
            r.1 == runs[0].1 && r.2 == runs[0].2 && r.3.to_bits() == runs[0].3.to_bits(),
            "{} differs from auto",
            r.0
        );
    }
    let o = Command::new(env!("CARGO_BIN_EXE_fshape"))
        .args(["match", &s, &t, "--config", &c, "--out", &tmp("simd_bad").display().to_string()])
        .env("FSHAPE_SIMD", "avx-512")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(1) && err.contains("FSHAPE_SIMD") && err.contains("auto, avx2 or scalar"), "{err}");
    assert!(!tmp("simd_bad").exists());
}

#[test]
fn two_maps_per_surface_are_registered_together_and_written_per_channel() {
    use fshape_mesh::io::{Encoding, ReadOptions, read_mesh, write_mesh};
    // An ellipsoid onto a sphere, each with two maps in two files: the
    // target's first map NaN on a cap (its wall, --allow-missing), its
    // second map in other units.
    let dir = tmp("two_maps");
    std::fs::create_dir_all(&dir).unwrap();
    let sphere = fshape_mesh::generate::icosphere(2, 0.5);
    let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [1.2 * p[0], p[1], p[2] / 1.2]).collect();
    let ellipsoid = sphere.clone().with_points(pts).unwrap();
    write_mesh(&dir.join("source.ply"), &ellipsoid, Encoding::Binary).unwrap();
    write_mesh(&dir.join("target.ply"), &sphere, Encoding::Binary).unwrap();
    let column = |name: &str, values: Vec<f64>| -> PathBuf {
        let path = dir.join(format!("{name}.csv"));
        let text: String =
            std::iter::once("value\n".to_string()).chain(values.iter().map(|v| format!("{v}\n"))).collect();
        std::fs::write(&path, text).unwrap();
        path
    };
    let map = |s: &fshape_mesh::FShape, f: &dyn Fn(&[f64]) -> f64| -> Vec<f64> {
        s.points().chunks_exact(3).map(f).collect()
    };
    let wall = |p: &[f64]| p[2] > 0.35;
    let files = [
        column("source1", map(&ellipsoid, &|p| p[0])),
        column("source2", map(&ellipsoid, &|p| 100.0 * p[1])),
        column("target1", map(&sphere, &|p| if wall(p) { f64::NAN } else { p[0] + 0.1 })),
        column("target2", map(&sphere, &|p| 100.0 * p[1] - 10.0)),
    ];
    let config = dir.join("config.toml");
    std::fs::write(&config, sphere_config(15).replace("\"gaussian:0.5\"", "\"gaussian:0.5,50\"")).unwrap();
    let s = |p: &std::path::Path| p.display().to_string();
    let out = dir.join("run");
    let (source, target, config) = (s(&dir.join("source.ply")), s(&dir.join("target.ply")), s(&config));
    let f: Vec<String> = files.iter().map(|p| s(p)).collect();
    // The pair with both maps on each side, as each command takes it.
    let pair: Vec<&str> = vec![
        &source,
        &target,
        "--signal",
        &f[0],
        "--signal",
        &f[1],
        "--target-signal",
        &f[2],
        "--target-signal",
        &f[3],
        "--allow-missing",
    ];
    let o = fshape(&[&["match"], &pair[..], &["--config", &config, "--out", &s(&out)]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The outputs carry both channels: states and matched shape as signal
    // and signal_2, the signal momentum as pf and pf_2.
    let matched = read_mesh(&out.join("matched.ply"), &ReadOptions::default()).unwrap();
    assert_eq!(matched.n_channels(), 2);
    let target_back = read_mesh(&out.join("target.ply"), &ReadOptions::default()).unwrap();
    assert_eq!(target_back.n_channels(), 2);
    let walled = sphere.points().chunks_exact(3).filter(|p| wall(p)).count();
    assert_eq!(target_back.mask().unwrap().iter().filter(|w| **w == 0.0).count(), walled);
    let pf = std::fs::read_to_string(out.join("pf.csv")).unwrap();
    assert!(pf.starts_with("pf,pf_2\n"), "{}", &pf[..40]);
    let vtk = String::from_utf8_lossy(&std::fs::read(out.join("momenta.vtk")).unwrap()).to_string();
    assert!(vtk.contains("SCALARS pf double") && vtk.contains("SCALARS pf_2 double"));
    assert_eq!(read_mesh(&out.join("state_000.vtk"), &ReadOptions::default()).unwrap().n_channels(), 2);
    // Each channel's error fell, judged on its own range.
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    for c in 0..2 {
        let rms = |q: &str| summary[q]["channels"][c]["signal_rms"].as_f64().unwrap();
        assert!(rms("quality") < 0.5 * rms("quality_before"), "channel {c}: {summary}");
    }
    // The report: a scene per channel (the viewer's picker), each
    // channel's error in the quality table.
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        page.contains("the geodesic, signal channel 1 of 2") && page.contains("the geodesic, signal channel 2 of 2")
    );
    assert!(page.contains("channel 2: signal error, rms"));
    // Its pictures: the first map as ever, the second in its own files.
    let files: Vec<&str> = summary["files"].as_array().unwrap().iter().filter_map(|f| f.as_str()).collect();
    for f in ["render_000.png", "target.png", "render_000_2.png", "target_2.png"] {
        assert!(out.join(f).exists() && files.contains(&f), "{f}");
    }
    assert_ne!(std::fs::read(out.join("target.png")).unwrap(), std::fs::read(out.join("target_2.png")).unwrap());
    // Its momenta shot again from its first state (both maps, the walls
    // masked) with the shoot.toml it wrote end where it ended.
    let file = |f: &str| s(&out.join(f));
    let again = dir.join("shot");
    let o = fshape(&[
        "shoot",
        &file("state_000.ply"),
        "--momentum",
        &file("p0.csv"),
        "--signal-momentum",
        &file("pf.csv"),
        "--config",
        &file("shoot.toml"),
        "--out",
        &s(&again),
        "--times",
        "1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let shot = read_mesh(&again.join("state_000.ply"), &ReadOptions::default()).unwrap();
    let close = |a: &[f64], b: &[f64]| {
        a.iter().zip(b).all(|(u, v)| (u - v).abs() < 1e-9 * (1.0 + v.abs()) || u.is_nan() && v.is_nan())
    };
    assert_eq!(shot.n_channels(), 2);
    assert!(close(shot.points(), matched.points()) && close(shot.signal().unwrap(), matched.signal().unwrap()));
    // `fshape info` and `fshape quality` read several maps alike.
    let v = json(&fshape(&["info", &target, "--signal", &f[2], "--signal", &f[3], "--allow-missing", "--json"]));
    assert_eq!(v["channels"].as_array().map(Vec::len), Some(2), "{v}");
    assert!((v["channels"][1]["max"].as_f64().unwrap() - 40.0).abs() < 1e-9, "{v}");
    let q = json(&fshape(&[&["quality"], &pair[..], &["--json"]].concat()));
    assert_eq!(q["channels"], summary["quality_before"]["channels"]);
    // A batch row of the same pair, its maps separated by `;`: the same
    // matched shape, to the byte.
    std::fs::write(
        dir.join("pairs.csv"),
        "source,target,source_signal,target_signal,name\n\
         source.ply,target.ply,source1.csv;source2.csv,target1.csv; target2.csv,pair\n",
    )
    .unwrap();
    let batch = dir.join("batch");
    let o = fshape(&["batch", &s(&dir.join("pairs.csv")), "--config", &config, "--out", &s(&batch), "--allow-missing"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(batch.join("pair/matched.ply")).unwrap(), std::fs::read(out.join("matched.ply")).unwrap());
    // Two maps against one: refused, with the counts.
    let o = fshape(&[
        "match",
        &source,
        &target,
        "--signal",
        &f[0],
        "--signal",
        &f[1],
        "--target-signal",
        &f[2],
        "--allow-missing",
        "--config",
        &config,
        "--out",
        &s(&dir.join("refused")),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("2 signal channels, the target 1"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // An atlas of the two, each subject's maps listed with `;`: the
    // template, each subject's p^f and momenta.csv carry both maps, and
    // summary.json each map's mean error.
    std::fs::write(
        dir.join("subjects.csv"),
        "source.ply,source1.csv;source2.csv\ntarget.ply,target1.csv;target2.csv\n",
    )
    .unwrap();
    let atlas = dir.join("atlas");
    let list = s(&dir.join("subjects.csv"));
    let o = fshape(&["atlas", "--subjects", &list, "--config", &config, "--out", &s(&atlas), "--allow-missing"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains(", map 2: "), "{}", String::from_utf8_lossy(&o.stdout));
    let template = read_mesh(&atlas.join("template.ply"), &ReadOptions::default()).unwrap();
    assert_eq!(template.n_channels(), 2);
    let pf = std::fs::read_to_string(atlas.join("subject_001/pf.csv")).unwrap();
    assert!(pf.starts_with("pf,pf_2\n"), "{}", &pf[..40]);
    let table = std::fs::read_to_string(atlas.join("momenta.csv")).unwrap();
    let header: Vec<&str> = table.lines().next().unwrap().split(',').collect();
    assert_eq!(header.len(), 1 + sphere.n_vertices() * (3 + 2));
    assert_eq!(header[1 + 3 * sphere.n_vertices()..][..4], ["pf_0", "pf_2_0", "pf_1", "pf_2_1"]);
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(atlas.join("summary.json")).unwrap()).unwrap();
    let per_map = summary["mean_signal_rms_per_channel"].as_array().unwrap();
    assert_eq!(per_map.len(), 2);
    assert_eq!(per_map[0], summary["mean_signal_rms"]);
    // Its report: the template in a scene per map, each map's error.
    let page = std::fs::read_to_string(atlas.join("report.html")).unwrap();
    assert!(page.contains("the template, map 2 of 2") && page.contains("map 2 error"));
    // Its pictures: the template's first map, and its second on its own.
    let (one, two) =
        (std::fs::read(atlas.join("template.png")).unwrap(), std::fs::read(atlas.join("template_2.png")).unwrap());
    assert!(one != two && summary["files"].as_array().unwrap().iter().any(|f| f == "template_2.png"));
    // A subject with one map fewer: refused, naming both.
    std::fs::write(dir.join("subjects.csv"), "source.ply,source1.csv;source2.csv\ntarget.ply,target1.csv\n").unwrap();
    let o =
        fshape(&["atlas", "--subjects", &list, "--config", &config, "--out", &s(&dir.join("no")), "--allow-missing"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("carries 2 signal map(s) per vertex and subject 1 carries 1"), "{err}");
}

#[test]
fn maps_of_another_length_than_the_mesh_are_refused_by_name() {
    let dir = tmp("short_maps");
    std::fs::create_dir_all(&dir).unwrap();
    let sphere = fshape_mesh::generate::icosphere(1, 0.5);
    let mesh = dir.join("sphere.ply");
    fshape_mesh::io::write_mesh(&mesh, &sphere, fshape_mesh::io::Encoding::Binary).unwrap();
    let n = sphere.n_vertices();
    let column = |name: &str, count: usize| -> String {
        let path = dir.join(name);
        std::fs::write(
            &path,
            std::iter::once("v\n".to_string()).chain((0..count).map(|v| format!("{v}\n"))).collect::<String>(),
        )
        .unwrap();
        path.display().to_string()
    };
    let (full, short) = (column("full.csv", n), column("short.csv", n - 2));
    let m = mesh.display().to_string();
    for order in [[&full, &short], [&short, &full]] {
        let o = fshape(&["info", &m, "--signal", order[0], "--signal", order[1]]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains("short.csv") && err.contains(&format!("{} values", n - 2)) && !err.contains("panicked"),
            "{err}"
        );
    }
}

#[test]
fn stats_on_an_atlas_of_two_maps_finds_the_group_difference_in_the_map_that_has_it() {
    use fshape_mesh::io::{Encoding, write_mesh};
    // Ten spheres of one mesh (five a group: 252 labellings, enough for a
    // corrected p under 0.05), two maps each, written as PLY (signal and
    // signal_2): the first map differs between subjects but not between
    // the groups; the second gains a bump at +x in group b alone.
    let dir = tmp("stats_two_maps");
    std::fs::create_dir_all(&dir).unwrap();
    let sphere = fshape_mesh::generate::icosphere(2, 0.5);
    let bump = |p: &[f64]| {
        let d2 = (p[0] - 0.5).powi(2) + p[1] * p[1] + p[2] * p[2];
        (-d2 / (2.0 * 0.15 * 0.15)).exp()
    };
    let mut list = String::new();
    let mut covariates = String::from("subject,group\n");
    for i in 0..10 {
        let group = i % 2;
        let noise = |v: usize, c: usize| 0.05 * (((v * 7 + i * 13 + c * 5) % 11) as f64 / 10.0 - 0.5);
        let f: Vec<f64> = sphere
            .points()
            .chunks_exact(3)
            .enumerate()
            .flat_map(|(v, p)| [p[2] + 0.1 * i as f64 + noise(v, 0), p[1] + 0.5 * group as f64 * bump(p) + noise(v, 1)])
            .collect();
        let a = 1.0 + 0.02 * i as f64;
        let pts: Vec<f64> = sphere.points().iter().map(|x| a * x).collect();
        let subject = sphere.clone().with_points(pts).unwrap().with_signals(Some(f), 2).unwrap();
        write_mesh(&dir.join(format!("s{i}.ply")), &subject, Encoding::Binary).unwrap();
        list.push_str(&format!("s{i}.ply\n"));
        covariates.push_str(&format!("{i},{}\n", ["a", "b"][group]));
    }
    std::fs::write(dir.join("list.csv"), list).unwrap();
    std::fs::write(dir.join("covariates.csv"), covariates).unwrap();
    let config = dir.join("atlas.toml");
    std::fs::write(&config, sphere_config(8).replace("\"gaussian:0.5\"", "\"gaussian:0.5,0.5\"")).unwrap();
    let s = |p: PathBuf| p.display().to_string();
    let (atlas, stats) = (dir.join("atlas"), dir.join("stats"));
    let o =
        fshape(&["atlas", "--subjects", &s(dir.join("list.csv")), "--config", &s(config), "--out", &s(atlas.clone())]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let args = |maps: Option<&str>, out: &PathBuf| -> Vec<String> {
        let mut v: Vec<String> =
            ["stats", &s(atlas.clone()), "--covariates", &s(dir.join("covariates.csv"))].map(String::from).to_vec();
        v.extend(["--contrast", "group", "--permutations", "500", "--out", &s(out.clone())].map(String::from));
        if let Some(m) = maps {
            v.extend(["--maps".to_string(), m.to_string()]);
        }
        v
    };
    let run = |v: Vec<String>| fshape(&v.iter().map(String::as_str).collect::<Vec<_>>());
    let o = run(args(None, &stats));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(stats.join("summary.json")).unwrap()).unwrap();
    let maps = summary["maps"].as_array().unwrap();
    let names: Vec<&str> = maps.iter().map(|m| m["map"].as_str().unwrap()).collect();
    assert_eq!(names, ["signal", "signal_2", "momentum", "displacement", "area"]);
    let found = |m: &str| maps.iter().find(|x| x["map"] == m).unwrap()["found"]["vertices"].as_u64().unwrap();
    // The difference is found in the second map, at the bump, and not in
    // the first.
    assert!(found("signal_2") > 0 && found("signal") == 0, "{summary}");
    let peak = &maps[1]["peak"]["position"];
    assert!(peak[0].as_f64().unwrap() > 0.35, "{peak}");
    assert!(stats.join("signal_2_t.gii").exists() && stats.join("signal_2.png").exists());
    // One map by name; a map the atlas does not carry is refused.
    let o = run(args(Some("signal_2"), &dir.join("one")));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run(args(Some("signal_3"), &dir.join("none")));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--maps signal_3") && err.contains("with 2 signal map(s)"), "{err}");
}

#[test]
fn regress_fits_each_subjects_visits_in_its_folder_and_resumes_to_the_same_bytes() {
    let (dir, _) = batch_inputs("regress");
    std::fs::write(
        dir.join("visits.csv"),
        "# two subjects; B's later visit counts twice\n\
         subject,age,mesh,signal,weight\n\
         A,50,sphere.ply,,\n\
         A,53.5,ellipsoid1.ply,signal1.csv,\n\
         A,52,ellipsoid0.ply,,1\n\
         B,10,sphere.ply,,\n\
         B,11,ellipsoid2.ply,,2\n",
    )
    .unwrap();
    let config = dir.join("regress.toml").display().to_string();
    std::fs::write(&config, sphere_config(40)).unwrap();
    let path = |name: &str| dir.join(name).display().to_string();
    let run = |out: &str, extra: &[&str]| {
        fshape(
            &[&["regress", "--visits", &path("visits.csv"), "--config", &config, "--out", &path(out)], extra].concat(),
        )
    };
    let o = run("run", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("A: 3 visits, ages 50 to 53.5") && stdout.contains("B: 2 visits, ages 10 to 11"),
        "{stdout}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run/A/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["kind"], "regression");
    assert_eq!((summary["t0"].as_f64(), summary["span"].as_f64()), (Some(50.0), Some(3.5)));
    let visits = summary["visits"].as_array().unwrap();
    let times: Vec<f64> = visits.iter().map(|v| v["time"].as_f64().unwrap()).collect();
    assert_eq!(times, [0.0, 1.0, 2.0 / 3.5]);
    // The later visits are closer to their fitted states than to the baseline.
    for v in &visits[1..] {
        let (before, after) =
            (v["quality_before"]["mean_distance"].as_f64().unwrap(), v["quality"]["mean_distance"].as_f64().unwrap());
        assert!(after < 0.5 * before, "{v}");
    }
    for file in ["fitted_002.ply", "visit_001.png", "p0.csv", "pf.csv", "rates.vtk", "trajectory.pvd", "energy.svg"] {
        assert!(dir.join("run/A").join(file).exists(), "{file}");
    }
    let rates = std::fs::read_to_string(dir.join("run/A/rates.csv")).unwrap();
    assert!(rates.starts_with("normal_velocity,signal_rate\n") && rates.lines().count() == 163, "{rates:.60}");
    // The page: the fitted geodesic, then each visit beside its fit;
    // `fshape report` writes the same page again from the folder.
    let page = std::fs::read_to_string(dir.join("run/A/report.html")).unwrap();
    assert!(page.contains("age 52 (visit 3)") && page.contains("visit 3 (age 52): its fit"), "{page:.300}");
    // The collection lists every state by age: 3 visits and 7 ages between.
    let pvd = std::fs::read_to_string(dir.join("run/A/trajectory.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 10, "{pvd}");
    assert!(dir.join("run/A/state_006.ply").exists() && !dir.join("run/A/state_007.ply").exists());
    std::fs::remove_file(dir.join("run/A/report.html")).unwrap();
    let again = fshape(&["report", &path("run/A")]);
    assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
    assert_eq!(std::fs::read_to_string(dir.join("run/A/report.html")).unwrap(), page);
    let record = <fshape_match::record::RegressionRecord as fshape_match::record::RunRecord>::read(
        &dir.join("run/B/summary.json"),
    )
    .unwrap();
    assert_eq!(record.visits[1].weight, 2.0);
    // Stopped after one iteration and resumed: the same momenta, byte for byte.
    let o = run("again", &["--subject", "B", "--stop-after", "1"]);
    assert!(o.status.success() && !dir.join("again/B/summary.json").exists(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run("again", &["--subject", "B", "--resume"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(dir.join("again/B/p0.csv")).unwrap(), std::fs::read(dir.join("run/B/p0.csv")).unwrap());
    assert!(!dir.join("again/A").exists());
    // A job array's task 1 of 2 takes every second subject from the second.
    let o = run("shard", &["--shard", "1/2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("shard/B/summary.json").exists() && !dir.join("shard/A").exists());
    // A table's mistakes are named with their line.
    std::fs::write(dir.join("bad.csv"), "subject,age,mesh\nA,50,sphere.ply\nA,fifty,ellipsoid0.ply\n").unwrap();
    let o = fshape(&["regress", "--visits", &path("bad.csv"), "--config", &config, "--out", &path("bad")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(1) && err.contains("bad.csv:3") && err.contains("age `fifty`"), "{err}");
    let o = run("none", &["--subject", "C"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(1) && err.contains("no subject `C` (the table has A, B)"), "{err}");
    // A subject that cannot be fitted (one visit) is said; the others run.
    std::fs::write(
        dir.join("dropout.csv"),
        "subject,age,mesh\nC,50,sphere.ply\nD,10,sphere.ply\nD,11,ellipsoid0.ply\n",
    )
    .unwrap();
    let o = fshape(&["regress", "--visits", &path("dropout.csv"), "--config", &config, "--out", &path("dropout")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("subject `C`") && err.contains("at least 2 visits") && err.contains("1 of 2 subjects failed"),
        "{err}"
    );
    assert!(dir.join("dropout/D/summary.json").exists() && !dir.join("dropout/C/summary.json").exists());
}

#[test]
fn the_regression_demo_writes_its_truth_comparison_and_pictures() {
    // A few iterations: the figures the guide quotes come from the full
    // run; the known truth's bounds are held by fshape-match's regression
    // tests.
    let out = tmp("regress_demo");
    let o = fshape(&["demo", "regress-spheres", "--max-iterations", "3", "--out", &out.display().to_string()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("age 62.2: the fit against the truth") && stdout.contains("relative L2 error"), "{stdout}");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("regress-spheres/truth.json")).unwrap()).unwrap();
    for b in truth["between_visits"].as_array().unwrap() {
        // Even after 9 iterations the fit is nearer the truth than the baseline.
        let (d, d0) =
            (b["quality"]["mean_distance"].as_f64().unwrap(), b["baseline_quality"]["mean_distance"].as_f64().unwrap());
        assert!(d < d0, "{b}");
    }
    assert!(truth["normal_rate_relative_l2_error"].as_f64().unwrap().is_finite());
    for file in ["truth_rate.png", "fit_rate.png", "regression/summary.json", "regression/report.html"] {
        assert!(out.join("regress-spheres").join(file).exists(), "{file}");
    }
}
