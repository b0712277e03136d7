//! Registration with several signal channels: a pair whose first channel
//! changes in one place and whose second changes in another is matched,
//! and each channel's change is found where it is and nowhere else.

use fshape_match::Metric;
use fshape_match::optimize::{Method, Settings};
use fshape_match::session::minimize;
use fshape_mesh::FShape;
use fshape_mesh::generate::icosphere;
use fshape_shoot::Problem;
use fshape_varifold::{GrassKernel, SignalKernel, VarifoldKernel};

use crate::model;

/// A bump of height 1 and width 0.25 around `c` on the unit sphere.
fn bump(p: &[f64], c: [f64; 3]) -> f64 {
    let d2: f64 = p.iter().zip(c).map(|(a, b)| (a - b) * (a - b)).sum();
    (-d2 / (2.0 * 0.25 * 0.25)).exp()
}

/// The largest of `err` (one per vertex of `sphere`) over the bump at `at`.
fn largest_near(sphere: &FShape, err: &[f64], at: [f64; 3]) -> f64 {
    sphere.points().chunks_exact(3).zip(err).filter(|(p, _)| bump(p, at) > 0.5).fold(0.0_f64, |m, (_, e)| m.max(*e))
}

/// Channel `c` of `s`'s signal.
fn channel(s: &FShape, c: usize) -> Vec<f64> {
    s.channel(c).expect("two channels")
}

#[test]
fn two_channels_changed_in_two_places_are_each_recovered_where_they_changed() {
    // The truth: nothing moves, each channel gains its bump.
    let sphere = icosphere(3, 1.0);
    let (north, east) = (NORTH, EAST);
    let (template, target) = two_bumps(&sphere);
    let m =
        model("kind = \"metamorphosis\"\nnorm = \"h1\"\nlength = 0.2\ngamma_f = 0.05\ngamma_w = 300.0", "", "rk4", 4);
    let kernel = VarifoldKernel::try_new(
        fshape_kernels::Kernel::gaussian(0.15).unwrap(),
        SignalKernel::Channels { sigmas: vec![0.5, 0.5] },
        GrassKernel::Binet,
    )
    .unwrap();
    let problem = Problem::new(&template, m).unwrap().with_target(&target, kernel).unwrap();
    let n = template.n_vertices();
    let settings = Settings {
        method: Method::Lbfgs { memory: 10 },
        max_iterations: 60,
        gradient_tolerance: 1e-6,
        ..Settings::default()
    };
    let (state, stop, unknowns) =
        minimize(&problem, Metric::L2, &vec![0.0; 3 * n], &vec![0.0; 2 * n], &settings, |_, _| {}).unwrap();
    let (p0, pf) = unknowns.unpack(&state.x);
    let traj = problem.shoot(&p0, &pf).unwrap();
    let end = template.clone().with_points(traj.points(traj.steps()).to_vec()).unwrap();
    let end = end.with_signals(Some(traj.signal(traj.steps()).to_vec()), 2).unwrap();
    // Per channel: the error everywhere, near the other channel's bump,
    // and at the start (the bump's height, 1).
    let moved = end.points().iter().zip(sphere.points()).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    let mut report = format!("{stop:?} after {} iterations; largest displacement {moved:.4}\n", state.iteration);
    for (c, (own, other)) in [(north, east), (east, north)].into_iter().enumerate() {
        let (got, want, start) = (channel(&end, c), channel(&target, c), channel(&template, c));
        let err: Vec<f64> = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).collect();
        let before = start.iter().zip(&want).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        let largest = err.iter().fold(0.0_f64, |m, e| m.max(*e));
        let mean = err.iter().sum::<f64>() / n as f64;
        let near = |at: [f64; 3]| largest_near(&sphere, &err, at);
        report += &format!(
            "channel {}: largest error {largest:.4} (from {before:.4}), mean {mean:.5}, at its bump {:.4}, at the other's {:.4}\n",
            c + 1,
            near(own),
            near(other)
        );
        assert!(before > 0.99, "{report}");
        assert!(largest < 0.02 && mean < 0.002, "{report}");
        assert!(near(other) < 0.005, "the other channel's change leaked into this one\n{report}");
    }
    assert!(moved < 0.02, "the geometry, unchanged, stays\n{report}");
    eprintln!("{report}");
}

/// The pair of these tests on `sphere`: the template carries 0.5 z
/// and 0.5 x; the target has the same geometry, a bump on channel 1 at
/// the north pole and one on channel 2 on the equator.
fn two_bumps(sphere: &FShape) -> (FShape, FShape) {
    let rows = |b: f64| -> Vec<f64> {
        sphere
            .points()
            .chunks_exact(3)
            .flat_map(|p| [0.5 * p[2] + b * bump(p, NORTH), 0.5 * p[0] + b * bump(p, EAST)])
            .collect()
    };
    (sphere.clone().with_signals(Some(rows(0.0)), 2).unwrap(), sphere.clone().with_signals(Some(rows(1.0)), 2).unwrap())
}

const NORTH: [f64; 3] = [0.0, 0.0, 1.0];
const EAST: [f64; 3] = [1.0, 0.0, 0.0];

#[test]
fn a_session_in_two_stages_recovers_each_channel_and_reports_each() {
    // The first test's pair through a Session: a coarse stage on a
    // simplified template (the momenta of both channels prolongated) and
    // the fine one, with the quality per channel.
    let sphere = icosphere(3, 1.0);
    let (template, target) = two_bumps(&sphere);
    let config = fshape_match::Config::parse(
        "[model]\nkind = \"metamorphosis\"\nnorm = \"h1\"\nlength = 0.2\ngamma_f = 0.05\ngamma_w = 300.0\n\
         normalize = false\n[deformation]\nwidths = [0.6, 0.3]\n\
         [attachment]\nkernel_geom = \"gaussian:0.15\"\nkernel_signal = \"gaussian:0.5,0.5\"\n\
         [schedule]\nkernel_geom = [\"gaussian:0.3\", \"gaussian:0.15\"]\nvertices = [162]\nmax_iterations = [30, 100]\n\
         [integrator]\nscheme = \"rk4\"\nsteps = 4\n",
    )
    .unwrap();
    let mut session = fshape_match::Session::new(&template, &target, &config).unwrap();
    session.run(&mut ()).unwrap();
    let r = session.result().unwrap();
    assert_eq!(r.stages.len(), 2);
    let steps = r.trajectory.steps();
    let end = sphere.clone().with_points(r.trajectory.points(steps).to_vec()).unwrap();
    let end = end.with_signals(Some(r.trajectory.signal(steps).to_vec()), 2).unwrap();
    let moved = end.points().iter().zip(sphere.points()).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    let mut report = format!("{} iterations; largest displacement {moved:.4}\n", r.iterations);
    let (before, after) = (&r.initial_quality, &r.quality);
    assert_eq!((before.channels.len(), after.channels.len()), (2, 2), "a quality per channel");
    for (c, (own, other)) in [(NORTH, EAST), (EAST, NORTH)].into_iter().enumerate() {
        let (got, want) = (channel(&end, c), channel(&target, c));
        let err: Vec<f64> = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).collect();
        let near = |at: [f64; 3]| largest_near(&sphere, &err, at);
        let (rms0, rms1) = (before.channels[c].signal_rms.unwrap(), after.channels[c].signal_rms.unwrap());
        report += &format!(
            "channel {}: signal rms {rms0:.4} -> {rms1:.5}; largest error {:.4}, at its bump {:.4}, at the other's {:.4}\n",
            c + 1,
            err.iter().fold(0.0_f64, |m, e| m.max(*e)),
            near(own),
            near(other)
        );
        assert!(rms0 > 0.03 && rms1 < 0.05 * rms0, "{report}");
        assert!(near(own) < 0.05, "{report}");
        assert!(near(other) < 0.01, "the other channel's change leaked into this one\n{report}");
    }
    // The top-level figures are channel 1's, and the summary names each.
    assert_eq!(after.signal_rms, after.channels[0].signal_rms);
    assert!(after.describe().contains("channel 2"), "{}", after.describe());
    assert!(moved < 0.02, "the geometry, unchanged, stays\n{report}");
    eprintln!("{report}");
}

/// The first test's pair on a coarser sphere with channel 2 in other
/// units (× `unit`), its kernel width alike, and a short two-stage
/// normalised session.
fn run_in_units(unit: f64, weights: &str) -> fshape_match::MatchResult {
    let (template, target) = two_bumps(&icosphere(2, 1.0));
    let scale = |s: FShape| {
        let rows: Vec<f64> = s.signal().unwrap().chunks_exact(2).flat_map(|r| [r[0], unit * r[1]]).collect();
        s.with_signals(Some(rows), 2).unwrap()
    };
    let config = fshape_match::Config::parse(&format!(
        "[model]\ngamma_f = 0.1\ngamma_w = 1000.0\n{weights}\n[deformation]\nwidths = [0.5]\n\
         [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:0.5,{}\"\n\
         [schedule]\nkernel_geom = [\"gaussian:0.6\", \"gaussian:0.3\"]\n\
         [integrator]\nsteps = 5\n[optimizer]\nmax_iterations = 6\n",
        0.5 * unit
    ))
    .unwrap();
    let mut session = fshape_match::Session::new(&scale(template), &scale(target), &config).unwrap();
    session.run(&mut ()).unwrap();
    session.result().unwrap()
}

#[test]
fn normalised_weights_let_each_channel_count_whatever_its_units() {
    // Channel 2 in units 16 times smaller (a power of two, so the scaled
    // computations round alike): the same registration, step for step,
    // channel 2's values 16 times larger.
    let values = |r: &fshape_match::MatchResult| -> Vec<f64> {
        r.stages.iter().flat_map(|st| std::iter::once(&st.initial).chain(&st.iterations)).map(|i| i.value).collect()
    };
    let (unit, other) = (run_in_units(1.0, ""), run_in_units(16.0, ""));
    let (a, b) = (values(&unit), values(&other));
    assert_eq!(a.len(), b.len(), "the same number of iterations");
    for (u, v) in a.iter().zip(&b) {
        assert!((u - v).abs() <= 1e-9 * u.abs(), "J {u} against {v}");
    }
    let last = |r: &fshape_match::MatchResult| r.trajectory.signal(r.trajectory.steps()).to_vec();
    for (i, (u, v)) in last(&unit).iter().zip(&last(&other)).enumerate() {
        let want = if i % 2 == 1 { 16.0 * u } else { *u };
        assert!((v - want).abs() <= 1e-9 * (1.0 + want.abs()), "value {i}: {v} against {want}");
    }
    // The quality, a fraction of each channel's range, is unit-free.
    let (qa, qb) = (&unit.quality.channels[1], &other.quality.channels[1]);
    assert!((qb.signal_rms.unwrap() - qa.signal_rms.unwrap()).abs() < 1e-9, "{qa:?} {qb:?}");
    // Without normalisation, the same weights fit channel 2 differently.
    let absolute = run_in_units(16.0, "normalize = false").quality.channels[1].signal_rms.unwrap();
    assert!((absolute / qa.signal_rms.unwrap() - 1.0).abs() > 0.01, "{absolute} against {qa:?}");
}

#[test]
fn channel_weights_are_relative_to_each_channels_deviation() {
    let (template, target) = two_bumps(&icosphere(2, 1.0));
    let text = |weights: &str| {
        format!(
            "[model]\n{weights}\n[deformation]\nwidths = [0.5]\n\
             [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:0.5,0.5\"\n"
        )
    };
    let plan = |weights: &str| {
        let config = fshape_match::Config::parse(&text(weights)).unwrap();
        fshape_match::Session::new(&template, &target, &config).map(|s| s.plan().clone())
    };
    let sd = |c: usize| {
        let f = channel(&target, c);
        let mean = f.iter().sum::<f64>() / f.len() as f64;
        (f.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / f.len() as f64).sqrt()
    };
    let (s1, s2) = (sd(0), sd(1));
    let p = plan("").unwrap();
    let scales = p.scales.as_ref().unwrap();
    assert!((scales.channels[0] - s1).abs() < 1e-14 && (scales.channels[1] - s2).abs() < 1e-14, "{scales:?}");
    assert_eq!(scales.signal, scales.channels[0]);
    let w = p.model.channel_weights();
    assert!(w.len() == 2 && w[0] == 1.0 && (w[1] - s1 * s1 / (s2 * s2)).abs() < 1e-14 * w[1], "{w:?}");
    let w = plan("channel_weights = [3, 2]").unwrap().model.channel_weights().to_vec();
    assert!((w[0] - 3.0).abs() < 1e-15 && (w[1] - 2.0 * s1 * s1 / (s2 * s2)).abs() < 1e-14 * w[1], "{w:?}");
    // As written without normalisation.
    let w = plan("normalize = false\nchannel_weights = [3, 2]").unwrap().model.channel_weights().to_vec();
    assert_eq!(w, [3.0, 2.0]);
    for (weights, says) in [
        ("channel_weights = [1, 2, 3]", "3 weights for shapes of 2 signal channels"),
        ("channel_weights = [1, -2]", "channel weight"),
    ] {
        let e = plan(weights).expect_err("refused").to_string();
        assert!(e.contains("model.channel_weights") && e.contains(says), "{weights}: {e}");
    }
}

#[test]
fn sessions_and_atlases_take_several_channels_when_every_shape_carries_the_same_count() {
    let s = icosphere(1, 1.0);
    let f = s.points().to_vec();
    let three = s.clone().with_signals(Some(f.clone()), 3).unwrap();
    let config = fshape_match::Config::parse(
        "[deformation]\nwidths = [0.5]\n[attachment]\nkernel_geom = \"gaussian:0.1\"\n\
         kernel_signal = \"gaussian:1,1,1\"\n",
    )
    .unwrap();
    fshape_match::Session::new(&three, &three, &config).expect("three channels on both sides");
    let pairs: Vec<f64> = f.chunks_exact(3).flat_map(|r| [r[0], r[1]]).collect();
    let two = s.clone().with_signals(Some(pairs), 2).unwrap();
    let e = fshape_match::Session::new(&three, &two, &config).err().expect("refused").to_string();
    assert!(e.contains("the source carries 3 signal channels, the target 2"), "{e}");
    fshape_match::Atlas::new(&s, &[three.clone(), three.clone()], &config).expect("three maps on every subject");
    let e = fshape_match::Atlas::new(&s, &[three.clone(), two.clone()], &config).err().expect("refused").to_string();
    assert!(e.contains("subject 0 carries 3 signal map(s) per vertex and subject 1 carries 2"), "{e}");
    let e = fshape_match::Atlas::new(&two, std::slice::from_ref(&three), &config).err().expect("refused").to_string();
    assert!(e.contains("the template carries 2 signal map(s) per vertex and subject 0 carries 3"), "{e}");
    // A stage template of several channels, given to a one-channel session.
    let geometric =
        fshape_match::Config::parse("[deformation]\nwidths = [0.5]\n[attachment]\nkernel_geom = \"gaussian:0.1\"\n")
            .unwrap();
    let one = s.clone().with_signal(Some(vec![0.0; s.n_vertices()])).unwrap();
    let session = fshape_match::Session::new(&one, &one, &geometric).unwrap();
    let e = session.with_stage_templates(vec![Some(three)]).err().expect("refused").to_string();
    assert!(e.contains("3 signal channels"), "{e}");
}

#[test]
fn a_source_without_a_signal_starts_from_zero_in_each_of_the_targets_channels() {
    let (_, target) = two_bumps(&icosphere(2, 1.0));
    let bare = icosphere(2, 1.0);
    let config = fshape_match::Config::parse(
        "[model]\nchannel_weights = [1, 2]\n[deformation]\nwidths = [0.5]\n\
         [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:0.5,0.5\"\n\
         [optimizer]\nmax_iterations = 3\n",
    )
    .unwrap();
    let mut session = fshape_match::Session::new(&bare, &target, &config).unwrap();
    assert_eq!(session.plan().model.channel_weights().len(), 2);
    session.run(&mut ()).unwrap();
    let r = session.result().unwrap();
    assert_eq!(r.pf.len(), 2 * bare.n_vertices());
    assert_eq!(r.trajectory.signal(0), vec![0.0; 2 * bare.n_vertices()].as_slice());
    // A stage template without a signal cannot stand for a start of two.
    let mut staged = config.clone();
    staged.schedule = Some(fshape_match::ScheduleSection::new(
        ["gaussian:0.6", "gaussian:0.3"].map(|k| fshape_match::PositionKernel::parse(k).unwrap()).to_vec(),
    ));
    let (template, _) = two_bumps(&icosphere(2, 1.0));
    let session = fshape_match::Session::new(&template, &target, &staged).unwrap();
    let e = session.with_stage_templates(vec![Some(icosphere(1, 1.0)), None]).err().expect("refused").to_string();
    assert!(e.contains("carries 2 signal channels and a stage template none"), "{e}");
}
