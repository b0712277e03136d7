//! Times the data attachment between the two fsaverage5 pial hemispheres
//! with their thickness maps, for `scripts/varifold_compare.sh` (which
//! times pykeops on the same inputs in the same run). Prints one JSON line.
//!
//! ```text
//! cargo run --release -p fshape-varifold --example varifold_timing -- SIGMA SIGMA_F SIGMA_T [--reps N] [--tol TAU]... [--export DIR]
//! ```
//! Kernel: Gaussian k_p of width SIGMA (mm), Gaussian k_f of width SIGMA_F,
//! unoriented Gaussian k_t of width SIGMA_T. Times `Attachment::eval_grad`
//! (A, ∂A/∂x, ∂A/∂f: the work of one matching iteration; ⟨Y,Y⟩ is computed
//! once beforehand, as in a matching), exact and truncated at each τ.
//! `--export DIR` writes the meshes (f64 points, u32 faces, f64 signals) and
//! the exact A and gradients for the other side's checks.

use std::path::{Path, PathBuf};
use std::time::Instant;

use fshape_kernels::Kernel;
use fshape_mesh::FShape;
use fshape_mesh::io::{self, ReadOptions};
use fshape_varifold::{Attachment, GrassKernel, SignalKernel, VarifoldKernel};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn write_f64(p: &Path, v: &[f64]) -> std::io::Result<()> {
    std::fs::write(p, v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>())
}

fn export(dir: &Path, name: &str, s: &FShape) -> anyhow::Result<()> {
    write_f64(&dir.join(format!("{name}_points.bin")), s.points())?;
    let faces: Vec<u8> = s.cells().iter().flat_map(|&c| (c as u32).to_le_bytes()).collect();
    std::fs::write(dir.join(format!("{name}_faces.bin")), faces)?;
    write_f64(&dir.join(format!("{name}_signal.bin")), s.signal().unwrap_or(&[]))?;
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (sigma, sigma_f, sigma_t) = (args[0].parse::<f64>()?, args[1].parse::<f64>()?, args[2].parse::<f64>()?);
    let (mut reps, mut tols, mut dir) = (3, Vec::new(), None);
    let mut k = 3;
    while k < args.len() {
        match args[k].as_str() {
            "--reps" => reps = args[k + 1].parse()?,
            "--tol" => tols.push(args[k + 1].parse::<f64>()?),
            "--export" => dir = Some(PathBuf::from(&args[k + 1])),
            other => anyhow::bail!("unknown argument {other}"),
        }
        k += 2;
    }
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/fsaverage5");
    let x = io::read_mesh(&data.join("lh.pial.thick.ply.gz"), &ReadOptions::default())?;
    let rh = io::read_mesh(&data.join("rh.pial.ply.gz"), &ReadOptions::default())?;
    let y = rh.with_signal(Some(io::csv::read_signal(&data.join("rh.thick.csv.gz"), false)?.values))?;
    let kernel = VarifoldKernel::try_new(
        Kernel::gaussian(sigma)?,
        SignalKernel::Gaussian { sigma: sigma_f },
        GrassKernel::UnorientedGaussian { sigma: sigma_t },
    )?;
    let time = |kern: &VarifoldKernel| -> anyhow::Result<(f64, f64, Vec<f64>, Vec<f64>)> {
        let att = Attachment::new(&y, kern.clone())?;
        let mut ts = Vec::new();
        let mut last = None;
        for _ in 0..reps {
            let t = Instant::now();
            last = Some(att.eval_grad(&x)?);
            ts.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let (d, g) = last.expect("reps ≥ 1");
        Ok((median(ts), d.value, g.points, g.signal))
    };
    let (exact_ms, a, gx, gf) = time(&kernel)?;
    let max_abs = |v: &[f64]| v.iter().map(|t| t.abs()).fold(0.0, f64::max);
    let max_diff = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max);
    let mut trunc = Vec::new();
    for tol in tols {
        let (ms, at, gxt, gft) = time(&kernel.truncated(tol)?)?;
        trunc.push(format!(
            "{{\"tol\": {tol:e}, \"ms\": {ms:.3}, \"rel_err_a\": {:e}, \"rel_err_gx\": {:e}, \"rel_err_gf\": {:e}}}",
            (at - a).abs() / a.abs(),
            max_diff(&gxt, &gx) / max_abs(&gx),
            max_diff(&gft, &gf) / max_abs(&gf)
        ));
    }
    if let Some(d) = dir {
        std::fs::create_dir_all(&d)?;
        export(&d, "x", &x)?;
        export(&d, "y", &y)?;
        write_f64(&d.join("ours_a.bin"), &[a])?;
        write_f64(&d.join("ours_gx.bin"), &gx)?;
        write_f64(&d.join("ours_gf.bin"), &gf)?;
    }
    println!(
        "{{\"cells\": [{}, {}], \"sigma\": {sigma}, \"a\": {a:e}, \"exact_ms\": {exact_ms:.3}, \"truncated\": [{}], \"threads\": {}}}",
        x.n_cells(),
        y.n_cells(),
        trunc.join(", "),
        rayon::current_num_threads()
    );
    Ok(())
}
