//! Times the per-pair engine with each spatial index (kiddo, obvhs) on the
//! 32k cortex, build included, for the record in ARCHITECTURE.md. The
//! kernel is a sum of five Gaussians (widths σ, 0.8σ, 0.6σ, 0.4σ, 0.2σ),
//! which the vectorised block path does not take (it takes up to four):
//! the run checks that each sum built the index it times.
//! `cargo run --release -p fshape-kernels --example index_timing`.

use std::path::PathBuf;
use std::time::Instant;

use fshape_kernels::{Kernel, KernelSums, Profile, SpatialIndex};
use fshape_mesh::io::{ReadOptions, read_mesh};

fn main() -> anyhow::Result<()> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/conte69_32k/lh.midthickness.ply.gz");
    let s = read_mesh(&path, &ReadOptions::default())?;
    let (x, diam) = (s.points(), s.bounding_box().diagonal());
    let b: Vec<f64> = (0..s.n_vertices()).map(|i| (i as f64 * 0.37).sin()).collect();
    println!("| workload | kiddo (ms) | obvhs (ms) | obvhs / kiddo |");
    println!("|---|---|---|---|");
    for f in [0.01, 0.02, 0.05] {
        let sigma = f * diam;
        let sigmas = [1.0, 0.8, 0.6, 0.4, 0.2].map(|r| r * sigma).to_vec();
        let k = Kernel::try_new(&Profile::Gaussians { sigmas, weights: vec![1.0; 5] })?.truncated(1e-6)?;
        let mut ms = Vec::new();
        for index in [SpatialIndex::Kiddo, SpatialIndex::Obvhs] {
            let mut t = Vec::new();
            for _ in 0..3 {
                let start = Instant::now();
                let sums = KernelSums::try_new(&k, x, 3)?.with_index(index);
                std::hint::black_box(sums.conv(x, &b, 1)?);
                anyhow::ensure!(sums.spatial_index_built() == Some(index), "the sum did not use {index:?}");
                t.push(start.elapsed().as_secs_f64() * 1e3);
            }
            t.sort_by(f64::total_cmp);
            ms.push(t[1]);
        }
        println!(
            "| 32492 points, 5 Gaussians σ = {f}·diam, τ = 1e-6, build + sum | {:.1} | {:.1} | {:.2} |",
            ms[0],
            ms[1],
            ms[1] / ms[0]
        );
    }
    Ok(())
}
