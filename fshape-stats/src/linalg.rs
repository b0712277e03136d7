//! The little dense linear algebra a general linear model needs, through
//! faer: a thin QR, an orthonormal complement and a Cholesky solve. The
//! matrices are (subjects × design columns) and (columns × columns), tens
//! by a few; every call runs sequentially (`Par::Seq`), so results do not
//! depend on the thread count, and the helpers keep the row-major slices
//! the model holds.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::linalg::householder;
use faer::linalg::qr::no_pivoting::factor as qr_factor;
use faer::{Conj, Mat, Par};

/// Relative norm below which a column counts as a combination of the
/// previous ones.
const DEPENDENT: f64 = 1e-10;

/// Sequential: the same bits for any number of threads.
const PAR: Par = Par::Seq;

fn matrix(x: &[f64], n: usize, p: usize) -> Mat<f64> {
    Mat::from_fn(n, p, |i, j| x[i * p + j])
}

/// Householder QR of the n × p matrix `a` in place (R above the diagonal,
/// the reflectors below) and its block factors.
fn householder_qr(a: &mut Mat<f64>) -> Mat<f64> {
    let (n, p) = (a.nrows(), a.ncols());
    let bs = qr_factor::recommended_block_size::<f64>(n, p);
    let mut coeff = Mat::<f64>::zeros(bs, n.min(p));
    let mut mem = MemBuffer::new(qr_factor::qr_in_place_scratch::<f64>(n, p, bs, PAR, Default::default()));
    qr_factor::qr_in_place(a.as_mut(), coeff.as_mut(), PAR, MemStack::new(&mut mem), Default::default());
    coeff
}

/// The first `cols` columns of Q from [`householder_qr`]'s output.
fn q_columns(factored: &Mat<f64>, coeff: &Mat<f64>, cols: usize) -> Mat<f64> {
    let n = factored.nrows();
    let mut q = Mat::<f64>::identity(n, cols);
    let mut mem = MemBuffer::new(householder::apply_block_householder_sequence_on_the_left_in_place_scratch::<f64>(
        n,
        coeff.nrows(),
        cols,
    ));
    householder::apply_block_householder_sequence_on_the_left_in_place_with_conj(
        factored.as_ref(),
        coeff.as_ref(),
        Conj::No,
        q.as_mut(),
        PAR,
        MemStack::new(&mut mem),
    );
    q
}

/// The thin QR factorisation X = Q R of an n × p matrix (row-major), with
/// R's diagonal positive (which makes it unique). `Err(j)`: column j is
/// (to 1e-10 of its norm) a combination of columns 0..j, or zero.
pub(crate) fn qr(x: &[f64], n: usize, p: usize) -> Result<(Vec<f64>, Vec<f64>), usize> {
    let norms: Vec<f64> = (0..p).map(|j| (0..n).map(|i| x[i * p + j].powi(2)).sum::<f64>().sqrt()).collect();
    let mut a = matrix(x, n, p);
    let coeff = householder_qr(&mut a);
    // |R_jj| is the norm of column j's part orthogonal to columns 0..j.
    for j in 0..n.min(p) {
        if norms[j] == 0.0 || a[(j, j)].abs() <= DEPENDENT * norms[j] {
            return Err(j);
        }
    }
    if p > n {
        return Err(n);
    }
    let q = q_columns(&a, &coeff, p);
    let sign: Vec<f64> = (0..p).map(|j| a[(j, j)].signum()).collect();
    let q_rows = (0..n * p).map(|k| sign[k % p] * q[(k / p, k % p)]).collect();
    let r_rows = (0..p * p).map(|k| if k % p >= k / p { sign[k / p] * a[(k / p, k % p)] } else { 0.0 }).collect();
    Ok((q_rows, r_rows))
}

/// An orthonormal basis (p × (p − r), row-major) of the vectors b with
/// C b = 0, for the r × p matrix C of full row rank: the last p − r
/// columns of the full Q of Cᵀ = Q R.
pub(crate) fn null_space(c: &[f64], r: usize, p: usize) -> Vec<f64> {
    let mut a = Mat::from_fn(p, r, |i, k| c[k * p + i]);
    let k = p - r;
    if r == 0 {
        return (0..p * p).map(|i| f64::from(u8::from(i / p == i % p))).collect();
    }
    let coeff = householder_qr(&mut a);
    let q = q_columns(&a, &coeff, p);
    (0..p * k).map(|i| q[(i / k, r + i % k)]).collect()
}

/// The Cholesky factor L (lower, row-major) of a symmetric positive
/// definite k × k matrix, or `None` when a pivot is not positive (to
/// 1e-12 of the diagonal's scale).
pub(crate) fn cholesky(a: &[f64], k: usize) -> Option<Vec<f64>> {
    let scale = (0..k).map(|i| a[i * k + i].abs()).fold(0.0, f64::max);
    let mut l = matrix(a, k, k);
    let mut mem = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(k, PAR, Default::default()));
    llt::factor::cholesky_in_place(l.as_mut(), Default::default(), PAR, MemStack::new(&mut mem), Default::default())
        .ok()?;
    if (0..k).any(|i| {
        let pivot = l[(i, i)] * l[(i, i)];
        pivot.is_nan() || pivot <= 1e-12 * scale
    }) {
        return None;
    }
    Some((0..k * k).map(|i| if i % k <= i / k { l[(i / k, i % k)] } else { 0.0 }).collect())
}

/// Solves L Lᵀ x = b in place with the factor of [`cholesky`].
pub(crate) fn cholesky_solve(l: &[f64], k: usize, b: &mut [f64]) {
    let factor = matrix(l, k, k);
    let mut rhs = Mat::from_fn(k, 1, |i, _| b[i]);
    llt::solve::solve_in_place(factor.as_ref(), rhs.as_mut(), PAR, MemStack::new(&mut []));
    for (i, v) in b.iter_mut().enumerate() {
        *v = rhs[(i, 0)];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qr_reproduces_the_matrix_and_q_is_orthonormal() {
        let x = [1.0, 2.0, 0.5, 1.0, -1.0, 3.0, 1.0, 0.0, 1.0, 1.0, 4.0, -2.0];
        let (n, p) = (4, 3);
        let (q, r) = qr(&x, n, p).unwrap();
        for i in 0..n {
            for j in 0..p {
                let qr_ij: f64 = (0..p).map(|k| q[i * p + k] * r[k * p + j]).sum();
                assert!((qr_ij - x[i * p + j]).abs() < 1e-12);
            }
        }
        for a in 0..p {
            for b in 0..p {
                let d: f64 = (0..n).map(|i| q[i * p + a] * q[i * p + b]).sum();
                assert!((d - f64::from(u8::from(a == b))).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn qr_names_the_first_dependent_column() {
        // Column 2 = column 0 + column 1.
        let x = [1.0, 2.0, 3.0, 1.0, -1.0, 0.0, 1.0, 0.0, 1.0];
        assert_eq!(qr(&x, 3, 3), Err(2));
        assert_eq!(qr(&[0.0, 1.0, 0.0, 1.0], 2, 2), Err(0));
        // More columns than rows: the first beyond the rank.
        assert_eq!(qr(&[1.0, 0.0, 2.0, 0.0, 1.0, 3.0], 2, 3), Err(2));
    }

    #[test]
    fn qr_agrees_with_gram_schmidt_on_random_matrices() {
        // The oracle: classical Gram–Schmidt, R's diagonal positive as
        // the fast path's convention makes it.
        let mut seed = 7_u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for (n, p) in [(5, 1), (12, 4), (40, 7)] {
            let x: Vec<f64> = (0..n * p).map(|_| next()).collect();
            let (q, r) = qr(&x, n, p).unwrap();
            let mut basis: Vec<Vec<f64>> = Vec::new();
            for j in 0..p {
                let mut v: Vec<f64> = (0..n).map(|i| x[i * p + j]).collect();
                for (k, b) in basis.iter().enumerate() {
                    let d: f64 = (0..n).map(|i| b[i] * x[i * p + j]).sum();
                    assert!((d - r[k * p + j]).abs() < 1e-12, "R[{k}][{j}]");
                    for i in 0..n {
                        v[i] -= d * b[i];
                    }
                }
                let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
                assert!((norm - r[j * p + j]).abs() < 1e-12, "R[{j}][{j}]");
                for i in 0..n {
                    assert!((v[i] / norm - q[i * p + j]).abs() < 1e-10, "Q[{i}][{j}]");
                }
                basis.push(v.iter().map(|a| a / norm).collect());
            }
        }
    }

    #[test]
    fn the_null_space_is_orthonormal_and_annihilated() {
        let c = [0.0, 1.0, -1.0, 2.0];
        let p = 4;
        let z = null_space(&c, 1, p);
        let k = p - 1;
        for col in 0..k {
            let dot: f64 = (0..p).map(|i| c[i] * z[i * k + col]).sum();
            assert!(dot.abs() < 1e-12);
            for other in 0..k {
                let d: f64 = (0..p).map(|i| z[i * k + col] * z[i * k + other]).sum();
                assert!((d - f64::from(u8::from(col == other))).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn cholesky_solves_and_refuses_an_indefinite_matrix() {
        let a = [4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0];
        let l = cholesky(&a, 3).unwrap();
        let mut b = [1.0, -2.0, 0.5];
        cholesky_solve(&l, 3, &mut b);
        let back: Vec<f64> = (0..3).map(|i| (0..3).map(|j| a[i * 3 + j] * b[j]).sum()).collect();
        for (got, want) in back.iter().zip([1.0, -2.0, 0.5]) {
            assert!((got - want).abs() < 1e-12);
        }
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }
}
