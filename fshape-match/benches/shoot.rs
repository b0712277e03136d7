//! One evaluation of the matching objective J and its exact gradient in the
//! paper's bunny setting (10242-vertex sphere onto the 2581-vertex bunny,
//! `data/configs/bunny.toml`, 10 RK4 steps), for L2 lumped and H1, exact
//! and truncated (τ = 1e-6) deformation kernels. Each evaluation takes tens
//! of seconds: run with `cargo bench -p fshape-shoot`. The forward/backward
//! and per-component split is printed by
//! `cargo run --release -p fshape-shoot --example shoot_timing`.

use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use fshape_match::{Config, demo};
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::io::{ReadOptions, read_mesh};
use fshape_shoot::Problem;

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let bunny = read_mesh(&root.join("data/stanford_bunny/bunny_qslim_2581v.ply.gz"), &ReadOptions::default())
        .expect("shipped bunny");
    let (template, target) = demo::bunny_setting(&bunny).expect("bunny setting");
    let base = std::fs::read_to_string(root.join("data/configs/bunny.toml")).expect("shipped config");
    let n = template.n_vertices();
    let mut rng = SplitMix64(1);
    let p0: Vec<f64> = (0..3 * n).map(|_| rng.range(-1e-3, 1e-3)).collect();
    let pf: Vec<f64> = (0..n).map(|_| rng.range(-1e-3, 1e-3)).collect();
    let mut group = c.benchmark_group("shoot");
    group.sample_size(10).warm_up_time(Duration::from_millis(1)).measurement_time(Duration::from_secs(1));
    for norm in ["l2-lumped", "h1"] {
        for (label, tol) in [("exact", ""), ("tau1e-6", "tolerance = 1e-6\n")] {
            let text = base
                .replace("norm = \"h1\"", &format!("norm = \"{norm}\""))
                .replace("weights = [1.0, 1.0]\n", &format!("weights = [1.0, 1.0]\n{tol}"));
            let config = Config::parse(&text).expect("config");
            let kernel = config.attachment_kernel().expect("attachment kernel");
            let problem = Problem::new(&template, config.model().expect("model"))
                .and_then(|p| p.with_target(&target, kernel))
                .expect("problem");
            group.bench_function(BenchmarkId::new(format!("objective_grad_{norm}"), label), |b| {
                b.iter(|| black_box(problem.objective_grad(&p0, &pf).expect("evaluation")))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
