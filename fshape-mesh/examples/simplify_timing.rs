//! Times the simplifier on a mesh and describes what it made.
//!
//! ```text
//! cargo run --release -p fshape-mesh --example simplify_timing -- MESH [SIGNAL.csv] --to N[,N...] [--out DIR]
//! ```
//!
//! For each count N: the time (median of 3), the vertices and triangles
//! reached, the worst triangle quality (4√3·area/Σ edge²; 1 equilateral),
//! the boundary loops and Euler characteristic against the input's, and
//! with `--out` the coarse mesh as DIR/coarse_N.ply.

use std::time::Instant;

use fshape_mesh::io::{self, Encoding, ReadOptions};
use fshape_mesh::{CellKind, FShape};

fn worst_quality(s: &FShape) -> f64 {
    let p = |i: usize| {
        let q = s.point(i);
        [q[0], q[1], if s.dim() == 3 { q[2] } else { 0.0 }]
    };
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    s.cell_iter()
        .map(|c| {
            let (a, b, d) = (p(c[0]), p(c[1]), p(c[2]));
            let (u, v) = (sub(b, a), sub(d, a));
            let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
            let e = dot(u, u) + dot(sub(d, b), sub(d, b)) + dot(v, v);
            2.0 * 3f64.sqrt() * dot(n, n).sqrt() / e
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut mesh = io::read_mesh(std::path::Path::new(&args[0]), &ReadOptions::default())?;
    let (mut counts, mut out) = (Vec::new(), None);
    let mut k = 1;
    while k < args.len() {
        match args[k].as_str() {
            "--to" => counts = args[k + 1].split(',').map(str::parse).collect::<Result<Vec<usize>, _>>()?,
            "--out" => out = Some(std::path::PathBuf::from(&args[k + 1])),
            signal => {
                let s = io::csv::read_signal(std::path::Path::new(signal), false)?;
                mesh = mesh.with_signal(Some(s.values))?;
                k -= 1;
            }
        }
        k += 2;
    }
    let topo = mesh.topology();
    println!(
        "{}: {} vertices, {} triangles, {} boundary loops, Euler {}, worst quality {:.3}",
        args[0],
        mesh.n_vertices(),
        mesh.n_cells(),
        topo.n_boundary_loops,
        topo.euler_characteristic(CellKind::Triangle, mesh.n_cells()),
        worst_quality(&mesh)
    );
    println!("| vertices asked | reached | triangles | seconds | worst quality | boundary loops | Euler |");
    println!("|---|---|---|---|---|---|---|");
    for n in counts {
        let mut times = Vec::new();
        let mut coarse = None;
        for _ in 0..3 {
            let t = Instant::now();
            coarse = Some(mesh.simplified(n)?.shape);
            times.push(t.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        let c = coarse.expect("three runs");
        let t = c.topology();
        println!(
            "| {n} | {} | {} | {:.2} | {:.3} | {} | {} |",
            c.n_vertices(),
            c.n_cells(),
            times[1],
            worst_quality(&c),
            t.n_boundary_loops,
            t.euler_characteristic(CellKind::Triangle, c.n_cells())
        );
        if let Some(dir) = &out {
            std::fs::create_dir_all(dir)?;
            io::write_mesh(&dir.join(format!("coarse_{n}.ply")), &c, Encoding::Binary)?;
        }
    }
    Ok(())
}
