//! Geometry and generators against hand-derived values and known limits.

use std::f64::consts::PI;

use fshape_mesh::generate::{circle, icosphere, image_grid, polyline, sample_image, square};
use fshape_mesh::io::image::Image;
use fshape_mesh::test_support::observed_order;
use fshape_mesh::{CellKind, FShape};

#[test]
fn hand_checked_cells() {
    // A unit right triangle in the plane and the same one tilted in 3-D.
    let t =
        FShape::try_new(3, CellKind::Triangle, vec![0., 0., 0., 1., 0., 0., 0., 1., 1.], vec![0, 1, 2], None).unwrap();
    // (1,0,0) × (0,1,1) = (0,−1,1): area √2/2, normal (0,−1,1)/2.
    assert_eq!(t.cell_vector(0), [0.0, -0.5, 0.5]);
    assert!((t.cell_volume(0) - 2f64.sqrt() / 2.0).abs() < 1e-15);
    assert_eq!(t.cell_centres(), vec![1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0]);
    // Lumped volumes: a third of the area each, summing to the area.
    let lumped = t.vertex_volumes();
    assert!(lumped.iter().all(|&a| (a - t.total_volume() / 3.0).abs() < 1e-15));
    // A 3-4-5 segment.
    let s = FShape::try_new(2, CellKind::Segment, vec![0., 0., 3., 4.], vec![0, 1], Some(vec![1.0, 2.0])).unwrap();
    assert_eq!(s.cell_volume(0), 5.0);
    assert_eq!(s.cell_vector(0), [3.0, 4.0, 0.0]);
    assert_eq!(s.cell_signal().unwrap(), vec![1.5]);
    assert_eq!(s.vertex_volumes(), vec![2.5, 2.5]);
}

#[test]
fn icosphere_counts_orientation_and_area_convergence() {
    let mut h = Vec::new();
    let mut err_area = Vec::new();
    let mut err_vol = Vec::new();
    for level in 0..=6u32 {
        let s = icosphere(level, 1.0);
        let four = 4usize.pow(level);
        assert_eq!((s.n_vertices(), s.n_cells()), (10 * four + 2, 20 * four), "level {level}");
        let t = s.topology();
        assert!(t.is_closed() && t.misoriented_facets.is_empty() && t.nonmanifold_facets.is_empty());
        assert_eq!(t.euler_characteristic(s.kind(), s.n_cells()), 2);
        // Outward normals: the enclosed volume is positive.
        let vol = s.signed_enclosed_volume().unwrap();
        assert!(vol > 0.0);
        // Each vertex on the unit sphere.
        assert!(
            s.points().chunks_exact(3).all(|p| ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 1.0).abs() < 1e-14)
        );
        if level >= 2 {
            h.push(0.5f64.powi(level as i32));
            err_area.push(4.0 * PI - s.total_volume());
            err_vol.push(4.0 * PI / 3.0 - vol);
        }
    }
    // An inscribed polyhedron with edge length h has area and volume errors
    // O(h²): the chord deviates from the sphere by O(h²).
    let p_area = observed_order(&h, &err_area);
    let p_vol = observed_order(&h, &err_vol);
    assert!((1.8..=2.2).contains(&p_area), "area order {p_area}");
    assert!((1.8..=2.2).contains(&p_vol), "volume order {p_vol}");
    assert_eq!(icosphere(5, 1.0).n_vertices(), 10242, "the paper's template");
}

#[test]
fn squares_cover_the_square_with_quality_triangles() {
    for (target, seed) in [(200, 0), (4900, 0), (4900, 7)] {
        let s = square(target, seed);
        assert!((s.total_volume() - 4.0).abs() < 1e-12, "area of [-1,1]²");
        let n = s.n_vertices() as f64;
        assert!((n / target as f64 - 1.0).abs() < 0.2, "{n} vertices for target {target}");
        let t = s.topology();
        assert_eq!(t.n_boundary_loops, 1);
        assert!(t.misoriented_facets.is_empty() && t.nonmanifold_facets.is_empty());
        assert!(s.cell_vectors().iter().all(|v| v[2] > 0.0), "counter-clockwise");
        let min_angle = min_angle_deg(&s);
        assert!(min_angle > 28.0, "min angle {min_angle}");
        assert!(s.validate().errors().next().is_none());
    }
    assert_ne!(square(4900, 0).points(), square(4900, 7).points(), "two different triangulations");
}

fn min_angle_deg(s: &FShape) -> f64 {
    let mut m = 180.0f64;
    for c in s.cell_iter() {
        for k in 0..3 {
            let (a, b, d) = (s.point(c[k]), s.point(c[(k + 1) % 3]), s.point(c[(k + 2) % 3]));
            let u = [b[0] - a[0], b[1] - a[1]];
            let v = [d[0] - a[0], d[1] - a[1]];
            let cos =
                (u[0] * v[0] + u[1] * v[1]) / ((u[0] * u[0] + u[1] * u[1]).sqrt() * (v[0] * v[0] + v[1] * v[1]).sqrt());
            m = m.min(cos.clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    m
}

#[test]
fn circles_and_polylines() {
    // Perimeter of the inscribed n-gon: 2n sin(π/n) → 2π with error O(1/n²).
    let ns = [16, 32, 64, 128];
    let errs: Vec<f64> = ns.iter().map(|&n| 2.0 * PI - circle(n, 1.0).total_volume()).collect();
    for (&n, e) in ns.iter().zip(&errs) {
        assert!((2.0 * PI - e - 2.0 * n as f64 * (PI / n as f64).sin()).abs() < 1e-12);
    }
    let h: Vec<f64> = ns.iter().map(|&n| 1.0 / n as f64).collect();
    let p = observed_order(&h, &errs);
    assert!((1.9..=2.1).contains(&p), "{p}");
    let c = circle(10, 2.0);
    assert!(c.topology().is_closed());
    let open = polyline(3, vec![0., 0., 0., 1., 0., 0., 1., 1., 0.], false).unwrap();
    assert_eq!(open.n_cells(), 2);
    assert_eq!(open.topology().n_boundary_loops, 2, "two end points");
    assert_eq!(open.total_volume(), 2.0);
}

#[test]
fn image_grid_and_bilinear_sampling() {
    // 3×2 image: pixel centres at x = −2/3, 0, 2/3 and y = 1/2, −1/2.
    let im = Image { width: 3, height: 2, values: vec![0., 1., 2., 3., 4., 5.] };
    assert_eq!(im.pixel_centre(0, 0), (-1.0 + 1.0 / 3.0, 0.5));
    assert_eq!(im.pixel_centre(2, 1), (1.0 - 1.0 / 3.0, -0.5));
    let g = image_grid(&im).unwrap();
    assert_eq!((g.n_vertices(), g.n_cells()), (6, 4));
    assert!(g.cell_vectors().iter().all(|v| v[2] > 0.0), "counter-clockwise");
    // The grid's area: (2 − 2/3) × (2 − 1) between the outer centres.
    assert!((g.total_volume() - 4.0 / 3.0).abs() < 1e-15);
    // Sampling at the grid's own vertices gives the pixel values back.
    assert_eq!(sample_image(&im, &g), im.values);
    // Halfway between the four top-left centres: the mean of 0, 1, 3, 4.
    assert!((im.sample(-1.0 / 3.0, 0.0) - 2.0).abs() < 1e-15);
    // Clamped outside the centres: the corner value.
    assert_eq!(im.sample(-1.0, 1.0), 0.0);
    assert_eq!(im.sample(1.0, -1.0), 5.0);
    // A linear image is reproduced exactly by bilinear interpolation.
    let lin = Image { width: 4, height: 4, values: (0..16).map(|k| (k % 4) as f64 + 10.0 * (k / 4) as f64).collect() };
    let (x, y) = (0.123, -0.321);
    let c = ((x + 1.0) * 4.0 - 1.0) / 2.0;
    let r = ((1.0 - y) * 4.0 - 1.0) / 2.0;
    assert!((lin.sample(x, y) - (c + 10.0 * r)).abs() < 1e-12);
}

#[test]
fn finite_difference_helpers_accept_right_and_reject_wrong_derivatives() {
    use fshape_mesh::generate::SplitMix64;
    use fshape_mesh::test_support::{check_gradient, check_jvp, random_direction};
    // f(x) = Σ sin(x_i) x_{i+1}: gradient by hand.
    let f = |x: &[f64]| x.windows(2).map(|w| w[0].sin() * w[1]).sum::<f64>();
    let grad = |x: &[f64]| {
        let mut g = vec![0.0; x.len()];
        for i in 0..x.len() - 1 {
            g[i] += x[i].cos() * x[i + 1];
            g[i + 1] += x[i].sin();
        }
        g
    };
    let mut rng = SplitMix64(11);
    let x = random_direction(6, &mut rng);
    let v = random_direction(6, &mut rng);
    let good = check_gradient(f, &x, &grad(&x), &v, 1e-5);
    assert!(good.rel_error < 1e-8, "{good:?}");
    let mut wrong = grad(&x);
    wrong[2] *= 1.01;
    let bad = check_gradient(f, &x, &wrong, &v, 1e-5);
    assert!(bad.rel_error > 1e-4, "a 1% error in one entry is seen: {bad:?}");
    // F(x) = (x0 x1, x1²): J v = (v0 x1 + x0 v1, 2 x1 v1).
    let big_f = |x: &[f64]| vec![x[0] * x[1], x[1] * x[1]];
    let (x, v) = ([0.3, -1.2], [0.7, 0.4]);
    let jv = [v[0] * x[1] + x[0] * v[1], 2.0 * x[1] * v[1]];
    assert!(check_jvp(big_f, &x, &v, &jv, 1e-5).rel_error < 1e-9);
    assert!(check_jvp(big_f, &x, &v, &[jv[0], 0.0], 1e-5).rel_error > 0.1);
}
