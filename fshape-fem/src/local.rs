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
    let want_stiffness = matches!(norm, Norm::H1 { .. });
    let (mut m, k, vol) = local_parts(kind, n, x, norm == Norm::L2Lumped, want_stiffness);
    if let Norm::H1 { length } = norm {
        let l2 = length * length;
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += k[i][j] * l2;
            }
        }
    }
    (m, vol)
}

/// [`local_matrix`] for f64 coordinates, written out for triangles: the
/// per-time-step assembly spends most of its time here, and the generic
/// version (kept for the dual-number derivatives) costs about twice as
/// much. The same formulas; a test compares the two on random cells.
#[inline]
pub(crate) fn local_matrix_f64(kind: CellKind, n: usize, x: &[f64], norm: Norm) -> (Local<f64>, f64) {
    if kind != CellKind::Triangle {
        return local_matrix(kind, n, x, norm);
    }
    let (mut e0, mut e1, mut e2) = ([0.0; 3], [0.0; 3], [0.0; 3]);
    for j in 0..n {
        e0[j] = x[2 * n + j] - x[n + j];
        e1[j] = x[j] - x[2 * n + j];
        e2[j] = x[n + j] - x[j];
    }
    let dot = |a: &[f64; 3], b: &[f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (d00, d11, d22, d01, d02, d12) =
        (dot(&e0, &e0), dot(&e1, &e1), dot(&e2, &e2), dot(&e0, &e1), dot(&e0, &e2), dot(&e1, &e2));
    // Lagrange's identity with u = e_2, v = −e_1 (as in local_parts).
    let area = (d22 * d11 - d12 * d12).sqrt() * 0.5;
    let mut m = match norm {
        Norm::L2Lumped => {
            let a = area / 3.0;
            [[a, 0.0, 0.0], [0.0, a, 0.0], [0.0, 0.0, a]]
        }
        _ => {
            let (d, o) = (area * (2.0 / 12.0), area * (1.0 / 12.0));
            [[d, o, o], [o, d, o], [o, o, d]]
        }
    };
    if let Norm::H1 { length } = norm {
        let w = (area * 4.0).recip();
        let k = [[w * d00, w * d01, w * d02], [w * d01, w * d11, w * d12], [w * d02, w * d12, w * d22]];
        let l2 = length * length;
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += k[i][j] * l2;
            }
        }
    }
    (m, area)
}

/// The mass part (lumped or P1) and, when asked, the stiffness part of a
/// cell's local matrix, and its volume (see [`local_matrix`]).
#[expect(clippy::needless_range_loop, reason = "index notation follows the formulas (e_i, K_ij)")]
pub(crate) fn local_parts<D: DualNum<Primitive = f64> + Copy>(
    kind: CellKind,
    n: usize,
    x: &[D],
    lumped: bool,
    stiffness: bool,
) -> (Local<D>, Local<D>, D) {
    let zero = D::from(0.0);
    let (mut m, mut k) = ([[zero; 3]; 3], [[zero; 3]; 3]);
    let p = |c: usize, j: usize| x[c * n + j];
    match kind {
        CellKind::Segment => {
            let len = (0..n).fold(zero, |acc, j| acc + (p(1, j) - p(0, j)) * (p(1, j) - p(0, j))).sqrt();
            for (i, row) in m.iter_mut().enumerate().take(2) {
                for (j, v) in row.iter_mut().enumerate().take(2) {
                    *v = match (lumped, i == j) {
                        (true, true) => len * 0.5,
                        (true, false) => zero,
                        (false, diag) => len * (if diag { 2.0 } else { 1.0 } / 6.0),
                    };
                }
            }
            if stiffness {
                let w = len.recip();
                k[0][0] = w;
                k[1][1] = w;
                k[0][1] = -w;
                k[1][0] = -w;
            }
            (m, k, len)
        }
        CellKind::Triangle => {
            // Edge vectors opposite each corner.
            let mut e = [[zero; 3]; 3];
            for j in 0..n {
                e[0][j] = p(2, j) - p(1, j);
                e[1][j] = p(0, j) - p(2, j);
                e[2][j] = p(1, j) - p(0, j);
            }
            let dot = |a: usize, b: usize| (0..n).fold(zero, |acc, j| acc + e[a][j] * e[b][j]);
            // Lagrange's identity |u × v|² = |u|²|v|² − (u·v)², with u = e_2,
            // v = −e_1 = c − a: works in R² and R³ alike.
            let (uu, vv, uv) = (dot(2, 2), dot(1, 1), -dot(2, 1));
            let area = (uu * vv - uv * uv).sqrt() * 0.5;
            for (i, row) in m.iter_mut().enumerate() {
                for (j, v) in row.iter_mut().enumerate() {
                    *v = match (lumped, i == j) {
                        (true, true) => area / 3.0,
                        (true, false) => zero,
                        (false, diag) => area * (if diag { 2.0 } else { 1.0 } / 12.0),
                    };
                }
            }
            if stiffness {
                let w = (area * 4.0).recip();
                for i in 0..3 {
                    for j in i..3 {
                        let v = w * dot(i, j);
                        k[i][j] = v;
                        k[j][i] = v;
                    }
                }
            }
            (m, k, area)
        }
    }
}

/// The volume of a cell from its corner coordinates (f64).
pub(crate) fn volume(kind: CellKind, n: usize, x: &[f64]) -> f64 {
    local_parts(kind, n, x, true, false).2
}

/// ∂/∂x of q = aᵀ D_τ(x) b for one cell, analytically, written into
/// `out[..corners·n]` (the same value num-dual gives, at a fraction of the
/// cost; the tests check both against finite differences). Generic over
/// the number type like [`local_matrix`]: with f64 it is the gradient, with
/// [`num_dual::Dual64`] coordinates x + ε dx its ε part is the Hessian of q
/// applied to dx ([`crate::SignalNorm::hvp`]).
///
/// Triangle (u = x₁ − x₀, v = x₂ − x₀, A² = (|u|²|v|² − (u·v)²)/4):
/// q = A·m(a, b) + ℓ² (E_a·E_b)/(4A), with m(a, b) = (a·b + Σa Σb)/12 for
/// the P1 mass, (a·b)/3 lumped, and E_a = Σ_i a_i e_i = Σ_k c_k(a) x_k,
/// c(a) = (a₁ − a₂, a₂ − a₀, a₀ − a₁), so ∂E_a/∂x_k = c_k(a) I and
/// ∂q/∂x_k = m ∂A/∂x_k + ℓ² [(c_k(a) E_b + c_k(b) E_a)/(4A) − (E_a·E_b)/(4A²) ∂A/∂x_k].
/// Segment (length L, t = (x₁ − x₀)/L): q = L·m(a, b) + ℓ² (a₁ − a₀)(b₁ − b₀)/L,
/// ∂q/∂x₁ = −∂q/∂x₀ = [m − ℓ² (a₁ − a₀)(b₁ − b₀)/L²] t.
#[expect(clippy::needless_range_loop, reason = "index notation follows the formulas (x_c, e_k)")]
pub(crate) fn local_grad<D: DualNum<Primitive = f64> + Copy>(
    kind: CellKind,
    n: usize,
    x: &[D],
    a: &[f64],
    b: &[f64],
    norm: Norm,
    out: &mut [D],
) {
    let lumped = norm == Norm::L2Lumped;
    let l2 = if let Norm::H1 { length } = norm { length * length } else { 0.0 };
    let p = |c: usize, k: usize| x[c * n + k];
    // Σ_k s_k t_k from the first term on: the bits of f64's `sum` (which
    // starts from −0.0) for every input.
    let dot = |s: &[D; 3], t: &[D; 3]| {
        let mut acc = s[0] * t[0];
        for k in 1..n {
            acc += s[k] * t[k];
        }
        acc
    };
    let zero = D::from(0.0);
    match kind {
        CellKind::Segment => {
            let mut d = [zero; 3];
            for k in 0..n {
                d[k] = p(1, k) - p(0, k);
            }
            let len = dot(&d, &d).sqrt();
            let m = if lumped {
                0.5 * (a[0] * b[0] + a[1] * b[1])
            } else {
                (2.0 * a[0] * b[0] + a[0] * b[1] + a[1] * b[0] + 2.0 * a[1] * b[1]) / 6.0
            };
            let coef = D::from(m) - D::from(l2 * (a[1] - a[0]) * (b[1] - b[0])) / (len * len);
            for k in 0..n {
                let t = d[k] / len;
                out[k] = -(coef * t);
                out[n + k] = coef * t;
            }
        }
        CellKind::Triangle => {
            let (mut u, mut v) = ([zero; 3], [zero; 3]);
            for k in 0..n {
                u[k] = p(1, k) - p(0, k);
                v[k] = p(2, k) - p(0, k);
            }
            let (uu, vv, uv) = (dot(&u, &u), dot(&v, &v), dot(&u, &v));
            let area = (uu * vv - uv * uv).sqrt() * 0.5;
            // ∂A/∂u = (u|v|² − (u·v)v)/(4A), ∂A/∂v = (v|u|² − (u·v)u)/(4A).
            let mut da = [[zero; 3]; 3];
            for k in 0..n {
                da[1][k] = (u[k] * vv - uv * v[k]) / (area * 4.0);
                da[2][k] = (v[k] * uu - uv * u[k]) / (area * 4.0);
                da[0][k] = -da[1][k] - da[2][k];
            }
            let m = if lumped {
                (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / 3.0
            } else {
                (a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + (a[0] + a[1] + a[2]) * (b[0] + b[1] + b[2])) / 12.0
            };
            let ca = [a[1] - a[2], a[2] - a[0], a[0] - a[1]];
            let cb = [b[1] - b[2], b[2] - b[0], b[0] - b[1]];
            let (mut ea, mut eb) = ([zero; 3], [zero; 3]);
            for c in 0..3 {
                for k in 0..n {
                    ea[k] += p(c, k) * ca[c];
                    eb[k] += p(c, k) * cb[c];
                }
            }
            let eab = dot(&ea, &eb);
            for c in 0..3 {
                for k in 0..n {
                    let stiff = (eb[k] * ca[c] + ea[k] * cb[c]) / (area * 4.0) - eab / (area * 4.0 * area) * da[c][k];
                    out[c * n + k] = da[c][k] * m + stiff * l2;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use num_dual::{Dual, Dual64, DualSVec64};

    use super::{MAX_LOCAL, local_grad, local_matrix, local_matrix_f64};
    use crate::Norm;
    use fshape_mesh::CellKind;

    /// The cell's gradient and Hessian–vector product of q = aᵀ D_τ(x) b by
    /// nested forward mode through [`local_matrix`] (the x-derivatives of
    /// the local matrix itself, nothing written by hand): the oracle of
    /// [`local_grad`] in f64 and in dual numbers.
    fn nested_dual(
        kind: CellKind,
        n: usize,
        x: &[f64],
        dx: &[f64],
        a: &[f64],
        b: &[f64],
        norm: Norm,
    ) -> (Vec<f64>, Vec<f64>) {
        let corners = x.len() / n;
        let zero = Dual::new(DualSVec64::<MAX_LOCAL>::from(0.0), DualSVec64::from(0.0));
        let mut xd = vec![zero; x.len()];
        for r in 0..x.len() {
            xd[r] = Dual::new(DualSVec64::from_re(x[r]).derivative(r), DualSVec64::from(dx[r]));
        }
        let (m, _) = local_matrix(kind, n, &xd, norm);
        let mut q = zero;
        for i in 0..corners {
            for j in 0..corners {
                q += m[i][j] * (a[i] * b[j]);
            }
        }
        let grad = q.re.eps.0.map_or(vec![0.0; x.len()], |g| g.as_slice()[..x.len()].to_vec());
        let hvp = q.eps.eps.0.map_or(vec![0.0; x.len()], |g| g.as_slice()[..x.len()].to_vec());
        (grad, hvp)
    }

    proptest! {
        #![proptest_config(fshape_mesh::test_support::strategies::config(256, 0x10ca1))]

        /// The hand-written f64 triangle formula is the generic one, bit for
        /// bit (same operations in the same order), in the plane and in space.
        #[test]
        fn the_f64_local_matrix_equals_the_generic_one(
            x in proptest::collection::vec(-10.0f64..10.0, 9),
            planar in any::<bool>(),
            length in 0.01f64..100.0,
        ) {
            let n = if planar { 2 } else { 3 };
            for norm in [Norm::L2Lumped, Norm::L2, Norm::H1 { length }] {
                let (fast, fast_area) = local_matrix_f64(CellKind::Triangle, n, &x[..3 * n], norm);
                let (slow, slow_area) = local_matrix::<f64>(CellKind::Triangle, n, &x[..3 * n], norm);
                prop_assert_eq!(fast_area.to_bits(), slow_area.to_bits());
                for i in 0..3 {
                    for j in 0..3 {
                        prop_assert_eq!(fast[i][j].to_bits(), slow[i][j].to_bits(), "{:?} entry ({}, {})", norm, i, j);
                    }
                }
            }
        }

        /// The analytic per-cell gradient equals nested forward-mode
        /// differentiation of the local matrix, and so does its forward
        /// mode in x + ε dx (the Hessian–vector product of
        /// `SignalNorm::hvp`), for segments and triangles in the plane and
        /// in space and every norm. Segments shorter than 0.05 and
        /// triangles of area below 0.01 (in a box of side 2) are left out:
        /// the derivatives blow up as the volume → 0.
        #[test]
        fn the_analytic_gradient_and_its_forward_mode_equal_nested_duals(
            x in proptest::collection::vec(-1.0f64..1.0, 9),
            dx in proptest::collection::vec(-1.0f64..1.0, 9),
            a in proptest::collection::vec(-1.0f64..1.0, 3),
            b in proptest::collection::vec(-1.0f64..1.0, 3),
            planar in any::<bool>(),
            segment in any::<bool>(),
            length in 0.1f64..3.0,
        ) {
            let n = if planar { 2 } else { 3 };
            let (kind, corners) = if segment { (CellKind::Segment, 2) } else { (CellKind::Triangle, 3) };
            let m = corners * n;
            let (x, dx) = (&x[..m], &dx[..m]);
            let vol = super::volume(kind, n, x);
            prop_assume!(vol > if segment { 0.05 } else { 0.01 });
            for norm in [Norm::L2Lumped, Norm::L2, Norm::H1 { length }] {
                let (grad, hvp) = nested_dual(kind, n, x, dx, &a, &b, norm);
                let mut g = [0.0; MAX_LOCAL];
                local_grad(kind, n, x, &a, &b, norm, &mut g[..m]);
                let xd: Vec<Dual64> = x.iter().zip(dx).map(|(&v, &d)| Dual64::new(v, d)).collect();
                let mut h = [Dual64::from(0.0); MAX_LOCAL];
                local_grad(kind, n, &xd, &a, &b, norm, &mut h[..m]);
                let scale = grad.iter().chain(&hvp).fold(1.0f64, |s, v| s.max(v.abs()));
                for r in 0..m {
                    prop_assert!((g[r] - grad[r]).abs() <= 1e-12 * scale, "{:?} gradient {}: {} against {}", norm, r, g[r], grad[r]);
                    prop_assert!((h[r].re - g[r]).abs() <= 1e-12 * scale, "{:?} value part {}", norm, r);
                    prop_assert!((h[r].eps - hvp[r]).abs() <= 1e-12 * scale, "{:?} hvp {}: {} against {}", norm, r, h[r].eps, hvp[r]);
                }
            }
        }
    }
}
