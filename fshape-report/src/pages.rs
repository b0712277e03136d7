//! The page of each kind of run, from its folder or from memory: a
//! registration (its geodesic, quality, stages, energy and
//! configuration), an atlas (its template, subjects and modes), a
//! regression (its fit at each visit beside the visit) and a batch (its
//! index with thumbnails).

use std::path::Path;

use base64::Engine;
use fshape_match::record::{AtlasRecord, BatchIndex, MatchRecord, RegressionRecord, RunRecord};
use fshape_match::{Quality, StageRecord};
use fshape_mesh::FShape;
use fshape_mesh::io::{self, ReadOptions};

use crate::page::{Page, escape, table};
use crate::scene::{map_scenes, scene};
use crate::{Result, file_error, render};

/// Subjects of an atlas shown one by one (as subjects.png).
const ATLAS_SUBJECTS: usize = 32;

fn read(path: &Path) -> Result<FShape> {
    Ok(io::read_mesh(path, &ReadOptions::default())?)
}

fn percent(v: Option<f64>) -> String {
    v.map_or("–".into(), |x| format!("{:.3} %", 100.0 * x))
}

/// The match quality before and after, as a table (empty for a record
/// from before quality was measured).
fn quality_table(before: Option<&Quality>, after: Option<&Quality>) -> String {
    let Some(after) = after else { return String::new() };
    type Figure = fn(&Quality) -> Option<f64>;
    let figures: [(&str, Figure); 6] = [
        ("mean distance (of the target's diagonal)", |q| Some(q.mean_distance)),
        ("95th percentile distance", |q| Some(q.p95_distance)),
        ("largest distance", |q| Some(q.max_distance)),
        ("share of the target within 1 %", |q| Some(q.target_within_1pct)),
        ("signal error, rms (of the target's range)", |q| q.signal_rms),
        ("signal error, 99th percentile", |q| q.signal_p99),
    ];
    let rows: Vec<Vec<String>> = figures
        .iter()
        .filter(|(_, f)| f(after).is_some())
        .map(|(name, f)| vec![escape(name), percent(before.and_then(f)), percent(f(after))])
        .chain(after.signal_roughness.map(|r| {
            vec![
                "signal roughness (its Dirichlet seminorm over the target's)".into(),
                before.and_then(|b| b.signal_roughness).map_or("–".into(), |b| format!("{b:.3}")),
                format!("{r:.3}"),
            ]
        }))
        // Several signal channels: each one's error (the rows above are the
        // first's), on its own range.
        .chain(after.channels.iter().enumerate().skip(1).map(|(c, q)| {
            vec![
                format!("channel {}: signal error, rms (of its range)", c + 1),
                percent(before.and_then(|b| b.channels.get(c)).and_then(|b| b.signal_rms)),
                percent(q.signal_rms),
            ]
        }))
        .collect();
    table("quality", &["", "before", "after"], &rows)
}

/// The stages, one row each.
fn stages_table(stages: &[StageRecord]) -> String {
    let rows: Vec<Vec<String>> = stages
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let last = s.iterations.last().unwrap_or(&s.initial);
            vec![
                format!("{}", k + 1),
                escape(&s.kernel_geom),
                s.iterations.len().to_string(),
                format!("{:.4e}", s.initial.value),
                format!("{:.4e}", last.value),
                escape(&s.reason),
            ]
        })
        .collect();
    table("stages", &["stage", "k_p", "iterations", "J at start", "J at end", "why it ended"], &rows)
}

/// "The run": the model and norm, J and its parts at the end, the counts
/// and time, and the stages' table.
fn run_section(names: (&str, &str), j: [f64; 3], counts: (usize, usize, f64), stages: &[StageRecord]) -> String {
    format!(
        "<h2>The run</h2><p>{} model, {} signal norm; J = {:.4e} (energy {:.4e}, data term {:.4e}) after {} iterations and {} evaluations in {:.1} s.</p>{}",
        escape(names.0),
        escape(names.1),
        j[0],
        j[1],
        j[2],
        counts.0,
        counts.1,
        counts.2,
        stages_table(stages)
    )
}

/// The (time, state file) pairs of a ParaView collection, in order.
fn collection(dir: &Path) -> Result<Vec<(f64, String)>> {
    let path = dir.join("trajectory.pvd");
    let text = std::fs::read_to_string(&path).map_err(|e| file_error(&path, e))?;
    io::vtk::parse_collection(&text).map_err(|e| file_error(&path, e))
}

/// The report of an `fshape match` folder.
pub fn match_page(dir: &Path, view: (f64, f64)) -> Result<Page> {
    let summary = MatchRecord::read(&dir.join("summary.json"))?;
    let states: Vec<(f64, FShape)> = collection(dir)?
        .into_iter()
        .map(|(t, file)| read(&dir.join(file.replace(".vtk", ".ply"))).map(|s| (t, s)))
        .collect::<Result<_>>()?;
    let target = read(&dir.join("target.ply"))?;
    let config = std::fs::read_to_string(dir.join("shoot.toml")).ok();
    let energy = std::fs::read_to_string(dir.join("energy.svg")).ok();
    registration_page(&states, &target, &summary, config.as_deref(), energy.as_deref(), view)
}

/// The report of a registration from what it produced: the geodesic's
/// states (time, shape), the target as matched, its record (what
/// `fshape match` writes as summary.json), the configuration's text and
/// the energy plot (SVG), when there are.
pub fn registration_page(
    states: &[(f64, FShape)],
    target: &FShape,
    summary: &MatchRecord,
    config: Option<&str>,
    energy_svg: Option<&str>,
    view: (f64, f64),
) -> Result<Page> {
    let labels: Vec<String> = states.iter().map(|(t, _)| format!("t = {t:.2}")).collect();
    // Several signal channels: a scene per channel, chosen with the
    // viewer's scene picker.
    let k = states.first().map_or(0, |(_, s)| s.n_channels());
    let frames: Vec<&FShape> = states.iter().map(|(_, s)| s).collect();
    let scenes = if k > 1 {
        let name = |c: usize| format!("the geodesic, signal channel {} of {k}", c + 1);
        map_scenes(name, &frames, &labels, Some(("target", target)))?
    } else {
        vec![scene("the geodesic", &frames, labels, Some(("target", target)))?]
    };
    let (before, after) = (summary.quality_before.as_ref(), summary.quality.as_ref());
    let mut sections = vec![
        format!("<h2>How close it came</h2>{}", quality_table(before, after)),
        run_section(
            (&summary.model, &summary.norm),
            [summary.final_value, summary.final_energy, summary.final_attachment],
            (summary.iterations, summary.evaluations, summary.seconds),
            &summary.stages,
        ),
    ];
    if let Some(a) = &summary.prealign {
        sections.push(format!(
            "<h2>Pre-alignment</h2><p>{} ({} moved): rotation {:.2}°, scale {:.4}, data term {:.4e} → {:.4e}.</p>",
            a.kind.name(),
            a.moving.name(),
            a.rotation_degrees,
            a.scale,
            a.attachment_before,
            a.attachment_after,
        ));
    }
    if let Some(svg) = energy_svg {
        sections.push(format!("<h2>The objective by iteration</h2><div class=\"figure\">{svg}</div>"));
    }
    if let Some(config) = config {
        sections.push(format!(
            "<h2>Configuration</h2><p>As run, with the weights the model used{}.</p><pre>{}</pre>",
            if summary.config.is_empty() {
                String::new()
            } else {
                format!(" (the file given was <code>{}</code>)", escape(&summary.config))
            },
            escape(config)
        ));
    }
    Ok(Page {
        title: format!("{} → {}", summary.source, summary.target),
        subtitle: format!(
            "fshape match: mean distance {} → {} of the diagonal{}",
            percent(before.map(|q| q.mean_distance)),
            percent(after.map(|q| q.mean_distance)),
            after.and_then(|q| q.signal_rms).map_or(String::new(), |e| format!(
                ", signal error {} → {} of its range",
                percent(before.and_then(|q| q.signal_rms)),
                percent(Some(e))
            ))
        ),
        view,
        scenes,
        sections,
    })
}

/// The report of an `fshape atlas` folder.
pub fn atlas_page(dir: &Path, view: (f64, f64)) -> Result<Page> {
    let summary = AtlasRecord::read(&dir.join("summary.json"))?;
    let template = read(&dir.join("template.ply"))?;
    let start = read(&dir.join("template_start.ply"))?;
    let subjects = summary
        .subjects
        .iter()
        .take(ATLAS_SUBJECTS)
        .map(|s| {
            Ok((read(&dir.join(&s.directory).join("matched.ply"))?, read(&dir.join(&s.directory).join("subject.ply"))?))
        })
        .collect::<Result<Vec<_>>>()?;
    let modes = (1..=summary.modes.len())
        .map(|k| {
            Ok((read(&dir.join(format!("mode_{k}_minus2sd.ply")))?, read(&dir.join(format!("mode_{k}_plus2sd.ply")))?))
        })
        .collect::<Result<Vec<_>>>()?;
    let energy = std::fs::read_to_string(dir.join("energy.svg")).ok();
    let shapes = AtlasShapes {
        template: &template,
        start: &start,
        subjects: subjects.iter().map(|(m, s)| (m, s)).collect(),
        modes: modes.iter().map(|(m, p)| (m, p)).collect(),
    };
    atlas_page_of(&summary, &shapes, energy.as_deref(), view)
}

/// The shapes an atlas's report shows.
pub struct AtlasShapes<'a> {
    /// The estimated template.
    pub template: &'a FShape,
    /// The initial template.
    pub start: &'a FShape,
    /// Per subject (the first 32 are shown; more may be
    /// given): the template shot onto it and the subject as the atlas saw
    /// it.
    pub subjects: Vec<(&'a FShape, &'a FShape)>,
    /// Per mode of the record: the template shot to −2 and +2 standard
    /// deviations.
    pub modes: Vec<(&'a FShape, &'a FShape)>,
}

/// The report of an atlas from its record, its shapes and the energy plot
/// (SVG), when there is one.
pub fn atlas_page_of(
    summary: &AtlasRecord,
    shapes: &AtlasShapes<'_>,
    energy_svg: Option<&str>,
    view: (f64, f64),
) -> Result<Page> {
    let (template, start) = (shapes.template, shapes.start);
    let labels = || vec!["the initial template".to_string(), "the estimated template".to_string()];
    let maps = template.n_channels().max(1);
    // Several maps: the template in a scene per map (the viewer's picker).
    let mut scenes = if maps > 1 {
        map_scenes(|c| format!("the template, map {} of {maps}", c + 1), &[start, template], &labels(), None)?
    } else {
        vec![scene("the template", &[start, template], labels(), None)?]
    };
    let subjects = &summary.subjects;
    let mut rows = Vec::new();
    for (i, s) in subjects.iter().enumerate() {
        if let Some(&(matched, subject)) = shapes.subjects.get(i).filter(|_| i < ATLAS_SUBJECTS) {
            scenes.push(scene(
                &format!("subject {i}: the template shot onto it"),
                &[template, matched],
                vec!["the template".into(), "shot onto the subject".into()],
                Some(("subject", subject)),
            )?);
        }
        let q = &s.quality;
        let mut row = vec![
            i.to_string(),
            escape(&s.file),
            percent(Some(q.mean_distance)),
            percent(Some(q.target_within_1pct)),
            percent(q.signal_rms),
        ];
        // Several maps: each further map's error in a column of its own.
        row.extend((1..maps).map(|c| percent(q.channels.get(c).and_then(|m| m.signal_rms))));
        row.push(percent(s.attachment_fall));
        rows.push(row);
    }
    let modes = &summary.modes;
    let mut mode_rows = Vec::new();
    for (k, (m, &(minus, plus))) in modes.iter().zip(&shapes.modes).enumerate() {
        scenes.push(scene(
            &format!("mode {} (±2 standard deviations)", k + 1),
            &[minus, template, plus],
            vec!["−2 SD".into(), "the template".into(), "+2 SD".into()],
            None,
        )?);
        mode_rows.push(vec![(k + 1).to_string(), format!("{:.4e}", m.sd), percent(Some(m.share))]);
    }
    let error = |c: usize| if maps == 1 { "signal error".to_string() } else { format!("map {} error", c + 1) };
    let header: Vec<String> = ["subject", "file", "mean distance", "within 1 %"]
        .map(String::from)
        .into_iter()
        .chain((0..maps).map(error))
        .chain(["data term removed".to_string()])
        .collect();
    let mut sections = vec![format!(
        "<h2>The subjects</h2><p>How close the template shot by each subject's momenta came to it. Click a header to sort.{}</p>{}",
        if subjects.len() > ATLAS_SUBJECTS {
            format!(" The viewer shows the first {ATLAS_SUBJECTS}.")
        } else {
            String::new()
        },
        table("sortable", &header.iter().map(String::as_str).collect::<Vec<_>>(), &rows)
    )];
    if !mode_rows.is_empty() {
        sections.push(format!(
            "<h2>Modes of variation</h2><p>Principal components of the initial momenta (energy metric); the viewer shoots the template to ±2 SD along each.</p>{}",
            table("modes", &["mode", "SD", "share of the variance"], &mode_rows)
        ));
    }
    sections.push(format!(
        "<h2>The mean objective by iteration</h2>{}",
        energy_svg.map_or(String::new(), |svg| format!("<div class=\"figure\">{svg}</div>"))
    ));
    Ok(Page {
        title: format!("Atlas of {} subjects", subjects.len()),
        subtitle: format!(
            "fshape atlas: {} model; the subjects matched from the template to {} of the diagonal on average",
            escape(&summary.model),
            percent(Some(summary.mean_distance))
        ),
        view,
        scenes,
        sections,
    })
}

/// The report of an `fshape batch` folder: its index, sortable, each row
/// with a thumbnail linking to its own report.
pub fn batch_page(dir: &Path, view: (f64, f64)) -> Result<Page> {
    batch_page_of(dir, &BatchIndex::read(&dir.join("index.json"))?, view)
}

/// The report of a batch from its index; `dir` holds the rows' folders
/// (their thumbnails and reports).
pub fn batch_page_of(dir: &Path, index: &BatchIndex, view: (f64, f64)) -> Result<Page> {
    let rows = &index.rows;
    let mut cells = Vec::new();
    for r in rows {
        let name = &r.name;
        let row_dir = dir.join(name);
        // The geodesic's last picture, as a thumbnail.
        let last = (0..1000).map(|k| row_dir.join(format!("render_{k:03}.png"))).take_while(|p| p.exists()).last();
        let thumb = last.and_then(|p| thumbnail(&p)).map_or(String::new(), |png| {
            format!(
                "<a href=\"{}/report.html\"><img class=\"thumb\" alt=\"{}\" src=\"data:image/png;base64,{}\"></a>",
                escape(name),
                escape(name),
                base64::engine::general_purpose::STANDARD.encode(png)
            )
        });
        let link = if row_dir.join("report.html").exists() {
            format!("<a href=\"{}/report.html\">{}</a>", escape(name), escape(name))
        } else {
            escape(name)
        };
        cells.push(vec![
            thumb,
            link,
            r.status.name().to_string(),
            percent(r.mean_distance),
            percent(r.target_within_1pct),
            percent(r.signal_rms),
            r.value.map_or(String::new(), |v| format!("{v:.4e}")),
            r.iterations.map_or(String::new(), |i| i.to_string()),
            r.seconds.map_or(String::new(), |s| format!("{s:.1}")),
            escape(r.error.as_deref().unwrap_or("")),
        ]);
    }
    Ok(Page {
        title: format!("Batch of {} pairs", rows.len()),
        subtitle: format!(
            "fshape batch: {} done, {} failed, {} incomplete, {} pending",
            index.done, index.failed, index.incomplete, index.pending
        ),
        view,
        scenes: Vec::new(),
        sections: vec![format!(
            "<h2>The pairs</h2><p>Click a header to sort, a picture or a name to open that registration's report.</p>{}",
            table(
                "sortable",
                &[
                    "",
                    "name",
                    "status",
                    "mean distance",
                    "within 1 %",
                    "signal error",
                    "J",
                    "iterations",
                    "seconds",
                    "error"
                ],
                &cells
            )
        )],
    })
}

/// A PNG render shrunk four times (the mean of each 4 × 4 block), as PNG.
fn thumbnail(path: &Path) -> Option<Vec<u8>> {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).ok()?));
    let mut reader = decoder.read_info().ok()?;
    let mut buf = vec![0; reader.output_buffer_size()?];
    let info = reader.next_frame(&mut buf).ok()?;
    let channels = info.color_type.samples();
    let (w, h) = (info.width as usize / 4, info.height as usize / 4);
    let mut rgb = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let sum: usize = (0..16)
                    .map(|b| {
                        usize::from(
                            buf[((4 * y + b / 4) * info.width as usize + 4 * x + b % 4) * channels
                                + c.min(channels - 1)],
                        )
                    })
                    .sum();
                rgb[(y * w + x) * 3 + c] = (sum / 16) as u8;
            }
        }
    }
    render::png_sized(&rgb, w as u32, h as u32).ok()
}

/// The report of an `fshape regress` folder (one subject's).
pub fn regression_page(dir: &Path, view: (f64, f64)) -> Result<Page> {
    let summary = RegressionRecord::read(&dir.join("summary.json"))?;
    let mut fitted = Vec::with_capacity(summary.visits.len());
    let mut visits = Vec::with_capacity(summary.visits.len());
    for i in 0..summary.visits.len() {
        fitted.push(read(&dir.join(format!("fitted_{i:03}.ply")))?);
        visits.push(read(&dir.join(format!("visit_{i:03}.ply")))?);
    }
    let states: Vec<(f64, FShape)> = collection(dir)?
        .into_iter()
        .map(|(age, file)| read(&dir.join(file.replace(".vtk", ".ply"))).map(|s| (age, s)))
        .collect::<Result<_>>()?;
    let config = std::fs::read_to_string(dir.join("shoot.toml")).ok();
    let energy = std::fs::read_to_string(dir.join("energy.svg")).ok();
    regression_page_of(&states, &fitted, &visits, &summary, config.as_deref(), energy.as_deref(), view)
}

/// The report of a regression from what it produced: the fitted geodesic
/// at some ages (`states`, in age order: the visits' and others), the fit
/// at each visit's age and each visit (in the record's order), its record,
/// the configuration's text and the energy plot. The first scene is the
/// fitted geodesic under a slider over those ages (a visit's marked) with
/// the last visit beside; then a scene per visit, its fit beside it.
pub fn regression_page_of(
    states: &[(f64, FShape)],
    fitted: &[FShape],
    visits: &[FShape],
    summary: &RegressionRecord,
    config: Option<&str>,
    energy_svg: Option<&str>,
    view: (f64, f64),
) -> Result<Page> {
    let mut order: Vec<usize> = (0..summary.visits.len().min(fitted.len()).min(visits.len())).collect();
    order.sort_by(|&a, &b| summary.visits[a].age.total_cmp(&summary.visits[b].age));
    let frames: Vec<&FShape> = states.iter().map(|(_, s)| s).collect();
    let labels: Vec<String> = states
        .iter()
        .map(|(age, _)| match summary.visits.iter().position(|v| v.age == *age) {
            Some(i) => format!("age {age} (visit {})", i + 1),
            None => format!("age {age:.2}"),
        })
        .collect();
    let last = order.last().map(|&i| &visits[i]);
    let mut scenes = vec![scene("the fitted geodesic", &frames, labels, last.map(|v| ("last visit", v)))?];
    for &i in &order {
        let v = &summary.visits[i];
        let name = format!("visit {} (age {}): its fit and the visit", i + 1, v.age);
        scenes.push(scene(&name, &[&fitted[i]], vec![format!("age {}", v.age)], Some(("visit", &visits[i])))?);
    }
    let rows: Vec<Vec<String>> = order
        .iter()
        .map(|&i| {
            let v = &summary.visits[i];
            vec![
                format!("{}", i + 1),
                escape(&v.file),
                format!("{}", v.age),
                format!("{:.3}", v.time),
                format!("{}", v.weight),
                format!(
                    "{} → {}",
                    percent(Some(v.quality_before.mean_distance)),
                    percent(Some(v.quality.mean_distance))
                ),
                format!("{} → {}", percent(v.quality_before.signal_rms), percent(v.quality.signal_rms)),
            ]
        })
        .collect();
    let header =
        ["visit", "file", "age", "t", "weight", "mean distance (baseline → fit)", "signal error (baseline → fit)"];
    let mut sections = vec![
        format!(
            "<h2>How close the fit is to each visit</h2><p>Ages {} to {} are mapped onto the geodesic's t ∈ [0, 1]; \
             the baseline is the earliest visit. Distances are fractions of each visit's diagonal, signal errors of its range.</p>{}",
            summary.t0,
            summary.t1,
            table("quality", &header, &rows)
        ),
        run_section(
            (&summary.model, &summary.norm),
            [summary.final_value, summary.final_energy, summary.final_attachment],
            (summary.iterations, summary.evaluations, summary.seconds),
            &summary.stages,
        ),
    ];
    if let Some(svg) = energy_svg {
        sections.push(format!("<h2>The objective by iteration</h2><div class=\"figure\">{svg}</div>"));
    }
    if let Some(config) = config {
        sections.push(format!(
            "<h2>Configuration</h2><p>As run, with the weights the model used.</p><pre>{}</pre>",
            escape(config)
        ));
    }
    let worst = summary.visits.iter().map(|v| v.quality.mean_distance).fold(0.0, f64::max);
    Ok(Page {
        title: format!(
            "{}: {} visits",
            if summary.subject.is_empty() { "regression" } else { &summary.subject },
            summary.visits.len()
        ),
        subtitle: format!(
            "fshape regress: ages {} to {}; the fit's largest mean distance to a visit {} of its diagonal",
            summary.t0,
            summary.t1,
            percent(Some(worst))
        ),
        view,
        scenes,
        sections,
    })
}
