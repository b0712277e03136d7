//! Hamiltonian conservation: H is a first integral of the flow, so along a
//! discrete trajectory its drift is the integrator's error, O(dt^q) for a
//! scheme of order q (4 for RK4, 2 for the midpoint scheme, 1 for Euler).
//! Random fshapes (surfaces and curves), momenta, signal momenta, norms and
//! models (metamorphosis, tangential, LDDMM).

use fshape_mesh::FShape;
use fshape_mesh::test_support::random_vector_field;
use fshape_mesh::test_support::strategies::{curves, icospheres};
use fshape_shoot::{ModelKind, Problem};
use proptest::prelude::*;

use crate::model;

/// max_k |H_k − H_0| / H_0 along a shooting with `steps` steps (no drift
/// tolerance: Euler's drift at few steps is what is measured).
fn drift(shape: &FShape, p0: &[f64], pf: &[f64], kind: ModelKind, norm: &str, scheme: &str, steps: usize) -> f64 {
    let m = model(0.5, norm, 0.3, 1.0, 0.5, scheme, steps).with_kind(kind).with_max_drift(f64::INFINITY).unwrap();
    let h = Problem::new(shape, m).unwrap().shoot(p0, pf).unwrap().hamiltonian;
    h.iter().map(|v| (v - h[0]).abs()).fold(0.0, f64::max) / h[0]
}

/// Relative drifts below this are rounding (a few ulps per step), where an
/// order means nothing.
const ROUNDING: f64 = 1e-12;

/// The observed order of the drift, and the drifts, for random momenta
/// and signal momenta (for the tangential model, the signal residual ζ);
/// `None` for the order when the drifts are rounding.
fn order(shape: &FShape, seed: u64, kind: ModelKind, norm: &str, scheme: &str) -> (Option<f64>, Vec<f64>) {
    let p0 = random_vector_field(shape.n_vertices(), shape.dim(), 0.3, seed);
    let pf = random_vector_field(shape.n_vertices(), 1, 0.3, seed + 1);
    // Measured over 30 seeds × 12 cases (scripts/proptest-seeds.sh): the
    // drift ratios approach 2^q from either side, so the least-squares slope
    // over three resolutions strayed to 4.4–4.6 for RK4 at 20/40/80 steps
    // (LDDMM and tangential) and to 1.54 for the midpoint scheme at
    // 80/160/320, and RK4's drift reached rounding (4e-16) on a curve with
    // small momenta. Hence: the order of the finest pair of resolutions
    // whose drifts are both above rounding, resolutions where it is
    // asymptotic, and q ± 0.5.
    let steps: [usize; 3] = match scheme {
        "midpoint" => [80, 160, 320],
        _ => [40, 80, 160],
    };
    let d: Vec<f64> = steps.iter().map(|&n| drift(shape, &p0, &pf, kind, norm, scheme, n)).collect();
    let q = (0..2).rev().find(|&i| d[i + 1] > ROUNDING).map(|i| (d[i] / d[i + 1]).log2());
    (q, d)
}

/// The order `q` is within 0.5 of `expected`, and the drift falls with the
/// step; or (no order) it is already at rounding at the two finer
/// resolutions, where H is conserved as well as f64 can tell.
fn assert_order(q: Option<f64>, d: &[f64], expected: f64, what: String) -> Result<(), TestCaseError> {
    if let Some(q) = q {
        prop_assert!((q - expected).abs() <= 0.5, "{what}: drifts {d:?}, order {q}");
    }
    prop_assert!(d[0] > d[1] || d[1] <= ROUNDING, "{what}: drifts {d:?} do not fall");
    Ok(())
}

/// The three models: metamorphosis, and the tangential model and LDDMM,
/// whose Hamiltonian is LDDMM's ½ pᵀK(x)p (the signal does not enter it).
fn kinds() -> impl Strategy<Value = ModelKind> {
    prop_oneof![Just(ModelKind::Metamorphosis), Just(ModelKind::Tangential), Just(ModelKind::Lddmm)]
}

proptest! {
    #![proptest_config(fshape_mesh::test_support::strategies::config(12, 77))]

    #[test]
    fn rk4_conserves_h_to_fourth_order(
        shape in prop_oneof![icospheres(1), curves(2, 30), curves(3, 30)],
        seed in any::<u64>(),
        kind in kinds(),
        norm in prop_oneof![Just("l2-lumped"), Just("l2"), Just("h1")],
    ) {
        let (q, d) = order(&shape, seed, kind, norm, "rk4");
        assert_order(q, &d, 4.0, format!("{kind:?}, {norm}"))?;
    }

    #[test]
    fn the_midpoint_scheme_conserves_h_to_second_order(
        shape in prop_oneof![icospheres(1), curves(2, 30), curves(3, 30)],
        seed in any::<u64>(),
        kind in kinds(),
        norm in prop_oneof![Just("l2-lumped"), Just("l2"), Just("h1")],
    ) {
        let (q, d) = order(&shape, seed, kind, norm, "midpoint");
        // Order 2; the explicit midpoint rule is not symplectic, so the drift
        // is its plain global error.
        assert_order(q, &d, 2.0, format!("{kind:?}, {norm}"))?;
    }

    #[test]
    fn euler_conserves_h_to_first_order(
        shape in prop_oneof![icospheres(1), curves(2, 30), curves(3, 30)],
        seed in any::<u64>(),
        kind in kinds(),
        norm in prop_oneof![Just("l2-lumped"), Just("l2"), Just("h1")],
    ) {
        let (q, d) = order(&shape, seed, kind, norm, "euler");
        assert_order(q, &d, 1.0, format!("{kind:?}, {norm}"))?;
    }
}
