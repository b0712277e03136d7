//! The energy metric of the momenta: the metric the geodesic's energy
//! puts on p_0 (the kernel matrix, [`KernelFactor`]) and on p^f (the
//! signal norm's matrix, [`NormMatrix`]).
//!
//! The energy of a geodesic is ½γ_V p_0ᵀK(x_0)p_0 (+ the signal's part):
//! its Hessian in p_0 is γ_V K(x_0), the Gram matrix of the deformation
//! kernel on the template, constant during a stage. A Gaussian K is
//! nearly singular, so in the Euclidean metric of p_0 the energy is badly
//! conditioned, and the data term more so: its gradient reaches p_0
//! through K, twice smoothed (∂J/∂p_0 ≈ K ∂A/∂x_1 for short times, its
//! Hessian ≈ K A'' K). In the metric ⟨δp, K δp⟩ (the squared V-norm of the
//! velocity δv = K δp that a change δp makes) the energy's Hessian becomes
//! the identity and the data term's K^{1/2}A''K^{1/2}: the gradient is
//! K⁻¹∂J/∂p_0, whose velocity K·K⁻¹∂J/∂p_0 is the classical V-gradient of
//! LDDMM (Beg et al. 2005).
//!
//! It enters the optimiser as L-BFGS's initial inverse Hessian H_0 =
//! γ (K + λD_0⁻¹)⁻¹ (any positive definite H_0 keeps the method's
//! guarantees), applied by a dense Cholesky factor computed once per
//! template. The ridge keeps the factor well defined where K is
//! numerically singular (wide kernels on fine meshes), at the price of
//! treating directions of K-eigenvalue below it as L²; a ten times smaller
//! ridge made line searches fail on the bunny (docs/guide/src/experiments.md). The
//! factor costs n³/3 operations and n² values for n vertices, hence
//! [`MAX_VERTICES`]: a larger template takes a two-scale approximation of
//! the same inverse ([`TwoLevel`]), whose cost grows linearly with the
//! vertices ([`MomentumMetric`] is either).

use fshape_fem::{Norm, SignalNorm};
use fshape_kernels::Kernel;
use fshape_mesh::FShape;
use fshape_shoot::{DenseKernelFactor, ShootError};

/// The ridge's size, relative to k(0)·r_0^d ([`KernelFactor`]).
pub const RIDGE: f64 = 1.5e-4;

/// The largest template (vertices) whose kernel matrix is factored: 16384
/// vertices is 2 GiB and about 1.5·10¹² operations (the bunny's
/// 10242-vertex template: 800 MiB and 10 s serial on the 2-core machine of
/// docs/guide/src/experiments.md, less than one evaluation of J there).
pub const MAX_VERTICES: usize = 16384;

/// The Cholesky factor of K(x_0) + λD_0⁻¹, applying H_0's shape
/// (K + λD_0⁻¹)⁻¹ to the p_0 block of the optimiser's unknowns. In the
/// energy metric p_0 = c·q with c a constant (1, or the normalisation's
/// 1/L), and the shape leaves c out: K and λD_0⁻¹ are both the same for a
/// copy of the data scaled in length (kernel widths scaled alike), so the
/// first step, −(K + λD_0⁻¹)⁻¹∂J/∂q, is too, as the normalised weights
/// promise (tested).
///
/// The ridge λD_0⁻¹ (D_0 the template's lumped mass) is the discrete form
/// of λ∫ρ² for the density ρ that p_0 samples (p_i ≈ ρ(x_i)m_i), so it
/// regularises the same continuous operator at every resolution, where a
/// multiple of the identity would weigh less on finer meshes. Its size
/// λ = [`RIDGE`]·k(0)·r_0^d has the units of K's action on densities
/// (r_0: the radius where k falls to e^{−1/2}k(0), σ for a Gaussian; d:
/// the cells' dimension), so it is scale-free too.
///
/// The factor is fshape-shoot's [`DenseKernelFactor`] (serial, so the bits
/// do not depend on the number of threads).
#[derive(Debug)]
pub struct KernelFactor(DenseKernelFactor);

/// The radius where k falls to e^{−1/2}·k(0) (σ for a Gaussian of width σ).
fn half_width(kernel: &Kernel) -> f64 {
    let target = (-0.5f64).exp() * kernel.value(0.0);
    let mut hi = 1.0;
    while kernel.value(hi * hi) > target {
        hi *= 2.0;
    }
    while kernel.value(hi * hi / 4.0) <= target && hi > 1e-300 {
        hi /= 2.0;
    }
    let mut lo = hi / 2.0;
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if kernel.value(mid * mid) > target { lo = mid } else { hi = mid }
    }
    hi
}

impl KernelFactor {
    /// Factors K(x_0) + λD_0⁻¹ on `template`. `Ok(None)` when the template has more than [`MAX_VERTICES`]
    /// vertices or the factorisation meets a pivot that is not positive (a
    /// kernel that is not positive definite); an error where the lumped
    /// mass is not defined (a degenerate cell).
    pub fn new(template: &FShape, kernel: &Kernel) -> Result<Option<KernelFactor>, ShootError> {
        let (n, dim) = (template.n_vertices(), template.dim());
        if n > MAX_VERTICES {
            return Ok(None);
        }
        let masses = SignalNorm::try_new(template, Norm::L2Lumped)?.assemble(template.points())?;
        let lambda = KernelFactor::ridge(kernel, template.kind().dim());
        let ridge: Vec<f64> = masses.iter().map(|m| lambda / m).collect();
        Ok(KernelFactor::factor(template.points(), dim, kernel, &ridge))
    }

    /// The Cholesky factor of K + diag(`ridge`) on the points `points`
    /// (`dim` coordinates each); `None` where a pivot is not positive.
    pub(crate) fn factor(points: &[f64], dim: usize, kernel: &Kernel, ridge: &[f64]) -> Option<KernelFactor> {
        DenseKernelFactor::new(points, dim, kernel, ridge).map(KernelFactor)
    }

    /// The ridge λ of a kernel on cells of dimension `cell_dim`, without
    /// the masses: λD_0⁻¹ is added to K.
    pub fn ridge(kernel: &Kernel, cell_dim: usize) -> f64 {
        RIDGE * kernel.value(0.0) * half_width(kernel).powi(cell_dim as i32)
    }

    /// v ← (K + λD_0⁻¹)⁻¹v on the first n·dim values of `v` (the p_0
    /// block, each dimension alike); the rest is left as it is.
    pub fn apply(&self, v: &mut [f64]) {
        self.0.solve_in_place(v);
    }
}

/// The signal norm's matrix D_s(x_0) on the template, applying H_0's
/// shape D_s/m̄ (m̄ the mean lumped mass) to the p^f block: the signal
/// energy is ½ p^fᵀD_s⁻¹p^f/γ_f (ḟ = D_s⁻¹p^f/γ_f), Hessian D_s⁻¹/γ_f, so
/// the energy's metric turns the energy's Hessian into the identity, as
/// the kernel's does for p_0. For H¹ (D_s = M + ℓ²S) it undoes the
/// smoothing that D_s⁻¹ puts between p^f and the data term; for the lumped
/// L² norm it is the L² metric (D_s = D_0). In the energy metric p^f = c·q
/// with c a constant, left out like the kernel factor's; dividing by m̄
/// makes the shape the same for a copy of the data scaled in length.
/// With several signal channels D_s applies to each; their weights w_c
/// (γ_f w_c) are left out like c, so the Hessian is the identity up to a
/// constant per channel.
#[derive(Debug)]
pub struct NormMatrix {
    norm: SignalNorm,
    points: Vec<f64>,
    /// 1/m̄.
    inv_mean_mass: f64,
    /// Where the p^f block starts in the unknowns.
    offset: usize,
    /// Signal channels in the block (vertex by vertex); each gets D_s.
    channels: usize,
}

impl NormMatrix {
    /// D_s(x_0) of `norm` on `template`; the p^f block starts at `offset`.
    /// Fails where the norm does (a degenerate cell).
    pub fn new(template: &FShape, norm: Norm, offset: usize) -> Result<NormMatrix, ShootError> {
        let signal_norm = SignalNorm::try_new(template, norm)?;
        let points = template.points().to_vec();
        let masses = SignalNorm::try_new(template, Norm::L2Lumped)?.assemble(&points)?;
        let mean = masses.iter().sum::<f64>() / masses.len().max(1) as f64;
        // Once here, so that `apply` cannot fail later.
        signal_norm.matvec(&points, &masses)?;
        let channels = template.n_channels().max(1);
        Ok(NormMatrix { norm: signal_norm, points, inv_mean_mass: 1.0 / mean, offset, channels })
    }

    /// v ← (D_s/m̄) v on the p^f block of `v`, channel by channel.
    pub fn apply(&self, v: &mut [f64]) {
        let block = &mut v[self.offset..];
        let k = self.channels;
        if k == 1 {
            let out = self.norm.matvec(&self.points, block).expect("checked when built");
            block.iter_mut().zip(&out).for_each(|(x, o)| *x = o * self.inv_mean_mass);
            return;
        }
        for c in 0..k {
            let channel: Vec<f64> = block.iter().skip(c).step_by(k).copied().collect();
            let out = self.norm.matvec(&self.points, &channel).expect("checked when built");
            block.iter_mut().skip(c).step_by(k).zip(&out).for_each(|(x, o)| *x = o * self.inv_mean_mass);
        }
    }
}

/// How much larger [`TwoLevel`]'s coarse ridge is than the fine one: the
/// coarse kernel matrix meets the fine velocities' averages only
/// approximately, and its inverse scales what it misses by M_c/λ_c. On a
/// 2562-vertex sphere (the precondition tests), the energy H gives a
/// smooth momentum's velocity against the exact A⁻¹'s: 13× too large
/// with the fine ridge, 2.8× with ten times it, 1.2× with a hundred times
/// (while random vectors lose weight: 0.033, 0.0049, 0.00067 of A⁻¹'s).
/// At ten times the two ratios spread over a factor of 565, where the
/// Euclidean metric's spread over 45 000.
pub const COARSE_RIDGE: f64 = 10.0;

/// The number of vertices of [`TwoLevel`]'s coarse space: enough to
/// resolve the kernel's smooth modes on a cortex, small enough that its
/// dense factor costs a second.
pub const COARSE_VERTICES: usize = 4000;

/// The energy metric's operator for a template of any size, where a
/// dense factor of A = K + λD_0⁻¹ is out of reach (more than
/// [`MAX_VERTICES`] vertices): A⁻¹ on the scales a coarse mesh resolves,
///
/// ```text
/// H = Q E⁻¹ Qᵀ + (I − S)ᵀ B (I − S),   S = R Qᵀ,   B = diag(m_i / (k̂(0) + λ)),
/// ```
///
/// with a coarse space of [`COARSE_VERTICES`] vertices (the template
/// simplified, [`FShape::simplified`]). Each fine vertex i has a closest
/// point on the coarse mesh with barycentric coordinates φ_c(x_i). Q
/// carries coarse momenta to the fine vertices, Q_ic = m_i φ_c(x_i)/M_c
/// with M_c = Σ_i m_i φ_c(x_i) (a coarse momentum keeps its total), so Qᵀ
/// averages fine velocities onto the coarse vertices; R interpolates
/// coarse velocities at the fine vertices (R_ic = φ_c(x_i)). E is the
/// coarse K_c + λ M_c⁻¹ (≈ QᵀAQ), factored densely: Q E⁻¹ Qᵀ is A⁻¹ on
/// the modes the coarse mesh resolves. What the coarse velocities do not
/// interpolate, (I − S) v, is scaled by B, A⁻¹ on the smoothest mode (on
/// a momentum p_i = ρ(x_i) m_i with ρ of frequency ξ, A acts as
/// (k̂(ξ) + λ)/m_i, k̂ the kernel's Fourier transform): never more than
/// the coarse term gives a smooth mode, so nothing the coarse space
/// misrepresents is amplified. (A⁻¹ itself scales the finest modes by
/// m_i/λ: inverting it by conjugate gradients or by the balancing
/// preconditioner of domain decomposition multiplies any error of the
/// coarse solve by that; measured, a smooth field came back 10⁷ times too
/// large, and 10⁴ times with B at the coarse mesh's cutoff frequency.)
/// H is symmetric, positive definite and linear: a proper L-BFGS H_0. An
/// application costs a few sparse maps and one coarse solve, no kernel
/// sum.
pub struct TwoLevel {
    dim: usize,
    /// B's diagonal, per vertex.
    fine: Vec<f64>,
    /// Per fine vertex, its three coarse vertices, Q's entries and R's.
    corners: Vec<[u32; 3]>,
    weights: Vec<[f64; 3]>,
    bary: Vec<[f64; 3]>,
    coarse: KernelFactor,
    n_coarse: usize,
}

impl std::fmt::Debug for TwoLevel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TwoLevel").field("n", &self.fine.len()).field("coarse", &self.n_coarse).finish_non_exhaustive()
    }
}

/// k̂(0) = ∫_{R^d} k(|x|²) dx, the kernel's integral on `d`-dimensional
/// cells, by radial quadrature: 2∫_0^∞ k(r²) dr, or 2π∫_0^∞ k(r²) r dr.
fn integral(kernel: &Kernel, d: usize) -> f64 {
    let r_max = 12.0 * half_width(kernel);
    let steps = 4000;
    let dr = r_max / steps as f64;
    (0..=steps)
        .map(|i| {
            let r = i as f64 * dr;
            let w = if i == 0 || i == steps { 0.5 } else { 1.0 };
            let k = kernel.value(r * r);
            w * dr * if d == 1 { 2.0 * k } else { 2.0 * std::f64::consts::PI * k * r }
        })
        .sum()
}

impl TwoLevel {
    /// The two-level operator on `template` with the deformation kernel
    /// `kernel` and a coarse space of `coarse` vertices. `Ok(None)` where
    /// the coarse factor meets a pivot that is not positive; an error
    /// where the lumped mass is not defined.
    pub fn new(template: &FShape, kernel: &Kernel, coarse: usize) -> Result<Option<TwoLevel>, crate::MatchError> {
        let (n, dim, cell_dim) = (template.n_vertices(), template.dim(), template.kind().dim());
        let lumped = || SignalNorm::try_new(template, Norm::L2Lumped)?.assemble(template.points());
        let masses = lumped().map_err(|e: fshape_fem::FemError| crate::MatchError::Shoot(e.into()))?;
        let lambda = KernelFactor::ridge(kernel, cell_dim);
        let small = template
            .simplified(coarse.min(n))
            .map_err(|source| crate::MatchError::Simplify {
                what: "template".into(),
                vertices: coarse,
                stage: 0,
                source,
            })?
            .shape;
        let closest = crate::quality::ClosestPoints::new(&small)?;
        let k = small.kind().n_corners();
        let (mut corners, mut weights, mut bary) =
            (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
        let mut total = vec![0.0; small.n_vertices()];
        for (i, m) in masses.iter().enumerate() {
            let x = template.point(i);
            let c = closest.closest([x[0], x[1], if dim == 3 { x[2] } else { 0.0 }]);
            let ids = &small.cells()[c.cell * k..(c.cell + 1) * k];
            let mut corner = [0u32; 3];
            let mut weight = [0.0; 3];
            for (j, (&id, &b)) in ids.iter().zip(&c.bary).enumerate() {
                corner[j] = id as u32;
                weight[j] = m * b;
                total[id] += m * b;
            }
            corners.push(corner);
            weights.push(weight);
            bary.push(c.bary);
        }
        // Each coarse vertex is a fine one, whose closest point is itself:
        // a total without mass means a vertex without area.
        if let Some(c) = total.iter().position(|t| t.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)) {
            return Err(crate::MatchError::Degenerate(format!(
                "the energy metric's coarse vertex {c} carries no area (a vertex without cells?)"
            )));
        }
        for (corner, weight) in corners.iter().zip(&mut weights) {
            for (j, w) in weight.iter_mut().enumerate() {
                *w /= total[corner[j] as usize];
            }
        }
        let coarse_ridge: Vec<f64> = total.iter().map(|t| COARSE_RIDGE * lambda / t).collect();
        let Some(factor) = KernelFactor::factor(small.points(), dim, kernel, &coarse_ridge) else { return Ok(None) };
        let smoothest = integral(kernel, cell_dim) + lambda;
        Ok(Some(TwoLevel {
            dim,
            fine: masses.iter().map(|m| m / smoothest).collect(),
            corners,
            weights,
            bary,
            coarse: factor,
            n_coarse: small.n_vertices(),
        }))
    }

    /// Qᵀ v (`weights`) or Rᵀ v (`bary`): fine values summed onto the
    /// coarse vertices.
    fn down(&self, v: &[f64], by: &[[f64; 3]]) -> Vec<f64> {
        let d = self.dim;
        let mut c = vec![0.0; self.n_coarse * d];
        for (i, (corner, w)) in self.corners.iter().zip(by).enumerate() {
            for j in 0..3 {
                for k in 0..d {
                    c[corner[j] as usize * d + k] += w[j] * v[i * d + k];
                }
            }
        }
        c
    }

    /// Q c (`weights`) or R c (`bary`): coarse values onto the fine vertices.
    fn up(&self, c: &[f64], by: &[[f64; 3]]) -> Vec<f64> {
        let d = self.dim;
        let mut v = vec![0.0; self.fine.len() * d];
        for (i, (corner, w)) in self.corners.iter().zip(by).enumerate() {
            for j in 0..3 {
                for k in 0..d {
                    v[i * d + k] += w[j] * c[corner[j] as usize * d + k];
                }
            }
        }
        v
    }

    /// v ← H v on the first n·dim values of `v` (the p_0 block); the rest
    /// is left as it is.
    pub fn apply(&self, v: &mut [f64]) {
        let d = self.dim;
        let n = self.fine.len() * d;
        let r = &v[..n];
        let averaged = self.down(r, &self.weights);
        // (I − S)ᵀ B (I − S) r, S = R Qᵀ.
        let s = self.up(&averaged, &self.bary);
        let mut c = averaged;
        self.coarse.apply(&mut c);
        let coarse = self.up(&c, &self.weights);
        let b: Vec<f64> = r.iter().zip(&s).enumerate().map(|(i, (a, b))| self.fine[i / d] * (a - b)).collect();
        let back = self.up(&self.down(&b, &self.bary), &self.weights);
        for (i, o) in v[..n].iter_mut().enumerate() {
            *o = coarse[i] + b[i] - back[i];
        }
    }
}

/// The energy metric of p_0 ([`Unknowns::scaled`](crate::unknowns::Unknowns::scaled)):
/// the dense factor up to [`MAX_VERTICES`] vertices, the two-level
/// operator beyond.
#[derive(Debug)]
pub enum MomentumMetric {
    /// (K + λD_0⁻¹)⁻¹ by a dense Cholesky factor.
    Dense(KernelFactor),
    /// Its two-level approximation ([`TwoLevel`]).
    TwoLevel(TwoLevel),
}

impl MomentumMetric {
    /// The metric of `template` with `kernel`: dense where it fits, else
    /// two-level; `None` where a factor meets a non-positive pivot.
    pub fn new(template: &FShape, kernel: &Kernel) -> Result<Option<MomentumMetric>, crate::MatchError> {
        if template.n_vertices() <= MAX_VERTICES {
            return Ok(KernelFactor::new(template, kernel)?.map(MomentumMetric::Dense));
        }
        Ok(TwoLevel::new(template, kernel, COARSE_VERTICES)?.map(MomentumMetric::TwoLevel))
    }

    /// v ← H v on the p_0 block of `v`.
    pub fn apply(&self, v: &mut [f64]) {
        match self {
            MomentumMetric::Dense(f) => f.apply(v),
            MomentumMetric::TwoLevel(t) => t.apply(v),
        }
    }
}
