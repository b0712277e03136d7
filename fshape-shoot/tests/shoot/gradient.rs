//! The exact gradient of J against central finite differences in random
//! directions, for every norm, model and integrator, with exact and
//! truncated deformation kernels.

use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, random_direction};
use fshape_shoot::Problem;
use fshape_varifold::VarifoldKernel;

use crate::{curves, model, momenta, surfaces};

fn attachment() -> VarifoldKernel {
    VarifoldKernel::parse("gaussian:0.4", Some("gaussian:0.7"), "binet").unwrap()
}

fn check(problem: &Problem, p0: &[f64], pf: &[f64], label: &str, rng: &mut SplitMix64) -> f64 {
    let g = problem.objective_grad(p0, pf).unwrap();
    let n = p0.len();
    let z: Vec<f64> = p0.iter().chain(pf).copied().collect();
    let grad: Vec<f64> = g.p0.iter().chain(&g.pf).copied().collect();
    let j = |z: &[f64]| problem.objective(&z[..n], &z[n..]).unwrap().0.value;
    let mut worst: f64 = 0.0;
    for _ in 0..2 {
        let v = random_direction(z.len(), rng);
        let c = check_gradient(j, &z, &grad, &v, 1e-5);
        assert!(c.rel_error < 1e-6, "{label}: {c:?}");
        worst = worst.max(c.rel_error);
    }
    worst
}

#[test]
fn the_gradient_of_j_matches_central_differences_for_every_norm_and_model() {
    let (template, target) = surfaces();
    let (p0, pf) = momenta(&template, 0.3, 1);
    let mut rng = SplitMix64(5);
    let mut worst: f64 = 0.0;
    for kind in ["metamorphosis", "tangential", "lddmm"] {
        for norm in ["l2-lumped", "l2", "h1"] {
            if kind == "lddmm" && norm != "l2-lumped" {
                continue; // no signal norm in pure LDDMM
            }
            for truncation in ["", "tolerance = 1e-6"] {
                let m = model(
                    &format!("kind = \"{kind}\"\nnorm = \"{norm}\"\nlength = 0.5\ngamma_f = 0.5\ngamma_w = 2.0"),
                    truncation,
                    "rk4",
                    5,
                );
                let problem = Problem::new(&template, m).unwrap().with_target(&target, attachment()).unwrap();
                let label = format!("{kind}, {norm}, '{truncation}'");
                worst = worst.max(check(&problem, &p0, &pf, &label, &mut rng));
            }
        }
    }
    eprintln!("worst relative error: {worst:e}");
}

#[test]
fn the_gradient_is_exact_for_each_integrator_and_for_curves() {
    let mut rng = SplitMix64(6);
    for scheme in ["rk4", "midpoint", "euler"] {
        for (what, (template, target)) in [("surface", crate::surfaces()), ("curve", curves())] {
            let (p0, pf) = momenta(&template, 0.3, 2);
            let m = model("norm = \"h1\"\nlength = 0.3", "", scheme, 4);
            let problem = Problem::new(&template, m).unwrap().with_target(&target, attachment()).unwrap();
            check(&problem, &p0, &pf, &format!("{scheme}, {what}"), &mut rng);
        }
    }
}

#[test]
fn the_gradient_is_exact_with_the_deformation_kernel_on_a_grid() {
    // The grid kernel's sums and derivatives are one operator's: J's
    // gradient through the shooting and its adjoint stays exact.
    let mut rng = SplitMix64(7);
    for (what, (template, target)) in [("surface", surfaces()), ("curve", curves())] {
        let (p0, pf) = momenta(&template, 0.3, 3);
        let dim = template.dim();
        for order in fshape_kernels::GRID_ORDERS {
            let m = model("norm = \"h1\"\nlength = 0.5\ngamma_f = 0.5\ngamma_w = 2.0", "", "rk4", 4);
            let k = m.kernel().clone();
            let grid = k.on_grid(k.grid_spacing(1e-3, order, dim).unwrap(), order, dim).unwrap();
            let problem =
                Problem::new(&template, m.with_kernel(grid)).unwrap().with_target(&target, attachment()).unwrap();
            assert!(problem.model().kernel().grid().is_some());
            check(&problem, &p0, &pf, &format!("grid order {order}, {what}"), &mut rng);
        }
    }
}

#[test]
fn a_problem_takes_the_grid_for_a_wide_kernel_on_many_points_within_its_tolerance() {
    let template = fshape_mesh::generate::icosphere(5, 1.0);
    let wide = model("", "tolerance = 1e-6", "rk4", 4);
    let problem = Problem::new(&template, wide.clone()).unwrap();
    let grid = problem.model().kernel().grid().expect("10242 points, sigma 0.6 and 0.3 on a unit sphere");
    assert!(grid.bound().value <= 1e-6);
    // Exact stays exact; a small template keeps its pairs.
    let exact = model("", "", "rk4", 4);
    assert_eq!(Problem::new(&template, exact).unwrap().model().kernel().path(), fshape_kernels::SumPath::Exact);
    let small = fshape_mesh::generate::icosphere(1, 1.0);
    assert!(Problem::new(&small, wide).unwrap().model().kernel().grid().is_none());
}

/// `shape` with the signal `scale`·(x + y²) plus a little noise.
fn with_signal(shape: FShape, scale: f64, rng: &mut SplitMix64) -> FShape {
    let d = shape.dim();
    let f: Vec<f64> =
        shape.points().chunks_exact(d).map(|p| scale * (p[0] + p[1] * p[1]) + 0.1 * rng.range(-1.0, 1.0)).collect();
    shape.with_signal(Some(f)).unwrap()
}

/// ∂J/∂x_0 and ∂J/∂f_0 (the template's gradient, momenta fixed) against
/// central differences of J with the template moved by `set_template`.
fn check_template(problem: &mut Problem, p0: &[f64], pf: &[f64], label: &str, rng: &mut SplitMix64) {
    let g = problem.objective_grad(p0, pf).unwrap();
    let (x0, f0) = (problem.template().points().to_vec(), problem.template().signal().unwrap().to_vec());
    let n = x0.len();
    let z: Vec<f64> = x0.iter().chain(&f0).copied().collect();
    let grad: Vec<f64> = g.x0.iter().chain(&g.f0).copied().collect();
    let cell = std::cell::RefCell::new(problem);
    let j = |z: &[f64]| {
        let mut p = cell.borrow_mut();
        p.set_template(&z[..n], Some(&z[n..])).unwrap();
        p.objective(p0, pf).unwrap().0.value
    };
    for _ in 0..2 {
        let v = random_direction(z.len(), rng);
        let c = check_gradient(j, &z, &grad, &v, 1e-5);
        assert!(c.rel_error < 1e-6, "{label}: {c:?}");
    }
    // Positions alone and the signal alone, so neither hides behind the other.
    for part in [0..n, n..z.len()] {
        let mut v = vec![0.0; z.len()];
        v[part.clone()].copy_from_slice(&random_direction(part.len(), rng));
        let c = check_gradient(j, &z, &grad, &v, 1e-5);
        assert!(c.rel_error < 1e-6, "{label}, {part:?}: {c:?}");
    }
}

#[test]
fn the_template_gradient_matches_central_differences_for_every_norm_and_model() {
    let mut rng = SplitMix64(8);
    let (template, target) = surfaces();
    let (template, target) = (with_signal(template, 1.0, &mut rng), with_signal(target, 0.5, &mut rng));
    let (p0, pf) = momenta(&template, 0.3, 3);
    for kind in ["metamorphosis", "tangential", "lddmm"] {
        for norm in ["l2-lumped", "l2", "h1"] {
            if kind == "lddmm" && norm != "l2-lumped" {
                continue;
            }
            let m = model(
                &format!("kind = \"{kind}\"\nnorm = \"{norm}\"\nlength = 0.5\ngamma_f = 0.5\ngamma_w = 2.0"),
                "",
                "rk4",
                5,
            );
            let mut problem = Problem::new(&template, m).unwrap().with_target(&target, attachment()).unwrap();
            check_template(&mut problem, &p0, &pf, &format!("{kind}, {norm}"), &mut rng);
        }
    }
    // Curves, with the midpoint rule.
    let (template, target) = curves();
    let (template, target) = (with_signal(template, 1.0, &mut rng), with_signal(target, 0.5, &mut rng));
    let (p0, pf) = momenta(&template, 0.3, 4);
    let m = model("norm = \"h1\"\nlength = 0.3", "", "midpoint", 4);
    let mut problem = Problem::new(&template, m).unwrap().with_target(&target, attachment()).unwrap();
    check_template(&mut problem, &p0, &pf, "curve, h1, midpoint", &mut rng);
}

#[test]
fn the_pullback_of_an_end_costate_matches_central_differences() {
    // Φ(p_0, p^f) = H(z_0) + ⟨a, x_1⟩ + ⟨b, f_1⟩ for fixed a, b.
    let mut rng = SplitMix64(12);
    let (template, _) = surfaces();
    let template = with_signal(template, 1.0, &mut rng);
    let (p0, pf) = momenta(&template, 0.3, 5);
    let n = template.n_vertices();
    let (a, b) = (random_direction(3 * n, &mut rng), random_direction(n, &mut rng));
    for kind in ["metamorphosis", "tangential", "lddmm"] {
        let m = model(&format!("kind = \"{kind}\"\nnorm = \"h1\"\nlength = 0.5\ngamma_f = 0.5"), "", "rk4", 5);
        let problem = Problem::new(&template, m).unwrap();
        let traj = problem.shoot(&p0, &pf).unwrap();
        let (gp, gf) = problem.pullback(&traj, &a, &b).unwrap();
        let phi = |z: &[f64]| {
            let t = problem.shoot(&z[..3 * n], &z[3 * n..]).unwrap();
            let k = t.steps();
            let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>();
            t.hamiltonian[0] + dot(&a, t.points(k)) + dot(&b, t.signal(k))
        };
        let z: Vec<f64> = p0.iter().chain(&pf).copied().collect();
        let grad: Vec<f64> = gp.iter().chain(&gf).copied().collect();
        for _ in 0..2 {
            let v = random_direction(z.len(), &mut rng);
            let c = check_gradient(phi, &z, &grad, &v, 1e-5);
            assert!(c.rel_error < 1e-6, "{kind}: {c:?}");
        }
    }
    // End co-states of the wrong length are refused by name.
    let m = model("norm = \"h1\"", "", "rk4", 3);
    let problem = Problem::new(&template, m).unwrap();
    let traj = problem.shoot(&p0, &pf).unwrap();
    let err = problem.pullback(&traj, &a[1..], &b).unwrap_err().to_string();
    assert!(err.contains("end co-state of x"), "{err}");
}

/// `shape` masked on a band (mask 0 where x > 0.3, a soft edge of weights
/// 0.5 beside it, 1 elsewhere), its signal there set to `value`.
fn banded(shape: &FShape, value: f64) -> FShape {
    let d = shape.dim();
    let m: Vec<f64> = shape
        .points()
        .chunks_exact(d)
        .map(|p| {
            if p[0] > 0.3 {
                0.0
            } else if p[0] > 0.15 {
                0.5
            } else {
                1.0
            }
        })
        .collect();
    let f: Vec<f64> = shape.signal().unwrap().iter().zip(&m).map(|(f, w)| if *w == 0.0 { value } else { *f }).collect();
    shape.clone().with_signal_and_mask(Some(f), Some(m)).unwrap()
}

#[test]
fn with_masks_the_gradient_is_exact_and_masked_values_are_never_read() {
    let (template, target) = surfaces();
    let (p0, pf) = momenta(&template, 0.3, 1);
    let mut rng = SplitMix64(9);
    for kind in ["metamorphosis", "tangential"] {
        for norm in ["l2-lumped", "h1"] {
            let m = model(
                &format!("kind = \"{kind}\"\nnorm = \"{norm}\"\nlength = 0.5\ngamma_f = 0.5\ngamma_w = 2.0"),
                "",
                "rk4",
                5,
            );
            let run = |value: f64| {
                let problem = Problem::new(&banded(&template, value), m.clone())
                    .unwrap()
                    .with_target(&banded(&target, value), attachment())
                    .unwrap();
                problem.objective_grad(&p0, &pf).unwrap()
            };
            let label = format!("{kind}, {norm}");
            let g = run(f64::NAN);
            // p^f's gradient is 0 where the template is masked: its signal
            // momentum is held at 0 there.
            let mask = banded(&template, 0.0).mask().unwrap().to_vec();
            assert!(mask.contains(&0.0) && mask.contains(&1.0) && mask.contains(&0.5), "{label}: the band");
            for (v, w) in mask.iter().enumerate() {
                if *w == 0.0 {
                    assert_eq!((g.pf[v], g.f0[v]), (0.0, 0.0), "{label}: vertex {v}");
                }
            }
            // The same bits whatever the masked values are, and whatever p^f is given there.
            let bits = |g: &fshape_shoot::Gradient| {
                let t = &g.trajectory;
                let last = t.steps();
                let mut b: Vec<u64> =
                    [g.objective.value].iter().chain(&g.p0).chain(&g.pf).map(|v| v.to_bits()).collect();
                b.extend(t.points(last).iter().map(|v| v.to_bits()));
                b
            };
            for value in [0.0, 1e300] {
                assert_eq!(bits(&run(value)), bits(&g), "{label}: masked values {value} were read");
            }
            let problem = Problem::new(&banded(&template, 0.0), m.clone())
                .unwrap()
                .with_target(&banded(&target, 0.0), attachment())
                .unwrap();
            let noisy: Vec<f64> = pf.iter().zip(&mask).map(|(p, w)| if *w == 0.0 { 123.0 } else { *p }).collect();
            assert_eq!(bits(&problem.objective_grad(&p0, &noisy).unwrap()), bits(&g), "{label}: masked p^f was read");
            check(&problem, &p0, &pf, &label, &mut rng);
        }
    }
}
