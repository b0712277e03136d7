//! Sobolev norms of signals on moving meshes: ‖f‖²_{H^s(x)} = fᵀ D_s(x) f
//! (paper section 4.2, `../shared/DESIGN.md` "Signal norms").
//!
//! - [`Norm::L2Lumped`]: D_0 diagonal, (D_0)_kk = (1/(d+1)) Σ_{τ∋k} r_τ
//!   (paper eq. lump).
//! - [`Norm::L2`]: the exact P1 mass matrix (paper eq. l2p2: the
//!   edge-midpoint rule is exact for products of P1 functions), local matrix
//!   (r_τ/12)(1+δ_ij) on triangles and (r_τ/6)(1+δ_ij) on segments.
//! - [`Norm::H1`]: P1 mass + ℓ²·P1 stiffness, Σ_τ r_τ |∇f_τ|² (cotangent
//!   weights). The paper takes ℓ = 1; mass scales with length^d and stiffness
//!   with length^(d−2), so on a cortex in millimetres the gradient term is
//!   negligible unless ℓ is set to a length of the data's scale.
//!
//! The metamorphosis dynamics need, for a moving x: solves D_s(x) h = b
//! ([`Solver`]: the Cholesky analysis is done once per connectivity, the
//! numeric factorisation per x), the gradient ∂_x(aᵀ D_s(x) b)
//! ([`SignalNorm::grad`]), its directional derivative (a Hessian–vector
//! product, [`SignalNorm::hvp`]) and (∂_x D_s · δx) h
//! ([`SignalNorm::dmatvec`]). The gradient is analytic per cell; the
//! second derivatives are forward-mode dual numbers (num-dual, x + ε δx)
//! through the generic per-cell formulas: the local matrix for `dmatvec`,
//! the analytic gradient for `hvp` (nested duals through the local matrix
//! are its test oracle: with them the FEM part of one H¹ evaluation of the
//! bunny's objective at 10242 vertices took 2.0 s instead of 1.1). All are exact and checked against central finite differences
//! in the tests.
//!
//! Local work runs cell by cell (in parallel with rayon unless
//! [`SignalNorm::with_parallel`] turns it off) and is gathered per output
//! index in a fixed order; the assembly of D_s is one serial scatter in cell
//! order. Serial and parallel results are equal bit for bit.
//!
//! ```
//! use fshape_fem::{Norm, SignalNorm};
//! use fshape_mesh::{CellKind, FShape};
//! // One unit right triangle: ∫ f² for f ≡ 1 is its area, 1/2.
//! let s = FShape::try_new(2, CellKind::Triangle, vec![0., 0., 1., 0., 0., 1.], vec![0, 1, 2], None)?;
//! let d = SignalNorm::try_new(&s, Norm::L2)?;
//! let q = d.quadratic(s.points(), &[1.0, 1.0, 1.0])?;
//! assert!((q - 0.5).abs() < 1e-15);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod local;
mod norm;
mod ordering;
mod solver;

pub use norm::{FillOrdering, SignalNorm, Workspace};
pub use solver::Solver;

/// Which signal norm D_s(x) to use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Norm {
    /// L² with mass lumping: a diagonal matrix.
    L2Lumped,
    /// L² with the exact P1 mass matrix.
    L2,
    /// H¹: P1 mass + `length`² × P1 stiffness.
    H1 {
        /// The length scale ℓ weighting the gradient term (paper: 1). Must
        /// be positive and finite.
        length: f64,
    },
}

impl Norm {
    /// The name used on the command line: `l2-lumped`, `l2`, `h1`.
    pub fn name(&self) -> &'static str {
        match self {
            Norm::L2Lumped => "l2-lumped",
            Norm::L2 => "l2",
            Norm::H1 { .. } => "h1",
        }
    }

    /// Parses `l2-lumped`, `l2` or `h1`; `length` is ℓ for H¹.
    pub fn parse(name: &str, length: f64) -> Result<Norm, FemError> {
        match name {
            "l2-lumped" => Ok(Norm::L2Lumped),
            "l2" => Ok(Norm::L2),
            "h1" => Ok(Norm::H1 { length }),
            _ => Err(FemError::UnknownNorm { name: name.to_string() }),
        }
    }
}

/// Why a signal-norm operation failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FemError {
    /// The norm's name is not one of `l2-lumped`, `l2`, `h1`.
    #[error("unknown signal norm `{name}` (expected l2-lumped, l2 or h1)")]
    UnknownNorm {
        /// The name given.
        name: String,
    },
    /// ℓ is not positive and finite.
    #[error("the H1 length scale must be positive and finite, got {length}")]
    Length {
        /// The value given.
        length: f64,
    },
    /// An input vector has the wrong length for the mesh.
    #[error("{what} has {found} entries; the mesh needs {expected}")]
    Dimension {
        /// Which input.
        what: &'static str,
        /// Required length.
        expected: usize,
        /// Length given.
        found: usize,
    },
    /// A cell has (numerically) zero volume where the operation needs a
    /// positive one: the stiffness matrix (cotangents) and every x-derivative
    /// are undefined there. Repair: drop zero-volume cells
    /// (`FShape::repaired`, or `fshape convert --repair`).
    #[error(
        "cell {cell} has zero volume ({volume:e}); the {what} is undefined there: drop zero-volume cells first (fshape convert --repair)"
    )]
    ZeroVolumeCell {
        /// Cell index.
        cell: usize,
        /// Its volume.
        volume: f64,
        /// What could not be computed.
        what: &'static str,
    },
    /// D_s(x) is singular: this vertex carries no mass (it is unused, or
    /// all its cells have zero volume). Repair: drop unused vertices and
    /// zero-volume cells.
    #[error(
        "the signal norm matrix is singular at vertex {vertex}, which carries no mass (unused or only in zero-volume cells): drop unused vertices and zero-volume cells first"
    )]
    Singular {
        /// Vertex index.
        vertex: usize,
    },
    /// The sparse Cholesky factorisation failed although every vertex
    /// carries mass (this indicates severe ill-conditioning).
    #[error("Cholesky factorisation failed: {message}")]
    Factorisation {
        /// faer's report.
        message: String,
    },
    /// The matrix would have more stored entries than the assembly's
    /// 32-bit entry index can address (a mesh of over a billion cells).
    #[error("the signal norm matrix would have {entries} stored entries, more than the 4294967294 supported")]
    TooLarge {
        /// Stored entries of the lower triangle.
        entries: usize,
    },
    /// [`Solver::solve`] was called before a successful [`Solver::factor`].
    #[error("solve called before a successful factorisation")]
    NotFactored,
}
