//! Cell features (centre, unit direction, weight, signal) and the chain
//! rule from feature gradients back to vertex positions and signal values.

use fshape_mesh::{CellKind, FShape};

use crate::VarifoldError;

/// The per-cell data a varifold sees, for n cells.
///
/// - `centre`: the cell's barycentre (n × dim).
/// - `dir`: the unit normal of a triangle in R³ (the orientation of its
///   corners, right-hand rule), the unit tangent x₁ − x₀ of a segment, or
///   for a triangle in the plane the sign of its oriented area (n × du,
///   `du` = 3, 2 or 1). Zero for a cell of zero volume.
/// - `weight`: the cell's d-volume r_τ (length or area).
/// - `signal`: the mean of the corners' signal values, if the shape has a
///   signal: k channels per cell (n × k, flat row-major), as the vertices.
/// - `mask`: with a masked shape, each cell's functional share m_τ ∈ [0, 1],
///   the smallest of its corners' mask weights, so that one masked corner
///   cannot bring its (missing) value into the cell's mean. A cell of share
///   0 has signal 0 here, never read.
///
/// A masked measure is two measures: the functional varifold of the masses
/// m_τ r_τ and the plain varifold of the masses (1 − m_τ) r_τ, compared
/// part with part (see [`crate::inner_product`]).
#[derive(Clone, Debug, PartialEq)]
pub struct CellFeatures {
    dim: usize,
    du: usize,
    centre: Vec<f64>,
    dir: Vec<f64>,
    weight: Vec<f64>,
    signal: Option<Vec<f64>>,
    /// Signal channels k (1 without a signal).
    channels: usize,
    mask: Option<Vec<f64>>,
}

/// A gradient with respect to the features of [`CellFeatures`], laid out
/// the same way.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureGrad {
    /// ∂/∂centre (n × dim).
    pub centre: Vec<f64>,
    /// ∂/∂dir (n × du), an unconstrained derivative (the chain rule projects
    /// it onto the unit sphere's tangent space).
    pub dir: Vec<f64>,
    /// ∂/∂weight (n).
    pub weight: Vec<f64>,
    /// ∂/∂signal (n × k, as the signal); zero when the signal kernel is
    /// constant.
    pub signal: Vec<f64>,
}

impl FeatureGrad {
    /// A zero gradient for the features `x` (the signal's block one
    /// channel wide when `x` has no signal).
    pub(crate) fn zeros(x: &CellFeatures) -> FeatureGrad {
        let n = x.len();
        FeatureGrad {
            centre: vec![0.0; n * x.dim()],
            dir: vec![0.0; n * x.dir_len()],
            weight: vec![0.0; n],
            signal: vec![0.0; n * x.n_channels().max(1)],
        }
    }
}

/// Number of direction components for a cell kind in a dimension.
pub(crate) fn dir_len(kind: CellKind, dim: usize) -> usize {
    match kind {
        CellKind::Segment => dim,
        CellKind::Triangle if dim == 2 => 1,
        CellKind::Triangle => 3,
    }
}

/// The cell vector N (half the cross product of the edges from corner 0 for
/// a triangle, x₁ − x₀ for a segment), in 3 components (zeros padded).
fn cell_vector(shape: &FShape, t: usize) -> [f64; 3] {
    shape.cell_vector(t)
}

impl CellFeatures {
    /// The features of every cell of `shape`. The shape's invariants
    /// (finite coordinates, indices in range) are checked at its
    /// construction; a signal value that is NaN or infinite is refused here
    /// with its vertex index.
    pub fn of(shape: &FShape) -> Result<CellFeatures, VarifoldError> {
        let vertex_mask = shape.mask();
        let nf = shape.n_channels().max(1);
        if let Some(f) = shape.signal()
            && let Some(i) = (0..f.len()).position(|i| !f[i].is_finite() && vertex_mask.is_none_or(|m| m[i / nf] > 0.0))
        {
            return Err(VarifoldError::NonFiniteSignal { vertex: i / nf, value: f[i] });
        }
        let (dim, kind) = (shape.dim(), shape.kind());
        let du = dir_len(kind, dim);
        let nc = kind.n_corners();
        let n = shape.n_cells();
        let mut centre = vec![0.0; n * dim];
        let mut dir = vec![0.0; n * du];
        let mut weight = vec![0.0; n];
        for (t, cell) in shape.cell_iter().enumerate() {
            for &v in cell {
                for (c, x) in centre[t * dim..(t + 1) * dim].iter_mut().zip(shape.point(v)) {
                    *c += x / nc as f64;
                }
            }
            let nv = cell_vector(shape, t);
            let r = (nv[0] * nv[0] + nv[1] * nv[1] + nv[2] * nv[2]).sqrt();
            weight[t] = r;
            if r > 0.0 {
                let d = &mut dir[t * du..(t + 1) * du];
                if du == 1 {
                    d[0] = nv[2].signum();
                } else {
                    for (k, dk) in d.iter_mut().enumerate() {
                        *dk = nv[k] / r;
                    }
                }
            }
        }
        let mask: Option<Vec<f64>> =
            vertex_mask.map(|m| shape.cell_iter().map(|cell| cell.iter().map(|&v| m[v]).fold(1.0, f64::min)).collect());
        let signal = shape.signal().map(|f| {
            let mut out = vec![0.0; n * nf];
            for (t, cell) in shape.cell_iter().enumerate() {
                // A masked cell's corners are not read.
                if mask.as_ref().is_some_and(|m| m[t] == 0.0) {
                    continue;
                }
                for (c, o) in out[t * nf..(t + 1) * nf].iter_mut().enumerate() {
                    *o = cell.iter().map(|&v| f[v * nf + c]).sum::<f64>() / nc as f64;
                }
            }
            out
        });
        Ok(CellFeatures { dim, du, centre, dir, weight, signal, channels: nf, mask })
    }

    /// The same cells with a functional share per cell in [0, 1] (see
    /// [`CellFeatures`]); `None` removes it.
    pub fn with_mask(mut self, mask: Option<Vec<f64>>) -> Result<CellFeatures, VarifoldError> {
        if let Some(m) = &mask {
            if m.len() != self.len() {
                return Err(VarifoldError::Dimension { what: "mask", expected: self.len(), found: m.len() });
            }
            if let Some(t) = m.iter().position(|w| !(0.0..=1.0).contains(w)) {
                return Err(VarifoldError::Feature { what: "mask", cell: t, value: m[t] });
            }
        }
        self.mask = mask;
        Ok(self)
    }

    /// The cells' functional shares, if masked.
    pub fn mask(&self) -> Option<&[f64]> {
        self.mask.as_deref()
    }

    /// A measure's two parts: the cells of positive share with masses
    /// m_τ r_τ and their signal, and the cells of share below 1 with
    /// masses (1 − m_τ) r_τ and no signal, each with the indices of its
    /// cells here. Without a mask every share is 1: all cells in the first
    /// part, none in the second.
    pub(crate) fn split(&self) -> [(CellFeatures, Vec<usize>); 2] {
        let share = |t: usize| self.mask.as_ref().map_or(1.0, |m| m[t]);
        let part = |keep: &dyn Fn(f64) -> bool, mass: &dyn Fn(f64) -> f64, signal: bool| {
            let idx: Vec<usize> = (0..self.len()).filter(|&t| keep(share(t))).collect();
            let pick = |v: &[f64], w: usize| idx.iter().flat_map(|&t| v[t * w..(t + 1) * w].iter().copied()).collect();
            let nf = self.channels;
            let features = CellFeatures {
                dim: self.dim,
                du: self.du,
                centre: pick(&self.centre, self.dim),
                dir: pick(&self.dir, self.du),
                weight: idx.iter().map(|&t| mass(share(t)) * self.weight[t]).collect(),
                signal: if signal { self.signal.as_ref().map(|f| pick(f, nf)) } else { None },
                channels: if signal { nf } else { 1 },
                mask: None,
            };
            (features, idx)
        };
        [part(&|w| w > 0.0, &|w| w, true), part(&|w| w < 1.0, &|w| 1.0 - w, false)]
    }

    /// Builds features directly (for measures that do not come from a mesh,
    /// and for tests), with one signal value per cell. `dir` rows should be
    /// unit vectors (or zero).
    pub fn from_parts(
        dim: usize,
        centre: Vec<f64>,
        dir: Vec<f64>,
        weight: Vec<f64>,
        signal: Option<Vec<f64>>,
    ) -> Result<CellFeatures, VarifoldError> {
        CellFeatures::from_parts_channels(dim, centre, dir, weight, signal, 1)
    }

    /// [`CellFeatures::from_parts`] with `channels` signal values per cell
    /// (n × k, flat row-major).
    pub fn from_parts_channels(
        dim: usize,
        centre: Vec<f64>,
        dir: Vec<f64>,
        weight: Vec<f64>,
        signal: Option<Vec<f64>>,
        channels: usize,
    ) -> Result<CellFeatures, VarifoldError> {
        if channels == 0 {
            return Err(VarifoldError::Channels { what: "signal", expected: 1, found: 0 });
        }
        if dim != 2 && dim != 3 {
            return Err(VarifoldError::PointDimension { found: dim });
        }
        let n = weight.len();
        let du = dir.len().checked_div(n).unwrap_or(dim);
        let checks = [
            ("centres", centre.len(), n * dim),
            ("directions", dir.len(), n * du),
            ("signal", signal.as_ref().map_or(n * channels, Vec::len), n * channels),
        ];
        for (what, found, expected) in checks {
            if found != expected {
                return Err(VarifoldError::Dimension { what, expected, found });
            }
        }
        if !matches!((dim, du), (2, 1) | (2, 2) | (3, 3)) {
            return Err(VarifoldError::Dimension { what: "direction components", expected: dim, found: du });
        }
        let rows: [(&'static str, &[f64], usize); 4] = [
            ("centre", &centre, dim),
            ("direction", &dir, du),
            ("weight", &weight, 1),
            ("signal", signal.as_deref().unwrap_or(&[]), channels),
        ];
        for (what, v, w) in rows {
            if let Some(i) = v.iter().position(|v| !v.is_finite() || (what == "weight" && *v < 0.0)) {
                return Err(VarifoldError::Feature { what, cell: i / w, value: v[i] });
            }
        }
        let channels = if signal.is_some() { channels } else { 1 };
        Ok(CellFeatures { dim, du, centre, dir, weight, signal, channels, mask: None })
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.weight.len()
    }

    /// `true` if there are no cells.
    pub fn is_empty(&self) -> bool {
        self.weight.is_empty()
    }

    /// Ambient dimension (2 or 3).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Components of a direction (3 for surfaces in R³ and curves in R³, 2
    /// for curves in the plane, 1 for triangles in the plane).
    pub fn dir_len(&self) -> usize {
        self.du
    }

    /// Centres, n × dim.
    pub fn centres(&self) -> &[f64] {
        &self.centre
    }

    /// Unit directions, n × du.
    pub fn dirs(&self) -> &[f64] {
        &self.dir
    }

    /// Weights (cell volumes).
    pub fn weights(&self) -> &[f64] {
        &self.weight
    }

    /// Cell signal values, [`CellFeatures::n_channels`] per cell, if any.
    pub fn signal(&self) -> Option<&[f64]> {
        self.signal.as_deref()
    }

    /// Signal channels per cell: 0 without a signal, else k ≥ 1.
    pub fn n_channels(&self) -> usize {
        if self.signal.is_some() { self.channels } else { 0 }
    }

    /// Total mass Σ_τ r_τ.
    pub fn mass(&self) -> f64 {
        self.weight.iter().sum()
    }
}

/// Pulls a gradient with respect to the cell features of `shape` back to
/// its vertices: returns (∂/∂points, n_vertices × dim, and ∂/∂signal,
/// n_vertices × k). With N the cell vector, r = |N| and u = N/r:
/// ∂/∂N = g_r u + (g_u − (u·g_u) u)/r; centre and signal are corner means.
/// A cell of zero volume has no direction and contributes only through its
/// centre and signal (its weight is 0, so those terms vanish too).
pub(crate) fn pull_back(shape: &FShape, g: &FeatureGrad) -> (Vec<f64>, Vec<f64>) {
    let (dim, kind) = (shape.dim(), shape.kind());
    let du = dir_len(kind, dim);
    let nc = kind.n_corners();
    let mut gx = vec![0.0; shape.n_vertices() * dim];
    let nf = shape.n_channels().max(1);
    let mut gf = vec![0.0; shape.n_vertices() * nf];
    for (t, cell) in shape.cell_iter().enumerate() {
        for &v in cell {
            for k in 0..dim {
                gx[v * dim + k] += g.centre[t * dim + k] / nc as f64;
            }
            for c in 0..nf {
                gf[v * nf + c] += g.signal[t * nf + c] / nc as f64;
            }
        }
        let nv = cell_vector(shape, t);
        let r = (nv[0] * nv[0] + nv[1] * nv[1] + nv[2] * nv[2]).sqrt();
        if r == 0.0 {
            continue;
        }
        let u = [nv[0] / r, nv[1] / r, nv[2] / r];
        // g_u padded to 3 components (a planar triangle's direction is N_z/r).
        let mut gu = [0.0; 3];
        match du {
            1 => gu[2] = g.dir[t],
            _ => gu[..du].copy_from_slice(&g.dir[t * du..(t + 1) * du]),
        }
        let ug: f64 = (0..3).map(|k| u[k] * gu[k]).sum();
        let gr = g.weight[t];
        let gn: [f64; 3] = std::array::from_fn(|k| gr * u[k] + (gu[k] - ug * u[k]) / r);
        let p = |c: usize| -> [f64; 3] {
            let q = shape.point(cell[c]);
            [q[0], q[1], q.get(2).copied().unwrap_or(0.0)]
        };
        let mut add = |v: usize, d: [f64; 3]| {
            for k in 0..dim {
                gx[v * dim + k] += d[k];
            }
        };
        match kind {
            CellKind::Segment => {
                add(cell[1], gn);
                add(cell[0], gn.map(|v| -v));
            }
            CellKind::Triangle => {
                // N = ½ e1 × e2: gN·dN = ½ de1·(e2 × gN) + ½ de2·(gN × e1).
                let (x0, x1, x2) = (p(0), p(1), p(2));
                let e1 = [x1[0] - x0[0], x1[1] - x0[1], x1[2] - x0[2]];
                let e2 = [x2[0] - x0[0], x2[1] - x0[1], x2[2] - x0[2]];
                let d1 = cross(e2, gn).map(|v| 0.5 * v);
                let d2 = cross(gn, e1).map(|v| 0.5 * v);
                add(cell[1], d1);
                add(cell[2], d2);
                add(cell[0], [-d1[0] - d2[0], -d1[1] - d2[1], -d1[2] - d2[2]]);
            }
        }
    }
    (gx, gf)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
