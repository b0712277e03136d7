//! One evaluation of the matching objective and its exact gradient in the
//! paper's bunny setting (`data/configs/bunny.toml`), for L2 lumped and H1,
//! exact and truncated (τ = 1e-6) deformation kernels; prints a Markdown
//! table of medians with the forward/backward split and the time spent in
//! kernel sums, FEM and the data attachment.
//!
//! ```text
//! cargo run --release -p fshape-match --example shoot_timing -- [REPS] [LEVEL]
//! ```
//!
//! LEVEL is the template's icosphere level (5, the paper's 10242 vertices,
//! by default; 3 and 4 are the demo's coarse stages).

use std::path::Path;

use fshape_match::{Config, demo};
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::io::{ReadOptions, read_mesh};
use fshape_shoot::Problem;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> anyhow::Result<()> {
    let reps: usize = std::env::args().nth(1).map(|s| s.parse()).transpose()?.unwrap_or(3);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let bunny = read_mesh(&root.join("data/stanford_bunny/bunny_qslim_2581v.ply.gz"), &ReadOptions::default())?;
    let level: u32 = std::env::args().nth(2).map(|s| s.parse()).transpose()?.unwrap_or(5);
    let (template, target) = demo::bunny_setting_at_level(&bunny, level)?;
    let base = std::fs::read_to_string(root.join("data/configs/bunny.toml"))?;
    let n = template.n_vertices();
    // Small random momenta (fixed seed): the cost does not depend on them.
    let mut rng = SplitMix64(1);
    let p0: Vec<f64> = (0..3 * n).map(|_| rng.range(-1e-3, 1e-3)).collect();
    let pf: Vec<f64> = (0..n).map(|_| rng.range(-1e-3, 1e-3)).collect();
    println!(
        "Median of {reps} evaluations of J and its gradient, {n}-vertex template, {} threads, seconds.",
        rayon_threads()
    );
    println!();
    println!("| norm | deformation kernel | total | forward | backward | kernel sums | FEM | data attachment |");
    println!("|---|---|---|---|---|---|---|---|");
    for norm in ["l2-lumped", "h1"] {
        for (label, tol) in [("exact", ""), ("tau=1e-6", "tolerance = 1e-6\n")] {
            let text = base
                .replace("norm = \"h1\"", &format!("norm = \"{norm}\""))
                .replace("weights = [1.0, 1.0]\n", &format!("weights = [1.0, 1.0]\n{tol}"));
            let config = Config::parse(&text)?;
            let problem =
                Problem::new(&template, config.model()?)?.with_target(&target, config.attachment_kernel()?)?;
            let mut rows: Vec<[f64; 6]> = Vec::new();
            for _ in 0..reps {
                let t = std::time::Instant::now();
                let g = problem.objective_grad(&p0, &pf)?;
                let total = t.elapsed().as_secs_f64();
                rows.push([total, g.forward, g.backward, g.timings.kernels, g.timings.fem, g.timings.attachment]);
            }
            let m: Vec<f64> = (0..6).map(|c| median(rows.iter().map(|r| r[c]).collect())).collect();
            println!(
                "| {norm} | {label} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
                m[0], m[1], m[2], m[3], m[4], m[5]
            );
        }
    }
    Ok(())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
