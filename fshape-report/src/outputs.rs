//! The folders runs leave, each computed whole before its first file is
//! written, each file written atomically: a registration's
//! ([`write_registration`]: the geodesic's states, the momenta, renders,
//! the matched and target surfaces, the energy plot, summary.json and
//! report.html), an atlas's ([`write_atlas`]), a group test's
//! ([`write_stats`]), a regression's ([`write_regression`]), a batch's
//! index ([`write_batch_index`]), and a geodesic's states as files
//! ([`trajectory_files`], which `fshape shoot` writes too).

use std::path::{Path, PathBuf};

use fshape_match::ops::regress::{RegressionLabels, RegressionRun};
use fshape_match::ops::{AtlasLabels, AtlasRun, Labels, Registration, StatsLabels, StatsRun};
use fshape_match::record::{AtlasRecord, BatchIndex, MatchRecord, RegressionRecord, RunRecord, StatsRecord};
use fshape_mesh::FShape;
use fshape_mesh::io::{self, Encoding};
use fshape_shoot::ModelKind;

use crate::ReportError;
use crate::render::{self, View};

type Result<T> = std::result::Result<T, ReportError>;

/// A file to write: its path and contents.
pub type Output = (PathBuf, Vec<u8>);

/// The states at `times` as VTK and PLY files, and a ParaView collection
/// (contents and names; nothing is written here).
pub fn trajectory_files(
    template: &FShape,
    traj: &fshape_shoot::Trajectory,
    times: &[f64],
    out: &Path,
) -> Result<(Vec<Output>, Vec<String>)> {
    let mut outputs: Vec<Output> = Vec::new();
    let mut files = Vec::new();
    let mut steps: Vec<(f64, String)> = Vec::new();
    for (k, &t) in times.iter().enumerate() {
        let (x, f) = traj.at(t);
        let state = template.clone().with_points(x)?.with_signals(Some(f), template.n_channels().max(1))?;
        for ext in ["vtk", "ply"] {
            let name = format!("state_{k:03}.{ext}");
            let format = if ext == "vtk" { io::Format::Vtk } else { io::Format::Ply };
            let mut bytes = Vec::new();
            io::write_to(&mut bytes, &state, format, Encoding::Binary)?;
            outputs.push((out.join(&name), bytes));
            files.push(name);
        }
        steps.push((t, format!("state_{k:03}.vtk")));
    }
    let entries: Vec<(f64, &str)> = steps.iter().map(|(t, f)| (*t, f.as_str())).collect();
    let pvd = io::vtk::collection(&entries);
    outputs.push((out.join("trajectory.pvd"), pvd.into_bytes()));
    files.push("trajectory.pvd".into());
    Ok((outputs, files))
}

/// Where and how a registration's folder is written.
#[derive(Clone, Copy, Debug)]
pub struct Folder<'a> {
    /// The folder (it must exist).
    pub out: &'a Path,
    /// What the record calls the inputs.
    pub labels: Labels<'a>,
    /// The times of the geodesic written as states and renders.
    pub times: &'a [f64],
    /// Azimuth and elevation of the renders and the page's camera, degrees.
    pub view: (f64, f64),
}

/// What [`write_registration`] wrote.
#[derive(Clone, Debug)]
pub struct Written {
    /// summary.json's contents.
    pub record: MatchRecord,
    /// The page.
    pub report: PathBuf,
    /// The number of files written, the page included.
    pub files: usize,
}

/// Writes the folder of a registration with a result (`None` without one):
/// the states at `folder.times` (VTK, PLY, a ParaView collection),
/// shoot.toml (the configuration with the weights used), p0.csv, pf.csv
/// (not for LDDMM), momenta.vtk, a render per state and of the target with
/// one camera and colour range, matched.ply and target.ply (what `fshape
/// transfer` carries values through), the energy plot, summary.json and
/// report.html. Everything is computed before the first file is written,
/// and each file is written atomically.
pub fn write_registration(reg: &Registration, folder: &Folder<'_>) -> Result<Option<Written>> {
    let Some(result) = &reg.result else { return Ok(None) };
    let Folder { out, labels, times, view } = *folder;
    let (p0, pf, traj) = (&result.p0, &result.pf, &result.trajectory);
    let template = &reg.template;
    let (mut outputs, mut files) = trajectory_files(template, traj, times, out)?;
    let dim = template.dim();
    let names: &[&str] = if dim == 3 { &["p_x", "p_y", "p_z"] } else { &["p_x", "p_y"] };
    // The configuration with the weights the model used, for `fshape shoot`.
    let shoot = format!(
        "# {} with the weights fshape match used (normalize = false): shoot p0.csv and pf.csv with it.\n\n{}",
        labels.config,
        reg.resolved.to_toml()
    );
    outputs.push((out.join("shoot.toml"), shoot.clone().into_bytes()));
    files.push("shoot.toml".into());
    outputs.push((out.join("p0.csv"), io::csv::vectors_text(names, p0).into_bytes()));
    files.push("p0.csv".into());
    let kind = reg.plan.model.kind();
    // Several signal channels: a column (and a VTK field) per channel,
    // pf, pf_2, ...
    let channels = template.n_channels().max(1);
    let pf_names: Vec<String> = (0..channels).map(|c| io::channel_name("pf", c)).collect();
    if kind != ModelKind::Lddmm {
        let name = if kind == ModelKind::Tangential { "zeta" } else { "pf" };
        let names: Vec<String> = (0..channels).map(|c| io::channel_name(name, c)).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        outputs.push((out.join("pf.csv"), io::csv::vectors_text(&names, pf).into_bytes()));
        files.push("pf.csv".into());
    }
    let pf_columns: Vec<Vec<f64>> =
        (0..channels).map(|c| pf.iter().skip(c).step_by(channels).copied().collect()).collect();
    let pf_fields: Vec<(&str, &[f64])> =
        pf_names.iter().zip(&pf_columns).map(|(n, c)| (n.as_str(), c.as_slice())).collect();
    let mut vtk = Vec::new();
    io::vtk::write_point_fields(&mut vtk, template, "fshape match: initial momenta", &[("p0", p0)], &pf_fields)?;
    outputs.push((out.join("momenta.vtk"), vtk));
    files.push("momenta.vtk".into());
    // Renders of the geodesic at the chosen times and of the target, all
    // with one camera, framing and colour range.
    let frames: Vec<FShape> = times
        .iter()
        .map(|&t| {
            let (x, f) = traj.at(t);
            template.clone().with_points(x)?.with_signals(Some(f), channels)
        })
        .collect::<std::result::Result<_, _>>()?;
    // The target as matched (moved by [prealign] move = "target").
    let target = &reg.target;
    let mut all: Vec<&FShape> = frames.iter().collect();
    all.push(target);
    let camera = View::fit(&all, view.0, view.1).with_range_of(&[&frames[0], target]);
    for (k, frame) in frames.iter().enumerate() {
        let name = format!("render_{k:03}.png");
        outputs.push((out.join(&name), render::picture(frame, &camera)?));
        files.push(name);
    }
    outputs.push((out.join("target.png"), render::picture(target, &camera)?));
    files.push("target.png".into());
    // Several maps: each after the first drawn the same way, in its own
    // range (render_000_2.png, …, target_2.png).
    for c in 1..template.n_channels() {
        let map = |s: &FShape| s.clone().with_signal(s.channel(c));
        let frames: Vec<FShape> = frames.iter().map(map).collect::<std::result::Result<_, _>>()?;
        let target = map(target)?;
        let mut all: Vec<&FShape> = frames.iter().collect();
        all.push(&target);
        let camera = View::fit(&all, view.0, view.1).with_range_of(&[&frames[0], &target]);
        for (k, frame) in frames.iter().enumerate() {
            let name = format!("{}.png", io::channel_name(&format!("render_{k:03}"), c));
            outputs.push((out.join(&name), render::picture(frame, &camera)?));
            files.push(name);
        }
        let name = format!("{}.png", io::channel_name("target", c));
        outputs.push((out.join(&name), render::picture(&target, &camera)?));
        files.push(name);
    }
    // The source at the end of the geodesic, whatever the times asked for:
    // with target.ply, what `fshape transfer` carries values through.
    let (x, f) = traj.at(1.0);
    let mut matched_ply = Vec::new();
    io::write_to(
        &mut matched_ply,
        &template.clone().with_points(x)?.with_signals(Some(f), channels)?,
        io::Format::Ply,
        Encoding::Binary,
    )?;
    outputs.push((out.join("matched.ply"), matched_ply));
    files.push("matched.ply".into());
    let mut target_ply = Vec::new();
    io::write_to(&mut target_ply, target, io::Format::Ply, Encoding::Binary)?;
    outputs.push((out.join("target.ply"), target_ply));
    files.push("target.ply".into());
    let gamma_w = reg.plan.model.gamma_w();
    let (svg, png) = crate::plot::energy_plot(&result.stages, gamma_w, "matching: objective by iteration")?;
    outputs.push((out.join("energy.svg"), svg.clone().into_bytes()));
    outputs.push((out.join("energy.png"), png));
    files.extend(["energy.svg".into(), "energy.png".into()]);
    files.push("report.html".into());
    let seconds = result.seconds + reg.stages_ended.elapsed().as_secs_f64();
    let Some(record) = reg.record(&labels, seconds, files) else { return Ok(None) };
    outputs.push((out.join("summary.json"), record.to_json()));
    // The page a colleague opens, from what is in memory: the states the
    // files hold, the record, the configuration and the plot (`fshape
    // report` builds the same page from the files).
    let states: Vec<(f64, FShape)> = times.iter().copied().zip(frames).collect();
    let page = crate::registration_page(&states, target, &record, Some(&shoot), Some(&svg), view)?;
    let report = out.join("report.html");
    outputs.push((report.clone(), crate::html(&page).into_bytes()));
    for (path, bytes) in &outputs {
        io::write_atomic(path, bytes, false)?;
    }
    Ok(Some(Written { record, report, files: outputs.len() }))
}

/// Where and how an atlas's folder is written.
#[derive(Clone, Copy, Debug)]
pub struct AtlasFolder<'a> {
    /// The folder.
    pub out: &'a Path,
    /// What the record calls the initial template.
    pub template: &'a str,
    /// What it calls the configuration.
    pub config: &'a str,
    /// What it calls each subject (its file).
    pub subjects: &'a [String],
    /// Azimuth and elevation of the pictures and the page's camera, degrees.
    pub view: (f64, f64),
}

/// What [`write_atlas`] wrote.
#[derive(Clone, Debug)]
pub struct AtlasWritten {
    /// summary.json's contents.
    pub record: AtlasRecord,
    /// The page.
    pub report: PathBuf,
    /// The number of files written, the page included.
    pub files: usize,
}

/// Writes the folder of an atlas with a result (`None` without one): the
/// template (PLY, VTK) and the initial one, per subject its momenta, the
/// template shot onto it and the subject as the atlas saw it
/// (`subject_NNN/`), momenta.csv (a row per subject), the principal modes
/// (pca.csv, the template at ±2 standard deviations), the pictures
/// (template, subjects beside their matched templates, modes), the energy
/// plot, summary.json and report.html.
pub fn write_atlas(run: &AtlasRun, folder: &AtlasFolder<'_>) -> Result<Option<AtlasWritten>> {
    let Some(result) = &run.result else { return Ok(None) };
    let AtlasFolder { out, view, .. } = *folder;
    let model = &run.plan.model;
    let mut outputs: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    let mut files: Vec<String> = Vec::new();
    let mut push = |name: String, bytes: Vec<u8>| {
        outputs.push((out.join(&name), bytes));
        files.push(name);
    };
    let ply = |shape: &FShape| -> Result<Vec<u8>> {
        let mut bytes = Vec::new();
        io::write_to(&mut bytes, shape, io::Format::Ply, Encoding::Binary)?;
        Ok(bytes)
    };
    push("template.ply".into(), ply(&result.template)?);
    let mut bytes = Vec::new();
    io::write_to(&mut bytes, &result.template, io::Format::Vtk, Encoding::Binary)?;
    push("template.vtk".into(), bytes);
    push("template_start.ply".into(), ply(&run.start)?);
    let dim = result.template.dim();
    let kind = model.kind();
    let names: &[&str] = if dim == 3 { &["p_x", "p_y", "p_z"] } else { &["p_x", "p_y"] };
    // Several maps: p^f's columns pf, pf_2, … (vertex v's pf_{v},
    // pf_2_{v}, … in momenta.csv), as a registration writes them.
    let channels = result.template.n_channels().max(1);
    let pf_names: Vec<String> = (0..channels).map(|c| io::channel_name("pf", c)).collect();
    // One row per subject: p_0 (vertex by vertex), then p^f (or ζ).
    let mut header: Vec<String> = vec!["subject".into()];
    for v in 0..result.template.n_vertices() {
        header.extend(names.iter().map(|n| format!("{n}_{v}")));
    }
    if kind != ModelKind::Lddmm {
        for v in 0..result.template.n_vertices() {
            header.extend(pf_names.iter().map(|n| format!("{n}_{v}")));
        }
    }
    let mut table = header.join(",") + "\n";
    for (i, (s, (seen, matched))) in result.subjects.iter().zip(&run.subjects).enumerate() {
        let dir = fshape_match::ops::subject_directory(i);
        push(format!("{dir}/p0.csv"), io::csv::vectors_text(names, &s.p0).into_bytes());
        if kind != ModelKind::Lddmm {
            let name = if kind == ModelKind::Tangential { "zeta" } else { "pf" };
            let columns: Vec<String> = (0..channels).map(|c| io::channel_name(name, c)).collect();
            let columns: Vec<&str> = columns.iter().map(String::as_str).collect();
            push(format!("{dir}/pf.csv"), io::csv::vectors_text(&columns, &s.pf).into_bytes());
        }
        push(format!("{dir}/matched.ply"), ply(matched)?);
        push(format!("{dir}/subject.ply"), ply(seen)?);
        let row: Vec<String> = std::iter::once(i.to_string())
            .chain(
                s.p0.iter().chain(if kind == ModelKind::Lddmm { &[][..] } else { &s.pf[..] }).map(|v| format!("{v:e}")),
            )
            .collect();
        table.push_str(&(row.join(",") + "\n"));
    }
    push("momenta.csv".into(), table.into_bytes());
    // Pictures: the template, and a grid of each subject (left, as the
    // atlas saw it) next to the template shot onto it (right), all with
    // one camera and colour range.
    let mut all: Vec<&FShape> = run.subjects.iter().map(|(seen, _)| seen).collect();
    all.push(&result.template);
    all.push(&run.start);
    let camera = View::fit(&all, view.0, view.1);
    push("template.png".into(), render::picture(&result.template, &camera)?);
    push("template_start.png".into(), render::picture(&run.start, &camera)?);
    // Several maps: each after the first in a picture of its own
    // (template_2.png, …), in its range over the subjects and templates.
    for c in 1..result.template.n_channels() {
        let map = |s: &FShape| s.clone().with_signal(s.channel(c));
        let shapes: Vec<FShape> = all.iter().map(|s| map(s)).collect::<std::result::Result<_, _>>()?;
        let refs: Vec<&FShape> = shapes.iter().collect();
        let view = View::fit(&refs, view.0, view.1);
        push(format!("{}.png", io::channel_name("template", c)), render::picture(&map(&result.template)?, &view)?);
    }
    // Each subject beside its matched template at a quarter of the render
    // size, GRID_PAIRS pairs a row.
    let tiles: Vec<&FShape> = run.subjects.iter().take(GRID_ROWS * GRID_PAIRS).flat_map(|(s, m)| [s, m]).collect();
    let (grid, width, height) =
        render::mosaic(tiles.iter().map(|shape| render::rasterise(shape, &camera)), 2 * GRID_PAIRS, 4);
    push("subjects.png".into(), render::png_sized(&grid, width, height)?);
    // The population's main modes of variation: principal components of
    // the initial momenta in the energy metric, the template shot to ±2
    // standard deviations along each.
    let mut mode_rows: Vec<&[FShape; 3]> = Vec::new();
    if let Some((pca, shapes)) = &run.modes {
        let mut scores = std::iter::once("subject".to_string())
            .chain((0..pca.modes.len()).map(|k| format!("mode_{}", k + 1)))
            .collect::<Vec<_>>()
            .join(",")
            + "\n";
        for (i, row) in pca.scores.iter().enumerate() {
            let cells: Vec<String> =
                std::iter::once(i.to_string()).chain(row.iter().map(|v| format!("{v:e}"))).collect();
            scores.push_str(&(cells.join(",") + "\n"));
        }
        push("pca.csv".into(), scores.into_bytes());
        for (k, row) in shapes.iter().enumerate() {
            for (c, shape) in [("minus2sd", &row[0]), ("plus2sd", &row[2])] {
                push(format!("mode_{}_{c}.ply", k + 1), ply(shape)?);
            }
            mode_rows.push(row);
        }
    }
    if !mode_rows.is_empty() {
        // A row per mode: −2, 0 and +2 standard deviations, at half size.
        let tiles: Vec<&FShape> = mode_rows.iter().flat_map(|row| row.iter()).collect();
        let (rgb, width, height) = render::mosaic(tiles.iter().map(|shape| render::rasterise(shape, &camera)), 3, 2);
        push("modes.png".into(), render::png_sized(&rgb, width, height)?);
    }
    let (svg, png) = crate::plot::energy_plot(&result.stages, model.gamma_w(), "atlas: mean objective by iteration")?;
    push("energy.svg".into(), svg.clone().into_bytes());
    push("energy.png".into(), png);
    files.push("report.html".into());
    let seconds = result.seconds + run.stages_ended.elapsed().as_secs_f64();
    let labels = AtlasLabels { template: folder.template, config: folder.config, subjects: folder.subjects };
    let Some(record) = run.record(&labels, seconds, files) else { return Ok(None) };
    outputs.push((out.join("summary.json"), record.to_json()));
    // The page a colleague opens, from what is in memory (`fshape report`
    // builds the same page from the files).
    let shapes = crate::AtlasShapes {
        template: &result.template,
        start: &run.start,
        subjects: run.subjects.iter().map(|(seen, matched)| (matched, seen)).collect(),
        modes: mode_rows.iter().map(|[minus, _, plus]| (minus, plus)).collect(),
    };
    let page = crate::atlas_page_of(&record, &shapes, Some(&svg), view)?;
    let report = out.join("report.html");
    outputs.push((report.clone(), crate::html(&page).into_bytes()));
    for (path, bytes) in &outputs {
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| io::WriteError::Io { path: parent.into(), source: e })?;
        }
        io::write_atomic(path, bytes, false)?;
    }
    Ok(Some(AtlasWritten { record, report, files: outputs.len() }))
}

/// Rows and subject pairs per row of an atlas's subjects picture.
const GRID_ROWS: usize = 8;
const GRID_PAIRS: usize = 4;

/// Writes a group test's folder (made if missing): per map its statistic,
/// effect, p and corrected p (and TFCE's two) as GIfTI, the statistic on
/// the template (PLY), its picture (every vertex above, where the
/// corrected p ≤ alpha below; TFCE's p when run), multivariate.csv and
/// summary.json. `started` is when the run began: the record's seconds
/// count the pictures. Returns the record and the number of files.
pub fn write_stats(
    run: &StatsRun,
    labels: StatsLabels<'_>,
    out: &Path,
    view: (f64, f64),
    started: std::time::Instant,
) -> Result<(StatsRecord, usize)> {
    let template = &run.template;
    let mut outputs: Vec<Output> = Vec::new();
    for (k, (map, test)) in run.maps.iter().enumerate() {
        let name = map.name();
        // In [`StatsRun::files`]' order: the GIfTI maps, the PLY, the PNG.
        let files = run.files(k);
        let arrays = run.arrays(k);
        for ((suffix, values), file) in arrays.iter().zip(&files) {
            let mut bytes = Vec::new();
            io::gifti::write_arrays(
                &mut bytes,
                &[io::gifti::signal_array(&format!("{name} {suffix}"), values)],
                io::gifti::WriteOptions::default(),
            )?;
            outputs.push((out.join(file), bytes));
        }
        let with_stat = template.clone().with_signal(Some(test.statistic.clone()))?;
        let mut ply = Vec::new();
        io::write_to(&mut ply, &with_stat, io::Format::Ply, Encoding::Binary)?;
        outputs.push((out.join(&files[arrays.len()]), ply));
        let significant = test.tfce_p_fwe.as_ref().unwrap_or(&test.p_fwe);
        let png = stats_picture(template, &test.statistic, significant, run.alpha, view)?;
        outputs.push((out.join(&files[arrays.len() + 1]), png));
    }
    let record = run.record(labels, started.elapsed().as_secs_f64());
    if let Some(m) = &record.multivariate {
        let csv = format!(
            "test,modes,statistic,p,permutations\n{},{},{:e},{},{}\n",
            m.test, m.modes, m.statistic, m.p, run.inference.permutations
        );
        outputs.push((out.join("multivariate.csv"), csv.into_bytes()));
    }
    outputs.push((out.join("summary.json"), serde_json::to_vec_pretty(&record).map_err(std::io::Error::from)?));
    std::fs::create_dir_all(out).map_err(|e| io::WriteError::Io { path: out.into(), source: e })?;
    for (path, bytes) in &outputs {
        io::write_atomic(path, bytes, false)?;
    }
    Ok((record, outputs.len()))
}

/// A statistic on the template, blue (negative) to red: above, every
/// vertex; below, only where the corrected p ≤ alpha. Surfaces in R³ are
/// seen from the camera and from behind.
fn stats_picture(template: &FShape, statistic: &[f64], p: &[f64], alpha: f64, view: (f64, f64)) -> Result<Vec<u8>> {
    let (azimuth, elevation) = view;
    let bound = statistic.iter().fold(0.0f64, |b, v| b.max(v.abs()));
    // Masked vertices stay NaN (drawn grey) in both rows.
    let shown: Vec<f64> =
        statistic.iter().zip(p).map(|(t, q)| if *q <= alpha || t.is_nan() { *t } else { 0.0 }).collect();
    let all = template.clone().with_signal(Some(statistic.to_vec()))?;
    let thresholded = template.clone().with_signal(Some(shown))?;
    let azimuths: &[f64] = if template.dim() == 3 { &[azimuth, azimuth + 180.0] } else { &[azimuth] };
    let views: Vec<View> = azimuths.iter().map(|&az| View::fit(&[template], az, elevation).diverging(bound)).collect();
    // A column per view: every vertex above, the thresholded map below.
    let tiles: Vec<(&FShape, &View)> =
        [&all, &thresholded].into_iter().flat_map(|s| views.iter().map(move |v| (s, v))).collect();
    let (rgb, width, height) =
        render::mosaic(tiles.iter().map(|(shape, view)| render::rasterise(shape, view)), views.len(), 1);
    Ok(render::png_sized(&rgb, width, height)?)
}

/// Writes a batch's index into `out`: index.csv (a row per pair, cells a
/// spreadsheet would run as formulas shown as text, since names and errors
/// come from users' files), index.json (the record) and report.html (the
/// page of every row).
pub fn write_batch_index(out: &Path, index: &BatchIndex, view: (f64, f64)) -> Result<()> {
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:e}"));
    let header = "row,line,name,source,target,status,value,attachment,mean_distance,p95_distance,target_within_1pct,\
                  signal_rms,iterations,seconds,error";
    let mut table = vec![header.split(',').map(str::to_string).collect::<Vec<_>>()];
    for e in &index.rows {
        table.push(vec![
            e.row.to_string(),
            e.line.to_string(),
            e.name.clone(),
            e.source.clone(),
            e.target.clone(),
            e.status.name().to_string(),
            opt(e.value),
            opt(e.attachment),
            opt(e.mean_distance),
            opt(e.p95_distance),
            opt(e.target_within_1pct),
            opt(e.signal_rms),
            e.iterations.map_or(String::new(), |i| i.to_string()),
            e.seconds.map_or(String::new(), |s| format!("{s:.3}")),
            e.error.clone().unwrap_or_default(),
        ]);
    }
    let csv = io::table::table_text(&table, true);
    std::fs::create_dir_all(out).map_err(|e| io::WriteError::Io { path: out.into(), source: e })?;
    io::write_atomic(&out.join("index.csv"), csv.as_bytes(), false)?;
    io::write_atomic(&out.join("index.json"), &index.to_json(), false)?;
    let page = crate::batch_page_of(out, index, view)?;
    io::write_atomic(&out.join("report.html"), crate::html(&page).as_bytes(), false)?;
    Ok(())
}

/// What [`write_regression`] wrote.
#[derive(Clone, Debug)]
pub struct RegressionWritten {
    /// summary.json's contents.
    pub record: RegressionRecord,
    /// The number of files written.
    pub files: usize,
}

/// Writes the folder of a finished regression (`None` without a result):
/// the fitted state at each visit's age (`fitted_000.ply`, `.vtk`, …, in
/// the visits' order) and at 9 evenly spaced ages (`state_000.ply`, …,
/// those not a visit's) with a ParaView collection of them all by age
/// (`trajectory.pvd`), a render of each fitted state and of each visit
/// with one camera and colour range, p0.csv, pf.csv (not for LDDMM),
/// momenta.vtk, the rates of change per unit age (rates.csv and
/// rates.vtk: the normal velocity and each map's rate at the baseline's
/// vertices), each visit (visit_000.ply, …), shoot.toml, the energy plot,
/// summary.json and report.html. Everything is
/// computed before the first file is written, each file atomically.
pub fn write_regression(
    run: &RegressionRun,
    labels: &RegressionLabels<'_>,
    out: &Path,
    view: (f64, f64),
) -> Result<Option<RegressionWritten>> {
    let Some(result) = &run.result else { return Ok(None) };
    let Some((normal, signal_rate)) = run.rates() else { return Ok(None) };
    let template = &run.baseline;
    let channels = template.n_channels().max(1);
    let traj = &result.trajectory;
    let nodes = &result.nodes;
    let mut outputs: Vec<Output> = Vec::new();
    let mut files: Vec<String> = Vec::new();
    let mut fitted = Vec::with_capacity(nodes.len());
    let mut steps: Vec<(f64, String)> = Vec::new();
    let mut between = Vec::new();
    for (i, &k) in nodes.iter().enumerate() {
        let state = template
            .clone()
            .with_points(traj.points(k).to_vec())?
            .with_signals(Some(traj.signal(k).to_vec()), channels)?;
        for (ext, format) in [("vtk", io::Format::Vtk), ("ply", io::Format::Ply)] {
            let name = format!("fitted_{i:03}.{ext}");
            let mut bytes = Vec::new();
            io::write_to(&mut bytes, &state, format, Encoding::Binary)?;
            outputs.push((out.join(&name), bytes));
            files.push(name);
        }
        steps.push((run.visits[i].age, format!("fitted_{i:03}.vtk")));
        fitted.push(state);
    }
    // Between the visits: the fit at 9 evenly spaced ages (those not a
    // visit's), state_000.ply, …, in the collection with the visits' fits.
    for k in 0..=8 {
        let age = if k == 8 { result.t1 } else { result.t0 + result.span * f64::from(k) / 8.0 };
        if run.visits.iter().any(|v| v.age == age) {
            continue;
        }
        let (x, f) = result.at_age(age);
        let state = template.clone().with_points(x)?.with_signals(Some(f), channels)?;
        let n = steps.len() - nodes.len();
        for (ext, format) in [("vtk", io::Format::Vtk), ("ply", io::Format::Ply)] {
            let name = format!("state_{n:03}.{ext}");
            let mut bytes = Vec::new();
            io::write_to(&mut bytes, &state, format, Encoding::Binary)?;
            outputs.push((out.join(&name), bytes));
            files.push(name);
        }
        steps.push((age, format!("state_{n:03}.vtk")));
        between.push(state);
    }
    steps.sort_by(|a, b| a.0.total_cmp(&b.0));
    let entries: Vec<(f64, &str)> = steps.iter().map(|(t, f)| (*t, f.as_str())).collect();
    outputs.push((out.join("trajectory.pvd"), io::vtk::collection(&entries).into_bytes()));
    files.push("trajectory.pvd".into());
    // The fitted states and the visits, one camera and colour range.
    let visits: Vec<&FShape> = run.visits.iter().map(|v| &v.shape).collect();
    let all: Vec<&FShape> = fitted.iter().chain(visits.iter().copied()).collect();
    let camera = View::fit(&all, view.0, view.1).with_range_of(&all);
    for (i, (f, v)) in fitted.iter().zip(&visits).enumerate() {
        for (name, shape) in [(format!("fitted_{i:03}.png"), f), (format!("visit_{i:03}.png"), *v)] {
            outputs.push((out.join(&name), render::picture(shape, &camera)?));
            files.push(name);
        }
        // The visit as fitted, for the report (`fshape report` reads it).
        let name = format!("visit_{i:03}.ply");
        let mut bytes = Vec::new();
        io::write_to(&mut bytes, v, io::Format::Ply, Encoding::Binary)?;
        outputs.push((out.join(&name), bytes));
        files.push(name);
    }
    let dim = template.dim();
    let names: &[&str] = if dim == 3 { &["p_x", "p_y", "p_z"] } else { &["p_x", "p_y"] };
    outputs.push((out.join("p0.csv"), io::csv::vectors_text(names, &result.p0).into_bytes()));
    files.push("p0.csv".into());
    let pf_names: Vec<String> = (0..channels).map(|c| io::channel_name("pf", c)).collect();
    let rate_names: Vec<String> = (0..channels).map(|c| io::channel_name("signal_rate", c)).collect();
    let columns = |v: &[f64]| -> Vec<Vec<f64>> {
        (0..channels).map(|c| v.iter().skip(c).step_by(channels).copied().collect()).collect()
    };
    let kind = run.plan.model.kind();
    if kind != ModelKind::Lddmm {
        let names: Vec<&str> = pf_names.iter().map(String::as_str).collect();
        outputs.push((out.join("pf.csv"), io::csv::vectors_text(&names, &result.pf).into_bytes()));
        files.push("pf.csv".into());
    }
    let pf_columns = columns(&result.pf);
    let pf_fields: Vec<(&str, &[f64])> =
        pf_names.iter().zip(&pf_columns).map(|(n, c)| (n.as_str(), c.as_slice())).collect();
    let mut vtk = Vec::new();
    io::vtk::write_point_fields(
        &mut vtk,
        template,
        "fshape regress: initial momenta",
        &[("p0", &result.p0)],
        &pf_fields,
    )?;
    outputs.push((out.join("momenta.vtk"), vtk));
    files.push("momenta.vtk".into());
    // Rates per unit age: the normal velocity (where the baseline has
    // normals) and each map's rate.
    let rate_columns = columns(&signal_rate);
    let mut rate_fields: Vec<(&str, &[f64])> = Vec::new();
    if !normal.is_empty() {
        rate_fields.push(("normal_velocity", &normal));
    }
    rate_fields.extend(rate_names.iter().zip(&rate_columns).map(|(n, c)| (n.as_str(), c.as_slice())));
    let header: Vec<&str> = rate_fields.iter().map(|(n, _)| *n).collect();
    let table: Vec<f64> = (0..template.n_vertices()).flat_map(|i| rate_fields.iter().map(move |(_, c)| c[i])).collect();
    outputs.push((out.join("rates.csv"), io::csv::vectors_text(&header, &table).into_bytes()));
    files.push("rates.csv".into());
    let mut vtk = Vec::new();
    io::vtk::write_point_fields(&mut vtk, template, "fshape regress: rates per unit age", &[], &rate_fields)?;
    outputs.push((out.join("rates.vtk"), vtk));
    files.push("rates.vtk".into());
    let shoot = format!(
        "# {} with the weights fshape regress used (normalize = false): shoot p0.csv and pf.csv with it \
         from the baseline; t = 1 is the last visit's age.\n\n{}",
        labels.config,
        run.resolved.to_toml()
    );
    outputs.push((out.join("shoot.toml"), shoot.clone().into_bytes()));
    files.push("shoot.toml".into());
    let gamma_w = run.plan.model.gamma_w();
    let (svg, png) = crate::plot::energy_plot(&result.stages, gamma_w, "regression: objective by iteration")?;
    outputs.push((out.join("energy.svg"), svg.clone().into_bytes()));
    outputs.push((out.join("energy.png"), png));
    files.extend(["energy.svg".into(), "energy.png".into(), "report.html".into()]);
    let seconds = result.seconds + run.stages_ended.elapsed().as_secs_f64();
    let Some(record) = run.record(labels, seconds, files) else { return Ok(None) };
    outputs.push((out.join("summary.json"), record.to_json()));
    let visit_shapes: Vec<FShape> = visits.iter().map(|v| (*v).clone()).collect();
    // The slider's states in age order, as the collection lists them.
    let mut states: Vec<(f64, FShape)> = run.visits.iter().map(|v| v.age).zip(fitted.iter().cloned()).collect();
    states.extend(steps.iter().filter(|(_, f)| f.starts_with("state_")).map(|(a, _)| *a).zip(between));
    states.sort_by(|a, b| a.0.total_cmp(&b.0));
    let page = crate::regression_page_of(&states, &fitted, &visit_shapes, &record, Some(&shoot), Some(&svg), view)?;
    outputs.push((out.join("report.html"), crate::html(&page).into_bytes()));
    for (path, bytes) in &outputs {
        io::write_atomic(path, bytes, false)?;
    }
    Ok(Some(RegressionWritten { record, files: outputs.len() }))
}
