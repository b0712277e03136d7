//! Registration of functional shapes as a library: what `fshape match`
//! does, for any caller (the program, atlas estimation, a Python binding,
//! a cluster job).
//!
//! - [`Config`]: the typed configuration (TOML or a value built in code),
//!   checked into a [`Plan`]: the model of fshape-shoot, the stages of a
//!   coarse-to-fine schedule, the optimiser's settings and the metrics of
//!   the unknowns.
//! - [`optimize`]: L-BFGS with a strong Wolfe line search and the paper's
//!   adaptive gradient descent, with a serde [`optimize::State`].
//! - [`unknowns`]: the packing of (p_0, p^f) into the optimiser's
//!   unknowns in their metrics, and J as an optimiser objective.
//! - [`Session`]: runs the stages with a checkpoint after every iteration,
//!   resumes from one (validated against the problem first) to the same
//!   bits as an uninterrupted run, and reports to an [`Observer`].
//! - [`ops`]: the operations the program, its demos and the Python
//!   package share (a registration: request in, [`ops::Registration`] out).
//! - [`demo`]: the paper's experimental settings built from shipped data.
//!
//! ```
//! use fshape_match::{Config, Session};
//! use fshape_mesh::test_support::perturbed_icosphere;
//! let source = perturbed_icosphere(1, 0.0, 1);
//! let target = perturbed_icosphere(1, 0.05, 2);
//! let mut config: Config = Config::parse(
//!     "[deformation]\nwidths = [0.5]\n[attachment]\nkernel_geom = \"gaussian:0.3\"\n",
//! )?;
//! config.optimizer.max_iterations = 5;
//! let mut session = Session::new(&source, &target, &config)?;
//! session.run(&mut ())?;
//! let result = session.result()?;
//! assert!(result.energies.attachment < result.stages[0].initial.attachment);
//! # Ok::<(), fshape_match::MatchError>(())
//! ```

use std::path::{Path, PathBuf};

pub mod atlas;
mod config;
pub mod demo;
pub mod linalg;
pub mod ops;
pub mod optimize;
pub mod prealign;
pub mod precondition;
pub mod quality;
pub mod record;
pub mod regression;
pub mod resolution;
pub mod runner;
pub mod session;
pub mod transfer;
pub mod unknowns;

pub use atlas::{Atlas, AtlasResult, Cluster, Local, SubjectResult};
pub use config::{
    AtlasSection, AttachmentSection, Config, DeformationSection, GrassKernelSpec, IntegratorSection, MethodKind,
    ModelSection, NormKind, OptimizerSection, Plan, PositionKernel, Scales, ScheduleSection, SignalKernelSpec,
    StageSpec, StageTable, TemplateKind,
};
pub use prealign::{AlignKind, Alignment, Moving, PrealignSection};
pub use quality::{ChannelQuality, Quality, quality};
pub use regression::{Regress, RegressionResult, Visit};
pub use runner::{
    CHECKPOINT_FORMAT, Checkpoint, Control, Current, Iteration, Observer, Observers, Outcome, Runner, StageRecord,
    StageSetup, Staged, StopAfter, UNCHECKED_FORMAT,
};
pub use session::{MatchResult, Session, fingerprint};
pub use unknowns::{Metric, Metrics};

/// Why a registration could not be set up or run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MatchError {
    /// A configuration value is out of range (`key`: its dotted name).
    #[error("configuration: {key}: {message}")]
    Config {
        /// The key, e.g. `model.gamma_v`.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The configuration could not be read: a syntax error, an unknown key,
    /// a value of the wrong type or spelling (toml's message gives the line).
    #[error("configuration{}: {message}", if key.is_empty() { String::new() } else { format!(": {key}") })]
    ConfigSyntax {
        /// The dotted key where reading failed (empty when unknown).
        key: String,
        /// toml's message, with line and column.
        message: String,
    },
    /// An error about a file's contents, naming the file.
    #[error("{}: {source}", path.display())]
    InFile {
        /// The file.
        path: PathBuf,
        /// What is wrong in it.
        source: Box<MatchError>,
    },
    /// A file could not be read or written.
    #[error("{}: {message}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// The system's message.
        message: String,
    },
    /// A checkpoint does not belong to this problem, or is damaged.
    #[error("{problem}")]
    Checkpoint {
        /// What is wrong, and what to do.
        problem: String,
    },
    /// Two shapes that must be of one kind (cell type and dimension) are
    /// not: source and target, template and subject, a stage template and
    /// its source, the shapes a quality or a transfer compares.
    #[error("{0}: shapes of one kind (the same cell type in the same dimension) are needed")]
    Kinds(String),
    /// Stage templates that do not fit the schedule or the source.
    #[error("stage templates: {0}")]
    StageTemplates(String),
    /// A stage index beyond the schedule.
    #[error("stage {stage} does not exist: the schedule has {stages} stage(s), counted from 0")]
    NoSuchStage {
        /// The index asked for.
        stage: usize,
        /// The schedule's length.
        stages: usize,
    },
    /// A vector of unknowns of the wrong length for its stage.
    #[error("{got} unknowns given for stage {stage}, which has {expected}")]
    UnknownsLength {
        /// The stage (from 0).
        stage: usize,
        /// The length given.
        got: usize,
        /// The stage's number of unknowns.
        expected: usize,
    },
    /// An atlas without subjects.
    #[error("an atlas needs at least one subject")]
    NoSubjects,
    /// A shape without the cells, area or extent a computation needs
    /// (which vertex or what, in the message).
    #[error("degenerate shape: {0}")]
    Degenerate(String),
    /// The processes of a distributed atlas gathered a wrong number of
    /// values: they are out of step (different inputs or versions).
    #[error(
        "the atlas's processes gathered {got} values where {expected} were expected: are they running the same inputs and version?"
    )]
    Gather {
        /// Values gathered.
        got: usize,
        /// Values expected (subjects × record width).
        expected: usize,
    },
    /// An argument out of its domain (which, and its value, in the message).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A table the user wrote (a batch's pairs) that cannot be used: the
    /// file, the line (from 1) when one is at fault, and why.
    #[error("{}{}: {message}", path.display(), line.map_or(String::new(), |l| format!(":{l}")))]
    Table {
        /// The table.
        path: PathBuf,
        /// The line at fault.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// A file could not be read (its path, and the line or byte at fault,
    /// in the message).
    #[error(transparent)]
    Read(#[from] fshape_mesh::io::ReadError),
    /// [`Session::result`] before every stage has run.
    #[error("the registration has not finished: run the session to its end first")]
    NotFinished,
    /// Shooting, the signal norm, the kernels or the data attachment refused
    /// their input.
    #[error(transparent)]
    Shoot(#[from] fshape_shoot::ShootError),
    /// A mesh could not be built.
    #[error(transparent)]
    Shape(#[from] fshape_mesh::ShapeError),
    /// A group test refused its covariates, contrast or maps.
    #[error(transparent)]
    Stats(#[from] fshape_stats::StatsError),
    /// A stage's template or target could not be simplified to the count
    /// `[schedule] vertices` gives.
    #[error("simplifying the {what} to {vertices} vertices for stage {stage}: {source}")]
    Simplify {
        /// `source`, `target`, `template` or `subject N`.
        what: String,
        /// The count asked for.
        vertices: usize,
        /// The stage (from 0).
        stage: usize,
        /// The simplifier's reason.
        source: fshape_mesh::SimplifyError,
    },
    /// Stage templates were given twice.
    #[error("stage templates are given both by hand (--stage-templates) and by [schedule] vertices: keep one")]
    StageTemplatesTwice,
    /// Another process of a distributed atlas failed (its own message is
    /// on that process's output).
    #[error("subject {subject} failed on process {rank} of the atlas")]
    Remote {
        /// The subject (from 0).
        subject: usize,
        /// The process that evaluated it.
        rank: usize,
    },
}

impl MatchError {
    /// The same error, naming the file it came from.
    pub fn in_file(self, path: &Path) -> MatchError {
        MatchError::InFile { path: path.to_path_buf(), source: Box::new(self) }
    }
}
