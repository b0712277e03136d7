//! `fshape info`: counts, extent, signal and the validation report of a mesh.

use std::path::{Path, PathBuf};

use anyhow::Result;
use fshape_mesh::{FShape, Finding, Severity};
use serde::Serialize;

use crate::inputs::load_masked;

/// `fshape info`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The mesh file.
    pub file: PathBuf,
    /// Vertex property to read as the signal (default: `signal` if present).
    #[arg(long)]
    pub signal_name: Option<String>,
    /// Per-vertex signal file replacing the mesh's signal: a CSV column with a
    /// header, GIfTI (.shape.gii, .func.gii), FreeSurfer curv (lh.thickness),
    /// .mgh/.mgz, or a CIFTI map as FILE.dscalar.nii:CORTEX_LEFT, with :MAP
    /// after it to pick a map. Repeated, one signal channel per file.
    #[arg(long)]
    pub signal: Vec<PathBuf>,
    /// A mask: a FreeSurfer .label, regions of a parcellation
    /// (lh.aparc.annot:insula, also .label.gii) or a per-vertex column of
    /// weights in [0, 1].
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Accept NaN in the signal file as missing values (each masks its vertex).
    #[arg(long)]
    pub allow_missing: bool,
    /// Print JSON for scripts.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> Result<()> {
    let masking = crate::inputs::Masking { mask: a.mask.as_deref(), allow_missing: a.allow_missing };
    info(&a.file, a.signal_name, &a.signal, &masking, a.json)
}

#[derive(Serialize)]
struct ProblemGroup {
    code: &'static str,
    count: usize,
    examples: Vec<String>,
}

#[derive(Serialize)]
struct SignalSummary {
    min: f64,
    max: f64,
    mean: f64,
}

impl SignalSummary {
    /// Over the values there are (NaN where masked); `None` without one.
    fn of(f: &[f64]) -> Option<SignalSummary> {
        let values = || f.iter().copied().filter(|v| !v.is_nan());
        (values().count() > 0).then(|| SignalSummary {
            min: values().fold(f64::INFINITY, f64::min),
            max: values().fold(f64::NEG_INFINITY, f64::max),
            mean: values().sum::<f64>() / values().count() as f64,
        })
    }
}

/// How many vertices a mask leaves without a value, in part, or whole.
#[derive(Serialize)]
struct MaskSummary {
    masked: usize,
    partial: usize,
    unmasked: usize,
}

#[derive(Serialize)]
struct Info {
    path: String,
    dim: usize,
    cell_kind: &'static str,
    n_vertices: usize,
    n_cells: usize,
    bbox_min: Vec<f64>,
    bbox_max: Vec<f64>,
    bbox_diagonal: f64,
    total_volume: f64,
    /// The first channel's.
    signal: Option<SignalSummary>,
    /// Each channel's, with several.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    channels: Vec<Option<SignalSummary>>,
    mask: Option<MaskSummary>,
    closed: bool,
    boundary_loops: usize,
    components: usize,
    euler_characteristic: i64,
    errors: Vec<ProblemGroup>,
    warnings: Vec<ProblemGroup>,
}

fn group(problems: &[&Finding]) -> Vec<ProblemGroup> {
    let mut out: Vec<ProblemGroup> = Vec::new();
    for p in problems {
        match out.iter_mut().find(|g| g.code == p.code()) {
            Some(g) => {
                g.count += 1;
                if g.examples.len() < 5 {
                    g.examples.push(p.to_string());
                }
            }
            None => out.push(ProblemGroup { code: p.code(), count: 1, examples: vec![p.to_string()] }),
        }
    }
    out
}

fn summary(path: &Path, s: &FShape) -> Info {
    let topo = s.topology();
    let bbox = s.bounding_box();
    let report = s.validate();
    let by = |sev| report.problems.iter().filter(|p| p.severity() == sev).collect::<Vec<_>>();
    Info {
        path: path.display().to_string(),
        dim: s.dim(),
        cell_kind: s.kind().name(),
        n_vertices: s.n_vertices(),
        n_cells: s.n_cells(),
        bbox_diagonal: bbox.diagonal(),
        bbox_min: bbox.min,
        bbox_max: bbox.max,
        total_volume: s.total_volume(),
        // Over the values there are (a masked vertex's is NaN).
        signal: s.channel(0).and_then(|f| SignalSummary::of(&f)),
        channels: match s.n_channels() {
            0 | 1 => Vec::new(),
            k => (0..k).map(|c| s.channel(c).and_then(|f| SignalSummary::of(&f))).collect(),
        },
        mask: s.mask().map(|m| MaskSummary {
            masked: m.iter().filter(|w| **w == 0.0).count(),
            partial: m.iter().filter(|w| **w > 0.0 && **w < 1.0).count(),
            unmasked: m.iter().filter(|w| **w == 1.0).count(),
        }),
        closed: topo.is_closed(),
        boundary_loops: topo.n_boundary_loops,
        components: topo.n_components,
        euler_characteristic: topo.euler_characteristic(s.kind(), s.n_cells()),
        errors: group(&by(Severity::Error)),
        warnings: group(&by(Severity::Warning)),
    }
}

fn info(
    path: &Path,
    signal_name: Option<String>,
    signal: &[PathBuf],
    masking: &crate::inputs::Masking,
    json: bool,
) -> Result<()> {
    let shape = load_masked(path, signal_name, signal, masking)?;
    let i = summary(path, &shape);
    if json {
        println!("{}", serde_json::to_string_pretty(&i)?);
        return Ok(());
    }
    println!("{}", i.path);
    println!("  {} mesh in R^{}: {} vertices, {} cells", i.cell_kind, i.dim, i.n_vertices, i.n_cells);
    println!("  bounding box {:?} .. {:?} (diagonal {:.6})", i.bbox_min, i.bbox_max, i.bbox_diagonal);
    println!("  total {}: {:.9}", if shape.kind().dim() == 1 { "length" } else { "area" }, i.total_volume);
    match (&i.signal, i.channels.len()) {
        (Some(f), 0) => println!("  signal: min {:.6}, max {:.6}, mean {:.6}", f.min, f.max, f.mean),
        (_, 0) => println!("  signal: none"),
        (_, k) => {
            println!("  signal: {k} channels");
            for (c, f) in i.channels.iter().enumerate() {
                match f {
                    Some(f) => println!("    {}: min {:.6}, max {:.6}, mean {:.6}", c + 1, f.min, f.max, f.mean),
                    None => println!("    {}: no value", c + 1),
                }
            }
        }
    }
    if let Some(m) = &i.mask {
        println!(
            "  mask: {} vertices masked (no signal value), {} partly (weight in (0, 1)), {} not",
            m.masked, m.partial, m.unmasked
        );
    }
    println!(
        "  {}, {} component(s), {} boundary loop(s), Euler characteristic {}",
        if i.closed { "closed" } else { "open" },
        i.components,
        i.boundary_loops,
        i.euler_characteristic
    );
    for (label, groups) in [("error", &i.errors), ("warning", &i.warnings)] {
        for g in groups {
            println!("  {label}: {} × {}: {}", g.count, g.code, g.examples.join("; "));
        }
    }
    if i.errors.is_empty() && i.warnings.is_empty() {
        println!("  no problems found");
    }
    Ok(())
}
