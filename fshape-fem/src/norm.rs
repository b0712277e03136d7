//! The signal norm of a fixed connectivity, evaluated at any vertex
//! positions x.

use std::sync::OnceLock;

use faer::Side;
use faer::sparse::SymbolicSparseColMat;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use fshape_mesh::{CellKind, FShape, ZERO_VOLUME_REL};
use num_dual::{Dual64, DualNum};
use rayon::prelude::*;

use crate::local::{Local, MAX_LOCAL, local_grad, local_matrix, local_matrix_f64, local_parts, volume};
use crate::{FemError, Norm};

/// Scratch memory for the `*_into` methods of [`SignalNorm`] (per-cell
/// values, kept between calls), so that a loop over time steps allocates
/// nothing once the first call has sized it. One per thread of work;
/// `Workspace::default()` is empty.
#[derive(Debug, Default)]
pub struct Workspace {
    per_cell: Vec<[f64; MAX_LOCAL]>,
    volumes: Vec<f64>,
    mass: Vec<f64>,
}

const NO_ENTRY: u32 = u32::MAX;

/// A signal norm D_s(x) for one connectivity: the sparsity pattern, the
/// Cholesky analysis and the incidence tables are built once, here; every
/// method takes the current vertex positions x (flat, `dim` per vertex).
#[derive(Debug)]
pub struct SignalNorm {
    norm: Norm,
    kind: CellKind,
    dim: usize,
    n_vertices: usize,
    cells: Vec<usize>,
    /// Lower-triangular CSC pattern of D (diagonal only for lumped).
    pub(crate) pattern: SymbolicSparseColMat<usize>,
    /// For each stored entry e, the local slots (cell·9 + 3i + j) that sum
    /// into it, in increasing order: `slots[slot_ptr[e]..slot_ptr[e + 1]]`.
    slot_ptr: Vec<usize>,
    slots: Vec<usize>,
    /// The inverse map: slot_entry[s] = the entry slot s sums into, or
    /// `NO_ENTRY` (the upper half of a local matrix, off-diagonal lumped).
    /// Built on the first [`SignalNorm::assemble_into`] (the raw-array
    /// assembly of mass and stiffness does not need it); u32 halves its
    /// memory, and `try_new` refuses patterns with 2³² − 1 entries or more.
    slot_entry: OnceLock<Vec<u32>>,
    /// For each vertex, its (cell·3 + corner) incidences in increasing order.
    inc_ptr: Vec<usize>,
    inc: Vec<usize>,
    /// Cholesky analysis (fill-reducing ordering, elimination tree), done on the first
    /// [`SignalNorm::solver`] call; never for the diagonal lumped norm.
    symbolic: OnceLock<Result<SymbolicCholesky<usize>, FemError>>,
    parallel: bool,
    ordering: FillOrdering,
}

/// The fill-reducing ordering of the Cholesky factor.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FillOrdering {
    /// Approximate minimum degree (faer's).
    Amd,
    /// METIS nested dissection, postordered by its elimination tree; AMD
    /// if METIS cannot order the pattern.
    #[default]
    NestedDissection,
}

impl SignalNorm {
    /// Builds the norm for the shape's connectivity (its positions are not
    /// kept: pass x to every method).
    pub fn try_new(shape: &FShape, norm: Norm) -> Result<Self, FemError> {
        if let Norm::H1 { length } = norm
            && !(length > 0.0 && length.is_finite())
        {
            return Err(FemError::Length { length });
        }
        let (kind, dim, n_vertices) = (shape.kind(), shape.dim(), shape.n_vertices());
        let cells = shape.cells().to_vec();
        let corners = kind.n_corners();
        let (inc_ptr, inc) = incidence(&cells, corners, n_vertices);
        let lumped = norm == Norm::L2Lumped;
        let Pattern { col_ptr, row_idx, slot_ptr, slots } = lower_pattern(&cells, corners, &inc_ptr, &inc, lumped);
        let pattern = SymbolicSparseColMat::new_checked(n_vertices, n_vertices, col_ptr, None, row_idx);
        let symbolic = OnceLock::new();
        let entries = slot_ptr.len() - 1;
        if u32::try_from(entries).map_or(true, |e| e == NO_ENTRY) {
            return Err(FemError::TooLarge { entries });
        }
        Ok(SignalNorm {
            slot_entry: OnceLock::new(),
            norm,
            kind,
            dim,
            n_vertices,
            cells,
            pattern,
            slot_ptr,
            slots,
            inc_ptr,
            inc,
            symbolic,
            parallel: true,
            ordering: FillOrdering::default(),
        })
    }

    /// The Cholesky analysis of the pattern (computed once), or `None` for
    /// the diagonal lumped norm.
    pub(crate) fn symbolic(&self) -> Result<Option<&SymbolicCholesky<usize>>, FemError> {
        if self.norm == Norm::L2Lumped {
            return Ok(None);
        }
        let s = self.symbolic.get_or_init(|| {
            let order = match self.ordering {
                FillOrdering::Amd => None,
                FillOrdering::NestedDissection => crate::ordering::nested_dissection(self.pattern.as_ref()),
            };
            let inverse = order.as_ref().map(|fwd| {
                let mut inv = vec![0usize; fwd.len()];
                for (k, &v) in fwd.iter().enumerate() {
                    inv[v] = k;
                }
                inv
            });
            let ordering = match (&order, &inverse) {
                (Some(fwd), Some(inv)) => {
                    SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(fwd, inv, self.n_vertices))
                }
                _ => SymmetricOrdering::Amd,
            };
            factorize_symbolic_cholesky(self.pattern.as_ref(), Side::Lower, ordering, CholeskySymbolicParams::default())
                .map_err(|e| FemError::Factorisation { message: format!("{e:?}") })
        });
        s.as_ref().map(Some).map_err(Clone::clone)
    }

    /// Chooses parallel (default) or serial evaluation. Both give the same
    /// results bit for bit.
    pub fn with_parallel(mut self, parallel: bool) -> Self {
        self.parallel = parallel;
        self
    }

    /// Chooses the fill-reducing ordering of the factorisation (before the
    /// first [`SignalNorm::solver`] call; later calls keep the analysis).
    pub fn with_ordering(mut self, ordering: FillOrdering) -> Self {
        self.ordering = ordering;
        self
    }

    /// The norm.
    pub fn norm(&self) -> Norm {
        self.norm
    }

    /// Number of vertices P (the size of D).
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }

    /// Number of stored entries of the lower triangle of D.
    pub fn nnz_lower(&self) -> usize {
        self.pattern.row_idx().len()
    }

    /// The lower-triangular pattern: column pointers and row indices (CSC).
    pub fn pattern(&self) -> (&[usize], &[usize]) {
        (self.pattern.col_ptr(), self.pattern.row_idx())
    }

    fn corners(&self) -> usize {
        self.kind.n_corners()
    }

    fn check_len(&self, what: &'static str, v: &[f64], expected: usize) -> Result<(), FemError> {
        if v.len() == expected { Ok(()) } else { Err(FemError::Dimension { what, expected, found: v.len() }) }
    }

    fn check_x(&self, x: &[f64]) -> Result<(), FemError> {
        self.check_len("x", x, self.n_vertices * self.dim)
    }

    /// The volume at or below which a cell counts as degenerate: the
    /// validator's rule, ZERO_VOLUME_REL × diag^d of x's bounding box.
    fn zero_volume_tolerance(&self, x: &[f64]) -> f64 {
        let n = self.dim;
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in x.chunks_exact(n) {
            for k in 0..n {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let diag = lo[..n].iter().zip(&hi[..n]).map(|(a, b)| (b - a) * (b - a)).sum::<f64>().sqrt();
        ZERO_VOLUME_REL * diag.powi(self.kind.dim() as i32)
    }

    /// Refuses zero-volume cells where `what` needs a positive volume.
    fn check_volumes(&self, x: &[f64], what: &'static str, ws: &mut Workspace) -> Result<(), FemError> {
        let tol = self.zero_volume_tolerance(x);
        self.fill_cells(&mut ws.volumes, |_, c| {
            let mut buf = [0.0; MAX_LOCAL];
            volume(self.kind, self.dim, self.gather_coords(x, c, &mut buf))
        });
        match ws.volumes.iter().position(|v| !exceeds(*v, tol)) {
            Some(cell) => Err(FemError::ZeroVolumeCell { cell, volume: ws.volumes[cell], what }),
            None => Ok(()),
        }
    }

    fn gather_coords<'b>(&self, x: &[f64], c: &[usize], buf: &'b mut [f64; MAX_LOCAL]) -> &'b [f64] {
        let n = self.dim;
        for (i, &v) in c.iter().enumerate() {
            buf[i * n..(i + 1) * n].copy_from_slice(&x[v * n..(v + 1) * n]);
        }
        &buf[..c.len() * n]
    }

    /// Runs `f` on every cell (in parallel if enabled), collecting results
    /// in cell order.
    fn map_cells<T: Send>(&self, f: impl Fn(usize, &[usize]) -> T + Sync + Send) -> Vec<T> {
        let k = self.corners();
        if self.parallel {
            self.cells.par_chunks_exact(k).enumerate().map(|(t, c)| f(t, c)).collect()
        } else {
            self.cells.chunks_exact(k).enumerate().map(|(t, c)| f(t, c)).collect()
        }
    }

    /// Like [`Self::map_cells`], into `out` (resized to the number of
    /// cells; no allocation once it has the capacity).
    fn fill_cells<T: Send + Copy + Default>(&self, out: &mut Vec<T>, f: impl Fn(usize, &[usize]) -> T + Sync + Send) {
        let k = self.corners();
        out.clear();
        out.resize(self.cells.len() / k, T::default());
        if self.parallel {
            out.par_iter_mut().zip(self.cells.par_chunks_exact(k)).enumerate().for_each(|(t, (o, c))| *o = f(t, c));
        } else {
            out.iter_mut().zip(self.cells.chunks_exact(k)).enumerate().for_each(|(t, (o, c))| *o = f(t, c));
        }
    }

    /// out[v·w + k] = Σ over v's incidences (t, i) of per_cell[t][i·w + k],
    /// summed in incidence order (deterministic, serial = parallel).
    fn gather_vertices(&self, per_cell: &[[f64; MAX_LOCAL]], w: usize, out: &mut [f64]) {
        let one = |v: usize, out: &mut [f64]| {
            out.fill(0.0);
            for &ti in &self.inc[self.inc_ptr[v]..self.inc_ptr[v + 1]] {
                let (t, i) = (ti / 3, ti % 3);
                for k in 0..w {
                    out[k] += per_cell[t][i * w + k];
                }
            }
        };
        if self.parallel {
            out.par_chunks_mut(w.max(1)).enumerate().for_each(|(v, o)| one(v, o));
        } else {
            out.chunks_mut(w.max(1)).enumerate().for_each(|(v, o)| one(v, o));
        }
    }

    /// The values of the lower triangle of D_s(x), in the order of
    /// [`SignalNorm::pattern`].
    ///
    /// ```
    /// use fshape_fem::{Norm, SignalNorm};
    /// // A single segment of length 2: lumped mass diag(1, 1).
    /// let s = fshape_mesh::FShape::try_new(2, fshape_mesh::CellKind::Segment, vec![0., 0., 2., 0.], vec![0, 1], None)?;
    /// let d = SignalNorm::try_new(&s, Norm::L2Lumped)?;
    /// assert_eq!(d.assemble(s.points())?, vec![1.0, 1.0]);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn assemble(&self, x: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut out = Vec::new();
        self.assemble_into(x, &mut Workspace::default(), &mut out)?;
        Ok(out)
    }

    /// [`SignalNorm::assemble`] into `out` (resized to
    /// [`SignalNorm::nnz_lower`]), with scratch memory from `ws`: no
    /// allocation once `ws` and `out` have been used on this mesh.
    pub fn assemble_into(&self, x: &[f64], ws: &mut Workspace, out: &mut Vec<f64>) -> Result<(), FemError> {
        self.check_x(x)?;
        let k = self.corners();
        let tol = self.zero_volume_tolerance(x);
        let check = matches!(self.norm, Norm::H1 { .. });
        out.clear();
        out.resize(self.nnz_lower(), 0.0);
        // One serial pass over the cells, scattering each local matrix into
        // the entries it belongs to. Cells are visited in increasing order,
        // so every entry is summed in the order of its slots, whatever the
        // threads elsewhere. Measured against parallel local matrices
        // followed by a parallel gather per entry: on two cores the single
        // pass is faster (no intermediate per-cell buffer, no wake-up of
        // the pool), which is what the per-step refactorisation needs.
        // The vertex masses (Σ of incident cell volumes: the lumped mass up
        // to a factor) come along for [`Self::check_mass`].
        ws.mass.clear();
        ws.mass.resize(self.n_vertices, 0.0);
        let slot_entry = self.slot_entry.get_or_init(|| {
            let mut map = vec![NO_ENTRY; self.cells.len() / k * MAX_LOCAL];
            for e in 0..self.slot_ptr.len() - 1 {
                for &s in &self.slots[self.slot_ptr[e]..self.slot_ptr[e + 1]] {
                    // Below NO_ENTRY: checked in try_new.
                    map[s] = e as u32;
                }
            }
            map
        });
        for (t, c) in self.cells.chunks_exact(k).enumerate() {
            let mut buf = [0.0; MAX_LOCAL];
            let (m, vol) = local_matrix_f64(self.kind, self.dim, self.gather_coords(x, c, &mut buf), self.norm);
            // The stiffness of a degenerate cell is not finite: refuse it.
            if check && !exceeds(vol, tol) {
                return Err(FemError::ZeroVolumeCell { cell: t, volume: vol, what: "stiffness matrix" });
            }
            for &v in c {
                ws.mass[v] += vol;
            }
            let se = &slot_entry[t * MAX_LOCAL..(t + 1) * MAX_LOCAL];
            for i in 0..k {
                for j in 0..k {
                    let e = se[3 * i + j];
                    if e != NO_ENTRY {
                        out[e as usize] += m[i][j];
                    }
                }
            }
        }
        Ok(())
    }

    /// The P1 mass and P1 stiffness values separately, on this norm's
    /// pattern (for the L2 and H1 norms, which share it), in one pass over
    /// the cells: what libigl's `massmatrix(FULL)` and `−cotmatrix` compute.
    pub fn assemble_mass_and_stiffness(&self, x: &[f64]) -> Result<(Vec<f64>, Vec<f64>), FemError> {
        self.check_x(x)?;
        if self.norm == Norm::L2Lumped {
            return Err(FemError::UnknownNorm { name: "stiffness on the lumped (diagonal) pattern".into() });
        }
        let tol = self.zero_volume_tolerance(x);
        let parts = self.map_cells(|_, c| {
            let mut buf = [0.0; MAX_LOCAL];
            local_parts(self.kind, self.dim, self.gather_coords(x, c, &mut buf), false, true)
        });
        if let Some(cell) = parts.iter().position(|p| !exceeds(p.2, tol)) {
            return Err(FemError::ZeroVolumeCell { cell, volume: parts[cell].2, what: "stiffness matrix" });
        }
        let entry = |e: usize| {
            self.slots[self.slot_ptr[e]..self.slot_ptr[e + 1]].iter().fold((0.0, 0.0), |(m, k), &s| {
                let (t, i, j) = (s / MAX_LOCAL, (s % MAX_LOCAL) / 3, s % 3);
                (m + parts[t].0[i][j], k + parts[t].1[i][j])
            })
        };
        let n = self.nnz_lower();
        let both: Vec<(f64, f64)> =
            if self.parallel { (0..n).into_par_iter().map(entry).collect() } else { (0..n).map(entry).collect() };
        Ok(both.into_iter().unzip())
    }

    /// D_s(x) h, computed cell by cell.
    pub fn matvec(&self, x: &[f64], h: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut out = vec![0.0; self.n_vertices];
        self.matvec_into(x, h, &mut Workspace::default(), &mut out)?;
        Ok(out)
    }

    /// [`SignalNorm::matvec`] into `out` (P values), with scratch memory
    /// from `ws`.
    pub fn matvec_into(&self, x: &[f64], h: &[f64], ws: &mut Workspace, out: &mut [f64]) -> Result<(), FemError> {
        self.check_x(x)?;
        self.check_len("h", h, self.n_vertices)?;
        self.check_len("output", out, self.n_vertices)?;
        if matches!(self.norm, Norm::H1 { .. }) {
            self.check_volumes(x, "stiffness matrix", ws)?;
        }
        self.fill_cells(&mut ws.per_cell, |_, c| {
            let mut buf = [0.0; MAX_LOCAL];
            let (m, _) = local_matrix_f64(self.kind, self.dim, self.gather_coords(x, c, &mut buf), self.norm);
            let mut out = [0.0; MAX_LOCAL];
            for i in 0..c.len() {
                out[i] = (0..c.len()).map(|j| m[i][j] * h[c[j]]).sum();
            }
            out
        });
        self.gather_vertices(&ws.per_cell, 1, out);
        Ok(())
    }

    /// The quadratic form fᵀ D_s(x) f = ‖f‖²_{H^s(x)}.
    pub fn quadratic(&self, x: &[f64], f: &[f64]) -> Result<f64, FemError> {
        self.check_x(x)?;
        self.check_len("f", f, self.n_vertices)?;
        if matches!(self.norm, Norm::H1 { .. }) {
            self.check_volumes(x, "stiffness matrix", &mut Workspace::default())?;
        }
        let per_cell = self.map_cells(|_, c| {
            let mut buf = [0.0; MAX_LOCAL];
            let (m, _) = local_matrix_f64(self.kind, self.dim, self.gather_coords(x, c, &mut buf), self.norm);
            bilinear(&m, c, f, f)
        });
        Ok(per_cell.iter().sum())
    }

    /// ∂_x (aᵀ D_s(x) b): the gradient with respect to every vertex
    /// position (flat, `dim` per vertex). With a = b = h this is
    /// ∂_x(hᵀ D_s(x) h), the signal term of the metamorphosis momentum
    /// equation.
    pub fn grad(&self, x: &[f64], a: &[f64], b: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut out = vec![0.0; x.len()];
        self.grad_into(x, a, b, &mut Workspace::default(), &mut out)?;
        Ok(out)
    }

    /// [`SignalNorm::grad`] into `out` (P·n values), with scratch memory
    /// from `ws`.
    pub fn grad_into(
        &self,
        x: &[f64],
        a: &[f64],
        b: &[f64],
        ws: &mut Workspace,
        out: &mut [f64],
    ) -> Result<(), FemError> {
        self.check_x(x)?;
        self.check_len("a", a, self.n_vertices)?;
        self.check_len("b", b, self.n_vertices)?;
        self.check_len("output", out, x.len())?;
        self.check_volumes(x, "x-derivative of the norm", ws)?;
        let n = self.dim;
        self.fill_cells(&mut ws.per_cell, |_, c| {
            let mut buf = [0.0; MAX_LOCAL];
            let coords = self.gather_coords(x, c, &mut buf);
            let (mut al, mut bl) = ([0.0; 3], [0.0; 3]);
            for (i, &v) in c.iter().enumerate() {
                al[i] = a[v];
                bl[i] = b[v];
            }
            let mut out = [0.0; MAX_LOCAL];
            local_grad(self.kind, n, coords, &al, &bl, self.norm, &mut out);
            out
        });
        self.gather_vertices(&ws.per_cell, n, out);
        Ok(())
    }

    /// The directional derivative of [`SignalNorm::grad`] in the direction
    /// `dx`: (∂²_x (aᵀ D_s(x) b)) dx, a Hessian–vector product: forward
    /// mode (x + ε dx) through the analytic per-cell gradient.
    pub fn hvp(&self, x: &[f64], a: &[f64], b: &[f64], dx: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut out = vec![0.0; x.len()];
        self.hvp_into(x, a, b, dx, &mut Workspace::default(), &mut out)?;
        Ok(out)
    }

    /// [`SignalNorm::hvp`] into `out` (P·n values), with scratch memory
    /// from `ws`.
    #[allow(clippy::too_many_arguments)]
    pub fn hvp_into(
        &self,
        x: &[f64],
        a: &[f64],
        b: &[f64],
        dx: &[f64],
        ws: &mut Workspace,
        out: &mut [f64],
    ) -> Result<(), FemError> {
        self.check_x(x)?;
        self.check_len("a", a, self.n_vertices)?;
        self.check_len("b", b, self.n_vertices)?;
        self.check_len("dx", dx, x.len())?;
        self.check_len("output", out, x.len())?;
        self.check_volumes(x, "x-derivative of the norm", ws)?;
        let n = self.dim;
        self.fill_cells(&mut ws.per_cell, |_, c| {
            let m = c.len() * n;
            let mut xd = [Dual64::from(0.0); MAX_LOCAL];
            let (mut al, mut bl) = ([0.0; 3], [0.0; 3]);
            for (i, &v) in c.iter().enumerate() {
                for k in 0..n {
                    xd[i * n + k] = Dual64::new(x[v * n + k], dx[v * n + k]);
                }
                al[i] = a[v];
                bl[i] = b[v];
            }
            let mut g = [Dual64::from(0.0); MAX_LOCAL];
            local_grad(self.kind, n, &xd[..m], &al, &bl, self.norm, &mut g[..m]);
            std::array::from_fn(|r| g[r].eps)
        });
        self.gather_vertices(&ws.per_cell, n, out);
        Ok(())
    }

    /// (∂_x D_s · dx) h = d/dε D_s(x + ε dx) h at ε = 0.
    pub fn dmatvec(&self, x: &[f64], dx: &[f64], h: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut out = vec![0.0; self.n_vertices];
        self.dmatvec_into(x, dx, h, &mut Workspace::default(), &mut out)?;
        Ok(out)
    }

    /// [`SignalNorm::dmatvec`] into `out` (P values), with scratch memory
    /// from `ws`.
    pub fn dmatvec_into(
        &self,
        x: &[f64],
        dx: &[f64],
        h: &[f64],
        ws: &mut Workspace,
        out: &mut [f64],
    ) -> Result<(), FemError> {
        self.check_x(x)?;
        self.check_len("dx", dx, x.len())?;
        self.check_len("h", h, self.n_vertices)?;
        self.check_len("output", out, self.n_vertices)?;
        self.check_volumes(x, "x-derivative of the norm", ws)?;
        let n = self.dim;
        self.fill_cells(&mut ws.per_cell, |_, c| {
            let mut xd = [Dual64::from(0.0); MAX_LOCAL];
            for (i, &v) in c.iter().enumerate() {
                for k in 0..n {
                    xd[i * n + k] = Dual64::new(x[v * n + k], dx[v * n + k]);
                }
            }
            let (mat, _) = local_matrix(self.kind, n, &xd[..c.len() * n], self.norm);
            let mut out = [0.0; MAX_LOCAL];
            for i in 0..c.len() {
                out[i] = (0..c.len()).map(|j| mat[i][j].eps * h[c[j]]).sum();
            }
            out
        });
        self.gather_vertices(&ws.per_cell, 1, out);
        Ok(())
    }

    /// Refuses a singular matrix: a vertex whose row of D sums to zero
    /// carries no mass: the summed volume of its cells, recorded in `ws` by
    /// the last [`Self::assemble_into`], is zero (or NaN).
    pub(crate) fn check_mass(&self, ws: &Workspace) -> Result<(), FemError> {
        match ws.mass.iter().position(|&m| !exceeds(m, 0.0)) {
            Some(vertex) => Err(FemError::Singular { vertex }),
            None => Ok(()),
        }
    }
}

/// For each vertex, its (cell·3 + corner) incidences in increasing order
/// (a counting sort: O(T)).
fn incidence(cells: &[usize], corners: usize, n_vertices: usize) -> (Vec<usize>, Vec<usize>) {
    let mut ptr = vec![0usize; n_vertices + 1];
    for &v in cells {
        ptr[v + 1] += 1;
    }
    for v in 0..n_vertices {
        ptr[v + 1] += ptr[v];
    }
    let mut fill = ptr.clone();
    let mut inc = vec![0usize; cells.len()];
    for (t, c) in cells.chunks_exact(corners).enumerate() {
        for (i, &v) in c.iter().enumerate() {
            inc[fill[v]] = t * 3 + i;
            fill[v] += 1;
        }
    }
    (ptr, inc)
}

/// The lower-triangular CSC pattern, and for each stored entry the local
/// slots (cell·9 + 3i + j) that sum into it.
struct Pattern {
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    slot_ptr: Vec<usize>,
    slots: Vec<usize>,
}

/// Builds the [`Pattern`]. Column j holds j itself (so an unused vertex
/// shows up as a zero pivot, reported as `Singular`, rather than as a
/// missing column) and, unless `lumped`, every neighbour i > j sharing a
/// cell with it. The slots of entry (i, j) are the local entries (t, a, b)
/// with corner b of cell t at j and corner a at i (one of each symmetric
/// pair), listed in increasing slot order so that every entry is summed in
/// the same order whatever the threads.
///
/// Everything is built column by column from the vertex→cell incidence
/// lists, a handful of entries each, in fixed chunks of columns run in
/// parallel and concatenated in order: no global sort, and a result that
/// does not depend on the number of threads.
fn lower_pattern(cells: &[usize], corners: usize, inc_ptr: &[usize], inc: &[usize], lumped: bool) -> Pattern {
    let n = inc_ptr.len() - 1;
    const CHUNK: usize = 4096;
    struct Chunk {
        row_lens: Vec<usize>,
        rows: Vec<usize>,
        slot_lens: Vec<usize>,
        slots: Vec<usize>,
    }
    let chunks: Vec<Chunk> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|k| {
            let mut out = Chunk { row_lens: vec![], rows: vec![], slot_lens: vec![], slots: vec![] };
            let (mut rows, mut pairs) = (Vec::new(), Vec::new());
            for j in k * CHUNK..((k + 1) * CHUNK).min(n) {
                rows.clear();
                pairs.clear();
                rows.push(j);
                for &ti in &inc[inc_ptr[j]..inc_ptr[j + 1]] {
                    let (t, b) = (ti / 3, ti % 3);
                    let c = &cells[t * corners..(t + 1) * corners];
                    for (a, &i) in c.iter().enumerate() {
                        if if lumped { a == b } else { i >= j } {
                            pairs.push((i, t * MAX_LOCAL + 3 * a + b));
                            rows.push(i);
                        }
                    }
                }
                rows.sort_unstable();
                rows.dedup();
                // Sorting (row, slot) groups the slots by entry, each group
                // in increasing slot order.
                pairs.sort_unstable();
                let mut p = 0;
                for &r in &rows {
                    let start = p;
                    while p < pairs.len() && pairs[p].0 == r {
                        out.slots.push(pairs[p].1);
                        p += 1;
                    }
                    out.slot_lens.push(p - start);
                }
                out.rows.extend_from_slice(&rows);
                out.row_lens.push(rows.len());
            }
            out
        })
        .collect();
    let nnz: usize = chunks.iter().map(|c| c.rows.len()).sum();
    let mut pat = Pattern {
        col_ptr: Vec::with_capacity(n + 1),
        row_idx: Vec::with_capacity(nnz),
        slot_ptr: Vec::with_capacity(nnz + 1),
        slots: Vec::with_capacity(chunks.iter().map(|c| c.slots.len()).sum()),
    };
    pat.col_ptr.push(0);
    pat.slot_ptr.push(0);
    for c in chunks {
        for l in c.row_lens {
            pat.col_ptr.push(pat.col_ptr[pat.col_ptr.len() - 1] + l);
        }
        for l in c.slot_lens {
            pat.slot_ptr.push(pat.slot_ptr[pat.slot_ptr.len() - 1] + l);
        }
        pat.row_idx.extend_from_slice(&c.rows);
        pat.slots.extend_from_slice(&c.slots);
    }
    pat
}

/// `v > tol`, false for NaN: a NaN volume or mass is as bad as a zero one.
fn exceeds(v: f64, tol: f64) -> bool {
    v.partial_cmp(&tol) == Some(std::cmp::Ordering::Greater)
}

/// aᵀ M b over one cell's corners.
fn bilinear<D: DualNum<Primitive = f64> + Copy>(m: &Local<D>, c: &[usize], a: &[f64], b: &[f64]) -> D {
    let mut q = D::from(0.0);
    for i in 0..c.len() {
        for j in 0..c.len() {
            q += m[i][j] * (a[c[i]] * b[c[j]]);
        }
    }
    q
}
