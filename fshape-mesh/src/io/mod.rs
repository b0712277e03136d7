//! Reading and writing fshapes: PLY, OBJ, VTK legacy, GIfTI, FreeSurfer
//! surfaces; per-vertex signals as CSV, GIfTI, FreeSurfer curv or MGH;
//! images.
//!
//! Every reader reports bad input as an error naming the file, the line
//! (text) or byte offset (binary) and what was expected; none panics and
//! none allocates more than the file can hold, whatever its header claims.
//! Every writer writes to a temporary file beside the target and renames it
//! into place, so a failed write never leaves a half-finished file.

use std::fmt;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use crate::shape::{CellKind, FShape, ShapeError};

pub mod cifti;
pub mod csv;
mod cursor;
pub mod freesurfer;
pub mod gifti;
pub mod image;
pub mod label;
pub mod mtx;
pub mod obj;
pub mod parcellation;
pub mod ply;
mod source;
pub mod table;
pub mod vtk;

use source::Expect;
pub use source::{EXPANSION, EXPANSION_FLOOR, Limits, PIPE_BYTES, limits, open_file, set_limits};

/// Where in a file a parse error happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of a text file (or text header).
    Line(usize),
    /// 0-based byte offset into binary data (after decompression).
    Byte(usize),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::Byte(b) => write!(f, "byte {b}"),
        }
    }
}

/// What went wrong while parsing.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ParseErrorKind {
    /// The data ended early (a truncated file or a record cut short).
    #[error("unexpected end of data: expected {expected}")]
    Eof {
        /// What was expected next.
        expected: &'static str,
    },
    /// A token or line is not what the format allows here.
    #[error("expected {expected}, found `{found}`")]
    BadToken {
        /// What was expected.
        expected: &'static str,
        /// The offending text (shortened).
        found: String,
    },
    /// A feature of the format that fshape does not read.
    #[error("unsupported {what}: `{found}`")]
    Unsupported {
        /// Which feature.
        what: &'static str,
        /// Its value in the file.
        found: String,
    },
    /// A required element or property is absent.
    #[error("missing {what}")]
    Missing {
        /// What is missing.
        what: &'static str,
    },
    /// The header claims more records than the rest of the file can hold.
    #[error("the header claims {claimed} {what}, but only {available} bytes follow")]
    Truncated {
        /// Which records.
        what: &'static str,
        /// The count in the header.
        claimed: u64,
        /// Bytes left in the file.
        available: usize,
    },
    /// A cell refers to a negative vertex index.
    #[error("cell {cell} has the negative vertex index {value}")]
    NegativeIndex {
        /// Cell index.
        cell: usize,
        /// The index in the file.
        value: i64,
    },
    /// Cells of different sizes in one file.
    #[error("cell {cell} has {found} vertices, but the first cell has {expected} (mixed cell sizes)")]
    MixedCellSizes {
        /// Cell index.
        cell: usize,
        /// Its vertex count.
        found: usize,
        /// The first cell's vertex count.
        expected: usize,
    },
    /// Cells that are neither segments nor triangles.
    #[error(
        "cell {cell} has {found} vertices; fshape reads segments (2) and triangles (3): triangulate polygons first"
    )]
    CellSize {
        /// Cell index.
        cell: usize,
        /// Its vertex count.
        found: usize,
    },
    /// A header declares more values than fshape's limit
    /// ([`Limits::max_values`]).
    #[error("the header claims {claimed} {what}, more than the limit of {limit} (set FSHAPE_MAX_VALUES to raise it)")]
    TooMany {
        /// Which values.
        what: &'static str,
        /// The count in the header.
        claimed: u64,
        /// The limit.
        limit: u64,
    },
    /// A signal goes on past the mesh's vertex count (reading stopped here).
    #[error("the signal goes on past the mesh's {vertices} vertices (value {} is here)", vertices + 1)]
    LongerThanMesh {
        /// The mesh's vertex count.
        vertices: u64,
    },
    /// A name asked for (a region, a structure, a map) is not in the file.
    #[error("no {what} named `{name}` (the file has: {})", list(.available))]
    UnknownName {
        /// What kind of name.
        what: &'static str,
        /// The name asked for.
        name: String,
        /// The names the file has.
        available: Vec<String>,
    },
    /// A file holding several things (structures, maps, regions) was
    /// given without saying which.
    #[error("name the {what} after the file, as {syntax} (the file has: {})", list(.available))]
    NotChosen {
        /// What must be chosen.
        what: &'static str,
        /// How to write the choice.
        syntax: &'static str,
        /// What the file has.
        available: Vec<String>,
    },
    /// Two counts that must agree do not.
    #[error("{what}: expected {expected}, found {found}")]
    CountMismatch {
        /// What is counted.
        what: &'static str,
        /// The required count.
        expected: u64,
        /// The count in the file.
        found: u64,
    },
}

/// A parse error with its place in the data.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{at}: {kind}")]
pub struct ParseError {
    /// Where it happened.
    pub at: Location,
    /// What happened.
    pub kind: ParseErrorKind,
}

/// Why reading a file failed. Every variant names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The file could not be opened or read (or gunzipped).
    #[error("{path}: {source}", path = .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The file's extension names no format fshape reads.
    #[error(
        "{path}: unknown format (expected .ply, .obj, .vtk or .gii, optionally .gz, or a FreeSurfer surface)",
        path = .path.display()
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The contents do not follow the format.
    #[error("{path}: {source}", path = .path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// What and where.
        source: ParseError,
    },
    /// The EXR reader rejected the file.
    #[error("{path}: EXR: {source}", path = .path.display())]
    Exr {
        /// The file.
        path: PathBuf,
        /// exr's error.
        source: exr::error::Error,
    },
    /// The parsed data is not a usable fshape (NaN coordinates, an index out
    /// of range, ...); every problem is listed with its index.
    #[error("{path}: {source}", path = .path.display())]
    Shape {
        /// The file.
        path: PathBuf,
        /// The problems.
        source: ShapeError,
    },
    /// A signal file holds a value that is not a finite number.
    #[error(
        "{path}: the value of vertex {vertex} (counting from 0) is {value}; signals must be finite{hint}",
        path = .path.display(),
        hint = if .value.is_nan() { " (NaN is a missing value: allowing them, with --allow-missing or allow_missing=True, masks their vertices)" } else { "" }
    )]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// The vertex.
        vertex: usize,
        /// Its value.
        value: f64,
    },
    /// A per-vertex file (a signal, a mask) whose count is not the
    /// surface's.
    #[error("{path}: {found} values for a surface of {expected} vertices", path = .path.display())]
    Count {
        /// The file.
        path: PathBuf,
        /// Values in it.
        found: usize,
        /// The surface's vertices.
        expected: usize,
    },
    /// The file does not hold what was asked of it: a structure, map or
    /// region it lacks, a surface of another vertex count.
    #[error("{path}: {source}", path = .path.display())]
    Select {
        /// The file.
        path: PathBuf,
        /// What is missing or does not fit.
        source: ParseErrorKind,
    },
    /// The signal property the caller named is not in the file.
    #[error("{path}: no per-vertex scalar named `{name}` (available: {avail})", path = .path.display(), avail = list(.available))]
    SignalNotFound {
        /// The file.
        path: PathBuf,
        /// The name asked for.
        name: String,
        /// The per-vertex scalars the file has.
        available: Vec<String>,
    },
}

impl ReadError {
    /// The file it names.
    pub fn path(&self) -> &Path {
        match self {
            ReadError::Io { path, .. }
            | ReadError::UnknownFormat { path }
            | ReadError::Parse { path, .. }
            | ReadError::Exr { path, .. }
            | ReadError::Shape { path, .. }
            | ReadError::NonFinite { path, .. }
            | ReadError::Count { path, .. }
            | ReadError::Select { path, .. }
            | ReadError::SignalNotFound { path, .. } => path,
        }
    }

    /// Where in the file, when the parser knows.
    pub fn location(&self) -> Option<Location> {
        match self {
            ReadError::Parse { source, .. } => Some(source.at),
            _ => None,
        }
    }
}

fn list(names: &[String]) -> String {
    if names.is_empty() { "none".to_string() } else { names.join(", ") }
}

/// Why writing a file failed. Nothing is left at the target path.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// Creating, writing or renaming failed.
    #[error("{path}: {source}", path = .path.display())]
    Io {
        /// The target file.
        path: PathBuf,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The extension names no format fshape writes.
    #[error(
        "{path}: unknown output format (expected .ply, .obj, .vtk or .gii, optionally .gz, or a FreeSurfer surface \
         name such as lh.pial)",
        path = .path.display()
    )]
    UnknownFormat {
        /// The target file.
        path: PathBuf,
    },
    /// The EXR writer failed.
    #[error("{path}: EXR: {source}", path = .path.display())]
    Exr {
        /// The target file.
        path: PathBuf,
        /// exr's error.
        source: exr::error::Error,
    },
    /// The extension names no format a parcellation is written in.
    #[error(
        "{path}: a parcellation is written as .annot (FreeSurfer), .label.gii (GIfTI) or .csv (a key per vertex)",
        path = .path.display()
    )]
    UnknownParcellationFormat {
        /// The target file.
        path: PathBuf,
    },
}

/// The per-vertex property read as the signal unless the caller names another.
pub const DEFAULT_SIGNAL_NAME: &str = "signal";

/// Options for [`read_mesh`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// The per-vertex scalar to read as the signal. `None` reads the
    /// property [`DEFAULT_SIGNAL_NAME`] if present and no signal otherwise;
    /// a named property must exist. Scanner fields (`confidence`,
    /// `intensity`, ...) are never taken as a signal unless named here.
    /// Properties `name_2`, `name_3`, … beside it are read as its further
    /// channels ([`channel_name`]).
    pub signal_name: Option<String>,
}

/// The name of channel `c` (from 0) of a signal named `base` in a file
/// with one property or array per channel (PLY, VTK, GIfTI): `base`, then
/// `base_2`, `base_3`, …, so that a reader that knows one signal reads
/// the first channel.
pub fn channel_name(base: &str, c: usize) -> String {
    if c == 0 { base.to_string() } else { format!("{base}_{}", c + 1) }
}

/// What `find` finds for the channels of a signal named `base`: `base`,
/// then `base_2`, `base_3`, … while they exist.
pub(crate) fn channel_columns<T>(base: &str, find: impl Fn(&str) -> Option<T>) -> Vec<T> {
    let mut found = Vec::new();
    while let Some(t) = find(&channel_name(base, found.len())) {
        found.push(t);
    }
    found
}

/// Columns of one value per vertex as rows of k values per vertex, as
/// many rows as the shortest column (check their lengths first).
pub fn interleave(columns: &[Vec<f64>]) -> Vec<f64> {
    let n = columns.iter().map(Vec::len).min().unwrap_or(0);
    (0..n).flat_map(|v| columns.iter().map(move |c| c[v])).collect()
}

/// Mesh file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Stanford PLY (ASCII, binary little or big endian).
    Ply,
    /// Wavefront OBJ (geometry only).
    Obj,
    /// VTK legacy POLYDATA (ASCII or binary).
    Vtk,
    /// GIfTI (`.gii`, `.surf.gii`): POINTSET and TRIANGLE arrays, and a
    /// per-vertex array as the signal.
    Gifti,
    /// A FreeSurfer triangle surface (`lh.pial`, `rh.white`, …; geometry
    /// only).
    FreeSurfer,
}

/// The last name part of FreeSurfer's surface files (`lh.pial`), by which
/// [`Format::from_path`] knows them; other names are read by their magic.
pub const FREESURFER_SURFACES: &[&str] =
    &["pial", "white", "inflated", "sphere", "orig", "smoothwm", "midthickness", "graymid", "reg", "qsphere"];

impl Format {
    /// The format named by a path's extension, looking through a final
    /// `.gz`; also whether the path is gzip-compressed.
    pub fn from_path(path: &Path) -> Option<(Format, bool)> {
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        // `.bz2` is read (decompressed by `read_bytes`), never written.
        let (stem, gz) = match (name.strip_suffix(".gz"), name.strip_suffix(".bz2")) {
            (Some(s), _) => (s.to_string(), true),
            (None, Some(s)) => (s.to_string(), false),
            (None, None) => (name, false),
        };
        let ext = stem.rsplit_once('.')?.1;
        let f = match ext {
            "ply" => Format::Ply,
            "obj" => Format::Obj,
            "vtk" => Format::Vtk,
            "gii" => Format::Gifti,
            e if FREESURFER_SURFACES.contains(&e) => Format::FreeSurfer,
            _ => return None,
        };
        Some((f, gz))
    }

    /// The format a file's first bytes announce (already gunzipped):
    /// FreeSurfer's magic, GIfTI's XML, PLY's and VTK's first lines. OBJ
    /// has no signature.
    pub fn sniff(data: &[u8]) -> Option<Format> {
        let text = data.strip_prefix(b"\xef\xbb\xbf").unwrap_or(data);
        if data.starts_with(&freesurfer::SURFACE_MAGIC) {
            Some(Format::FreeSurfer)
        } else if text.starts_with(b"ply") {
            Some(Format::Ply)
        } else if text.starts_with(b"# vtk DataFile") {
            Some(Format::Vtk)
        } else if text.starts_with(b"<?xml") || text.starts_with(b"<GIFTI") {
            Some(Format::Gifti)
        } else {
            None
        }
    }
}

/// Text or binary encoding for writers that offer both.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Encoding {
    /// Human-readable text; floats in Rust's shortest round-trip `{:e}` form.
    Ascii,
    /// Binary (little endian for PLY; VTK legacy binary is big endian by
    /// definition). Round trips are bitwise.
    #[default]
    Binary,
}

/// Per-vertex data as parsed, before it becomes an [`FShape`].
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct RawMesh {
    pub(crate) dim: usize,
    pub(crate) cell_size: Option<usize>,
    pub(crate) points: Vec<f64>,
    pub(crate) cells: Vec<usize>,
    pub(crate) signal: Option<Vec<f64>>,
    /// The signal's channel count (0 or 1: one).
    pub(crate) channels: usize,
    /// The vertex mask (PLY property `mask`), if the file has one.
    pub(crate) mask: Option<Vec<f64>>,
    /// Names of every per-vertex scalar in the file.
    pub(crate) scalars: Vec<String>,
}

impl RawMesh {
    pub(crate) fn into_shape(self, path: &Path, opts: &ReadOptions) -> Result<FShape, ReadError> {
        if let (Some(name), None) = (&opts.signal_name, &self.signal) {
            return Err(ReadError::SignalNotFound { path: path.into(), name: name.clone(), available: self.scalars });
        }
        let kind = if self.cell_size == Some(2) { CellKind::Segment } else { CellKind::Triangle };
        let shape = FShape::try_new(self.dim, kind, self.points, self.cells, None)
            .and_then(|s| s.with_signals_and_mask(self.signal, self.channels.max(1), self.mask));
        shape.map_err(|source| ReadError::Shape { path: path.into(), source })
    }
}

/// Reads a whole file, gunzipping it when it starts with the gzip magic
/// (and bunzipping a `.bz2`), within the [`Limits`]: devices and folders
/// are refused, pipes and decompressed data are capped.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>, ReadError> {
    source::open(path, Expect::Any)?.read_all(path)
}

/// Reads a mesh (PLY, OBJ or VTK legacy, each optionally gzipped), with its
/// signal per [`ReadOptions`].
///
/// ```no_run
/// use fshape_mesh::io::{read_mesh, ReadOptions};
/// let s = read_mesh("lh.pial.thick.ply".as_ref(), &ReadOptions::default())?;
/// println!("{} vertices, signal: {}", s.n_vertices(), s.signal().is_some());
/// # Ok::<(), fshape_mesh::io::ReadError>(())
/// ```
///
/// A path whose extension names no format (FreeSurfer's `lh.pial`) is read
/// by its first bytes ([`Format::sniff`]).
pub fn read_mesh(path: &Path, opts: &ReadOptions) -> Result<FShape, ReadError> {
    if let Some((format, _)) = Format::from_path(path) {
        let data = source::open(path, Expect::Mesh(format))?.read_all(path)?;
        return parse_mesh(&data, format, opts, path);
    }
    if std::fs::metadata(path).is_err() {
        return Err(ReadError::UnknownFormat { path: path.into() });
    }
    let input = source::open(path, Expect::Any)?;
    let format = Format::sniff(&input.prefix).ok_or_else(|| ReadError::UnknownFormat { path: path.into() })?;
    let data = input.read_all(path)?;
    parse_mesh(&data, format, opts, path)
}

/// Parses mesh data already in memory (decompressed); `path` names the
/// source in error messages, and its folder holds a GIfTI file's external
/// data files.
pub fn parse_mesh(data: &[u8], format: Format, opts: &ReadOptions, path: &Path) -> Result<FShape, ReadError> {
    let name = opts.signal_name.as_deref().unwrap_or(DEFAULT_SIGNAL_NAME);
    let parse = |source| ReadError::Parse { path: path.into(), source };
    let raw = match format {
        Format::Ply => ply::parse(data, name).map_err(parse)?,
        Format::Vtk => vtk::parse(data, name).map_err(parse)?,
        Format::Obj => obj::parse(data).map_err(parse)?,
        Format::Gifti => gifti::to_raw(gifti::parse_in(data, path.parent()).map_err(parse)?, name).map_err(parse)?,
        Format::FreeSurfer => freesurfer::parse_surface(data).map_err(parse)?,
    };
    raw.into_shape(path, opts)
}

/// `.bz2` files are read, not written.
fn refuse_bz2(path: &Path) -> Result<(), WriteError> {
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("bz2")) {
        return Err(WriteError::Io {
            path: path.into(),
            source: std::io::Error::new(
                std::io::ErrorKind::Unsupported,
                "bzip2 files are read but not written: use .gz to compress",
            ),
        });
    }
    Ok(())
}

/// Writes a mesh in the format its extension names (`.ply`, `.obj`,
/// `.vtk`, `.gii`, each optionally followed by `.gz`, or a FreeSurfer
/// surface name such as `lh.pial`). OBJ and FreeSurfer surfaces carry no
/// signal; GIfTI and FreeSurfer store single precision.
/// The write is atomic: a temporary file is renamed into place.
pub fn write_mesh(path: &Path, shape: &FShape, encoding: Encoding) -> Result<(), WriteError> {
    refuse_bz2(path)?;
    let (format, gz) = Format::from_path(path).ok_or_else(|| WriteError::UnknownFormat { path: path.into() })?;
    let mut bytes = Vec::new();
    write_to(&mut bytes, shape, format, encoding).map_err(|source| WriteError::Io { path: path.into(), source })?;
    write_atomic(path, &bytes, gz)
}

/// Writes a mesh in the given format to any writer (uncompressed). OBJ
/// ignores `encoding` and carries no signal.
pub fn write_to(w: &mut impl Write, shape: &FShape, format: Format, encoding: Encoding) -> std::io::Result<()> {
    match format {
        Format::Ply => ply::write(w, shape, encoding),
        Format::Vtk => vtk::write(w, shape, encoding),
        Format::Obj => obj::write(w, shape),
        Format::Gifti => gifti::write(w, shape, encoding),
        Format::FreeSurfer => freesurfer::write_surface(w, shape),
    }
}

/// Per-vertex signal file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SignalFormat {
    /// One column with a header ([`csv::parse_signal`]).
    Csv,
    /// A GIfTI data file (`.shape.gii`, `.func.gii`) with one per-vertex array.
    Gifti,
    /// A FreeSurfer curv file (`lh.thickness`, `lh.curv`, …).
    Curv,
    /// A FreeSurfer MGH volume of n × 1 × 1 values (`.mgh`, `.mgz`).
    Mgh,
}

/// The last name part of FreeSurfer's per-vertex files (`lh.thickness`),
/// by which [`SignalFormat::from_path`] knows a path to write; reading
/// goes by the magic.
pub const FREESURFER_CURVS: &[&str] = &["thickness", "curv", "sulc", "area", "volume", "jacobian_white"];

impl SignalFormat {
    /// The format a path names: `.gii`, `.mgh`/`.mgz`, a FreeSurfer
    /// per-vertex name (`lh.thickness`); anything else is CSV.
    pub fn from_path(path: &Path) -> SignalFormat {
        let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        let stem = name.strip_suffix(".gz").or_else(|| name.strip_suffix(".bz2")).unwrap_or(&name);
        match stem.rsplit_once('.').map(|(_, e)| e) {
            Some("gii") => SignalFormat::Gifti,
            Some("mgh" | "mgz") => SignalFormat::Mgh,
            Some(e) if FREESURFER_CURVS.contains(&e) => SignalFormat::Curv,
            _ => SignalFormat::Csv,
        }
    }

    /// The format of a signal file's contents (already gunzipped), by its
    /// first bytes, with the path's MGH extension as the one tie-breaker
    /// (MGH has no magic).
    pub fn detect(data: &[u8], path: &Path) -> SignalFormat {
        if data.starts_with(&freesurfer::CURV_MAGIC) {
            SignalFormat::Curv
        } else if Format::sniff(data) == Some(Format::Gifti) {
            SignalFormat::Gifti
        } else if SignalFormat::from_path(path) == SignalFormat::Mgh || data.starts_with(&[0, 0, 0, 1]) {
            SignalFormat::Mgh
        } else {
            SignalFormat::Csv
        }
    }
}

/// Reads a per-vertex signal from a CSV column, a GIfTI data file, a
/// FreeSurfer curv file or an MGH/MGZ file (chosen by [`SignalFormat::detect`]).
/// Values must be finite.
pub fn read_signal(path: &Path) -> Result<csv::SignalColumn, ReadError> {
    read_signal_for(path, None, false)
}

/// Splits `FILE:SELECTOR` (a CIFTI file's structure and map, a
/// parcellation's regions) into the file and the selector. A path that
/// names a file is all file; otherwise the file is the longest part
/// before a `:` that names one.
pub fn split_selector(path: &Path) -> (PathBuf, Option<String>) {
    if path.exists() {
        return (path.into(), None);
    }
    let s = path.to_string_lossy();
    for (k, _) in s.match_indices(':').collect::<Vec<_>>().into_iter().rev() {
        if Path::new(&s[..k]).exists() {
            return (PathBuf::from(&s[..k]), Some(s[k + 1..].to_string()));
        }
    }
    (path.into(), None)
}

/// Whether a path names a parcellation: a FreeSurfer `.annot`, a GIfTI
/// `.label.gii` or a CIFTI-2 `.dlabel.nii`.
fn is_parcellation(path: &Path) -> bool {
    let name = path.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    name.ends_with(".annot") || name.ends_with(".label.gii") || is_dlabel(name)
}

/// Whether a file name (lower case) is a CIFTI-2 label file's (gzipped
/// or not).
fn is_dlabel(name: &str) -> bool {
    name.strip_suffix(".gz").unwrap_or(name).ends_with(".dlabel.nii")
}

/// Reads a parcellation: a FreeSurfer `.annot`
/// ([`freesurfer::parse_annot`]), a GIfTI label array with its label
/// table ([`gifti::parcellation`]), or one surface structure's map of a
/// CIFTI-2 label file, named after the file as for a map:
/// `parcels.dlabel.nii:CORTEX_LEFT[:MAP]` ([`cifti::Cifti::parcellation`];
/// the vertices the structure leaves out carry its `???` key).
pub fn read_parcellation(path: &Path) -> Result<parcellation::Parcellation, ReadError> {
    let (file, selector) = split_selector(path);
    let path = file.as_path();
    let data = source::open(path, Expect::Any)?.read_all(path)?;
    if cifti::is_nifti2(&data) {
        return read_cifti_parcellation(path, data, selector.as_deref(), None);
    }
    if let Some(sel) = selector {
        return Err(ReadError::Select {
            path: path.into(),
            source: ParseErrorKind::Unsupported {
                what: "selector (only a CIFTI-2 file takes FILE:STRUCTURE)",
                found: sel,
            },
        });
    }
    let parse = |source| ReadError::Parse { path: path.into(), source };
    if Format::sniff(&data) == Some(Format::Gifti) {
        gifti::parcellation(&gifti::parse_in(&data, path.parent()).map_err(parse)?).map_err(parse)
    } else {
        freesurfer::parse_annot(&data).map_err(parse)
    }
}

/// A mask for a surface of `n_vertices` vertices: a FreeSurfer `.label`
/// (its vertices 1, the rest 0; [`label::Label::mask`]), the regions of a
/// parcellation named after the file (`lh.aparc.annot:precentral,postcentral`,
/// also a `.label.gii`, and after a CIFTI-2 label file's structure and map:
/// `parcels.dlabel.nii:CORTEX_LEFT[:MAP]:V1_ROI`), or a per-vertex column of weights in [0, 1] in
/// any format [`read_signal`] reads (the weights' range is checked when
/// the mask joins its shape).
pub fn read_mask(path: &Path, n_vertices: usize) -> Result<Vec<f64>, ReadError> {
    let (file, selector) = split_selector(path);
    let name = file.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    if name.ends_with(".label") || name.ends_with(".label.gz") {
        return label::read_label(&file)?
            .mask(n_vertices)
            .map_err(|source| ReadError::Parse { path: file.clone(), source });
    }
    if is_dlabel(&name) {
        // FILE:STRUCTURE[:MAP]:REGION,REGION
        let Some((cifti_selector, regions)) = selector.as_deref().and_then(|s| s.rsplit_once(':')) else {
            return Err(ReadError::Select {
                path: file,
                source: ParseErrorKind::NotChosen {
                    what: "structure and regions",
                    syntax: "FILE:STRUCTURE:REGION,REGION or FILE:STRUCTURE:MAP:REGION,REGION",
                    available: Vec::new(),
                },
            });
        };
        let data = source::open(&file, Expect::Any)?.read_all(&file)?;
        let p = read_cifti_parcellation(&file, data, Some(cifti_selector), Some(n_vertices))?;
        return regions_mask(file, &p, regions, "FILE:STRUCTURE[:MAP]:REGION,REGION");
    }
    if is_parcellation(&file) {
        let p = read_parcellation(&file)?;
        if p.keys.len() != n_vertices {
            return Err(ReadError::Count { path: file, found: p.keys.len(), expected: n_vertices });
        }
        return regions_mask(file, &p, &selector.unwrap_or_default(), "FILE:REGION,REGION");
    }
    let column = read_signal_for(path, Some(n_vertices), false)?;
    if column.values.len() != n_vertices {
        return Err(ReadError::Count { path: path.into(), found: column.values.len(), expected: n_vertices });
    }
    Ok(column.values)
}

/// The mask of a parcellation's regions named in `regions` (comma
/// separated); none named is an error listing the table's names, written
/// as `syntax` says.
fn regions_mask(
    file: PathBuf,
    p: &parcellation::Parcellation,
    regions: &str,
    syntax: &'static str,
) -> Result<Vec<f64>, ReadError> {
    let names: Vec<&str> = regions.split(',').map(str::trim).filter(|n| !n.is_empty()).collect();
    if names.is_empty() {
        let available = p.regions.iter().map(|r| r.name.clone()).collect();
        let source = ParseErrorKind::NotChosen { what: "regions", syntax, available };
        return Err(ReadError::Select { path: file, source });
    }
    p.mask(&names).map_err(|source| ReadError::Select { path: file, source })
}

/// [`read_signal`] for a mesh of `n_vertices` vertices: a CSV column is
/// read as a stream and refused at its first value past that count, so a
/// runaway file costs no more than the values expected. With
/// `allow_missing`, NaN (a missing value, as HCP writes on the medial
/// wall) is accepted; infinities never are.
///
/// A CIFTI-2 dense file (`.dscalar.nii`) is read for one surface structure,
/// named after the file with, when the file has several maps, the map's
/// name or number: `maps.dscalar.nii:CORTEX_LEFT:thickness`
/// ([`cifti::Cifti::surface`]); the vertices the structure leaves out (the
/// medial wall) are missing values. A table of several maps (CSV) or a
/// GIfTI data file of several arrays is read for the one named after the
/// file, by name or number from 1: `maps.csv:myelin`, `maps.func.gii:2`.
pub fn read_signal_for(
    path: &Path,
    n_vertices: Option<usize>,
    allow_missing: bool,
) -> Result<csv::SignalColumn, ReadError> {
    let (file, selector) = split_selector(path);
    let path = file.as_path();
    let input = source::open(path, Expect::Signal)?;
    if cifti::is_nifti2(&input.prefix) {
        let column = read_cifti(path, input, selector.as_deref(), n_vertices)?;
        if let Some(k) = column.values.iter().position(|v| !(v.is_finite() || allow_missing && v.is_nan())) {
            return Err(ReadError::NonFinite { path: path.into(), vertex: k, value: column.values[k] });
        }
        return Ok(column);
    }
    let parse = |source| ReadError::Parse { path: path.into(), source };
    if let Some(f) = Format::sniff(&input.prefix).filter(|&f| f != Format::Gifti) {
        return Err(parse(ParseError {
            at: Location::Byte(0),
            kind: ParseErrorKind::Unsupported {
                what: "signal file: this is a mesh (give it as the mesh, and its signal by name)",
                found: format!("{f:?}"),
            },
        }));
    }
    if SignalFormat::detect(&input.prefix, path) == SignalFormat::Csv && selector.is_none() {
        let mut reader = std::io::BufReader::new(std::io::Cursor::new(input.prefix).chain(input.rest));
        let column = csv::parse_signal_from(&mut reader, allow_missing, n_vertices).map_err(|e| match e {
            csv::StreamError::Io(source) => ReadError::Io { path: path.into(), source },
            csv::StreamError::Parse(source) => parse(source),
        })?;
        return Ok(column);
    }
    let data = input.read_all(path)?;
    // lh.thickness and lh.thickness.mgz are both "thickness".
    let stem = || {
        let n = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let n = n.strip_suffix(".gz").unwrap_or(&n);
        let n = n.strip_suffix(".mgh").or_else(|| n.strip_suffix(".mgz")).unwrap_or(n);
        n.rsplit('.').next().unwrap_or(n).to_string()
    };
    let format = SignalFormat::detect(&data, path);
    if let (Some(sel), SignalFormat::Curv | SignalFormat::Mgh) = (&selector, format) {
        return Err(ReadError::Select {
            path: path.into(),
            source: ParseErrorKind::Unsupported { what: "selector after a file of one map", found: sel.clone() },
        });
    }
    let column = match format {
        SignalFormat::Csv => match &selector {
            Some(sel) => csv::parse_table_column(&data, sel).map_err(parse)?,
            None => return csv::parse_signal(&data, false).map_err(parse),
        },
        SignalFormat::Gifti => {
            let g = gifti::parse_in(&data, path.parent()).map_err(parse)?;
            let (name, values) = gifti::signal_named(&g, selector.as_deref()).map_err(parse)?;
            csv::SignalColumn { name, values }
        }
        SignalFormat::Curv => csv::SignalColumn { name: stem(), values: freesurfer::parse_curv(&data).map_err(parse)? },
        SignalFormat::Mgh => csv::SignalColumn { name: stem(), values: freesurfer::parse_mgh(&data).map_err(parse)? },
    };
    if let Some(k) = column.values.iter().position(|v| !(v.is_finite() || allow_missing && v.is_nan())) {
        return Err(ReadError::NonFinite { path: path.into(), vertex: k, value: column.values[k] });
    }
    Ok(column)
}

/// One surface structure's map of a CIFTI-2 file, `selector` being
/// `STRUCTURE[:MAP]`; without `n_vertices`, the structure's surface size
/// (within what the file's size can stand for). A label file is refused:
/// its keys are no values to average.
fn read_cifti(
    path: &Path,
    input: source::Input,
    selector: Option<&str>,
    n_vertices: Option<usize>,
) -> Result<csv::SignalColumn, ReadError> {
    let c =
        cifti::Cifti::parse(input.read_all(path)?).map_err(|source| ReadError::Parse { path: path.into(), source })?;
    let select = |source| ReadError::Select { path: path.into(), source };
    if c.labels.is_some() {
        return Err(select(ParseErrorKind::Unsupported {
            what: "CIFTI file as a map: it holds region keys (a .dlabel.nii); give it as a parcellation, \
                   a mask's regions or to fshape transfer",
            found: "label tables".into(),
        }));
    }
    let (structure, map, n) = cifti_selection(path, &c, selector, n_vertices)?;
    let values = c.surface(structure, map, n).map_err(select)?;
    let name = c.maps[c.map_index(map).map_err(select)?].clone();
    Ok(csv::SignalColumn { name, values })
}

/// The structure, the map and the surface's vertex count a CIFTI
/// `selector` (`STRUCTURE[:MAP]`) names; without `n_vertices`, the
/// structure's surface size, within what the file's size can stand for.
fn cifti_selection<'a>(
    path: &Path,
    c: &cifti::Cifti,
    selector: Option<&'a str>,
    n_vertices: Option<usize>,
) -> Result<(&'a str, Option<&'a str>, usize), ReadError> {
    let select = |source| ReadError::Select { path: path.into(), source };
    let (structure, map) = match selector.map(|s| s.split_once(':').unwrap_or((s, ""))) {
        Some((s, m)) if !s.is_empty() => (s, Some(m).filter(|m| !m.is_empty())),
        _ => {
            return Err(select(ParseErrorKind::NotChosen {
                what: "surface structure",
                syntax: "FILE:STRUCTURE or FILE:STRUCTURE:MAP",
                available: c
                    .models
                    .iter()
                    .filter(|m| m.surface_vertices.is_some())
                    .map(|m| m.structure.clone())
                    .collect(),
            }));
        }
    };
    let n = match n_vertices {
        Some(n) => n,
        None => {
            let n = c.model(structure).map_err(select)?.surface_vertices.expect("a surface model");
            let room = source::EXPANSION.saturating_mul(c.size() as u64).max(source::EXPANSION_FLOOR);
            if n as u64 > room {
                return Err(select(ParseErrorKind::Unsupported {
                    what: "surface size, without a mesh, for a file this small (read it with the mesh's vertex count)",
                    found: n.to_string(),
                }));
            }
            n
        }
    };
    Ok((structure, map, n))
}

/// A CIFTI-2 label file's (`.dlabel.nii`) map of a structure as a
/// parcellation ([`cifti::Cifti::parcellation`]), `selector` being
/// `STRUCTURE[:MAP]`.
fn read_cifti_parcellation(
    path: &Path,
    data: Vec<u8>,
    selector: Option<&str>,
    n_vertices: Option<usize>,
) -> Result<parcellation::Parcellation, ReadError> {
    let c = cifti::Cifti::parse(data).map_err(|source| ReadError::Parse { path: path.into(), source })?;
    let (structure, map, n) = cifti_selection(path, &c, selector, n_vertices)?;
    c.parcellation(structure, map, n).map_err(|source| ReadError::Select { path: path.into(), source })
}

/// Reads a CIFTI-2 file whole ([`cifti::Cifti::parse`]), to read its maps
/// or write one back into a copy ([`cifti::Cifti::with_surface`], then
/// [`write_atomic`]).
pub fn read_cifti_file(path: &Path) -> Result<cifti::Cifti, ReadError> {
    cifti::Cifti::parse(source::open(path, Expect::Any)?.read_all(path)?)
        .map_err(|source| ReadError::Parse { path: path.into(), source })
}

/// Writes a per-vertex signal in the format the path names
/// ([`SignalFormat::from_path`]; GIfTI, curv and MGH store single
/// precision), atomically. `faces` is the surface's triangle count, which
/// a curv file records.
pub fn write_signal(path: &Path, name: &str, values: &[f64], faces: usize) -> Result<(), WriteError> {
    refuse_bz2(path)?;
    let io = |source| WriteError::Io { path: path.into(), source };
    let gz = path.extension().is_some_and(|e| e == "gz" || e == "mgz");
    let bytes = match SignalFormat::from_path(path) {
        SignalFormat::Csv => return csv::write_signal(path, name, values),
        SignalFormat::Gifti => {
            let mut b = Vec::new();
            gifti::write_arrays(&mut b, &[gifti::signal_array(name, values)], gifti::WriteOptions::default())
                .map_err(io)?;
            b
        }
        SignalFormat::Curv => freesurfer::curv_bytes(values, faces).map_err(io)?,
        SignalFormat::Mgh => freesurfer::mgh_bytes(values).map_err(io)?,
    };
    write_atomic(path, &bytes, gz)
}

/// Writes a parcellation in the format the path names, atomically:
/// `.annot` (FreeSurfer: the keys become the table's rows,
/// [`freesurfer::annot_bytes`]), `.label.gii` (GIfTI: the keys and their
/// table kept, [`gifti::label_file`]) or `.csv` (a column `key`, −1 for
/// no region).
pub fn write_parcellation(path: &Path, p: &parcellation::Parcellation) -> Result<(), WriteError> {
    let io = |source| WriteError::Io { path: path.into(), source };
    let name = path.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    if name.ends_with(".annot") {
        write_atomic(path, &freesurfer::annot_bytes(p).map_err(io)?, false)
    } else if name.ends_with(".label.gii") {
        let mut bytes = Vec::new();
        gifti::write_parcellation(&mut bytes, p, gifti::WriteOptions::default()).map_err(io)?;
        write_atomic(path, &bytes, false)
    } else if name.ends_with(".csv") {
        let keys: Vec<f64> = p.keys.iter().map(|&k| f64::from(k)).collect();
        csv::write_signal(path, "key", &keys)
    } else {
        Err(WriteError::UnknownParcellationFormat { path: path.into() })
    }
}

/// Writes `bytes` (gzipped when `gz`) to a temporary file beside `path`,
/// then renames it over `path`, so readers never see a partial file.
pub fn write_atomic(path: &Path, bytes: &[u8], gz: bool) -> Result<(), WriteError> {
    let io = |source| WriteError::Io { path: path.into(), source };
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
    let result = (|| {
        let file = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(file);
        if gz {
            let mut enc = flate2::write::GzEncoder::new(&mut w, flate2::Compression::default());
            enc.write_all(bytes)?;
            enc.finish()?;
        } else {
            w.write_all(bytes)?;
        }
        w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io)
}
