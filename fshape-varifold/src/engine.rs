//! The vectorised pair sums behind every inner product: for each target
//! cell i of X and the cells j of Y that [`BlockPairs`] hands it (all of
//! them, or those within k_p's support),
//!
//! - s0_i = Σ_j r_j k_p k_f k_t,
//! - gc_i = Σ_j r_j 2k_p' (c_i − c_j) k_f k_t,
//! - gu_i = Σ_j r_j k_p k_f k_t'(s) u_j,
//! - gf_i = Σ_j r_j k_p ∂_f k_f k_t (one sum per signal channel),
//!
//! with k_p, k_f, k_t at u = |c_i − c_j|², f_i − f_j, s = u_i·u_j; for the
//! Gaussian k_f = exp(−Σ_c b_c (f_ic − f_jc)²), ∂_{f_ic} k_f =
//! −2 b_c (f_ic − f_jc) k_f. Without a signal kernel, one channel of zeros
//! stands in for the signal.
//! Then ⟨μ_X, μ_Y⟩ = Σ_i r_i s0_i, and r_i times the other sums are its
//! derivatives in c_i, u_i and f_i (s0_i is the one in r_i).
//!
//! Targets are processed [`L`] at a time as lanes, like fshape-kernels'
//! own vectorised paths, inside a pulp dispatch so the lane loops compile
//! to the CPU's SIMD instructions. Each target's sum runs over j in the
//! order BlockPairs fixes, so results do not depend on the thread count.

#![expect(clippy::needless_range_loop, reason = "explicit lane loops are the vectorisation idiom")]

use fshape_kernels::BlockPairs;
use fshape_kernels::lanes::{L, exp_lanes, sq_dist_lanes};
use pulp::{Simd, WithSimd};

use crate::{CellFeatures, GrassKernel, VarifoldError, VarifoldKernel};

/// The most signal channels a varifold compares (a run-time count up to
/// this bound, so that one compiled kernel serves every k).
pub const MAX_CHANNELS: usize = 8;

/// Per-lane sums of one target block, aligned to a cache line: the
/// accumulators' loads and stores then never straddle two (4 % of the
/// time on AVX2 in the fsaverage5 timing example).
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Acc<const D: usize, const DU: usize, const NF: usize> {
    s0: [f64; L],
    gc: [[f64; L]; D],
    gu: [[f64; L]; DU],
    gf: [[f64; L]; NF],
}

/// One target block against one run of sorted sources.
///
/// `NF` bounds the signal channels `nf`: 1, the common case compiled with
/// one channel's arrays (MAX_CHANNELS' arrays cost 55 % more time there:
/// the fsaverage5 pair's exact sums, AVX-512, 2026-12-06), or
/// [`MAX_CHANNELS`].
struct Tile<'a, const D: usize, const DU: usize, const GRAD: bool, const NF: usize> {
    k: &'a VarifoldKernel,
    /// k's direction kernel and whether its signal kernel is constant,
    /// read once (the loops do not go back to `k` for them).
    grass: GrassKernel,
    functional: bool,
    /// Signal channels (1, of zeros, without a signal kernel), and each
    /// channel's b_c = 1/(2σ_c²) (0 without a signal kernel).
    nf: usize,
    b: &'a [f64; MAX_CHANNELS],
    tc: &'a [[f64; L]; D],
    tu: &'a [[f64; L]; DU],
    tf: &'a [[f64; L]; NF],
    sc: &'a [[f64; D]],
    su: &'a [[f64; DU]],
    /// `nf` values per source cell.
    sf: &'a [f64],
    sr: &'a [f64],
    tapered: bool,
    acc: Acc<D, DU, NF>,
}

impl<const D: usize, const DU: usize, const GRAD: bool, const NF: usize> WithSimd for Tile<'_, D, DU, GRAD, NF> {
    type Output = Acc<D, DU, NF>;

    #[inline(always)]
    fn with_simd<S: Simd>(mut self, _simd: S) -> Self::Output {
        if let Some((a, w, taper)) = self.k.position().single_gaussian() {
            self.fused(a, w, if self.tapered { taper } else { None });
            return self.acc;
        }
        let acc = &mut self.acc;
        for j in 0..self.sr.len() {
            let (cj, uj, rj) = (&self.sc[j], &self.su[j], self.sr[j]);
            let u2 = sq_dist_lanes(self.tc, cj);
            let (kp, kp1) = self.k.position().lanes(&u2, self.tapered);
            // k_f and f_i − f_j per channel (k_f's derivative in
            // v_c = (f_ic − f_jc)² is −b_c k_f).
            let nf = if NF == 1 { 1 } else { self.nf };
            let mut df = [[0.0; L]; NF];
            let kf = if !self.functional {
                [1.0; L]
            } else {
                let mut arg = [0.0; L];
                for c in 0..nf {
                    let (b, fj) = (self.b[c], self.sf[j * nf + c]);
                    for l in 0..L {
                        df[c][l] = self.tf[c][l] - fj;
                        let a = -b * df[c][l] * df[c][l];
                        arg[l] = if c == 0 { a } else { arg[l] + a };
                    }
                }
                exp_lanes(arg)
            };
            let mut s = [0.0; L];
            for k in 0..DU {
                for l in 0..L {
                    s[l] += self.tu[k][l] * uj[k];
                }
            }
            // k_t = p·e^{arg_t}, k_t' = (p·q + p')·e^{arg_t} (grass_lanes).
            let (p, p1, q, arg_t) = grass_lanes(self.grass, &s);
            let et = match arg_t {
                Some(at) => exp_lanes(at),
                None => [1.0; L],
            };
            let (mut kt, mut kt1) = ([0.0; L], [0.0; L]);
            for l in 0..L {
                kt[l] = p[l] * et[l];
                kt1[l] = (p[l] * q[l] + p1[l]) * et[l];
            }
            let mut m = [0.0; L];
            for l in 0..L {
                m[l] = rj * kf[l] * kt[l];
                acc.s0[l] += kp[l] * m[l];
            }
            if GRAD {
                for k in 0..D {
                    for l in 0..L {
                        acc.gc[k][l] += 2.0 * kp1[l] * m[l] * (self.tc[k][l] - cj[k]);
                    }
                }
                let mut w = [0.0; L];
                for l in 0..L {
                    w[l] = rj * kp[l] * kf[l] * kt1[l];
                }
                if self.functional {
                    for c in 0..nf {
                        let b = self.b[c];
                        for l in 0..L {
                            acc.gf[c][l] += 2.0 * rj * kp[l] * (-b * kf[l]) * df[c][l] * kt[l];
                        }
                    }
                }
                for k in 0..DU {
                    for l in 0..L {
                        acc.gu[k][l] += w[l] * uj[k];
                    }
                }
            }
        }
        self.acc
    }
}

impl<const D: usize, const DU: usize, const GRAD: bool, const NF: usize> Tile<'_, D, DU, GRAD, NF> {
    /// The common case, k_p a single Gaussian w·exp(−a u): the exponential
    /// factors k_p, k_f and (for the Gaussian direction kernels) k_t are
    /// computed as one exponential of the sum of their arguments, three
    /// times fewer than the general loop. The same sums to rounding (the
    /// oracle tests cover both loops).
    #[inline(always)]
    fn fused(&mut self, a: f64, w: f64, taper: Option<fshape_kernels::Taper>) {
        let acc = &mut self.acc;
        let nf = if NF == 1 { 1 } else { self.nf };
        let bs: [f64; NF] = std::array::from_fn(|c| self.b[c]);
        let sf = self.sf;
        for j in 0..self.sr.len() {
            let (cj, uj, rj) = (&self.sc[j], &self.su[j], self.sr[j]);
            let u2 = sq_dist_lanes(self.tc, cj);
            let mut df = [[0.0; L]; NF];
            for c in 0..nf {
                let fj = sf.get(j * nf + c).copied().unwrap_or(0.0);
                for l in 0..L {
                    df[c][l] = self.tf[c][l] - fj;
                }
            }
            let mut s = [0.0; L];
            for k in 0..DU {
                for l in 0..L {
                    s[l] += self.tu[k][l] * uj[k];
                }
            }
            // arg = −a u − b v (+ the Gaussian k_t's argument); the
            // polynomial k_t (p, p') and the k_t'/k_t of the exponential one.
            let mut arg = [0.0; L];
            for l in 0..L {
                arg[l] = -a * u2[l] - bs[0] * df[0][l] * df[0][l];
            }
            for c in 1..nf {
                for l in 0..L {
                    arg[l] -= bs[c] * df[c][l] * df[c][l];
                }
            }
            let (p, p1, q, arg_t) = grass_lanes(self.grass, &s);
            if let Some(at) = arg_t {
                for l in 0..L {
                    arg[l] += at[l];
                }
            }
            // m = w r_j exp(arg): the untapered product; with the taper t(u),
            // the term is m·t·p and its u-derivative m·(−a t + t')·p.
            let e = exp_lanes(arg);
            let (mut m, mut mt, mut mdu) = ([0.0; L], [0.0; L], [0.0; L]);
            for l in 0..L {
                m[l] = w * rj * e[l];
            }
            match taper {
                Some(t) => {
                    let (ts, tds) = t.lanes(&u2);
                    for l in 0..L {
                        mt[l] = m[l] * ts[l];
                        mdu[l] = m[l] * (-a * ts[l] + tds[l]);
                    }
                }
                None => {
                    for l in 0..L {
                        mt[l] = m[l];
                        mdu[l] = -a * m[l];
                    }
                }
            }
            for l in 0..L {
                acc.s0[l] += mt[l] * p[l];
            }
            if GRAD {
                for k in 0..D {
                    for l in 0..L {
                        acc.gc[k][l] += 2.0 * mdu[l] * p[l] * (self.tc[k][l] - cj[k]);
                    }
                }
                let mut g = [0.0; L];
                for l in 0..L {
                    acc.gf[0][l] += -2.0 * bs[0] * mt[l] * p[l] * df[0][l];
                    g[l] = mt[l] * (p[l] * q[l] + p1[l]);
                }
                for c in 1..nf {
                    for l in 0..L {
                        acc.gf[c][l] += -2.0 * bs[c] * mt[l] * p[l] * df[c][l];
                    }
                }
                for k in 0..DU {
                    for l in 0..L {
                        acc.gu[k][l] += g[l] * uj[k];
                    }
                }
            }
        }
    }
}

/// k_t in factored form for the lanes of s = u_i·u_j: k_t = p·e^{arg},
/// k_t' = (p·q + p')·e^{arg}, with `arg` `None` (e^{arg} = 1) for the
/// polynomial kernels. Returns (p, p', q, arg). The fused loop adds `arg`
/// into its one exponential; the general loop takes its own.
#[inline(always)]
fn grass_lanes(grass: GrassKernel, s: &[f64; L]) -> ([f64; L], [f64; L], [f64; L], Option<[f64; L]>) {
    let (mut p, mut p1, mut q, mut arg) = ([1.0; L], [0.0; L], [0.0; L], [0.0; L]);
    match grass {
        GrassKernel::Linear => {
            p = *s;
            p1 = [1.0; L];
            return (p, p1, q, None);
        }
        GrassKernel::Binet => {
            for l in 0..L {
                p[l] = s[l] * s[l];
                p1[l] = 2.0 * s[l];
            }
            return (p, p1, q, None);
        }
        GrassKernel::OrientedGaussian { sigma } => {
            let c = 2.0 / (sigma * sigma);
            for l in 0..L {
                arg[l] = c * (s[l] - 1.0);
                q[l] = c;
            }
        }
        GrassKernel::UnorientedGaussian { sigma } => {
            let c = 2.0 / (sigma * sigma);
            for l in 0..L {
                arg[l] = c * (s[l] * s[l] - 1.0);
                q[l] = 2.0 * c * s[l];
            }
        }
    }
    (p, p1, q, Some(arg))
}

/// The per-target sums (module doc) of every cell of `x` against `y`: rows
/// [s0] or, with `grad`, [s0, gc (dim), gu (du), gf (one per channel)].
pub(crate) fn pair_sums(
    x: &CellFeatures,
    y: &CellFeatures,
    k: &VarifoldKernel,
    grad: bool,
    parallel: bool,
) -> Result<Vec<f64>, VarifoldError> {
    match (x.dim(), x.dir_len(), grad) {
        (2, 1, false) => run::<2, 1, false>(x, y, k, parallel),
        (2, 1, true) => run::<2, 1, true>(x, y, k, parallel),
        (2, 2, false) => run::<2, 2, false>(x, y, k, parallel),
        (2, 2, true) => run::<2, 2, true>(x, y, k, parallel),
        (3, 3, false) => run::<3, 3, false>(x, y, k, parallel),
        (3, 3, true) => run::<3, 3, true>(x, y, k, parallel),
        (dim, du, _) => Err(VarifoldError::Dimension { what: "direction components", expected: dim, found: du }),
    }
}

/// The widest row: s0, 3 centre and 3 direction components, the signal
/// channels.
const MAX_ROW: usize = 7 + MAX_CHANNELS;

/// Row width of [`pair_sums`]' output, with `nf` signal channels.
pub(crate) fn row_len(dim: usize, du: usize, nf: usize, grad: bool) -> usize {
    if grad { 1 + dim + du + nf } else { 1 }
}

/// The channel count the sums run over and each channel's b_c = 1/(2σ_c²):
/// the signal kernel's, or one channel of zeros without a signal kernel.
pub(crate) fn channels(x: &CellFeatures, k: &VarifoldKernel) -> Result<(usize, [f64; MAX_CHANNELS]), VarifoldError> {
    let mut b = [0.0; MAX_CHANNELS];
    if k.signal().is_constant() {
        return Ok((1, b));
    }
    let nf = x.n_channels();
    if nf > MAX_CHANNELS {
        return Err(VarifoldError::Channels { what: "signal channels (at most 8)", expected: MAX_CHANNELS, found: nf });
    }
    for (c, bc) in b.iter_mut().enumerate().take(nf) {
        let sigma = k.signal().width(c, nf)?;
        *bc = 0.5 / (sigma * sigma);
    }
    Ok((nf, b))
}

fn run<const D: usize, const DU: usize, const GRAD: bool>(
    x: &CellFeatures,
    y: &CellFeatures,
    k: &VarifoldKernel,
    parallel: bool,
) -> Result<Vec<f64>, VarifoldError> {
    let (nf, b) = channels(x, k)?;
    if nf == 1 {
        run_channels::<D, DU, GRAD, 1>(x, y, k, (nf, b), parallel)
    } else {
        run_channels::<D, DU, GRAD, MAX_CHANNELS>(x, y, k, (nf, b), parallel)
    }
}

fn run_channels<const D: usize, const DU: usize, const GRAD: bool, const NF: usize>(
    x: &CellFeatures,
    y: &CellFeatures,
    k: &VarifoldKernel,
    (nf, b): (usize, [f64; MAX_CHANNELS]),
    parallel: bool,
) -> Result<Vec<f64>, VarifoldError> {
    let pairs = BlockPairs::try_new(x.centres(), y.centres(), D, k.position())?;
    let order = pairs.source_order();
    // Without a signal kernel the signals are not read (one channel of 0).
    let functional = !k.signal().is_constant();
    let (yf, xf) = if functional { (y.signal(), x.signal()) } else { (None, None) };
    let sc: Vec<[f64; D]> = order.iter().map(|&j| std::array::from_fn(|c| y.centres()[j * D + c])).collect();
    let su: Vec<[f64; DU]> = order.iter().map(|&j| std::array::from_fn(|c| y.dirs()[j * DU + c])).collect();
    let sf: Vec<f64> = match yf {
        Some(f) => order.iter().flat_map(|&j| f[j * nf..(j + 1) * nf].iter().copied()).collect(),
        None => vec![0.0; order.len()],
    };
    let sr: Vec<f64> = order.iter().map(|&j| y.weights()[j]).collect();
    let w = row_len(D, DU, nf, GRAD);
    let arch = fshape_kernels::simd::arch();
    let blocks = pairs.map_blocks(parallel, |targets, runs| {
        let n = targets.len();
        // Unused lanes repeat the last target; their sums are discarded.
        let lane = |l: usize| targets[l.min(n - 1)];
        let tc: [[f64; L]; D] = std::array::from_fn(|c| std::array::from_fn(|l| x.centres()[lane(l) * D + c]));
        let tu: [[f64; L]; DU] = std::array::from_fn(|c| std::array::from_fn(|l| x.dirs()[lane(l) * DU + c]));
        let tf: [[f64; L]; NF] = std::array::from_fn(|c| {
            std::array::from_fn(|l| xf.filter(|_| c < nf).map_or(0.0, |f| f[lane(l) * nf + c]))
        });
        let mut acc = Acc::<D, DU, NF> { s0: [0.0; L], gc: [[0.0; L]; D], gu: [[0.0; L]; DU], gf: [[0.0; L]; NF] };
        for run in runs {
            let r = run.range.clone();
            let tile = Tile::<D, DU, GRAD, NF> {
                k,
                grass: k.grass(),
                functional,
                nf,
                b: &b,
                tc: &tc,
                tu: &tu,
                tf: &tf,
                sc: &sc[r.clone()],
                su: &su[r.clone()],
                sf: &sf[r.start * nf..r.end * nf],
                sr: &sr[r],
                tapered: run.tapered,
                acc,
            };
            acc = arch.dispatch(tile);
        }
        let mut rows = Vec::with_capacity(n);
        for (l, &i) in targets.iter().enumerate() {
            let mut row = [0.0; MAX_ROW];
            row[0] = acc.s0[l];
            if GRAD {
                for c in 0..D {
                    row[1 + c] = acc.gc[c][l];
                }
                for c in 0..DU {
                    row[1 + D + c] = acc.gu[c][l];
                }
                for c in 0..nf {
                    row[1 + D + DU + c] = acc.gf[c][l];
                }
            }
            rows.push((i, row));
        }
        rows
    });
    let mut out = vec![0.0; x.len() * w];
    for (i, row) in blocks.into_iter().flatten() {
        out[i * w..(i + 1) * w].copy_from_slice(&row[..w]);
    }
    Ok(out)
}
