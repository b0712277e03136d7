//! The discrete functional shape: vertices, cells and an optional signal.

pub use crate::cell::CellKind;
use crate::validate::{self, Finding};

/// Why an [`FShape`] could not be built.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum ShapeError {
    /// The ambient dimension is not 2 or 3. Pass `dim = 2` for curves or
    /// flat domains in the plane, `dim = 3` otherwise.
    #[error("ambient dimension {dim} is not supported (use 2 or 3)")]
    Dimension {
        /// The dimension given.
        dim: usize,
    },
    /// The flat coordinate array does not hold a whole number of points.
    #[error("{len} coordinates do not make whole {dim}-D points")]
    PointsLength {
        /// Length of the coordinate array.
        len: usize,
        /// Ambient dimension.
        dim: usize,
    },
    /// The flat cell array does not hold a whole number of cells.
    #[error("{len} cell indices do not make whole {kind}s of {corners} vertices")]
    CellsLength {
        /// Length of the index array.
        len: usize,
        /// Cell kind name.
        kind: &'static str,
        /// Vertices per cell.
        corners: usize,
    },
    /// A signal was given with zero channels per vertex.
    #[error("a signal has at least one channel per vertex")]
    Channels,
    /// The data is well formed but some values make the shape unusable
    /// (NaN coordinates, an index out of range, ...). Every such problem is
    /// listed with its index; fix the input or use the repairs of
    /// [`FShape::repaired`] for the ones it can fix.
    #[error("invalid fshape: {}", validate::summarise(.problems))]
    Invalid {
        /// Every blocking problem found, in index order.
        problems: Vec<Finding>,
    },
}

/// A discrete functional shape (paper section 4): vertices `x` (P × n, flat
/// row-major), cells `C` (T × (d+1), flat) and an optional per-vertex signal
/// `f` (P × k values, flat row-major: the k channels of vertex 0, then of
/// vertex 1, ...; k = 1 unless built with [`FShape::with_signals`]).
/// Absent signal means a purely geometric shape.
///
/// The type guarantees what every computation needs: finite coordinates and
/// signal, cell indices in range, no repeated index inside a cell, a signal
/// of the right length. Conditions that still allow computing (unused
/// vertices, zero-volume or duplicate cells, boundaries, non-manifold edges,
/// inconsistent orientation) are reported by [`FShape::validate`] as
/// warnings.
///
/// ```
/// use fshape_mesh::{CellKind, FShape};
/// // The unit right triangle has area 1/2.
/// let s = FShape::try_new(2, CellKind::Triangle, vec![0., 0., 1., 0., 0., 1.], vec![0, 1, 2], None)?;
/// assert_eq!(s.total_volume(), 0.5);
/// # Ok::<(), fshape_mesh::ShapeError>(())
/// ```
///
/// A shape may carry a **mask**: one weight in [0, 1] per vertex saying how
/// much its signal value counts (0: the vertex has no value, as HCP's
/// medial wall; 1: a full value; between: a soft edge). The geometry is
/// all real; only the signal is masked. At a vertex of mask 0 the signal
/// is stored as NaN whatever was given (nothing may read it), so that two
/// shapes differing only there are the same shape. A mask masks every
/// channel of a vertex.
#[derive(Clone, Debug)]
pub struct FShape {
    dim: usize,
    kind: CellKind,
    points: Vec<f64>,
    cells: Vec<usize>,
    signal: Option<Vec<f64>>,
    /// Signal values per vertex (1 without a signal, so that the flat
    /// layout's arithmetic needs no special case).
    channels: usize,
    mask: Option<Vec<f64>>,
}

/// Equal coordinates, cells, mask and signal, a NaN signal value (a masked
/// vertex's) equal to a NaN.
impl PartialEq for FShape {
    fn eq(&self, other: &Self) -> bool {
        let same = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
        };
        self.dim == other.dim
            && self.kind == other.kind
            && self.points == other.points
            && self.cells == other.cells
            && self.mask == other.mask
            && self.channels == other.channels
            && match (&self.signal, &other.signal) {
                (Some(a), Some(b)) => same(a, b),
                (None, None) => true,
                _ => false,
            }
    }
}

impl FShape {
    /// Builds an fshape, checking everything a computation relies on.
    ///
    /// `points` holds `dim` coordinates per vertex, `cells` holds
    /// `kind.n_corners()` vertex indices per cell, `signal` one value per
    /// vertex. Every blocking problem is reported at once with its index.
    pub fn try_new(
        dim: usize,
        kind: CellKind,
        points: Vec<f64>,
        cells: Vec<usize>,
        signal: Option<Vec<f64>>,
    ) -> Result<Self, ShapeError> {
        if dim != 2 && dim != 3 {
            return Err(ShapeError::Dimension { dim });
        }
        if !points.len().is_multiple_of(dim) {
            return Err(ShapeError::PointsLength { len: points.len(), dim });
        }
        if !cells.len().is_multiple_of(kind.n_corners()) {
            return Err(ShapeError::CellsLength { len: cells.len(), kind: kind.name(), corners: kind.n_corners() });
        }
        FShape::checked(dim, kind, points, cells, signal, 1, None)
    }

    fn checked(
        dim: usize,
        kind: CellKind,
        points: Vec<f64>,
        cells: Vec<usize>,
        mut signal: Option<Vec<f64>>,
        channels: usize,
        mask: Option<Vec<f64>>,
    ) -> Result<Self, ShapeError> {
        if channels == 0 && signal.is_some() {
            return Err(ShapeError::Channels);
        }
        let channels = channels.max(1);
        let problems =
            validate::blocking_problems(dim, kind, &points, &cells, signal.as_deref(), channels, mask.as_deref());
        if !problems.is_empty() {
            return Err(ShapeError::Invalid { problems });
        }
        if let (Some(f), Some(m)) = (&mut signal, &mask) {
            for (v, w) in f.chunks_exact_mut(channels).zip(m) {
                if *w == 0.0 {
                    v.fill(f64::NAN);
                }
            }
        }
        let channels = if signal.is_some() { channels } else { 1 };
        Ok(FShape { dim, kind, points, cells, signal, channels, mask })
    }

    /// Replaces (or removes) the signal by one value per vertex, checking
    /// its length and values (NaN is accepted at masked vertices only); the
    /// mask is kept.
    pub fn with_signal(self, signal: Option<Vec<f64>>) -> Result<Self, ShapeError> {
        FShape::checked(self.dim, self.kind, self.points, self.cells, signal, 1, self.mask)
    }

    /// Replaces (or removes) the signal by `channels` values per vertex
    /// (several maps on one surface: thickness, myelin, curvature), flat
    /// row-major: vertex v's channel c is `signal[v * channels + c]`. The
    /// mask is kept and masks every channel.
    ///
    /// ```
    /// use fshape_mesh::{CellKind, FShape};
    /// let s = FShape::try_new(2, CellKind::Triangle, vec![0., 0., 1., 0., 0., 1.], vec![0, 1, 2], None)?;
    /// let s = s.with_signals(Some(vec![1.0, 10.0, 2.0, 20.0, 3.0, 30.0]), 2)?;
    /// assert_eq!((s.n_channels(), s.channel(1).unwrap()), (2, vec![10.0, 20.0, 30.0]));
    /// # Ok::<(), fshape_mesh::ShapeError>(())
    /// ```
    pub fn with_signals(self, signal: Option<Vec<f64>>, channels: usize) -> Result<Self, ShapeError> {
        FShape::checked(self.dim, self.kind, self.points, self.cells, signal, channels, self.mask)
    }

    /// [`FShape::with_signals`] and [`FShape::with_mask`] together.
    pub fn with_signals_and_mask(
        self,
        signal: Option<Vec<f64>>,
        channels: usize,
        mask: Option<Vec<f64>>,
    ) -> Result<Self, ShapeError> {
        FShape::checked(self.dim, self.kind, self.points, self.cells, signal, channels, mask)
    }

    /// Replaces (or removes) the mask (see [`FShape`]): one weight in
    /// [0, 1] per vertex. The signal must be finite where the mask is
    /// positive, and is set to NaN where it is 0.
    ///
    /// ```
    /// use fshape_mesh::{CellKind, FShape};
    /// let s = FShape::try_new(2, CellKind::Triangle, vec![0., 0., 1., 0., 0., 1.], vec![0, 1, 2], None)?;
    /// let s = s.with_signal_and_mask(Some(vec![1.0, f64::NAN, 3.0]), Some(vec![1.0, 0.0, 0.5]))?;
    /// assert!(s.signal().unwrap()[1].is_nan() && s.mask().unwrap()[2] == 0.5);
    /// # Ok::<(), fshape_mesh::ShapeError>(())
    /// ```
    pub fn with_mask(self, mask: Option<Vec<f64>>) -> Result<Self, ShapeError> {
        FShape::checked(self.dim, self.kind, self.points, self.cells, self.signal, self.channels, mask)
    }

    /// Replaces the signal (one value per vertex) and the mask together (a
    /// signal with missing values and the mask that says where they are).
    pub fn with_signal_and_mask(self, signal: Option<Vec<f64>>, mask: Option<Vec<f64>>) -> Result<Self, ShapeError> {
        FShape::checked(self.dim, self.kind, self.points, self.cells, signal, 1, mask)
    }

    /// Replaces the vertex positions (same count, same dimension), as when a
    /// shape moves along a deformation; signal and mask are kept.
    pub fn with_points(self, points: Vec<f64>) -> Result<Self, ShapeError> {
        FShape::checked(self.dim, self.kind, points, self.cells, self.signal, self.channels, self.mask)
    }

    /// The mask, one weight in [0, 1] per vertex, if any (see [`FShape`]).
    pub fn mask(&self) -> Option<&[f64]> {
        self.mask.as_deref()
    }

    /// Ambient dimension n (2 or 3).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Cell kind (segment or triangle).
    pub fn kind(&self) -> CellKind {
        self.kind
    }

    /// Number of vertices P.
    pub fn n_vertices(&self) -> usize {
        self.points.len() / self.dim
    }

    /// Number of cells T.
    pub fn n_cells(&self) -> usize {
        self.cells.len() / self.kind.n_corners()
    }

    /// All coordinates, `dim` per vertex.
    pub fn points(&self) -> &[f64] {
        &self.points
    }

    /// The coordinates of vertex `i`.
    ///
    /// # Panics
    /// If `i >= self.n_vertices()`.
    #[track_caller]
    pub fn point(&self, i: usize) -> &[f64] {
        &self.points[i * self.dim..(i + 1) * self.dim]
    }

    /// All cell indices, `kind.n_corners()` per cell.
    pub fn cells(&self) -> &[usize] {
        &self.cells
    }

    /// The vertex indices of cell `t`.
    ///
    /// # Panics
    /// If `t >= self.n_cells()`.
    #[track_caller]
    pub fn cell(&self, t: usize) -> &[usize] {
        let c = self.kind.n_corners();
        &self.cells[t * c..(t + 1) * c]
    }

    /// Iterator over the cells.
    pub fn cell_iter(&self) -> std::slice::ChunksExact<'_, usize> {
        self.cells.chunks_exact(self.kind.n_corners())
    }

    /// The signal, [`FShape::n_channels`] values per vertex (flat
    /// row-major), if any.
    pub fn signal(&self) -> Option<&[f64]> {
        self.signal.as_deref()
    }

    /// Signal values per vertex: 0 without a signal, else k ≥ 1.
    pub fn n_channels(&self) -> usize {
        if self.signal.is_some() { self.channels } else { 0 }
    }

    /// Channel `c` of the signal, one value per vertex, if the shape has a
    /// signal with that channel.
    pub fn channel(&self, c: usize) -> Option<Vec<f64>> {
        let k = self.channels;
        self.signal.as_ref().filter(|_| c < k).map(|f| f.iter().skip(c).step_by(k).copied().collect())
    }

    /// Takes the parts apart: `(dim, kind, points, cells, signal)` (the
    /// mask, if any, is dropped: read it with [`FShape::mask`] first, and
    /// the signal is flat: read [`FShape::n_channels`] first).
    pub fn into_parts(self) -> (usize, CellKind, Vec<f64>, Vec<usize>, Option<Vec<f64>>) {
        (self.dim, self.kind, self.points, self.cells, self.signal)
    }
}
