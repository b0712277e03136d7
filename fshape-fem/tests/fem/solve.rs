//! Factorisation and solves, and the errors for singular input.

use fshape_fem::{FemError, Norm, SignalNorm};
use fshape_mesh::generate::{SplitMix64, icosphere};
use fshape_mesh::test_support::{observed_order, random_direction};
use fshape_mesh::{CellKind, FShape};
use proptest::prelude::*;

#[test]
fn solves_invert_the_matrix_and_reuse_the_analysis_as_x_moves() {
    for s in crate::shapes() {
        let mut rng = SplitMix64(3);
        for norm in crate::NORMS {
            let d = SignalNorm::try_new(&s, norm).unwrap();
            let mut solver = d.solver().unwrap();
            // Factor at x, then at a moved x, with the same solver.
            let moved: Vec<f64> = s.points().iter().map(|v| v * 1.3 + 0.01 * rng.range(-1.0, 1.0)).collect();
            for x in [s.points().to_vec(), moved] {
                solver.factor(&x).unwrap();
                let h_true = random_direction(s.n_vertices(), &mut rng);
                let b = d.matvec(&x, &h_true).unwrap();
                let h = solver.solve(&b).unwrap();
                let err = h.iter().zip(&h_true).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                assert!(err < 1e-9, "{norm:?}: {err}");
            }
        }
    }
}

proptest! {
    #![proptest_config(fshape_mesh::test_support::strategies::config(16, 77))]

    #[test]
    fn every_norm_is_positive_definite(s in fshape_mesh::test_support::strategies::any_small(), seed in any::<u64>()) {
        let mut rng = SplitMix64(seed);
        let f = random_direction(s.n_vertices(), &mut rng);
        for norm in crate::NORMS {
            let d = SignalNorm::try_new(&s, norm).unwrap();
            prop_assert!(d.quadratic(s.points(), &f).unwrap() > 0.0);
            // Cholesky succeeds only on a positive definite matrix.
            prop_assert!(d.solver().unwrap().factor(s.points()).is_ok());
        }
    }
}

#[test]
fn h1_solution_on_spheres_of_radius_r() {
    // DESIGN / issue: D_1 h = c·z·a on a sphere of radius r (a the lumped
    // areas of the unit icosphere, z its unit-sphere coordinate) gives
    // h ≈ c z /(r² + 2ℓ²): z is a degree-1 spherical harmonic, −Δ_S z = 2z/r²,
    // and the mass scales with r².
    let (c, ell) = (1.7, 0.6);
    for r in [0.5, 1.0, 2.0] {
        let mut h_sizes = vec![];
        let mut errs = vec![];
        for level in 2..=5u32 {
            let unit = icosphere(level, 1.0);
            let a = unit.vertex_volumes();
            let z: Vec<f64> = unit.points().chunks_exact(3).map(|p| p[2]).collect();
            let x: Vec<f64> = unit.points().iter().map(|v| v * r).collect();
            let d = SignalNorm::try_new(&unit, Norm::H1 { length: ell }).unwrap();
            let mut solver = d.solver().unwrap();
            solver.factor(&x).unwrap();
            let b: Vec<f64> = z.iter().zip(&a).map(|(z, a)| c * z * a).collect();
            let h = solver.solve(&b).unwrap();
            let err = h.iter().zip(&z).map(|(h, z)| (h - c * z / (r * r + 2.0 * ell * ell)).abs()).fold(0.0, f64::max);
            h_sizes.push(0.5f64.powi(level as i32));
            errs.push(err / (c / (r * r + 2.0 * ell * ell)));
        }
        let p = observed_order(&h_sizes, &errs);
        assert!(errs[3] < 5e-3, "r = {r}: relative error {errs:?}");
        assert!((1.7..=2.3).contains(&p), "r = {r}: order {p} ({errs:?})");
    }
}

#[test]
fn singular_and_degenerate_input_is_refused_with_its_index() {
    // Vertex 3 is unused: no mass.
    let s = FShape::try_new(2, CellKind::Triangle, vec![0., 0., 1., 0., 0., 1., 5., 5.], vec![0, 1, 2], None).unwrap();
    for norm in crate::NORMS {
        let d = SignalNorm::try_new(&s, norm).unwrap();
        assert_eq!(d.solver().unwrap().factor(s.points()), Err(FemError::Singular { vertex: 3 }));
    }
    // Cell 1 is flat (collinear corners): stiffness and derivatives refuse.
    let flat =
        FShape::try_new(2, CellKind::Triangle, vec![0., 0., 1., 0., 0., 1., 2., 0.], vec![0, 1, 2, 0, 1, 3], None)
            .unwrap();
    let d = SignalNorm::try_new(&flat, Norm::H1 { length: 1.0 }).unwrap();
    let err = d.assemble(flat.points()).unwrap_err();
    assert!(matches!(err, FemError::ZeroVolumeCell { cell: 1, .. }), "{err}");
    assert!(err.to_string().contains("fshape convert --repair"));
    let m = SignalNorm::try_new(&flat, Norm::L2).unwrap();
    assert!(m.assemble(flat.points()).is_ok(), "the mass matrix is defined on zero-area cells");
    assert!(matches!(m.grad(flat.points(), &[1.0; 4], &[1.0; 4]), Err(FemError::ZeroVolumeCell { cell: 1, .. })));
    // Bad parameters and lengths.
    for length in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(SignalNorm::try_new(&s, Norm::H1 { length }), Err(FemError::Length { .. })));
    }
    let d = SignalNorm::try_new(&s, Norm::L2).unwrap();
    assert_eq!(d.quadratic(s.points(), &[1.0; 3]), Err(FemError::Dimension { what: "f", expected: 4, found: 3 }));
    assert_eq!(d.solver().unwrap().solve(&[1.0; 4]), Err(FemError::NotFactored));
}

#[test]
fn nested_dissection_and_amd_orderings_solve_alike_and_nested_dissection_fills_less() {
    use fshape_fem::FillOrdering;
    // The paper's template size (10242 vertices), slightly perturbed so
    // that no symmetry hides an ordering error.
    let s = icosphere(5, 1.0);
    let mut rng = SplitMix64(11);
    let x: Vec<f64> = s.points().iter().map(|v| v * (1.0 + 0.05 * rng.range(-1.0, 1.0))).collect();
    let h_true = random_direction(s.n_vertices(), &mut rng);
    let mut fill = Vec::new();
    for ordering in [FillOrdering::NestedDissection, FillOrdering::Amd] {
        let d = SignalNorm::try_new(&s, Norm::H1 { length: 0.3 }).unwrap().with_ordering(ordering);
        let mut solver = d.solver().unwrap();
        solver.factor(&x).unwrap();
        let h = solver.solve(&d.matvec(&x, &h_true).unwrap()).unwrap();
        let err = h.iter().zip(&h_true).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(err < 1e-10, "{ordering:?}: {err}");
        fill.push(solver.l_len());
    }
    eprintln!("factor values, nested dissection vs AMD: {fill:?}");
    assert!(fill[0] < fill[1], "factor values, nested dissection vs AMD: {fill:?}");
}
