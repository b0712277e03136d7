//! The run records: what `fshape match`, `atlas`, `shoot`, `regress` and
//! `batch` write as summary.json (batch: index.json), as one type per kind, written and
//! read back through the same type by every crate that touches them (the
//! report, batch, stats, the demos, Python). `fshape stats` writes a
//! [`StatsRecord`].
//!
//! Each record starts with two keys: `kind` (`match`, `atlas`, `shoot`,
//! `batch`, `stats`, `regression`) and `format` ([`FORMAT`]); the rest are the keys users
//! and scripts already read, unchanged. A file written before the records
//! were typed has neither: its kind is recognised by its keys (a group
//! test has `contrast`, an atlas `subjects`, a batch index `rows`, a shoot `hamiltonian_drift`, a match
//! `source` and `target`) and its format is 0. Keys added since (the match
//! quality, the scales, a stage's setup) are optional or default on read,
//! so the guide's summaries of 2026-11 still read (a test). A record of a
//! newer format is refused rather than half read.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::{Alignment, Metrics, Quality, Scales, StageRecord};

/// The format the records are written in. Raise it when a key changes its
/// meaning or disappears (adding an optional key does not).
pub const FORMAT: u32 = 1;

/// What kind of run wrote a record.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// `fshape match`: one registration.
    Match,
    /// `fshape atlas`: a template and its subjects.
    Atlas,
    /// `fshape shoot`: a geodesic from given momenta.
    Shoot,
    /// `fshape batch`: the index of many registrations.
    Batch,
    /// `fshape stats`: a group analysis.
    Stats,
    /// `fshape regress`: one subject's geodesic regression.
    Regression,
}

impl Kind {
    /// The name in `kind`.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Match => "match",
            Kind::Atlas => "atlas",
            Kind::Shoot => "shoot",
            Kind::Batch => "batch",
            Kind::Stats => "stats",
            Kind::Regression => "regression",
        }
    }
}

/// A record that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be read.
    #[error("{}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The path names a FIFO, a device or a folder, not a file.
    #[error("{}: not a regular file (a FIFO, a device or a folder?): a run record is a file", path.display())]
    NotAFile {
        /// The path.
        path: PathBuf,
    },
    /// The file is not JSON.
    #[error("{}: not JSON ({message})", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// serde_json's account, with its line and column.
        message: String,
    },
    /// A key is missing or holds the wrong kind of value.
    #[error("{}: `{key}`: {message}", path.display())]
    Field {
        /// The file.
        path: PathBuf,
        /// The key's path (`stages[0].initial.value`).
        key: String,
        /// What was wrong.
        message: String,
    },
    /// A record of another kind than asked for.
    #[error("{}: the record of an fshape {found} run, not of {expected}", path.display(), found = found.name(), expected = expected.name())]
    Kind {
        /// The file.
        path: PathBuf,
        /// What it holds.
        found: Kind,
        /// What was asked for.
        expected: Kind,
    },
    /// Written by a newer fshape.
    #[error("{}: record format {found}, newer than this fshape reads ({FORMAT}); update fshape", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// Its `format`.
        found: u32,
    },
    /// Neither a `kind` nor the keys of any kind.
    #[error("{}: not an fshape run record (no `kind`, and not the keys of a match, atlas, shoot, batch or stats record)", path.display())]
    Unknown {
        /// The file.
        path: PathBuf,
    },
}

fn kind_match() -> Kind {
    Kind::Match
}
fn kind_atlas() -> Kind {
    Kind::Atlas
}
fn kind_shoot() -> Kind {
    Kind::Shoot
}
fn kind_batch() -> Kind {
    Kind::Batch
}
fn kind_stats() -> Kind {
    Kind::Stats
}

/// `fshape match`'s summary.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MatchRecord {
    /// [`Kind::Match`].
    #[serde(default = "kind_match")]
    pub kind: Kind,
    /// [`FORMAT`] (0: written before the records were typed).
    #[serde(default)]
    pub format: u32,
    /// The source's file, as given.
    pub source: String,
    /// The target's file, as given.
    pub target: String,
    /// The configuration file, as given.
    pub config: String,
    /// The model's name (`metamorphosis`, …).
    pub model: String,
    /// The signal norm's name.
    pub norm: String,
    /// The weights as written.
    pub gamma_v: f64,
    /// See `gamma_v`.
    pub gamma_f: f64,
    /// See `gamma_v`.
    pub gamma_w: f64,
    /// The scales the weights were normalised by (`null`: as written).
    #[serde(default)]
    pub scales: Option<Scales>,
    /// The weights the model used, (γ_V, γ_f, γ_W).
    #[serde(default)]
    pub effective_weights: [f64; 3],
    /// Time steps of the geodesic.
    pub steps: usize,
    /// The metrics of the unknowns.
    #[serde(default)]
    pub metrics: Metrics,
    /// Every stage, with its iterations.
    pub stages: Vec<StageRecord>,
    /// J at the result.
    pub final_value: f64,
    /// Its path energy.
    pub final_energy: f64,
    /// Its data term.
    pub final_attachment: f64,
    /// √H_0: the geodesic distance (metamorphosis; the path energy's root
    /// otherwise).
    #[serde(default)]
    pub geodesic_distance: f64,
    /// H along the geodesic.
    #[serde(default)]
    pub hamiltonian: Vec<f64>,
    /// How close the matched shape is to the target (fractions of the
    /// target's diagonal and signal range); `None` in records from before
    /// it was measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<Quality>,
    /// How close the template was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality_before: Option<Quality>,
    /// The pre-alignment the registration ran after (`[prealign]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prealign: Option<Alignment>,
    /// Accepted iterations over all stages.
    pub iterations: usize,
    /// Objective evaluations.
    pub evaluations: usize,
    /// Wall time, with the outputs.
    pub seconds: f64,
    /// The files written beside it.
    #[serde(default)]
    pub files: Vec<String>,
}

/// One subject of an atlas.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SubjectRecord {
    /// Its mesh file, as given.
    pub file: String,
    /// J_i at the result.
    pub value: f64,
    /// Its path energy.
    pub energy: f64,
    /// Its data term.
    pub attachment: f64,
    /// A at the start (the initial template against the subject).
    pub attachment_start: f64,
    /// The share of it the atlas removed, 1 − attachment/attachment_start
    /// (`None` for a subject that is the initial template, A = 0 at the
    /// start).
    pub attachment_fall: Option<f64>,
    /// How close the template shot by the subject's momenta came to it.
    pub quality: Quality,
    /// How close the estimated template itself is.
    pub template_quality: Quality,
    /// The pre-alignment that moved the subject onto the initial template.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prealign: Option<Alignment>,
    /// Its folder, beside summary.json.
    pub directory: String,
}

/// A principal mode of an atlas's initial momenta.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModeRecord {
    /// Standard deviation, in √(2 × energy).
    pub sd: f64,
    /// Share of the total variance.
    pub share: f64,
}

/// `fshape atlas`'s summary.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AtlasRecord {
    /// [`Kind::Atlas`].
    #[serde(default = "kind_atlas")]
    pub kind: Kind,
    /// [`FORMAT`].
    #[serde(default)]
    pub format: u32,
    /// The initial template's file.
    pub template_start: String,
    /// The configuration file, as given.
    pub config: String,
    /// The model's name.
    pub model: String,
    /// The signal norm's name.
    pub norm: String,
    /// The weights as written.
    pub gamma_v: f64,
    /// See `gamma_v`.
    pub gamma_f: f64,
    /// See `gamma_v`.
    pub gamma_w: f64,
    /// The scales the weights were normalised by.
    #[serde(default)]
    pub scales: Option<Scales>,
    /// The weights the model used.
    #[serde(default)]
    pub effective_weights: [f64; 3],
    /// Per stage, J and its parts per iteration: means over the subjects.
    pub stages: Vec<StageRecord>,
    /// The mean J at the result.
    pub final_value: f64,
    /// Its path energy.
    pub final_energy: f64,
    /// Its data term.
    pub final_attachment: f64,
    /// Every subject.
    pub subjects: Vec<SubjectRecord>,
    /// The mean over the subjects of their mean distances after matching.
    pub mean_distance: f64,
    /// The same for the signal error (`None` unless every subject has one).
    pub mean_signal_rms: Option<f64>,
    /// With several maps, the same for each map (the first is
    /// `mean_signal_rms`); empty with one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub mean_signal_rms_per_channel: Vec<Option<f64>>,
    /// The principal modes of the initial momenta (energy metric).
    #[serde(default)]
    pub modes: Vec<ModeRecord>,
    /// The smallest share of a subject's data term the atlas removed
    /// (`None` when every subject started at A = 0).
    #[serde(default)]
    pub min_attachment_fall: Option<f64>,
    /// Accepted iterations.
    pub iterations: usize,
    /// Objective evaluations.
    pub evaluations: usize,
    /// Wall time, with the outputs.
    pub seconds: f64,
    /// The files written beside it.
    #[serde(default)]
    pub files: Vec<String>,
}

/// The end of a shot geodesic against its start.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FinalState {
    /// Largest vertex displacement |x_1 − x_0|.
    pub max_displacement: f64,
    /// Root-mean-square displacement.
    pub rms_displacement: f64,
    /// ‖f_1 − f_0‖∞.
    pub max_signal_change: f64,
    /// Largest momentum norm |p_1|.
    pub max_momentum: f64,
}

/// Where a shot's time went, seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShootTiming {
    /// All of it.
    pub total: f64,
    /// In the kernel sums.
    pub kernels: f64,
    /// In the finite-element operators.
    pub fem: f64,
}

/// `fshape shoot`'s summary.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShootRecord {
    /// [`Kind::Shoot`].
    #[serde(default = "kind_shoot")]
    pub kind: Kind,
    /// [`FORMAT`].
    #[serde(default)]
    pub format: u32,
    /// The shape shot, as given.
    pub source: String,
    /// The configuration file, as given.
    pub config: String,
    /// The model's name.
    pub model: String,
    /// The signal norm's name.
    pub norm: String,
    /// The integrator's name.
    pub integrator: String,
    /// Time steps.
    pub steps: usize,
    /// H(z_k) at every step k = 0..N.
    pub hamiltonian: Vec<f64>,
    /// Relative drift max_k |H_k − H_0| / |H_0| (0 when H_0 = 0).
    pub hamiltonian_drift: f64,
    /// The times of the states written.
    pub times: Vec<f64>,
    /// The files written beside it.
    pub files: Vec<String>,
    /// The end state against the start.
    pub final_state: FinalState,
    /// Where the time went.
    pub seconds: ShootTiming,
}

/// Where a batch row stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Its summary.json is there.
    Done,
    /// Its error.txt is there (or its line is invalid).
    Failed,
    /// A checkpoint and no result.
    Incomplete,
    /// Not started.
    Pending,
}

impl Status {
    /// The name in index.json and index.csv.
    pub fn name(self) -> &'static str {
        match self {
            Status::Done => "done",
            Status::Failed => "failed",
            Status::Incomplete => "incomplete",
            Status::Pending => "pending",
        }
    }
}

/// A row of a batch index: its pair and, when done, its figures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BatchRow {
    /// Its number, from 1.
    pub row: usize,
    /// Its line in the pairs table.
    pub line: usize,
    /// Its folder's name.
    pub name: String,
    /// The source's file.
    pub source: String,
    /// The target's file.
    pub target: String,
    /// Where it stands.
    pub status: Status,
    /// J at the result.
    pub value: Option<f64>,
    /// The data term at the result.
    pub attachment: Option<f64>,
    /// [`Quality::mean_distance`] at the result.
    pub mean_distance: Option<f64>,
    /// [`Quality::p95_distance`].
    pub p95_distance: Option<f64>,
    /// [`Quality::target_within_1pct`].
    pub target_within_1pct: Option<f64>,
    /// [`Quality::signal_rms`].
    pub signal_rms: Option<f64>,
    /// Accepted iterations.
    pub iterations: Option<u64>,
    /// Wall time.
    pub seconds: Option<f64>,
    /// Why it failed.
    pub error: Option<String>,
}

/// `fshape batch`'s index.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BatchIndex {
    /// [`Kind::Batch`].
    #[serde(default = "kind_batch")]
    pub kind: Kind,
    /// [`FORMAT`].
    #[serde(default)]
    pub format: u32,
    /// The pairs table.
    pub pairs: String,
    /// The configuration file, as given.
    pub config: String,
    /// Every row.
    pub rows: Vec<BatchRow>,
    /// Rows done.
    pub done: usize,
    /// Rows failed.
    pub failed: usize,
    /// Rows with a checkpoint and no result.
    pub incomplete: usize,
    /// Rows not started.
    pub pending: usize,
}

/// `fshape stats`'s summary.json: the design, the contrast, and per map
/// its peak and what reaches the level.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StatsRecord {
    /// [`Kind::Stats`].
    #[serde(default = "kind_stats")]
    pub kind: Kind,
    /// [`FORMAT`].
    #[serde(default)]
    pub format: u32,
    /// The atlas's folder, as given.
    pub atlas: String,
    /// The covariates table, as given.
    pub covariates: String,
    /// Subjects tested.
    pub subjects: usize,
    /// Covariates rows that name no subject of the atlas.
    pub rows_not_in_the_atlas: Vec<String>,
    /// The design matrix and its terms.
    pub design: fshape_stats::Design,
    /// The contrast tested.
    pub contrast: fshape_stats::Contrast,
    /// Permutations, seed, tail, TFCE.
    pub inference: fshape_stats::Inference,
    /// The level of the counts and of the thresholded pictures.
    pub alpha: f64,
    /// The template's masked vertices, left out of every test.
    #[serde(default)]
    pub masked_vertices: usize,
    /// Each map's test.
    pub maps: Vec<MapRecord>,
    /// The test on the momenta's principal scores.
    pub multivariate: Option<ScoresRecord>,
    /// Wall time.
    pub seconds: f64,
}

/// One map's test in a [`StatsRecord`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapRecord {
    /// Its name (`signal`, `signal_2`, `momentum`, …).
    pub map: String,
    /// What it measures.
    pub description: String,
    /// `t` or `F`.
    pub statistic: String,
    /// Degrees of freedom (numerator, denominator).
    pub dof: (usize, usize),
    /// The tested value (|t| when two-sided) that reaches p_FWE ≤ alpha.
    pub critical: f64,
    /// The vertex of the largest tested value.
    pub peak: Peak,
    /// What the maximum statistic's correction finds.
    pub found: Found,
    /// What TFCE's correction finds, when run.
    pub tfce: Option<Found>,
    /// Its files in the folder.
    pub files: Vec<String>,
}

/// A map's peak.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Peak {
    /// The template's vertex.
    pub vertex: usize,
    /// Its position.
    pub position: Vec<f64>,
    /// The statistic there.
    pub statistic: f64,
    /// The contrast's effect there.
    pub effect: f64,
    /// Its uncorrected p.
    pub p_uncorrected: f64,
    /// Its corrected p.
    pub p_fwe: f64,
}

/// Where a corrected p reaches the level.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Found {
    /// Vertices with corrected p ≤ alpha.
    pub vertices: usize,
    /// Their share of the tested area (length for a curve).
    pub area_share: f64,
    /// The smallest corrected p.
    pub min_p_fwe: f64,
}

/// The multivariate test on the momenta's principal scores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScoresRecord {
    /// The statistic's name.
    pub test: String,
    /// Scores entered (the first ones).
    pub modes: usize,
    /// Its value.
    pub statistic: f64,
    /// Its permutation p.
    pub p: f64,
}

/// One visit of a regression, as fitted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VisitRecord {
    /// Its mesh file, as given.
    pub file: String,
    /// Its age, as given.
    pub age: f64,
    /// Its time on the geodesic, (age − t0)/span.
    pub time: f64,
    /// Its weight.
    pub weight: f64,
    /// A(fitted state at its time; the visit).
    pub attachment: f64,
    /// How close the fitted state at its time is to it.
    pub quality: Quality,
    /// How close the baseline is to it.
    pub quality_before: Quality,
    /// Its pre-alignment onto the baseline (`[prealign]`), if any: the
    /// qualities are of the visit as aligned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prealign: Option<Alignment>,
}

/// `fshape regress`'s summary.json: one subject's regression.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegressionRecord {
    /// [`Kind::Regression`].
    pub kind: Kind,
    /// [`FORMAT`].
    pub format: u32,
    /// The subject, as the visits table names it (`subject` without a
    /// `subject` column).
    pub subject: String,
    /// The visits table, as given.
    pub visits_table: String,
    /// The configuration file, as given.
    pub config: String,
    /// The model's name.
    pub model: String,
    /// The signal norm's name.
    pub norm: String,
    /// The weights as written.
    pub gamma_v: f64,
    /// See `gamma_v`.
    pub gamma_f: f64,
    /// See `gamma_v`.
    pub gamma_w: f64,
    /// The scales the weights were normalised by (`null`: as written).
    pub scales: Option<Scales>,
    /// The weights the model used, (γ_V, γ_f, γ_W).
    pub effective_weights: [f64; 3],
    /// Uniform time steps of the geodesic (a node is added at each visit).
    pub steps: usize,
    /// The metrics of the unknowns.
    pub metrics: Metrics,
    /// The age at the baseline (t = 0).
    pub t0: f64,
    /// The span of ages mapped onto [0, 1]: rates per unit age are the
    /// geodesic's velocities divided by it.
    pub span: f64,
    /// The age at t = 1 (the latest visit's).
    pub t1: f64,
    /// Every visit, in the table's order.
    pub visits: Vec<VisitRecord>,
    /// Every stage, with its iterations.
    pub stages: Vec<StageRecord>,
    /// J at the result.
    pub final_value: f64,
    /// Its path energy.
    pub final_energy: f64,
    /// Its data term, Σ_v w_v A_v.
    pub final_attachment: f64,
    /// √H_0.
    pub geodesic_distance: f64,
    /// H along the geodesic.
    pub hamiltonian: Vec<f64>,
    /// Accepted iterations over all stages.
    pub iterations: usize,
    /// Objective evaluations.
    pub evaluations: usize,
    /// Wall time, with the outputs.
    pub seconds: f64,
    /// The files written beside it.
    pub files: Vec<String>,
}

/// Any record, read by its kind.
#[derive(Clone, Debug, PartialEq)]
pub enum Record {
    /// A registration.
    Match(Box<MatchRecord>),
    /// An atlas.
    Atlas(Box<AtlasRecord>),
    /// A shot geodesic.
    Shoot(Box<ShootRecord>),
    /// A batch index.
    Batch(Box<BatchIndex>),
    /// A group test.
    Stats(Box<StatsRecord>),
    /// A geodesic regression.
    Regression(Box<RegressionRecord>),
}

impl Record {
    /// Reads the record in `path`, whatever its kind.
    pub fn read(path: &Path) -> Result<Record, RecordError> {
        let (kind, value) = read_value(path)?;
        Ok(match kind {
            Kind::Match => Record::Match(Box::new(typed(path, value)?)),
            Kind::Atlas => Record::Atlas(Box::new(typed(path, value)?)),
            Kind::Shoot => Record::Shoot(Box::new(typed(path, value)?)),
            Kind::Batch => Record::Batch(Box::new(typed(path, value)?)),
            Kind::Stats => Record::Stats(Box::new(typed(path, value)?)),
            Kind::Regression => Record::Regression(Box::new(typed(path, value)?)),
        })
    }

    /// Its kind.
    pub fn kind(&self) -> Kind {
        match self {
            Record::Match(_) => Kind::Match,
            Record::Atlas(_) => Kind::Atlas,
            Record::Shoot(_) => Kind::Shoot,
            Record::Batch(_) => Kind::Batch,
            Record::Stats(_) => Kind::Stats,
            Record::Regression(_) => Kind::Regression,
        }
    }
}

/// Reading and writing one kind of record.
pub trait RunRecord: Serialize + serde::de::DeserializeOwned {
    /// Its kind.
    const KIND: Kind;

    /// Reads it from `path`, refusing a record of another kind or of a
    /// newer format, and naming the key that is missing or wrong.
    fn read(path: &Path) -> Result<Self, RecordError> {
        let (kind, value) = read_value(path)?;
        if kind != Self::KIND {
            return Err(RecordError::Kind { path: path.to_path_buf(), found: kind, expected: Self::KIND });
        }
        typed(path, value)
    }

    /// As written to summary.json: pretty JSON.
    fn to_json(&self) -> Vec<u8> {
        // The records hold numbers, strings, lists and maps with string
        // keys: serde_json cannot fail on them.
        serde_json::to_vec_pretty(self).expect("a run record serialises")
    }
}

impl RunRecord for MatchRecord {
    const KIND: Kind = Kind::Match;
}
impl RunRecord for AtlasRecord {
    const KIND: Kind = Kind::Atlas;
}
impl RunRecord for ShootRecord {
    const KIND: Kind = Kind::Shoot;
}
impl RunRecord for BatchIndex {
    const KIND: Kind = Kind::Batch;
}
impl RunRecord for StatsRecord {
    const KIND: Kind = Kind::Stats;
}
impl RunRecord for RegressionRecord {
    const KIND: Kind = Kind::Regression;
}

/// The file's JSON and its kind (from `kind`, or from its keys), its
/// format checked.
fn read_value(path: &Path) -> Result<(Kind, serde_json::Value), RecordError> {
    // A regular file only, read no further than its length: a FIFO or a
    // device named as summary.json neither blocks nor fills the memory.
    // Checked before opening (opening a FIFO waits for a writer) and
    // again on the file opened.
    let read_err = |source| RecordError::Read { path: path.to_path_buf(), source };
    let not_regular = || RecordError::NotAFile { path: path.to_path_buf() };
    if !std::fs::metadata(path).map_err(read_err)?.is_file() {
        return Err(not_regular());
    }
    let file = std::fs::File::open(path).map_err(read_err)?;
    let meta = file.metadata().map_err(read_err)?;
    if !meta.is_file() {
        return Err(not_regular());
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0).min(1 << 26));
    std::io::Read::read_to_end(&mut std::io::Read::take(file, meta.len()), &mut bytes).map_err(read_err)?;
    let value: serde_json::Value = serde_json::from_slice(&bytes)
        .map_err(|e| RecordError::Json { path: path.to_path_buf(), message: e.to_string() })?;
    let Some(object) = value.as_object() else {
        return Err(RecordError::Unknown { path: path.to_path_buf() });
    };
    let kind = match object.get("kind") {
        Some(k) => Kind::deserialize(k).map_err(|e| RecordError::Field {
            path: path.to_path_buf(),
            key: "kind".into(),
            message: e.to_string(),
        })?,
        None if object.contains_key("contrast") => Kind::Stats,
        None if object.contains_key("subjects") => Kind::Atlas,
        None if object.contains_key("rows") => Kind::Batch,
        None if object.contains_key("hamiltonian_drift") => Kind::Shoot,
        None if object.contains_key("source") && object.contains_key("target") => Kind::Match,
        None => return Err(RecordError::Unknown { path: path.to_path_buf() }),
    };
    if let Some(f) = object.get("format") {
        let found = f.as_u64().and_then(|f| u32::try_from(f).ok()).ok_or_else(|| RecordError::Field {
            path: path.to_path_buf(),
            key: "format".into(),
            message: format!("{f} is not a format number"),
        })?;
        if found > FORMAT {
            return Err(RecordError::Format { path: path.to_path_buf(), found });
        }
    }
    Ok((kind, value))
}

fn typed<T: serde::de::DeserializeOwned>(path: &Path, value: serde_json::Value) -> Result<T, RecordError> {
    serde_path_to_error::deserialize(value).map_err(|e| RecordError::Field {
        path: path.to_path_buf(),
        key: e.path().to_string(),
        message: e.inner().to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn guide(path: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/guide/src/experiments").join(path)
    }

    #[test]
    fn the_guides_summaries_from_before_the_typed_records_still_read() {
        for case in ["digits/ratio_20", "bunny/h1", "cortex/metamorphosis"] {
            let path = guide(&format!("{case}/summary.json"));
            let r = MatchRecord::read(&path).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!((r.kind, r.format), (Kind::Match, 0), "{case}");
            assert!(r.quality.is_none() && r.prealign.is_none(), "{case}: keys it never had");
            // The values are the file's, not defaults.
            let raw: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
            assert_eq!(r.final_value, raw["final_value"].as_f64().unwrap(), "{case}");
            assert_eq!(r.stages.len(), raw["stages"].as_array().unwrap().len(), "{case}");
            assert_eq!(r.stages[0].iterations.len(), raw["stages"][0]["iterations"].as_array().unwrap().len());
            assert_eq!(r.iterations, raw["iterations"].as_u64().unwrap() as usize, "{case}");
            assert_eq!(r.hamiltonian.len(), raw["hamiltonian"].as_array().unwrap().len(), "{case}");
            assert!(matches!(Record::read(&path).unwrap(), Record::Match(_)), "{case}: its kind from its keys");
            // Written again, it reads back the same and says what it is.
            let again: serde_json::Value = serde_json::from_slice(&r.to_json()).unwrap();
            assert_eq!((again["kind"].as_str(), again["format"].as_u64()), (Some("match"), Some(0)));
        }
    }

    #[test]
    fn the_guides_stats_summaries_from_before_the_typed_records_still_read() {
        for case in ["stats-spheres", "stats-digits"] {
            let path = guide(&format!("{case}/stats_summary.json"));
            let r = StatsRecord::read(&path).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!((r.kind, r.format, r.masked_vertices), (Kind::Stats, 0, 0), "{case}");
            let raw: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
            assert_eq!(r.maps.len(), raw["maps"].as_array().unwrap().len(), "{case}");
            assert_eq!(r.maps[0].peak.statistic, raw["maps"][0]["peak"]["statistic"].as_f64().unwrap(), "{case}");
            assert_eq!(r.design.x.len(), raw["design"]["x"].as_array().unwrap().len(), "{case}");
            assert_eq!(r.contrast.weights.len(), r.design.columns.len(), "{case}");
            assert!(matches!(Record::read(&path).unwrap(), Record::Stats(_)), "{case}: its kind from its keys");
            // Written again, every key the file had is there with its value.
            let again: serde_json::Value = serde_json::from_slice(&r.to_json()).unwrap();
            for (key, value) in raw.as_object().unwrap() {
                assert_eq!(&again[key], value, "{case}: {key}");
            }
        }
    }

    #[test]
    fn a_record_of_another_kind_a_newer_format_or_a_wrong_key_is_refused_by_name() {
        let dir = std::env::temp_dir().join(format!("fshape-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let src = guide("digits/ratio_20/summary.json");
        let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&src).unwrap()).unwrap();
        let write = |name: &str, v: &serde_json::Value| {
            let p = dir.join(name);
            std::fs::write(&p, serde_json::to_vec(v).unwrap()).unwrap();
            p
        };
        let p = write("ok.json", &v);
        let atlas = AtlasRecord::read(&p).unwrap_err().to_string();
        assert!(atlas.contains("the record of an fshape match run, not of atlas"), "{atlas}");
        v["format"] = (FORMAT + 1).into();
        let newer = MatchRecord::read(&write("newer.json", &v)).unwrap_err().to_string();
        assert!(newer.contains(&format!("record format {}", FORMAT + 1)), "{newer}");
        v["format"] = FORMAT.into();
        v["stages"][0]["initial"]["value"] = "high".into();
        let wrong = MatchRecord::read(&write("wrong.json", &v)).unwrap_err().to_string();
        assert!(wrong.contains("`stages[0].initial.value`") && wrong.contains("wrong.json"), "{wrong}");
        let none = Record::read(&write("none.json", &serde_json::json!({"a": 1}))).unwrap_err().to_string();
        assert!(none.contains("not an fshape run record"), "{none}");
        #[cfg(unix)]
        {
            let device = Record::read(Path::new("/dev/zero")).unwrap_err().to_string();
            assert!(device.contains("not a regular file"), "{device}");
            // A FIFO is refused at once: opening it would wait for a writer.
            let fifo = dir.join("fifo.json");
            if std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success()) {
                let e = Record::read(&fifo).unwrap_err().to_string();
                assert!(e.contains("fifo.json") && e.contains("not a regular file"), "{e}");
            }
        }
        std::fs::write(dir.join("bad.json"), b"{\"source\": ").unwrap();
        let bad = Record::read(&dir.join("bad.json")).unwrap_err().to_string();
        assert!(bad.contains("bad.json: not JSON"), "{bad}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
