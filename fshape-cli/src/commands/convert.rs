//! `fshape convert`: between mesh formats, optionally with a signal file and repairs.

use std::path::{Path, PathBuf};

use anyhow::Result;
use fshape_mesh::Repairs;
use fshape_mesh::io::{self, Encoding};

use crate::inputs::load;

/// `fshape convert`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// Input mesh.
    pub input: PathBuf,
    /// Output mesh; its extension chooses the format.
    pub output: PathBuf,
    /// Vertex property of the input to read as the signal.
    #[arg(long)]
    pub signal_name: Option<String>,
    /// Per-vertex signal file replacing the input's signal (CSV, GIfTI, FreeSurfer curv or MGH).
    #[arg(long)]
    pub signal: Option<PathBuf>,
    /// Write ASCII instead of binary (PLY, VTK).
    #[arg(long)]
    pub ascii: bool,
    /// Drop unused vertices, zero-volume and duplicate cells before writing.
    #[arg(long)]
    pub repair: bool,
}

pub fn run(a: Args) -> Result<()> {
    convert(&a.input, &a.output, a.signal_name, a.signal.as_deref(), a.ascii, a.repair)
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
