//! Integration tests of fshape-shoot (one binary, modules in `tests/shoot/`).

#[path = "shoot/config.rs"]
mod config;
#[path = "shoot/dynamics.rs"]
mod dynamics;
#[path = "shoot/gradient.rs"]
mod gradient;
#[path = "shoot/matching.rs"]
mod matching;
#[path = "shoot/optimize.rs"]
mod optimize;

use fshape_mesh::FShape;
use fshape_mesh::test_support::{perturbed_icosphere, random_curve, random_vector_field};
use fshape_shoot::{Config, Model};

/// A model from the lines of a `[model]` section plus defaults elsewhere.
pub fn model(model_lines: &str, deformation_lines: &str, integrator: &str, steps: usize) -> Model {
    let text = format!(
        "[model]\n{model_lines}\n[deformation]\nwidths = [0.6, 0.3]\n{deformation_lines}\n\
         [integrator]\nscheme = \"{integrator}\"\nsteps = {steps}\n"
    );
    Config::parse(&text).unwrap().model().unwrap()
}

/// Template and target surfaces (42 and 162 vertices) and a curve pair.
pub fn surfaces() -> (FShape, FShape) {
    let target = perturbed_icosphere(2, 0.1, 9);
    let pts: Vec<f64> = target.points().chunks_exact(3).flat_map(|p| [1.2 * p[0], p[1], 0.8 * p[2]]).collect();
    (perturbed_icosphere(1, 0.05, 3), target.with_points(pts).unwrap())
}

/// Random momenta (p_0, p^f) for a shape.
pub fn momenta(s: &FShape, scale: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    (
        random_vector_field(s.n_vertices(), s.dim(), scale, seed),
        random_vector_field(s.n_vertices(), 1, scale, seed + 100),
    )
}

/// A closed curve in the plane for the d = 1 cases.
pub fn curves() -> (FShape, FShape) {
    (random_curve(2, 24, 4), random_curve(2, 40, 5))
}
