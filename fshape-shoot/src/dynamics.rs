//! The Hamiltonian vector field F(z) of the reduced metamorphosis
//! Hamiltonian (DESIGN.md "The discrete model") and its exact directional
//! and transposed derivatives.
//!
//! State z = (x, f, p, p^f), flat: [x (P·n) | f (P) | p (P·n) | p^f (P)].
//!
//! - ẋ = K_{x,x} p / γ_V
//! - ḟ = h / γ_f, h = D_s(x)⁻¹ p^f
//! - ṗ = −∂_x(pᵀK p)/(2γ_V) + ∂_x(hᵀD_s(x)h)|_h/(2γ_f)
//! - ṗ^f = 0
//!
//! With signal dynamics off (LDDMM, and the geometry of the tangential
//! model) ḟ = 0 and the p^f terms vanish. F = 𝕁∇H with 𝕁(a_x, a_f, a_p,
//! a_pf) = (a_p, a_pf, −a_x, −a_f), so dFᵀv = 𝕁 dF(𝕁v): one directional
//! derivative per transposed product.

use fshape_fem::{SignalNorm, Solver};
use fshape_kernels::{Kernel, KernelSums};

use crate::ShootError;

/// Index ranges of the flat state.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    /// P·n.
    pub(crate) pn: usize,
    /// P.
    pub(crate) p: usize,
    /// n.
    pub(crate) dim: usize,
}

impl Layout {
    pub(crate) fn len(&self) -> usize {
        2 * self.pn + 2 * self.p
    }
    pub(crate) fn x(&self) -> std::ops::Range<usize> {
        0..self.pn
    }
    pub(crate) fn f(&self) -> std::ops::Range<usize> {
        self.pn..self.pn + self.p
    }
    pub(crate) fn mom(&self) -> std::ops::Range<usize> {
        self.pn + self.p..2 * self.pn + self.p
    }
    pub(crate) fn pf(&self) -> std::ops::Range<usize> {
        2 * self.pn + self.p..self.len()
    }
    /// 𝕁 v.
    pub(crate) fn symplectic(&self, v: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.len()];
        out[self.x()].copy_from_slice(&v[self.mom()]);
        out[self.f()].copy_from_slice(&v[self.pf()]);
        for (o, a) in out[self.mom()].iter_mut().zip(&v[self.x()]) {
            *o = -a;
        }
        for (o, a) in out[self.pf()].iter_mut().zip(&v[self.f()]) {
            *o = -a;
        }
        out
    }
}

/// The vector field of one model: the deformation kernel, the weights and,
/// when the signal evolves, the signal norm.
pub(crate) struct Dynamics<'a> {
    pub(crate) kernel: &'a Kernel,
    /// `Some` when the signal evolves (metamorphosis).
    pub(crate) fem: Option<&'a SignalNorm>,
    pub(crate) gamma_v: f64,
    pub(crate) gamma_f: f64,
    pub(crate) layout: Layout,
}

/// Time spent in each part of the computation (seconds).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Timings {
    /// Kernel sums (deformation).
    pub kernels: f64,
    /// FEM assembly, factorisation, solves and x-derivatives.
    pub fem: f64,
    /// The data attachment and its gradient.
    pub attachment: f64,
}

fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = std::time::Instant::now();
    let out = f();
    *acc += t.elapsed().as_secs_f64();
    out
}

impl Dynamics<'_> {
    /// F(z), and h = D⁻¹p^f (empty without signal dynamics). `solver` is
    /// refactored at z's x.
    pub(crate) fn field(
        &self,
        z: &[f64],
        solver: &mut Option<Solver<'_>>,
        t: &mut Timings,
    ) -> Result<(Vec<f64>, Vec<f64>), ShootError> {
        let l = self.layout;
        let (x, p) = (&z[l.x()], &z[l.mom()]);
        let mut out = vec![0.0; l.len()];
        let (kp, gk) = timed(&mut t.kernels, || -> Result<_, ShootError> {
            let sums = KernelSums::try_new(self.kernel, x, l.dim)?;
            Ok(sums.conv_and_grad(x, p, p, l.dim)?)
        })?;
        for (o, v) in out[l.x()].iter_mut().zip(&kp) {
            *o = v / self.gamma_v;
        }
        // ∂_x(pᵀKp) = 2·grad_cross (the self term counts each pair twice).
        for (o, v) in out[l.mom()].iter_mut().zip(&gk) {
            *o = -v / self.gamma_v;
        }
        let mut h = Vec::new();
        if let (Some(fem), Some(solver)) = (self.fem, solver.as_mut()) {
            timed(&mut t.fem, || -> Result<(), ShootError> {
                solver.factor(x)?;
                h = solver.solve(&z[l.pf()])?;
                let gd = fem.grad(x, &h, &h)?;
                for (o, v) in out[l.mom()].iter_mut().zip(&gd) {
                    *o += v / (2.0 * self.gamma_f);
                }
                Ok(())
            })?;
            for (o, v) in out[l.f()].iter_mut().zip(&h) {
                *o = v / self.gamma_f;
            }
        }
        Ok((out, h))
    }

    /// dF(z)·w, exact. `solver` must be factored at z's x and `h` be
    /// D⁻¹p^f there (both as left by [`Dynamics::field`]).
    pub(crate) fn jvp(
        &self,
        z: &[f64],
        h: &[f64],
        w: &[f64],
        solver: &mut Option<Solver<'_>>,
        t: &mut Timings,
    ) -> Result<Vec<f64>, ShootError> {
        let l = self.layout;
        let (x, p) = (&z[l.x()], &z[l.mom()]);
        let (dx, dp) = (&w[l.x()], &w[l.mom()]);
        let mut out = vec![0.0; l.len()];
        let (dkp, dgk) = timed(&mut t.kernels, || -> Result<_, ShootError> {
            let sums = KernelSums::try_new(self.kernel, x, l.dim)?;
            Ok(sums.conv_and_grad_jvp(x, dx, dx, p, dp, p, dp, l.dim)?)
        })?;
        for (o, v) in out[l.x()].iter_mut().zip(&dkp) {
            *o = v / self.gamma_v;
        }
        for (o, v) in out[l.mom()].iter_mut().zip(&dgk) {
            *o = -v / self.gamma_v;
        }
        if let (Some(fem), Some(solver)) = (self.fem, solver.as_mut()) {
            let dh = timed(&mut t.fem, || -> Result<Vec<f64>, ShootError> {
                // δh = D⁻¹(δp^f − (∂D·δx) h).
                let dd = fem.dmatvec(x, dx, h)?;
                let rhs: Vec<f64> = w[l.pf()].iter().zip(&dd).map(|(a, b)| a - b).collect();
                let dh = solver.solve(&rhs)?;
                // δ[∂_x(hᵀDh)] = ∂²_x(hᵀDh)·δx + 2 ∂_x(δhᵀ D h).
                let hv = fem.hvp(x, h, h, dx)?;
                let g = fem.grad(x, &dh, h)?;
                for ((o, a), b) in out[l.mom()].iter_mut().zip(&hv).zip(&g) {
                    *o += (a + 2.0 * b) / (2.0 * self.gamma_f);
                }
                Ok(dh)
            })?;
            for (o, v) in out[l.f()].iter_mut().zip(&dh) {
                *o = v / self.gamma_f;
            }
        }
        Ok(out)
    }

    /// dF(z)ᵀ·v = 𝕁 dF(z)(𝕁 v).
    pub(crate) fn vjp(
        &self,
        z: &[f64],
        h: &[f64],
        v: &[f64],
        solver: &mut Option<Solver<'_>>,
        t: &mut Timings,
    ) -> Result<Vec<f64>, ShootError> {
        let l = self.layout;
        let jv = self.jvp(z, h, &l.symplectic(v), solver, t)?;
        Ok(l.symplectic(&jv))
    }
}
