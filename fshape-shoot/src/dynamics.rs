//! The Hamiltonian vector field F(z) of the reduced metamorphosis
//! Hamiltonian (DESIGN.md "The discrete model") and its exact directional
//! and transposed derivatives.
//!
//! State z = (x, f, p, p^f), flat: [x (P·n) | f (P·k) | p (P·n) | p^f (P·k)],
//! with k signal channels stored vertex by vertex (f[v·k + c], as
//! [`fshape_mesh::FShape`] holds them).
//!
//! - ẋ = K_{x,x} p / γ_V
//! - ḟ_c = h_c / γ_c, h_c = D_s(x)⁻¹ p^f_c for each channel c
//! - ṗ = −∂_x(pᵀK p)/(2γ_V) + Σ_c ∂_x(h_cᵀD_s(x)h_c)|_h/(2γ_c)
//! - ṗ^f = 0
//!
//! where γ_c = γ_f w_c, a channel's weight w_c scaling its signal norm
//! (w_c = 1 by default). Every channel shares D_s(x) and its one
//! factorisation per evaluation.
//!
//! With signal dynamics off (LDDMM, and the geometry of the tangential
//! model) ḟ = 0 and the p^f terms vanish. F = 𝕁∇H with 𝕁(a_x, a_f, a_p,
//! a_pf) = (a_p, a_pf, −a_x, −a_f), so dFᵀv = 𝕁 dF(𝕁v): one directional
//! derivative per transposed product.

use fshape_fem::{SignalNorm, Solver, Workspace};
use fshape_kernels::{Kernel, KernelSums, SumWorkspace};

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
    /// k, the signal channels.
    pub(crate) nf: usize,
}

impl Layout {
    /// P·k, the length of the f and p^f blocks.
    pub(crate) fn pk(&self) -> usize {
        self.p * self.nf
    }
    pub(crate) fn len(&self) -> usize {
        2 * self.pn + 2 * self.pk()
    }
    pub(crate) fn x(&self) -> std::ops::Range<usize> {
        0..self.pn
    }
    pub(crate) fn f(&self) -> std::ops::Range<usize> {
        self.pn..self.pn + self.pk()
    }
    pub(crate) fn mom(&self) -> std::ops::Range<usize> {
        self.pn + self.pk()..2 * self.pn + self.pk()
    }
    pub(crate) fn pf(&self) -> std::ops::Range<usize> {
        2 * self.pn + self.pk()..self.len()
    }
    /// out = 𝕁 v.
    pub(crate) fn symplectic(&self, v: &[f64], out: &mut [f64]) {
        out[self.x()].copy_from_slice(&v[self.mom()]);
        out[self.f()].copy_from_slice(&v[self.pf()]);
        for (o, a) in out[self.mom()].iter_mut().zip(&v[self.x()]) {
            *o = -a;
        }
        for (o, a) in out[self.pf()].iter_mut().zip(&v[self.f()]) {
            *o = -a;
        }
    }
}

/// The vector field of one model: the deformation kernel, the weights and,
/// when the signal evolves, the signal norm.
pub(crate) struct Dynamics<'a> {
    pub(crate) kernel: &'a Kernel,
    /// `Some` when the signal evolves (metamorphosis).
    pub(crate) fem: Option<&'a SignalNorm>,
    pub(crate) gamma_v: f64,
    /// γ_c = γ_f w_c, one per signal channel.
    pub(crate) gamma_f: &'a [f64],
    pub(crate) layout: Layout,
    /// Kernel sums in parallel (the FEM norm carries its own setting).
    pub(crate) parallel: bool,
}

/// Time spent in each part of the computation (seconds).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Timings {
    /// Kernel sums (deformation).
    pub kernels: f64,
    /// FEM assembly, factorisation, solves and x-derivatives. In parallel
    /// runs of the metamorphosis model they run while the kernel sums do,
    /// so the two times overlap (their sum exceeds the wall time).
    pub fem: f64,
    /// The data attachment and its gradient.
    pub attachment: f64,
}

/// Runs `f`, adding its wall time to `acc` (seconds).
pub(crate) fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = std::time::Instant::now();
    let out = f();
    *acc += t.elapsed().as_secs_f64();
    out
}

/// The memory one shooting (or adjoint) pass reuses at every evaluation
/// of the field: the kernel and FEM workspaces, the factorisation, and the
/// intermediate vectors. Sized on first use; after that the time-stepping
/// loops allocate nothing (tested with a counting allocator).
pub(crate) struct Scratch<'s> {
    kern: KernelScratch,
    fem: FemScratch<'s>,
    /// The state length: 𝕁v and dF(𝕁v).
    jv: Vec<f64>,
    jw: Vec<f64>,
}

/// The kernel sums' part of [`Scratch`] (apart from the FEM's, so that the
/// two parts of the field can run at the same time).
struct KernelScratch {
    sums: SumWorkspace,
    /// P·n: K p and ∂_x(pᵀKp) (or their JVPs).
    kp: Vec<f64>,
    gk: Vec<f64>,
}

/// The FEM's part of [`Scratch`].
struct FemScratch<'s> {
    ws: Workspace,
    solver: Option<Solver<'s>>,
    /// P·n: the FEM x-derivatives.
    gd: Vec<f64>,
    hv: Vec<f64>,
    /// P (P·k with several channels): (∂D·δx)h, then δh.
    dd: Vec<f64>,
    /// With several channels: one channel of h and of δh (P), and one
    /// channel's x-derivatives (P·n) before they are summed.
    hc: Vec<f64>,
    dc: Vec<f64>,
    gc: Vec<f64>,
    vc: Vec<f64>,
}

impl<'s> Scratch<'s> {
    pub(crate) fn new(layout: Layout, fem: Option<&'s SignalNorm>) -> Result<Self, ShootError> {
        let (pn, p, len) = (layout.pn, layout.p, layout.len());
        Ok(Scratch {
            kern: KernelScratch { sums: SumWorkspace::default(), kp: vec![0.0; pn], gk: vec![0.0; pn] },
            fem: FemScratch {
                ws: Workspace::default(),
                solver: match fem {
                    Some(fem) => Some(fem.solver()?),
                    None => None,
                },
                gd: vec![0.0; pn],
                hv: vec![0.0; pn],
                dd: vec![0.0; layout.pk()],
                hc: vec![0.0; if layout.nf > 1 { p } else { 0 }],
                dc: vec![0.0; if layout.nf > 1 { p } else { 0 }],
                gc: vec![0.0; if layout.nf > 1 { pn } else { 0 }],
                vc: vec![0.0; if layout.nf > 1 { pn } else { 0 }],
            },
            jv: vec![0.0; len],
            jw: vec![0.0; len],
        })
    }
}

impl FemScratch<'_> {
    /// Refactors D at `x` and solves D h_c = pf_c into `h` for each of the
    /// `nf` channels (stored vertex by vertex).
    fn solve_at(&mut self, x: &[f64], pf: &[f64], h: &mut [f64], nf: usize) -> Result<(), ShootError> {
        if let Some(solver) = self.solver.as_mut() {
            solver.factor(x)?;
            if nf == 1 {
                h.copy_from_slice(pf);
                solver.solve_in_place(h)?;
            } else {
                for c in 0..nf {
                    gather(pf, c, nf, &mut self.hc);
                    solver.solve_in_place(&mut self.hc)?;
                    scatter(&self.hc, c, nf, h);
                }
            }
        }
        Ok(())
    }
}

/// out = channel `c` of the vertex-by-vertex `v` of `nf` channels.
fn gather(v: &[f64], c: usize, nf: usize, out: &mut [f64]) {
    for (o, a) in out.iter_mut().zip(v.iter().skip(c).step_by(nf)) {
        *o = *a;
    }
}

/// Channel `c` of the vertex-by-vertex `v` of `nf` channels = `a`.
fn scatter(a: &[f64], c: usize, nf: usize, v: &mut [f64]) {
    for (o, a) in v.iter_mut().skip(c).step_by(nf).zip(a) {
        *o = *a;
    }
}

/// Runs the kernel part and the FEM part of one field evaluation, at the
/// same time when `together` (the FEM's factorisation and solves are
/// serial: on two threads the kernel sums' chunks fill the other one).
/// Each part writes only its own scratch, so the results are the same bits
/// either way. The timings are each part's wall time, so with `together`
/// they overlap.
fn both<A: Send, B: Send>(together: bool, a: impl FnOnce() -> A + Send, b: impl FnOnce() -> B + Send) -> (A, B) {
    if together { rayon::join(a, b) } else { (a(), b()) }
}

impl Dynamics<'_> {
    /// Runs `kernel` (the kernel sums at x, into the kernel scratch) and
    /// `signal` (the FEM part, when the signal evolves), at the same time in
    /// parallel runs (see [`both`]). Returns whether the FEM part ran.
    fn run_parts<'s>(
        &self,
        x: &[f64],
        s: &mut Scratch<'s>,
        t: &mut Timings,
        kernel: impl FnOnce(&KernelSums<'_>, &mut KernelScratch) -> Result<(), ShootError> + Send,
        signal: impl FnOnce(&SignalNorm, &mut FemScratch<'s>) -> Result<(), ShootError> + Send,
    ) -> Result<bool, ShootError> {
        let (kern, fs) = (&mut s.kern, &mut s.fem);
        let (t_kernels, t_fem) = (&mut t.kernels, &mut t.fem);
        let norm = self.fem.filter(|_| fs.solver.is_some());
        let (kernels, fem) = both(
            self.parallel && norm.is_some(),
            || {
                timed(t_kernels, || -> Result<(), ShootError> {
                    let sums = KernelSums::try_new(self.kernel, x, self.layout.dim)?.with_parallel(self.parallel);
                    kernel(&sums, kern)
                })
            },
            || match norm {
                Some(fem) => timed(t_fem, || signal(fem, fs)),
                None => Ok(()),
            },
        );
        kernels?;
        fem?;
        Ok(norm.is_some())
    }

    /// The kernel's rates from its sums in `k` (K p and ∂_x(pᵀKp), or their
    /// directional derivatives): ẋ = K p / γ_V, ṗ = −∂_x(pᵀKp)/(2γ_V) (the
    /// self sum counts each pair twice, so it is 2·grad_cross), and
    /// ṗ^f = 0, into `out`.
    fn kernel_rates(&self, k: &KernelScratch, out: &mut [f64]) {
        let l = self.layout;
        for (o, v) in out[l.x()].iter_mut().zip(&k.kp) {
            *o = v / self.gamma_v;
        }
        for (o, v) in out[l.mom()].iter_mut().zip(&k.gk) {
            *o = -v / self.gamma_v;
        }
        out[l.pf()].fill(0.0);
    }

    /// out = F(z), and h = D⁻¹p^f (untouched without signal dynamics). The
    /// solver in `s` is refactored at z's x.
    pub(crate) fn field(
        &self,
        z: &[f64],
        h: &mut [f64],
        out: &mut [f64],
        s: &mut Scratch<'_>,
        t: &mut Timings,
    ) -> Result<(), ShootError> {
        let l = self.layout;
        let (x, p, pf) = (&z[l.x()], &z[l.mom()], &z[l.pf()]);
        let signal = self.run_parts(
            x,
            s,
            t,
            // Each pair once where the kernel allows it (sums of Gaussians).
            |sums, k| Ok(sums.self_conv_and_grad_into(&mut k.sums, p, l.dim, &mut k.kp, &mut k.gk)?),
            |fem, fs| {
                fs.solve_at(x, pf, h, l.nf)?;
                if l.nf == 1 {
                    return Ok(fem.grad_into(x, h, h, &mut fs.ws, &mut fs.gd)?);
                }
                // Σ_c ∂_x(h_cᵀDh_c)/γ_c, brought to 1/γ_0's scale below.
                fs.gd.fill(0.0);
                for c in 0..l.nf {
                    gather(h, c, l.nf, &mut fs.hc);
                    fem.grad_into(x, &fs.hc, &fs.hc, &mut fs.ws, &mut fs.gc)?;
                    let w = self.gamma_f[0] / self.gamma_f[c];
                    for (o, v) in fs.gd.iter_mut().zip(&fs.gc) {
                        *o += w * v;
                    }
                }
                Ok(())
            },
        )?;
        self.kernel_rates(&s.kern, out);
        if signal {
            let g0 = self.gamma_f[0];
            for (o, v) in out[l.mom()].iter_mut().zip(&s.fem.gd) {
                *o += v / (2.0 * g0);
            }
            for (i, (o, v)) in out[l.f()].iter_mut().zip(h.iter()).enumerate() {
                *o = v / self.gamma_f[i % l.nf];
            }
        } else {
            out[l.f()].fill(0.0);
        }
        Ok(())
    }

    /// out = dF(z)·w, exact. The solver in `s` is refactored at z's x and
    /// h set to D⁻¹p^f there ([`FemScratch::solve_at`]), as the adjoint
    /// visits the stages in reverse.
    pub(crate) fn jvp(
        &self,
        z: &[f64],
        h: &mut [f64],
        w: &[f64],
        out: &mut [f64],
        s: &mut Scratch<'_>,
        t: &mut Timings,
    ) -> Result<(), ShootError> {
        let l = self.layout;
        let (x, p, pf) = (&z[l.x()], &z[l.mom()], &z[l.pf()]);
        let (dx, dp) = (&w[l.x()], &w[l.mom()]);
        let signal = self.run_parts(
            x,
            s,
            t,
            |sums, k| Ok(sums.self_conv_and_grad_jvp_into(&mut k.sums, dx, p, dp, l.dim, &mut k.kp, &mut k.gk)?),
            |fem, fs| {
                fs.solve_at(x, pf, h, l.nf)?;
                if fs.solver.is_none() {
                    return Ok(());
                }
                if l.nf == 1 {
                    let solver = fs.solver.as_mut().expect("checked");
                    // δh = D⁻¹(δp^f − (∂D·δx) h).
                    fem.dmatvec_into(x, dx, h, &mut fs.ws, &mut fs.dd)?;
                    for (d, a) in fs.dd.iter_mut().zip(&w[l.pf()]) {
                        *d = a - *d;
                    }
                    solver.solve_in_place(&mut fs.dd)?;
                    // δ[∂_x(hᵀDh)] = ∂²_x(hᵀDh)·δx + 2 ∂_x(δhᵀ D h).
                    fem.hvp_into(x, h, h, dx, &mut fs.ws, &mut fs.hv)?;
                    return Ok(fem.grad_into(x, &fs.dd, h, &mut fs.ws, &mut fs.gd)?);
                }
                // The same per channel, the x-derivatives summed with
                // weights γ_0/γ_c (brought to 1/γ_0's scale below).
                fs.hv.fill(0.0);
                fs.gd.fill(0.0);
                for c in 0..l.nf {
                    gather(h, c, l.nf, &mut fs.hc);
                    fem.dmatvec_into(x, dx, &fs.hc, &mut fs.ws, &mut fs.dc)?;
                    for (d, a) in fs.dc.iter_mut().zip(w[l.pf()].iter().skip(c).step_by(l.nf)) {
                        *d = a - *d;
                    }
                    fs.solver.as_mut().expect("checked").solve_in_place(&mut fs.dc)?;
                    scatter(&fs.dc, c, l.nf, &mut fs.dd);
                    let wc = self.gamma_f[0] / self.gamma_f[c];
                    fem.hvp_into(x, &fs.hc, &fs.hc, dx, &mut fs.ws, &mut fs.vc)?;
                    for (o, v) in fs.hv.iter_mut().zip(&fs.vc) {
                        *o += wc * v;
                    }
                    fem.grad_into(x, &fs.dc, &fs.hc, &mut fs.ws, &mut fs.gc)?;
                    for (o, v) in fs.gd.iter_mut().zip(&fs.gc) {
                        *o += wc * v;
                    }
                }
                Ok(())
            },
        )?;
        self.kernel_rates(&s.kern, out);
        if signal {
            let g0 = self.gamma_f[0];
            for ((o, a), b) in out[l.mom()].iter_mut().zip(&s.fem.hv).zip(&s.fem.gd) {
                *o += (a + 2.0 * b) / (2.0 * g0);
            }
            for (i, (o, v)) in out[l.f()].iter_mut().zip(&s.fem.dd).enumerate() {
                *o = v / self.gamma_f[i % l.nf];
            }
        } else {
            out[l.f()].fill(0.0);
        }
        Ok(())
    }

    /// out = dF(z)ᵀ·v = 𝕁 dF(z)(𝕁 v) (`h`: as for [`Dynamics::jvp`]).
    pub(crate) fn vjp(
        &self,
        z: &[f64],
        h: &mut [f64],
        v: &[f64],
        out: &mut [f64],
        s: &mut Scratch<'_>,
        t: &mut Timings,
    ) -> Result<(), ShootError> {
        let l = self.layout;
        // Moved out of `s` for the call (no allocation) and back.
        let (mut jv, mut jw) = (std::mem::take(&mut s.jv), std::mem::take(&mut s.jw));
        l.symplectic(v, &mut jv);
        let r = self.jvp(z, h, &jv, &mut jw, s, t);
        l.symplectic(&jw, out);
        (s.jv, s.jw) = (jv, jw);
        r
    }
}
