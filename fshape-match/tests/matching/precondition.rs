//! The kernel metric of p_0: its factor against the kernel matrix written
//! out, and what it does to the optimiser on an ill-conditioned quadratic.

use fshape_kernels::Kernel;
use fshape_match::optimize::{Evaluation, Method, Objective, Settings, State, Stop};
use fshape_match::precondition::{KernelFactor, RIDGE};
use fshape_mesh::test_support::random_vector_field;

#[test]
fn the_kernel_factor_inverts_the_kernel_matrix_with_its_ridge() {
    // Points on a perturbed sphere, a sum of two Gaussians, and a block of
    // signal unknowns after p_0 that must stay as it is.
    let shape = fshape_mesh::test_support::perturbed_icosphere(2, 0.05, 3);
    let (n, d) = (shape.n_vertices(), 3);
    let kernel =
        Kernel::try_new(&fshape_kernels::Profile::Gaussians { sigmas: vec![0.6, 0.3], weights: vec![1.0, 0.5] })
            .unwrap();
    let factor = KernelFactor::new(&shape, &kernel).unwrap().expect("a positive definite kernel");
    let v = random_vector_field(n, d, 1.0, 6);
    let mut w = v.clone();
    w.extend([7.0, -3.0]);
    factor.apply(&mut w);
    assert_eq!(&w[n * d..], &[7.0, -3.0], "the signal block changed");
    // (K + λD⁻¹) w must give v back: K written out pair by pair, the
    // lumped masses as a third of the adjacent triangles' areas, λ from
    // the kernel's widths: the profile's value e^{−1/2}·k(0) at r_0.
    let x = shape.points();
    let mut masses = vec![0.0; n];
    for c in shape.cells().chunks_exact(3) {
        let p = |k: usize| &x[3 * c[k]..3 * c[k] + 3];
        let (a, b) = ([0, 1, 2].map(|e| p(1)[e] - p(0)[e]), [0, 1, 2].map(|e| p(2)[e] - p(0)[e]));
        let cross = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
        let area = 0.5 * cross.iter().map(|v| v * v).sum::<f64>().sqrt();
        c.iter().for_each(|&i| masses[i] += area / 3.0);
    }
    let lambda = KernelFactor::ridge(&kernel, 2);
    let r0_squared = lambda / (RIDGE * kernel.value(0.0));
    assert!((kernel.value(r0_squared) / kernel.value(0.0) - (-0.5f64).exp()).abs() < 1e-12);
    let mut worst: f64 = 0.0;
    for i in 0..n {
        for c in 0..d {
            let mut s = lambda / masses[i] * w[i * d + c];
            for j in 0..n {
                let u: f64 = (0..d).map(|e| (x[i * d + e] - x[j * d + e]).powi(2)).sum();
                s += kernel.value(u) * w[j * d + c];
            }
            worst = worst.max((s - v[i * d + c]).abs());
        }
    }
    let size = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(worst < 1e-8 * size, "residual {worst:e}");
}

#[test]
fn the_factor_is_refused_above_its_size_limit() {
    let n = fshape_match::precondition::MAX_VERTICES + 1;
    let points: Vec<f64> = (0..n).flat_map(|i| [i as f64, 0.0]).collect();
    let cells: Vec<usize> = (0..n - 1).flat_map(|i| [i, i + 1]).collect();
    let curve = fshape_mesh::FShape::try_new(2, fshape_mesh::CellKind::Segment, points, cells, None).unwrap();
    let kernel = Kernel::gaussian(1.0).unwrap();
    assert!(KernelFactor::new(&curve, &kernel).unwrap().is_none());
}

/// ½ xᵀA x − bᵀx with A = K + 1e-6·I for a Gaussian Gram matrix K on 40
/// points of a line: the shape of a momentum energy, condition ~10⁶.
/// Optionally preconditioned by A⁻¹ up to a factor (as a kernel metric).
struct Gram {
    a: Vec<f64>,
    ainv: Option<Vec<f64>>,
}

impl Gram {
    const N: usize = 40;
    fn new(preconditioned: bool) -> Gram {
        let n = Self::N;
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let u = ((i as f64 - j as f64) / 8.0).powi(2);
                a[i * n + j] = (-u).exp() + if i == j { 1e-6 } else { 0.0 };
            }
        }
        // A⁻¹ by Gauss–Jordan elimination (the test's own, not the crate's),
        // times 3: the preconditioner is known only up to a factor.
        let ainv = preconditioned.then(|| {
            let mut m: Vec<f64> = (0..n)
                .flat_map(|i| (0..2 * n).map(move |j| (i, j)))
                .map(|(i, j)| {
                    if j < n {
                        a[i * n + j]
                    } else if j - n == i {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect();
            for c in 0..n {
                let p = m[c * 2 * n + c];
                for j in 0..2 * n {
                    m[c * 2 * n + j] /= p;
                }
                for r in 0..n {
                    if r != c {
                        let f = m[r * 2 * n + c];
                        for j in 0..2 * n {
                            m[r * 2 * n + j] -= f * m[c * 2 * n + j];
                        }
                    }
                }
            }
            (0..n * n).map(|k| 3.0 * m[(k / n) * 2 * n + n + k % n]).collect()
        });
        Gram { a, ainv }
    }
    fn b(i: usize) -> f64 {
        (i as f64 * 0.7).sin()
    }
}

impl Objective for Gram {
    type Error = ();
    type Parts = ();
    fn value_grad(&mut self, x: &[f64]) -> Result<Evaluation<()>, ()> {
        let n = Self::N;
        let ax: Vec<f64> = (0..n).map(|i| (0..n).map(|j| self.a[i * n + j] * x[j]).sum()).collect();
        let value = (0..n).map(|i| 0.5 * x[i] * ax[i] - Self::b(i) * x[i]).sum();
        Ok((value, (0..n).map(|i| ax[i] - Self::b(i)).collect()).into())
    }
    fn precondition(&self, v: &mut [f64]) {
        if let Some(m) = &self.ainv {
            let n = Self::N;
            let w: Vec<f64> = (0..n).map(|i| (0..n).map(|j| m[i * n + j] * v[j]).sum()).collect();
            v.copy_from_slice(&w);
        }
    }
}

#[test]
fn a_preconditioner_close_to_the_inverse_hessian_makes_an_ill_conditioned_quadratic_easy() {
    let settings = Settings {
        method: Method::Lbfgs { memory: 5 },
        max_iterations: 500,
        gradient_tolerance: 1e-8,
        decrease_tolerance: 0.0,
        decrease_window: 0,
        ..Settings::default()
    };
    let mut runs = Vec::new();
    for preconditioned in [true, false] {
        let mut f = Gram::new(preconditioned);
        let mut state = State::start(vec![0.0; Gram::N], &mut f).unwrap().0;
        let stop = state.run(&settings, &mut f, |_| {}).unwrap();
        runs.push((stop, state.iteration));
    }
    // With M⁻¹ = 3A⁻¹ the first direction is 3× Newton's and the line
    // search finds the minimiser along it; then ‖∇J‖ is at rounding level.
    assert!(runs[0].0 == Stop::Gradient && runs[0].1 <= 3, "preconditioned: {:?}", runs[0]);
    assert!(runs[1].1 > 10 * runs[0].1.max(1), "plain L-BFGS was as fast: {:?} against {:?}", runs[1], runs[0]);
}

#[test]
fn the_two_level_metric_is_symmetric_positive_and_near_the_dense_inverse() {
    use fshape_match::precondition::TwoLevel;
    // A 2562-vertex sphere, small enough for the dense factor to judge by.
    let shape = fshape_mesh::test_support::perturbed_icosphere(4, 0.02, 5);
    let (n, d) = (shape.n_vertices(), 3);
    let kernel =
        Kernel::try_new(&fshape_kernels::Profile::Gaussians { sigmas: vec![0.6, 0.3], weights: vec![1.0, 0.5] })
            .unwrap();
    let dense = KernelFactor::new(&shape, &kernel).unwrap().unwrap();
    let two = TwoLevel::new(&shape, &kernel, 400).unwrap().expect("a positive definite coarse kernel");
    let apply = |m: &dyn Fn(&mut [f64]), v: &[f64]| {
        let mut w = v.to_vec();
        w.extend([5.0]);
        m(&mut w);
        assert_eq!(w[n * d], 5.0, "the signal block changed");
        w.truncate(n * d);
        w
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (u, v) = (random_vector_field(n, d, 1.0, 7), random_vector_field(n, d, 1.0, 8));
    let (hu, hv) = (apply(&|w| two.apply(w), &u), apply(&|w| two.apply(w), &v));
    // Symmetric and positive.
    assert!((dot(&u, &hv) - dot(&v, &hu)).abs() <= 1e-9 * dot(&u, &hu).abs().max(dot(&v, &hv).abs()));
    assert!(dot(&u, &hu) > 0.0 && dot(&v, &hv) > 0.0);
    // A x for a smooth momentum x (a density the coarse mesh resolves,
    // times the lumped masses), where the dense factor gives x back, and
    // random vectors: the energy H gives each against A⁻¹'s stays within
    // a factor of 20 for the smooth one, and the two ratios' spread is at
    // least ten times smaller than the Euclidean metric's (H = I).
    let masses = shape.vertex_volumes();
    let x_smooth: Vec<f64> = shape
        .points()
        .chunks_exact(3)
        .zip(&masses)
        .flat_map(|(p, m)| [m * p[1], m * p[2] * p[0], m * (1.0 - p[0])])
        .collect();
    let lambda = KernelFactor::ridge(&kernel, 2);
    let mut ax = vec![0.0; n * d];
    for i in 0..n {
        for j in 0..n {
            let u: f64 = (0..3).map(|c| (shape.points()[3 * i + c] - shape.points()[3 * j + c]).powi(2)).sum();
            for c in 0..3 {
                ax[3 * i + c] += kernel.value(u) * x_smooth[3 * j + c];
            }
        }
        for c in 0..3 {
            ax[3 * i + c] += lambda / masses[i] * x_smooth[3 * i + c];
        }
    }
    let (exact, approx) = (apply(&|w| dense.apply(w), &ax), apply(&|w| two.apply(w), &ax));
    let rel = |a: &[f64], b: &[f64]| {
        a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum::<f64>().sqrt()
            / b.iter().map(|q| q * q).sum::<f64>().sqrt()
    };
    assert!(rel(&exact, &x_smooth) < 1e-6, "dense: {}", rel(&exact, &x_smooth));
    let du = apply(&|w| dense.apply(w), &u);
    let smooth = dot(&ax, &approx) / dot(&ax, &exact);
    let random = dot(&u, &hu) / dot(&u, &du);
    assert!((0.05..20.0).contains(&smooth), "smooth: energy ratio {smooth}");
    let euclidean = (dot(&ax, &ax) / dot(&ax, &exact)) / (dot(&u, &u) / dot(&u, &du));
    assert!(smooth / random < 0.1 * euclidean, "spread {} against the Euclidean {euclidean}", smooth / random);
}
