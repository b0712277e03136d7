//! Block-sparse pair enumeration for the vectorised sums.
//!
//! Targets and sources are sorted along a k-d order (recursive median
//! splits) into contiguous blocks with bounding boxes. For each block of
//! [`L`] targets, the source blocks whose box comes within the support
//! radius are summed densely with a vectorised kernel (`fast.rs`, or
//! another crate's) and the others skipped; a source block entirely within
//! the inner radius needs no taper. This keeps the exact path's SIMD speed
//! on the surviving pairs, which a per-pair tree visit cannot (measured in
//! the README). Each target's sum runs over source blocks in increasing
//! order, so the results do not depend on the number of threads.

use rayon::prelude::*;

use crate::fast::L;

/// Sources per block.
const LEAF: usize = 64;

/// Points sorted into blocks, with the blocks' bounding boxes (unused
/// coordinates of planar points are 0).
#[derive(Default)]
struct Blocks {
    /// order[k] = original index of the k-th sorted point.
    order: Vec<usize>,
    /// Block b covers sorted points start[b]..start[b + 1].
    start: Vec<usize>,
    lo: Vec<[f64; 3]>,
    hi: Vec<[f64; 3]>,
}

impl Blocks {
    /// Sorts `p` into blocks, reusing this value's memory (no allocation
    /// once it has held as many points).
    fn rebuild(&mut self, p: &[f64], dim: usize, size: usize) {
        let n = p.len() / dim;
        let Blocks { order, start, lo, hi } = self;
        order.clear();
        order.extend(0..n);
        start.clear();
        kd_sort(p, dim, order, size, start, 0);
        start.push(n);
        lo.clear();
        hi.clear();
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
    }

    /// Points in their own order, in consecutive blocks of `size` (no
    /// boxes: for an untapered kernel nothing is ever skipped).
    fn rebuild_identity(&mut self, n: usize, size: usize) {
        self.order.clear();
        self.order.extend(0..n);
        self.start.clear();
        self.start.extend((0..n).step_by(size));
        self.start.push(n);
        let blocks = self.start.len() - 1;
        self.lo.clear();
        self.lo.resize(blocks, [0.0; 3]);
        self.hi.clear();
        self.hi.resize(blocks, [0.0; 3]);
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
#[derive(Default)]
pub struct BlockPairs {
    tgt: Blocks,
    src: Blocks,
    taper: Option<crate::Taper>,
    /// The runs of target block t: `runs[run_ptr[t]..run_ptr[t + 1]]`.
    runs: Vec<SourceRun>,
    run_ptr: Vec<usize>,
    /// Targets per block: [`L`], or the mixed-precision path's own lane count.
    tgt_size: usize,
}

impl BlockPairs {
    /// Sorts targets `x` and sources `y` (`dim` = 2 or 3 coordinates per
    /// point, flat) into blocks for `kernel`'s support radius.
    pub fn try_new(x: &[f64], y: &[f64], dim: usize, kernel: &crate::Kernel) -> Result<Self, crate::KernelError> {
        use crate::KernelError;
        if dim != 2 && dim != 3 {
            return Err(KernelError::PointDimension { found: dim });
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
        Ok(BlockPairs::with_taper(x, y, dim, kernel.taper()))
    }

    /// The same without validation (callers inside the crate validated).
    pub(crate) fn with_taper(x: &[f64], y: &[f64], dim: usize, taper: Option<crate::Taper>) -> Self {
        let mut pairs = BlockPairs::default();
        pairs.rebuild(x, y, dim, taper);
        pairs
    }

    /// [`BlockPairs::with_taper`] into this value's memory: no allocation
    /// once it has held as many points (the shooting rebuilds the blocks at
    /// every evaluation of its vector field, as the points move).
    pub(crate) fn rebuild(&mut self, x: &[f64], y: &[f64], dim: usize, taper: Option<crate::Taper>) {
        // Exact sums visit every source: sorting would only cost time.
        self.rebuild_blocks(x, y, dim, taper, taper.is_some(), L);
    }

    /// [`BlockPairs::rebuild`] with `tgt_size` targets per block, sorting
    /// into k-d blocks even for an untapered kernel if `sort` (the
    /// mixed-precision sums need spatially small target blocks of their own
    /// lane count: `mixed.rs`).
    pub(crate) fn rebuild_blocks(
        &mut self,
        x: &[f64],
        y: &[f64],
        dim: usize,
        taper: Option<crate::Taper>,
        sort: bool,
        tgt_size: usize,
    ) {
        self.taper = taper;
        self.tgt_size = tgt_size;
        if sort {
            self.tgt.rebuild(x, dim, tgt_size);
            self.src.rebuild(y, dim, LEAF);
        } else {
            self.tgt.rebuild_identity(x.len() / dim, tgt_size);
            self.src.rebuild_identity(y.len() / dim, LEAF);
        }
        // Every target block's runs, in one serial pass over the block
        // pairs (box tests only: ~0.1 % of the cheapest sum's time).
        let mut runs = std::mem::take(&mut self.runs);
        runs.clear();
        self.run_ptr.clear();
        self.run_ptr.push(0);
        for t in 0..self.tgt.n_blocks() {
            self.push_runs(t, &mut runs);
            self.run_ptr.push(runs.len());
        }
        self.runs = runs;
    }

    /// Target block t's original indices and source runs.
    fn block(&self, t: usize) -> (&[usize], &[SourceRun]) {
        (&self.tgt.order[self.tgt.start[t]..self.tgt.start[t + 1]], &self.runs[self.run_ptr[t]..self.run_ptr[t + 1]])
    }

    /// sorted position → original target index.
    pub(crate) fn target_order(&self) -> &[usize] {
        &self.tgt.order
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
            let (targets, runs) = self.block(t);
            f(targets, runs)
        };
        if parallel {
            (0..self.tgt.n_blocks()).into_par_iter().map(block).collect()
        } else {
            (0..self.tgt.n_blocks()).map(block).collect()
        }
    }

    /// Calls `f(targets, runs, rows)` for every target block, where `rows`
    /// is the block's part of `out`: `w` values per target, the targets in
    /// sorted order (block b owns `out[w·L·b..]`, every block but the last
    /// holding exactly L targets). Allocation-free.
    pub(crate) fn for_each_block(
        &self,
        parallel: bool,
        out: &mut [f64],
        w: usize,
        f: impl Fn(&[usize], &[SourceRun], &mut [f64]) + Sync,
    ) {
        let block = |(t, rows): (usize, &mut [f64])| {
            let (targets, runs) = self.block(t);
            debug_assert_eq!(rows.len(), targets.len() * w);
            f(targets, runs, rows)
        };
        let chunk = (self.tgt_size * w).max(1);
        if parallel {
            out.par_chunks_mut(chunk).enumerate().for_each(block);
        } else {
            out.chunks_mut(chunk).enumerate().for_each(block);
        }
    }

    /// Appends the source runs that can reach target block `t` to `runs`.
    fn push_runs(&self, t: usize, runs: &mut Vec<SourceRun>) {
        let first = runs.len();
        {
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
                match runs[first..].last_mut() {
                    Some(last) if last.range.end == range.start && last.tapered == tapered => {
                        last.range.end = range.end
                    }
                    _ => runs.push(SourceRun { range, tapered }),
                }
            }
        }
    }
}
