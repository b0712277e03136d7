//! Inner products of (functional) varifolds, the data attachment A, and
//! their gradients.

use fshape_mesh::FShape;

use crate::engine::{channels, pair_sums, row_len};
use crate::features::pull_back;
use crate::{CellFeatures, FeatureGrad, VarifoldError, VarifoldKernel};

/// A(X, Y) = ⟨X,X⟩ − 2⟨X,Y⟩ + ⟨Y,Y⟩ with its three inner products.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Distance {
    /// A(X, Y) itself (a squared distance; not its square root).
    pub value: f64,
    /// ⟨μ_X, μ_X⟩.
    pub xx: f64,
    /// ⟨μ_X, μ_Y⟩.
    pub xy: f64,
    /// ⟨μ_Y, μ_Y⟩.
    pub yy: f64,
}

/// The gradient of A with respect to the source shape's vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeGrad {
    /// ∂A/∂x (n_vertices × dim, flat). Unused vertices get 0.
    pub points: Vec<f64>,
    /// ∂A/∂f (n_vertices × k); all 0 when the signal kernel is constant.
    pub signal: Vec<f64>,
}

fn compatible(x: &CellFeatures, y: &CellFeatures, k: &VarifoldKernel) -> Result<(), VarifoldError> {
    if (x.dim(), x.dir_len()) != (y.dim(), y.dir_len()) {
        return Err(VarifoldError::Incompatible {
            source_dim: x.dim(),
            source_dir: x.dir_len(),
            target_dim: y.dim(),
            target_dir: y.dir_len(),
        });
    }
    if !k.signal().is_constant() {
        for (which, f) in [("source", x), ("target", y)] {
            if f.signal().is_none() {
                return Err(VarifoldError::MissingSignal { which });
            }
        }
        if x.n_channels() != y.n_channels() {
            return Err(VarifoldError::Channels {
                what: "the target's signal against the source's",
                expected: x.n_channels(),
                found: y.n_channels(),
            });
        }
        k.signal().width(0, x.n_channels())?;
    }
    Ok(())
}

/// ⟨μ_X, μ_Y⟩ = Σ_τ Σ_σ r_τ r_σ k_p(|c_τ − c_σ|²) k_f(f_τ − f_σ) k_t(u_τ·u_σ).
///
/// ```
/// use fshape_kernels::Kernel;
/// use fshape_mesh::generate::circle;
/// use fshape_varifold::{CellFeatures, GrassKernel, SignalKernel, VarifoldKernel, inner_product};
/// // Two unit segments on the x axis, both oriented +x, at distance 1:
/// let x = CellFeatures::from_parts(2, vec![0.0, 0.0], vec![1.0, 0.0], vec![1.0], None)?;
/// let y = CellFeatures::from_parts(2, vec![1.0, 0.0], vec![1.0, 0.0], vec![1.0], None)?;
/// let k = VarifoldKernel::try_new(Kernel::gaussian(1.0)?, SignalKernel::Constant, GrassKernel::Linear)?;
/// let ip = inner_product(&x, &y, &k)?;
/// assert!((ip - (-0.5f64).exp()).abs() < 1e-15); // k_p(1) with σ = 1, k_t(1) = 1
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn inner_product(x: &CellFeatures, y: &CellFeatures, k: &VarifoldKernel) -> Result<f64, VarifoldError> {
    inner(x, y, k, false, true).map(|(v, _)| v)
}

/// ⟨μ_X, μ_Y⟩ and its gradient with respect to X's features.
pub fn inner_product_grad(
    x: &CellFeatures,
    y: &CellFeatures,
    k: &VarifoldKernel,
) -> Result<(f64, FeatureGrad), VarifoldError> {
    inner(x, y, k, true, true).map(|(v, g)| (v, g.expect("requested")))
}

/// With a mask on either side, the inner product of the two parts
/// ([`CellFeatures`]): ⟨X,Y⟩ = ⟨X_f, Y_f⟩ + ⟨X_g, Y_g⟩ with k_f on the
/// functional parts and no signal factor on the geometric ones, that is
/// the kernel k_p k_t (m m' k_f + (1 − m)(1 − m')): a sum of products of
/// positive definite kernels, so A stays a squared distance (without the
/// geometric term when [`VarifoldKernel::masked_geometry`] is off: k_p k_t
/// m m' k_f alone, still positive definite). The parts go
/// through the same pair engine as unmasked measures; an unmasked side
/// counts as share 1 everywhere, and all-ones masks give the same bits as
/// none.
fn inner(
    x: &CellFeatures,
    y: &CellFeatures,
    k: &VarifoldKernel,
    grad: bool,
    parallel: bool,
) -> Result<(f64, Option<FeatureGrad>), VarifoldError> {
    if x.mask().is_none() && y.mask().is_none() {
        return inner_plain(x, y, k, grad, parallel);
    }
    compatible(x, y, k)?;
    let ([(xf, xfi), (xg, xgi)], [(yf, _), (yg, _)]) = (x.split(), y.split());
    let geometric = k.geometric();
    let mut value = 0.0;
    let (d, du) = (x.dim(), x.dir_len());
    let nf = x.n_channels().max(1);
    let mut g = FeatureGrad::zeros(x);
    let share = x.mask();
    for (xp, idx, yp, kp, functional) in [(&xf, &xfi, &yf, k, true), (&xg, &xgi, &yg, &geometric, false)] {
        if xp.is_empty() || yp.is_empty() || (!functional && !k.masked_geometry()) {
            continue;
        }
        let (v, gp) = inner_plain(xp, yp, kp, grad, parallel)?;
        value += v;
        let Some(gp) = gp else { continue };
        for (i, &t) in idx.iter().enumerate() {
            // The part's mass is m r (or (1 − m) r): its derivative in r.
            let m = share.map_or(1.0, |m| if functional { m[t] } else { 1.0 - m[t] });
            g.weight[t] += m * gp.weight[i];
            for c in 0..d {
                g.centre[t * d + c] += gp.centre[i * d + c];
            }
            for c in 0..du {
                g.dir[t * du + c] += gp.dir[i * du + c];
            }
            // The geometric part's gradient in the signal is zero (one
            // channel of it, added as before for k = 1).
            if functional || nf == 1 {
                for c in 0..nf {
                    g.signal[t * nf + c] += gp.signal[i * nf + c];
                }
            }
        }
    }
    Ok((value, grad.then_some(g)))
}

fn inner_plain(
    x: &CellFeatures,
    y: &CellFeatures,
    k: &VarifoldKernel,
    grad: bool,
    parallel: bool,
) -> Result<(f64, Option<FeatureGrad>), VarifoldError> {
    compatible(x, y, k)?;
    let (d, du) = (x.dim(), x.dir_len());
    let (nf, _) = channels(x, k)?;
    let w = row_len(d, du, nf, grad);
    let rows = pair_sums(x, y, k, grad, parallel)?;
    let r = x.weights();
    // Summed in cell order: deterministic.
    let value = rows.chunks_exact(w).zip(r).map(|(row, ri)| ri * row[0]).sum();
    if !grad {
        return Ok((value, None));
    }
    // The gradient in the signal has the signal's shape (one channel of
    // zeros for a geometric kernel).
    let xf = x.n_channels().max(1);
    let mut g = FeatureGrad::zeros(x);
    for (i, row) in rows.chunks_exact(w).enumerate() {
        g.weight[i] = row[0];
        for c in 0..d {
            g.centre[i * d + c] = r[i] * row[1 + c];
        }
        for c in 0..du {
            g.dir[i * du + c] = r[i] * row[1 + d + c];
        }
        if nf == xf {
            for c in 0..nf {
                g.signal[i * nf + c] = r[i] * row[1 + d + du + c];
            }
        }
    }
    Ok((value, Some(g)))
}

/// The data attachment to a fixed target Y: A(X, Y) for any source X,
/// with ⟨Y,Y⟩ computed once (in a matching, once, not per iteration).
///
/// ```
/// use fshape_kernels::Kernel;
/// use fshape_mesh::generate::icosphere;
/// use fshape_varifold::{Attachment, GrassKernel, SignalKernel, VarifoldKernel};
/// let k = VarifoldKernel::try_new(Kernel::gaussian(0.5)?, SignalKernel::Constant, GrassKernel::Binet)?;
/// let target = icosphere(2, 1.0);
/// let att = Attachment::new(&target, k)?;
/// // A shape is at distance 0 from itself; a bigger sphere is not.
/// assert!(att.eval(&target)?.value.abs() < 1e-12 * att.target_self());
/// assert!(att.eval(&icosphere(2, 1.2))?.value > 0.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct Attachment {
    target: CellFeatures,
    kernel: VarifoldKernel,
    yy: f64,
    parallel: bool,
}

impl Attachment {
    /// Prepares A(·, target): computes the target's features and ⟨Y,Y⟩.
    pub fn new(target: &FShape, kernel: VarifoldKernel) -> Result<Self, VarifoldError> {
        Self::from_features(CellFeatures::of(target)?, kernel)
    }

    /// The same from features.
    pub fn from_features(target: CellFeatures, kernel: VarifoldKernel) -> Result<Self, VarifoldError> {
        // ⟨Y,Y⟩ below pairs the target with itself: say it is the target
        // that lacks a signal, not the "source" of that pairing.
        if !kernel.signal().is_constant() && target.signal().is_none() {
            return Err(VarifoldError::MissingSignal { which: "target" });
        }
        let (yy, _) = inner(&target, &target, &kernel, false, true)?;
        Ok(Attachment { target, kernel, yy, parallel: true })
    }

    /// Parallel (default) or serial evaluation; the results are identical.
    pub fn with_parallel(mut self, parallel: bool) -> Self {
        self.parallel = parallel;
        self
    }

    /// ⟨μ_Y, μ_Y⟩.
    pub fn target_self(&self) -> f64 {
        self.yy
    }

    /// The kernel.
    pub fn kernel(&self) -> &VarifoldKernel {
        &self.kernel
    }

    /// A(X, Y) and its inner products.
    pub fn eval(&self, x: &FShape) -> Result<Distance, VarifoldError> {
        self.eval_features(&CellFeatures::of(x)?)
    }

    /// A(X, Y) from X's features.
    pub fn eval_features(&self, x: &CellFeatures) -> Result<Distance, VarifoldError> {
        compatible(x, &self.target, &self.kernel)?;
        let (xx, _) = inner(x, x, &self.kernel, false, self.parallel)?;
        let (xy, _) = inner(x, &self.target, &self.kernel, false, self.parallel)?;
        Ok(Distance { value: xx - 2.0 * xy + self.yy, xx, xy, yy: self.yy })
    }

    /// A(X, Y) and its gradient with respect to X's features:
    /// ∂A = 2 ∂₁⟨X,X⟩ − 2 ∂₁⟨X,Y⟩ (the self term counts each cell twice).
    pub fn eval_grad_features(&self, x: &CellFeatures) -> Result<(Distance, FeatureGrad), VarifoldError> {
        compatible(x, &self.target, &self.kernel)?;
        let (xx, gxx) = inner(x, x, &self.kernel, true, self.parallel)?;
        let (xy, gxy) = inner(x, &self.target, &self.kernel, true, self.parallel)?;
        let (gxx, gxy) = (gxx.expect("requested"), gxy.expect("requested"));
        let comb = |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(p, q)| 2.0 * p - 2.0 * q).collect() };
        let g = FeatureGrad {
            centre: comb(&gxx.centre, &gxy.centre),
            dir: comb(&gxx.dir, &gxy.dir),
            weight: comb(&gxx.weight, &gxy.weight),
            signal: comb(&gxx.signal, &gxy.signal),
        };
        Ok((Distance { value: xx - 2.0 * xy + self.yy, xx, xy, yy: self.yy }, g))
    }

    /// A(X, Y) and its gradient with respect to X's vertex positions and
    /// vertex signal values (chain rule through the cell features).
    pub fn eval_grad(&self, x: &FShape) -> Result<(Distance, ShapeGrad), VarifoldError> {
        let (d, g) = self.eval_grad_features(&CellFeatures::of(x)?)?;
        let (points, signal) = pull_back(x, &g);
        Ok((d, ShapeGrad { points, signal }))
    }
}

/// A(X, Y) between two shapes (see [`Attachment`] to reuse the target).
pub fn distance(x: &FShape, y: &FShape, kernel: &VarifoldKernel) -> Result<Distance, VarifoldError> {
    Attachment::new(y, kernel.clone())?.eval(x)
}
