//! Geodesic regression: its exact gradient against central differences
//! (visits at irregular times, on meshes of their own), its time grid,
//! and its agreement with matching when the only visit is at t = 1.

use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, perturbed_icosphere, random_direction};
use fshape_shoot::{Problem, Regression};
use fshape_varifold::VarifoldKernel;

use crate::{model, momenta, surfaces};

fn attachment() -> VarifoldKernel {
    VarifoldKernel::parse("gaussian:0.4", Some("gaussian:0.7"), "binet").unwrap()
}

/// `shape` stretched by (sx, sy, sz), with the signal a·x + b·z.
fn visit(shape: &FShape, s: [f64; 3], a: f64, b: f64) -> FShape {
    let pts: Vec<f64> = shape.points().chunks_exact(3).flat_map(|p| [s[0] * p[0], s[1] * p[1], s[2] * p[2]]).collect();
    let f: Vec<f64> = pts.chunks_exact(3).map(|p| a * p[0] + b * p[2]).collect();
    shape.clone().with_points(pts).unwrap().with_signal(Some(f)).unwrap()
}

/// Visits at irregular times on three different meshes (42, 162 and 92
/// vertices, the last masked on a band).
fn visits() -> Vec<(f64, FShape, f64)> {
    let coarse = perturbed_icosphere(1, 0.05, 21);
    let fine = perturbed_icosphere(2, 0.05, 22);
    let mid = fine.simplified(92).unwrap().shape;
    let n = mid.n_vertices();
    let masked = visit(&mid, [1.15, 1.0, 0.85], 0.8, 0.5);
    let mask: Vec<f64> = masked.points().chunks_exact(3).map(|p| if p[0] > 0.4 { 0.0 } else { 1.0 }).collect();
    let masked = masked.clone().with_signal_and_mask(masked.signal().map(<[f64]>::to_vec), Some(mask)).unwrap();
    assert_eq!(masked.n_vertices(), n);
    vec![
        (0.23, visit(&coarse, [1.05, 1.0, 0.95], 0.3, 0.1), 1.0),
        (0.61, visit(&fine, [1.1, 1.0, 0.9], 0.6, 0.3), 0.7),
        (1.0, masked, 1.3),
    ]
}

fn regression(template: &FShape, kind: &str, norm: &str, steps: usize) -> Regression {
    let m = model(
        &format!("kind = \"{kind}\"\nnorm = \"{norm}\"\nlength = 0.5\ngamma_f = 0.5\ngamma_w = 2.0"),
        "",
        "rk4",
        steps,
    );
    let mut r = Regression::new(Problem::new(template, m).unwrap()).unwrap();
    for (t, shape, w) in visits() {
        r = r.with_visit(t, &shape, attachment(), w).unwrap();
    }
    r
}

#[test]
fn the_gradient_of_a_regression_matches_central_differences() {
    let (template, _) = surfaces();
    let template = visit(&template, [1.0; 3], 0.2, 0.0);
    let (p0, pf) = momenta(&template, 0.3, 4);
    let n = p0.len();
    let mut rng = SplitMix64(31);
    for (kind, norm) in [("metamorphosis", "l2-lumped"), ("metamorphosis", "h1"), ("lddmm", "l2-lumped")] {
        let r = regression(&template, kind, norm, 5);
        let g = r.objective_grad(&p0, &pf).unwrap();
        assert!(g.objective.attachments.iter().all(|a| *a > 0.0), "{kind}: {:?}", g.objective.attachments);
        let j = |z: &[f64]| r.objective(&z[..n], &z[n..]).unwrap().0.value;
        let z: Vec<f64> = p0.iter().chain(&pf).copied().collect();
        let grad: Vec<f64> = g.p0.iter().chain(&g.pf).copied().collect();
        for _ in 0..3 {
            let v = random_direction(z.len(), &mut rng);
            let c = check_gradient(j, &z, &grad, &v, 1e-5);
            assert!(c.rel_error < 1e-6, "{kind}, {norm}: {c:?}");
        }
        // Each visit's jump counts: moving one visit changes J and its
        // gradient in p_0.
        if kind == "metamorphosis" && norm == "h1" {
            let m = model("norm = \"h1\"\nlength = 0.5\ngamma_f = 0.5\ngamma_w = 2.0", "", "rk4", 5);
            // The first visit at weight 0: the same time grid, no jump there.
            let mut fewer = Regression::new(Problem::new(&template, m).unwrap()).unwrap();
            for (k, (t, shape, w)) in visits().into_iter().enumerate() {
                fewer = fewer.with_visit(t, &shape, attachment(), if k == 0 { 0.0 } else { w }).unwrap();
            }
            assert_eq!(fewer.times(), r.times());
            let h = fewer.objective_grad(&p0, &pf).unwrap();
            let diff = g.p0.iter().zip(&h.p0).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(diff > 1e-6, "the first visit's jump is missing: {diff}");
        }
    }
}

#[test]
fn the_time_grid_has_a_node_at_every_visit_and_bounded_steps() {
    let (template, _) = surfaces();
    let r = regression(&template, "metamorphosis", "l2-lumped", 10);
    let (times, nodes) = r.times();
    assert_eq!((times[0], *times.last().unwrap()), (0.0, 1.0));
    for ((t, _, _), k) in visits().iter().zip(nodes) {
        assert_eq!(times[*k], *t);
    }
    for w in times.windows(2) {
        let step = w[1] - w[0];
        assert!(step > 0.0 && step <= 0.125 + 1e-15, "{step}");
    }
    // 0.23 and 0.61 are 0.03 and 0.01 from the uniform nodes 0.2 and 0.6:
    // 0.6 is dropped (closer than a quarter step), 0.2 kept.
    assert!(times.contains(&0.2) && !times.contains(&0.6), "{times:?}");
    assert_eq!(times.len(), 12);
    // N/N is 1 however N rounds: a visit at 1 adds no step (k·(1/N) for
    // N = 49 is 1 − 2⁻⁵³).
    let m = model("", "", "rk4", 49);
    let ends = Regression::new(Problem::new(&template, m).unwrap())
        .unwrap()
        .with_visit(0.0, &template, attachment(), 1.0)
        .unwrap()
        .with_visit(1.0, &template, attachment(), 1.0)
        .unwrap();
    assert_eq!(ends.times().0.len(), 50);
    // The trajectory's nodes are the grid's.
    let (p0, pf) = momenta(&template, 0.1, 2);
    let traj = r.shoot(&p0, &pf).unwrap();
    assert_eq!(traj.steps(), times.len() - 1);
    for (k, t) in times.iter().enumerate() {
        assert_eq!(traj.time(k), *t);
    }
    // Interpolation is exact at the nodes, on this grid too.
    let (x, _) = traj.at(times[3]);
    assert_eq!(x, traj.points(3));
}

#[test]
fn one_visit_at_the_end_is_matching() {
    let (template, target) = surfaces();
    let template = visit(&template, [1.0; 3], 0.2, 0.0);
    let target = visit(&target, [1.0; 3], 0.5, 0.2);
    let (p0, pf) = momenta(&template, 0.3, 6);
    let m = model("norm = \"h1\"\nlength = 0.5\ngamma_f = 0.5\ngamma_w = 2.0", "", "rk4", 6);
    let problem = Problem::new(&template, m.clone()).unwrap().with_target(&target, attachment()).unwrap();
    let r = Regression::new(Problem::new(&template, m).unwrap())
        .unwrap()
        .with_visit(1.0, &target, attachment(), 1.0)
        .unwrap();
    let (a, b) = (problem.objective_grad(&p0, &pf).unwrap(), r.objective_grad(&p0, &pf).unwrap());
    let close = |u: f64, v: f64| (u - v).abs() <= 1e-12 * u.abs().max(v.abs());
    assert!(close(a.objective.value, b.objective.value), "{:?} {:?}", a.objective, b.objective);
    assert!(close(a.objective.attachment, b.objective.attachments[0]));
    for (u, v) in a.p0.iter().chain(&a.pf).zip(b.p0.iter().chain(&b.pf)) {
        assert!((u - v).abs() <= 1e-10 * (1.0 + u.abs()), "{u} {v}");
    }
}

#[test]
fn a_regression_refuses_what_it_cannot_fit_by_name() {
    let (template, target) = surfaces();
    let m = |kind: &str| model(&format!("kind = \"{kind}\""), "", "rk4", 4);
    let err = Regression::new(Problem::new(&template, m("tangential")).unwrap()).err().unwrap().to_string();
    assert!(err.contains("tangential cannot be regressed"), "{err}");
    let r = Regression::new(Problem::new(&template, m("metamorphosis")).unwrap()).unwrap();
    let (p0, pf) = momenta(&template, 0.1, 1);
    assert!(r.objective(&p0, &pf).unwrap_err().to_string().contains("no visits"));
    let err = r.with_visit(1.5, &target, attachment(), 1.0).err().unwrap().to_string();
    assert!(err.contains("1.5 of visit 0 is outside"), "{err}");
    let r = Regression::new(Problem::new(&template, m("metamorphosis")).unwrap()).unwrap();
    let err = r.with_visit(0.5, &target, attachment(), f64::NAN).err().unwrap().to_string();
    assert!(err.contains("weight"), "{err}");
}
