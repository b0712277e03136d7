//! `fshape shoot`: a geodesic from a template and initial momenta.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fshape_match::record::RunRecord;
use fshape_mesh::FShape;
use fshape_mesh::io;

use crate::inputs::load;
use fshape_report::outputs::trajectory_files;

/// `fshape shoot`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The template mesh (its signal, if any, is f_0; else 0).
    pub source: PathBuf,
    /// Initial momenta p_0: CSV, a header line, then p_x,p_y (or p_x,p_y,p_z) per vertex.
    #[arg(long)]
    pub momentum: PathBuf,
    /// Signal momentum p^f (CSV, a column per signal channel of the
    /// template: pf, or pf, pf_2, ...; default 0). For the tangential
    /// model, the signal residual ζ.
    #[arg(long)]
    pub signal_momentum: Option<PathBuf>,
    /// Model configuration (TOML; see fshape_match::Config).
    #[arg(long)]
    pub config: PathBuf,
    /// Output directory (created if needed).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub times: crate::args::Times,
    /// Vertex property of SOURCE to read as the signal.
    #[arg(long)]
    pub signal_name: Option<String>,
}

pub fn run(a: Args) -> Result<()> {
    shoot(&ShootArgs {
        source: &a.source,
        momentum: &a.momentum,
        signal_momentum: a.signal_momentum.as_deref(),
        config: &a.config,
        out: &a.out,
        times: &a.times.times,
        signal_name: a.signal_name,
    })
}

struct ShootArgs<'a> {
    source: &'a Path,
    momentum: &'a Path,
    signal_momentum: Option<&'a Path>,
    config: &'a Path,
    out: &'a Path,
    times: &'a [f64],
    signal_name: Option<String>,
}

/// The initial momenta of `--momentum` and `--signal-momentum` (0 without
/// one), checked against the template's vertices and channels.
fn momenta(a: &ShootArgs<'_>, shape: &FShape) -> Result<(Vec<f64>, Vec<f64>)> {
    let (n, dim) = (shape.n_vertices(), shape.dim());
    let p0 = io::csv::read_vectors(a.momentum, dim)?;
    if p0.len() != n * dim {
        anyhow::bail!("{}: {} rows, but {} has {n} vertices", a.momentum.display(), p0.len() / dim, a.source.display());
    }
    // Several signal channels: a column per channel (pf.csv of a match
    // of several maps).
    let k = shape.n_channels().max(1);
    let pf = match a.signal_momentum {
        Some(p) if k > 1 => {
            let v = io::csv::read_vectors(p, k)?;
            if v.len() != n * k {
                anyhow::bail!("{}: {} rows, but {} has {n} vertices", p.display(), v.len() / k, a.source.display());
            }
            v
        }
        Some(p) => {
            let v = io::read_signal(p)?.values;
            if v.len() != n {
                anyhow::bail!("{}: {} values, but {} has {n} vertices", p.display(), v.len(), a.source.display());
            }
            v
        }
        None => vec![0.0; n * k],
    };
    Ok((p0, pf))
}

fn shoot(a: &ShootArgs<'_>) -> Result<()> {
    let start = std::time::Instant::now();
    let config = crate::inputs::read_config(a.config, true)?;
    let model = config.model()?;
    if config.model.normalize {
        anyhow::bail!(
            "{}: [model] normalize = true makes the weights relative to a registration's target, and shooting \
             has none: set normalize = false (the weights are then taken as written), or shoot a registration's \
             momenta with the shoot.toml that fshape match wrote next to them",
            a.config.display()
        );
    }
    if let Some(t) = a.times.iter().find(|t| !(0.0..=1.0).contains(*t)) {
        anyhow::bail!("--times: {t} is outside [0, 1]");
    }
    let shape = load(a.source, a.signal_name.clone(), None)?;
    let (p0, pf) = momenta(a, &shape)?;
    let shot = fshape_match::ops::shoot(&shape, &model, &p0, &pf)
        .with_context(|| format!("shooting from {}", a.source.display()))?;
    // Everything is computed before anything is written.
    let (mut outputs, files) = trajectory_files(&shot.template, &shot.trajectory, a.times, a.out)?;
    let (source, config) = (a.source.display().to_string(), a.config.display().to_string());
    let summary = shot.record((&source, &config), a.times, files, start.elapsed().as_secs_f64());
    let steps = summary.steps;
    outputs.push((a.out.join("summary.json"), summary.to_json()));
    std::fs::create_dir_all(a.out).with_context(|| format!("creating {}", a.out.display()))?;
    for (path, bytes) in &outputs {
        io::write_atomic(path, bytes, false)?;
    }
    println!(
        "{}: {} steps, H from {:.6e} to {:.6e}, max displacement {:.4e}; wrote {} files to {}",
        a.source.display(),
        steps,
        summary.hamiltonian[0],
        summary.hamiltonian[steps],
        summary.final_state.max_displacement,
        outputs.len(),
        a.out.display()
    );
    Ok(())
}
