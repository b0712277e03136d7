//! Block-sparse evaluation of truncated single-Gaussian sums.
//!
//! Targets and sources are sorted along a k-d order (recursive median
//! splits) into contiguous blocks with bounding boxes. For each block of
//! [`L`] targets, the source blocks whose box comes within the support
//! radius are summed densely with the vectorised kernel of `fast.rs` and
//! the others skipped; a source block entirely within the inner radius
//! needs no taper. This keeps the exact path's SIMD speed on the surviving
//! pairs, which a per-pair tree visit cannot (measured in the README).
//! Each target's sum runs over source blocks in increasing order, so the
//! results do not depend on the number of threads.

#![expect(clippy::needless_range_loop, reason = "explicit lane loops are the vectorisation idiom")]

use pulp::{Arch, Simd, WithSimd};
use rayon::prelude::*;

use crate::fast::{L, exp_lanes, sq_dist_lanes};

/// Sources per block.
const LEAF: usize = 64;

/// Points sorted into blocks, with the blocks' bounding boxes (unused
/// coordinates of planar points are 0).
struct Blocks {
    /// order[k] = original index of the k-th sorted point.
    order: Vec<usize>,
    /// Block b covers sorted points start[b]..start[b + 1].
    start: Vec<usize>,
    lo: Vec<[f64; 3]>,
    hi: Vec<[f64; 3]>,
}

impl Blocks {
    fn new(p: &[f64], dim: usize, size: usize) -> Self {
        let n = p.len() / dim;
        let mut order: Vec<usize> = (0..n).collect();
        let mut start = Vec::new();
        kd_sort(p, dim, &mut order, size, &mut start, 0);
        start.push(n);
        let (mut lo, mut hi) = (Vec::new(), Vec::new());
        for w in start.windows(2) {
            let (mut l, mut h) = ([0.0; 3], [0.0; 3]);
            for k in 0..dim {
                l[k] = f64::INFINITY;
                h[k] = f64::NEG_INFINITY;
                for &i in &order[w[0]..w[1]] {
                    l[k] = l[k].min(p[i * dim + k]);
                    h[k] = h[k].max(p[i * dim + k]);
                }
            }
            lo.push(l);
            hi.push(h);
        }
        Blocks { order, start, lo, hi }
    }

    fn n_blocks(&self) -> usize {
        self.start.len() - 1
    }
}

/// Sorts `idx` into a k-d order whose leaves hold at most `size` points
/// (all but the last leaf of a split hold exactly a multiple of `size`).
fn kd_sort(p: &[f64], dim: usize, idx: &mut [usize], size: usize, starts: &mut Vec<usize>, offset: usize) {
    if idx.len() <= size {
        if !idx.is_empty() {
            starts.push(offset);
        }
        return;
    }
    let spread = |axis: usize| {
        let (lo, hi) = idx.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| {
            let v = p[i * dim + axis];
            (lo.min(v), hi.max(v))
        });
        hi - lo
    };
    let axis = (0..dim).max_by(|&a, &b| spread(a).total_cmp(&spread(b))).unwrap_or(0);
    let mid = ((idx.len() / 2).div_ceil(size) * size).clamp(1, idx.len() - 1);
    idx.select_nth_unstable_by(mid, |&u, &v| p[u * dim + axis].total_cmp(&p[v * dim + axis]).then(u.cmp(&v)));
    let (left, right) = idx.split_at_mut(mid);
    kd_sort(p, dim, left, size, starts, offset);
    kd_sort(p, dim, right, size, starts, offset + mid);
}

/// Squared distance between two boxes (0 if they overlap), and the squared
/// largest distance between their points.
fn box_dist2(alo: &[f64; 3], ahi: &[f64; 3], blo: &[f64; 3], bhi: &[f64; 3]) -> (f64, f64) {
    let (mut near, mut far) = (0.0, 0.0);
    for k in 0..3 {
        let gap = (blo[k] - ahi[k]).max(alo[k] - bhi[k]).max(0.0);
        let span = (bhi[k] - alo[k]).max(ahi[k] - blo[k]);
        near += gap * gap;
        far += span * span;
    }
    (near, far)
}

/// The taper of `Kernel::truncated`, per lane: 1 − S((u − u_in)/(u_out − u_in)).
#[derive(Clone, Copy)]
pub(crate) struct TaperLanes {
    pub(crate) u_in: f64,
    pub(crate) u_out: f64,
}

struct Tile<'a, const D: usize, const BD: usize> {
    a: f64,
    taper: Option<TaperLanes>,
    x: &'a [[f64; L]; D],
    /// Sorted source coordinates and weights of the block.
    y: &'a [[f64; D]],
    b: &'a [[f64; BD]],
    acc: [[f64; L]; BD],
}

impl<const D: usize, const BD: usize> WithSimd for Tile<'_, D, BD> {
    type Output = [[f64; L]; BD];

    #[inline(always)]
    fn with_simd<S: Simd>(mut self, _simd: S) -> Self::Output {
        for (yj, bj) in self.y.iter().zip(self.b) {
            let u = sq_dist_lanes(self.x, yj);
            let mut arg = [0.0; L];
            for l in 0..L {
                arg[l] = -self.a * u[l];
            }
            let mut e = exp_lanes(arg);
            if let Some(t) = self.taper {
                let inv = 1.0 / (t.u_out - t.u_in);
                for l in 0..L {
                    let s = ((u[l] - t.u_in) * inv).clamp(0.0, 1.0);
                    e[l] *= 1.0 - s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
                }
            }
            for c in 0..BD {
                for l in 0..L {
                    self.acc[c][l] += e[l] * bj[c];
                }
            }
        }
        self.acc
    }
}

/// Σ_j w exp(−a|x_i − y_j|²) s(|x_i − y_j|²) b_j with the taper s of
/// `taper`, visiting only source blocks within the support radius.
#[allow(clippy::too_many_arguments)]
pub(crate) fn truncated_conv(
    a: f64,
    w: f64,
    taper: TaperLanes,
    x: &[f64],
    y: &[f64],
    dim: usize,
    b: &[f64],
    bdim: usize,
    parallel: bool,
) -> Option<Vec<f64>> {
    match (dim, bdim) {
        (2, 1) => Some(conv::<2, 1>(a, w, taper, x, y, b, parallel)),
        (2, 2) => Some(conv::<2, 2>(a, w, taper, x, y, b, parallel)),
        (2, 3) => Some(conv::<2, 3>(a, w, taper, x, y, b, parallel)),
        (3, 1) => Some(conv::<3, 1>(a, w, taper, x, y, b, parallel)),
        (3, 2) => Some(conv::<3, 2>(a, w, taper, x, y, b, parallel)),
        (3, 3) => Some(conv::<3, 3>(a, w, taper, x, y, b, parallel)),
        _ => None,
    }
}

fn conv<const D: usize, const BD: usize>(
    a: f64,
    w: f64,
    taper: TaperLanes,
    x: &[f64],
    y: &[f64],
    b: &[f64],
    parallel: bool,
) -> Vec<f64> {
    let src = Blocks::new(y, D, LEAF);
    let ys: Vec<[f64; D]> = src.order.iter().map(|&j| std::array::from_fn(|k| y[j * D + k])).collect();
    let bs: Vec<[f64; BD]> = src.order.iter().map(|&j| std::array::from_fn(|c| b[j * BD + c])).collect();
    let tgt = Blocks::new(x, D, L);
    let arch = Arch::new();
    let block = |t: usize| -> Vec<(usize, [f64; BD])> {
        let ids = &tgt.order[tgt.start[t]..tgt.start[t + 1]];
        let lanes = ids.len();
        let mut xs = [[0.0; L]; D];
        for (k, xk) in xs.iter_mut().enumerate() {
            for (l, v) in xk.iter_mut().enumerate() {
                *v = x[ids[l.min(lanes - 1)] * D + k];
            }
        }
        let mut acc = [[0.0; L]; BD];
        for s in 0..src.n_blocks() {
            let (near, far) = box_dist2(&tgt.lo[t], &tgt.hi[t], &src.lo[s], &src.hi[s]);
            if near >= taper.u_out {
                continue;
            }
            let range = src.start[s]..src.start[s + 1];
            let tile = Tile::<D, BD> {
                a,
                taper: (far > taper.u_in).then_some(taper),
                x: &xs,
                y: &ys[range.clone()],
                b: &bs[range],
                acc,
            };
            acc = arch.dispatch(tile);
        }
        (0..lanes).map(|l| (ids[l], std::array::from_fn(|c| w * acc[c][l]))).collect()
    };
    let parts: Vec<Vec<(usize, [f64; BD])>> = if parallel {
        (0..tgt.n_blocks()).into_par_iter().map(block).collect()
    } else {
        (0..tgt.n_blocks()).map(block).collect()
    };
    let mut out = vec![0.0; x.len() / D * BD];
    for (i, v) in parts.into_iter().flatten() {
        out[i * BD..(i + 1) * BD].copy_from_slice(&v);
    }
    out
}

/// A run of sorted sources, `range` in the order of
/// [`BlockPairs::source_order`], that may interact with a target block.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SourceRun {
    /// Positions in the sorted source order.
    pub range: std::ops::Range<usize>,
    /// `false` if every pair of the run lies inside the taper's inner
    /// radius (or the kernel is not truncated): the taper is 1 there and can
    /// be skipped ([`Kernel::lanes`](crate::Kernel::lanes)).
    pub tapered: bool,
}

/// The block-sparse pair engine other crates build their vectorised sums
/// on (fshape-varifold's data attachment uses it): targets are sorted into
/// blocks of at most [`L`](crate::lanes::L) points and sources into blocks
/// of 64, both along a k-d order, and each target block is handed the runs
/// of sources whose bounding boxes come within the kernel's support radius
/// (all of them for an untapered kernel).
///
/// The caller permutes its source data once into
/// [`source_order`](Self::source_order), then in
/// [`map_blocks`](Self::map_blocks) loads a target block into lanes and
/// sums over the runs in the order given. That order depends only on the
/// data, so results do not depend on the number of threads.
///
/// ```
/// use fshape_kernels::{BlockPairs, Kernel};
/// let x = [0.0, 0.0, 5.0, 0.0];
/// let y = [0.1, 0.0, 9.0, 9.0];
/// let k = Kernel::gaussian(0.5)?.truncated(1e-8)?;
/// let pairs = BlockPairs::try_new(&x, &y, 2, &k)?;
/// // Count, per target, the sources a truncated sum has to visit.
/// let counts = pairs.map_blocks(false, |targets, runs| {
///     let n: usize = runs.iter().map(|r| r.range.len()).sum();
///     targets.iter().map(|&i| (i, n)).collect::<Vec<_>>()
/// });
/// assert_eq!(counts.concat(), [(0, 2), (1, 2)]); // one block of each: nothing skipped
/// # Ok::<(), fshape_kernels::KernelError>(())
/// ```
pub struct BlockPairs {
    tgt: Blocks,
    src: Blocks,
    taper: Option<crate::Taper>,
}

impl BlockPairs {
    /// Sorts targets `x` and sources `y` (`dim` = 2 or 3 coordinates per
    /// point, flat) into blocks for `kernel`'s support radius.
    pub fn try_new(x: &[f64], y: &[f64], dim: usize, kernel: &crate::Kernel) -> Result<Self, crate::KernelError> {
        use crate::KernelError;
        if dim != 2 && dim != 3 {
            return Err(KernelError::Dimension { what: "point dimension", expected: 3, found: dim });
        }
        for (what, p) in [("target coordinates", x), ("source coordinates", y)] {
            if !p.len().is_multiple_of(dim) {
                return Err(KernelError::Dimension { what, expected: p.len() / dim * dim, found: p.len() });
            }
        }
        for (what, p) in [("target point", x), ("source point", y)] {
            if let Some(i) = p.iter().position(|v| !v.is_finite()) {
                return Err(KernelError::NonFinite { what, index: i / dim });
            }
        }
        Ok(BlockPairs { tgt: Blocks::new(x, dim, L), src: Blocks::new(y, dim, LEAF), taper: kernel.taper() })
    }

    /// sorted position → original source index.
    pub fn source_order(&self) -> &[usize] {
        &self.src.order
    }

    /// Number of target blocks.
    pub fn n_target_blocks(&self) -> usize {
        self.tgt.n_blocks()
    }

    /// Calls `f(targets, runs)` for every target block, in parallel or not,
    /// and returns the results in block order. `targets` holds the original
    /// indices of the block's (at most [`L`](crate::lanes::L)) targets;
    /// `runs` the source runs that can reach them, in increasing order.
    pub fn map_blocks<T: Send>(&self, parallel: bool, f: impl Fn(&[usize], &[SourceRun]) -> T + Sync) -> Vec<T> {
        let block = |t: usize| {
            let mut runs: Vec<SourceRun> = Vec::new();
            for s in 0..self.src.n_blocks() {
                let tapered = match self.taper {
                    None => false,
                    Some(taper) => {
                        let (near, far) = box_dist2(&self.tgt.lo[t], &self.tgt.hi[t], &self.src.lo[s], &self.src.hi[s]);
                        if near >= taper.u_out {
                            continue;
                        }
                        far > taper.u_in
                    }
                };
                let range = self.src.start[s]..self.src.start[s + 1];
                // Merge with the previous run when contiguous and alike.
                match runs.last_mut() {
                    Some(last) if last.range.end == range.start && last.tapered == tapered => {
                        last.range.end = range.end
                    }
                    _ => runs.push(SourceRun { range, tapered }),
                }
            }
            f(&self.tgt.order[self.tgt.start[t]..self.tgt.start[t + 1]], &runs)
        };
        if parallel {
            (0..self.tgt.n_blocks()).into_par_iter().map(block).collect()
        } else {
            (0..self.tgt.n_blocks()).map(block).collect()
        }
    }
}
