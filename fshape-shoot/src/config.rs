//! The TOML configuration of a model (serde), validated into a [`Model`].
//!
//! ```toml
//! [model]
//! kind = "metamorphosis"   # metamorphosis | tangential | lddmm   (default metamorphosis)
//! norm = "h1"              # l2-lumped | l2 | h1                  (default l2-lumped)
//! length = 1.0             # ℓ of the H1 norm, in mesh units      (default 1)
//! gamma_v = 1.0            # weight γ_V of the deformation energy (default 1)
//! gamma_f = 1.0            # weight γ_f of the signal energy      (default 1)
//! gamma_w = 1.0            # weight γ_W of the data attachment    (default 1)
//!
//! [deformation]
//! widths = [0.2, 0.1]      # Gaussian widths σ_i, exp(−u/(2σ²))   (required)
//! weights = [1.0, 1.0]     # one per width                        (default all 1)
//! tolerance = 1e-6         # smooth truncation τ                  (default: exact)
//!
//! [integrator]
//! scheme = "rk4"           # rk4 | midpoint | euler               (default rk4)
//! steps = 10               # time steps on [0, 1]                 (default 10)
//!
//! [attachment]
//! kernel_geom = "gaussian:0.05"     # as `fshape distance --kernel-geom` (required)
//! kernel_signal = "gaussian:0.5"    # omit for a purely geometric term
//! kernel_grass = "binet"            # (default binet)
//! tolerance = 1e-6                  # truncation of k_p (default: exact)
//!
//! [optimizer]                       # matching only; every key optional
//! method = "lbfgs"                  # lbfgs | gradient-descent          (default lbfgs)
//! memory = 10                       # L-BFGS correction pairs           (default 10)
//! block_scaling = true              # L-BFGS: own scale for p_0 and p^f (default true)
//! increase = 1.2                    # gradient descent: step growth     (default 1.2)
//! max_iterations = 200              # per schedule stage                (default 200)
//! gradient_tolerance = 1e-3         # stop at |∇J| ≤ tol·|∇J at start|  (default 1e-3)
//! decrease_tolerance = 1e-6         # stop when J fell by ≤ tol·|J|...  (default 1e-6)
//! decrease_window = 10              # ...over this many iterations      (default 10)
//! signal_metric = "l2"              # metric of p^f: l2 (L²(x_0), the paper's) | euclidean (default l2)
//! momentum_metric = "euclidean"     # metric of p_0: euclidean | l2     (default euclidean)
//!
//! [schedule]                        # coarse to fine (default: one stage, [attachment])
//! kernel_geom = ["gaussian:0.2", "gaussian:0.1", "gaussian:0.05"]
//! ```
//!
//! Unknown keys are refused by name; every value is checked before any work.

use fshape_fem::Norm;
use fshape_kernels::{Kernel, Profile};
use fshape_varifold::VarifoldKernel;
use serde::Deserialize;

use crate::matching::{Metrics, SignalMetric};
use crate::optimize::{Method, Settings};
use crate::{Integrator, Model, ModelKind, ShootError};

/// The whole file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// `[model]`.
    #[serde(default)]
    pub model: ModelSection,
    /// `[deformation]`.
    pub deformation: DeformationSection,
    /// `[integrator]`.
    #[serde(default)]
    pub integrator: IntegratorSection,
    /// `[attachment]` (needed for matching, not for shooting).
    pub attachment: Option<AttachmentSection>,
    /// `[optimizer]` (matching).
    #[serde(default)]
    pub optimizer: OptimizerSection,
    /// `[schedule]` (matching).
    pub schedule: Option<ScheduleSection>,
}

/// `[optimizer]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OptimizerSection {
    /// lbfgs | gradient-descent.
    pub method: String,
    /// L-BFGS memory.
    pub memory: usize,
    /// L-BFGS: one initial scale per block of unknowns.
    pub block_scaling: bool,
    /// Gradient descent step growth.
    pub increase: f64,
    /// Iterations per stage.
    pub max_iterations: usize,
    /// Relative gradient tolerance.
    pub gradient_tolerance: f64,
    /// Relative decrease tolerance.
    pub decrease_tolerance: f64,
    /// Window of the decrease test.
    pub decrease_window: usize,
    /// l2 | euclidean.
    pub signal_metric: String,
    /// euclidean | l2.
    pub momentum_metric: String,
}

impl Default for OptimizerSection {
    fn default() -> Self {
        let d = crate::optimize::Settings::default();
        OptimizerSection {
            method: "lbfgs".into(),
            memory: 10,
            block_scaling: d.block_scaling,
            increase: 1.2,
            max_iterations: d.max_iterations,
            gradient_tolerance: d.gradient_tolerance,
            decrease_tolerance: d.decrease_tolerance,
            decrease_window: d.decrease_window,
            signal_metric: "l2".into(),
            momentum_metric: "euclidean".into(),
        }
    }
}

/// `[schedule]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScheduleSection {
    /// The position kernel of each stage, coarse to fine.
    pub kernel_geom: Vec<String>,
}

/// `[model]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelSection {
    /// metamorphosis | tangential | lddmm.
    pub kind: String,
    /// l2-lumped | l2 | h1.
    pub norm: String,
    /// ℓ of the H1 norm.
    pub length: f64,
    /// γ_V.
    pub gamma_v: f64,
    /// γ_f.
    pub gamma_f: f64,
    /// γ_W.
    pub gamma_w: f64,
}

impl Default for ModelSection {
    fn default() -> Self {
        ModelSection {
            kind: "metamorphosis".into(),
            norm: "l2-lumped".into(),
            length: 1.0,
            gamma_v: 1.0,
            gamma_f: 1.0,
            gamma_w: 1.0,
        }
    }
}

/// `[deformation]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeformationSection {
    /// Gaussian widths.
    pub widths: Vec<f64>,
    /// Weights, one per width (default all 1).
    pub weights: Option<Vec<f64>>,
    /// Truncation tolerance (default exact).
    pub tolerance: Option<f64>,
}

/// `[integrator]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IntegratorSection {
    /// rk4 | midpoint | euler.
    pub scheme: String,
    /// Number of time steps.
    pub steps: usize,
}

impl Default for IntegratorSection {
    fn default() -> Self {
        IntegratorSection { scheme: "rk4".into(), steps: 10 }
    }
}

/// `[attachment]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttachmentSection {
    /// Position kernel, as `fshape distance --kernel-geom`.
    pub kernel_geom: String,
    /// Signal kernel (omit for a geometric term).
    pub kernel_signal: Option<String>,
    /// Direction kernel (default binet).
    #[serde(default = "binet")]
    pub kernel_grass: String,
    /// Truncation tolerance of k_p (default exact).
    pub tolerance: Option<f64>,
}

fn binet() -> String {
    "binet".into()
}

impl Config {
    /// Parses TOML text (errors name the key and the line).
    ///
    /// ```
    /// let c = fshape_shoot::Config::parse("[deformation]\nwidths = [0.2, 0.1]\n")?;
    /// let model = c.model()?;
    /// assert_eq!(model.steps, 10);
    /// assert!(fshape_shoot::Config::parse("[deformation]\nwidths = [0.2]\nwidht = 1\n").is_err());
    /// # Ok::<(), fshape_shoot::ShootError>(())
    /// ```
    pub fn parse(text: &str) -> Result<Config, ShootError> {
        toml::from_str(text).map_err(|e| ShootError::Config(e.to_string()))
    }

    /// Reads and parses a file.
    pub fn read(path: &std::path::Path) -> Result<Config, ShootError> {
        let text = std::fs::read_to_string(path).map_err(|e| ShootError::Config(format!("{}: {e}", path.display())))?;
        Config::parse(&text).map_err(|e| match e {
            ShootError::Config(m) => ShootError::Config(format!("{}: {m}", path.display())),
            other => other,
        })
    }

    /// The validated model.
    pub fn model(&self) -> Result<Model, ShootError> {
        let bad = |key: &str, why: String| ShootError::Config(format!("{key}: {why}"));
        let m = &self.model;
        let kind = match m.kind.as_str() {
            "metamorphosis" => ModelKind::Metamorphosis,
            "tangential" => ModelKind::Tangential,
            "lddmm" => ModelKind::Lddmm,
            other => return Err(bad("model.kind", format!("`{other}` (expected metamorphosis, tangential or lddmm)"))),
        };
        for (key, v) in [("model.gamma_v", m.gamma_v), ("model.gamma_f", m.gamma_f), ("model.gamma_w", m.gamma_w)] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(bad(key, format!("must be positive and finite, got {v}")));
            }
        }
        let norm = Norm::parse(&m.norm, m.length).map_err(|e| bad("model.norm", e.to_string()))?;
        if let Norm::H1 { length } = norm
            && !(length > 0.0 && length.is_finite())
        {
            return Err(bad("model.length", format!("must be positive and finite, got {length}")));
        }
        let d = &self.deformation;
        let weights = d.weights.clone().unwrap_or_else(|| vec![1.0; d.widths.len()]);
        let profile = Profile::Gaussians { sigmas: d.widths.clone(), weights };
        let mut kernel = Kernel::try_new(&profile).map_err(|e| bad("deformation", e.to_string()))?;
        if let Some(tol) = d.tolerance {
            kernel = kernel.truncated(tol).map_err(|e| bad("deformation.tolerance", e.to_string()))?;
        }
        let integrator = match self.integrator.scheme.as_str() {
            "rk4" => Integrator::Rk4,
            "midpoint" => Integrator::Midpoint,
            "euler" => Integrator::Euler,
            other => return Err(bad("integrator.scheme", format!("`{other}` (expected rk4, midpoint or euler)"))),
        };
        if self.integrator.steps == 0 {
            return Err(bad("integrator.steps", "must be at least 1".into()));
        }
        Ok(Model {
            kind,
            norm,
            gamma_v: m.gamma_v,
            gamma_f: m.gamma_f,
            gamma_w: m.gamma_w,
            kernel,
            integrator,
            steps: self.integrator.steps,
        })
    }

    /// The data attachment kernel of `[attachment]`.
    pub fn attachment_kernel(&self) -> Result<VarifoldKernel, ShootError> {
        let a = self.attachment.as_ref().ok_or_else(|| ShootError::Config("missing section [attachment]".into()))?;
        self.attachment_with_geom(&a.kernel_geom, "attachment")
    }

    fn attachment_with_geom(&self, geom: &str, key: &str) -> Result<VarifoldKernel, ShootError> {
        let a = self.attachment.as_ref().ok_or_else(|| ShootError::Config("missing section [attachment]".into()))?;
        let bad = |e: fshape_varifold::VarifoldError| ShootError::Config(format!("{key}: {e}"));
        let mut k = VarifoldKernel::parse(geom, a.kernel_signal.as_deref(), &a.kernel_grass).map_err(bad)?;
        if let Some(tol) = a.tolerance {
            k = k.truncated(tol).map_err(bad)?;
        }
        Ok(k)
    }

    /// The attachment kernel of each stage of the coarse-to-fine schedule
    /// (`[schedule] kernel_geom` with the rest of `[attachment]`), or the
    /// single `[attachment]` kernel.
    pub fn schedule(&self) -> Result<Vec<(String, VarifoldKernel)>, ShootError> {
        match &self.schedule {
            None => {
                let geom = self.attachment.as_ref().map(|a| a.kernel_geom.clone()).unwrap_or_default();
                Ok(vec![(geom, self.attachment_kernel()?)])
            }
            Some(s) if s.kernel_geom.is_empty() => {
                Err(ShootError::Config("schedule.kernel_geom: needs at least one kernel".into()))
            }
            Some(s) => s
                .kernel_geom
                .iter()
                .enumerate()
                .map(|(i, g)| Ok((g.clone(), self.attachment_with_geom(g, &format!("schedule.kernel_geom[{i}]"))?)))
                .collect(),
        }
    }

    /// The optimiser settings and the metrics of the unknowns.
    pub fn optimizer(&self) -> Result<(Settings, Metrics), ShootError> {
        let bad = |key: &str, why: String| ShootError::Config(format!("optimizer.{key}: {why}"));
        let o = &self.optimizer;
        let method = match o.method.as_str() {
            "lbfgs" if o.memory >= 1 => Method::Lbfgs { memory: o.memory },
            "lbfgs" => return Err(bad("memory", "must be at least 1".into())),
            "gradient-descent" if o.increase > 1.0 && o.increase.is_finite() => {
                Method::GradientDescent { increase: o.increase }
            }
            "gradient-descent" => {
                return Err(bad("increase", format!("must be finite and above 1, got {}", o.increase)));
            }
            other => return Err(bad("method", format!("`{other}` (expected lbfgs or gradient-descent)"))),
        };
        for (key, v) in [("gradient_tolerance", o.gradient_tolerance), ("decrease_tolerance", o.decrease_tolerance)] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(bad(key, format!("must be finite and at least 0, got {v}")));
            }
        }
        let parse = |key: &str, v: &str| match v {
            "l2" => Ok(SignalMetric::L2),
            "euclidean" => Ok(SignalMetric::Euclidean),
            other => Err(bad(key, format!("`{other}` (expected l2 or euclidean)"))),
        };
        let metric = Metrics {
            signal: parse("signal_metric", &o.signal_metric)?,
            momentum: parse("momentum_metric", &o.momentum_metric)?,
        };
        let settings = Settings {
            method,
            max_iterations: o.max_iterations,
            gradient_tolerance: o.gradient_tolerance,
            decrease_tolerance: o.decrease_tolerance,
            decrease_window: o.decrease_window,
            block_scaling: o.block_scaling,
            ..Settings::default()
        };
        Ok((settings, metric))
    }
}
