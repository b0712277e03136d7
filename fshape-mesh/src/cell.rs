//! The kinds of cells and their facets, which every other module names.

/// The kind of cell an fshape is made of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CellKind {
    /// Segments (d = 1): polygonal curves in R² or R³.
    Segment,
    /// Triangles (d = 2): surfaces in R³ or flat triangulated domains in R².
    Triangle,
}

impl CellKind {
    /// Number of vertices of one cell, d + 1.
    pub fn n_corners(self) -> usize {
        match self {
            CellKind::Segment => 2,
            CellKind::Triangle => 3,
        }
    }

    /// Intrinsic dimension d of the cells.
    pub fn dim(self) -> usize {
        self.n_corners() - 1
    }

    /// A lower-case name (`"segment"`, `"triangle"`), used in reports.
    pub fn name(self) -> &'static str {
        match self {
            CellKind::Segment => "segment",
            CellKind::Triangle => "triangle",
        }
    }
}

/// A facet: an edge `[a, b]` of a triangle mesh, or a vertex `[v, v]` of a
/// curve (both entries equal).
pub type Facet = [usize; 2];
