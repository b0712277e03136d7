//! `fshape match`: the registration of fshape-match's [`Session`] with
//! the program's parts around it: arguments, a progress bar, file names,
//! renders and the summary. The session checkpoints after every accepted
//! iteration, so a run killed at any point resumes (`--resume`) to the
//! result an uninterrupted run gives, bit for bit.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use fshape_match::record::{self, MatchRecord, RunRecord};
use fshape_match::{Config, MatchError, Outcome, Session};
use fshape_mesh::FShape;
use fshape_mesh::io;
use fshape_shoot::{ModelKind, ShootError};
use fshape_varifold::VarifoldError;

use crate::plots::energy_plot;
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

/// The library says "the target shape has no signal"; the user knows it by
/// its file. (A source without a signal starts from f_0 = 0: only the
/// target's signal is compared.)
fn name_the_target(e: MatchError, target: &Path) -> anyhow::Error {
    match e {
        MatchError::Shoot(ShootError::Varifold(VarifoldError::MissingSignal { which: "target" })) => anyhow::anyhow!(
            "{}: the target has no signal, but [attachment] kernel_signal compares signals: give one with \
             --target-signal FILE (or name a PLY/VTK/GIfTI property with --signal-name), or remove kernel_signal \
             for a purely geometric match",
            target.display()
        ),
        e => e.into(),
    }
}

pub fn run_with(a: &MatchArgs<'_>) -> Result<()> {
    let config = Config::read(a.config)?;
    let source = crate::inputs::load_masked(a.source, a.signal_name.clone(), a.signals.0, &a.masking.0)?;
    let target = crate::inputs::load_masked(a.target, a.signal_name.clone(), a.signals.1, &a.masking.1)?;
    // The run's clock starts here: the setup (pre-alignment, simplified
    // stages) reports on it too.
    let mut progress = Progress::new(f64::NAN, a.stop_after, a.verbosity).labelled(a.label);
    let session = match Session::new_observed(&source, &target, &config, &mut progress) {
        Err(e @ MatchError::Kinds(_)) => bail!("{} and {}: {e}", a.source.display(), a.target.display()),
        other => other.with_context(|| format!("setting up {} -> {}", a.source.display(), a.target.display()))?,
    };
    let session =
        match crate::inputs::stage_templates(a.stage_templates, a.signal_name.clone(), session.plan().stages.len())? {
            None => session,
            Some(templates) => session.with_stage_templates(templates).context("--stage-templates")?,
        };
    let checkpoint_path = a.out.join("checkpoint.bin");
    if a.resume {
        crate::inputs::warn_if_unchecked(&checkpoint_path);
    }
    let session = if a.resume { session.resume_from_file(&checkpoint_path).context("--resume")? } else { session };
    std::fs::create_dir_all(a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut session = session.with_checkpoint_file(&checkpoint_path);
    let model = session.plan().model.clone();
    let metrics = session.plan().metrics;
    progress.set_gamma_w(model.gamma_w());
    if session.run(&mut progress).map_err(|e| name_the_target(e, a.target))? == Outcome::Interrupted {
        progress.abandon("stopped by --stop-after; continue with --resume");
        eprintln!("stopped after the requested iterations; checkpoint in {}", checkpoint_path.display());
        return Ok(());
    }
    // The checkpoint holds the time until the last stage ended; the result
    // and its files are counted from here.
    let after = Instant::now();
    let result = session.result()?;
    let (p0, pf, traj) = (&result.p0, &result.pf, &result.trajectory);
    let template = session.problem().template().clone();
    let (mut outputs, mut files) = crate::outputs::trajectory_files(&template, traj, a.times, a.out)?;
    let dim = template.dim();
    let names: &[&str] = if dim == 3 { &["p_x", "p_y", "p_z"] } else { &["p_x", "p_y"] };
    // The configuration with the weights the model used, for `fshape shoot`.
    let shoot = format!(
        "# {} with the weights fshape match used (normalize = false): shoot p0.csv and pf.csv with it.\n\n{}",
        a.config.display(),
        config.resolved(session.plan().scales.as_ref()).to_toml()
    );
    outputs.push((a.out.join("shoot.toml"), shoot.clone().into_bytes()));
    files.push("shoot.toml".into());
    outputs.push((a.out.join("p0.csv"), io::csv::vectors_text(names, p0).into_bytes()));
    files.push("p0.csv".into());
    let kind = model.kind();
    // Several signal channels: a column (and a VTK field) per channel,
    // pf, pf_2, ...
    let channels = template.n_channels().max(1);
    let pf_names: Vec<String> = (0..channels).map(|c| io::channel_name("pf", c)).collect();
    if kind != ModelKind::Lddmm {
        let name = if kind == ModelKind::Tangential { "zeta" } else { "pf" };
        let names: Vec<String> = (0..channels).map(|c| io::channel_name(name, c)).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        outputs.push((a.out.join("pf.csv"), io::csv::vectors_text(&names, pf).into_bytes()));
        files.push("pf.csv".into());
    }
    let pf_columns: Vec<Vec<f64>> =
        (0..channels).map(|c| pf.iter().skip(c).step_by(channels).copied().collect()).collect();
    let pf_fields: Vec<(&str, &[f64])> =
        pf_names.iter().zip(&pf_columns).map(|(n, c)| (n.as_str(), c.as_slice())).collect();
    let mut vtk = Vec::new();
    io::vtk::write_point_fields(&mut vtk, &template, "fshape match: initial momenta", &[("p0", p0)], &pf_fields)?;
    outputs.push((a.out.join("momenta.vtk"), vtk));
    files.push("momenta.vtk".into());
    // Renders of the geodesic at the chosen times and of the target, all
    // with one camera, framing and colour range.
    let frames: Vec<FShape> = a
        .times
        .iter()
        .map(|&t| {
            let (x, f) = traj.at(t);
            template.clone().with_points(x)?.with_signals(Some(f), channels)
        })
        .collect::<Result<_, _>>()?;
    // The target as matched (moved by [prealign] move = "target").
    let target = session.target().clone();
    let mut all: Vec<&FShape> = frames.iter().collect();
    all.push(&target);
    let view = crate::render::View::fit(&all, a.view.0, a.view.1).with_range_of(&[&frames[0], &target]);
    for (k, frame) in frames.iter().enumerate() {
        let name = format!("render_{k:03}.png");
        outputs.push((a.out.join(&name), crate::render::picture(frame, &view)?));
        files.push(name);
    }
    outputs.push((a.out.join("target.png"), crate::render::picture(&target, &view)?));
    files.push("target.png".into());
    // The source at the end of the geodesic, whatever --times asked for:
    // with target.ply, what `fshape transfer` carries values through.
    let (x, f) = traj.at(1.0);
    let mut matched_ply = Vec::new();
    io::write_to(
        &mut matched_ply,
        &template.clone().with_points(x)?.with_signals(Some(f), channels)?,
        io::Format::Ply,
        io::Encoding::Binary,
    )?;
    outputs.push((a.out.join("matched.ply"), matched_ply));
    files.push("matched.ply".into());
    let mut target_ply = Vec::new();
    io::write_to(&mut target_ply, &target, io::Format::Ply, io::Encoding::Binary)?;
    outputs.push((a.out.join("target.ply"), target_ply));
    files.push("target.ply".into());
    let (svg, png) = energy_plot(&result.stages, model.gamma_w(), "matching: objective by iteration")?;
    outputs.push((a.out.join("energy.svg"), svg.clone().into_bytes()));
    outputs.push((a.out.join("energy.png"), png));
    files.extend(["energy.svg".into(), "energy.png".into()]);
    let e = result.energies;
    let summary = MatchRecord {
        kind: record::Kind::Match,
        format: record::FORMAT,
        source: a.source.display().to_string(),
        target: a.target.display().to_string(),
        config: a.config.display().to_string(),
        model: kind.name().into(),
        norm: model.norm().name().into(),
        gamma_v: config.model.gamma_v,
        gamma_f: config.model.gamma_f,
        gamma_w: config.model.gamma_w,
        scales: session.plan().scales.clone(),
        effective_weights: [model.gamma_v(), model.gamma_f(), model.gamma_w()],
        steps: model.steps(),
        metrics,
        stages: result.stages.clone(),
        final_value: e.value,
        final_energy: e.energy,
        final_attachment: e.attachment,
        geodesic_distance: e.energy.max(0.0).sqrt(),
        hamiltonian: traj.hamiltonian.clone(),
        quality: Some(result.quality.clone()),
        quality_before: Some(result.initial_quality.clone()),
        prealign: result.alignment.clone(),
        iterations: result.iterations,
        evaluations: result.evaluations,
        seconds: result.seconds + after.elapsed().as_secs_f64(),
        files: files.iter().cloned().chain(["report.html".to_string()]).collect(),
    };
    outputs.push((a.out.join("summary.json"), summary.to_json()));
    // The page a colleague opens, from what is in memory: the states the
    // files hold, the record, the configuration and the plot (`fshape
    // report` builds the same page from the files).
    let states: Vec<(f64, FShape)> = a.times.iter().copied().zip(frames).collect();
    let page = fshape_report::registration_page(&states, &target, &summary, Some(&shoot), Some(&svg), a.view)?;
    let report = a.out.join("report.html");
    outputs.push((report.clone(), fshape_report::html(&page).into_bytes()));
    for (path, bytes) in &outputs {
        io::write_atomic(path, bytes, false)?;
    }
    println!(
        "{} -> {}: J {:.4e} after {} iterations in {} stage(s), {:.0} s",
        a.source.display(),
        a.target.display(),
        e.value,
        result.iterations,
        result.stages.len(),
        summary.seconds
    );
    if let Some(al) = &result.alignment {
        println!(
            "  prealigned    {}: rotation {:.1} deg, scale {:.3}, attachment {:.3e} -> {:.3e} (summary.json: prealign)",
            al.kind.name(),
            al.rotation_degrees,
            al.scale,
            al.attachment_before,
            al.attachment_after
        );
    }
    for line in brief(&result.initial_quality, &result.quality) {
        println!("  {line}");
    }
    println!(
        "  report        {} ({} files beside it; every figure in summary.json)",
        report.display(),
        outputs.len() - 1
    );
    Ok(())
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
