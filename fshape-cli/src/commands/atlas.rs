//! `fshape atlas`: a template estimated from a population with
//! fshape-match's [`ops::estimate_atlas`], with the program's parts around it: the
//! subjects' files, a progress bar, the outputs and the summary. The atlas
//! checkpoints after every accepted iteration; `--resume` continues to the
//! bits an uninterrupted run gives.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use fshape_match::ops::{self, AtlasRequest, Checkpointing};
use fshape_match::{MatchError, Observers, Outcome, StopAfter};
use fshape_mesh::FShape;
use fshape_mesh::io;
use fshape_report::outputs::{self, AtlasFolder};

/// `fshape atlas`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The subjects' meshes (with a `signal` vertex property).
    pub subjects: Vec<PathBuf>,
    /// A list of subjects, one per line: `mesh[,signal file[,mask file]]`
    /// (a mask as for `fshape match --source-mask`; several maps as
    /// `thickness.csv;myelin.csv`, a map each, every subject the same
    /// maps), paths relative to the list (read before the positional ones).
    #[arg(long = "subjects")]
    pub list: Option<PathBuf>,
    /// The initial template (default: the first subject). Without a
    /// signal it takes the subjects' mean (vertex by vertex when they
    /// share its vertices).
    #[arg(long)]
    pub template: Option<PathBuf>,
    /// The initial template's mask (as --source-mask of `fshape match`).
    /// Without one, a template that takes the subjects' mean signal is
    /// masked where none of them has a value.
    #[arg(long)]
    pub template_mask: Option<PathBuf>,
    /// Accept NaN in signal files as missing values: each masks its
    /// vertex.
    #[arg(long)]
    pub allow_missing: bool,
    #[command(flatten)]
    pub run: crate::args::Run,
    /// Vertex property of every mesh to read as the signal.
    #[arg(long)]
    pub signal_name: Option<String>,
    #[command(flatten)]
    pub view: crate::args::View,
    /// Coarser versions of the initial template (same surface, fewer
    /// vertices; without a signal they take the template's), one per
    /// stage before the last: the coarse stages run on them and carry
    /// the template and momenta to the next.
    #[arg(long, value_delimiter = ',')]
    pub stage_templates: Vec<PathBuf>,
    #[command(flatten)]
    pub report: crate::args::Report,
}

pub fn run(a: Args) -> Result<()> {
    run_with(&AtlasArgs {
        subjects: &a.subjects,
        list: a.list.as_deref(),
        template: a.template.as_deref(),
        template_mask: a.template_mask.as_deref(),
        allow_missing: a.allow_missing,
        config: &a.run.config,
        out: &a.run.out,
        resume: a.run.resume,
        stop_after: a.run.stop_after,
        signal_name: a.signal_name,
        view: a.view.camera.pair(),
        stage_templates: &a.stage_templates,
        verbosity: a.report.verbosity(),
    })
}

/// The command's arguments.
pub struct AtlasArgs<'a> {
    /// The subjects' mesh files (after those of `--subjects`).
    pub subjects: &'a [PathBuf],
    /// A list file: one subject per line, `mesh[,signal[,mask]]`.
    pub list: Option<&'a Path>,
    /// The initial template (default: the first subject).
    pub template: Option<&'a Path>,
    /// Its mask.
    pub template_mask: Option<&'a Path>,
    /// NaN in a signal file masks its vertex.
    pub allow_missing: bool,
    pub config: &'a Path,
    pub out: &'a Path,
    pub resume: bool,
    pub stop_after: Option<usize>,
    pub signal_name: Option<String>,
    /// Azimuth and elevation of the renders, degrees.
    pub view: (f64, f64),
    /// Coarser initial templates, one per stage before the last.
    pub stage_templates: &'a [PathBuf],
    /// How the run reports its progress.
    pub verbosity: crate::args::Verbosity,
}

/// A subject's files: its mesh, its maps (none: the mesh's own signal)
/// and its mask.
struct SubjectFiles {
    mesh: PathBuf,
    signals: Vec<PathBuf>,
    mask: Option<PathBuf>,
}

/// The subjects' files: the list file's, then the positional ones.
fn subject_paths(a: &AtlasArgs<'_>) -> Result<Vec<SubjectFiles>> {
    let mut paths = Vec::new();
    if let Some(list) = a.list {
        let base = list.parent().unwrap_or(Path::new("."));
        for io::table::Record { line, fields } in io::table::read_table(list)? {
            let optional = |k: usize| fields.get(k).filter(|s| !s.is_empty()).map(|s| base.join(s));
            let mesh = match &fields[..] {
                [mesh] | [mesh, _] | [mesh, _, _] => mesh,
                _ => bail!(
                    "{}:{line}: expected `mesh[,signal[,mask]]`, found {} cells: {}",
                    list.display(),
                    fields.len(),
                    fields.join(" | ")
                ),
            };
            if mesh.is_empty() {
                bail!("{}:{line}: no mesh named (expected `mesh[,signal[,mask]]`)", list.display());
            }
            // Several maps: `a.csv;b.csv`, a channel each (as in batch's pairs).
            let signals = fields
                .get(1)
                .into_iter()
                .flat_map(|f| f.split(';'))
                .map(str::trim)
                .filter(|f| !f.is_empty())
                .map(|f| base.join(f))
                .collect();
            paths.push(SubjectFiles { mesh: base.join(mesh), signals, mask: optional(2) });
        }
    }
    paths.extend(a.subjects.iter().map(|p| SubjectFiles { mesh: p.clone(), signals: Vec::new(), mask: None }));
    if paths.is_empty() {
        bail!("no subjects: give their files, or --subjects LIST");
    }
    Ok(paths)
}

pub fn run_with(a: &AtlasArgs<'_>) -> Result<()> {
    #[cfg(feature = "mpi")]
    {
        if let Some((world, universe)) = crate::processes::init()? {
            use fshape_match::Cluster;
            let (rank, size) = (world.rank(), world.size());
            if rank == 0 {
                eprintln!("atlas over {size} processes (MPI)");
            }
            return match run_on(a, Some(Box::new(world)), rank) {
                Ok(()) => Ok(()),
                Err(e) => {
                    eprintln!("error (process {rank} of {size}): {}", crate::inputs::message(&e));
                    crate::processes::abort(&universe)
                }
            };
        }
    }
    run_on(a, None, 0)
}

/// [`run`] as process `rank` of `cluster` (none: alone).
fn run_on(a: &AtlasArgs<'_>, cluster: Option<Box<dyn fshape_match::Cluster>>, rank: usize) -> Result<()> {
    // (Under mpirun, said once: by process 0.)
    let config = crate::inputs::read_config(a.config, rank == 0)?;
    let paths = subject_paths(a)?;
    let subjects: Vec<FShape> = paths
        .iter()
        .map(|s| {
            let masking = crate::inputs::Masking { mask: s.mask.as_deref(), allow_missing: a.allow_missing };
            crate::inputs::load_masked(&s.mesh, a.signal_name.clone(), &s.signals, &masking)
        })
        .collect::<Result<_>>()?;
    let template_masking = crate::inputs::Masking { mask: a.template_mask, allow_missing: a.allow_missing };
    let (template_path, template) = match a.template {
        Some(p) => (p.to_path_buf(), crate::inputs::load_masked(p, a.signal_name.clone(), &[], &template_masking)?),
        None if a.template_mask.is_some() => bail!("--template-mask needs --template (the first subject has its own)"),
        None => (paths[0].mesh.clone(), subjects[0].clone()),
    };
    let template = fshape_match::atlas::initial_template(template, &subjects)?;
    let templates = crate::inputs::stage_templates(a.stage_templates, a.signal_name.clone(), config.stage_count())?;
    let checkpoint = a.out.join("checkpoint.bin");
    if a.resume && rank == 0 {
        crate::inputs::warn_if_unchecked(&checkpoint);
    }
    // Every process reads the checkpoint it resumes from; process 0 alone
    // writes it, and the outputs.
    let checkpointing = match (a.resume, rank) {
        (true, 0) => Checkpointing::Resume(checkpoint.clone()),
        (true, _) => Checkpointing::ReadOnly(checkpoint.clone()),
        (false, 0) => Checkpointing::Start(checkpoint.clone()),
        (false, _) => Checkpointing::None,
    };
    // The run's clock starts here: the subjects' pre-alignments report on
    // it too (on process 0 only). Every process runs the same iterations,
    // so --stop-after stops them all at once; only process 0 shows them.
    let mut progress = crate::progress::Progress::new(a.verbosity);
    let mut budget = StopAfter(a.stop_after);
    let request =
        AtlasRequest { template: &template, subjects: &subjects, config: &config, modes: MODES, collect: rank == 0 };
    let observers = if rank == 0 { Observers::new().with(&mut progress) } else { Observers::new() };
    let mut observers = observers.with(&mut budget);
    let run = ops::estimate_atlas(&request, templates, &checkpointing, cluster, &mut observers);
    drop(observers);
    let run = match run {
        Ok(run) => run,
        Err(e @ MatchError::Kinds(_)) => bail!("{}: {e}", template_path.display()),
        Err(e @ (MatchError::Checkpoint { .. } | MatchError::InFile { .. })) if a.resume => {
            return Err(anyhow::Error::new(e).context("--resume"));
        }
        Err(e @ MatchError::StageTemplates(_)) => return Err(anyhow::Error::new(e).context("--stage-templates")),
        Err(e) => return Err(anyhow::Error::new(e).context(format!("the atlas of {} subjects", subjects.len()))),
    };
    if rank > 0 {
        return Ok(());
    }
    if run.outcome == Outcome::Interrupted {
        progress.abandon("stopped by --stop-after; continue with --resume");
        eprintln!("stopped after the requested iterations; checkpoint in {}", checkpoint.display());
        return Ok(());
    }
    let (template_label, config_label) = (template_path.display().to_string(), a.config.display().to_string());
    let subject_labels: Vec<String> = paths.iter().map(|p| p.mesh.display().to_string()).collect();
    let folder = AtlasFolder {
        out: a.out,
        template: &template_label,
        config: &config_label,
        subjects: &subject_labels,
        view: a.view,
    };
    progress.outputs(a.out);
    let Some(written) = outputs::write_atlas(&run, &folder)? else {
        bail!("the atlas of {} subjects ended without a result", subjects.len());
    };
    print_summary(&written);
    Ok(())
}

/// The few lines `fshape atlas` prints (summary.json has every figure).
fn print_summary(written: &outputs::AtlasWritten) {
    let summary = &written.record;
    println!(
        "atlas of {} subjects: J {:.6e} (mean energy {:.4e}, mean attachment {:.4e}) after {} iterations in {} stage(s); wrote {} files and {}",
        summary.subjects.len(),
        summary.final_value,
        summary.final_energy,
        summary.final_attachment,
        summary.iterations,
        summary.stages.len(),
        written.files - 1,
        written.report.display()
    );
    let mut signal =
        summary.mean_signal_rms.map_or(String::new(), |r| format!(", signal error {:.2}% of its range", 100.0 * r));
    for (c, r) in summary.mean_signal_rms_per_channel.iter().enumerate().skip(1) {
        if let Some(r) = r {
            signal.push_str(&format!(", map {}: {:.2}%", c + 1, 100.0 * r));
        }
    }
    let fall = summary
        .min_attachment_fall
        .map_or(String::new(), |f| format!("; every subject's data term fell by at least {:.2}%", 100.0 * f));
    println!(
        "  subjects matched from the template: mean distance {:.3}% of the diagonal (mean over subjects){signal}{fall}",
        100.0 * summary.mean_distance,
    );
}

/// Principal modes written and drawn.
const MODES: usize = 3;
