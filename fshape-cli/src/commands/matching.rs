//! `fshape match`: the registration of fshape-match's [`ops::register`] with
//! the program's parts around it: arguments, a progress bar, file names,
//! renders and the summary. The session checkpoints after every accepted
//! iteration, so a run killed at any point resumes (`--resume`) to the
//! result an uninterrupted run gives, bit for bit.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use fshape_match::ops::{self, Checkpointing, Labels, MatchRequest};
use fshape_match::{MatchError, Observers, Outcome, StopAfter};
use fshape_report::outputs::{self, Folder};

use crate::progress::Progress;

/// `fshape match`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The template mesh (its signal, if any, is f_0; else 0).
    pub source: PathBuf,
    /// The target mesh.
    pub target: PathBuf,
    #[command(flatten)]
    pub run: crate::args::Run,
    #[command(flatten)]
    pub times: crate::args::Times,
    #[command(flatten)]
    pub signals: crate::args::Signals,
    #[command(flatten)]
    pub view: crate::args::View,
    #[command(flatten)]
    pub report: crate::args::Report,
    /// Coarser versions of SOURCE (same surface, fewer vertices, with
    /// its signal), one per stage before the last: the coarse stages
    /// run on them and carry their momenta to the next.
    #[arg(long, value_delimiter = ',')]
    pub stage_templates: Vec<PathBuf>,
}

pub fn run(a: Args) -> Result<()> {
    run_with(&MatchArgs {
        source: &a.source,
        target: &a.target,
        signals: a.signals.files(),
        masking: a.signals.masking(),
        config: &a.run.config,
        out: &a.run.out,
        resume: a.run.resume,
        stop_after: a.run.stop_after,
        signal_name: a.signals.signal_name.clone(),
        times: &a.times.times,
        view: a.view.camera.pair(),
        stage_templates: &a.stage_templates,
        verbosity: a.report.verbosity(),
        label: None,
    })
}

/// What a registration needs from the command line (the demos and
/// `fshape batch` make it too).
pub struct MatchArgs<'a> {
    pub source: &'a Path,
    pub target: &'a Path,
    /// Per-vertex signal CSVs of the source and the target.
    pub signals: (&'a [std::path::PathBuf], &'a [std::path::PathBuf]),
    /// Their masks.
    pub masking: (crate::inputs::Masking<'a>, crate::inputs::Masking<'a>),
    pub config: &'a Path,
    pub out: &'a Path,
    pub resume: bool,
    pub stop_after: Option<usize>,
    pub signal_name: Option<String>,
    pub times: &'a [f64],
    /// Azimuth and elevation of the renders, degrees.
    pub view: (f64, f64),
    /// Coarser templates of the stages before the last (empty: all stages
    /// on the source).
    pub stage_templates: &'a [std::path::PathBuf],
    /// How the run reports its progress.
    pub verbosity: crate::args::Verbosity,
    /// What starts each progress line (a batch row's name), if anything.
    pub label: Option<&'a str>,
}

pub fn run_with(a: &MatchArgs<'_>) -> Result<()> {
    // A batch row does not repeat what the batch said once.
    let config = crate::inputs::read_config(a.config, a.label.is_none())?;
    let source = crate::inputs::load_masked(a.source, a.signal_name.clone(), a.signals.0, &a.masking.0)?;
    let target = crate::inputs::load_masked(a.target, a.signal_name.clone(), a.signals.1, &a.masking.1)?;
    let stages = config.stage_count();
    let templates = crate::inputs::stage_templates(a.stage_templates, a.signal_name.clone(), stages)?;
    let checkpoint = a.out.join("checkpoint.bin");
    let checkpointing = if a.resume {
        crate::inputs::warn_if_unchecked(&checkpoint);
        Checkpointing::Resume(checkpoint.clone())
    } else {
        Checkpointing::Start(checkpoint.clone())
    };
    // The run's clock starts here: the setup (pre-alignment, simplified
    // stages) reports on it too.
    let mut progress = Progress::new(a.verbosity).labelled(a.label);
    let mut budget = StopAfter(a.stop_after);
    let request = MatchRequest { source: &source, target: &target, config: &config, result_when_stopped: false };
    let mut observers = Observers::new().with(&mut progress).with(&mut budget);
    let run = ops::register(&request, templates, &checkpointing, &mut observers);
    drop(observers);
    let reg = run.map_err(|e| failure(a, e))?;
    let pair = || format!("{} -> {}", a.source.display(), a.target.display());
    if reg.outcome == Outcome::Interrupted {
        progress.abandon("stopped by --stop-after; continue with --resume");
        eprintln!("stopped after the requested iterations; checkpoint in {}", checkpoint.display());
        return Ok(());
    }
    let (source_label, target_label, config_label) =
        (a.source.display().to_string(), a.target.display().to_string(), a.config.display().to_string());
    let folder = Folder {
        out: a.out,
        labels: Labels { source: &source_label, target: &target_label, config: &config_label },
        times: a.times,
        view: a.view,
    };
    progress.outputs(a.out);
    let Some(written) = outputs::write_registration(&reg, &folder)? else {
        bail!("{}: the run ended without a result", pair());
    };
    let summary = &written.record;
    println!(
        "{}: J {:.4e} after {} iterations in {} stage(s), {:.0} s",
        pair(),
        summary.final_value,
        summary.iterations,
        summary.stages.len(),
        summary.seconds
    );
    if let Some(al) = &summary.prealign {
        println!(
            "  prealigned    {}: rotation {:.1} deg, scale {:.3}, attachment {:.3e} -> {:.3e} (summary.json: prealign)",
            al.kind.name(),
            al.rotation_degrees,
            al.scale,
            al.attachment_before,
            al.attachment_after
        );
    }
    if let (Some(before), Some(after)) = (&summary.quality_before, &summary.quality) {
        for line in brief(before, after) {
            println!("  {line}");
        }
    }
    println!(
        "  report        {} ({} files beside it; every figure in summary.json)",
        written.report.display(),
        written.files - 1
    );
    Ok(())
}

/// A registration's error, said with the files and flags it concerns.
fn failure(a: &MatchArgs<'_>, e: MatchError) -> anyhow::Error {
    match e {
        MatchError::Kinds(_) => anyhow::anyhow!("{} and {}: {e}", a.source.display(), a.target.display()),
        // The library says "the target shape has no signal"; the user knows
        // it by its file. (A source without a signal starts from f_0 = 0:
        // only the target's signal is compared.)
        e if e.is_missing_target_signal() => anyhow::anyhow!(
            "{}: the target has no signal, but [attachment] kernel_signal compares signals: give one with \
             --target-signal FILE (or name a PLY/VTK/GIfTI property with --signal-name), or remove kernel_signal \
             for a purely geometric match",
            a.target.display()
        ),
        e @ (MatchError::Checkpoint { .. } | MatchError::InFile { .. }) if a.resume => {
            anyhow::Error::new(e).context("--resume")
        }
        e @ MatchError::StageTemplates(_) => anyhow::Error::new(e).context("--stage-templates"),
        e => anyhow::Error::new(e).context(format!("matching {} -> {}", a.source.display(), a.target.display())),
    }
}

/// How close the template was and the matched shape is, in a few lines
/// (`fshape quality` and summary.json have every figure).
pub(crate) fn brief(before: &fshape_match::Quality, after: &fshape_match::Quality) -> Vec<String> {
    let pct = |v: f64| format!("{:.3}%", 100.0 * v);
    let mut lines = vec![
        format!(
            "mean distance {} -> {} of the diagonal (95th percentile {})",
            pct(before.mean_distance),
            pct(after.mean_distance),
            pct(after.p95_distance)
        ),
        format!(
            "within 1%     {:.1}% -> {:.1}% of the target",
            100.0 * before.target_within_1pct,
            100.0 * after.target_within_1pct
        ),
    ];
    if let (Some(b), Some(e)) = (before.signal_rms, after.signal_rms) {
        lines.push(format!("signal error  {:.2}% -> {:.2}% of its range (rms)", 100.0 * b, 100.0 * e));
    }
    lines
}
