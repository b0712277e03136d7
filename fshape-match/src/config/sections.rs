//! The sections of the file each a type: `[model]`, `[deformation]`,
//! `[integrator]`, `[attachment]` (with its kernels parsed once, when
//! read), `[optimizer]` and `[atlas]`.

use std::fmt;

use fshape_kernels::Kernel;
use fshape_shoot::{Integrator, ModelKind};
use fshape_varifold::{GrassKernel, SignalKernel};
use serde::{Deserialize, Serialize};

use crate::optimize::Settings;
use crate::unknowns::{Metric, Metrics};

/// Which template model an atlas estimates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TemplateKind {
    /// The template's positions and signal are unknowns (fshapesTk's
    /// free template; its position gradient smoothed by the kernel).
    #[default]
    Free,
    /// The template is the initial one (the hypertemplate) shot by its own
    /// momenta P_0 (LDDMM, the deformation kernel), with (γ_V0/2)‖v‖²_V
    /// added to J; its signal is an unknown as in the free template.
    Hypertemplate,
}

/// `[atlas]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AtlasSection {
    /// free | hypertemplate (default free).
    pub template: TemplateKind,
    /// γ_V0, the weight of the hypertemplate's deformation energy
    /// (normalised like γ_V; default 1).
    pub gamma_v0: f64,
}

impl Default for AtlasSection {
    fn default() -> Self {
        AtlasSection { template: TemplateKind::Free, gamma_v0: 1.0 }
    }
}

/// The signal norm's name (`l2-lumped`, `l2`, `h1`); H¹'s length is
/// `[model] length`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum NormKind {
    /// Lumped L² (diagonal mass).
    #[default]
    #[serde(rename = "l2-lumped")]
    L2Lumped,
    /// L² with the P1 mass matrix.
    #[serde(rename = "l2")]
    L2,
    /// H¹ = mass + ℓ² stiffness.
    #[serde(rename = "h1")]
    H1,
}

/// `[model]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelSection {
    /// metamorphosis | tangential | lddmm: the signal changes along the
    /// path (the paper's metamorphosis), by a residual added on the
    /// template and carried by the flow (tangential), or not at all
    /// (LDDMM: geometry only).
    pub kind: ModelKind,
    /// The signal norm: l2-lumped (diagonal mass) | l2 (P1 mass) | h1
    /// (mass + ℓ² stiffness).
    pub norm: NormKind,
    /// ℓ of the H¹ norm, in the data's length unit.
    pub length: f64,
    /// γ_V, the weight of the deformation energy.
    pub gamma_v: f64,
    /// γ_f, the weight of the signal change's energy.
    pub gamma_f: f64,
    /// γ_W, the weight of the data attachment.
    pub gamma_w: f64,
    /// Weights relative to the data's scale ("Scale-free weights" below;
    /// false: as written, in the data's units).
    pub normalize: bool,
    /// A weight w_c per signal channel, multiplying γ_f for channel c
    /// (empty, the default: 1 for each; as many as the shapes have
    /// channels otherwise).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub channel_weights: Vec<f64>,
}

impl Default for ModelSection {
    fn default() -> Self {
        ModelSection {
            kind: ModelKind::Metamorphosis,
            norm: NormKind::L2Lumped,
            length: 1.0,
            gamma_v: 1.0,
            gamma_f: 0.1,
            gamma_w: 1e3,
            normalize: true,
            channel_weights: Vec::new(),
        }
    }
}

/// `[deformation]`: a sum of Gaussians.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeformationSection {
    /// Gaussian widths.
    pub widths: Vec<f64>,
    /// Weights, one per width (default all 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<Vec<f64>>,
    /// Truncation tolerance (default exact).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
}

/// `[integrator]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IntegratorSection {
    /// rk4 | midpoint | euler.
    pub scheme: Integrator,
    /// Number of time steps.
    pub steps: usize,
    /// The relative drift of the Hamiltonian beyond which a shooting is
    /// reported as diverged (fshape-shoot's `Model::with_max_drift`).
    pub max_drift: f64,
}

impl Default for IntegratorSection {
    fn default() -> Self {
        IntegratorSection { scheme: Integrator::Rk4, steps: 10, max_drift: fshape_shoot::DEFAULT_MAX_DRIFT }
    }
}

/// A kernel written as text in the file and parsed once, when read: it is
/// stored as both, so that it serialises back to the same text.
macro_rules! kernel_spec {
    ($(#[$doc:meta])* $name:ident, $kernel:ty, $parse:expr) => {
        $(#[$doc])*
        #[derive(Clone, Debug, Serialize, Deserialize)]
        #[serde(try_from = "String", into = "String")]
        pub struct $name {
            text: String,
            kernel: $kernel,
        }

        impl $name {
            /// Parses the text (the width checked).
            pub fn parse(text: &str) -> Result<Self, fshape_varifold::VarifoldError> {
                let parse: fn(&str) -> Result<$kernel, fshape_varifold::VarifoldError> = $parse;
                Ok($name { kernel: parse(text)?, text: text.to_string() })
            }

            /// The text, as written.
            pub fn text(&self) -> &str {
                &self.text
            }

            /// The parsed kernel.
            pub fn kernel(&self) -> &$kernel {
                &self.kernel
            }
        }

        impl TryFrom<String> for $name {
            type Error = String;
            fn try_from(text: String) -> Result<Self, String> {
                $name::parse(&text).map_err(|e| e.to_string())
            }
        }

        impl From<$name> for String {
            fn from(k: $name) -> String {
                k.text
            }
        }

        impl PartialEq for $name {
            fn eq(&self, other: &Self) -> bool {
                self.text == other.text
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.text)
            }
        }
    };
}

kernel_spec!(
    /// A position kernel k_p: `gaussian:σ`, `gaussian:σ1,σ2,…` or `cauchy:σ`.
    PositionKernel,
    Kernel,
    fshape_varifold::parse_position
);
kernel_spec!(
    /// A signal kernel k_f: `gaussian:σ_f`, or `gaussian:σ_1,σ_2,…` for a
    /// width per signal channel.
    SignalKernelSpec,
    SignalKernel,
    SignalKernel::parse
);
kernel_spec!(
    /// A direction kernel k_t: `linear`, `binet`, `gaussian-oriented:σ_t`,
    /// `gaussian-unoriented:σ_t`.
    GrassKernelSpec,
    GrassKernel,
    GrassKernel::parse
);

/// `[attachment]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttachmentSection {
    /// Position kernel, as `fshape distance --kernel-geom`.
    pub kernel_geom: PositionKernel,
    /// Signal kernel (omit for a geometric term): `gaussian:σ_f`, or
    /// `gaussian:σ_1,σ_2,…` with a width per signal channel for shapes of
    /// several channels (one `--signal` file per channel).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernel_signal: Option<SignalKernelSpec>,
    /// Direction kernel (default binet).
    #[serde(default = "binet")]
    pub kernel_grass: GrassKernelSpec,
    /// Truncation tolerance of k_p (default exact).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    /// Whether a masked region's geometry counts in the attachment
    /// (default true: a medial wall is real surface, only its signal is
    /// missing; false leaves it free to lie anywhere).
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub masked_geometry: bool,
}

fn yes() -> bool {
    true
}

// serde's skip_serializing_if passes a reference.
fn is_true(b: &bool) -> bool {
    *b
}

fn binet() -> GrassKernelSpec {
    GrassKernelSpec::parse("binet").expect("a valid kernel")
}

/// The optimiser's name (`lbfgs`, `gradient-descent`); its parameter is
/// `memory` or `increase`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MethodKind {
    /// L-BFGS with a strong Wolfe line search.
    #[default]
    Lbfgs,
    /// The paper's gradient descent with an adaptive step.
    GradientDescent,
}

/// `[optimizer]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OptimizerSection {
    /// lbfgs | gradient-descent.
    pub method: MethodKind,
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
    /// Metric of p^f: l2 | euclidean | energy.
    pub signal_metric: Metric,
    /// Metric of p_0: euclidean | l2 | energy.
    pub momentum_metric: Metric,
}

impl Default for OptimizerSection {
    fn default() -> Self {
        let d = Settings::default();
        let m = Metrics::default();
        OptimizerSection {
            method: MethodKind::Lbfgs,
            memory: 10,
            block_scaling: d.block_scaling,
            increase: 1.2,
            max_iterations: d.max_iterations,
            gradient_tolerance: d.gradient_tolerance,
            decrease_tolerance: d.decrease_tolerance,
            decrease_window: d.decrease_window,
            signal_metric: m.signal,
            momentum_metric: m.momentum,
        }
    }
}
