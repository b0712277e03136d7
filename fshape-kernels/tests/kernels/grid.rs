//! The grid path against the exact sums: within its stated bound on
//! random clouds (2-D and 3-D, uniform and clustered, several widths and
//! orders), its derivatives by finite differences (they are the exact
//! derivatives of the grid kernel), the same bits serial and parallel and
//! for any number of threads, the lattice's invariances, positivity, and
//! refusals.

use fshape_kernels::{GRID_ORDERS, Kernel, KernelError, KernelSums, Profile, SumWorkspace};
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, check_jvp, random_direction};

use crate::{clustered, uniform};

/// The exact sums by the obvious double loop: Σ_j k(u_ij) b_j and the
/// x-gradient Σ_j 2k'(u_ij)(a_i·b_j)(x_i − y_j), with |a_i·b_j| summed
/// alongside (the gradient bound's scale).
fn exact(
    k: &Kernel,
    x: &[f64],
    y: &[f64],
    dim: usize,
    a: &[f64],
    b: &[f64],
    c: usize,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (nx, ny) = (x.len() / dim, y.len() / dim);
    let (mut conv, mut grad, mut ab_abs) = (vec![0.0; nx * c], vec![0.0; nx * dim], vec![0.0; nx]);
    for i in 0..nx {
        for j in 0..ny {
            let d: Vec<f64> = (0..dim).map(|e| x[i * dim + e] - y[j * dim + e]).collect();
            let u: f64 = d.iter().map(|v| v * v).sum();
            let [k0, k1, _] = k.derivatives(u);
            let ab: f64 = (0..c).map(|e| a[i * c + e] * b[j * c + e]).sum();
            for e in 0..c {
                conv[i * c + e] += k0 * b[j * c + e];
            }
            for e in 0..dim {
                grad[i * dim + e] += 2.0 * k1 * ab * d[e];
            }
            ab_abs[i] += ab.abs();
        }
    }
    (conv, grad, ab_abs)
}

/// Σ_t w_t/(σ_t√e): the scale of the gradient bound.
fn slope_scale(sigmas: &[f64], weights: &[f64]) -> f64 {
    sigmas.iter().zip(weights).map(|(s, w)| w / (s * std::f64::consts::E.sqrt())).sum()
}

#[test]
fn grid_sums_are_within_the_stated_bound() {
    let mut rng = SplitMix64(41);
    let profiles = [(vec![0.15], vec![1.0]), (vec![0.4], vec![1.0]), (vec![0.3, 0.12], vec![1.0, 0.6])];
    let mut largest_share: f64 = 0.0;
    for dim in [2, 3] {
        let clouds = [
            (uniform(400, dim, &mut rng), uniform(300, dim, &mut rng)),
            (clustered(350, dim, &mut rng), uniform(250, dim, &mut rng)),
        ];
        for (sigmas, weights) in &profiles {
            let base =
                Kernel::try_new(&Profile::Gaussians { sigmas: sigmas.clone(), weights: weights.clone() }).unwrap();
            // Order 4 needs a lattice σ/20 fine for 1e-6: not worth it.
            for (order, tol) in [(4, 1e-3), (6, 1e-3), (6, 1e-6), (8, 1e-4), (8, 1e-6)] {
                {
                    let h = base.grid_spacing(tol, order, dim).unwrap();
                    let grid = base.on_grid(h, order, dim).unwrap();
                    let bound = grid.grid().unwrap().bound();
                    assert!(bound.value <= tol * 1.001 && bound.gradient <= 10.0 * tol * 1.001, "{bound:?}");
                    for (x, y) in &clouds {
                        let c = 2;
                        let b: Vec<f64> = (0..y.len() / dim * c).map(|_| rng.range(-1.0, 1.0)).collect();
                        let a: Vec<f64> = (0..x.len() / dim * c).map(|_| rng.range(-1.0, 1.0)).collect();
                        let sums = KernelSums::try_new(&grid, y, dim).unwrap();
                        let (conv, grad) = sums.conv_and_grad(x, &a, b.as_slice(), c).unwrap();
                        let (conv0, grad0, ab_abs) = exact(&base, x, y, dim, &a, &b, c);
                        let k0 = base.value(0.0);
                        let b_abs: Vec<f64> =
                            (0..c).map(|e| b.iter().skip(e).step_by(c).map(|v| v.abs()).sum()).collect();
                        let name = format!("dim {dim} sigmas {sigmas:?} order {order} tol {tol:e}");
                        for i in 0..x.len() / dim {
                            for e in 0..c {
                                let err = (conv[i * c + e] - conv0[i * c + e]).abs();
                                let allowed = bound.value * k0 * b_abs[e];
                                assert!(
                                    err <= allowed * (1.0 + 1e-9) + 1e-13 * k0 * b_abs[e],
                                    "{name}: {err:e} > {allowed:e}"
                                );
                                largest_share = largest_share.max(err / allowed);
                            }
                            for e in 0..dim {
                                let err = (grad[i * dim + e] - grad0[i * dim + e]).abs();
                                let allowed = bound.gradient * slope_scale(sigmas, weights) * ab_abs[i];
                                assert!(
                                    err <= allowed * (1.0 + 1e-9) + 1e-12 * allowed.max(1e-300),
                                    "{name} gradient: {err:e} > {allowed:e}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }
    // The test measures an approximation: its errors are not rounding.
    assert!(largest_share > 1e-4, "largest error / bound {largest_share:e}");
}

#[test]
fn grid_derivatives_are_the_exact_derivatives_of_the_grid_sums() {
    // Central differences with h = 1e-6 (tests/kernels/derivatives.rs).
    const H: f64 = 1e-6;
    const TOL: f64 = 1e-6;
    let mut rng = SplitMix64(43);
    let base = Kernel::try_new(&Profile::Gaussians { sigmas: vec![0.35, 0.2], weights: vec![1.0, 0.5] }).unwrap();
    for dim in [2, 3] {
        for order in GRID_ORDERS {
            let k = base.on_grid(base.grid_spacing(1e-3, order, dim).unwrap(), order, dim).unwrap();
            let (n, m, c) = (30, 25, dim);
            let (x, y) = (uniform(n, dim, &mut rng), uniform(m, dim, &mut rng));
            let (a, b) = (random_direction(n * c, &mut rng), random_direction(m * c, &mut rng));
            let v = random_direction(x.len(), &mut rng);
            let name = format!("dim {dim} order {order}");
            // aᵀ K̃_xy b in x, and in y.
            let sums = KernelSums::try_new(&k, &y, dim).unwrap();
            let f = |xx: &[f64]| sums.conv(xx, &b, c).unwrap().iter().zip(&a).map(|(p, q)| p * q).sum::<f64>();
            let g = sums.grad_cross(&x, &a, &b, c).unwrap();
            let check = check_gradient(f, &x, &g, &v, H);
            assert!(check.rel_error < TOL, "{name} cross: {check:?}");
            // pᵀ K̃_xx p with both slots moving: twice grad_cross (K̃ symmetric).
            let p = random_direction(n * c, &mut rng);
            let f = |xx: &[f64]| {
                let s = KernelSums::try_new(&k, xx, dim).unwrap();
                s.conv(xx, &p, c).unwrap().iter().zip(&p).map(|(u, w)| u * w).sum::<f64>()
            };
            let g: Vec<f64> = KernelSums::try_new(&k, &x, dim)
                .unwrap()
                .grad_cross(&x, &p, &p, c)
                .unwrap()
                .iter()
                .map(|v| 2.0 * v)
                .collect();
            let check = check_gradient(f, &x, &g, &v, H);
            assert!(check.rel_error < TOL, "{name} self: {check:?}");
            // Jacobian–vector products, every input moving.
            let (dx, dy) = (random_direction(x.len(), &mut rng), random_direction(y.len(), &mut rng));
            let (da, db) = (random_direction(n * c, &mut rng), random_direction(m * c, &mut rng));
            let (nx, ny, na) = (x.len(), y.len(), n * c);
            let z: Vec<f64> = [&x[..], &y, &a, &b].concat();
            let dz: Vec<f64> = [&dx[..], &dy, &da, &db].concat();
            let split = |z: &[f64]| {
                let (x, r) = z.split_at(nx);
                let (y, r) = r.split_at(ny);
                let (a, b) = r.split_at(na);
                (x.to_vec(), y.to_vec(), a.to_vec(), b.to_vec())
            };
            let conv = |z: &[f64]| {
                let (x, y, _, b) = split(z);
                KernelSums::try_new(&k, &y, dim).unwrap().conv(&x, &b, c).unwrap()
            };
            let grad = |z: &[f64]| {
                let (x, y, a, b) = split(z);
                KernelSums::try_new(&k, &y, dim).unwrap().grad_cross(&x, &a, &b, c).unwrap()
            };
            let (jc, jg) = sums.conv_and_grad_jvp(&x, &dx, &dy, &a, &da, &b, &db, c).unwrap();
            let check = check_jvp(conv, &z, &dz, &jc, H);
            assert!(check.rel_error < TOL, "{name} conv_jvp: {check:?}");
            let check = check_jvp(grad, &z, &dz, &jg, H);
            assert!(check.rel_error < TOL, "{name} grad_cross_jvp: {check:?}");
            // The separate calls give the fused ones' values.
            assert_eq!(sums.conv_jvp(&x, &dx, &dy, &b, &db, c).unwrap(), jc);
            assert_eq!(sums.grad_cross_jvp(&x, &dx, &dy, &a, &da, &b, &db, c).unwrap(), jg);
        }
    }
}

/// Every grid operation on `pts` (self sums, as the shooting calls them).
fn all_outputs(k: &Kernel, pts: &[f64], p: &[f64], dp: &[f64], dx: &[f64], parallel: bool) -> Vec<Vec<f64>> {
    let dim = 3;
    let n = pts.len() / dim;
    let sums = KernelSums::try_new(k, pts, dim).unwrap().with_parallel(parallel);
    let mut ws = SumWorkspace::default();
    let (mut kp, mut gk) = (vec![0.0; n * dim], vec![0.0; n * dim]);
    sums.self_conv_and_grad_into(&mut ws, p, dim, &mut kp, &mut gk).unwrap();
    let (mut jkp, mut jgk) = (vec![0.0; n * dim], vec![0.0; n * dim]);
    sums.self_conv_and_grad_jvp_into(&mut ws, dx, p, dp, dim, &mut jkp, &mut jgk).unwrap();
    vec![kp, gk, jkp, jgk, sums.conv(pts, p, dim).unwrap()]
}

#[test]
fn grid_sums_are_the_same_bits_serial_parallel_and_on_any_number_of_threads() {
    let mut rng = SplitMix64(44);
    let k = Kernel::gaussian(0.1).unwrap();
    let k = k.on_grid(k.grid_spacing(1e-6, 6, 3).unwrap(), 6, 3).unwrap();
    let n = 3000;
    let pts =
        clustered(n, 3, &mut rng).iter().zip(uniform(n, 3, &mut rng)).map(|(a, b)| 0.5 * a + b).collect::<Vec<_>>();
    let (p, dp, dx) =
        (random_direction(3 * n, &mut rng), random_direction(3 * n, &mut rng), random_direction(3 * n, &mut rng));
    let serial = all_outputs(&k, &pts, &p, &dp, &dx, false);
    for threads in [1, 2, 3, 5] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let parallel = pool.install(|| all_outputs(&k, &pts, &p, &dp, &dx, true));
        assert!(serial == parallel, "{threads} threads");
    }
    // The self sums are the general sums at x = y.
    let sums = KernelSums::try_new(&k, &pts, 3).unwrap();
    let (conv, grad) = sums.conv_and_grad(&pts, &p, &p, 3).unwrap();
    assert!(conv == serial[0] && grad == serial[1]);
}

#[test]
fn the_grid_kernel_is_invariant_under_lattice_translations_symmetric_and_positive() {
    let mut rng = SplitMix64(45);
    let base = Kernel::gaussian(0.3).unwrap();
    for dim in [2, 3] {
        let h = base.grid_spacing(1e-4, 6, dim).unwrap();
        let k = base.on_grid(h, 6, dim).unwrap();
        let (x, y) = (uniform(40, dim, &mut rng), uniform(35, dim, &mut rng));
        let b = random_direction(35, &mut rng);
        let out = KernelSums::try_new(&k, &y, dim).unwrap().conv(&x, &b, 1).unwrap();
        // Moved by a lattice vector, the sums are the same: the lattice, not
        // the points, fixes the kernel.
        let shift = |v: &[f64]| {
            v.chunks_exact(dim)
                .flat_map(|p| p.iter().enumerate().map(|(e, c)| c + (e as f64 + 3.0) * 7.0 * h))
                .collect::<Vec<_>>()
        };
        let (xs, ys) = (shift(&x), shift(&y));
        let moved = KernelSums::try_new(&k, &ys, dim).unwrap().conv(&xs, &b, 1).unwrap();
        for (u, v) in out.iter().zip(&moved) {
            assert!((u - v).abs() <= 1e-12 * b.iter().map(|v| v.abs()).sum::<f64>(), "dim {dim}: {u} {v}");
        }
        // k̃(x_i, y_j) = k̃(y_j, x_i): aᵀK̃_xy b = bᵀK̃_yx a.
        let a = random_direction(40, &mut rng);
        let ab: f64 = out.iter().zip(&a).map(|(u, v)| u * v).sum();
        let ba: f64 =
            KernelSums::try_new(&k, &x, dim).unwrap().conv(&y, &a, 1).unwrap().iter().zip(&b).map(|(u, v)| u * v).sum();
        assert!((ab - ba).abs() <= 1e-12 * ab.abs().max(1.0), "dim {dim}: {ab} {ba}");
        // Positive semi-definite: bᵀK̃b ≥ 0 for random b on clustered points,
        // where the exact Gram matrix is nearly singular.
        let z = clustered(60, dim, &mut rng);
        let sums = KernelSums::try_new(&k, &z, dim).unwrap();
        for _ in 0..20 {
            let w = random_direction(60, &mut rng);
            let q: f64 = sums.conv(&z, &w, 1).unwrap().iter().zip(&w).map(|(u, v)| u * v).sum();
            assert!(q >= -1e-12 * w.iter().map(|v| v * v).sum::<f64>(), "dim {dim}: {q}");
        }
    }
}

#[test]
fn the_grid_path_refuses_what_it_cannot_sum() {
    let cauchy = Kernel::try_new(&Profile::Cauchy { sigma: 0.3 }).unwrap();
    assert_eq!(cauchy.on_grid(0.1, 6, 3), Err(KernelError::GridProfile));
    let k = Kernel::gaussian(0.3).unwrap();
    assert_eq!(k.on_grid(0.1, 3, 3), Err(KernelError::GridOrder { order: 3 }));
    assert_eq!(k.on_grid(0.1, 5, 3), Err(KernelError::GridOrder { order: 5 }));
    assert_eq!(k.on_grid(0.1, 9, 3), Err(KernelError::GridOrder { order: 9 }));
    assert_eq!(k.on_grid(-0.1, 6, 3), Err(KernelError::Width { sigma: -0.1 }));
    assert_eq!(k.on_grid(0.1, 6, 4), Err(KernelError::PointDimension { found: 4 }));
    assert!(matches!(k.grid_spacing(2.0, 6, 3), Err(KernelError::Tolerance { .. })));
    let g = k.on_grid(0.1, 6, 3).unwrap();
    let y = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    let sums = KernelSums::try_new(&g, &y, 3).unwrap();
    assert_eq!(sums.conv(&[0.5; 3], &[1.0; 10], 5), Err(KernelError::GridChannels { found: 5, max: 4 }));
    // Points a million lattice steps apart in every axis: no window that size.
    let far = [0.0, 0.0, 0.0, 1e5, 1e5, 1e5];
    let sums = KernelSums::try_new(&g, &far, 3).unwrap();
    assert!(matches!(sums.conv(&far, &[1.0, 1.0], 1), Err(KernelError::GridTooLarge { .. })));
    // A truncated kernel put on a grid loses its taper; a grid kernel
    // truncated loses its grid.
    let t = k.truncated(1e-6).unwrap().on_grid(0.1, 6, 3).unwrap();
    assert!(t.taper().is_none() && t.grid().is_some());
    assert!(g.truncated(1e-6).unwrap().grid().is_none());
}

#[test]
fn the_cheapest_path_within_the_tolerance_is_chosen_for_the_points() {
    use fshape_kernels::SumPath;
    let mut rng = SplitMix64(46);
    let gaussian = |s: f64| Kernel::gaussian(s).unwrap();
    // Exact means exact, whatever the points.
    let many = uniform(20_000, 3, &mut rng);
    assert_eq!(gaussian(0.3).for_points(&many, 3).unwrap().path(), SumPath::Exact);
    // Wide against the spacing of many points: the grid, within τ.
    let wide = gaussian(0.3).truncated(1e-6).unwrap().for_points(&many, 3).unwrap();
    let Some(grid) = wide.grid() else { panic!("{}", wide.path()) };
    assert!(grid.bound().value <= 1e-6 && wide.tolerance() == Some(1e-6), "{}", wide.path());
    // Narrow: truncation keeps few pairs.
    let narrow = gaussian(0.01).truncated(1e-6).unwrap().for_points(&many, 3).unwrap();
    assert!(matches!(narrow.path(), SumPath::Truncated { .. }), "{}", narrow.path());
    // Few points: pairs are cheaper than a lattice.
    let few = uniform(150, 3, &mut rng);
    let small = gaussian(0.3).truncated(1e-6).unwrap().for_points(&few, 3).unwrap();
    assert!(small.grid().is_none(), "{}", small.path());
    // Planar points too; and the choice is a function of its inputs.
    let plane = uniform(20_000, 2, &mut rng);
    let k = gaussian(0.2).truncated(1e-6).unwrap();
    let (a, b) = (k.for_points(&plane, 2).unwrap(), k.for_points(&plane, 2).unwrap());
    assert!(a.grid().is_some() && a == b, "{}", a.path());
    // Cauchy kernels have no grid path: truncated as asked.
    let cauchy = Kernel::try_new(&Profile::Cauchy { sigma: 0.3 }).unwrap().truncated(1e-6).unwrap();
    assert!(matches!(cauchy.for_points(&many, 3).unwrap().path(), SumPath::Truncated { .. }));
}
