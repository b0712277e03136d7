//! `fshape regress`: fshape-match's [`regress()`] for every subject of a
//! visits table, each in its own folder, with the program's parts around
//! it: arguments, reading each visit's files, a progress bar, the outputs
//! and a few lines of results. Each subject's regression checkpoints
//! after every accepted iteration (`--resume` continues it).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use fshape_match::ops::Checkpointing;
use fshape_match::ops::regress::{self, RegressionLabels, SubjectVisits, regress};
use fshape_match::{Observers, Outcome, StopAfter, Visit};
use fshape_report::outputs;

use crate::progress::Progress;

/// `fshape regress`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The visits: a CSV table with a header naming `age` and `mesh` and,
    /// optionally, `subject`, `signal` (files separated by `;`, one per
    /// map), `mask` and `weight`; paths relative to the table.
    #[arg(long)]
    pub visits: PathBuf,
    #[command(flatten)]
    pub run: crate::args::Run,
    /// Vertex property of the meshes to read as the signal (default `signal`).
    #[arg(long)]
    pub signal_name: Option<String>,
    /// Accept NaN in signal files as missing values: each masks its vertex
    /// (HCP's maps are NaN on the medial wall).
    #[arg(long)]
    pub allow_missing: bool,
    /// Regress only this subject (as the table names it).
    #[arg(long)]
    pub subject: Option<String>,
    /// This job's share of the subjects, task I of N (the subjects in the
    /// table's order, every N-th from the I-th); under a Slurm job array,
    /// its array variables say it when this is not given.
    #[arg(long, value_parser = crate::args::shard)]
    pub shard: Option<crate::args::Shard>,
    #[command(flatten)]
    pub view: crate::args::View,
    #[command(flatten)]
    pub report: crate::args::Report,
}

pub fn run(a: Args) -> Result<()> {
    let config = crate::inputs::read_config(&a.run.config, true)?;
    let subjects = regress::read_visits(&a.visits)?;
    let table_has_subjects = subjects.len() > 1 || subjects[0].subject != "subject";
    let (shard, shards) = match a.shard {
        Some(s) => (s.index, s.count),
        None => crate::commands::batch::shard_from_env()?.unwrap_or((0, 1)),
    };
    let chosen: Vec<&SubjectVisits> = subjects
        .iter()
        .enumerate()
        .filter(|(i, s)| i % shards == shard && a.subject.as_ref().is_none_or(|name| *name == s.subject))
        .map(|(_, s)| s)
        .collect();
    if chosen.is_empty() && shards > 1 {
        eprintln!("task {shard} of {shards}: no subject of {} (it has {})", a.visits.display(), subjects.len());
        return Ok(());
    }
    if chosen.is_empty() {
        let names: Vec<&str> = subjects.iter().map(|s| s.subject.as_str()).collect();
        bail!(
            "{}: no subject `{}` (the table has {})",
            a.visits.display(),
            a.subject.unwrap_or_default(),
            names.join(", ")
        );
    }
    // A subject that fails (a file missing, a single visit) is said and
    // the others still run; the exit status is 1 if any failed.
    let mut failed = 0;
    let count = chosen.len();
    for s in chosen {
        // One subject: OUT itself; several: OUT/SUBJECT.
        let out = if table_has_subjects { a.run.out.join(&s.subject) } else { a.run.out.clone() };
        let done =
            one(&a, &config, s, &out).with_context(|| format!("subject `{}` of {}", s.subject, a.visits.display()));
        match done {
            Err(e) if count > 1 => {
                eprintln!("error: {e:#}");
                failed += 1;
            }
            other => drop(other?),
        }
    }
    if failed > 0 {
        bail!("{failed} of {count} subjects failed (each said above); the others are in {}", a.run.out.display());
    }
    Ok(())
}

/// Regresses subject `s` into `out` and prints its lines; the run, once
/// finished (`None` when stopped by `--stop-after`).
pub(crate) fn one(
    a: &Args,
    config: &fshape_match::Config,
    s: &SubjectVisits,
    out: &std::path::Path,
) -> Result<Option<regress::RegressionRun>> {
    let mut visits = Vec::with_capacity(s.visits.len());
    for row in &s.visits {
        let masking = crate::inputs::Masking { mask: row.mask.as_deref(), allow_missing: a.allow_missing };
        let shape = crate::inputs::load_masked(&row.mesh, a.signal_name.clone(), &row.signal, &masking)
            .with_context(|| format!("the visit on line {}", row.line))?;
        visits.push(Visit { age: row.age, shape, weight: row.weight });
    }
    let checkpoint = out.join("checkpoint.bin");
    let checkpointing = if a.run.resume {
        crate::inputs::warn_if_unchecked(&checkpoint);
        Checkpointing::Resume(checkpoint.clone())
    } else {
        Checkpointing::Start(checkpoint.clone())
    };
    let mut progress = Progress::new(a.report.verbosity()).labelled(Some(&s.subject));
    let mut budget = StopAfter(a.run.stop_after);
    let mut observers = Observers::new().with(&mut progress).with(&mut budget);
    let run = regress(visits, config, &checkpointing, &mut observers);
    drop(observers);
    let run = run?;
    if run.outcome == Outcome::Interrupted {
        progress.abandon("stopped by --stop-after; continue with --resume");
        eprintln!("stopped after the requested iterations; checkpoint in {}", checkpoint.display());
        return Ok(None);
    }
    progress.outputs(out);
    let files: Vec<String> = s.visits.iter().map(|v| v.mesh.display().to_string()).collect();
    let (table, config_label) = (a.visits.display().to_string(), a.run.config.display().to_string());
    let labels = RegressionLabels { subject: &s.subject, table: &table, visits: &files, config: &config_label };
    let Some(written) = outputs::write_regression(&run, &labels, out, a.view.camera.pair())? else {
        bail!("the run ended without a result");
    };
    let r = &written.record;
    println!(
        "{}: {} visits, ages {} to {}: J {:.4e} after {} iterations in {} stage(s), {:.0} s",
        s.subject,
        r.visits.len(),
        r.t0,
        r.t1,
        r.final_value,
        r.iterations,
        r.stages.len(),
        r.seconds
    );
    for v in &r.visits {
        let pct = |x: f64| format!("{:.3}%", 100.0 * x);
        let mut line = format!(
            "  age {:<8} mean distance {} -> {} of the diagonal",
            v.age,
            pct(v.quality_before.mean_distance),
            pct(v.quality.mean_distance)
        );
        if let (Some(b), Some(e)) = (v.quality_before.signal_rms, v.quality.signal_rms) {
            line.push_str(&format!(", signal error {:.2}% -> {:.2}%", 100.0 * b, 100.0 * e));
        }
        println!("{line}");
    }
    println!("  outputs       {} ({} files; rates per unit age in rates.csv)", out.display(), written.files);
    Ok(Some(run))
}
