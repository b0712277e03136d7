//! A `Model` cannot hold nonsense, and a shooting that leaves the
//! geodesic says so.

use fshape_fem::Norm;
use fshape_kernels::Kernel;
use fshape_mesh::generate::icosphere;
use fshape_shoot::{Integrator, Model, Problem, ShootError};

use crate::{model, momenta, surfaces};

#[test]
fn a_model_refuses_values_no_shooting_can_use() {
    let m = || Model::new(Kernel::gaussian(0.3).unwrap());
    for (what, result) in [
        ("steps", m().with_integrator(Integrator::Rk4, 0)),
        ("gamma_v", m().with_weights(0.0, 1.0, 1.0)),
        ("gamma_f", m().with_weights(1.0, f64::NAN, 1.0)),
        ("gamma_w", m().with_weights(1.0, 1.0, f64::INFINITY)),
        ("gamma_w", m().with_weights(1.0, 1.0, -2.0)),
        ("norm length", m().with_norm(Norm::H1 { length: -1.0 })),
        ("norm length", m().with_norm(Norm::H1 { length: f64::NAN })),
        ("max_drift", m().with_max_drift(0.0)),
        ("max_drift", m().with_max_drift(f64::NAN)),
    ] {
        let e = result.expect_err(what);
        assert!(matches!(e, ShootError::Invalid { what: w, .. } if w == what), "{what}: {e}");
        assert!(e.to_string().contains(what), "{e}");
    }
    // Defaults, as documented on Model::new.
    let d = m();
    assert_eq!((d.steps(), d.integrator(), d.norm()), (10, Integrator::Rk4, Norm::L2Lumped));
    assert_eq!((d.gamma_v(), d.gamma_f(), d.gamma_w()), (1.0, 1.0, 1.0));
}

#[test]
fn huge_momenta_are_reported_as_divergence_not_returned() {
    // The case: momenta of 1e6 on a small sphere.
    let sphere = icosphere(1, 0.1);
    let n = sphere.n_vertices();
    let p0: Vec<f64> = sphere.points().iter().map(|c| 1e6 * c.signum()).collect();
    // Metamorphosis (the flow collapses cells on the way) and LDDMM (no
    // signal norm: the Hamiltonian's drift tells).
    for kind in [fshape_shoot::ModelKind::Metamorphosis, fshape_shoot::ModelKind::Lddmm] {
        let problem = Problem::new(&sphere, Model::new(Kernel::gaussian(0.05).unwrap()).with_kind(kind)).unwrap();
        let e = problem.shoot(&p0, &vec![0.0; n]).expect_err("a diverging shooting");
        assert!(
            matches!(e, ShootError::Drift { .. } | ShootError::Diverged { .. } | ShootError::Collapsed { .. }),
            "{kind:?}: {e}"
        );
        let text = e.to_string();
        assert!(text.contains("diverged") && text.contains("reduce the momenta or add time steps"), "{text}");
    }
    let problem = Problem::new(&sphere, Model::new(Kernel::gaussian(0.05).unwrap())).unwrap();
    // The same momenta, scaled down, shoot without complaint, and the
    // check can be turned off.
    let small: Vec<f64> = p0.iter().map(|v| v * 1e-8).collect();
    let traj = problem.shoot(&small, &vec![0.0; n]).unwrap();
    assert!(traj.drift().0 < 1e-6, "{:?}", traj.drift());
}

#[test]
fn the_drift_check_fires_at_its_tolerance_and_not_below() {
    let (template, _) = surfaces();
    let (p0, pf) = momenta(&template, 0.3, 11);
    let coarse = model("norm = \"h1\"", "", "euler", 2);
    let drift = Problem::new(&template, coarse.clone()).unwrap().shoot(&p0, &pf).unwrap().drift().0;
    assert!(drift > 0.0);
    let strict = coarse.clone().with_max_drift(0.5 * drift).unwrap();
    let e = Problem::new(&template, strict).unwrap().shoot(&p0, &pf).expect_err("drift above tolerance");
    match e {
        ShootError::Drift { drift: d, tolerance, .. } => assert_eq!((d, tolerance), (drift, 0.5 * drift)),
        other => panic!("{other}"),
    }
    let loose = coarse.with_max_drift(2.0 * drift).unwrap();
    Problem::new(&template, loose).unwrap().shoot(&p0, &pf).unwrap();
}

#[test]
fn interpolation_takes_any_time_without_panicking() {
    let (template, _) = surfaces();
    let (p0, pf) = momenta(&template, 0.1, 12);
    let traj = Problem::new(&template, model("", "", "rk4", 1)).unwrap().shoot(&p0, &pf).unwrap();
    let (x0, _) = traj.at(0.0);
    assert_eq!(x0, traj.points(0));
    let (x1, _) = traj.at(1.0);
    assert_eq!(x1, traj.points(1));
    for t in [-1.0, 2.0, f64::NAN, f64::INFINITY] {
        let (x, f) = traj.at(t);
        assert_eq!((x.len(), f.len()), (traj.points(0).len(), template.n_vertices()));
    }
}

#[test]
fn one_parallel_switch_reaches_the_attachment_and_the_flow_with_the_same_bits() {
    let (template, target) = surfaces();
    let (p0, pf) = momenta(&template, 0.2, 13);
    let kernel = fshape_varifold::VarifoldKernel::parse("gaussian:0.4", Some("gaussian:0.7"), "binet").unwrap();
    let m = model("norm = \"h1\"\nlength = 0.5", "tolerance = 1e-6", "rk4", 4);
    let parallel = Problem::new(&template, m.clone()).unwrap().with_target(&target, kernel.clone()).unwrap();
    // Switched off after the target is set: the attachment follows.
    let serial = Problem::new(&template, m).unwrap().with_target(&target, kernel).unwrap().with_parallel(false);
    assert!(parallel.parallel() && !serial.parallel());
    let (a, b) = (parallel.objective_grad(&p0, &pf).unwrap(), serial.objective_grad(&p0, &pf).unwrap());
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(a.objective.value.to_bits(), b.objective.value.to_bits());
    assert_eq!((bits(&a.p0), bits(&a.pf)), (bits(&b.p0), bits(&b.pf)));
    let y0: Vec<f64> = target.points()[..30].to_vec();
    let (fa, fb) = (parallel.flow_points(&a.trajectory, &y0).unwrap(), serial.flow_points(&b.trajectory, &y0).unwrap());
    assert_eq!(fa.iter().map(|v| bits(v)).collect::<Vec<_>>(), fb.iter().map(|v| bits(v)).collect::<Vec<_>>());
}
