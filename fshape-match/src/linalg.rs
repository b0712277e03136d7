//! Dense decompositions of the small matrices the matching layer needs
//! (a population's Gram matrix, a shape's second moments), through faer.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{self, ComputeEigenvectors};

use crate::MatchError;

/// The eigenvalues (in decreasing order) and unit eigenvectors (the columns
/// of a row-major n × n matrix, in the same order) of the symmetric n × n
/// matrix `a` (row-major; its lower triangle is read). faer's
/// self-adjoint eigendecomposition, sequential so that the result does not
/// depend on the thread count; each eigenvector's sign is fixed so that
/// its entry of largest magnitude (the first of equals) is positive, which
/// makes the result a function of `a` alone. An error when an entry is
/// not finite or the iteration does not converge.
pub fn symmetric_eigen(a: &[f64], n: usize) -> Result<(Vec<f64>, Vec<f64>), MatchError> {
    assert_eq!(a.len(), n * n, "an n × n matrix");
    if let Some(k) = a.iter().position(|v| !v.is_finite()) {
        return Err(MatchError::InvalidInput(format!(
            "eigendecomposition: entry ({}, {}) of the {n} × {n} matrix is {}",
            k / n,
            k % n,
            a[k]
        )));
    }
    let m = faer::Mat::<f64>::from_fn(n, n, |i, j| a[i * n + j]);
    let mut s = faer::diag::Diag::<f64>::zeros(n);
    let mut u = faer::Mat::<f64>::zeros(n, n);
    let par = faer::Par::Seq;
    let mut mem =
        MemBuffer::new(evd::self_adjoint_evd_scratch::<f64>(n, ComputeEigenvectors::Yes, par, Default::default()));
    evd::self_adjoint_evd(m.as_ref(), s.as_mut(), Some(u.as_mut()), par, MemStack::new(&mut mem), Default::default())
        .map_err(|e| MatchError::InvalidInput(format!("eigendecomposition of a {n} × {n} matrix: {e:?}")))?;
    // faer's order is nondecreasing: reversed, largest first.
    let values: Vec<f64> = (0..n).rev().map(|k| s[k]).collect();
    let mut vectors = vec![0.0; n * n];
    for (col, k) in (0..n).rev().enumerate() {
        let v: Vec<f64> = (0..n).map(|i| u[(i, k)]).collect();
        let peak = v.iter().enumerate().fold(0, |best, (i, x)| if x.abs() > v[best].abs() { i } else { best });
        let sign = if v.get(peak).is_some_and(|&x| x < 0.0) { -1.0 } else { 1.0 };
        for (i, x) in v.iter().enumerate() {
            vectors[i * n + col] = sign * x;
        }
    }
    Ok((values, vectors))
}
