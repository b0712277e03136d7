//! The exceptions, by what went wrong, so that a script can catch what it
//! can act on: `FShapeError` (a `ValueError`) and its kinds —
//! `InputError` (a file or value given is not what it must be; a file's
//! `path` and, for text, `line`), `ConfigError` (the configuration),
//! `CheckpointError` (a checkpoint damaged or of other inputs) and
//! `DivergenceError` (the integration left finite numbers). Each library
//! error is sorted here by its type and variant ([`Fault`]), never by its
//! message.

use std::path::PathBuf;

use fshape_match::MatchError;
use fshape_mesh::io::{Location, ReadError};
use fshape_shoot::ShootError;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

pyo3::create_exception!(
    fshape,
    FShapeError,
    PyValueError,
    "Bad input or a failed computation; the message says what and where. Its subclasses say which kind."
);
pyo3::create_exception!(
    fshape,
    InputError,
    FShapeError,
    "A file or value given is not what it must be; `path` and `line` name the file and, for text, the line (None when not known)."
);
pyo3::create_exception!(fshape, ConfigError, FShapeError, "The configuration: a key, its value or its TOML.");
pyo3::create_exception!(
    fshape,
    CheckpointError,
    FShapeError,
    "A checkpoint that is damaged, of another format, or of other inputs or settings."
);
pyo3::create_exception!(
    fshape,
    DivergenceError,
    FShapeError,
    "The integration left finite numbers or collapsed a cell: reduce the momenta or add time steps."
);

/// Which exception an error raises.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Input,
    Config,
    Checkpoint,
    Divergence,
    /// Neither the input's nor the configuration's fault (writing a file,
    /// a run not finished): `FShapeError` itself.
    Other,
}

/// An error with its kind and, for a file, where.
pub(crate) struct Fault {
    kind: Kind,
    message: String,
    path: Option<PathBuf>,
    line: Option<usize>,
}

impl Fault {
    fn new(kind: Kind, message: impl std::fmt::Display) -> Fault {
        Fault { kind, message: message.to_string(), path: None, line: None }
    }

    fn at(mut self, path: &std::path::Path, line: Option<usize>) -> Fault {
        self.path = Some(path.to_path_buf());
        self.line = line;
        self
    }
}

impl From<Fault> for PyErr {
    fn from(f: Fault) -> PyErr {
        let e = match f.kind {
            Kind::Input => InputError::new_err(f.message),
            Kind::Config => ConfigError::new_err(f.message),
            Kind::Checkpoint => CheckpointError::new_err(f.message),
            Kind::Divergence => DivergenceError::new_err(f.message),
            Kind::Other => FShapeError::new_err(f.message),
        };
        if f.kind == Kind::Input {
            Python::attach(|py| {
                let value = e.value(py);
                let path = f.path.map(|p| p.display().to_string());
                // Setting attributes on a fresh exception instance cannot
                // fail short of memory; the message already says it all.
                let _ = value.setattr("path", path);
                let _ = value.setattr("line", f.line);
            });
        }
        e
    }
}

/// What a library error is, by its type.
pub(crate) trait Classify: std::fmt::Display {
    fn fault(&self) -> Fault {
        Fault::new(Kind::Input, self)
    }
}

impl Classify for String {}
impl Classify for &str {}
impl Classify for fshape_mesh::ShapeError {}
impl Classify for fshape_stats::StatsError {
    fn fault(&self) -> Fault {
        let fault = Fault::new(Kind::Input, self);
        match self {
            fshape_stats::StatsError::Table { table, line, .. } => fault.at(std::path::Path::new(table), Some(*line)),
            _ => fault,
        }
    }
}
impl Classify for fshape_mesh::CoarsenError {}
impl Classify for fshape_fem::FemError {}
impl Classify for fshape_varifold::VarifoldError {}
impl Classify for numpy::AsSliceError {}
impl Classify for numpy::ndarray::ShapeError {}
impl Classify for fshape_match::record::RecordError {}

impl Classify for ReadError {
    fn fault(&self) -> Fault {
        let line = match self.location() {
            Some(Location::Line(l)) => Some(l),
            _ => None,
        };
        Fault::new(Kind::Input, self).at(self.path(), line)
    }
}

impl Classify for fshape_mesh::io::WriteError {
    fn fault(&self) -> Fault {
        match self {
            // A name whose format fshape does not write is the caller's.
            fshape_mesh::io::WriteError::UnknownFormat { path } => Fault::new(Kind::Input, self).at(path, None),
            _ => Fault::new(Kind::Other, self),
        }
    }
}

impl Classify for std::io::Error {
    fn fault(&self) -> Fault {
        Fault::new(Kind::Other, self)
    }
}

impl Classify for ShootError {
    fn fault(&self) -> Fault {
        let kind = match self {
            ShootError::Diverged { .. } | ShootError::Collapsed { .. } | ShootError::Drift { .. } => Kind::Divergence,
            _ => Kind::Input,
        };
        Fault::new(kind, self)
    }
}

impl Classify for MatchError {
    fn fault(&self) -> Fault {
        match self {
            MatchError::Config { .. } | MatchError::ConfigSyntax { .. } => Fault::new(Kind::Config, self),
            MatchError::Checkpoint { .. } => Fault::new(Kind::Checkpoint, self),
            MatchError::Shoot(e) => Fault { message: self.to_string(), ..e.fault() },
            MatchError::InFile { path, source } => {
                let inner = source.fault();
                let fault = Fault { message: self.to_string(), ..inner };
                if fault.kind == Kind::Input && fault.path.is_none() { fault.at(path, None) } else { fault }
            }
            MatchError::File { path, .. } => Fault::new(Kind::Input, self).at(path, None),
            MatchError::Table { path, line, .. } => Fault::new(Kind::Input, self).at(path, *line),
            MatchError::Read(e) => e.fault(),
            MatchError::NotFinished | MatchError::Gather { .. } | MatchError::Remote { .. } => {
                Fault::new(Kind::Other, self)
            }
            _ => Fault::new(Kind::Input, self),
        }
    }
}

impl Classify for fshape_report::ReportError {
    fn fault(&self) -> Fault {
        use fshape_report::ReportError as R;
        match self {
            R::Read(e) => Fault { message: self.to_string(), ..e.fault() },
            R::Record(_) | R::File { .. } | R::NotAnOutput { .. } | R::Shape(_) | R::Simplify(_) => {
                Fault::new(Kind::Input, self)
            }
            _ => Fault::new(Kind::Other, self),
        }
    }
}

/// The exception for `e`.
pub(crate) fn err<E: Classify>(e: E) -> PyErr {
    e.fault().into()
}

/// `FShapeError` itself, for what is neither bad input nor a failed
/// computation (a run the progress callback stopped).
pub(crate) fn other(message: impl std::fmt::Display) -> PyErr {
    Fault::new(Kind::Other, message).into()
}
