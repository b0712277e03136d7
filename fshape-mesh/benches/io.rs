//! Reading, writing and validating meshes of growing size (icospheres).
//! Run with `cargo bench -p fshape-mesh`.

use std::hint::black_box;
use std::path::Path;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use fshape_mesh::generate::icosphere;
use fshape_mesh::io::{Encoding, Format, ReadOptions, parse_mesh, write_to};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("mesh");
    group.sample_size(20);
    for level in [4u32, 6] {
        let shape = fshape_mesh::test_support::perturbed_icosphere(level, 0.05, 1);
        let n = shape.n_cells();
        for (name, enc) in [("ply_binary", Encoding::Binary), ("ply_ascii", Encoding::Ascii)] {
            let mut bytes = Vec::new();
            write_to(&mut bytes, &shape, Format::Ply, enc).unwrap();
            group.bench_with_input(BenchmarkId::new(format!("parse_{name}"), n), &bytes, |b, bytes| {
                b.iter(|| {
                    parse_mesh(black_box(bytes), Format::Ply, &ReadOptions::default(), Path::new("bench")).unwrap()
                })
            });
        }
        group.bench_with_input(BenchmarkId::new("validate", n), &shape, |b, s| b.iter(|| black_box(s).validate()));
        group.bench_with_input(BenchmarkId::new("icosphere", n), &level, |b, &l| {
            b.iter(|| icosphere(black_box(l), 1.0))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
