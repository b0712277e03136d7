//! Forward shooting with explicit Runge–Kutta schemes, the discrete
//! adjoint, and the matching objective J with its exact gradient.

use fshape_fem::SignalNorm;
use fshape_mesh::FShape;
use fshape_varifold::{Attachment, VarifoldKernel};

use crate::dynamics::{Dynamics, Layout, Scratch, Timings, timed};
use crate::{Integrator, Model, ModelKind, ShootError};

impl Integrator {
    /// The Butcher tableau (a strictly lower triangular, row by row; b).
    pub(crate) fn tableau(self) -> (&'static [&'static [f64]], &'static [f64]) {
        match self {
            Integrator::Euler => (&[&[]], &[1.0]),
            Integrator::Midpoint => (&[&[], &[0.5]], &[0.0, 1.0]),
            Integrator::Rk4 => {
                (&[&[], &[0.5], &[0.0, 0.5], &[0.0, 0.0, 1.0]], &[1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0])
            }
        }
    }
}

/// A shooting: the states at the time steps (t_k = k/N, or given node
/// times, [`Trajectory::time`]), the stage states
/// (kept for the adjoint), the Hamiltonian at every step and timings.
#[derive(Clone, Debug)]
pub struct Trajectory {
    layout: Layout,
    /// Stages per step.
    n_stages: usize,
    /// z at t_0..t_N, one state after another (allocated once).
    nodes: Vec<f64>,
    /// F(z) at the nodes (for interpolation).
    slopes: Vec<f64>,
    /// Stage states: step k's stage i at (k·n_stages + i)·len.
    stages: Vec<f64>,
    /// H(z_k) at every node.
    pub hamiltonian: Vec<f64>,
    /// Where the forward time went.
    pub timings: Timings,
    /// Tangential model: the residual ζ (the nodes carry f_0 + ζ from
    /// t = 0, the value the data term sees; [`Trajectory::at`] reports the
    /// paper's f_0 + tζ). Empty for the other models.
    zeta: Vec<f64>,
    /// The node times t_0 = 0 < … < t_N = 1 of a grid that is not
    /// uniform (a regression's, with a node at every visit); empty for
    /// the uniform t_k = k/N.
    times: Vec<f64>,
}

impl Trajectory {
    /// The relative drift of the Hamiltonian, max_k |H_k − H_0| / |H_0|
    /// (0 when H_0 = 0), and the first step where it is reached.
    pub fn drift(&self) -> (f64, usize) {
        let h0 = self.hamiltonian[0];
        if h0 == 0.0 {
            return (0.0, 0);
        }
        let mut worst = (0.0, 0);
        for (k, h) in self.hamiltonian.iter().enumerate() {
            let d = (h - h0).abs() / h0.abs();
            if d > worst.0 {
                worst = (d, k);
            }
        }
        worst
    }

    /// Number of time steps N.
    pub fn steps(&self) -> usize {
        self.nodes.len() / self.layout.len() - 1
    }

    /// The time of node k: k/N on the uniform grid.
    ///
    /// # Panics
    ///
    /// If k > [`Trajectory::steps`].
    #[track_caller]
    pub fn time(&self, k: usize) -> f64 {
        let n = self.steps();
        assert!(k <= n, "node {k} of {n} steps");
        if self.times.is_empty() { k as f64 / n as f64 } else { self.times[k] }
    }

    /// The length of step k (from node k to k + 1).
    pub(crate) fn dt(&self, k: usize) -> f64 {
        if self.times.is_empty() { 1.0 / self.steps() as f64 } else { self.times[k + 1] - self.times[k] }
    }

    /// The state's layout.
    pub(crate) fn layout(&self) -> Layout {
        self.layout
    }

    /// The integrator's stages per step.
    pub(crate) fn stages_per_step(&self) -> usize {
        self.n_stages
    }

    /// z at step k.
    pub(crate) fn node(&self, k: usize) -> &[f64] {
        let len = self.layout.len();
        &self.nodes[k * len..(k + 1) * len]
    }

    /// F(z) at step k.
    pub(crate) fn slope(&self, k: usize) -> &[f64] {
        let len = self.layout.len();
        &self.slopes[k * len..(k + 1) * len]
    }

    /// Stage i of step k.
    pub(crate) fn stage(&self, k: usize, i: usize) -> &[f64] {
        let len = self.layout.len();
        let at = (k * self.n_stages + i) * len;
        &self.stages[at..at + len]
    }

    /// Vertex positions at step k (flat).
    ///
    /// # Panics
    ///
    /// If k > [`Trajectory::steps`].
    #[track_caller]
    pub fn points(&self, k: usize) -> &[f64] {
        &self.node(k)[self.layout.x()]
    }

    /// Signal at step k (P × k values, vertex by vertex).
    ///
    /// # Panics
    ///
    /// If k > [`Trajectory::steps`].
    #[track_caller]
    pub fn signal(&self, k: usize) -> &[f64] {
        &self.node(k)[self.layout.f()]
    }

    /// Momenta p at step k.
    ///
    /// # Panics
    ///
    /// If k > [`Trajectory::steps`].
    #[track_caller]
    pub fn momenta(&self, k: usize) -> &[f64] {
        &self.node(k)[self.layout.mom()]
    }

    /// Signal momentum p^f at step k.
    ///
    /// # Panics
    ///
    /// If k > [`Trajectory::steps`].
    #[track_caller]
    pub fn signal_momentum(&self, k: usize) -> &[f64] {
        &self.node(k)[self.layout.pf()]
    }

    /// The velocities (ẋ, ḟ) at node k: K p / γ_V at the points and, for
    /// metamorphosis, the signal velocity D_s⁻¹p^f_c/(γ_f w_c) of each
    /// channel c (zeros otherwise).
    /// ⟨p, ẋ⟩ + ⟨p^f, ḟ⟩ is twice the Hamiltonian there.
    pub fn velocity(&self, k: usize) -> (&[f64], &[f64]) {
        let z = self.slope(k);
        (&z[self.layout.x()], &z[self.layout.f()])
    }

    /// (x, f) at any t ∈ [0, 1]: cubic Hermite interpolation between the
    /// steps with the field's ẋ, ḟ at both ends (exact at the steps). For
    /// the tangential model f is the paper's affine path f_0 + tζ.
    pub fn at(&self, t: f64) -> (Vec<f64>, Vec<f64>) {
        let n = self.steps();
        let (k, u) = if self.times.is_empty() {
            let s = (t.clamp(0.0, 1.0) * n as f64).min(n as f64);
            let k = (s.floor() as usize).min(n - 1);
            (k, s - k as f64)
        } else {
            // The last node at or before t (the first step for t ≤ 0).
            let k = self.times.partition_point(|&s| s <= t).saturating_sub(1).min(n - 1);
            (k, ((t - self.times[k]) / self.dt(k)).clamp(0.0, 1.0))
        };
        let dt = self.dt(k);
        let (h00, h10, h01, h11) = (
            2.0 * u.powi(3) - 3.0 * u * u + 1.0,
            u.powi(3) - 2.0 * u * u + u,
            -2.0 * u.powi(3) + 3.0 * u * u,
            u.powi(3) - u * u,
        );
        let (z0, z1, d0, d1) = (self.node(k), self.node(k + 1), self.slope(k), self.slope(k + 1));
        let interp = |r: std::ops::Range<usize>| -> Vec<f64> {
            r.map(|i| h00 * z0[i] + h10 * dt * d0[i] + h01 * z1[i] + h11 * dt * d1[i]).collect()
        };
        let mut f = interp(self.layout.f());
        // f is f_0 + ζ here (constant along the path): f_0 + tζ is that
        // minus (1 − t)ζ.
        let back = 1.0 - t.clamp(0.0, 1.0);
        for (v, z) in f.iter_mut().zip(&self.zeta) {
            *v -= back * z;
        }
        (interp(self.layout.x()), f)
    }
}

/// The value of the matching objective J and its parts.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Energies {
    /// J = energy + γ_W·A.
    pub value: f64,
    /// H(x_0, p_0, p^f) (metamorphosis, LDDMM), plus (γ_f/2)ζᵀD_s(x_0)ζ for
    /// the tangential model: the path energy.
    pub energy: f64,
    /// The signal part of the energy.
    pub signal_energy: f64,
    /// A(x_1, f_1; target).
    pub attachment: f64,
}

/// A matching problem: template, model, and (optionally) a target.
pub struct Problem {
    template: FShape,
    model: Model,
    fem: Option<SignalNorm>,
    attachment: Option<Attachment>,
    pub(crate) layout: Layout,
    /// γ_c = γ_f w_c for each signal channel.
    gamma_f: Vec<f64>,
    parallel: bool,
}

impl Problem {
    /// Shooting only (no target). The deformation kernel's sums take the
    /// cheapest path within its tolerance for this template's points
    /// ([`fshape_kernels::Kernel::for_points`]: exact, truncated or on a
    /// grid), chosen here once, so that every shooting of this problem
    /// computes the same function; [`Problem::model`] has the kernel
    /// chosen, whose [`fshape_kernels::Kernel::path`] tells which.
    pub fn new(template: &FShape, model: Model) -> Result<Self, ShootError> {
        let (n, dim) = (template.n_vertices(), template.dim());
        let kernel = model.kernel().for_points(template.points(), dim)?;
        let model = model.with_kernel(kernel);
        let fem = if model.kind() == ModelKind::Lddmm {
            None
        } else {
            let fem = SignalNorm::try_new(template, model.norm())?;
            // Run the symbolic analysis now, once for every evaluation.
            fem.solver()?;
            Some(fem)
        };
        let mut template = template.clone();
        if template.signal().is_none() {
            template = template.with_signal(Some(vec![0.0; n]))?;
        }
        let nf = template.n_channels();
        let weights = model.channel_weights();
        if !weights.is_empty() && weights.len() != nf {
            return Err(ShootError::Dimension { what: "signal channel weights", expected: nf, found: weights.len() });
        }
        let gamma_f = (0..nf).map(|c| model.gamma_f() * weights.get(c).copied().unwrap_or(1.0)).collect();
        Ok(Problem {
            template,
            model,
            fem,
            attachment: None,
            layout: Layout { pn: n * dim, p: n, dim, nf },
            gamma_f,
            parallel: true,
        })
    }

    /// With a target and data attachment kernel (⟨Y,Y⟩ computed here, once).
    pub fn with_target(mut self, target: &FShape, kernel: VarifoldKernel) -> Result<Self, ShootError> {
        self.attachment = Some(Attachment::new(target, kernel)?.with_parallel(self.parallel));
        Ok(self)
    }

    /// Replaces the target or its data attachment kernel (a coarse-to-fine
    /// schedule changes the kernel between stages).
    pub fn set_target(&mut self, target: &FShape, kernel: VarifoldKernel) -> Result<(), ShootError> {
        self.attachment = Some(Attachment::new(target, kernel)?.with_parallel(self.parallel));
        Ok(())
    }

    /// Replaces the template's vertex positions and signal, keeping its
    /// cells (an atlas moves its template between iterations). The signal
    /// norm's symbolic analysis depends only on the cells, so it is kept.
    /// `signal` may be `None` for a zero signal.
    pub fn set_template(&mut self, points: &[f64], signal: Option<&[f64]>) -> Result<(), ShootError> {
        let pk = self.layout.pk();
        let signal = signal.map_or_else(|| vec![0.0; pk], <[f64]>::to_vec);
        // (A cell the move degenerated is refused by the first shot, which
        // names it.)
        let nf = self.layout.nf;
        self.template = self.template.clone().with_points(points.to_vec())?.with_signals(Some(signal), nf)?;
        Ok(())
    }

    /// Replaces the integrator and its number of steps (a coarse-to-fine
    /// schedule may shoot its coarse stages more cheaply); the rest of the
    /// model is kept.
    pub fn set_integrator(&mut self, integrator: crate::Integrator, steps: usize) -> Result<(), ShootError> {
        self.model = self.model.clone().with_integrator(integrator, steps)?;
        Ok(())
    }

    /// Parallel (default) or serial work everywhere below: kernel sums and
    /// FEM operations in the shooting and its adjoint, the data attachment
    /// (this target and any later one) and [`Problem::flow_points`]. Serial
    /// is for running many problems at once, one per thread. The results
    /// are identical bit for bit.
    pub fn with_parallel(mut self, parallel: bool) -> Self {
        self.set_parallel(parallel);
        self
    }

    /// [`Problem::with_parallel`] in place.
    pub fn set_parallel(&mut self, parallel: bool) {
        self.parallel = parallel;
        self.fem = self.fem.take().map(|f| f.with_parallel(parallel));
        self.attachment = self.attachment.take().map(|a| a.with_parallel(parallel));
    }

    /// Whether the work runs in parallel ([`Problem::with_parallel`]).
    pub fn parallel(&self) -> bool {
        self.parallel
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The template (with a zero signal if it had none).
    pub fn template(&self) -> &FShape {
        &self.template
    }

    pub(crate) fn dynamics(&self) -> Dynamics<'_> {
        let evolving = self.model.kind() == ModelKind::Metamorphosis;
        Dynamics {
            kernel: self.model.kernel(),
            fem: if evolving { self.fem.as_ref() } else { None },
            gamma_v: self.model.gamma_v(),
            gamma_f: &self.gamma_f,
            layout: self.layout,
            parallel: self.parallel,
        }
    }

    pub(crate) fn check(&self, p0: &[f64], pf: &[f64]) -> Result<(), ShootError> {
        self.check_as(["momentum p0", "signal momentum"], p0, pf)
    }

    /// [`Problem::check`] with the two arrays called `names` in errors.
    pub(crate) fn check_as(&self, names: [&'static str; 2], p0: &[f64], pf: &[f64]) -> Result<(), ShootError> {
        let l = self.layout;
        for (what, v, n) in [(names[0], p0, l.pn), (names[1], pf, l.pk())] {
            if v.len() != n {
                return Err(ShootError::Dimension { what, expected: n, found: v.len() });
            }
            if let Some(i) = v.iter().position(|a| !a.is_finite()) {
                return Err(ShootError::NonFinite { what, index: i / (n / l.p).max(1) });
            }
        }
        Ok(())
    }

    /// The initial state: for the tangential model the signal residual ζ
    /// is added to the template signal (and p^f is 0).
    pub(crate) fn initial(&self, p0: &[f64], pf: &[f64]) -> Vec<f64> {
        let l = self.layout;
        let mut z = vec![0.0; l.len()];
        z[l.x()].copy_from_slice(self.template.points());
        z[l.f()].copy_from_slice(self.template.signal().expect("set in new"));
        // A masked vertex's signal (NaN: no value) starts at 0 and is never
        // read: the attachment leaves masked cells' signal out and the
        // dynamics do not read f.
        for v in z[l.f()].iter_mut().filter(|v| v.is_nan()) {
            *v = 0.0;
        }
        z[l.mom()].copy_from_slice(p0);
        let pf = self.unmasked(pf);
        match self.model.kind() {
            ModelKind::Metamorphosis => z[l.pf()].copy_from_slice(&pf),
            ModelKind::Tangential => {
                for (a, b) in z[l.f()].iter_mut().zip(pf.iter()) {
                    *a += b;
                }
            }
            ModelKind::Lddmm => {}
        }
        z
    }

    /// p^f (or ζ) with its masked entries set to 0: the signal control is
    /// zero where the template's mask is 0 (the signal there has no value),
    /// whatever the caller gives; the gradient is projected the same way.
    pub(crate) fn unmasked<'a>(&self, pf: &'a [f64]) -> std::borrow::Cow<'a, [f64]> {
        match self.template.mask() {
            Some(m) if m.contains(&0.0) => {
                let mut out = pf.to_vec();
                self.project_masked(&mut out);
                std::borrow::Cow::Owned(out)
            }
            _ => std::borrow::Cow::Borrowed(pf),
        }
    }

    /// Zeroes a gradient's masked entries (the adjoint of [`Problem::unmasked`]).
    pub(crate) fn project_masked(&self, g: &mut [f64]) {
        if let Some(m) = self.template.mask() {
            // Every channel of a masked vertex.
            for (g, w) in g.chunks_exact_mut(self.layout.nf).zip(m) {
                if *w == 0.0 {
                    g.fill(0.0);
                }
            }
        }
    }

    /// Shoots from the template with momenta p_0 (P × n) and p^f (P × k,
    /// one per vertex and signal channel, vertex by vertex; for the
    /// tangential model the signal residual ζ, for LDDMM ignored).
    pub fn shoot(&self, p0: &[f64], pf: &[f64]) -> Result<Trajectory, ShootError> {
        self.check(p0, pf)?;
        let mut traj = self.shoot_from(self.initial(p0, pf), Vec::new())?;
        if self.model.kind() == ModelKind::Tangential {
            traj.zeta = self.unmasked(pf).into_owned();
        }
        Ok(traj)
    }

    /// The forward pass on the node times `times` (empty: the model's
    /// uniform steps). Every buffer is allocated here, before the first
    /// step: the loop over steps allocates nothing.
    pub(crate) fn shoot_from(&self, z0: Vec<f64>, times: Vec<f64>) -> Result<Trajectory, ShootError> {
        let dynamics = self.dynamics();
        let mut scratch = Scratch::new(self.layout, dynamics.fem)?;
        let (a, b) = self.model.integrator().tableau();
        let n = if times.is_empty() { self.model.steps() } else { times.len() - 1 };
        let uniform = 1.0 / n as f64;
        let step_length = |k: usize| if times.is_empty() { uniform } else { times[k + 1] - times[k] };
        let mut t = Timings::default();
        let l = self.layout;
        let (len, s) = (l.len(), b.len());
        let mut nodes = vec![0.0; (n + 1) * len];
        let mut slopes = vec![0.0; (n + 1) * len];
        let mut stages = vec![0.0; n * s * len];
        let mut ham = Vec::with_capacity(n + 1);
        // Stage slopes k_i, and h = D⁻¹p^f (not kept).
        let mut ks = vec![0.0; s * len];
        let mut h = vec![0.0; l.pk()];
        nodes[..len].copy_from_slice(&z0);
        for step in 0..=n {
            let (done, rest) = nodes.split_at_mut((step + 1) * len);
            let z = &done[step * len..];
            let k0 = &mut slopes[step * len..(step + 1) * len];
            dynamics.field(z, &mut h, k0, &mut scratch, &mut t).map_err(|e| collapsed(e, step, step > 0))?;
            let energy = 0.5 * (dot(&z[l.mom()], &k0[l.x()]) + dot(&z[l.pf()], &k0[l.f()]));
            if !energy.is_finite() || z.iter().any(|v| !v.is_finite()) {
                return Err(ShootError::Diverged { step });
            }
            ham.push(energy);
            if step == n {
                break;
            }
            let dt = step_length(step);
            ks[..len].copy_from_slice(k0);
            let zs = &mut stages[step * s * len..(step + 1) * s * len];
            zs[..len].copy_from_slice(z);
            for i in 1..s {
                let (prev, cur) = ks.split_at_mut(i * len);
                let zi = &mut zs[i * len..(i + 1) * len];
                zi.copy_from_slice(z);
                for (j, aij) in a[i].iter().enumerate() {
                    if *aij != 0.0 {
                        axpy(zi, dt * aij, &prev[j * len..(j + 1) * len]);
                    }
                }
                dynamics
                    .field(zi, &mut h, &mut cur[..len], &mut scratch, &mut t)
                    .map_err(|e| collapsed(e, step, true))?;
            }
            let next = &mut rest[..len];
            next.copy_from_slice(z);
            for (i, bi) in b.iter().enumerate() {
                if *bi != 0.0 {
                    axpy(next, dt * bi, &ks[i * len..(i + 1) * len]);
                }
            }
        }
        let traj = Trajectory {
            layout: l,
            n_stages: s,
            nodes,
            slopes,
            stages,
            hamiltonian: ham,
            timings: t,
            zeta: Vec::new(),
            times,
        };
        let (drift, step) = traj.drift();
        let tolerance = self.model.max_drift();
        if drift > tolerance {
            return Err(ShootError::Drift { drift, initial: traj.hamiltonian[0], step, tolerance });
        }
        Ok(traj)
    }

    fn attachment(&self) -> Result<&Attachment, ShootError> {
        self.attachment.as_ref().ok_or(ShootError::NoTarget)
    }

    /// The signal part of the energy and its gradient in the control pf.
    fn signal_energy(&self, pf: &[f64], t: &mut Timings) -> Result<(f64, Vec<f64>), ShootError> {
        let nf = self.layout.nf;
        match (self.model.kind(), &self.fem) {
            (ModelKind::Tangential, Some(fem)) if nf == 1 => timed(&mut t.fem, || {
                // (γ_f/2) ζᵀD(x_0)ζ, gradient γ_f D(x_0)ζ.
                let g = self.gamma_f[0];
                let dz = fem.matvec(self.template.points(), pf)?;
                Ok((0.5 * g * dot(pf, &dz), dz.iter().map(|v| g * v).collect()))
            }),
            // Σ_c (γ_c/2) ζ_cᵀD(x_0)ζ_c, channel by channel.
            (ModelKind::Tangential, Some(fem)) => timed(&mut t.fem, || {
                let (mut energy, mut grad) = (0.0, vec![0.0; pf.len()]);
                for c in 0..nf {
                    let zc: Vec<f64> = pf.iter().skip(c).step_by(nf).copied().collect();
                    let dz = fem.matvec(self.template.points(), &zc)?;
                    let g = self.gamma_f[c];
                    energy += 0.5 * g * dot(&zc, &dz);
                    for (o, v) in grad.iter_mut().skip(c).step_by(nf).zip(&dz) {
                        *o = g * v;
                    }
                }
                Ok((energy, grad))
            }),
            _ => Ok((0.0, vec![0.0; self.layout.pk()])),
        }
    }

    /// J(p_0, p^f) and its parts.
    pub fn objective(&self, p0: &[f64], pf: &[f64]) -> Result<(Energies, Trajectory), ShootError> {
        self.evaluate(p0, pf, false).map(|e| (e.objective, e.trajectory))
    }

    /// Shoots and evaluates J; with `grad`, the attachment's gradient and the
    /// signal energy's come from the same evaluations (each done once).
    fn evaluate(&self, p0: &[f64], pf: &[f64], grad: bool) -> Result<Evaluation, ShootError> {
        let att = self.attachment()?;
        let traj = self.shoot(p0, pf)?;
        let mut t = traj.timings;
        let (es, ges) = self.signal_energy(&self.unmasked(pf), &mut t)?;
        let last = self.model.steps();
        let x1 = self.template.clone().with_points(traj.points(last).to_vec())?;
        let x1 = x1.with_signals(Some(traj.signal(last).to_vec()), self.layout.nf)?;
        let (a, ga) = if grad {
            let (d, g) = timed(&mut t.attachment, || att.eval_grad(&x1))?;
            (d.value, Some(g))
        } else {
            (timed(&mut t.attachment, || att.eval(&x1))?.value, None)
        };
        let h0 = traj.hamiltonian[0];
        let metamorphosis_signal = if self.model.kind() == ModelKind::Metamorphosis {
            0.5 * dot(&traj.node(0)[self.layout.pf()], &traj.slope(0)[self.layout.f()])
        } else {
            0.0
        };
        let energy = h0 + es;
        let objective = Energies {
            value: energy + self.model.gamma_w() * a,
            energy,
            signal_energy: es + metamorphosis_signal,
            attachment: a,
        };
        Ok(Evaluation {
            objective,
            trajectory: Trajectory { timings: t, ..traj },
            attachment_grad: ga,
            signal_grad: ges,
        })
    }

    /// J and its exact gradient (∂J/∂p_0, ∂J/∂p^f): the discrete adjoint
    /// of the integrator in use, so the gradient is that of the discrete
    /// J. Also returns the timings: forward, backward.
    pub fn objective_grad(&self, p0: &[f64], pf: &[f64]) -> Result<Gradient, ShootError> {
        let start = std::time::Instant::now();
        let Evaluation { objective: obj, trajectory: traj, attachment_grad, signal_grad: ges } =
            self.evaluate(p0, pf, true)?;
        let ga = attachment_grad.expect("requested");
        let forward = start.elapsed().as_secs_f64();
        let mut t = traj.timings;
        let l = self.layout;
        let back = std::time::Instant::now();
        // λ_N = ∂J/∂z_N.
        let gw = self.model.gamma_w();
        let mut lam = vec![0.0; l.len()];
        for (o, v) in lam[l.x()].iter_mut().zip(&ga.points) {
            *o = gw * v;
        }
        for (o, v) in lam[l.f()].iter_mut().zip(&ga.signal) {
            *o = gw * v;
        }
        let lam = self.backward(&traj, lam, &[], &mut t)?;
        let backward = back.elapsed().as_secs_f64();
        // ∂J/∂p_0 = ∂H_0/∂p + λ_p; ∂J/∂p^f = ∂H_0/∂p^f + λ_pf (metamorphosis),
        // or the signal energy's gradient + λ_f (tangential: f_0 = f + ζ).
        let k0 = traj.slope(0);
        let grad_p: Vec<f64> = lam[l.mom()].iter().zip(&k0[l.x()]).map(|(a, b)| a + b).collect();
        let grad_pf: Vec<f64> = match self.model.kind() {
            ModelKind::Metamorphosis => lam[l.pf()].iter().zip(&k0[l.f()]).map(|(a, b)| a + b).collect(),
            ModelKind::Tangential => lam[l.f()].iter().zip(&ges).map(|(a, b)| a + b).collect(),
            ModelKind::Lddmm => vec![0.0; l.pk()],
        };
        // The template's gradient: ∂J/∂x_0 = λ_x + ∂H_0/∂x, and ∂H/∂x = −ṗ,
        // the momentum's slope at t = 0 with the sign changed; the
        // tangential model's (γ_f/2)ζᵀD(x_0)ζ adds (γ_f/2)∂_x(ζᵀDζ).
        // ∂J/∂f_0 = λ_f: H does not depend on f (f_0 + ζ for tangential).
        let mut grad_pf = grad_pf;
        self.project_masked(&mut grad_pf);
        let mut grad_x: Vec<f64> = lam[l.x()].iter().zip(&k0[l.mom()]).map(|(a, b)| a - b).collect();
        if let (ModelKind::Tangential, Some(fem)) = (self.model.kind(), &self.fem) {
            let pf = self.unmasked(pf);
            let nf = l.nf;
            for c in 0..nf {
                let zc: std::borrow::Cow<'_, [f64]> = if nf == 1 {
                    std::borrow::Cow::Borrowed(&pf)
                } else {
                    std::borrow::Cow::Owned(pf.iter().skip(c).step_by(nf).copied().collect())
                };
                let g = timed(&mut t.fem, || fem.grad(self.template.points(), &zc, &zc))?;
                axpy(&mut grad_x, 0.5 * self.gamma_f[c], &g);
            }
        }
        let mut grad_f = lam[l.f()].to_vec();
        self.project_masked(&mut grad_f);
        Ok(Gradient {
            objective: obj,
            p0: grad_p,
            pf: grad_pf,
            x0: grad_x,
            f0: grad_f,
            forward,
            backward,
            timings: t,
            trajectory: traj,
        })
    }

    /// The adjoint pass: from λ = ∂Φ/∂z_N at the end of `traj`, ∂Φ/∂z_0
    /// through the integrator's steps (the discrete adjoint). `jumps`
    /// (node k, ∂Φ/∂z_k's explicit part, a full state's length) are added
    /// as the pass reaches their node: Φ that also reads the states
    /// between the ends (a regression's visits) jumps there.
    pub(crate) fn backward(
        &self,
        traj: &Trajectory,
        mut lam: Vec<f64>,
        jumps: &[(usize, Vec<f64>)],
        t: &mut Timings,
    ) -> Result<Vec<f64>, ShootError> {
        let l = self.layout;
        let last = traj.steps();
        let dynamics = self.dynamics();
        let mut scratch = Scratch::new(l, dynamics.fem)?;
        let (a, b) = self.model.integrator().tableau();
        let (len, s) = (l.len(), b.len());
        let jump = |lam: &mut Vec<f64>, node: usize| {
            for (_, g) in jumps.iter().filter(|(k, _)| *k == node) {
                axpy(lam, 1.0, g);
            }
        };
        // ∂J/∂Z_i for the stages of one step, ∂J/∂k_i, and h at a stage.
        let mut gz = vec![0.0; s * len];
        let mut gk = vec![0.0; len];
        let mut h = vec![0.0; l.pk()];
        for step in (0..last).rev() {
            jump(&mut lam, step + 1);
            let dt = traj.dt(step);
            for i in (0..s).rev() {
                // ∂J/∂k_i = dt b_i λ + Σ_{j>i} dt a_ji ∂J/∂Z_j.
                for (g, v) in gk.iter_mut().zip(&lam) {
                    *g = dt * b[i] * v;
                }
                let (mine, later) = gz.split_at_mut((i + 1) * len);
                for j in i + 1..s {
                    let aji = a[j].get(i).copied().unwrap_or(0.0);
                    if aji != 0.0 {
                        axpy(&mut gk, dt * aji, &later[(j - i - 1) * len..(j - i) * len]);
                    }
                }
                let gzi = &mut mine[i * len..];
                if gk.iter().all(|v| *v == 0.0) {
                    gzi.fill(0.0);
                    continue;
                }
                // Refactored at Z_i, h recovered there.
                let zi = traj.stage(step, i);
                dynamics.vjp(zi, &mut h, &gk, gzi, &mut scratch, t)?;
            }
            for g in gz.chunks_exact(len) {
                axpy(&mut lam, 1.0, g);
            }
        }
        jump(&mut lam, 0);
        Ok(lam)
    }

    /// The gradient of Φ = H(z_0) + ⟨end_x, x_1⟩ + ⟨end_f, f_1⟩ in (p_0,
    /// p^f) along `traj` (shot from p_0, p^f by [`Problem::shoot`]): the
    /// adjoint with a given end co-state, for a template that is itself
    /// shot (an atlas's hypertemplate), where ∂J/∂x_1 comes from
    /// elsewhere. For LDDMM the ∂/∂p^f part is zeros.
    pub fn pullback(
        &self,
        traj: &Trajectory,
        end_x: &[f64],
        end_f: &[f64],
    ) -> Result<(Vec<f64>, Vec<f64>), ShootError> {
        let l = self.layout;
        for (what, v, n) in [("end co-state of x", end_x, l.pn), ("end co-state of f", end_f, l.pk())] {
            if v.len() != n {
                return Err(ShootError::Dimension { what, expected: n, found: v.len() });
            }
        }
        let mut lam = vec![0.0; l.len()];
        lam[l.x()].copy_from_slice(end_x);
        lam[l.f()].copy_from_slice(end_f);
        let mut t = Timings::default();
        let lam = self.backward(traj, lam, &[], &mut t)?;
        let k0 = traj.slope(0);
        let grad_p = lam[l.mom()].iter().zip(&k0[l.x()]).map(|(a, b)| a + b).collect();
        let grad_pf = match self.model.kind() {
            ModelKind::Metamorphosis => lam[l.pf()].iter().zip(&k0[l.f()]).map(|(a, b)| a + b).collect(),
            ModelKind::Tangential => lam[l.f()].to_vec(),
            ModelKind::Lddmm => vec![0.0; l.pk()],
        };
        Ok((grad_p, grad_pf))
    }

    /// Flows extra points (M × n) along a trajectory: ẏ = K_{y,x} p / γ_V,
    /// integrated with the same scheme and stages as the shooting. Returns
    /// their positions at every step.
    pub fn flow_points(&self, traj: &Trajectory, y0: &[f64]) -> Result<Vec<Vec<f64>>, ShootError> {
        let l = self.layout;
        if !y0.len().is_multiple_of(l.dim) {
            return Err(ShootError::Points { what: "points to flow", found: y0.len(), dim: l.dim });
        }
        let (a, b) = self.model.integrator().tableau();
        let field = |y: &[f64], z: &[f64]| -> Result<Vec<f64>, ShootError> {
            let sums = fshape_kernels::KernelSums::try_new(self.model.kernel(), &z[l.x()], l.dim)?
                .with_parallel(self.parallel);
            Ok(sums.conv(y, &z[l.mom()], l.dim)?.iter().map(|v| v / self.model.gamma_v()).collect())
        };
        let mut y = y0.to_vec();
        let mut out = vec![y.clone()];
        for step in 0..traj.steps() {
            let dt = traj.dt(step);
            let mut ks: Vec<Vec<f64>> = Vec::new();
            for (i, ai) in a.iter().enumerate() {
                let mut yi = y.clone();
                for (aij, kj) in ai.iter().zip(&ks) {
                    axpy(&mut yi, dt * aij, kj);
                }
                ks.push(field(&yi, traj.stage(step, i))?);
            }
            for (bi, ki) in b.iter().zip(&ks) {
                axpy(&mut y, dt * bi, ki);
            }
            out.push(y.clone());
        }
        Ok(out)
    }
}

/// A signal-norm error on a state the flow produced (not the template's
/// own) means the flow degenerated a cell: divergence, reported as such.
fn collapsed(e: ShootError, step: usize, moved: bool) -> ShootError {
    match e {
        ShootError::Fem(source) if moved => ShootError::Collapsed { step, source },
        other => other,
    }
}

/// One forward evaluation of J, with the end-point gradients when asked.
struct Evaluation {
    objective: Energies,
    trajectory: Trajectory,
    attachment_grad: Option<fshape_varifold::ShapeGrad>,
    /// ∂/∂p^f of the signal energy (tangential model; zeros otherwise).
    signal_grad: Vec<f64>,
}

/// J, its gradient and where the time went.
#[derive(Clone, Debug)]
pub struct Gradient {
    /// J and its parts.
    pub objective: Energies,
    /// ∂J/∂p_0 (P × n).
    pub p0: Vec<f64>,
    /// ∂J/∂p^f (P × k): ∂J/∂ζ for the tangential model, zeros for LDDMM.
    pub pf: Vec<f64>,
    /// ∂J/∂x_0 (P × n): the gradient in the template's vertex positions,
    /// momenta held fixed (an atlas's template gradient).
    pub x0: Vec<f64>,
    /// ∂J/∂f_0 (P × k): the gradient in the template's signal, momenta held
    /// fixed.
    pub f0: Vec<f64>,
    /// Seconds in the forward pass (shooting + A).
    pub forward: f64,
    /// Seconds in the backward pass (adjoint).
    pub backward: f64,
    /// Split by component over both passes.
    pub timings: Timings,
    /// The forward trajectory.
    pub trajectory: Trajectory,
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

pub(crate) fn axpy(y: &mut [f64], a: f64, x: &[f64]) {
    for (u, v) in y.iter_mut().zip(x) {
        *u += a * v;
    }
}
