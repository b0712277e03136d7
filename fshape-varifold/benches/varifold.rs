//! Data attachment benchmarks between the two fsaverage5 pial hemispheres
//! with their thickness maps (20480 triangles each): A with ∂A/∂x and ∂A/∂f
//! (one matching iteration), and A alone (a line-search step), for
//! σ ∈ {5, 10, 20} mm, exact and truncated at τ = 1e-6. Run with
//! `cargo bench -p fshape-varifold`; the pykeops comparison is
//! `scripts/varifold_compare.sh`.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use fshape_kernels::Kernel;
use fshape_mesh::io::{self, ReadOptions};
use fshape_varifold::{Attachment, GrassKernel, SignalKernel, VarifoldKernel};

fn bench(c: &mut Criterion) {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/fsaverage5");
    let x = io::read_mesh(&data.join("lh.pial.thick.ply.gz"), &ReadOptions::default()).expect("shipped cortex");
    let thick = io::csv::read_signal(&data.join("rh.thick.csv.gz"), false).expect("shipped thickness");
    let y = io::read_mesh(&data.join("rh.pial.ply.gz"), &ReadOptions::default())
        .expect("shipped cortex")
        .with_signal(Some(thick.values))
        .expect("one thickness per vertex");
    let mut group = c.benchmark_group("varifold");
    group.sample_size(10).warm_up_time(Duration::from_millis(300)).measurement_time(Duration::from_secs(5));
    for sigma in [5.0, 10.0, 20.0] {
        let exact = VarifoldKernel::try_new(
            Kernel::gaussian(sigma).unwrap(),
            SignalKernel::Gaussian { sigma: 0.5 },
            GrassKernel::UnorientedGaussian { sigma: 0.5 },
        )
        .unwrap();
        for (label, k) in [("exact", exact.clone()), ("tau1e-6", exact.truncated(1e-6).unwrap())] {
            let att = Attachment::new(&y, k).unwrap();
            group.bench_function(BenchmarkId::new(format!("value_grad_{label}"), sigma), |b| {
                b.iter(|| black_box(att.eval_grad(&x).unwrap()))
            });
            if sigma == 10.0 {
                group.bench_function(BenchmarkId::new(format!("value_{label}"), sigma), |b| {
                    b.iter(|| black_box(att.eval(&x).unwrap()))
                });
            }
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
