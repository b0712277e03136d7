//! Data attachment terms between fshapes: functional varifolds, varifolds
//! and currents (`../shared/DESIGN.md`, "Data attachment"; paper eq.
//! fvarifold), with exact gradients in the vertex positions and the vertex
//! signal values.
//!
//! Each cell τ of a mesh becomes a weighted Dirac r_τ δ_(c_τ, u_τ, f_τ): its
//! centre, unit normal or tangent, signal (mean of its corners) and volume
//! ([`CellFeatures`]). Two such measures are compared through a product
//! kernel ([`VarifoldKernel`]): position k_p (any fshape-kernels
//! [`Kernel`](fshape_kernels::Kernel): Gaussian, sums of Gaussians, Cauchy,
//! exact or truncated), signal k_f (Gaussian, or constant for purely
//! geometric shapes) and direction k_t (linear = currents, Binet, oriented
//! and unoriented Gaussians):
//!
//! ⟨μ_X, μ_Y⟩ = Σ_τ Σ_σ r_τ r_σ k_p(|c_τ − c_σ|²) k_f(f_τ − f_σ) k_t(u_τ·u_σ),
//! A(X, Y) = ⟨X,X⟩ − 2⟨X,Y⟩ + ⟨Y,Y⟩.
//!
//! **Width convention**: a Gaussian of width σ is exp(−u/(2σ²)) for k_p and
//! k_f; fshapesTk and KeOps write exp(−u/σ²), so their σ is ours times √2.
//! k_t's Gaussians keep fshapesTk's form exp(−2(1 − s)/σ_t²).
//!
//! Sums run on fshape-kernels' block-sparse pair engine
//! ([`BlockPairs`](fshape_kernels::BlockPairs)) with a vectorised product
//! kernel; a truncated k_p skips blocks of cells beyond its support.
//! Cells of zero volume carry no mass; unused vertices carry none either.
//!
//! ```
//! use fshape_kernels::Kernel;
//! use fshape_mesh::test_support::perturbed_icosphere;
//! use fshape_varifold::{Attachment, GrassKernel, SignalKernel, VarifoldKernel};
//! let k = VarifoldKernel::try_new(
//!     Kernel::gaussian(0.3)?,
//!     SignalKernel::Gaussian { sigma: 0.5 },
//!     GrassKernel::UnorientedGaussian { sigma: 0.5 },
//! )?;
//! let (x, y) = (perturbed_icosphere(2, 0.05, 1), perturbed_icosphere(2, 0.05, 2));
//! let (a, grad) = Attachment::new(&y, k)?.eval_grad(&x)?;
//! assert!(a.value > 0.0 && grad.points.len() == 3 * x.n_vertices());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod attach;
mod engine;
mod features;
mod kernel;

pub use attach::{Attachment, Distance, ShapeGrad, distance, inner_product, inner_product_grad};
pub use engine::MAX_CHANNELS;
pub use features::{CellFeatures, FeatureGrad};
pub use kernel::{GrassKernel, SignalKernel, VarifoldKernel, parse_position};

/// Why a data attachment could not be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum VarifoldError {
    /// The position kernel or its pair engine refused its input.
    #[error(transparent)]
    Kernel(#[from] fshape_kernels::KernelError),
    /// A kernel width is not positive and finite.
    #[error("{what} width must be positive and finite, got {sigma}")]
    Width {
        /// Which kernel.
        what: &'static str,
        /// The width given.
        sigma: f64,
    },
    /// A vertex's signal value is NaN or infinite.
    #[error("signal value of vertex {vertex} is {value}; a data attachment needs finite signal values")]
    NonFiniteSignal {
        /// Vertex index.
        vertex: usize,
        /// The value.
        value: f64,
    },
    /// A feature given to [`CellFeatures::from_parts`] is not finite (or a
    /// weight is negative).
    #[error("{what} of cell {cell} is {value}: features must be finite and weights non-negative")]
    Feature {
        /// Which feature.
        what: &'static str,
        /// Cell index.
        cell: usize,
        /// The value.
        value: f64,
    },
    /// An array has the wrong length.
    #[error("{what}: expected {expected} values, found {found}")]
    Dimension {
        /// Which array.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Length given.
        found: usize,
    },
    /// Points must have 2 or 3 coordinates.
    #[error("point dimension: expected 2 or 3 coordinates per point, found {found}")]
    PointDimension {
        /// The dimension given.
        found: usize,
    },
    /// The two shapes are not of the same kind.
    #[error(
        "source and target differ: source cells live in R^{source_dim} with {source_dir}-component directions, \
         target cells in R^{target_dim} with {target_dir} (compare curves with curves, surfaces with surfaces)"
    )]
    Incompatible {
        /// Source ambient dimension.
        source_dim: usize,
        /// Source direction components.
        source_dir: usize,
        /// Target ambient dimension.
        target_dim: usize,
        /// Target direction components.
        target_dir: usize,
    },
    /// A kernel specification could not be parsed.
    #[error("{what} `{input}` not understood: expected {expected}")]
    Parse {
        /// Which kernel.
        what: &'static str,
        /// The text given.
        input: String,
        /// The accepted forms.
        expected: &'static str,
    },
    /// Channel counts disagree: the source's and the target's signals, or
    /// a per-channel signal kernel's widths and the signals.
    #[error("{what}: expected {expected} channels, found {found}")]
    Channels {
        /// What was counted.
        what: &'static str,
        /// The channels expected.
        expected: usize,
        /// The channels found.
        found: usize,
    },
    /// A signal kernel needs signals on both shapes.
    #[error(
        "the signal kernel compares signal values, but the {which} shape has no signal (use a constant signal kernel for purely geometric shapes)"
    )]
    MissingSignal {
        /// "source" or "target".
        which: &'static str,
    },
}
