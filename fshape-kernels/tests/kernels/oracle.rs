//! Every fast path against a brute-force double loop, on uniform, clustered
//! and degenerate inputs; the truncation bound; symmetry; PSD; serial =
//! parallel.

use fshape_kernels::{BlockPairs, Kernel, KernelSums, Precision, RunSearch};
use fshape_mesh::generate::SplitMix64;
use proptest::prelude::*;

use crate::{clustered, kernels, uniform};

/// The obvious double loop, with the kernel's scalar value.
fn brute(k: &Kernel, x: &[f64], y: &[f64], dim: usize, b: &[f64], bdim: usize) -> Vec<f64> {
    let (nx, ny) = (x.len() / dim, y.len() / dim);
    let mut out = vec![0.0; nx * bdim];
    for i in 0..nx {
        for j in 0..ny {
            let u: f64 = (0..dim).map(|c| (x[i * dim + c] - y[j * dim + c]).powi(2)).sum();
            for c in 0..bdim {
                out[i * bdim + c] += k.value(u) * b[j * bdim + c];
            }
        }
    }
    out
}

/// k(0) Σ_j |b_j|: a bound on Σ_j |k(u_ij) b_j| (every profile here is
/// maximal at 0), the scale rounding errors are relative to.
fn magnitude(k: &Kernel, b: &[f64]) -> f64 {
    k.value(0.0) * b.iter().map(|v| v.abs()).sum::<f64>()
}

fn cases(seed: u64) -> Vec<(usize, Vec<f64>, Vec<f64>)> {
    let mut rng = SplitMix64(seed);
    let mut out = Vec::new();
    for dim in [2, 3] {
        out.push((dim, uniform(37, dim, &mut rng), uniform(53, dim, &mut rng)));
        out.push((dim, clustered(41, dim, &mut rng), clustered(29, dim, &mut rng)));
        out.push((dim, uniform(1, dim, &mut rng), uniform(17, dim, &mut rng))); // N = 1
        out.push((dim, uniform(5, dim, &mut rng), Vec::new())); // M = 0
        let same = uniform(1, dim, &mut rng);
        out.push((dim, same.repeat(6), same.repeat(9))); // all points equal
    }
    out
}

proptest! {
    #![proptest_config(fshape_mesh::test_support::strategies::config(12, 1234))]

    #[test]
    fn conv_matches_the_brute_force_oracle(seed in any::<u64>(), bdim in 1usize..4) {
        for (name, k) in kernels() {
            for (dim, x, y) in cases(seed) {
                let mut rng = SplitMix64(seed ^ 7);
                let b: Vec<f64> = (0..y.len() / dim * bdim).map(|_| rng.range(-1.0, 1.0)).collect();
                let sums = KernelSums::try_new(&k, &y, dim).unwrap();
                let fast = sums.conv(&x, &b, bdim).unwrap();
                let slow = brute(&k, &x, &y, dim, &b, bdim);
                let scale = magnitude(&k, &b);
                for i in 0..fast.len() {
                    // Different summation order (and wide's exp on the
                    // vectorised path): a few ulps per term.
                    prop_assert!((fast[i] - slow[i]).abs() <= 1e-14 * scale, "{} dim {}: {} vs {}", name, dim, fast[i], slow[i]);
                }
            }
        }
    }
}

#[test]
fn truncation_error_is_within_the_stated_bound() {
    let mut rng = SplitMix64(99);
    for dim in [2, 3] {
        let x = uniform(300, dim, &mut rng);
        let b: Vec<f64> = (0..300).map(|_| rng.range(-1.0, 1.0)).collect();
        for tol in [1e-3, 1e-6, 1e-9] {
            for (name, base) in kernels().into_iter().filter(|(_, k)| k.taper().is_none()) {
                let trunc = base.truncated(tol).unwrap();
                let exact = KernelSums::try_new(&base, &x, dim).unwrap().conv(&x, &b, 1).unwrap();
                let approx = KernelSums::try_new(&trunc, &x, dim).unwrap().conv(&x, &b, 1).unwrap();
                let u_in = trunc.taper().unwrap().u_in;
                for i in 0..300 {
                    // Σ |b_j| over the j the truncation changes (u ≥ u_in).
                    let changed: f64 = (0..300)
                        .filter(|&j| (0..dim).map(|c| (x[i * dim + c] - x[j * dim + c]).powi(2)).sum::<f64>() >= u_in)
                        .map(|j| b[j].abs())
                        .sum();
                    let bound = tol * base.value(0.0) * changed;
                    // Plus rounding: the two paths sum 300 terms in different
                    // orders, a few ulps of Σ |k b_j| ≤ k(0) Σ |b_j|.
                    let rounding = 1e-14 * base.value(0.0) * b.iter().map(|v| v.abs()).sum::<f64>();
                    prop_assert_bound((approx[i] - exact[i]).abs(), bound * (1.0 + 1e-9) + rounding, &name);
                }
            }
        }
    }
}

fn prop_assert_bound(err: f64, bound: f64, name: &str) {
    assert!(err <= bound, "{name}: error {err:e} above the bound {bound:e}");
}

#[test]
fn cross_sums_are_symmetric_and_gram_matrices_psd() {
    let mut rng = SplitMix64(5);
    for (name, k) in kernels() {
        let (x, y) = (uniform(40, 3, &mut rng), uniform(30, 3, &mut rng));
        let a: Vec<f64> = (0..40).map(|_| rng.range(-1.0, 1.0)).collect();
        let b: Vec<f64> = (0..30).map(|_| rng.range(-1.0, 1.0)).collect();
        // aᵀ (K_xy b) = bᵀ (K_yx a).
        let kb = KernelSums::try_new(&k, &y, 3).unwrap().conv(&x, &b, 1).unwrap();
        let ka = KernelSums::try_new(&k, &x, 3).unwrap().conv(&y, &a, 1).unwrap();
        let (l, r): (f64, f64) =
            (a.iter().zip(&kb).map(|(u, v)| u * v).sum(), b.iter().zip(&ka).map(|(u, v)| u * v).sum());
        assert!((l - r).abs() <= 1e-13 * (l.abs() + 1.0), "{name}");
        // vᵀ K_xx v ≥ 0 for the (positive definite) untruncated kernels; the
        // taper is not a positive definite function, so a truncated Gram
        // matrix may dip below zero by up to τ k(0) Σ|v|².
        if k.taper().is_none() {
            for _ in 0..20 {
                let v: Vec<f64> = (0..40).map(|_| rng.range(-1.0, 1.0)).collect();
                let kv = KernelSums::try_new(&k, &x, 3).unwrap().conv(&x, &v, 1).unwrap();
                let q: f64 = v.iter().zip(&kv).map(|(u, w)| u * w).sum();
                assert!(q >= -1e-12, "{name}: vᵀKv = {q}");
            }
        }
    }
}

#[test]
fn serial_and_parallel_are_bitwise_equal() {
    let mut rng = SplitMix64(8);
    let x = uniform(500, 3, &mut rng);
    let p: Vec<f64> = (0..1500).map(|_| rng.range(-1.0, 1.0)).collect();
    for (_, k) in kernels() {
        let par = KernelSums::try_new(&k, &x, 3).unwrap();
        let ser = KernelSums::try_new(&k, &x, 3).unwrap().with_parallel(false);
        assert_eq!(par.conv(&x, &p, 3).unwrap(), ser.conv(&x, &p, 3).unwrap());
        assert_eq!(par.grad_cross(&x, &p, &p, 3).unwrap(), ser.grad_cross(&x, &p, &p, 3).unwrap());
        let (par, ser) = (par.with_precision(Precision::MixedF32), ser.with_precision(Precision::MixedF32));
        assert_eq!(par.conv(&x, &p, 3).unwrap(), ser.conv(&x, &p, 3).unwrap());
    }
}

#[test]
fn bad_points_are_refused() {
    let k = Kernel::gaussian(1.0).unwrap();
    assert!(KernelSums::try_new(&k, &[0.0, f64::NAN, 0.0], 3).is_err());
    assert!(KernelSums::try_new(&k, &[0.0; 4], 3).is_err());
    assert!(KernelSums::try_new(&k, &[0.0; 4], 4).is_err());
    let s = KernelSums::try_new(&k, &[0.0; 6], 3).unwrap();
    let e = s.conv(&[0.0, 0.0, f64::INFINITY], &[1.0, 1.0], 1).unwrap_err();
    assert!(e.to_string().contains("target point 0"), "{e}");
    assert!(s.conv(&[0.0; 3], &[1.0], 1).is_err(), "b of the wrong length");
}

#[test]
fn both_spatial_indexes_match_the_oracle() {
    use fshape_kernels::{Profile, SpatialIndex};
    let mut rng = SplitMix64(31);
    // Kernels the vectorised block path does not take, so that the
    // per-pair engine and its spatial index serve them: a Cauchy kernel
    // and a sum of five Gaussians (the block path takes up to four).
    let five =
        Profile::Gaussians { sigmas: vec![0.02, 0.03, 0.04, 0.05, 0.06], weights: vec![1.0, 0.5, 0.3, 0.2, 0.1] };
    let kernels = [
        ("Cauchy", Kernel::try_new(&Profile::Cauchy { sigma: 0.01 }).unwrap().truncated(1e-2).unwrap()),
        ("five Gaussians", Kernel::try_new(&five).unwrap().truncated(1e-6).unwrap()),
    ];
    for dim in [2, 3] {
        let (x, y) = (clustered(200, dim, &mut rng), uniform(300, dim, &mut rng));
        let b: Vec<f64> = (0..300).map(|_| rng.range(-1.0, 1.0)).collect();
        let a: Vec<f64> = (0..200).map(|_| rng.range(-1.0, 1.0)).collect();
        for (name, k) in &kernels {
            let radius = k.support_radius().unwrap();
            assert!(radius < 0.5, "{name}: a support radius of {radius} would keep every pair");
            let slow = brute(k, &x, &y, dim, &b, 1);
            // Σ_j 2 k'(u)(a_i b_j)(x_i − y_j), from the profile's derivative.
            let mut slow_grad = vec![0.0; 200 * dim];
            for i in 0..200 {
                for j in 0..300 {
                    let d: Vec<f64> = (0..dim).map(|c| x[i * dim + c] - y[j * dim + c]).collect();
                    let u: f64 = d.iter().map(|v| v * v).sum();
                    for c in 0..dim {
                        slow_grad[i * dim + c] += 2.0 * k.derivatives(u)[1] * a[i] * b[j] * d[c];
                    }
                }
            }
            let grad_scale = slow_grad.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for index in [SpatialIndex::Kiddo, SpatialIndex::Obvhs] {
                let sums = KernelSums::try_new(k, &y, dim).unwrap().with_index(index);
                assert_eq!(sums.spatial_index_built(), None, "built before any sum");
                let fast = sums.conv(&x, &b, 1).unwrap();
                // The path this test is for: fails if these sums move to
                // another engine or index.
                assert_eq!(sums.spatial_index_built(), Some(index), "{name}, dim {dim}: conv did not use {index:?}");
                for i in 0..200 {
                    assert!((fast[i] - slow[i]).abs() <= 1e-14 * magnitude(k, &b), "{name}, {index:?}, dim {dim}");
                }
                let sums = KernelSums::try_new(k, &y, dim).unwrap().with_index(index);
                let grad = sums.grad_cross(&x, &a, &b, 1).unwrap();
                assert_eq!(
                    sums.spatial_index_built(),
                    Some(index),
                    "{name}, dim {dim}: grad_cross did not use {index:?}"
                );
                for (g, s) in grad.iter().zip(&slow_grad) {
                    assert!((g - s).abs() <= 1e-13 * grad_scale, "{name}, {index:?}, dim {dim}: {g} vs {s}");
                }
            }
        }
        // The block path builds no index: a truncated Gaussian is summed by
        // blocks whatever index is asked for.
        let g = Kernel::gaussian(0.08).unwrap().truncated(1e-6).unwrap();
        let sums = KernelSums::try_new(&g, &y, dim).unwrap().with_index(SpatialIndex::Kiddo);
        sums.conv(&x, &b, 1).unwrap();
        assert_eq!(sums.spatial_index_built(), None, "dim {dim}");
    }
}

#[test]
fn cross_gradient_matches_the_brute_force_oracle() {
    let mut rng = SplitMix64(77);
    for (name, k) in kernels() {
        for (dim, x, y) in cases(3) {
            let bdim = dim;
            let (nx, ny) = (x.len() / dim, y.len() / dim);
            let a: Vec<f64> = (0..nx * bdim).map(|_| rng.range(-1.0, 1.0)).collect();
            let b: Vec<f64> = (0..ny * bdim).map(|_| rng.range(-1.0, 1.0)).collect();
            let sums = KernelSums::try_new(&k, &y, dim).unwrap();
            let fast = sums.grad_cross(&x, &a, &b, bdim).unwrap();
            // The fused pass sums the same terms in the same order.
            let conv = sums.conv(&x, &b, bdim).unwrap();
            assert_eq!(sums.conv_and_grad(&x, &a, &b, bdim).unwrap(), (conv, fast.clone()), "{name}");
            // Σ_j 2 k'(u)(a_i·b_j)(x_i − y_j), the obvious double loop.
            let mut slow = vec![0.0; nx * dim];
            let mut scale: f64 = 0.0;
            for i in 0..nx {
                for j in 0..ny {
                    let d: Vec<f64> = (0..dim).map(|c| x[i * dim + c] - y[j * dim + c]).collect();
                    let u: f64 = d.iter().map(|v| v * v).sum();
                    let ab: f64 = (0..bdim).map(|c| a[i * bdim + c] * b[j * bdim + c]).sum();
                    let s = 2.0 * k.derivatives(u)[1] * ab;
                    for c in 0..dim {
                        slow[i * dim + c] += s * d[c];
                        scale = scale.max((s * d[c]).abs());
                    }
                }
            }
            for (p, q) in fast.iter().zip(&slow) {
                assert!((p - q).abs() <= 1e-13 * scale * ny.max(1) as f64, "{name} dim {dim}: {p} vs {q}");
            }
        }
    }
}

#[test]
fn jacobian_vector_products_match_the_brute_force_oracle() {
    let mut rng = SplitMix64(78);
    for (name, k) in kernels() {
        for (dim, x, y) in cases(4) {
            let bd = dim;
            let (nx, ny) = (x.len() / dim, y.len() / dim);
            let mut r = |n: usize| -> Vec<f64> { (0..n).map(|_| rng.range(-1.0, 1.0)).collect() };
            let (dx, dy, a, da, b, db) = (r(x.len()), r(y.len()), r(nx * bd), r(nx * bd), r(ny * bd), r(ny * bd));
            let sums = KernelSums::try_new(&k, &y, dim).unwrap();
            let cj = sums.conv_jvp(&x, &dx, &dy, &b, &db, bd).unwrap();
            let gj = sums.grad_cross_jvp(&x, &dx, &dy, &a, &da, &b, &db, bd).unwrap();
            // The formulas of the docs, as an obvious double loop.
            let (mut cs, mut gs) = (vec![0.0; nx * bd], vec![0.0; nx * dim]);
            let mut scale: f64 = 1e-300;
            for i in 0..nx {
                for j in 0..ny {
                    let d: Vec<f64> = (0..dim).map(|c| x[i * dim + c] - y[j * dim + c]).collect();
                    let dd: Vec<f64> = (0..dim).map(|c| dx[i * dim + c] - dy[j * dim + c]).collect();
                    let u: f64 = d.iter().map(|v| v * v).sum();
                    let du: f64 = 2.0 * d.iter().zip(&dd).map(|(p, q)| p * q).sum::<f64>();
                    let [k0, k1, k2] = k.derivatives(u);
                    let ab: f64 = (0..bd).map(|c| a[i * bd + c] * b[j * bd + c]).sum();
                    let dab: f64 =
                        (0..bd).map(|c| da[i * bd + c] * b[j * bd + c] + a[i * bd + c] * db[j * bd + c]).sum();
                    for c in 0..bd {
                        let t = k1 * du * b[j * bd + c] + k0 * db[j * bd + c];
                        cs[i * bd + c] += t;
                        scale = scale.max(t.abs());
                    }
                    for c in 0..dim {
                        let t = 2.0 * k2 * du * ab * d[c] + 2.0 * k1 * dab * d[c] + 2.0 * k1 * ab * dd[c];
                        gs[i * dim + c] += t;
                        scale = scale.max(t.abs());
                    }
                }
            }
            let tol = 1e-13 * scale * ny.max(1) as f64;
            assert!(cj.iter().zip(&cs).all(|(p, q)| (p - q).abs() <= tol), "{name} conv_jvp dim {dim}");
            assert!(gj.iter().zip(&gs).all(|(p, q)| (p - q).abs() <= tol), "{name} grad_cross_jvp dim {dim}");
            // The fused pass sums the same terms in the same order.
            assert_eq!(sums.conv_and_grad_jvp(&x, &dx, &dy, &a, &da, &b, &db, bd).unwrap(), (cj, gj), "{name}");
        }
    }
}

#[test]
fn block_pairs_hand_every_pair_within_the_support_to_its_target_once() {
    for (name, k) in kernels() {
        for (case, (dim, x, y)) in cases(11).into_iter().enumerate() {
            // Larger sets too, so that there are several blocks of each.
            let mut rng = SplitMix64(case as u64);
            let (x, y) = if case == 0 { (uniform(300, dim, &mut rng), uniform(400, dim, &mut rng)) } else { (x, y) };
            for search in [RunSearch::AllBlocks, RunSearch::Bvh] {
                let pairs = BlockPairs::try_new_with_search(&x, &y, dim, &k, search).unwrap();
                assert_eq!(pairs.used_bvh(), search == RunSearch::Bvh && k.taper().is_some(), "{name}, case {case}");
                let order = pairs.source_order();
                let (nx, ny) = (x.len() / dim, y.len() / dim);
                let mut seen = vec![vec![0u32; ny]; nx]; // visits of each pair (i, j)
                let mut untapered_ok = true;
                let u =
                    |i: usize, j: usize| -> f64 { (0..dim).map(|c| (x[i * dim + c] - y[j * dim + c]).powi(2)).sum() };
                let visits = pairs.map_blocks(true, |targets, runs| {
                    let mut v = Vec::new();
                    for &i in targets {
                        for run in runs {
                            for &j in &order[run.range.clone()] {
                                v.push((i, j, run.tapered));
                            }
                        }
                    }
                    v
                });
                for (i, j, tapered) in visits.into_iter().flatten() {
                    seen[i][j] += 1;
                    if let (Some(t), false) = (k.taper(), tapered) {
                        untapered_ok &= u(i, j) <= t.u_in;
                    }
                }
                assert!(untapered_ok, "{name}, case {case}: an untapered run holds a pair beyond u_in");
                for (i, row) in seen.iter().enumerate() {
                    for (j, &count) in row.iter().enumerate() {
                        let needed = k.support_radius().is_none_or(|r| u(i, j) < r * r);
                        assert!(count <= 1, "{name}, case {case}: pair ({i}, {j}) visited twice");
                        assert!(
                            !needed || count == 1,
                            "{name}, case {case}: pair ({i}, {j}) within the support is missed"
                        );
                    }
                }
            }
        }
    }
}

/// Every target block's (targets, runs), as `BlockPairs` hands them out.
fn all_runs(pairs: &fshape_kernels::BlockPairs) -> Vec<(Vec<usize>, Vec<fshape_kernels::SourceRun>)> {
    pairs.map_blocks(false, |targets, runs| (targets.to_vec(), runs.to_vec()))
}

proptest! {
    #![proptest_config(fshape_mesh::test_support::strategies::config(24, 4321))]

    /// The BVH finds exactly the runs a scan of every source block finds
    /// (so every sum has the same bits), on random sets of many blocks:
    /// uniform or clustered, in the plane or in space, narrow or wide kernels.
    #[test]
    fn the_bvh_finds_the_runs_of_the_scan(seed in any::<u64>(), nx in 1usize..3000, ny in 1usize..6000,
                                          sigma in 0.002f64..0.3, dim in 2usize..4, clusters in any::<bool>()) {
        let mut rng = SplitMix64(seed);
        let draw = |n, rng: &mut SplitMix64| if clusters { clustered(n, dim, rng) } else { uniform(n, dim, rng) };
        let (x, y) = (draw(nx, &mut rng), draw(ny, &mut rng));
        let k = Kernel::gaussian(sigma).unwrap().truncated(1e-6).unwrap();
        let scan = BlockPairs::try_new_with_search(&x, &y, dim, &k, RunSearch::AllBlocks).unwrap();
        let bvh = BlockPairs::try_new_with_search(&x, &y, dim, &k, RunSearch::Bvh).unwrap();
        prop_assert!(bvh.used_bvh() && !scan.used_bvh());
        prop_assert_eq!(scan.source_order(), bvh.source_order());
        prop_assert!(all_runs(&scan) == all_runs(&bvh));
    }
}

/// `RunSearch::Auto` scans the source blocks of small sets and takes the
/// BVH from 256 blocks (16384 sources) on, with the same runs.
#[test]
fn auto_search_takes_the_bvh_for_many_blocks() {
    let mut rng = SplitMix64(5);
    let k = Kernel::gaussian(0.02).unwrap().truncated(1e-6).unwrap();
    for (ny, bvh) in [(16_320, false), (16_384, true)] {
        let (x, y) = (uniform(2000, 3, &mut rng), uniform(ny, 3, &mut rng));
        let auto = BlockPairs::try_new(&x, &y, 3, &k).unwrap();
        assert_eq!(auto.used_bvh(), bvh, "{ny} sources");
        let scan = BlockPairs::try_new_with_search(&x, &y, 3, &k, RunSearch::AllBlocks).unwrap();
        assert!(all_runs(&auto) == all_runs(&scan), "{ny} sources");
    }
    // An untapered kernel pairs every block: nothing to search.
    let exact = Kernel::gaussian(0.02).unwrap();
    let y = uniform(20_000, 3, &mut rng);
    assert!(!BlockPairs::try_new(&y, &y, 3, &exact).unwrap().used_bvh());
}

/// The `_into` sums with one workspace reused across kernels, dimensions
/// and point counts (growing and shrinking) give what fresh calls give, bit
/// for bit: nothing stale survives in the reused memory.
#[test]
fn a_reused_workspace_gives_the_results_of_fresh_calls() {
    use fshape_kernels::SumWorkspace;
    let mut rng = SplitMix64(77);
    let mut ws = SumWorkspace::default();
    for (name, k) in kernels() {
        for (dim, n) in [(3, 300), (2, 70), (3, 33), (3, 300)] {
            let x = clustered(n, dim, &mut rng);
            let mut r = |len: usize| -> Vec<f64> { (0..len).map(|_| rng.range(-1.0, 1.0)).collect() };
            let (dx, a, da) = (r(n * dim), r(n * dim), r(n * dim));
            let s = KernelSums::try_new(&k, &x, dim).unwrap();
            let (mut conv, mut grad) = (vec![0.0; n * dim], vec![0.0; n * dim]);
            s.conv_and_grad_into(&mut ws, &x, &a, &a, dim, &mut conv, &mut grad).unwrap();
            assert_eq!((conv.clone(), grad.clone()), s.conv_and_grad(&x, &a, &a, dim).unwrap(), "{name}");
            s.conv_and_grad_jvp_into(&mut ws, &x, &dx, &dx, &a, &da, &a, &da, dim, &mut conv, &mut grad).unwrap();
            let fresh = s.conv_and_grad_jvp(&x, &dx, &dx, &a, &da, &a, &da, dim).unwrap();
            assert_eq!((conv.clone(), grad.clone()), fresh, "{name}");
            let e = s.conv_and_grad_into(&mut ws, &x, &a, &a, dim, &mut conv[1..], &mut grad).unwrap_err();
            assert!(e.to_string().contains("conv output"), "{e}");
        }
    }
}

#[test]
fn self_sums_visiting_each_pair_once_match_the_general_sums() {
    // The symmetric path (exact sums of Gaussians: each pair once, its
    // mirror to the source) against conv_and_grad(_jvp) with x = y, a = b,
    // da = db, dx = dy, for point counts around the 16-lane blocks and past
    // the 8 chunks (300 points: 19 blocks), clustered points with exact
    // repeats, and every weight dimension. Truncated and Cauchy kernels take
    // the general path: the same bits.
    use fshape_kernels::SumWorkspace;
    let mut rng = SplitMix64(79);
    for (name, k) in kernels() {
        let general_only = name.contains("truncated") || name.contains("Cauchy");
        for dim in [2, 3] {
            for n in [1, 15, 16, 17, 41, 300] {
                let y = if n == 41 { clustered(n, dim, &mut rng) } else { uniform(n, dim, &mut rng) };
                for bd in 1..=3 {
                    let mut r = |n: usize| -> Vec<f64> { (0..n).map(|_| rng.range(-1.0, 1.0)).collect() };
                    let (dy, b, db) = (r(y.len()), r(n * bd), r(n * bd));
                    let sums = KernelSums::try_new(&k, &y, dim).unwrap();
                    let mut ws = SumWorkspace::default();
                    let (mut c, mut g) = (vec![0.0; n * bd], vec![0.0; n * dim]);
                    sums.self_conv_and_grad_into(&mut ws, &b, bd, &mut c, &mut g).unwrap();
                    let (mut cj, mut gj) = (vec![0.0; n * bd], vec![0.0; n * dim]);
                    sums.self_conv_and_grad_jvp_into(&mut ws, &dy, &b, &db, bd, &mut cj, &mut gj).unwrap();
                    let (c0, g0) = sums.conv_and_grad(&y, &b, &b, bd).unwrap();
                    let (cj0, gj0) = sums.conv_and_grad_jvp(&y, &dy, &dy, &b, &db, &b, &db, bd).unwrap();
                    for (what, fast, general) in
                        [("conv", &c, &c0), ("grad", &g, &g0), ("conv jvp", &cj, &cj0), ("grad jvp", &gj, &gj0)]
                    {
                        if general_only {
                            assert_eq!(fast, general, "{name} {what}");
                            continue;
                        }
                        // Another summation order: rounding relative to the
                        // largest output, times the terms per output.
                        let scale = general.iter().map(|v| v.abs()).fold(1e-300, f64::max);
                        let worst = fast.iter().zip(general.iter()).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max);
                        assert!(worst <= 1e-14 * scale * n as f64, "{name} dim {dim} n {n} bd {bd} {what}: {worst:e}");
                    }
                }
            }
        }
    }
}
