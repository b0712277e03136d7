//! Drive a registration from Rust: read two meshes and a configuration,
//! run the schedule with a progress observer and a checkpoint file
//! (resuming from it when present), and print the result.
//!
//! ```sh
//! cargo run --release -p fshape-match --example register -- SOURCE TARGET CONFIG.toml OUT_DIR
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fshape_match::{Config, Control, Iteration, Observer, Outcome, Session, StageRecord, StageSpec};
use fshape_mesh::io::{ReadOptions, read_mesh};

/// Prints one line per event; a Python callback or a GUI would do the same.
struct Log;

impl Observer for Log {
    fn stage_started(&mut self, stage: usize, stages: usize, spec: &StageSpec, done: usize) -> Control {
        println!("stage {}/{stages}: k_p = {} ({done} iterations already done)", stage + 1, spec.label);
        Control::Continue
    }
    fn iteration(&mut self, _stage: usize, it: &Iteration) -> Control {
        println!("  {:3}: J {:.6e} = H {:.4e} + γ_W A, A {:.4e}", it.iteration, it.value, it.energy, it.attachment);
        Control::Continue // Control::Stop leaves the checkpoint to resume from
    }
    fn stage_finished(&mut self, _stage: usize, record: &StageRecord) {
        println!("  {} after {} iterations", record.reason, record.iterations.len());
    }
}

fn main() -> Result<()> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let [source, target, config, out] = &args[..] else {
        anyhow::bail!("usage: register SOURCE TARGET CONFIG.toml OUT_DIR");
    };
    let source = read_mesh(source, &ReadOptions::default())?;
    let target = read_mesh(target, &ReadOptions::default())?;
    let config = Config::read(config)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let checkpoint: &Path = &out.join("checkpoint.bin");
    let mut session = Session::new(&source, &target, &config)?;
    if checkpoint.exists() {
        session = session.resume_from_file(checkpoint)?; // checked against these inputs first
    }
    let mut session = session.with_checkpoint_file(checkpoint);
    if session.run(&mut Log)? == Outcome::Interrupted {
        return Ok(());
    }
    let result = session.result()?;
    println!(
        "J {:.6e} (energy {:.4e}, attachment {:.4e}) after {} iterations, {:.1} s",
        result.energies.value, result.energies.energy, result.energies.attachment, result.iterations, result.seconds
    );
    let n = session.problem().template().n_vertices();
    println!("p0: {} values, pf: {} values, {} time steps", result.p0.len(), n, result.trajectory.steps());
    Ok(())
}
