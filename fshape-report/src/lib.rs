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

use std::path::{Path, PathBuf};

pub mod outputs;
mod page;
mod pages;
pub mod plot;
pub mod render;
mod scene;

use fshape_match::record::{Record, RecordError};
use fshape_mesh::io;

pub use page::{Page, escape, html, table};
pub use pages::{
    AtlasShapes, atlas_page, atlas_page_of, batch_page, batch_page_of, match_page, registration_page, regression_page,
    regression_page_of,
};
pub use scene::{DISPLAY_VERTICES, Scene, scene};

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

pub(crate) fn file_error(path: &Path, message: impl std::fmt::Display) -> ReportError {
    ReportError::File { path: path.to_path_buf(), message: message.to_string() }
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
            Record::Regression(_) => regression_page(dir, view)?,
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
