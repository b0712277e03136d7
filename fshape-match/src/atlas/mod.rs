//! Atlas estimation: a template fshape (x̄, f̄) and, per subject Y_i, the
//! momenta (p_0ⁱ, p^{f,i}) of a geodesic from the template to it,
//! minimising the mean of the subjects' matching objectives
//!
//! ```text
//! J(x̄, f̄, (p_0ⁱ, p^{f,i})_i) = (1/N) Σ_i [ H(x̄, f̄, p_0ⁱ, p^{f,i}) + γ_W A(x_1ⁱ, f_1ⁱ; Y_i) ]
//! ```
//!
//! jointly in every unknown by L-BFGS: the *free template* of the fshape
//! literature (fshapesTk's), whose positions and signal are unknowns. The
//! mean rather than the sum keeps γ_W's meaning per subject whatever the
//! population's size. Each subject's term and its gradients, in its own
//! momenta and in the template ([`fshape_shoot::Gradient::x0`], `f0`), come
//! from one shooting and its adjoint; the subjects are evaluated in
//! parallel and their template gradients summed in subject order, so a
//! run gives the same bits for any number of threads.
//!
//! The unknowns, in order: the template's positions (divided by the length
//! scale L when the weights are normalised), its signal (each of its k
//! maps divided by that map's signal scale S_c), then each subject's momenta packed as in matching
//! ([`crate::unknowns::Unknowns`]). L-BFGS's initial Hessian is block-diagonal
//! ([`crate::optimize::Objective::precondition`]): on the positions the
//! deformation kernel K(x̄) (the Sobolev gradient: a step moves the template
//! by a velocity field of V, as fshapesTk smooths its template gradient),
//! on the signal the lumped mass's inverse D̄⁻¹ (the L² gradient of a
//! function; ∂J/∂f̄ is a density), on each subject's momenta the matching
//! metric. These matrices are built once, on the initial template, so that
//! the change of variables is fixed for the whole run and a checkpoint's
//! unknowns mean the same in every stage.
//!
//! The *hypertemplate* model (`[atlas] template = "hypertemplate"`)
//! replaces the template's positions by momenta P_0 that shoot the initial
//! template (the hypertemplate, fixed) to the template by LDDMM with the
//! deformation kernel, and adds their energy (γ_V0/2)‖v‖²_V to J: the
//! template stays a diffeomorphic image of the hypertemplate (no folds, its
//! mesh quality kept), at the price of one more shooting per evaluation.
//! The gradient in P_0 is the adjoint of that shooting with the subjects'
//! mean ∂J/∂x̄ as its end co-state ([`Problem::pullback`]); P_0 takes the
//! matching metric of momenta. The signal stays a free unknown. The free
//! template is the default: it is fshapesTk's, costs nothing more than the
//! subjects, and on the known-answer test comes back as close.
//!
//! Stages may run on coarser versions of the initial template
//! ([`Runner::with_stage_templates`]), each with its own unknowns; between
//! them the template's displacement and signal change are interpolated as
//! functions and the momenta carried keeping their velocity field, as in
//! matching.
//!
//! The modules: [`objective`] (J, its gradient and the gathered records),
//! [`cluster`] (the processes subjects are shared among), `levels` (one
//! resolution's working set and the transfer between them), [`pca`] (the
//! population's modes).

pub mod cluster;
mod levels;
pub mod objective;
pub mod pca;

use fshape_mesh::FShape;
use fshape_shoot::{Energies, ModelKind, Problem, Trajectory};

pub use cluster::{Cluster, Local};
use levels::Level;
pub use objective::AtlasObjective;
pub use pca::{Mode, Modes};

use crate::runner::{Fnv, Runner, StageSetup, Staged, Stages};
use crate::{Config, MatchError, StageRecord};

impl AtlasResult {
    /// The template shot by subject `i`'s momenta: the shape at t = 1
    /// that is matched to it (the template's cells and mask).
    ///
    /// # Panics
    ///
    /// If there is no subject `i`.
    pub fn matched(&self, i: usize) -> Result<FShape, MatchError> {
        matched(&self.template, &self.subjects[i].trajectory)
    }
}

/// `template` moved to the end of `trajectory`, with its signal there.
fn matched(template: &FShape, trajectory: &Trajectory) -> Result<FShape, MatchError> {
    let last = trajectory.steps();
    let k = template.n_channels();
    Ok(template
        .clone()
        .with_points(trajectory.points(last).to_vec())?
        .with_signals(Some(trajectory.signal(last).to_vec()), k)?)
}

/// The initial template as the CLI and the Python package take it: a
/// template without a signal gets the subjects' mean signal, vertex by
/// vertex when every subject has the template's vertex count, else their
/// overall mean; with a signal, or when no subject has one, it is kept.
/// With several maps per vertex every map is averaged on its own; the
/// shapes that carry a signal must carry the same number of maps
/// ([`channels`]).
///
/// Masks: a subject's signal counts with its mask's weight (its masked
/// vertices not at all). The template keeps a mask it was given;
/// otherwise, when the subjects share its vertices and one of them is
/// masked, its mask is the largest of theirs vertex by vertex, so a
/// vertex is masked where no subject has a value (the medial wall of a
/// population on one standard mesh, such as fs_LR 32k). A vertex of the
/// template's mask without any subject's value takes the overall mean.
pub fn initial_template(template: FShape, subjects: &[FShape]) -> Result<FShape, MatchError> {
    let k = channels(&template, subjects)?;
    if template.signal().is_some() {
        return Ok(template);
    }
    let n = template.n_vertices();
    let with: Vec<(&[f64], Option<&[f64]>)> =
        subjects.iter().filter_map(|s| s.signal().map(|f| (f, s.mask()))).collect();
    if with.is_empty() {
        return Ok(template);
    }
    let weight = |m: Option<&[f64]>, v: usize| m.map_or(1.0, |m| m[v]);
    // A weighted sum and its total weight, a masked value left out.
    let add = |(s, t): (f64, f64), w: f64, x: f64| if w > 0.0 { (s + w * x, t + w) } else { (s, t) };
    // Each map's overall mean, its values read vertex by vertex.
    let overall: Vec<f64> = (0..k)
        .map(|c| {
            let (sum, total) = with.iter().fold((0.0, 0.0), |acc, (f, m)| {
                f.iter().skip(c).step_by(k).enumerate().fold(acc, |acc, (v, &x)| add(acc, weight(*m, v), x))
            });
            if total > 0.0 { sum / total } else { 0.0 }
        })
        .collect();
    if !with.iter().all(|(f, _)| f.len() == n * k) {
        let signal = (0..n).flat_map(|_| overall.iter().copied()).collect();
        return Ok(template.with_signals(Some(signal), k)?);
    }
    let own = template.mask().map(<[f64]>::to_vec);
    let largest = with
        .iter()
        .any(|(_, m)| m.is_some())
        .then(|| (0..n).map(|v| with.iter().map(|(_, m)| weight(*m, v)).fold(0.0, f64::max)).collect::<Vec<f64>>());
    let mask = own.or(largest);
    let signal = (0..n * k)
        .map(|i| {
            let (v, c) = (i / k, i % k);
            let (s, t) = with.iter().fold((0.0, 0.0), |acc, (f, m)| add(acc, weight(*m, v), f[i]));
            if t > 0.0 { s / t } else { overall[c] }
        })
        .collect();
    Ok(template.with_signals_and_mask(Some(signal), k, mask)?)
}

/// The number of maps per vertex of an atlas of `template` and
/// `subjects`: the count every shape with a signal carries (1 when none
/// has one). Shapes that carry different counts are an error naming them.
pub fn channels(template: &FShape, subjects: &[FShape]) -> Result<usize, MatchError> {
    let named = std::iter::once(("the template".to_string(), template))
        .chain(subjects.iter().enumerate().map(|(i, s)| (format!("subject {i}"), s)));
    let mut first: Option<(String, usize)> = None;
    for (name, shape) in named.filter(|(_, s)| s.signal().is_some()) {
        let k = shape.n_channels();
        match &first {
            None => first = Some((name, k)),
            Some((which, j)) if *j != k => {
                return Err(MatchError::InvalidInput(format!(
                    "{which} carries {j} signal map(s) per vertex and {name} carries {k}: an atlas's shapes carry \
                     the same maps"
                )));
            }
            Some(_) => {}
        }
    }
    Ok(first.map_or(1, |(_, k)| k))
}

/// One subject's part of an atlas result.
#[derive(Clone, Debug)]
pub struct SubjectResult {
    /// Its initial momenta p_0 (P × n, on the template's vertices).
    pub p0: Vec<f64>,
    /// Its signal momentum p^f (ζ for the tangential model, 0 for LDDMM).
    pub pf: Vec<f64>,
    /// Its J_i and parts, with the last stage's kernel.
    pub energies: Energies,
    /// The geodesic from the template to it.
    pub trajectory: Trajectory,
    /// How close the template shot by its momenta came to it.
    pub quality: crate::Quality,
    /// How close the estimated template itself is to it.
    pub template_quality: crate::Quality,
    /// The data term A at the start: the initial template against it,
    /// with the last stage's kernel.
    pub initial_attachment: f64,
    /// The pre-alignment that moved it onto the initial template
    /// (`[prealign]`), if any.
    pub alignment: Option<crate::Alignment>,
}

/// The atlas: the template and every subject's geodesic.
#[derive(Clone, Debug)]
pub struct AtlasResult {
    /// The estimated template (the initial template's cells).
    pub template: FShape,
    /// Hypertemplate model: the momenta P_0 shooting the initial template
    /// (the hypertemplate) to the template.
    pub template_momenta: Option<Vec<f64>>,
    /// Per subject, in the order given.
    pub subjects: Vec<SubjectResult>,
    /// The mean J and parts at the result.
    pub energies: Energies,
    /// Every stage's records (J and parts are means over the subjects).
    pub stages: Vec<StageRecord>,
    /// Accepted iterations, all stages.
    pub iterations: usize,
    /// Objective evaluations, all stages.
    pub evaluations: usize,
    /// Wall seconds, all runs.
    pub seconds: f64,
}

/// The population problem: the initial template, the subjects, the
/// working level and the processes the subjects are shared among. Built by
/// [`Atlas::new`](Runner::new) and run by the [`Runner`].
pub struct Population {
    /// The plan, the initial template at full resolution (with a signal:
    /// the stages' start) and the stage templates.
    stages: Stages,
    /// The subjects (pre-aligned with `[prealign]`).
    subjects: Vec<FShape>,
    /// Per subject, the pre-alignment that moved it, if any.
    alignments: Vec<Option<crate::Alignment>>,
    /// Per stage, the subjects simplified for it (`[schedule] vertices`
    /// with coarse targets) or `None` (the subjects themselves).
    stage_subjects: Vec<Option<Vec<FShape>>>,
    hyper_model: Option<fshape_shoot::Model>,
    /// The working level, built when first needed (after
    /// [`Atlas::with_cluster`](Runner::with_cluster), so that a process
    /// sets up only its own subjects).
    level: Option<Level>,
    /// The key of the level's template ([`StageTemplates::of`]).
    on: Option<usize>,
    cluster: Box<dyn Cluster>,
    /// The stage whose data term the level's problems hold.
    staged: Option<usize>,
}

/// An atlas estimation run: stages of the schedule one after the other,
/// with a checkpoint after every accepted iteration and resume to the same
/// bits, as [`crate::Session`] for one registration. Stages may run on
/// coarser versions of the initial template
/// ([`Runner::with_stage_templates`]).
pub type Atlas = Runner<Population>;

/// FNV-1a, as hex, of the initial template, the subjects and the
/// configuration.
pub fn atlas_fingerprint(template: &FShape, subjects: &[FShape], config: &Config) -> String {
    let mut h = Fnv::new();
    h.eat(b"atlas");
    h.shape(template);
    for s in subjects {
        h.shape(s);
    }
    // (Its schedule as arrays: either form of one schedule, one fingerprint.)
    h.eat(config.clone().with_schedule_arrays().to_toml().as_bytes());
    // As for a pair: masked inputs' signal scale skips masked vertices
    // since this tag.
    if std::iter::once(template).chain(subjects).any(|s| s.mask().is_some()) {
        h.eat(b"masked deviation");
    }
    h.hex()
}

/// The number of a subject's unknowns on a template of `n` vertices in
/// R^dim with `k` maps.
fn subject_len(n: usize, dim: usize, k: usize, kind: ModelKind) -> usize {
    n * dim + if kind == ModelKind::Lddmm { 0 } else { n * k }
}

impl Population {
    /// The number of unknowns of stage `stage`: its template's positions
    /// and signal, then every subject's momenta.
    fn len_at(&self, stage: usize) -> usize {
        let t = self.stages.template_of(stage).1;
        let (n, k) = (t.n_vertices(), t.n_channels());
        n * (t.dim() + k) + self.subjects.len() * subject_len(n, t.dim(), k, self.stages.plan.model.kind())
    }

    /// The starting unknowns of stage `stage`'s template
    /// ([`Atlas::len_at`] values): the initial template (P_0 = 0 for the
    /// hypertemplate) and zero momenta.
    fn initial_unknowns_at(&mut self, stage: usize) -> Result<Vec<f64>, MatchError> {
        self.check_stage(stage)?;
        self.ensure_level(stage)?;
        let n = self.subjects.len();
        Ok(self.level().start(n))
    }

    fn stage_target(&mut self, k: usize) -> Result<(), MatchError> {
        self.ensure_level(k)?;
        if self.staged != Some(k) {
            let stage = &self.stages.plan.stages[k];
            let subjects = self.stage_subjects.get(k).and_then(Option::as_ref).unwrap_or(&self.subjects);
            let level = self.level.as_mut().expect("ensured");
            for (problem, subject) in level.problems.iter_mut().zip(&subjects[level.mine.clone()]) {
                problem.set_target(subject, stage.kernel.clone())?;
                problem.set_integrator(stage.integrator.0, stage.integrator.1)?;
            }
            self.staged = Some(k);
        }
        Ok(())
    }

    /// Errors unless `stage` is in the schedule.
    fn check_stage(&self, stage: usize) -> Result<(), MatchError> {
        if stage >= self.stages.plan.stages.len() {
            return Err(MatchError::NoSuchStage { stage, stages: self.stages.plan.stages.len() });
        }
        Ok(())
    }

    /// Errors unless `stage` is in the schedule and `x` has its number of
    /// unknowns.
    fn check_len(&self, stage: usize, x: &[f64]) -> Result<(), MatchError> {
        self.check_stage(stage)?;
        let n = self.len_at(stage);
        if x.len() != n {
            return Err(MatchError::UnknownsLength { stage, got: x.len(), expected: n });
        }
        Ok(())
    }
}

impl Staged for Population {
    type Objective<'a> = AtlasObjective<'a>;
    const START: &'static str = "initial template";
    const INPUTS: &'static str = "template, subjects or configuration";

    fn stages(&self) -> &Stages {
        &self.stages
    }

    fn stages_mut(&mut self) -> &mut Stages {
        &mut self.stages
    }

    /// A stage template without a signal takes the initial template's,
    /// read at its vertices.
    fn stage_template(&self, template: FShape) -> Result<FShape, MatchError> {
        if template.signal().is_some() {
            return Ok(template);
        }
        let source = &self.stages.start;
        let (signal, mask) = crate::resolution::sample_signal(source, &template)?;
        let mask = template.mask().map(<[f64]>::to_vec).or(mask);
        Ok(template.with_signals_and_mask(Some(signal), source.n_channels(), mask)?)
    }

    fn len_at(&self, k: usize) -> usize {
        Population::len_at(self, k)
    }

    fn start(&mut self, k: usize, warm: Option<&[f64]>) -> Result<Vec<f64>, MatchError> {
        match warm {
            None => self.initial_unknowns_at(k),
            // On a finer template the solution is carried over.
            Some(w) => self.prolongate_unknowns(k - 1, w, k),
        }
    }

    fn prepare(&mut self, k: usize) -> Result<StageSetup, MatchError> {
        self.stage_target(k)?;
        let first = self.stage_subjects.get(k).and_then(Option::as_ref).unwrap_or(&self.subjects);
        let level = self.level.as_ref().expect("ensured");
        Ok(StageSetup {
            template_vertices: level.template.n_vertices(),
            target_vertices: first[0].n_vertices(),
            deformation: level.deformation.clone(),
            attachment: self.stages.plan.stages[k].kernel.position().path().to_string(),
        })
    }

    fn objective(&mut self, _k: usize) -> AtlasObjective<'_> {
        let n = self.subjects.len();
        self.level.as_mut().expect("prepared").objective(self.cluster.as_ref(), n)
    }
}

impl Runner<Population> {
    /// Checks the configuration and the shapes and builds one problem per
    /// subject on the initial `template`. With `model.normalize`, the
    /// scales (length L, signal S) are the initial template's against the
    /// first subject's, as [`Config::plan`] takes them for one match.
    pub fn new(template: &FShape, subjects: &[FShape], config: &Config) -> Result<Atlas, MatchError> {
        Self::new_observed(template, subjects, config, &mut ())
    }

    /// [`new`](Self::new), telling `observer` what the setup does
    /// ([`crate::Observer::setup`]: each subject's pre-alignment) as it goes.
    pub fn new_observed(
        template: &FShape,
        subjects: &[FShape],
        config: &Config,
        observer: &mut dyn crate::Observer,
    ) -> Result<Atlas, MatchError> {
        let k = channels(template, subjects)?;
        let first = subjects.first().ok_or(MatchError::NoSubjects)?;
        for (i, s) in subjects.iter().enumerate() {
            if s.dim() != template.dim() || s.kind() != template.kind() {
                return Err(MatchError::Kinds(format!(
                    "subject {i} is a {} mesh in R^{}, the template a {} mesh in R^{}",
                    s.kind().name(),
                    s.dim(),
                    template.kind().name(),
                    template.dim()
                )));
            }
        }
        // With `[prealign]`, every subject is moved onto the initial
        // template first (one pass; the plan then sees the moved subjects).
        let (moved, alignments) = match config.prealign.as_ref().filter(|s| s.kind != crate::AlignKind::None) {
            None => (subjects.to_vec(), vec![None; subjects.len()]),
            Some(section) => {
                let kernel = config.plan(template, first)?.stages[0].kernel.clone();
                let mut moved = Vec::with_capacity(subjects.len());
                let mut alignments = Vec::with_capacity(subjects.len());
                for (i, s) in subjects.iter().enumerate() {
                    observer.setup(&format!(
                        "pre-alignment ({}) of subject {} of {} begins",
                        section.kind.name(),
                        i + 1,
                        subjects.len()
                    ));
                    let a = crate::prealign::prealign(s, template, &kernel, section)?;
                    observer.setup(&format!("pre-alignment of subject {}: {}", i + 1, a.describe()));
                    moved.push(a.apply(s)?);
                    alignments.push(Some(a));
                }
                (moved, alignments)
            }
        };
        let subjects = &moved[..];
        let plan = config.plan(template, &subjects[0])?;
        let source = match template.signal() {
            Some(_) => template.clone(),
            None => template.clone().with_signals(Some(vec![0.0; template.n_vertices() * k]), k)?,
        };
        let section = config.atlas.clone().unwrap_or_default();
        let hyper_model = match section.template {
            crate::TemplateKind::Free => None,
            crate::TemplateKind::Hypertemplate => {
                let g = section.gamma_v0;
                if !(g > 0.0 && g.is_finite()) {
                    return Err(MatchError::Config {
                        key: "atlas.gamma_v0".into(),
                        message: format!("must be positive and finite, got {g}"),
                    });
                }
                let gamma_v0 = match &plan.scales {
                    Some(s) if config.model.normalize => s.effective(g, 1.0, 1.0).0,
                    _ => g,
                };
                let m = &plan.model;
                Some(m.clone().with_kind(ModelKind::Lddmm).with_weights(gamma_v0, m.gamma_f(), m.gamma_w())?)
            }
        };
        let counts: Vec<Option<usize>> = plan.stages.iter().map(|s| s.vertices).collect();
        let auto = counts.iter().any(Option::is_some);
        let templates = crate::resolution::simplified_stages(&source, &counts, "template")?;
        let mut stage_subjects = vec![None; plan.stages.len()];
        if plan.stages.iter().any(|s| s.coarse_target) {
            let counts: Vec<Option<usize>> =
                plan.stages.iter().map(|s| s.vertices.filter(|_| s.coarse_target)).collect();
            let mut per_subject = Vec::with_capacity(subjects.len());
            for (i, subject) in subjects.iter().enumerate() {
                per_subject.push(crate::resolution::simplified_stages(subject, &counts, &format!("subject {i}"))?);
            }
            for (k, slot) in stage_subjects.iter_mut().enumerate() {
                if counts[k].is_some() {
                    *slot = Some(
                        per_subject
                            .iter()
                            .zip(subjects)
                            .map(|(c, s)| c[k].clone().unwrap_or_else(|| s.clone()))
                            .collect(),
                    );
                }
            }
        }
        let stages = plan.stages.len();
        let fingerprint = atlas_fingerprint(&source, subjects, config);
        let population = Population {
            stages: Stages::new(plan, source),
            subjects: subjects.to_vec(),
            alignments,
            stage_subjects,
            hyper_model,
            level: None,
            on: None,
            cluster: Box::new(Local),
            staged: None,
        };
        debug_assert_eq!(population.stage_subjects.len(), stages);
        let atlas = Runner::of(population, fingerprint);
        if !auto {
            return Ok(atlas);
        }
        atlas.set_stage_templates(templates, false)
    }

    /// Shares the subjects' evaluations among the processes of `cluster`
    /// (every process builds the same atlas and runs it; results are the
    /// same bits as on one process). Give a checkpoint file to one
    /// process only.
    pub fn with_cluster(mut self, cluster: Box<dyn Cluster>) -> Atlas {
        self.staged.cluster = cluster;
        self
    }

    /// The initial template (with a zero signal if it had none).
    pub fn initial_template(&self) -> &FShape {
        &self.staged.stages.start
    }

    /// The number of unknowns of stage `stage`: its template's positions
    /// and signal, then every subject's momenta.
    pub fn len_at(&self, stage: usize) -> usize {
        self.staged.len_at(stage)
    }

    /// The number of unknowns at full resolution (the last stage's).
    pub fn len(&self) -> usize {
        self.len_at(self.plan().stages.len() - 1)
    }

    /// Whether there are no unknowns (never: a template has vertices).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The starting unknowns of stage `stage`'s template
    /// ([`Atlas::len_at`](Runner::len_at) values): the initial template
    /// (P_0 = 0 for the hypertemplate) and zero momenta.
    pub fn initial_unknowns_at(&mut self, stage: usize) -> Result<Vec<f64>, MatchError> {
        self.staged.initial_unknowns_at(stage)
    }

    /// [`Atlas::initial_unknowns_at`](Runner::initial_unknowns_at) the
    /// last stage (full resolution).
    pub fn initial_unknowns(&mut self) -> Result<Vec<f64>, MatchError> {
        self.initial_unknowns_at(self.plan().stages.len() - 1)
    }

    /// How many subjects this process has set up (its block of the
    /// cluster's subjects, once a stage has started; 0 before).
    pub fn subjects_set_up(&self) -> usize {
        self.staged.level.as_ref().map_or(0, |l| l.problems.len())
    }

    /// Stage `stage`'s unknowns `x` read as the template they put (its
    /// positions and signal) and every subject's momenta (p_0, p^f).
    #[allow(clippy::type_complexity)]
    pub fn unpack(&mut self, stage: usize, x: &[f64]) -> Result<(FShape, Vec<(Vec<f64>, Vec<f64>)>), MatchError> {
        self.staged.check_len(stage, x)?;
        let s = self.staged.solution(stage, x)?;
        Ok((s.template, s.momenta))
    }

    /// Stage `from`'s unknowns `x` carried to stage `to`'s template (as
    /// [`Runner::run`] does between stages on different templates; `x`
    /// itself when the two stages share one).
    pub fn prolongate_unknowns(&mut self, from: usize, x: &[f64], to: usize) -> Result<Vec<f64>, MatchError> {
        self.staged.prolongate_unknowns(from, x, to)
    }

    /// The result of a finished run: the template, and every subject's
    /// momenta shot once more with the last stage's data term.
    pub fn result(&mut self) -> Result<AtlasResult, MatchError> {
        if !self.is_finished() {
            return Err(MatchError::NotFinished);
        }
        let x = self.checkpoint().warm.clone().ok_or(MatchError::NotFinished)?;
        let (iterations, evaluations) = self.checkpoint().totals();
        let (stages, seconds) = (self.checkpoint().done.clone(), self.checkpoint().seconds);
        let population = &mut self.staged;
        let last_stage = population.stages.plan.stages.len() - 1;
        population.stage_target(last_stage)?;
        let stage = &population.stages.plan.stages[last_stage];
        let model = population.stages.plan.model.clone();
        let level = population.level.as_mut().expect("ensured");
        let (template, template_momenta, hyper_energy) = level.template_at(&x)?;
        let len = level.unknowns.len();
        let offset = template.n_vertices() * (template.dim() + template.n_channels());
        let n = population.subjects.len() as f64;
        let mut energies = Energies { value: 0.0, energy: 0.0, signal_energy: 0.0, attachment: 0.0 };
        let mut subjects = Vec::with_capacity(population.subjects.len());
        let start = &population.stages.start;
        let k = start.n_channels();
        let zeros = (vec![0.0; start.n_vertices() * start.dim()], vec![0.0; start.n_vertices() * k]);
        for (i, subject) in population.subjects.iter().enumerate() {
            // This process's subjects are set up; the others (on process 0
            // of a cluster, which reports) one at a time.
            let mut spare;
            let problem = match i.checked_sub(level.mine.start).and_then(|j| level.problems.get_mut(j)) {
                Some(p) => p,
                None => {
                    spare = Problem::new(&level.template, model.clone())?.with_target(subject, stage.kernel.clone())?;
                    spare.set_integrator(stage.integrator.0, stage.integrator.1)?;
                    &mut spare
                }
            };
            problem.set_template(start.points(), start.signal())?;
            let initial_attachment = problem.objective(&zeros.0, &zeros.1)?.0.attachment;
            problem.set_template(template.points(), template.signal())?;
            let (p0, pf) = level.unknowns.unpack(&x[offset + i * len..offset + (i + 1) * len]);
            let (e, trajectory) = problem.objective(&p0, &pf)?;
            energies.value += e.value / n;
            energies.energy += e.energy / n;
            energies.signal_energy += e.signal_energy / n;
            energies.attachment += e.attachment / n;
            let matched = matched(&template, &trajectory)?;
            subjects.push(SubjectResult {
                quality: crate::quality(&matched, subject)?,
                template_quality: crate::quality(&template, subject)?,
                initial_attachment,
                alignment: population.alignments[i].clone(),
                p0,
                pf,
                energies: e,
                trajectory,
            });
        }
        energies.value += hyper_energy;
        energies.energy += hyper_energy;
        Ok(AtlasResult { template, template_momenta, subjects, energies, stages, iterations, evaluations, seconds })
    }

    /// J (the mean over subjects) and its gradient in the [`Atlas::len`](Runner::len)
    /// unknowns `x`, with stage `stage`'s data term: for tests, and for
    /// callers that drive an optimiser themselves.
    pub fn value_grad(&mut self, stage: usize, x: &[f64]) -> Result<(f64, Vec<f64>), MatchError> {
        use crate::optimize::Objective;
        let population = &mut self.staged;
        population.check_len(stage, x)?;
        population.stage_target(stage)?;
        let e = population.objective(stage).value_grad(x)?;
        Ok((e.value, e.grad))
    }

    /// Applies stage `stage`'s initial Hessian shape M⁻¹ (module docs) to
    /// `v` ([`Atlas::len_at`](Runner::len_at) values).
    pub fn precondition(&mut self, stage: usize, v: &mut [f64]) -> Result<(), MatchError> {
        use crate::optimize::Objective;
        let population = &mut self.staged;
        population.check_len(stage, v)?;
        population.ensure_level(stage)?;
        population.objective(stage).precondition(v);
        Ok(())
    }
}
