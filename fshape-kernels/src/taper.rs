//! What every evaluation path shares and no path owns: the quintic taper
//! of truncated kernels and the terms of a sum of Gaussians (kept apart
//! from `profile`, which chooses among the paths, so that the paths need
//! not import it back).

/// s(x) = 1 − (6x⁵ − 15x⁴ + 10x³) of the quintic taper, x = (u − u_in) /
/// (u_out − u_in) ∈ [0, 1]: the one formula every evaluation path uses,
/// written once for f64 and f32 (the literals take the type of `x`).
macro_rules! quintic_taper {
    ($x:expr) => {{
        let x = $x;
        1.0 - x * x * x * (10.0 + x * (-15.0 + 6.0 * x))
    }};
}
pub(crate) use quintic_taper;

/// ds/dx and d²s/dx² of [`quintic_taper!`] (multiply by 1/(u_out − u_in)
/// once or twice for the derivatives in u).
#[inline(always)]
pub(crate) fn quintic_taper_derivatives(x: f64) -> (f64, f64) {
    (-30.0 * x * x * (1.0 - x) * (1.0 - x), -60.0 * x * (1.0 - x) * (1.0 - 2.0 * x))
}

/// The C² taper of a truncated kernel: the profile is multiplied by
/// s(u) = 1 − S((u − u_in)/(u_out − u_in)), with S the quintic smoothstep
/// 6t⁵ − 15t⁴ + 10t³ (zero first and second derivatives at both ends), so
/// the truncated kernel is a C² function of u and exactly 0 beyond u_out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Taper {
    /// Squared radius where the taper starts: k(u_in) = τ·k(0).
    pub u_in: f64,
    /// Squared radius where the kernel reaches 0.
    pub u_out: f64,
}

/// The most Gaussian terms the vectorised exact paths take.
pub(crate) const MAX_TERMS: usize = 4;

/// The terms of a sum of Gaussians, Σ_t w_t exp(−a_t u).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GaussTerms {
    pub(crate) a: [f64; MAX_TERMS],
    pub(crate) w: [f64; MAX_TERMS],
    pub(crate) n: usize,
    /// When every a_t is an integer multiple m_t ≤ [`MAX_POWER`] of the
    /// smallest one (widths σ, σ/2, σ/√3, ...: the usual multi-scale
    /// kernels), `Some(m)`: then exp(−a_t u) = exp(−a_min u)^{m_t}, one
    /// exponential per pair instead of one per term.
    pub(crate) powers: Option<[u32; MAX_TERMS]>,
    /// Per term, 1e-300^{1/m_t}: below it the power is set to 0.
    pub(crate) floors: [f64; MAX_TERMS],
}

/// The largest integer ratio of widths² computed by powering.
pub(crate) const MAX_POWER: u32 = 16;
