//! A registration run: the stages of the schedule one after the other,
//! each warm-started from the last, with a checkpoint after every accepted
//! iteration. A run stopped anywhere (an observer's [`Control::Stop`], a
//! kill between two checkpoints) resumes from its checkpoint to the result
//! an uninterrupted run gives, bit for bit: the optimiser's whole state is
//! in the checkpoint, and every evaluation is deterministic.

use std::path::{Path, PathBuf};
use std::time::Instant;

use fshape_mesh::FShape;
use fshape_shoot::{Energies, Problem, Trajectory};
use serde::{Deserialize, Serialize};

use crate::optimize::{Objective, Settings, State, Stop};
use crate::unknowns::{MatchObjective, Unknowns};
use crate::{Config, MatchError, Plan, StageSpec};

/// The checkpoint format this version writes and reads: 3, binary
/// ([`Checkpoint::to_bytes`]); format 2 was JSON.
pub const CHECKPOINT_FORMAT: u32 = 3;

/// The first bytes of a checkpoint file, before its format number.
const CHECKPOINT_MAGIC: &[u8; 16] = b"fshape-checkpnt\n";

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
    /// What it ran on.
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
    /// [`fingerprint`] of the inputs: a checkpoint of other inputs is
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
    /// The file's bytes: the 16-byte magic `fshape-checkpnt\n`, the format (u32, little
    /// endian), then the checkpoint in postcard's binary encoding (f64 as
    /// their 8 bytes, so a resumed run continues bit for bit). At 150k
    /// vertices a checkpoint holds about 13 million values (the point,
    /// its gradient and L-BFGS's pairs): about 110 MB, where the JSON of
    /// format 2 took 2.7 times as much (22.9 MB against 61.5 MB measured
    /// at 32 492 vertices).
    pub fn to_bytes(&self) -> Result<Vec<u8>, MatchError> {
        let mut bytes = CHECKPOINT_MAGIC.to_vec();
        bytes.extend(self.format.to_le_bytes());
        postcard::to_extend(self, bytes).map_err(|e| checkpoint_error(format!("could not encode the checkpoint: {e}")))
    }

    /// A checkpoint from its file's bytes; anything else (another file, an
    /// earlier format, a truncated or damaged file) is an error saying so.
    pub fn from_bytes(bytes: &[u8]) -> Result<Checkpoint, MatchError> {
        if bytes.first() == Some(&b'{') {
            return Err(checkpoint_error(
                "this is a JSON checkpoint of an earlier version (format 2); this version reads format 3: start again without resuming",
            ));
        }
        let Some(rest) = bytes.strip_prefix(CHECKPOINT_MAGIC) else {
            return Err(checkpoint_error("not an fshape checkpoint (its first bytes are not fshape's)"));
        };
        let Some((format, body)) = rest.split_first_chunk::<4>() else {
            return Err(checkpoint_error("the checkpoint ends before its format number (a truncated file)"));
        };
        let format = u32::from_le_bytes(*format);
        if format != CHECKPOINT_FORMAT {
            return Err(checkpoint_error(format!(
                "the checkpoint is of format {format} (this version reads format {CHECKPOINT_FORMAT}); start again without resuming"
            )));
        }
        postcard::from_bytes(body).map_err(|e| {
            checkpoint_error(format!("the checkpoint is damaged or truncated ({e}); start again without resuming"))
        })
    }

    /// [`Checkpoint::from_bytes`] of a file; errors name it.
    pub fn read(path: &Path) -> Result<Checkpoint, MatchError> {
        let bytes =
            std::fs::read(path).map_err(|e| MatchError::File { path: path.to_path_buf(), message: e.to_string() })?;
        Checkpoint::from_bytes(&bytes).map_err(|e| e.in_file(path))
    }
}

/// What an observer wants after an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Go on.
    Continue,
    /// Stop now, leaving the checkpoint to resume from.
    Stop,
}

/// Sees the run's progress (a progress bar, a log, a Python callback) and
/// may stop it. Every method has a default that does nothing; `()` is the
/// observer that watches nothing.
pub trait Observer {
    /// Stage `stage` (of `stages`) starts, or resumes with `done`
    /// iterations already made.
    fn stage_started(&mut self, stage: usize, stages: usize, spec: &StageSpec, done: usize) -> Control {
        let _ = (stage, stages, spec, done);
        Control::Continue
    }
    /// An iteration was accepted (and checkpointed).
    fn iteration(&mut self, stage: usize, record: &Iteration) -> Control {
        let _ = (stage, record);
        Control::Continue
    }
    /// A stage ended.
    fn stage_finished(&mut self, stage: usize, record: &StageRecord) {
        let _ = (stage, record);
    }
}

impl Observer for () {}

/// How [`Session::run`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Every stage ran to its stopping rule.
    Finished,
    /// An observer stopped the run; the checkpoint holds where it was.
    Interrupted,
}

/// The registration's result.
#[derive(Clone, Debug)]
pub struct MatchResult {
    /// The initial momenta p_0 (P × n).
    pub p0: Vec<f64>,
    /// The signal momentum p^f (P; ζ for the tangential model, 0 for LDDMM).
    pub pf: Vec<f64>,
    /// J and its parts at the result, with the last stage's kernel.
    pub energies: Energies,
    /// The geodesic from the template.
    pub trajectory: Trajectory,
    /// Every finished stage's records.
    pub stages: Vec<StageRecord>,
    /// Accepted iterations, all stages.
    pub iterations: usize,
    /// Objective evaluations, all stages.
    pub evaluations: usize,
    /// Wall seconds, all runs.
    pub seconds: f64,
    /// How close the matched shape (x_1, f_1) is to the target.
    pub quality: crate::Quality,
    /// How close the template was, for comparison.
    pub initial_quality: crate::Quality,
    /// Whether every stage ran to its stopping rule; `false` for
    /// [`Session::result_so_far`] of a run stopped before its end.
    pub finished: bool,
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
    }

    pub(crate) fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

/// FNV-1a, as hex, of the source, the target and the configuration (as
/// data: the shapes bit for bit, and the configuration's TOML with every
/// default written out).
pub fn fingerprint(source: &FShape, target: &FShape, config: &Config) -> String {
    let mut h = Fnv::new();
    h.shape(source);
    h.shape(target);
    h.eat(config.to_toml().as_bytes());
    h.hex()
}

/// A registration of a source onto a target with a [`Config`], run stage
/// by stage ([`Session::run`]), resumable ([`Session::resume`]).
pub struct Session {
    plan: Plan,
    problem: Problem,
    source: FShape,
    target: FShape,
    unknowns: Unknowns,
    checkpoint: Checkpoint,
    checkpoint_file: Option<PathBuf>,
    /// The stage whose data term the problem holds.
    staged: Option<usize>,
    /// A coarser template per stage (`None`: the source), empty for none.
    stage_templates: Vec<Option<FShape>>,
    /// A coarser target per stage (`None`: the target), empty for none.
    stage_targets: Vec<Option<FShape>>,
    /// Per stage, which template it runs on: the first stage with an equal
    /// template, or `None` for the source (equal templates share a problem
    /// and need no transfer between them).
    template_keys: Vec<Option<usize>>,
    /// The template the problem holds: the stage whose template it is, or
    /// `None` for the source.
    on_template: Option<usize>,
    /// Whether `unknowns` carries the metric's matrices for the template
    /// the problem holds (built by the first stage on it: a stage template
    /// may replace the source before any stage runs on it).
    metric_built: bool,
    parallel: bool,
}

/// Records the time and writes the checkpoint to `file`, if any.
pub(crate) fn save(checkpoint: &mut Checkpoint, file: Option<&Path>, seconds: f64) -> Result<(), MatchError> {
    checkpoint.seconds = seconds;
    let Some(path) = file else { return Ok(()) };
    let bytes = checkpoint.to_bytes()?;
    fshape_mesh::io::write_atomic(path, &bytes, false)
        .map_err(|e| MatchError::File { path: path.to_path_buf(), message: e.to_string() })
}

/// An objective that remembers J's parts at its recent evaluations.
pub(crate) trait StageObjective: Objective {
    /// J's parts at the evaluated point whose J is `value`, bit for bit
    /// (the accepted point of a line search, whose value the optimiser's
    /// state holds), searched among the evaluations since the last call,
    /// which are then forgotten.
    fn parts_of(&mut self, value: f64) -> Option<Energies>;
}

/// The parts of the evaluation in `recent` whose J is `value` (the last
/// such, bit for bit); `recent` is then cleared. The body of every
/// [`StageObjective::parts_of`].
pub(crate) fn take_parts(recent: &mut Vec<Energies>, value: f64) -> Option<Energies> {
    let found = recent.iter().rev().find(|e| e.value.to_bits() == value.to_bits()).copied();
    recent.clear();
    found
}

/// Where a stage starts.
pub(crate) enum StageStart {
    /// Where an interrupted run left it.
    Resume(Box<Current>),
    /// At these unknowns, evaluated first.
    At(Vec<f64>),
}

/// A run's checkpoint, where it is written, and the run's clock.
pub(crate) struct Journal<'a> {
    pub checkpoint: &'a mut Checkpoint,
    pub file: Option<&'a Path>,
    /// Wall seconds over every run of this registration.
    pub clock: &'a dyn Fn() -> f64,
    /// The schedule's number of stages.
    pub stages: usize,
}

impl Journal<'_> {
    fn save(&mut self) -> Result<(), MatchError> {
        save(self.checkpoint, self.file, (self.clock)())
    }
}

/// Runs stage `k` (whose rule is `spec`, the other settings `base`) from
/// `start` until it stops by its rule, checkpointing after every accepted
/// iteration; a finished stage goes to the journal's finished stages and
/// its end becomes the warm start. [`Outcome::Interrupted`] when the
/// observer stops it, with the stage under way in the checkpoint.
/// [`Session::run`] and [`crate::Atlas::run`] share it.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_stage<O>(
    k: usize,
    spec: &StageSpec,
    setup: StageSetup,
    base: &Settings,
    objective: &mut O,
    start: StageStart,
    journal: &mut Journal<'_>,
    observer: &mut impl Observer,
) -> Result<Outcome, MatchError>
where
    O: StageObjective,
    MatchError: From<O::Error>,
{
    let settings = Settings {
        max_iterations: spec.max_iterations,
        decrease_tolerance: spec.decrease.0,
        decrease_window: spec.decrease.1,
        ..*base
    };
    let mut current = match start {
        StageStart::Resume(current) => *current,
        StageStart::At(x0) => {
            let state = State::start(x0, objective)?;
            let parts = objective.parts_of(state.value).expect("the starting point was evaluated");
            Current { initial: Iteration::of(&state, &parts), state, iterations: Vec::new() }
        }
    };
    if observer.stage_started(k, journal.stages, spec, current.iterations.len()) == Control::Stop {
        journal.checkpoint.current = Some(current);
        journal.save()?;
        return Ok(Outcome::Interrupted);
    }
    let stop = loop {
        if let Some(stop) = current.state.iterate(&settings, objective)? {
            break stop;
        }
        // The accepted point's parts: a line search may accept a point
        // before its last evaluation.
        let parts = objective.parts_of(current.state.value).expect("an accepted step was evaluated");
        let record = Iteration::of(&current.state, &parts);
        current.iterations.push(record.clone());
        let control = observer.iteration(k, &record);
        journal.checkpoint.current = Some(current);
        journal.save()?;
        if control == Control::Stop {
            return Ok(Outcome::Interrupted);
        }
        current = journal.checkpoint.current.take().expect("just set");
    };
    let record = StageRecord {
        kernel_geom: spec.label.clone(),
        setup,
        stop,
        reason: stop.describe().into(),
        initial: current.initial,
        iterations: current.iterations,
    };
    journal.checkpoint.warm = Some(current.state.x);
    observer.stage_finished(k, &record);
    journal.checkpoint.done.push(record);
    journal.save()?;
    Ok(Outcome::Finished)
}

pub(crate) fn checkpoint_error(problem: impl Into<String>) -> MatchError {
    MatchError::Checkpoint { problem: problem.into() }
}

impl Session {
    /// Checks the configuration and the shapes, builds the problem (signal
    /// norm analysis, once) and starts an empty checkpoint.
    pub fn new(source: &FShape, target: &FShape, config: &Config) -> Result<Session, MatchError> {
        if source.dim() != target.dim() || source.kind() != target.kind() {
            return Err(MatchError::Kinds(format!(
                "the source is a {} mesh in R^{}, the target a {} mesh in R^{}",
                source.kind().name(),
                source.dim(),
                target.kind().name(),
                target.dim()
            )));
        }
        let plan = config.plan(source, target)?;
        let counts: Vec<Option<usize>> = plan.stages.iter().map(|s| s.vertices).collect();
        let auto = counts.iter().any(Option::is_some);
        let templates = crate::resolution::simplified_stages(source, &counts, "source")?;
        let targets = if plan.stages.iter().any(|s| s.coarse_target) {
            let counts: Vec<Option<usize>> =
                plan.stages.iter().map(|s| s.vertices.filter(|_| s.coarse_target)).collect();
            crate::resolution::simplified_stages(target, &counts, "target")?
        } else {
            Vec::new()
        };
        // The problem on the first stage's template: a source that stage
        // templates replace at once is not set up.
        let problem = Problem::new(templates.first().and_then(Option::as_ref).unwrap_or(source), plan.model.clone())?;
        // The metric's matrices (a dense kernel factor) wait for the first
        // stage on the source: it may run on a stage template first.
        let unknowns = Unknowns::for_template(source, plan.model.kind(), plan.metrics, plan.scales)?;
        let checkpoint = Checkpoint {
            format: CHECKPOINT_FORMAT,
            fingerprint: fingerprint(source, target, config),
            done: Vec::new(),
            current: None,
            warm: None,
            seconds: 0.0,
        };
        let session = Session {
            plan,
            problem,
            source: source.clone(),
            target: target.clone(),
            unknowns,
            checkpoint,
            checkpoint_file: None,
            staged: None,
            stage_templates: Vec::new(),
            stage_targets: targets,
            template_keys: Vec::new(),
            on_template: None,
            metric_built: false,
            parallel: true,
        };
        // The problem holds stage 0's template: say so, or the first stage
        // would set it up again.
        let mut session = if auto { session.set_stage_templates(templates)? } else { session };
        session.on_template = session.template_of(0).0;
        Ok(session)
    }

    /// Writes the checkpoint to `path` (atomically, [`Checkpoint::to_bytes`]) after every
    /// accepted iteration, at the end of every stage and when stopped.
    pub fn with_checkpoint_file(mut self, path: &Path) -> Session {
        self.checkpoint_file = Some(path.to_path_buf());
        self
    }

    /// Parallel (default) or serial work in every evaluation; the results
    /// are the same bit for bit.
    pub fn with_parallel(mut self, parallel: bool) -> Session {
        self.problem.set_parallel(parallel);
        self.parallel = parallel;
        self
    }

    /// Runs stage k on a coarser template `templates[k]` (the same surface
    /// at a lower resolution, with its signal), or on the source where it
    /// is `None`; the last stage is always the source. Between stages on
    /// different templates the momenta are carried over keeping their
    /// velocity field ([`crate::resolution::prolongate_fitted`]). The templates enter the
    /// checkpoint's fingerprint: call this before [`Session::resume`].
    pub fn with_stage_templates(self, templates: Vec<Option<FShape>>) -> Result<Session, MatchError> {
        if self.plan.stages.iter().any(|s| s.vertices.is_some()) {
            return Err(MatchError::StageTemplatesTwice);
        }
        let on = self.on_template;
        let mut session = self.set_stage_templates(templates)?;
        // The problem still holds the source.
        session.on_template = on;
        Ok(session)
    }

    /// [`Session::with_stage_templates`], from the schedule's counts too.
    fn set_stage_templates(mut self, templates: Vec<Option<FShape>>) -> Result<Session, MatchError> {
        let n = self.plan.stages.len();
        if templates.len() != n {
            return Err(MatchError::StageTemplates(format!(
                "{} given for a schedule of {n} stages (one per stage, the last None)",
                templates.len()
            )));
        }
        if templates.last().is_some_and(Option::is_some) {
            return Err(MatchError::StageTemplates(
                "the last stage runs on the source: its stage template must be None".into(),
            ));
        }
        for (k, t) in templates.iter().enumerate() {
            if let Some(t) = t
                && (t.dim() != self.source.dim() || t.kind() != self.source.kind() || t.n_cells() == 0)
            {
                return Err(MatchError::StageTemplates(format!(
                    "stage {k}'s template is not a non-empty mesh of the source's kind and dimension"
                )));
            }
        }
        let mut h = Fnv::new();
        h.eat(self.checkpoint.fingerprint.as_bytes());
        for t in &templates {
            match t {
                Some(t) => h.shape(t),
                None => h.eat(b"source"),
            }
        }
        self.checkpoint.fingerprint = h.hex();
        self.template_keys = (0..n)
            .map(|k| match &templates[k] {
                Some(t) if *t != self.source => templates.iter().position(|u| u.as_ref() == Some(t)),
                _ => None,
            })
            .collect();
        self.stage_templates = templates;
        Ok(self)
    }

    /// The template of stage k and its key (`template_keys`).
    fn template_of(&self, k: usize) -> (Option<usize>, &FShape) {
        match self.template_keys.get(k) {
            Some(Some(j)) => (Some(*j), self.stage_templates[*j].as_ref().expect("a key names a template")),
            _ => (None, &self.source),
        }
    }

    /// The number of unknowns of stage k.
    fn unknowns_len(&self, k: usize) -> usize {
        let t = self.template_of(k).1;
        let signal = if self.plan.model.kind() == fshape_shoot::ModelKind::Lddmm { 0 } else { t.n_vertices() };
        t.n_vertices() * t.dim() + signal
    }

    /// The packing of stage k's unknowns.
    fn unknowns_of(&self, k: usize) -> Result<Unknowns, MatchError> {
        let t = self.template_of(k).1;
        Ok(Unknowns::for_template(t, self.plan.model.kind(), self.plan.metrics, self.plan.scales)?)
    }

    /// Continues from `checkpoint`, after checking that it belongs to these
    /// inputs (fingerprint), was written by this format, and holds arrays of
    /// the problem's sizes with finite values.
    pub fn resume(mut self, checkpoint: Checkpoint) -> Result<Session, MatchError> {
        self.validate(&checkpoint)?;
        self.checkpoint = checkpoint;
        Ok(self)
    }

    /// [`Session::resume`] from a checkpoint file ([`Checkpoint::read`]);
    /// errors name the file.
    pub fn resume_from_file(self, path: &Path) -> Result<Session, MatchError> {
        let checkpoint = Checkpoint::read(path)?;
        self.resume(checkpoint).map_err(|e| e.in_file(path))
    }

    fn validate(&self, c: &Checkpoint) -> Result<(), MatchError> {
        if c.format != CHECKPOINT_FORMAT {
            return Err(checkpoint_error(format!(
                "the checkpoint is of format {} (this version reads format {CHECKPOINT_FORMAT}); start again without resuming",
                c.format
            )));
        }
        if c.fingerprint != self.checkpoint.fingerprint {
            return Err(checkpoint_error(
                "the checkpoint was written for other inputs (source, target or configuration changed); remove it or start without resuming",
            ));
        }
        validate_arrays(c, self.plan.stages.len(), |k| self.unknowns_len(k))
    }

    /// The checked plan.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The problem (template, model, current target).
    pub fn problem(&self) -> &Problem {
        &self.problem
    }

    /// The packing of the unknowns (of the stage that ran or runs last; it
    /// carries the energy metric's matrices once a stage has started).
    pub fn unknowns(&self) -> &Unknowns {
        &self.unknowns
    }

    /// The checkpoint as of now.
    pub fn checkpoint(&self) -> &Checkpoint {
        &self.checkpoint
    }

    /// Whether every stage has run.
    pub fn is_finished(&self) -> bool {
        self.checkpoint.done.len() == self.plan.stages.len()
    }

    fn stage_target(&mut self, k: usize) -> Result<(), MatchError> {
        let (key, template) = self.template_of(k);
        if key != self.on_template {
            self.problem = Problem::new(template, self.plan.model.clone())?.with_parallel(self.parallel);
            self.on_template = key;
            self.staged = None;
            self.metric_built = false;
        }
        if !self.metric_built {
            self.unknowns = Unknowns::scaled(&self.problem, self.plan.metrics, self.plan.scales)?;
            self.metric_built = true;
        }
        if self.staged != Some(k) {
            let stage = &self.plan.stages[k];
            let target = self.stage_targets.get(k).and_then(Option::as_ref).unwrap_or(&self.target);
            self.problem.set_target(target, stage.kernel.clone())?;
            self.problem.set_integrator(stage.integrator.0, stage.integrator.1)?;
            self.staged = Some(k);
        }
        Ok(())
    }

    /// Runs the remaining stages (all of them on a new session) until each
    /// stops by its rule, or until `observer` says [`Control::Stop`].
    pub fn run(&mut self, observer: &mut impl Observer) -> Result<Outcome, MatchError> {
        let start = Instant::now();
        let earlier = self.checkpoint.seconds;
        let clock = move || earlier + start.elapsed().as_secs_f64();
        let stages = self.plan.stages.len();
        while self.checkpoint.done.len() < stages {
            let k = self.checkpoint.done.len();
            // Carried over before stage k's metric is built, so that the
            // transfer's dense factor and the metric's are not held at once.
            let carried = if self.checkpoint.current.is_none() { self.carried(k)? } else { None };
            self.stage_target(k)?;
            let begin = match self.checkpoint.current.take() {
                Some(current) => StageStart::Resume(Box::new(current)),
                None => StageStart::At(match carried {
                    Some(x) => x,
                    None => self.checkpoint.warm.clone().unwrap_or_else(|| vec![0.0; self.unknowns.len()]),
                }),
            };
            let mut objective = MatchObjective::new(&self.problem, self.unknowns.clone());
            let mut journal = Journal {
                checkpoint: &mut self.checkpoint,
                file: self.checkpoint_file.as_deref(),
                clock: &clock,
                stages,
            };
            let spec = &self.plan.stages[k];
            let setup = StageSetup {
                template_vertices: self.problem.template().n_vertices(),
                target_vertices: self
                    .stage_targets
                    .get(k)
                    .and_then(Option::as_ref)
                    .unwrap_or(&self.target)
                    .n_vertices(),
                deformation: self.problem.model().kernel().path().to_string(),
                attachment: spec.kernel.position().path().to_string(),
            };
            if run_stage(k, spec, setup, &self.plan.settings, &mut objective, begin, &mut journal, observer)?
                == Outcome::Interrupted
            {
                return Ok(Outcome::Interrupted);
            }
        }
        Ok(Outcome::Finished)
    }

    /// The unknowns stage `k` starts from where it runs on another
    /// template than stage k − 1: the last stage's end carried over
    /// ([`crate::resolution::prolongate_fitted`]). `None` where stage k
    /// starts from zero (the first) or from the last stage's end as it is.
    fn carried(&self, k: usize) -> Result<Option<Vec<f64>>, MatchError> {
        let Some(w) = &self.checkpoint.warm else { return Ok(None) };
        if k == 0 || self.template_of(k - 1).0 == self.template_of(k).0 {
            return Ok(None);
        }
        let (p0, pf) = self.unknowns_of(k - 1)?.unpack(w);
        let (coarse, fine) = (self.template_of(k - 1).1, self.template_of(k).1);
        let kind = self.plan.model.kind();
        let (p0, pf) = crate::resolution::prolongate_fitted(coarse, fine, &p0, &pf, kind, self.plan.model.kernel())?;
        Ok(Some(self.unknowns_of(k)?.pack(&p0, &pf)))
    }

    /// The result of a finished run: the final momenta, shot once more with
    /// the last stage's data term.
    pub fn result(&mut self) -> Result<MatchResult, MatchError> {
        if !self.is_finished() {
            return Err(MatchError::NotFinished);
        }
        let x = self.checkpoint.warm.clone().ok_or(MatchError::NotFinished)?;
        let (p0, pf) = self.unknowns_of(self.plan.stages.len() - 1)?.unpack(&x);
        self.shot(p0, pf, true)
    }

    /// The result as of now, for a run an observer stopped before its end
    /// (scipy's callbacks and argmin's observers end a run, they do not
    /// fail it): the current point of the stage under way, or the end of
    /// the last finished stage, carried to the source's vertices if that
    /// stage ran on a coarser template, and shot with the last stage's
    /// data term like [`Session::result`], marked `finished: false`. The
    /// finished run's result once every stage has run; `None` before the
    /// first iteration of the first stage.
    pub fn result_so_far(&mut self) -> Result<Option<MatchResult>, MatchError> {
        if self.is_finished() {
            return self.result().map(Some);
        }
        let done = self.checkpoint.done.len();
        let (k, x) = match (&self.checkpoint.current, &self.checkpoint.warm) {
            (Some(current), _) => (done, current.state.x.clone()),
            (None, Some(warm)) => (done - 1, warm.clone()),
            (None, None) => return Ok(None),
        };
        let last = self.plan.stages.len() - 1;
        let (mut p0, mut pf) = self.unknowns_of(k)?.unpack(&x);
        if self.template_of(k).0 != self.template_of(last).0 {
            let (coarse, fine) = (self.template_of(k).1, self.template_of(last).1);
            let kind = self.plan.model.kind();
            (p0, pf) = crate::resolution::prolongate_fitted(coarse, fine, &p0, &pf, kind, self.plan.model.kernel())?;
        }
        self.shot(p0, pf, false).map(Some)
    }

    /// Shoots momenta on the source with the last stage's data term and
    /// measures where they end.
    fn shot(&mut self, p0: Vec<f64>, pf: Vec<f64>, finished: bool) -> Result<MatchResult, MatchError> {
        self.stage_target(self.plan.stages.len() - 1)?;
        let (energies, trajectory) = self.problem.objective(&p0, &pf)?;
        let template = self.problem.template();
        let last = trajectory.steps();
        let matched = template
            .clone()
            .with_points(trajectory.points(last).to_vec())?
            .with_signal(Some(trajectory.signal(last).to_vec()))?;
        let quality = crate::quality(&matched, &self.target)?;
        let initial_quality = crate::quality(template, &self.target)?;
        // Finished stages, and the one under way when stopped within it.
        let stages = self.checkpoint.done.clone();
        let mut runs: Vec<(&[Iteration], &Iteration)> =
            stages.iter().map(|s| (s.iterations.as_slice(), &s.initial)).collect();
        if let Some(current) = &self.checkpoint.current {
            runs.push((&current.iterations, &current.initial));
        }
        let iterations = runs.iter().map(|(its, _)| its.len()).sum();
        let evaluations = runs.iter().map(|(its, initial)| its.last().unwrap_or(initial).evaluations).sum();
        Ok(MatchResult {
            p0,
            pf,
            energies,
            trajectory,
            stages,
            iterations,
            evaluations,
            seconds: self.checkpoint.seconds,
            quality,
            initial_quality,
            finished,
        })
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
