//! The little dense linear algebra a general linear model needs: a thin QR
//! by Gram–Schmidt, an orthonormal complement and a Cholesky solve. The
//! matrices are (subjects × design columns) and (columns × columns), tens
//! by a few, so plain loops are the clearest and fast enough.

/// Relative norm below which a column counts as a combination of the
/// previous ones.
const DEPENDENT: f64 = 1e-10;

/// The thin QR factorisation X = Q R of an n × p matrix (row-major) by
/// modified Gram–Schmidt, each column orthogonalised twice (which makes Q
/// orthonormal to rounding for any conditioning short of dependence).
/// `Err(j)`: column j is (to 1e-10 of its norm) a combination of columns
/// 0..j, or zero.
pub(crate) fn qr(x: &[f64], n: usize, p: usize) -> Result<(Vec<f64>, Vec<f64>), usize> {
    let mut q = vec![0.0; n * p];
    let mut r = vec![0.0; p * p];
    for j in 0..p {
        let mut v: Vec<f64> = (0..n).map(|i| x[i * p + j]).collect();
        let norm0 = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        for _ in 0..2 {
            for k in 0..j {
                let d: f64 = (0..n).map(|i| q[i * p + k] * v[i]).sum();
                r[k * p + j] += d;
                for (i, vi) in v.iter_mut().enumerate() {
                    *vi -= d * q[i * p + k];
                }
            }
        }
        let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        if norm0 == 0.0 || norm <= DEPENDENT * norm0 {
            return Err(j);
        }
        r[j * p + j] = norm;
        for (i, vi) in v.iter().enumerate() {
            q[i * p + j] = vi / norm;
        }
    }
    Ok((q, r))
}

/// An orthonormal basis (p × (p − r), row-major) of the vectors b with
/// C b = 0, for the r × p matrix C of full row rank: C's rows are
/// orthonormalised, then the unit vectors e_0, e_1, … are orthogonalised
/// against them and kept while independent.
pub(crate) fn null_space(c: &[f64], r: usize, p: usize) -> Vec<f64> {
    let mut basis: Vec<Vec<f64>> = Vec::with_capacity(p);
    let push = |mut v: Vec<f64>, keep: bool, out: &mut Vec<Vec<f64>>| -> bool {
        let norm0 = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        for _ in 0..2 {
            for b in out.iter() {
                let d: f64 = b.iter().zip(&v).map(|(a, c)| a * c).sum();
                for (vi, bi) in v.iter_mut().zip(b) {
                    *vi -= d * bi;
                }
            }
        }
        let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        if norm0 == 0.0 || norm <= 1e-8 * norm0 {
            return false;
        }
        if keep {
            out.push(v.iter().map(|a| a / norm).collect());
        }
        true
    };
    for k in 0..r {
        push(c[k * p..(k + 1) * p].to_vec(), true, &mut basis);
    }
    let rows = basis.len();
    for j in 0..p {
        if basis.len() == p {
            break;
        }
        let mut e = vec![0.0; p];
        e[j] = 1.0;
        push(e, true, &mut basis);
    }
    let k = p - rows;
    let mut out = vec![0.0; p * k];
    for (col, b) in basis[rows..].iter().enumerate() {
        for (i, &v) in b.iter().enumerate() {
            out[i * k + col] = v;
        }
    }
    out
}

/// The Cholesky factor L (lower, row-major) of a symmetric positive
/// definite k × k matrix, or `None` when a pivot is not positive (to
/// 1e-12 of the diagonal's scale).
pub(crate) fn cholesky(a: &[f64], k: usize) -> Option<Vec<f64>> {
    let scale = (0..k).map(|i| a[i * k + i].abs()).fold(0.0, f64::max);
    let mut l = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..=i {
            let s: f64 = a[i * k + j] - (0..j).map(|m| l[i * k + m] * l[j * k + m]).sum::<f64>();
            if i == j {
                if s.is_nan() || s <= 1e-12 * scale {
                    return None;
                }
                l[i * k + i] = s.sqrt();
            } else {
                l[i * k + j] = s / l[j * k + j];
            }
        }
    }
    Some(l)
}

/// Solves L Lᵀ x = b in place with the factor of [`cholesky`].
pub(crate) fn cholesky_solve(l: &[f64], k: usize, b: &mut [f64]) {
    for i in 0..k {
        b[i] = (b[i] - (0..i).map(|m| l[i * k + m] * b[m]).sum::<f64>()) / l[i * k + i];
    }
    for i in (0..k).rev() {
        b[i] = (b[i] - (i + 1..k).map(|m| l[m * k + i] * b[m]).sum::<f64>()) / l[i * k + i];
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
