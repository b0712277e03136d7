//! The three factors of the product kernel: position k_p, signal k_f and
//! direction (Grassmannian) k_t.

use fshape_kernels::Kernel;

use crate::VarifoldError;

/// k_f, a function of the signal difference f − g ∈ ℝᵏ (k channels per
/// cell, [`crate::CellFeatures`]).
#[derive(Clone, Debug, PartialEq)]
pub enum SignalKernel {
    /// k_f ≡ 1: the purely geometric varifold or current (signals ignored).
    Constant,
    /// exp(−|f − g|² / (2σ_f²)), one width for every channel (the
    /// project's width convention; fshapesTk's σ is this σ times √2).
    Gaussian {
        /// Width σ_f > 0.
        sigma: f64,
    },
    /// Π_c exp(−(f_c − g_c)² / (2σ_c²)): a width per channel, for maps of
    /// different units (thickness in mm, myelin as a ratio). A product of
    /// positive definite kernels, so positive definite.
    Channels {
        /// Width σ_c > 0 of each channel; as many as the signal has.
        sigmas: Vec<f64>,
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
/// k((c, u, f), (c', u', f')) = k_p(|c − c'|²) · k_f(f − f') · k_t(u·u').
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
    /// Whether a masked region's geometry counts (the geometric part of a
    /// masked measure, [`crate::CellFeatures`]); true unless set.
    masked_geometry: bool,
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
        Ok(VarifoldKernel { position, signal: signal.checked()?, grass: grass.checked()?, masked_geometry: true })
    }

    /// The same kernel with k_p smoothly truncated at tolerance τ
    /// ([`Kernel::truncated`]).
    pub fn truncated(&self, tol: f64) -> Result<Self, VarifoldError> {
        Ok(VarifoldKernel { position: self.position.truncated(tol)?, ..self.clone() })
    }

    /// The same kernel where a masked region's geometry counts or not:
    /// with `false` the attachment of masked measures is the fvarifold of
    /// the mask-weighted masses alone (still a squared distance), and
    /// what is masked is free to lie anywhere. Unmasked measures are not
    /// concerned.
    pub fn with_masked_geometry(self, counts: bool) -> Self {
        VarifoldKernel { masked_geometry: counts, ..self }
    }

    /// Whether a masked region's geometry counts (default true).
    pub fn masked_geometry(&self) -> bool {
        self.masked_geometry
    }

    /// k_p.
    pub fn position(&self) -> &Kernel {
        &self.position
    }

    /// k_f.
    pub fn signal(&self) -> &SignalKernel {
        &self.signal
    }

    /// k_t.
    pub fn grass(&self) -> GrassKernel {
        self.grass
    }

    /// The same kernel without its signal factor (k_f = 1): the kernel of
    /// a masked measure's geometric part.
    pub(crate) fn geometric(&self) -> VarifoldKernel {
        VarifoldKernel { signal: SignalKernel::Constant, ..self.clone() }
    }
}

impl SignalKernel {
    /// k_f(f, g) for two signals of the same channel count (the obvious
    /// formula, for oracles and tests).
    pub fn eval(&self, f: &[f64], g: &[f64]) -> Result<f64, VarifoldError> {
        if f.len() != g.len() {
            return Err(VarifoldError::Channels { what: "signal values compared", expected: f.len(), found: g.len() });
        }
        let mut arg = 0.0;
        for (c, (a, b)) in f.iter().zip(g).enumerate() {
            if self.is_constant() {
                return Ok(1.0);
            }
            let sigma = self.width(c, f.len())?;
            arg -= (a - b) * (a - b) / (2.0 * sigma * sigma);
        }
        Ok(arg.exp())
    }

    /// Whether k_f ≡ 1 (signals not compared).
    pub fn is_constant(&self) -> bool {
        matches!(self, SignalKernel::Constant)
    }

    /// The width σ_c of channel `c` for signals of `channels` channels;
    /// an error when a per-channel kernel has another number of widths.
    pub fn width(&self, c: usize, channels: usize) -> Result<f64, VarifoldError> {
        match self {
            SignalKernel::Constant => Ok(f64::INFINITY),
            SignalKernel::Gaussian { sigma } => Ok(*sigma),
            SignalKernel::Channels { sigmas } if sigmas.len() == channels => Ok(sigmas[c]),
            SignalKernel::Channels { sigmas } => {
                Err(VarifoldError::Channels { what: "signal kernel widths", expected: channels, found: sigmas.len() })
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

/// Splits "name:args" and parses the comma-separated numbers of args.
fn parse_spec(what: &'static str, spec: &str, expected: &'static str) -> Result<(String, Vec<f64>), VarifoldError> {
    let bad = || VarifoldError::Parse { what, input: spec.to_string(), expected };
    let (name, args) = spec.split_once(':').unwrap_or((spec, ""));
    let nums = if args.is_empty() {
        Vec::new()
    } else {
        args.split(',').map(|a| a.trim().parse::<f64>().map_err(|_| bad())).collect::<Result<_, _>>()?
    };
    Ok((name.trim().to_ascii_lowercase(), nums))
}

impl VarifoldKernel {
    /// Parses the command line's kernel specifications:
    /// position `gaussian:σ`, `gaussian:σ1,σ2,…` (a sum with unit weights)
    /// or `cauchy:σ`; signal `gaussian:σ_f` or `None` (constant); direction
    /// `linear`, `binet`, `gaussian-oriented:σ_t` or `gaussian-unoriented:σ_t`.
    ///
    /// ```
    /// use fshape_varifold::{GrassKernel, SignalKernel, VarifoldKernel};
    /// let k = VarifoldKernel::parse("gaussian:5", Some("gaussian:0.3"), "gaussian-unoriented:0.5")?;
    /// assert_eq!(k.signal(), &SignalKernel::Gaussian { sigma: 0.3 });
    /// assert_eq!(k.grass(), GrassKernel::UnorientedGaussian { sigma: 0.5 });
    /// assert!(VarifoldKernel::parse("gauss:5", None, "binet").is_err());
    /// # Ok::<(), fshape_varifold::VarifoldError>(())
    /// ```
    pub fn parse(position: &str, signal: Option<&str>, grass: &str) -> Result<Self, VarifoldError> {
        let signal = match signal {
            None => SignalKernel::Constant,
            Some(spec) => SignalKernel::parse(spec)?,
        };
        VarifoldKernel::try_new(parse_position(position)?, signal, GrassKernel::parse(grass)?)
    }
}

/// Parses a position kernel k_p: `gaussian:σ`, `gaussian:σ1,σ2,…` (a sum
/// with unit weights) or `cauchy:σ`.
///
/// ```
/// let k = fshape_varifold::parse_position("gaussian:0.2,0.1")?;
/// assert_eq!(k.value(0.0), 2.0);
/// assert!(fshape_varifold::parse_position("gaussian:-1").is_err());
/// # Ok::<(), fshape_varifold::VarifoldError>(())
/// ```
pub fn parse_position(spec: &str) -> Result<Kernel, VarifoldError> {
    use fshape_kernels::Profile;
    const GEOM: &str = "gaussian:σ, gaussian:σ1,σ2,... or cauchy:σ";
    let (name, nums) = parse_spec("position kernel", spec, GEOM)?;
    let profile = match (name.as_str(), nums.as_slice()) {
        ("gaussian", [sigma]) => Profile::Gaussian { sigma: *sigma },
        ("gaussian", s) if s.len() > 1 => Profile::Gaussians { sigmas: s.to_vec(), weights: vec![1.0; s.len()] },
        ("cauchy", [sigma]) => Profile::Cauchy { sigma: *sigma },
        _ => return Err(VarifoldError::Parse { what: "position kernel", input: spec.to_string(), expected: GEOM }),
    };
    Kernel::try_new(&profile).map_err(|e| match e {
        fshape_kernels::KernelError::Width { sigma } => VarifoldError::Width { what: "position kernel", sigma },
        other => other.into(),
    })
}

impl SignalKernel {
    /// Parses `gaussian:σ_f` (one width for every channel) or
    /// `gaussian:σ_1,σ_2,…` (a width per channel), the widths checked.
    ///
    /// ```
    /// use fshape_varifold::SignalKernel;
    /// assert_eq!(SignalKernel::parse("gaussian:0.5,2")?, SignalKernel::Channels { sigmas: vec![0.5, 2.0] });
    /// assert!(SignalKernel::parse("gaussian:0.5,0").is_err());
    /// # Ok::<(), fshape_varifold::VarifoldError>(())
    /// ```
    pub fn parse(spec: &str) -> Result<SignalKernel, VarifoldError> {
        const SIG: &str = "gaussian:σ_f or gaussian:σ_1,σ_2,... (a width per channel)";
        let k = match parse_spec("signal kernel", spec, SIG)? {
            (name, nums) if name == "gaussian" && nums.len() == 1 => SignalKernel::Gaussian { sigma: nums[0] },
            (name, nums) if name == "gaussian" && nums.len() > 1 => SignalKernel::Channels { sigmas: nums },
            _ => return Err(VarifoldError::Parse { what: "signal kernel", input: spec.to_string(), expected: SIG }),
        };
        k.checked()
    }

    /// Itself if its width (if any) is positive and finite.
    fn checked(self) -> Result<SignalKernel, VarifoldError> {
        match &self {
            SignalKernel::Gaussian { sigma } => check_width("signal kernel", *sigma)?,
            SignalKernel::Channels { sigmas } => {
                if sigmas.is_empty() {
                    return Err(VarifoldError::Channels { what: "signal kernel widths", expected: 1, found: 0 });
                }
                for &sigma in sigmas {
                    check_width("signal kernel", sigma)?;
                }
            }
            SignalKernel::Constant => {}
        }
        Ok(self)
    }
}

impl GrassKernel {
    /// Parses `linear`, `binet`, `gaussian-oriented:σ_t` or
    /// `gaussian-unoriented:σ_t` (the width checked).
    pub fn parse(spec: &str) -> Result<GrassKernel, VarifoldError> {
        const GR: &str = "linear, binet, gaussian-oriented:σ_t or gaussian-unoriented:σ_t";
        let k = match parse_spec("direction kernel", spec, GR)? {
            (name, nums) if name == "linear" && nums.is_empty() => GrassKernel::Linear,
            (name, nums) if name == "binet" && nums.is_empty() => GrassKernel::Binet,
            (name, nums) if name == "gaussian-oriented" && nums.len() == 1 => {
                GrassKernel::OrientedGaussian { sigma: nums[0] }
            }
            (name, nums) if name == "gaussian-unoriented" && nums.len() == 1 => {
                GrassKernel::UnorientedGaussian { sigma: nums[0] }
            }
            _ => return Err(VarifoldError::Parse { what: "direction kernel", input: spec.to_string(), expected: GR }),
        };
        k.checked()
    }

    /// Itself if its width (if any) is positive and finite.
    fn checked(self) -> Result<GrassKernel, VarifoldError> {
        match self {
            GrassKernel::OrientedGaussian { sigma } | GrassKernel::UnorientedGaussian { sigma } => {
                check_width("direction kernel", sigma).map(|()| self)
            }
            GrassKernel::Linear | GrassKernel::Binet => Ok(self),
        }
    }
}

fn check_width(what: &'static str, sigma: f64) -> Result<(), VarifoldError> {
    if sigma > 0.0 && sigma.is_finite() { Ok(()) } else { Err(VarifoldError::Width { what, sigma }) }
}
