//! Integration tests of fshape-varifold (one binary, modules in `tests/varifold/`).

#[path = "varifold/channels.rs"]
mod channels;
#[path = "varifold/convergence.rs"]
mod convergence;
#[path = "varifold/derivatives.rs"]
mod derivatives;
#[path = "varifold/masks.rs"]
mod masks;
#[path = "varifold/oracle.rs"]
mod oracle;
#[path = "varifold/properties.rs"]
mod properties;

use fshape_kernels::{Kernel, Profile};
use fshape_mesh::FShape;
use fshape_mesh::test_support::{perturbed_icosphere, random_curve, random_square};
use fshape_varifold::{GrassKernel, SignalKernel, VarifoldKernel};

/// Every direction kernel.
pub const GRASS: [GrassKernel; 4] = [
    GrassKernel::Linear,
    GrassKernel::Binet,
    GrassKernel::OrientedGaussian { sigma: 0.7 },
    GrassKernel::UnorientedGaussian { sigma: 0.7 },
];

/// Position kernels: one Gaussian (the engine's fused loop), a sum of two
/// and Cauchy (its general loop), and one truncated kernel for each loop.
pub fn position_kernels() -> Vec<Kernel> {
    let g = Kernel::gaussian(0.4).unwrap();
    let cauchy = Kernel::try_new(&Profile::Cauchy { sigma: 0.3 }).unwrap();
    vec![
        g.clone(),
        Kernel::try_new(&Profile::Gaussians { sigmas: vec![0.6, 0.25], weights: vec![1.0, 0.5] }).unwrap(),
        cauchy.truncated(0.2).unwrap(), // tapers from radius 0.6 to 0.75, inside the shapes
        cauchy,
        g.truncated(1e-3).unwrap(),
    ]
}

/// Every combination of the three factors (with a Gaussian signal kernel,
/// and a constant one for the first position kernel).
pub fn kernels() -> Vec<VarifoldKernel> {
    let mut out = Vec::new();
    for (p, kp) in position_kernels().into_iter().enumerate() {
        for grass in GRASS {
            out.push(VarifoldKernel::try_new(kp.clone(), SignalKernel::Gaussian { sigma: 0.5 }, grass).unwrap());
            if p == 0 {
                out.push(VarifoldKernel::try_new(kp.clone(), SignalKernel::Constant, grass).unwrap());
            }
        }
    }
    out
}

/// Pairs of random fshapes of each kind: surfaces in R³, curves in R² and
/// R³, triangulated squares in R². Sizes above one block of cells (16).
pub fn shape_pairs(seed: u64) -> Vec<(&'static str, FShape, FShape)> {
    vec![
        ("surface", perturbed_icosphere(1, 0.1, seed), perturbed_icosphere(2, 0.1, seed + 1)),
        ("curve in R^2", random_curve(2, 45, seed), random_curve(2, 70, seed + 1)),
        ("curve in R^3", random_curve(3, 50, seed), random_curve(3, 33, seed + 1)),
        ("square", random_square(40, seed), random_square(60, seed + 1)),
    ]
}
