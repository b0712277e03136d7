//! The one stage engine: a [`Runner`] runs the stages of a schedule one
//! after the other, each warm-started from the last, with a checkpoint
//! after every accepted iteration, observers that see the progress and may
//! stop it, and resume to the same bits. What is run is a [`Staged`]
//! problem: a registration of one pair ([`crate::Session`]) or an atlas of
//! a population ([`crate::Atlas`]). The problem supplies each stage's
//! objective and where it starts; the runner owns the loop, the clock, the
//! checkpoint and the stage templates' bookkeeping (argmin's Executor
//! split: the problem gives cost and gradient, the driver does the rest).
//!
//! A run stopped anywhere (an observer's [`Control::Stop`], a kill between
//! two checkpoints) resumes from its checkpoint to the result an
//! uninterrupted run gives, bit for bit: the optimiser's whole state is in
//! the checkpoint, and every evaluation is deterministic.

mod checkpoint;

use std::path::{Path, PathBuf};
use std::time::Instant;

use fshape_mesh::FShape;
use fshape_shoot::Energies;

pub use checkpoint::{CHECKPOINT_FORMAT, Checkpoint, Current, Iteration, StageRecord, StageSetup, UNCHECKED_FORMAT};
pub(crate) use checkpoint::{Fnv, checkpoint_error};

use crate::optimize::{Objective, Settings, State, Step};
use crate::{MatchError, Plan, StageSpec};

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
    /// A step of the setup before the stages began or ended (pre-alignment,
    /// the stages' simplified shapes), said in a few words: what a silent
    /// half minute on a large pair was spent on.
    fn setup(&mut self, step: &str) {
        let _ = step;
    }
    /// The setup is done: the checked plan (the model with its effective
    /// weights, the stages) the run follows. Called by the operations
    /// ([`crate::ops`]) before the first stage.
    fn planned(&mut self, plan: &Plan) {
        let _ = plan;
    }
}

impl Observer for () {}

impl Control {
    /// Stop when either says so.
    fn or(self, other: Control) -> Control {
        if self == Control::Stop { Control::Stop } else { other }
    }
}

/// Several observers as one, in argmin's manner: each is told every event,
/// in the order they were added, and the run stops when any of them asks
/// (the others are still told of that event). A display, a log,
/// `--stop-after`'s budget and a Python callback are each an observer of
/// their own.
#[derive(Default)]
pub struct Observers<'a>(Vec<&'a mut dyn Observer>);

impl<'a> Observers<'a> {
    /// No observer yet.
    pub fn new() -> Observers<'a> {
        Observers(Vec::new())
    }

    /// With `observer` told after those already added.
    pub fn with(mut self, observer: &'a mut dyn Observer) -> Observers<'a> {
        self.0.push(observer);
        self
    }
}

impl Observer for Observers<'_> {
    fn stage_started(&mut self, stage: usize, stages: usize, spec: &StageSpec, done: usize) -> Control {
        self.0.iter_mut().fold(Control::Continue, |c, o| o.stage_started(stage, stages, spec, done).or(c))
    }

    fn iteration(&mut self, stage: usize, record: &Iteration) -> Control {
        self.0.iter_mut().fold(Control::Continue, |c, o| o.iteration(stage, record).or(c))
    }

    fn stage_finished(&mut self, stage: usize, record: &StageRecord) {
        self.0.iter_mut().for_each(|o| o.stage_finished(stage, record));
    }

    fn setup(&mut self, step: &str) {
        self.0.iter_mut().for_each(|o| o.setup(step));
    }

    fn planned(&mut self, plan: &Plan) {
        self.0.iter_mut().for_each(|o| o.planned(plan));
    }
}

/// Stops a run after a number of accepted iterations of this invocation
/// (`--stop-after`: a run resumed from its checkpoint counts afresh), or
/// at its first stage when the number is 0; `None` never stops.
#[derive(Clone, Copy, Debug)]
pub struct StopAfter(pub Option<usize>);

impl StopAfter {
    fn control(self) -> Control {
        if self.0 == Some(0) { Control::Stop } else { Control::Continue }
    }
}

impl Observer for StopAfter {
    fn stage_started(&mut self, _stage: usize, _stages: usize, _spec: &StageSpec, _done: usize) -> Control {
        self.control()
    }

    fn iteration(&mut self, _stage: usize, _record: &Iteration) -> Control {
        self.0 = self.0.map(|n| n.saturating_sub(1));
        self.control()
    }
}

/// How [`Runner::run`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Every stage ran to its stopping rule.
    Finished,
    /// An observer stopped the run; the checkpoint holds where it was.
    Interrupted,
}

/// A problem run in stages: what a [`Runner`] needs of it. Implemented by
/// the pair registration ([`crate::session::Pair`]) and the population
/// ([`crate::atlas::Population`]).
pub trait Staged {
    /// One stage's objective: J with its parts (means over the subjects
    /// for an atlas).
    type Objective<'a>: Objective<Parts = Energies, Error = MatchError>
    where
        Self: 'a;
    /// What the shape the stages start from is called in messages
    /// ("source", "initial template").
    const START: &'static str;
    /// What the checkpoint's fingerprint covers, for the message refusing
    /// another run's checkpoint.
    const INPUTS: &'static str;
    /// The plan, the shape the stages start from and the stage templates.
    fn stages(&self) -> &Stages;
    /// The same, to set the stage templates.
    fn stages_mut(&mut self) -> &mut Stages;
    /// A hand-made stage template (in the frame of the inputs as given)
    /// as the stages run on it (default: as given).
    fn stage_template(&self, template: FShape) -> Result<FShape, MatchError> {
        Ok(template)
    }
    /// The number of unknowns of stage `k`.
    fn len_at(&self, k: usize) -> usize;
    /// Where a fresh stage `k` starts: from scratch for the first,
    /// otherwise from `warm`, the last finished stage's end (carried to
    /// stage k's template where that differs).
    fn start(&mut self, k: usize, warm: Option<&[f64]>) -> Result<Vec<f64>, MatchError>;
    /// Sets stage `k` up (its template, targets and integrator) and says
    /// what it runs on.
    fn prepare(&mut self, k: usize) -> Result<StageSetup, MatchError>;
    /// Stage `k`'s objective, after [`Staged::prepare`].
    fn objective(&mut self, k: usize) -> Self::Objective<'_>;
}

/// What a staged problem is run from: the checked plan, the shape the
/// stages start from (the last stage runs on it) and the stage templates.
pub struct Stages {
    pub(crate) plan: Plan,
    pub(crate) start: FShape,
    pub(crate) templates: StageTemplates,
}

impl Stages {
    /// `plan` starting from `start`, without stage templates.
    pub(crate) fn new(plan: Plan, start: FShape) -> Stages {
        Stages { plan, start, templates: StageTemplates::default() }
    }

    /// The template of stage k and its key ([`StageTemplates::of`]).
    pub(crate) fn template_of(&self, k: usize) -> (Option<usize>, &FShape) {
        self.templates.of(k, &self.start)
    }

    /// The number of unknowns of stage k: p_0, and p^f unless LDDMM (one
    /// channel for a template without a signal, which is given a zero one).
    pub(crate) fn unknowns_len(&self, k: usize) -> usize {
        let t = self.template_of(k).1;
        let signal = if self.plan.model.kind() == fshape_shoot::ModelKind::Lddmm {
            0
        } else {
            t.n_vertices() * t.n_channels().max(1)
        };
        t.n_vertices() * t.dim() + signal
    }

    /// The packing of stage k's unknowns (without the metric's matrices).
    pub(crate) fn unknowns_of(&self, k: usize) -> Result<crate::unknowns::Unknowns, MatchError> {
        let plan = &self.plan;
        Ok(crate::unknowns::Unknowns::for_template(
            self.template_of(k).1,
            plan.model.kind(),
            plan.metrics,
            plan.scales.as_ref(),
        )?)
    }

    /// Where stage `k` starts: zeros for the first (or without `warm`),
    /// else `warm`, the last stage's end, carried to stage k's template
    /// where that differs ([`crate::resolution::prolongate_fitted`]).
    pub(crate) fn start_of(&self, k: usize, warm: Option<&[f64]>) -> Result<Vec<f64>, MatchError> {
        let Some(w) = warm else { return Ok(vec![0.0; self.unknowns_len(k)]) };
        if k == 0 || self.template_of(k - 1).0 == self.template_of(k).0 {
            return Ok(w.to_vec());
        }
        let (p0, pf) = self.unknowns_of(k - 1)?.unpack(w);
        let (coarse, fine) = (self.template_of(k - 1).1, self.template_of(k).1);
        let model = &self.plan.model;
        let (p0, pf) = crate::resolution::prolongate_fitted(coarse, fine, &p0, &pf, model.kind(), model.kernel())?;
        Ok(self.unknowns_of(k)?.pack(&p0, &pf))
    }
}

/// The stage templates of a schedule: per stage a coarser version of the
/// start shape or `None` (the start shape itself), and which stages share
/// one (equal templates share a problem and need no transfer between
/// them).
#[derive(Clone, Debug, Default)]
pub struct StageTemplates {
    templates: Vec<Option<FShape>>,
    /// Per stage, the first stage with an equal template, or `None` for the
    /// start shape.
    keys: Vec<Option<usize>>,
}

impl StageTemplates {
    /// Stage k's template and its key: stages with one key run on one
    /// template (`None`: `start`).
    pub fn of<'a>(&'a self, k: usize, start: &'a FShape) -> (Option<usize>, &'a FShape) {
        match self.keys.get(k) {
            Some(Some(j)) => (Some(*j), self.templates[*j].as_ref().expect("a key names a template")),
            _ => (None, start),
        }
    }

    /// Checks `templates` (one per stage of `staged`'s schedule, the last
    /// `None`, each a non-empty mesh of the start shape's kind and
    /// dimension), completes those the user `given` ([`Staged::stage_template`];
    /// simplified ones are made complete) and keys them.
    fn checked<S: Staged>(
        staged: &S,
        templates: Vec<Option<FShape>>,
        given: bool,
    ) -> Result<StageTemplates, MatchError> {
        let (n, start, what) = (staged.stages().plan.stages.len(), &staged.stages().start, S::START);
        if let Some(t) =
            templates.iter().flatten().find(|t| t.signal().is_some() && t.n_channels() != start.n_channels())
        {
            return Err(MatchError::StageTemplates(format!(
                "a stage template carries {} signal channels, the {what} {}",
                t.n_channels(),
                start.n_channels()
            )));
        }
        if templates.len() != n {
            return Err(MatchError::StageTemplates(format!(
                "{} given for a schedule of {n} stages (one per stage, the last None)",
                templates.len()
            )));
        }
        if templates.last().is_some_and(Option::is_some) {
            return Err(MatchError::StageTemplates(format!(
                "the last stage runs on the {what}: its stage template must be None"
            )));
        }
        let mut filled = Vec::with_capacity(n);
        for (k, t) in templates.into_iter().enumerate() {
            filled.push(match t {
                None => None,
                Some(t) if t.dim() != start.dim() || t.kind() != start.kind() || t.n_cells() == 0 => {
                    return Err(MatchError::StageTemplates(format!(
                        "stage {k}'s template is not a non-empty mesh of the {what}'s kind and dimension"
                    )));
                }
                Some(t) if given => Some(staged.stage_template(t)?),
                Some(t) => Some(t),
            });
        }
        // The channels are checked once each stage template is complete (an
        // atlas's takes the initial template's maps).
        if start.n_channels() > 1 && filled.iter().flatten().any(|t| t.signal().is_none()) {
            return Err(MatchError::StageTemplates(format!(
                "the {what} carries {} signal channels and a stage template none: give the stage templates \
                 the {what}'s channels",
                start.n_channels()
            )));
        }
        let keys = (0..n)
            .map(|k| match &filled[k] {
                Some(t) if t != start => filled.iter().position(|u| u.as_ref() == Some(t)),
                _ => None,
            })
            .collect();
        Ok(StageTemplates { templates: filled, keys })
    }

    /// `fingerprint` extended by the templates.
    fn fingerprint(&self, fingerprint: &str) -> String {
        let mut h = Fnv::new();
        h.eat(fingerprint.as_bytes());
        for t in &self.templates {
            match t {
                Some(t) => h.shape(t),
                None => h.eat(b"source"),
            }
        }
        h.hex()
    }
}

/// Where a stage starts.
enum StageStart {
    /// Where an interrupted run left it.
    Resume(Box<Current>),
    /// At these unknowns, evaluated first.
    At(Vec<f64>),
}

/// Runs a [`Staged`] problem stage by stage ([`Runner::run`]), resumable
/// ([`Runner::resume`]). [`crate::Session`] and [`crate::Atlas`] are its
/// two kinds.
pub struct Runner<S> {
    pub(crate) staged: S,
    checkpoint: Checkpoint,
    checkpoint_file: Option<PathBuf>,
}

impl<S: Staged> Runner<S> {
    /// A runner of `staged` with an empty checkpoint of these inputs.
    pub(crate) fn of(staged: S, fingerprint: String) -> Runner<S> {
        let checkpoint = Checkpoint {
            format: CHECKPOINT_FORMAT,
            fingerprint,
            done: Vec::new(),
            current: None,
            warm: None,
            seconds: 0.0,
        };
        Runner { staged, checkpoint, checkpoint_file: None }
    }

    /// Writes the checkpoint to `path` (atomically,
    /// [`Checkpoint::to_bytes`]) after every accepted iteration, at the end
    /// of every stage and when stopped.
    pub fn with_checkpoint_file(mut self, path: &Path) -> Self {
        self.checkpoint_file = Some(path.to_path_buf());
        self
    }

    /// Runs stage k on a coarser version of the start shape `templates[k]`
    /// (the same surface at a lower resolution, with its signal), or on
    /// the start shape where it is `None`; the last stage always runs on
    /// the start shape. Between stages on different templates the solution
    /// is carried over keeping its velocity field
    /// ([`crate::resolution::prolongate_fitted`]). The templates enter the
    /// checkpoint's fingerprint: call this before [`Runner::resume`]. An
    /// error where the schedule's `vertices` make the templates already.
    pub fn with_stage_templates(self, templates: Vec<Option<FShape>>) -> Result<Self, MatchError> {
        if self.plan().stages.iter().any(|s| s.vertices.is_some()) {
            return Err(MatchError::StageTemplatesTwice);
        }
        self.set_stage_templates(templates, true)
    }

    /// [`Runner::with_stage_templates`] (`given`), or the schedule's
    /// simplified copies of the start shape.
    pub(crate) fn set_stage_templates(
        mut self,
        templates: Vec<Option<FShape>>,
        given: bool,
    ) -> Result<Self, MatchError> {
        let templates = StageTemplates::checked(&self.staged, templates, given)?;
        self.checkpoint.fingerprint = templates.fingerprint(&self.checkpoint.fingerprint);
        self.staged.stages_mut().templates = templates;
        Ok(self)
    }

    /// Continues from `checkpoint`, after checking that it belongs to these
    /// inputs (fingerprint), was written by this format, and holds arrays of
    /// the problem's sizes with finite values.
    pub fn resume(mut self, mut checkpoint: Checkpoint) -> Result<Self, MatchError> {
        if checkpoint.format != CHECKPOINT_FORMAT && checkpoint.format != checkpoint::UNCHECKED_FORMAT {
            return Err(checkpoint_error(format!(
                "the checkpoint is of format {} (this version reads formats {} and {CHECKPOINT_FORMAT}); start again \
                 without resuming",
                checkpoint.format,
                checkpoint::UNCHECKED_FORMAT
            )));
        }
        // A format-3 checkpoint continues as format 4: the same contents,
        // written from now on with their checksum.
        checkpoint.format = CHECKPOINT_FORMAT;
        if checkpoint.fingerprint != self.checkpoint.fingerprint {
            return Err(checkpoint_error(format!(
                "the checkpoint was written for other inputs ({} changed); remove it or start without resuming",
                S::INPUTS
            )));
        }
        checkpoint::validate_arrays(&checkpoint, self.plan().stages.len(), |k| self.staged.len_at(k))?;
        self.checkpoint = checkpoint;
        Ok(self)
    }

    /// [`Runner::resume`] from a checkpoint file ([`Checkpoint::read`]);
    /// errors name the file.
    pub fn resume_from_file(self, path: &Path) -> Result<Self, MatchError> {
        let checkpoint = Checkpoint::read(path)?;
        self.resume(checkpoint).map_err(|e| e.in_file(path))
    }

    /// Writes the checkpoint to `path` ([`Runner::with_checkpoint_file`]),
    /// first continuing from it when the file exists
    /// ([`Runner::resume_from_file`]): the same call starts a run or
    /// continues a stopped one (the Python package's policy; the program
    /// asks for `--resume` instead). A checkpoint of other inputs is an
    /// error, never overwritten.
    pub fn continuing_from(self, path: &Path) -> Result<Self, MatchError> {
        let runner = if path.exists() { self.resume_from_file(path)? } else { self };
        Ok(runner.with_checkpoint_file(path))
    }

    /// The checked plan.
    pub fn plan(&self) -> &Plan {
        &self.staged.stages().plan
    }

    /// The checkpoint as of now.
    pub fn checkpoint(&self) -> &Checkpoint {
        &self.checkpoint
    }

    /// Whether every stage has run.
    pub fn is_finished(&self) -> bool {
        self.checkpoint.done.len() == self.plan().stages.len()
    }

    /// Runs the remaining stages (all of them on a new run) until each
    /// stops by its rule, or until `observer` says [`Control::Stop`].
    pub fn run(&mut self, observer: &mut impl Observer) -> Result<Outcome, MatchError> {
        let start = Instant::now();
        let earlier = self.checkpoint.seconds;
        let clock = move || earlier + start.elapsed().as_secs_f64();
        let stages = self.plan().stages.len();
        while self.checkpoint.done.len() < stages {
            let k = self.checkpoint.done.len();
            let begin = match self.checkpoint.current.take() {
                Some(current) => StageStart::Resume(Box::new(current)),
                None => StageStart::At(self.staged.start(k, self.checkpoint.warm.as_deref())?),
            };
            let setup = self.staged.prepare(k)?;
            let spec = self.plan().stages[k].clone();
            let settings = Settings {
                max_iterations: spec.max_iterations,
                decrease_tolerance: spec.decrease.0,
                decrease_window: spec.decrease.1,
                ..self.plan().settings
            };
            let mut stage = Stage {
                k,
                stages,
                spec: &spec,
                settings,
                checkpoint: &mut self.checkpoint,
                file: self.checkpoint_file.as_deref(),
                clock: &clock,
            };
            let mut objective = self.staged.objective(k);
            if stage.run(setup, &mut objective, begin, observer)? == Outcome::Interrupted {
                return Ok(Outcome::Interrupted);
            }
        }
        Ok(Outcome::Finished)
    }
}

/// One stage under way: its rule, the run's checkpoint, where it is
/// written, and the run's clock.
struct Stage<'a> {
    k: usize,
    stages: usize,
    spec: &'a StageSpec,
    settings: Settings,
    checkpoint: &'a mut Checkpoint,
    file: Option<&'a Path>,
    /// Wall seconds over every run.
    clock: &'a dyn Fn() -> f64,
}

impl Stage<'_> {
    fn save(&mut self) -> Result<(), MatchError> {
        checkpoint::save(self.checkpoint, self.file, (self.clock)())
    }

    /// Runs the stage from `start` until it stops by its rule,
    /// checkpointing after every accepted iteration; a finished stage goes
    /// to the checkpoint's finished stages and its end becomes the warm
    /// start. [`Outcome::Interrupted`] when the observer stops it, with the
    /// stage under way in the checkpoint.
    fn run<O: Objective<Parts = Energies, Error = MatchError>>(
        &mut self,
        setup: StageSetup,
        objective: &mut O,
        start: StageStart,
        observer: &mut impl Observer,
    ) -> Result<Outcome, MatchError> {
        let k = self.k;
        let mut current = match start {
            StageStart::Resume(current) => *current,
            StageStart::At(x0) => {
                let (state, parts) = State::start(x0, objective)?;
                Current { initial: Iteration::of(&state, &parts), state, iterations: Vec::new() }
            }
        };
        if observer.stage_started(k, self.stages, self.spec, current.iterations.len()) == Control::Stop {
            self.checkpoint.current = Some(current);
            self.save()?;
            return Ok(Outcome::Interrupted);
        }
        let stop = loop {
            let parts = match current.state.iterate(&self.settings, objective)? {
                Step::Stopped(stop) => break stop,
                Step::Accepted(parts) => parts,
            };
            let record = Iteration::of(&current.state, &parts);
            current.iterations.push(record.clone());
            let control = observer.iteration(k, &record);
            self.checkpoint.current = Some(current);
            self.save()?;
            if control == Control::Stop {
                return Ok(Outcome::Interrupted);
            }
            current = self.checkpoint.current.take().expect("just set");
        };
        let record = StageRecord {
            kernel_geom: self.spec.label.clone(),
            setup,
            stop,
            reason: stop.describe().into(),
            initial: current.initial,
            iterations: current.iterations,
        };
        self.checkpoint.warm = Some(current.state.x);
        observer.stage_finished(k, &record);
        self.checkpoint.done.push(record);
        self.save()?;
        Ok(Outcome::Finished)
    }
}
