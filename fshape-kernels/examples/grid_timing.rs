//! The grid path against today's paths on a native-resolution cortex: the
//! shooting's fused sum (K p and ∂_x(pᵀK p)/2 at the points themselves)
//! and its Jacobian–vector product, over every vertex of a surface.
//!
//! ```text
//! cargo run --release -p fshape-kernels --example grid_timing -- [MESH] [--sigma S] [--tol T] [--reps N] [--sample M] [--grid-only] [--order P]
//! ```
//!
//! `--grid-only` times the grid paths alone (no exact sums, no errors);
//! `--order P` times only the grid of B-spline order P (default 4, 6, 8).
//!
//! MESH defaults to data/pycortex_S1/lh.pia.ply.gz (152 893 vertices, mm),
//! σ to 20 mm and τ to 1e-6 (the cortex demo's deformation kernel). The
//! weights p are uniform in [−1, 1]³ (seeded). Errors are against the
//! exact f64 sums by a plain double loop over every source, at `--sample`
//! targets spread over the vertices: max_i |err_i| / max_i |exact_i| for
//! K p and for the gradient. Times are medians of `--reps` runs (the exact
//! and truncated paths: of 3); every path builds what it needs inside the
//! timed call, as the shooting does at each step.

use std::time::Instant;

use fshape_kernels::{Kernel, KernelSums, SumWorkspace};
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::io;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median wall time (ms) of `reps` runs of `f`, and its last output.
fn time<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut ts = Vec::new();
    let mut out = None;
    for _ in 0..reps {
        let t = Instant::now();
        out = Some(f());
        ts.push(t.elapsed().as_secs_f64() * 1e3);
    }
    (median(ts), out.expect("at least one run"))
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let mut mesh = String::from("data/pycortex_S1/lh.pia.ply.gz");
    let (mut sigma, mut tol, mut reps, mut sample) = (20.0, 1e-6, 5, 2000);
    let mut grid_only = false;
    let mut orders = vec![4, 6, 8];
    while let Some(a) = args.next() {
        let mut val = || args.next().ok_or_else(|| anyhow::anyhow!("{a} needs a value"));
        match a.as_str() {
            "--sigma" => sigma = val()?.parse()?,
            "--tol" => tol = val()?.parse()?,
            "--reps" => reps = val()?.parse()?,
            "--sample" => sample = val()?.parse()?,
            "--grid-only" => grid_only = true,
            "--order" => orders = vec![val()?.parse()?],
            other if !other.starts_with("--") => mesh = other.to_string(),
            other => anyhow::bail!("unknown argument {other}"),
        }
    }
    let shape = io::read_mesh(std::path::Path::new(&mesh), &io::ReadOptions::default())?;
    let (x, n, dim) = (shape.points().to_vec(), shape.n_vertices(), shape.dim());
    let mut rng = SplitMix64(7);
    let p: Vec<f64> = (0..n * dim).map(|_| rng.range(-1.0, 1.0)).collect();
    let (dx, dp): (Vec<f64>, Vec<f64>) =
        ((0..n * dim).map(|_| rng.range(-1.0, 1.0)).collect(), (0..n * dim).map(|_| rng.range(-1.0, 1.0)).collect());
    let base = Kernel::gaussian(sigma)?;
    println!("{mesh}: {n} points, sigma {sigma}, tolerance {tol:e}, {} threads", rayon::current_num_threads());

    // The exact sums at a sample of targets, by the obvious double loop.
    let sample = if grid_only { 0 } else { sample.min(n) };
    let picks: Vec<usize> = (0..sample).map(|k| k * n / sample).collect();
    let t = Instant::now();
    let (mut conv0, mut grad0) = (vec![0.0; picks.len() * dim], vec![0.0; picks.len() * dim]);
    for (s, &i) in picks.iter().enumerate() {
        for j in 0..n {
            let d: Vec<f64> = (0..dim).map(|c| x[i * dim + c] - x[j * dim + c]).collect();
            let u: f64 = d.iter().map(|v| v * v).sum();
            let [k, k1, _] = base.derivatives(u);
            let pp: f64 = (0..dim).map(|c| p[i * dim + c] * p[j * dim + c]).sum();
            for c in 0..dim {
                conv0[s * dim + c] += k * p[j * dim + c];
                grad0[s * dim + c] += 2.0 * k1 * pp * d[c];
            }
        }
    }
    println!("exact f64 double loop at {} targets: {:.1} s", picks.len(), t.elapsed().as_secs_f64());
    let rel = |out: &[f64], exact: &[f64]| {
        let big = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let err = picks
            .iter()
            .enumerate()
            .flat_map(|(s, &i)| (0..dim).map(move |c| (s, i, c)))
            .fold(0.0f64, |m, (s, i, c)| m.max((out[i * dim + c] - exact[s * dim + c]).abs()));
        err / big
    };

    let fused = |k: &Kernel, reps: usize| {
        let mut ws = SumWorkspace::default();
        time(reps, || {
            let sums = KernelSums::try_new(k, &x, dim).expect("valid points");
            let (mut kp, mut gk) = (vec![0.0; n * dim], vec![0.0; n * dim]);
            sums.self_conv_and_grad_into(&mut ws, &p, dim, &mut kp, &mut gk).expect("valid sums");
            (kp, gk)
        })
    };
    let jvp = |k: &Kernel, reps: usize| {
        let mut ws = SumWorkspace::default();
        time(reps, || {
            let sums = KernelSums::try_new(k, &x, dim).expect("valid points");
            let (mut kp, mut gk) = (vec![0.0; n * dim], vec![0.0; n * dim]);
            sums.self_conv_and_grad_jvp_into(&mut ws, &dx, &p, &dp, dim, &mut kp, &mut gk).expect("valid sums");
            kp
        })
        .0
    };
    println!("| path | K p and gradient (ms) | JVP (ms) | rel. error K p | rel. error gradient |");
    println!("|---|---|---|---|---|");
    let truncated = base.truncated(tol)?;
    let mut baseline = f64::INFINITY;
    let todays = [(format!("truncated tau={tol:e} (today's path)"), &truncated), ("exact".to_string(), &base)];
    for (name, k) in if grid_only { &todays[..0] } else { &todays[..] } {
        let (ms, (kp, gk)) = fused(k, 3);
        let jms = jvp(k, 3);
        baseline = baseline.min(ms);
        println!("| {name} | {ms:.0} | {jms:.0} | {:.1e} | {:.1e} |", rel(&kp, &conv0), rel(&gk, &grad0));
    }
    for order in orders {
        let h = base.grid_spacing(tol, order, dim)?;
        let k = base.on_grid(h, order, dim)?;
        let (ms, (kp, gk)) = fused(&k, reps);
        let jms = jvp(&k, reps);
        println!(
            "| grid order {order}, h = {h:.3} (sigma/{:.1}), bound {:.1e} | {ms:.1} | {jms:.1} | {:.1e} | {:.1e} |",
            sigma / h,
            k.grid().expect("a grid kernel").bound().value,
            rel(&kp, &conv0),
            rel(&gk, &grad0)
        );
        println!("  speed-up over the faster of today's paths: {:.0}x", baseline / ms);
    }
    Ok(())
}
