//! The theory checks (one binary, modules in `tests/validate/`).

#[path = "validate/conservation.rs"]
mod conservation;
#[path = "validate/hamiltonian.rs"]
mod hamiltonian;
#[path = "validate/sphere.rs"]
mod sphere;

use fshape_fem::Norm;
use fshape_kernels::Kernel;
use fshape_shoot::{Integrator, Model};

/// A metamorphosis model: one Gaussian of width σ, the given norm and ℓ,
/// γ_V, γ_f, the scheme (rk4, midpoint, euler) with `steps` steps.
pub fn model(sigma: f64, norm: &str, length: f64, gamma_v: f64, gamma_f: f64, scheme: &str, steps: usize) -> Model {
    let integrator = match scheme {
        "rk4" => Integrator::Rk4,
        "midpoint" => Integrator::Midpoint,
        "euler" => Integrator::Euler,
        other => panic!("scheme {other}"),
    };
    Model::new(Kernel::gaussian(sigma).unwrap())
        .with_norm(Norm::parse(norm, length).unwrap())
        .and_then(|m| m.with_weights(gamma_v, gamma_f, 1.0))
        .and_then(|m| m.with_integrator(integrator, steps))
        .unwrap()
}
