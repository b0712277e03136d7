//! Undoing one midpoint subdivision: the coarse mesh an icosphere or a
//! FreeSurfer icosahedral surface (fsaverage, fsaverage5, ...) was refined
//! from.
//!
//! Midpoint subdivision splits every triangle (a, b, c) into four, adding
//! one vertex per edge after the existing ones: (a, m_ab, m_ca), (b, m_bc,
//! m_ab), (c, m_ca, m_bc) and (m_ab, m_bc, m_ca). A closed surface of T
//! triangles and V vertices becomes one of 4T triangles and V + 3T/2
//! vertices whose first V vertices are the old ones. fshape's icospheres
//! are built so, and so are FreeSurfer's icosahedral surfaces (fsaverage5's
//! first 2562 vertices are fsaverage4's, its first 642 fsaverage3's), even
//! after the vertices moved (a pial surface): the coarse vertex is the
//! same point, so the coarse surface is a subsample of the fine one, with
//! its signal. This is what multi-resolution stages need on such surfaces
//! without a general mesh simplifier.

use std::collections::BTreeSet;

use crate::{CellKind, FShape, ShapeError};

/// Why a mesh is not one midpoint subdivision of a coarser one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CoarsenError {
    /// Only closed triangle surfaces are handled.
    #[error("only closed triangle surfaces can be coarsened, got a {0}")]
    Kind(&'static str),
    /// The counts do not fit: a subdivision of a closed surface of T
    /// triangles and V vertices has 4T triangles and V + 3T/2 vertices.
    #[error(
        "{vertices} vertices and {triangles} triangles are not one midpoint subdivision of a closed surface \
         (4T triangles and V + 3T/2 vertices for T triangles and V vertices before)"
    )]
    Counts {
        /// Vertices of the mesh.
        vertices: usize,
        /// Triangles of the mesh.
        triangles: usize,
    },
    /// A vertex after the coarse ones does not split one coarse edge.
    #[error(
        "vertex {vertex} should split an edge between two of the first {coarse} vertices, \
         but {found} of its neighbours are among them (the vertices are not in subdivision order)"
    )]
    NotAMidpoint {
        /// The vertex.
        vertex: usize,
        /// How many of its neighbours are coarse vertices.
        found: usize,
        /// The number of coarse vertices.
        coarse: usize,
    },
    /// The corner triangles do not make the expected coarse triangles.
    #[error("the corner triangles make {found} coarse triangles, not {expected}")]
    Triangles {
        /// Coarse triangles found.
        found: usize,
        /// Coarse triangles expected (a quarter of the triangles).
        expected: usize,
    },
    /// The coarse mesh is not a valid shape.
    #[error("the coarse mesh: {0}")]
    Shape(#[from] ShapeError),
}

impl FShape {
    /// The mesh this one was made from by one midpoint subdivision (see
    /// the module docs): its first vertices, their signal, and the coarse
    /// triangles with this mesh's orientation. An error where this mesh is
    /// not such a subdivision (a general mesh needs a simplifier instead).
    ///
    /// ```
    /// use fshape_mesh::generate::icosphere;
    /// let coarse = icosphere(3, 1.0).coarsened()?;
    /// assert_eq!((coarse.n_vertices(), coarse.n_cells()), (162, 320));
    /// assert_eq!(coarse.points(), icosphere(2, 1.0).points());
    /// # Ok::<(), fshape_mesh::CoarsenError>(())
    /// ```
    pub fn coarsened(&self) -> Result<FShape, CoarsenError> {
        if self.kind() != CellKind::Triangle {
            return Err(CoarsenError::Kind(self.kind().name()));
        }
        let (v, t) = (self.n_vertices(), self.n_cells());
        let counts = CoarsenError::Counts { vertices: v, triangles: t };
        if !t.is_multiple_of(8) || t == 0 {
            return Err(counts);
        }
        let (tc, edges) = (t / 4, 3 * t / 8);
        let Some(nc) = v.checked_sub(edges).filter(|&n| n >= 3) else { return Err(counts) };
        let cells = self.cells();
        // The coarse neighbours of every new vertex: the ends of its edge.
        let mut coarse_nb: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); v - nc];
        for tri in cells.chunks_exact(3) {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                if a >= nc && b < nc {
                    coarse_nb[a - nc].insert(b);
                }
                if b >= nc && a < nc {
                    coarse_nb[b - nc].insert(a);
                }
            }
        }
        let mut ends = Vec::with_capacity(v - nc);
        for (k, nb) in coarse_nb.iter().enumerate() {
            let [a, b] = nb.iter().copied().collect::<Vec<_>>()[..] else {
                return Err(CoarsenError::NotAMidpoint { vertex: nc + k, found: nb.len(), coarse: nc });
            };
            ends.push((a, b));
        }
        let other = |m: usize, a: usize| -> Option<usize> {
            let (p, q) = ends[m - nc];
            if p == a {
                Some(q)
            } else if q == a {
                Some(p)
            } else {
                None
            }
        };
        // Each coarse triangle from its corner at its smallest vertex.
        let mut coarse = Vec::with_capacity(3 * tc);
        for tri in cells.chunks_exact(3) {
            let old: Vec<usize> = (0..3).filter(|&k| tri[k] < nc).collect();
            let [k] = old[..] else { continue };
            let (a, m1, m2) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
            if let (Some(b), Some(c)) = (other(m1, a), other(m2, a))
                && a < b
                && a < c
            {
                coarse.extend([a, b, c]);
            }
        }
        if coarse.len() != 3 * tc {
            return Err(CoarsenError::Triangles { found: coarse.len() / 3, expected: tc });
        }
        let dim = self.dim();
        let points = self.points()[..nc * dim].to_vec();
        let k = self.n_channels().max(1);
        let signal = self.signal().map(|s| s[..nc * k].to_vec());
        let mask = self.mask().map(|m| m[..nc].to_vec());
        Ok(FShape::try_new(dim, CellKind::Triangle, points, coarse, None)?.with_signals_and_mask(signal, k, mask)?)
    }
}

#[cfg(test)]
mod tests {
    use super::CoarsenError;
    use crate::generate::{icosphere, square};

    /// Triangles as sets of rotations: the same oriented triangle however
    /// its corners are listed first.
    fn oriented(cells: &[usize]) -> std::collections::BTreeSet<[usize; 3]> {
        cells
            .chunks_exact(3)
            .map(|t| {
                let k = (0..3).min_by_key(|&k| t[k]).unwrap();
                [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
            })
            .collect()
    }

    #[test]
    fn an_icosphere_coarsens_to_the_level_below_with_its_orientation() {
        for level in 1..=4 {
            let fine = icosphere(level, 2.0);
            let signal: Vec<f64> = fine.points().chunks_exact(3).map(|p| p[0] - p[2]).collect();
            let fine = fine.with_signal(Some(signal.clone())).unwrap();
            let coarse = fine.coarsened().unwrap();
            let expected = icosphere(level - 1, 2.0);
            assert_eq!(coarse.points(), expected.points());
            assert_eq!(oriented(coarse.cells()), oriented(expected.cells()), "level {level}");
            assert_eq!(coarse.signal().unwrap(), &signal[..coarse.n_vertices()]);
        }
    }

    #[test]
    fn meshes_that_are_not_a_subdivision_are_refused_with_the_reason() {
        // Open surface: the counts of a closed subdivision do not fit.
        assert!(matches!(square(300, 1).coarsened(), Err(CoarsenError::Counts { .. })));
        // The level-0 icosahedron: 12 vertices, 20 triangles.
        assert!(matches!(icosphere(0, 1.0).coarsened(), Err(CoarsenError::Counts { .. })));
        // Vertex order not the subdivision's: the last vertex moved first.
        let s = icosphere(2, 1.0);
        let n = s.n_vertices();
        let renumber = |i: usize| if i == n - 1 { 0 } else { i + 1 };
        let mut points = vec![0.0; 3 * n];
        for i in 0..n {
            points[3 * renumber(i)..3 * renumber(i) + 3].copy_from_slice(s.point(i));
        }
        let cells: Vec<usize> = s.cells().iter().map(|&i| renumber(i)).collect();
        let shuffled = crate::FShape::try_new(3, crate::CellKind::Triangle, points, cells, None).unwrap();
        let err = shuffled.coarsened().unwrap_err();
        assert!(matches!(err, CoarsenError::NotAMidpoint { .. }), "{err}");
    }
}
