//! Kernel-sum benchmarks on real cortex points: N = M ∈ {10³, 10⁴, 32·10³}
//! (conte69) with σ ∈ {0.01, 0.05, 0.2} × diameter, and 10⁵ (pycortex S1)
//! with σ = 0.05 × diameter, exact and truncated (τ = 1e-6, 1e-9),
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
    // 10⁵ points: the 152893-vertex pycortex S1 pial surface, one width.
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/pycortex_S1/lh.pia.ply.gz");
    let large = read_mesh(&path, &ReadOptions::default()).expect("shipped cortex");
    let mut group = c.benchmark_group("kernels");
    group.sample_size(10).warm_up_time(Duration::from_millis(300)).measurement_time(Duration::from_secs(2));
    for (mesh, n, widths) in [
        (&cortex, 1_000usize, &[0.01, 0.05, 0.2][..]),
        (&cortex, 10_000, &[0.01, 0.05, 0.2]),
        (&cortex, cortex.n_vertices(), &[0.01, 0.05, 0.2]),
        (&large, 100_000, &[0.05]),
    ] {
        // Vertices k·P/n: a subset spread over the whole surface.
        let x: Vec<f64> = (0..n).flat_map(|k| mesh.point(k * mesh.n_vertices() / n).to_vec()).collect();
        let diam = mesh.bounding_box().diagonal();
        let mut rng = SplitMix64(1);
        let b: Vec<f64> = (0..3 * n).map(|_| rng.uniform()).collect();
        for &f in widths {
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

/// The shooting's fused self-interaction sums (K p and ∂_x(pᵀKp)/2, and
/// their directional derivatives) with the bunny's deformation kernel
/// (Gaussians of widths 0.2 and 0.1, unit weights) on icospheres of radius
/// 0.35: the general path (`conv_and_grad_into` with x = y) against the
/// one that visits each pair once (`self_conv_and_grad_into`).
fn shooting(c: &mut Criterion) {
    use fshape_kernels::{Profile, SumWorkspace};
    let mut group = c.benchmark_group("shooting");
    group.sample_size(10).warm_up_time(Duration::from_millis(300)).measurement_time(Duration::from_secs(2));
    let k = Kernel::try_new(&Profile::Gaussians { sigmas: vec![0.2, 0.1], weights: vec![1.0, 1.0] }).unwrap();
    for level in [4, 5] {
        let sphere = fshape_mesh::generate::icosphere(level, 0.35);
        let y = sphere.points().to_vec();
        let n = y.len() / 3;
        let mut rng = SplitMix64(2);
        let mut r = |len: usize| -> Vec<f64> { (0..len).map(|_| rng.range(-1.0, 1.0)).collect() };
        let (p, dy, dp) = (r(3 * n), r(3 * n), r(3 * n));
        let sums = KernelSums::try_new(&k, &y, 3).unwrap();
        let mut ws = SumWorkspace::default();
        let (mut conv, mut grad) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
        group.bench_function(BenchmarkId::new("conv_and_grad_general", n), |bch| {
            bch.iter(|| sums.conv_and_grad_into(&mut ws, &y, &p, &p, 3, &mut conv, &mut grad).unwrap())
        });
        group.bench_function(BenchmarkId::new("conv_and_grad_self", n), |bch| {
            bch.iter(|| sums.self_conv_and_grad_into(&mut ws, &p, 3, &mut conv, &mut grad).unwrap())
        });
        group.bench_function(BenchmarkId::new("jvp_general", n), |bch| {
            bch.iter(|| {
                sums.conv_and_grad_jvp_into(&mut ws, &y, &dy, &dy, &p, &dp, &p, &dp, 3, &mut conv, &mut grad).unwrap()
            })
        });
        group.bench_function(BenchmarkId::new("jvp_self", n), |bch| {
            bch.iter(|| sums.self_conv_and_grad_jvp_into(&mut ws, &dy, &p, &dp, 3, &mut conv, &mut grad).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, bench, shooting);
criterion_main!(benches);
