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

/// Channel `c` of `s`'s signal.
fn channel(s: &FShape, c: usize) -> Vec<f64> {
    s.channel(c).expect("two channels")
}

#[test]
fn two_channels_changed_in_two_places_are_each_recovered_where_they_changed() {
    // The template carries 0.5 z and 0.5 x; the target has the same
    // geometry, a bump on channel 1 at the north pole and one on channel 2
    // on the equator. The truth: nothing moves, each channel gains its bump.
    let sphere = icosphere(3, 1.0);
    let (north, east) = ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
    let rows = |with_bumps: bool| -> Vec<f64> {
        let b = if with_bumps { 1.0 } else { 0.0 };
        sphere
            .points()
            .chunks_exact(3)
            .flat_map(|p| [0.5 * p[2] + b * bump(p, north), 0.5 * p[0] + b * bump(p, east)])
            .collect()
    };
    let template = sphere.clone().with_signals(Some(rows(false)), 2).unwrap();
    let target = sphere.clone().with_signals(Some(rows(true)), 2).unwrap();
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
        let near = |c: [f64; 3]| -> f64 {
            sphere
                .points()
                .chunks_exact(3)
                .zip(&err)
                .filter(|(p, _)| bump(p, c) > 0.5)
                .fold(0.0_f64, |m, (_, e)| m.max(*e))
        };
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

#[test]
fn sessions_and_atlases_name_what_they_do_not_carry_yet() {
    let s = icosphere(1, 1.0);
    let f = s.points().to_vec();
    let three = s.clone().with_signals(Some(f), 3).unwrap();
    let config =
        fshape_match::Config::parse("[deformation]\nwidths = [0.5]\n[attachment]\nkernel_geom = \"gaussian:0.1\"\n")
            .unwrap();
    let e = fshape_match::Session::new(&three, &three, &config).err().expect("refused").to_string();
    assert!(e.contains("3 signal channels") && e.contains("minimize"), "{e}");
    let e = fshape_match::Atlas::new(&s, &[three.clone(), three.clone()], &config).err().expect("refused").to_string();
    assert!(e.contains("3 signal channels"), "{e}");
    // A stage template of several channels, given to a one-channel session.
    let one = s.clone().with_signal(Some(vec![0.0; s.n_vertices()])).unwrap();
    let session = fshape_match::Session::new(&one, &one, &config).unwrap();
    let e = session.with_stage_templates(vec![Some(three)]).err().expect("refused").to_string();
    assert!(e.contains("3 signal channels"), "{e}");
}
