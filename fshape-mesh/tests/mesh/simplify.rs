//! The simplifier: the vertex count reached, a valid surface (manifold,
//! oriented, no flipped or degenerate triangle, the topology kept), the
//! signal carried, and the distance to the original bounded, on spheres,
//! flat domains and the real bunny.

use fshape_mesh::generate::{icosphere, square};
use fshape_mesh::io::{ReadOptions, read_mesh};
use fshape_mesh::{CellKind, FShape, MIN_QUALITY, SimplifyError, SimplifyOptions};

use crate::data;

fn p3(s: &FShape, i: usize) -> [f64; 3] {
    let p = s.point(i);
    [p[0], p[1], if s.dim() == 3 { p[2] } else { 0.0 }]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The distance from q to the triangle (a, b, c) (Ericson's closest point).
fn point_triangle(q: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(q, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    let at =
        |u: f64, v: f64| [a[0] + u * ab[0] + v * ac[0], a[1] + u * ab[1] + v * ac[1], a[2] + u * ab[2] + v * ac[2]];
    let dist = |p: [f64; 3]| dot(sub(q, p), sub(q, p)).sqrt();
    if d1 <= 0.0 && d2 <= 0.0 {
        return dist(a);
    }
    let bp = sub(q, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return dist(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return dist(at(d1 / (d1 - d3), 0.0));
    }
    let cp = sub(q, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return dist(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return dist(at(0.0, d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return dist([b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])]);
    }
    let denom = 1.0 / (va + vb + vc);
    dist(at(vb * denom, vc * denom))
}

/// The largest distance from a vertex of `fine` to the surface `coarse`
/// (brute force over the coarse triangles).
fn max_distance(fine: &FShape, coarse: &FShape) -> f64 {
    (0..fine.n_vertices())
        .map(|i| {
            let q = p3(fine, i);
            coarse
                .cell_iter()
                .map(|c| point_triangle(q, p3(coarse, c[0]), p3(coarse, c[1]), p3(coarse, c[2])))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max)
}

/// Valid for computation and manifold, consistently oriented, with no
/// degenerate cell or unused vertex: nothing but a boundary to report.
fn sound(s: &FShape) -> bool {
    s.validate().problems.iter().all(|p| p.code() == "boundary")
}

/// Every triangle's quality 4√3·area/Σ edge² and its area vector.
fn triangles(s: &FShape) -> Vec<(f64, [f64; 3])> {
    s.cell_iter()
        .map(|c| {
            let (a, b, d) = (p3(s, c[0]), p3(s, c[1]), p3(s, c[2]));
            let n = cross(sub(b, a), sub(d, a));
            let edges = dot(sub(b, a), sub(b, a)) + dot(sub(d, b), sub(d, b)) + dot(sub(a, d), sub(a, d));
            (2.0 * 3f64.sqrt() * dot(n, n).sqrt() / edges, n)
        })
        .collect()
}

#[test]
fn a_sphere_reaches_the_count_as_a_clean_closed_surface_near_the_original() {
    let fine = icosphere(5, 1.0);
    let z: Vec<f64> = (0..fine.n_vertices()).map(|i| fine.point(i)[2]).collect();
    let fine = fine.with_signal(Some(z)).unwrap();
    for target in [2562, 500, 100] {
        let out = fine.simplified(target).unwrap();
        let coarse = &out.shape;
        assert_eq!(coarse.n_vertices(), target);
        assert!(coarse.validate().is_clean(), "{target}: {:?}", coarse.validate());
        let topo = coarse.topology();
        assert!(topo.is_closed());
        assert_eq!(topo.euler_characteristic(CellKind::Triangle, coarse.n_cells()), 2);
        // Outward, not degenerate: every normal points away from the centre.
        for (q, n) in triangles(coarse) {
            assert!(q > 1e-3, "{target}: quality {q}");
            assert!(n.iter().all(|v| v.is_finite()));
        }
        for c in coarse.cell_iter() {
            let (a, b, d) = (p3(coarse, c[0]), p3(coarse, c[1]), p3(coarse, c[2]));
            let centre = [(a[0] + b[0] + d[0]) / 3.0, (a[1] + b[1] + d[1]) / 3.0, (a[2] + b[2] + d[2]) / 3.0];
            assert!(dot(cross(sub(b, a), sub(d, a)), centre) > 0.0, "{target}: a face turned inward");
        }
        // The kept vertices are fine vertices with their signal values.
        for (i, &k) in out.kept.iter().enumerate() {
            assert_eq!(coarse.point(i), fine.point(k));
            assert_eq!(coarse.signal().unwrap()[i], fine.signal().unwrap()[k]);
        }
        assert!(out.kept.windows(2).all(|w| w[0] < w[1]));
        // Every fine vertex is near the coarse surface: within the sagitta
        // of the coarse edges (about h²/8 for edges of length h on the unit
        // sphere), with a margin for uneven edges.
        let h = (4.0 * std::f64::consts::PI / (coarse.n_cells() as f64 * 3f64.sqrt() / 4.0)).sqrt();
        let d = max_distance(&fine, coarse);
        assert!(d <= h * h / 2.0, "{target}: distance {d} against h {h}");
    }
}

/// The rms difference between `truth` at the fine vertices and the
/// coarse mesh's P1 map `c` there (by point location; flat meshes).
fn p1_rms(fine: &FShape, coarse: &FShape, c: usize, truth: &[f64]) -> f64 {
    let f = coarse.channel(c).unwrap();
    let mut sq = 0.0;
    for (i, truth) in truth.iter().enumerate() {
        let q = p3(fine, i);
        let mut best = (f64::INFINITY, 0.0);
        for t in coarse.cell_iter() {
            let (a, b, d) = (p3(coarse, t[0]), p3(coarse, t[1]), p3(coarse, t[2]));
            let area = cross(sub(b, a), sub(d, a))[2];
            let l1 = cross(sub(d, b), sub(q, b))[2] / area;
            let l2 = cross(sub(a, d), sub(q, d))[2] / area;
            let l0 = 1.0 - l1 - l2;
            let outside = (-l0).max(-l1).max(-l2);
            if outside < best.0 {
                best = (outside, l1 * f[t[0]] + l2 * f[t[1]] + l0 * f[t[2]]);
            }
        }
        sq += (best.1 - truth).powi(2);
    }
    (sq / fine.n_vertices() as f64).sqrt()
}

/// A disc of 1 in 0 on a flat square: a feature only the signal shows.
fn disc_on(fine: &FShape) -> Vec<f64> {
    (0..fine.n_vertices())
        .map(|i| {
            let p = fine.point(i);
            if (p[0] - 0.2).powi(2) + (p[1] + 0.1).powi(2) < 0.25 { 1.0 } else { 0.0 }
        })
        .collect()
}

#[test]
fn the_signal_weight_keeps_a_sharp_signal_where_it_changes() {
    // A flat square with a disc of signal 1 in signal 0: the disc's edge
    // is a feature only the signal shows.
    let fine = square(4000, 7);
    let disc = disc_on(&fine);
    let fine = fine.with_signal(Some(disc.clone())).unwrap();
    let error = |weight: f64| {
        let coarse = fine.simplified_with(400, &SimplifyOptions { signal_weight: weight }).unwrap().shape;
        assert_eq!(coarse.n_vertices(), 400);
        assert!(sound(&coarse), "{:?}", coarse.validate());
        // Still counter-clockwise and unflattened.
        for (q, n) in triangles(&coarse) {
            assert!(n[2] > 0.0 && q >= MIN_QUALITY.min(0.01), "quality {q}, normal {n:?}");
        }
        p1_rms(&fine, &coarse, 0, &disc)
    };
    let (with, without) = (error(1.0), error(0.0));
    assert!(with < 0.75 * without, "rms error with the signal {with}, without {without}");
    // The square's outline is kept: its corners are still there.
    let coarse = fine.simplified(400).unwrap().shape;
    let bb = coarse.bounding_box();
    assert_eq!(bb, fine.bounding_box());
}

#[test]
fn every_map_is_weighed_and_a_constant_one_changes_nothing() {
    // The disc in the second of two maps is kept as well as alone.
    let fine = square(4000, 7);
    let disc = disc_on(&fine);
    let n = fine.n_vertices();
    let interleave = |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).flat_map(|(x, y)| [*x, *y]).collect() };
    let zeros = vec![0.0; n];
    let two = fine.clone().with_signals(Some(interleave(&zeros, &disc)), 2).unwrap();
    let coarse = two.simplified(400).unwrap().shape;
    assert_eq!(coarse.n_vertices(), 400);
    assert!(sound(&coarse), "{:?}", coarse.validate());
    let second = p1_rms(&fine, &coarse, 1, &disc);
    // Weighing only the first (constant) map leaves the disc to chance.
    let geometry_only = fine.clone().with_signal(Some(zeros.clone())).unwrap().simplified(400).unwrap();
    let kept: Vec<f64> = geometry_only.kept.iter().map(|&i| disc[i]).collect();
    let blind = geometry_only.shape.with_signal(Some(kept)).unwrap();
    let without = p1_rms(&fine, &blind, 0, &disc);
    assert!(second < 0.75 * without, "the second map's rms error {second}, with it ignored {without}");
    // A constant second map adds nothing: the same vertices and cells as
    // the first map alone.
    let alone = fine.clone().with_signal(Some(disc.clone())).unwrap().simplified(400).unwrap();
    let with_constant = fine.with_signals(Some(interleave(&disc, &zeros)), 2).unwrap().simplified(400).unwrap();
    assert_eq!(alone.kept, with_constant.kept);
    assert_eq!(alone.shape.cells(), with_constant.shape.cells());
}

#[test]
fn the_bunny_keeps_its_holes_and_its_shape() {
    let bunny = read_mesh(&data("stanford_bunny/bunny_qslim_2581v.ply.gz"), &ReadOptions::default()).unwrap();
    let coarse = bunny.simplified(600).unwrap().shape;
    assert_eq!(coarse.n_vertices(), 600);
    assert!(sound(&coarse), "{:?}", coarse.validate());
    let (a, b) = (bunny.topology(), coarse.topology());
    assert_eq!((a.n_boundary_loops, a.n_components), (b.n_boundary_loops, b.n_components));
    assert_eq!(
        a.euler_characteristic(CellKind::Triangle, bunny.n_cells()),
        b.euler_characteristic(CellKind::Triangle, coarse.n_cells())
    );
    // Within 1 % of the bunny's diagonal everywhere.
    let d = max_distance(&bunny, &coarse);
    assert!(d < 0.01 * bunny.bounding_box().diagonal(), "{d}");
}

#[test]
fn what_cannot_be_simplified_is_refused() {
    let circle = fshape_mesh::generate::circle(40, 1.0);
    assert!(matches!(circle.simplified(10), Err(SimplifyError::NotTriangles { .. })));
    let sphere = icosphere(2, 1.0);
    assert_eq!(sphere.simplified(3), Err(SimplifyError::TooFew { requested: 3 }));
    assert!(matches!(
        sphere.simplified_with(50, &SimplifyOptions { signal_weight: f64::NAN }),
        Err(SimplifyError::SignalWeight { .. })
    ));
    // Already small enough: the mesh itself.
    let same = sphere.simplified(1000).unwrap();
    assert_eq!(same.shape, sphere);
    assert_eq!(same.kept, (0..sphere.n_vertices()).collect::<Vec<_>>());
}
