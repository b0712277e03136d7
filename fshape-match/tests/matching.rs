//! Integration tests of fshape-match (one binary, modules in `tests/matching/`).

#[path = "matching/atlas.rs"]
mod atlas;
#[path = "matching/channels.rs"]
mod channels;
#[path = "matching/config.rs"]
mod config;
#[path = "matching/errors.rs"]
mod errors;
#[path = "matching/objective.rs"]
mod objective;
#[path = "matching/optimize.rs"]
mod optimize;
#[path = "matching/prealign.rs"]
mod prealign;
#[path = "matching/precondition.rs"]
mod precondition;
#[path = "matching/quality.rs"]
mod quality;
#[path = "matching/reference.rs"]
mod reference;
#[path = "matching/regression.rs"]
mod regression;
#[path = "matching/resolution.rs"]
mod resolution;
#[path = "matching/session.rs"]
mod session;

use fshape_match::Config;
use fshape_mesh::FShape;
use fshape_mesh::test_support::random_vector_field;
use fshape_shoot::Model;

/// A model from the lines of a `[model]` section plus defaults elsewhere.
pub fn model(model_lines: &str, deformation_lines: &str, integrator: &str, steps: usize) -> Model {
    // The weights these tests were written with (the defaults are
    // scale-free weights for real data: γ_f = 0.1, γ_W = 1000).
    let mut model_lines = model_lines.to_string();
    for (key, value) in [("gamma_f", "1.0"), ("gamma_w", "1.0")] {
        if !model_lines.contains(key) {
            model_lines.push_str(&format!("\n{key} = {value}"));
        }
    }
    let text = format!(
        "[model]\n{model_lines}\n[deformation]\nwidths = [0.6, 0.3]\n{deformation_lines}\n\
         [integrator]\nscheme = \"{integrator}\"\nsteps = {steps}\n"
    );
    Config::parse(&text).unwrap().model().unwrap()
}

/// Random momenta (p_0, p^f) for a shape.
pub fn momenta(s: &FShape, scale: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    (
        random_vector_field(s.n_vertices(), s.dim(), scale, seed),
        random_vector_field(s.n_vertices(), 1, scale, seed + 100),
    )
}
