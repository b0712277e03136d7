//! The vectorised path for the most common case: an exact sum with one
//! Gaussian. Four targets are processed together in the lanes of an f64x4
//! (wide), so each target's sum still runs over j in increasing order, and
//! each y_j is loaded once per four targets. The lanes are fixed by i (block
//! i/4), so results do not depend on the number of threads. `wide`'s exp
//! differs from libm's by a few ulps; the tests bound it against the scalar
//! oracle.

use rayon::prelude::*;
use wide::f64x4;

/// Σ_j w exp(−a |x_i − y_j|²) b_j for every target i.
#[allow(clippy::too_many_arguments)]
pub(crate) fn gaussian_conv(
    a: f64,
    w: f64,
    x: &[f64],
    y: &[f64],
    dim: usize,
    b: &[f64],
    bdim: usize,
    parallel: bool,
) -> Vec<f64> {
    const L: usize = 4;
    let nx = x.len() / dim;
    let m = y.len() / dim;
    let mut out = vec![0.0; nx * bdim];
    let block = |(blk, o): (usize, &mut [f64])| {
        let i0 = blk * L;
        let lanes = o.len() / bdim.max(1);
        // Target coordinates by axis, the last target repeated in unused lanes.
        let mut xs = [f64x4::ZERO; 3];
        for (k, xk) in xs.iter_mut().enumerate().take(dim) {
            let mut lane = [0.0; L];
            for (l, v) in lane.iter_mut().enumerate() {
                *v = x[(i0 + l.min(lanes - 1)) * dim + k];
            }
            *xk = f64x4::new(lane);
        }
        let na = f64x4::splat(-a);
        let mut acc = vec![f64x4::ZERO; bdim];
        for j in 0..m {
            let yj = &y[j * dim..(j + 1) * dim];
            let mut u = f64x4::ZERO;
            for k in 0..dim {
                let d = xs[k] - f64x4::splat(yj[k]);
                u += d * d;
            }
            let e = (u * na).exp();
            for (c, acc_c) in acc.iter_mut().enumerate() {
                *acc_c += e * f64x4::splat(b[j * bdim + c]);
            }
        }
        for (c, acc_c) in acc.iter().enumerate() {
            let v = acc_c.to_array();
            for l in 0..lanes {
                o[l * bdim + c] = w * v[l];
            }
        }
    };
    if parallel {
        out.par_chunks_mut(L * bdim.max(1)).enumerate().for_each(block);
    } else {
        out.chunks_mut(L * bdim.max(1)).enumerate().for_each(block);
    }
    out
}
