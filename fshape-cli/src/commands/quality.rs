//! `fshape quality`: how close a shape is to a target.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use crate::inputs::load_masked;

/// `fshape quality`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The shape X (e.g. a registration's state at t = 1).
    pub source: PathBuf,
    /// The target Y.
    pub target: PathBuf,
    #[command(flatten)]
    pub signals: crate::args::Signals,
    /// Print JSON for scripts.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    quality(&a.source, &a.target, &a.signals, a.json)
}

/// `fshape quality`: the match quality of one file against another.
fn quality(source: &Path, target: &Path, signals: &crate::args::Signals, json: bool) -> Result<()> {
    let (files, masking) = (signals.files(), signals.masking());
    let x = load_masked(source, signals.signal_name.clone(), files.0, &masking.0)?;
    let y = load_masked(target, signals.signal_name.clone(), files.1, &masking.1)?;
    let q = fshape_match::quality(&x, &y)
        .with_context(|| format!("the quality of {} against {}", source.display(), target.display()))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&q)?);
    } else {
        println!("{} against {}: {}", source.display(), target.display(), q.describe());
    }
    Ok(())
}
