//! Several signal channels per vertex (f ∈ ℝᵏ: thickness, myelin,
//! curvature on one surface): the engine against the definition's double
//! sum, exact gradients, and one channel as the special case it must be.

use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, random_direction};
use fshape_varifold::{Attachment, CellFeatures, SignalKernel, VarifoldError, VarifoldKernel, inner_product};

use crate::masks::{brute_masked, masked};
use crate::oracle::{brute_inner, scale};
use crate::{GRASS, position_kernels, shape_pairs};

/// `s` with `k` channels: its (first) signal channel, then k − 1 smooth maps of the
/// coordinates of other amplitudes (up to 3) plus noise.
fn with_channels(s: &FShape, k: usize, seed: u64) -> FShape {
    let mut rng = SplitMix64(seed);
    let f0 = s.channel(0).expect("test shapes carry a signal");
    let mut f = Vec::with_capacity(s.n_vertices() * k);
    for (v, &first) in f0.iter().enumerate() {
        let p = s.point(v);
        f.push(first);
        for c in 1..k {
            f.push(c as f64 * (2.0 * p[0] - c as f64 * p[1]).sin() + 0.2 * rng.normal());
        }
    }
    s.clone().with_signals(Some(f), k).unwrap()
}

/// The two signal kernels on k channels: one width, and a width each.
fn signal_kernels(k: usize) -> [SignalKernel; 2] {
    [
        SignalKernel::Gaussian { sigma: 0.5 },
        SignalKernel::Channels { sigmas: (0..k).map(|c| 0.4 + 0.5 * c as f64).collect() },
    ]
}

fn kernels(k: usize) -> Vec<VarifoldKernel> {
    let mut out = Vec::new();
    for kp in position_kernels() {
        for grass in GRASS {
            for sk in signal_kernels(k) {
                out.push(VarifoldKernel::try_new(kp.clone(), sk, grass).unwrap());
            }
        }
    }
    out
}

#[test]
fn inner_products_on_several_channels_are_the_definitions_double_sum() {
    for (what, x, y) in shape_pairs(31) {
        let (x, y) = (with_channels(&x, 3, 1), with_channels(&y, 3, 2));
        let (ex, ey) = (CellFeatures::of(&x).unwrap(), CellFeatures::of(&y).unwrap());
        assert_eq!((ex.n_channels(), ex.signal().unwrap().len()), (3, 3 * ex.len()));
        for k in kernels(3) {
            let fast = inner_product(&ex, &ey, &k).unwrap();
            let slow = brute_inner(&x, &y, &k);
            assert!((fast - slow).abs() <= 1e-13 * scale(&x, &y, &k), "{what}, {k:?}: {fast} vs {slow}");
            // Masked: every channel of a masked vertex is out.
            let (mx, my) = (masked(&x, 5), masked(&y, 6));
            let fast = Attachment::new(&my, k.clone()).unwrap().eval(&mx).unwrap();
            let slow = brute_masked(&mx, &mx, &k) - 2.0 * brute_masked(&mx, &my, &k) + brute_masked(&my, &my, &k);
            let tol = 1e-13 * (scale(&x, &x, &k) + scale(&y, &y, &k));
            assert!((fast.value - slow).abs() <= tol, "{what}, masked, {k:?}: {} vs {slow}", fast.value);
        }
    }
}

#[test]
fn gradients_on_several_channels_match_central_differences() {
    let mut rng = SplitMix64(99);
    for (what, x, y) in shape_pairs(37) {
        let (x, y) = (with_channels(&x, 3, 3), with_channels(&y, 3, 4));
        for (i, k) in kernels(3).into_iter().enumerate() {
            // Every position kernel and signal kernel, two direction kernels.
            if i % 8 >= 4 {
                continue;
            }
            for (xm, ym) in [(x.clone(), y.clone()), (masked(&x, 8), masked(&y, 9))] {
                let att = Attachment::new(&ym, k.clone()).unwrap();
                let (_, g) = att.eval_grad(&xm).unwrap();
                assert_eq!(g.signal.len(), 3 * xm.n_vertices());
                let a = |s: &FShape| att.eval(s).unwrap().value;
                let v = random_direction(xm.points().len(), &mut rng);
                let c = check_gradient(
                    |p| a(&xm.clone().with_points(p.to_vec()).unwrap()),
                    xm.points(),
                    &g.points,
                    &v,
                    1e-5,
                );
                let size: f64 = g.points.iter().zip(&v).map(|(a, b)| (a * b).abs()).sum();
                assert!((c.numeric - c.analytic).abs() < 1e-7 * size, "{what}, {k:?}: ∂A/∂x {c:?}");
                // Masked values are NaN: perturb the others only.
                let f: Vec<f64> = xm.signal().unwrap().iter().map(|v| if v.is_nan() { 0.0 } else { *v }).collect();
                let v: Vec<f64> = random_direction(f.len(), &mut rng)
                    .into_iter()
                    .zip(xm.signal().unwrap())
                    .map(|(d, v)| if v.is_nan() { 0.0 } else { d })
                    .collect();
                let refill = |f: &[f64]| xm.clone().with_signals(Some(f.to_vec()), 3).unwrap();
                let c = check_gradient(|f| a(&refill(f)), &f, &g.signal, &v, 1e-5);
                let size: f64 = g.signal.iter().zip(&v).map(|(a, b)| (a * b).abs()).sum();
                assert!((c.numeric - c.analytic).abs() < 1e-7 * size, "{what}, {k:?}: ∂A/∂f {c:?}");
            }
        }
    }
}

#[test]
fn a_constant_extra_channel_changes_no_bit() {
    // exp(−b·0²) = 1 exactly and −b·0·0 adds nothing: a second channel that
    // is the same constant on both shapes leaves A and the gradients as
    // they are with one channel, bit for bit.
    let add_constant = |s: &FShape| {
        let f: Vec<f64> = s.signal().unwrap().iter().flat_map(|&v| [v, 2.5]).collect();
        s.clone().with_signals(Some(f), 2).unwrap()
    };
    for (what, x, y) in shape_pairs(41) {
        for (x, y) in [(x.clone(), y.clone()), (masked(&x, 2), masked(&y, 3))] {
            for kp in position_kernels() {
                for grass in GRASS {
                    let one =
                        VarifoldKernel::try_new(kp.clone(), SignalKernel::Gaussian { sigma: 0.5 }, grass).unwrap();
                    let two =
                        VarifoldKernel::try_new(kp.clone(), SignalKernel::Channels { sigmas: vec![0.5, 0.1] }, grass)
                            .unwrap();
                    let (d1, g1) = Attachment::new(&y, one).unwrap().eval_grad(&x).unwrap();
                    let (d2, g2) =
                        Attachment::new(&add_constant(&y), two).unwrap().eval_grad(&add_constant(&x)).unwrap();
                    assert_eq!(d1, d2, "{what}, {kp:?}, {grass:?}");
                    assert_eq!(g1.points, g2.points, "{what}, {kp:?}, {grass:?}");
                    let first: Vec<f64> = g2.signal.iter().step_by(2).copied().collect();
                    assert_eq!(g1.signal, first, "{what}, {kp:?}, {grass:?}");
                    assert!(g2.signal.iter().skip(1).step_by(2).all(|&v| v == 0.0));
                }
            }
        }
    }
}

#[test]
fn a_change_in_one_channel_is_seen_and_counts_must_agree() {
    let (_, x, _) = shape_pairs(43).swap_remove(0);
    let x = with_channels(&x, 2, 7);
    let k = VarifoldKernel::try_new(
        position_kernels()[0].clone(),
        SignalKernel::Channels { sigmas: vec![0.5, 0.5] },
        GRASS[1],
    )
    .unwrap();
    // The same geometry and first channel, the second raised by 0.3.
    let f: Vec<f64> =
        x.signal().unwrap().iter().enumerate().map(|(i, v)| if i % 2 == 1 { v + 0.3 } else { *v }).collect();
    let y = x.clone().with_signals(Some(f), 2).unwrap();
    let att = Attachment::new(&y, k.clone()).unwrap();
    assert!(att.eval(&x).unwrap().value > 1e-3 * att.target_self());
    assert!(att.eval(&y).unwrap().value.abs() < 1e-12 * att.target_self());
    // Two channels against three; widths for three on two channels; nine.
    let three = with_channels(&x, 3, 8);
    assert!(matches!(att.eval(&three), Err(VarifoldError::Channels { expected: 3, found: 2, .. })));
    let k3 = VarifoldKernel::try_new(
        position_kernels()[0].clone(),
        SignalKernel::Channels { sigmas: vec![1.0; 3] },
        GRASS[1],
    )
    .unwrap();
    assert!(matches!(Attachment::new(&y, k3), Err(VarifoldError::Channels { expected: 2, found: 3, .. })));
    let nine = with_channels(&x, 9, 9);
    let g = VarifoldKernel::try_new(position_kernels()[0].clone(), SignalKernel::Gaussian { sigma: 1.0 }, GRASS[1])
        .unwrap();
    let e = Attachment::new(&nine, g).unwrap_err();
    assert!(e.to_string().contains("at most 8"), "{e}");
}
