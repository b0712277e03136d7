//! Times fshape-fem on one mesh for `scripts/fem_compare.sh` (which times
//! libigl on the same mesh in the same run) and prints one JSON line.
//!
//! ```text
//! cargo run --release -p fshape-fem --example fem_timing -- MESH|ico:LEVEL [--reps N] [--export PLY]
//! ```
//! - assembly: from raw vertex and cell arrays to the P1 mass and stiffness
//!   values, counting the shape's validation and the sparsity pattern;
//! - refactor_solve: assembly and numeric Cholesky of D_1 (ℓ = 1) at x
//!   with the saved analysis, plus one solve (nested-dissection ordering,
//!   the default; `refactor_solve_amd_ms` with AMD, `l_len_*` their fill);
//! - `--export` writes the mesh as binary PLY for the other side to read.

use std::path::Path;
use std::time::Instant;

use fshape_fem::{FillOrdering, Norm, SignalNorm};
use fshape_mesh::FShape;
use fshape_mesh::io::{Encoding, ReadOptions, read_mesh, write_mesh};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let target =
        args.first().ok_or_else(|| anyhow::anyhow!("usage: fem_timing MESH|ico:LEVEL [--reps N] [--export PLY]"))?;
    let flag = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned();
    let reps: usize = flag("--reps").map_or(Ok(7), |s| s.parse())?;
    let shape = match target.strip_prefix("ico:") {
        Some(level) => fshape_mesh::generate::icosphere(level.parse()?, 1.0),
        None => read_mesh(Path::new(target), &ReadOptions::default())?,
    };
    if let Some(path) = flag("--export") {
        write_mesh(Path::new(&path), &shape, Encoding::Binary)?;
    }
    let (dim, kind, points, cells) = (shape.dim(), shape.kind(), shape.points().to_vec(), shape.cells().to_vec());
    let assembly = time_ms(reps, || {
        let s = FShape::try_new(dim, kind, points.clone(), cells.clone(), None).expect("valid mesh");
        let d = SignalNorm::try_new(&s, Norm::L2).expect("pattern");
        std::hint::black_box(d.assemble_mass_and_stiffness(s.points()).expect("assembly"));
    });
    let d = SignalNorm::try_new(&shape, Norm::H1 { length: 1.0 })?;
    let fixed = time_ms(reps, || {
        std::hint::black_box(d.assemble(&points).expect("assembly"));
    });
    let b = vec![1.0; shape.n_vertices()];
    // (analysis ms, refactor+solve ms, factor values) for one ordering.
    let run = |ordering: FillOrdering| -> anyhow::Result<(f64, f64, usize)> {
        let d = SignalNorm::try_new(&shape, Norm::H1 { length: 1.0 })?.with_ordering(ordering);
        let t = Instant::now();
        let mut solver = d.solver()?;
        let symbolic_ms = t.elapsed().as_secs_f64() * 1e3;
        let ms = time_ms(reps, || {
            solver.factor(&points).expect("factor");
            std::hint::black_box(solver.solve(&b).expect("solve"));
        });
        Ok((symbolic_ms, ms, solver.l_len()))
    };
    let (symbolic_ms, refactor_solve, l_len) = run(FillOrdering::NestedDissection)?;
    let (symbolic_amd_ms, refactor_solve_amd, l_len_amd) = run(FillOrdering::Amd)?;
    println!(
        "{{\"mesh\": \"{target}\", \"n_vertices\": {}, \"n_cells\": {}, \"assembly_ms\": {assembly:.3}, \"assembly_fixed_pattern_ms\": {fixed:.3}, \"symbolic_ms\": {symbolic_ms:.3}, \"refactor_solve_ms\": {refactor_solve:.3}, \"l_len\": {l_len}, \"symbolic_amd_ms\": {symbolic_amd_ms:.3}, \"refactor_solve_amd_ms\": {refactor_solve_amd:.3}, \"l_len_amd\": {l_len_amd}, \"threads\": {}}}",
        shape.n_vertices(),
        shape.n_cells(),
        rayon::current_num_threads()
    );
    Ok(())
}
