//! The model: which signal dynamics, which signal norm, the weights, the
//! deformation kernel and the integrator. A [`Model`] is valid by
//! construction: every setter checks its value, and the fields are private.

use std::num::NonZeroUsize;

use fshape_fem::Norm;
use fshape_kernels::Kernel;

use crate::ShootError;

/// Which model the signal follows (configuration spellings:
/// `metamorphosis`, `tangential`, `lddmm`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    /// Metamorphosis: the signal evolves along the path, its change costed
    /// by D_s(x_t) on the moving shape.
    #[default]
    Metamorphosis,
    /// Tangential model: LDDMM geometry, signal residual on the template.
    Tangential,
    /// Pure LDDMM: the signal is carried unchanged.
    Lddmm,
}

impl ModelKind {
    /// The configuration spelling.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Metamorphosis => "metamorphosis",
            ModelKind::Tangential => "tangential",
            ModelKind::Lddmm => "lddmm",
        }
    }
}

/// Time integrator (configuration spellings: `rk4`, `midpoint`, `euler`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Integrator {
    /// Classical fourth-order Runge–Kutta (default).
    #[default]
    Rk4,
    /// Explicit midpoint (second order; fshapesTk's scheme).
    Midpoint,
    /// Forward Euler.
    Euler,
}

impl Integrator {
    /// The configuration spelling.
    pub fn name(self) -> &'static str {
        match self {
            Integrator::Rk4 => "rk4",
            Integrator::Midpoint => "midpoint",
            Integrator::Euler => "euler",
        }
    }
}

/// A validated model. Built with [`Model::new`] and the `with_*` setters,
/// each of which refuses a value no computation can use (a weight that is
/// not positive and finite, zero time steps, an H¹ length that is not
/// positive), so a `Model` always describes a shooting that can run.
///
/// ```
/// use fshape_fem::Norm;
/// use fshape_kernels::Kernel;
/// use fshape_shoot::{Integrator, Model, ModelKind};
/// let m = Model::new(Kernel::gaussian(0.2)?)
///     .with_kind(ModelKind::Tangential)
///     .with_norm(Norm::H1 { length: 0.5 })?
///     .with_weights(1.0, 0.1, 100.0)?
///     .with_integrator(Integrator::Midpoint, 20)?;
/// assert_eq!((m.steps(), m.gamma_w()), (20, 100.0));
/// assert!(Model::new(Kernel::gaussian(0.2)?).with_integrator(Integrator::Rk4, 0).is_err());
/// assert!(Model::new(Kernel::gaussian(0.2)?).with_weights(1.0, f64::NAN, 1.0).is_err());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct Model {
    kind: ModelKind,
    norm: Norm,
    gamma_v: f64,
    gamma_f: f64,
    /// w_c per signal channel (empty: 1 for every channel).
    channel_weights: Vec<f64>,
    gamma_w: f64,
    kernel: Kernel,
    integrator: Integrator,
    steps: NonZeroUsize,
    max_drift: f64,
}

/// The default tolerance on the relative drift of the Hamiltonian.
pub const DEFAULT_MAX_DRIFT: f64 = 0.5;

fn positive(what: &'static str, v: f64) -> Result<f64, ShootError> {
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(ShootError::Invalid { what, why: format!("must be positive and finite, got {v}") })
    }
}

impl Model {
    /// Metamorphosis with the lumped L² norm, γ_V = γ_f = γ_W = 1, RK4 with
    /// 10 steps, deformation kernel `kernel` (a Gaussian or a sum of
    /// Gaussians, exact or truncated) and a Hamiltonian drift tolerance of
    /// [`DEFAULT_MAX_DRIFT`].
    pub fn new(kernel: Kernel) -> Model {
        Model {
            kind: ModelKind::Metamorphosis,
            norm: Norm::L2Lumped,
            gamma_v: 1.0,
            gamma_f: 1.0,
            channel_weights: Vec::new(),
            gamma_w: 1.0,
            kernel,
            integrator: Integrator::Rk4,
            steps: NonZeroUsize::new(10).expect("10 > 0"),
            max_drift: DEFAULT_MAX_DRIFT,
        }
    }

    /// The signal dynamics.
    pub fn with_kind(mut self, kind: ModelKind) -> Model {
        self.kind = kind;
        self
    }

    /// The signal norm D_s (an H¹ length must be positive and finite).
    pub fn with_norm(mut self, norm: Norm) -> Result<Model, ShootError> {
        if let Norm::H1 { length } = norm {
            positive("norm length", length)?;
        }
        self.norm = norm;
        Ok(self)
    }

    /// γ_V (deformation energy), γ_f (signal energy), γ_W (data term):
    /// each positive and finite.
    pub fn with_weights(mut self, gamma_v: f64, gamma_f: f64, gamma_w: f64) -> Result<Model, ShootError> {
        self.gamma_v = positive("gamma_v", gamma_v)?;
        self.gamma_f = positive("gamma_f", gamma_f)?;
        self.gamma_w = positive("gamma_w", gamma_w)?;
        Ok(self)
    }

    /// The deformation kernel.
    pub fn with_kernel(mut self, kernel: Kernel) -> Model {
        self.kernel = kernel;
        self
    }

    /// The integrator and its number of time steps on [0, 1] (at least 1).
    pub fn with_integrator(mut self, integrator: Integrator, steps: usize) -> Result<Model, ShootError> {
        self.steps = NonZeroUsize::new(steps)
            .ok_or_else(|| ShootError::Invalid { what: "steps", why: "must be at least 1, got 0".into() })?;
        self.integrator = integrator;
        Ok(self)
    }

    /// The largest relative drift max_k |H_k − H_0| / |H_0| of the
    /// Hamiltonian a shooting may show before it is reported as diverged
    /// (positive; `f64::INFINITY` turns the check off). A geodesic conserves
    /// H; an explicit integrator drifts by O(Δt^order), tiny for a
    /// well-resolved path, so a drift of order one means the integration no
    /// longer follows the geodesic.
    pub fn with_max_drift(mut self, max_drift: f64) -> Result<Model, ShootError> {
        if max_drift.is_nan() || max_drift <= 0.0 {
            return Err(ShootError::Invalid { what: "max_drift", why: format!("must be positive, got {max_drift}") });
        }
        self.max_drift = max_drift;
        Ok(self)
    }

    /// Metamorphosis, tangential or LDDMM.
    pub fn kind(&self) -> ModelKind {
        self.kind
    }

    /// The signal norm D_s.
    pub fn norm(&self) -> Norm {
        self.norm
    }

    /// γ_V.
    pub fn gamma_v(&self) -> f64 {
        self.gamma_v
    }

    /// γ_f.
    pub fn gamma_f(&self) -> f64 {
        self.gamma_f
    }

    /// A weight w_c > 0 per signal channel: channel c's signal norm is
    /// weighted by γ_f w_c (its cost of changing; a channel in other units
    /// needs its own). As many as the template has channels; empty (the
    /// default) is 1 for every channel.
    pub fn with_channel_weights(mut self, weights: Vec<f64>) -> Result<Model, ShootError> {
        for &w in &weights {
            positive("signal channel weight", w)?;
        }
        self.channel_weights = weights;
        Ok(self)
    }

    /// The weights of [`Model::with_channel_weights`] (empty: all 1).
    pub fn channel_weights(&self) -> &[f64] {
        &self.channel_weights
    }

    /// γ_W.
    pub fn gamma_w(&self) -> f64 {
        self.gamma_w
    }

    /// The deformation kernel.
    pub fn kernel(&self) -> &Kernel {
        &self.kernel
    }

    /// The time integrator.
    pub fn integrator(&self) -> Integrator {
        self.integrator
    }

    /// Number of time steps on [0, 1] (at least 1).
    pub fn steps(&self) -> usize {
        self.steps.get()
    }

    /// The Hamiltonian drift tolerance ([`Model::with_max_drift`]).
    pub fn max_drift(&self) -> f64 {
        self.max_drift
    }
}
