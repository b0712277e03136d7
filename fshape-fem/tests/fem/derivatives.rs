//! Every x-derivative against central finite differences, and serial
//! against parallel evaluation, bit for bit.

use fshape_fem::{Norm, SignalNorm};
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, check_jvp, random_direction};

use crate::{NORMS, shapes};

/// h = 1e-6 relative to unit-size shapes: truncation O(h²) ≈ 1e-12 and
/// rounding O(ε/h) ≈ 1e-10 against derivatives of order one, so 1e-7 is a
/// safe bound that a wrong derivative (off by a term) cannot meet.
const H: f64 = 1e-6;
const TOL: f64 = 1e-7;

#[test]
fn gradient_hvp_and_dmatvec_match_finite_differences() {
    let mut rng = SplitMix64(42);
    for s in shapes() {
        let x = s.points().to_vec();
        let p = s.n_vertices();
        for norm in NORMS {
            let d = SignalNorm::try_new(&s, norm).unwrap();
            let a = random_direction(p, &mut rng);
            let b = random_direction(p, &mut rng);
            let dx = random_direction(x.len(), &mut rng);
            let what = format!("{norm:?} on {:?} in R^{}", s.kind(), s.dim());
            // ∂_x(aᵀ D b) against the bilinear value aᵀ (D b).
            let value = |y: &[f64]| d.matvec(y, &b).unwrap().iter().zip(&a).map(|(u, v)| u * v).sum::<f64>();
            let g = d.grad(&x, &a, &b).unwrap();
            let c = check_gradient(value, &x, &g, &dx, H);
            assert!(c.rel_error < TOL, "grad {what}: {c:?}");
            // Quadratic form: grad with a = b.
            let gq = d.grad(&x, &a, &a).unwrap();
            let c = check_gradient(|y: &[f64]| d.quadratic(y, &a).unwrap(), &x, &gq, &dx, H);
            assert!(c.rel_error < TOL, "quadratic grad {what}: {c:?}");
            // HVP against the finite difference of the gradient.
            let hv = d.hvp(&x, &a, &b, &dx).unwrap();
            let c = check_jvp(|y: &[f64]| d.grad(y, &a, &b).unwrap(), &x, &dx, &hv, H);
            assert!(c.rel_error < TOL, "hvp {what}: {c:?}");
            // (∂D·dx) b against the finite difference of D b.
            let dm = d.dmatvec(&x, &dx, &b).unwrap();
            let c = check_jvp(|y: &[f64]| d.matvec(y, &b).unwrap(), &x, &dx, &dm, H);
            assert!(c.rel_error < TOL, "dmatvec {what}: {c:?}");
        }
    }
}

#[test]
fn serial_and_parallel_results_are_bitwise_equal() {
    let s = fshape_mesh::test_support::perturbed_icosphere(4, 0.1, 7);
    let x = s.points();
    let mut rng = SplitMix64(5);
    let a = random_direction(s.n_vertices(), &mut rng);
    let dx = random_direction(x.len(), &mut rng);
    for norm in crate::NORMS {
        let par = SignalNorm::try_new(&s, norm).unwrap();
        let ser = SignalNorm::try_new(&s, norm).unwrap().with_parallel(false);
        assert_eq!(par.assemble(x).unwrap(), ser.assemble(x).unwrap());
        assert_eq!(par.matvec(x, &a).unwrap(), ser.matvec(x, &a).unwrap());
        assert_eq!(par.quadratic(x, &a).unwrap().to_bits(), ser.quadratic(x, &a).unwrap().to_bits());
        assert_eq!(par.grad(x, &a, &a).unwrap(), ser.grad(x, &a, &a).unwrap());
        assert_eq!(par.hvp(x, &a, &a, &dx).unwrap(), ser.hvp(x, &a, &a, &dx).unwrap());
        assert_eq!(par.dmatvec(x, &dx, &a).unwrap(), ser.dmatvec(x, &dx, &a).unwrap());
        // The from-scratch P1 mass and stiffness (the libigl comparison's
        // path): parallel local matrices, then a per-entry gather.
        if norm != Norm::L2Lumped {
            assert_eq!(par.assemble_mass_and_stiffness(x).unwrap(), ser.assemble_mass_and_stiffness(x).unwrap());
        }
    }
}

/// The `_into` forms with one workspace reused across operations and
/// positions give what fresh calls give, bit for bit (no stale scratch),
/// and refuse an output of the wrong length by name.
#[test]
fn a_reused_workspace_gives_the_results_of_fresh_calls() {
    use fshape_fem::{FemError, Workspace};
    let s = fshape_mesh::test_support::perturbed_icosphere(3, 0.1, 11);
    let mut rng = SplitMix64(9);
    let a = random_direction(s.n_vertices(), &mut rng);
    let b = random_direction(s.n_vertices(), &mut rng);
    let dx = random_direction(s.points().len(), &mut rng);
    let moved: Vec<f64> = s.points().iter().zip(&dx).map(|(p, d)| p + 0.05 * d).collect();
    for norm in crate::NORMS {
        let d = SignalNorm::try_new(&s, norm).unwrap();
        let mut ws = Workspace::default();
        let (mut vals, mut g, mut v) = (Vec::new(), vec![0.0; dx.len()], vec![0.0; a.len()]);
        for x in [s.points(), &moved[..], s.points()] {
            d.assemble_into(x, &mut ws, &mut vals).unwrap();
            assert_eq!(vals, d.assemble(x).unwrap());
            d.grad_into(x, &a, &b, &mut ws, &mut g).unwrap();
            assert_eq!(g, d.grad(x, &a, &b).unwrap());
            d.hvp_into(x, &a, &b, &dx, &mut ws, &mut g).unwrap();
            assert_eq!(g, d.hvp(x, &a, &b, &dx).unwrap());
            d.dmatvec_into(x, &dx, &a, &mut ws, &mut v).unwrap();
            assert_eq!(v, d.dmatvec(x, &dx, &a).unwrap());
            d.matvec_into(x, &a, &mut ws, &mut v).unwrap();
            assert_eq!(v, d.matvec(x, &a).unwrap());
        }
        let mut short = vec![0.0; 2];
        assert_eq!(
            d.grad_into(s.points(), &a, &b, &mut ws, &mut short),
            Err(FemError::Dimension { what: "output", expected: dx.len(), found: 2 })
        );
    }
}
