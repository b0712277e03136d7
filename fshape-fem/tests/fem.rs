//! Integration tests of fshape-fem (one binary, modules in `tests/fem/`).

#[path = "fem/analytic.rs"]
mod analytic;
#[path = "fem/derivatives.rs"]
mod derivatives;
#[path = "fem/libigl.rs"]
mod libigl;
#[path = "fem/solve.rs"]
mod solve;

use fshape_fem::Norm;
use fshape_mesh::FShape;

/// Every norm the crate offers (ℓ = 0.7 so that the stiffness weight is
/// not 1 and a missing ℓ² would show).
pub const NORMS: [Norm; 3] = [Norm::L2Lumped, Norm::L2, Norm::H1 { length: 0.7 }];

/// Small random shapes of every kind: surface in R³, flat domain in R²,
/// curves in R² and R³.
pub fn shapes() -> Vec<FShape> {
    use fshape_mesh::test_support::{perturbed_icosphere, random_curve, random_square};
    vec![perturbed_icosphere(1, 0.15, 1), random_square(40, 2), random_curve(2, 12, 3), random_curve(3, 12, 4)]
}
