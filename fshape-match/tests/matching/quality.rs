//! Match quality: exact values on parallel planes, the closest-point search
//! against a brute-force oracle of another construction, identical shapes.

use fshape_match::quality::ClosestPoints;
use fshape_match::{Quality, quality};
use fshape_mesh::test_support::{perturbed_icosphere, random_curve};
use fshape_mesh::{CellKind, FShape};

/// The Delaunay square [-1, 1]² at height z in R³, with signal x + c.
fn square_at(z: f64, c: f64) -> FShape {
    let sq = fshape_mesh::generate::square(300, 4);
    let pts: Vec<f64> = sq.points().chunks_exact(2).flat_map(|p| [p[0], p[1], z]).collect();
    let f: Vec<f64> = pts.chunks_exact(3).map(|p| p[0] + c).collect();
    FShape::try_new(3, CellKind::Triangle, pts, sq.cells().to_vec(), Some(f)).unwrap()
}

#[test]
fn parallel_squares_are_at_their_offset_and_a_shifted_signal_at_its_shift() {
    let target = square_at(0.0, 0.0);
    let diag = 8f64.sqrt();
    for (h, c) in [(0.01, 0.1), (0.05, -0.3)] {
        let q: Quality = quality(&square_at(h, c), &target).unwrap();
        assert!((q.diagonal - diag).abs() < 1e-12);
        for v in [q.mean_distance, q.p95_distance, q.max_distance] {
            assert!((v - h / diag).abs() < 1e-12, "{v} against {}", h / diag);
        }
        assert_eq!(q.target_within_1pct, if h <= 0.01 * diag { 1.0 } else { 0.0 });
        assert!(q.target_within_1pct.is_sign_positive() && q.shape_beyond_1pct.is_sign_positive());
        // The signal x + c against x on a square whose x spans [-1, 1].
        assert!((q.signal_range - 2.0).abs() < 1e-12);
        assert!((q.signal_rms.unwrap() - c.abs() / 2.0).abs() < 1e-12, "{:?}", q.signal_rms);
        // The error is |c| everywhere: so is its 99th percentile.
        assert!((q.signal_p99.unwrap() - c.abs() / 2.0).abs() < 1e-12, "{:?}", q.signal_p99);
        // All of the target is on one side of 1 %: that part is the whole rms.
        let (within, beyond) = (q.signal_rms_within_1pct, q.signal_rms_beyond_1pct);
        if h <= 0.01 * diag {
            assert_eq!((within, beyond), (q.signal_rms, None));
        } else {
            assert_eq!((within, beyond), (None, q.signal_rms));
        }
        // The same gradient on the same square.
        assert!((q.signal_roughness.unwrap() - 1.0).abs() < 1e-12, "{:?}", q.signal_roughness);
        // From the shape's side: the same error, and the whole shape on the
        // same side of 1 % as the whole target.
        assert!((q.signal_rms_on_shape.unwrap() - c.abs() / 2.0).abs() < 1e-12, "{q:?}");
        if h <= 0.01 * diag {
            assert_eq!((q.shape_beyond_1pct, q.signal_rms_on_shape_beyond_1pct), (0.0, None));
            assert_eq!(q.signal_roughness_beyond_1pct, None);
        } else {
            assert_eq!((q.shape_beyond_1pct, q.signal_rms_on_shape_beyond_1pct), (1.0, q.signal_rms_on_shape));
            assert!((q.signal_roughness_beyond_1pct.unwrap() - 1.0).abs() < 1e-12, "{q:?}");
        }
    }
}

/// `square`'s triangles whose centre is farther than `r` from the origin,
/// with the vertices they use: a square with a round hole.
fn with_hole(square: &FShape, r: f64) -> FShape {
    let mut keep = Vec::new();
    for c in square.cells().chunks_exact(3) {
        let centre: Vec<f64> = (0..2).map(|k| c.iter().map(|&v| square.point(v)[k]).sum::<f64>() / 3.0).collect();
        if centre[0].hypot(centre[1]) > r {
            keep.extend_from_slice(c);
        }
    }
    let mut new_id = vec![usize::MAX; square.n_vertices()];
    let (mut pts, mut f) = (Vec::new(), Vec::new());
    for &v in &keep {
        if new_id[v] == usize::MAX {
            new_id[v] = f.len();
            pts.extend_from_slice(square.point(v));
            f.push(square.signal().unwrap()[v]);
        }
    }
    let cells = keep.iter().map(|&v| new_id[v]).collect();
    FShape::try_new(3, CellKind::Triangle, pts, cells, Some(f)).unwrap()
}

#[test]
fn the_signal_over_the_targets_holes_is_seen_from_the_shapes_side_only() {
    // The target has a hole of radius 0.5 (18 % of the diagonal); the
    // shape is the whole square, on the target where the target is, with
    // the target's signal x there. Inside the hole, away from its rim, the
    // shape's signal either continues x (smooth) or alternates ±0.5
    // around it (the paper's L² artefact, where nothing constrains it).
    let square = square_at(0.0, 0.0);
    let target = with_hole(&square, 0.5);
    let (smooth, rough) = {
        let signal = |e: f64| -> Vec<f64> {
            let wiggle = |v: usize| if v.is_multiple_of(2) { e } else { -e };
            let inside = |p: &[f64]| p[0].hypot(p[1]) < 0.35;
            square
                .points()
                .chunks_exact(3)
                .enumerate()
                .map(|(v, p)| p[0] + if inside(p) { wiggle(v) } else { 0.0 })
                .collect()
        };
        (square.clone().with_signal(Some(signal(0.0))).unwrap(), square.clone().with_signal(Some(signal(0.5))).unwrap())
    };
    let (qs, qr) = (quality(&smooth, &target).unwrap(), quality(&rough, &target).unwrap());
    // The target's side sees no difference: each of its samples is on the
    // shape, where the two signals agree and equal the target's.
    for q in [&qs, &qr] {
        assert!(q.signal_rms.unwrap() < 1e-15 && q.target_within_1pct == 1.0, "{q:?}");
    }
    // The shape's side sees the hole: the area beyond 1 % is the disc of
    // radius 0.5 − 0.028 (up to the jagged rim of triangles), a sixth of
    // the square's 4.
    let disc = std::f64::consts::PI * (0.5 - 0.01 * 8f64.sqrt()).powi(2) / 4.0;
    assert_eq!(qs.shape_beyond_1pct, qr.shape_beyond_1pct);
    assert!((qs.shape_beyond_1pct - disc).abs() < 0.2 * disc, "{qs:?}");
    // Past the target's boundary: exactly the triangles cut out, every
    // sample there having its closest point on the rim, every other one
    // lying on the target.
    let area = |s: &FShape| s.cell_volumes().iter().sum::<f64>();
    let cut = 1.0 - area(&target) / area(&square);
    assert!(cut > 0.1);
    for q in [&qs, &qr] {
        assert!((q.shape_past_boundary - cut).abs() < 1e-12, "{} against {cut}", q.shape_past_boundary);
    }
    // x continued over the hole: the gradient per area of the target's.
    assert!((qs.signal_roughness_beyond_1pct.unwrap() - 1.0).abs() < 1e-12, "{qs:?}");
    assert!((qs.signal_roughness_past_boundary.unwrap() - 1.0).abs() < 1e-12, "{qs:?}");
    // x against the rim's values: at most the hole's radius, 0.25 of the range.
    assert!(qs.signal_rms_on_shape_beyond_1pct.unwrap() < 0.25, "{qs:?}");
    // The oscillation: a larger error and a much rougher signal there.
    let (es, er) = (qs.signal_rms_on_shape_beyond_1pct.unwrap(), qr.signal_rms_on_shape_beyond_1pct.unwrap());
    assert!(er > es + 0.03, "{er} against {es}");
    assert!(qr.signal_rms_past_boundary.unwrap() > qs.signal_rms_past_boundary.unwrap() + 0.03, "{qr:?}");
    assert!(qr.signal_roughness_beyond_1pct.unwrap() > 3.0, "{qr:?}");
    assert!(qr.signal_roughness_past_boundary.unwrap() > 3.0, "{qr:?}");
    // A closed target has no boundary to be past.
    let sphere = perturbed_icosphere(2, 0.1, 5);
    let f: Vec<f64> = sphere.points().chunks_exact(3).map(|p| p[0]).collect();
    let sphere = sphere.with_signal(Some(f)).unwrap();
    let q = quality(&sphere.clone().with_points(sphere.points().iter().map(|x| 1.2 * x).collect()).unwrap(), &sphere)
        .unwrap();
    assert_eq!((q.shape_past_boundary, q.signal_rms_past_boundary), (0.0, None), "{q:?}");
    // +0, not the −0 of an empty float sum (which the JSON would print).
    assert!(q.shape_past_boundary.is_sign_positive() && q.shape_beyond_1pct.is_sign_positive(), "{q:?}");
}

#[test]
fn the_error_from_the_shapes_side_is_the_targets_error_with_the_roles_swapped() {
    // Another path to the same numbers: the error at the shape's samples
    // against the target's closest points is what `quality(target, shape)`
    // computes as its target-side error, in the other range.
    let mut rng = fshape_mesh::generate::SplitMix64(41);
    let range = |f: &[f64]| {
        f.iter().copied().fold(f64::NEG_INFINITY, f64::max) - f.iter().copied().fold(f64::INFINITY, f64::min)
    };
    for (a, b) in [
        (perturbed_icosphere(2, 0.2, 3), perturbed_icosphere(2, 0.2, 4)),
        (random_curve(2, 40, 5), random_curve(2, 30, 6)),
    ] {
        let mut signal = |s: FShape| {
            let f: Vec<f64> = (0..s.n_vertices()).map(|_| rng.range(-1.0, 1.0)).collect();
            s.with_signal(Some(f)).unwrap()
        };
        let (a, b) = (signal(a), signal(b));
        let (ab, ba) = (quality(&a, &b).unwrap(), quality(&b, &a).unwrap());
        let (ra, rb) = (range(a.signal().unwrap()), range(b.signal().unwrap()));
        let (ours, theirs) = (ab.signal_rms_on_shape.unwrap() * rb, ba.signal_rms.unwrap() * ra);
        assert!((ours - theirs).abs() < 1e-12 * theirs, "{ours} against {theirs}");
    }
}

#[test]
fn the_signal_error_splits_at_one_percent_into_parts_that_make_the_whole() {
    // The half x > 0 of the target's square lifted by 0.05 (1.8 % of the
    // diagonal) and given the signal x + 0.3; the half x < 0 left in place
    // with x + 0.1. Far from the fold, the part within 1 % sees the
    // error 0.1 and the part beyond 0.3 (of the range 2).
    let target = square_at(0.0, 0.0);
    let (pts, f): (Vec<f64>, Vec<f64>) = {
        let mut pts = target.points().to_vec();
        let mut f = Vec::new();
        for p in pts.chunks_exact_mut(3) {
            let right = p[0] > 0.0;
            p[2] = if right { 0.05 } else { 0.0 };
            f.push(p[0] + if right { 0.3 } else { 0.1 });
        }
        (pts, f)
    };
    let shape = target.clone().with_points(pts).unwrap().with_signal(Some(f)).unwrap();
    let q = quality(&shape, &target).unwrap();
    let (rms, a) = (q.signal_rms.unwrap(), q.target_within_1pct);
    let (within, beyond) = (q.signal_rms_within_1pct.unwrap(), q.signal_rms_beyond_1pct.unwrap());
    // Area-weighted means of squares: the parts recombine to the whole.
    let whole = (a * within * within + (1.0 - a) * beyond * beyond).sqrt();
    assert!((whole - rms).abs() < 1e-12 * rms, "{whole} against {rms}");
    // About half the area on each side, each with its own error (the
    // triangles across x = 0 blur the two a little).
    assert!((a - 0.5).abs() < 0.1, "{q:?}");
    assert!((within - 0.05).abs() < 0.01 && (beyond - 0.15).abs() < 0.01, "{q:?}");
}

#[test]
fn roughness_is_the_ratio_of_gradients_and_grows_with_oscillation() {
    let target = square_at(0.0, 0.0);
    // f = x on the square [-1, 1]²: ∫|∇f|² = its area, 4.
    let d = fshape_match::quality::dirichlet_seminorm(&target).unwrap();
    assert!((d - 2.0).abs() < 1e-12, "{d}");
    let steeper = {
        let f: Vec<f64> = target.points().chunks_exact(3).map(|p| 3.0 * p[0] - 1.0).collect();
        target.clone().with_signal(Some(f)).unwrap()
    };
    let q = quality(&steeper, &target).unwrap();
    assert!((q.signal_roughness.unwrap() - 3.0).abs() < 1e-12, "{q:?}");
    // ±e alternating with the vertex index: an rms error of under 2 % of
    // the range, smaller than the offsets of the test above (which keep the
    // roughness at 1), but edges of about 0.1 turn ±0.05 into gradients
    // of the order of the target's own.
    let e = 0.05;
    let wiggle = |v: usize| if v.is_multiple_of(2) { e } else { -e };
    let f: Vec<f64> = target.points().chunks_exact(3).enumerate().map(|(v, p)| p[0] + wiggle(v)).collect();
    let rough = quality(&target.clone().with_signal(Some(f)).unwrap(), &target).unwrap();
    assert!(rough.signal_rms.unwrap() < 0.02, "{rough:?}");
    assert!(rough.signal_roughness.unwrap() > 1.2, "{rough:?}");
    assert!(rough.signal_p99.unwrap() <= e / 2.0 + 1e-12, "{rough:?}");
    // Without a signal on either side there is no roughness.
    assert_eq!(quality(&target.clone().with_signal(None).unwrap(), &target).unwrap().signal_roughness, None);
}

/// ∫|∇f|² by another construction: the H¹ form (mass + ℓ² stiffness, ℓ =
/// 1) minus the L² form, both from fshape-fem.
fn fem_dirichlet(s: &FShape) -> f64 {
    use fshape_fem::{Norm, SignalNorm};
    let f = s.signal().unwrap();
    let h1 = SignalNorm::try_new(s, Norm::H1 { length: 1.0 }).unwrap().quadratic(s.points(), f).unwrap();
    let l2 = SignalNorm::try_new(s, Norm::L2).unwrap().quadratic(s.points(), f).unwrap();
    h1 - l2
}

#[test]
fn the_dirichlet_seminorm_agrees_with_the_finite_element_forms() {
    let mut rng = fshape_mesh::generate::SplitMix64(29);
    let shapes = [perturbed_icosphere(2, 0.2, 3), random_curve(2, 40, 5), random_curve(3, 25, 6)];
    for s in shapes {
        let f: Vec<f64> = (0..s.n_vertices()).map(|_| rng.range(-1.0, 1.0)).collect();
        let s = s.with_signal(Some(f)).unwrap();
        let ours = fshape_match::quality::dirichlet_seminorm(&s).unwrap();
        let theirs = fem_dirichlet(&s).sqrt();
        assert!((ours - theirs).abs() < 1e-10 * theirs, "{ours} against {theirs}");
    }
}

#[test]
fn a_shape_matches_itself() {
    let s = perturbed_icosphere(2, 0.1, 5);
    let f: Vec<f64> = s.points().chunks_exact(3).map(|p| p[2]).collect();
    let s = s.with_signal(Some(f)).unwrap();
    let q = quality(&s, &s).unwrap();
    assert!(q.mean_distance < 1e-15 && q.max_distance < 1e-15, "{q:?}");
    assert_eq!(q.target_within_1pct, 1.0);
    assert!(q.signal_rms.unwrap() < 1e-15);
    // Without a signal on the target there is no signal error.
    assert_eq!(quality(&s, &s.clone().with_signal(None).unwrap()).unwrap().signal_rms, None);
}

/// Distance from p to triangle abc by another construction than the
/// library's: the projection onto the plane if it falls inside, else the
/// nearest of the three edges.
fn oracle_triangle(p: [f64; 3], t: [[f64; 3]; 3]) -> f64 {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let seg = |a: [f64; 3], b: [f64; 3]| {
        let ab = sub(b, a);
        let t = (dot(sub(p, a), ab) / dot(ab, ab)).clamp(0.0, 1.0);
        let q = sub(p, [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]]);
        dot(q, q).sqrt()
    };
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let nn = dot(n, n);
    let h = dot(sub(p, t[0]), n) / nn;
    let proj = [p[0] - h * n[0], p[1] - h * n[1], p[2] - h * n[2]];
    let inside = (0..3).all(|k| dot(cross(sub(t[(k + 1) % 3], t[k]), sub(proj, t[k])), n) >= 0.0);
    let edges = seg(t[0], t[1]).min(seg(t[1], t[2])).min(seg(t[2], t[0]));
    if inside { (h.abs() * nn.sqrt()).min(edges) } else { edges }
}

/// The search against the brute-force oracle at 400 random points of
/// [-1.5, 1.5]³ around the triangle mesh `s`.
fn agrees_on_triangles(s: &FShape, rng: &mut fshape_mesh::generate::SplitMix64) {
    let cp = ClosestPoints::new(s).unwrap();
    let p3 = |v: usize| -> [f64; 3] { std::array::from_fn(|k| s.point(v)[k]) };
    for _ in 0..400 {
        let q = [rng.range(-1.5, 1.5), rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)];
        let brute = s
            .cells()
            .chunks_exact(3)
            .map(|c| oracle_triangle(q, [p3(c[0]), p3(c[1]), p3(c[2])]))
            .fold(f64::INFINITY, f64::min);
        let got = cp.closest(q).distance;
        assert!((got - brute).abs() <= 1e-12 * (1.0 + brute), "{q:?}: {got} against {brute}");
    }
}

#[test]
fn the_closest_point_search_agrees_with_brute_force() {
    let mut rng = fshape_mesh::generate::SplitMix64(17);
    // Triangles in R³.
    let s = perturbed_icosphere(2, 0.2, 8);
    agrees_on_triangles(&s, &mut rng);
    // A soup of triangles whose sizes span three decades, with long
    // slivers among them (the search groups cells by size).
    let mut points = Vec::new();
    for t in 0..300 {
        let centre = [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)];
        let size = 10f64.powf(rng.range(-3.0, 0.0));
        let stretch = if t % 10 == 0 { 20.0 } else { 1.0 };
        for k in 0..3 {
            let along = if k == 1 { stretch } else { 1.0 };
            points.extend((0..3).map(|d| centre[d] + size * along * rng.range(-1.0, 1.0)));
        }
    }
    let soup = FShape::try_new(3, CellKind::Triangle, points, (0..900).collect(), None).unwrap();
    agrees_on_triangles(&soup, &mut rng);
    // Segments in the plane.
    let curve = random_curve(2, 30, 3);
    let cp = ClosestPoints::new(&curve).unwrap();
    for _ in 0..400 {
        let q = [rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), 0.0];
        let brute = curve
            .cells()
            .chunks_exact(2)
            .map(|c| {
                let (a, b) = (curve.point(c[0]), curve.point(c[1]));
                let ab = [b[0] - a[0], b[1] - a[1]];
                let t =
                    (((q[0] - a[0]) * ab[0] + (q[1] - a[1]) * ab[1]) / (ab[0] * ab[0] + ab[1] * ab[1])).clamp(0.0, 1.0);
                ((q[0] - a[0] - t * ab[0]).powi(2) + (q[1] - a[1] - t * ab[1]).powi(2)).sqrt()
            })
            .fold(f64::INFINITY, f64::min);
        let got = cp.closest(q).distance;
        assert!((got - brute).abs() <= 1e-12 * (1.0 + brute), "{q:?}: {got} against {brute}");
    }
}

#[test]
fn shapes_of_different_kinds_have_no_quality() {
    let e = quality(&perturbed_icosphere(1, 0.0, 1), &random_curve(3, 10, 1)).unwrap_err();
    assert!(e.to_string().contains("differ"), "{e}");
}

#[test]
fn masked_values_count_in_no_signal_error() {
    // The shifted squares again, with the half x > 0.5 masked on both and
    // its values wild there: the errors are those of the unmasked part, |c|.
    let mask =
        |s: &FShape| -> Vec<f64> { s.points().chunks_exact(3).map(|p| if p[0] > 0.5 { 0.0 } else { 1.0 }).collect() };
    let wild = |s: FShape| {
        let m = mask(&s);
        let f: Vec<f64> = s.signal().unwrap().iter().zip(&m).map(|(f, w)| if *w == 0.0 { 1e6 } else { *f }).collect();
        s.with_signal_and_mask(Some(f), Some(m)).unwrap()
    };
    let (target, shape) = (wild(square_at(0.0, 0.0)), wild(square_at(0.01, 0.1)));
    let q = quality(&shape, &target).unwrap();
    for v in [q.signal_rms, q.signal_rms_on_shape] {
        let v = v.unwrap();
        // Range: x over the unmasked part, [-1, 0.5] at the vertices.
        assert!((v - 0.1 / q.signal_range).abs() < 1e-9, "{v} ({q:?})");
    }
    assert!((q.signal_range - 1.5).abs() < 0.05, "{}", q.signal_range);
    assert!(q.signal_roughness.unwrap().is_finite());
}

#[test]
fn each_channel_is_judged_on_its_own_range() {
    // Channel 1 is x + 0.1 against x (range 2); channel 2 is 3y against
    // 3y + 0.6 (range 6): errors of 5 % and 10 % of their ranges.
    let with = |s: FShape, c: [f64; 2]| -> FShape {
        let rows: Vec<f64> = s.points().chunks_exact(3).flat_map(|p| [p[0] + c[0], 3.0 * p[1] + c[1]]).collect();
        s.with_signals(Some(rows), 2).unwrap()
    };
    let (shape, target) = (with(square_at(0.01, 0.0), [0.1, 0.0]), with(square_at(0.0, 0.0), [0.0, 0.6]));
    let q = quality(&shape, &target).unwrap();
    assert_eq!(q.channels.len(), 2);
    for (c, (range, rms)) in [(2.0, 0.05), (6.0, 0.1)].into_iter().enumerate() {
        let ch = &q.channels[c];
        assert!((ch.signal_range - range).abs() < 1e-12, "channel {c}: {ch:?}");
        assert!((ch.signal_rms.unwrap() - rms).abs() < 1e-12, "channel {c}: {ch:?}");
        assert!((ch.signal_rms_on_shape.unwrap() - rms).abs() < 1e-12, "channel {c}: {ch:?}");
        assert!((ch.signal_roughness.unwrap() - 1.0).abs() < 1e-12, "channel {c}: {ch:?}");
    }
    // Channel 1's figures are the top-level ones; each channel alone is
    // judged as a one-channel shape would be.
    assert_eq!((q.signal_rms, q.signal_range), (q.channels[0].signal_rms, q.channels[0].signal_range));
    for c in 0..2 {
        let alone = |s: &FShape| s.clone().with_signal(Some(s.channel(c).unwrap())).unwrap();
        let one = quality(&alone(&shape), &alone(&target)).unwrap();
        assert_eq!(one.signal_rms, q.channels[c].signal_rms, "channel {c}");
        assert_eq!(one.signal_p99, q.channels[c].signal_p99, "channel {c}");
        assert!(one.channels.is_empty());
    }
    assert!(q.describe().contains("channel 2: signal error 10"), "{}", q.describe());
    // Shapes of different channel counts are not compared.
    let one = square_at(0.0, 0.0);
    let e = quality(&shape, &one).expect_err("refused").to_string();
    assert!(e.contains("channel"), "{e}");
}
