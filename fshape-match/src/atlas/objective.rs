//! The atlas objective: the mean of the subjects' matching objectives as a
//! function of the template's unknowns and every subject's momenta, its
//! gradient, and the initial Hessian's shape ([`super`]'s docs). Each
//! process evaluates its subjects and gathers every subject's record
//! (a status, its parts and gradients) in subject order.

use fshape_fem::{Norm, SignalNorm};
use fshape_kernels::{Kernel, KernelSums};
use fshape_mesh::FShape;
use fshape_shoot::{Energies, Problem, ShootError, Trajectory};
use rayon::prelude::*;

use super::Cluster;
use crate::MatchError;
use crate::optimize::Evaluation;
use crate::session::step_too_far;
use crate::unknowns::Unknowns;

/// The template blocks' change of variables and initial Hessian.
pub(super) struct TemplateMetric {
    /// x̄ = length · u_x.
    pub(super) length: f64,
    /// f̄ = S_c · u_f, one S_c per map (c = 0, 1, … in turn).
    pub(super) signal: Vec<f64>,
    /// The deformation kernel and the initial template's positions: M⁻¹
    /// on the positions is K(x̄_0).
    kernel: Kernel,
    points: Vec<f64>,
    dim: usize,
    /// m̄/m_i, the lumped masses' inverse scaled to mean 1, for every
    /// map of a vertex.
    inv_mass: Vec<f64>,
}

impl TemplateMetric {
    pub(super) fn new(template: &FShape, kernel: &Kernel, scales: Option<&crate::Scales>) -> Result<Self, ShootError> {
        let masses = SignalNorm::try_new(template, Norm::L2Lumped)?.assemble(template.points())?;
        if let Some(v) = masses.iter().position(|m| m.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)) {
            return Err(fshape_fem::FemError::Singular { vertex: v }.into());
        }
        let mean = masses.iter().sum::<f64>() / masses.len() as f64;
        // Built once here, so that applying it later cannot fail.
        KernelSums::try_new(kernel, template.points(), template.dim())?;
        let k = template.n_channels().max(1);
        Ok(TemplateMetric {
            length: scales.map_or(1.0, |s| s.length),
            signal: (0..k).map(|c| scales.map_or(1.0, |s| s.channel(c))).collect(),
            kernel: kernel.clone(),
            points: template.points().to_vec(),
            dim: template.dim(),
            inv_mass: masses.iter().flat_map(|m| std::iter::repeat_n(mean / m, k)).collect(),
        })
    }
}

/// The hypertemplate's shooting: an LDDMM problem on the initial template
/// and the packing of its momenta P_0.
pub(super) struct Hyper {
    pub(super) problem: Problem,
    pub(super) unknowns: Unknowns,
}

/// The template's positions of the first block of unknowns: scaled
/// positions (free template), or the end of the hypertemplate's shooting
/// by the P_0 they pack (with its trajectory, for the adjoint).
pub(super) fn positions(
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

/// How a subject's evaluation went, the first value of its record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Status {
    /// Evaluated: the record holds its terms.
    Evaluated,
    /// Its shooting diverged past the first point: a step too far, which
    /// the line search undoes.
    TooFar,
    /// An error of the setup (reported by the process that met it).
    Failed,
}

impl Status {
    /// As a gathered value: the gather moves f64s only.
    fn code(self) -> f64 {
        match self {
            Status::Evaluated => 0.0,
            Status::TooFar => 1.0,
            Status::Failed => 2.0,
        }
    }

    /// From a gathered value; anything else is a damaged gather.
    fn of(code: f64) -> Option<Status> {
        [Status::Evaluated, Status::TooFar, Status::Failed].into_iter().find(|s| s.code() == code)
    }
}

/// A subject's record in a gather: its [`Status`], then J_i's four parts,
/// ∂J_i/∂(its unknowns), ∂J_i/∂x̄ and ∂J_i/∂f̄ (zeros unless evaluated).
struct Record;

impl Record {
    /// The number of values of a record: `len` unknowns of a subject on a
    /// template with P·n = `pn` positions and P = `p` vertices.
    fn len(len: usize, pn: usize, p: usize) -> usize {
        5 + len + pn + p
    }

    /// Appends an evaluated subject's record.
    fn evaluated(records: &mut Vec<f64>, e: &SubjectEval) {
        let en = e.energies;
        records.extend([Status::Evaluated.code(), en.value, en.energy, en.signal_energy, en.attachment]);
        records.extend(e.grad.iter().chain(&e.x0).chain(&e.f0));
    }

    /// Appends the record of a subject not evaluated, `width` values.
    fn not_evaluated(records: &mut Vec<f64>, status: Status, width: usize) {
        records.push(status.code());
        records.resize(records.len() + width - 1, 0.0);
    }
}

/// The atlas objective in the unknowns (module docs): the subjects'
/// problems hold the template of the last evaluation.
pub struct AtlasObjective<'p> {
    pub(super) cluster: &'p dyn Cluster,
    /// This process's subjects' problems (`mine`), of `n_subjects`.
    pub(super) problems: &'p mut [Problem],
    pub(super) mine: std::ops::Range<usize>,
    pub(super) n_subjects: usize,
    pub(super) unknowns: Unknowns,
    pub(super) metric: &'p TemplateMetric,
    pub(super) hyper: Option<&'p Hyper>,
    /// P·n and P·k of the template (P vertices, k maps).
    pub(super) pn: usize,
    pub(super) p: usize,
    pub(super) evaluations: usize,
}

impl AtlasObjective<'_> {
    fn subject_len(&self) -> usize {
        self.unknowns.len()
    }

    /// Past the first point, a shooting that diverged is a step too far,
    /// which the line search undoes (as in matching): `None`, else the
    /// error.
    fn step_too_far(&self, err: ShootError) -> Result<(), MatchError> {
        if self.evaluations > 1 && step_too_far(&err) { Ok(()) } else { Err(err.into()) }
    }
}

impl crate::optimize::Objective for AtlasObjective<'_> {
    type Error = MatchError;
    /// J's parts, means over the subjects.
    type Parts = Energies;

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

    fn value_grad(&mut self, x: &[f64]) -> Result<Evaluation<Energies>, MatchError> {
        self.evaluations += 1;
        let nan = || {
            let parts = Energies { value: f64::NAN, energy: f64::NAN, signal_energy: f64::NAN, attachment: f64::NAN };
            Ok(Evaluation { value: f64::NAN, grad: vec![f64::NAN; x.len()], parts })
        };
        let (points, traj) = match positions(self.hyper, self.metric, &x[..self.pn]) {
            Ok(p) => p,
            Err(e) => return self.step_too_far(e).and_then(|()| nan()),
        };
        let scales = &self.metric.signal;
        let signal: Vec<f64> =
            x[self.pn..self.pn + self.p].iter().zip(scales.iter().cycle()).map(|(u, s)| u * s).collect();
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
        let width = Record::len(len, self.pn, self.p);
        let mut records = Vec::with_capacity(evals.len() * width);
        let mut failure = None;
        for (k, e) in evals.into_iter().enumerate() {
            match e {
                Ok(e) => Record::evaluated(&mut records, &e),
                Err(err) => {
                    let status = match self.step_too_far(err) {
                        Ok(()) => Status::TooFar,
                        Err(err) => {
                            failure.get_or_insert((mine.start + k, err));
                            Status::Failed
                        }
                    };
                    Record::not_evaluated(&mut records, status, width);
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
            match Status::of(r[0]) {
                Some(Status::Evaluated) => {}
                Some(Status::TooFar) => return nan(),
                // Failed (or a damaged record): the error where it was met,
                // else the process that met it.
                Some(Status::Failed) | None => {
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
            for ((g, v), s) in grad[self.pn..self.pn + self.p].iter_mut().zip(f0).zip(scales.iter().cycle()) {
                *g += v * s / n;
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
        Ok(Evaluation { value: mean.value, grad, parts: mean })
    }
}
