//! The configuration file: defaults, unknown keys, checked values.

use fshape_match::Config;
use fshape_mesh::test_support::perturbed_icosphere;
use fshape_shoot::{Integrator, ModelKind};

#[test]
fn defaults_are_documented_values() {
    let c = Config::parse("[deformation]\nwidths = [0.2, 0.1]\n").unwrap();
    let m = c.model().unwrap();
    assert_eq!(m.kind(), ModelKind::Metamorphosis);
    assert_eq!(m.norm(), fshape_fem::Norm::L2Lumped);
    // The scale-free defaults (module docs of fshape_match::config).
    assert_eq!((m.gamma_v(), m.gamma_f(), m.gamma_w()), (1.0, 0.1, 1000.0));
    assert_eq!((m.integrator(), m.steps(), m.max_drift()), (Integrator::Rk4, 10, 0.5));
    assert!(m.kernel().taper().is_none());
    // Weights default to 1: k(0) = 2 for two widths.
    assert_eq!(m.kernel().value(0.0), 2.0);
}

#[test]
fn unknown_keys_and_bad_values_are_refused_by_name() {
    for (text, needle) in [
        ("[deformation]\nwidths = [0.2]\nwidht = 1\n", "widht"),
        ("[deformation]\nwidths = [0.2]\n[modle]\n", "modle"),
        ("[deformation]\nwidths = [0.2]\n[model]\ngamma_v = 0\n", "model.gamma_v"),
        ("[deformation]\nwidths = [0.2]\n[model]\nkind = \"magic\"\n", "model.kind"),
        ("[deformation]\nwidths = [0.2]\n[model]\nnorm = \"h2\"\n", "model.norm"),
        ("[deformation]\nwidths = [0.2]\n[model]\nnorm = \"h1\"\nlength = -1\n", "model.length"),
        ("[deformation]\nwidths = [-0.2]\n", "deformation"),
        ("[deformation]\nwidths = [0.2, 0.1]\nweights = [1]\n", "deformation"),
        ("[deformation]\nwidths = [0.2]\ntolerance = 3\n", "deformation.tolerance"),
        ("[deformation]\nwidths = [0.2]\n[integrator]\nsteps = 0\n", "integrator.steps"),
        ("[deformation]\nwidths = [0.2]\n[integrator]\nscheme = \"rk5\"\n", "integrator.scheme"),
        ("[model]\ngamma_v = 1\n", "deformation"),
    ] {
        let err = Config::parse(text).and_then(|c| c.model()).expect_err(text).to_string();
        assert!(err.contains(needle), "{text:?}: {err}");
    }
}

#[test]
fn values_of_the_wrong_type_or_spelling_name_their_key_and_line() {
    let base = "[deformation]\nwidths = [0.2]\n";
    for (extra, key, line) in [
        ("[model]\nkind = \"magic\"\n", "model.kind", 4),
        ("[model]\ngamma_v = \"one\"\n", "model.gamma_v", 4),
        ("[integrator]\n\nscheme = \"rk5\"\n", "integrator.scheme", 5),
        ("[attachment]\nkernel_geom = \"gaussian:0\"\n", "attachment.kernel_geom", 4),
        ("[attachment]\nkernel_geom = \"gaussian:1\"\nkernel_grass = \"bient\"\n", "attachment.kernel_grass", 5),
        (
            "[attachment]\nkernel_geom = \"gaussian:1\"\nkernel_signal = \"gaussian:-2\"\n",
            "attachment.kernel_signal",
            5,
        ),
        ("[optimizer]\nmethod = \"newton\"\n", "optimizer.method", 4),
        ("[optimizer]\nsignal_metric = \"h1\"\n", "optimizer.signal_metric", 4),
        ("[schedule]\nkernel_geom = [\"gaussian:0.4\", \"gaussian:-1\"]\n", "schedule.kernel_geom[1]", 4),
    ] {
        let text = format!("{base}{extra}");
        let e = Config::parse(&text).expect_err(&text).to_string();
        assert!(e.contains(key) && e.contains(&format!("line {line}")), "{extra:?}: {e}");
    }
    // A kernel is parsed once, when read: its width is checked there.
    let e = Config::parse(&format!("{base}[attachment]\nkernel_geom = \"gaussian:0\"\n")).unwrap_err().to_string();
    assert!(e.contains("position kernel"), "{e}");
}

#[test]
fn a_config_written_with_serde_reads_back_to_the_same_value() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/configs/bunny.toml");
    let shipped = Config::read(&path).unwrap();
    let mut full = shipped.clone();
    full.model.kind = fshape_shoot::ModelKind::Tangential;
    full.integrator.scheme = Integrator::Midpoint;
    full.optimizer.method = fshape_match::MethodKind::GradientDescent;
    full.optimizer.signal_metric = fshape_match::Metric::Euclidean;
    full.schedule = Some(fshape_match::ScheduleSection {
        kernel_geom: ["gaussian:0.2", "cauchy:0.1"].map(|k| fshape_match::PositionKernel::parse(k).unwrap()).to_vec(),
        scheme: Some(vec![Integrator::Euler, Integrator::Rk4]),
        steps: Some(vec![3, 10]),
        max_iterations: Some(vec![50, 20]),
        decrease_tolerance: Some(vec![1e-2, 1e-3]),
        decrease_window: Some(vec![10, 3]),
        vertices: Some(vec![500]),
        coarse_targets: Some(false),
    });
    for c in [shipped, full] {
        let text = c.to_toml();
        assert_eq!(Config::parse(&text).unwrap(), c, "{text}");
    }
    // The spellings users write are the ones serde writes.
    let text = Config::read(&path).unwrap().to_toml();
    for needle in [
        "kind = \"metamorphosis\"",
        "norm = \"h1\"",
        "scheme = \"rk4\"",
        "method = \"lbfgs\"",
        "kernel_geom = \"gaussian:0.05\"",
    ] {
        assert!(text.contains(needle), "{needle} in {text}");
    }
}

#[test]
fn the_shipped_bunny_config_parses() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/configs/bunny.toml");
    let c = Config::read(&path).unwrap();
    let m = c.model().unwrap();
    assert_eq!(m.steps(), 10);
    c.attachment_kernel().unwrap();
}

#[test]
fn the_bunny_setting_is_centred_scaled_and_textured_as_the_issue_states() {
    use fshape_mesh::io::{ReadOptions, read_mesh};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/stanford_bunny/bunny_qslim_2581v.ply.gz");
    let bunny = read_mesh(&path, &ReadOptions::default()).unwrap();
    let (template, target) = fshape_match::demo::bunny_setting(&bunny).unwrap();
    assert_eq!((target.n_vertices(), template.n_vertices()), (2581, 10242));
    assert!((target.bounding_box().diagonal() - 1.0).abs() < 1e-12);
    let n = target.n_vertices() as f64;
    for k in 0..3 {
        let mean: f64 = target.points().chunks_exact(3).map(|p| p[k]).sum::<f64>() / n;
        assert!(mean.abs() < 1e-12, "centroid coordinate {k} = {mean}");
    }
    // The signal at one vertex, by the formula in the target coordinates.
    let b = target.bounding_box();
    let (px, py) = (b.max[0] - b.min[0], b.max[1] - b.min[1]);
    let p = target.point(100);
    assert!((target.signal().unwrap()[100] - ((3.0 * p[0] / px).sin() + p[1] / py)).abs() < 1e-14);
    let r = template.point(7).iter().map(|v| v * v).sum::<f64>().sqrt();
    assert!((r - 0.35).abs() < 1e-12 && template.signal().unwrap().iter().all(|&v| v == 0.0));
}

/// The fuzz target `config`'s committed corpus, replayed with its
/// property: a configuration that parses is written to TOML that parses
/// to the same configuration.
#[test]
fn the_config_fuzz_corpus_keeps_its_round_trip() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus/config");
    let files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    assert!(files.len() >= 3, "{}: {} inputs", dir.display(), files.len());
    let mut parsed = 0;
    for file in files {
        let data = std::fs::read(&file).unwrap();
        let Ok(text) = std::str::from_utf8(&data) else { continue };
        let Ok(config) = Config::parse(text) else { continue };
        let written = config.to_toml();
        let back = Config::parse(&written).unwrap_or_else(|e| panic!("{}: {e}\n{written}", file.display()));
        assert_eq!(back.to_toml(), written, "{}", file.display());
        parsed += 1;
    }
    assert!(parsed >= 3, "the seeds parse");
}

/// A stage as a schedule says it: label, integrator, iteration limit,
/// decrease test, template vertices, coarse target.
type Stage = (String, (Integrator, usize), usize, (f64, usize), Option<usize>, bool);

/// What a schedule of stages says, comparable.
fn stages(c: &Config) -> Vec<Stage> {
    c.schedule()
        .unwrap()
        .into_iter()
        .map(|s| (s.label, s.integrator, s.max_iterations, s.decrease, s.vertices, s.coarse_target))
        .collect()
}

#[test]
fn the_older_arrays_read_with_a_warning_and_are_written_as_tables_with_the_same_stages() {
    let base = "[deformation]\nwidths = [0.2]\n[attachment]\nkernel_geom = \"gaussian:0.1\"\n\
                [integrator]\nsteps = 8\n[optimizer]\nmax_iterations = 40\n";
    let schedules = [
        "kernel_geom = [\"gaussian:0.3\", \"gaussian:0.1\"]\n",
        "kernel_geom = [\"gaussian:0.4\", \"gaussian:0.2\", \"gaussian:0.1\"]\nmax_iterations = [100, 40, 10]\n\
         scheme = [\"midpoint\", \"euler\", \"rk4\"]\nsteps = [4, 6, 8]\ndecrease_tolerance = [1e-2, 1e-3, 1e-4]\n\
         decrease_window = [5, 4, 3]\nvertices = [500, 2000]\ncoarse_targets = false\n",
        "kernel_geom = [\"gaussian:0.3\", \"gaussian:0.1\"]\nvertices = [900]\n",
    ];
    for schedule in schedules {
        let arrays = Config::parse(&format!("{base}[schedule]\n{schedule}")).unwrap();
        let warnings = arrays.warnings();
        assert!(warnings.len() == 1 && warnings[0].contains("[[stage]]"), "{warnings:?}");
        let tables = arrays.clone().with_stage_tables();
        assert!(tables.schedule.is_none() && tables.warnings().is_empty());
        assert_eq!(stages(&tables), stages(&arrays), "{schedule}");
        // What a run writes (its resolved configuration) is in tables, and
        // reads back to the same value.
        let resolved = arrays.resolved(None);
        let text = resolved.to_toml();
        assert!(text.contains("[[stage]]") && !text.contains("[schedule]"), "{text}");
        assert_eq!(Config::parse(&text).unwrap(), resolved);
        assert_eq!(stages(&resolved), stages(&arrays));
    }
    // Either form of one schedule is one problem: the checkpoint of a run
    // configured with the arrays resumes with the tables.
    let (source, target) = (perturbed_icosphere(1, 0.0, 1), perturbed_icosphere(1, 0.05, 2));
    let arrays = Config::parse(&format!("{base}[schedule]\n{}", schedules[1])).unwrap();
    let fingerprint = |c: &Config| fshape_match::fingerprint(&source, &target, c);
    assert_eq!(fingerprint(&arrays.clone().with_stage_tables()), fingerprint(&arrays));
    let mut other = arrays.clone();
    other.optimizer.max_iterations += 1;
    assert_ne!(fingerprint(&other), fingerprint(&arrays));
    // Arrays of the wrong length stay arrays, for their check to name.
    let short =
        Config::parse(&format!("{base}[schedule]\nkernel_geom = [\"gaussian:0.3\", \"gaussian:0.1\"]\nsteps = [4]\n"))
            .unwrap();
    assert_eq!(short.clone().with_stage_tables(), short);
    assert!(short.schedule().unwrap_err().to_string().contains("schedule.steps"));
}

#[test]
fn a_schedule_of_stage_tables_is_the_schedule_of_its_arrays() {
    let base = "[deformation]\nwidths = [0.2]\n[attachment]\nkernel_geom = \"gaussian:0.1\"\n\
                [optimizer]\nmax_iterations = 40\ndecrease_window = 7\n";
    let arrays = format!(
        "{base}[schedule]\nkernel_geom = [\"gaussian:0.4\", \"gaussian:0.2\", \"gaussian:0.1\"]\n\
         max_iterations = [100, 40, 10]\nscheme = [\"midpoint\", \"rk4\", \"rk4\"]\n\
         vertices = [500, 2000]\ncoarse_targets = false\n"
    );
    let tables = format!(
        "{base}[[stage]]\nkernel_geom = \"gaussian:0.4\"\nmax_iterations = 100\nscheme = \"midpoint\"\n\
         vertices = 500\ncoarse_target = false\n\n\
         [[stage]]\nkernel_geom = \"gaussian:0.2\"\nvertices = 2000\n\n\
         [[stage]]\nkernel_geom = \"gaussian:0.1\"\nmax_iterations = 10\n"
    );
    let (a, t) = (Config::parse(&arrays).unwrap(), Config::parse(&tables).unwrap());
    assert_eq!(stages(&t), stages(&a));
    assert_eq!((t.stage_count(), a.stage_count()), (3, 3));
    assert_eq!(stages(&t)[1], ("gaussian:0.2".into(), (Integrator::Rk4, 10), 40, (1e-6, 7), Some(2000), false));
    // Written and read back as tables.
    let text = t.to_toml();
    assert!(text.contains("[[stage]]"), "{text}");
    assert_eq!(Config::parse(&text).unwrap(), t);
    // What tables could say wrongly is refused, naming the stage.
    let stage = |body: &str| format!("{base}{body}");
    let last = "[[stage]]\nkernel_geom = \"gaussian:0.1\"\n";
    for (text, says) in [
        (format!("{arrays}{last}"), "the schedule is given twice"),
        (
            stage(&format!("[[stage]]\nkernel_geom = \"gaussian:0.4\"\n{last}vertices = 900\n")),
            "stage[1].vertices: the last stage runs on the source",
        ),
        (
            stage(&format!(
                "[[stage]]\nkernel_geom = \"gaussian:0.4\"\nvertices = 500\n[[stage]]\nkernel_geom = \"gaussian:0.2\"\n{last}"
            )),
            "stage[1].vertices: every stage before the last",
        ),
        (
            stage(&format!(
                "[[stage]]\nkernel_geom = \"gaussian:0.4\"\nvertices = 500\ncoarse_target = true\n[[stage]]\nkernel_geom = \"gaussian:0.2\"\nvertices = 900\ncoarse_target = false\n{last}"
            )),
            "stage[1].coarse_target: must be the same",
        ),
        (
            stage(&format!("[[stage]]\nkernel_geom = \"gaussian:0.4\"\ncoarse_target = true\n{last}")),
            "stage[0].coarse_target: needs vertices",
        ),
        (
            stage(&format!("[[stage]]\nkernel_geom = \"gaussian:0.4\"\nsteps = 0\n{last}")),
            "stage[0].steps: must be at least 1",
        ),
        (
            stage(&format!("[[stage]]\nkernel_geom = \"gaussian:0.4\"\n{last}scheme = \"euler\"\n")),
            "stage[1]: the last stage must use",
        ),
        (
            stage(&format!("[[stage]]\nkernel_geom = \"gaussian:0.4\"\ndecrease_tolerance = -1\n{last}")),
            "stage[0].decrease_tolerance",
        ),
    ] {
        let e = Config::parse(&text).and_then(|c| c.schedule()).unwrap_err().to_string();
        assert!(e.contains(says), "{says}: {e}");
    }
    let e = Config::parse(&stage(&format!("{last}[[stage]]\nkernel_geom = \"gaussian:0.1\"\nmax_iteration = 3\n")))
        .unwrap_err();
    assert!(e.to_string().contains("stage") && e.to_string().contains("max_iteration"), "{e}");
}
