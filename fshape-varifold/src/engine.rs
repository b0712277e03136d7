//! The vectorised pair sums behind every inner product: for each target
//! cell i of X and the cells j of Y that [`BlockPairs`] hands it (all of
//! them, or those within k_p's support),
//!
//! - s0_i = Σ_j r_j k_p k_f k_t,
//! - gc_i = Σ_j r_j 2k_p' (c_i − c_j) k_f k_t,
//! - gu_i = Σ_j r_j k_p k_f k_t'(s) u_j,
//! - gf_i = Σ_j r_j k_p k_f'(v) 2(f_i − f_j) k_t,
//!
//! with k_p, k_f, k_t at u = |c_i − c_j|², v = (f_i − f_j)², s = u_i·u_j.
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

use crate::{CellFeatures, GrassKernel, SignalKernel, VarifoldError, VarifoldKernel};

/// Per-lane sums of one target block.
#[derive(Clone, Copy)]
struct Acc<const D: usize, const DU: usize> {
    s0: [f64; L],
    gc: [[f64; L]; D],
    gu: [[f64; L]; DU],
    gf: [f64; L],
}

/// One target block against one run of sorted sources.
struct Tile<'a, const D: usize, const DU: usize, const GRAD: bool> {
    k: &'a VarifoldKernel,
    tc: &'a [[f64; L]; D],
    tu: &'a [[f64; L]; DU],
    tf: &'a [f64; L],
    sc: &'a [[f64; D]],
    su: &'a [[f64; DU]],
    sf: &'a [f64],
    sr: &'a [f64],
    tapered: bool,
    acc: Acc<D, DU>,
}

impl<const D: usize, const DU: usize, const GRAD: bool> WithSimd for Tile<'_, D, DU, GRAD> {
    type Output = Acc<D, DU>;

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
            // k_f and its derivative, and f_i − f_j.
            let mut df = [0.0; L];
            let (kf, kf1) = match self.k.signal() {
                SignalKernel::Constant => ([1.0; L], [0.0; L]),
                SignalKernel::Gaussian { sigma } => {
                    let b = 0.5 / (sigma * sigma);
                    let mut arg = [0.0; L];
                    for l in 0..L {
                        df[l] = self.tf[l] - self.sf[j];
                        arg[l] = -b * df[l] * df[l];
                    }
                    let e = exp_lanes(arg);
                    let mut e1 = [0.0; L];
                    for l in 0..L {
                        e1[l] = -b * e[l];
                    }
                    (e, e1)
                }
            };
            let mut s = [0.0; L];
            for k in 0..DU {
                for l in 0..L {
                    s[l] += self.tu[k][l] * uj[k];
                }
            }
            // k_t = p·e^{arg_t}, k_t' = (p·q + p')·e^{arg_t} (grass_lanes).
            let (p, p1, q, arg_t) = grass_lanes(self.k.grass(), &s);
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
                    acc.gf[l] += 2.0 * rj * kp[l] * kf1[l] * df[l] * kt[l];
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

impl<const D: usize, const DU: usize, const GRAD: bool> Tile<'_, D, DU, GRAD> {
    /// The common case, k_p a single Gaussian w·exp(−a u): the exponential
    /// factors k_p, k_f and (for the Gaussian direction kernels) k_t are
    /// computed as one exponential of the sum of their arguments, three
    /// times fewer than the general loop. The same sums to rounding (the
    /// oracle tests cover both loops).
    #[inline(always)]
    fn fused(&mut self, a: f64, w: f64, taper: Option<fshape_kernels::Taper>) {
        let acc = &mut self.acc;
        let b = match self.k.signal() {
            SignalKernel::Constant => 0.0,
            SignalKernel::Gaussian { sigma } => 0.5 / (sigma * sigma),
        };
        for j in 0..self.sr.len() {
            let (cj, uj, rj) = (&self.sc[j], &self.su[j], self.sr[j]);
            let u2 = sq_dist_lanes(self.tc, cj);
            let mut df = [0.0; L];
            let fj = self.sf.get(j).copied().unwrap_or(0.0);
            for l in 0..L {
                df[l] = self.tf[l] - fj;
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
                arg[l] = -a * u2[l] - b * df[l] * df[l];
            }
            let (p, p1, q, arg_t) = grass_lanes(self.k.grass(), &s);
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
                    acc.gf[l] += -2.0 * b * mt[l] * p[l] * df[l];
                    g[l] = mt[l] * (p[l] * q[l] + p1[l]);
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
/// [s0] or, with `grad`, [s0, gc (dim), gu (du), gf].
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

/// The widest row: s0, 3 centre and 3 direction components, the signal.
const MAX_ROW: usize = 8;

/// Row width of [`pair_sums`]' output.
pub(crate) fn row_len(dim: usize, du: usize, grad: bool) -> usize {
    if grad { 2 + dim + du } else { 1 }
}

fn run<const D: usize, const DU: usize, const GRAD: bool>(
    x: &CellFeatures,
    y: &CellFeatures,
    k: &VarifoldKernel,
    parallel: bool,
) -> Result<Vec<f64>, VarifoldError> {
    let pairs = BlockPairs::try_new(x.centres(), y.centres(), D, k.position())?;
    let order = pairs.source_order();
    let zeros = vec![0.0; y.len()];
    let (yf, xf) = (y.signal().unwrap_or(&zeros), x.signal());
    let sc: Vec<[f64; D]> = order.iter().map(|&j| std::array::from_fn(|c| y.centres()[j * D + c])).collect();
    let su: Vec<[f64; DU]> = order.iter().map(|&j| std::array::from_fn(|c| y.dirs()[j * DU + c])).collect();
    let sf: Vec<f64> = order.iter().map(|&j| yf[j]).collect();
    let sr: Vec<f64> = order.iter().map(|&j| y.weights()[j]).collect();
    let w = row_len(D, DU, GRAD);
    let arch = fshape_kernels::simd::arch();
    let blocks = pairs.map_blocks(parallel, |targets, runs| {
        let n = targets.len();
        // Unused lanes repeat the last target; their sums are discarded.
        let lane = |l: usize| targets[l.min(n - 1)];
        let tc: [[f64; L]; D] = std::array::from_fn(|c| std::array::from_fn(|l| x.centres()[lane(l) * D + c]));
        let tu: [[f64; L]; DU] = std::array::from_fn(|c| std::array::from_fn(|l| x.dirs()[lane(l) * DU + c]));
        let tf: [f64; L] = std::array::from_fn(|l| xf.map_or(0.0, |f| f[lane(l)]));
        let mut acc = Acc::<D, DU> { s0: [0.0; L], gc: [[0.0; L]; D], gu: [[0.0; L]; DU], gf: [0.0; L] };
        for run in runs {
            let r = run.range.clone();
            let tile = Tile::<D, DU, GRAD> {
                k,
                tc: &tc,
                tu: &tu,
                tf: &tf,
                sc: &sc[r.clone()],
                su: &su[r.clone()],
                sf: &sf[r.clone()],
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
                row[1 + D + DU] = acc.gf[l];
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
