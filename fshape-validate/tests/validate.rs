//! The theory checks (one binary, modules in `tests/validate/`).

#[path = "validate/conservation.rs"]
mod conservation;
#[path = "validate/hamiltonian.rs"]
mod hamiltonian;
#[path = "validate/sphere.rs"]
mod sphere;

use fshape_shoot::{Config, Model};

/// A metamorphosis model: one Gaussian of width σ, the given norm and ℓ,
/// γ_V, γ_f, RK4 with `steps` steps.
pub fn model(sigma: f64, norm: &str, length: f64, gamma_v: f64, gamma_f: f64, scheme: &str, steps: usize) -> Model {
    let text = format!(
        "[model]\nnorm = \"{norm}\"\nlength = {length}\ngamma_v = {gamma_v}\ngamma_f = {gamma_f}\n\
         [deformation]\nwidths = [{sigma}]\n[integrator]\nscheme = \"{scheme}\"\nsteps = {steps}\n"
    );
    Config::parse(&text).unwrap().model().unwrap()
}
