//! The configuration of a registration: a TOML file, or a value built in
//! code and written with serde. Every choice is a typed value (the
//! spellings below are serde's), kernels are parsed once when the file is
//! read, and [`Config::plan`] checks every number before any work.
//!
//! ```toml
//! [model]
//! kind = "metamorphosis"   # metamorphosis | tangential | lddmm   (default metamorphosis)
//! norm = "h1"              # l2-lumped | l2 | h1                  (default l2-lumped)
//! length = 1.0             # ℓ of the H1 norm, in mesh units      (default 1)
//! gamma_v = 1.0            # weight γ_V of the deformation energy (default 1)
//! gamma_f = 0.1            # weight γ_f of the signal energy      (default 0.1)
//! gamma_w = 1000.0         # weight γ_W of the data attachment    (default 1000)
//! normalize = true         # weights relative to the data's scale (default true; see below)
//! channel_weights = [1, 2] # w_c: channel c's γ_f is γ_f·w_c      (default all 1; one per channel)
//!
//! [deformation]
//! widths = [0.2, 0.1]      # Gaussian widths σ_i, exp(−u/(2σ²))   (required)
//! weights = [1.0, 1.0]     # one per width                        (default all 1)
//! tolerance = 1e-6         # smooth truncation τ                  (default: exact)
//!
//! [integrator]
//! scheme = "rk4"           # rk4 | midpoint | euler               (default rk4)
//! steps = 10               # time steps on [0, 1]                 (default 10)
//! max_drift = 0.5          # relative drift of H reported as divergence (default 0.5)
//!
//! [attachment]
//! kernel_geom = "gaussian:0.05"     # as `fshape distance --kernel-geom` (required)
//! kernel_signal = "gaussian:0.5"    # omit for a purely geometric term
//! kernel_grass = "binet"            # (default binet)
//! tolerance = 1e-6                  # truncation of k_p (default: exact)
//! masked_geometry = true            # a masked region's geometry counts (default true)
//!
//! [optimizer]                       # matching and atlases; every key optional
//! method = "lbfgs"                  # lbfgs | gradient-descent          (default lbfgs)
//! memory = 10                       # L-BFGS correction pairs           (default 10)
//! block_scaling = true              # L-BFGS: own scale for p_0 and p^f (default true)
//! increase = 1.2                    # gradient descent: step growth     (default 1.2)
//! max_iterations = 200              # per schedule stage                (default 200)
//! gradient_tolerance = 1e-3         # stop at |∇J| ≤ tol·|∇J at start|  (default 1e-3)
//! decrease_tolerance = 1e-6         # stop when J fell by ≤ tol·|J|...  (default 1e-6)
//! decrease_window = 10              # ...over this many iterations      (default 10)
//! signal_metric = "l2"              # metric of p^f: l2 (L²(x_0), the paper's) | euclidean | energy (default l2)
//! momentum_metric = "energy"        # metric of p_0: euclidean | l2 | energy (default energy)
//!
//! [schedule]                        # coarse to fine (default: one stage, [attachment])
//! kernel_geom = ["gaussian:0.2", "gaussian:0.1", "gaussian:0.05"]
//! scheme = ["midpoint", "midpoint", "rk4"]  # per stage (default [integrator]'s; the last must be it)
//! steps = [5, 5, 10]                        # per stage (likewise)
//! max_iterations = [200, 100, 30]           # per stage (default [optimizer]'s)
//! decrease_tolerance = [1e-2, 1e-2, 1e-3]    # per stage (default [optimizer]'s)
//! decrease_window = [10, 10, 3]              # per stage (default [optimizer]'s)
//! vertices = [2000, 10000]                   # each stage's template but the last (default: the source)
//! coarse_targets = true                      # with vertices: the target simplified alike (default true)
//!
//! # or the same schedule, a table per stage (each key as above, for its
//! # stage; one left out takes [integrator]'s or [optimizer]'s):
//! # [[stage]]
//! # kernel_geom = "gaussian:0.2"
//! # scheme = "midpoint"
//! # max_iterations = 200
//! # vertices = 2000
//! # [[stage]]
//! # ...
//!
//! [atlas]                           # fshape atlas only
//! template = "free"                 # free | hypertemplate              (default free)
//! gamma_v0 = 1.0                    # hypertemplate: weight γ_V0 of its energy (default 1)
//!
//! [prealign]                         # before matching (crate::prealign)
//! kind = "rigid"                    # none | rigid | similarity | affine (default none)
//! move = "source"                   # source | target: which is moved  (default source; atlases move the subjects)
//! max_iterations = 100              # L-BFGS iterations per start        (default 100)
//! ```
//!
//! **Scale-free weights** (`normalize = true`, the default). The three
//! terms of J have units: the deformation energy (γ_V/2)‖v‖²_V grows like
//! L² when the shapes are scaled by L (displacements ∝ L, kernel widths
//! ∝ L), the signal energy (γ_f/2)‖ḟ‖²_{H^s} like S²·L^d (S the signal's
//! scale, d the cells' dimension: ∫ḟ² over an area L^d), and the data
//! term A like L^{2d} (a double sum of cell volumes). With normalization
//! the model uses γ_V/L², γ_f/(S²·L^d) and γ_W/L^{2d}, i.e. J is computed
//! as if the shapes had diagonal 1 and the signal a standard deviation of
//! 1, so one set of weights means the same on a unit bunny, a square of
//! side 2 and a cortex in millimetres. L is the target's bounding-box
//! diagonal and S the standard deviation of the target's vertex signal
//! (of the template's when the target's is constant or absent; 1 when
//! both are). With several channels, channel c's γ_f is
//! γ_f·w_c/(S_c²·L^d), S_c that channel's deviation and w_c its
//! `channel_weights` entry, so each map counts as if it had a deviation of
//! 1 whatever its units (thickness in mm beside myelin as a ratio).
//! Deviations skip masked and missing vertices and weigh the rest by
//! their mask. Shooting alone has no target: [`Config::model`] takes the
//! weights as written, and a registration's output has its effective
//! weights ([`Config::resolved`]) for shooting its momenta again. Kernel widths and the H¹ length stay in the data's units:
//! choose them as fractions of the shapes' size. What each weight does:
//! γ_W/γ_V sets how closely the geometry is fitted (larger: closer, at a
//! larger deformation); γ_W/γ_f how closely the signal is (larger: a
//! closer signal, changed more along the path; with an L² norm, also a
//! signal that oscillates where the target does not pin it, as over the
//! bunny's holes: the paper's observation, measured in docs/guide/src/experiments.md,
//! and why `fshape demo bunny` uses γ_f = 0.01); γ_V/γ_f how the match
//! shares the work between moving the signal with the shape and changing
//! it (the paper's ratios 1, 20, 100 on the digits). `normalize = false`
//! takes the weights as they are, in the data's units.
//!
//! Unknown keys are refused by name. A value of the wrong type or
//! spelling is refused while reading, with its key and line; a number out
//! of range by [`Config::plan`], with its key.

use std::fmt;
use std::path::Path;

use fshape_fem::Norm;
use fshape_kernels::{Kernel, Profile};
use fshape_mesh::FShape;
use fshape_shoot::{Integrator, Model, ModelKind};
use fshape_varifold::{GrassKernel, SignalKernel, VarifoldKernel};
use serde::{Deserialize, Serialize};

use crate::MatchError;
use crate::optimize::{Method, Settings};
use crate::unknowns::{Metric, Metrics};

/// The whole file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
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
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attachment: Option<AttachmentSection>,
    /// `[optimizer]` (matching).
    #[serde(default)]
    pub optimizer: OptimizerSection,
    /// `[schedule]` (matching).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<ScheduleSection>,
    /// `[[stage]]`: the schedule as one table per stage (not with
    /// `[schedule]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage: Option<Vec<StageTable>>,
    /// `[atlas]` (atlas estimation only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub atlas: Option<AtlasSection>,
    /// `[prealign]` (matching and atlases; none by default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prealign: Option<crate::prealign::PrealignSection>,
}

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

/// The scales of the data that normalised weights are relative to
/// (module docs): L, S and d.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scales {
    /// L: the bounding-box diagonal.
    pub length: f64,
    /// S: the signal's standard deviation (1 without one); with several
    /// channels, the first channel's.
    pub signal: f64,
    /// d: the dimension of the cells (1 curves, 2 surfaces).
    pub cell_dim: usize,
    /// S_c, one per channel when there are several (empty with one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub channels: Vec<f64>,
}

impl Scales {
    /// L from `target`, S (per channel) from the target's signal, else the
    /// template's, else 1; d from the template. A deviation is taken over
    /// the vertices that carry a value, weighted by their mask.
    pub fn of(template: &FShape, target: &FShape) -> Result<Scales, MatchError> {
        let length = target.bounding_box().diagonal();
        if !(length > 0.0 && length.is_finite()) {
            return Err(bad(
                "model.normalize",
                format!("the shapes' bounding-box diagonal is {length}; normalize = false"),
            ));
        }
        let k = target.n_channels().max(template.n_channels()).max(1);
        let deviation = |c: usize| deviation(target, c).or_else(|| deviation(template, c)).unwrap_or(1.0);
        let channels: Vec<f64> = if k > 1 { (0..k).map(deviation).collect() } else { Vec::new() };
        Ok(Scales { length, signal: deviation(0), cell_dim: template.kind().dim(), channels })
    }

    /// The effective (γ_V, γ_f, γ_W) of the written ones: γ_V/L²,
    /// γ_f/(S²·L^d), γ_W/L^{2d}.
    pub fn effective(&self, gamma_v: f64, gamma_f: f64, gamma_w: f64) -> (f64, f64, f64) {
        let (l, d) = (self.length, self.cell_dim as i32);
        (gamma_v / (l * l), gamma_f / (self.signal * self.signal * l.powi(d)), gamma_w / l.powi(2 * d))
    }

    /// The effective channel weights of the written ones `w` (empty: all
    /// 1): w_c·S²/S_c², so that channel c's γ_f is γ_f w_c/(S_c²·L^d) with
    /// [`Scales::effective`]'s γ_f. Empty with one channel.
    pub fn channel_weights(&self, w: &[f64]) -> Vec<f64> {
        let s2 = self.signal * self.signal;
        self.channels.iter().enumerate().map(|(c, sc)| w.get(c).copied().unwrap_or(1.0) * s2 / (sc * sc)).collect()
    }

    /// S_c of channel `c` (S with one channel).
    pub fn channel(&self, c: usize) -> f64 {
        self.channels.get(c).copied().unwrap_or(self.signal)
    }
}

/// The standard deviation of channel `c` of a shape's signal over the
/// vertices with a value, weighted by the mask; `None` without a signal,
/// or when it is constant there. Unmasked, it is the plain deviation
/// (weights of 1 change no bit).
fn deviation(s: &FShape, c: usize) -> Option<f64> {
    let k = s.n_channels();
    let f = s.signal().filter(|f| !f.is_empty() && c < k)?;
    let weight = |v: usize| s.mask().map_or(1.0, |m| m[v]);
    let values = || {
        f.iter()
            .skip(c)
            .step_by(k)
            .enumerate()
            .map(move |(v, &x)| (weight(v), x))
            .filter(|(w, x)| *w > 0.0 && !x.is_nan())
    };
    let total: f64 = values().map(|(w, _)| w).sum();
    let mean = values().map(|(w, x)| w * x).sum::<f64>() / total;
    let sd = (values().map(|(w, x)| w * (x - mean) * (x - mean)).sum::<f64>() / total).sqrt();
    (sd > 0.0 && sd.is_finite()).then_some(sd)
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
    /// reported as diverged ([`Model::with_max_drift`]).
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

/// `[schedule]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScheduleSection {
    /// The position kernel of each stage, coarse to fine.
    pub kernel_geom: Vec<PositionKernel>,
    /// The integrator of each stage (default: `[integrator] scheme` for
    /// all); the last must be `[integrator]`'s: the model asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scheme: Option<Vec<Integrator>>,
    /// The time steps of each stage (default: `[integrator] steps` for
    /// all); the last must be `[integrator]`'s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<Vec<usize>>,
    /// The iteration limit of each stage (default: `[optimizer]
    /// max_iterations` for all): coarse stages may do most of the work.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iterations: Option<Vec<usize>>,
    /// The relative-decrease tolerance of each stage (default:
    /// `[optimizer] decrease_tolerance` for all).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decrease_tolerance: Option<Vec<f64>>,
    /// The window of each stage's decrease test (default: `[optimizer]
    /// decrease_window` for all): a short final stage needs a short window.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decrease_window: Option<Vec<usize>>,
    /// The vertex count of each stage's template but the last, which runs
    /// on the source: the source simplified to it
    /// ([`fshape_mesh::FShape::simplified`], keeping a subset of its
    /// vertices with their signal); a count at least the source's is the
    /// source. One value per stage before the last, as
    /// `--stage-templates` takes one mesh each (default: every stage on the
    /// source). Not with hand-made stage templates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertices: Option<Vec<usize>>,
    /// With `vertices`: each such stage also matches the target simplified
    /// to the same count (default true), so that a coarse stage's data
    /// term costs what its template's size calls for; the last stage
    /// always matches the target itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_targets: Option<bool>,
}

impl ScheduleSection {
    /// Stages with these position kernels, each with `[integrator]`'s
    /// scheme and steps.
    pub fn new(kernel_geom: Vec<PositionKernel>) -> ScheduleSection {
        ScheduleSection {
            kernel_geom,
            scheme: None,
            steps: None,
            max_iterations: None,
            decrease_tolerance: None,
            decrease_window: None,
            vertices: None,
            coarse_targets: None,
        }
    }
}

/// `[[stage]]`. The schedule written as one table per stage, coarse to
/// fine, instead of `[schedule]`'s arrays (not both): each stage's keys
/// together, so no array can have one value too few. A key a stage leaves
/// out takes `[integrator]`'s or `[optimizer]`'s value; errors name the
/// stage (`stage[1].vertices`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageTable {
    /// The stage's position kernel.
    pub kernel_geom: PositionKernel,
    /// Its integrator (the last stage's must be `[integrator]`'s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scheme: Option<Integrator>,
    /// Its time steps (the last stage's must be `[integrator]`'s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<usize>,
    /// Its iteration limit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iterations: Option<usize>,
    /// Its relative-decrease tolerance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decrease_tolerance: Option<f64>,
    /// The window of its decrease test.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decrease_window: Option<usize>,
    /// The vertex count of its template: every stage before the last has
    /// one, or none does; the last runs on the source.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertices: Option<usize>,
    /// With `vertices`: whether it matches the target simplified alike
    /// (default true; the same in every stage that says).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_target: Option<bool>,
}

/// One stage of the schedule: what it is called in reports and its data
/// attachment kernel.
#[derive(Clone, Debug)]
pub struct StageSpec {
    /// The stage's position kernel as written (`gaussian:0.1`).
    pub label: String,
    /// The data attachment kernel of the stage.
    pub kernel: VarifoldKernel,
    /// The stage's integrator and time steps (coarse stages may shoot
    /// more cheaply; the last stage's are the model's).
    pub integrator: (Integrator, usize),
    /// The stage's iteration limit.
    pub max_iterations: usize,
    /// The stage's relative-decrease tolerance and window.
    pub decrease: (f64, usize),
    /// The vertex count of the stage's template (`[schedule] vertices`;
    /// `None`: the source, or a hand-made stage template).
    pub vertices: Option<usize>,
    /// Whether the stage matches the target simplified to `vertices`.
    pub coarse_target: bool,
}

/// Everything a registration needs, checked: the model, the stages, the
/// optimiser settings and the metrics of the unknowns.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The model (with the effective weights when normalised).
    pub model: Model,
    /// The scales the weights were normalised by (`None`: as written).
    pub scales: Option<Scales>,
    /// The stages, coarse to fine (at least one).
    pub stages: Vec<StageSpec>,
    /// Optimiser settings (per stage).
    pub settings: Settings,
    /// Metrics of p_0 and p^f.
    pub metrics: Metrics,
}

fn bad(key: impl Into<String>, message: impl Into<String>) -> MatchError {
    MatchError::Config { key: key.into(), message: message.into() }
}

fn positive(key: &str, v: f64) -> Result<f64, MatchError> {
    if v > 0.0 && v.is_finite() { Ok(v) } else { Err(bad(key, format!("must be positive and finite, got {v}"))) }
}

impl Config {
    /// The number of stages `[schedule]` asks for (1 without one), read
    /// before the plan is checked: what a caller counts stage templates
    /// against.
    pub fn stage_count(&self) -> usize {
        match (&self.schedule, &self.stage) {
            (_, Some(tables)) => tables.len(),
            (Some(s), None) => s.kernel_geom.len(),
            (None, None) => 1,
        }
    }

    /// A configuration with the deformation kernel's widths and every
    /// other section at its default (no attachment, no schedule).
    pub fn new(widths: Vec<f64>) -> Config {
        Config {
            model: ModelSection::default(),
            deformation: DeformationSection { widths, weights: None, tolerance: None },
            integrator: IntegratorSection::default(),
            attachment: None,
            optimizer: OptimizerSection::default(),
            schedule: None,
            stage: None,
            atlas: None,
            prealign: None,
        }
    }

    /// Parses TOML text. A syntax error, an unknown key or a value of the
    /// wrong type or spelling names its key and line.
    ///
    /// ```
    /// let c = fshape_match::Config::parse("[deformation]\nwidths = [0.2, 0.1]\n")?;
    /// assert_eq!(c.model()?.steps(), 10);
    /// let e = fshape_match::Config::parse("[deformation]\nwidths = [0.2]\n[model]\nkind = \"magic\"\n").unwrap_err();
    /// assert!(e.to_string().contains("model.kind") && e.to_string().contains("line 4"));
    /// # Ok::<(), fshape_match::MatchError>(())
    /// ```
    pub fn parse(text: &str) -> Result<Config, MatchError> {
        let de = toml::Deserializer::parse(text).map_err(|e| MatchError::ConfigSyntax {
            key: String::new(),
            message: e.to_string().trim_end().to_string(),
        })?;
        serde_path_to_error::deserialize(de).map_err(|e| {
            let key = e.path().to_string();
            MatchError::ConfigSyntax {
                key: if key == "." { String::new() } else { key },
                message: e.into_inner().to_string().trim_end().to_string(),
            }
        })
    }

    /// Reads and parses a file (errors name it).
    pub fn read(path: &Path) -> Result<Config, MatchError> {
        // Bounded like every input: a device or folder is refused.
        let file = |message: String| MatchError::File { path: path.to_path_buf(), message };
        let bytes = fshape_mesh::io::read_bytes(path).map_err(|e| match e {
            fshape_mesh::io::ReadError::Io { source, .. } => file(source.to_string()),
            other => file(other.to_string()),
        })?;
        let text = String::from_utf8(bytes).map_err(|e| file(format!("not UTF-8 text ({e})")))?;
        Config::parse(&text).map_err(|e| e.in_file(path))
    }

    /// The TOML text of this configuration (every key, defaults included).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a Config always serialises")
    }

    /// The validated model with the weights as written, whatever
    /// `normalize` says (use [`Config::model_for`] for shapes).
    pub fn model(&self) -> Result<Model, MatchError> {
        self.model_scaled(None)
    }

    /// The validated model for matching `template` onto `target`: with
    /// `normalize`, the weights relative to the data's [`Scales`], which
    /// are returned too.
    pub fn model_for(&self, template: &FShape, target: &FShape) -> Result<(Model, Option<Scales>), MatchError> {
        let k = template.n_channels().max(target.n_channels()).max(1);
        let w = self.model.channel_weights.len();
        if w != 0 && w != k {
            return Err(bad("model.channel_weights", format!("{w} weights for shapes of {k} signal channels")));
        }
        let scales = if self.model.normalize { Some(Scales::of(template, target)?) } else { None };
        Ok((self.model_scaled(scales.as_ref())?, scales))
    }

    fn model_scaled(&self, scales: Option<&Scales>) -> Result<Model, MatchError> {
        let m = &self.model;
        let d = &self.deformation;
        for (key, v) in [("model.gamma_v", m.gamma_v), ("model.gamma_f", m.gamma_f), ("model.gamma_w", m.gamma_w)] {
            positive(key, v)?;
        }
        let norm = match m.norm {
            NormKind::L2Lumped => Norm::L2Lumped,
            NormKind::L2 => Norm::L2,
            NormKind::H1 => Norm::H1 { length: positive("model.length", m.length)? },
        };
        let weights = d.weights.clone().unwrap_or_else(|| vec![1.0; d.widths.len()]);
        let profile = Profile::Gaussians { sigmas: d.widths.clone(), weights };
        let mut kernel = Kernel::try_new(&profile).map_err(|e| bad("deformation", e.to_string()))?;
        if let Some(tol) = d.tolerance {
            kernel = kernel.truncated(tol).map_err(|e| bad("deformation.tolerance", e.to_string()))?;
        }
        if self.integrator.steps == 0 {
            return Err(bad("integrator.steps", "must be at least 1, got 0"));
        }
        if self.integrator.max_drift.is_nan() || self.integrator.max_drift <= 0.0 {
            return Err(bad("integrator.max_drift", format!("must be positive, got {}", self.integrator.max_drift)));
        }
        let (gamma_v, gamma_f, gamma_w) = match scales {
            Some(s) => s.effective(m.gamma_v, m.gamma_f, m.gamma_w),
            None => (m.gamma_v, m.gamma_f, m.gamma_w),
        };
        let channel_weights = match scales {
            Some(s) if !s.channels.is_empty() => s.channel_weights(&m.channel_weights),
            _ => m.channel_weights.clone(),
        };
        let model = Model::new(kernel)
            .with_kind(m.kind)
            .with_norm(norm)
            .and_then(|model| model.with_weights(gamma_v, gamma_f, gamma_w))
            .and_then(|model| model.with_integrator(self.integrator.scheme, self.integrator.steps))
            .and_then(|model| model.with_max_drift(self.integrator.max_drift))
            .map_err(|e| bad("model", e.to_string()))?
            .with_channel_weights(channel_weights)
            .map_err(|e| bad("model.channel_weights", e.to_string()))?;
        Ok(model)
    }

    fn attachment_section(&self) -> Result<&AttachmentSection, MatchError> {
        self.attachment.as_ref().ok_or_else(|| bad("attachment", "missing section [attachment]"))
    }

    /// The data attachment kernel of `[attachment]`.
    pub fn attachment_kernel(&self) -> Result<VarifoldKernel, MatchError> {
        let a = self.attachment_section()?;
        self.attachment_with(&a.kernel_geom, "attachment")
    }

    fn attachment_with(&self, geom: &PositionKernel, key: &str) -> Result<VarifoldKernel, MatchError> {
        let a = self.attachment_section()?;
        let signal = a.kernel_signal.as_ref().map_or(SignalKernel::Constant, |s| s.kernel().clone());
        let mut k = VarifoldKernel::try_new(geom.kernel().clone(), signal, *a.kernel_grass.kernel())
            .map_err(|e| bad(key, e.to_string()))?;
        if let Some(tol) = a.tolerance {
            k = k.truncated(tol).map_err(|e| bad("attachment.tolerance", e.to_string()))?;
        }
        Ok(k.with_masked_geometry(a.masked_geometry))
    }

    /// The stages of the coarse-to-fine schedule (`[schedule] kernel_geom`
    /// with the rest of `[attachment]`), or the single `[attachment]` stage.
    pub fn schedule(&self) -> Result<Vec<StageSpec>, MatchError> {
        let from_tables;
        let schedule = match (&self.schedule, &self.stage) {
            (Some(_), Some(_)) => {
                return Err(bad(
                    "stage",
                    "the schedule is given twice: as [schedule]'s arrays and as [[stage]] tables; keep one",
                ));
            }
            (None, Some(tables)) => {
                from_tables = self.tables_as_schedule(tables)?;
                Some(&from_tables)
            }
            (schedule, None) => schedule.as_ref(),
        };
        match schedule {
            None => {
                let geom = &self.attachment_section()?.kernel_geom;
                let integrator = (self.integrator.scheme, self.integrator.steps);
                let max_iterations = self.optimizer.max_iterations;
                Ok(vec![StageSpec {
                    label: geom.text().to_string(),
                    kernel: self.attachment_kernel()?,
                    integrator,
                    max_iterations,
                    decrease: (self.optimizer.decrease_tolerance, self.optimizer.decrease_window),
                    vertices: None,
                    coarse_target: false,
                }])
            }
            Some(s) if s.kernel_geom.is_empty() => Err(bad("schedule.kernel_geom", "needs at least one kernel")),
            Some(s) => {
                let n = s.kernel_geom.len();
                // A stage's key as the file wrote it.
                let key = |name: &str, i: usize| {
                    if self.stage.is_some() { format!("stage[{i}].{name}") } else { format!("schedule.{name}[{i}]") }
                };
                let per_stage = |key: &str, len: Option<usize>| match len {
                    Some(len) if len != n => Err(bad(
                        format!("schedule.{key}"),
                        format!("{len} values for {n} stages (one per kernel_geom)"),
                    )),
                    _ => Ok(()),
                };
                per_stage("scheme", s.scheme.as_ref().map(Vec::len))?;
                per_stage("steps", s.steps.as_ref().map(Vec::len))?;
                per_stage("max_iterations", s.max_iterations.as_ref().map(Vec::len))?;
                per_stage("decrease_tolerance", s.decrease_tolerance.as_ref().map(Vec::len))?;
                per_stage("decrease_window", s.decrease_window.as_ref().map(Vec::len))?;
                let tolerance =
                    |i: usize| s.decrease_tolerance.as_ref().map_or(self.optimizer.decrease_tolerance, |v| v[i]);
                let window = |i: usize| s.decrease_window.as_ref().map_or(self.optimizer.decrease_window, |v| v[i]);
                if let Some(i) = (0..n).find(|&i| !(tolerance(i) >= 0.0 && tolerance(i).is_finite())) {
                    return Err(bad(
                        key("decrease_tolerance", i),
                        format!("must be finite and at least 0, got {}", tolerance(i)),
                    ));
                }
                let budget = |i: usize| s.max_iterations.as_ref().map_or(self.optimizer.max_iterations, |v| v[i]);
                let scheme = |i: usize| s.scheme.as_ref().map_or(self.integrator.scheme, |v| v[i]);
                let steps = |i: usize| s.steps.as_ref().map_or(self.integrator.steps, |v| v[i]);
                if scheme(n - 1) != self.integrator.scheme || steps(n - 1) != self.integrator.steps {
                    let last = if self.stage.is_some() { format!("stage[{}]", n - 1) } else { "schedule".into() };
                    return Err(bad(
                        last,
                        "the last stage must use [integrator]'s scheme and steps (the model asked for; coarser ones are for the stages before)",
                    ));
                }
                if let Some(i) = (0..n).find(|&i| steps(i) == 0) {
                    return Err(bad(key("steps", i), "must be at least 1"));
                }
                if let Some(v) = &s.vertices {
                    if v.len() + 1 != n {
                        return Err(bad(
                            "schedule.vertices",
                            format!(
                                "{} values for {n} stages: one per stage before the last, which runs on the source",
                                v.len()
                            ),
                        ));
                    }
                    if let Some(i) = v.iter().position(|&c| c < 4) {
                        return Err(bad(
                            key("vertices", i),
                            format!("a surface needs at least 4 vertices, got {}", v[i]),
                        ));
                    }
                }
                if s.coarse_targets.is_some() && s.vertices.is_none() {
                    return Err(bad("schedule.coarse_targets", "needs schedule.vertices"));
                }
                let vertices = |i: usize| s.vertices.as_ref().and_then(|v| v.get(i).copied());
                let coarse_target = s.coarse_targets.unwrap_or(true);
                (0..n)
                    .map(|i| {
                        let g = &s.kernel_geom[i];
                        let kernel = self.attachment_with(g, &key("kernel_geom", i))?;
                        Ok(StageSpec {
                            label: g.text().to_string(),
                            kernel,
                            integrator: (scheme(i), steps(i)),
                            max_iterations: budget(i),
                            decrease: (tolerance(i), window(i)),
                            vertices: vertices(i),
                            coarse_target: coarse_target && vertices(i).is_some(),
                        })
                    })
                    .collect()
            }
        }
    }

    /// `[[stage]]` tables as `[schedule]`'s arrays: a key some stages give
    /// takes, in the others, `[integrator]`'s or `[optimizer]`'s value.
    /// What arrays cannot say wrongly but tables can is refused here,
    /// naming the stage.
    fn tables_as_schedule(&self, tables: &[StageTable]) -> Result<ScheduleSection, MatchError> {
        let n = tables.len();
        if n == 0 {
            return Err(bad("stage", "needs at least one [[stage]]"));
        }
        fn column<T: Copy>(
            tables: &[StageTable],
            get: impl Fn(&StageTable) -> Option<T>,
            default: T,
        ) -> Option<Vec<T>> {
            tables.iter().any(|t| get(t).is_some()).then(|| tables.iter().map(|t| get(t).unwrap_or(default)).collect())
        }
        if tables[n - 1].vertices.is_some() {
            return Err(bad(format!("stage[{}].vertices", n - 1), "the last stage runs on the source: no vertices"));
        }
        let with_vertices = tables.iter().filter(|t| t.vertices.is_some()).count();
        if with_vertices != 0 && with_vertices != n - 1 {
            let i = tables.iter().position(|t| t.vertices.is_none()).expect("one without");
            return Err(bad(
                format!("stage[{i}].vertices"),
                "every stage before the last gives its template's vertex count, or none does",
            ));
        }
        let mut coarse = tables.iter().enumerate().filter_map(|(i, t)| t.coarse_target.map(|c| (i, c)));
        let coarse_targets = match coarse.next() {
            None => None,
            Some((i, _)) if with_vertices == 0 => {
                return Err(bad(format!("stage[{i}].coarse_target"), "needs vertices"));
            }
            Some((_, c)) => {
                if let Some((j, _)) = coarse.find(|&(_, d)| d != c) {
                    return Err(bad(
                        format!("stage[{j}].coarse_target"),
                        "must be the same in every stage that gives it (the schedule has one setting)",
                    ));
                }
                Some(c)
            }
        };
        let (i, o) = (&self.integrator, &self.optimizer);
        Ok(ScheduleSection {
            kernel_geom: tables.iter().map(|t| t.kernel_geom.clone()).collect(),
            scheme: column(tables, |t| t.scheme, i.scheme),
            steps: column(tables, |t| t.steps, i.steps),
            max_iterations: column(tables, |t| t.max_iterations, o.max_iterations),
            decrease_tolerance: column(tables, |t| t.decrease_tolerance, o.decrease_tolerance),
            decrease_window: column(tables, |t| t.decrease_window, o.decrease_window),
            vertices: (with_vertices > 0).then(|| tables[..n - 1].iter().filter_map(|t| t.vertices).collect()),
            coarse_targets,
        })
    }

    /// The optimiser settings and the metrics of the unknowns.
    pub fn optimizer(&self) -> Result<(Settings, Metrics), MatchError> {
        let o = &self.optimizer;
        let method = match o.method {
            MethodKind::Lbfgs if o.memory >= 1 => Method::Lbfgs { memory: o.memory },
            MethodKind::Lbfgs => return Err(bad("optimizer.memory", "must be at least 1")),
            MethodKind::GradientDescent if o.increase > 1.0 && o.increase.is_finite() => {
                Method::GradientDescent { increase: o.increase }
            }
            MethodKind::GradientDescent => {
                return Err(bad("optimizer.increase", format!("must be finite and above 1, got {}", o.increase)));
            }
        };
        for (key, v) in [
            ("optimizer.gradient_tolerance", o.gradient_tolerance),
            ("optimizer.decrease_tolerance", o.decrease_tolerance),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(bad(key, format!("must be finite and at least 0, got {v}")));
            }
        }
        if o.signal_metric == Metric::Energy && self.model.kind == fshape_shoot::ModelKind::Tangential {
            return Err(bad(
                "optimizer.signal_metric",
                "the energy metric is the metamorphosis momentum's; the tangential model's ζ takes l2 or euclidean",
            ));
        }
        let metrics = Metrics { signal: o.signal_metric, momentum: o.momentum_metric };
        let settings = Settings {
            method,
            max_iterations: o.max_iterations,
            gradient_tolerance: o.gradient_tolerance,
            decrease_tolerance: o.decrease_tolerance,
            decrease_window: o.decrease_window,
            block_scaling: o.block_scaling,
            ..Settings::default()
        };
        Ok((settings, metrics))
    }

    /// This configuration with the weights a model normalised by `scales`
    /// uses, written out (`normalize = false`): what shooting the
    /// registration's momenta again needs.
    pub fn resolved(&self, scales: Option<&Scales>) -> Config {
        let mut c = self.clone();
        if let (true, Some(s)) = (c.model.normalize, scales) {
            let (v, f, w) = s.effective(c.model.gamma_v, c.model.gamma_f, c.model.gamma_w);
            (c.model.gamma_v, c.model.gamma_f, c.model.gamma_w) = (v, f, w);
            if !s.channels.is_empty() {
                c.model.channel_weights = s.channel_weights(&c.model.channel_weights);
            }
        }
        c.model.normalize = false;
        c
    }

    /// Everything checked at once for matching `template` onto `target`:
    /// the model (normalised by their scales if asked), the stages, the
    /// optimiser.
    pub fn plan(&self, template: &FShape, target: &FShape) -> Result<Plan, MatchError> {
        let (model, scales) = self.model_for(template, target)?;
        let stages = self.schedule()?;
        let (settings, metrics) = self.optimizer()?;
        Ok(Plan { model, scales, stages, settings, metrics })
    }
}
