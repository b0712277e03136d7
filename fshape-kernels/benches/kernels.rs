//! Kernel-sum benchmarks on real cortex points: N = M ∈ {10³, 10⁴, 32·10³},
//! σ ∈ {0.01, 0.05, 0.2} × diameter, exact and truncated (τ = 1e-6, 1e-9),
//! Gaussian sums with 3-vector weights, in f64 and in mixed precision
//! (`_mixed`: pair terms in f32), and the gradient of pᵀKp. Run with
//! `cargo bench -p fshape-kernels`; the pykeops comparison is
//! `scripts/kernel_compare.sh`.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use fshape_kernels::{Kernel, KernelSums, Precision};
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::io::{ReadOptions, read_mesh};

fn bench(c: &mut Criterion) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/conte69_32k/lh.midthickness.ply.gz");
    let cortex = read_mesh(&path, &ReadOptions::default()).expect("shipped cortex");
    let diam = cortex.bounding_box().diagonal();
    let mut group = c.benchmark_group("kernels");
    group.sample_size(10).warm_up_time(Duration::from_millis(300)).measurement_time(Duration::from_secs(2));
    for n in [1_000usize, 10_000, cortex.n_vertices()] {
        // Every (P/n)-th vertex: a subset spread over the whole surface.
        let step = cortex.n_vertices() / n;
        let x: Vec<f64> = (0..n).flat_map(|k| cortex.point(k * step).to_vec()).collect();
        let mut rng = SplitMix64(1);
        let b: Vec<f64> = (0..3 * n).map(|_| rng.uniform()).collect();
        for f in [0.01, 0.05, 0.2] {
            let exact = Kernel::gaussian(f * diam).unwrap();
            for (label, k) in [
                ("exact", exact.clone()),
                ("tau1e-6", exact.truncated(1e-6).unwrap()),
                ("tau1e-9", exact.truncated(1e-9).unwrap()),
            ] {
                for (prec, precision) in [("", Precision::F64), ("_mixed", Precision::MixedF32)] {
                    let id = BenchmarkId::new(format!("conv_{label}{prec}_sigma{f}"), n);
                    group.bench_function(id, |bch| {
                        bch.iter(|| {
                            let sums = KernelSums::try_new(&k, &x, 3).unwrap().with_precision(precision);
                            black_box(sums.conv(&x, &b, 3).unwrap())
                        })
                    });
                }
            }
        }
        if n <= 10_000 {
            let k = Kernel::gaussian(0.05 * diam).unwrap();
            group.bench_function(BenchmarkId::new("grad_pKp_exact_sigma0.05", n), |bch| {
                bch.iter(|| black_box(KernelSums::try_new(&k, &x, 3).unwrap().grad_cross(&x, &b, &b, 3).unwrap()))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
