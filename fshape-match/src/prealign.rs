//! Pre-alignment: the rigid motion, similarity or affine map T that brings
//! a source closest to a target in the data attachment, before a
//! registration (`[prealign]`). Subjects scanned in different frames are
//! brought into one; the deformation then only has to explain the shape.
//!
//! T(x) = M (x − c) + c + t, with c the source's centroid, is found by
//! minimising A(T(X), Y) (the configured functional varifold: positions,
//! directions and signal; the signal is carried, not changed) with
//! L-BFGS over t, the rotation, the log-scale and (affine) M itself, from
//! several starts, as H2_SurfaceMatch and py-lddmm start a varifold rigid
//! fit: the rotations that take the source's principal axes to the
//! target's, composed with every rotation of the cube's group (24 in 3-D,
//! 4 in the plane), so that the axes' order and signs, which the
//! principal axes leave open, are all tried. A rotation is R₀ Exp(ω) (ω
//! a rotation vector; its gradient through SO(3)'s right Jacobian, Solà
//! et al., "A micro Lie theory", eq. 143), a scale s₀ e^σ, a translation
//! t₀ + L τ with L the source's diagonal. The starts are compared on
//! copies of at most [`START_VERTICES`] vertices (simplified surfaces):
//! [`START_ITERATIONS`] iterations each, then the [`FINALISTS`] best to
//! convergence; the best of those is refined on the shapes themselves,
//! or on copies of [`REFINE_VERTICES`] vertices when they are larger.

use fshape_mesh::FShape;
use fshape_varifold::{Attachment, VarifoldKernel};
use serde::{Deserialize, Serialize};

use crate::MatchError;
use crate::optimize::{Method, Settings, State, Stop};

/// Which map a pre-alignment looks for (`[prealign] kind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AlignKind {
    /// No pre-alignment (the default).
    #[default]
    None,
    /// A rotation and a translation.
    Rigid,
    /// A rotation, a translation and a uniform scale.
    Similarity,
    /// A linear map and a translation (the similarity first, then refined).
    Affine,
}

impl AlignKind {
    /// The configuration's spelling: `none`, `rigid`, `similarity`, `affine`.
    pub fn name(self) -> &'static str {
        match self {
            AlignKind::None => "none",
            AlignKind::Rigid => "rigid",
            AlignKind::Similarity => "similarity",
            AlignKind::Affine => "affine",
        }
    }
}

/// Which shape the map moves (`[prealign] move`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Moving {
    /// T moves the source onto the target: the registration runs, and its
    /// results are, in the target's frame (the default).
    #[default]
    Source,
    /// T⁻¹ moves the target onto the source: the results are in the
    /// source's frame.
    Target,
}

impl Moving {
    /// Its name in the configuration (`source`, `target`).
    pub fn name(self) -> &'static str {
        match self {
            Moving::Source => "source",
            Moving::Target => "target",
        }
    }
}

/// `[prealign]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PrealignSection {
    /// none | rigid | similarity | affine (default none).
    pub kind: AlignKind,
    /// source | target: which shape is moved (default source).
    #[serde(rename = "move")]
    pub moving: Moving,
    /// L-BFGS iterations per start, and for the refinement (default 100).
    pub max_iterations: usize,
}

impl Default for PrealignSection {
    fn default() -> Self {
        PrealignSection { kind: AlignKind::None, moving: Moving::Source, max_iterations: 100 }
    }
}

/// The starts are compared on copies of at most this many vertices.
pub const START_VERTICES: usize = 500;

/// Every start first runs this many iterations; the best [`FINALISTS`]
/// then run to convergence on the coarse copies.
pub const START_ITERATIONS: usize = 15;

/// How many starts run on after their first iterations.
pub const FINALISTS: usize = 3;

/// The best start is refined on copies of at most this many vertices
/// (the shapes themselves up to this size): seven parameters need no
/// more, and an exact attachment on a 150k-vertex cortex would cost
/// 10¹⁰ kernel pairs an evaluation.
pub const REFINE_VERTICES: usize = 4000;

/// A pre-alignment's result: T(x) = `matrix` · (x, 1), taking the source's
/// frame to the target's, and how close it brought them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Alignment {
    /// What was looked for.
    pub kind: AlignKind,
    /// Which shape the registration moved (T on the source, or T⁻¹ on the
    /// target).
    pub moving: Moving,
    /// T as a homogeneous (dim + 1) × (dim + 1) matrix, row-major (4 × 4
    /// in 3-D, 3 × 3 in the plane): the linear part and the translation.
    pub matrix: Vec<Vec<f64>>,
    /// The scale (the linear part's determinant to the power 1/dim).
    pub scale: f64,
    /// The rotation's angle in degrees: of the linear part divided by its
    /// scale (the rotation itself for a rigid or similarity map; only
    /// indicative for an affine one).
    pub rotation_degrees: f64,
    /// The translation of the source's centroid.
    pub translation: Vec<f64>,
    /// A(X, Y) before and A(T(X), Y) after (on the copies of at most
    /// [`REFINE_VERTICES`] vertices the map was refined on).
    pub attachment_before: f64,
    /// See `attachment_before`.
    pub attachment_after: f64,
    /// Which of the starts won (its index), of how many.
    pub start: usize,
    /// See `start`.
    pub starts: usize,
}

impl Alignment {
    /// In a few words: the rotation, the scale and the data term before
    /// and after.
    pub fn describe(&self) -> String {
        format!(
            "rotation {:.1} deg, scale {:.3}, data term {:.3e} -> {:.3e} (start {} of {})",
            self.rotation_degrees,
            self.scale,
            self.attachment_before,
            self.attachment_after,
            self.start + 1,
            self.starts
        )
    }

    /// The linear part M and the translation b of T(x) = M x + b.
    pub fn linear_and_offset(&self) -> (Vec<f64>, Vec<f64>) {
        let d = self.matrix.len() - 1;
        let m = (0..d).flat_map(|i| self.matrix[i][..d].to_vec()).collect();
        let b = (0..d).map(|i| self.matrix[i][d]).collect();
        (m, b)
    }

    /// `shape` moved by T.
    pub fn apply(&self, shape: &FShape) -> Result<FShape, MatchError> {
        let (m, b) = self.linear_and_offset();
        Ok(shape.clone().with_points(transform(shape.points(), shape.dim(), &m, &b))?)
    }

    /// `shape` moved by T⁻¹ (for results in the source's frame).
    pub fn apply_inverse(&self, shape: &FShape) -> Result<FShape, MatchError> {
        let (m, b) = self.linear_and_offset();
        let d = shape.dim();
        let inv = inverse(&m, d).ok_or_else(|| MatchError::Degenerate("the pre-alignment's map is singular".into()))?;
        let nb: Vec<f64> = (0..d).map(|i| -(0..d).map(|j| inv[i * d + j] * b[j]).sum::<f64>()).collect();
        Ok(shape.clone().with_points(transform(shape.points(), d, &inv, &nb))?)
    }
}

/// Points moved by x ↦ m x + b (m row-major d × d).
fn transform(points: &[f64], d: usize, m: &[f64], b: &[f64]) -> Vec<f64> {
    points
        .chunks_exact(d)
        .flat_map(|x| (0..d).map(move |i| (0..d).map(|j| m[i * d + j] * x[j]).sum::<f64>() + b[i]))
        .collect()
}

/// The inverse of a 2 × 2 or 3 × 3 matrix, `None` when singular.
fn inverse(m: &[f64], d: usize) -> Option<Vec<f64>> {
    let det = determinant(m, d);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    Some(if d == 2 {
        vec![m[3] / det, -m[1] / det, -m[2] / det, m[0] / det]
    } else {
        let c = |i: usize, j: usize| m[i * 3 + j];
        let mut out = vec![0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                // The cofactor of (j, i), over the determinant.
                let (a, b) = ((j + 1) % 3, (j + 2) % 3);
                let (p, q) = ((i + 1) % 3, (i + 2) % 3);
                out[i * 3 + j] = (c(a, p) * c(b, q) - c(a, q) * c(b, p)) / det;
            }
        }
        out
    })
}

fn determinant(m: &[f64], d: usize) -> f64 {
    if d == 2 {
        m[0] * m[3] - m[1] * m[2]
    } else {
        m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6])
    }
}

fn matmul(a: &[f64], b: &[f64], d: usize) -> Vec<f64> {
    (0..d * d).map(|k| (0..d).map(|l| a[(k / d) * d + l] * b[l * d + k % d]).sum()).collect()
}

fn transpose(a: &[f64], d: usize) -> Vec<f64> {
    (0..d * d).map(|k| a[(k % d) * d + k / d]).collect()
}

/// ω̂, the cross-product matrix of ω.
fn hat(w: &[f64]) -> [f64; 9] {
    [0.0, -w[2], w[1], w[2], 0.0, -w[0], -w[1], w[0], 0.0]
}

/// Exp(ω) on SO(3) (Rodrigues), or the plane rotation by the angle `w[0]`.
pub fn rotation(w: &[f64], d: usize) -> Vec<f64> {
    if d == 2 {
        let (s, c) = w[0].sin_cos();
        return vec![c, -s, s, c];
    }
    let theta2: f64 = w.iter().map(|v| v * v).sum();
    let theta = theta2.sqrt();
    // sin θ/θ and (1 − cos θ)/θ², by their series near 0.
    let (a, b) = if theta < 1e-4 {
        (1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0)
    } else {
        (theta.sin() / theta, (1.0 - theta.cos()) / theta2)
    };
    let h = hat(w);
    let h2 = matmul(&h, &h, 3);
    (0..9).map(|k| if k % 4 == 0 { 1.0 } else { 0.0 } + a * h[k] + b * h2[k]).collect()
}

/// SO(3)'s right Jacobian J_r(ω): Exp(ω + δ) ≈ Exp(ω) Exp(J_r(ω) δ).
fn right_jacobian(w: &[f64]) -> Vec<f64> {
    let theta2: f64 = w.iter().map(|v| v * v).sum();
    let theta = theta2.sqrt();
    // (1 − cos θ)/θ² and (θ − sin θ)/θ³.
    let (a, b) = if theta < 1e-4 {
        (0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0)
    } else {
        ((1.0 - theta.cos()) / theta2, (theta - theta.sin()) / (theta2 * theta))
    };
    let h = hat(w);
    let h2 = matmul(&h, &h, 3);
    (0..9).map(|k| if k % 4 == 0 { 1.0 } else { 0.0 } - a * h[k] + b * h2[k]).collect()
}

/// Where a fit starts: T₀(x) = s₀ R₀ (x − c) + c + t₀.
#[derive(Clone, Debug)]
struct Start {
    rotation: Vec<f64>,
    scale: f64,
    translation: Vec<f64>,
}

/// The fit's unknowns: τ (d), the rotation (3 in 3-D, 1 in the plane),
/// the log-scale σ (similarity and affine), and B (affine: M = M₀ + B,
/// d²), read against a start.
pub struct Fit<'a> {
    attachment: &'a Attachment,
    source: &'a FShape,
    kind: AlignKind,
    centre: Vec<f64>,
    length: f64,
    start: Start,
    /// The affine refinement's starting linear part (M = m0 + B).
    m0: Option<Vec<f64>>,
}

impl<'a> Fit<'a> {
    fn d(&self) -> usize {
        self.source.dim()
    }

    fn n_rot(&self) -> usize {
        if self.d() == 2 { 1 } else { 3 }
    }

    /// The number of unknowns.
    pub fn len(&self) -> usize {
        let d = self.d();
        match (self.kind, &self.m0) {
            (_, Some(_)) => d + d * d,
            (AlignKind::Similarity, None) => d + self.n_rot() + 1,
            _ => d + self.n_rot(),
        }
    }

    /// Whether there are no unknowns (never).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The linear part M and the translation t (of T(x) = M (x − c) + c + t) at `u`.
    fn map(&self, u: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let d = self.d();
        let t: Vec<f64> = (0..d).map(|i| self.start.translation[i] + self.length * u[i]).collect();
        if let Some(m0) = &self.m0 {
            let m = m0.iter().zip(&u[d..]).map(|(a, b)| a + b).collect();
            return (m, t);
        }
        let (r, s) = self.rotation_and_scale(u);
        (r.iter().map(|v| s * v).collect(), t)
    }

    /// R = R₀ Exp(ω) and s = s₀ e^σ at `u` (rigid and similarity fits).
    fn rotation_and_scale(&self, u: &[f64]) -> (Vec<f64>, f64) {
        let (d, n_rot) = (self.d(), self.n_rot());
        let r = matmul(&self.start.rotation, &rotation(&u[d..d + n_rot], d), d);
        let s = match self.kind {
            AlignKind::Similarity => self.start.scale * u[d + n_rot].exp(),
            _ => self.start.scale,
        };
        (r, s)
    }

    /// T(x) = M x + b as (M, b).
    fn affine(&self, u: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let d = self.d();
        let (m, t) = self.map(u);
        let b = (0..d)
            .map(|i| self.centre[i] + t[i] - (0..d).map(|j| m[i * d + j] * self.centre[j]).sum::<f64>())
            .collect();
        (m, b)
    }

    /// The start moved to the unknowns `u` (rotation, scale and
    /// translation folded in), so that a new fit from it starts at `u`.
    fn advanced(&self, u: &[f64]) -> Start {
        let (_, translation) = self.map(u);
        let (rotation, scale) = self.rotation_and_scale(u);
        Start { rotation, scale, translation }
    }

    /// A(T(X), Y) and its gradient in the unknowns.
    pub fn value_grad(&self, u: &[f64]) -> Result<(f64, Vec<f64>), MatchError> {
        let d = self.d();
        let (m, b) = self.affine(u);
        let points = transform(self.source.points(), d, &m, &b);
        if points.iter().any(|v| !v.is_finite()) {
            // A trial step too far (a scale overflowing): the line search
            // steps back.
            return Ok((f64::NAN, vec![f64::NAN; u.len()]));
        }
        let moved = self.source.clone().with_points(points)?;
        let (dist, g) = self.attachment.eval_grad(&moved).map_err(fshape_shoot::ShootError::from)?;
        // Σ g_i and G = Σ g_i (x_i − c)ᵀ.
        let mut sum = vec![0.0; d];
        let mut big_g = vec![0.0; d * d];
        for (x, gi) in self.source.points().chunks_exact(d).zip(g.points.chunks_exact(d)) {
            for i in 0..d {
                sum[i] += gi[i];
                for j in 0..d {
                    big_g[i * d + j] += gi[i] * (x[j] - self.centre[j]);
                }
            }
        }
        let mut grad: Vec<f64> = sum.iter().map(|v| self.length * v).collect();
        if self.m0.is_some() {
            grad.extend(&big_g);
            return Ok((dist.value, grad));
        }
        let (r, s) = self.rotation_and_scale(u);
        // ∂A/∂R = s G; with M = Rᵀ G, δA = s a·(J_r δω).
        let mm = matmul(&transpose(&r, d), &big_g, d);
        if d == 2 {
            grad.push(s * (mm[2] - mm[1]));
        } else {
            let a = [mm[7] - mm[5], mm[2] - mm[6], mm[3] - mm[1]];
            let j = right_jacobian(&u[d..d + 3]);
            grad.extend((0..3).map(|k| s * (0..3).map(|i| j[i * 3 + k] * a[i]).sum::<f64>()));
        }
        if self.kind == AlignKind::Similarity {
            grad.push(s * r.iter().zip(&big_g).map(|(a, b)| a * b).sum::<f64>());
        }
        Ok((dist.value, grad))
    }

    /// Minimises from `u = 0` (the start); the unknowns, A there and why
    /// it stopped.
    fn minimise(&self, max_iterations: usize) -> Result<(Vec<f64>, f64, Stop), MatchError> {
        let settings = Settings {
            method: Method::Lbfgs { memory: 10 },
            max_iterations,
            gradient_tolerance: 1e-6,
            decrease_tolerance: 1e-8,
            decrease_window: 5,
            ..Settings::default()
        };
        let mut objective = |u: &[f64]| self.value_grad(u);
        let (mut state, ()) = State::start(vec![0.0; self.len()], &mut objective)?;
        let stop = state.run(&settings, &mut objective, |_| {})?;
        Ok((state.x, state.value, stop))
    }
}

/// The area-weighted centroid and principal axes (columns of a proper
/// rotation, largest spread first) of a shape's cells.
fn moments(shape: &FShape) -> Result<(Vec<f64>, Vec<f64>), MatchError> {
    let d = shape.dim();
    let (centres, weights) = (shape.cell_centres(), shape.cell_volumes());
    let total: f64 = weights.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let mut c = vec![0.0; d];
    for (x, w) in centres.chunks_exact(d).zip(&weights) {
        for i in 0..d {
            c[i] += w * x[i] / total;
        }
    }
    let mut cov = vec![0.0; d * d];
    for (x, w) in centres.chunks_exact(d).zip(&weights) {
        for i in 0..d {
            for j in 0..d {
                cov[i * d + j] += w * (x[i] - c[i]) * (x[j] - c[j]) / total;
            }
        }
    }
    let (_, mut axes) = crate::linalg::symmetric_eigen(&cov, d)?;
    if determinant(&axes, d) < 0.0 {
        for i in 0..d {
            axes[i * d + d - 1] = -axes[i * d + d - 1];
        }
    }
    Ok((c, axes))
}

/// The proper rotations of the cube (24) or of the square (4), as
/// signed permutation matrices.
fn cube_group(d: usize) -> Vec<Vec<f64>> {
    let perms: Vec<Vec<usize>> = if d == 2 {
        vec![vec![0, 1], vec![1, 0]]
    } else {
        vec![vec![0, 1, 2], vec![0, 2, 1], vec![1, 0, 2], vec![1, 2, 0], vec![2, 0, 1], vec![2, 1, 0]]
    };
    let mut out = Vec::new();
    for p in &perms {
        for signs in 0..(1 << d) {
            let mut m = vec![0.0; d * d];
            for i in 0..d {
                m[i * d + p[i]] = if signs >> i & 1 == 1 { -1.0 } else { 1.0 };
            }
            if determinant(&m, d) > 0.0 {
                out.push(m);
            }
        }
    }
    out
}

/// At most `vertices` vertices: the shape, or (a surface) its simplified
/// copy.
fn coarse(shape: &FShape, vertices: usize, what: &str) -> Result<FShape, MatchError> {
    if shape.n_vertices() <= vertices || shape.kind() != fshape_mesh::CellKind::Triangle {
        return Ok(shape.clone());
    }
    shape.simplified(vertices).map(|s| s.shape).map_err(|source| MatchError::Simplify {
        what: format!("{what} (pre-alignment)"),
        vertices,
        stage: 0,
        source,
    })
}

/// The map of `kind` that brings `source` closest to `target` in the
/// attachment of `kernel` (module docs). `moving` is recorded for the
/// caller, which applies T or T⁻¹.
pub fn prealign(
    source: &FShape,
    target: &FShape,
    kernel: &VarifoldKernel,
    section: &PrealignSection,
) -> Result<Alignment, MatchError> {
    if section.kind == AlignKind::None {
        return Err(MatchError::InvalidInput("prealign: kind is none".into()));
    }
    if source.dim() != target.dim() || source.kind() != target.kind() {
        return Err(MatchError::Kinds("pre-alignment: the source and the target are not the same kind of mesh".into()));
    }
    if section.max_iterations == 0 {
        return Err(MatchError::Config { key: "prealign.max_iterations".into(), message: "must be at least 1".into() });
    }
    let d = source.dim();
    let (cs, axes_s) = moments(source)?;
    let (ct, axes_t) = moments(target)?;
    let length = source.bounding_box().diagonal().max(f64::MIN_POSITIVE);
    let scale0 = match section.kind {
        AlignKind::Rigid => 1.0,
        _ => {
            let cell_dim = source.kind().n_corners() - 1;
            (target.total_volume() / source.total_volume()).powf(1.0 / cell_dim as f64)
        }
    };
    if !(scale0.is_finite() && scale0 > 0.0) {
        return Err(MatchError::Degenerate("pre-alignment: a shape has no area or length".into()));
    }
    let translation: Vec<f64> = (0..d).map(|i| ct[i] - cs[i]).collect();
    let starts: Vec<Start> = cube_group(d)
        .iter()
        .map(|p| Start {
            rotation: matmul(&matmul(&axes_t, p, d), &transpose(&axes_s, d), d),
            scale: scale0,
            translation: translation.clone(),
        })
        .collect();
    let fit_kind = if section.kind == AlignKind::Affine { AlignKind::Similarity } else { section.kind };
    // The starts on coarse copies: a few iterations each, then the best
    // few to convergence, then the best of those on the shapes themselves.
    let (source_c, target_c) = (coarse(source, START_VERTICES, "source")?, coarse(target, START_VERTICES, "target")?);
    let attachment_c = Attachment::new(&target_c, kernel.clone()).map_err(fshape_shoot::ShootError::from)?;
    let fit_c = |start: &Start| Fit {
        attachment: &attachment_c,
        source: &source_c,
        kind: fit_kind,
        centre: cs.clone(),
        length,
        start: start.clone(),
        m0: None,
    };
    let mut tried: Vec<(f64, usize, Start)> = Vec::with_capacity(starts.len());
    for (k, start) in starts.iter().enumerate() {
        let fit = fit_c(start);
        let (u, value, _) = fit.minimise(START_ITERATIONS.min(section.max_iterations))?;
        if value.is_finite() {
            tried.push((value, k, fit.advanced(&u)));
        }
    }
    tried.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut best: Option<(f64, usize, Start)> = None;
    for (_, k, start) in tried.into_iter().take(FINALISTS) {
        let fit = fit_c(&start);
        let (u, value, _) = fit.minimise(section.max_iterations)?;
        if value.is_finite() && best.as_ref().is_none_or(|b| value < b.0) {
            best = Some((value, k, fit.advanced(&u)));
        }
    }
    let (_, k, start) =
        best.ok_or_else(|| MatchError::Degenerate("pre-alignment: no start gave a finite attachment".into()))?;
    // The winner refined on the shapes themselves, or on finer copies.
    let (source_f, target_f) = (coarse(source, REFINE_VERTICES, "source")?, coarse(target, REFINE_VERTICES, "target")?);
    let attachment = Attachment::new(&target_f, kernel.clone()).map_err(fshape_shoot::ShootError::from)?;
    let fit =
        Fit { attachment: &attachment, source: &source_f, kind: fit_kind, centre: cs.clone(), length, start, m0: None };
    let (u, _, _) = fit.minimise(section.max_iterations)?;
    let (mut m, mut b) = fit.affine(&u);
    if section.kind == AlignKind::Affine {
        let (mm, t) = fit.map(&u);
        let affine =
            Fit { m0: Some(mm), start: Start { translation: t, ..fit.start.clone() }, kind: AlignKind::Affine, ..fit };
        let (u, _, _) = affine.minimise(section.max_iterations)?;
        (m, b) = affine.affine(&u);
    }
    let before = attachment.eval(&source_f).map_err(fshape_shoot::ShootError::from)?.value;
    let moved = source_f.clone().with_points(transform(source_f.points(), d, &m, &b))?;
    let after = attachment.eval(&moved).map_err(fshape_shoot::ShootError::from)?.value;
    let scale = determinant(&m, d).abs().powf(1.0 / d as f64);
    let r: Vec<f64> = m.iter().map(|v| v / scale).collect();
    let cos = if d == 2 { r[0] } else { ((r[0] + r[4] + r[8] - 1.0) / 2.0).clamp(-1.0, 1.0) };
    let mut matrix: Vec<Vec<f64>> =
        (0..d).map(|i| m[i * d..(i + 1) * d].iter().copied().chain([b[i]]).collect()).collect();
    matrix.push((0..=d).map(|j| if j == d { 1.0 } else { 0.0 }).collect());
    let moved_centre: Vec<f64> =
        (0..d).map(|i| (0..d).map(|j| m[i * d + j] * cs[j]).sum::<f64>() + b[i] - cs[i]).collect();
    Ok(Alignment {
        kind: section.kind,
        moving: section.moving,
        matrix,
        scale,
        rotation_degrees: cos.clamp(-1.0, 1.0).acos().to_degrees(),
        translation: moved_centre,
        attachment_before: before,
        attachment_after: after,
        start: k,
        starts: starts.len(),
    })
}

/// The fit of `kind` from the identity start, for tests of its gradient:
/// unknowns of [`Fit::len`], value and gradient by [`Fit::value_grad`].
pub fn fit_for_tests<'a>(source: &'a FShape, attachment: &'a Attachment, kind: AlignKind, affine: bool) -> Fit<'a> {
    let d = source.dim();
    let (centre, _) = moments(source).expect("a test shape has finite moments");
    let identity: Vec<f64> = (0..d * d).map(|k| if k % (d + 1) == 0 { 1.0 } else { 0.0 }).collect();
    // A start away from the identity, so that no term vanishes by symmetry.
    let w: Vec<f64> = if d == 2 { vec![0.3] } else { vec![0.3, -0.2, 0.5] };
    let start = Start { rotation: rotation(&w, d), scale: 1.1, translation: vec![0.05; d] };
    Fit {
        attachment,
        source,
        kind,
        centre,
        length: source.bounding_box().diagonal(),
        m0: affine.then(|| identity.iter().map(|v| 0.9 * v).collect()),
        start,
    }
}

/// The pair as a registration sees it: with a `[prealign]` kind, the
/// source moved by T onto the target (or the target by T⁻¹ onto the
/// source, `move = "target"`), T found with the first stage's attachment;
/// else the pair as given.
pub fn prealigned(
    source: &FShape,
    target: &FShape,
    config: &crate::Config,
    observer: &mut dyn crate::Observer,
) -> Result<(FShape, FShape, Option<Alignment>), MatchError> {
    let Some(section) = config.prealign.as_ref().filter(|s| s.kind != AlignKind::None) else {
        return Ok((source.clone(), target.clone(), None));
    };
    let plan = config.plan(source, target)?;
    observer.setup(&format!("pre-alignment ({}) begins", section.kind.name()));
    let alignment = prealign(source, target, &plan.stages[0].kernel, section)?;
    observer.setup(&format!("pre-alignment: {}", alignment.describe()));
    Ok(match section.moving {
        Moving::Source => (alignment.apply(source)?, target.clone(), Some(alignment)),
        Moving::Target => (source.clone(), alignment.apply_inverse(target)?, Some(alignment)),
    })
}
