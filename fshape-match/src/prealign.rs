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
/// The 3 × 3 matrices and 3-vectors of the maps (f64 glam, already the
/// kernels' geometry crate): a plane's map is one of space leaving z
/// alone, so one type serves both dimensions.
pub use glam::{DMat3, DVec3};
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

    /// The linear part M and the translation b of T(x) = M x + b (in the
    /// plane: in the first two rows and columns, the third those of the
    /// identity).
    pub fn linear_and_offset(&self) -> (DMat3, DVec3) {
        let d = self.matrix.len() - 1;
        let at = |i: usize, j: usize| if i < d && j < d { self.matrix[i][j] } else { f64::from(u8::from(i == j)) };
        let m = DMat3::from_cols_array_2d(&[0, 1, 2].map(|j| [0, 1, 2].map(|i| at(i, j))));
        let b = DVec3::from_array([0, 1, 2].map(|i| if i < d { self.matrix[i][d] } else { 0.0 }));
        (m, b)
    }

    /// `shape` moved by T.
    pub fn apply(&self, shape: &FShape) -> Result<FShape, MatchError> {
        let (m, b) = self.linear_and_offset();
        Ok(shape.clone().with_points(transform(shape.points(), shape.dim(), &m, b))?)
    }

    /// `shape` moved by T⁻¹ (for results in the source's frame).
    pub fn apply_inverse(&self, shape: &FShape) -> Result<FShape, MatchError> {
        let (m, b) = self.linear_and_offset();
        let det = m.determinant();
        if det == 0.0 || !det.is_finite() {
            return Err(MatchError::Degenerate("the pre-alignment's map is singular".into()));
        }
        let inv = m.inverse();
        Ok(shape.clone().with_points(transform(shape.points(), shape.dim(), &inv, -(inv * b)))?)
    }
}

/// A point of the plane or of space as a 3-vector (z = 0 in the plane).
fn point(x: &[f64]) -> DVec3 {
    DVec3::new(x[0], x[1], x.get(2).copied().unwrap_or(0.0))
}

/// Points of dimension `d` moved by x ↦ m x + b.
fn transform(points: &[f64], d: usize, m: &DMat3, b: DVec3) -> Vec<f64> {
    points.chunks_exact(d).flat_map(|x| (*m * point(x) + b).to_array().into_iter().take(d)).collect()
}

/// M's entries row by row, d × d (the affine fit's unknowns' order).
fn rows_of(m: &DMat3, d: usize) -> impl Iterator<Item = f64> + '_ {
    (0..d).flat_map(move |i| (0..d).map(move |j| m.col(j)[i]))
}

/// ω̂, the cross-product matrix of ω.
fn hat(w: DVec3) -> DMat3 {
    DMat3::from_cols(DVec3::new(0.0, w.z, -w.y), DVec3::new(-w.z, 0.0, w.x), DVec3::new(w.y, -w.x, 0.0))
}

/// The rotation vector of the unknowns `w`: ω in space, (0, 0, θ) in the
/// plane (a rotation about the axis the plane leaves out).
fn rotation_vector(w: &[f64]) -> DVec3 {
    if w.len() == 1 { DVec3::new(0.0, 0.0, w[0]) } else { DVec3::new(w[0], w[1], w[2]) }
}

/// Exp(ω) on SO(3) (Rodrigues) of a rotation vector `w` (3 entries), or
/// the plane's rotation by the angle `w[0]` (1 entry: about z).
pub fn rotation(w: &[f64]) -> DMat3 {
    if w.len() == 1 {
        return DMat3::from_rotation_z(w[0]);
    }
    let w = rotation_vector(w);
    let theta2 = w.length_squared();
    let theta = theta2.sqrt();
    // sin θ/θ and (1 − cos θ)/θ², by their series near 0.
    let (a, b) = if theta < 1e-4 {
        (1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0)
    } else {
        (theta.sin() / theta, (1.0 - theta.cos()) / theta2)
    };
    let h = hat(w);
    DMat3::IDENTITY + h * a + (h * h) * b
}

/// SO(3)'s right Jacobian J_r(ω): Exp(ω + δ) ≈ Exp(ω) Exp(J_r(ω) δ).
fn right_jacobian(w: DVec3) -> DMat3 {
    let theta2 = w.length_squared();
    let theta = theta2.sqrt();
    // (1 − cos θ)/θ² and (θ − sin θ)/θ³.
    let (a, b) = if theta < 1e-4 {
        (0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0)
    } else {
        ((1.0 - theta.cos()) / theta2, (theta - theta.sin()) / (theta2 * theta))
    };
    let h = hat(w);
    DMat3::IDENTITY - h * a + (h * h) * b
}

/// Where a fit starts: T₀(x) = s₀ R₀ (x − c) + c + t₀.
#[derive(Clone, Debug)]
struct Start {
    rotation: DMat3,
    scale: f64,
    translation: DVec3,
}

/// The fit's unknowns: τ (d), the rotation (3 in 3-D, 1 in the plane),
/// the log-scale σ (similarity and affine), and B (affine: M = M₀ + B,
/// d², row by row), read against a start.
pub struct Fit<'a> {
    attachment: &'a Attachment,
    source: &'a FShape,
    kind: AlignKind,
    centre: DVec3,
    length: f64,
    start: Start,
    /// The affine refinement's starting linear part (M = m0 + B).
    m0: Option<DMat3>,
}

/// `m` with its third row and column those of the identity in the plane
/// (d = 2), so that its determinant and inverse are the plane's.
fn planar(m: DMat3, d: usize) -> DMat3 {
    if d == 2 { DMat3::from_cols(m.x_axis.with_z(0.0), m.y_axis.with_z(0.0), DVec3::Z) } else { m }
}

/// The d × d matrix of `rows` (row by row) in the top-left corner, zeros
/// elsewhere.
fn from_rows(rows: &[f64], d: usize) -> DMat3 {
    DMat3::from_cols_array_2d(&[0, 1, 2].map(|j| [0, 1, 2].map(|i| if i < d && j < d { rows[i * d + j] } else { 0.0 })))
}

/// The rank-one u vᵀ.
fn outer(u: DVec3, v: DVec3) -> DMat3 {
    DMat3::from_cols(u * v.x, u * v.y, u * v.z)
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
    fn map(&self, u: &[f64]) -> (DMat3, DVec3) {
        let d = self.d();
        let t = self.start.translation + point(&u[..d]) * self.length;
        if let Some(m0) = &self.m0 {
            return (*m0 + from_rows(&u[d..], d), t);
        }
        let (r, s) = self.rotation_and_scale(u);
        (planar(r * s, d), t)
    }

    /// R = R₀ Exp(ω) and s = s₀ e^σ at `u` (rigid and similarity fits).
    fn rotation_and_scale(&self, u: &[f64]) -> (DMat3, f64) {
        let (d, n_rot) = (self.d(), self.n_rot());
        let r = self.start.rotation * rotation(&u[d..d + n_rot]);
        let s = match self.kind {
            AlignKind::Similarity => self.start.scale * u[d + n_rot].exp(),
            _ => self.start.scale,
        };
        (r, s)
    }

    /// T(x) = M x + b as (M, b).
    fn affine(&self, u: &[f64]) -> (DMat3, DVec3) {
        let (m, t) = self.map(u);
        (m, self.centre + t - m * self.centre)
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
        let points = transform(self.source.points(), d, &m, b);
        if points.iter().any(|v| !v.is_finite()) {
            // A trial step too far (a scale overflowing): the line search
            // steps back.
            return Ok((f64::NAN, vec![f64::NAN; u.len()]));
        }
        let moved = self.source.clone().with_points(points)?;
        let (dist, g) = self.attachment.eval_grad(&moved).map_err(fshape_shoot::ShootError::from)?;
        // Σ g_i and G = Σ g_i (x_i − c)ᵀ.
        let (mut sum, mut big_g) = (DVec3::ZERO, DMat3::ZERO);
        for (x, gi) in self.source.points().chunks_exact(d).zip(g.points.chunks_exact(d)) {
            let gi = point(gi);
            sum += gi;
            big_g += outer(gi, point(x) - self.centre);
        }
        let mut grad: Vec<f64> = sum.to_array()[..d].iter().map(|v| self.length * v).collect();
        if self.m0.is_some() {
            grad.extend(rows_of(&big_g, d));
            return Ok((dist.value, grad));
        }
        let (r, s) = self.rotation_and_scale(u);
        // ∂A/∂R = s G; with M = Rᵀ G, δA = s a·(J_r δω), a = vee(M − Mᵀ).
        let mm = r.transpose() * big_g;
        let a = DVec3::new(mm.y_axis.z - mm.z_axis.y, mm.z_axis.x - mm.x_axis.z, mm.x_axis.y - mm.y_axis.x);
        if d == 2 {
            // About z only: J_r((0, 0, θ)) leaves z alone.
            grad.push(s * a.z);
        } else {
            let j = right_jacobian(rotation_vector(&u[d..d + 3]));
            grad.extend([j.x_axis, j.y_axis, j.z_axis].map(|column| s * column.dot(a)));
        }
        if self.kind == AlignKind::Similarity {
            grad.push(s * rows_of(&r, d).zip(rows_of(&big_g, d)).map(|(a, b)| a * b).sum::<f64>());
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
fn moments(shape: &FShape) -> Result<(DVec3, DMat3), MatchError> {
    let d = shape.dim();
    let (centres, weights) = (shape.cell_centres(), shape.cell_volumes());
    let total: f64 = weights.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let mut c = DVec3::ZERO;
    for (x, w) in centres.chunks_exact(d).zip(&weights) {
        c += point(x) * w / total;
    }
    let mut cov = vec![0.0; d * d];
    for (x, w) in centres.chunks_exact(d).zip(&weights) {
        let x = point(x) - c;
        for i in 0..d {
            for j in 0..d {
                cov[i * d + j] += w * x[i] * x[j] / total;
            }
        }
    }
    let (_, axes) = crate::linalg::symmetric_eigen(&cov, d)?;
    let mut axes = planar(from_rows(&axes, d), d);
    if axes.determinant() < 0.0 {
        *axes.col_mut(d - 1) = -axes.col(d - 1);
    }
    Ok((c, axes))
}

/// The proper rotations of the cube (24) or of the square (4, about z),
/// as signed permutation matrices.
fn cube_group(d: usize) -> Vec<DMat3> {
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
            let m = planar(from_rows(&m, d), d);
            if m.determinant() > 0.0 {
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
    let translation = ct - cs;
    let starts: Vec<Start> = cube_group(d)
        .iter()
        .map(|p| Start { rotation: axes_t * *p * axes_s.transpose(), scale: scale0, translation })
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
        centre: cs,
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
    let fit = Fit { attachment: &attachment, source: &source_f, kind: fit_kind, centre: cs, length, start, m0: None };
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
    let moved = source_f.clone().with_points(transform(source_f.points(), d, &m, b))?;
    let after = attachment.eval(&moved).map_err(fshape_shoot::ShootError::from)?.value;
    let scale = m.determinant().abs().powf(1.0 / d as f64);
    let r = m / scale;
    let cos = if d == 2 { r.x_axis.x } else { ((r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0) };
    let mut matrix: Vec<Vec<f64>> = (0..d).map(|i| (0..d).map(|j| m.col(j)[i]).chain([b[i]]).collect()).collect();
    matrix.push((0..=d).map(|j| if j == d { 1.0 } else { 0.0 }).collect());
    let moved_centre = m * cs + b - cs;
    Ok(Alignment {
        kind: section.kind,
        moving: section.moving,
        matrix,
        scale,
        rotation_degrees: cos.clamp(-1.0, 1.0).acos().to_degrees(),
        translation: moved_centre.to_array()[..d].to_vec(),
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
    // A start away from the identity, so that no term vanishes by symmetry.
    let w: &[f64] = if d == 2 { &[0.3] } else { &[0.3, -0.2, 0.5] };
    let start = Start { rotation: rotation(w), scale: 1.1, translation: point(&[0.05; 3][..d]) };
    Fit {
        attachment,
        source,
        kind,
        centre,
        length: source.bounding_box().diagonal(),
        m0: affine.then(|| planar(DMat3::IDENTITY * 0.9, d)),
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
