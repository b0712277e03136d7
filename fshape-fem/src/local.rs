//! Local (per-cell) matrices, generic over the number type so that one
//! formula gives values (f64) and exact x-derivatives (num-dual forward
//! mode).

use fshape_mesh::CellKind;
use num_dual::DualNum;

use crate::Norm;

/// The largest local coordinate count: 3 corners × 3 coordinates.
pub(crate) const MAX_LOCAL: usize = 9;

/// Per-cell matrices are at most 3 × 3.
pub(crate) type Local<D> = [[D; 3]; 3];

/// The local matrix of one cell for `norm`, from its corner coordinates
/// `x` (`corners × n`, flat). Returns the matrix and the cell's volume r_τ.
///
/// Triangle (corners a, b, c; e_i the edge opposite corner i, e_0 = c − b,
/// e_1 = a − c, e_2 = b − a; area A):
/// - lumped mass: diag(A/3);
/// - P1 mass: (A/12)(1 + δ_ij), from the edge-midpoint rule of the paper
///   (section 4.2.2), exact for products of P1 functions;
/// - P1 stiffness: e_i·e_j / (4A) (∇φ_i = n × e_i / 2A), the cotangent
///   weights in another form.
///
/// Segment (length L): lumped diag(L/2); P1 mass (L/6)(1 + δ_ij); stiffness
/// (1/L)[[1, −1], [−1, 1]].
///
/// H¹ is mass + ℓ²·stiffness. The volume is √(‖·‖²), whose derivative is
/// undefined at zero volume: callers refuse degenerate cells before asking
/// for stiffness derivatives.
pub(crate) fn local_matrix<D: DualNum<Primitive = f64> + Copy>(
    kind: CellKind,
    n: usize,
    x: &[D],
    norm: Norm,
) -> (Local<D>, D) {
    let zero = D::from(0.0);
    let mut m = [[zero; 3]; 3];
    let p = |c: usize, k: usize| x[c * n + k];
    match kind {
        CellKind::Segment => {
            let len2 = (0..n).fold(zero, |acc, k| acc + (p(1, k) - p(0, k)) * (p(1, k) - p(0, k)));
            let len = len2.sqrt();
            match norm {
                Norm::L2Lumped => {
                    m[0][0] = len * 0.5;
                    m[1][1] = len * 0.5;
                }
                Norm::L2 | Norm::H1 { .. } => {
                    for (i, row) in m.iter_mut().enumerate().take(2) {
                        for (j, v) in row.iter_mut().enumerate().take(2) {
                            *v = len * (if i == j { 2.0 } else { 1.0 } / 6.0);
                        }
                    }
                }
            }
            if let Norm::H1 { length } = norm {
                let k = D::from(length * length) / len;
                m[0][0] += k;
                m[1][1] += k;
                m[0][1] -= k;
                m[1][0] -= k;
            }
            (m, len)
        }
        CellKind::Triangle => {
            // Edge vectors opposite each corner.
            let e = |i: usize, k: usize| match i {
                0 => p(2, k) - p(1, k),
                1 => p(0, k) - p(2, k),
                _ => p(1, k) - p(0, k),
            };
            let dot = |i: usize, j: usize| (0..n).fold(zero, |acc, k| acc + e(i, k) * e(j, k));
            // Lagrange's identity |u × v|² = |u|²|v|² − (u·v)², with u = e_2,
            // v = −e_1 = c − a: works in R² and R³ alike.
            let (uu, vv, uv) = (dot(2, 2), dot(1, 1), -dot(2, 1));
            let area = (uu * vv - uv * uv).sqrt() * 0.5;
            match norm {
                Norm::L2Lumped => {
                    for (i, row) in m.iter_mut().enumerate() {
                        row[i] = area / 3.0;
                    }
                }
                Norm::L2 | Norm::H1 { .. } => {
                    for (i, row) in m.iter_mut().enumerate() {
                        for (j, v) in row.iter_mut().enumerate() {
                            *v = area * (if i == j { 2.0 } else { 1.0 } / 12.0);
                        }
                    }
                }
            }
            if let Norm::H1 { length } = norm {
                let w = D::from(length * length) / (area * 4.0);
                for (i, row) in m.iter_mut().enumerate() {
                    for (j, v) in row.iter_mut().enumerate() {
                        *v += w * dot(i, j);
                    }
                }
            }
            (m, area)
        }
    }
}

/// The volume of a cell from its corner coordinates (f64).
pub(crate) fn volume(kind: CellKind, n: usize, x: &[f64]) -> f64 {
    local_matrix(kind, n, x, Norm::L2Lumped).1
}
