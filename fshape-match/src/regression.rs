//! Geodesic regression of one subject's visits: the visits problem
//! ([`Visits`]) that the stage engine ([`crate::runner`]) runs as a
//! [`Regress`] (stages coarse to fine, observers, checkpoints, resume),
//! J in the unknowns as an objective ([`RegressionObjective`]), and the
//! result.
//!
//! Time: the visits' ages a_v are mapped onto the shooting interval by
//! t_v = (a_v − a_0)/(a_last − a_0), so the earliest visit is the
//! baseline at t = 0 and the latest is at t = 1; the fitted momenta are
//! per that span (a velocity per year is the geodesic's velocity divided
//! by the span in years, [`RegressionResult::span`]). The baseline (the
//! template the geodesic starts from) is the earliest visit's mesh as
//! given; every visit, the earliest included, is attached with its
//! weight. With a `[prealign]` kind, every other visit is first moved
//! onto the baseline by its own map (rigid, similarity or affine, found on
//! the first stage's attachment as for a pair; `move` is not read: the
//! baseline is the frame), so that a subject scanned in different
//! positions is fitted in one frame. The model is fshape-shoot's [`Regression`]: the time grid has a
//! node at every visit, the adjoint jumps there.

use fshape_mesh::FShape;
use fshape_shoot::{Energies, Problem, Regression, RegressionEnergies, Trajectory};

use crate::optimize::Evaluation;
use crate::runner::{Fnv, Observer, Runner, StageRecord, StageSetup, Staged, Stages};
use crate::unknowns::Unknowns;
use crate::{Config, MatchError};

/// One visit: the subject's age (any unit) at it, its mesh with its
/// signal and mask, and its weight in J.
#[derive(Clone, Debug)]
pub struct Visit {
    /// The age or time of the visit.
    pub age: f64,
    /// The visit's functional shape.
    pub shape: FShape,
    /// Its weight w_v ≥ 0 (1 by default).
    pub weight: f64,
}

/// The regression's result.
#[derive(Clone, Debug)]
pub struct RegressionResult {
    /// The initial momenta p_0 (P × n) on the baseline, per `span`.
    pub p0: Vec<f64>,
    /// The signal momentum p^f (P × k; 0 for LDDMM).
    pub pf: Vec<f64>,
    /// J and its parts, each visit's attachment among them.
    pub energies: RegressionEnergies,
    /// The fitted geodesic from the baseline, on the normalised time
    /// grid (a node at every visit).
    pub trajectory: Trajectory,
    /// The age at t = 0 (the earliest visit's).
    pub t0: f64,
    /// The ages' span mapped onto [0, 1].
    pub span: f64,
    /// The age at t = 1 (the latest visit's, as given).
    pub t1: f64,
    /// Each visit's normalised time, in the order given.
    pub times: Vec<f64>,
    /// Each visit's node on the trajectory (its time is the node's).
    pub nodes: Vec<usize>,
    /// How close the fitted state at each visit's time is to the visit.
    pub quality: Vec<crate::Quality>,
    /// How close the baseline is to each visit, for comparison.
    pub initial_quality: Vec<crate::Quality>,
    /// Each visit's pre-alignment onto the baseline (`[prealign]`; `None`
    /// for the baseline and without one). The qualities above are of the
    /// visits as aligned.
    pub alignments: Vec<Option<crate::Alignment>>,
    /// Every finished stage's records.
    pub stages: Vec<StageRecord>,
    /// Accepted iterations, all stages.
    pub iterations: usize,
    /// Objective evaluations, all stages.
    pub evaluations: usize,
    /// Wall seconds, all runs.
    pub seconds: f64,
    /// Whether every stage ran to its stopping rule.
    pub finished: bool,
}

impl RegressionResult {
    /// The fitted state (x, f) at age `age` (within the visits' span; the
    /// trajectory's interpolation between its nodes).
    pub fn at_age(&self, age: f64) -> (Vec<f64>, Vec<f64>) {
        self.trajectory.at((age - self.t0) / self.span)
    }
}

/// The visits problem: the baseline's stages and the regression on the
/// template the current stage runs on.
pub struct Visits {
    stages: Stages,
    visits: Vec<Visit>,
    /// Normalised times, in the visits' order.
    times: Vec<f64>,
    /// Each visit's pre-alignment onto the baseline, if any.
    alignments: Vec<Option<crate::Alignment>>,
    t0: f64,
    span: f64,
    t1: f64,
    /// The regression of the stage set up (`None` before the first).
    regression: Option<Regression>,
    unknowns: Unknowns,
    /// The stage the regression is set up for.
    staged: Option<usize>,
    parallel: bool,
}

/// A geodesic regression run stage by stage ([`Runner::run`]),
/// resumable ([`Runner::resume`]).
pub type Regress = Runner<Visits>;

/// FNV-1a, as hex, of the visits (ages, weights, shapes bit for bit) and
/// the configuration, as [`crate::fingerprint`] for a pair.
pub fn fingerprint(visits: &[Visit], config: &Config) -> String {
    let mut h = Fnv::new();
    h.eat(b"regression");
    for v in visits {
        h.eat(&v.age.to_le_bytes());
        h.eat(&v.weight.to_le_bytes());
        h.shape(&v.shape);
    }
    h.eat(config.clone().with_schedule_arrays().to_toml().as_bytes());
    h.hex()
}

impl Visits {
    /// Sets stage k up: its integrator and attachment kernel on every
    /// visit, on its template. The problem (the signal norm's analysis) and
    /// the metric's matrices (a dense factor) are built again only when
    /// the template changes, as for a pair.
    fn set_stage(&mut self, k: usize) -> Result<(), MatchError> {
        if self.staged == Some(k) {
            return Ok(());
        }
        let plan = &self.stages.plan;
        let stage = &plan.stages[k];
        let (key, template) = self.stages.template_of(k);
        let same = self.staged.is_some_and(|j| self.stages.template_of(j).0 == key);
        let mut problem = match self.regression.take() {
            Some(r) if same => r.into_problem(),
            _ => Problem::new(template, plan.model.clone())?.with_parallel(self.parallel),
        };
        problem.set_integrator(stage.integrator.0, stage.integrator.1)?;
        if !same {
            self.unknowns = Unknowns::scaled(&problem, plan.metrics, plan.scales.as_ref())?;
        }
        let mut r = Regression::new(problem)?;
        for (v, t) in self.visits.iter().zip(&self.times) {
            r = r.with_visit(*t, &v.shape, stage.kernel.clone(), v.weight)?;
        }
        self.regression = Some(r);
        self.staged = Some(k);
        Ok(())
    }

    /// The regression of the stage set up.
    fn current(&self) -> &Regression {
        self.regression.as_ref().expect("set_stage runs before any evaluation")
    }
}

impl Staged for Visits {
    type Objective<'a> = RegressionObjective<'a>;
    const START: &'static str = "baseline";
    const INPUTS: &'static str = "visits or configuration";

    fn stages(&self) -> &Stages {
        &self.stages
    }

    fn stages_mut(&mut self) -> &mut Stages {
        &mut self.stages
    }

    fn len_at(&self, k: usize) -> usize {
        self.stages.unknowns_len(k)
    }

    fn start(&mut self, k: usize, warm: Option<&[f64]>) -> Result<Vec<f64>, MatchError> {
        self.stages.start_of(k, warm)
    }

    fn prepare(&mut self, k: usize) -> Result<StageSetup, MatchError> {
        self.set_stage(k)?;
        let problem = self.current().problem();
        Ok(StageSetup {
            template_vertices: problem.template().n_vertices(),
            target_vertices: self.visits.iter().map(|v| v.shape.n_vertices()).sum(),
            deformation: problem.model().kernel().path().to_string(),
            attachment: self.stages.plan.stages[k].kernel.position().path().to_string(),
        })
    }

    fn objective(&mut self, _k: usize) -> RegressionObjective<'_> {
        RegressionObjective::new(self.current(), self.unknowns.clone())
    }
}

impl Runner<Visits> {
    /// Checks the visits and the configuration and sets the regression up:
    /// the earliest visit is the baseline, the ages are mapped onto [0, 1].
    pub fn new(visits: Vec<Visit>, config: &Config) -> Result<Regress, MatchError> {
        Self::new_observed(visits, config, &mut ())
    }

    /// [`new`](Self::new), telling `observer` what the setup does.
    pub fn new_observed(
        visits: Vec<Visit>,
        config: &Config,
        observer: &mut dyn Observer,
    ) -> Result<Regress, MatchError> {
        let bad = |why: String| Err(MatchError::InvalidInput(why));
        if visits.len() < 2 {
            return bad(format!("a regression needs at least 2 visits, found {}", visits.len()));
        }
        for (i, v) in visits.iter().enumerate() {
            if !v.age.is_finite() {
                return bad(format!("visit {i}: its age {} is not a number", v.age));
            }
            if !(v.weight.is_finite() && v.weight >= 0.0) {
                return bad(format!("visit {i}: its weight {} is not a finite number ≥ 0", v.weight));
            }
        }
        let first = (0..visits.len()).min_by(|&a, &b| visits[a].age.total_cmp(&visits[b].age)).expect("2 visits");
        let last = (0..visits.len()).max_by(|&a, &b| visits[a].age.total_cmp(&visits[b].age)).expect("2 visits");
        let (t0, span) = (visits[first].age, visits[last].age - visits[first].age);
        let visits_last_age = visits[last].age;
        if span <= 0.0 {
            return bad(format!("every visit is at age {t0}: a regression needs visits at two ages at least"));
        }
        let baseline = &visits[first].shape;
        for (i, v) in visits.iter().enumerate() {
            let s = &v.shape;
            if s.dim() != baseline.dim() || s.kind() != baseline.kind() {
                return Err(MatchError::Kinds(format!(
                    "visit {i} is a {} mesh in R^{}, the baseline (visit {first}) a {} mesh in R^{}",
                    s.kind().name(),
                    s.dim(),
                    baseline.kind().name(),
                    baseline.dim()
                )));
            }
            if s.n_channels() != baseline.n_channels() || s.signal().is_some() != baseline.signal().is_some() {
                return bad(format!(
                    "visit {i} carries {} signal channel(s), the baseline (visit {first}) {}",
                    if s.signal().is_some() { s.n_channels() } else { 0 },
                    if baseline.signal().is_some() { baseline.n_channels() } else { 0 },
                ));
            }
        }
        let times = visits.iter().map(|v| (v.age - t0) / span).collect();
        // With [prealign], every other visit moved onto the baseline.
        let mut visits = visits;
        let mut alignments = vec![None; visits.len()];
        if config.prealign.as_ref().is_some_and(|s| s.kind != crate::AlignKind::None) {
            let mut onto = config.clone();
            if let Some(s) = onto.prealign.as_mut() {
                s.moving = crate::Moving::Source;
            }
            let baseline = visits[first].shape.clone();
            for (i, v) in visits.iter_mut().enumerate().filter(|(i, _)| *i != first) {
                observer.setup(&format!("visit {i} onto the baseline"));
                let (moved, _, alignment) = crate::prealign::prealigned(&v.shape, &baseline, &onto, observer)?;
                v.shape = moved;
                alignments[i] = alignment;
            }
        }
        let baseline = &visits[first].shape;
        let plan = config.plan(baseline, &visits[last].shape)?;
        let counts: Vec<Option<usize>> = plan.stages.iter().map(|s| s.vertices).collect();
        let auto = counts.iter().any(Option::is_some);
        if auto {
            observer.setup(&format!("simplifying the baseline for {} stage(s)", counts.iter().flatten().count()));
        }
        let templates = crate::resolution::simplified_stages(baseline, &counts, "baseline")?;
        let fingerprint = fingerprint(&visits, config);
        let stages = Stages::new(plan, baseline.clone());
        // A placeholder until the first stage sets its own up.
        let unknowns = Unknowns::for_template(baseline, stages.plan.model.kind(), stages.plan.metrics, None)?;
        let staged = Visits {
            stages,
            visits,
            times,
            alignments,
            t0,
            span,
            t1: visits_last_age,
            regression: None,
            unknowns,
            staged: None,
            parallel: true,
        };
        let runner = Runner::of(staged, fingerprint);
        if auto { runner.set_stage_templates(templates, false) } else { Ok(runner) }
    }

    /// The visits as fitted: in the baseline's frame with `[prealign]`.
    pub fn visits(&self) -> &[Visit] {
        &self.staged.visits
    }

    /// The baseline: the earliest visit's mesh, which the last stage runs on.
    pub fn baseline(&self) -> &FShape {
        &self.staged.stages.start
    }

    /// Parallel (default) or serial work in every evaluation; the results
    /// are the same bit for bit.
    pub fn with_parallel(mut self, parallel: bool) -> Regress {
        self.staged.parallel = parallel;
        self.staged.staged = None;
        self
    }

    /// The result of a finished run: the final momenta on the baseline,
    /// shot once more with the last stage's attachment, and each visit's
    /// quality.
    pub fn result(&mut self) -> Result<RegressionResult, MatchError> {
        if !self.is_finished() {
            return Err(MatchError::NotFinished);
        }
        let x = self.checkpoint().warm.clone().ok_or(MatchError::NotFinished)?;
        let last = self.plan().stages.len() - 1;
        let (p0, pf) = self.staged.stages.unknowns_of(last)?.unpack(&x);
        let v = &mut self.staged;
        v.set_stage(last)?;
        let regression = v.current();
        let (energies, trajectory) = regression.objective(&p0, &pf)?;
        let template = regression.problem().template();
        let nodes = regression.times().1.to_vec();
        let mut quality = Vec::with_capacity(v.visits.len());
        let mut initial_quality = Vec::with_capacity(v.visits.len());
        for (visit, &k) in v.visits.iter().zip(&nodes) {
            let fitted = template
                .clone()
                .with_points(trajectory.points(k).to_vec())?
                .with_signals(Some(trajectory.signal(k).to_vec()), template.n_channels())?;
            quality.push(crate::quality(&fitted, &visit.shape)?);
            initial_quality.push(crate::quality(template, &visit.shape)?);
        }
        let (t0, span, t1, times, alignments) = (v.t0, v.span, v.t1, v.times.clone(), v.alignments.clone());
        let checkpoint = self.checkpoint();
        let (iterations, evaluations) = checkpoint.totals();
        Ok(RegressionResult {
            p0,
            pf,
            energies,
            trajectory,
            t0,
            span,
            t1,
            times,
            nodes,
            quality,
            initial_quality,
            alignments,
            stages: checkpoint.done.clone(),
            iterations,
            evaluations,
            seconds: checkpoint.seconds,
            finished: true,
        })
    }
}

/// The regression's J and its gradient in the unknowns, with J's parts
/// as a pair's [`Energies`] (the attachment is Σ_v w_v A_v).
pub struct RegressionObjective<'p> {
    regression: &'p Regression,
    unknowns: Unknowns,
    evaluations: usize,
}

impl<'p> RegressionObjective<'p> {
    /// J of `regression` in `unknowns`.
    pub fn new(regression: &'p Regression, unknowns: Unknowns) -> Self {
        RegressionObjective { regression, unknowns, evaluations: 0 }
    }
}

impl crate::optimize::Objective for RegressionObjective<'_> {
    type Error = MatchError;
    type Parts = Energies;

    fn blocks(&self) -> Vec<usize> {
        self.unknowns.blocks()
    }

    fn precondition(&self, v: &mut [f64]) {
        self.unknowns.precondition(v);
    }

    fn value_grad(&mut self, x: &[f64]) -> Result<Evaluation<Energies>, MatchError> {
        let (p0, pf) = self.unknowns.unpack(x);
        self.evaluations += 1;
        let g = match self.regression.objective_grad(&p0, &pf) {
            Ok(g) => g,
            // As for a pair: past the first point, a step that went too far.
            Err(e) => return crate::session::too_far(e, self.evaluations, x.len()),
        };
        let o = &g.objective;
        let parts = Energies { value: o.value, energy: o.energy, signal_energy: o.signal_energy, attachment: o.data };
        Ok(Evaluation { value: o.value, grad: self.unknowns.pack_grad(&g.p0, &g.pf), parts })
    }
}
