//! The shooting's self-interaction sums, visiting each pair once.
//!
//! The Hamiltonian field needs, at the points y themselves (targets =
//! sources) and with a = b = p,
//!
//! - conv_i = Σ_j k_ij b_j and grad_i = Σ_j 2k'_ij (b_i·b_j)(y_i − y_j),
//! - and their directional derivatives when (y, b) move by (dy, db).
//!
//! The kernel is symmetric (k_ij = k_ji), so pair (i, j) gives j the mirror
//! of what it gives i: k_ij b_i to conv_j, and exactly −(its term) to
//! grad_j, because b_i·b_j, du_ij and the kernel values are symmetric and
//! y_i − y_j, dy_i − dy_j antisymmetric (the same holds term by term for
//! the directional derivatives, whose a·b and da·b + a·db are symmetric
//! when a = b and da = db). One exponential per unordered pair instead of
//! two: about half the work of [`crate::fast`]'s path for these sums.
//!
//! Blocks of [`L`] points in their own order are the lanes. Block I sums
//! its own block densely (each ordered pair from its target's side, as the
//! general path does), then every later point j once, adding the lanes'
//! terms to the lanes and their mirror, summed over the lanes in a fixed
//! tree, to j. The blocks are cut into at most [`CHUNKS`] contiguous
//! chunks of about equal work; each chunk accumulates into its own array,
//! and each output is the sum of the chunks' arrays in chunk order. The
//! chunks depend only on the number of points, not on the threads: serial
//! and parallel results are equal bit for bit. Exact (untruncated) sums of
//! Gaussians only: a truncated kernel already skips most pairs.

// Lane loops indexed by the lane number are the shape LLVM's vectoriser
// turns into SIMD (as in `fast.rs`).
#![expect(clippy::needless_range_loop, reason = "explicit lane loops are the vectorisation idiom")]

use pulp::{Simd, WithSimd};
use rayon::prelude::*;

use crate::fast::{FastWorkspace, L, gauss_lanes, sq_dist_lanes};
use crate::taper::GaussTerms;

/// The most chunks the blocks are cut into (fewer for fewer blocks). A
/// constant, so that the results do not depend on the number of threads;
/// 8 keeps two to four threads busy on the unequal tail of the work.
pub(crate) const CHUNKS: usize = 8;

/// The inputs, flat, in the points' own order (`dy`, `db` empty for the
/// sums themselves).
#[derive(Clone, Copy)]
pub(crate) struct SelfInputs<'a> {
    pub(crate) y: &'a [f64],
    pub(crate) dy: &'a [f64],
    pub(crate) b: &'a [f64],
    pub(crate) db: &'a [f64],
}

/// Σ_l v[l] in a fixed tree (the same bits on every instruction set).
#[inline(always)]
fn hsum(v: &[f64; L]) -> f64 {
    let mut h = [0.0; L / 2];
    for l in 0..L / 2 {
        h[l] = v[l] + v[l + L / 2];
    }
    let mut q = [0.0; L / 4];
    for l in 0..L / 4 {
        q[l] = h[l] + h[l + L / 4];
    }
    const { assert!(L == 16) };
    let mut e = [0.0; 2];
    for l in 0..2 {
        e[l] = q[l] + q[l + 2];
    }
    e[0] + e[1]
}

/// One block's lanes: coordinates (unused lanes repeat the last point) and
/// weights (0 in unused lanes, so that they give nothing to any j).
struct Lanes<const D: usize, const BD: usize> {
    y: [[f64; L]; D],
    dy: [[f64; L]; D],
    b: [[f64; L]; BD],
    db: [[f64; L]; BD],
}

/// One chunk of blocks and its accumulator: `W = BD + D` values per point
/// (conv, then grad).
struct Chunk<'a, const D: usize, const BD: usize, const JVP: bool> {
    terms: &'a GaussTerms,
    inp: SelfInputs<'a>,
    n: usize,
    blocks: std::ops::Range<usize>,
    acc: &'a mut [f64],
}

impl<const D: usize, const BD: usize, const JVP: bool> WithSimd for Chunk<'_, D, BD, JVP> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(mut self, _simd: S) {
        for block in self.blocks.clone() {
            self.block(block);
        }
    }
}

impl<const D: usize, const BD: usize, const JVP: bool> Chunk<'_, D, BD, JVP> {
    const W: usize = BD + D;

    #[inline(always)]
    fn block(&mut self, block: usize) {
        let (n, inp) = (self.n, self.inp);
        let start = block * L;
        let end = (start + L).min(n);
        let last = end - start - 1;
        let coord = |v: &[f64], k: usize, l: usize| v[(start + l.min(last)) * D + k];
        let weight =
            |v: &[f64], c: usize, l: usize| if l <= last && !v.is_empty() { v[(start + l) * BD + c] } else { 0.0 };
        let t = Lanes::<D, BD> {
            y: std::array::from_fn(|k| std::array::from_fn(|l| coord(inp.y, k, l))),
            dy: std::array::from_fn(|k| std::array::from_fn(|l| if JVP { coord(inp.dy, k, l) } else { 0.0 })),
            b: std::array::from_fn(|c| std::array::from_fn(|l| weight(inp.b, c, l))),
            db: std::array::from_fn(|c| std::array::from_fn(|l| if JVP { weight(inp.db, c, l) } else { 0.0 })),
        };
        let mut acc = [[0.0; L]; 6];
        // The block itself: every ordered pair from its target's side.
        for j in start..end {
            self.pair::<false>(&t, j, &mut acc);
        }
        // Later points: each pair once, its mirror to j.
        for j in end..n {
            let m = self.pair::<true>(&t, j, &mut acc);
            for (a, v) in self.acc[j * Self::W..(j + 1) * Self::W].iter_mut().zip(&m) {
                *a += v;
            }
        }
        for l in 0..=last {
            for (r, a) in self.acc[(start + l) * Self::W..(start + l + 1) * Self::W].iter_mut().enumerate() {
                *a += acc[r][l];
            }
        }
    }

    /// Adds pair (lanes, j)'s terms to the lanes' `acc` and, if `MIRROR`,
    /// returns j's (the first W values).
    #[inline(always)]
    fn pair<const MIRROR: bool>(&self, t: &Lanes<D, BD>, j: usize, acc: &mut [[f64; L]; 6]) -> [f64; 6] {
        let inp = self.inp;
        let yj = &inp.y[j * D..(j + 1) * D];
        let bj = &inp.b[j * BD..(j + 1) * BD];
        let u = sq_dist_lanes(&t.y, yj);
        let (k0, k1, k2) = gauss_lanes(self.terms, &u, true, JVP);
        let mut m = [0.0; 6];
        // The lanes' terms are those of `fast.rs` (CONV_GRAD, BOTH_JVP) with
        // a = b, da = db, grouped for fused multiply-adds (so equal to the
        // general path's to rounding, not bit for bit).
        if !JVP {
            for c in 0..BD {
                for l in 0..L {
                    acc[c][l] = k0[l].mul_add(bj[c], acc[c][l]);
                }
            }
            let mut ab = [0.0; L];
            for c in 0..BD {
                for l in 0..L {
                    ab[l] = t.b[c][l].mul_add(bj[c], ab[l]);
                }
            }
            let mut kab = [0.0; L];
            for l in 0..L {
                kab[l] = 2.0 * k1[l] * ab[l];
            }
            let mut g = [[0.0; L]; D];
            for k in 0..D {
                for l in 0..L {
                    g[k][l] = kab[l] * (t.y[k][l] - yj[k]);
                    acc[BD + k][l] += g[k][l];
                }
            }
            if MIRROR {
                for c in 0..BD {
                    let mut v = [0.0; L];
                    for l in 0..L {
                        v[l] = k0[l] * t.b[c][l];
                    }
                    m[c] = hsum(&v);
                }
                for k in 0..D {
                    m[BD + k] = -hsum(&g[k]);
                }
            }
        } else {
            let dyj = &inp.dy[j * D..(j + 1) * D];
            let dbj = &inp.db[j * BD..(j + 1) * BD];
            let mut du = [0.0; L];
            for k in 0..D {
                for l in 0..L {
                    du[l] = (2.0 * (t.y[k][l] - yj[k])).mul_add(t.dy[k][l] - dyj[k], du[l]);
                }
            }
            for c in 0..BD {
                for l in 0..L {
                    acc[c][l] = (k1[l] * du[l]).mul_add(bj[c], k0[l].mul_add(dbj[c], acc[c][l]));
                }
            }
            let (mut ab, mut dab) = ([0.0; L], [0.0; L]);
            for c in 0..BD {
                for l in 0..L {
                    ab[l] = t.b[c][l].mul_add(bj[c], ab[l]);
                }
            }
            for c in 0..BD {
                for l in 0..L {
                    dab[l] = t.db[c][l].mul_add(bj[c], t.b[c][l].mul_add(dbj[c], dab[l]));
                }
            }
            // g = A·diff + B·ddiff, A = 2k''·du·ab + 2k'·dab, B = 2k'·ab.
            let (mut ca, mut cb) = ([0.0; L], [0.0; L]);
            for l in 0..L {
                ca[l] = (2.0 * k1[l]).mul_add(dab[l], 2.0 * k2[l] * du[l] * ab[l]);
                cb[l] = 2.0 * k1[l] * ab[l];
            }
            let mut g = [[0.0; L]; D];
            for k in 0..D {
                for l in 0..L {
                    let diff = t.y[k][l] - yj[k];
                    let ddiff = t.dy[k][l] - dyj[k];
                    g[k][l] = ca[l].mul_add(diff, cb[l] * ddiff);
                    acc[BD + k][l] += g[k][l];
                }
            }
            if MIRROR {
                for c in 0..BD {
                    let mut v = [0.0; L];
                    for l in 0..L {
                        v[l] = (k1[l] * du[l]).mul_add(t.b[c][l], k0[l] * t.db[c][l]);
                    }
                    m[c] = hsum(&v);
                }
                for k in 0..D {
                    m[BD + k] = -hsum(&g[k]);
                }
            }
        }
        m
    }
}

/// The first block of each chunk, and the end: `blocks` cut into at most
/// [`CHUNKS`] contiguous ranges of about equal work (block I visits the
/// blocks from I on; with few blocks some chunks may be empty).
fn chunk_bounds(blocks: usize) -> ([usize; CHUNKS + 1], usize) {
    let chunks = CHUNKS.min(blocks).max(1);
    let total = blocks * (blocks + 1) / 2;
    let mut bounds = [blocks; CHUNKS + 1];
    bounds[0] = 0;
    let (mut c, mut done) = (1, 0);
    for block in 0..blocks {
        while c < chunks && done * chunks >= c * total {
            bounds[c] = block;
            c += 1;
        }
        done += blocks - block;
    }
    while c < chunks {
        bounds[c] = blocks;
        c += 1;
    }
    (bounds, chunks)
}

/// The sums (`JVP` false: conv and grad; true: their directional
/// derivatives) for `D` = 2 or 3 coordinates and `BD` = 1 to 3 weight
/// components, into `conv` (N × BD) and `grad` (N × D); `false` (nothing
/// written) for other dimensions. Lengths were checked by the caller.
#[allow(clippy::too_many_arguments)]
pub(crate) fn self_sums_into<const JVP: bool>(
    terms: &GaussTerms,
    inp: SelfInputs<'_>,
    dim: usize,
    bdim: usize,
    parallel: bool,
    ws: &mut FastWorkspace,
    conv: &mut [f64],
    grad: &mut [f64],
) -> bool {
    match (dim, bdim) {
        (2, 1) => run::<2, 1, JVP>(terms, inp, parallel, ws, conv, grad),
        (2, 2) => run::<2, 2, JVP>(terms, inp, parallel, ws, conv, grad),
        (2, 3) => run::<2, 3, JVP>(terms, inp, parallel, ws, conv, grad),
        (3, 1) => run::<3, 1, JVP>(terms, inp, parallel, ws, conv, grad),
        (3, 2) => run::<3, 2, JVP>(terms, inp, parallel, ws, conv, grad),
        (3, 3) => run::<3, 3, JVP>(terms, inp, parallel, ws, conv, grad),
        _ => return false,
    }
    true
}

fn run<const D: usize, const BD: usize, const JVP: bool>(
    terms: &GaussTerms,
    inp: SelfInputs<'_>,
    parallel: bool,
    ws: &mut FastWorkspace,
    conv: &mut [f64],
    grad: &mut [f64],
) {
    let w = BD + D;
    let n = inp.y.len() / D;
    if n == 0 {
        return;
    }
    let (bounds, chunks) = chunk_bounds(n.div_ceil(L));
    #[cfg(test)]
    let scalar = ws.scalar;
    #[cfg(not(test))]
    let scalar = false;
    let acc = &mut ws.chunks;
    acc.clear();
    acc.resize(chunks * n * w, 0.0);
    let arch = crate::simd::arch();
    let chunk = |(c, acc): (usize, &mut [f64])| {
        let blocks = bounds[c]..bounds[c + 1];
        let task = Chunk::<D, BD, JVP> { terms, inp, n, blocks, acc };
        if scalar { task.with_simd(pulp::Scalar::new()) } else { arch.dispatch(task) }
    };
    if parallel {
        acc.par_chunks_mut(n * w).enumerate().for_each(chunk);
    } else {
        acc.chunks_mut(n * w).enumerate().for_each(chunk);
    }
    // Each output: the chunks' values in chunk order (chunk c holds
    // nothing for the points before its first block).
    for i in 0..n {
        let first = (i / L).min(bounds[chunks]);
        let upto = bounds[..chunks].iter().take_while(|&&b| b <= first).count();
        for r in 0..w {
            let mut v = 0.0;
            for c in 0..upto {
                v += acc[(c * n + i) * w + r];
            }
            if r < BD {
                conv[i * BD + r] = v;
            } else {
                grad[i * D + r - BD] = v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{CHUNKS, SelfInputs, chunk_bounds, self_sums_into};
    use crate::fast::FastWorkspace;
    use crate::{Kernel, Profile};

    #[test]
    fn chunks_cover_the_blocks_in_order_with_balanced_work() {
        for blocks in [1, 2, 7, 8, 9, 100, 641] {
            let (b, chunks) = chunk_bounds(blocks);
            assert_eq!(chunks, CHUNKS.min(blocks));
            assert_eq!(b[0], 0);
            assert_eq!(b[chunks], blocks);
            assert!(b[..=chunks].windows(2).all(|w| w[0] <= w[1]), "{blocks}: {b:?}");
            if blocks >= 100 {
                let work = |r: std::ops::Range<usize>| r.map(|k| blocks - k).sum::<usize>() as f64;
                let ideal = work(0..blocks) / chunks as f64;
                for c in 0..chunks {
                    let w = work(b[c]..b[c + 1]);
                    // Off by at most the largest block's work.
                    assert!((w - ideal).abs() <= blocks as f64, "{blocks}: chunk {c} has {w} against {ideal}");
                }
            }
        }
    }

    #[test]
    fn every_instruction_set_and_thread_count_gives_the_same_bits() {
        let mut seed = 11u64;
        let mut rnd = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let n = 300; // 19 blocks, the last partly used: 8 chunks
        let mut v = |len: usize| (0..len).map(|_| rnd()).collect::<Vec<f64>>();
        let (y, dy, b, db) = (v(3 * n), v(3 * n), v(3 * n), v(3 * n));
        let inp = SelfInputs { y: &y, dy: &dy, b: &b, db: &db };
        let kernel = Kernel::try_new(&Profile::Gaussians { sigmas: vec![0.3, 0.15], weights: vec![1.0, 0.5] }).unwrap();
        let terms = kernel.gaussian_terms().unwrap();
        for jvp in [false, true] {
            let mut outs = Vec::new();
            for (scalar, parallel) in [(false, true), (true, true), (false, false)] {
                let mut ws = FastWorkspace::default();
                ws.scalar = scalar;
                let (mut conv, mut grad) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
                let sums = if jvp { self_sums_into::<true> } else { self_sums_into::<false> };
                assert!(sums(&terms, inp, 3, 3, parallel, &mut ws, &mut conv, &mut grad));
                outs.push([conv, grad].concat());
            }
            assert!(outs[0].iter().all(|v| *v != 0.0));
            for o in &outs[1..] {
                assert!(outs[0].iter().zip(o).all(|(p, q)| p.to_bits() == q.to_bits()), "jvp {jvp}");
            }
        }
    }
}
