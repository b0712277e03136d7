//! The three factors of the product kernel: position k_p, signal k_f and
//! direction (Grassmannian) k_t.

use fshape_kernels::Kernel;

use crate::VarifoldError;

/// k_f, a function of v = (f − g)², the squared signal difference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SignalKernel {
    /// k_f ≡ 1: the purely geometric varifold or current (signals ignored).
    Constant,
    /// exp(−v / (2σ_f²)) (the project's width convention; fshapesTk's σ is
    /// this σ times √2).
    Gaussian {
        /// Width σ_f > 0.
        sigma: f64,
    },
}

/// k_t, a function of s = u·v, the dot product of two unit directions
/// (normals of surfaces, tangents of curves).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GrassKernel {
    /// s: currents (oriented; cancels opposite orientations).
    Linear,
    /// s²: the Binet kernel (unoriented varifolds).
    Binet,
    /// exp(−2(1 − s)/σ_t²) = exp(−|u − v|²/σ_t²): oriented varifolds.
    OrientedGaussian {
        /// Width σ_t > 0 (fshapesTk's form, kept as is).
        sigma: f64,
    },
    /// exp(−2(1 − s²)/σ_t²): unoriented varifolds.
    UnorientedGaussian {
        /// Width σ_t > 0 (fshapesTk's form, kept as is).
        sigma: f64,
    },
}

/// The product kernel of a (functional) varifold:
/// k((c, u, f), (c', u', f')) = k_p(|c − c'|²) · k_f((f − f')²) · k_t(u·u').
///
/// Every factor here is positive definite (k_t's Gaussians are power series
/// in s with non-negative coefficients), so A(X, Y) ≥ 0 for an untruncated
/// kernel. Truncation ([`VarifoldKernel::truncated`]) applies to k_p only;
/// since |k_f k_t| ≤ 1, each inner product then changes by at most
/// τ·k_p(0)·(Σ_τ r_τ)(Σ_σ r_σ), but the tapered k_p need not be positive
/// definite, so A can fall below 0 by that much.
#[derive(Clone, Debug, PartialEq)]
pub struct VarifoldKernel {
    position: Kernel,
    signal: SignalKernel,
    grass: GrassKernel,
}

impl VarifoldKernel {
    /// Combines the three factors, checking the widths of k_f and k_t (k_p's
    /// are checked when it is built).
    ///
    /// ```
    /// use fshape_kernels::Kernel;
    /// use fshape_varifold::{GrassKernel, SignalKernel, VarifoldKernel};
    /// let k = VarifoldKernel::try_new(Kernel::gaussian(5.0)?, SignalKernel::Gaussian { sigma: 0.5 }, GrassKernel::Binet)?;
    /// assert!(VarifoldKernel::try_new(Kernel::gaussian(5.0)?, SignalKernel::Gaussian { sigma: -1.0 }, GrassKernel::Binet).is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn try_new(position: Kernel, signal: SignalKernel, grass: GrassKernel) -> Result<Self, VarifoldError> {
        let check = |what, sigma: f64| {
            if sigma > 0.0 && sigma.is_finite() { Ok(()) } else { Err(VarifoldError::Width { what, sigma }) }
        };
        if let SignalKernel::Gaussian { sigma } = signal {
            check("signal kernel", sigma)?;
        }
        if let GrassKernel::OrientedGaussian { sigma } | GrassKernel::UnorientedGaussian { sigma } = grass {
            check("direction kernel", sigma)?;
        }
        Ok(VarifoldKernel { position, signal, grass })
    }

    /// The same kernel with k_p smoothly truncated at tolerance τ
    /// ([`Kernel::truncated`]).
    pub fn truncated(&self, tol: f64) -> Result<Self, VarifoldError> {
        Ok(VarifoldKernel { position: self.position.truncated(tol)?, ..self.clone() })
    }

    /// k_p.
    pub fn position(&self) -> &Kernel {
        &self.position
    }

    /// k_f.
    pub fn signal(&self) -> SignalKernel {
        self.signal
    }

    /// k_t.
    pub fn grass(&self) -> GrassKernel {
        self.grass
    }
}

impl SignalKernel {
    /// (k_f(v), k_f'(v)) for v = (f − g)².
    pub fn eval(self, v: f64) -> (f64, f64) {
        match self {
            SignalKernel::Constant => (1.0, 0.0),
            SignalKernel::Gaussian { sigma } => {
                let b = 0.5 / (sigma * sigma);
                let e = (-b * v).exp();
                (e, -b * e)
            }
        }
    }
}

impl GrassKernel {
    /// (k_t(s), k_t'(s)) for s = u·v.
    pub fn eval(self, s: f64) -> (f64, f64) {
        match self {
            GrassKernel::Linear => (s, 1.0),
            GrassKernel::Binet => (s * s, 2.0 * s),
            GrassKernel::OrientedGaussian { sigma } => {
                let c = 2.0 / (sigma * sigma);
                let e = (c * (s - 1.0)).exp();
                (e, c * e)
            }
            GrassKernel::UnorientedGaussian { sigma } => {
                let c = 2.0 / (sigma * sigma);
                let e = (c * (s * s - 1.0)).exp();
                (e, 2.0 * c * s * e)
            }
        }
    }

    /// Whether k_t(−s) = k_t(s): flipping a cell's orientation changes nothing.
    pub fn is_unoriented(self) -> bool {
        matches!(self, GrassKernel::Binet | GrassKernel::UnorientedGaussian { .. })
    }
}
