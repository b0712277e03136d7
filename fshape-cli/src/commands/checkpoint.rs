//! `fshape checkpoint`: where a run's checkpoint stands, as one line of
//! JSON (the checkpoint itself is binary, `fshape_match::Checkpoint`).

use std::path::{Path, PathBuf};

use anyhow::Result;
use fshape_match::Checkpoint;

/// Prints the checkpoint's format, finished stages, the stage under way
/// with its accepted iterations and evaluations, and the wall seconds so
/// far.
/// `fshape checkpoint`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The checkpoint file.
    pub file: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    show(&a.file)
}

fn show(path: &Path) -> Result<()> {
    let c = Checkpoint::read(path)?;
    let (iterations, evaluations) = match &c.current {
        Some(cur) => (cur.iterations.len(), cur.state.evaluations),
        None => (0, 0),
    };
    let summary = serde_json::json!({
        "format": c.format,
        "stages_done": c.done.len(),
        "stage_under_way": c.current.is_some(),
        "iterations": iterations,
        "evaluations": evaluations,
        "iterations_done": c.done.iter().map(|s| s.iterations.len()).sum::<usize>(),
        "seconds": c.seconds,
    });
    println!("{summary}");
    Ok(())
}
