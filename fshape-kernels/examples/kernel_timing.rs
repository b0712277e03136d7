//! Times fshape-kernels for `scripts/kernel_compare.sh`, which times pykeops
//! on the same inputs in the same run. Prints one JSON line.
//!
//! ```text
//! cargo run --release -p fshape-kernels --example kernel_timing -- POINTS.bin SIGMA [--reps N] [--tol TAU]... [--out OUT.bin]
//! ```
//! POINTS.bin: little-endian f64, N × 6 (x, y, z, b1, b2, b3). Sums
//! out_i = Σ_j exp(−|x_i − x_j|²/(2σ²)) b_j over the same points (N = M),
//! exact and truncated at each τ; `--out` writes the exact result (N × 3 f64)
//! for the error check on the other side.

use std::time::Instant;

use fshape_kernels::{Kernel, KernelSums, Precision};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (path, sigma) = (&args[0], args[1].parse::<f64>()?);
    let mut reps = 3;
    let mut tols = Vec::new();
    let mut out_path = None;
    let mut k = 2;
    while k < args.len() {
        match args[k].as_str() {
            "--reps" => reps = args[k + 1].parse()?,
            "--tol" => tols.push(args[k + 1].parse::<f64>()?),
            "--out" => out_path = Some(args[k + 1].clone()),
            other => anyhow::bail!("unknown argument {other}"),
        }
        k += 2;
    }
    let raw: Vec<f64> =
        std::fs::read(path)?.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect();
    let x: Vec<f64> = raw.chunks_exact(6).flat_map(|r| [r[0], r[1], r[2]]).collect();
    let b: Vec<f64> = raw.chunks_exact(6).flat_map(|r| [r[3], r[4], r[5]]).collect();
    let kernel = Kernel::gaussian(sigma)?;
    let time = |kern: &Kernel, precision: Precision| -> anyhow::Result<(f64, Vec<f64>)> {
        let mut ts = Vec::new();
        let mut out = Vec::new();
        for _ in 0..reps {
            let t = Instant::now();
            // Building the tree counts: it is rebuilt whenever the points move.
            let sums = KernelSums::try_new(kern, &x, 3)?.with_precision(precision);
            out = sums.conv(&x, &b, 3)?;
            ts.push(t.elapsed().as_secs_f64() * 1e3);
        }
        Ok((median(ts), out))
    };
    let (exact_ms, exact) = time(&kernel, Precision::F64)?;
    let max_exact = exact.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let rel_err = |out: &[f64]| out.iter().zip(&exact).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max) / max_exact;
    let (mixed_ms, mixed) = time(&kernel, Precision::MixedF32)?;
    let mixed_err = rel_err(&mixed);
    let mut trunc = Vec::new();
    for tol in tols {
        let (ms, out) = time(&kernel.truncated(tol)?, Precision::F64)?;
        let (ms32, out32) = time(&kernel.truncated(tol)?, Precision::MixedF32)?;
        let (err, err32) = (rel_err(&out), rel_err(&out32));
        trunc.push(format!(
            "{{\"tol\": {tol:e}, \"ms\": {ms:.3}, \"rel_err\": {err:e}, \"mixed_ms\": {ms32:.3}, \"mixed_rel_err\": {err32:e}}}"
        ));
    }
    if let Some(p) = out_path {
        std::fs::write(p, exact.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>())?;
    }
    println!(
        "{{\"n\": {}, \"sigma\": {sigma}, \"exact_ms\": {exact_ms:.3}, \"mixed_ms\": {mixed_ms:.3}, \"mixed_rel_err\": {mixed_err:e}, \"truncated\": [{}], \"threads\": {}}}",
        x.len() / 3,
        trunc.join(", "),
        rayon::current_num_threads()
    );
    Ok(())
}
