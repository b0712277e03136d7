//! Radial kernel profiles k(u) of the squared distance u = |x − y|², with
//! exact first and second derivatives, and the smooth truncation.

use crate::KernelError;
use crate::fast::{L, exp_lanes};
use crate::grid::{GRID_ORDERS, Grid};
use crate::taper::{GaussTerms, MAX_POWER, MAX_TERMS, Taper, quintic_taper, quintic_taper_derivatives};

/// A kernel profile as the user states it. Widths follow the project's one
/// convention: "a Gaussian of width σ" is exp(−u / (2σ²)). fshapesTk and
/// KeOps write exp(−u / σ²): their σ is ours times √2.
#[derive(Clone, Debug, PartialEq)]
pub enum Profile {
    /// exp(−u / (2σ²)).
    Gaussian {
        /// Width σ > 0.
        sigma: f64,
    },
    /// Σ_i w_i exp(−u / (2σ_i²)): a multi-scale deformation kernel.
    Gaussians {
        /// Widths σ_i > 0.
        sigmas: Vec<f64>,
        /// Weights w_i ≥ 0 (finite, not all zero), one per width.
        weights: Vec<f64>,
    },
    /// 1 / (1 + u/σ²).
    Cauchy {
        /// Width σ > 0.
        sigma: f64,
    },
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Term {
    /// w · exp(−a u), a = 1/(2σ²).
    Gauss { a: f64, w: f64 },
    /// 1 / (1 + c u), c = 1/σ².
    Cauchy { c: f64 },
}

/// How a kernel's sums are evaluated ([`Kernel::path`]); its `Display`
/// is the sentence reports use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SumPath {
    /// Every pair.
    Exact,
    /// Pairs within the support radius of a smooth taper.
    Truncated {
        /// The tolerance τ it was made for.
        tolerance: Option<f64>,
        /// The radius beyond which the kernel is 0.
        radius: f64,
    },
    /// Particle–mesh on a lattice ([`crate::grid`]).
    Grid {
        /// The tolerance τ the spacing was chosen for.
        tolerance: Option<f64>,
        /// The lattice spacing h.
        spacing: f64,
        /// The B-spline order.
        order: usize,
        /// The bound on the kernel's values, relative to k(0).
        bound: f64,
    },
}

impl std::fmt::Display for SumPath {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let tol = |t: &Option<f64>| t.map(|t| format!(", tolerance {t:e}")).unwrap_or_default();
        match self {
            SumPath::Exact => write!(f, "exact"),
            SumPath::Truncated { tolerance, radius } => write!(f, "truncated at radius {radius:.4}{}", tol(tolerance)),
            SumPath::Grid { tolerance, spacing, order, bound } => {
                write!(f, "grid of spacing {spacing:.4}, order {order}, bound {bound:.1e}{}", tol(tolerance))
            }
        }
    }
}

/// How much wider the outer taper radius is than the inner one.
pub const TAPER_WIDTH: f64 = 0.25;

/// A validated kernel: a sum of terms, optionally tapered to zero
/// ([`Kernel::truncated`]) or summed on a grid ([`Kernel::on_grid`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Kernel {
    terms: Vec<Term>,
    taper: Option<Taper>,
    grid: Option<Grid>,
    /// The error budget τ the kernel was truncated or gridded for.
    tolerance: Option<f64>,
}

impl Kernel {
    /// Validates a profile: every width positive and finite, weights finite
    /// and non-negative, not all zero, one weight per width.
    pub fn try_new(profile: &Profile) -> Result<Kernel, KernelError> {
        let width = |sigma: f64| {
            if sigma > 0.0 && sigma.is_finite() { Ok(sigma) } else { Err(KernelError::Width { sigma }) }
        };
        let terms = match profile {
            Profile::Gaussian { sigma } => vec![Term::Gauss { a: 0.5 / width(*sigma)?.powi(2), w: 1.0 }],
            Profile::Cauchy { sigma } => vec![Term::Cauchy { c: 1.0 / width(*sigma)?.powi(2) }],
            Profile::Gaussians { sigmas, weights } => {
                if sigmas.len() != weights.len() || sigmas.is_empty() {
                    return Err(KernelError::Weights { widths: sigmas.len(), weights: weights.len() });
                }
                if weights.iter().any(|w| !(w.is_finite() && *w >= 0.0)) || weights.iter().all(|&w| w == 0.0) {
                    return Err(KernelError::WeightValue { weights: weights.clone() });
                }
                sigmas
                    .iter()
                    .zip(weights)
                    .map(|(&s, &w)| Ok(Term::Gauss { a: 0.5 / width(s)?.powi(2), w }))
                    .collect::<Result<_, _>>()?
            }
        };
        Ok(Kernel { terms, taper: None, grid: None, tolerance: None })
    }

    /// A single Gaussian of width σ.
    pub fn gaussian(sigma: f64) -> Result<Kernel, KernelError> {
        Kernel::try_new(&Profile::Gaussian { sigma })
    }

    /// The same kernel, smoothly truncated for tolerance τ ∈ (0, 1): the
    /// taper starts at the radius r_in where k falls to τ·k(0) and ends at
    /// r_out = (1 + [`TAPER_WIDTH`])·r_in. Since k is decreasing, every pair
    /// the truncation changes has k ≤ τ·k(0), hence the per-output bound
    /// |out_i − exact_i| ≤ τ·k(0)·Σ_{j changed} |b_j|.
    pub fn truncated(&self, tol: f64) -> Result<Kernel, KernelError> {
        if !(tol > 0.0 && tol < 1.0) {
            return Err(KernelError::Tolerance { tol });
        }
        let base = Kernel { terms: self.terms.clone(), taper: None, grid: None, tolerance: None };
        let target = tol * base.value(0.0);
        // k is decreasing in u: bracket then bisect for k(u_in) = target.
        let mut hi = self
            .terms
            .iter()
            .map(|t| match *t {
                Term::Gauss { a, .. } => 1.0 / a,
                Term::Cauchy { c } => 1.0 / c,
            })
            .fold(0.0, f64::max);
        while base.value(hi) > target {
            hi *= 2.0;
        }
        let mut lo = 0.0;
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if base.value(mid) > target { lo = mid } else { hi = mid }
        }
        let r_in = hi.sqrt();
        let r_out = (1.0 + TAPER_WIDTH) * r_in;
        Ok(Kernel {
            terms: self.terms.clone(),
            taper: Some(Taper { u_in: r_in * r_in, u_out: r_out * r_out }),
            grid: None,
            tolerance: Some(tol),
        })
    }

    /// The same sum of Gaussians (untruncated) summed on a grid: the
    /// particle–mesh kernel k̃ of the module [`crate::grid`], with lattice
    /// spacing `spacing` and B-spline order `order` ∈ [`GRID_ORDERS`], in
    /// `dim` dimensions (the dimension sets the error bound,
    /// [`Grid::bound`]). Every sum of [`crate::KernelSums`] with this kernel
    /// is the grid's, and every derivative the exact derivative of k̃;
    /// [`Kernel::value`] and [`Kernel::derivatives`] stay the profile k
    /// that k̃ approximates. Cauchy kernels have no grid path.
    ///
    /// ```
    /// use fshape_kernels::{Kernel, KernelSums};
    /// let k = Kernel::gaussian(1.0)?;
    /// let g = k.on_grid(k.grid_spacing(1e-6, 4, 3)?, 4, 3)?;
    /// assert!(g.grid().unwrap().bound().value <= 1e-6);
    /// let (y, b) = ([0.0, 0.0, 0.0, 1.0, 0.5, -0.2], [1.0, 2.0]);
    /// let exact = KernelSums::try_new(&k, &y, 3)?.conv(&[0.3, 0.1, 0.0], &b, 1)?;
    /// let grid = KernelSums::try_new(&g, &y, 3)?.conv(&[0.3, 0.1, 0.0], &b, 1)?;
    /// assert!((grid[0] - exact[0]).abs() <= 1e-6 * 3.0);
    /// # Ok::<(), fshape_kernels::KernelError>(())
    /// ```
    pub fn on_grid(&self, spacing: f64, order: usize, dim: usize) -> Result<Kernel, KernelError> {
        let terms = self.gaussian_terms_untruncated().ok_or(KernelError::GridProfile)?;
        if !(spacing > 0.0 && spacing.is_finite()) {
            return Err(KernelError::Width { sigma: spacing });
        }
        if !GRID_ORDERS.contains(&order) {
            return Err(KernelError::GridOrder { order });
        }
        if dim != 2 && dim != 3 {
            return Err(KernelError::PointDimension { found: dim });
        }
        let grid = Some(Grid::new(&terms, spacing, order, dim));
        Ok(Kernel { terms: self.terms.clone(), taper: None, grid, tolerance: None })
    }

    /// The error budget τ of a kernel made by [`Kernel::truncated`] or
    /// chosen by [`Kernel::for_points`] (`None`: exact, or a grid of a
    /// spacing given by hand).
    pub fn tolerance(&self) -> Option<f64> {
        self.tolerance
    }

    /// The cheapest evaluation of this kernel's sums over `points` (`dim`
    /// coordinates each) as targets and sources, the shooting's sums,
    /// within the kernel's tolerance ([`Kernel::tolerance`]): exact,
    /// truncated ([`Kernel::truncated`]), or on a grid of order 4, 6 or 8
    /// at the spacing the tolerance allows ([`Kernel::grid_spacing`]),
    /// whichever [`predicted_seconds`] finds
    /// cheapest. A kernel without a tolerance is returned as it is: exact
    /// means exact. The choice depends only on the points and the kernel,
    /// so the same template always gets the same path; keep it while the
    /// points move (a shooting, an optimisation), so that one function is
    /// minimised. [`Kernel::path`] tells which was chosen.
    pub fn for_points(&self, points: &[f64], dim: usize) -> Result<Kernel, KernelError> {
        let Some(tol) = self.tolerance else { return Ok(self.clone()) };
        let truncated = self.truncated(tol)?;
        if self.gaussian_terms_untruncated().is_none() || !(dim == 2 || dim == 3) || points.is_empty() {
            return Ok(truncated);
        }
        let exact = Kernel { tolerance: Some(tol), ..self.untapered() };
        let mut best = (predicted_seconds(&exact, points, dim), exact);
        let trunc_cost = predicted_seconds(&truncated, points, dim);
        if trunc_cost < best.0 {
            best = (trunc_cost, truncated);
        }
        for order in GRID_ORDERS {
            let spacing = self.grid_spacing(tol, order, dim)?;
            let grid = Kernel { tolerance: Some(tol), ..self.on_grid(spacing, order, dim)? };
            let cost = predicted_seconds(&grid, points, dim);
            if cost < best.0 {
                best = (cost, grid);
            }
        }
        Ok(best.1)
    }

    /// The kernel without its taper or grid.
    fn untapered(&self) -> Kernel {
        Kernel { terms: self.terms.clone(), taper: None, grid: None, tolerance: None }
    }

    /// How the kernel's sums are evaluated, for reports.
    pub fn path(&self) -> SumPath {
        match (&self.grid, self.taper) {
            (Some(g), _) => SumPath::Grid {
                tolerance: self.tolerance,
                spacing: g.spacing(),
                order: g.order(),
                bound: g.bound().value,
            },
            (None, Some(t)) => SumPath::Truncated { tolerance: self.tolerance, radius: t.u_out.sqrt() },
            (None, None) => SumPath::Exact,
        }
    }

    /// The largest lattice spacing at which the grid path of order `order`
    /// in `dim` dimensions keeps its bounds ([`Grid::bound`]) within `tol`
    /// for the values and [`crate::grid::GRADIENT_SLACK`]·`tol` for the
    /// gradient: min_t σ_t·(h/σ)_p(τ), each Gaussian term then within them.
    pub fn grid_spacing(&self, tol: f64, order: usize, dim: usize) -> Result<f64, KernelError> {
        if !(tol > 0.0 && tol < 1.0) {
            return Err(KernelError::Tolerance { tol });
        }
        if !GRID_ORDERS.contains(&order) {
            return Err(KernelError::GridOrder { order });
        }
        if dim != 2 && dim != 3 {
            return Err(KernelError::PointDimension { found: dim });
        }
        let terms = self.gaussian_terms_untruncated().ok_or(KernelError::GridProfile)?;
        let sigma = terms.a[..terms.n].iter().map(|a| (0.5 / a).sqrt()).fold(f64::INFINITY, f64::min);
        Ok(sigma / crate::grid::ratio_for(tol, order, dim))
    }

    /// The grid, if the kernel is summed on one ([`Kernel::on_grid`]).
    pub fn grid(&self) -> Option<&Grid> {
        self.grid.as_ref()
    }

    /// The taper, if the kernel is truncated.
    pub fn taper(&self) -> Option<Taper> {
        self.taper
    }

    /// The radius beyond which the kernel is exactly zero (`None`: never).
    pub fn support_radius(&self) -> Option<f64> {
        self.taper.map(|t| t.u_out.sqrt())
    }

    /// k(u).
    ///
    /// ```
    /// let k = fshape_kernels::Kernel::gaussian(2.0)?;
    /// assert_eq!(k.value(0.0), 1.0);
    /// assert!((k.value(8.0) - (-1.0f64).exp()).abs() < 1e-15); // u = 2σ²
    /// # Ok::<(), fshape_kernels::KernelError>(())
    /// ```
    #[inline]
    pub fn value(&self, u: f64) -> f64 {
        self.derivatives(u)[0]
    }

    /// [k(u), k'(u), k''(u)], derivatives with respect to u.
    #[inline]
    pub fn derivatives(&self, u: f64) -> [f64; 3] {
        if let Some(t) = self.taper
            && u >= t.u_out
        {
            return [0.0; 3];
        }
        let mut k = [0.0; 3];
        for term in &self.terms {
            match *term {
                Term::Gauss { a, w } => {
                    let e = w * (-a * u).exp();
                    k[0] += e;
                    k[1] -= a * e;
                    k[2] += a * a * e;
                }
                Term::Cauchy { c } => {
                    let q = 1.0 / (1.0 + c * u);
                    k[0] += q;
                    k[1] -= c * q * q;
                    k[2] += 2.0 * c * c * q * q * q;
                }
            }
        }
        match self.taper {
            Some(t) if u > t.u_in => {
                let h = t.u_out - t.u_in;
                let x = (u - t.u_in) / h;
                // s, s' and s'' in u.
                let s = quintic_taper!(x);
                let (dx, ddx) = quintic_taper_derivatives(x);
                let (ds, dds) = (dx / h, ddx / (h * h));
                [k[0] * s, k[1] * s + k[0] * ds, k[2] * s + 2.0 * k[1] * ds + k[0] * dds]
            }
            _ => k,
        }
    }

    /// k(u) and k'(u) for the [`L`](crate::lanes::L) lanes of `u`, for
    /// vectorised block kernels in other crates (called inside a
    /// `pulp::WithSimd` body, it inlines and vectorises there). With
    /// `apply_taper` false the taper is skipped: only correct where every
    /// lane has u ≤ u_in ([`SourceRun::tapered`](crate::SourceRun)).
    /// Agrees with [`Kernel::derivatives`] to a few ulps (tested).
    #[inline(always)]
    pub fn lanes(&self, u: &[f64; L], apply_taper: bool) -> ([f64; L], [f64; L]) {
        let (mut k0, mut k1) = ([0.0; L], [0.0; L]);
        for term in &self.terms {
            match *term {
                Term::Gauss { a, w } => {
                    let mut arg = [0.0; L];
                    for l in 0..L {
                        arg[l] = -a * u[l];
                    }
                    let e = exp_lanes(arg);
                    for l in 0..L {
                        k0[l] += w * e[l];
                        k1[l] -= a * w * e[l];
                    }
                }
                Term::Cauchy { c } => {
                    for l in 0..L {
                        let q = 1.0 / (1.0 + c * u[l]);
                        k0[l] += q;
                        k1[l] -= c * q * q;
                    }
                }
            }
        }
        if let (Some(t), true) = (self.taper, apply_taper) {
            let (s, ds) = t.lanes(u);
            for l in 0..L {
                k1[l] = k1[l] * s[l] + k0[l] * ds[l];
                k0[l] *= s[l];
            }
        }
        (k0, k1)
    }

    /// For a sum of at most [`MAX_TERMS`] Gaussians, exact or truncated
    /// (the case with vectorised paths): the coefficients a_t = 1/(2σ_t²)
    /// and weights w_t (the taper is [`Kernel::taper`]).
    pub(crate) fn gaussian_terms(&self) -> Option<GaussTerms> {
        if self.terms.len() > MAX_TERMS {
            return None;
        }
        self.gaussian_terms_untruncated()
    }

    /// The terms of a sum of at most [`MAX_TERMS`] Gaussians, whatever its
    /// evaluation path.
    pub(crate) fn gaussian_terms_untruncated(&self) -> Option<GaussTerms> {
        if self.terms.len() > MAX_TERMS {
            return None;
        }
        let mut g =
            GaussTerms { a: [0.0; MAX_TERMS], w: [0.0; MAX_TERMS], n: 0, powers: None, floors: [0.0; MAX_TERMS] };
        for term in &self.terms {
            match *term {
                Term::Gauss { a, w } => {
                    g.a[g.n] = a;
                    g.w[g.n] = w;
                    g.n += 1;
                }
                Term::Cauchy { .. } => return None,
            }
        }
        if g.n > 1 {
            let base = g.a[..g.n].iter().copied().fold(f64::INFINITY, f64::min);
            let mut powers = [0u32; MAX_TERMS];
            let mut all = true;
            for ((a, power), floor) in g.a[..g.n].iter().zip(&mut powers).zip(&mut g.floors) {
                let r = a / base;
                let m = r.round();
                all &= (r - m).abs() <= 1e-12 * r && m <= MAX_POWER as f64;
                *power = m as u32;
                *floor = 1e-300f64.powf(1.0 / m.max(1.0));
            }
            if all {
                g.powers = Some(powers);
            }
        }
        Some(g)
    }

    /// For a single Gaussian w·exp(−a u) (the case with vectorised paths,
    /// and the one other crates fuse with their own exponential factors):
    /// its coefficient a = 1/(2σ²), weight w, and taper if truncated.
    pub fn single_gaussian(&self) -> Option<(f64, f64, Option<Taper>)> {
        match self.terms.as_slice() {
            [Term::Gauss { a, w }] => Some((*a, *w, self.taper)),
            _ => None,
        }
    }
}

/// The cost model behind [`Kernel::for_points`] (here, beside the choice
/// it serves, so that the grid need not know the kernel): seconds for one
/// fused self sum (K p and ∂_x(pᵀKp)/2, three weight components) over
/// `points`, with `kernel`'s path. The constants were measured on the
/// project's 2-core machine (AVX-512) with `cargo run --release -p
/// fshape-kernels --example grid_timing` on the 152 893 points of
/// pycortex's S1 cortex; only their ratios matter for the choice:
///
/// - exact: 0.77 ns a pair (each pair once, the symmetric path);
/// - truncated: 0.87 ns a pair within the support radius, counted at 64
///   sample targets;
/// - grid: 0.21 µs + 0.64 ns·p^d a point (spreading and interpolating),
///   plus 0.155 ns per filter tap and node along each axis, per channel
///   and Gaussian term (the convolution).
pub fn predicted_seconds(kernel: &Kernel, points: &[f64], dim: usize) -> f64 {
    const EXACT_PAIR: f64 = 0.77e-9;
    const TRUNCATED_PAIR: f64 = 0.87e-9;
    const GRID_POINT: f64 = 0.21e-6;
    const GRID_NODE: f64 = 0.64e-9;
    const GRID_TAP: f64 = 0.155e-9;
    let n = (points.len() / dim) as f64;
    if let Some(grid) = kernel.grid() {
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in points.chunks_exact(dim) {
            for a in 0..dim {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let p = grid.order() as f64;
        let along: Vec<f64> = (0..dim).map(|a| (hi[a] - lo[a]) / grid.spacing() + p).collect();
        let nodes: f64 = along.iter().product();
        let reach = 2.0 * grid.taps() as f64;
        let taps: f64 = along.iter().map(|&l| l.min(reach)).sum();
        let terms = grid.n_terms() as f64;
        return n * (GRID_POINT + GRID_NODE * p.powi(dim as i32)) + nodes * taps * 3.0 * terms * GRID_TAP;
    }
    let Some(r) = kernel.support_radius() else { return 0.5 * n * n * 2.0 * EXACT_PAIR };
    // The share of pairs within the radius, at 64 targets spread over the points.
    let m = points.len() / dim;
    let samples = m.min(64);
    let within: usize = (0..samples)
        .map(|k| {
            let xi = &points[k * m / samples * dim..][..dim];
            points
                .chunks_exact(dim)
                .filter(|y| y.iter().zip(xi).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() < r * r)
                .count()
        })
        .sum();
    n * (within as f64 / samples as f64) * TRUNCATED_PAIR
}
