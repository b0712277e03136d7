//! Parallel transport of momenta along a shot geodesic: how a subject's
//! rate of change, a momentum at its own baseline, is carried to an atlas
//! template so that rates of different subjects can be compared.
//!
//! The discrete metamorphosis is the geodesic flow of a Riemannian metric
//! on the states q = (x, f): H = ½ πᵀG*(x)π with the cometric
//!
//! G*(x) = diag(K(x)/γ_V ⊗ I_d, D_s(x)⁻¹/γ_c for each channel c)
//!
//! (DESIGN.md "The discrete model"; LDDMM keeps the x block only). A
//! momentum β stands for the tangent vector w = G*β, and parallel
//! transport is Levi-Civita's for that metric.
//!
//! The scheme is the fanning scheme of Louis, Charlier, Jusselin, Pal and
//! Durrleman ("A fanning scheme for the parallel transport along
//! geodesics on Riemannian manifolds", SIAM J. Numer. Anal. 56(4), 2018),
//! which needs only the geodesic flow and the metric. At node k of the
//! shooting, with step h = t_{k+1} − t_k:
//!
//! 1. J(h), the Jacobi field of the geodesics from q_k with momentum
//!    p_k + εβ_k, differentiated in ε at 0 (J(0) = 0, J'(0) = w_k);
//! 2. w_{k+1} = J(h)/h;
//! 3. β_{k+1} = G(q_{k+1}) w_{k+1}: β_x = γ_V K(x_{k+1})⁻¹ w_x and
//!    β_{f,c} = γ_c D_s(x_{k+1}) w_{f,c}.
//!
//! Why it converges: in a parallel frame the Jacobi equation
//! J'' = −R(J, γ')γ' with J(0) = 0 gives
//! J(h) = h P_h w − (h³/6) P_h R(w, γ')γ' + O(h⁴), so step 2 errs by O(h²)
//! and N steps by O(h): order 1 (the paper's theorem). The integrator's own step must be exact to O(h³) for
//! this, so Euler (whose derivative in p is h·w, missing the connection's
//! h² term) is refused; midpoint and RK4 qualify.
//!
//! Where this departs from the paper and from Deformetrica: J is not taken
//! by central differences of two perturbed shootings (with ε = h), but as
//! the exact derivative of the integrator's step, stage by stage with the
//! field's exact directional derivative (`Dynamics::jvp`): no ε to
//! choose, and no second-order finite-difference error. Nothing is
//! renormalised: the norm and the component along the geodesic, which
//! exact transport keeps, are reported at both ends ([`Transported`]), so
//! their drift measures the scheme's error.
//!
//! Masks: a masked vertex's signal momentum is kept at 0 at every node,
//! as every control is. Under the lumped L² norm (diagonal D_s) the
//! masked model is a Riemannian one on the unmasked signal values and
//! this is its transport. Under a norm whose D_s is not diagonal (L², H¹)
//! the velocity D_s⁻¹p^f reaches masked vertices while their momenta stay
//! 0: the model is then constrained, and zeroing at every node defines the
//! transport used, which is not Levi-Civita's of the unmasked metric and
//! has no reference to converge to. A geodesic still carries its own
//! momentum to its end (tests/shoot/transport.rs).
//!
//! Step 3 solves with the dense kernel matrix (a Cholesky factor per
//! node, [`MAX_TRANSPORT_VERTICES`] at most, with exact or truncated
//! kernel sums: grid sums approximate a kernel whose matrix this does not
//! have, so they are refused): the kernel matrix of a
//! finely sampled surface is badly conditioned, and a factor that meets a
//! non-positive pivot is an error naming the node. Transport on a
//! decimated template is the way around both.

use fshape_kernels::SumPath;

use crate::dynamics::{Dynamics, Scratch, Timings};
use crate::shoot::{axpy, dot};
use crate::{DenseKernelFactor, Integrator, ModelKind, Problem, ShootError, Trajectory};

/// The most vertices [`Problem::transport`] takes: its dense kernel
/// factor holds n² values (128 MiB at this size) and costs n³/3 flops
/// per node.
pub const MAX_TRANSPORT_VERTICES: usize = 4096;

/// Momenta carried to the last node of a trajectory by
/// [`Problem::transport`].
#[derive(Clone, Debug, PartialEq)]
pub struct Transported {
    /// β_x at the last node (P × n, vertex by vertex).
    pub momentum: Vec<f64>,
    /// β_f at the last node (P × k; masked vertices 0; LDDMM: all 0).
    pub signal_momentum: Vec<f64>,
    /// ‖β‖² = βᵀG*β at the first node and at the last. Parallel transport
    /// keeps it; the scheme changes it by O(h).
    pub norm: [f64; 2],
    /// ⟨β, γ'⟩ = βᵀG*π, the component along the geodesic's own velocity,
    /// at the first node and at the last; kept by parallel transport too.
    pub along: [f64; 2],
}

impl Problem {
    /// Carries the momenta (`momentum`, P × n; `signal_momentum`, P × k,
    /// masked entries taken as 0) from the first node of `traj`, a
    /// shooting of this problem, to its last node by parallel transport
    /// (the module's fanning scheme; first order in the step).
    ///
    /// Transport back along the same geodesic is transport along the
    /// shooting from its end with momenta −(p_N, p^f_N).
    ///
    /// # Errors
    ///
    /// Mismatched lengths or non-finite momenta; the tangential model or
    /// the Euler integrator; a trajectory of another problem; more than
    /// [`MAX_TRANSPORT_VERTICES`] vertices; grid kernel sums; a kernel
    /// matrix that is not numerically positive definite at some node.
    pub fn transport(
        &self,
        traj: &Trajectory,
        momentum: &[f64],
        signal_momentum: &[f64],
    ) -> Result<Transported, ShootError> {
        self.refuse_transport(traj, momentum, signal_momentum)?;
        let l = self.layout;
        let (a, b) = self.model().integrator().tableau();
        let dynamics = self.dynamics();
        let mut scratch = Scratch::new(l, dynamics.fem)?;
        let mut t = Timings::default();
        let mut h = vec![0.0; l.pk()];
        let (len, s) = (l.len(), b.len());
        // dz: the perturbation (0, 0, β_x, β_f) at node k, then its image.
        let mut dz = vec![0.0; len];
        dz[l.mom()].copy_from_slice(momentum);
        dz[l.pf()].copy_from_slice(&self.unmasked(signal_momentum));
        if dynamics.fem.is_none() {
            dz[l.pf()].fill(0.0);
        }
        let first = measure(&dynamics, traj, 0, &dz, &mut scratch, &mut h, &mut t)?;
        let mut dks = vec![0.0; s * len];
        let mut dzi = vec![0.0; len];
        let mut next = vec![0.0; len];
        for k in 0..traj.steps() {
            let dt = traj.dt(k);
            // The step's exact tangent-linear map applied to dz.
            for i in 0..s {
                dzi.copy_from_slice(&dz);
                for (j, aij) in a[i].iter().enumerate() {
                    if *aij != 0.0 {
                        axpy(&mut dzi, dt * aij, &dks[j * len..(j + 1) * len]);
                    }
                }
                let out = &mut dks[i * len..(i + 1) * len];
                dynamics.jvp(traj.stage(k, i), &mut h, &dzi, out, &mut scratch, &mut t)?;
            }
            next.copy_from_slice(&dz);
            for (i, bi) in b.iter().enumerate() {
                if *bi != 0.0 {
                    axpy(&mut next, dt * bi, &dks[i * len..(i + 1) * len]);
                }
            }
            // w_{k+1} = J(h)/h, then β_{k+1} = G(q_{k+1}) w_{k+1}.
            let node = traj.node(k + 1);
            let x = &node[l.x()];
            let wx: Vec<f64> = next[l.x()].iter().map(|v| v / dt).collect();
            let beta = self.kernel_solve(x, wx, k + 1)?;
            dz.fill(0.0);
            for (o, v) in dz[l.mom()].iter_mut().zip(&beta) {
                *o = self.model().gamma_v() * v;
            }
            if let Some(fem) = dynamics.fem {
                let mut wc = vec![0.0; l.p];
                for c in 0..l.nf {
                    for (o, v) in wc.iter_mut().zip(next[l.f()].iter().skip(c).step_by(l.nf)) {
                        *o = v / dt;
                    }
                    let bc = fem.matvec(x, &wc)?;
                    let g = dynamics.gamma_f[c];
                    for (o, v) in dz[l.pf()].iter_mut().skip(c).step_by(l.nf).zip(&bc) {
                        *o = g * v;
                    }
                }
                self.project_masked(&mut dz[l.pf()]);
            }
            if let Some(i) = dz.iter().position(|v| !v.is_finite()) {
                return Err(ShootError::Transport { node: k + 1, why: format!("entry {i} is not finite") });
            }
        }
        let last = measure(&dynamics, traj, traj.steps(), &dz, &mut scratch, &mut h, &mut t)?;
        Ok(Transported {
            momentum: dz[l.mom()].to_vec(),
            signal_momentum: dz[l.pf()].to_vec(),
            norm: [first.0, last.0],
            along: [first.1, last.1],
        })
    }

    /// Carries the momenta (`momentum`, `signal_momentum`) from the last
    /// node of `traj`, a shooting of this problem, back to its first: the
    /// transport along the shooting from the end (its points and signal)
    /// with the momenta −(p_N, p^f_N), on the model's uniform steps. This
    /// is how a rate at a subject's shape (the end of a registration from
    /// the atlas template) is carried to the template.
    ///
    /// # Errors
    ///
    /// As [`Problem::transport`], and any error of the shooting back.
    pub fn transport_back(
        &self,
        traj: &Trajectory,
        momentum: &[f64],
        signal_momentum: &[f64],
    ) -> Result<Transported, ShootError> {
        self.refuse_transport(traj, momentum, signal_momentum)?;
        let l = self.layout;
        let n = traj.steps();
        let end = self.template().clone().with_points(traj.points(n).to_vec())?;
        let end = end.with_signals_and_mask(
            Some(traj.signal(n).to_vec()),
            l.nf,
            self.template().mask().map(<[f64]>::to_vec),
        )?;
        let back = Problem::new(&end, self.model().clone())?.with_parallel(self.parallel());
        let neg = |v: &[f64]| v.iter().map(|a| -a).collect::<Vec<f64>>();
        let reversed = back.shoot(&neg(traj.momenta(n)), &neg(traj.signal_momentum(n)))?;
        back.transport(&reversed, momentum, signal_momentum)
    }

    /// What [`Problem::transport`] refuses, checked before any work.
    fn refuse_transport(&self, traj: &Trajectory, momentum: &[f64], signal_momentum: &[f64]) -> Result<(), ShootError> {
        let l = self.layout;
        let refuse = |why: String| Err(ShootError::CannotTransport { why });
        self.check_as(["the momentum to carry", "the signal momentum to carry"], momentum, signal_momentum)?;
        if self.model().kind() == ModelKind::Tangential {
            return refuse("it is defined for metamorphosis and LDDMM, not the tangential model".into());
        }
        let integrator = self.model().integrator();
        if integrator == Integrator::Euler {
            return refuse(
                "it needs a second-order integrator (midpoint or rk4): Euler's step misses the connection's h² term"
                    .into(),
            );
        }
        let t = traj.layout();
        if (t.p, t.dim, t.nf) != (l.p, l.dim, l.nf) || traj.stages_per_step() != integrator.tableau().1.len() {
            return refuse(format!(
                "the trajectory has {} points in {}-D with {} signal channels and {} stages a step, the problem {} in \
                 {}-D with {} and {}: it is not this problem's shooting",
                t.p,
                t.dim,
                t.nf,
                traj.stages_per_step(),
                l.p,
                l.dim,
                l.nf,
                integrator.tableau().1.len()
            ));
        }
        if l.p > MAX_TRANSPORT_VERTICES {
            return refuse(format!(
                "it solves with the dense kernel matrix: {} vertices is more than {MAX_TRANSPORT_VERTICES}; \
                 transport on a decimated template",
                l.p
            ));
        }
        if let SumPath::Grid { .. } = self.model().kernel().path() {
            return refuse(
                "it solves with the kernel's matrix, which grid sums only approximate: set no deformation tolerance \
                 (exact sums) or a template small enough for truncated ones"
                    .into(),
            );
        }
        Ok(())
    }

    /// K(x)⁻¹ w for the P × n vector field `w` (each coordinate alike), by
    /// a dense Cholesky factor of the kernel matrix at `x`.
    fn kernel_solve(&self, x: &[f64], mut w: Vec<f64>, node: usize) -> Result<Vec<f64>, ShootError> {
        let factor = DenseKernelFactor::new(x, self.layout.dim, self.model().kernel(), &vec![0.0; self.layout.p])
            .ok_or_else(|| ShootError::Transport {
                node,
                why: "the kernel matrix is not numerically positive definite (points closer than the kernel \
                      resolves; transport on a decimated template)"
                    .into(),
            })?;
        factor.solve_in_place(&mut w);
        Ok(w)
    }
}

/// ‖β‖² = βᵀG*β and ⟨β, γ'⟩ at node k, with β the momenta of `dz`: G*β
/// is the field's x and f rates at (x_k, f_k, β).
fn measure(
    dynamics: &Dynamics<'_>,
    traj: &Trajectory,
    k: usize,
    dz: &[f64],
    scratch: &mut Scratch<'_>,
    h: &mut [f64],
    t: &mut Timings,
) -> Result<(f64, f64), ShootError> {
    let l = dynamics.layout;
    let mut z = traj.node(k).to_vec();
    z[l.mom()].copy_from_slice(&dz[l.mom()]);
    z[l.pf()].copy_from_slice(&dz[l.pf()]);
    let mut rates = vec![0.0; l.len()];
    dynamics.field(&z, h, &mut rates, scratch, t)?;
    let norm = dot(&dz[l.mom()], &rates[l.x()]) + dot(&dz[l.pf()], &rates[l.f()]);
    let slope = traj.slope(k);
    let along = dot(&dz[l.mom()], &slope[l.x()]) + dot(&dz[l.pf()], &slope[l.f()]);
    Ok((norm, along))
}
