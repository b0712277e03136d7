//! `fshape transfer`: a map, a parcellation or a label carried through a
//! registration, from the source's vertices onto the target's or back:
//! the files read and written here, the work in [`ops::transfer`]
//! ([`fshape_match::transfer`] holds the rules).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fshape_match::ops::{self, TransferRequest, TransferValues};
use fshape_match::transfer::Carried;
use fshape_mesh::FShape;
use fshape_mesh::io::{self, ReadOptions, label::Label, parcellation::Parcellation};
use serde::Serialize;

/// `fshape transfer`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// A registration's folder: `fshape match`'s output (matched.ply and
    /// target.ply) or one subject's folder of an `fshape atlas`
    /// (subject_NNN: matched.ply and subject.ply; its source is the
    /// template).
    pub run: PathBuf,
    /// What to carry, on the vertices of the surface it comes from: a map
    /// (CSV, GIfTI, curv, MGH, or CIFTI-2 as FILE:STRUCTURE or
    /// FILE:STRUCTURE:MAP; NaN marks vertices without a value), a
    /// parcellation (.annot, .label.gii, or a CIFTI-2 .dlabel.nii as
    /// FILE:STRUCTURE or FILE:STRUCTURE:MAP) or a FreeSurfer .label.
    pub input: PathBuf,
    /// Where to write it, on the receiving surface's vertices, in the
    /// format its name says: a map as a signal file (.csv, .gii, .mgh,
    /// .mgz, or a FreeSurfer name such as lh.thickness), a parcellation
    /// as .annot, .label.gii (its keys and table kept) or .csv (a key per
    /// vertex, −1 for none), a label as .label.
    pub output: PathBuf,
    /// The surface that receives the values: `target` (from the source's
    /// vertices) or `source` (from the target's).
    #[arg(long, value_enum, default_value_t = Onto::Target)]
    pub onto: Onto,
    /// Vertices farther than this from the surface the values come from
    /// get none (NaN, or no region): a length in the meshes' units, or a
    /// percentage of the target's bounding-box diagonal.
    #[arg(long, default_value = "2%", value_name = "LENGTH|PERCENT%")]
    pub max_distance: String,
    /// A mask on the surface the values come from (as `match` takes it: a
    /// .label, FILE:REGION,REGION of a parcellation, or weights in
    /// [0, 1]): its vertices under 0.5 carry no value, as if NaN (a map)
    /// or in no region (a parcellation or a label). The registration's
    /// own mask of that surface (a medial wall, kept in matched.ply or
    /// target.ply) applies too unless --no-run-mask.
    #[arg(long, value_name = "MASK")]
    pub mask: Option<PathBuf>,
    /// Carry values from the vertices the registration masked as well
    /// (by default they carry none: their values did not count in the
    /// match, and a FreeSurfer map's 0 on the medial wall is no value).
    #[arg(long)]
    pub no_run_mask: bool,
    /// Print JSON for scripts.
    #[arg(long)]
    pub json: bool,
}

/// Which side of the registration receives the values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Onto {
    /// The target's vertices, from the source's.
    Target,
    /// The source's vertices, from the target's.
    Source,
}

/// What `transfer` did, printed for the user (and as JSON).
#[derive(Serialize)]
struct Summary {
    run: String,
    input: String,
    output: String,
    onto: Onto,
    /// map, parcellation or label.
    kind: &'static str,
    /// The distance limit in the meshes' units.
    max_distance: f64,
    /// Vertices of the giving surface that carry nothing: under 0.5 in
    /// the registration's mask (unless --no-run-mask) or in --mask.
    masked: usize,
    /// Whether the registration masked the giving surface and its mask
    /// applied.
    run_mask: bool,
    /// Vertices of the receiving surface, those beyond the limit and (a
    /// map) those whose closest cell had too few corners with a value.
    #[serde(flatten)]
    carried: Carried,
    /// Distances of the receiving vertices to the other surface, as
    /// percentages of the target's bounding-box diagonal.
    distance_median_percent: f64,
    distance_p95_percent: f64,
    distance_max_percent: f64,
}

/// The two meshes of a registration folder: the matched source (the
/// source's vertices at the end of the geodesic) and the target as
/// matched.
fn registration(run: &Path) -> Result<(FShape, FShape)> {
    let matched = run.join("matched.ply");
    if !matched.is_file() {
        if run.join("template.ply").is_file() {
            bail!(
                "{}: an atlas folder; give one subject's folder (e.g. {}) to carry between the template and that subject",
                run.display(),
                run.join("subject_000").display()
            );
        }
        bail!(
            "{}: no matched.ply here (an `fshape match` output folder, or an atlas subject's folder, holds it)",
            run.display()
        );
    }
    let target = ["target.ply", "subject.ply"].iter().map(|n| run.join(n)).find(|p| p.is_file());
    let Some(target) = target else {
        bail!("{}: matched.ply without target.ply (a match) or subject.ply (an atlas subject)", run.display());
    };
    let read = |p: &Path| io::read_mesh(p, &ReadOptions::default()).with_context(|| format!("reading {}", p.display()));
    Ok((read(&matched)?, read(&target)?))
}

/// `--max-distance`: a length, or a percentage of `diagonal`.
fn max_distance(text: &str, diagonal: f64) -> Result<f64> {
    let t = text.trim();
    let (number, percent) = match t.strip_suffix('%') {
        Some(n) => (n.trim(), true),
        None => (t, false),
    };
    let v: f64 = number.parse().ok().filter(|v: &f64| *v >= 0.0 && !v.is_nan()).with_context(|| {
        format!("--max-distance {text:?}: expected a non-negative length or a percentage such as 2%")
    })?;
    Ok(if percent { v / 100.0 * diagonal } else { v })
}

fn is_label(path: &Path) -> bool {
    let name = path.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    name.ends_with(".label") || name.ends_with(".label.gz")
}

fn is_parcellation(path: &Path) -> bool {
    let name = path.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    name.ends_with(".annot") || name.ends_with(".label.gii")
}

/// Whether a path names a CIFTI-2 label file, with or without its
/// `:STRUCTURE[:MAP]`.
fn is_dlabel(path: &Path) -> bool {
    let (file, _) = io::split_selector(path);
    let name = file.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    name.strip_suffix(".gz").unwrap_or(&name).ends_with(".dlabel.nii")
}

/// What is carried: a map (a number per vertex, interpolated), a
/// parcellation or a label (regions, never averaged).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Map,
    Parcellation,
    Label,
}

/// The input's kind, by its name and, for a GIfTI file, by its contents (a
/// NIFTI_INTENT_LABEL array is a parcellation whatever its name).
fn kind_of(input: &Path) -> Result<Kind> {
    if is_label(input) {
        return Ok(Kind::Label);
    }
    if is_parcellation(input) || is_dlabel(input) {
        return Ok(Kind::Parcellation);
    }
    let name = input.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let stem = name.strip_suffix(".gz").unwrap_or(&name);
    if stem.ends_with(".gii") && io::read_parcellation(input).is_ok() {
        return Ok(Kind::Parcellation);
    }
    Ok(Kind::Map)
}

/// The output's format must suit the input's kind (checked before any work).
fn check_output(kind: Kind, output: &Path) -> Result<()> {
    let name = output.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    match kind {
        Kind::Label if !is_label(output) => {
            bail!("{}: a label is written as a FreeSurfer .label", output.display())
        }
        Kind::Parcellation if !(name.ends_with(".annot") || name.ends_with(".label.gii") || name.ends_with(".csv")) => {
            Err(io::WriteError::UnknownParcellationFormat { path: output.into() }.into())
        }
        Kind::Map
            if is_label(output)
                || is_parcellation(output)
                || (io::SignalFormat::from_path(output) == io::SignalFormat::Csv
                    && !(name.ends_with(".csv") || name.ends_with(".csv.gz"))) =>
        {
            bail!(
                "{}: a map is written as a signal file: .csv, .gii, .mgh, .mgz or a FreeSurfer name such as lh.thickness",
                output.display()
            )
        }
        _ => Ok(()),
    }
}

/// The values to carry, read and checked against the giving surface
/// before any closest point is computed.
enum Input {
    Map { name: String, values: Vec<f64> },
    Parcellation(Parcellation),
    Label(Vec<i32>),
}

fn read_input(kind: Kind, path: &Path, n: usize, side: &str) -> Result<Input> {
    let what = || format!("{} (on the {side}'s {n} vertices)", path.display());
    let count = |found: usize| -> Result<()> {
        if found != n {
            return Err(io::ReadError::Count { path: path.to_path_buf(), found, expected: n }).with_context(what);
        }
        Ok(())
    };
    Ok(match kind {
        Kind::Label => {
            let label = io::label::read_label(path)?;
            let mask = label
                .mask(n)
                .map_err(|source| io::ReadError::Parse { path: path.to_path_buf(), source })
                .with_context(what)?;
            Input::Label(mask.iter().map(|&m| if m > 0.0 { 0 } else { -1 }).collect())
        }
        Kind::Parcellation => {
            let p = io::read_parcellation(path)?;
            count(p.keys.len())?;
            Input::Parcellation(p)
        }
        Kind::Map => {
            let column = io::read_signal_for(path, Some(n), true).with_context(what)?;
            count(column.values.len())?;
            let name = if column.name.is_empty() { "signal".to_string() } else { column.name };
            Input::Map { name, values: column.values }
        }
    })
}

/// `--mask`: which of the giving surface's vertices carry nothing (weight
/// under 0.5); weights outside [0, 1] are refused, naming the vertex.
fn read_masked(mask: Option<&Path>, n: usize, side: &str) -> Result<Vec<bool>> {
    let Some(m) = mask else { return Ok(vec![false; n]) };
    let context = || format!("--mask {} (on the {side}'s {n} vertices)", m.display());
    let w = io::read_mask(m, n).with_context(context)?;
    if let Some(v) = w.iter().position(|w| !(0.0..=1.0).contains(w)) {
        bail!("{}: vertex {v} has the weight {}; a mask's weights are in [0, 1]", context(), w[v]);
    }
    Ok(w.iter().map(|&w| w < 0.5).collect())
}

pub fn run(a: Args) -> Result<()> {
    let kind = kind_of(&a.input)?;
    check_output(kind, &a.output)?;
    let (matched, target) = registration(&a.run)?;
    let (from, onto) = match a.onto {
        Onto::Target => (&matched, &target),
        Onto::Source => (&target, &matched),
    };
    let diagonal = target.bounding_box().diagonal();
    let limit = max_distance(&a.max_distance, diagonal)?;
    let n = from.n_vertices();
    let side = if a.onto == Onto::Target { "source" } else { "target" };
    let masked = read_masked(a.mask.as_deref(), n, side)?;
    let input = read_input(kind, &a.input, n, side)?;
    let (values, regions, name) = match input {
        Input::Label(keys) => (TransferValues::Keys(keys), None, None),
        Input::Parcellation(p) => (TransferValues::Keys(p.keys), Some(p.regions), None),
        Input::Map { name, values } => (TransferValues::Map(values), None, Some(name)),
    };
    let request =
        TransferRequest { from, onto, values, masked, run_mask: !a.no_run_mask, max_distance: limit, diagonal };
    let run = ops::transfer(request).context("carrying the values between the two surfaces")?;
    let kind = match (run.values, kind) {
        (TransferValues::Keys(out), Kind::Label) => {
            let vertices: Vec<usize> = (0..out.len()).filter(|&v| out[v] == 0).collect();
            let points = vertices.iter().flat_map(|&v| point3(onto, v)).collect();
            let values = vec![0.0; vertices.len()];
            io::label::write_label(&a.output, &Label { vertices, points, values }, "fshape-transfer")?;
            "label"
        }
        (TransferValues::Keys(keys), _) => {
            io::write_parcellation(&a.output, &Parcellation { keys, regions: regions.unwrap_or_default() })?;
            "parcellation"
        }
        (TransferValues::Map(out), _) => {
            io::write_signal(&a.output, name.as_deref().unwrap_or("signal"), &out, onto.n_cells())?;
            "map"
        }
    };
    let [median, p95, max] = run.distance_percent;
    let summary = Summary {
        run: a.run.display().to_string(),
        input: a.input.display().to_string(),
        output: a.output.display().to_string(),
        onto: a.onto,
        kind,
        max_distance: limit,
        masked: run.masked,
        run_mask: run.run_mask,
        carried: run.carried,
        distance_median_percent: median,
        distance_p95_percent: p95,
        distance_max_percent: max,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("{}", summary.line(side, &a.max_distance));
    }
    Ok(())
}

impl Summary {
    /// The line printed for the user: what went where, how many vertices
    /// got nothing, how far apart the surfaces are.
    fn line(&self, side: &str, max_distance: &str) -> String {
        let masked = match (self.masked, self.run_mask) {
            (0, _) => String::new(),
            (k, true) => format!(" ({k} {side} vertices masked, the registration's mask included)"),
            (k, false) => format!(" ({k} {side} vertices masked)"),
        };
        format!(
            "{} -> {}: a {} onto the {}'s {} vertices{masked}; {} beyond {} ({}), {} without a value; distance to the other surface: median {:.3} %, 95th percentile {:.3} %, max {:.3} % of the target's diagonal",
            self.input,
            self.output,
            self.kind,
            if self.onto == Onto::Target { "target" } else { "source" },
            self.carried.vertices,
            self.carried.beyond,
            max_distance,
            format_length(self.max_distance),
            self.carried.missing,
            self.distance_median_percent,
            self.distance_p95_percent,
            self.distance_max_percent,
        )
    }
}

fn format_length(v: f64) -> String {
    format!("{v:.4}")
}

fn point3(shape: &FShape, v: usize) -> [f64; 3] {
    let p = shape.point(v);
    [p[0], p[1], if p.len() == 3 { p[2] } else { 0.0 }]
}
