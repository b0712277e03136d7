//! The vectorised paths for the most common case: exact sums with a
//! Gaussian or a sum of a few Gaussians (the multi-scale deformation
//! kernels): out_i = Σ_j k(|x_i − y_j|²) b_j, the x-gradient of aᵀK b, and
//! the directional derivatives of both (the exact adjoint of shooting).
//!
//! Eight targets are processed together as the lanes of `[f64; 8]` arrays,
//! so each target's sum still runs over j in increasing order and each y_j
//! is loaded once per eight targets; the lanes are fixed by i (block i/8),
//! so results do not depend on the number of threads. The block kernel is
//! plain lane-wise arithmetic, compiled through pulp's runtime dispatch
//! (AVX-512, AVX2 or scalar, whichever the CPU has) so that LLVM vectorises
//! it without special build flags and without unsafe code here. It uses no
//! fused multiply-add, so every instruction set gives the same bits.
//!
//! The exponential is written here ([`exp_lanes`]) because the arguments
//! are always finite and ≤ 0: the general-purpose SIMD exps (wide's, with
//! NaN/overflow handling and a degree-13 polynomial) cost about twice as
//! much. Its accuracy against libm is tested.

// Lane loops indexed by the lane number are the shape LLVM's vectoriser
// turns into SIMD; iterator chains over several arrays are not.
#![expect(clippy::needless_range_loop, reason = "explicit lane loops are the vectorisation idiom")]

use pulp::{Arch, Simd, WithSimd};
use rayon::prelude::*;

use crate::profile::GaussTerms;

/// Lanes per block.
pub const L: usize = 32;

/// exp(x) for each lane, for x ≤ 0 (x < −708 gives 0, below
/// f64's normal range); also exact to a few ulps for 0 < x ≤ 1 (rounding
/// can push a Gaussian's argument slightly above 0), tested. Cody–Waite reduction x = n ln2 + r, |r| ≤ ln2/2,
/// the degree-12 Taylor polynomial of e^r (truncation < 2e-16 relative),
/// and 2ⁿ built from its exponent bits.
#[inline(always)]
pub fn exp_lanes(x: [f64; L]) -> [f64; L] {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    // 1.5·2^52: adding it rounds to an integer held in the low mantissa bits.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    const LN2_HI: f64 = 0.693_145_751_953_125;
    const LN2_LO: f64 = 1.428_606_820_309_417_3e-6;
    const C: [f64; 13] = [
        1.0,
        1.0,
        1.0 / 2.0,
        1.0 / 6.0,
        1.0 / 24.0,
        1.0 / 120.0,
        1.0 / 720.0,
        1.0 / 5040.0,
        1.0 / 40320.0,
        1.0 / 362_880.0,
        1.0 / 3_628_800.0,
        1.0 / 39_916_800.0,
        1.0 / 479_001_600.0,
    ];
    // Each stage is a plain loop over the lanes, the shape LLVM vectorises.
    let mut xl = [0.0; L];
    for l in 0..L {
        xl[l] = if x[l] < -708.0 { -708.0 } else { x[l] };
    }
    let mut t = [0.0; L];
    let mut r = [0.0; L];
    for l in 0..L {
        t[l] = xl[l] * LOG2E + MAGIC;
        let n = t[l] - MAGIC;
        // n·LN2_HI is exact (LN2_HI has 11 significant bits, |n| ≤ 1022).
        r[l] = (xl[l] - n * LN2_HI) - n * LN2_LO;
    }
    // Estrin's scheme: the same polynomial with a dependency depth of 4
    // instead of Horner's 12, so the lanes' chains overlap.
    let mut p = [0.0; L];
    for l in 0..L {
        let x = r[l];
        let x2 = x * x;
        let x4 = x2 * x2;
        let x8 = x4 * x4;
        let q0 = C[0] + C[1] * x;
        let q1 = C[2] + C[3] * x;
        let q2 = C[4] + C[5] * x;
        let q3 = C[6] + C[7] * x;
        let q4 = C[8] + C[9] * x;
        let q5 = C[10] + C[11] * x;
        let s0 = q0 + q1 * x2;
        let s1 = q2 + q3 * x2;
        let s2 = q4 + q5 * x2 + C[12] * x4;
        p[l] = (s0 + s1 * x4) + s2 * x8;
    }
    let mut out = [0.0; L];
    for l in 0..L {
        // 2ⁿ: the low bits of t hold n (offset by MAGIC's bit pattern).
        let bits = (t[l].to_bits() as i64 - MAGIC.to_bits() as i64 + 1023) << 52;
        let e = p[l] * f64::from_bits(bits as u64);
        out[l] = if x[l] < -708.0 { 0.0 } else { e };
    }
    out
}

/// |x_l − y|² for the L targets held by axis in `x`.
#[inline(always)]
pub(crate) fn sq_dist_lanes<const D: usize>(x: &[[f64; L]; D], y: &[f64]) -> [f64; L] {
    let mut u = [0.0; L];
    for k in 0..D {
        for l in 0..L {
            let d = x[k][l] - y[k];
            u[l] += d * d;
        }
    }
    u
}

/// What a block computes, per target i (k = Σ_t w_t exp(−a_t u), u = |x_i − y_j|²):
/// `CONV`: Σ_j k b_j; `GRAD`: Σ_j 2k' (a_i·b_j)(x_i − y_j); `CONV_JVP` and
/// `GRAD_JVP`: their directional derivatives when x, y, a, b move by
/// dx, dy, da, db (formulas in `sums.rs`).
pub(crate) const CONV: u8 = 0;
pub(crate) const GRAD: u8 = 1;
pub(crate) const CONV_JVP: u8 = 2;
pub(crate) const GRAD_JVP: u8 = 3;

/// The flat inputs of a vectorised sum; unused ones are empty.
#[derive(Clone, Copy)]
pub(crate) struct Inputs<'a> {
    pub(crate) x: &'a [f64],
    pub(crate) dx: &'a [f64],
    pub(crate) y: &'a [f64],
    pub(crate) dy: &'a [f64],
    pub(crate) a: &'a [f64],
    pub(crate) da: &'a [f64],
    pub(crate) b: &'a [f64],
    pub(crate) db: &'a [f64],
}

/// The per-lane target data of one block, by axis or component.
struct Lanes<const D: usize, const BD: usize> {
    x: [[f64; L]; D],
    dx: [[f64; L]; D],
    a: [[f64; L]; BD],
    da: [[f64; L]; BD],
}

/// One block of L targets against every source.
struct Block<'a, const D: usize, const BD: usize, const MODE: u8> {
    terms: &'a GaussTerms,
    t: &'a Lanes<D, BD>,
    inp: Inputs<'a>,
}

impl<const D: usize, const BD: usize, const MODE: u8> WithSimd for Block<'_, D, BD, MODE> {
    /// BD sums per lane (conv modes) or D components (gradient modes); 3
    /// rows are allocated for simplicity (D, BD ≤ 3).
    type Output = [[f64; L]; 3];

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> Self::Output {
        let (t, inp) = (self.t, self.inp);
        let mut acc = [[0.0; L]; 3];
        let m = inp.y.len() / D;
        for j in 0..m {
            let yj = &inp.y[j * D..(j + 1) * D];
            let bj = &inp.b[j * BD..(j + 1) * BD];
            let u = sq_dist_lanes(&t.x, yj);
            // k, k', k'' summed over the terms (each from one exponential).
            let (mut k0, mut k1, mut k2) = ([0.0; L], [0.0; L], [0.0; L]);
            for term in 0..self.terms.n {
                let (a, w) = (self.terms.a[term], self.terms.w[term]);
                let mut arg = [0.0; L];
                for l in 0..L {
                    arg[l] = -a * u[l];
                }
                let e = exp_lanes(arg);
                for l in 0..L {
                    k0[l] += w * e[l];
                    k1[l] -= a * w * e[l];
                    k2[l] += a * a * w * e[l];
                }
            }
            // du = 2 (x_i − y_j)·(dx_i − dy_j), for the JVP modes.
            let mut du = [0.0; L];
            if MODE == CONV_JVP || MODE == GRAD_JVP {
                let dyj = &inp.dy[j * D..(j + 1) * D];
                for k in 0..D {
                    for l in 0..L {
                        du[l] += 2.0 * (t.x[k][l] - yj[k]) * (t.dx[k][l] - dyj[k]);
                    }
                }
            }
            match MODE {
                CONV => {
                    for c in 0..BD {
                        for l in 0..L {
                            acc[c][l] += k0[l] * bj[c];
                        }
                    }
                }
                CONV_JVP => {
                    let dbj = &inp.db[j * BD..(j + 1) * BD];
                    for c in 0..BD {
                        for l in 0..L {
                            acc[c][l] += k1[l] * du[l] * bj[c] + k0[l] * dbj[c];
                        }
                    }
                }
                _ => {
                    let mut ab = [0.0; L];
                    for c in 0..BD {
                        for l in 0..L {
                            ab[l] += t.a[c][l] * bj[c];
                        }
                    }
                    if MODE == GRAD {
                        for k in 0..D {
                            for l in 0..L {
                                acc[k][l] += 2.0 * k1[l] * ab[l] * (t.x[k][l] - yj[k]);
                            }
                        }
                    } else {
                        let (dyj, dbj) = (&inp.dy[j * D..(j + 1) * D], &inp.db[j * BD..(j + 1) * BD]);
                        let mut dab = [0.0; L];
                        for c in 0..BD {
                            for l in 0..L {
                                dab[l] += t.da[c][l] * bj[c] + t.a[c][l] * dbj[c];
                            }
                        }
                        for k in 0..D {
                            for l in 0..L {
                                let diff = t.x[k][l] - yj[k];
                                let ddiff = t.dx[k][l] - dyj[k];
                                acc[k][l] += 2.0 * k2[l] * du[l] * ab[l] * diff
                                    + 2.0 * k1[l] * dab[l] * diff
                                    + 2.0 * k1[l] * ab[l] * ddiff;
                            }
                        }
                    }
                }
            }
        }
        acc
    }
}

/// Runs `MODE` for every target, for an untapered sum of Gaussians, points
/// in 2-D or 3-D and weights of 1 to 3 components (`None` otherwise: the
/// caller uses the general path).
pub(crate) fn gaussian_sum<const MODE: u8>(
    terms: &GaussTerms,
    inp: Inputs<'_>,
    dim: usize,
    bdim: usize,
    parallel: bool,
) -> Option<Vec<f64>> {
    Some(match (dim, bdim) {
        (2, 1) => run::<2, 1, MODE>(terms, inp, parallel),
        (2, 2) => run::<2, 2, MODE>(terms, inp, parallel),
        (2, 3) => run::<2, 3, MODE>(terms, inp, parallel),
        (3, 1) => run::<3, 1, MODE>(terms, inp, parallel),
        (3, 2) => run::<3, 2, MODE>(terms, inp, parallel),
        (3, 3) => run::<3, 3, MODE>(terms, inp, parallel),
        _ => return None,
    })
}

fn run<const D: usize, const BD: usize, const MODE: u8>(
    terms: &GaussTerms,
    inp: Inputs<'_>,
    parallel: bool,
) -> Vec<f64> {
    let nx = inp.x.len() / D;
    let w_out = if MODE == CONV || MODE == CONV_JVP { BD } else { D };
    let mut out = vec![0.0; nx * w_out];
    let arch = Arch::new();
    let uses_a = MODE == GRAD || MODE == GRAD_JVP;
    let uses_d = MODE == CONV_JVP || MODE == GRAD_JVP;
    let block = |(blk, o): (usize, &mut [f64])| {
        let i0 = blk * L;
        let lanes = o.len() / w_out;
        // Unused lanes repeat the last target.
        let lane = |l: usize| i0 + l.min(lanes - 1);
        let pick = |v: &[f64], w: usize, on: bool, c: usize, l: usize| if on { v[lane(l) * w + c] } else { 0.0 };
        let t = Lanes::<D, BD> {
            x: std::array::from_fn(|k| std::array::from_fn(|l| inp.x[lane(l) * D + k])),
            dx: std::array::from_fn(|k| std::array::from_fn(|l| pick(inp.dx, D, uses_d, k, l))),
            a: std::array::from_fn(|c| std::array::from_fn(|l| pick(inp.a, BD, uses_a, c, l))),
            da: std::array::from_fn(|c| std::array::from_fn(|l| pick(inp.da, BD, uses_a && uses_d, c, l))),
        };
        let acc = arch.dispatch(Block::<D, BD, MODE> { terms, t: &t, inp });
        for (c, acc_c) in acc.iter().enumerate().take(w_out) {
            for l in 0..lanes {
                o[l * w_out + c] = acc_c[l];
            }
        }
    };
    if parallel {
        out.par_chunks_mut(L * w_out).enumerate().for_each(block);
    } else {
        out.chunks_mut(L * w_out).enumerate().for_each(block);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::{L, exp_lanes};
    #[test]
    fn the_vectorised_exponential_is_accurate_to_a_few_ulps() {
        // The whole domain used (arguments −a·u ≤ 0), densely near 0 where the
        // Gaussian is large, plus the underflow edge.
        let mut worst: f64 = 0.0;
        let mut args: Vec<f64> = (0..200_000).map(|k| -(k as f64) * 708.0 / 200_000.0).collect();
        args.extend((0..10_000).map(|k| -(k as f64) * 1e-6));
        args.extend([0.0, -1e-300, -707.9, -708.0]);
        args.extend((0..1000).map(|k| k as f64 * 1e-3)); // 0 < x ≤ 1
        for chunk in args.chunks(L) {
            let mut x = [0.0; L];
            x[..chunk.len()].copy_from_slice(chunk);
            let e = exp_lanes(x);
            for (l, &a) in chunk.iter().enumerate() {
                let exact = a.exp();
                worst = worst.max((e[l] - exact).abs() / exact);
            }
        }
        // Degree-12 polynomial on |r| ≤ ln2/2 (truncation < 2e-16) plus ~12
        // roundings: a few ulps.
        assert!(worst < 8.0 * f64::EPSILON, "max relative error {worst:e}");
        // Below the normal range the result is 0.
        let mut x = [-800.0; L];
        x[0] = f64::NEG_INFINITY;
        assert_eq!(exp_lanes(x), [0.0; L]);
    }
}
