//! Moving a solution between templates of different resolutions.
//!
//! The momenta p_0 and p^f are densities (see [`crate::unknowns`]): at a
//! vertex, p_i ≈ ρ(x_i)·m_i with ρ a density on the surface and m_i the
//! vertex's lumped area. What a coarse solution means is ρ, so the fine
//! momenta are the fine areas times ρ interpolated linearly from the
//! coarse mesh at each fine vertex (at its closest point on the coarse
//! mesh). Then the velocity field K p = Σ_j k(·, x_j) ρ(x_j) m_j and the
//! signal velocity D_s⁻¹ p^f/γ_f are two quadratures of the same
//! integrals, and the prolongated solution shoots to nearly the same end
//! (tested).
//!
//! The velocity field is only kept to the accuracy of that quadrature,
//! and a fine mesh sees what the coarse quadrature gets wrong: on the
//! bunny, a level-3 sphere's converged solution carried to level 4 so
//! shoots to an attachment ten times the coarse end's (docs/guide/src/experiments.md,
//! “a deep stage on the coarse sphere”). [`prolongate_fitted`] instead takes the fine p_0 whose
//! velocity at the fine vertices *is* the coarse solution's there, a
//! regularised least-squares fit; the stages of a [`crate::Session`] use it.

use fshape_kernels::Kernel;
use fshape_mesh::FShape;
use fshape_shoot::ModelKind;

use crate::MatchError;
use crate::precondition::{KernelFactor, MAX_VERTICES};
use crate::quality::ClosestPoints;

/// The fit's ridge ([`prolongate_fitted`]), relative to k(0) at a vertex
/// of the fine mesh's mean area.
pub const FIT_RIDGE: f64 = 1e-6;

/// The momenta of `coarse` carried to `fine` so that the deformation's
/// velocity field at the fine vertices is kept: p^f as in [`prolongate`]
/// (the signal's velocity is local), and the fine p_0 = q solving
///
/// (K_ff + ε·k(0)·m̄·D_f⁻¹) q = K_fc p_0,
///
/// with K_ff = k(x_i^f, x_j^f), K_fc = k(x_i^f, x_j^c) the deformation
/// kernel `kernel`'s matrices, D_f the fine lumped areas, m̄ their mean and
/// ε = [`FIT_RIDGE`]. Without the ridge, K_ff q = K_fc p_0 is the
/// velocity's interpolation at the fine vertices; K_ff is numerically
/// singular for a Gaussian wider than the mesh spacing, and the ridge (the
/// fit minimises ½qᵀK_ff q − qᵀK_fc p_0 + ½ε k(0) m̄ Σ q_i²/m_i, a penalty
/// on the density q_i/m_i) picks among the momenta of nearly equal
/// velocity the one of smallest density. Both terms scale alike with the
/// data, so the transfer is the same for a copy scaled in length.
///
/// Up to [`MAX_VERTICES`] fine vertices the solve is dense (a Cholesky
/// factor, n²/2 values and n³/3 operations, about 10 s for 10242
/// vertices on the machine of docs/guide/src/experiments.md). Beyond, it is
/// [`FIT_ITERATIONS`] steps of conjugate gradients on the kernel's fast
/// sums (its evaluation path for the fine template, as the fine stage's
/// shooting takes it), from the momenta carried as densities
/// ([`prolongate`]): each step costs one kernel sum, and conjugate
/// gradients reduce first the error along the kernel matrix's large
/// eigenvalues — the smooth part of the velocity, which the densities'
/// quadrature gets wrong — and leave the rest, which the ridge would
/// have kept small, as the densities had it. Where the dense factor
/// fails, p_0 is carried as a density.
pub fn prolongate_fitted(
    coarse: &FShape,
    fine: &FShape,
    p0: &[f64],
    pf: &[f64],
    kind: ModelKind,
    kernel: &Kernel,
) -> Result<(Vec<f64>, Vec<f64>), MatchError> {
    VelocityFit::new(fine, kernel)?.carry(coarse, p0, pf, kind)
}

/// The conjugate-gradient steps of [`prolongate_fitted`] beyond
/// [`MAX_VERTICES`] fine vertices.
pub const FIT_ITERATIONS: usize = 20;

/// [`prolongate_fitted`] onto one fine template, its factor computed
/// once for any number of coarse solutions (an atlas's subjects).
pub struct VelocityFit {
    fine: FShape,
    kernel: Kernel,
    /// How p_0 is fitted.
    solve: FitSolve,
}

/// How [`VelocityFit`] solves for the fine p_0.
enum FitSolve {
    /// The factor of K_ff + ε·k(0)·m̄·D_f⁻¹.
    Dense(KernelFactor),
    /// Conjugate gradients on the fine template's fast sums (`kernel`,
    /// its evaluation path for the fine points) with the ridge's diagonal
    /// ε·k(0)·m̄/m_i.
    Iterative { kernel: Kernel, ridge: Vec<f64> },
    /// No fit: the densities' transfer.
    Densities,
}

impl std::fmt::Debug for VelocityFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let solve = match self.solve {
            FitSolve::Dense(_) => "dense",
            FitSolve::Iterative { .. } => "iterative",
            FitSolve::Densities => "densities",
        };
        f.debug_struct("VelocityFit").field("n", &self.fine.n_vertices()).field("solve", &solve).finish_non_exhaustive()
    }
}

impl VelocityFit {
    /// Factors the fit's matrix on `fine` with the deformation kernel
    /// `kernel`. Fails where a fine vertex has no area (an unused vertex
    /// or a degenerate cell).
    pub fn new(fine: &FShape, kernel: &Kernel) -> Result<VelocityFit, MatchError> {
        let nf = fine.n_vertices();
        VelocityFit::with(fine, kernel, nf > MAX_VERTICES)
    }

    /// The fit large templates get ([`FIT_ITERATIONS`] steps of conjugate
    /// gradients), on a template of any size.
    pub fn iterative(fine: &FShape, kernel: &Kernel) -> Result<VelocityFit, MatchError> {
        VelocityFit::with(fine, kernel, true)
    }

    fn with(fine: &FShape, kernel: &Kernel, iterative: bool) -> Result<VelocityFit, MatchError> {
        let (nf, dim) = (fine.n_vertices(), fine.dim());
        let mf = fine.vertex_volumes();
        if let Some(v) = mf.iter().position(|m| m.is_nan() || *m <= 0.0) {
            return Err(MatchError::Degenerate(format!(
                "prolongation: fine vertex {v} has no area (unused or degenerate)"
            )));
        }
        let mean = mf.iter().sum::<f64>() / nf as f64;
        let scale = FIT_RIDGE * kernel.value(0.0) * mean;
        let ridge: Vec<f64> = mf.iter().map(|m| scale / m).collect();
        let solve = if iterative {
            let path = kernel.for_points(fine.points(), dim).map_err(fshape_shoot::ShootError::from)?;
            FitSolve::Iterative { kernel: path, ridge }
        } else {
            KernelFactor::factor(fine.points(), dim, kernel, &ridge).map_or(FitSolve::Densities, FitSolve::Dense)
        };
        Ok(VelocityFit { fine: fine.clone(), kernel: kernel.clone(), solve })
    }

    /// Whether p_0 is fitted (false: carried as a density).
    pub fn fits(&self) -> bool {
        !matches!(self.solve, FitSolve::Densities)
    }

    /// The momenta `p0`, `pf` of `coarse` carried to the fine template.
    pub fn carry(
        &self,
        coarse: &FShape,
        p0: &[f64],
        pf: &[f64],
        kind: ModelKind,
    ) -> Result<(Vec<f64>, Vec<f64>), MatchError> {
        let (q0, qf) = prolongate(coarse, &self.fine, p0, pf, kind)?;
        let dim = self.fine.dim();
        match &self.solve {
            FitSolve::Densities => Ok((q0, qf)),
            FitSolve::Dense(factor) => {
                // K_fc p_0: the coarse velocity at the fine vertices, a plain sum.
                let mut v = vec![0.0; q0.len()];
                for (x, out) in self.fine.points().chunks_exact(dim).zip(v.chunks_exact_mut(dim)) {
                    for (y, p) in coarse.points().chunks_exact(dim).zip(p0.chunks_exact(dim)) {
                        let u: f64 = x.iter().zip(y).map(|(a, b)| (a - b) * (a - b)).sum();
                        let k = self.kernel.value(u);
                        out.iter_mut().zip(p).for_each(|(o, p)| *o += k * p);
                    }
                }
                factor.apply(&mut v);
                Ok((v, qf))
            }
            FitSolve::Iterative { kernel, ridge } => {
                // K_fc p_0 with the fine stage's evaluation of the kernel.
                let to_fine = fshape_kernels::KernelSums::try_new(kernel, coarse.points(), dim)
                    .map_err(fshape_shoot::ShootError::from)?;
                let b = to_fine.conv(self.fine.points(), p0, dim).map_err(fshape_shoot::ShootError::from)?;
                let fine = fshape_kernels::KernelSums::try_new(kernel, self.fine.points(), dim)
                    .map_err(fshape_shoot::ShootError::from)?;
                let a = |q: &[f64]| -> Result<Vec<f64>, MatchError> {
                    let mut out = fine.conv(self.fine.points(), q, dim).map_err(fshape_shoot::ShootError::from)?;
                    for (i, o) in out.iter_mut().enumerate() {
                        *o += ridge[i / dim] * q[i];
                    }
                    Ok(out)
                };
                Ok((conjugate_gradients(a, &b, q0, FIT_ITERATIONS)?, qf))
            }
        }
    }
}

/// The coarse versions of `shape` that stages ask for: per stage, `shape`
/// simplified to `counts[k]` vertices ([`FShape::simplified`]), or `None`
/// (the shape itself) where the count is `None` or at least the shape's.
/// Each distinct count is simplified once, so stages of equal counts get
/// equal meshes (and share a problem). `what` names the shape in errors.
pub fn simplified_stages(
    shape: &FShape,
    counts: &[Option<usize>],
    what: &str,
) -> Result<Vec<Option<FShape>>, MatchError> {
    let mut made: Vec<(usize, FShape)> = Vec::new();
    let mut out = Vec::with_capacity(counts.len());
    for (stage, count) in counts.iter().enumerate() {
        let Some(&n) = count.as_ref().filter(|&&n| n < shape.n_vertices()) else {
            out.push(None);
            continue;
        };
        if let Some((_, m)) = made.iter().find(|(c, _)| *c == n) {
            out.push(Some(m.clone()));
            continue;
        }
        let coarse = shape
            .simplified(n)
            .map_err(|source| MatchError::Simplify { what: what.to_string(), vertices: n, stage, source })?
            .shape;
        made.push((n, coarse.clone()));
        out.push(Some(coarse));
    }
    Ok(out)
}

/// `steps` steps of conjugate gradients on A q = b (A symmetric positive
/// definite, applied by `a`) from `q`; serial dot products, so the bits
/// do not depend on the threads.
fn conjugate_gradients(
    a: impl Fn(&[f64]) -> Result<Vec<f64>, MatchError>,
    b: &[f64],
    mut q: Vec<f64>,
    steps: usize,
) -> Result<Vec<f64>, MatchError> {
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>();
    let aq = a(&q)?;
    let mut r: Vec<f64> = b.iter().zip(&aq).map(|(b, a)| b - a).collect();
    let mut d = r.clone();
    let mut rr = dot(&r, &r);
    for _ in 0..steps {
        if rr.is_nan() || rr <= 0.0 {
            break;
        }
        let ad = a(&d)?;
        let alpha = rr / dot(&d, &ad);
        if !alpha.is_finite() {
            break;
        }
        q.iter_mut().zip(&d).for_each(|(x, p)| *x += alpha * p);
        r.iter_mut().zip(&ad).for_each(|(x, p)| *x -= alpha * p);
        let next = dot(&r, &r);
        let beta = next / rr;
        d.iter_mut().zip(&r).for_each(|(p, x)| *p = x + beta * *p);
        rr = next;
    }
    Ok(q)
}

/// The momenta (p_0: P_c × n, p^f: P_c × k, k the coarse template's
/// signal channels) of `coarse` carried to `fine` (the same surface at
/// another resolution): fine areas times the coarse densities
/// interpolated at the fine vertices. For the tangential model (`kind`)
/// the signal control ζ is a function and is interpolated as one.
pub fn prolongate(
    coarse: &FShape,
    fine: &FShape,
    p0: &[f64],
    pf: &[f64],
    kind: ModelKind,
) -> Result<(Vec<f64>, Vec<f64>), MatchError> {
    let signal_density = kind != ModelKind::Tangential;
    let (nc, dim, k) = (coarse.n_vertices(), coarse.dim(), coarse.n_channels().max(1));
    if fine.dim() != dim || fine.kind() != coarse.kind() {
        return Err(MatchError::Kinds("prolongation: the coarse and fine templates differ".into()));
    }
    if p0.len() != nc * dim || pf.len() != nc * k {
        return Err(MatchError::InvalidInput(format!(
            "prolongation: {} and {} momentum values for a coarse template of {nc} vertices in R^{dim} and {k} signal channels",
            p0.len(),
            pf.len()
        )));
    }
    let (mc, mf) = (coarse.vertex_volumes(), fine.vertex_volumes());
    if let Some(v) = mc.iter().position(|m| m.is_nan() || *m <= 0.0) {
        return Err(MatchError::Degenerate(format!(
            "prolongation: coarse vertex {v} has no area (unused or degenerate)"
        )));
    }
    let density0: Vec<f64> = p0.iter().enumerate().map(|(i, p)| p / mc[i / dim]).collect();
    let densityf: Vec<f64> =
        if signal_density { pf.iter().enumerate().map(|(i, p)| p / mc[i / k]).collect() } else { pf.to_vec() };
    // Both densities in one pass of closest points: dim + k values a vertex.
    let both: Vec<f64> = density0
        .chunks_exact(dim)
        .zip(densityf.chunks_exact(k))
        .flat_map(|(d, f)| d.iter().chain(f))
        .copied()
        .collect();
    let rho = sample(coarse, fine, &both, dim + k)?;
    let (mut q0, mut qf) = (Vec::with_capacity(mf.len() * dim), Vec::with_capacity(mf.len() * k));
    for (r, m) in rho.chunks_exact(dim + k).zip(&mf) {
        q0.extend(r[..dim].iter().map(|r| m * r));
        qf.extend(r[dim..].iter().map(|r| if signal_density { m * r } else { *r }));
    }
    Ok((q0, qf))
}

/// `coarse`'s signal (and mask) read at `fine`'s vertices as [`sample`]
/// reads values, every channel alike (k values a vertex). With a mask m
/// the signal read is the mask-weighted mean Σ bᵢ mᵢ fᵢ / Σ bᵢ mᵢ of the
/// closest cell's corners (b the barycentric weights), so a masked
/// corner's missing value never enters; the mask read is Σ bᵢ mᵢ, 0 (and
/// the signal NaN) where every corner is masked, a soft edge in between.
pub fn sample_signal(coarse: &FShape, fine: &FShape) -> Result<(Vec<f64>, Option<Vec<f64>>), MatchError> {
    let signal = coarse.signal().ok_or_else(|| MatchError::InvalidInput("resampling: no signal to read".into()))?;
    let k = coarse.n_channels();
    let Some(mask) = coarse.mask() else {
        return Ok((sample(coarse, fine, signal, k)?, None));
    };
    let rows: Vec<f64> = signal
        .chunks_exact(k)
        .zip(mask)
        .flat_map(|(f, &m)| f.iter().map(move |&f| if m > 0.0 { m * f } else { 0.0 }).chain([m]))
        .collect();
    let read = sample(coarse, fine, &rows, k + 1)?;
    let mut out = Vec::with_capacity(fine.n_vertices() * k);
    let mut weights = Vec::with_capacity(fine.n_vertices());
    for r in read.chunks_exact(k + 1) {
        let m = r[k];
        out.extend(r[..k].iter().map(|f| if m > 0.0 { f / m } else { f64::NAN }));
        weights.push(if m > 0.0 { m.min(1.0) } else { 0.0 });
    }
    Ok((out, Some(weights)))
}

/// The piecewise-linear function of `coarse` with `width` values per
/// vertex (`values`, vertex-major) read at every vertex of `fine`, at its
/// closest point on `coarse`: `width` values per fine vertex.
pub fn sample(coarse: &FShape, fine: &FShape, values: &[f64], width: usize) -> Result<Vec<f64>, MatchError> {
    let dim = coarse.dim();
    if fine.dim() != dim || fine.kind() != coarse.kind() {
        return Err(MatchError::Kinds("resampling: the coarse and fine meshes differ".into()));
    }
    if values.len() != coarse.n_vertices() * width {
        return Err(MatchError::InvalidInput(format!(
            "resampling: {} values for {} vertices of {width} each",
            values.len(),
            coarse.n_vertices()
        )));
    }
    let closest = ClosestPoints::new(coarse)?;
    let k = coarse.kind().n_corners();
    let mut out = Vec::with_capacity(fine.n_vertices() * width);
    for v in 0..fine.n_vertices() {
        let x = fine.point(v);
        let c = closest.closest([x[0], x[1], if dim == 3 { x[2] } else { 0.0 }]);
        let ids = &coarse.cells()[c.cell * k..(c.cell + 1) * k];
        for axis in 0..width {
            out.push(ids.iter().zip(c.bary).map(|(&u, w)| w * values[u * width + axis]).sum());
        }
    }
    Ok(out)
}
