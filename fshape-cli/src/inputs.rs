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
    let column = io::read_signal(csv)?;
    shape
        .with_signal(Some(column.values))
        .with_context(|| format!("attaching the signal of {} to {}", csv.display(), path.display()))
}
