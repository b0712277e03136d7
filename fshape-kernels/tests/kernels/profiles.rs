//! Profiles: values, derivatives, validation, and the taper.

use fshape_kernels::{Kernel, KernelError, Profile, TAPER_WIDTH};

use crate::kernels;

#[test]
fn hand_checked_values() {
    let g = Kernel::gaussian(0.5).unwrap();
    // u = 2σ² = 0.5 gives e^{-1}.
    assert!((g.value(0.5) - (-1.0f64).exp()).abs() < 1e-16);
    let c = Kernel::try_new(&Profile::Cauchy { sigma: 2.0 }).unwrap();
    assert_eq!(c.value(4.0), 0.5);
    let s = Kernel::try_new(&Profile::Gaussians { sigmas: vec![1.0, 2.0], weights: vec![1.0, 3.0] }).unwrap();
    assert_eq!(s.value(0.0), 4.0);
}

#[test]
fn derivatives_match_central_differences() {
    // h = 1e-6 on u of order 0.01–1: truncation ~1e-12, rounding ~1e-10.
    let h = 1e-6;
    for (name, k) in kernels() {
        let r = k.support_radius().unwrap_or(2.0);
        for t in [0.0, 0.05, 0.3, 0.6, 0.79, 0.85, 0.9, 0.97] {
            let u = (t * r).powi(2) + 1e-3; // inside, in and past the taper
            let [_, d1, d2] = k.derivatives(u);
            let fd1 = (k.value(u + h) - k.value(u - h)) / (2.0 * h);
            let fd2 = (k.derivatives(u + h)[1] - k.derivatives(u - h)[1]) / (2.0 * h);
            // Relative to the derivative's own size, with a floor for
            // points where it vanishes (beyond the support).
            let ok = |a: f64, b: f64, floor: f64| (a - b).abs() <= 1e-6 * a.abs().max(b.abs()) + floor;
            let k0 = k.value(0.0);
            assert!(ok(d1, fd1, 1e-9 * k0), "{name} k' at u = {u}: {d1} vs {fd1}");
            assert!(ok(d2, fd2, 1e-9 * k0), "{name} k'' at u = {u}: {d2} vs {fd2}");
        }
    }
}

#[test]
fn the_taper_is_c2_and_bounded_by_the_tolerance() {
    for tol in [1e-3, 1e-6, 1e-9] {
        for (name, base) in kernels().into_iter().filter(|(_, k)| k.taper().is_none()) {
            let k = base.truncated(tol).unwrap();
            let t = k.taper().unwrap();
            let k0 = base.value(0.0);
            // The taper starts where the kernel reaches τ·k(0).
            assert!((base.value(t.u_in) - tol * k0).abs() <= 1e-9 * tol * k0, "{name}");
            assert!((t.u_out.sqrt() / t.u_in.sqrt() - (1.0 + TAPER_WIDTH)).abs() < 1e-12);
            // Inside: unchanged. Beyond u_in: |k_t − k| ≤ k ≤ τ k(0). Beyond u_out: 0.
            assert_eq!(k.derivatives(0.5 * t.u_in), base.derivatives(0.5 * t.u_in));
            for s in 0..=20 {
                let u = t.u_in + (t.u_out - t.u_in) * s as f64 / 20.0;
                assert!((k.value(u) - base.value(u)).abs() <= tol * k0 * (1.0 + 1e-12), "{name}");
            }
            assert_eq!(k.derivatives(t.u_out * 1.0001), [0.0; 3]);
            // C²: value, k' and k'' continuous across both ends of the taper.
            for u in [t.u_in, t.u_out] {
                let e = 1e-9 * u;
                let (lo, hi) = (k.derivatives(u - e), k.derivatives(u + e));
                let scales = [k0, k0 / u, k0 / (u * u)];
                for d in 0..3 {
                    assert!(
                        (lo[d] - hi[d]).abs() <= 1e-6 * scales[d],
                        "{name} τ={tol}: derivative {d} jumps at u = {u}: {lo:?} {hi:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn bad_parameters_are_refused() {
    for sigma in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(Kernel::gaussian(sigma), Err(KernelError::Width { .. })));
        assert!(matches!(Kernel::try_new(&Profile::Cauchy { sigma }), Err(KernelError::Width { .. })));
    }
    let bad = |sigmas: Vec<f64>, weights: Vec<f64>| Kernel::try_new(&Profile::Gaussians { sigmas, weights });
    assert!(matches!(bad(vec![1.0], vec![1.0, 2.0]), Err(KernelError::Weights { widths: 1, weights: 2 })));
    assert!(matches!(bad(vec![], vec![]), Err(KernelError::Weights { .. })));
    assert!(matches!(bad(vec![1.0, 2.0], vec![0.0, 0.0]), Err(KernelError::WeightValue { .. })));
    assert!(matches!(bad(vec![1.0], vec![f64::NAN]), Err(KernelError::WeightValue { .. })));
    assert!(matches!(bad(vec![1.0], vec![-1.0]), Err(KernelError::WeightValue { .. })));
    let g = Kernel::gaussian(1.0).unwrap();
    for tol in [0.0, 1.0, -0.1, f64::NAN] {
        assert!(matches!(g.truncated(tol), Err(KernelError::Tolerance { .. })));
    }
    // The Gaussian's truncation radius: σ √(2 ln(1/τ)).
    let t = Kernel::gaussian(0.3).unwrap().truncated(1e-6).unwrap().taper().unwrap();
    assert!((t.u_in.sqrt() - 0.3 * (2.0 * 1e6f64.ln()).sqrt()).abs() < 1e-12);
}

#[test]
fn lane_values_and_slopes_match_the_scalar_profile() {
    use fshape_kernels::lanes::L;
    for (name, k) in crate::kernels() {
        let top = k.taper().map_or(30.0, |t| 1.2 * t.u_out);
        let us: Vec<f64> = (0..4 * L).map(|i| top * (i as f64 / (4 * L - 1) as f64).powi(2)).collect();
        for chunk in us.chunks(L) {
            let u: [f64; L] = chunk.try_into().unwrap();
            let (k0, k1) = k.lanes(&u, true);
            for l in 0..L {
                let d = k.derivatives(u[l]);
                // A few ulps of k(0) and of |k'(0)|, the scales of the values.
                let (s0, s1) = (k.value(0.0), k.derivatives(0.0)[1].abs());
                assert!((k0[l] - d[0]).abs() <= 1e-15 * s0, "{name}: k({}) = {} vs {}", u[l], k0[l], d[0]);
                assert!((k1[l] - d[1]).abs() <= 1e-15 * s1, "{name}: k'({}) = {} vs {}", u[l], k1[l], d[1]);
            }
        }
    }
}
