//! The checkpoint: everything needed to continue a run, as a binary file
//! with a format number; the records of stages and iterations it carries;
//! the checks a checkpoint passes before a run resumes from it.

use std::path::Path;

use fshape_mesh::FShape;
use fshape_shoot::Energies;
use serde::{Deserialize, Serialize};

use crate::MatchError;
use crate::optimize::{State, Stop};

/// The checkpoint format this version writes: 4, binary with a checksum
/// ([`Checkpoint::to_bytes`]). Format 3 (the same without the checksum)
/// is still read; format 2 was JSON.
pub const CHECKPOINT_FORMAT: u32 = 4;

/// The earlier binary format still read: no checksum, so damage in it goes
/// unnoticed until it shows in the run.
pub const UNCHECKED_FORMAT: u32 = 3;

/// The first bytes of a checkpoint file, before its format number.
const CHECKPOINT_MAGIC: &[u8; 16] = b"fshape-checkpnt\n";

/// Where a damaged checkpoint leaves the user.
const START_AGAIN: &str = "start again without --resume (delete the checkpoint or choose another output folder)";

/// J and its parts after one accepted iteration (or at a stage's start).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Iteration {
    /// The iteration within its stage (0: the stage's starting point).
    pub iteration: usize,
    /// J at the accepted point.
    pub value: f64,
    /// The path energy.
    pub energy: f64,
    /// Its signal part.
    pub signal_energy: f64,
    /// A(x_1, f_1; target).
    pub attachment: f64,
    /// The accepted step length.
    pub step: f64,
    /// Objective evaluations of the stage so far.
    pub evaluations: usize,
}

impl Iteration {
    pub(crate) fn of(state: &State, parts: &Energies) -> Iteration {
        Iteration {
            iteration: state.iteration,
            value: parts.value,
            energy: parts.energy,
            signal_energy: parts.signal_energy,
            attachment: parts.attachment,
            step: state.step,
            evaluations: state.evaluations,
        }
    }
}

/// What a stage ran on: the sizes of its shapes and how its kernel sums
/// were evaluated ([`fshape_kernels::SumPath`], as sentences).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct StageSetup {
    /// Vertices of the stage's template.
    pub template_vertices: usize,
    /// Vertices of the stage's target (of the first subject's, for an atlas).
    pub target_vertices: usize,
    /// The deformation kernel's sums: exact, truncated or on a grid.
    pub deformation: String,
    /// The data attachment's position kernel: exact or truncated.
    pub attachment: String,
}

/// A finished stage.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct StageRecord {
    /// The stage's position kernel as written.
    pub kernel_geom: String,
    /// What it ran on (empty in records from before it was kept).
    #[serde(default)]
    pub setup: StageSetup,
    /// Why it stopped.
    pub stop: Stop,
    /// The same, as a sentence.
    pub reason: String,
    /// J's parts at the stage's start.
    pub initial: Iteration,
    /// Every accepted iteration.
    pub iterations: Vec<Iteration>,
}

/// The stage under way: the optimiser's state and its records so far.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Current {
    /// The optimiser's state.
    pub state: State,
    /// J's parts at the stage's start.
    pub initial: Iteration,
    /// Accepted iterations so far.
    pub iterations: Vec<Iteration>,
}

/// Everything needed to continue a registration.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Checkpoint {
    /// [`CHECKPOINT_FORMAT`] of the version that wrote it.
    pub format: u32,
    /// [`crate::fingerprint`] of the inputs: a checkpoint of other inputs is
    /// refused.
    pub fingerprint: String,
    /// Finished stages.
    pub done: Vec<StageRecord>,
    /// The stage under way (`None` between stages).
    pub current: Option<Current>,
    /// The unknowns at the end of the last finished stage (warm start).
    pub warm: Option<Vec<f64>>,
    /// Wall seconds spent on this registration so far, over every run.
    pub seconds: f64,
}

impl Checkpoint {
    /// The file's bytes: the 16-byte magic `fshape-checkpnt\n`, the format
    /// (u32, little endian), the checkpoint in postcard's binary encoding
    /// (f64 as their 8 bytes, so a resumed run continues bit for bit), then
    /// the CRC-32 (crc32fast, little endian) of everything before it. At
    /// 150k vertices a checkpoint holds about 13 million values (the
    /// point, its gradient and L-BFGS's pairs): about 110 MB, where the
    /// JSON of format 2 took 2.7 times as much (22.9 MB against 61.5 MB
    /// measured at 32 492 vertices).
    pub fn to_bytes(&self) -> Result<Vec<u8>, MatchError> {
        let mut bytes = CHECKPOINT_MAGIC.to_vec();
        bytes.extend(self.format.to_le_bytes());
        let mut bytes = postcard::to_extend(self, bytes)
            .map_err(|e| checkpoint_error(format!("could not encode the checkpoint: {e}")))?;
        let crc = crc32fast::hash(&bytes);
        bytes.extend(crc.to_le_bytes());
        Ok(bytes)
    }

    /// A checkpoint from its file's bytes; anything else (another file, an
    /// earlier format, a truncated or damaged file) is an error saying so.
    /// The checksum is checked before anything else is read; a format-3
    /// file (no checksum) is read as it is, and its [`Checkpoint::format`]
    /// says so.
    pub fn from_bytes(bytes: &[u8]) -> Result<Checkpoint, MatchError> {
        if bytes.first() == Some(&b'{') {
            return Err(checkpoint_error(format!(
                "this is a JSON checkpoint of an earlier version (format 2); this version reads formats \
                 {UNCHECKED_FORMAT} and {CHECKPOINT_FORMAT}: {START_AGAIN}"
            )));
        }
        let checked = |bytes: &[u8]| -> Option<usize> {
            let (content, crc) = bytes.split_last_chunk::<4>()?;
            (crc32fast::hash(content) == u32::from_le_bytes(*crc)).then_some(content.len())
        };
        if bytes.len() < CHECKPOINT_MAGIC.len() + 4 && CHECKPOINT_MAGIC.starts_with(&bytes[..bytes.len().min(16)]) {
            return Err(damaged("it ends before its format number"));
        }
        let Some(rest) = bytes.strip_prefix(CHECKPOINT_MAGIC) else {
            if checked(bytes).is_none() && bytes.len() > CHECKPOINT_MAGIC.len() + 8 {
                // A damaged magic is still damage if the rest is a checkpoint.
                let near = bytes.iter().zip(CHECKPOINT_MAGIC).filter(|(a, b)| a == b).count();
                if near >= CHECKPOINT_MAGIC.len() - 2 {
                    return Err(damaged("its first bytes"));
                }
            }
            return Err(checkpoint_error("not an fshape checkpoint (its first bytes are not fshape's)"));
        };
        let Some((format, _)) = rest.split_first_chunk::<4>() else {
            return Err(damaged("it ends before its format number"));
        };
        let format = u32::from_le_bytes(*format);
        let body_end = if format == UNCHECKED_FORMAT {
            bytes.len()
        } else {
            match checked(bytes) {
                Some(end) if format == CHECKPOINT_FORMAT => end,
                Some(_) => {
                    return Err(checkpoint_error(format!(
                        "the checkpoint is of format {format} (this version reads formats {UNCHECKED_FORMAT} and \
                         {CHECKPOINT_FORMAT}); {START_AGAIN}"
                    )));
                }
                None => return Err(damaged("its checksum does not match its contents")),
            }
        };
        let body = &bytes[CHECKPOINT_MAGIC.len() + 4..body_end];
        let (checkpoint, left): (Checkpoint, _) =
            postcard::take_from_bytes(body).map_err(|e| damaged(&format!("it cannot be decoded: {e}")))?;
        if !left.is_empty() {
            return Err(damaged(&format!("{} bytes follow its end", left.len())));
        }
        if checkpoint.format != format {
            return Err(damaged("its two format numbers differ"));
        }
        Ok(checkpoint)
    }

    /// The format number in a checkpoint file's header (its first 20
    /// bytes), or `None` if the file is not one (to warn before resuming
    /// a format-3 file without reading all of it).
    pub fn file_format(path: &Path) -> Option<u32> {
        let mut head = [0u8; 20];
        let (mut file, _) = fshape_mesh::io::open_file(path).ok()?;
        std::io::Read::read_exact(&mut file, &mut head).ok()?;
        let format = head.strip_prefix(CHECKPOINT_MAGIC)?;
        Some(u32::from_le_bytes(format.try_into().ok()?))
    }

    /// [`Checkpoint::from_bytes`] of a file; errors name it.
    pub fn read(path: &Path) -> Result<Checkpoint, MatchError> {
        // Bounded like every input: a device or folder is refused.
        let bytes = fshape_mesh::io::read_bytes(path).map_err(|e| {
            let message = match e {
                fshape_mesh::io::ReadError::Io { source, .. } => source.to_string(),
                other => other.to_string(),
            };
            MatchError::File { path: path.to_path_buf(), message }
        })?;
        Checkpoint::from_bytes(&bytes).map_err(|e| e.in_file(path))
    }
}

impl Checkpoint {
    /// Accepted iterations and objective evaluations over the finished
    /// stages and the one under way.
    pub(crate) fn totals(&self) -> (usize, usize) {
        let mut runs: Vec<(&[Iteration], &Iteration)> =
            self.done.iter().map(|s| (s.iterations.as_slice(), &s.initial)).collect();
        if let Some(current) = &self.current {
            runs.push((&current.iterations, &current.initial));
        }
        let iterations = runs.iter().map(|(its, _)| its.len()).sum();
        let evaluations = runs.iter().map(|(its, initial)| its.last().unwrap_or(initial).evaluations).sum();
        (iterations, evaluations)
    }
}

/// Records the time and writes the checkpoint to `file`, if any.
pub(crate) fn save(checkpoint: &mut Checkpoint, file: Option<&Path>, seconds: f64) -> Result<(), MatchError> {
    checkpoint.seconds = seconds;
    let Some(path) = file else { return Ok(()) };
    let bytes = checkpoint.to_bytes()?;
    fshape_mesh::io::write_atomic(path, &bytes, false)
        .map_err(|e| MatchError::File { path: path.to_path_buf(), message: e.to_string() })
}

fn damaged(why: &str) -> MatchError {
    checkpoint_error(format!("the checkpoint is damaged or truncated ({why}); {START_AGAIN}"))
}

pub(crate) fn checkpoint_error(problem: impl Into<String>) -> MatchError {
    MatchError::Checkpoint { problem: problem.into() }
}

/// FNV-1a, 64 bits: only to recognise a checkpoint of the same inputs
/// (no cryptographic need).
pub(crate) struct Fnv(u64);

impl Fnv {
    pub(crate) fn new() -> Fnv {
        Fnv(0xcbf2_9ce4_8422_2325)
    }

    /// Feeds `bytes`, then a separator.
    pub(crate) fn eat(&mut self, bytes: &[u8]) {
        for &b in bytes.iter().chain(&[0xff]) {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }

    /// Feeds a shape as data: dimension, cell type, coordinates, cells and
    /// signal bit for bit.
    pub(crate) fn shape(&mut self, s: &FShape) {
        self.eat(&(s.dim() as u64).to_le_bytes());
        self.eat(s.kind().name().as_bytes());
        self.eat(&s.points().iter().flat_map(|v| v.to_bits().to_le_bytes()).collect::<Vec<u8>>());
        self.eat(&s.cells().iter().flat_map(|c| (*c as u64).to_le_bytes()).collect::<Vec<u8>>());
        self.eat(&s.signal().unwrap_or(&[]).iter().flat_map(|v| v.to_bits().to_le_bytes()).collect::<Vec<u8>>());
        // The channel count and a mask enter only when they are not the
        // defaults, so one-channel unmasked inputs keep their fingerprints
        // (and their checkpoints) from before channels and masks existed.
        if s.n_channels() > 1 {
            self.eat(b"channels");
            self.eat(&(s.n_channels() as u64).to_le_bytes());
        }
        if let Some(m) = s.mask() {
            self.eat(b"mask");
            self.eat(&m.iter().flat_map(|v| v.to_bits().to_le_bytes()).collect::<Vec<u8>>());
        }
    }

    pub(crate) fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

/// Checks a checkpoint's arrays against a schedule of `stages` stages whose
/// stage k has `len(k)` unknowns: sizes, finite values, a warm start after
/// finished stages, the optimiser's state consistent.
pub(crate) fn validate_arrays(c: &Checkpoint, stages: usize, len: impl Fn(usize) -> usize) -> Result<(), MatchError> {
    if c.done.len() > stages {
        return Err(checkpoint_error(format!(
            "the checkpoint has {} finished stages, but the schedule has {stages}",
            c.done.len()
        )));
    }
    // The warm start is the last finished stage's unknowns, the state
    // those of the stage under way.
    let done = c.done.len();
    let (n_warm, n) = (len(done.saturating_sub(1)), len(done));
    let vector = |what: &str, v: &[f64], n: usize| -> Result<(), MatchError> {
        if v.len() != n {
            return Err(checkpoint_error(format!(
                "the checkpoint's {what} has {} values, the problem has {n} unknowns",
                v.len()
            )));
        }
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(checkpoint_error(format!("the checkpoint's {what}[{i}] is not finite")));
        }
        Ok(())
    };
    if let Some(w) = &c.warm {
        vector("warm", w, n_warm)?;
    }
    if !c.done.is_empty() && c.warm.is_none() {
        return Err(checkpoint_error("the checkpoint has finished stages but no warm start (warm is missing)"));
    }
    if let Some(cur) = &c.current {
        if c.done.len() == stages {
            return Err(checkpoint_error("the checkpoint has a stage under way after the last stage"));
        }
        let s = &cur.state;
        vector("current.state.x", &s.x, n)?;
        vector("current.state.grad", &s.grad, n)?;
        if s.s.len() != s.y.len() {
            return Err(checkpoint_error(format!(
                "the checkpoint's current.state has {} steps s but {} gradient differences y",
                s.s.len(),
                s.y.len()
            )));
        }
        for (k, (a, b)) in s.s.iter().zip(&s.y).enumerate() {
            vector(&format!("current.state.s[{k}]"), a, n)?;
            vector(&format!("current.state.y[{k}]"), b, n)?;
        }
        let scalars = [("value", s.value), ("grad_norm0", s.grad_norm0), ("step", s.step)];
        if let Some((what, v)) = scalars.iter().find(|(_, v)| !v.is_finite()) {
            return Err(checkpoint_error(format!("the checkpoint's current.state.{what} is {v}")));
        }
        if s.values.is_empty() || s.values.iter().any(|v| !v.is_finite()) {
            return Err(checkpoint_error(
                "the checkpoint's current.state.values must be finite values, J at the start first",
            ));
        }
    }
    if !(c.seconds >= 0.0 && c.seconds.is_finite()) {
        return Err(checkpoint_error(format!("the checkpoint's seconds is {}", c.seconds)));
    }
    Ok(())
}
