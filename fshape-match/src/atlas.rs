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
//! scale L when the weights are normalised), its signal (divided by the
//! signal scale S), then each subject's momenta packed as in matching
//! ([`Unknowns`]). L-BFGS's initial Hessian is block-diagonal
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
//! ([`Atlas::with_stage_templates`]), each with its own unknowns; between
//! them the template's displacement and signal change are interpolated as
//! functions and the momenta carried keeping their velocity field, as in
//! matching.

use std::path::{Path, PathBuf};
use std::time::Instant;

use fshape_fem::{Norm, SignalNorm};
use fshape_kernels::{Kernel, KernelSums};
use fshape_mesh::FShape;
use fshape_shoot::{Energies, ModelKind, Problem, ShootError, Trajectory};
use rayon::prelude::*;

use crate::session::{Fnv, Journal, StageStart, checkpoint_error, run_stage};
use crate::unknowns::Unknowns;
use crate::{CHECKPOINT_FORMAT, Checkpoint, Config, MatchError, Observer, Outcome, Plan, StageRecord};

/// The template blocks' change of variables and initial Hessian.
struct TemplateMetric {
    /// x̄ = length · u_x.
    length: f64,
    /// f̄ = signal · u_f.
    signal: f64,
    /// The deformation kernel and the initial template's positions: M⁻¹
    /// on the positions is K(x̄_0).
    kernel: Kernel,
    points: Vec<f64>,
    dim: usize,
    /// m̄/m_i, the lumped masses' inverse scaled to mean 1.
    inv_mass: Vec<f64>,
}

impl TemplateMetric {
    fn new(template: &FShape, kernel: &Kernel, scales: Option<crate::Scales>) -> Result<Self, ShootError> {
        let masses = SignalNorm::try_new(template, Norm::L2Lumped)?.assemble(template.points())?;
        if let Some(v) = masses.iter().position(|m| m.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)) {
            return Err(fshape_fem::FemError::Singular { vertex: v }.into());
        }
        let mean = masses.iter().sum::<f64>() / masses.len() as f64;
        // Built once here, so that applying it later cannot fail.
        KernelSums::try_new(kernel, template.points(), template.dim())?;
        Ok(TemplateMetric {
            length: scales.map_or(1.0, |s| s.length),
            signal: scales.map_or(1.0, |s| s.signal),
            kernel: kernel.clone(),
            points: template.points().to_vec(),
            dim: template.dim(),
            inv_mass: masses.iter().map(|m| mean / m).collect(),
        })
    }
}

/// The hypertemplate's shooting: an LDDMM problem on the initial template
/// and the packing of its momenta P_0.
struct Hyper {
    problem: Problem,
    unknowns: Unknowns,
}

/// The template's positions of the first block of unknowns: scaled
/// positions (free template), or the end of the hypertemplate's shooting
/// by the P_0 they pack (with its trajectory, for the adjoint).
fn positions(
    hyper: Option<&Hyper>,
    metric: &TemplateMetric,
    block: &[f64],
) -> Result<(Vec<f64>, Option<Trajectory>), ShootError> {
    match hyper {
        None => Ok((block.iter().map(|u| u * metric.length).collect(), None)),
        Some(h) => {
            let (p0, pf) = h.unknowns.unpack(block);
            let traj = h.problem.shoot(&p0, &pf)?;
            Ok((traj.points(traj.steps()).to_vec(), Some(traj)))
        }
    }
}

/// One subject's evaluation, without its trajectory (one trajectory per
/// thread at a time).
struct SubjectEval {
    energies: Energies,
    /// ∂J_i/∂(its unknowns).
    grad: Vec<f64>,
    /// ∂J_i/∂x̄ and ∂J_i/∂f̄.
    x0: Vec<f64>,
    f0: Vec<f64>,
}

/// The processes an atlas's subjects are shared among (MPI ranks, say):
/// process r evaluates the subjects of [`Cluster::subjects`]`(r)`, a
/// contiguous block, and every process gathers every subject's terms in
/// subject order and sums them itself, so that J, its gradient and the
/// optimiser's state are the same bits on every process, and the same as
/// on one process, for any number of processes. The default is one
/// process ([`Local`]).
pub trait Cluster {
    /// This process's index, from 0.
    fn rank(&self) -> usize;
    /// The number of processes.
    fn size(&self) -> usize;
    /// Collective: every process's `mine`, concatenated in rank order.
    fn all_gather(&self, mine: &[f64]) -> Vec<f64>;
    /// The subjects (of `n`) process `rank` evaluates: contiguous blocks
    /// in order, of sizes differing by at most one.
    fn subjects(&self, rank: usize, n: usize) -> std::ops::Range<usize> {
        let size = self.size().max(1);
        rank * n / size..(rank + 1) * n / size
    }
}

/// One process: gathering is the identity.
#[derive(Clone, Copy, Debug, Default)]
pub struct Local;

impl Cluster for Local {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn all_gather(&self, mine: &[f64]) -> Vec<f64> {
        mine.to_vec()
    }
}

/// A subject's record in a gather: its status (0 evaluated, 1 a step too
/// far, 2 failed), then J_i's four parts, ∂J_i/∂(its unknowns), ∂J_i/∂x̄
/// and ∂J_i/∂f̄ (zeros unless evaluated).
fn record_len(len: usize, pn: usize, p: usize) -> usize {
    5 + len + pn + p
}

/// The atlas objective in the unknowns (module docs): the subjects'
/// problems hold the template of the last evaluation.
pub struct AtlasObjective<'p> {
    cluster: &'p dyn Cluster,
    /// This process's subjects' problems (`mine`), of `n_subjects`.
    problems: &'p mut [Problem],
    mine: std::ops::Range<usize>,
    n_subjects: usize,
    unknowns: Unknowns,
    metric: &'p TemplateMetric,
    hyper: Option<&'p Hyper>,
    /// P·n and P of the template.
    pn: usize,
    p: usize,
    /// The mean parts of every evaluation since `parts_of` last found one.
    recent: Vec<Energies>,
    evaluations: usize,
}

impl AtlasObjective<'_> {
    fn subject_len(&self) -> usize {
        self.unknowns.len()
    }

    /// Past the first point, a shooting that diverged is a step too far,
    /// which the line search undoes (as in matching): `None`, else the
    /// error.
    fn step_too_far(&self, err: ShootError) -> Result<(), MatchError> {
        if self.evaluations > 1
            && !matches!(err, ShootError::Invalid { .. } | ShootError::Dimension { .. } | ShootError::NoTarget)
        {
            Ok(())
        } else {
            Err(err.into())
        }
    }
}

impl crate::session::StageObjective for AtlasObjective<'_> {
    /// J's mean parts (as [`crate::unknowns::MatchObjective::parts_of`]).
    fn parts_of(&mut self, value: f64) -> Option<Energies> {
        crate::session::take_parts(&mut self.recent, value)
    }
}

impl crate::optimize::Objective for AtlasObjective<'_> {
    type Error = MatchError;

    /// Template positions, template signal, then each subject's p_0 and
    /// (with a signal control) p^f.
    fn blocks(&self) -> Vec<usize> {
        let mut starts = vec![self.pn];
        let m = self.subject_len();
        let signal_block = m > self.pn;
        for i in 0..self.n_subjects {
            let start = self.pn + self.p + i * m;
            starts.push(start);
            if signal_block {
                starts.push(start + self.pn);
            }
        }
        starts
    }

    fn precondition(&self, v: &mut [f64]) {
        let m = self.metric;
        match self.hyper {
            Some(h) => h.unknowns.precondition(&mut v[..self.pn]),
            None => {
                let sums = KernelSums::try_new(&m.kernel, &m.points, m.dim).expect("checked when built");
                let kv = sums.conv(&m.points, &v[..self.pn], m.dim).expect("checked when built");
                v[..self.pn].copy_from_slice(&kv);
            }
        }
        for (x, w) in v[self.pn..self.pn + self.p].iter_mut().zip(&m.inv_mass) {
            *x *= w;
        }
        let len = self.subject_len();
        for chunk in v[self.pn + self.p..].chunks_exact_mut(len) {
            self.unknowns.precondition(chunk);
        }
    }

    fn value_grad(&mut self, x: &[f64]) -> Result<(f64, Vec<f64>), MatchError> {
        self.evaluations += 1;
        let nan = || Ok((f64::NAN, vec![f64::NAN; x.len()]));
        let (points, traj) = match positions(self.hyper, self.metric, &x[..self.pn]) {
            Ok(p) => p,
            Err(e) => return self.step_too_far(e).and_then(|()| nan()),
        };
        let signal: Vec<f64> = x[self.pn..self.pn + self.p].iter().map(|u| u * self.metric.signal).collect();
        let len = self.subject_len();
        let unknowns = &self.unknowns;
        let (n_subjects, mine) = (self.n_subjects, self.mine.clone());
        let evals: Vec<Result<SubjectEval, ShootError>> = self
            .problems
            .par_iter_mut()
            .zip(x[self.pn + self.p..].par_chunks(len).skip(mine.start).take(mine.len()))
            .map(|(problem, xi)| {
                problem.set_template(&points, Some(&signal))?;
                let (p0, pf) = unknowns.unpack(xi);
                let g = problem.objective_grad(&p0, &pf)?;
                Ok(SubjectEval { energies: g.objective, grad: unknowns.pack_grad(&g.p0, &g.pf), x0: g.x0, f0: g.f0 })
            })
            .collect();
        // This process's records, gathered from all in subject order.
        let width = record_len(len, self.pn, self.p);
        let mut records = Vec::with_capacity(evals.len() * width);
        let mut failure = None;
        for (k, e) in evals.into_iter().enumerate() {
            match e {
                Ok(e) => {
                    let en = e.energies;
                    records.extend([0.0, en.value, en.energy, en.signal_energy, en.attachment]);
                    records.extend(e.grad.iter().chain(&e.x0).chain(&e.f0));
                }
                Err(err) => {
                    let status = match self.step_too_far(err) {
                        Ok(()) => 1.0,
                        Err(err) => {
                            failure.get_or_insert((mine.start + k, err));
                            2.0
                        }
                    };
                    records.push(status);
                    records.resize(records.len() + width - 1, 0.0);
                }
            }
        }
        let all = self.cluster.all_gather(&records);
        if all.len() != n_subjects * width {
            return Err(MatchError::Gather { got: all.len(), expected: n_subjects * width });
        }
        let n = n_subjects as f64;
        let mut grad = vec![0.0; x.len()];
        let mut mean = Energies { value: 0.0, energy: 0.0, signal_energy: 0.0, attachment: 0.0 };
        // ∂J/∂x̄, the mean of the subjects'.
        let mut gx = vec![0.0; self.pn];
        // Summed in subject order, read from the records: the same bits for
        // any number of threads or processes.
        for (i, r) in all.chunks_exact(width).enumerate() {
            if r[0] == 1.0 {
                return nan();
            }
            if r[0] != 0.0 {
                return Err(match failure {
                    Some((j, err)) if j == i => err,
                    _ => {
                        let rank = (0..self.cluster.size())
                            .find(|&q| self.cluster.subjects(q, n_subjects).contains(&i))
                            .unwrap_or(0);
                        MatchError::Remote { subject: i, rank }
                    }
                });
            }
            let (parts, rest) = r[1..].split_at(4);
            let (g_own, rest) = rest.split_at(len);
            let (x0, f0) = rest.split_at(self.pn);
            mean.value += parts[0] / n;
            mean.energy += parts[1] / n;
            mean.signal_energy += parts[2] / n;
            mean.attachment += parts[3] / n;
            for (g, v) in gx.iter_mut().zip(x0) {
                *g += v / n;
            }
            for (g, v) in grad[self.pn..self.pn + self.p].iter_mut().zip(f0) {
                *g += v * self.metric.signal / n;
            }
            let start = self.pn + self.p + i * len;
            for (g, v) in grad[start..start + len].iter_mut().zip(g_own) {
                *g = v / n;
            }
        }
        match (self.hyper, traj) {
            (Some(h), Some(traj)) => {
                // J also has the hypertemplate's energy H(P_0); its
                // gradient and the subjects' through x̄(P_0) by the adjoint.
                let (gp, _) = match h.problem.pullback(&traj, &gx, &vec![0.0; self.p]) {
                    Ok(g) => g,
                    Err(e) => return self.step_too_far(e).and_then(|()| nan()),
                };
                let e0 = traj.hamiltonian[0];
                mean.value += e0;
                mean.energy += e0;
                grad[..self.pn].copy_from_slice(&h.unknowns.pack_grad(&gp, &[]));
            }
            _ => {
                for (g, v) in grad[..self.pn].iter_mut().zip(&gx) {
                    *g = v * self.metric.length;
                }
            }
        }
        self.recent.push(mean);
        Ok((mean.value, grad))
    }
}

/// The initial template as the CLI and the Python package take it: a
/// template without a signal gets the subjects' mean signal, vertex by
/// vertex when every subject has the template's vertex count, else their
/// overall mean; with a signal, or when no subject has one, it is kept.
pub fn initial_template(template: FShape, subjects: &[FShape]) -> Result<FShape, MatchError> {
    if template.signal().is_some() {
        return Ok(template);
    }
    let n = template.n_vertices();
    let signals: Vec<&[f64]> = subjects.iter().filter_map(|s| s.signal()).collect();
    if signals.is_empty() {
        return Ok(template);
    }
    let mean = if signals.iter().all(|f| f.len() == n) {
        (0..n).map(|v| signals.iter().map(|f| f[v]).sum::<f64>() / signals.len() as f64).collect()
    } else {
        let (sum, count) = signals.iter().fold((0.0, 0usize), |(s, c), f| (s + f.iter().sum::<f64>(), c + f.len()));
        vec![sum / count.max(1) as f64; n]
    };
    Ok(template.with_signal(Some(mean))?)
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

/// One resolution's working set: the initial template at it (with a
/// signal), the subjects' problems on it, the packing of their momenta,
/// the template blocks' metric and the hypertemplate's shooting.
struct Level {
    template: FShape,
    /// The problems of this process's subjects (`mine`), in order: the
    /// others are set up by the processes that evaluate them.
    problems: Vec<Problem>,
    mine: std::ops::Range<usize>,
    unknowns: Unknowns,
    metric: TemplateMetric,
    hyper: Option<Hyper>,
    /// How the deformation kernel's sums are evaluated on this template.
    deformation: String,
}

impl Level {
    fn new(
        template: &FShape,
        mine: std::ops::Range<usize>,
        plan: &Plan,
        hyper: Option<&fshape_shoot::Model>,
    ) -> Result<Level, MatchError> {
        // Parallel over the subjects, each subject's work serial (the same
        // bits as parallel problems): the subjects fill the threads without
        // nested parallelism.
        let problems = mine
            .clone()
            .map(|_| Problem::new(template, plan.model.clone()).map(|p| p.with_parallel(false)))
            .collect::<Result<Vec<_>, _>>()?;
        let spare;
        let first = match problems.first() {
            Some(p) => p,
            None => {
                spare = Problem::new(template, plan.model.clone())?;
                &spare
            }
        };
        let deformation = first.model().kernel().path().to_string();
        let unknowns = Unknowns::scaled(first, plan.metrics, plan.scales)?;
        let metric = TemplateMetric::new(template, plan.model.kernel(), plan.scales)?;
        let hyper = match hyper {
            None => None,
            Some(model) => {
                let problem = Problem::new(template, model.clone())?;
                let unknowns = Unknowns::scaled(&problem, plan.metrics, plan.scales)?;
                Some(Hyper { problem, unknowns })
            }
        };
        Ok(Level { template: template.clone(), problems, mine, unknowns, metric, hyper, deformation })
    }

    /// The template's positions and signal at the unknowns `x` of this
    /// level, and the hypertemplate's momenta and energy (0 without one).
    fn template_at(&self, x: &[f64]) -> Result<(FShape, Option<Vec<f64>>, f64), MatchError> {
        let pn = self.template.n_vertices() * self.template.dim();
        let p = self.template.n_vertices();
        let (points, traj) = positions(self.hyper.as_ref(), &self.metric, &x[..pn])?;
        let signal = x[pn..pn + p].iter().map(|u| u * self.metric.signal).collect();
        let momenta = self.hyper.as_ref().map(|h| h.unknowns.unpack(&x[..pn]).0);
        let energy = traj.map_or(0.0, |t| t.hamiltonian[0]);
        Ok((self.template.clone().with_points(points)?.with_signal(Some(signal))?, momenta, energy))
    }

    /// The unknowns at the start: the initial template (P_0 = 0 for the
    /// hypertemplate) and zero momenta.
    fn start(&self, subjects: usize) -> Vec<f64> {
        let mut x: Vec<f64> = match self.hyper {
            // P_0 = 0: the template starts as the hypertemplate.
            Some(_) => vec![0.0; self.template.points().len()],
            None => self.template.points().iter().map(|v| v / self.metric.length).collect(),
        };
        x.extend(self.template.signal().expect("levels carry a signal").iter().map(|v| v / self.metric.signal));
        x.resize(x.len() + subjects * self.unknowns.len(), 0.0);
        x
    }

    fn objective<'a>(&'a mut self, cluster: &'a dyn Cluster, n_subjects: usize) -> AtlasObjective<'a> {
        let t = &self.template;
        AtlasObjective {
            cluster,
            pn: t.n_vertices() * t.dim(),
            p: t.n_vertices(),
            problems: &mut self.problems,
            mine: self.mine.clone(),
            n_subjects,
            unknowns: self.unknowns.clone(),
            metric: &self.metric,
            hyper: self.hyper.as_ref(),
            recent: Vec::new(),
            evaluations: 0,
        }
    }
}

/// What a stage's solution says, independently of its mesh: the template
/// (its displacement and signal change from the level's initial template)
/// and every subject's momenta, with the hypertemplate's momenta.
struct Solution {
    initial: FShape,
    template: FShape,
    hyper_p0: Option<Vec<f64>>,
    momenta: Vec<(Vec<f64>, Vec<f64>)>,
}

/// An atlas estimation run: stages of the schedule one after the other,
/// with a checkpoint after every accepted iteration and resume to the same
/// bits, as [`crate::Session`] for one registration. Stages may run on
/// coarser versions of the initial template ([`Atlas::with_stage_templates`]).
pub struct Atlas {
    plan: Plan,
    /// The initial template at full resolution (with a signal).
    source: FShape,
    subjects: Vec<FShape>,
    /// Per stage, its coarser initial template or `None` (the source).
    stage_templates: Vec<Option<FShape>>,
    /// Per stage, the subjects simplified for it (`[schedule] vertices`
    /// with coarse targets) or `None` (the subjects themselves).
    stage_subjects: Vec<Option<Vec<FShape>>>,
    /// Per stage, the index of the first stage template equal to its own
    /// (`None`: the source): stages on one key share a level.
    keys: Vec<Option<usize>>,
    hyper_model: Option<fshape_shoot::Model>,
    /// The working level, built when first needed (after
    /// [`Atlas::with_cluster`], so that a process sets up only its own
    /// subjects).
    level: Option<Level>,
    on: Option<usize>,
    cluster: Box<dyn Cluster>,
    checkpoint: Checkpoint,
    checkpoint_file: Option<PathBuf>,
    staged: Option<usize>,
}

/// FNV-1a, as hex, of the initial template, the subjects and the
/// configuration.
pub fn atlas_fingerprint(template: &FShape, subjects: &[FShape], config: &Config) -> String {
    let mut h = Fnv::new();
    h.eat(b"atlas");
    h.shape(template);
    for s in subjects {
        h.shape(s);
    }
    h.eat(config.to_toml().as_bytes());
    h.hex()
}

/// The number of a subject's unknowns on a template of `n` vertices in R^dim.
fn subject_len(n: usize, dim: usize, kind: ModelKind) -> usize {
    n * dim + if kind == ModelKind::Lddmm { 0 } else { n }
}

impl Atlas {
    /// Checks the configuration and the shapes and builds one problem per
    /// subject on the initial `template`. With `model.normalize`, the
    /// scales (length L, signal S) are the initial template's against the
    /// first subject's, as [`Config::plan`] takes them for one match.
    pub fn new(template: &FShape, subjects: &[FShape], config: &Config) -> Result<Atlas, MatchError> {
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
        let plan = config.plan(template, first)?;
        let source = match template.signal() {
            Some(_) => template.clone(),
            None => template.clone().with_signal(Some(vec![0.0; template.n_vertices()]))?,
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
                let gamma_v0 = match plan.scales {
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
        let checkpoint = Checkpoint {
            format: CHECKPOINT_FORMAT,
            fingerprint: atlas_fingerprint(&source, subjects, config),
            done: Vec::new(),
            current: None,
            warm: None,
            seconds: 0.0,
        };
        let stages = plan.stages.len();
        let atlas = Atlas {
            plan,
            source,
            subjects: subjects.to_vec(),
            stage_templates: vec![None; stages],
            stage_subjects,
            keys: vec![None; stages],
            hyper_model,
            level: None,
            on: None,
            cluster: Box::new(Local),
            checkpoint,
            checkpoint_file: None,
            staged: None,
        };
        if !auto {
            return Ok(atlas);
        }
        atlas.set_stage_templates(templates)
    }

    /// Runs stage k on a coarser initial template `templates[k]` (the same
    /// surface at a lower resolution), or on the initial template where it
    /// is `None`; the last stage is always the initial template. A stage
    /// template without a signal takes the initial template's, read at its
    /// vertices. Between stages on different templates the solution is
    /// carried over: the template's displacement and signal change as
    /// functions (interpolated at the finer vertices), the momenta keeping
    /// their velocity field ([`crate::resolution::prolongate_fitted`], one
    /// factor for all subjects). The templates enter
    /// the checkpoint's fingerprint: call this before [`Atlas::resume`].
    pub fn with_stage_templates(self, templates: Vec<Option<FShape>>) -> Result<Atlas, MatchError> {
        if self.plan.stages.iter().any(|s| s.vertices.is_some()) {
            return Err(MatchError::StageTemplatesTwice);
        }
        self.set_stage_templates(templates)
    }

    /// [`Atlas::with_stage_templates`], from the schedule's counts too.
    fn set_stage_templates(mut self, templates: Vec<Option<FShape>>) -> Result<Atlas, MatchError> {
        let n = self.plan.stages.len();
        if templates.len() != n {
            return Err(MatchError::StageTemplates(format!(
                "{} given for a schedule of {n} stages (one per stage, the last None)",
                templates.len()
            )));
        }
        if templates.last().is_some_and(Option::is_some) {
            return Err(MatchError::StageTemplates(
                "the last stage runs on the initial template: its stage template must be None".into(),
            ));
        }
        let source = &self.source;
        let mut filled = Vec::with_capacity(n);
        for (k, t) in templates.into_iter().enumerate() {
            let t = match t {
                None => None,
                Some(t) if t.dim() != source.dim() || t.kind() != source.kind() || t.n_cells() == 0 => {
                    return Err(MatchError::StageTemplates(format!(
                        "stage {k}'s template is not a non-empty mesh of the initial template's kind and dimension"
                    )));
                }
                Some(t) if t.signal().is_some() => Some(t),
                Some(t) => {
                    let signal = crate::resolution::sample(source, &t, source.signal().expect("set in new"), 1)?;
                    Some(t.with_signal(Some(signal))?)
                }
            };
            filled.push(t);
        }
        let mut h = Fnv::new();
        h.eat(self.checkpoint.fingerprint.as_bytes());
        for t in &filled {
            match t {
                Some(t) => h.shape(t),
                None => h.eat(b"source"),
            }
        }
        self.checkpoint.fingerprint = h.hex();
        self.keys = (0..n)
            .map(|k| match &filled[k] {
                Some(t) if *t != self.source => filled.iter().position(|u| u.as_ref() == Some(t)),
                _ => None,
            })
            .collect();
        self.stage_templates = filled;
        Ok(self)
    }

    /// Shares the subjects' evaluations among the processes of `cluster`
    /// (every process builds the same atlas and runs it; results are the
    /// same bits as on one process). Give a checkpoint file to one
    /// process only.
    pub fn with_cluster(mut self, cluster: Box<dyn Cluster>) -> Atlas {
        self.cluster = cluster;
        self
    }

    /// Writes the checkpoint to `path` after every accepted iteration, at
    /// the end of every stage and when stopped.
    pub fn with_checkpoint_file(mut self, path: &Path) -> Atlas {
        self.checkpoint_file = Some(path.to_path_buf());
        self
    }

    /// The checked plan.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The initial template (with a zero signal if it had none).
    pub fn initial_template(&self) -> &FShape {
        &self.source
    }

    /// The checkpoint as of now.
    pub fn checkpoint(&self) -> &Checkpoint {
        &self.checkpoint
    }

    /// Whether every stage has run.
    pub fn is_finished(&self) -> bool {
        self.checkpoint.done.len() == self.plan.stages.len()
    }

    /// The initial template of stage k and its key.
    fn template_of(&self, k: usize) -> (Option<usize>, &FShape) {
        match self.keys.get(k) {
            Some(Some(j)) => (Some(*j), self.stage_templates[*j].as_ref().expect("a key names a template")),
            _ => (None, &self.source),
        }
    }

    /// The number of unknowns of stage `stage`: its template's positions
    /// and signal, then every subject's momenta.
    pub fn len_at(&self, stage: usize) -> usize {
        let t = self.template_of(stage).1;
        let n = t.n_vertices();
        n * (t.dim() + 1) + self.subjects.len() * subject_len(n, t.dim(), self.plan.model.kind())
    }

    /// The number of unknowns at full resolution (the last stage's).
    pub fn len(&self) -> usize {
        self.len_at(self.plan.stages.len() - 1)
    }

    /// Whether there are no unknowns (never: a template has vertices).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The starting unknowns of stage `stage`'s template
    /// ([`Atlas::len_at`] values): the initial template (P_0 = 0 for the
    /// hypertemplate) and zero momenta.
    pub fn initial_unknowns_at(&mut self, stage: usize) -> Result<Vec<f64>, MatchError> {
        self.check_stage(stage)?;
        self.ensure_level(stage)?;
        let n = self.subjects.len();
        Ok(self.level().start(n))
    }

    /// [`Atlas::initial_unknowns_at`] the last stage (full resolution).
    pub fn initial_unknowns(&mut self) -> Result<Vec<f64>, MatchError> {
        self.initial_unknowns_at(self.plan.stages.len() - 1)
    }

    /// Continues from `checkpoint` after checking it belongs to these
    /// inputs and holds finite arrays of this problem's size.
    pub fn resume(mut self, checkpoint: Checkpoint) -> Result<Atlas, MatchError> {
        if checkpoint.format != CHECKPOINT_FORMAT {
            return Err(checkpoint_error(format!(
                "the checkpoint is of format {} (this version reads format {CHECKPOINT_FORMAT}); start again without resuming",
                checkpoint.format
            )));
        }
        if checkpoint.fingerprint != self.checkpoint.fingerprint {
            return Err(checkpoint_error(
                "the checkpoint was written for other inputs (template, subjects or configuration changed); remove it or start without resuming",
            ));
        }
        crate::session::validate_arrays(&checkpoint, self.plan.stages.len(), |k| self.len_at(k))?;
        self.checkpoint = checkpoint;
        Ok(self)
    }

    /// [`Atlas::resume`] from a checkpoint file; errors name the file.
    pub fn resume_from_file(self, path: &Path) -> Result<Atlas, MatchError> {
        let checkpoint = Checkpoint::read(path)?;
        self.resume(checkpoint).map_err(|e| e.in_file(path))
    }

    /// Makes stage k's template the working level (this process's
    /// subjects only) and returns it.
    fn ensure_level(&mut self, k: usize) -> Result<&mut Level, MatchError> {
        let key = self.template_of(k).0;
        if self.level.is_none() || key != self.on {
            let mine = self.cluster.subjects(self.cluster.rank(), self.subjects.len());
            // The old level goes first: two levels' problems are not held at once.
            self.level = None;
            let template = self.template_of(k).1;
            let level = Level::new(template, mine, &self.plan, self.hyper_model.as_ref())?;
            self.level = Some(level);
            self.on = key;
            self.staged = None;
        }
        Ok(self.level.as_mut().expect("just built"))
    }

    /// The working level, after [`Atlas::ensure_level`].
    fn level(&mut self) -> &mut Level {
        self.level.as_mut().expect("ensure_level runs first")
    }

    /// How many subjects this process has set up (its block of the
    /// cluster's subjects, once a stage has started; 0 before).
    pub fn subjects_set_up(&self) -> usize {
        self.level.as_ref().map_or(0, |l| l.problems.len())
    }

    fn stage_target(&mut self, k: usize) -> Result<(), MatchError> {
        self.ensure_level(k)?;
        if self.staged != Some(k) {
            let stage = &self.plan.stages[k];
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

    /// Stage k's unknowns `x` read as a [`Solution`].
    fn solution(&mut self, k: usize, x: &[f64]) -> Result<Solution, MatchError> {
        let level = &*self.ensure_level(k)?;
        let (template, hyper_p0, _) = level.template_at(x)?;
        let offset = level.template.n_vertices() * (level.template.dim() + 1);
        let momenta = x[offset..].chunks_exact(level.unknowns.len()).map(|xi| level.unknowns.unpack(xi)).collect();
        Ok(Solution { initial: level.template.clone(), template, hyper_p0, momenta })
    }

    /// A solution carried to stage k's (finer) template, as its unknowns.
    fn prolongate(&mut self, k: usize, coarse: &Solution) -> Result<Vec<f64>, MatchError> {
        use crate::resolution::{VelocityFit, prolongate_fitted, sample};
        self.ensure_level(k)?;
        let level = self.level.as_ref().expect("ensured");
        let fine0 = &level.template;
        let (n, dim) = (fine0.n_vertices(), fine0.dim());
        let kind = self.plan.model.kind();
        // The template's displacement and signal change, one pass of
        // closest points: dim + 1 values a vertex.
        let (now, was) = (&coarse.template, &coarse.initial);
        let change: Vec<f64> = now
            .points()
            .chunks_exact(dim)
            .zip(was.points().chunks_exact(dim))
            .zip(now.signal().expect("set").iter().zip(was.signal().expect("set")))
            .flat_map(|((a, b), (f, g))| a.iter().zip(b).map(|(a, b)| a - b).chain([f - g]))
            .collect();
        let change = sample(was, fine0, &change, dim + 1)?;
        let signal: Vec<f64> = change
            .chunks_exact(dim + 1)
            .zip(fine0.signal().expect("levels carry a signal"))
            .map(|(d, f)| f + d[dim])
            .collect();
        let (mut x, points) = match (&level.hyper, &coarse.hyper_p0) {
            (Some(h), Some(p0)) => {
                let zero = vec![0.0; was.n_vertices()];
                let (q0, _) = prolongate_fitted(was, fine0, p0, &zero, ModelKind::Lddmm, h.problem.model().kernel())?;
                let block = h.unknowns.pack(&q0, &[]);
                let (points, _) = positions(Some(h), &level.metric, &block)?;
                (block, points)
            }
            _ => {
                let points: Vec<f64> = fine0
                    .points()
                    .chunks_exact(dim)
                    .zip(change.chunks_exact(dim + 1))
                    .flat_map(|(a, d)| a.iter().zip(d).map(|(a, d)| a + d))
                    .collect();
                (points.iter().map(|v| v / level.metric.length).collect(), points)
            }
        };
        x.extend(signal.iter().map(|v| v / level.metric.signal));
        let fine = fine0.clone().with_points(points)?;
        // One factor on the (moved) fine template for every subject.
        let fit = VelocityFit::new(&fine, self.plan.model.kernel())?;
        for (p0, pf) in &coarse.momenta {
            let (q0, qf) = fit.carry(&coarse.template, p0, pf, kind)?;
            x.extend(level.unknowns.pack(&q0, &qf));
        }
        debug_assert_eq!(x.len(), n * (dim + 1) + self.subjects.len() * level.unknowns.len());
        Ok(x)
    }

    /// Stage `stage`'s unknowns `x` read as the template they put (its
    /// positions and signal) and every subject's momenta (p_0, p^f).
    #[allow(clippy::type_complexity)]
    pub fn unpack(&mut self, stage: usize, x: &[f64]) -> Result<(FShape, Vec<(Vec<f64>, Vec<f64>)>), MatchError> {
        self.check_len(stage, x)?;
        let s = self.solution(stage, x)?;
        Ok((s.template, s.momenta))
    }

    /// Stage `from`'s unknowns `x` carried to stage `to`'s template (as
    /// [`Atlas::run`] does between stages on different templates; `x`
    /// itself when the two stages share one).
    pub fn prolongate_unknowns(&mut self, from: usize, x: &[f64], to: usize) -> Result<Vec<f64>, MatchError> {
        self.check_len(from, x)?;
        self.check_stage(to)?;
        if self.template_of(from).0 == self.template_of(to).0 {
            return Ok(x.to_vec());
        }
        let coarse = self.solution(from, x)?;
        self.prolongate(to, &coarse)
    }

    /// Errors unless `stage` is in the schedule.
    fn check_stage(&self, stage: usize) -> Result<(), MatchError> {
        if stage >= self.plan.stages.len() {
            return Err(MatchError::NoSuchStage { stage, stages: self.plan.stages.len() });
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

    /// Runs the remaining stages until each stops by its rule, or until
    /// `observer` says [`Control::Stop`](crate::Control::Stop). J and its
    /// parts in the records are means over the subjects.
    pub fn run(&mut self, observer: &mut impl Observer) -> Result<Outcome, MatchError> {
        let start = Instant::now();
        let earlier = self.checkpoint.seconds;
        let clock = move || earlier + start.elapsed().as_secs_f64();
        let stages = self.plan.stages.len();
        while self.checkpoint.done.len() < stages {
            let k = self.checkpoint.done.len();
            let begin = match self.checkpoint.current.take() {
                Some(current) => StageStart::Resume(Box::new(current)),
                None => StageStart::At(match self.checkpoint.warm.clone() {
                    None => self.initial_unknowns_at(k)?,
                    // On a finer template the solution is carried over.
                    Some(w) => self.prolongate_unknowns(k - 1, &w, k)?,
                }),
            };
            self.stage_target(k)?;
            let first = self.stage_subjects.get(k).and_then(Option::as_ref).unwrap_or(&self.subjects);
            let level = self.level.as_mut().expect("ensured");
            let setup = crate::session::StageSetup {
                template_vertices: level.template.n_vertices(),
                target_vertices: first[0].n_vertices(),
                deformation: level.deformation.clone(),
                attachment: self.plan.stages[k].kernel.position().path().to_string(),
            };
            let mut objective = level.objective(self.cluster.as_ref(), self.subjects.len());
            let mut journal = Journal {
                checkpoint: &mut self.checkpoint,
                file: self.checkpoint_file.as_deref(),
                clock: &clock,
                stages,
            };
            let spec = &self.plan.stages[k];
            if run_stage(k, spec, setup, &self.plan.settings, &mut objective, begin, &mut journal, observer)?
                == Outcome::Interrupted
            {
                return Ok(Outcome::Interrupted);
            }
        }
        Ok(Outcome::Finished)
    }

    /// The result of a finished run: the template, and every subject's
    /// momenta shot once more with the last stage's data term.
    pub fn result(&mut self) -> Result<AtlasResult, MatchError> {
        if !self.is_finished() {
            return Err(MatchError::NotFinished);
        }
        let last_stage = self.plan.stages.len() - 1;
        self.stage_target(last_stage)?;
        let x = self.checkpoint.warm.clone().ok_or(MatchError::NotFinished)?;
        let stage = &self.plan.stages[last_stage];
        let model = self.plan.model.clone();
        let level = self.level.as_mut().expect("ensured");
        let (template, template_momenta, hyper_energy) = level.template_at(&x)?;
        let len = level.unknowns.len();
        let offset = template.n_vertices() * (template.dim() + 1);
        let n = self.subjects.len() as f64;
        let mut energies = Energies { value: 0.0, energy: 0.0, signal_energy: 0.0, attachment: 0.0 };
        let mut subjects = Vec::with_capacity(self.subjects.len());
        let start = &self.source;
        let zeros = (vec![0.0; start.n_vertices() * start.dim()], vec![0.0; start.n_vertices()]);
        for (i, subject) in self.subjects.iter().enumerate() {
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
            let last = trajectory.steps();
            let matched = template
                .clone()
                .with_points(trajectory.points(last).to_vec())?
                .with_signal(Some(trajectory.signal(last).to_vec()))?;
            subjects.push(SubjectResult {
                quality: crate::quality(&matched, subject)?,
                template_quality: crate::quality(&template, subject)?,
                initial_attachment,
                p0,
                pf,
                energies: e,
                trajectory,
            });
        }
        let done = &self.checkpoint.done;
        energies.value += hyper_energy;
        energies.energy += hyper_energy;
        Ok(AtlasResult {
            template,
            template_momenta,
            subjects,
            energies,
            stages: done.clone(),
            iterations: done.iter().map(|s| s.iterations.len()).sum(),
            evaluations: done.iter().map(|s| s.iterations.last().unwrap_or(&s.initial).evaluations).sum(),
            seconds: self.checkpoint.seconds,
        })
    }
}

impl Atlas {
    /// J (the mean over subjects) and its gradient in the [`Atlas::len`]
    /// unknowns `x`, with stage `stage`'s data term: for tests, and for
    /// callers that drive an optimiser themselves.
    pub fn value_grad(&mut self, stage: usize, x: &[f64]) -> Result<(f64, Vec<f64>), MatchError> {
        use crate::optimize::Objective;
        self.check_len(stage, x)?;
        self.stage_target(stage)?;
        let n = self.subjects.len();
        self.level.as_mut().expect("ensured").objective(self.cluster.as_ref(), n).value_grad(x)
    }

    /// Applies stage `stage`'s initial Hessian shape M⁻¹ (module docs) to
    /// `v` ([`Atlas::len_at`] values).
    pub fn precondition(&mut self, stage: usize, v: &mut [f64]) -> Result<(), MatchError> {
        use crate::optimize::Objective;
        self.check_len(stage, v)?;
        let n = self.subjects.len();
        self.ensure_level(stage)?;
        self.level.as_mut().expect("ensured").objective(self.cluster.as_ref(), n).precondition(v);
        Ok(())
    }
}

/// The eigenvalues (in decreasing order) and unit eigenvectors (the columns
/// of a row-major n × n matrix, in the same order) of the symmetric n × n
/// matrix `a` (row-major), by cyclic Jacobi rotations: a small, serial,
/// deterministic solver for the Gram matrices of a population (n = the
/// number of subjects).
pub fn symmetric_eigen(a: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    assert_eq!(a.len(), n * n, "an n × n matrix");
    let mut a = a.to_vec();
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    let scale: f64 = a.iter().map(|x| x * x).sum();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|p| (0..n).filter(move |&q| q != p).map(move |q| (p, q)))
            .map(|(p, q)| a[p * n + q].powi(2))
            .sum();
        if off <= 1e-30 * scale || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                // The rotation that zeroes a_pq (Numerical Recipes, 11.1).
                let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k * n + p], a[k * n + q]);
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p * n + k], a[q * n + k]);
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| a[j * n + j].total_cmp(&a[i * n + i]).then(i.cmp(&j)));
    let values = order.iter().map(|&i| a[i * n + i]).collect();
    let mut vectors = vec![0.0; n * n];
    for (col, &i) in order.iter().enumerate() {
        for k in 0..n {
            vectors[k * n + col] = v[k * n + i];
        }
    }
    (values, vectors)
}

/// One principal mode of the population's initial momenta.
#[derive(Clone, Debug)]
pub struct Mode {
    /// Its standard deviation over the population (in the metric's units:
    /// √(2 × energy)).
    pub sd: f64,
    /// Its share of the total variance.
    pub share: f64,
    /// The unit direction (p_0, p^f or ζ) on the template's vertices.
    pub p0: Vec<f64>,
    /// Its signal part.
    pub pf: Vec<f64>,
}

/// Principal component analysis of an atlas's initial momenta.
#[derive(Clone, Debug)]
pub struct Modes {
    /// The subjects' mean momenta.
    pub mean_p0: Vec<f64>,
    /// Their mean signal momentum.
    pub mean_pf: Vec<f64>,
    /// The modes, largest variance first.
    pub modes: Vec<Mode>,
    /// Per subject, its coordinate along each mode.
    pub scores: Vec<Vec<f64>>,
}

impl Atlas {
    /// The principal modes of the subjects' initial momenta (at most
    /// `count`), in the metric of the geodesic energy at the template:
    /// ⟨m, m'⟩ = ⟨p_0, K p_0'⟩/γ_V + ⟨p^f, D_s⁻¹ p^f'⟩/γ_f (metamorphosis;
    /// LDDMM without the second term; tangential with γ_f⟨ζ, D_s ζ'⟩), so
    /// that a mode's variance is an energy, independent of the mesh (the
    /// momenta are densities). The Gram matrix of the centred momenta is
    /// diagonalised (Deformetrica's and Vaillant et al.'s tangent PCA); a
    /// mode is the combination of the subjects' momenta along its
    /// eigenvector, of unit norm.
    pub fn principal_modes(&self, result: &AtlasResult, count: usize) -> Result<Modes, MatchError> {
        let subjects = &result.subjects;
        let n = subjects.len();
        let (pn, p) = (result.template.n_vertices() * result.template.dim(), result.template.n_vertices());
        let kind = self.plan.model.kind();
        // Each subject's momenta paired with the metric: (K p_0/γ_V, the signal's).
        let tangential = if kind == ModelKind::Tangential {
            let fem = SignalNorm::try_new(&result.template, self.plan.model.norm()).map_err(ShootError::from)?;
            let g = self.plan.model.gamma_f();
            Some(
                subjects
                    .iter()
                    .map(|s| Ok(fem.matvec(result.template.points(), &s.pf)?.iter().map(|v| g * v).collect()))
                    .collect::<Result<Vec<Vec<f64>>, ShootError>>()?,
            )
        } else {
            None
        };
        let paired = |i: usize| -> (&[f64], &[f64]) {
            let (vx, vf) = subjects[i].trajectory.velocity(0);
            match &tangential {
                Some(t) => (vx, &t[i]),
                None => (vx, vf),
            }
        };
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let mut gram = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let (vx, vf) = paired(j);
                gram[i * n + j] = dot(&subjects[i].p0, vx) + dot(&subjects[i].pf, vf);
            }
        }
        // Symmetric up to rounding; centred: C G C with C = I − 11ᵀ/n.
        let sym: Vec<f64> = (0..n * n).map(|k| 0.5 * (gram[k] + gram[(k % n) * n + k / n])).collect();
        let row_mean: Vec<f64> = (0..n).map(|i| sym[i * n..(i + 1) * n].iter().sum::<f64>() / n as f64).collect();
        let all_mean = row_mean.iter().sum::<f64>() / n as f64;
        let centred: Vec<f64> = (0..n * n).map(|k| sym[k] - row_mean[k / n] - row_mean[k % n] + all_mean).collect();
        let (values, vectors) = symmetric_eigen(&centred, n);
        let total: f64 = values.iter().filter(|v| **v > 0.0).sum();
        let mean_p0: Vec<f64> = (0..pn).map(|k| subjects.iter().map(|s| s.p0[k]).sum::<f64>() / n as f64).collect();
        let mean_pf: Vec<f64> = (0..p).map(|k| subjects.iter().map(|s| s.pf[k]).sum::<f64>() / n as f64).collect();
        let mut modes = Vec::new();
        let dof = n.saturating_sub(1).max(1) as f64;
        for (k, &lambda) in values.iter().enumerate().take(count.min(n.saturating_sub(1))) {
            if lambda.is_nan() || lambda <= 1e-12 * total {
                break;
            }
            let root = lambda.sqrt();
            let weight = |i: usize| vectors[i * n + k] / root;
            let p0 = (0..pn).map(|c| (0..n).map(|i| weight(i) * (subjects[i].p0[c] - mean_p0[c])).sum()).collect();
            let pf = (0..p).map(|c| (0..n).map(|i| weight(i) * (subjects[i].pf[c] - mean_pf[c])).sum()).collect();
            modes.push(Mode { sd: (lambda / dof).sqrt(), share: lambda / total, p0, pf });
        }
        let scores =
            (0..n).map(|i| (0..modes.len()).map(|k| values[k].sqrt() * vectors[i * n + k]).collect()).collect();
        Ok(Modes { mean_p0, mean_pf, modes, scores })
    }

    /// The template of `result` shot by momenta (p_0, p^f): the shape at
    /// t = 1 (to see a mode at ±2 standard deviations).
    pub fn shoot_template(&mut self, result: &AtlasResult, p0: &[f64], pf: &[f64]) -> Result<FShape, MatchError> {
        let model = self.plan.model.clone();
        let level = self.ensure_level(self.plan.stages.len() - 1)?;
        let t = &result.template;
        let mut spare;
        let problem = match level.problems.first_mut() {
            Some(p) => p,
            None => {
                spare = Problem::new(&level.template, model)?;
                &mut spare
            }
        };
        problem.set_template(t.points(), t.signal())?;
        let traj = problem.shoot(p0, pf)?;
        let k = traj.steps();
        Ok(t.clone().with_points(traj.points(k).to_vec())?.with_signal(Some(traj.signal(k).to_vec()))?)
    }
}
