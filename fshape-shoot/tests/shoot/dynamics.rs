//! Properties of the flow: time reversal, rest, the LDDMM limit, flowing
//! extra points.

use fshape_mesh::FShape;
use fshape_shoot::Problem;

use crate::{model, momenta, surfaces};

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(u, v)| (u - v).abs()).fold(0.0, f64::max)
}

/// Shoots forward, then back from (x_1, f_1, −p_1, −p^f); returns the
/// largest error in x and f on return.
fn round_trip(template: &FShape, scheme: &str, steps: usize) -> f64 {
    let m = model("norm = \"h1\"\nlength = 0.5\ngamma_f = 0.5", "", scheme, steps);
    let (p0, pf) = momenta(template, 0.5, 3);
    let forward = Problem::new(template, m.clone()).unwrap().shoot(&p0, &pf).unwrap();
    let end = template
        .clone()
        .with_points(forward.points(steps).to_vec())
        .unwrap()
        .with_signal(Some(forward.signal(steps).to_vec()))
        .unwrap();
    let back_p: Vec<f64> = forward.momenta(steps).iter().map(|v| -v).collect();
    let back_pf: Vec<f64> = pf.iter().map(|v| -v).collect();
    let back = Problem::new(&end, m).unwrap().shoot(&back_p, &back_pf).unwrap();
    max_diff(back.points(steps), template.points()).max(max_diff(back.signal(steps), template.signal().unwrap()))
}

#[test]
fn shooting_back_with_negated_momenta_returns_to_the_start_at_the_integrators_order() {
    // The flow is reversible: (x, f, −p, −p^f) retraces the path. A step of
    // a method of order q errs locally by C(z)dt^{q+1}; stepping back with
    // −dt adds C(z)(−dt)^{q+1}, so for even q (RK4, midpoint) the leading
    // terms cancel and the round trip is O(dt^{q+1}) globally, while Euler's
    // doubles and stays O(dt).
    let (template, _) = surfaces();
    for (scheme, order) in [("rk4", 5.0), ("midpoint", 3.0), ("euler", 1.0)] {
        let (e1, e2) = (round_trip(&template, scheme, 16), round_trip(&template, scheme, 32));
        let observed = (e1 / e2).log2();
        eprintln!("{scheme}: error {e1:e} at 16 steps, {e2:e} at 32, order {observed:.2}");
        assert!((observed - order).abs() < 0.5, "{scheme}: errors {e1:e}, {e2:e}, order {observed}");
        if scheme == "rk4" {
            assert!(e2 < 1e-5, "rk4 round trip error {e2:e}");
        }
    }
}

#[test]
fn zero_momenta_leave_the_shape_still() {
    let (template, _) = surfaces();
    for kind in ["metamorphosis", "tangential", "lddmm"] {
        let m = model(&format!("kind = \"{kind}\"\nnorm = \"h1\""), "", "rk4", 10);
        let n = template.n_vertices();
        let traj = Problem::new(&template, m).unwrap().shoot(&vec![0.0; 3 * n], &vec![0.0; n]).unwrap();
        for k in 0..=10 {
            assert_eq!(traj.points(k), template.points(), "{kind}: x moved at step {k}");
            assert_eq!(traj.signal(k), template.signal().unwrap(), "{kind}: f changed at step {k}");
        }
        assert!(traj.hamiltonian.iter().all(|&h| h == 0.0));
    }
}

#[test]
fn a_metamorphosis_with_a_huge_signal_weight_is_lddmm() {
    // γ_f → ∞: ḟ = h/γ_f and the signal force |h|²/γ_f vanish like 1/γ_f.
    let (template, _) = surfaces();
    let (p0, pf) = momenta(&template, 0.5, 4);
    let lddmm = Problem::new(&template, model("kind = \"lddmm\"", "", "rk4", 10)).unwrap().shoot(&p0, &pf).unwrap();
    let mut errs = Vec::new();
    for gf in [1e4, 1e6] {
        let m = model(&format!("norm = \"h1\"\ngamma_f = {gf}"), "", "rk4", 10);
        let meta = Problem::new(&template, m).unwrap().shoot(&p0, &pf).unwrap();
        let e = max_diff(meta.points(10), lddmm.points(10)).max(max_diff(meta.signal(10), lddmm.signal(10)));
        errs.push(e);
    }
    eprintln!("difference to LDDMM at γ_f = 1e4, 1e6: {errs:?}");
    // 100 times the weight, 100 times closer (within 10 %).
    let ratio = errs[0] / errs[1];
    assert!((90.0..110.0).contains(&ratio) && errs[1] < 1e-5, "{errs:?}");
}

#[test]
fn flowed_points_follow_the_vertices() {
    // Flowing the template's own vertices as extra points reproduces the
    // shooting (same scheme, same stages).
    let (template, _) = surfaces();
    let (p0, pf) = momenta(&template, 0.5, 5);
    let problem = Problem::new(&template, model("norm = \"l2\"", "", "rk4", 6)).unwrap();
    let traj = problem.shoot(&p0, &pf).unwrap();
    let flowed = problem.flow_points(&traj, template.points()).unwrap();
    for (k, y) in flowed.iter().enumerate() {
        assert!(max_diff(y, traj.points(k)) < 1e-13, "step {k}");
    }
    // And interpolation is exact at the steps.
    let (x, f) = traj.at(0.5);
    assert_eq!((x.as_slice(), f.as_slice()), (traj.points(3), traj.signal(3)));
}

#[test]
fn the_hamiltonian_is_conserved_to_the_integrators_order() {
    // H is a first integral; RK4 keeps it to O(dt⁴). (fshape-validate owns
    // the full study.)
    let (template, _) = surfaces();
    let (p0, pf) = momenta(&template, 0.5, 6);
    let drift = |steps: usize| {
        let m = model("norm = \"h1\"\nlength = 0.5", "", "rk4", steps);
        let h = Problem::new(&template, m).unwrap().shoot(&p0, &pf).unwrap().hamiltonian;
        h.iter().map(|v| (v - h[0]).abs()).fold(0.0, f64::max) / h[0]
    };
    let (d1, d2) = (drift(20), drift(40));
    let order = (d1 / d2).log2();
    eprintln!("relative drift of H: {d1:e} at 20 steps, {d2:e} at 40, order {order:.2}");
    assert!((3.5..4.5).contains(&order) && d2 < 1e-6, "drifts {d1:e}, {d2:e}");
}

#[test]
fn the_tangential_path_reports_the_affine_signal_and_the_lddmm_geometry() {
    // The paper's tangential model: geometry by LDDMM, signal f_0 + tζ.
    let (template, _) = surfaces();
    let (p0, zeta) = momenta(&template, 0.5, 5);
    let tan = Problem::new(&template, model("kind = \"tangential\"\nnorm = \"h1\"", "", "rk4", 10)).unwrap();
    let lddmm = Problem::new(&template, model("kind = \"lddmm\"", "", "rk4", 10)).unwrap();
    let (traj, geom) = (tan.shoot(&p0, &zeta).unwrap(), lddmm.shoot(&p0, &zeta).unwrap());
    let f0 = template.signal().unwrap();
    for t in [0.0, 0.3, 0.5, 1.0] {
        let ((x, f), (xl, _)) = (traj.at(t), geom.at(t));
        assert_eq!(x, xl, "t = {t}: the geometry is LDDMM's");
        let affine: Vec<f64> = f0.iter().zip(&zeta).map(|(a, z)| a + t * z).collect();
        assert!(max_diff(&f, &affine) < 1e-12, "t = {t}: {}", max_diff(&f, &affine));
    }
    // What the data term sees at t = 1 is f_0 + ζ.
    assert!(max_diff(traj.signal(10), &traj.at(1.0).1) < 1e-12);
}
