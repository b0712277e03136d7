//! Cell geometry (volumes, centres, weighted normals or tangents), lumped
//! vertex volumes, bounding boxes.

use crate::shape::{CellKind, FShape};

/// Axis-aligned bounding box of the vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundingBox {
    /// Smallest coordinate on each axis (`dim` values).
    pub min: Vec<f64>,
    /// Largest coordinate on each axis (`dim` values).
    pub max: Vec<f64>,
}

impl BoundingBox {
    /// Length of the diagonal, ‖max − min‖; 0 for an empty shape.
    pub fn diagonal(&self) -> f64 {
        self.min.iter().zip(&self.max).map(|(a, b)| (b - a) * (b - a)).sum::<f64>().sqrt()
    }
}

fn sub(a: &[f64], b: &[f64]) -> [f64; 3] {
    let mut d = [0.0; 3];
    for k in 0..a.len() {
        d[k] = a[k] - b[k];
    }
    d
}

fn cross(u: [f64; 3], v: [f64; 3]) -> [f64; 3] {
    [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

impl FShape {
    /// The volume-weighted direction of cell `t`, always as 3 components:
    /// for a segment [a, b] its tangent b − a (length = segment length; the
    /// third component is 0 in the plane); for a triangle (a, b, c) its
    /// area-weighted normal (b − a) × (c − a) / 2, whose norm is the area
    /// and which points to the side from which a, b, c turn
    /// counter-clockwise. A planar triangle gets (0, 0, ± area).
    ///
    /// ```
    /// use fshape_mesh::{CellKind, FShape};
    /// let s = FShape::try_new(3, CellKind::Triangle,
    ///     vec![0., 0., 0., 1., 0., 0., 0., 1., 0.], vec![0, 1, 2], None)?;
    /// assert_eq!(s.cell_vector(0), [0.0, 0.0, 0.5]);
    /// # Ok::<(), fshape_mesh::ShapeError>(())
    /// ```
    ///
    /// # Panics
    /// If `t >= self.n_cells()`.
    #[track_caller]
    pub fn cell_vector(&self, t: usize) -> [f64; 3] {
        let c = self.cell(t);
        let a = self.point(c[0]);
        let e1 = sub(self.point(c[1]), a);
        match self.kind() {
            CellKind::Segment => e1,
            CellKind::Triangle => {
                let e2 = sub(self.point(c[2]), a);
                let n = cross(e1, e2);
                [0.5 * n[0], 0.5 * n[1], 0.5 * n[2]]
            }
        }
    }

    /// The d-volume r_τ of cell `t` (length of a segment, area of a
    /// triangle); the norm of [`FShape::cell_vector`].
    ///
    /// # Panics
    /// If `t >= self.n_cells()`.
    #[track_caller]
    pub fn cell_volume(&self, t: usize) -> f64 {
        norm(self.cell_vector(t))
    }

    /// The d-volumes of all cells.
    pub fn cell_volumes(&self) -> Vec<f64> {
        (0..self.n_cells()).map(|t| self.cell_volume(t)).collect()
    }

    /// The weighted directions of all cells, 3 components per cell (see
    /// [`FShape::cell_vector`]).
    pub fn cell_vectors(&self) -> Vec<[f64; 3]> {
        (0..self.n_cells()).map(|t| self.cell_vector(t)).collect()
    }

    /// The barycentre of every cell, `dim` coordinates per cell.
    pub fn cell_centres(&self) -> Vec<f64> {
        let (n, w) = (self.dim(), 1.0 / self.kind().n_corners() as f64);
        let mut out = vec![0.0; self.n_cells() * n];
        for (t, cell) in self.cell_iter().enumerate() {
            for &v in cell {
                for k in 0..n {
                    out[t * n + k] += w * self.point(v)[k];
                }
            }
        }
        out
    }

    /// The mean signal of every cell's vertices (the paper's f_τ), one
    /// value per cell and channel (flat row-major, as the vertex signal), or
    /// `None` for a shape without signal.
    pub fn cell_signal(&self) -> Option<Vec<f64>> {
        let f = self.signal()?;
        let k = self.n_channels();
        let w = 1.0 / self.kind().n_corners() as f64;
        Some(
            self.cell_iter()
                .flat_map(|c| (0..k).map(move |ch| w * c.iter().map(|&v| f[v * k + ch]).sum::<f64>()))
                .collect(),
        )
    }

    /// Lumped vertex volumes (DESIGN.md, D_0 lumped): vertex k gets
    /// (1/(d+1)) Σ_{τ∋k} r_τ. Unused vertices get 0. They sum to the total
    /// volume.
    pub fn vertex_volumes(&self) -> Vec<f64> {
        let w = 1.0 / self.kind().n_corners() as f64;
        let mut out = vec![0.0; self.n_vertices()];
        for (t, cell) in self.cell_iter().enumerate() {
            let r = self.cell_volume(t);
            for &v in cell {
                out[v] += w * r;
            }
        }
        out
    }

    /// Total d-volume Σ_τ r_τ (length of a curve, area of a surface).
    pub fn total_volume(&self) -> f64 {
        (0..self.n_cells()).map(|t| self.cell_volume(t)).sum()
    }

    /// The bounding box of all vertices (used or not). For a shape without
    /// vertices both corners are `dim` zeros.
    pub fn bounding_box(&self) -> BoundingBox {
        let n = self.dim();
        if self.n_vertices() == 0 {
            return BoundingBox { min: vec![0.0; n], max: vec![0.0; n] };
        }
        let mut min = vec![f64::INFINITY; n];
        let mut max = vec![f64::NEG_INFINITY; n];
        for p in self.points().chunks_exact(n) {
            for k in 0..n {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
        BoundingBox { min, max }
    }

    /// Signed volume enclosed by a closed surface in R³, Σ_τ a·(b×c)/6:
    /// positive when the normals point outward. `None` for curves and
    /// planar shapes. Meaningless (but finite) for an open surface.
    pub fn signed_enclosed_volume(&self) -> Option<f64> {
        if self.kind() != CellKind::Triangle || self.dim() != 3 {
            return None;
        }
        let p = |v: usize| -> [f64; 3] {
            let q = self.point(v);
            [q[0], q[1], q[2]]
        };
        let vol = self
            .cell_iter()
            .map(|c| {
                let (a, b, d) = (p(c[0]), p(c[1]), p(c[2]));
                let n = cross(b, d);
                (a[0] * n[0] + a[1] * n[1] + a[2] * n[2]) / 6.0
            })
            .sum();
        Some(vol)
    }
}
