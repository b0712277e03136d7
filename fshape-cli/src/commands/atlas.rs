//! `fshape atlas`: a template estimated from a population with
//! fshape-match's [`Atlas`], with the program's parts around it: the
//! subjects' files, a progress bar, the outputs and the summary. The atlas
//! checkpoints after every accepted iteration; `--resume` continues to the
//! bits an uninterrupted run gives.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use fshape_match::record::{self, AtlasRecord, ModeRecord, RunRecord, SubjectRecord};
use fshape_match::{Atlas, Config, MatchError, Outcome};
use fshape_mesh::FShape;
use fshape_mesh::io::{self, Encoding};
use fshape_shoot::ModelKind;

use fshape_report::render::{self, SIZE, View};

/// `fshape atlas`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The subjects' meshes (with a `signal` vertex property).
    pub subjects: Vec<PathBuf>,
    /// A list of subjects, one per line: `mesh[,signal file[,mask file]]`
    /// (a mask as for `fshape match --source-mask`), paths relative to the
    /// list (read before the positional ones).
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

/// A subject's files: its mesh, its signal and its mask.
struct SubjectFiles {
    mesh: PathBuf,
    signal: Option<PathBuf>,
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
            paths.push(SubjectFiles { mesh: base.join(mesh), signal: optional(1), mask: optional(2) });
        }
    }
    paths.extend(a.subjects.iter().map(|p| SubjectFiles { mesh: p.clone(), signal: None, mask: None }));
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
    let config = Config::read(a.config)?;
    let paths = subject_paths(a)?;
    let subjects: Vec<FShape> = paths
        .iter()
        .map(|s| {
            let masking = crate::inputs::Masking { mask: s.mask.as_deref(), allow_missing: a.allow_missing };
            crate::inputs::load_masked(&s.mesh, a.signal_name.clone(), s.signal.as_slice(), &masking)
        })
        .collect::<Result<_>>()?;
    let template_masking = crate::inputs::Masking { mask: a.template_mask, allow_missing: a.allow_missing };
    let (template_path, template) = match a.template {
        Some(p) => (p.to_path_buf(), crate::inputs::load_masked(p, a.signal_name.clone(), &[], &template_masking)?),
        None if a.template_mask.is_some() => bail!("--template-mask needs --template (the first subject has its own)"),
        None => (paths[0].mesh.clone(), subjects[0].clone()),
    };
    let template = fshape_match::atlas::initial_template(template, &subjects)?;
    // The run's clock starts here: the subjects' pre-alignments report on
    // it too (on process 0 only).
    let mut progress = crate::progress::Progress::new(f64::NAN, a.stop_after, a.verbosity);
    if rank > 0 {
        progress = progress.hidden();
    }
    let atlas = match Atlas::new_observed(&template, &subjects, &config, &mut progress) {
        Err(e @ MatchError::Kinds(_)) => bail!("{}: {e}", template_path.display()),
        other => other.with_context(|| format!("setting up the atlas of {} subjects", subjects.len()))?,
    };
    let atlas =
        match crate::inputs::stage_templates(a.stage_templates, a.signal_name.clone(), atlas.plan().stages.len())? {
            None => atlas,
            Some(templates) => atlas.with_stage_templates(templates).context("--stage-templates")?,
        };
    let checkpoint_path = a.out.join("checkpoint.bin");
    if a.resume {
        crate::inputs::warn_if_unchecked(&checkpoint_path);
    }
    let atlas = if a.resume { atlas.resume_from_file(&checkpoint_path).context("--resume")? } else { atlas };
    let atlas = match cluster {
        Some(c) => atlas.with_cluster(c),
        None => atlas,
    };
    let model = atlas.plan().model.clone();
    progress.set_gamma_w(model.gamma_w());
    if rank > 0 {
        // Every process runs the same iterations (so --stop-after stops
        // them all at once, counted by its hidden progress); process 0
        // writes.
        let mut atlas = atlas;
        atlas.run(&mut progress)?;
        return Ok(());
    }
    std::fs::create_dir_all(a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut atlas = atlas.with_checkpoint_file(&checkpoint_path);
    if atlas.run(&mut progress)? == Outcome::Interrupted {
        progress.abandon("stopped by --stop-after; continue with --resume");
        eprintln!("stopped after the requested iterations; checkpoint in {}", checkpoint_path.display());
        return Ok(());
    }
    let after = Instant::now();
    let result = atlas.result()?;
    let mut outputs: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    let mut files: Vec<String> = Vec::new();
    let mut push = |name: String, bytes: Vec<u8>| {
        outputs.push((a.out.join(&name), bytes));
        files.push(name);
    };
    for (name, format) in [("template.ply", io::Format::Ply), ("template.vtk", io::Format::Vtk)] {
        let mut bytes = Vec::new();
        io::write_to(&mut bytes, &result.template, format, Encoding::Binary)?;
        push(name.into(), bytes);
    }
    let mut bytes = Vec::new();
    io::write_to(&mut bytes, atlas.initial_template(), io::Format::Ply, Encoding::Binary)?;
    push("template_start.ply".into(), bytes);
    let dim = result.template.dim();
    let kind = model.kind();
    let names: &[&str] = if dim == 3 { &["p_x", "p_y", "p_z"] } else { &["p_x", "p_y"] };
    // One row per subject: p_0 (vertex by vertex), then p^f (or ζ).
    let mut header: Vec<String> = vec!["subject".into()];
    for v in 0..result.template.n_vertices() {
        header.extend(names.iter().map(|n| format!("{n}_{v}")));
    }
    if kind != ModelKind::Lddmm {
        header.extend((0..result.template.n_vertices()).map(|v| format!("pf_{v}")));
    }
    let mut table = header.join(",") + "\n";
    // Each subject as the atlas saw it (pre-aligned with [prealign]).
    let subjects: Vec<FShape> = subjects
        .iter()
        .zip(&result.subjects)
        .map(|(s, r)| r.alignment.as_ref().map_or_else(|| Ok(s.clone()), |a| a.apply(s)))
        .collect::<Result<_, _>>()?;
    let mut matched = Vec::new();
    let mut subject_summaries = Vec::new();
    for (i, (s, SubjectFiles { mesh: path, .. })) in result.subjects.iter().zip(&paths).enumerate() {
        let dir = format!("subject_{i:03}");
        push(format!("{dir}/p0.csv"), io::csv::vectors_text(names, &s.p0).into_bytes());
        if kind != ModelKind::Lddmm {
            let name = if kind == ModelKind::Tangential { "zeta" } else { "pf" };
            push(format!("{dir}/pf.csv"), io::csv::vectors_text(&[name], &s.pf).into_bytes());
        }
        let last = s.trajectory.steps();
        let end = result
            .template
            .clone()
            .with_points(s.trajectory.points(last).to_vec())?
            .with_signal(Some(s.trajectory.signal(last).to_vec()))?;
        let mut bytes = Vec::new();
        io::write_to(&mut bytes, &end, io::Format::Ply, Encoding::Binary)?;
        push(format!("{dir}/matched.ply"), bytes);
        matched.push(end);
        let mut bytes = Vec::new();
        io::write_to(&mut bytes, &subjects[i], io::Format::Ply, Encoding::Binary)?;
        push(format!("{dir}/subject.ply"), bytes);
        let row: Vec<String> = std::iter::once(i.to_string())
            .chain(
                s.p0.iter().chain(if kind == ModelKind::Lddmm { &[][..] } else { &s.pf[..] }).map(|v| format!("{v:e}")),
            )
            .collect();
        table.push_str(&(row.join(",") + "\n"));
        subject_summaries.push(SubjectRecord {
            file: path.display().to_string(),
            value: s.energies.value,
            energy: s.energies.energy,
            attachment: s.energies.attachment,
            attachment_start: s.initial_attachment,
            attachment_fall: (s.initial_attachment > 0.0).then(|| 1.0 - s.energies.attachment / s.initial_attachment),
            quality: s.quality.clone(),
            template_quality: s.template_quality.clone(),
            prealign: s.alignment.clone(),
            directory: dir,
        });
    }
    push("momenta.csv".into(), table.into_bytes());
    // Pictures: the template, and a grid of each subject (left, as the
    // atlas saw it) next to the template shot onto it (right), all with
    // one camera and colour range.
    let mut all: Vec<&FShape> = subjects.iter().collect();
    all.push(&result.template);
    all.push(atlas.initial_template());
    let view = View::fit(&all, a.view.0, a.view.1);
    push("template.png".into(), render::picture(&result.template, &view)?);
    push("template_start.png".into(), render::picture(atlas.initial_template(), &view)?);
    let pairs: Vec<(&FShape, &FShape)> = subjects.iter().zip(&matched).take(GRID_ROWS * GRID_PAIRS).collect();
    let (grid, width, height) = grid(&pairs, &view);
    push("subjects.png".into(), render::png_sized(&grid, width, height)?);
    // The population's main modes of variation: principal components of
    // the initial momenta in the energy metric, the template shot to ±2
    // standard deviations along each.
    let pca = atlas.principal_modes(&result, MODES)?;
    let mut scores = std::iter::once("subject".to_string())
        .chain((0..pca.modes.len()).map(|k| format!("mode_{}", k + 1)))
        .collect::<Vec<_>>()
        .join(",")
        + "\n";
    for (i, row) in pca.scores.iter().enumerate() {
        let cells: Vec<String> = std::iter::once(i.to_string()).chain(row.iter().map(|v| format!("{v:e}"))).collect();
        scores.push_str(&(cells.join(",") + "\n"));
    }
    push("pca.csv".into(), scores.into_bytes());
    let mut mode_rows: Vec<[FShape; 3]> = Vec::new();
    let mut mode_summaries = Vec::new();
    for (k, mode) in pca.modes.iter().enumerate() {
        let at = |c: f64| -> (Vec<f64>, Vec<f64>) {
            let p0 = pca.mean_p0.iter().zip(&mode.p0).map(|(m, e)| m + c * mode.sd * e).collect();
            let pf = pca.mean_pf.iter().zip(&mode.pf).map(|(m, e)| m + c * mode.sd * e).collect();
            (p0, pf)
        };
        let mut row = Vec::new();
        for c in [-2.0, 0.0, 2.0] {
            let (p0, pf) = at(c);
            row.push(atlas.shoot_template(&result, &p0, &pf)?);
        }
        for (c, shape) in [("minus2sd", &row[0]), ("plus2sd", &row[2])] {
            let mut bytes = Vec::new();
            io::write_to(&mut bytes, shape, io::Format::Ply, Encoding::Binary)?;
            push(format!("mode_{}_{c}.ply", k + 1), bytes);
        }
        mode_summaries.push(ModeRecord { sd: mode.sd, share: mode.share });
        mode_rows.push([row[0].clone(), row[1].clone(), row[2].clone()]);
    }
    if !mode_rows.is_empty() {
        let pairs: Vec<(&FShape, &FShape, &FShape)> = mode_rows.iter().map(|r| (&r[0], &r[1], &r[2])).collect();
        let (rgb, width, height) = mode_grid(&pairs, &view);
        push("modes.png".into(), render::png_sized(&rgb, width, height)?);
    }
    let (svg, png) =
        fshape_report::plot::energy_plot(&result.stages, model.gamma_w(), "atlas: mean objective by iteration")?;
    push("energy.svg".into(), svg.clone().into_bytes());
    push("energy.png".into(), png);
    let n = result.subjects.len() as f64;
    let mean_distance = result.subjects.iter().map(|s| s.quality.mean_distance).sum::<f64>() / n;
    let rms: Vec<f64> = result.subjects.iter().filter_map(|s| s.quality.signal_rms).collect();
    let mean_signal_rms = (rms.len() == result.subjects.len()).then(|| rms.iter().sum::<f64>() / n);
    let min_attachment_fall = result
        .subjects
        .iter()
        .filter(|s| s.initial_attachment > 0.0)
        .map(|s| 1.0 - s.energies.attachment / s.initial_attachment)
        .reduce(f64::min);
    let e = result.energies;
    let summary = AtlasRecord {
        kind: record::Kind::Atlas,
        format: record::FORMAT,
        template_start: template_path.display().to_string(),
        config: a.config.display().to_string(),
        model: kind.name().into(),
        norm: model.norm().name().into(),
        gamma_v: config.model.gamma_v,
        gamma_f: config.model.gamma_f,
        gamma_w: config.model.gamma_w,
        scales: atlas.plan().scales.clone(),
        effective_weights: [model.gamma_v(), model.gamma_f(), model.gamma_w()],
        stages: result.stages.clone(),
        final_value: e.value,
        final_energy: e.energy,
        final_attachment: e.attachment,
        subjects: subject_summaries,
        mean_distance,
        mean_signal_rms,
        min_attachment_fall,
        modes: mode_summaries,
        iterations: result.iterations,
        evaluations: result.evaluations,
        seconds: result.seconds + after.elapsed().as_secs_f64(),
        files: files.iter().cloned().chain(["report.html".to_string()]).collect(),
    };
    outputs.push((a.out.join("summary.json"), summary.to_json()));
    // The page a colleague opens, from what is in memory (`fshape report`
    // builds the same page from the files).
    let shapes = fshape_report::AtlasShapes {
        template: &result.template,
        start: atlas.initial_template(),
        subjects: matched.iter().zip(&subjects).collect(),
        modes: mode_rows.iter().map(|[minus, _, plus]| (minus, plus)).collect(),
    };
    let page = fshape_report::atlas_page_of(&summary, &shapes, Some(&svg), a.view)?;
    let report = a.out.join("report.html");
    outputs.push((report.clone(), fshape_report::html(&page).into_bytes()));
    for (path, bytes) in &outputs {
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        io::write_atomic(path, bytes, false)?;
    }
    println!(
        "atlas of {} subjects: J {:.6e} (mean energy {:.4e}, mean attachment {:.4e}) after {} iterations in {} stage(s); wrote {} files and {}",
        result.subjects.len(),
        e.value,
        e.energy,
        e.attachment,
        result.iterations,
        result.stages.len(),
        outputs.len() - 1,
        report.display()
    );
    let signal = mean_signal_rms.map_or(String::new(), |r| format!(", signal error {:.2}% of its range", 100.0 * r));
    let fall = min_attachment_fall
        .map_or(String::new(), |f| format!("; every subject's data term fell by at least {:.2}%", 100.0 * f));
    println!(
        "  subjects matched from the template: mean distance {:.3}% of the diagonal (mean over subjects){signal}{fall}",
        100.0 * mean_distance,
    );
    Ok(())
}

/// Principal modes written and drawn.
const MODES: usize = 3;

/// One row per mode: the template shot to −2, 0 and +2 standard
/// deviations, at half the render size: (RGB, width, height).
fn mode_grid(rows: &[(&FShape, &FShape, &FShape)], view: &View) -> (Vec<u8>, u32, u32) {
    let tile = SIZE / 2;
    let (width, height) = (3 * tile, rows.len() * tile);
    let mut rgb = vec![255u8; width * height * 3];
    for (r, (a, b, c)) in rows.iter().enumerate() {
        for (col, shape) in [a, b, c].iter().enumerate() {
            let full = render::rasterise(shape, view);
            for y in 0..tile {
                for x in 0..tile {
                    let dst = ((r * tile + y) * width + col * tile + x) * 3;
                    for ch in 0..3 {
                        let sum: usize =
                            (0..4).map(|b| usize::from(full[((2 * y + b / 2) * SIZE + 2 * x + b % 2) * 3 + ch])).sum();
                        rgb[dst + ch] = (sum / 4) as u8;
                    }
                }
            }
        }
    }
    (rgb, width as u32, height as u32)
}

/// Rows and subject pairs per row of the subjects' picture.
const GRID_ROWS: usize = 8;
const GRID_PAIRS: usize = 4;

/// Each subject next to its matched template, at a quarter of the render
/// size, `GRID_PAIRS` pairs per row: (RGB, width, height).
fn grid(pairs: &[(&FShape, &FShape)], view: &View) -> (Vec<u8>, u32, u32) {
    let tile = SIZE / 4;
    let rows = pairs.len().div_ceil(GRID_PAIRS).max(1);
    let (width, height) = (2 * GRID_PAIRS * tile, rows * tile);
    let mut rgb = vec![255u8; width * height * 3];
    for (k, (subject, matched)) in pairs.iter().enumerate() {
        for (j, shape) in [subject, matched].iter().enumerate() {
            let full = render::rasterise(shape, view);
            let (col, row) = (2 * (k % GRID_PAIRS) + j, k / GRID_PAIRS);
            for y in 0..tile {
                for x in 0..tile {
                    // The mean of each 4 × 4 block.
                    let dst = ((row * tile + y) * width + col * tile + x) * 3;
                    for c in 0..3 {
                        let sum: usize =
                            (0..16).map(|b| usize::from(full[((4 * y + b / 4) * SIZE + 4 * x + b % 4) * 3 + c])).sum();
                        rgb[dst + c] = (sum / 16) as u8;
                    }
                }
            }
        }
    }
    (rgb, width as u32, height as u32)
}
