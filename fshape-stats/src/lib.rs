//! Group statistics on functional shapes: where does a population's shape
//! or signal differ with a covariate (a group, an age), once an atlas has
//! put every subject in correspondence with a template.
//!
//! - [`maps`]: per-vertex maps of each subject on the template (signal
//!   change, normal momentum, normal displacement, log area change);
//! - [`design`]: the covariates table, the design matrix and contrasts, as
//!   FSL and PALM users write them;
//! - [`glm`]: a general linear model per vertex with Freedman–Lane
//!   permutations, family-wise error by the maximum statistic and, as an
//!   option, threshold-free cluster enhancement on the mesh ([`tfce`]); and
//!   the multivariate test (Hotelling–Lawley, T² for two groups) on the
//!   momenta's principal scores.
//!
//! Results are deterministic: the same seed gives the same bits for any
//! number of threads.
//!
//! ```
//! use fshape_stats::{Design, Inference, test_maps};
//! // Six subjects in two groups, one vertex where group 1 is higher.
//! let design = Design::from_matrix(
//!     vec!["intercept".into(), "group".into()],
//!     vec![1., 0., 1., 0., 1., 0., 1., 1., 1., 1., 1., 1.],
//! )?;
//! let contrast = design.contrast("group")?;
//! let maps = [0.1, -0.2, 0.05, 1.0, 1.2, 0.9];
//! let inference = Inference { permutations: 720, ..Inference::default() };
//! let test = test_maps(&design, &contrast, &maps, 1, None, &inference)?;
//! assert!(test.statistic[0] > 8.0);
//! // Only the observed grouping and its mirror reach that |t|:
//! // 2 × 3!·3! of the 720 orderings.
//! assert!((test.p_fwe[0] - 0.1).abs() < 0.035);
//! # Ok::<(), fshape_stats::StatsError>(())
//! ```

pub mod design;
pub mod glm;
mod linalg;
pub mod maps;
pub mod tfce;

pub use design::{Contrast, Covariates, Design, Term};
pub use glm::{Inference, MapTest, ScoresTest, StatKind, Tail, test_maps, test_maps_within, test_scores};
pub use maps::{Map, MapKind, subject_map, vertex_normals};
pub use tfce::{MeshGraph, TfceParams};

/// What can go wrong in a group test; each names the place.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StatsError {
    /// A cell or line of the covariates table is wrong.
    #[error("{table}, line {line}{}: {message}", column.as_ref().map_or(String::new(), |c| format!(", column `{c}`")))]
    Table {
        /// The table's path.
        table: String,
        /// 1-based line.
        line: usize,
        /// The column, when one is at fault.
        column: Option<String>,
        /// What is wrong.
        message: String,
    },
    /// A subject of the atlas has no row in the table.
    #[error("{table}: subject {subject} ({names}) has no row: give one row per subject, named by any of these")]
    MissingSubject {
        /// The table's path.
        table: String,
        /// The subject's index in the atlas.
        subject: usize,
        /// The names a row may call it by.
        names: String,
    },
    /// The design cannot be estimated (a constant or dependent column,
    /// too few subjects).
    #[error("design: {message}")]
    Design {
        /// What is wrong.
        message: String,
    },
    /// A contrast cannot be read or tested.
    #[error("contrast `{contrast}`: {message}")]
    Contrast {
        /// As given.
        contrast: String,
        /// What is wrong.
        message: String,
    },
    /// The maps or scores do not fit the design (counts, non-finite
    /// values, a map the template does not allow).
    #[error("maps: {message}")]
    Maps {
        /// What is wrong.
        message: String,
    },
    /// The inference's settings are out of range.
    #[error("inference: {message}")]
    Inference {
        /// What is wrong.
        message: String,
    },
}
