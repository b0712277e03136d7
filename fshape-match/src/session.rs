//! A registration of a source onto a target: the pair problem
//! ([`Pair`]) that the stage engine ([`crate::runner`]) runs as a
//! [`Session`], J in the unknowns as an objective ([`MatchObjective`]),
//! and the result.

use fshape_mesh::FShape;
use fshape_shoot::{Energies, Problem, ShootError, Trajectory};

use crate::optimize::{Evaluation, Settings, State, Step, Stop};
use crate::runner::{Fnv, Observer, Runner, StageRecord, StageSetup, Staged, Stages};
use crate::unknowns::{Metrics, Unknowns};
use crate::{Config, MatchError};

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
    /// The pre-alignment the registration ran after (`[prealign]`), if
    /// any: the source and the result are in the target's frame (or the
    /// target in the source's, `move = "target"`).
    pub alignment: Option<crate::Alignment>,
    /// Whether every stage ran to its stopping rule; `false` for
    /// [`Session::result_so_far`](Runner::result_so_far) of a run stopped before its end.
    pub finished: bool,
}

/// FNV-1a, as hex, of the source, the target and the configuration (as
/// data: the shapes bit for bit, and the configuration's TOML with every
/// default written out and its schedule as `[schedule]`'s arrays).
pub fn fingerprint(source: &FShape, target: &FShape, config: &Config) -> String {
    let mut h = Fnv::new();
    h.shape(source);
    h.shape(target);
    // (Its schedule as arrays: either form of one schedule, one fingerprint.)
    h.eat(config.clone().with_schedule_arrays().to_toml().as_bytes());
    // Masked inputs' signal scale skips their masked vertices since this
    // tag: a checkpoint of a masked pair from before ran another
    // objective, and is refused.
    if source.mask().is_some() || target.mask().is_some() {
        h.eat(b"masked deviation");
    }
    h.hex()
}

/// The pair problem: a source, a target, the problem on the template
/// the current stage runs on, and the packing of its unknowns. Built by
/// [`Session::new`](Runner::new) and run by the [`Runner`].
pub struct Pair {
    /// The plan, the source (the stages' start) and the stage templates.
    stages: Stages,
    problem: Problem,
    target: FShape,
    /// The pre-alignment that moved the source or the target, if any.
    alignment: Option<crate::Alignment>,
    unknowns: Unknowns,
    /// The stage whose data term the problem holds.
    staged: Option<usize>,
    /// A coarser target per stage (`None`: the target), empty for none.
    stage_targets: Vec<Option<FShape>>,
    /// The template the problem holds: its key in `templates` (`None`:
    /// the source).
    on_template: Option<usize>,
    /// Whether `unknowns` carries the metric's matrices for the template
    /// the problem holds (built by the first stage on it: a stage template
    /// may replace the source before any stage runs on it).
    metric_built: bool,
    parallel: bool,
}

/// A registration of a source onto a target with a [`Config`], run stage
/// by stage ([`Runner::run`]), resumable ([`Runner::resume`]).
pub type Session = Runner<Pair>;

impl Pair {
    fn stage_target(&mut self, k: usize) -> Result<(), MatchError> {
        let (key, template) = self.stages.template_of(k);
        if key != self.on_template {
            self.problem = Problem::new(template, self.stages.plan.model.clone())?.with_parallel(self.parallel);
            self.on_template = key;
            self.staged = None;
            self.metric_built = false;
        }
        if !self.metric_built {
            self.unknowns =
                Unknowns::scaled(&self.problem, self.stages.plan.metrics, self.stages.plan.scales.as_ref())?;
            self.metric_built = true;
        }
        if self.staged != Some(k) {
            let stage = &self.stages.plan.stages[k];
            let target = self.stage_targets.get(k).and_then(Option::as_ref).unwrap_or(&self.target);
            self.problem.set_target(target, stage.kernel.clone())?;
            self.problem.set_integrator(stage.integrator.0, stage.integrator.1)?;
            self.staged = Some(k);
        }
        Ok(())
    }
}

impl Staged for Pair {
    type Objective<'a> = MatchObjective<'a>;
    const START: &'static str = "source";
    const INPUTS: &'static str = "source, target or configuration";

    fn stages(&self) -> &Stages {
        &self.stages
    }

    fn stages_mut(&mut self) -> &mut Stages {
        &mut self.stages
    }

    /// A stage template moves with the source when `[prealign]` moved it.
    fn stage_template(&self, template: FShape) -> Result<FShape, MatchError> {
        match &self.alignment {
            Some(a) if a.moving == crate::Moving::Source => a.apply(&template),
            _ => Ok(template),
        }
    }

    fn len_at(&self, k: usize) -> usize {
        self.stages.unknowns_len(k)
    }

    fn start(&mut self, k: usize, warm: Option<&[f64]>) -> Result<Vec<f64>, MatchError> {
        // Carried over before stage k's metric is built, so that the
        // transfer's dense factor and the metric's are not held at once.
        self.stages.start_of(k, warm)
    }

    fn prepare(&mut self, k: usize) -> Result<StageSetup, MatchError> {
        self.stage_target(k)?;
        Ok(StageSetup {
            template_vertices: self.problem.template().n_vertices(),
            target_vertices: self.stage_targets.get(k).and_then(Option::as_ref).unwrap_or(&self.target).n_vertices(),
            deformation: self.problem.model().kernel().path().to_string(),
            attachment: self.stages.plan.stages[k].kernel.position().path().to_string(),
        })
    }

    fn objective(&mut self, _k: usize) -> MatchObjective<'_> {
        MatchObjective::new(&self.problem, self.unknowns.clone())
    }
}

impl Runner<Pair> {
    /// Checks the configuration and the shapes, builds the problem (signal
    /// norm analysis, once) and starts an empty checkpoint.
    pub fn new(source: &FShape, target: &FShape, config: &Config) -> Result<Session, MatchError> {
        Self::new_observed(source, target, config, &mut ())
    }

    /// [`new`](Self::new), telling `observer` what the setup does
    /// ([`Observer::setup`]: the pre-alignment, the stages' simplified
    /// shapes) as it goes.
    pub fn new_observed(
        source: &FShape,
        target: &FShape,
        config: &Config,
        observer: &mut dyn Observer,
    ) -> Result<Session, MatchError> {
        if source.dim() != target.dim() || source.kind() != target.kind() {
            return Err(MatchError::Kinds(format!(
                "the source is a {} mesh in R^{}, the target a {} mesh in R^{}",
                source.kind().name(),
                source.dim(),
                target.kind().name(),
                target.dim()
            )));
        }
        if source.signal().is_some() && target.signal().is_some() && source.n_channels() != target.n_channels() {
            return Err(MatchError::InvalidInput(format!(
                "the source carries {} signal channels, the target {}",
                source.n_channels(),
                target.n_channels()
            )));
        }
        // A source without a signal starts from f_0 = 0 in as many
        // channels as the target has.
        let zeros;
        let source = match (source.signal(), target.n_channels()) {
            (None, k) if k > 1 => {
                zeros = source.clone().with_signals(Some(vec![0.0; source.n_vertices() * k]), k)?;
                &zeros
            }
            _ => source,
        };
        // With `[prealign]`, the registration runs on the aligned pair.
        let (source, target, alignment) = crate::prealign::prealigned(source, target, config, observer)?;
        let (source, target) = (&source, &target);
        let plan = config.plan(source, target)?;
        let counts: Vec<Option<usize>> = plan.stages.iter().map(|s| s.vertices).collect();
        let auto = counts.iter().any(Option::is_some);
        if auto {
            observer.setup(&format!("simplifying the source for {} stage(s)", counts.iter().flatten().count()));
        }
        let templates = crate::resolution::simplified_stages(source, &counts, "source")?;
        let targets = if plan.stages.iter().any(|s| s.coarse_target) {
            let counts: Vec<Option<usize>> =
                plan.stages.iter().map(|s| s.vertices.filter(|_| s.coarse_target)).collect();
            crate::resolution::simplified_stages(target, &counts, "target")?
        } else {
            Vec::new()
        };
        observer.setup("setting up the first stage's problem");
        // The problem on the first stage's template: a source that stage
        // templates replace at once is not set up.
        let problem = Problem::new(templates.first().and_then(Option::as_ref).unwrap_or(source), plan.model.clone())?;
        // The metric's matrices (a dense kernel factor) wait for the first
        // stage on the source: it may run on a stage template first.
        let unknowns = Unknowns::for_template(source, plan.model.kind(), plan.metrics, plan.scales.as_ref())?;
        let pair = Pair {
            stages: Stages::new(plan, source.clone()),
            problem,
            target: target.clone(),
            alignment,
            unknowns,
            staged: None,
            stage_targets: targets,
            on_template: None,
            metric_built: false,
            parallel: true,
        };
        let session = Runner::of(pair, fingerprint(source, target, config));
        let mut session = if auto { session.set_stage_templates(templates, false)? } else { session };
        // The problem holds stage 0's template: say so, or the first stage
        // would set it up again.
        session.staged.on_template = session.staged.stages.template_of(0).0;
        Ok(session)
    }

    /// Parallel (default) or serial work in every evaluation; the results
    /// are the same bit for bit.
    pub fn with_parallel(mut self, parallel: bool) -> Session {
        self.staged.problem.set_parallel(parallel);
        self.staged.parallel = parallel;
        self
    }

    /// The pre-alignment the session runs after (`[prealign]`), if any.
    pub fn alignment(&self) -> Option<&crate::Alignment> {
        self.staged.alignment.as_ref()
    }

    /// The target the session matches (moved by T⁻¹ with `[prealign]
    /// move = "target"`).
    pub fn target(&self) -> &FShape {
        &self.staged.target
    }

    /// The problem (template, model, current target).
    pub fn problem(&self) -> &Problem {
        &self.staged.problem
    }

    /// The packing of the unknowns (of the stage that ran or runs last; it
    /// carries the energy metric's matrices once a stage has started).
    pub fn unknowns(&self) -> &Unknowns {
        &self.staged.unknowns
    }

    /// The result of a finished run: the final momenta, shot once more with
    /// the last stage's data term.
    pub fn result(&mut self) -> Result<MatchResult, MatchError> {
        if !self.is_finished() {
            return Err(MatchError::NotFinished);
        }
        let x = self.checkpoint().warm.clone().ok_or(MatchError::NotFinished)?;
        let (p0, pf) = self.staged.stages.unknowns_of(self.plan().stages.len() - 1)?.unpack(&x);
        self.shot(p0, pf, true)
    }

    /// The result as of now, for a run an observer stopped before its end
    /// (scipy's callbacks and argmin's observers end a run, they do not
    /// fail it): the current point of the stage under way, or the end of
    /// the last finished stage, carried to the source's vertices if that
    /// stage ran on a coarser template, and shot with the last stage's
    /// data term like [`Session::result`](Runner::result), marked
    /// `finished: false`. The finished run's result once every stage has
    /// run; `None` before the first iteration of the first stage.
    pub fn result_so_far(&mut self) -> Result<Option<MatchResult>, MatchError> {
        if self.is_finished() {
            return self.result().map(Some);
        }
        let c = self.checkpoint();
        let done = c.done.len();
        let (k, x) = match (&c.current, &c.warm) {
            (Some(current), _) => (done, current.state.x.clone()),
            (None, Some(warm)) => (done - 1, warm.clone()),
            (None, None) => return Ok(None),
        };
        let pair = &self.staged;
        let last = pair.stages.plan.stages.len() - 1;
        let (mut p0, mut pf) = pair.stages.unknowns_of(k)?.unpack(&x);
        if pair.stages.template_of(k).0 != pair.stages.template_of(last).0 {
            let (coarse, fine) = (pair.stages.template_of(k).1, pair.stages.template_of(last).1);
            let model = &pair.stages.plan.model;
            (p0, pf) = crate::resolution::prolongate_fitted(coarse, fine, &p0, &pf, model.kind(), model.kernel())?;
        }
        self.shot(p0, pf, false).map(Some)
    }

    /// Shoots momenta on the source with the last stage's data term and
    /// measures where they end.
    fn shot(&mut self, p0: Vec<f64>, pf: Vec<f64>, finished: bool) -> Result<MatchResult, MatchError> {
        let pair = &mut self.staged;
        pair.stage_target(pair.stages.plan.stages.len() - 1)?;
        let (energies, trajectory) = pair.problem.objective(&p0, &pf)?;
        let template = pair.problem.template();
        let last = trajectory.steps();
        let matched = template
            .clone()
            .with_points(trajectory.points(last).to_vec())?
            .with_signals(Some(trajectory.signal(last).to_vec()), template.n_channels().max(1))?;
        let quality = crate::quality(&matched, &pair.target)?;
        let initial_quality = crate::quality(template, &pair.target)?;
        let alignment = pair.alignment.clone();
        // Finished stages, and the one under way when stopped within it.
        let checkpoint = self.checkpoint();
        let (iterations, evaluations) = checkpoint.totals();
        Ok(MatchResult {
            p0,
            pf,
            energies,
            trajectory,
            stages: checkpoint.done.clone(),
            iterations,
            evaluations,
            seconds: checkpoint.seconds,
            quality,
            initial_quality,
            alignment,
            finished,
        })
    }
}

/// J and its gradient in the unknowns, with J's parts.
pub struct MatchObjective<'p> {
    problem: &'p Problem,
    unknowns: Unknowns,
    /// Evaluations so far (the first one's errors are always reported).
    evaluations: usize,
}

impl<'p> MatchObjective<'p> {
    /// J of `problem` in `unknowns`.
    pub fn new(problem: &'p Problem, unknowns: Unknowns) -> Self {
        MatchObjective { problem, unknowns, evaluations: 0 }
    }

    /// The packing.
    pub fn unknowns(&self) -> &Unknowns {
        &self.unknowns
    }
}

impl crate::optimize::Objective for MatchObjective<'_> {
    type Error = MatchError;
    type Parts = Energies;

    /// p_0, then the signal's control (when there is one).
    fn blocks(&self) -> Vec<usize> {
        self.unknowns.blocks()
    }

    fn precondition(&self, v: &mut [f64]) {
        self.unknowns.precondition(v);
    }

    fn value_grad(&mut self, x: &[f64]) -> Result<Evaluation<Energies>, MatchError> {
        let (p0, pf) = self.unknowns.unpack(x);
        self.evaluations += 1;
        let g = match self.problem.objective_grad(&p0, &pf) {
            Ok(g) => g,
            Err(e) => return too_far(e, self.evaluations, x.len()),
        };
        let grad = self.unknowns.pack_grad(&g.p0, &g.pf);
        Ok(Evaluation { value: g.objective.value, grad, parts: g.objective })
    }
}

/// A shooting's error as an objective sees it: after the first point, a
/// shooting that diverges, or folds the mesh until a cell has no area, is
/// a step that went too far: the line search steps back (a non-finite
/// value, `len` NaN gradient entries), the run goes on. At the first point,
/// and for errors of the setup itself, the error is the answer.
pub(crate) fn too_far(e: ShootError, evaluations: usize, len: usize) -> Result<Evaluation<Energies>, MatchError> {
    if evaluations > 1 && step_too_far(&e) {
        let nan = Energies { value: f64::NAN, energy: f64::NAN, signal_energy: f64::NAN, attachment: f64::NAN };
        return Ok(Evaluation { value: f64::NAN, grad: vec![f64::NAN; len], parts: nan });
    }
    Err(e.into())
}

/// Whether a shooting's error, past an objective's first point, is a step
/// that went too far (which the line search undoes) rather than an error
/// of the setup.
pub(crate) fn step_too_far(e: &ShootError) -> bool {
    !matches!(e, ShootError::Invalid { .. } | ShootError::Dimension { .. } | ShootError::NoTarget)
}

/// Minimises J from (p_0, p^f) with `settings`, in one stage and in
/// memory (a [`crate::Session`] adds stages, checkpoints and resume);
/// `each` sees the optimiser state and J's parts after every accepted
/// step. Returns the final state (its `x` unpacks with
/// [`Unknowns::unpack`]) and why it stopped.
pub fn minimize(
    problem: &Problem,
    metric: impl Into<Metrics>,
    p0: &[f64],
    pf: &[f64],
    settings: &Settings,
    mut each: impl FnMut(&State, &Energies),
) -> Result<(State, Stop, Unknowns), crate::MatchError> {
    let unknowns = Unknowns::new(problem, metric)?;
    let mut objective = MatchObjective::new(problem, unknowns.clone());
    let (mut state, _) = State::start(unknowns.pack(p0, pf), &mut objective)?;
    let stop = loop {
        match state.iterate(settings, &mut objective)? {
            Step::Stopped(stop) => break stop,
            Step::Accepted(parts) => each(&state, &parts),
        }
    };
    Ok((state, stop, unknowns))
}
