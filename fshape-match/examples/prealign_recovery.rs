//! Pre-alignment with known truth: real shapes moved by random
//! similarities (any rotation angle, scale 0.7–1.4, a shift of up to half
//! the diagonal on each axis) and brought back by `[prealign] kind =
//! "similarity"`; then a registration from a rigidly moved copy, with
//! `kind = "rigid"`, against the same registration on the pair as given.
//!
//! ```text
//! cargo run --release -p fshape-match --example prealign_recovery -- [CASES]
//! ```
//!
//! Prints, per shape, the worst rotation error (degrees) and vertex error
//! (% of the diagonal) over CASES motions (default 20) with the median
//! time of an alignment; then both registrations' quality. The shapes:
//! the Stanford bunny (2581 vertices, geometry only) and fsaverage5's left
//! pial surface with its thickness (10 242 vertices); the registration is
//! the README's Python example (fsaverage3's left hemisphere onto the
//! right one mirrored, H¹ metamorphosis, 10 mm attachment kernel).

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use fshape_kernels::Kernel;
use fshape_match::prealign::{AlignKind, DMat3, DVec3, Moving, PrealignSection, prealign, rotation};
use fshape_match::{Config, Session};
use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::io::{ReadOptions, read_mesh};
use fshape_varifold::{GrassKernel, SignalKernel, VarifoldKernel};

fn data(path: &str) -> Result<FShape> {
    Ok(read_mesh(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../data").join(path), &ReadOptions::default())?)
}

/// `shape` moved by x ↦ s R x + t.
fn moved(shape: &FShape, r: &DMat3, s: f64, t: &[f64]) -> Result<FShape> {
    let pts = shape
        .points()
        .chunks_exact(3)
        .flat_map(|x| (0..3).map(move |i| s * (0..3).map(|j| r.col(j)[i] * x[j]).sum::<f64>() + t[i]))
        .collect();
    Ok(shape.clone().with_points(pts)?)
}

/// A rotation with a uniform axis and an angle uniform in [0°, 180°].
fn random_rotation(rng: &mut SplitMix64) -> DMat3 {
    loop {
        let v: Vec<f64> = (0..3).map(|_| rng.range(-1.0, 1.0)).collect();
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n > 0.1 && n <= 1.0 {
            let theta = rng.range(0.0, std::f64::consts::PI);
            return rotation(&v.iter().map(|a| a / n * theta).collect::<Vec<_>>());
        }
    }
}

fn recovery(name: &str, shape: &FShape, cases: usize, seed: u64) -> Result<()> {
    let diagonal = shape.bounding_box().diagonal();
    let signal = if shape.signal().is_some() { SignalKernel::Gaussian { sigma: 1.0 } } else { SignalKernel::Constant };
    let kernel = VarifoldKernel::try_new(Kernel::gaussian(0.05 * diagonal)?, signal, GrassKernel::Binet)?;
    let section = PrealignSection { kind: AlignKind::Similarity, moving: Moving::Source, max_iterations: 100 };
    let mut rng = SplitMix64(seed);
    let (mut worst_degrees, mut worst_distance, mut times) = (0.0f64, 0.0f64, Vec::new());
    for _ in 0..cases {
        let r = random_rotation(&mut rng);
        let s = rng.range(0.7, 1.4);
        let t: Vec<f64> = (0..3).map(|_| rng.range(-0.5, 0.5) * diagonal).collect();
        let source = moved(shape, &r, s, &t)?;
        let clock = Instant::now();
        let a = prealign(&source, shape, &kernel, &section)?;
        times.push(clock.elapsed().as_secs_f64());
        let back = a.apply(&source)?;
        let distance = back
            .points()
            .chunks_exact(3)
            .zip(shape.points().chunks_exact(3))
            .map(|(p, q)| p.iter().zip(q).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        let (m, _) = a.linear_and_offset();
        // T's linear part times s R is the identity when T undoes the motion.
        let u = m * r * s;
        // Its angle from the skew part and the trace (accurate near 0).
        let skew = DVec3::new(u.y_axis.z - u.z_axis.y, u.z_axis.x - u.x_axis.z, u.x_axis.y - u.y_axis.x).length();
        let degrees = (0.5 * skew).atan2(0.5 * (u.x_axis.x + u.y_axis.y + u.z_axis.z - 1.0)).to_degrees();
        worst_degrees = worst_degrees.max(degrees);
        worst_distance = worst_distance.max(distance / diagonal);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{name}: {cases} random similarities: worst rotation error {worst_degrees:.2e} deg, worst vertex error \
         {:.2e}% of the diagonal; median {:.2} s per alignment",
        100.0 * worst_distance,
        times[times.len() / 2]
    );
    Ok(())
}

/// The README's Python example as a configuration, with `prealign`.
fn example_config(prealign: Option<&str>) -> Result<Config> {
    let mut text = String::from(
        r#"
[model]
norm = "h1"
length = 5.0
[deformation]
widths = [20.0, 10.0]
[attachment]
kernel_geom = "gaussian:10"
kernel_signal = "gaussian:1"
kernel_grass = "gaussian-unoriented:0.5"
[optimizer]
max_iterations = 200
decrease_tolerance = 1e-2
decrease_window = 5
momentum_metric = "energy"
"#,
    );
    if let Some(kind) = prealign {
        text.push_str(&format!("[prealign]\nkind = \"{kind}\"\n"));
    }
    Ok(Config::parse(&text)?)
}

fn registration() -> Result<()> {
    let lh = data("fsaverage5/lh.pial.thick.ply.gz")?.coarsened()?.coarsened()?;
    let rh = data("fsaverage5/rh.pial.ply.gz")?;
    let thick = fshape_mesh::io::csv::read_signal(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/fsaverage5/rh.thick.csv.gz"),
        false,
    )?;
    // x -> -x, each triangle's last corners swapped to keep the orientation.
    let points = rh.points().chunks_exact(3).flat_map(|p| [-p[0], p[1], p[2]]).collect();
    let cells = rh.cells().chunks_exact(3).flat_map(|c| [c[0], c[2], c[1]]).collect();
    let mirrored = FShape::try_new(3, rh.kind(), points, cells, Some(thick.values))?;
    let goal = mirrored.coarsened()?.coarsened()?;
    let run = |source: &FShape, config: &Config| -> Result<()> {
        let clock = Instant::now();
        let mut session = Session::new(source, &goal, config)?;
        session.run(&mut ())?;
        let r = session.result()?;
        let (q0, q) = (&r.initial_quality, &r.quality);
        if let Some(a) = &r.alignment {
            println!(
                "  prealigned: rotation {:.2} deg, attachment {:.4e} -> {:.4e}",
                a.rotation_degrees, a.attachment_before, a.attachment_after
            );
        }
        println!(
            "  mean distance {:.3}% -> {:.3}%, within 1% {:.1}% -> {:.1}%, thickness error {:.2}% -> {:.2}%, \
             {} iterations, {:.1} s",
            100.0 * q0.mean_distance,
            100.0 * q.mean_distance,
            100.0 * q0.target_within_1pct,
            100.0 * q.target_within_1pct,
            100.0 * q0.signal_rms.unwrap_or(f64::NAN),
            100.0 * q.signal_rms.unwrap_or(f64::NAN),
            r.iterations,
            clock.elapsed().as_secs_f64()
        );
        Ok(())
    };
    println!("registration, the pair as given, no pre-alignment:");
    run(&lh, &example_config(None)?)?;
    let mut rng = SplitMix64(77);
    let r = random_rotation(&mut rng);
    let source = moved(&lh, &r, 1.0, &[40.0, -25.0, 30.0])?;
    println!("registration, the source turned and moved 55 mm, [prealign] rigid:");
    run(&source, &example_config(Some("rigid"))?)?;
    println!("registration, the same moved source, no pre-alignment:");
    run(&source, &example_config(None)?)
}

fn main() -> Result<()> {
    let cases: usize = std::env::args().nth(1).map_or(Ok(20), |a| a.parse())?;
    recovery("bunny (2581 vertices)", &data("stanford_bunny/bunny_qslim_2581v.ply.gz")?, cases, 1)?;
    recovery(
        "fsaverage5 left pial with thickness (10242 vertices)",
        &data("fsaverage5/lh.pial.thick.ply.gz")?,
        cases,
        2,
    )?;
    registration()
}
