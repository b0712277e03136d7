//! Times the truncated Gaussian sum's block path at scale, finding each
//! target block's source runs by scanning every source block
//! (`RunSearch::AllBlocks`, the path before the BVH) and by the BVH
//! (`RunSearch::Bvh`), for the table in the README:
//! `cargo run --release -p fshape-kernels --example block_timing [N…]
//! [--max-pairs P]` (the sum is skipped, "–", where the runs hold more than
//! P pairs).
//!
//! The points are N area-weighted random samples of pycortex's S1 pial
//! surface (153k vertices; `data/pycortex_S1`), the same for both searches;
//! the kernel is one Gaussian of σ = 0.01 and 0.05 of the bounding-box
//! diagonal, truncated at τ = 1e-6; the sum is K b at the points
//! themselves (b = 1 component). Times are medians of 5 runs for the block
//! building, of 3 for the sum (1 at 10⁶ points), both searches in one run.

use std::path::PathBuf;
use std::time::Instant;

use fshape_kernels::{BlockPairs, Kernel, KernelSums, RunSearch};
use fshape_mesh::io::{ReadOptions, read_mesh};

/// SplitMix64: a small, fixed random stream.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `n` points drawn uniformly on the triangles of (`p`, `cells`).
fn sample(p: &[f64], cells: &[usize], n: usize) -> Vec<f64> {
    let corner = |c: usize, k: usize| &p[cells[c] * 3..cells[c] * 3 + 3][k];
    let mut cum = Vec::with_capacity(cells.len() / 3);
    let mut total = 0.0;
    for t in 0..cells.len() / 3 {
        let e = |a: usize, b: usize| [0, 1, 2].map(|k| corner(3 * t + b, k) - corner(3 * t + a, k));
        let (u, v) = (e(0, 1), e(0, 2));
        let c = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        total += 0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        cum.push(total);
    }
    let mut rng = Rng(2026);
    let mut out = Vec::with_capacity(3 * n);
    for _ in 0..n {
        let t = cum.partition_point(|&a| a < rng.next() * total).min(cum.len() - 1);
        let (mut r, mut s) = (rng.next(), rng.next());
        if r + s > 1.0 {
            (r, s) = (1.0 - r, 1.0 - s);
        }
        for k in 0..3 {
            let (a, b, c) = (corner(3 * t, k), corner(3 * t + 1, k), corner(3 * t + 2, k));
            out.push(a + r * (b - a) + s * (c - a));
        }
    }
    out
}

/// Median wall time of `reps` calls of `f`, in ms.
fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[reps / 2]
}

fn main() -> anyhow::Result<()> {
    let (mut sizes, mut max_pairs) = (Vec::new(), f64::INFINITY);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--max-pairs" => {
                max_pairs = args.next().ok_or_else(|| anyhow::anyhow!("--max-pairs needs a number"))?.parse()?
            }
            n => sizes.push(n.parse()?),
        }
    }
    if sizes.is_empty() {
        sizes = vec![10_000, 100_000, 1_000_000];
    }
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/pycortex_S1/lh.pia.ply.gz");
    let s = read_mesh(&path, &ReadOptions::default())?;
    let diam = s.bounding_box().diagonal();
    println!(
        "| points | σ / diam | pairs in runs | runs, scan (ms) | runs, BVH (ms) | scan / BVH | sum, scan (ms) | sum, BVH (ms) | scan / BVH |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for &n in &sizes {
        let x = sample(s.points(), s.cells(), n);
        let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        for f in [0.01, 0.05] {
            let k = Kernel::gaussian(f * diam)?.truncated(1e-6)?;
            let mut build = Vec::new();
            let mut sum = Vec::new();
            let mut out = Vec::new();
            let mut n_pairs = 0.0;
            for search in [RunSearch::AllBlocks, RunSearch::Bvh] {
                let pairs = BlockPairs::try_new_with_search(&x, &x, 3, &k, search)?;
                assert_eq!(pairs.used_bvh(), search == RunSearch::Bvh);
                let counts =
                    pairs.map_blocks(true, |t, runs| t.len() * runs.iter().map(|r| r.range.len()).sum::<usize>());
                n_pairs = counts.iter().sum::<usize>() as f64;
                build.push(median_ms(5, || {
                    std::hint::black_box(BlockPairs::try_new_with_search(&x, &x, 3, &k, search).ok());
                }));
                if n_pairs > max_pairs {
                    continue;
                }
                let sums = KernelSums::try_new(&k, &x, 3)?.with_run_search(search);
                sum.push(median_ms(if n >= 1_000_000 { 1 } else { 3 }, || {
                    out.push(sums.conv(&x, &b, 1).ok());
                }));
            }
            let cell = |v: Option<&f64>| v.map_or("–".to_string(), |ms| format!("{ms:.0}"));
            let ratio = if sum.len() == 2 { format!("{:.2}", sum[0] / sum[1]) } else { "–".to_string() };
            // The same runs, so the same bits.
            assert!(out.windows(2).all(|w| w[0] == w[1]));
            println!(
                "| {n} | {f} | {n_pairs:.2e} | {:.1} | {:.1} | {:.1} | {} | {} | {ratio} |",
                build[0],
                build[1],
                build[0] / build[1],
                cell(sum.first()),
                cell(sum.get(1)),
            );
        }
    }
    Ok(())
}
