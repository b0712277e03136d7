//! The vectorised block engine against a brute-force double loop written
//! from the definition, on every kernel and kind of shape; serial = parallel.

use fshape_mesh::{CellKind, FShape};
use fshape_varifold::{Attachment, CellFeatures, GrassKernel, SignalKernel, VarifoldKernel, inner_product};

use crate::{kernels, shape_pairs};

/// One cell's centre, direction, weight and signal channels.
type Cell = (Vec<f64>, Vec<f64>, f64, Vec<f64>);

/// Every cell's [`Cell`] straight from its corners.
fn features(s: &FShape) -> Vec<Cell> {
    let d = s.dim();
    s.cell_iter()
        .map(|cell| {
            let p = |k: usize| -> Vec<f64> {
                let q = s.point(cell[k]);
                (0..3).map(|c| q.get(c).copied().unwrap_or(0.0)).collect()
            };
            let n = cell.len() as f64;
            let centre: Vec<f64> = (0..d).map(|c| cell.iter().map(|&v| s.point(v)[c]).sum::<f64>() / n).collect();
            let k = s.n_channels();
            let f: Vec<f64> =
                (0..k).map(|c| cell.iter().map(|&v| s.signal().unwrap()[v * k + c]).sum::<f64>() / n).collect();
            let e1: Vec<f64> = (0..3).map(|c| p(1)[c] - p(0)[c]).collect();
            let vector = match s.kind() {
                CellKind::Segment => e1,
                CellKind::Triangle => {
                    let e2: Vec<f64> = (0..3).map(|c| p(2)[c] - p(0)[c]).collect();
                    vec![
                        0.5 * (e1[1] * e2[2] - e1[2] * e2[1]),
                        0.5 * (e1[2] * e2[0] - e1[0] * e2[2]),
                        0.5 * (e1[0] * e2[1] - e1[1] * e2[0]),
                    ]
                }
            };
            let r = vector.iter().map(|v| v * v).sum::<f64>().sqrt();
            let dir = match (s.kind(), d) {
                (CellKind::Triangle, 2) => vec![vector[2] / r],
                _ => vector[..d].iter().map(|v| v / r).collect(),
            };
            (centre, dir, r, f)
        })
        .collect()
}

/// ⟨μ_X, μ_Y⟩ by the definition, with scalar exponentials.
pub fn brute_inner(x: &FShape, y: &FShape, k: &VarifoldKernel) -> f64 {
    let (fx, fy) = (features(x), features(y));
    let mut total = 0.0;
    for (ci, ui, ri, fi) in &fx {
        for (cj, uj, rj, fj) in &fy {
            let u: f64 = ci.iter().zip(cj).map(|(a, b)| (a - b).powi(2)).sum();
            let s: f64 = ui.iter().zip(uj).map(|(a, b)| a * b).sum();
            let kf = signal_factor(k.signal(), fi, fj);
            let kt = match k.grass() {
                GrassKernel::Linear => s,
                GrassKernel::Binet => s * s,
                GrassKernel::OrientedGaussian { sigma } => (-2.0 * (1.0 - s) / (sigma * sigma)).exp(),
                GrassKernel::UnorientedGaussian { sigma } => (-2.0 * (1.0 - s * s) / (sigma * sigma)).exp(),
            };
            total += ri * rj * k.position().value(u) * kf * kt;
        }
    }
    total
}

/// k_f by its definition: Π_c exp(−(f_c − g_c)²/(2σ_c²)), one σ for
/// every channel or one per channel.
pub fn signal_factor(k: &SignalKernel, f: &[f64], g: &[f64]) -> f64 {
    assert_eq!(f.len(), g.len());
    let sigma = |c: usize| match k {
        SignalKernel::Gaussian { sigma } => *sigma,
        SignalKernel::Channels { sigmas } => sigmas[c],
        _ => f64::INFINITY,
    };
    if k.is_constant() {
        return 1.0;
    }
    (0..f.len()).map(|c| (-(f[c] - g[c]).powi(2) / (2.0 * sigma(c) * sigma(c))).exp()).product()
}

/// Σ r r k_p(0): the scale of an inner product (|k_f k_t| ≤ 1).
pub fn scale(x: &FShape, y: &FShape, k: &VarifoldKernel) -> f64 {
    k.position().value(0.0) * x.total_volume() * y.total_volume()
}

#[test]
fn inner_products_and_distances_match_the_definition() {
    for (what, x, y) in shape_pairs(3) {
        let (ex, ey) = (CellFeatures::of(&x).unwrap(), CellFeatures::of(&y).unwrap());
        for k in kernels() {
            for (a, b, fa, fb) in [(&x, &y, &ex, &ey), (&x, &x, &ex, &ex), (&y, &x, &ey, &ex)] {
                let fast = inner_product(fa, fb, &k).unwrap();
                let slow = brute_inner(a, b, &k);
                let tol = 1e-13 * scale(a, b, &k);
                assert!((fast - slow).abs() <= tol, "{what}, {k:?}: {fast} vs {slow}");
            }
            let d = Attachment::new(&y, k.clone()).unwrap().eval(&x).unwrap();
            let slow = brute_inner(&x, &x, &k) - 2.0 * brute_inner(&x, &y, &k) + brute_inner(&y, &y, &k);
            let tol = 1e-13 * (scale(&x, &x, &k) + scale(&y, &y, &k));
            assert!((d.value - slow).abs() <= tol, "{what}, {k:?}: A = {} vs {slow}", d.value);
        }
    }
}

#[test]
fn serial_and_parallel_evaluations_are_identical() {
    for (what, x, y) in shape_pairs(5) {
        for k in kernels() {
            let att = Attachment::new(&y, k.clone()).unwrap();
            let (d1, g1) = att.clone().with_parallel(false).eval_grad(&x).unwrap();
            let (d2, g2) = att.with_parallel(true).eval_grad(&x).unwrap();
            assert_eq!(d1, d2, "{what}, {k:?}");
            assert_eq!(g1, g2, "{what}, {k:?}");
        }
    }
}

#[test]
fn the_value_only_path_agrees_with_the_gradient_path() {
    for (what, x, y) in shape_pairs(8) {
        for k in kernels() {
            let att = Attachment::new(&y, k.clone()).unwrap();
            let (d, _) = att.eval_grad(&x).unwrap();
            // Same sums in the same order: equal bit for bit.
            assert_eq!(att.eval(&x).unwrap(), d, "{what}, {k:?}");
        }
    }
}

#[test]
fn truncation_stays_within_its_bound() {
    // |Δ⟨X,Y⟩| ≤ τ k_p(0) Σr Σr since |k_f k_t| ≤ 1 and every changed pair
    // has k_p ≤ τ k_p(0).
    for (what, x, y) in shape_pairs(9) {
        let (ex, ey) = (CellFeatures::of(&x).unwrap(), CellFeatures::of(&y).unwrap());
        for k in kernels().into_iter().filter(|k| k.position().taper().is_none()) {
            for tol in [1e-2, 1e-6] {
                let kt = k.truncated(tol).unwrap();
                let (a, b) = (inner_product(&ex, &ey, &k).unwrap(), inner_product(&ex, &ey, &kt).unwrap());
                let bound = tol * scale(&x, &y, &k) * (1.0 + 1e-9);
                assert!((a - b).abs() <= bound, "{what}, {k:?}, τ = {tol}: {a} vs {b}");
            }
        }
    }
}
