//! `report.html`: one self-contained page per run that a colleague opens
//! in a browser, offline. Every byte it needs is inside: the meshes as
//! base64 of gzip-compressed float32 arrays (inflated by the browser's
//! own DecompressionStream), the viewer (`viewer.js`, WebGL written here,
//! no library) and the style. A registration shows its geodesic (time
//! slider, play, the target beside or overlaid), the match quality, the
//! stages, the energy plot and the configuration; an atlas its template,
//! each subject and the modes as sliders; a batch its index, sortable,
//! with thumbnails linking to each row's report.
//!
//! Reports are built from the files a run writes, so `fshape report DIR`
//! gives the same page afterwards; [`registration_page`] builds a
//! registration's page from memory (the Python package's `report`). Surfaces above [`DISPLAY_VERTICES`]
//! are simplified for display (fshape-mesh's simplifier) and the page
//! says so.
//!
//! Beside the page, the pictures a run leaves ([`render`]: PNG renders of
//! meshes coloured by their signal; [`plot`]: the energy curve) and the
//! folder a registration writes ([`outputs`]).

use std::io::Write;
use std::path::{Path, PathBuf};

pub mod outputs;
pub mod plot;
pub mod render;

use base64::Engine;
use fshape_match::record::{AtlasRecord, BatchIndex, MatchRecord, Record, RecordError, RunRecord};
use fshape_match::{Quality, StageRecord};
use fshape_mesh::io::{self, ReadOptions};
use fshape_mesh::{CellKind, FShape};
use serde::Serialize;

/// What can stop a report; each names its file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReportError {
    /// A mesh of the folder could not be read.
    #[error(transparent)]
    Read(#[from] io::ReadError),
    /// The page could not be written.
    #[error(transparent)]
    Write(#[from] io::WriteError),
    /// A file is missing, unreadable or not what a run writes.
    #[error("{}: {message}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// The folder holds no `fshape match`, `atlas` or `batch` output.
    #[error("{}: not an fshape match, atlas or batch folder (no summary.json or index.json)", path.display())]
    NotAnOutput {
        /// The folder.
        path: PathBuf,
    },
    /// A run record (summary.json, index.json) could not be read.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// A surface too large to show could not be simplified for display.
    #[error("simplifying for display: {0}")]
    Simplify(#[from] fshape_mesh::SimplifyError),
    /// A shape could not be rebuilt for display or output (a state of the
    /// geodesic, a signal channel taken apart).
    #[error("building a shape to show or write: {0}")]
    Shape(#[from] fshape_mesh::ShapeError),
    /// A file's bytes could not be encoded in memory.
    #[error("encoding an output: {0}")]
    Encode(#[from] std::io::Error),
    /// A picture could not be encoded as PNG.
    #[error("encoding a PNG picture: {0}")]
    Png(#[from] png::EncodingError),
    /// A plot could not be drawn.
    #[error("plot: {0}")]
    Plot(String),
    /// A scene has no shape to show.
    #[error("{scene}: no frames to show")]
    NoFrames {
        /// The scene's name.
        scene: String,
    },
}

type Result<T> = std::result::Result<T, ReportError>;

fn file_error(path: &Path, message: impl std::fmt::Display) -> ReportError {
    ReportError::File { path: path.to_path_buf(), message: message.to_string() }
}

/// Vertices above which a surface is simplified for display.
pub const DISPLAY_VERTICES: usize = 40_000;

/// Subjects of an atlas shown one by one (as subjects.png).
const ATLAS_SUBJECTS: usize = 32;

fn gzip_base64(bytes: &[u8]) -> String {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing to memory cannot fail.
    enc.write_all(bytes).expect("in memory");
    base64::engine::general_purpose::STANDARD.encode(enc.finish().expect("in memory"))
}

fn packed_f32(values: impl Iterator<Item = f64>) -> String {
    let bytes: Vec<u8> = values.flat_map(|v| (v as f32).to_le_bytes()).collect();
    gzip_base64(&bytes)
}

/// One mesh for the viewer: cells, positions (three per vertex) and
/// signals, per frame.
#[derive(Serialize)]
struct MeshData {
    kind: &'static str,
    planar: bool,
    cells: String,
    frames: Vec<String>,
    signals: Option<Vec<String>>,
}

/// What the viewer shows at a time: a mesh whose frames the slider moves
/// through (interpolating between them), and a second mesh beside it or
/// overlaid (the target).
#[derive(Serialize)]
pub struct Scene {
    name: String,
    labels: Vec<String>,
    note: Option<String>,
    mesh: MeshData,
    companion: Option<MeshData>,
    /// What the companion is ("target", "subject").
    companion_name: String,
    range: Option<[f64; 2]>,
    /// The mesh's and the companion's frames and cells are the scene
    /// before's (another map of the same shapes): they are not repeated.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    same_geometry: bool,
}

/// `frames` (one mesh, the same cells) with the simplification applied,
/// if any: the kept vertices of the first frame and its coarse cells.
fn mesh_data(frames: &[&FShape]) -> Result<(MeshData, Option<usize>)> {
    mesh_data_within(frames, DISPLAY_VERTICES)
}

/// [`mesh_data`] with the display limit given.
fn mesh_data_within(frames: &[&FShape], limit: usize) -> Result<(MeshData, Option<usize>)> {
    let first = frames[0];
    let (cells, kept): (Vec<usize>, Option<Vec<usize>>) =
        if first.n_vertices() > limit && first.kind() == CellKind::Triangle {
            let s = first.simplified(limit)?;
            (s.shape.cells().iter().map(|&c| s.kept[c]).collect(), Some(s.kept))
        } else {
            (first.cells().to_vec(), None)
        };
    // Renumber to the kept vertices (all of them when not simplified).
    let order: Vec<usize> = kept.clone().unwrap_or_else(|| (0..first.n_vertices()).collect());
    let mut index = vec![u32::MAX; first.n_vertices()];
    for (k, &v) in order.iter().enumerate() {
        index[v] = k as u32;
    }
    let cell_bytes: Vec<u8> = cells.iter().flat_map(|&v| index[v].to_le_bytes()).collect();
    let d = first.dim();
    let mut positions = Vec::new();
    let mut signals = Vec::new();
    for f in frames {
        positions.push(packed_f32(order.iter().flat_map(|&v| {
            let p = f.point(v);
            [p[0], p[1], if d == 3 { p[2] } else { 0.0 }]
        })));
        // Several channels: the first is shown.
        if let Some(s) = f.channel(0) {
            signals.push(packed_f32(order.iter().map(|&v| s[v])));
        }
    }
    let data = MeshData {
        kind: if first.kind() == CellKind::Triangle { "triangle" } else { "segment" },
        planar: d == 2,
        cells: gzip_base64(&cell_bytes),
        frames: positions,
        signals: (signals.len() == frames.len()).then_some(signals),
    };
    Ok((data, kept.map(|k| k.len())))
}

/// A scene: `frames` under the slider (labelled), `companion` (named, as
/// "target") beside. The colour range spans the first frame's and the
/// companion's signals.
pub fn scene(name: &str, frames: &[&FShape], labels: Vec<String>, companion: Option<(&str, &FShape)>) -> Result<Scene> {
    let (companion_name, companion) = match companion {
        Some((n, c)) => (n.to_string(), Some(c)),
        None => (String::new(), None),
    };
    if frames.is_empty() {
        return Err(ReportError::NoFrames { scene: name.to_string() });
    }
    let (mesh, simplified) = mesh_data(frames)?;
    let (companion_data, companion_simplified) = match companion {
        Some(c) => {
            let (m, s) = mesh_data(&[c])?;
            (Some(m), s)
        }
        None => (None, None),
    };
    let mut notes = Vec::new();
    if let Some(k) = simplified {
        notes.push(format!(
            "shown simplified from {} to {k} vertices (the files hold every vertex)",
            frames[0].n_vertices()
        ));
    }
    if let (Some(k), Some(c)) = (companion_simplified, companion) {
        notes.push(format!("the {companion_name} is shown simplified from {} to {k} vertices", c.n_vertices()));
    }
    if frames[0].n_channels() > 1 {
        notes.push(format!(
            "the colours show the first of its {} signal channels (the files hold each)",
            frames[0].n_channels()
        ));
    }
    let values = frames[0].channel(0).into_iter().chain(companion.and_then(|c| c.channel(0))).flatten();
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    Ok(Scene {
        name: name.to_string(),
        labels,
        note: (!notes.is_empty()).then(|| format!("{}.", notes.join("; "))),
        mesh,
        companion: companion_data,
        companion_name,
        range: (lo < hi).then_some([lo, hi]),
        same_geometry: false,
    })
}

/// `s` with map `c` of its signal alone (to show one map of several).
fn one_map(s: &FShape, c: usize) -> Result<FShape> {
    Ok(s.clone().with_signal(s.channel(c))?)
}

/// A scene per map of `frames` (and of the companion), named by `name(c)`,
/// for the viewer's picker. The first holds the geometry; each other holds
/// its map only and shares the first's frames and cells, so that k maps
/// cost one geometry in the page.
fn map_scenes(
    name: impl Fn(usize) -> String,
    frames: &[&FShape],
    labels: &[String],
    companion: Option<(&str, &FShape)>,
) -> Result<Vec<Scene>> {
    let k = frames.first().map_or(1, |f| f.n_channels().max(1));
    (0..k)
        .map(|c| {
            let maps: Vec<FShape> = frames.iter().map(|f| one_map(f, c)).collect::<Result<_>>()?;
            let maps: Vec<&FShape> = maps.iter().collect();
            let other = companion.map(|(n, s)| Ok::<_, ReportError>((n, one_map(s, c)?))).transpose()?;
            let mut sc = scene(&name(c), &maps, labels.to_vec(), other.as_ref().map(|(n, s)| (*n, s)))?;
            if c > 0 {
                sc.same_geometry = true;
                for m in std::iter::once(&mut sc.mesh).chain(sc.companion.as_mut()) {
                    m.cells.clear();
                    m.frames.clear();
                }
            }
            Ok(sc)
        })
        .collect()
}

/// HTML-escaped text.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// A page: its title, a line under it, the viewer's scenes and camera,
/// and the sections below the viewer (HTML).
pub struct Page {
    /// The page's title.
    pub title: String,
    /// The line under it.
    pub subtitle: String,
    /// The camera's azimuth and elevation, degrees.
    pub view: (f64, f64),
    /// What the viewer shows (none: no viewer).
    pub scenes: Vec<Scene>,
    /// The sections below the viewer, HTML.
    pub sections: Vec<String>,
}

/// The data's JSON as the text of a script element: `<`, `>` and `&` as
/// `\u003c`, `\u003e`, `\u0026`, so that no name in it can end the
/// element (`</script>`) or swallow the next one (`<!--<script>`).
fn script_json(value: &serde_json::Value) -> String {
    let json = serde_json::to_string(value).expect("plain values");
    json.replace('<', "\\u003c").replace('>', "\\u003e").replace('&', "\\u0026")
}

/// The Content-Security-Policy source of an inline script: its SHA-256,
/// so that the page runs its own script and no other, even one a missed
/// escape let in.
fn script_hash(script: &str) -> String {
    use base64::Engine;
    use sha2::Digest;
    format!("'sha256-{}'", base64::engine::general_purpose::STANDARD.encode(sha2::Sha256::digest(script.as_bytes())))
}

/// The page's HTML. Its one script runs by its hash (no inline script
/// else can); the data is JSON in a non-running script element.
pub fn html(page: &Page) -> String {
    let data = serde_json::json!({ "scenes": page.scenes, "view": [page.view.0, page.view.1] });
    let data = script_json(&data);
    let js = concat!("\n", include_str!("viewer.js"));
    let viewer = if page.scenes.is_empty() {
        String::new()
    } else {
        concat!(
            "<section id=\"viewer\">\n",
            "<div class=\"controls\"><label>show <select id=\"scene\"></select></label>",
            "<button id=\"play\">▶ play</button><input type=\"range\" id=\"frame\" min=\"0\" max=\"0\" value=\"0\" aria-label=\"time\">",
            "<span id=\"frame-label\"></span>",
            "<select id=\"companion\" aria-label=\"the second shape\"><option value=\"beside\">beside</option>",
            "<option value=\"overlay\">overlaid</option><option value=\"hidden\">hidden</option></select></div>\n",
            "<canvas id=\"view\"></canvas>\n",
            "<div id=\"colourbar\"><span>signal</span><span id=\"lo\"></span><canvas id=\"bar\" width=\"256\" height=\"12\"></canvas><span id=\"hi\"></span>",
            "<span class=\"hint\">drag to turn, wheel to zoom, double-click to reset</span></div>\n",
            "<p class=\"note\" id=\"note\"></p><p id=\"status\">loading the 3-D view…</p>\n</section>\n"
        )
        .to_string()
    };
    format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; script-src {hash}; style-src 'unsafe-inline'; img-src data:\">\n\
         <title>{title}</title>\n<style>\n{css}</style></head>\n<body>\n<h1>{title}</h1>\n<p class=\"subtitle\">{subtitle}</p>\n{viewer}{sections}\n\
         <p class=\"subtitle\">Written by fshape {version}; every figure is also in the folder's JSON files.</p>\n\
         <script type=\"application/json\" id=\"fshape-data\">{data}</script>\n<script>{js}</script>\n</body></html>\n",
        hash = script_hash(js),
        title = escape(&page.title),
        subtitle = escape(&page.subtitle),
        css = include_str!("style.css"),
        sections = page.sections.join("\n"),
        version = env!("CARGO_PKG_VERSION"),
    )
}

/// A table: a header row and rows of cells (already HTML).
pub fn table(class: &str, header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = format!("<table class=\"{class}\"><thead><tr>");
    for h in header {
        s.push_str(&format!("<th>{}</th>", escape(h)));
    }
    s.push_str("</tr></thead><tbody>");
    for row in rows {
        s.push_str("<tr>");
        for c in row {
            s.push_str(&format!("<td>{c}</td>"));
        }
        s.push_str("</tr>");
    }
    s.push_str("</tbody></table>");
    s
}

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

/// The (time, state file) pairs of a ParaView collection, in order.
fn collection(dir: &Path) -> Result<Vec<(f64, String)>> {
    let path = dir.join("trajectory.pvd");
    let text = std::fs::read_to_string(&path).map_err(|e| file_error(&path, e))?;
    let attr = |line: &str, key: &str| -> Option<String> {
        let start = line.find(&format!("{key}=\""))? + key.len() + 2;
        Some(line[start..].split('"').next()?.to_string())
    };
    let mut out = Vec::new();
    for line in text.lines().filter(|l| l.contains("<DataSet")) {
        let (Some(t), Some(file)) = (attr(line, "timestep"), attr(line, "file")) else { continue };
        out.push((t.parse().map_err(|_| file_error(&path, format!("timestep `{t}` is not a number")))?, file));
    }
    if out.is_empty() {
        return Err(file_error(&path, "no states"));
    }
    Ok(out)
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
        format!(
            "<h2>The run</h2><p>{} model, {} signal norm; J = {:.4e} (energy {:.4e}, data term {:.4e}) after {} iterations and {} evaluations in {:.1} s.</p>{}",
            escape(&summary.model),
            escape(&summary.norm),
            summary.final_value,
            summary.final_energy,
            summary.final_attachment,
            summary.iterations,
            summary.evaluations,
            summary.seconds,
            stages_table(&summary.stages)
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

/// Which kind of run a folder holds.
pub fn write_report(dir: &Path, view: (f64, f64)) -> Result<PathBuf> {
    let page = if dir.join("index.json").exists() {
        batch_page(dir, view)?
    } else {
        if !dir.join("summary.json").exists() {
            return Err(ReportError::NotAnOutput { path: dir.to_path_buf() });
        }
        match Record::read(&dir.join("summary.json"))? {
            Record::Atlas(_) => atlas_page(dir, view)?,
            Record::Match(_) => match_page(dir, view)?,
            other => {
                return Err(ReportError::File {
                    path: dir.join("summary.json"),
                    message: format!("the record of an fshape {} run, which has no report", other.kind().name()),
                });
            }
        }
    };
    let path = dir.join("report.html");
    io::write_atomic(&path, html(&page).as_bytes(), false)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    fn unpack(b64: &str) -> Vec<u8> {
        let gz = base64::engine::general_purpose::STANDARD.decode(b64).unwrap();
        let mut bytes = Vec::new();
        flate2::read::GzDecoder::new(&gz[..]).read_to_end(&mut bytes).unwrap();
        bytes
    }

    #[test]
    fn a_large_surface_is_shown_simplified_every_frame_at_the_kept_vertices() {
        let sphere = fshape_mesh::generate::icosphere(4, 1.0); // 2562 vertices
        let f: Vec<f64> = sphere.points().chunks_exact(3).map(|p| p[2]).collect();
        let first = sphere.clone().with_signal(Some(f.clone())).unwrap();
        let grown = first.clone().with_points(sphere.points().iter().map(|x| 2.0 * x).collect()).unwrap();
        let (data, kept) = mesh_data_within(&[&first, &grown], 500).unwrap();
        let kept = kept.expect("simplified");
        assert!((400..=600).contains(&kept), "{kept}");
        let cells: Vec<u32> =
            unpack(&data.cells).chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        assert!(cells.iter().all(|&c| (c as usize) < kept));
        let floats = |b64: &str| -> Vec<f32> {
            unpack(b64).chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        };
        let (x0, x1) = (floats(&data.frames[0]), floats(&data.frames[1]));
        assert_eq!(x0.len(), 3 * kept);
        // The same vertices in both frames: the second is the first doubled,
        // each a point of the unit sphere carrying its own z.
        for (a, b) in x0.iter().zip(&x1) {
            assert_eq!(2.0 * a, *b);
        }
        let signal = floats(&data.signals.as_ref().unwrap()[0]);
        for (v, z) in signal.iter().enumerate() {
            assert_eq!(*z, x0[3 * v + 2]);
            let r: f32 = (0..3).map(|k| x0[3 * v + k].powi(2)).sum::<f32>().sqrt();
            assert!((r - 1.0).abs() < 1e-5);
        }
        // Below the limit nothing is simplified.
        let (small, none) = mesh_data_within(&[&first], 10_000).unwrap();
        assert!(none.is_none());
        assert_eq!(floats(&small.frames[0]).len(), 3 * 2562);
    }

    #[test]
    fn each_map_has_a_scene_and_the_maps_share_one_geometry() {
        let sphere = fshape_mesh::generate::icosphere(3, 1.0);
        let f: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [p[0], 10.0 * p[2]]).collect();
        let two = sphere.clone().with_signals(Some(f), 2).unwrap();
        let grown = two.clone().with_points(sphere.points().iter().map(|x| 1.5 * x).collect()).unwrap();
        let scenes =
            map_scenes(|c| format!("map {c}"), &[&two, &grown], &["a".into(), "b".into()], Some(("target", &grown)))
                .unwrap();
        assert_eq!(scenes.len(), 2);
        // The first holds the frames and cells; the second only its map.
        let (first, second) = (&scenes[0], &scenes[1]);
        assert!(!first.same_geometry && first.mesh.frames.len() == 2 && !first.mesh.cells.is_empty());
        assert!(second.same_geometry && second.mesh.frames.is_empty() && second.mesh.cells.is_empty());
        assert!(second.companion.as_ref().is_some_and(|c| c.frames.is_empty() && c.signals.is_some()));
        let floats = |b64: &str| -> Vec<f32> {
            unpack(b64).chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        };
        // Each its own map and its own colour range.
        let x = floats(&first.mesh.frames[0]);
        let m2 = floats(&second.mesh.signals.as_ref().unwrap()[0]);
        for (v, value) in m2.iter().enumerate() {
            assert_eq!(*value, (10.0 * sphere.point(v)[2]) as f32);
            assert_eq!(floats(&first.mesh.signals.as_ref().unwrap()[0])[v], x[3 * v]);
        }
        let range = |s: &Scene| s.range.unwrap();
        assert!(range(second)[1] > 5.0 * range(first)[1], "{:?} {:?}", range(first), range(second));
    }

    #[test]
    fn the_data_holds_no_markup_and_the_policy_names_the_page_script_alone() {
        let name = "</script><!--<script>&\"'>";
        let value = serde_json::json!({ "name": name });
        let text = script_json(&value);
        assert!(!text.contains(['<', '>', '&']), "{text}");
        assert_eq!(serde_json::from_str::<serde_json::Value>(&text).unwrap(), value);
        let page = html(&Page {
            title: name.into(),
            subtitle: String::new(),
            view: (0.0, 0.0),
            scenes: vec![],
            sections: vec![],
        });
        assert!(!page.contains("script-src 'unsafe-inline'"), "{page}");
        // The hash in the policy is that of the text between <script> and </script>.
        let start = page.rfind("<script>").unwrap() + "<script>".len();
        let end = page.rfind("</script>").unwrap();
        assert!(page.contains(&format!("script-src {};", script_hash(&page[start..end]))));
        // Known vector (FIPS 180-2): SHA-256("abc").
        assert_eq!(script_hash("abc"), "'sha256-ungWv48Bz+pBQUDeXa4iI7ADYaOWF3qctBD/YfIAFa0='");
    }

    #[test]
    fn escaping_keeps_text_text() {
        assert_eq!(escape("<a href=\"x\">&</a>"), "&lt;a href=&quot;x&quot;&gt;&amp;&lt;/a&gt;");
    }
}
