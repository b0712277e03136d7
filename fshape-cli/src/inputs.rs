//! What several commands read and how they report: meshes with signal
//! files, stage templates, the error chain as one line.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fshape_mesh::FShape;
use fshape_mesh::io::{self, ReadOptions};

/// `--stage-templates`: the meshes, then `None` for the last stage (none
/// given: no stage templates).
pub fn stage_templates(
    paths: &[PathBuf],
    signal_name: Option<String>,
    stages: usize,
) -> Result<Option<Vec<Option<FShape>>>> {
    if paths.is_empty() {
        return Ok(None);
    }
    if paths.len() + 1 != stages {
        bail!(
            "--stage-templates: {} meshes for a schedule of {stages} stages: give one per stage before the last ({})",
            paths.len(),
            stages.saturating_sub(1)
        );
    }
    let mut templates =
        paths.iter().map(|p| load(p, signal_name.clone(), None).map(Some)).collect::<Result<Vec<_>>>()?;
    templates.push(None);
    Ok(Some(templates))
}

/// The error and its causes joined by ": ", skipping a cause whose text the
/// previous message already contains (the library errors name their source
/// in their own message and also return it from `source()`).
pub fn message(e: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in e.chain() {
        let m = cause.to_string();
        if !parts.last().is_some_and(|p| p.contains(&m)) {
            parts.push(m);
        }
    }
    parts.join(": ")
}

/// Reads a mesh and, if given, replaces its signal by a signal file's (CSV
/// column, GIfTI data array, FreeSurfer curv or MGH).
pub fn load(path: &Path, signal_name: Option<String>, signal: Option<&Path>) -> Result<FShape> {
    let shape = io::read_mesh(path, &ReadOptions { signal_name })?;
    let Some(csv) = signal else { return Ok(shape) };
    let column = io::read_signal_for(csv, Some(shape.n_vertices()))?;
    shape
        .with_signal(Some(column.values))
        .with_context(|| format!("attaching the signal of {} to {}", csv.display(), path.display()))
}

/// Warns when `--resume` reads a format-3 checkpoint: it has no checksum,
/// so damage in it would go unnoticed (it is read, and written back as
/// the current format). Reads the header only.
pub fn warn_if_unchecked(checkpoint: &Path) {
    let mut head = [0u8; 20];
    let read = std::fs::File::open(checkpoint).and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head));
    if read.is_ok() && u32::from_le_bytes([head[16], head[17], head[18], head[19]]) == fshape_match::UNCHECKED_FORMAT {
        eprintln!(
            "warning: {} is a format-{} checkpoint, without a checksum: it is read as it is, and a damaged byte \
             in it would go unnoticed; the checkpoints written from now on carry one",
            checkpoint.display(),
            fshape_match::UNCHECKED_FORMAT
        );
    }
}
