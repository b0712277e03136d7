//! Block-sparse pair enumeration for the vectorised sums.
//!
//! Targets and sources are sorted along a k-d order (recursive median
//! splits) into contiguous blocks with bounding boxes. For each block of
//! [`L`] targets, the source blocks whose box comes within the support
//! radius are summed densely with a vectorised kernel (`fast.rs`, or
//! another crate's) and the others skipped; a source block entirely within
//! the inner radius needs no taper. This keeps the exact path's SIMD speed
//! on the surviving pairs, which a per-pair tree visit cannot (measured in
//! the README). The source blocks within reach of each target block are
//! found by an obvhs BVH over the source blocks' boxes when there are many
//! ([`RunSearch`]), by testing every one when there are few; either way
//! each target's sum runs over source blocks in increasing order, so the
//! results depend neither on the search nor on the number of threads.

use rayon::prelude::*;

use crate::fast::L;

/// Sources per block.
const LEAF: usize = 64;

/// Source blocks from which [`RunSearch::Auto`] finds runs with the BVH
/// rather than by testing every source block (measured: README, "Truncated
/// sums at scale").
const BVH_MIN_BLOCKS: usize = 256;

/// Consecutive target blocks (siblings in the k-d order) that share one
/// BVH query.
const GROUP: usize = 4;

/// How [`BlockPairs`] finds, for a truncated kernel, the source blocks
/// within the support radius of each target block. The runs, and so the
/// bits of every sum, do not depend on the choice.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RunSearch {
    /// The BVH for many source blocks, the scan below (where testing every
    /// block costs less than building the BVH).
    #[default]
    Auto,
    /// An obvhs BVH over the source blocks' bounding boxes: O(log B + hits)
    /// per target block.
    Bvh,
    /// A box test of every source block: O(B) per target block.
    AllBlocks,
}

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
        kd_sort(p, dim, order, size);
        kd_starts(n, size, 0, start);
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
/// (all but the last leaf of a split hold exactly a multiple of `size`),
/// the two halves of a large split in parallel (each owns its half: the
/// order does not depend on the threads).
fn kd_sort(p: &[f64], dim: usize, idx: &mut [usize], size: usize) {
    if idx.len() <= size {
        return;
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for &i in idx.iter() {
        for k in 0..dim {
            let v = p[i * dim + k];
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        }
    }
    let axis = (0..dim).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
    let mid = kd_mid(idx.len(), size);
    idx.select_nth_unstable_by(mid, |&u, &v| p[u * dim + axis].total_cmp(&p[v * dim + axis]).then(u.cmp(&v)));
    let (left, right) = idx.split_at_mut(mid);
    if left.len() >= PAR_SORT {
        rayon::join(|| kd_sort(p, dim, left, size), || kd_sort(p, dim, right, size));
    } else {
        kd_sort(p, dim, left, size);
        kd_sort(p, dim, right, size);
    }
}

/// Points from which [`kd_sort`] sorts the two halves of a split in
/// parallel.
const PAR_SORT: usize = 1 << 14;

/// Where [`kd_sort`] splits `len` points (> `size`): the first multiple of
/// `size` from the middle on.
fn kd_mid(len: usize, size: usize) -> usize {
    ((len / 2).div_ceil(size) * size).clamp(1, len - 1)
}

/// The first sorted position of each of [`kd_sort`]'s leaves over `len`
/// points from `offset` (they depend on the number of points only).
fn kd_starts(len: usize, size: usize, offset: usize, starts: &mut Vec<usize>) {
    if len <= size {
        if len > 0 {
            starts.push(offset);
        }
        return;
    }
    let mid = kd_mid(len, size);
    kd_starts(mid, size, offset, starts);
    kd_starts(len - mid, size, offset + mid, starts);
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
    search: RunSearch,
    used_bvh: bool,
}

impl BlockPairs {
    /// Sorts targets `x` and sources `y` (`dim` = 2 or 3 coordinates per
    /// point, flat) into blocks for `kernel`'s support radius.
    pub fn try_new(x: &[f64], y: &[f64], dim: usize, kernel: &crate::Kernel) -> Result<Self, crate::KernelError> {
        BlockPairs::try_new_with_search(x, y, dim, kernel, RunSearch::Auto)
    }

    /// [`BlockPairs::try_new`] with the source blocks within reach found
    /// as `search` says; the runs are the same for every choice.
    pub fn try_new_with_search(
        x: &[f64],
        y: &[f64],
        dim: usize,
        kernel: &crate::Kernel,
        search: RunSearch,
    ) -> Result<Self, crate::KernelError> {
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
        let mut pairs = BlockPairs { search, ..BlockPairs::default() };
        pairs.rebuild(x, y, dim, kernel.taper());
        Ok(pairs)
    }

    /// [`BlockPairs::try_new`] without validation, into this value's
    /// memory: no allocation once it has held as many points, except the
    /// BVH search's tree and per-group runs (a truncated kernel with 256
    /// source blocks or more, where they are small against the sum). The
    /// shooting rebuilds the blocks at every evaluation of its vector
    /// field, as the points move.
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
        // Every target block's runs, in one serial pass: a scan of all
        // source blocks while there are few (box tests only, allocation
        // free), a BVH beyond.
        let mut runs = std::mem::take(&mut self.runs);
        let mut run_ptr = std::mem::take(&mut self.run_ptr);
        runs.clear();
        run_ptr.clear();
        run_ptr.push(0);
        // The BVH needs the blocks' boxes, which only sorting computes.
        self.used_bvh = sort
            && match (taper, self.search) {
                (None, _) | (_, RunSearch::AllBlocks) => false,
                (Some(_), RunSearch::Bvh) => true,
                (Some(_), RunSearch::Auto) => self.src.n_blocks() >= BVH_MIN_BLOCKS,
            };
        match taper {
            Some(taper) if self.used_bvh => self.bvh_runs(taper, &mut runs, &mut run_ptr),
            _ => {
                for t in 0..self.tgt.n_blocks() {
                    self.push_runs(t, 0..self.src.n_blocks(), &mut runs);
                    run_ptr.push(runs.len());
                }
            }
        }
        self.runs = runs;
        self.run_ptr = run_ptr;
    }

    /// Sets how the next builds find the source blocks within reach of
    /// each target block.
    pub(crate) fn set_search(&mut self, search: RunSearch) {
        self.search = search;
    }

    /// Whether the last build found the runs with the BVH.
    pub fn used_bvh(&self) -> bool {
        self.used_bvh
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

    /// Appends to `runs` the runs of the source blocks among `candidates`
    /// (increasing block indices, a superset of those within reach) that
    /// can reach target block `t`.
    fn push_runs(&self, t: usize, candidates: impl Iterator<Item = usize>, runs: &mut Vec<SourceRun>) {
        let first = runs.len();
        for s in candidates {
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
                Some(last) if last.range.end == range.start && last.tapered == tapered => last.range.end = range.end,
                _ => runs.push(SourceRun { range, tapered }),
            }
        }
    }

    /// Every target block's runs, their candidates found by an obvhs BVH
    /// over the source blocks' boxes (f32, the query box padded beyond f32
    /// rounding), one query for [`GROUP`] consecutive (k-d sibling) target
    /// blocks (groups in parallel), marked in a bit set and read back in increasing order, so
    /// that the exact f64 test of [`BlockPairs::push_runs`] sees the blocks
    /// in the same order as a scan of all of them and gives the same runs.
    fn bvh_runs(&self, taper: crate::Taper, runs: &mut Vec<SourceRun>, run_ptr: &mut Vec<usize>) {
        use glam::Vec3A;
        use obvhs::aabb::Aabb;
        let f32s = |p: &[f64; 3]| Vec3A::new(p[0] as f32, p[1] as f32, p[2] as f32);
        let boxes: Vec<Aabb> =
            self.src.lo.iter().zip(&self.src.hi).map(|(lo, hi)| Aabb::new(f32s(lo), f32s(hi))).collect();
        let bvh =
            obvhs::bvh2::builder::build_bvh2(&boxes, obvhs::BvhBuildParams::fast_build(), &mut Default::default());
        // f32 rounding moves a coordinate by at most 2⁻²⁴ of its size.
        let r = taper.u_out.sqrt();
        let size = self.src.lo.iter().chain(&self.src.hi).chain(&self.tgt.lo).chain(&self.tgt.hi).flatten();
        let scale = size.fold(0.0f64, |m, v| m.max(v.abs())) + r;
        let reach = Vec3A::splat((r + 1e-6 * scale) as f32);
        let words = self.src.n_blocks().div_ceil(64);
        let n = self.tgt.n_blocks();
        // Groups in parallel, each into its own runs, joined in order.
        let group_runs = |marks: &mut Vec<u64>, group: usize| {
            let blocks = group..(group + GROUP).min(n);
            let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
            for t in blocks.clone() {
                lo = lo.min(f32s(&self.tgt.lo[t]));
                hi = hi.max(f32s(&self.tgt.hi[t]));
            }
            marks.clear();
            marks.resize(words, 0);
            bvh.aabb_traverse(Aabb::new(lo - reach, hi + reach), |bvh, id| {
                let node = &bvh.nodes[id as usize];
                let first = node.first_index as usize;
                for &s in &bvh.primitive_indices[first..first + node.prim_count as usize] {
                    marks[s as usize / 64] |= 1 << (s % 64);
                }
                true
            });
            let mut runs = Vec::new();
            let mut ends = [0; GROUP];
            for (k, t) in blocks.enumerate() {
                self.push_runs(t, set_bits(marks), &mut runs);
                ends[k] = runs.len();
            }
            (runs, ends)
        };
        let groups: Vec<_> = (0..n).into_par_iter().step_by(GROUP).map_init(Vec::new, group_runs).collect();
        for (k, (group, ends)) in groups.into_iter().enumerate() {
            let base = runs.len();
            runs.extend(group);
            let blocks = GROUP.min(n - GROUP * k);
            run_ptr.extend(ends[..blocks].iter().map(|e| base + e));
        }
    }
}

/// The positions of the set bits of `marks`, in increasing order.
fn set_bits(marks: &[u64]) -> impl Iterator<Item = usize> + '_ {
    marks.iter().enumerate().flat_map(|(w, &m)| {
        let mut m = m;
        std::iter::from_fn(move || {
            (m != 0).then(|| {
                let b = m.trailing_zeros() as usize;
                m &= m - 1;
                64 * w + b
            })
        })
    })
}
