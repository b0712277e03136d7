//! Values against hand-derived and analytic ones.

use std::f64::consts::PI;

use fshape_fem::{Norm, SignalNorm};
use fshape_mesh::generate::{icosphere, square};
use fshape_mesh::test_support::observed_order;
use fshape_mesh::{CellKind, FShape};

use crate::{NORMS, shapes};

fn quad(s: &FShape, norm: Norm, f: &[f64]) -> f64 {
    SignalNorm::try_new(s, norm).unwrap().quadratic(s.points(), f).unwrap()
}

#[test]
fn mass_sums_to_total_volume_and_stiffness_rows_to_zero() {
    for s in shapes() {
        let ones = vec![1.0; s.n_vertices()];
        let vol = s.total_volume();
        for norm in [Norm::L2Lumped, Norm::L2] {
            // 1ᵀ M 1 is the sum of all entries of M.
            let q = quad(&s, norm, &ones);
            assert!((q - vol).abs() <= 1e-13 * vol, "{norm:?} {q} {vol}");
            let d = SignalNorm::try_new(&s, norm).unwrap();
            let (col_ptr, row_idx) = d.pattern();
            let vals = d.assemble(s.points()).unwrap();
            let mut total = 0.0;
            for c in 0..d.n_vertices() {
                for e in col_ptr[c]..col_ptr[c + 1] {
                    total += if row_idx[e] == c { vals[e] } else { 2.0 * vals[e] };
                }
            }
            assert!((total - vol).abs() <= 1e-13 * vol);
        }
        // K 1 = 0: the H1 and L2 products with constants agree.
        let h1 = SignalNorm::try_new(&s, Norm::H1 { length: 0.7 }).unwrap().matvec(s.points(), &ones).unwrap();
        let l2 = SignalNorm::try_new(&s, Norm::L2).unwrap().matvec(s.points(), &ones).unwrap();
        let scale = l2.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(h1.iter().zip(&l2).all(|(a, b)| (a - b).abs() <= 1e-12 * scale.max(1.0)));
    }
}

#[test]
fn stiffness_is_exact_for_linear_functions_on_flat_cells() {
    let ell = 0.7;
    let stiff = |s: &FShape, f: &[f64]| (quad(s, Norm::H1 { length: ell }, f) - quad(s, Norm::L2, f)) / (ell * ell);
    // Flat domain: f = 2x − 3y + 1, |∇f|² = 13, area 4.
    let sq = square(300, 5);
    let f: Vec<f64> = sq.points().chunks_exact(2).map(|p| 2.0 * p[0] - 3.0 * p[1] + 1.0).collect();
    assert!((stiff(&sq, &f) - 4.0 * 13.0).abs() < 1e-10);
    // The same square tilted into R³ (rotated about the x axis by 0.4 rad),
    // the same signal values: the in-plane gradient is unchanged.
    let (c, s) = (0.4f64.cos(), 0.4f64.sin());
    let pts3: Vec<f64> = sq.points().chunks_exact(2).flat_map(|p| [p[0], c * p[1], s * p[1]]).collect();
    let tilted = FShape::try_new(3, CellKind::Triangle, pts3, sq.cells().to_vec(), None).unwrap();
    assert!((stiff(&tilted, &f) - 52.0).abs() < 1e-10);
    // A straight polyline of length 5 with f = 0.5·arclength: Σ L (f')² = 5/4.
    let pts: Vec<f64> = (0..=10).flat_map(|k| [0.3 * k as f64, 0.4 * k as f64]).collect();
    let line = fshape_mesh::generate::polyline(2, pts, false).unwrap();
    let g: Vec<f64> = (0..=10).map(|k| 0.5 * 0.5 * k as f64).collect();
    assert!((stiff(&line, &g) - 1.25).abs() < 1e-12);
}

#[test]
fn p1_mass_matches_the_paper_quadrature_on_one_cell() {
    // Paper section 4.2.2: Σ r/3 (f12² + f23² + f31²) with edge midpoints.
    let t =
        FShape::try_new(3, CellKind::Triangle, vec![0., 0., 0., 2., 0., 0., 0., 1., 1.], vec![0, 1, 2], None).unwrap();
    let f = [0.3f64, -1.1, 2.0];
    let r = t.total_volume();
    let mid = |i: usize, j: usize| -> f64 { 0.5 * (f[i] + f[j]) };
    let paper = r / 3.0 * (mid(0, 1).powi(2) + mid(1, 2).powi(2) + mid(2, 0).powi(2));
    assert!((quad(&t, Norm::L2, &f) - paper).abs() < 1e-14);
    // Segment: r/6 (f1² + 4 f12² + f2²).
    let s = FShape::try_new(2, CellKind::Segment, vec![0., 0., 3., 4.], vec![0, 1], None).unwrap();
    let g = [0.5f64, 2.5];
    let paper = 5.0 / 6.0 * (g[0] * g[0] + 4.0 * (0.5 * (g[0] + g[1])).powi(2) + g[1] * g[1]);
    assert!((quad(&s, Norm::L2, &g) - paper).abs() < 1e-14);
}

#[test]
fn icosphere_integrals_of_z_converge_at_second_order() {
    // f = z on the unit sphere: ∫ f² = 4π/3, ∫ |∇_S f|² = 8π/3.
    let (mut h, mut e_lumped, mut e_mass, mut e_stiff) = (vec![], vec![], vec![], vec![]);
    for level in 2..=6u32 {
        let s = icosphere(level, 1.0);
        let z: Vec<f64> = s.points().chunks_exact(3).map(|p| p[2]).collect();
        let m = quad(&s, Norm::L2, &z);
        let k = quad(&s, Norm::H1 { length: 1.0 }, &z) - m;
        h.push(0.5f64.powi(level as i32));
        e_lumped.push((quad(&s, Norm::L2Lumped, &z) - 4.0 * PI / 3.0).abs());
        e_mass.push((m - 4.0 * PI / 3.0).abs());
        e_stiff.push((k - 8.0 * PI / 3.0).abs());
    }
    // P1 interpolation error O(h²) plus the inscribed polyhedron's area
    // error O(h²); the energy error is O(h²) too (the first-order term
    // integrates against an O(h²) interpolation error).
    for (name, e) in [("lumped", &e_lumped), ("mass", &e_mass), ("stiffness", &e_stiff)] {
        let p = observed_order(&h, e);
        assert!((1.8..=2.2).contains(&p), "{name}: order {p}, errors {e:?}");
    }
}

#[test]
fn rigid_motions_and_renumbering_leave_the_norm_unchanged() {
    for s in shapes() {
        let n = s.dim();
        let f = s.signal().unwrap().to_vec();
        // Rotation about z by 0.9 rad (and about the plane's normal in 2-D)
        // plus a translation.
        let (c, sn) = (0.9f64.cos(), 0.9f64.sin());
        let moved: Vec<f64> = s
            .points()
            .chunks_exact(n)
            .flat_map(|p| {
                let mut q = p.to_vec();
                q[0] = c * p[0] - sn * p[1] + 3.0;
                q[1] = sn * p[0] + c * p[1] - 1.0;
                if n == 3 {
                    q[2] += 0.5;
                }
                q
            })
            .collect();
        // Renumbering: vertex v becomes P−1−v, cells listed backwards.
        let p = s.n_vertices();
        let renum_pts: Vec<f64> = (0..p).rev().flat_map(|v| s.point(v).to_vec()).collect();
        let renum_cells: Vec<usize> =
            s.cell_iter().rev().flat_map(|c| c.iter().map(|&v| p - 1 - v).collect::<Vec<_>>()).collect();
        let renum_f: Vec<f64> = (0..p).rev().map(|v| f[v]).collect();
        let renum = FShape::try_new(n, s.kind(), renum_pts, renum_cells, None).unwrap();
        for norm in NORMS {
            let d = SignalNorm::try_new(&s, norm).unwrap();
            let q = d.quadratic(s.points(), &f).unwrap();
            assert!((d.quadratic(&moved, &f).unwrap() - q).abs() <= 1e-12 * q.abs());
            let q2 = SignalNorm::try_new(&renum, norm).unwrap().quadratic(renum.points(), &renum_f).unwrap();
            assert!((q2 - q).abs() <= 1e-12 * q.abs(), "{norm:?}");
        }
    }
}
