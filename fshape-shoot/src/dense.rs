//! A dense Cholesky factor of a kernel matrix plus a diagonal, K + diag(r),
//! on a point set, and solves with it on P × n vector fields (each
//! coordinate alike): parallel transport's velocity-to-momentum map
//! (r = 0) and fshape-match's energy metric of p_0 (r a ridge).
//!
//! The factorisation and the solves are faer's blocked dense Cholesky,
//! run serially (`Par::Seq`): faer's parallel reductions would make the
//! bits depend on the number of threads.

use fshape_kernels::Kernel;

/// The Cholesky factor L of K + diag(r) (LLᵀ = K + diag(r)), with
/// K_ij = k(|x_i − x_j|²) the kernel's profile (its exact values, also
/// for a kernel whose sums are truncated or on a grid).
pub struct DenseKernelFactor {
    dim: usize,
    l: faer::Mat<f64>,
}

impl std::fmt::Debug for DenseKernelFactor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DenseKernelFactor").field("n", &self.l.nrows()).field("dim", &self.dim).finish_non_exhaustive()
    }
}

impl DenseKernelFactor {
    /// Factors K + diag(`ridge`) on `points` (`dim` coordinates each, one
    /// ridge value per point); `None` where a pivot is not positive.
    pub fn new(points: &[f64], dim: usize, kernel: &Kernel, ridge: &[f64]) -> Option<DenseKernelFactor> {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::linalg::cholesky::llt::factor;
        let n = ridge.len();
        debug_assert_eq!(points.len(), n * dim);
        // The lower triangle, column by column (faer is column-major).
        let mut l = faer::Mat::<f64>::zeros(n, n);
        for j in 0..n {
            let xj = &points[j * dim..(j + 1) * dim];
            let col = l.col_mut(j).try_as_col_major_mut().expect("a fresh matrix is contiguous").as_slice_mut();
            for (i, v) in col.iter_mut().enumerate().skip(j) {
                let xi = &points[i * dim..(i + 1) * dim];
                *v = kernel.value(xi.iter().zip(xj).map(|(a, b)| (a - b) * (a - b)).sum());
            }
            col[j] += ridge[j];
        }
        let par = faer::Par::Seq;
        let mut mem = MemBuffer::new(factor::cholesky_in_place_scratch::<f64>(n, par, Default::default()));
        let done =
            factor::cholesky_in_place(l.as_mut(), Default::default(), par, MemStack::new(&mut mem), Default::default());
        done.ok().map(|_| DenseKernelFactor { dim, l })
    }

    /// The number of points n.
    pub fn n(&self) -> usize {
        self.l.nrows()
    }

    /// The points' dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// v ← (K + diag(r))⁻¹v on the first n·dim values of `v` (a P × n
    /// vector field, each coordinate alike); the rest is left as it is.
    pub fn solve_in_place(&self, v: &mut [f64]) {
        use faer::dyn_stack::MemStack;
        let (n, d) = (self.l.nrows(), self.dim);
        // The block is n × d row-major: as a matrix, d × n column-major; its
        // transpose is the n × d right-hand side.
        let mut rhs = faer::Mat::<f64>::from_fn(n, d, |i, c| v[i * d + c]);
        faer::linalg::cholesky::llt::solve::solve_in_place(
            self.l.as_ref(),
            rhs.as_mut(),
            faer::Par::Seq,
            MemStack::new(&mut []),
        );
        for i in 0..n {
            for c in 0..d {
                v[i * d + c] = rhs[(i, c)];
            }
        }
    }
}
