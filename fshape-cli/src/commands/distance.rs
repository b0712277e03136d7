//! `fshape distance`: the data attachment between two fshapes.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fshape_mesh::FShape;
use serde::Serialize;

/// `fshape distance`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The source mesh X.
    pub source: PathBuf,
    /// The target mesh Y.
    pub target: PathBuf,
    /// Position kernel: gaussian:σ, gaussian:σ1,σ2,... (a sum) or cauchy:σ.
    #[arg(long)]
    pub kernel_geom: String,
    /// Signal kernel gaussian:σ_f (omit for the purely geometric distance).
    #[arg(long)]
    pub kernel_signal: Option<String>,
    /// Direction kernel: linear (currents), binet, gaussian-oriented:σ_t
    /// or gaussian-unoriented:σ_t.
    #[arg(long)]
    pub kernel_grass: String,
    /// Truncate the position kernel at tolerance τ (changes each inner
    /// product by at most τ·k(0)·mass(X)·mass(Y)); exact by default.
    #[arg(long)]
    pub tolerance: Option<f64>,
    #[command(flatten)]
    pub signals: crate::args::Signals,
    /// Print JSON for scripts.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    distance(&DistanceArgs {
        source: &a.source,
        target: &a.target,
        kernel: (&a.kernel_geom, a.kernel_signal.as_deref(), &a.kernel_grass),
        tolerance: a.tolerance,
        signal_name: a.signals.signal_name.clone(),
        signals: a.signals.files(),
        json: a.json,
    })
}

struct DistanceArgs<'a> {
    source: &'a Path,
    target: &'a Path,
    kernel: (&'a str, Option<&'a str>, &'a str),
    tolerance: Option<f64>,
    signal_name: Option<String>,
    signals: (&'a [std::path::PathBuf], &'a [std::path::PathBuf]),
    json: bool,
}

#[derive(Serialize)]
struct DistanceSummary {
    source: String,
    target: String,
    kernel_geom: String,
    kernel_signal: Option<String>,
    kernel_grass: String,
    tolerance: Option<f64>,
    /// A(X, Y), a squared distance.
    value: f64,
    xx: f64,
    xy: f64,
    yy: f64,
    source_cells: usize,
    target_cells: usize,
    seconds: f64,
}

/// Prints the load-time warnings that matter to a data attachment.
fn warn_massless(path: &Path, s: &FShape) {
    let report = s.validate();
    for (code, what) in [("unused_vertex", "unused vertices"), ("zero_volume_cell", "cells of zero volume")] {
        let n = report.count(code);
        if n > 0 {
            eprintln!("warning: {}: {n} {what}; they carry no mass in the data attachment", path.display());
        }
    }
}

fn distance(a: &DistanceArgs<'_>) -> Result<()> {
    let (geom, signal, grass) = a.kernel;
    let kernel = fshape_match::ops::attachment_kernel(geom, signal, grass, a.tolerance)?;
    let x = crate::inputs::load_masked(a.source, a.signal_name.clone(), a.signals.0, &Default::default())?;
    let y = crate::inputs::load_masked(a.target, a.signal_name.clone(), a.signals.1, &Default::default())?;
    warn_massless(a.source, &x);
    warn_massless(a.target, &y);
    let start = std::time::Instant::now();
    let d = fshape_match::ops::attachment(&x, &y, &kernel)
        .with_context(|| format!("A({}, {})", a.source.display(), a.target.display()))?;
    let summary = DistanceSummary {
        source: a.source.display().to_string(),
        target: a.target.display().to_string(),
        kernel_geom: geom.to_string(),
        kernel_signal: signal.map(str::to_string),
        kernel_grass: grass.to_string(),
        tolerance: a.tolerance,
        value: d.value,
        xx: d.xx,
        xy: d.xy,
        yy: d.yy,
        source_cells: x.n_cells(),
        target_cells: y.n_cells(),
        seconds: start.elapsed().as_secs_f64(),
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("A = {:.12e}", d.value);
        println!("<X,X> = {:.12e}\n<X,Y> = {:.12e}\n<Y,Y> = {:.12e}", d.xx, d.xy, d.yy);
        println!("({} and {} cells, {:.3} s)", x.n_cells(), y.n_cells(), summary.seconds);
    }
    Ok(())
}
