//! Metamorphosis of functional shapes (paper section 4.3,
//! `../shared/DESIGN.md` "The discrete model"): the reduced Hamiltonian
//!
//! H(x, p, p^f) = 1/(2γ_V) Σ_{k,l} k(|x_k − x_l|²) p_k·p_l + 1/(2γ_f) p^fᵀ D_s(x)⁻¹ p^f,
//!
//! geodesic shooting of (x, f, p, p^f) with RK4, midpoint or Euler, and the
//! matching objective J(p_0, p^f) = H(x_0, p_0, p^f) + γ_W A(x_1, f_1; target)
//! with its **exact** gradient: the discrete adjoint of the integrator in
//! use, whose transposed Jacobian products come from the symplectic
//! identity dFᵀv = 𝕁 dF(𝕁v) and the analytic directional derivatives of
//! fshape-kernels and fshape-fem (not the paper's finite-difference trick).
//!
//! Baselines: pure LDDMM (the signal rides along unchanged) and the
//! tangential model (geometry by LDDMM; the signal residual ζ lives on the
//! template, f_1 = f_0 + ζ, cost (γ_f/2) ζᵀ D_s(x_0) ζ).
//!
//! ```
//! use fshape_kernels::Kernel;
//! use fshape_mesh::generate::icosphere;
//! use fshape_shoot::{Model, Problem};
//! let model = Model::new(Kernel::gaussian(0.5)?);
//! let sphere = icosphere(1, 1.0);
//! let problem = Problem::new(&sphere, model)?;
//! // Zero momenta: nothing moves.
//! let traj = problem.shoot(&vec![0.0; 3 * sphere.n_vertices()], &vec![0.0; sphere.n_vertices()])?;
//! assert_eq!(traj.points(10), sphere.points());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! [`Problem::transport`] carries momenta along a shooting by parallel
//! transport (the fanning scheme, with the integrator's exact
//! tangent-linear step).
//!
//! [`Regression`] fits one geodesic to several observations at their
//! times (geodesic regression), with the same exact adjoint.
//!
//! The configuration file, the optimiser and the registration workflow
//! (stages, checkpoints) are fshape-match's; this crate is the model.

mod dense;
mod dynamics;
mod model;
mod regression;
mod shoot;
mod transport;

pub use dense::DenseKernelFactor;
pub use dynamics::Timings;
pub use model::{DEFAULT_MAX_DRIFT, Integrator, Model, ModelKind};
pub use regression::{Regression, RegressionEnergies, RegressionGradient};
pub use shoot::{Energies, Gradient, Problem, Trajectory};
pub use transport::{MAX_TRANSPORT_VERTICES, Transported};

/// Why shooting or matching failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ShootError {
    /// A model parameter is out of range (the message names it).
    #[error("model: {what} {why}")]
    Invalid {
        /// Which parameter.
        what: &'static str,
        /// What is wrong with it.
        why: String,
    },
    /// A kernel sum refused its input.
    #[error(transparent)]
    Kernel(#[from] fshape_kernels::KernelError),
    /// The signal norm refused its input (e.g. a cell of zero volume).
    #[error(transparent)]
    Fem(#[from] fshape_fem::FemError),
    /// The data attachment refused its input.
    #[error(transparent)]
    Varifold(#[from] fshape_varifold::VarifoldError),
    /// A mesh could not be built.
    #[error(transparent)]
    Shape(#[from] fshape_mesh::ShapeError),
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
    /// An input value is NaN or infinite.
    #[error("{what} of vertex {index} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Vertex index.
        index: usize,
    },
    /// The state became NaN or infinite.
    #[error("shooting diverged at step {step} (NaN or infinite state); reduce the momenta or add time steps")]
    Diverged {
        /// The step.
        step: usize,
    },
    /// The flow degenerated a cell of the moving mesh (its signal norm is
    /// no longer defined).
    #[error(
        "shooting diverged at step {step}: the flow collapsed a cell ({source}); reduce the momenta or add time steps"
    )]
    Collapsed {
        /// The step.
        step: usize,
        /// The signal norm's error.
        source: fshape_fem::FemError,
    },
    /// The Hamiltonian, which a geodesic conserves, drifted by more than
    /// the model's tolerance: the integration is not to be trusted.
    #[error(
        "shooting diverged: the Hamiltonian drifted by {drift:.3e} of its initial value {initial:.3e} at step {step} \
         (tolerance {tolerance:e}); reduce the momenta or add time steps"
    )]
    Drift {
        /// max_k |H_k − H_0| / |H_0|.
        drift: f64,
        /// H_0.
        initial: f64,
        /// The first step where the drift is largest.
        step: usize,
        /// The model's tolerance ([`Model::max_drift`]).
        tolerance: f64,
    },
    /// Parallel transport cannot be done for this problem or input
    /// ([`Problem::transport`]).
    #[error("cannot transport: {why}")]
    CannotTransport {
        /// Why.
        why: String,
    },
    /// Parallel transport failed at a node of the trajectory
    /// ([`Problem::transport`]).
    #[error("transport failed at node {node}: {why}")]
    Transport {
        /// The node.
        node: usize,
        /// What went wrong.
        why: String,
    },
    /// Matching needs a target ([`Problem::with_target`]).
    #[error("no target: matching needs Problem::with_target")]
    NoTarget,
    /// Points of another dimension than the template's.
    #[error("{what}: {found} coordinates is not a whole number of {dim}-D points")]
    Points {
        /// Which array.
        what: &'static str,
        /// Its length.
        found: usize,
        /// The template's dimension.
        dim: usize,
    },
}
