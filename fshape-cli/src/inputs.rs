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
    let signals: Vec<PathBuf> = signal.map(Path::to_path_buf).into_iter().collect();
    load_masked(path, signal_name, &signals, &Masking::default())
}

/// How a shape's signal is masked: a mask file, and whether a signal
/// file's NaN mark vertices without a value.
#[derive(Clone, Debug, Default)]
pub struct Masking<'a> {
    /// A mask file: a FreeSurfer `.label` (its vertices 1, the rest 0) or
    /// a per-vertex column of weights in [0, 1] (CSV, GIfTI, curv, MGH).
    pub mask: Option<&'a Path>,
    /// NaN in the signal file masks its vertex (HCP's medial wall).
    pub allow_missing: bool,
}

/// [`load`] with a mask and any number of signal files, one channel each:
/// the mask file's weights, with 0 wherever a signal file has NaN when
/// missing values are allowed.
pub fn load_masked(path: &Path, signal_name: Option<String>, signals: &[PathBuf], m: &Masking) -> Result<FShape> {
    let shape = io::read_mesh(path, &ReadOptions { signal_name })?;
    let n = shape.n_vertices();
    let mut mask = m.mask.map(|p| io::read_mask(p, n)).transpose()?;
    if signals.is_empty() {
        return match mask {
            Some(mask) => shape.with_mask(Some(mask)).with_context(|| format!("masking {}", path.display())),
            None => Ok(shape),
        };
    }
    let columns: Vec<Vec<f64>> = signals
        .iter()
        .map(|file| {
            let values = io::read_signal_for(file, Some(n), m.allow_missing)?.values;
            if values.len() != n {
                bail!("{}: {} values, but {} has {n} vertices", file.display(), values.len(), path.display());
            }
            Ok(values)
        })
        .collect::<Result<_>>()?;
    for column in &columns {
        if column.iter().any(|v| v.is_nan()) {
            let weights = mask.get_or_insert_with(|| vec![1.0; n]);
            for (w, v) in weights.iter_mut().zip(column) {
                if v.is_nan() {
                    *w = 0.0;
                }
            }
        }
    }
    let k = columns.len();
    let rows = io::interleave(&columns);
    let names: Vec<String> = signals.iter().map(|f| f.display().to_string()).collect();
    shape
        .with_signals_and_mask(Some(rows), k, mask)
        .with_context(|| format!("attaching the signal of {} to {}", names.join(", "), path.display()))
}

/// Warns when `--resume` reads a format-3 checkpoint: it has no checksum,
/// so damage in it would go unnoticed (it is read, and written back as
/// the current format). Reads the header only.
pub fn warn_if_unchecked(checkpoint: &Path) {
    if fshape_match::Checkpoint::file_format(checkpoint) == Some(fshape_match::UNCHECKED_FORMAT) {
        eprintln!(
            "warning: {} is a format-{} checkpoint, without a checksum: it is read as it is, and a damaged byte \
             in it would go unnoticed; the checkpoints written from now on carry one",
            checkpoint.display(),
            fshape_match::UNCHECKED_FORMAT
        );
    }
}

/// Reads a configuration file; with `warn`, prints on stderr each form it
/// uses that reads but is better written otherwise (`[schedule]`'s
/// arrays), naming the file.
pub fn read_config(path: &Path, warn: bool) -> Result<fshape_match::Config> {
    let config = fshape_match::Config::read(path)?;
    if warn {
        for w in config.warnings() {
            eprintln!("warning: {}: {w}", path.display());
        }
    }
    Ok(config)
}
