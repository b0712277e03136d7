//! Mixed-precision sums out_i = Σ_j k(|x_i − y_j|²) b_j for sums of
//! Gaussians, exact or truncated ([`Precision::MixedF32`]): f64 inputs and
//! results, the pair terms evaluated in f32 (twice the SIMD lanes of f64
//! and an exponential of degree 7 instead of 12), summed in f32 over at
//! most [`FLUSH`] sources and then in f64.
//!
//! Accuracy. Coordinates enter f32 relative to the centre c of the target
//! block (k-d sorted, so blocks are small): x_i − c and y_j − c are
//! rounded, so x_i − y_j carries an error of a few f32 ulps of
//! |x_i − y_j| + h, h the block's half-diagonal. With ε = 2⁻²⁴ and a the
//! largest 1/(2σ_t²), each output obeys (derived term by term in the code
//! below; tested against an f64 oracle on random inputs)
//!
//! |out_i − exact_i| ≤ ε Σ_j |b_j| [ k_ij (32 + 3a(h² + 4u_ij))
//!              + 1{u_in < u_ij < u_out} k⁰_ij (80 + 2(2h² + 9u_ij + u_in)/(u_out − u_in)) ]
//!              + 5·10⁻³⁸ Σ_t w_t Σ_j |b_j|
//!
//! where exact_i is the f64 sum of the same (possibly truncated) kernel,
//! u_ij = |x_i − y_j|² and k⁰ the untapered kernel. The first term: the
//! rounded difference gives |δu| ≤ ε(2h² + 9u), the f32 exponent
//! −a·u then errs by ε·a(2h² + 11u); the exponential adds 6ε, the weights,
//! terms, products and the taper's multiplication 8ε, the f32 partial sum
//! 15ε. The second: the taper s(u) computed in f32 (|s'| ≤ 1.875/(u_out −
//! u_in) times the error of u − u_in, plus 71ε for its polynomial), which
//! only matters where k⁰ ≤ τ·k(0). The last: f32 exponentials below e^{−87}
//! (f32's normal range) are set to 0. The terms in a·u weigh little where
//! they are large (a·u·e^{−au} ≤ 1/e), so the constant dominates in
//! practice: the measured max_i |err_i| / max_i |exact_i| on the 32k
//! cortex is about 10⁻⁷ (README), and the test's largest error is 0.1 of
//! the bound.
//!
//! Sums are taken in an order fixed by the data (block runs, then j), so
//! serial and parallel results agree bit for bit, as on the f64 paths.

#![expect(clippy::needless_range_loop, reason = "explicit lane loops are the vectorisation idiom")]

use pulp::{Simd, WithSimd};

use crate::taper::{GaussTerms, quintic_taper};
use crate::{BlockPairs, SourceRun, Taper};

/// Targets per block, as f32 lanes: 32 (two AVX-512 registers) measured
/// 1.3× faster here than the f64 paths' 16.
const L: usize = 32;

/// Sources summed in f32 before the partial sums join the f64 ones: the
/// f32 accumulation error stays below (FLUSH − 1)·ε of Σ|k b|.
const FLUSH: usize = 16;

/// Which arithmetic [`KernelSums::conv`](crate::KernelSums::conv) uses for
/// sums of Gaussians.
///
/// ```
/// use fshape_kernels::{Kernel, KernelSums, Precision};
/// let k = Kernel::gaussian(1.0)?.truncated(1e-6)?;
/// let y = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
/// let sums = KernelSums::try_new(&k, &y, 3)?.with_precision(Precision::MixedF32);
/// let out = sums.conv(&[0.0, 0.0, 0.0], &[1.0, 1.0], 1)?;
/// // Within a few f32 roundings of 1 + e^{−1/2}.
/// assert!((out[0] - (1.0 + (-0.5f64).exp())).abs() < 1e-6);
/// # Ok::<(), fshape_kernels::KernelError>(())
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precision {
    /// f64 throughout (the default; every derivative is always f64).
    #[default]
    F64,
    /// Pair terms in f32, partial sums of 16 terms added in f64, results in
    /// f64, with the per-output error bound of the crate's `mixed` module
    /// (ε₃₂ times a small multiple of Σ_j k_ij |b_j|). About twice as fast.
    /// Only [`KernelSums::conv`](crate::KernelSums::conv) of sums of
    /// Gaussians uses it; other kernels and operations stay f64.
    MixedF32,
}

/// exp(x) for each lane, x ≤ 0, in f32 (x < −87 gives 0, below f32's
/// normal range). Cody–Waite reduction x = n ln2 + r, |r| ≤ ln2/2, the
/// degree-7 Taylor polynomial of e^r (truncation < 6e-9 relative), 2ⁿ from
/// its exponent bits: within 3 f32 ulps of e^x (tested).
#[inline(always)]
fn exp_lanes_f32(x: [f32; L]) -> [f32; L] {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // 1.5·2^23: adding it rounds to an integer held in the low mantissa bits.
    const MAGIC: f32 = 12_582_912.0;
    // ln 2 = LN2_HI + LN2_LO, LN2_HI with 9 significant bits so that
    // n·LN2_HI is exact for |n| ≤ 126.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let mut out = [0.0f32; L];
    for l in 0..L {
        let xl = if x[l] < -87.0 { -87.0 } else { x[l] };
        let t = xl * LOG2E + MAGIC;
        let n = t - MAGIC;
        let r = (xl - n * LN2_HI) - n * LN2_LO;
        // Estrin's scheme for 1 + r + r²/2 + … + r⁷/7!.
        let r2 = r * r;
        let r4 = r2 * r2;
        let q0 = 1.0 + r;
        let q1 = 0.5 + r * (1.0 / 6.0);
        let q2 = (1.0 / 24.0) + r * (1.0 / 120.0);
        let q3 = (1.0 / 720.0) + r * (1.0 / 5040.0);
        let p = (q0 + q1 * r2) + (q2 + q3 * r2) * r4;
        let bits = ((t.to_bits() as i32 - MAGIC.to_bits() as i32 + 127) << 23) as u32;
        let e = p * f32::from_bits(bits);
        out[l] = if x[l] < -87.0 { 0.0 } else { e };
    }
    out
}

/// The kernel's terms and taper in f32.
#[derive(Clone, Copy)]
struct Terms32 {
    a: [f32; crate::taper::MAX_TERMS],
    w: [f32; crate::taper::MAX_TERMS],
    n: usize,
    /// (u_in, 1/(u_out − u_in)).
    taper: Option<(f32, f32)>,
}

impl Terms32 {
    fn new(terms: &GaussTerms, taper: Option<Taper>) -> Self {
        Terms32 {
            a: terms.a.map(|v| v as f32),
            w: terms.w.map(|v| v as f32),
            n: terms.n,
            taper: taper.map(|t| (t.u_in as f32, (1.0 / (t.u_out - t.u_in)) as f32)),
        }
    }
}

/// One block of L targets (coordinates relative to `centre`, in f32)
/// against its source runs.
struct Block<'a, const D: usize, const BD: usize> {
    terms: Terms32,
    centre: [f64; D],
    x: &'a [[f32; L]; D],
    /// Sorted sources (f64) and weights (f32).
    ys: &'a [[f64; D]],
    bs: &'a [[f32; BD]],
    runs: &'a [SourceRun],
}

impl<const D: usize, const BD: usize> WithSimd for Block<'_, D, BD> {
    type Output = [[f64; L]; BD];

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> Self::Output {
        let mut acc = [[0.0f64; L]; BD];
        for run in self.runs {
            let taper = if run.tapered { self.terms.taper } else { None };
            let mut start = run.range.start;
            while start < run.range.end {
                let end = (start + FLUSH).min(run.range.end);
                let part = self.chunk(start..end, taper);
                for c in 0..BD {
                    for l in 0..L {
                        acc[c][l] += part[c][l] as f64;
                    }
                }
                start = end;
            }
        }
        acc
    }
}

impl<const D: usize, const BD: usize> Block<'_, D, BD> {
    /// Σ_j k b_j over sorted sources `range`, in f32.
    #[inline(always)]
    fn chunk(&self, range: std::ops::Range<usize>, taper: Option<(f32, f32)>) -> [[f32; L]; BD] {
        let tm = &self.terms;
        let mut acc = [[0.0f32; L]; BD];
        for j in range {
            // Rounded once per source, relative to the block centre.
            let y: [f32; D] = std::array::from_fn(|k| (self.ys[j][k] - self.centre[k]) as f32);
            let mut u = [0.0f32; L];
            for k in 0..D {
                for l in 0..L {
                    let d = self.x[k][l] - y[k];
                    u[l] += d * d;
                }
            }
            let mut k0 = [0.0f32; L];
            for t in 0..tm.n {
                let mut arg = [0.0f32; L];
                for l in 0..L {
                    arg[l] = -tm.a[t] * u[l];
                }
                let e = exp_lanes_f32(arg);
                for l in 0..L {
                    k0[l] += tm.w[t] * e[l];
                }
            }
            if let Some((u_in, inv)) = taper {
                for l in 0..L {
                    let x = ((u[l] - u_in) * inv).clamp(0.0, 1.0);
                    k0[l] *= quintic_taper!(x);
                }
            }
            let b = &self.bs[j];
            for c in 0..BD {
                for l in 0..L {
                    acc[c][l] += k0[l] * b[c];
                }
            }
        }
        acc
    }
}

/// The mixed-precision conv for 2 or 3 dimensions and 1 to 3 weight
/// components (`None` otherwise, or where f32 cannot hold the kernel's
/// 1/(2σ²) as a normal number or the squared distances: the caller then
/// takes the f64 path). Inputs were validated by the caller.
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv(
    terms: &GaussTerms,
    taper: Option<Taper>,
    x: &[f64],
    y: &[f64],
    b: &[f64],
    dim: usize,
    bdim: usize,
    parallel: bool,
) -> Option<Vec<f64>> {
    let a_fits = terms.a[..terms.n].iter().all(|&a| (a as f32).is_normal());
    let extent = x.iter().chain(y).fold(0.0f64, |m, v| m.max(v.abs()));
    if !a_fits || extent > 1e18 {
        return None;
    }
    Some(match (dim, bdim) {
        (2, 1) => run::<2, 1>(terms, taper, x, y, b, parallel),
        (2, 2) => run::<2, 2>(terms, taper, x, y, b, parallel),
        (2, 3) => run::<2, 3>(terms, taper, x, y, b, parallel),
        (3, 1) => run::<3, 1>(terms, taper, x, y, b, parallel),
        (3, 2) => run::<3, 2>(terms, taper, x, y, b, parallel),
        (3, 3) => run::<3, 3>(terms, taper, x, y, b, parallel),
        _ => return None,
    })
}

/// The centre of the bounding box of the targets `idx` of `x`.
fn block_centre<const D: usize>(x: &[f64], idx: &[usize]) -> [f64; D] {
    std::array::from_fn(|k| {
        let (lo, hi) = idx
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| (lo.min(x[i * D + k]), hi.max(x[i * D + k])));
        0.5 * (lo + hi)
    })
}

fn run<const D: usize, const BD: usize>(
    terms: &GaussTerms,
    taper: Option<Taper>,
    x: &[f64],
    y: &[f64],
    b: &[f64],
    parallel: bool,
) -> Vec<f64> {
    // Sorted even for an exact kernel: the error bound grows with the
    // target blocks' size.
    let mut pairs = BlockPairs::default();
    pairs.rebuild_blocks(x, y, D, taper, true, L);
    let order = pairs.source_order();
    let ys: Vec<[f64; D]> = order.iter().map(|&j| std::array::from_fn(|k| y[j * D + k])).collect();
    let bs: Vec<[f32; BD]> = order.iter().map(|&j| std::array::from_fn(|c| b[j * BD + c] as f32)).collect();
    let n = x.len() / D;
    let mut rows = vec![0.0; n * BD];
    let arch = crate::simd::arch();
    let tm = Terms32::new(terms, taper);
    pairs.for_each_block(parallel, &mut rows, BD, |targets, runs, out| {
        let centre = block_centre::<D>(x, targets);
        // Unused lanes repeat the last target.
        let lane = |l: usize| targets[l.min(targets.len() - 1)];
        let xl: [[f32; L]; D] =
            std::array::from_fn(|k| std::array::from_fn(|l| (x[lane(l) * D + k] - centre[k]) as f32));
        let acc = arch.dispatch(Block::<D, BD> { terms: tm, centre, x: &xl, ys: &ys, bs: &bs, runs });
        for (l, row) in out.chunks_exact_mut(BD).enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = acc[c][l];
            }
        }
    });
    let mut out = vec![0.0; n * BD];
    for (row, &i) in rows.chunks_exact(BD).zip(pairs.target_order()) {
        out[i * BD..(i + 1) * BD].copy_from_slice(row);
    }
    out
}

#[cfg(test)]
mod tests {
    use fshape_mesh::generate::SplitMix64;
    use proptest::prelude::*;

    use super::{L, exp_lanes_f32};
    use crate::{BlockPairs, Kernel, KernelSums, Precision, Profile};

    /// Uniform points in [0, 1]^dim, or three tight clusters with exact
    /// repeats.
    fn points(n: usize, dim: usize, clustered: bool, rng: &mut SplitMix64) -> Vec<f64> {
        let centres: Vec<f64> = (0..3 * dim).map(|_| rng.uniform()).collect();
        let mut out: Vec<f64> = Vec::with_capacity(n * dim);
        for i in 0..n {
            if clustered && i % 7 == 3 {
                let prev = out[(i - 1) * dim..i * dim].to_vec();
                out.extend(prev);
            } else if clustered {
                out.extend((0..dim).map(|k| centres[(i % 3) * dim + k] + 0.01 * rng.range(-1.0, 1.0)));
            } else {
                out.extend((0..dim).map(|_| rng.uniform()));
            }
        }
        out
    }

    /// The stated bound (module docs) for each output, computed with f64
    /// double loops, with h the half-diagonal of the target's block.
    #[allow(clippy::too_many_arguments)]
    fn check(base: &Kernel, k: &Kernel, x: &[f64], y: &[f64], b: &[f64], dim: usize, bdim: usize, name: &str) -> f64 {
        let eps = f64::from(f32::EPSILON) / 2.0;
        let out = KernelSums::try_new(k, y, dim).unwrap().with_precision(Precision::MixedF32).conv(x, b, bdim).unwrap();
        let (nx, ny) = (x.len() / dim, y.len() / dim);
        let mut h = vec![0.0; nx];
        let mut pairs = BlockPairs::default();
        pairs.rebuild_blocks(x, y, dim, k.taper(), true, super::L);
        pairs
            .map_blocks(false, |targets, _| {
                let half: f64 = (0..dim)
                    .map(|c| {
                        let v = targets.iter().map(|&i| x[i * dim + c]);
                        let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
                        (0.5 * (hi - lo)).powi(2)
                    })
                    .sum::<f64>()
                    .sqrt();
                targets.iter().map(|&i| (i, half)).collect::<Vec<_>>()
            })
            .concat()
            .into_iter()
            .for_each(|(i, half)| h[i] = half);
        let a = base.gaussian_terms().unwrap();
        let a_max = a.a[..a.n].iter().copied().fold(0.0, f64::max);
        let mut worst: f64 = 0.0;
        for i in 0..nx {
            for c in 0..bdim {
                let (mut exact, mut bound, mut scale) = (0.0, 0.0, 0.0);
                for j in 0..ny {
                    let u: f64 = (0..dim).map(|d| (x[i * dim + d] - y[j * dim + d]).powi(2)).sum();
                    let (kij, bj) = (k.value(u), b[j * bdim + c]);
                    exact += kij * bj;
                    scale += kij * bj.abs();
                    let mut term = kij * (32.0 + 3.0 * a_max * (h[i] * h[i] + 4.0 * u));
                    if let Some(t) = k.taper().filter(|t| u > t.u_in && u < t.u_out) {
                        let hh = 2.0 * h[i] * h[i] + 9.0 * u + t.u_in;
                        term += base.value(u) * (80.0 + 2.0 * hh / (t.u_out - t.u_in));
                    }
                    bound += eps * term * bj.abs();
                }
                bound += 5e-38 * a.w[..a.n].iter().sum::<f64>() * (0..ny).map(|j| b[j * bdim + c].abs()).sum::<f64>();
                let err = (out[i * bdim + c] - exact).abs();
                // Plus the f64 oracle's own rounding.
                assert!(err <= bound + 1e-14 * scale, "{name}: target {i}: error {err:e} above the bound {bound:e}");
                if bound > 0.0 {
                    worst = worst.max(err / bound);
                }
            }
        }
        worst
    }

    #[test]
    fn widths_and_coordinates_beyond_f32_take_the_f64_path() {
        // 1/(2σ²) overflows f32 for σ = 1e-25 (then −a·0 would be NaN at a
        // repeated point) and is 0 in f32 for σ = 1e25; coordinates of 1e30
        // square beyond f32. Each must give the f64 result, bit for bit.
        let y = [0.0, 0.0, 0.0, 1e-26, 0.0, 0.0, 2.0, 1.0, 0.0];
        let big = [1e30, 0.0, 0.0, -1e30, 0.0, 0.0, 0.0, 0.0, 0.0];
        let b = [1.0, 2.0, 3.0];
        for (sigma, pts) in [(1e-25, &y), (1e25, &y), (1.0, &big)] {
            let k = Kernel::gaussian(sigma).unwrap();
            let f64_sum = KernelSums::try_new(&k, pts, 3).unwrap().conv(pts, &b, 1).unwrap();
            let mixed = KernelSums::try_new(&k, pts, 3).unwrap().with_precision(Precision::MixedF32);
            let out = mixed.conv(pts, &b, 1).unwrap();
            assert!(out.iter().all(|v| v.is_finite()), "sigma {sigma}: {out:?}");
            assert_eq!(out, f64_sum, "sigma {sigma}");
        }
    }

    proptest! {
        #![proptest_config(fshape_mesh::test_support::strategies::config(6, 2024))]

        #[test]
        fn mixed_precision_sums_are_within_the_stated_bound(seed in any::<u64>()) {
            let mut rng = SplitMix64(seed);
            let mut worst: f64 = 0.0;
            let profiles = [
                Profile::Gaussian { sigma: 0.4 },
                Profile::Gaussian { sigma: 0.05 },
                Profile::Gaussians { sigmas: vec![0.5, 0.2], weights: vec![1.0, 0.5] },
            ];
            for p in profiles {
                let base = Kernel::try_new(&p).unwrap();
                for k in [base.clone(), base.truncated(1e-3).unwrap(), base.truncated(1e-6).unwrap()] {
                    for dim in [2, 3] {
                        for bdim in 1..=3 {
                            let cases = [
                                (points(37, dim, false, &mut rng), points(300, dim, false, &mut rng)),
                                (points(41, dim, true, &mut rng), points(290, dim, true, &mut rng)),
                                (points(1, dim, false, &mut rng), points(17, dim, false, &mut rng)), // N = 1
                                (points(5, dim, false, &mut rng), Vec::new()),                       // M = 0
                                (points(1, dim, false, &mut rng).repeat(6), points(1, dim, false, &mut rng).repeat(9)),
                            ];
                            for (x, y) in cases {
                                let b: Vec<f64> = (0..y.len() / dim * bdim).map(|_| rng.range(-1.0, 1.0)).collect();
                                let name = format!("{p:?} {:?} dim {dim} bdim {bdim} n {}", k.taper(), x.len() / dim);
                                worst = worst.max(check(&base, &k, &x, &y, &b, dim, bdim, &name));
                            }
                        }
                    }
                }
            }
            // The f32 arithmetic is really used (an f64 result would sit far
            // below the bound) and the bound is not slack by orders of magnitude.
            assert!(worst > 0.01, "errors at most {worst:e} of the bound");
            eprintln!("largest error / bound: {worst:.3}");
        }
    }

    #[test]
    fn the_f32_exponential_is_accurate_to_a_few_ulps() {
        let mut args: Vec<f32> = (0..200_000).map(|k| -(k as f32) * 87.0 / 200_000.0).collect();
        args.extend((0..10_000).map(|k| -(k as f32) * 1e-6));
        args.extend([0.0, -1e-30, -86.9, -87.0]);
        let mut worst: f64 = 0.0;
        for chunk in args.chunks(L) {
            let mut x = [0.0f32; L];
            x[..chunk.len()].copy_from_slice(chunk);
            let e = exp_lanes_f32(x);
            for (l, &a) in chunk.iter().enumerate() {
                let exact = (a as f64).exp();
                worst = worst.max((e[l] as f64 - exact).abs() / exact);
            }
        }
        assert!(worst < 3.0 * f32::EPSILON as f64, "max relative error {worst:e}");
        let mut x = [-100.0f32; L];
        x[0] = f32::NEG_INFINITY;
        assert_eq!(exp_lanes_f32(x), [0.0; L]);
    }
}
