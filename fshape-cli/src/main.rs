//! `fshape`: inspect, convert and (in later releases) register functional
//! shapes. Exit codes: 0 success, 1 bad input (the message names the file
//! and the place), 2 usage error.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use fshape_fem::{Norm, SignalNorm};
use fshape_mesh::io::{self, Encoding, ReadOptions};
use fshape_mesh::{FShape, Problem, Repairs, Severity};
use serde::Serialize;

#[derive(Parser)]
#[command(name = "fshape", version, about = "Functional shapes: meshes carrying a signal, and their metamorphoses")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print counts, dimension, bounding box, total volume, signal range and
    /// the validation report of a mesh file (.ply, .obj, .vtk, optionally .gz).
    Info {
        /// The mesh file.
        file: PathBuf,
        /// Vertex property to read as the signal (default: `signal` if present).
        #[arg(long)]
        signal_name: Option<String>,
        /// Per-vertex signal CSV (one column with a header) replacing the file's signal.
        #[arg(long)]
        signal: Option<PathBuf>,
        /// Print JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// Assemble the signal norm matrix D_s of a mesh (lumped or P1 mass, or
    /// H1 = mass + length² × stiffness) and print a summary; optionally
    /// export it in MatrixMarket format (symmetric, lower triangle).
    Fem {
        /// The mesh file.
        file: PathBuf,
        /// Which norm: l2-lumped, l2 or h1.
        #[arg(long, default_value = "h1")]
        norm: String,
        /// Length scale ℓ of the H1 gradient term, in the mesh's units
        /// (the paper uses 1; choose a length of the data's scale, e.g. a few
        /// mm on a cortex).
        #[arg(long, default_value_t = 1.0)]
        length: f64,
        /// Write D_s to this MatrixMarket file.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// Convert between mesh formats (by extension: .ply, .obj, .vtk, each
    /// optionally .gz), optionally attaching a signal from a CSV file.
    Convert {
        /// Input mesh.
        input: PathBuf,
        /// Output mesh; its extension chooses the format.
        output: PathBuf,
        /// Vertex property of the input to read as the signal.
        #[arg(long)]
        signal_name: Option<String>,
        /// Per-vertex signal CSV replacing the input's signal.
        #[arg(long)]
        signal: Option<PathBuf>,
        /// Write ASCII instead of binary (PLY, VTK).
        #[arg(long)]
        ascii: bool,
        /// Drop unused vertices, zero-volume and duplicate cells before writing.
        #[arg(long)]
        repair: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info { file, signal_name, signal, json } => info(&file, signal_name, signal.as_deref(), json),
        Command::Fem { file, norm, length, out, json } => fem(&file, &norm, length, out.as_deref(), json),
        Command::Convert { input, output, signal_name, signal, ascii, repair } => {
            convert(&input, &output, signal_name, signal.as_deref(), ascii, repair)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// Reads a mesh and, if given, replaces its signal by a CSV column.
fn load(path: &Path, signal_name: Option<String>, signal: Option<&Path>) -> Result<FShape> {
    let shape = io::read_mesh(path, &ReadOptions { signal_name })?;
    let Some(csv) = signal else { return Ok(shape) };
    let column = io::csv::read_signal(csv, false)?;
    shape
        .with_signal(Some(column.values))
        .with_context(|| format!("attaching the signal of {} to {}", csv.display(), path.display()))
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
    signal: Option<SignalSummary>,
    closed: bool,
    boundary_loops: usize,
    components: usize,
    euler_characteristic: i64,
    errors: Vec<ProblemGroup>,
    warnings: Vec<ProblemGroup>,
}

fn group(problems: &[&Problem]) -> Vec<ProblemGroup> {
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
        signal: s.signal().filter(|f| !f.is_empty()).map(|f| SignalSummary {
            min: f.iter().copied().fold(f64::INFINITY, f64::min),
            max: f.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            mean: f.iter().sum::<f64>() / f.len() as f64,
        }),
        closed: topo.is_closed(),
        boundary_loops: topo.n_boundary_loops,
        components: topo.n_components,
        euler_characteristic: topo.euler_characteristic(s.kind(), s.n_cells()),
        errors: group(&by(Severity::Error)),
        warnings: group(&by(Severity::Warning)),
    }
}

fn info(path: &Path, signal_name: Option<String>, signal: Option<&Path>, json: bool) -> Result<()> {
    let shape = load(path, signal_name, signal)?;
    let i = summary(path, &shape);
    if json {
        println!("{}", serde_json::to_string_pretty(&i)?);
        return Ok(());
    }
    println!("{}", i.path);
    println!("  {} mesh in R^{}: {} vertices, {} cells", i.cell_kind, i.dim, i.n_vertices, i.n_cells);
    println!("  bounding box {:?} .. {:?} (diagonal {:.6})", i.bbox_min, i.bbox_max, i.bbox_diagonal);
    println!("  total {}: {:.9}", if shape.kind().dim() == 1 { "length" } else { "area" }, i.total_volume);
    match &i.signal {
        Some(f) => println!("  signal: min {:.6}, max {:.6}, mean {:.6}", f.min, f.max, f.mean),
        None => println!("  signal: none"),
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

fn convert(
    input: &Path,
    output: &Path,
    signal_name: Option<String>,
    signal: Option<&Path>,
    ascii: bool,
    repair: bool,
) -> Result<()> {
    let mut shape = load(input, signal_name, signal)?;
    if repair {
        let (fixed, log) = shape.repaired(Repairs::ALL);
        eprintln!("repair: dropped {} cell(s) and {} vertex(es)", log.dropped_cells.len(), log.dropped_vertices.len());
        shape = fixed;
    }
    let encoding = if ascii { Encoding::Ascii } else { Encoding::Binary };
    io::write_mesh(output, &shape, encoding)?;
    Ok(())
}

#[derive(Serialize)]
struct FemSummary {
    path: String,
    norm: &'static str,
    length: Option<f64>,
    n: usize,
    nnz: usize,
    nnz_lower: usize,
    trace: f64,
    total_area: f64,
}

fn fem(path: &Path, norm: &str, length: f64, out: Option<&Path>, json: bool) -> Result<()> {
    let shape = load(path, None, None)?;
    let norm = Norm::parse(norm, length)?;
    let d = SignalNorm::try_new(&shape, norm)?;
    let values = d.assemble(shape.points()).with_context(|| format!("assembling D for {}", path.display()))?;
    let (col_ptr, row_idx) = d.pattern();
    let mut trace = 0.0;
    for c in 0..d.n_vertices() {
        for e in col_ptr[c]..col_ptr[c + 1] {
            if row_idx[e] == c {
                trace += values[e];
            }
        }
    }
    let n = d.n_vertices();
    let summary = FemSummary {
        path: path.display().to_string(),
        norm: norm.name(),
        length: matches!(norm, Norm::H1 { .. }).then_some(length),
        n,
        nnz: 2 * values.len() - n,
        nnz_lower: values.len(),
        trace,
        total_area: shape.total_volume(),
    };
    if let Some(out) = out {
        let mut text = String::from("%%MatrixMarket matrix coordinate real symmetric\n");
        text.push_str(&format!("% fshape signal norm {} of {}\n", norm.name(), path.display()));
        text.push_str(&format!("{n} {n} {}\n", values.len()));
        for c in 0..n {
            for e in col_ptr[c]..col_ptr[c + 1] {
                text.push_str(&format!("{} {} {:e}\n", row_idx[e] + 1, c + 1, values[e]));
            }
        }
        io::write_atomic(out, text.as_bytes(), false)?;
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "{}: {} norm, {} × {} matrix, {} nonzeros ({} in the lower triangle)",
            summary.path, summary.norm, n, n, summary.nnz, summary.nnz_lower
        );
        println!("  trace {:.9e}, total area {:.9e}", summary.trace, summary.total_area);
    }
    Ok(())
}
