//! The session: stages in order, an observer that sees and stops, resume
//! to the same bits, and checkpoints checked before use.

use fshape_match::{
    CHECKPOINT_FORMAT, Checkpoint, Config, Control, Iteration, MatchError, Observer, Observers, Outcome, Session,
    StageRecord, StageSpec, StopAfter,
};
use fshape_mesh::FShape;
use fshape_mesh::test_support::perturbed_icosphere;

fn inputs() -> (FShape, FShape, Config) {
    let source = perturbed_icosphere(1, 0.0, 1);
    let n = source.n_vertices();
    let source = source.with_signal(Some(vec![0.0; n])).unwrap();
    let target = perturbed_icosphere(1, 0.08, 2);
    let signal: Vec<f64> = target.points().chunks_exact(3).map(|p| 0.5 * p[0]).collect();
    let target = target.with_signal(Some(signal)).unwrap();
    let mut config = Config::parse(
        "[model]\ngamma_w = 10.0\ngamma_f = 1.0\n[deformation]\nwidths = [0.5]\n\
         [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:1.0\"\n\
         [schedule]\nkernel_geom = [\"gaussian:0.6\", \"gaussian:0.3\"]\n",
    )
    .unwrap();
    config.integrator.steps = 5;
    config.optimizer.max_iterations = 6;
    (source, target, config)
}

/// Records every event; stops after `stop_after` iterations.
#[derive(Default)]
struct Recorder {
    events: Vec<String>,
    iterations: Vec<Iteration>,
    stop_after: Option<usize>,
}

impl Observer for Recorder {
    fn stage_started(&mut self, stage: usize, stages: usize, spec: &StageSpec, done: usize) -> Control {
        self.events.push(format!("start {stage}/{stages} {} {done}", spec.label));
        Control::Continue
    }
    fn iteration(&mut self, stage: usize, record: &Iteration) -> Control {
        self.events.push(format!("iteration {stage} {}", record.iteration));
        self.iterations.push(record.clone());
        match self.stop_after {
            Some(n) if self.iterations.len() >= n => Control::Stop,
            _ => Control::Continue,
        }
    }
    fn stage_finished(&mut self, stage: usize, record: &StageRecord) {
        self.events.push(format!("finish {stage} {:?}", record.stop));
    }
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn stages_run_in_order_and_the_observer_sees_each_iteration() {
    let (source, target, config) = inputs();
    let mut session = Session::new(&source, &target, &config).unwrap();
    let mut rec = Recorder::default();
    assert!(matches!(session.result(), Err(MatchError::NotFinished)));
    assert_eq!(session.run(&mut rec).unwrap(), Outcome::Finished);
    let result = session.result().unwrap();
    assert_eq!(result.stages.len(), 2);
    assert_eq!(rec.events[0], "start 0/2 gaussian:0.6 0");
    assert!(rec.events.iter().any(|e| e == "start 1/2 gaussian:0.3 0"));
    assert_eq!(rec.iterations.len(), result.iterations);
    // Each stage's records are the observer's, in order.
    let recorded: Vec<&Iteration> = result.stages.iter().flat_map(|s| &s.iterations).collect();
    assert!(recorded.iter().zip(&rec.iterations).all(|(a, b)| *a == b));
    // The second stage starts where the first ended, and the fit improves.
    assert!(
        result.energies.attachment < 0.5 * result.stages[1].initial.attachment.max(result.stages[0].initial.attachment)
    );
    assert_eq!(result.energies.value.to_bits(), result.stages[1].iterations.last().unwrap().value.to_bits());
}

#[test]
fn observers_compose_each_told_every_event_and_any_may_stop_the_run() {
    let (source, target, config) = inputs();
    // Two recorders and a budget of four iterations: both recorders see
    // the same four, and the run stops there, as with one observer.
    let mut whole = Session::new(&source, &target, &config).unwrap();
    let (mut first, mut second, mut budget) = (Recorder::default(), Recorder::default(), StopAfter(Some(4)));
    let mut observers = Observers::new().with(&mut first).with(&mut budget).with(&mut second);
    assert_eq!(whole.run(&mut observers).unwrap(), Outcome::Interrupted);
    drop(observers);
    assert_eq!(first.iterations.len(), 4);
    assert_eq!(first.events, second.events, "each told every event, the one that stopped too");
    let mut alone = Recorder { stop_after: Some(4), ..Recorder::default() };
    Session::new(&source, &target, &config).unwrap().run(&mut alone).unwrap();
    assert_eq!(alone.events, first.events);
    // A budget of none never stops; of 0, at the first stage.
    let mut zero = StopAfter(Some(0));
    assert_eq!(Session::new(&source, &target, &config).unwrap().run(&mut zero).unwrap(), Outcome::Interrupted);
    let mut none = StopAfter(None);
    assert_eq!(Session::new(&source, &target, &config).unwrap().run(&mut none).unwrap(), Outcome::Finished);
}

#[test]
fn a_stopped_session_resumes_to_the_same_bits() {
    let (source, target, config) = inputs();
    let mut whole = Session::new(&source, &target, &config).unwrap();
    whole.run(&mut ()).unwrap();
    let expected = whole.result().unwrap();
    for stop_after in [1, 6, 8] {
        let dir = std::env::temp_dir().join(format!("fshape-match-resume-{}-{stop_after}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("checkpoint.bin");
        let mut first = Session::new(&source, &target, &config).unwrap().with_checkpoint_file(&file);
        let mut rec = Recorder { stop_after: Some(stop_after), ..Recorder::default() };
        assert_eq!(first.run(&mut rec).unwrap(), Outcome::Interrupted);
        // A new session (a new process, in practice) from the file.
        let mut second = Session::new(&source, &target, &config).unwrap().resume_from_file(&file).unwrap();
        assert_eq!(second.run(&mut ()).unwrap(), Outcome::Finished);
        let got = second.result().unwrap();
        assert_eq!(bits(&got.p0), bits(&expected.p0), "stopped after {stop_after}");
        assert_eq!(bits(&got.pf), bits(&expected.pf));
        assert_eq!(got.stages, expected.stages);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

/// A checkpoint after three iterations, and the session it belongs to.
fn checkpoint_after_three() -> (Checkpoint, impl Fn() -> Session) {
    let (source, target, config) = inputs();
    let mut session = Session::new(&source, &target, &config).unwrap();
    session.run(&mut Recorder { stop_after: Some(3), ..Recorder::default() }).unwrap();
    let ck = session.checkpoint().clone();
    (ck, move || Session::new(&source, &target, &config).unwrap())
}

#[test]
fn a_damaged_or_foreign_checkpoint_is_refused_with_what_is_wrong() {
    let (good, fresh) = checkpoint_after_three();
    assert!(good.current.is_some());
    fresh().resume(good.clone()).unwrap();
    let n = good.current.as_ref().unwrap().state.x.len();
    type Damage = fn(&mut Checkpoint);
    let cases: [(Damage, &str); 9] = [
        (|c| c.current.as_mut().unwrap().state.x.truncate(5), "current.state.x has 5 values"),
        (|c| c.current.as_mut().unwrap().state.grad.pop().map(drop).unwrap_or(()), "current.state.grad has"),
        (|c| c.current.as_mut().unwrap().state.s[0].truncate(1), "current.state.s[0] has 1 values"),
        (|c| drop(c.current.as_mut().unwrap().state.y.pop_back()), "steps s but"),
        (|c| c.current.as_mut().unwrap().state.x[7] = f64::NAN, "current.state.x[7] is not finite"),
        (|c| c.current.as_mut().unwrap().state.value = f64::INFINITY, "current.state.value"),
        (|c| c.fingerprint = "0123456789abcdef".into(), "written for other inputs"),
        (|c| c.format = CHECKPOINT_FORMAT + 1, "format"),
        (|c| c.warm = Some(vec![0.0; 3]), "warm has 3 values"),
    ];
    for (damage, needle) in cases {
        let mut bad = good.clone();
        damage(&mut bad);
        let e = match fresh().resume(bad) {
            Ok(_) => panic!("{needle}: accepted"),
            Err(e) => e,
        };
        assert!(matches!(e, MatchError::Checkpoint { .. }), "{e}");
        assert!(e.to_string().contains(needle), "{needle}: {e}");
    }
    assert!(n > 5);
}

#[test]
fn a_checkpoint_file_cut_short_or_with_short_arrays_names_the_file() {
    let (good, fresh) = checkpoint_after_three();
    let dir = std::env::temp_dir().join(format!("fshape-match-damaged-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("checkpoint.bin");
    // Truncated bytes, another file, an earlier format: each said as it is.
    let bytes = good.to_bytes().unwrap();
    for (contents, says) in [
        (bytes[..bytes.len() / 2].to_vec(), "damaged or truncated (its checksum does not match"),
        (bytes[..18].to_vec(), "before its format number"),
        (b"ply\nformat ascii 1.0\n".to_vec(), "not an fshape checkpoint"),
        (serde_json::to_vec(&serde_json::json!({"format": 2})).unwrap(), "JSON checkpoint of an earlier version"),
    ] {
        std::fs::write(&file, contents).unwrap();
        let e = fresh().resume_from_file(&file).err().expect("refused").to_string();
        assert!(e.contains(&file.display().to_string()) && e.contains(says), "{says}: {e}");
    }
    // A later format, its checksum intact.
    let mut other = bytes[..bytes.len() - 4].to_vec();
    other[16] = 9;
    other.extend(crc32fast::hash(&other).to_le_bytes());
    std::fs::write(&file, other).unwrap();
    let e = fresh().resume_from_file(&file).err().expect("refused").to_string();
    assert!(e.contains("format 9"), "{e}");
    // A well-formed checkpoint whose arrays were cut short.
    let mut short = good.clone();
    short.current.as_mut().unwrap().state.x.truncate(10);
    std::fs::write(&file, short.to_bytes().unwrap()).unwrap();
    let e = fresh().resume_from_file(&file).err().expect("refused").to_string();
    assert!(e.contains(&file.display().to_string()) && e.contains("current.state.x has 10 values"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn source_and_target_of_different_kinds_are_refused() {
    let (source, _, config) = inputs();
    let curve = fshape_mesh::generate::circle(20, 1.0);
    let e = Session::new(&source, &curve, &config).err().expect("refused");
    assert!(matches!(e, MatchError::Kinds(_)), "{e}");
}

#[test]
fn a_serial_session_gives_the_bits_of_a_parallel_one() {
    let (source, target, mut config) = inputs();
    config.optimizer.max_iterations = 3;
    let mut results = Vec::new();
    for parallel in [true, false] {
        let mut s = Session::new(&source, &target, &config).unwrap().with_parallel(parallel);
        s.run(&mut ()).unwrap();
        results.push(s.result().unwrap());
    }
    assert_eq!(bits(&results[0].p0), bits(&results[1].p0));
    assert_eq!(bits(&results[0].pf), bits(&results[1].pf));
    assert_eq!(results[0].stages, results[1].stages);
}

/// The inputs with lengths times `l` and signals times `s`, and every
/// width (deformation, k_p, k_f) scaled to match.
fn scaled_inputs(l: f64, s: f64) -> (FShape, FShape, Config) {
    let (source, target, mut config) = inputs();
    let scale = |shape: FShape| {
        let pts: Vec<f64> = shape.points().iter().map(|v| v * l).collect();
        let f: Vec<f64> = shape.signal().unwrap().iter().map(|v| v * s).collect();
        shape.with_points(pts).unwrap().with_signal(Some(f)).unwrap()
    };
    config.deformation.widths = config.deformation.widths.iter().map(|w| w * l).collect();
    let a = config.attachment.as_mut().unwrap();
    a.kernel_geom = fshape_match::PositionKernel::parse(&format!("gaussian:{}", 0.3 * l)).unwrap();
    a.kernel_signal = Some(fshape_match::SignalKernelSpec::parse(&format!("gaussian:{s}")).unwrap());
    config.schedule = Some(fshape_match::ScheduleSection::new(
        [0.6, 0.3].map(|w| fshape_match::PositionKernel::parse(&format!("gaussian:{}", w * l)).unwrap()).to_vec(),
    ));
    (scale(source), scale(target), config)
}

#[test]
fn normalised_weights_give_the_same_registration_at_any_scale() {
    // The default model and metrics, p_0 in its L² metric, and the
    // tangential model (whose signal control is a function, not a density).
    type Variant = fn(&mut Config);
    let variants: [(&str, Variant); 3] = [
        ("default", |_| {}),
        ("momentum l2", |c| c.optimizer.momentum_metric = fshape_match::Metric::L2),
        ("tangential", |c| c.model.kind = fshape_shoot::ModelKind::Tangential),
    ];
    for (name, variant) in variants {
        let run = |l: f64, s: f64, normalize: bool| {
            let (source, target, mut config) = scaled_inputs(l, s);
            config.model.normalize = normalize;
            variant(&mut config);
            let mut session = Session::new(&source, &target, &config).unwrap();
            session.run(&mut ()).unwrap();
            session.result().unwrap()
        };
        let unit = run(1.0, 1.0, true);
        // Powers of two: the scaled computations round alike, so the runs
        // take the same steps.
        for (l, s) in [(8.0, 0.25), (0.125, 16.0)] {
            let other = run(l, s, true);
            let values = |r: &fshape_match::MatchResult| -> Vec<f64> {
                r.stages
                    .iter()
                    .flat_map(|st| std::iter::once(&st.initial).chain(&st.iterations))
                    .map(|i| i.value)
                    .collect()
            };
            let (a, b) = (values(&unit), values(&other));
            assert_eq!(a.len(), b.len(), "{name}, L = {l}, S = {s}: the same number of iterations");
            for (u, v) in a.iter().zip(&b) {
                assert!((u - v).abs() <= 1e-9 * u.abs(), "{name}, L = {l}, S = {s}: J {u} against {v}");
            }
            let (qa, qb) = (&unit.quality, &other.quality);
            assert!((qa.mean_distance - qb.mean_distance).abs() < 1e-9, "{name}");
            assert!((qa.signal_rms.unwrap() - qb.signal_rms.unwrap()).abs() < 1e-9, "{name}");
            // Without normalisation the same weights fit differently.
            let absolute = run(l, s, false);
            assert!((absolute.quality.mean_distance - qa.mean_distance).abs() > 1e-3 * qa.mean_distance, "{name}, {l}");
        }
    }
}

#[test]
fn the_scales_are_the_targets_diagonal_and_signal_deviation() {
    let (source, target, config) = inputs();
    let session = Session::new(&source, &target, &config).unwrap();
    let s = session.plan().scales.clone().expect("normalised by default");
    assert_eq!(s.length, target.bounding_box().diagonal());
    let f = target.signal().unwrap();
    let mean = f.iter().sum::<f64>() / f.len() as f64;
    let sd = (f.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / f.len() as f64).sqrt();
    assert!((s.signal - sd).abs() < 1e-15 && s.cell_dim == 2);
    let m = &session.plan().model;
    let (l, gw) = (s.length, config.model.gamma_w);
    assert!((m.gamma_w() - gw / l.powi(4)).abs() < 1e-12 * m.gamma_w());
    assert!((m.gamma_v() - config.model.gamma_v / (l * l)).abs() < 1e-15);
    assert!((m.gamma_f() - config.model.gamma_f / (sd * sd * l * l)).abs() < 1e-12 * m.gamma_f());
}

#[test]
fn the_signal_scale_skips_masked_and_missing_vertices_and_weighs_the_rest() {
    // The first ten target vertices are masked out with no value (NaN),
    // the next ten half in: S is the mask-weighted deviation of the rest.
    let (source, target, _) = inputs();
    let n = target.n_vertices();
    let mut f = target.signal().unwrap().to_vec();
    let mask: Vec<f64> = (0..n)
        .map(|v| {
            if v < 10 {
                0.0
            } else if v < 20 {
                0.5
            } else {
                1.0
            }
        })
        .collect();
    f[..10].fill(f64::NAN);
    let masked = target.clone().with_signal_and_mask(Some(f.clone()), Some(mask.clone())).unwrap();
    let s = fshape_match::Scales::of(&source, &masked).unwrap();
    let total: f64 = mask.iter().sum();
    let mean = f.iter().zip(&mask).skip(10).map(|(x, w)| w * x).sum::<f64>() / total;
    let sd = (f.iter().zip(&mask).skip(10).map(|(x, w)| w * (x - mean).powi(2)).sum::<f64>() / total).sqrt();
    assert!((s.signal - sd).abs() < 1e-14 * sd, "{} against {sd}", s.signal);
    // Unmasked, the plain deviation, to the bit.
    let plain = fshape_match::Scales::of(&source, &target).unwrap();
    let g = target.signal().unwrap();
    let mean = g.iter().sum::<f64>() / n as f64;
    let sd = (g.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    assert_eq!(plain.signal, sd);
}

#[test]
fn coarse_stages_may_shoot_with_a_cheaper_integrator_and_the_last_is_the_model() {
    let (source, target, mut config) = inputs();
    let mut schedule = config.schedule.clone().unwrap();
    schedule.scheme = Some(vec![fshape_shoot::Integrator::Euler, fshape_shoot::Integrator::Rk4]);
    schedule.steps = Some(vec![2, 5]);
    config.schedule = Some(schedule.clone());
    let mut session = Session::new(&source, &target, &config).unwrap();
    let stages = &session.plan().stages;
    assert_eq!(
        (stages[0].integrator, stages[1].integrator),
        ((fshape_shoot::Integrator::Euler, 2), (fshape_shoot::Integrator::Rk4, 5))
    );
    session.run(&mut ()).unwrap();
    let r = session.result().unwrap();
    // The result is shot with the model asked for (RK4, 5 steps), and the
    // last stage's iterations are that model's J.
    assert_eq!(r.trajectory.steps(), 5);
    assert_eq!(r.energies.value.to_bits(), r.stages[1].iterations.last().unwrap().value.to_bits());
    // A coarse first stage is a different optimisation from the plain one.
    let mut plain = Session::new(&source, &target, &inputs().2).unwrap();
    plain.run(&mut ()).unwrap();
    assert_ne!(plain.result().unwrap().stages[0].iterations, r.stages[0].iterations);
    // Lists of the wrong length, or a last stage other than [integrator],
    // are refused by name.
    for (scheme, steps, key) in [
        (Some(vec![fshape_shoot::Integrator::Euler]), None, "schedule.scheme"),
        (None, Some(vec![2, 5, 5]), "schedule.steps"),
        (None, Some(vec![2, 4]), "last stage"),
        (None, Some(vec![0, 5]), "schedule.steps[0]"),
    ] {
        let mut c = config.clone();
        c.schedule = Some(fshape_match::ScheduleSection { scheme, steps, ..schedule.clone() });
        let e = Session::new(&source, &target, &c).err().expect("refused").to_string();
        assert!(e.contains(key), "{key}: {e}");
    }
}

/// The unit icosphere of `level` with signal 0 (a template).
fn sphere(level: u32) -> FShape {
    let s = fshape_mesh::generate::icosphere(level, 1.0);
    let n = s.n_vertices();
    s.with_signal(Some(vec![0.0; n])).unwrap()
}

#[test]
fn coarse_stages_on_coarser_templates_carry_their_momenta_to_the_fine_one() {
    let (_, target, mut config) = inputs();
    let source = sphere(3);
    let mut schedule = config.schedule.clone().unwrap();
    schedule.kernel_geom.insert(0, fshape_match::PositionKernel::parse("gaussian:0.8").unwrap());
    config.schedule = Some(schedule);
    let templates = vec![Some(sphere(1)), Some(sphere(2)), None];
    let session = || Session::new(&source, &target, &config).unwrap().with_stage_templates(templates.clone()).unwrap();
    let mut whole = session();
    let mut rec = Recorder::default();
    whole.run(&mut rec).unwrap();
    let r = whole.result().unwrap();
    assert_eq!(r.p0.len(), 3 * source.n_vertices());
    assert!(r.quality.mean_distance < 0.5 * r.initial_quality.mean_distance, "{:?}", r.quality);
    // Each stage starts where the last ended: the data term of stage 0's
    // result on its coarse template, with stage 1's kernel, is what stage 1
    // starts from on the finer template after the transfer.
    let mut coarse_run = session();
    coarse_run.run(&mut Recorder { stop_after: Some(r.stages[0].iterations.len()), ..Recorder::default() }).unwrap();
    let x0 = coarse_run.checkpoint().current.as_ref().unwrap().state.x.clone();
    let plan = whole.plan();
    let coarse = fshape_shoot::Problem::new(&sphere(1), plan.model.clone())
        .unwrap()
        .with_target(&target, plan.stages[1].kernel.clone())
        .unwrap();
    let unknowns = fshape_match::unknowns::Unknowns::scaled(&coarse, plan.metrics, plan.scales.as_ref()).unwrap();
    let (p0, pf) = unknowns.unpack(&x0);
    let on_coarse = coarse.objective(&p0, &pf).unwrap().0.attachment;
    let n = sphere(2).n_vertices();
    let at_rest = fshape_shoot::Problem::new(&sphere(2), plan.model.clone())
        .unwrap()
        .with_target(&target, plan.stages[1].kernel.clone())
        .unwrap()
        .objective(&vec![0.0; 3 * n], &vec![0.0; n])
        .unwrap()
        .0
        .attachment;
    let start1 = r.stages[1].initial.attachment;
    eprintln!(
        "stage 1 starts at A = {start1:.4} on the finer template, {on_coarse:.4} on the coarse one, {at_rest:.4} at rest"
    );
    assert!(
        (start1 - on_coarse).abs() < 0.25 * on_coarse && start1 < at_rest,
        "{start1} against {on_coarse} ({at_rest} at rest)"
    );
    // Stopped on the coarse template, resumed from the file: the same bits.
    let dir = std::env::temp_dir().join(format!("fshape-match-multires-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("checkpoint.bin");
    let mut first = session().with_checkpoint_file(&file);
    first.run(&mut Recorder { stop_after: Some(3), ..Recorder::default() }).unwrap();
    let x = first.checkpoint().current.as_ref().unwrap().state.x.len();
    assert_eq!(x, 4 * sphere(1).n_vertices(), "stage 0 runs on the level-1 sphere");
    let mut second = session().resume_from_file(&file).unwrap();
    second.run(&mut ()).unwrap();
    let again = second.result().unwrap();
    assert_eq!(bits(&again.p0), bits(&r.p0));
    assert_eq!(again.stages, r.stages);
    // Without the templates, the checkpoint is another problem's.
    let e =
        Session::new(&source, &target, &config).unwrap().resume_from_file(&file).err().expect("refused").to_string();
    assert!(e.contains("other inputs"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
    // The last stage runs on the source.
    let bad = Session::new(&source, &target, &config).unwrap().with_stage_templates(vec![None, None, Some(sphere(2))]);
    assert!(bad.is_err());
}

#[test]
fn each_stage_may_have_its_own_iteration_limit_and_decrease_test() {
    let (source, target, mut config) = inputs();
    let mut schedule = config.schedule.clone().unwrap();
    schedule.max_iterations = Some(vec![2, 4]);
    config.schedule = Some(schedule.clone());
    let mut session = Session::new(&source, &target, &config).unwrap();
    session.run(&mut ()).unwrap();
    let r = session.result().unwrap();
    // The plain run (6 per stage) reaches its cap in both stages, so these
    // reach theirs.
    assert_eq!((r.stages[0].iterations.len(), r.stages[1].iterations.len()), (2, 4));
    schedule.max_iterations = Some(vec![2]);
    config.schedule = Some(schedule.clone());
    let e = Session::new(&source, &target, &config).err().expect("refused").to_string();
    assert!(e.contains("schedule.max_iterations"), "{e}");
    // A decrease test per stage: J can never fall by more than all of it,
    // so a tolerance of 1 over a window of 1 ends the first stage after one
    // iteration, on that test; the second keeps [optimizer]'s (and its cap).
    schedule.max_iterations = None;
    schedule.decrease_tolerance = Some(vec![1.0, config.optimizer.decrease_tolerance]);
    schedule.decrease_window = Some(vec![1, config.optimizer.decrease_window]);
    config.schedule = Some(schedule.clone());
    let mut session = Session::new(&source, &target, &config).unwrap();
    session.run(&mut ()).unwrap();
    let r = session.result().unwrap();
    assert_eq!((r.stages[0].stop, r.stages[0].iterations.len()), (fshape_match::optimize::Stop::Decrease, 1));
    assert_eq!((r.stages[1].stop, r.stages[1].iterations.len()), (fshape_match::optimize::Stop::Iterations, 6));
    schedule.decrease_tolerance = Some(vec![f64::NAN, 1.0]);
    config.schedule = Some(schedule);
    let e = Session::new(&source, &target, &config).err().expect("refused").to_string();
    assert!(e.contains("schedule.decrease_tolerance[0]"), "{e}");
}

/// Stops when stage `at` starts.
struct StopAtStage(usize);

impl Observer for StopAtStage {
    fn stage_started(&mut self, stage: usize, _: usize, _: &StageSpec, _: usize) -> Control {
        if stage == self.0 { Control::Stop } else { Control::Continue }
    }
}

#[test]
fn stages_on_equal_templates_share_them_without_a_transfer() {
    let (_, target, mut config) = inputs();
    let mut schedule = config.schedule.clone().unwrap();
    schedule.kernel_geom.insert(0, fshape_match::PositionKernel::parse("gaussian:0.8").unwrap());
    config.schedule = Some(schedule);
    // Two equal coarse templates (separate values), then the source.
    let mut session = Session::new(&sphere(2), &target, &config)
        .unwrap()
        .with_stage_templates(vec![Some(sphere(1)), Some(sphere(1)), None])
        .unwrap();
    assert_eq!(session.run(&mut StopAtStage(1)).unwrap(), Outcome::Interrupted);
    let ck = session.checkpoint();
    // Stage 1 starts from stage 0's unknowns as they are.
    assert_eq!(bits(&ck.current.as_ref().unwrap().state.x), bits(ck.warm.as_ref().unwrap()));
}

/// A 642-vertex source and target and a three-stage schedule.
fn fine_inputs(vertices: &str) -> (FShape, FShape, Config) {
    let source = perturbed_icosphere(3, 0.02, 4);
    let signal: Vec<f64> = source.points().chunks_exact(3).map(|p| 0.3 * p[2]).collect();
    let source = source.with_signal(Some(signal)).unwrap();
    let target = perturbed_icosphere(3, 0.08, 5);
    let signal: Vec<f64> = target.points().chunks_exact(3).map(|p| 0.5 * p[0]).collect();
    let target = target.with_signal(Some(signal)).unwrap();
    let mut config = Config::parse(&format!(
        "[model]\ngamma_w = 10.0\ngamma_f = 1.0\n[deformation]\nwidths = [0.5]\n\
         [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:1.0\"\n\
         [schedule]\nkernel_geom = [\"gaussian:0.6\", \"gaussian:0.3\", \"gaussian:0.3\"]\n{vertices}\n"
    ))
    .unwrap();
    config.integrator.steps = 4;
    config.optimizer.max_iterations = 4;
    (source, target, config)
}

#[test]
fn stages_from_vertex_counts_run_on_simplified_templates_and_targets() {
    let (source, target, config) = fine_inputs("vertices = [60, 200]");
    let mut session = Session::new(&source, &target, &config).unwrap();
    session.run(&mut ()).unwrap();
    let result = session.result().unwrap();
    let sizes: Vec<(usize, usize)> =
        result.stages.iter().map(|s| (s.setup.template_vertices, s.setup.target_vertices)).collect();
    assert_eq!(sizes, [(60, 60), (200, 200), (642, 642)]);
    assert!(result.stages.iter().all(|s| s.setup.deformation == "exact" && s.setup.attachment == "exact"));
    assert!(result.energies.attachment < result.stages[0].initial.attachment);
    // Without coarse targets, the counts are the hand-made templates
    // `FShape::simplified` gives, to the bit.
    let (_, _, auto) = fine_inputs("vertices = [60, 200]\ncoarse_targets = false");
    let mut a = Session::new(&source, &target, &auto).unwrap();
    a.run(&mut ()).unwrap();
    let (_, _, plain) = fine_inputs("");
    let templates = vec![Some(source.simplified(60).unwrap().shape), Some(source.simplified(200).unwrap().shape), None];
    let mut b = Session::new(&source, &target, &plain).unwrap().with_stage_templates(templates).unwrap();
    b.run(&mut ()).unwrap();
    let (ra, rb) = (a.result().unwrap(), b.result().unwrap());
    assert_eq!(bits(&ra.p0), bits(&rb.p0));
    assert_eq!(ra.stages[1].setup.target_vertices, 642);
    // Both at once is an error.
    let twice = Session::new(&source, &target, &auto).unwrap().with_stage_templates(vec![None, None, None]);
    assert!(matches!(twice, Err(MatchError::StageTemplatesTwice)));
}

#[test]
fn vertex_counts_are_checked_with_their_key() {
    let (source, target, _) = fine_inputs("");
    for (lines, key) in [
        ("vertices = [60]", "schedule.vertices"),
        ("vertices = [60, 200, 300]", "schedule.vertices"),
        ("vertices = [60, 3]", "schedule.vertices[1]"),
        ("coarse_targets = false", "schedule.coarse_targets"),
    ] {
        let (_, _, config) = fine_inputs(lines);
        match Session::new(&source, &target, &config) {
            Err(MatchError::Config { key: k, .. }) => assert_eq!(k, key, "{lines}"),
            other => panic!("{lines}: {:?}", other.map(|_| ())),
        }
    }
}

#[test]
fn a_stopped_run_gives_its_result_so_far_on_the_source_and_then_goes_on_unchanged() {
    let (source, target, config) = fine_inputs("vertices = [60, 200]");
    let mut whole = Session::new(&source, &target, &config).unwrap();
    whole.run(&mut ()).unwrap();
    let whole = whole.result().unwrap();
    assert!(whole.finished);
    let mut session = Session::new(&source, &target, &config).unwrap();
    assert!(session.result_so_far().unwrap().is_none(), "nothing before the first iteration");
    // Stopped in the first stage, on the 60-vertex template.
    let mut stop = Recorder { stop_after: Some(3), ..Recorder::default() };
    assert_eq!(session.run(&mut stop).unwrap(), Outcome::Interrupted);
    let so_far = session.result_so_far().unwrap().expect("three iterations");
    assert!(!so_far.finished);
    assert_eq!((so_far.iterations, so_far.p0.len(), so_far.pf.len()), (3, 642 * 3, 642));
    assert!(so_far.stages.is_empty(), "no stage finished");
    assert!(so_far.energies.value.is_finite() && so_far.quality.signal_rms.is_some());
    assert!(matches!(session.result(), Err(MatchError::NotFinished)));
    // The session goes on to the bits of a run never stopped.
    assert_eq!(session.run(&mut ()).unwrap(), Outcome::Finished);
    let end = session.result_so_far().unwrap().unwrap();
    assert!(end.finished);
    assert_eq!((bits(&end.p0), bits(&end.pf)), (bits(&whole.p0), bits(&whole.pf)));
    assert_eq!(end.iterations, whole.iterations);
    // Stopped in the last stage, on the source: the result is the point the
    // optimiser holds, J as the observer saw it at the last iteration.
    let mut late = Session::new(&source, &target, &config).unwrap();
    let mut stop = Recorder { stop_after: Some(whole.iterations - 1), ..Recorder::default() };
    assert_eq!(late.run(&mut stop).unwrap(), Outcome::Interrupted);
    let so_far = late.result_so_far().unwrap().unwrap();
    assert_eq!(so_far.stages.len(), 2);
    assert_eq!(so_far.energies.value.to_bits(), stop.iterations.last().unwrap().value.to_bits());
}

#[test]
fn a_flipped_byte_anywhere_or_a_cut_anywhere_is_refused_as_damaged() {
    let (good, _) = checkpoint_after_three();
    let bytes = good.to_bytes().unwrap();
    assert!(bytes.len() > 1000, "a checkpoint with its L-BFGS pairs: {} bytes", bytes.len());
    for k in 0..bytes.len() {
        for flip in [0x01, 0x80] {
            let mut bad = bytes.clone();
            bad[k] ^= flip;
            let e = match Checkpoint::from_bytes(&bad) {
                Ok(_) => panic!("byte {k} ^ {flip:#x}: accepted"),
                Err(e) => e.to_string(),
            };
            assert!(e.contains("damaged") && e.contains("without --resume"), "byte {k} ^ {flip:#x}: {e}");
        }
    }
    for len in 0..bytes.len() {
        let e = match Checkpoint::from_bytes(&bytes[..len]) {
            Ok(_) => panic!("cut to {len} bytes: accepted"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains("damaged or truncated"), "cut to {len} bytes: {e}");
    }
}

#[test]
fn a_format_3_checkpoint_without_checksum_is_read_and_continues_as_format_4() {
    let (good, fresh) = checkpoint_after_three();
    let mut old = good.clone();
    old.format = fshape_match::UNCHECKED_FORMAT;
    // Format 3 is format 4 without the trailing checksum.
    let v4 = old.to_bytes().unwrap();
    let v3 = &v4[..v4.len() - 4];
    let read = Checkpoint::from_bytes(v3).unwrap();
    assert_eq!(read.format, 3);
    assert_eq!(read.current.as_ref().unwrap().state.x, good.current.as_ref().unwrap().state.x);
    let session = fresh().resume(read).unwrap();
    assert_eq!(session.checkpoint().format, CHECKPOINT_FORMAT);
    // With its checksum, a format-3 header is damage (the format says no checksum).
    assert!(Checkpoint::from_bytes(&v4).unwrap_err().to_string().contains("4 bytes follow its end"));
    // The header alone tells the format, for the program's warning before it resumes.
    let file = std::env::temp_dir().join(format!("fshape-format-{}.bin", std::process::id()));
    for (bytes, format) in
        [(v3.to_vec(), Some(3)), (good.to_bytes().unwrap(), Some(CHECKPOINT_FORMAT)), (b"ply\n".to_vec(), None)]
    {
        std::fs::write(&file, bytes).unwrap();
        assert_eq!(Checkpoint::file_format(&file), format);
    }
    std::fs::remove_file(&file).unwrap();
}
