//! Kernel sums for shape analysis: out_i = Σ_j k(|x_i − y_j|²) b_j and the
//! derivatives LDDMM shooting and varifold data terms need
//! (`../shared/DESIGN.md`, "The discrete model" and "Truncated kernels").
//!
//! - [`Profile`] / [`Kernel`]: Gaussian exp(−u/(2σ²)), weighted sums of
//!   Gaussians, Cauchy 1/(1 + u/σ²), as functions of the squared distance u,
//!   with exact k' and k''. **Width convention**: fshapesTk and KeOps write
//!   exp(−u/σ²), so their σ is ours times √2.
//! - [`Kernel::truncated`]: the same kernel multiplied by a C² taper that
//!   starts where k falls to τ·k(0) and reaches 0 at 1.25 times that
//!   radius. The truncated kernel is itself a smooth kernel, so every
//!   gradient identity (and finite-difference test) holds for it exactly,
//!   and each output obeys |out_i − exact_i| ≤ τ·k(0)·Σ_{j changed} |b_j|.
//! - [`KernelSums`]: sums against source points y, in parallel over targets
//!   and deterministic (serial = parallel, bitwise). Sums of Gaussians take
//!   a vectorised block path (exact: every j; truncated: blocks of sources
//!   beyond the support radius skipped); other kernels the general engine,
//!   which visits every j or only the j a spatial index (obvhs BVH or
//!   kiddo k-d tree) finds within the support. Derivatives:
//!   [`KernelSums::grad_cross`] (∂_x of aᵀK b), [`KernelSums::conv_jvp`] and
//!   [`KernelSums::grad_cross_jvp`] (directional derivatives for the exact
//!   adjoint of shooting), fused pairs of them sharing the exponentials
//!   ([`KernelSums::conv_and_grad`], [`KernelSums::conv_and_grad_jvp`]), and
//!   [`KernelSums::map_targets`], the general engine.
//! - [`Precision::MixedF32`]: [`KernelSums::conv`] of sums of Gaussians
//!   with the pair terms in f32 (f64 inputs, partial sums and results),
//!   about twice as fast, within a stated and tested per-output bound.
//!
//! ```
//! use fshape_kernels::{Kernel, KernelSums};
//! let k = Kernel::gaussian(0.5)?;
//! let y = [0.0, 0.0, 1.0, 0.0]; // two sources in the plane
//! let sums = KernelSums::try_new(&k, &y, 2)?;
//! // At a source, with unit weights, the sum is 1 + exp(−1/(2·0.25)).
//! let out = sums.conv(&[0.0, 0.0], &[1.0, 1.0], 1)?;
//! assert!((out[0] - (1.0 + (-2.0f64).exp())).abs() < 1e-14);
//! # Ok::<(), fshape_kernels::KernelError>(())
//! ```

mod blocks;
mod fast;
pub mod grid;
mod mixed;
mod profile;
pub mod simd;
mod sums;
mod symmetric;
mod taper;

pub use blocks::{BlockPairs, RunSearch, SourceRun};
pub use grid::{GRID_ORDERS, Grid, GridBound};
pub use mixed::Precision;
pub use profile::{Kernel, Profile, SumPath, TAPER_WIDTH, predicted_seconds};
pub use sums::{KernelSums, Pair, SpatialIndex, SumWorkspace};
pub use taper::Taper;

/// Lane-wise building blocks for vectorised kernels in other crates: a
/// block of [`L`](lanes::L) targets is held as `[f64; L]` arrays, and plain loops over
/// the lanes inside a `pulp::WithSimd` body compile to SIMD.
pub mod lanes {
    pub use crate::fast::{L, exp_lanes, sq_dist_lanes};
}

/// Why a kernel or a kernel sum could not be set up.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum KernelError {
    /// A kernel width is not positive and finite.
    #[error("kernel width must be positive and finite, got {sigma}")]
    Width {
        /// The width given.
        sigma: f64,
    },
    /// A sum of Gaussians needs one weight per width.
    #[error("a sum of Gaussians needs one weight per width ({widths} widths, {weights} weights)")]
    Weights {
        /// Number of widths.
        widths: usize,
        /// Number of weights.
        weights: usize,
    },
    /// Weights must be finite, non-negative and not all zero.
    #[error("kernel weights must be finite, non-negative and not all zero, got {weights:?}")]
    WeightValue {
        /// The weights given.
        weights: Vec<f64>,
    },
    /// The truncation tolerance must lie in (0, 1).
    #[error("truncation tolerance must lie in (0, 1), got {tol}")]
    Tolerance {
        /// The tolerance given.
        tol: f64,
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
    /// The spatial index of a truncated sum takes at most 2³² − 1 sources.
    #[error("{n} source points exceed the spatial index's capacity (2^32 - 1)")]
    TooManyPoints {
        /// Number of sources.
        n: usize,
    },
    /// Only sums of Gaussians have a grid path.
    #[error("only a Gaussian or a sum of at most 4 Gaussians can be summed on a grid")]
    GridProfile,
    /// The grid path's B-spline order is out of range.
    #[error("grid B-spline order must be 4, 6 or 8, got {order}")]
    GridOrder {
        /// The order given.
        order: usize,
    },
    /// The grid path takes 1 to `max` weight components per point.
    #[error("a grid sum takes 1 to {max} weight components per point, got {found}")]
    GridChannels {
        /// Components given.
        found: usize,
        /// The most the grid path takes.
        max: usize,
    },
    /// The points spread over more lattice nodes than the grid path
    /// allocates (points far apart for the spacing, or a diverging flow).
    #[error("the points span {nodes} lattice nodes of spacing {spacing}, more than a grid sum allocates")]
    GridTooLarge {
        /// Nodes the window would have (`usize::MAX`: beyond counting).
        nodes: usize,
        /// The lattice spacing.
        spacing: f64,
    },
    /// A point has a NaN or infinite coordinate.
    #[error("{what} {index} has a NaN or infinite coordinate")]
    NonFinite {
        /// Which point set.
        what: &'static str,
        /// Point index.
        index: usize,
    },
}
