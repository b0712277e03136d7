//! Geodesic regression by metamorphosis: one geodesic from a baseline
//! fshape observed at several times (a subject's visits).
//!
//! The unknowns are the initial momenta (p_0, p^f) at t = 0; the visits
//! are at normalised times t_v ∈ [0, 1] (fshape-match maps ages onto
//! them) with weights w_v, each a mesh of its own with its signal and
//! mask. The objective is
//!
//! J(p_0, p^f) = H(x_0, p_0, p^f) + γ_W Σ_v w_v A(x(t_v), f(t_v); visit v),
//!
//! the geodesic's energy plus the attachment of its state at every visit's
//! time. The states are read where the integrator puts them: the time grid
//! is the model's uniform one with a node added at every visit's time (a
//! uniform node closer than a quarter step to a visit is dropped, so no
//! step is longer than 1.5 uniform steps; see `grid`). The gradient is the discrete adjoint of that integration:
//! the co-state integrates backward from 0 and jumps by
//! γ_W w_v ∂A_v/∂(x, f) at each visit's node, so it is exact for the
//! discrete J (tests/shoot/regression.rs against central differences).

use fshape_mesh::FShape;
use fshape_varifold::{Attachment, VarifoldKernel};

use crate::dynamics::{Timings, timed};
use crate::shoot::{axpy, dot};
use crate::{ModelKind, Problem, ShootError, Trajectory};

/// One visit: its normalised time, weight, and attachment (the visit's
/// mesh and ⟨Y, Y⟩ computed once).
struct Visit {
    time: f64,
    weight: f64,
    attachment: Attachment,
}

/// A geodesic regression: a [`Problem`] (template = the baseline at
/// t = 0, model) and its visits.
pub struct Regression {
    problem: Problem,
    visits: Vec<Visit>,
    /// The integration's node times (`grid` of the visits' times), and
    /// each visit's node: set as visits are added.
    times: Vec<f64>,
    nodes: Vec<usize>,
}

/// The regression objective's value and its parts.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RegressionEnergies {
    /// J = energy + γ_W · data.
    pub value: f64,
    /// H(x_0, p_0, p^f): the geodesic's energy on [0, 1].
    pub energy: f64,
    /// The signal part of the energy (metamorphosis).
    pub signal_energy: f64,
    /// Σ_v w_v A_v, the weighted attachments.
    pub data: f64,
    /// A_v, the attachment of the state at each visit's time to the visit
    /// (unweighted), in the order the visits were added.
    pub attachments: Vec<f64>,
}

/// J, its exact gradient, and the trajectory it was evaluated on.
#[derive(Clone, Debug)]
pub struct RegressionGradient {
    /// J and its parts.
    pub objective: RegressionEnergies,
    /// ∂J/∂p_0 (P × n).
    pub p0: Vec<f64>,
    /// ∂J/∂p^f (P × k; zeros for LDDMM).
    pub pf: Vec<f64>,
    /// The forward trajectory (on [`Regression::times`]).
    pub trajectory: Trajectory,
    /// Where the time went, both passes.
    pub timings: Timings,
}

/// The node times 0 = t_0 < … < t_N = 1 for `steps` uniform steps and
/// visits at `visits` (each in [0, 1]), and the node of each visit: the
/// uniform nodes, less those closer than a quarter step to a visit, and
/// the visits' times. Steps are then shorter than 1.5/`steps` (two
/// neighbouring uniform nodes may both give way to visits); visits close
/// to each other or to 0 or 1 make short steps, which cost an evaluation
/// each and lose no accuracy.
pub(crate) fn grid(steps: usize, visits: &[f64]) -> (Vec<f64>, Vec<usize>) {
    let h = 1.0 / steps as f64;
    let mut times: Vec<f64> = visits.to_vec();
    for k in 0..=steps {
        // k/N as the uniform grid's Trajectory::time has it (k·h can miss 1).
        let u = k as f64 / steps as f64;
        let end = k == 0 || k == steps;
        if end || visits.iter().all(|v| (v - u).abs() >= 0.25 * h) {
            times.push(u);
        }
    }
    times.sort_by(f64::total_cmp);
    times.dedup();
    let nodes = visits.iter().map(|v| times.partition_point(|t| t < v)).collect();
    (times, nodes)
}

impl Regression {
    /// A regression of `problem`'s template (the baseline, at t = 0)
    /// along its model, without visits yet. The tangential model is
    /// refused: its signal residual is an end-point control, not a path.
    pub fn new(problem: Problem) -> Result<Self, ShootError> {
        if problem.model().kind() == ModelKind::Tangential {
            return Err(ShootError::Invalid {
                what: "kind",
                why: "tangential cannot be regressed: its signal residual is a control at the end, not a path \
                      (use metamorphosis or lddmm)"
                    .into(),
            });
        }
        Ok(Regression { problem, visits: Vec::new(), times: Vec::new(), nodes: Vec::new() })
    }

    /// Adds a visit: `shape` observed at normalised time `time` ∈ [0, 1]
    /// with weight `weight` ≥ 0, compared with the attachment `kernel`.
    pub fn with_visit(
        mut self,
        time: f64,
        shape: &FShape,
        kernel: VarifoldKernel,
        weight: f64,
    ) -> Result<Self, ShootError> {
        let index = self.visits.len();
        if !(0.0..=1.0).contains(&time) {
            return Err(ShootError::Invalid {
                what: "visit time",
                why: format!("{time} of visit {index} is outside the regression's interval [0, 1]"),
            });
        }
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(ShootError::Invalid {
                what: "visit weight",
                why: format!("{weight} of visit {index} is not a finite number ≥ 0"),
            });
        }
        if shape.dim() != self.problem.template().dim() {
            return Err(ShootError::Invalid {
                what: "visit",
                why: format!(
                    "visit {index} is in {}-D, the baseline in {}-D",
                    shape.dim(),
                    self.problem.template().dim()
                ),
            });
        }
        let attachment = Attachment::new(shape, kernel)?.with_parallel(self.problem.parallel());
        self.visits.push(Visit { time, weight, attachment });
        let t: Vec<f64> = self.visits.iter().map(|v| v.time).collect();
        (self.times, self.nodes) = grid(self.problem.model().steps(), &t);
        Ok(self)
    }

    /// The problem (template and model).
    pub fn problem(&self) -> &Problem {
        &self.problem
    }

    /// The problem back, without the visits (a coarse-to-fine stage on
    /// the same template keeps its signal norm's analysis).
    pub fn into_problem(self) -> Problem {
        self.problem
    }

    /// The number of visits.
    pub fn visits(&self) -> usize {
        self.visits.len()
    }

    /// The node times of the integration (the uniform steps with a node at
    /// every visit, see the module docs) and each visit's node.
    pub fn times(&self) -> (&[f64], &[usize]) {
        (&self.times, &self.nodes)
    }

    /// Shoots (p_0, p^f) on the regression's time grid.
    pub fn shoot(&self, p0: &[f64], pf: &[f64]) -> Result<Trajectory, ShootError> {
        self.problem.check(p0, pf)?;
        self.problem.shoot_from(self.problem.initial(p0, pf), self.times.clone())
    }

    /// The state at node k as an fshape on the baseline's cells.
    fn state(&self, traj: &Trajectory, k: usize) -> Result<FShape, ShootError> {
        let t = self.problem.template();
        Ok(t.clone()
            .with_points(traj.points(k).to_vec())?
            .with_signals(Some(traj.signal(k).to_vec()), t.n_channels())?)
    }

    fn energies(&self, traj: &Trajectory, attachments: Vec<f64>) -> RegressionEnergies {
        let l = self.problem.layout;
        let energy = traj.hamiltonian[0];
        let signal_energy = if self.problem.model().kind() == ModelKind::Metamorphosis {
            0.5 * dot(&traj.node(0)[l.pf()], &traj.slope(0)[l.f()])
        } else {
            0.0
        };
        let gw = self.problem.model().gamma_w();
        let data: f64 = self.visits.iter().zip(&attachments).map(|(v, a)| v.weight * a).sum();
        RegressionEnergies { value: energy + gw * data, energy, signal_energy, data, attachments }
    }

    fn no_visits(&self) -> Result<(), ShootError> {
        if self.visits.is_empty() {
            return Err(ShootError::Invalid { what: "regression", why: "has no visits".into() });
        }
        Ok(())
    }

    /// J(p_0, p^f) and its parts, with the trajectory.
    pub fn objective(&self, p0: &[f64], pf: &[f64]) -> Result<(RegressionEnergies, Trajectory), ShootError> {
        self.no_visits()?;
        let traj = self.shoot(p0, pf)?;
        let mut a = Vec::with_capacity(self.visits.len());
        for (v, &k) in self.visits.iter().zip(&self.nodes) {
            a.push(v.attachment.eval(&self.state(&traj, k)?)?.value);
        }
        Ok((self.energies(&traj, a), traj))
    }

    /// J and its exact gradient: the discrete adjoint with a jump at every
    /// visit's node.
    pub fn objective_grad(&self, p0: &[f64], pf: &[f64]) -> Result<RegressionGradient, ShootError> {
        self.no_visits()?;
        let traj = self.shoot(p0, pf)?;
        let mut t = traj.timings;
        let l = self.problem.layout;
        let gw = self.problem.model().gamma_w();
        let mut a = Vec::with_capacity(self.visits.len());
        let mut jumps = Vec::with_capacity(self.visits.len());
        for (v, &k) in self.visits.iter().zip(&self.nodes) {
            let state = self.state(&traj, k)?;
            let (d, g) = timed(&mut t.attachment, || v.attachment.eval_grad(&state))?;
            a.push(d.value);
            let mut jump = vec![0.0; l.len()];
            axpy(&mut jump[l.x()], gw * v.weight, &g.points);
            axpy(&mut jump[l.f()], gw * v.weight, &g.signal);
            jumps.push((k, jump));
        }
        let lam = self.problem.backward(&traj, vec![0.0; l.len()], &jumps, &mut t)?;
        // ∂J/∂p_0 = ∂H_0/∂p + λ_p, ∂J/∂p^f = ∂H_0/∂p^f + λ_pf (metamorphosis).
        let k0 = traj.slope(0);
        let p0_grad = lam[l.mom()].iter().zip(&k0[l.x()]).map(|(a, b)| a + b).collect();
        let mut pf_grad: Vec<f64> = match self.problem.model().kind() {
            ModelKind::Metamorphosis => lam[l.pf()].iter().zip(&k0[l.f()]).map(|(a, b)| a + b).collect(),
            _ => vec![0.0; l.pk()],
        };
        self.problem.project_masked(&mut pf_grad);
        Ok(RegressionGradient {
            objective: self.energies(&traj, a),
            p0: p0_grad,
            pf: pf_grad,
            trajectory: traj,
            timings: t,
        })
    }
}
