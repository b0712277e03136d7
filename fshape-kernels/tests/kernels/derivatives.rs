//! Gradients and Jacobian–vector products against central finite differences.

use fshape_kernels::KernelSums;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, check_jvp, random_direction};

use crate::{kernels, uniform};

const H: f64 = 1e-6;
/// Central differences with h = 1e-6 on O(1) data: truncation ~1e-12,
/// rounding ~1e-10 relative; a missing or wrong term is off by O(1).
const TOL: f64 = 1e-6;

#[test]
fn cross_gradient_and_self_gradient() {
    let mut rng = SplitMix64(21);
    for (name, k) in kernels() {
        for dim in [2, 3] {
            let (x, y) = (uniform(25, dim, &mut rng), uniform(20, dim, &mut rng));
            let bdim = dim;
            let a = random_direction(25 * bdim, &mut rng);
            let b = random_direction(20 * bdim, &mut rng);
            let v = random_direction(x.len(), &mut rng);
            let sums = KernelSums::try_new(&k, &y, dim).unwrap();
            // aᵀ K_xy b as a function of x.
            let f = |xx: &[f64]| sums.conv(xx, &b, bdim).unwrap().iter().zip(&a).map(|(p, q)| p * q).sum::<f64>();
            let g = sums.grad_cross(&x, &a, &b, bdim).unwrap();
            let c = check_gradient(f, &x, &g, &v, H);
            assert!(c.rel_error < TOL, "{name} cross dim {dim}: {c:?}");
            // pᵀ K_xx p with both slots moving: gradient = 2 grad_cross(x, x, p, p).
            let p = random_direction(25 * bdim, &mut rng);
            let f = |xx: &[f64]| {
                let s = KernelSums::try_new(&k, xx, dim).unwrap();
                s.conv(xx, &p, bdim).unwrap().iter().zip(&p).map(|(u, w)| u * w).sum::<f64>()
            };
            let g: Vec<f64> = KernelSums::try_new(&k, &x, dim)
                .unwrap()
                .grad_cross(&x, &p, &p, bdim)
                .unwrap()
                .iter()
                .map(|v| 2.0 * v)
                .collect();
            let c = check_gradient(f, &x, &g, &v, H);
            assert!(c.rel_error < TOL, "{name} self dim {dim}: {c:?}");
        }
    }
}

#[test]
fn jacobian_vector_products() {
    let mut rng = SplitMix64(22);
    for (name, k) in kernels() {
        let dim = 3;
        let x = uniform(20, dim, &mut rng);
        let p = random_direction(60, &mut rng);
        let a = random_direction(60, &mut rng);
        let (dx, dp, da) =
            (random_direction(60, &mut rng), random_direction(60, &mut rng), random_direction(60, &mut rng));
        // Self-interaction: y = x moves with x; b = p moves too.
        let state = |z: &[f64]| (z[..60].to_vec(), z[60..120].to_vec(), z[120..].to_vec());
        let z: Vec<f64> = x.iter().chain(&p).chain(&a).copied().collect();
        let dz: Vec<f64> = dx.iter().chain(&dp).chain(&da).copied().collect();
        let conv = |z: &[f64]| {
            let (x, p, _) = state(z);
            KernelSums::try_new(&k, &x, dim).unwrap().conv(&x, &p, 3).unwrap()
        };
        let sums = KernelSums::try_new(&k, &x, dim).unwrap();
        let jv = sums.conv_jvp(&x, &dx, &dx, &p, &dp, 3).unwrap();
        let c = check_jvp(conv, &z, &dz, &jv, H);
        assert!(c.rel_error < TOL, "{name} conv_jvp: {c:?}");
        let grad = |z: &[f64]| {
            let (x, p, a) = state(z);
            KernelSums::try_new(&k, &x, dim).unwrap().grad_cross(&x, &a, &p, 3).unwrap()
        };
        let jv = sums.grad_cross_jvp(&x, &dx, &dx, &a, &da, &p, &dp, 3).unwrap();
        let c = check_jvp(grad, &z, &dz, &jv, H);
        assert!(c.rel_error < TOL, "{name} grad_cross_jvp: {c:?}");
    }
}
