//! The vectorised paths for the most common case: sums with a Gaussian or a
//! sum of a few Gaussians (the multi-scale deformation kernels), exact or
//! smoothly truncated: out_i = Σ_j k(|x_i − y_j|²) b_j, the x-gradient of
//! aᵀK b, the directional derivatives of both (the exact adjoint of
//! shooting), and fused pairs of them that share the exponentials.
//!
//! Targets are processed [`L`] at a time as the lanes of `[f64; L]` arrays
//! and sources in the runs that [`BlockPairs`] hands each target block (all
//! sources for an exact kernel; those whose block comes within the support
//! radius for a truncated one, with the taper skipped where a whole run is
//! inside its inner radius). Each target's sum runs over the sources in the
//! order BlockPairs fixes, so results do not depend on the number of
//! threads. The block kernel is plain lane-wise arithmetic, compiled through
//! pulp's runtime dispatch (AVX-512, AVX2 or scalar, whichever the CPU has
//! and [`crate::simd`]'s cap allows)
//! so that LLVM vectorises it without special build flags and without
//! unsafe code here. Its fused multiply-adds are `f64::mul_add`, one
//! rounding each whatever the instruction set: vfmadd under AVX2 and
//! AVX-512, the C library's correctly rounded `fma` in the scalar fallback
//! (slow, but only x86 CPUs older than AVX2 take it), so every
//! instruction set gives the same bits. They made the shooting's kernel
//! sums 1.06 to 1.3 times faster (`cargo bench -p fshape-kernels --bench
//! kernels -- shooting`, docs/guide/src/experiments.md, “a faster evaluation”).
//!
//! The exponential is written here ([`exp_lanes`]) because the arguments
//! are always finite and ≤ 0: the general-purpose SIMD exps (wide's, with
//! NaN/overflow handling and a degree-13 polynomial) cost about twice as
//! much. Its accuracy against libm is tested.

// Lane loops indexed by the lane number are the shape LLVM's vectoriser
// turns into SIMD; iterator chains over several arrays are not.
#![expect(clippy::needless_range_loop, reason = "explicit lane loops are the vectorisation idiom")]

use pulp::{Simd, WithSimd};

use crate::BlockPairs;
use crate::taper::{GaussTerms, Taper, quintic_taper, quintic_taper_derivatives};

/// Lanes per block: 16 f64 lanes: two AVX-512 registers per lane array. The shooting's fused
/// sums keep a dozen such arrays live; at 32 lanes they were 1.3× slower
/// (presumably register spills; not profiled), the plain sums no faster.
pub const L: usize = 16;

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
        t[l] = xl[l].mul_add(LOG2E, MAGIC);
        let n = t[l] - MAGIC;
        // n·LN2_HI is exact (LN2_HI has 11 significant bits, |n| ≤ 1022).
        r[l] = n.mul_add(-LN2_LO, n.mul_add(-LN2_HI, xl[l]));
    }
    // Estrin's scheme: the same polynomial with a dependency depth of 4
    // instead of Horner's 12, so the lanes' chains overlap.
    let mut p = [0.0; L];
    for l in 0..L {
        let x = r[l];
        let x2 = x * x;
        let x4 = x2 * x2;
        let x8 = x4 * x4;
        let q0 = x.mul_add(C[1], C[0]);
        let q1 = x.mul_add(C[3], C[2]);
        let q2 = x.mul_add(C[5], C[4]);
        let q3 = x.mul_add(C[7], C[6]);
        let q4 = x.mul_add(C[9], C[8]);
        let q5 = x.mul_add(C[11], C[10]);
        let s0 = q1.mul_add(x2, q0);
        let s1 = q3.mul_add(x2, q2);
        let s2 = x4.mul_add(C[12], q5.mul_add(x2, q4));
        p[l] = s2.mul_add(x8, s1.mul_add(x4, s0));
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

/// |x_l − y|² for the L targets held by axis in `x` (y: at least D
/// coordinates), summed over the axes in order.
#[inline(always)]
pub fn sq_dist_lanes<const D: usize>(x: &[[f64; L]; D], y: &[f64]) -> [f64; L] {
    let mut u = [0.0; L];
    for k in 0..D {
        for l in 0..L {
            let d = x[k][l] - y[k];
            u[l] = d.mul_add(d, u[l]);
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
/// `CONV` then `GRAD` in one pass (rows 0..BD, then BD..BD + D).
pub(crate) const CONV_GRAD: u8 = 4;
/// `CONV_JVP` then `GRAD_JVP` in one pass.
pub(crate) const BOTH_JVP: u8 = 5;

/// Output rows of a mode.
pub(crate) const fn rows(mode: u8, d: usize, bd: usize) -> usize {
    match mode {
        CONV | CONV_JVP => bd,
        GRAD | GRAD_JVP => d,
        _ => bd + d,
    }
}

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

/// The sorted sources of one run and their weights (empty when unused).
#[derive(Clone, Copy)]
struct Run<'a, const D: usize, const BD: usize> {
    y: &'a [[f64; D]],
    dy: &'a [[f64; D]],
    b: &'a [[f64; BD]],
    db: &'a [[f64; BD]],
}

/// One block of L targets against its runs of sources (one dispatch per
/// block: the accumulators stay in registers or L1 across runs).
struct Block<'a, const D: usize, const BD: usize, const MODE: u8> {
    terms: &'a GaussTerms,
    taper: Option<Taper>,
    t: &'a Lanes<D, BD>,
    /// All sorted sources; `runs` index into them.
    all: Run<'a, D, BD>,
    runs: &'a [crate::SourceRun],
}

/// e^m per lane (m ≥ 1) by repeated squaring; 0 where e < `floor` =
/// 1e-300^{1/m}, i.e. where e^m would fall below 1e-300.
#[inline(always)]
fn power_lanes(e: [f64; L], m: u32, floor: f64) -> [f64; L] {
    if m == 1 {
        return e;
    }
    let mut b = [0.0; L];
    for l in 0..L {
        b[l] = if e[l] < floor { 0.0 } else { e[l] };
    }
    let mut out = [1.0; L];
    let mut k = m;
    while k > 0 {
        if k & 1 == 1 {
            for l in 0..L {
                out[l] *= b[l];
            }
        }
        k >>= 1;
        if k > 0 {
            for l in 0..L {
                b[l] *= b[l];
            }
        }
    }
    out
}

/// k, k' (if `d1`) and k'' (if `d2`) of the sum of Gaussians `terms` at
/// the lanes' squared distances `u` (zero where not asked), summed over the
/// terms in order. With integer ratios a_t = m_t·a_min, one exponential e
/// and its powers e^{m_t} (a few ulps from exp(−a_t u); lanes where the
/// power would be subnormal are set to 0, as exp_lanes does below e^−708,
/// to avoid slow subnormal arithmetic).
#[inline(always)]
pub(crate) fn gauss_lanes(terms: &GaussTerms, u: &[f64; L], d1: bool, d2: bool) -> ([f64; L], [f64; L], [f64; L]) {
    let (mut k0, mut k1, mut k2) = ([0.0; L], [0.0; L], [0.0; L]);
    let base = match terms.powers {
        Some(_) => {
            let a = terms.a[..terms.n].iter().copied().fold(f64::INFINITY, f64::min);
            let mut arg = [0.0; L];
            for l in 0..L {
                arg[l] = -a * u[l];
            }
            Some(exp_lanes(arg))
        }
        None => None,
    };
    for term in 0..terms.n {
        let (a, w) = (terms.a[term], terms.w[term]);
        let e = match (base, terms.powers) {
            (Some(e1), Some(m)) => power_lanes(e1, m[term], terms.floors[term]),
            _ => {
                let mut arg = [0.0; L];
                for l in 0..L {
                    arg[l] = -a * u[l];
                }
                exp_lanes(arg)
            }
        };
        // Only the derivatives asked for (constants after inlining).
        for l in 0..L {
            k0[l] = e[l].mul_add(w, k0[l]);
        }
        if d1 {
            for l in 0..L {
                k1[l] = e[l].mul_add(-(a * w), k1[l]);
            }
        }
        if d2 {
            for l in 0..L {
                k2[l] = e[l].mul_add(a * a * w, k2[l]);
            }
        }
    }
    (k0, k1, k2)
}

/// s(u), s'(u), s''(u) of the quintic taper (see `Kernel::derivatives`).
#[inline(always)]
fn taper_lanes(t: Taper, u: &[f64; L]) -> ([f64; L], [f64; L], [f64; L]) {
    let h = t.u_out - t.u_in;
    let inv = 1.0 / h;
    let (mut s, mut ds, mut dds) = ([0.0; L], [0.0; L], [0.0; L]);
    for l in 0..L {
        let x = ((u[l] - t.u_in) * inv).clamp(0.0, 1.0);
        let (dx, ddx) = quintic_taper_derivatives(x);
        s[l] = quintic_taper!(x);
        ds[l] = dx * inv;
        dds[l] = ddx * inv * inv;
    }
    (s, ds, dds)
}

impl<const D: usize, const BD: usize, const MODE: u8> WithSimd for Block<'_, D, BD, MODE> {
    /// Up to 6 rows per lane: BD sums, D gradient components, or both.
    type Output = [[f64; L]; 6];

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> Self::Output {
        let mut acc = [[0.0; L]; 6];
        for r in self.runs {
            let run = Run {
                y: part(self.all.y, &r.range),
                dy: part(self.all.dy, &r.range),
                b: part(self.all.b, &r.range),
                db: part(self.all.db, &r.range),
            };
            self.run(run, if r.tapered { self.taper } else { None }, &mut acc);
        }
        acc
    }
}

impl<const D: usize, const BD: usize, const MODE: u8> Block<'_, D, BD, MODE> {
    #[inline(always)]
    fn run(&self, run: Run<'_, D, BD>, taper: Option<Taper>, acc: &mut [[f64; L]; 6]) {
        let t = self.t;
        let conv = matches!(MODE, CONV | CONV_JVP | CONV_GRAD | BOTH_JVP);
        let grad = matches!(MODE, GRAD | GRAD_JVP | CONV_GRAD | BOTH_JVP);
        let jvp = matches!(MODE, CONV_JVP | GRAD_JVP | BOTH_JVP);
        // Gradient rows follow the conv rows in the fused modes.
        let g0 = if conv { BD } else { 0 };
        for j in 0..run.y.len() {
            let (yj, bj) = (&run.y[j], &run.b[j]);
            let u = sq_dist_lanes(&t.x, yj);
            let (mut k0, mut k1, mut k2) = gauss_lanes(self.terms, &u, grad || jvp, grad && jvp);
            if let Some(tp) = taper {
                if grad || jvp {
                    let (s, ds, dds) = taper_lanes(tp, &u);
                    for l in 0..L {
                        k2[l] = k2[l] * s[l] + 2.0 * k1[l] * ds[l] + k0[l] * dds[l];
                        k1[l] = k1[l] * s[l] + k0[l] * ds[l];
                        k0[l] *= s[l];
                    }
                } else {
                    let (s, _) = tp.lanes(&u);
                    for l in 0..L {
                        k0[l] *= s[l];
                    }
                }
            }
            // du = 2 (x_i − y_j)·(dx_i − dy_j), for the JVP modes.
            let mut du = [0.0; L];
            if jvp {
                let dyj = &run.dy[j];
                for k in 0..D {
                    for l in 0..L {
                        du[l] += 2.0 * (t.x[k][l] - yj[k]) * (t.dx[k][l] - dyj[k]);
                    }
                }
            }
            if conv {
                if jvp {
                    let dbj = &run.db[j];
                    for c in 0..BD {
                        for l in 0..L {
                            acc[c][l] += k1[l] * du[l] * bj[c] + k0[l] * dbj[c];
                        }
                    }
                } else {
                    for c in 0..BD {
                        for l in 0..L {
                            acc[c][l] += k0[l] * bj[c];
                        }
                    }
                }
            }
            if grad {
                let mut ab = [0.0; L];
                for c in 0..BD {
                    for l in 0..L {
                        ab[l] += t.a[c][l] * bj[c];
                    }
                }
                if !jvp {
                    for k in 0..D {
                        for l in 0..L {
                            acc[g0 + k][l] += 2.0 * k1[l] * ab[l] * (t.x[k][l] - yj[k]);
                        }
                    }
                } else {
                    let (dyj, dbj) = (&run.dy[j], &run.db[j]);
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
                            acc[g0 + k][l] += 2.0 * k2[l] * du[l] * ab[l] * diff
                                + 2.0 * k1[l] * dab[l] * diff
                                + 2.0 * k1[l] * ab[l] * ddiff;
                        }
                    }
                }
            }
        }
    }
}

/// Memory reused by the vectorised sums from call to call: the blocks, the
/// sources and weights gathered into block order, and the rows of the
/// targets in block order. After a first call on as many points, a call
/// allocates nothing (the shooting calls these at every stage) unless a
/// truncated kernel's run search builds its BVH (256 source blocks or more).
#[derive(Default)]
pub(crate) struct FastWorkspace {
    pub(crate) pairs: BlockPairs,
    ys: Vec<f64>,
    bs: Vec<f64>,
    dys: Vec<f64>,
    dbs: Vec<f64>,
    rows: Vec<f64>,
    /// The symmetric sums' per-chunk accumulators (`symmetric.rs`).
    pub(crate) chunks: Vec<f64>,
    /// Run the block kernel without SIMD dispatch (baseline x86-64), for
    /// the test that every instruction set gives the same bits.
    #[cfg(test)]
    pub(crate) scalar: bool,
}

/// Computes the sum `MODE` for Gaussian sums in 2 or 3 dimensions with
/// 1 to 3 weight components, writing each target's first `split` output
/// values into `out1` and the rest into `out2` (`rows(MODE)` values per
/// target in all). Returns `false` for other dimensions (the caller uses
/// the general path). Inputs and output lengths were checked by the caller.
#[allow(clippy::too_many_arguments)]
pub(crate) fn gaussian_sum_into<const MODE: u8>(
    terms: &GaussTerms,
    taper: Option<Taper>,
    inp: Inputs<'_>,
    dim: usize,
    bdim: usize,
    parallel: bool,
    ws: &mut FastWorkspace,
    split: usize,
    out1: &mut [f64],
    out2: &mut [f64],
) -> bool {
    let outs = Outs { split, out1, out2 };
    match (dim, bdim) {
        (2, 1) => run::<2, 1, MODE>(terms, taper, inp, parallel, ws, outs),
        (2, 2) => run::<2, 2, MODE>(terms, taper, inp, parallel, ws, outs),
        (2, 3) => run::<2, 3, MODE>(terms, taper, inp, parallel, ws, outs),
        (3, 1) => run::<3, 1, MODE>(terms, taper, inp, parallel, ws, outs),
        (3, 2) => run::<3, 2, MODE>(terms, taper, inp, parallel, ws, outs),
        (3, 3) => run::<3, 3, MODE>(terms, taper, inp, parallel, ws, outs),
        _ => return false,
    }
    true
}

/// The number of output values per target of `MODE` (`None` outside the
/// dimensions of the vectorised path).
pub(crate) fn out_rows<const MODE: u8>(dim: usize, bdim: usize) -> Option<usize> {
    ((dim == 2 || dim == 3) && (1..=3).contains(&bdim)).then(|| rows(MODE, dim, bdim))
}

/// Where the rows go: values 0..split of each row to `out1`, the rest to
/// `out2`.
struct Outs<'o> {
    split: usize,
    out1: &'o mut [f64],
    out2: &'o mut [f64],
}

/// `v` (rows of `W`) gathered into the sorted source order, into `out`
/// (left empty if `v` is).
fn gather<const W: usize>(v: &[f64], order: &[usize], out: &mut Vec<f64>) {
    out.clear();
    if v.is_empty() {
        return;
    }
    out.extend(order.iter().flat_map(|&j| &v[j * W..(j + 1) * W]));
}

/// `v[range]`, or `v` itself if it is empty (an unused input).
fn part<'v, T>(v: &'v [T], range: &std::ops::Range<usize>) -> &'v [T] {
    if v.is_empty() { v } else { &v[range.clone()] }
}

fn run<const D: usize, const BD: usize, const MODE: u8>(
    terms: &GaussTerms,
    taper: Option<Taper>,
    inp: Inputs<'_>,
    parallel: bool,
    ws: &mut FastWorkspace,
    outs: Outs<'_>,
) {
    let w_out = rows(MODE, D, BD);
    let uses_a = matches!(MODE, GRAD | GRAD_JVP | CONV_GRAD | BOTH_JVP);
    let uses_d = matches!(MODE, CONV_JVP | GRAD_JVP | BOTH_JVP);
    // Inputs were validated by the caller; the taper only decides which
    // runs BlockPairs hands out.
    #[cfg(test)]
    let scalar = ws.scalar;
    #[cfg(not(test))]
    let scalar = false;
    let FastWorkspace { pairs, ys, bs, dys, dbs, rows, .. } = ws;
    pairs.rebuild(inp.x, inp.y, D, taper);
    let order = pairs.source_order();
    gather::<D>(inp.y, order, ys);
    gather::<BD>(inp.b, order, bs);
    gather::<D>(if uses_d { inp.dy } else { &[] }, order, dys);
    gather::<BD>(if uses_d { inp.db } else { &[] }, order, dbs);
    let all = Run { y: ys.as_chunks().0, dy: dys.as_chunks().0, b: bs.as_chunks().0, db: dbs.as_chunks().0 };
    let n = inp.x.len() / D;
    rows.clear();
    rows.resize(n * w_out, 0.0);
    let arch = crate::simd::arch();
    pairs.for_each_block(parallel, rows, w_out, |targets, runs, out| {
        let lanes = targets.len();
        // Unused lanes repeat the last target.
        let lane = |l: usize| targets[l.min(lanes - 1)];
        let pick = |v: &[f64], w: usize, on: bool, c: usize, l: usize| if on { v[lane(l) * w + c] } else { 0.0 };
        let t = Lanes::<D, BD> {
            x: std::array::from_fn(|k| std::array::from_fn(|l| inp.x[lane(l) * D + k])),
            dx: std::array::from_fn(|k| std::array::from_fn(|l| pick(inp.dx, D, uses_d, k, l))),
            a: std::array::from_fn(|c| std::array::from_fn(|l| pick(inp.a, BD, uses_a, c, l))),
            da: std::array::from_fn(|c| std::array::from_fn(|l| pick(inp.da, BD, uses_a && uses_d, c, l))),
        };
        let block = Block::<D, BD, MODE> { terms, taper, t: &t, all, runs };
        let acc = if scalar { block.with_simd(pulp::Scalar::new()) } else { arch.dispatch(block) };
        for (l, row) in out.chunks_exact_mut(w_out).enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = acc[c][l];
            }
        }
    });
    // Back to the caller's order and split.
    let Outs { split, out1, out2 } = outs;
    let w2 = w_out - split;
    for (row, &i) in rows.chunks_exact(w_out).zip(pairs.target_order()) {
        out1[i * split..(i + 1) * split].copy_from_slice(&row[..split]);
        out2[i * w2..(i + 1) * w2].copy_from_slice(&row[split..]);
    }
}

// The taper's lanes live here, beside the lane count they take.
impl Taper {
    /// The taper s(u) and its derivative s'(u) for the lanes of `u` (s = 1
    /// below u_in, 0 beyond u_out).
    #[inline(always)]
    pub fn lanes(&self, u: &[f64; L]) -> ([f64; L], [f64; L]) {
        let inv = 1.0 / (self.u_out - self.u_in);
        let (mut s, mut ds) = ([0.0; L], [0.0; L]);
        for l in 0..L {
            let x = ((u[l] - self.u_in) * inv).clamp(0.0, 1.0);
            s[l] = quintic_taper!(x);
            ds[l] = quintic_taper_derivatives(x).0 * inv;
        }
        (s, ds)
    }
}

#[cfg(test)]
mod tests {
    use super::{BOTH_JVP, CONV_GRAD, FastWorkspace, Inputs, L, exp_lanes, gaussian_sum_into};
    use crate::{Kernel, Profile};

    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        // The runtime dispatch (AVX-512 or AVX2 where the CPU has them)
        // against the baseline x86-64 build of the same block kernel, for
        // the two fused modes (which between them use every line of it),
        // a two-term sum with integer ratio (the power path), exact and
        // truncated (tapered and untapered runs).
        let mut seed = 7u64;
        let mut rnd = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (n, m) = (70, 150);
        let mut v = |len: usize| (0..len).map(|_| rnd()).collect::<Vec<f64>>();
        let (x, dx, y, dy, a, da, b, db) =
            (v(3 * n), v(3 * n), v(3 * m), v(3 * m), v(3 * n), v(3 * n), v(3 * m), v(3 * m));
        let inp = Inputs { x: &x, dx: &dx, y: &y, dy: &dy, a: &a, da: &da, b: &b, db: &db };
        let exact = Kernel::try_new(&Profile::Gaussians { sigmas: vec![0.3, 0.15], weights: vec![1.0, 0.5] }).unwrap();
        for kernel in [exact.clone(), exact.truncated(1e-6).unwrap()] {
            let terms = kernel.gaussian_terms().unwrap();
            for mode in [CONV_GRAD, BOTH_JVP] {
                let mut outs = Vec::new();
                for scalar in [false, true] {
                    let mut ws = FastWorkspace { scalar, ..Default::default() };
                    let mut out = vec![0.0; n * 6];
                    let sum = match mode {
                        CONV_GRAD => gaussian_sum_into::<CONV_GRAD>,
                        _ => gaussian_sum_into::<BOTH_JVP>,
                    };
                    assert!(sum(&terms, kernel.taper(), inp, 3, 3, true, &mut ws, 6, &mut out, &mut []));
                    outs.push(out);
                }
                assert!(outs[0].iter().any(|v| *v != 0.0));
                let same = outs[0].iter().zip(&outs[1]).all(|(p, q)| p.to_bits() == q.to_bits());
                assert!(same, "mode {mode}, truncated {}", kernel.taper().is_some());
            }
        }
    }

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
