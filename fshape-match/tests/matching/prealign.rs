//! Pre-alignment: the fit's gradient against central differences, and
//! known motions of real shapes (the bunny, a cortex) undone: any
//! rotation, a translation and a scale brought back within 1° and 1 % of
//! the diagonal.

use fshape_kernels::Kernel;
use fshape_match::prealign::{AlignKind, DMat3, DVec3, Moving, PrealignSection, fit_for_tests, prealign, rotation};
use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::io::{ReadOptions, read_mesh};
use fshape_mesh::test_support::{check_gradient, perturbed_icosphere, random_curve, random_direction};
use fshape_varifold::{Attachment, GrassKernel, SignalKernel, VarifoldKernel};

fn kernel(width: f64, signal: bool, dim: usize) -> VarifoldKernel {
    let grass = if dim == 2 { GrassKernel::Linear } else { GrassKernel::Binet };
    let signal = if signal { SignalKernel::Gaussian { sigma: 1.0 } } else { SignalKernel::Constant };
    VarifoldKernel::try_new(Kernel::gaussian(width).unwrap(), signal, grass).unwrap()
}

/// `shape` moved by x ↦ s R x + t.
fn moved(shape: &FShape, r: &DMat3, s: f64, t: &[f64]) -> FShape {
    let d = shape.dim();
    let pts = shape
        .points()
        .chunks_exact(d)
        .flat_map(|x| (0..d).map(move |i| s * (0..d).map(|j| r.col(j)[i] * x[j]).sum::<f64>() + t[i]))
        .collect();
    shape.clone().with_points(pts).unwrap()
}

#[test]
fn the_fit_gradient_matches_central_differences() {
    let surface = perturbed_icosphere(2, 0.1, 3);
    let target3 = moved(&perturbed_icosphere(2, 0.1, 4), &rotation(&[0.2, 0.1, -0.3]), 1.2, &[0.1, 0.0, -0.1]);
    let curve = random_curve(2, 40, 5);
    let target2 = moved(&random_curve(2, 40, 6), &rotation(&[0.4]), 0.9, &[0.05, 0.1]);
    let mut rng = SplitMix64(7);
    for (source, target) in [(&surface, &target3), (&curve, &target2)] {
        let attachment = Attachment::new(target, kernel(0.4, true, source.dim())).unwrap();
        for (kind, affine) in [(AlignKind::Rigid, false), (AlignKind::Similarity, false), (AlignKind::Affine, true)] {
            let fit = fit_for_tests(source, &attachment, kind, affine);
            let u: Vec<f64> = random_direction(fit.len(), &mut rng).iter().map(|v| 0.3 * v).collect();
            let (_, grad) = fit.value_grad(&u).unwrap();
            for _ in 0..3 {
                let v = random_direction(fit.len(), &mut rng);
                let c = check_gradient(|u| fit.value_grad(u).unwrap().0, &u, &grad, &v, 1e-5);
                assert!(c.rel_error < 1e-6, "{}-D {kind:?}: {c:?}", source.dim());
            }
        }
    }
}

/// The rotation angle between two rotations, in degrees: of u = aᵀb,
/// from its skew part and trace (accurate near 0 and π).
fn angle(a: &DMat3, b: &DMat3) -> f64 {
    let u = a.transpose() * *b;
    let skew = DVec3::new(u.y_axis.z - u.z_axis.y, u.z_axis.x - u.x_axis.z, u.x_axis.y - u.y_axis.x).length();
    (0.5 * skew).atan2(0.5 * (u.x_axis.x + u.y_axis.y + u.z_axis.z - 1.0)).to_degrees()
}

/// A random rotation (uniform axis, angle uniform in [0°, 180°]).
fn random_rotation(rng: &mut SplitMix64) -> DMat3 {
    let axis: Vec<f64> = loop {
        let v = random_direction(3, rng);
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n > 0.1 && n <= 1.0 {
            break v.iter().map(|x| x / n).collect();
        }
    };
    let theta = rng.range(0.0, std::f64::consts::PI);
    rotation(&axis.iter().map(|a| a * theta).collect::<Vec<_>>())
}

/// Moves `shape` by random similarities (the `cases` of the sequence drawn
/// from `seed`) and checks that the alignment of the moved copy onto
/// `shape` undoes each: rotation within 1°, every vertex within 1 % of the
/// diagonal of where it was.
fn undoes_random_motions(shape: &FShape, width: f64, seed: u64, cases: std::ops::Range<usize>) {
    let diagonal = shape.bounding_box().diagonal();
    let k = kernel(width * diagonal, shape.signal().is_some(), 3);
    let mut rng = SplitMix64(seed);
    for case in 0..cases.end {
        let r = random_rotation(&mut rng);
        let s = rng.range(0.7, 1.4);
        let t: Vec<f64> = random_direction(3, &mut rng).iter().map(|v| 0.5 * diagonal * v).collect();
        if !cases.contains(&case) {
            continue;
        }
        let source = moved(shape, &r, s, &t);
        let section = PrealignSection { kind: AlignKind::Similarity, moving: Moving::Source, max_iterations: 100 };
        let a = prealign(&source, shape, &k, &section).unwrap();
        let back = a.apply(&source).unwrap();
        let worst = back
            .points()
            .chunks_exact(3)
            .zip(shape.points().chunks_exact(3))
            .map(|(p, q)| p.iter().zip(q).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        let (m, _) = a.linear_and_offset();
        // T ∘ (s R ·) should be the identity: T's linear part ≈ Rᵀ / s.
        let undone = m * r * s;
        let identity = DMat3::IDENTITY;
        let degrees = angle(&undone, &identity);
        assert!(
            degrees < 1.0 && worst < 0.01 * diagonal,
            "case {case} (rotation {:.1}°, scale {s:.3}): off by {degrees:.3}° and {:.3}% of the diagonal (start {} of {})",
            angle(&r, &identity),
            100.0 * worst / diagonal,
            a.start,
            a.starts
        );
        assert!(a.attachment_after < 1e-3 * a.attachment_before, "{} -> {}", a.attachment_before, a.attachment_after);
    }
}

fn data(path: &str) -> FShape {
    let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data").join(path);
    read_mesh(&file, &ReadOptions::default()).unwrap()
}

// The Stanford bunny (2581 vertices; it carries no signal: geometry
// alone), under two random similarities, one test each so that the two
// run side by side.
#[test]
fn the_bunny_under_a_random_similarity_comes_back() {
    undoes_random_motions(&data("stanford_bunny/bunny_qslim_2581v.ply.gz"), 0.05, 11, 0..1);
}

#[test]
fn the_bunny_under_another_random_similarity_comes_back() {
    undoes_random_motions(&data("stanford_bunny/bunny_qslim_2581v.ply.gz"), 0.05, 11, 1..2);
}

#[test]
fn a_cortex_under_random_similarities_comes_back() {
    // fsaverage5's left pial surface with its thickness, at fsaverage4
    // (2562 vertices: the first of its icosahedral levels).
    let cortex = data("fsaverage5/lh.pial.thick.ply.gz").coarsened().unwrap();
    undoes_random_motions(&cortex, 0.05, 12, 0..1);
}

#[test]
fn a_pair_is_registered_in_the_target_frame_after_prealignment() {
    // A sphere with a signal onto a rotated, shifted copy of itself made
    // bumpy: with `[prealign]` the session runs on the aligned source,
    // which is already close, and says how it moved it.
    let target = perturbed_icosphere(2, 0.05, 21);
    let source = moved(&perturbed_icosphere(2, 0.0, 21), &rotation(&[0.0, 2.0, 0.5]), 1.0, &[3.0, -1.0, 0.5]);
    let text = "[model]\nnormalize = false\ngamma_f = 1.0\ngamma_w = 1.0\n[deformation]\nwidths = [0.5]\n\
        [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_grass = \"binet\"\n[optimizer]\nmax_iterations = 3\n\
        [prealign]\nkind = \"rigid\"\n";
    let config = fshape_match::Config::parse(text).unwrap();
    let mut session = fshape_match::Session::new(&source, &target, &config).unwrap();
    let a = session.alignment().expect("aligned").clone();
    assert_eq!(a.kind, AlignKind::Rigid);
    assert!((a.scale - 1.0).abs() < 1e-12, "a rigid motion keeps the scale: {}", a.scale);
    assert!(a.attachment_after < 0.05 * a.attachment_before, "{} -> {}", a.attachment_before, a.attachment_after);
    session.run(&mut ()).unwrap();
    let r = session.result().unwrap();
    assert_eq!(r.alignment.as_ref(), Some(&a));
    // The template is the aligned source: already within a few percent.
    assert!(r.initial_quality.mean_distance < 0.05, "{:?}", r.initial_quality);
    // Without it the same pair starts far apart.
    let unaligned = fshape_match::quality(&source, &target).unwrap();
    assert!(unaligned.mean_distance > 0.3, "{unaligned:?}");
}
