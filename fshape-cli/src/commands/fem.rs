//! `fshape fem`: the signal norm's matrix D_s of a mesh.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fshape_match::ops::{self, Norm};
use fshape_mesh::io;
use serde::Serialize;

use crate::inputs::load;

/// `fshape fem`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The mesh file.
    pub file: PathBuf,
    /// Which norm.
    #[arg(long, value_enum, default_value_t = NormName::H1)]
    pub norm: NormName,
    /// Length scale ℓ of the H1 gradient term, in the mesh's units
    /// (the paper uses 1; choose a length of the data's scale, e.g. a few
    /// mm on a cortex).
    #[arg(long, default_value_t = 1.0)]
    pub length: f64,
    /// Write D_s to this MatrixMarket file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print JSON for scripts.
    #[arg(long)]
    pub json: bool,
}

/// The signal norms by their names on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum NormName {
    /// Lumped L² (diagonal mass).
    #[value(name = "l2-lumped")]
    L2Lumped,
    /// L² with the P1 mass matrix.
    L2,
    /// H¹: P1 mass + ℓ² × P1 stiffness.
    H1,
}

impl NormName {
    fn norm(self, length: f64) -> Norm {
        match self {
            NormName::L2Lumped => Norm::L2Lumped,
            NormName::L2 => Norm::L2,
            NormName::H1 => Norm::H1 { length },
        }
    }
}

pub fn run(a: Args) -> Result<()> {
    fem(&a.file, a.norm.norm(a.length), a.out.as_deref(), a.json)
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

fn fem(path: &Path, norm: Norm, out: Option<&Path>, json: bool) -> Result<()> {
    let shape = load(path, None, None)?;
    let d = ops::signal_norm_matrix(&shape, norm).with_context(|| format!("assembling D for {}", path.display()))?;
    let n = d.n;
    let summary = FemSummary {
        path: path.display().to_string(),
        norm: norm.name(),
        length: match norm {
            Norm::H1 { length } => Some(length),
            _ => None,
        },
        n,
        nnz: 2 * d.values.len() - n,
        nnz_lower: d.values.len(),
        trace: d.trace,
        total_area: shape.total_volume(),
    };
    if let Some(out) = out {
        let comment = format!("fshape signal norm {} of {}", norm.name(), path.display());
        io::mtx::write_symmetric_lower(out, n, &d.column_start, &d.row_index, &d.values, &comment)?;
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
