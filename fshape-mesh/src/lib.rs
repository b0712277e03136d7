//! Discrete functional shapes ("fshapes"): a mesh whose vertices carry one
//! real signal value each, as in Charon, Charlier & Trouvé, *Metamorphoses
//! of functional shapes in Sobolev spaces*, section 4.
//!
//! An fshape is X = (x, f, C): vertices x ∈ R^{P×n} (n = 2 or 3), cells
//! C ∈ {0..P}^{T×(d+1)} (segments, d = 1, or triangles, d = 2) and a signal
//! f ∈ R^P (optional: a purely geometric shape has none). This crate owns
//! that type and everything about it that needs no kernel or finite
//! element:
//!
//! - [`FShape`]: construction with checks, accessors, cell geometry (volumes
//!   r_τ, centres, area-weighted normals or tangents, lumped vertex volumes),
//!   [`FShape::topology`] (boundary, components, orientation).
//! - [`FShape::validate`]: every problem with its index, split into errors
//!   and warnings ([`Finding`], [`Severity`]), and [`FShape::repaired`].
//! - [`io`]: PLY, OBJ and VTK legacy readers and writers (ASCII and binary,
//!   gzip by magic bytes or `.gz`), per-vertex signal CSV, images (EXR, digit
//!   CSV). Parsers never panic or over-allocate on bad input, and report the
//!   file and line or byte offset; writers are atomic.
//! - [`FShape::simplified`]: any triangle mesh down to a vertex count,
//!   keeping a subset of its vertices with their signal (quadric error
//!   with a signal term), for coarse registration stages.
//! - [`generate`]: icospheres, Delaunay squares, circles, image grids.
//! - `test_support` (feature `test-support`): finite-difference checks,
//!   convergence orders and proptest strategies for the other fshape crates.
//!
//! Conventions: f64 everywhere; points and cells are flat row-major arrays;
//! triangles are counter-clockwise seen from their normal's side.
//!
//! ```
//! use fshape_mesh::generate::icosphere;
//! let sphere = icosphere(3, 1.0);
//! let area = sphere.total_volume();
//! // Inscribed in the unit sphere: the area is below 4π by O(h²), 0.06 at level 3.
//! assert!(area < 4.0 * std::f64::consts::PI && area > 4.0 * std::f64::consts::PI - 0.1);
//! assert!(sphere.topology().is_closed());
//! assert!(sphere.validate().is_clean());
//! ```

mod cell;
mod check;
mod coarsen;
mod geometry;
mod shape;
mod simplify;
mod topology;
mod validate;

pub mod generate;
pub mod io;
#[cfg(feature = "test-support")]
pub mod test_support;

pub use coarsen::CoarsenError;
pub use geometry::BoundingBox;
pub use shape::{CellKind, FShape, ShapeError};
pub use simplify::{MIN_QUALITY, Simplified, SimplifyError, SimplifyOptions};
pub use topology::{Facet, Topology};
pub use validate::{Finding, RepairLog, Repairs, Severity, Validation, ZERO_VOLUME_REL, summarise};
