//! Geodesic regression recovers a known trajectory: visits sampled from a
//! shot metamorphosis at irregular times, each remeshed, are fitted, and
//! the fit is compared with the truth at other times (between the visits)
//! and in its initial velocity.

use fshape_match::{Config, MatchError, Outcome, Regress, StopAfter, Visit};
use fshape_mesh::FShape;
use fshape_mesh::test_support::perturbed_icosphere;
use fshape_shoot::{Model, Problem};

/// The truth: a sphere (642 vertices) with the signal 0.5 + 0.4 z,
/// stretched along x and squeezed along z while its signal grows along y.
fn truth() -> (FShape, fshape_shoot::Trajectory) {
    truth_scaled(1.0, false)
}

/// [`truth`] with the momenta times `a`, from a lumpy sphere whose signal
/// also varies along x if `lumpy` (no symmetry left for a rigid map).
fn truth_scaled(a: f64, lumpy: bool) -> (FShape, fshape_shoot::Trajectory) {
    let sphere = perturbed_icosphere(3, if lumpy { 0.1 } else { 0.0 }, 1);
    let x = if lumpy { 0.3 } else { 0.0 };
    let f: Vec<f64> = sphere.points().chunks_exact(3).map(|p| 0.5 + 0.4 * p[2] + x * p[0]).collect();
    let sphere = sphere.with_signal(Some(f)).unwrap();
    let config = config();
    let model: Model =
        config.plan(&sphere, &sphere).unwrap().model.with_integrator(fshape_shoot::Integrator::Rk4, 40).unwrap();
    let problem = Problem::new(&sphere, model).unwrap();
    let m = sphere.vertex_volumes();
    let p0: Vec<f64> = sphere
        .points()
        .chunks_exact(3)
        .zip(&m)
        .flat_map(|(p, m)| [0.08 * a * m * p[0], 0.0, -0.05 * a * m * p[2]])
        .collect();
    let pf: Vec<f64> = sphere.points().chunks_exact(3).zip(&m).map(|(p, m)| 0.06 * a * m * p[1]).collect();
    let traj = problem.shoot(&p0, &pf).unwrap();
    (sphere, traj)
}

fn config() -> Config {
    let mut config = Config::parse(
        "[model]\nkind = \"metamorphosis\"\nnorm = \"l2-lumped\"\ngamma_w = 200.0\ngamma_f = 1.0\n\
         [deformation]\nwidths = [0.6]\n\
         [attachment]\nkernel_geom = \"gaussian:0.15\"\nkernel_signal = \"gaussian:0.5\"\n\
         [[stage]]\nkernel_geom = \"gaussian:0.4\"\n[[stage]]\nkernel_geom = \"gaussian:0.15\"\n",
    )
    .unwrap();
    config.integrator.steps = 10;
    config.optimizer.max_iterations = 60;
    config
}

/// The truth at normalised time t on the fine mesh.
fn state(sphere: &FShape, traj: &fshape_shoot::Trajectory, t: f64) -> FShape {
    let (x, f) = traj.at(t);
    sphere.clone().with_points(x).unwrap().with_signal(Some(f)).unwrap()
}

/// Area-weighted vertex normals (unit).
fn normals(shape: &FShape) -> Vec<[f64; 3]> {
    let mut n = vec![[0.0; 3]; shape.n_vertices()];
    for (c, v) in shape.cells().chunks_exact(3).zip(shape.cell_vectors()) {
        for &i in c {
            for d in 0..3 {
                n[i][d] += v[d];
            }
        }
    }
    n.iter()
        .map(|v| {
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            [v[0] / l, v[1] / l, v[2] / l]
        })
        .collect()
}

#[test]
fn a_regression_recovers_a_known_trajectory_between_its_visits() {
    let (sphere, traj) = truth();
    // Visits at irregular ages (60 to 64: t = 0, 0.35, 0.6, 1), each the
    // truth remeshed to its own vertex count; the first is the baseline.
    let ages = [60.0, 61.4, 62.4, 64.0];
    let counts = [400, 350, 450, 380];
    let mut kept = Vec::new();
    let visits: Vec<Visit> = ages
        .iter()
        .zip(counts)
        .map(|(age, n)| {
            let s = state(&sphere, &traj, (age - 60.0) / 4.0).simplified(n).unwrap();
            kept.push(s.kept);
            Visit { age: *age, shape: s.shape, weight: 1.0 }
        })
        .collect();
    let baseline = visits[0].shape.clone();
    let mut run = Regress::new(visits, &config()).unwrap();
    run.run(&mut ()).unwrap();
    let result = run.result().unwrap();
    eprintln!("{:?} iterations {} evaluations {}", result.energies, result.iterations, result.evaluations);
    for s in &result.stages {
        eprintln!("stage {:?}", s.stop);
    }
    assert_eq!((result.t0, result.span), (60.0, 4.0));
    for (q, q0) in result.quality.iter().zip(&result.initial_quality).skip(1) {
        eprintln!("visit: {} (baseline: {})", q.describe(), q0.describe());
    }
    // Between the visits, the fitted geodesic is the truth's.
    for age in [60.6, 62.0, 63.2] {
        let truth = state(&sphere, &traj, (age - 60.0) / 4.0);
        let (x, f) = result.at_age(age);
        let fitted = baseline.clone().with_points(x).unwrap().with_signal(Some(f)).unwrap();
        let q = fshape_match::quality(&fitted, &truth).unwrap();
        let q0 = fshape_match::quality(&baseline, &truth).unwrap();
        eprintln!("age {age}: {} (baseline: {})", q.describe(), q0.describe());
        assert!(
            q0.mean_distance > 5.0 * q.mean_distance.max(0.0005),
            "the truth moved at age {age}: {}",
            q0.describe()
        );
        assert!(q.mean_distance <= 0.005, "age {age}: {}", q.describe());
        assert!(q.signal_rms.unwrap() <= 0.02, "age {age}: {}", q.describe());
    }
    // The initial velocity's normal component: relative L² error against
    // the truth's at the baseline's vertices (a subset of the truth's).
    let (v_fit, _) = result.trajectory.velocity(0);
    let (v_true, _) = traj.velocity(0);
    let n = normals(&baseline);
    let (mut err, mut norm) = (0.0, 0.0);
    for (i, (&fine, n)) in kept[0].iter().zip(&n).enumerate() {
        let dot = |v: &[f64], k: usize| (0..3).map(|d| v[3 * k + d] * n[d]).sum::<f64>();
        // Per year: the fit's span is 4 years, the truth's too.
        let (a, b) = (dot(v_fit, i), dot(v_true, fine));
        err += (a - b) * (a - b);
        norm += b * b;
    }
    let rel = (err / norm).sqrt();
    eprintln!("normal velocity: relative L² error {rel:.4}");
    assert!(rel <= 0.1, "{rel}");
}

#[test]
fn a_regression_refuses_visits_it_cannot_fit_by_name() {
    let s = perturbed_icosphere(1, 0.0, 1);
    let visit = |age: f64, weight: f64| Visit { age, shape: s.clone(), weight };
    let err = |visits: Vec<Visit>| match Regress::new(visits, &config()) {
        Err(MatchError::InvalidInput(m)) => m,
        Err(other) => panic!("{other}"),
        Ok(_) => panic!("accepted"),
    };
    assert!(err(vec![visit(1.0, 1.0)]).contains("at least 2 visits"));
    assert!(err(vec![visit(1.0, 1.0), visit(1.0, 1.0)]).contains("every visit is at age 1"));
    assert!(err(vec![visit(1.0, 1.0), visit(f64::NAN, 1.0)]).contains("visit 1: its age NaN"));
    assert!(err(vec![visit(1.0, -1.0), visit(2.0, 1.0)]).contains("visit 0: its weight -1"));
    let two = s.clone().with_signals(Some(vec![0.0; 2 * s.n_vertices()]), 2).unwrap();
    let m = err(vec![visit(1.0, 1.0), Visit { age: 2.0, shape: two, weight: 1.0 }]);
    assert!(m.contains("visit 1 carries 2 signal channel(s), the baseline (visit 0) 1"), "{m}");
}

#[test]
fn a_stopped_regression_resumes_to_the_same_bits_and_serial_is_parallel() {
    let (sphere, traj) = truth();
    let visits: Vec<Visit> = [(0.0, 120), (0.4, 100), (1.0, 110)]
        .iter()
        .map(|&(t, n)| Visit {
            age: 2.0 * t,
            shape: state(&sphere, &traj, t).simplified(n).unwrap().shape,
            weight: 1.0,
        })
        .collect();
    let mut config = config();
    config.optimizer.max_iterations = 4;
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let mut whole = Regress::new(visits.clone(), &config).unwrap();
    whole.run(&mut ()).unwrap();
    let expected = whole.result().unwrap();
    let mut serial = Regress::new(visits.clone(), &config).unwrap().with_parallel(false);
    serial.run(&mut ()).unwrap();
    assert_eq!(bits(&serial.result().unwrap().p0), bits(&expected.p0));
    for stop_after in [2, 5] {
        let mut first = Regress::new(visits.clone(), &config).unwrap();
        assert_eq!(first.run(&mut StopAfter(Some(stop_after))).unwrap(), Outcome::Interrupted);
        let mut second = Regress::new(visits.clone(), &config).unwrap().resume(first.checkpoint().clone()).unwrap();
        assert_eq!(second.run(&mut ()).unwrap(), Outcome::Finished);
        let got = second.result().unwrap();
        assert_eq!(bits(&got.p0), bits(&expected.p0), "stopped after {stop_after}");
        assert_eq!(bits(&got.pf), bits(&expected.pf));
    }
    // Another visit's checkpoint is refused.
    let mut other = visits.clone();
    other[1].age = 0.9;
    let e = Regress::new(other, &config).unwrap().resume(expected_checkpoint(&visits, &config)).err().unwrap();
    assert!(e.to_string().contains("visits or configuration"), "{e}");
}

fn expected_checkpoint(visits: &[Visit], config: &Config) -> fshape_match::Checkpoint {
    let mut run = Regress::new(visits.to_vec(), config).unwrap();
    run.run(&mut StopAfter(Some(1))).unwrap();
    run.checkpoint().clone()
}

#[test]
fn with_prealign_each_visit_scanned_elsewhere_is_moved_onto_the_baseline() {
    // A change over the visits small beside the scanner's move, as in a
    // study (a rigid map cannot be told from a large stretch).
    let (sphere, traj) = truth_scaled(0.1, true);
    let (angle, shift) = (20f64.to_radians(), [0.1, -0.05, 0.2]);
    let moved = |s: FShape| {
        let (c, sn) = (angle.cos(), angle.sin());
        let pts: Vec<f64> = s
            .points()
            .chunks_exact(3)
            .flat_map(|p| [p[0] + shift[0], c * p[1] - sn * p[2] + shift[1], sn * p[1] + c * p[2] + shift[2]])
            .collect();
        s.with_points(pts).unwrap()
    };
    let visits = |rotate: bool| -> Vec<Visit> {
        [(0.0, 120), (0.5, 100), (1.0, 110)]
            .iter()
            .map(|&(t, n)| {
                let shape = state(&sphere, &traj, t).simplified(n).unwrap().shape;
                let shape = if rotate && t > 0.0 { moved(shape) } else { shape };
                Visit { age: t, shape, weight: 1.0 }
            })
            .collect()
    };
    let mut config = config();
    config.optimizer.max_iterations = 40;
    let fit = |visits: Vec<Visit>, config: &Config| {
        let mut run = Regress::new(visits, config).unwrap();
        run.run(&mut ()).unwrap();
        run.result().unwrap()
    };
    let still = fit(visits(false), &config);
    let mut aligned = config.clone();
    aligned.prealign = Config::parse("[deformation]\nwidths = [1.0]\n[prealign]\nkind = \"rigid\"\n").unwrap().prealign;
    let moved = fit(visits(true), &aligned);
    assert!(moved.alignments[0].is_none());
    for (i, a) in moved.alignments.iter().enumerate().skip(1) {
        let a = a.as_ref().unwrap();
        // Not 20° exactly: a rigid map of a changed shape takes part of the
        // change (measured 2026-12-07: the last visit's is 17.3°). What
        // matters is the next line, the fit as close as without the move.
        assert!((a.rotation_degrees - 20.0).abs() < 3.0, "visit {i}: {}", a.describe());
        let (q, q0) = (&moved.quality[i], &still.quality[i]);
        eprintln!("visit {i}: {} (unmoved visits: {})", q.describe(), q0.describe());
        assert!(q.mean_distance <= 1.5 * q0.mean_distance + 0.001, "visit {i}");
    }
}

#[test]
fn visits_without_a_signal_regress_from_a_coarse_stage_to_the_baseline() {
    // Meshes without a signal (the template gets a zero one), the first
    // stage on a simplified baseline whose momenta are carried to the next.
    let sphere = fshape_mesh::generate::icosphere(2, 1.0);
    assert!(sphere.signal().is_none());
    let stretched = |a: f64| {
        let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [a * p[0], p[1], p[2] / a]).collect();
        sphere.clone().with_points(pts).unwrap()
    };
    let visits = vec![
        Visit { age: 0.0, shape: sphere.clone(), weight: 1.0 },
        Visit { age: 1.0, shape: stretched(1.1), weight: 1.0 },
        Visit { age: 2.0, shape: stretched(1.2), weight: 1.0 },
    ];
    let mut config = Config::parse(
        "[deformation]\nwidths = [0.6]\n[attachment]\nkernel_geom = \"gaussian:0.15\"\n\
         [[stage]]\nkernel_geom = \"gaussian:0.3\"\nvertices = 60\n[[stage]]\nkernel_geom = \"gaussian:0.15\"\n",
    )
    .unwrap();
    config.optimizer.max_iterations = 15;
    let mut run = Regress::new(visits, &config).unwrap();
    run.run(&mut ()).unwrap();
    let r = run.result().unwrap();
    assert_eq!(r.stages.len(), 2);
    assert_eq!(r.p0.len(), 3 * sphere.n_vertices());
    for (q, q0) in r.quality.iter().zip(&r.initial_quality).skip(1) {
        assert!(q.mean_distance < 0.5 * q0.mean_distance, "{} from {}", q.describe(), q0.describe());
    }
}
