//! Solving D_s(x) h = b with a factorisation reused across x.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::SparseColMatRef;
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky};
use faer::{Conj, MatMut, Par, Side};

use crate::norm::{SignalNorm, Workspace};
use crate::{FemError, Norm};

/// A workspace that factors D_s(x) for successive x (same connectivity) and
/// solves with it. The symbolic analysis lives in the [`SignalNorm`]; the
/// numeric factor, the assembled values and the scratch memory are
/// allocated by the first `factor`, so later `factor` and `solve_in_place`
/// calls do not allocate.
///
/// ```
/// use fshape_fem::{Norm, SignalNorm};
/// let s = fshape_mesh::generate::icosphere(2, 1.0);
/// let d = SignalNorm::try_new(&s, Norm::H1 { length: 1.0 })?;
/// let mut solver = d.solver()?;
/// solver.factor(s.points())?;
/// let b = d.matvec(s.points(), &vec![1.0; s.n_vertices()])?;
/// let h = solver.solve(&b)?; // D h = D·1
/// assert!(h.iter().all(|v| (v - 1.0).abs() < 1e-12));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct Solver<'a> {
    norm: &'a SignalNorm,
    symbolic: Option<&'a SymbolicCholesky<usize>>,
    values: Vec<f64>,
    ws: Workspace,
    l_values: Vec<f64>,
    mem: MemBuffer,
    factored: bool,
}

impl SignalNorm {
    /// A solver workspace for this norm. The first call runs the Cholesky
    /// analysis of the pattern (fill-reducing [`crate::FillOrdering`],
    /// nested dissection by default; elimination tree); later
    /// calls reuse it.
    pub fn solver(&self) -> Result<Solver<'_>, FemError> {
        let symbolic = self.symbolic()?;
        let (l_len, req) = match symbolic {
            Some(s) => (
                s.len_val(),
                StackReq::any_of(&[
                    s.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
                    s.solve_in_place_scratch::<f64>(1, Par::Seq),
                ]),
            ),
            None => (0, StackReq::EMPTY),
        };
        Ok(Solver {
            norm: self,
            symbolic,
            values: Vec::new(),
            ws: Workspace::default(),
            l_values: vec![0.0; l_len],
            mem: MemBuffer::new(req),
            factored: false,
        })
    }
}

impl Solver<'_> {
    /// Assembles and factors D_s(x) (numeric factorisation only: the
    /// ordering and elimination tree are reused).
    pub fn factor(&mut self, x: &[f64]) -> Result<(), FemError> {
        self.factored = false;
        self.norm.assemble_into(x, &mut self.ws, &mut self.values)?;
        self.norm.check_mass(&self.ws)?;
        if let Some(symbolic) = self.symbolic {
            let a = SparseColMatRef::new(self.norm.pattern.as_ref(), &self.values);
            symbolic
                .factorize_numeric_llt::<f64>(
                    &mut self.l_values,
                    a,
                    Side::Lower,
                    LltRegularization::default(),
                    Par::Seq,
                    MemStack::new(&mut self.mem),
                    Default::default(),
                )
                .map_err(|e| FemError::Factorisation { message: format!("{e:?}") })?;
        }
        self.factored = true;
        Ok(())
    }

    /// Solves D_s(x) h = b in place (b becomes h), for the x of the last
    /// successful [`Solver::factor`].
    pub fn solve_in_place(&mut self, b: &mut [f64]) -> Result<(), FemError> {
        if !self.factored {
            return Err(FemError::NotFactored);
        }
        let n = self.norm.n_vertices();
        if b.len() != n {
            return Err(FemError::Dimension { what: "right-hand side", expected: n, found: b.len() });
        }
        match (self.symbolic, self.norm.norm()) {
            (None, Norm::L2Lumped) => b.iter_mut().zip(&self.values).for_each(|(v, d)| *v /= d),
            (Some(symbolic), _) => {
                let llt = LltRef::<usize, f64>::new(symbolic, &self.l_values);
                let rhs = MatMut::from_column_major_slice_mut(b, n, 1);
                llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.mem));
            }
            (None, _) => unreachable!("only the lumped norm has no symbolic factorisation"),
        }
        Ok(())
    }

    /// Solves D_s(x) h = b, returning h.
    pub fn solve(&mut self, b: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut h = b.to_vec();
        self.solve_in_place(&mut h)?;
        Ok(h)
    }

    /// Number of stored values of the Cholesky factor (a measure of fill).
    pub fn l_len(&self) -> usize {
        self.l_values.len()
    }

    /// The assembled lower-triangle values of the last factored D_s(x).
    pub fn values(&self) -> &[f64] {
        &self.values
    }
}
