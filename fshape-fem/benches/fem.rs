//! FEM benchmarks: assembly of each matrix (from raw arrays, and values on a
//! fixed pattern), the x-gradient of hᵀ D(x) h, and refactorise + solve of
//! D_1 (nested-dissection and AMD orderings), on icospheres of ~10⁴, ~10⁵ and ~10⁶ triangles and the
//! 305k-triangle real cortex. Run with `cargo bench -p fshape-fem`; the
//! comparison with libigl is `scripts/fem_compare.sh`.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use fshape_fem::{FillOrdering, Norm, SignalNorm};
use fshape_mesh::FShape;
use fshape_mesh::generate::icosphere;
use fshape_mesh::io::{ReadOptions, read_mesh};

fn meshes() -> Vec<(String, FShape)> {
    let cortex = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/pycortex_S1/lh.pia.ply.gz");
    let mut out: Vec<(String, FShape)> =
        [5u32, 6, 8].iter().map(|&l| (format!("icosphere{l}"), icosphere(l, 1.0))).collect();
    out.push(("cortex_S1".into(), read_mesh(&cortex, &ReadOptions::default()).expect("shipped cortex")));
    out
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("fem");
    group.sample_size(10).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    for (name, s) in meshes() {
        let id = |op: &str| BenchmarkId::new(op, format!("{name}-{}tri", s.n_cells()));
        let x = s.points();
        let (dim, kind) = (s.dim(), s.kind());
        group.bench_function(id("mass_stiffness_from_raw_arrays"), |b| {
            b.iter(|| {
                let sh = FShape::try_new(dim, kind, x.to_vec(), s.cells().to_vec(), None).unwrap();
                let d = SignalNorm::try_new(&sh, Norm::L2).unwrap();
                black_box(d.assemble_mass_and_stiffness(sh.points()).unwrap())
            })
        });
        for norm in [Norm::L2Lumped, Norm::L2, Norm::H1 { length: 1.0 }] {
            let d = SignalNorm::try_new(&s, norm).unwrap();
            group.bench_function(id(&format!("assemble_{}", norm.name())), |b| {
                b.iter(|| black_box(d.assemble(x).unwrap()))
            });
        }
        let h: Vec<f64> = x.chunks_exact(dim).map(|p| p[0].sin() + p[1]).collect();
        let d = SignalNorm::try_new(&s, Norm::H1 { length: 1.0 }).unwrap();
        group.bench_function(id("grad_h1"), |b| b.iter(|| black_box(d.grad(x, &h, &h).unwrap())));
        // Nested dissection (the default) and AMD, for the record of the
        // choice (README).
        for (op, ordering) in
            [("refactor_solve_h1", FillOrdering::NestedDissection), ("refactor_solve_h1_amd", FillOrdering::Amd)]
        {
            let d = SignalNorm::try_new(&s, Norm::H1 { length: 1.0 }).unwrap().with_ordering(ordering);
            let mut solver = d.solver().unwrap();
            group.bench_function(id(op), |b| {
                b.iter(|| {
                    solver.factor(x).unwrap();
                    black_box(solver.solve(&h).unwrap())
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
