//! Integration tests of fshape-shoot (one binary, modules in `tests/shoot/`).

#[path = "shoot/channels.rs"]
mod channels;
#[path = "shoot/dynamics.rs"]
mod dynamics;
#[path = "shoot/gradient.rs"]
mod gradient;
#[path = "shoot/model.rs"]
mod model;
#[path = "shoot/regression.rs"]
mod regression;
#[path = "shoot/transport.rs"]
mod transport;

use fshape_fem::Norm;
use fshape_kernels::Kernel;
use fshape_mesh::FShape;
use fshape_mesh::test_support::{perturbed_icosphere, random_curve, random_vector_field};
use fshape_shoot::{Integrator, Model, ModelKind};

/// A model from `key = value` lines (kind, norm, length, gamma_v, gamma_f,
/// gamma_w; the configuration file's spellings), deformation widths 0.6
/// and 0.3, truncated when `deformation_lines` sets `tolerance = τ`.
pub fn model(model_lines: &str, deformation_lines: &str, integrator: &str, steps: usize) -> Model {
    let pairs = |text: &str| -> Vec<(String, String)> {
        text.lines()
            .filter_map(|l| l.split_once('='))
            .map(|(k, v)| (k.trim().to_string(), v.trim().trim_matches('"').to_string()))
            .collect()
    };
    let get = |text: &str, key: &str| pairs(text).into_iter().find(|(k, _)| k == key).map(|(_, v)| v);
    let num = |key: &str, default: f64| get(model_lines, key).map_or(default, |v| v.parse().unwrap());
    let kind = match get(model_lines, "kind").as_deref() {
        None | Some("metamorphosis") => ModelKind::Metamorphosis,
        Some("tangential") => ModelKind::Tangential,
        Some("lddmm") => ModelKind::Lddmm,
        Some(other) => panic!("kind {other}"),
    };
    let norm = match get(model_lines, "norm").as_deref() {
        None | Some("l2-lumped") => Norm::L2Lumped,
        Some("l2") => Norm::L2,
        Some("h1") => Norm::H1 { length: num("length", 1.0) },
        Some(other) => panic!("norm {other}"),
    };
    let scheme = match integrator {
        "rk4" => Integrator::Rk4,
        "midpoint" => Integrator::Midpoint,
        "euler" => Integrator::Euler,
        other => panic!("integrator {other}"),
    };
    let mut kernel =
        Kernel::try_new(&fshape_kernels::Profile::Gaussians { sigmas: vec![0.6, 0.3], weights: vec![1.0; 2] }).unwrap();
    if let Some(tol) = get(deformation_lines, "tolerance") {
        kernel = kernel.truncated(tol.parse().unwrap()).unwrap();
    }
    Model::new(kernel)
        .with_kind(kind)
        .with_norm(norm)
        .unwrap()
        .with_weights(num("gamma_v", 1.0), num("gamma_f", 1.0), num("gamma_w", 1.0))
        .unwrap()
        .with_integrator(scheme, steps)
        .unwrap()
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
