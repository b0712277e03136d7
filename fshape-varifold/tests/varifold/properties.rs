//! What a distance between measures must satisfy: A(X, X) = 0, A ≥ 0,
//! symmetry, invariance under rigid motions, vertex renumbering and cell
//! reordering, and the behaviour of each direction kernel when one cell's
//! orientation flips.

use fshape_mesh::generate::SplitMix64;
use fshape_mesh::{CellKind, FShape};
use fshape_varifold::{CellFeatures, GrassKernel, VarifoldKernel, distance, inner_product};

use crate::oracle::scale;
use crate::{kernels, shape_pairs};

fn tol(x: &FShape, y: &FShape, k: &VarifoldKernel) -> f64 {
    1e-12 * (scale(x, x, k) + scale(y, y, k))
}

#[test]
fn a_shape_is_at_distance_zero_from_itself_and_distances_are_nonnegative_and_symmetric() {
    for (what, x, y) in shape_pairs(31) {
        // Untruncated kernels only: a tapered k_p need not be positive definite.
        for k in kernels().into_iter().filter(|k| k.position().taper().is_none()) {
            let t = tol(&x, &y, &k);
            assert!(distance(&x, &x, &k).unwrap().value.abs() <= t, "{what}, {k:?}: A(X, X) ≠ 0");
            let (dxy, dyx) = (distance(&x, &y, &k).unwrap(), distance(&y, &x, &k).unwrap());
            assert!(dxy.value >= -t, "{what}, {k:?}: A = {} < 0", dxy.value);
            assert!(
                (dxy.value - dyx.value).abs() <= t,
                "{what}, {k:?}: A(X,Y) = {} ≠ A(Y,X) = {}",
                dxy.value,
                dyx.value
            );
            assert!((dxy.xy - dyx.xy).abs() <= t, "{what}, {k:?}: ⟨X,Y⟩ ≠ ⟨Y,X⟩");
            // The shapes do differ: A is not trivially 0.
            assert!(dxy.value > 1e3 * t, "{what}, {k:?}: A = {} is suspiciously small", dxy.value);
        }
    }
}

/// A random rotation (det +1) of R^dim and a translation, applied to points.
fn rigid(s: &FShape, seed: u64) -> FShape {
    let mut rng = SplitMix64(seed);
    let d = s.dim();
    let m: Vec<[f64; 3]> = if d == 2 {
        let a = rng.range(0.0, std::f64::consts::TAU);
        vec![[a.cos(), -a.sin(), 0.0], [a.sin(), a.cos(), 0.0]]
    } else {
        // Rotation from a random unit quaternion.
        let q: Vec<f64> = (0..4).map(|_| rng.range(-1.0, 1.0)).collect();
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let (w, x, y, z) = (q[0] / n, q[1] / n, q[2] / n, q[3] / n);
        vec![
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ]
    };
    let shift: Vec<f64> = (0..d).map(|_| rng.range(-3.0, 3.0)).collect();
    let mut pts = Vec::with_capacity(s.points().len());
    for p in s.points().chunks_exact(d) {
        for r in 0..d {
            pts.push((0..d).map(|c| m[r][c] * p[c]).sum::<f64>() + shift[r]);
        }
    }
    s.clone().with_points(pts).unwrap()
}

/// The same fshape with vertices renumbered, cells shuffled and each
/// cell's corners rotated cyclically (orientation kept).
fn renumbered(s: &FShape, seed: u64) -> FShape {
    let mut rng = SplitMix64(seed);
    let n = s.n_vertices();
    let mut perm: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        perm.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    let d = s.dim();
    let mut pts = vec![0.0; n * d];
    let mut sig = vec![0.0; n];
    for (old, &new) in perm.iter().enumerate() {
        pts[new * d..(new + 1) * d].copy_from_slice(s.point(old));
        sig[new] = s.signal().unwrap()[old];
    }
    let mut cells: Vec<Vec<usize>> = s.cell_iter().map(|c| c.iter().map(|&v| perm[v]).collect()).collect();
    for i in (1..cells.len()).rev() {
        cells.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    if s.kind() == CellKind::Triangle {
        for (t, c) in cells.iter_mut().enumerate() {
            c.rotate_left(t % 3);
        }
    }
    FShape::try_new(d, s.kind(), pts, cells.concat(), Some(sig)).unwrap()
}

#[test]
fn distances_are_invariant_under_rigid_motions_renumbering_and_cell_order() {
    for (what, x, y) in shape_pairs(37) {
        for k in kernels() {
            let a = distance(&x, &y, &k).unwrap().value;
            let t = tol(&x, &y, &k);
            let moved = distance(&rigid(&x, 1), &rigid(&y, 1), &k).unwrap().value;
            assert!((a - moved).abs() <= t, "{what}, {k:?}: rigid motion changes A: {a} vs {moved}");
            let renum = distance(&renumbered(&x, 2), &renumbered(&y, 3), &k).unwrap().value;
            assert!((a - renum).abs() <= t, "{what}, {k:?}: renumbering changes A: {a} vs {renum}");
        }
        // And A does see a non-rigid change (the test can fail).
        let k = &kernels()[0];
        let stretched = x.clone().with_points(x.points().iter().map(|v| 1.1 * v).collect()).unwrap();
        assert!((distance(&stretched, &y, k).unwrap().value - distance(&x, &y, k).unwrap().value).abs() > 1e-6);
    }
}

#[test]
fn flipping_one_cell_changes_exactly_what_each_direction_kernel_says() {
    for (what, x, y) in shape_pairs(41) {
        // Cell 0 with two corners swapped: its direction is negated.
        let mut cells = x.cells().to_vec();
        cells.swap(0, 1);
        let flipped =
            FShape::try_new(x.dim(), x.kind(), x.points().to_vec(), cells, x.signal().map(<[f64]>::to_vec)).unwrap();
        let (ex, ef, ey) =
            (CellFeatures::of(&x).unwrap(), CellFeatures::of(&flipped).unwrap(), CellFeatures::of(&y).unwrap());
        // Cell 0 alone, as a one-cell measure.
        let (d, du) = (ex.dim(), ex.dir_len());
        let single = CellFeatures::from_parts(
            d,
            ex.centres()[..d].to_vec(),
            ex.dirs()[..du].to_vec(),
            vec![ex.weights()[0]],
            Some(vec![ex.signal().unwrap()[0]]),
        )
        .unwrap();
        for k in kernels() {
            let before = inner_product(&ex, &ey, &k).unwrap();
            let after = inner_product(&ef, &ey, &k).unwrap();
            let t = 1e-12 * scale(&x, &y, &k);
            match k.grass() {
                g if g.is_unoriented() => {
                    assert!((before - after).abs() <= t, "{what}, {k:?}: unoriented kernel sees a flip")
                }
                GrassKernel::Linear => {
                    // Currents are linear in the direction: the flipped cell's
                    // term changes sign, so ⟨X',Y⟩ = ⟨X,Y⟩ − 2⟨δ_0,Y⟩.
                    let cell = inner_product(&single, &ey, &k).unwrap();
                    assert!(cell.abs() > 1e3 * t, "{what}: cell 0 does not interact with Y");
                    assert!(
                        (after - (before - 2.0 * cell)).abs() <= t,
                        "{what}, {k:?}: {after} vs {before} − 2·{cell}"
                    );
                }
                _ => assert!((before - after).abs() > 1e3 * t, "{what}, {k:?}: oriented kernel misses a flip"),
            }
        }
    }
}

#[test]
fn a_missing_signal_is_blamed_on_the_shape_that_lacks_it() {
    use fshape_varifold::{Attachment, VarifoldError};
    let with = fshape_mesh::generate::circle(16, 1.0);
    let f: Vec<f64> = with.points().chunks_exact(2).map(|p| p[0]).collect();
    let with = with.with_signal(Some(f)).unwrap();
    let without = fshape_mesh::generate::circle(16, 1.2);
    let k = VarifoldKernel::parse("gaussian:0.5", Some("gaussian:1"), "binet").unwrap();
    let e = Attachment::new(&without, k.clone()).unwrap_err();
    assert_eq!(e, VarifoldError::MissingSignal { which: "target" });
    let e = Attachment::new(&with, k.clone()).unwrap().eval(&without).unwrap_err();
    assert_eq!(e, VarifoldError::MissingSignal { which: "source" });
    assert_eq!(distance(&without, &with, &k).unwrap_err(), VarifoldError::MissingSignal { which: "source" });
    assert_eq!(distance(&with, &without, &k).unwrap_err(), VarifoldError::MissingSignal { which: "target" });
}
