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
//! use fshape_mesh::generate::icosphere;
//! use fshape_shoot::{Config, Problem};
//! let model = Config::parse("[deformation]\nwidths = [0.5]\n")?.model()?;
//! let sphere = icosphere(1, 1.0);
//! let problem = Problem::new(&sphere, model)?;
//! // Zero momenta: nothing moves.
//! let traj = problem.shoot(&vec![0.0; 3 * sphere.n_vertices()], &vec![0.0; sphere.n_vertices()])?;
//! assert_eq!(traj.points(10), sphere.points());
//! # Ok::<(), fshape_shoot::ShootError>(())
//! ```

mod config;
mod dynamics;
pub mod matching;
pub mod optimize;
pub mod paper;
mod shoot;

pub use config::{
    AttachmentSection, Config, DeformationSection, IntegratorSection, ModelSection, OptimizerSection, ScheduleSection,
};
pub use dynamics::Timings;
pub use shoot::{Gradient, Objective, Problem, Trajectory};

use fshape_fem::Norm;
use fshape_kernels::Kernel;

/// Which model the signal follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// Metamorphosis: the signal evolves along the path, its change costed
    /// by D_s(x_t) on the moving shape.
    Metamorphosis,
    /// Tangential model: LDDMM geometry, signal residual on the template.
    Tangential,
    /// Pure LDDMM: the signal is carried unchanged.
    Lddmm,
}

/// Time integrator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Integrator {
    /// Classical fourth-order Runge–Kutta (default).
    Rk4,
    /// Explicit midpoint (second order; fshapesTk's scheme).
    Midpoint,
    /// Forward Euler.
    Euler,
}

/// A validated model (built by [`Config::model`]).
#[derive(Clone, Debug)]
pub struct Model {
    /// Metamorphosis, tangential or LDDMM.
    pub kind: ModelKind,
    /// The signal norm D_s.
    pub norm: Norm,
    /// γ_V.
    pub gamma_v: f64,
    /// γ_f.
    pub gamma_f: f64,
    /// γ_W.
    pub gamma_w: f64,
    /// Deformation kernel (a sum of Gaussians, exact or truncated).
    pub kernel: Kernel,
    /// Time integrator.
    pub integrator: Integrator,
    /// Number of time steps on [0, 1].
    pub steps: usize,
}

/// Why shooting or matching failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ShootError {
    /// The configuration is invalid (the message names the key).
    #[error("configuration: {0}")]
    Config(String),
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
    /// Matching needs a target ([`Problem::with_target`]).
    #[error("no target: matching needs Problem::with_target")]
    NoTarget,
}
