//! Central finite-difference checks of ∂A/∂x and ∂A/∂f on random meshes
//! with random signals, for every kernel (exact and truncated).

use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, random_direction};
use fshape_varifold::{Attachment, CellFeatures, inner_product_grad};

use crate::{kernels, shape_pairs};

fn moved(s: &FShape, points: &[f64]) -> FShape {
    s.clone().with_points(points.to_vec()).unwrap()
}

fn resignalled(s: &FShape, f: &[f64]) -> FShape {
    s.clone().with_signal(Some(f.to_vec())).unwrap()
}

/// |numeric − analytic| relative to Σ_k |g_k v_k|, the size of the terms
/// the directional derivative sums: A = ⟨X,X⟩ − 2⟨X,Y⟩ + ⟨Y,Y⟩ cancels, so
/// along a random direction ⟨∇A, v⟩ can be far smaller than its terms,
/// and the difference quotient's rounding error (ε⟨X,X⟩/h) is relative to
/// those terms, not to the sum.
fn error(c: &fshape_mesh::test_support::FdCheck, g: &[f64], v: &[f64]) -> f64 {
    let size: f64 = g.iter().zip(v).map(|(a, b)| (a * b).abs()).sum();
    (c.numeric - c.analytic).abs() / size
}

#[test]
fn gradients_in_positions_and_signals_match_central_differences() {
    let mut rng = SplitMix64(42);
    let mut worst: f64 = 0.0;
    for (what, x, y) in shape_pairs(17) {
        for k in kernels() {
            let att = Attachment::new(&y, k.clone()).unwrap();
            let (_, g) = att.eval_grad(&x).unwrap();
            let a = |s: &FShape| att.eval(s).unwrap().value;
            for _ in 0..2 {
                let v = random_direction(x.points().len(), &mut rng);
                let c = check_gradient(|p| a(&moved(&x, p)), x.points(), &g.points, &v, 1e-5);
                let e = error(&c, &g.points, &v);
                assert!(e < 1e-7, "{what}, {k:?}: ∂A/∂x {c:?}, error {e:e}");
                worst = worst.max(e);
                let f = x.signal().unwrap();
                let v = random_direction(f.len(), &mut rng);
                let c = check_gradient(|f| a(&resignalled(&x, f)), f, &g.signal, &v, 1e-5);
                if k.signal().is_constant() {
                    assert!(c.numeric == 0.0 && c.analytic == 0.0, "{what}, {k:?}: A depends on f");
                } else {
                    let e = error(&c, &g.signal, &v);
                    assert!(e < 1e-7, "{what}, {k:?}: ∂A/∂f {c:?}, error {e:e}");
                    worst = worst.max(e);
                }
            }
        }
    }
    eprintln!("worst error: {worst:e}");
}

#[test]
fn feature_gradients_of_an_inner_product_match_central_differences() {
    // Below the chain rule: ⟨X,Y⟩ as a function of X's centres, directions
    // (unconstrained), weights and signals.
    let mut rng = SplitMix64(7);
    for (what, x, y) in shape_pairs(23) {
        let (ex, ey) = (CellFeatures::of(&x).unwrap(), CellFeatures::of(&y).unwrap());
        for k in kernels() {
            let (_, g) = inner_product_grad(&ex, &ey, &k).unwrap();
            let rebuild = |c: &[f64], u: &[f64], r: &[f64], f: &[f64]| {
                let fx = CellFeatures::from_parts(ex.dim(), c.to_vec(), u.to_vec(), r.to_vec(), Some(f.to_vec()));
                fshape_varifold::inner_product(&fx.unwrap(), &ey, &k).unwrap()
            };
            let (c0, u0, r0, f0) = (ex.centres(), ex.dirs(), ex.weights(), ex.signal().unwrap());
            let checks = [
                (
                    "centre",
                    check_gradient(
                        |c| rebuild(c, u0, r0, f0),
                        c0,
                        &g.centre,
                        &random_direction(c0.len(), &mut rng),
                        1e-5,
                    ),
                ),
                (
                    "direction",
                    check_gradient(|u| rebuild(c0, u, r0, f0), u0, &g.dir, &random_direction(u0.len(), &mut rng), 1e-6),
                ),
                (
                    "weight",
                    check_gradient(
                        |r| rebuild(c0, u0, r, f0),
                        r0,
                        &g.weight,
                        &random_direction(r0.len(), &mut rng).iter().map(|v| v.abs() * 1e-2).collect::<Vec<_>>(),
                        1e-3,
                    ),
                ),
                (
                    "signal",
                    check_gradient(
                        |f| rebuild(c0, u0, r0, f),
                        f0,
                        &g.signal,
                        &random_direction(f0.len(), &mut rng),
                        1e-5,
                    ),
                ),
            ];
            for (which, c) in checks {
                let tol = if which == "signal" && k.signal().is_constant() { 0.0 } else { 1e-6 };
                assert!(c.rel_error <= tol, "{what}, {k:?}: ∂/∂{which} {c:?}");
            }
        }
    }
}
