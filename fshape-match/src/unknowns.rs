//! The unknowns of matching and their metrics: how (p_0, p^f) are packed
//! into the optimiser's vector and in which metric it steps.
//!
//! The optimiser sees one flat vector of unknowns: p_0 (P × n), then, when
//! the signal has a control (metamorphosis: p^f; tangential: ζ), P more
//! values. A metric on a block is a change of variables with the lumped
//! mass D_0 = diag(m) of the template, so that a Euclidean step in the new
//! unknowns q is a gradient step in that metric, and L-BFGS and its line
//! search work in one consistent metric. Which change depends on what the
//! block is:
//!
//! - **p^f and p_0 are momenta: densities** (covectors). They pair with
//!   nodal values by the plain sum (⟨p^f, δf⟩ = Σ p^f_i δf_i), so
//!   p^f_i ≈ ρ(x_i) m_i for a density ρ, and ∂J/∂p^f_i behaves like a
//!   function's values. The L² metric of densities is
//!   ‖ρ‖² = Σ ρ_i² m_i = p^fᵀ D_0⁻¹ p^f, whose gradient is D_0 ∂J/∂p^f:
//!   the paper's step (4), which makes the signal velocity
//!   ḟ = D_s⁻¹ p^f/γ_f of a step the same function whatever the mesh. As a
//!   change of variables: p^f = D_0^{1/2} q.
//! - **ζ (tangential model) is a function** on the template: its L² metric
//!   is ζᵀ D_0 ζ, the gradient D_0⁻¹ ∂J/∂ζ, the change ζ = D_0^{−1/2} q.
//!
//! `Metric::Euclidean` keeps the plain vertex values. (Until this version
//! the momenta took the function's change, D_0^{−1/2}, which made a step's
//! signal velocity scale like 1/m²: `tests/matching/objective.rs` tells the
//! two apart on a graded mesh.)

use fshape_fem::{Norm, SignalNorm};
use fshape_shoot::{ModelKind, Problem, ShootError};

use crate::precondition::{MomentumMetric, NormMatrix};

/// The metric in which one block of unknowns is optimised (configuration
/// spellings `l2`, `euclidean`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Metric {
    /// L²(x_0) with the lumped mass of the template (the paper's, for p^f).
    /// (The capitalised names are how summaries before 2026-12 wrote them.)
    #[serde(alias = "L2")]
    L2,
    /// The Euclidean metric of the vertex values.
    #[serde(alias = "Euclidean")]
    Euclidean,
    /// The metric of the geodesic's energy ([`crate::precondition`]), as
    /// L-BFGS's initial Hessian: ⟨δp, K(x_0) δp⟩ on p_0 (the V-norm of the
    /// velocity), ⟨δp^f, D_s(x_0)⁻¹ δp^f⟩ on p^f (the signal norm of the
    /// signal velocity; metamorphosis only).
    #[serde(alias = "Energy")]
    Energy,
}

/// The metrics of the two blocks of unknowns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Metrics {
    /// Of p_0 (default the energy's: fewer iterations to the same fit,
    /// docs/guide/src/experiments.md).
    pub momentum: Metric,
    /// Of p^f or ζ (default L², the paper's).
    pub signal: Metric,
}

impl Default for Metrics {
    fn default() -> Self {
        Metrics { momentum: Metric::Energy, signal: Metric::L2 }
    }
}

impl From<Metric> for Metrics {
    /// `signal` for p^f, the default (energy) for p_0.
    fn from(signal: Metric) -> Self {
        Metrics { signal, ..Metrics::default() }
    }
}

/// The packing of (p_0, p^f) into the optimiser's unknowns.
#[derive(Clone, Debug)]
pub struct Unknowns {
    /// The energy metric of p_0: the kernel matrix's factor, or its
    /// two-level approximation on larger templates.
    factor: Option<std::sync::Arc<MomentumMetric>>,
    /// The energy metric of p^f: the signal norm's matrix.
    signal_matrix: Option<std::sync::Arc<NormMatrix>>,
    /// P·n and P·k (k signal channels).
    pn: usize,
    p: usize,
    /// p^f = scale ⊙ q (empty: no signal control, LDDMM).
    scale: Vec<f64>,
    /// p_0 = scale_p ⊙ q_0 (P·n values).
    scale_p: Vec<f64>,
}

impl Unknowns {
    /// The packing for `problem` with its blocks in `metrics` (a
    /// [`Metric`] alone sets the signal block's).
    pub fn new(problem: &Problem, metrics: impl Into<Metrics>) -> Result<Unknowns, crate::MatchError> {
        Unknowns::scaled(problem, metrics, None)
    }

    /// The packing of a problem whose weights were normalised by `scales`
    /// ([`crate::Scales`]): the unknowns are then those of the shapes
    /// rescaled to diagonal 1 and signal deviation 1 (p_0 times L, p^f
    /// times S, ζ divided by S, and the metric's L^{d/2} for the mass), so
    /// that the optimiser takes the same steps at any scale of the data.
    pub fn scaled(
        problem: &Problem,
        metrics: impl Into<Metrics>,
        scales: Option<&crate::Scales>,
    ) -> Result<Unknowns, crate::MatchError> {
        let metrics = metrics.into();
        let mut unknowns = Unknowns::for_template(problem.template(), problem.model().kind(), metrics, scales)?;
        if metrics.momentum == Metric::Energy {
            let t = problem.template();
            unknowns.factor = MomentumMetric::new(t, problem.model().kernel())?.map(std::sync::Arc::new);
        }
        if metrics.signal == Metric::Energy && problem.model().kind() == ModelKind::Metamorphosis {
            let t = problem.template();
            let matrix = NormMatrix::new(t, problem.model().norm(), unknowns.pn)?;
            unknowns.signal_matrix = Some(std::sync::Arc::new(matrix));
        }
        Ok(unknowns)
    }

    /// Whether p_0 is in the energy metric (`Metric::Energy` and a kernel
    /// matrix whose factor exists).
    pub fn kernel_metric(&self) -> bool {
        self.factor.is_some()
    }

    /// [`Unknowns::scaled`] from the template and the model kind alone.
    pub fn for_template(
        t: &fshape_mesh::FShape,
        kind: ModelKind,
        metrics: impl Into<Metrics>,
        scales: Option<&crate::Scales>,
    ) -> Result<Unknowns, ShootError> {
        let metrics = metrics.into();
        let (p, pn, dim) = (t.n_vertices(), t.n_vertices() * t.dim(), t.dim());
        // Every channel of a vertex shares its scale (p^f is vertex by vertex).
        let k = t.n_channels().max(1);
        let per_channel = |v: Vec<f64>| -> Vec<f64> {
            if k == 1 { v } else { v.iter().flat_map(|s| std::iter::repeat_n(*s, k)).collect() }
        };
        // √m per vertex for densities, 1/√m for functions.
        let mass_scale = |density: bool| -> Result<Vec<f64>, ShootError> {
            let masses = SignalNorm::try_new(t, Norm::L2Lumped)?.assemble(t.points())?;
            if let Some(v) = masses.iter().position(|m| m.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)) {
                return Err(fshape_fem::FemError::Singular { vertex: v }.into());
            }
            Ok(masses.iter().map(|m| if density { m.sqrt() } else { 1.0 / m.sqrt() }).collect())
        };
        let mut scale = match (kind, metrics.signal) {
            (ModelKind::Lddmm, _) => Vec::new(),
            (_, Metric::Euclidean | Metric::Energy) => vec![1.0; p * k],
            (ModelKind::Metamorphosis, Metric::L2) => per_channel(mass_scale(true)?),
            (ModelKind::Tangential, Metric::L2) => per_channel(mass_scale(false)?),
        };
        let mut scale_p = match metrics.momentum {
            Metric::Euclidean | Metric::Energy => vec![1.0; pn],
            Metric::L2 => mass_scale(true)?.iter().flat_map(|s| std::iter::repeat_n(*s, dim)).collect(),
        };
        if let Some(sc) = scales {
            // In the rescaled data: p_0' = L p_0, p^f' = S p^f, ζ' = ζ/S,
            // and the mass m' = m / L^d in the L² metrics.
            let half_d = sc.length.powf(0.5 * sc.cell_dim as f64);
            let l2 = |m: Metric| if m == Metric::L2 { half_d } else { 1.0 };
            let c0 = 1.0 / (sc.length * l2(metrics.momentum));
            // S_c of each channel (channel c's unknowns are c, c + k, …).
            let cf: Vec<f64> = (0..k)
                .map(|c| match kind {
                    ModelKind::Tangential => sc.channel(c) * l2(metrics.signal),
                    _ => 1.0 / (sc.channel(c) * l2(metrics.signal)),
                })
                .collect();
            scale_p.iter_mut().for_each(|v| *v *= c0);
            scale.iter_mut().zip(cf.iter().cycle()).for_each(|(v, c)| *v *= c);
        }
        Ok(Unknowns { factor: None, signal_matrix: None, pn, p: p * k, scale, scale_p })
    }

    /// Number of unknowns.
    pub fn len(&self) -> usize {
        self.pn + self.scale.len()
    }

    /// Whether there are none (an empty template).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The unknowns of (p_0, p^f).
    pub fn pack(&self, p0: &[f64], pf: &[f64]) -> Vec<f64> {
        let mut x: Vec<f64> = p0.iter().zip(&self.scale_p).map(|(v, s)| v / s).collect();
        x.extend(pf.iter().zip(&self.scale).map(|(v, s)| v / s));
        x
    }

    /// (p_0, p^f) of the unknowns (p^f all 0 without a signal control).
    ///
    /// # Panics
    ///
    /// If `x` does not have [`Unknowns::len`] values (a checkpoint is
    /// checked for this before its values reach here).
    #[track_caller]
    pub fn unpack(&self, x: &[f64]) -> (Vec<f64>, Vec<f64>) {
        assert_eq!(x.len(), self.len(), "unknowns of another problem");
        let p0 = x[..self.pn].iter().zip(&self.scale_p).map(|(q, s)| q * s).collect();
        let pf = if self.scale.is_empty() {
            vec![0.0; self.p]
        } else {
            x[self.pn..].iter().zip(&self.scale).map(|(q, s)| q * s).collect()
        };
        (p0, pf)
    }
}

impl Unknowns {
    /// The gradient in the unknowns of a gradient in (p_0, p^f).
    pub fn pack_grad(&self, g_p0: &[f64], g_pf: &[f64]) -> Vec<f64> {
        let mut grad: Vec<f64> = g_p0.iter().zip(&self.scale_p).map(|(v, s)| v * s).collect();
        grad.extend(g_pf.iter().zip(&self.scale).map(|(v, s)| v * s));
        grad
    }

    /// Where the signal's block starts (after p_0), when there is one:
    /// [`crate::optimize::Objective::blocks`].
    pub fn blocks(&self) -> Vec<usize> {
        if self.scale.is_empty() { Vec::new() } else { vec![self.pn] }
    }

    /// Applies the initial Hessian's shape of the energy metrics (if any)
    /// to `v`, one problem's unknowns.
    pub(crate) fn precondition(&self, v: &mut [f64]) {
        if let Some(f) = &self.factor {
            f.apply(v);
        }
        if let Some(m) = &self.signal_matrix {
            m.apply(v);
        }
    }
}
