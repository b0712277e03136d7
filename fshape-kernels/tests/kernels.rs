//! Integration tests of fshape-kernels (one binary, modules in `tests/kernels/`).

#[path = "kernels/derivatives.rs"]
mod derivatives;
#[path = "kernels/grid.rs"]
mod grid;
#[path = "kernels/oracle.rs"]
mod oracle;
#[path = "kernels/profiles.rs"]
mod profiles;

use fshape_kernels::{Kernel, Profile};
use fshape_mesh::generate::SplitMix64;

/// The kernels under test: each profile, plain and truncated.
pub fn kernels() -> Vec<(String, Kernel)> {
    let profiles = [
        Profile::Gaussian { sigma: 0.4 },
        Profile::Gaussians { sigmas: vec![0.5, 0.2], weights: vec![1.0, 0.5] },
        // Widths σ and σ/2: exp(−a₂u) is computed as exp(−a₁u)⁴.
        Profile::Gaussians { sigmas: vec![0.4, 0.2], weights: vec![1.0, 0.7] },
        Profile::Cauchy { sigma: 0.3 },
    ];
    let mut out = Vec::new();
    for p in profiles {
        let k = Kernel::try_new(&p).unwrap();
        out.push((format!("{p:?} truncated 1e-3"), k.truncated(1e-3).unwrap()));
        out.push((format!("{p:?}"), k));
    }
    out
}

/// `n` points of `dim` coordinates, uniform in [0, 1]^dim.
pub fn uniform(n: usize, dim: usize, rng: &mut SplitMix64) -> Vec<f64> {
    (0..n * dim).map(|_| rng.uniform()).collect()
}

/// `n` points in a few tight clusters, with some exact repeats.
pub fn clustered(n: usize, dim: usize, rng: &mut SplitMix64) -> Vec<f64> {
    let centres = uniform(3, dim, rng);
    let mut out = Vec::with_capacity(n * dim);
    for i in 0..n {
        if i % 7 == 3 && i > 0 {
            let prev = out[(i - 1) * dim..i * dim].to_vec();
            out.extend(prev); // an exact repeat of the previous point
            continue;
        }
        let c = (i % 3) * dim;
        for k in 0..dim {
            out.push(centres[c + k] + 0.01 * rng.range(-1.0, 1.0));
        }
    }
    out
}
