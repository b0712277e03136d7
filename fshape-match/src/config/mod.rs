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
//! [[stage]]                         # coarse to fine, a table per stage (default: one stage, [attachment])
//! kernel_geom = "gaussian:0.2"      # the stage's position kernel      (required)
//! scheme = "midpoint"               # its integrator (default [integrator]'s; the last stage's must be it)
//! steps = 5                         # its time steps (likewise)
//! max_iterations = 200              # (default [optimizer]'s)
//! decrease_tolerance = 1e-2         # (default [optimizer]'s)
//! decrease_window = 10              # (default [optimizer]'s)
//! vertices = 2000                   # its template: the source simplified (every stage but the last, or none)
//! coarse_target = true              # with vertices: the target simplified alike (default true)
//! [[stage]]
//! kernel_geom = "gaussian:0.1"      # the last stage runs on the source and target themselves
//!
//! # or, the older form of the same schedule (still read, with a warning):
//! # [schedule]
//! # kernel_geom = ["gaussian:0.2", "gaussian:0.1"]
//! # scheme = ["midpoint", "rk4"]   # and steps, max_iterations, decrease_tolerance,
//! # vertices = [2000]              # decrease_window: an array each; coarse_targets = true
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

use std::path::Path;

use fshape_fem::Norm;
use fshape_kernels::{Kernel, Profile};
use fshape_mesh::FShape;
use fshape_shoot::Model;
use fshape_varifold::{SignalKernel, VarifoldKernel};
use serde::{Deserialize, Serialize};

use crate::MatchError;
use crate::optimize::{Method, Settings};
use crate::unknowns::{Metric, Metrics};

mod check;
mod scales;
mod schedule;
mod sections;

pub use scales::Scales;
pub use schedule::{ScheduleSection, StageSpec, StageTable};
pub use sections::{
    AtlasSection, AttachmentSection, DeformationSection, GrassKernelSpec, IntegratorSection, MethodKind, ModelSection,
    NormKind, OptimizerSection, PositionKernel, SignalKernelSpec, TemplateKind,
};

use check::{bad, positive};

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

impl Config {
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
    /// registration's momenta again needs (its schedule as `[[stage]]` tables).
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
        c.with_stage_tables()
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
