//! A geodesic regression with a known answer: an ellipsoid thinning at a
//! known place while its signal falls there, seen at irregular ages on
//! meshes of their own.

use std::path::Path;

use anyhow::{Context, Result};
use fshape_match::ops::ModelKind;
use fshape_match::{Config, NormKind};
use fshape_mesh::FShape;
use fshape_mesh::io::{self, Encoding, write_mesh};

use super::attachment;

/// The visits' ages (years) and each one's vertex count after remeshing.
const VISITS: [(f64, usize); 5] = [(60.0, 560), (61.3, 520), (63.1, 600), (64.2, 540), (66.0, 580)];

/// Ages between the visits where the fit is compared with the truth.
const BETWEEN: [f64; 3] = [60.7, 62.2, 65.1];

/// The truth: the level-3 icosphere of radius 0.5 stretched by 1.3, 1,
/// 0.75 (642 vertices) carrying 2z, shot by momenta that push it inward
/// (p_0 = −m_i n_i b(x_i), m the lumped mass, n the vertex normal) and
/// lower its signal (p^f = −0.8 m_i b(x_i)) in a Gaussian bump b (width
/// 0.15) around the +x pole (H¹ metamorphosis, deformation width 0.3),
/// over 6 years.
fn truth(config: &Config) -> Result<(FShape, fshape_match::ops::Trajectory)> {
    let sphere = fshape_mesh::generate::icosphere(3, 0.5);
    let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [1.3 * p[0], p[1], 0.75 * p[2]]).collect();
    let f: Vec<f64> = pts.chunks_exact(3).map(|p| 2.0 * p[2]).collect();
    let shape = sphere.with_points(pts)?.with_signal(Some(f))?;
    let normals = fshape_stats::maps::vertex_normals(&shape).context("the ellipsoid's normals")?;
    let mass = shape.vertex_volumes();
    let bump = |p: &[f64]| (-((p[0] - 0.65).powi(2) + p[1] * p[1] + p[2] * p[2]) / (2.0 * 0.15 * 0.15)).exp();
    let mut p0 = Vec::with_capacity(3 * shape.n_vertices());
    let mut pf = Vec::with_capacity(shape.n_vertices());
    for ((p, n), m) in shape.points().chunks_exact(3).zip(&normals).zip(&mass) {
        let w = bump(p) * m;
        p0.extend(n.iter().map(|c| -w * c));
        pf.push(-0.8 * w);
    }
    let plan = config.plan(&shape, &shape)?;
    let traj = fshape_match::ops::shoot(&shape, &plan.model, &p0, &pf)?.trajectory;
    Ok((shape, traj))
}

pub fn regress_spheres(out: &Path, max_iterations: usize, gamma_w: f64) -> Result<()> {
    let dir = out.join("regress-spheres");
    let inputs = dir.join("visits");
    std::fs::create_dir_all(&inputs).with_context(|| format!("creating {}", inputs.display()))?;
    let mut config = Config::new(vec![0.3]);
    config.model.kind = ModelKind::Metamorphosis;
    config.model.norm = NormKind::H1;
    config.model.length = 0.3;
    config.model.gamma_w = gamma_w;
    config.integrator.steps = 10;
    config.attachment = Some(attachment(0.05, 0.25, None)?);
    config.optimizer.momentum_metric = fshape_match::Metric::Energy;
    config.optimizer.max_iterations = 3 * max_iterations;
    config.optimizer.decrease_tolerance = 1e-3;
    config.optimizer.decrease_window = 5;
    let (shape, traj) = truth(&config)?;
    let (first, span) = (VISITS[0].0, VISITS[VISITS.len() - 1].0 - VISITS[0].0);
    let state = |age: f64| -> Result<FShape> {
        let (x, f) = traj.at((age - first) / span);
        Ok(shape.clone().with_points(x)?.with_signal(Some(f))?)
    };
    // Each visit is the truth at its age, remeshed to its own vertex count.
    let mut table = String::from("# the truth at each age, remeshed\nage,mesh\n");
    let mut kept = Vec::new();
    for (k, (age, n)) in VISITS.iter().enumerate() {
        let s = state(*age)?.simplified(*n)?;
        let name = format!("visit_{k}.ply");
        write_mesh(&inputs.join(&name), &s.shape, Encoding::Binary)?;
        table.push_str(&format!("{age},{name}\n"));
        kept.push(s.kept);
    }
    let table_path = inputs.join("visits.csv");
    io::write_atomic(&table_path, table.as_bytes(), false)?;
    write_mesh(&dir.join("truth_start.ply"), &shape, Encoding::Binary)?;
    let run = dir.join("regression");
    std::fs::create_dir_all(&run).with_context(|| format!("creating {}", run.display()))?;
    let cfg = run.join("config.toml");
    let header = "# fshape demo regress-spheres: a regression with a known answer, H1 metamorphosis,\n\
                  # scale-free weights, p_0 in the energy metric, one stage ending when J fell by\n\
                  # less than 1e-3 over 5 iterations.\n\n";
    io::write_atomic(&cfg, format!("{header}{}", config.clone().with_stage_tables().to_toml()).as_bytes(), false)?;
    eprintln!("regress-spheres: {} visits of a thinning ellipsoid, remeshed -> {}", VISITS.len(), run.display());
    let args = crate::commands::regress::Args {
        visits: table_path.clone(),
        run: crate::args::Run { config: cfg, out: run.clone(), resume: false, stop_after: None },
        signal_name: None,
        allow_missing: false,
        subject: None,
        shard: None,
        view: crate::args::View { camera: crate::args::DEFAULT_CAMERA },
        report: crate::args::Report { quiet: false, verbose: false },
    };
    let subjects = fshape_match::ops::regress::read_visits(&table_path)?;
    let config = crate::inputs::read_config(&args.run.config, false)?;
    let fitted =
        crate::commands::regress::one(&args, &config, &subjects[0], &run)?.context("the regression stopped")?;
    judge(&dir, &fitted, &shape, &traj, &kept[0])
}

/// The fit against the truth between the visits and in its rate, printed
/// and written to DIR/truth.json, with pictures of both.
fn judge(
    dir: &Path,
    fitted: &fshape_match::ops::regress::RegressionRun,
    shape: &FShape,
    traj: &fshape_match::ops::Trajectory,
    kept: &[usize],
) -> Result<()> {
    let (first, span) = (VISITS[0].0, VISITS[VISITS.len() - 1].0 - VISITS[0].0);
    let state = |age: f64| -> Result<FShape> {
        let (x, f) = traj.at((age - first) / span);
        Ok(shape.clone().with_points(x)?.with_signal(Some(f))?)
    };
    let result = fitted.result.as_ref().context("no result")?;
    // Between the visits: the fit against the truth.
    let baseline = &fitted.baseline;
    let mut between = Vec::new();
    for age in BETWEEN {
        let (x, f) = result.at_age(age);
        let fit = baseline.clone().with_points(x)?.with_signal(Some(f))?;
        let truth = state(age)?;
        let q = fshape_match::quality(&fit, &truth)?;
        let q0 = fshape_match::quality(baseline, &truth)?;
        println!(
            "  age {age}: the fit against the truth: mean distance {:.3}% (baseline {:.3}%), signal error {:.2}% (baseline {:.2}%)",
            100.0 * q.mean_distance,
            100.0 * q0.mean_distance,
            100.0 * q.signal_rms.unwrap_or(f64::NAN),
            100.0 * q0.signal_rms.unwrap_or(f64::NAN)
        );
        between.push(serde_json::json!({ "age": age, "quality": q, "baseline_quality": q0 }));
    }
    // The rate of thinning: the normal velocity per year at the baseline's
    // vertices (a subset of the truth's) against the truth's.
    let (rate, _) = fitted.rates().context("no rates")?;
    let normals = fshape_stats::maps::vertex_normals(shape).context("normals")?;
    let (v, _) = traj.velocity(0);
    let (mut err, mut norm) = (0.0, 0.0);
    for (i, &fine) in kept.iter().enumerate() {
        let truth_rate: f64 = (0..3).map(|d| v[3 * fine + d] * normals[fine][d]).sum::<f64>() / span;
        err += (rate[i] - truth_rate).powi(2);
        norm += truth_rate * truth_rate;
    }
    let rate_error = (err / norm).sqrt();
    println!("  the normal velocity per year against the truth's: relative L2 error {:.1}%", 100.0 * rate_error);
    let report = serde_json::json!({ "between_visits": between, "normal_rate_relative_l2_error": rate_error });
    io::write_atomic(&dir.join("truth.json"), serde_json::to_string_pretty(&report)?.as_bytes(), false)?;
    // Pictures: the truth and the fit at the middle age between visits,
    // and the rate maps, one camera.
    let (azimuth, elevation) = (30.0, 20.0);
    let age = BETWEEN[1];
    let (x, f) = result.at_age(age);
    let fit = baseline.clone().with_points(x)?.with_signal(Some(f))?;
    let truth = state(age)?;
    let view = fshape_report::render::View::fit(&[&truth, &fit], azimuth, elevation).with_range_of(&[&truth, &fit]);
    for (name, s) in [("truth_between.png", &truth), ("fit_between.png", &fit)] {
        io::write_atomic(&dir.join(name), &fshape_report::render::picture(s, &view)?, false)?;
    }
    let truth_rates: Vec<f64> =
        normals.iter().zip(v.chunks_exact(3)).map(|(n, v)| (n[0] * v[0] + n[1] * v[1] + n[2] * v[2]) / span).collect();
    let truth_map = shape.clone().with_signal(Some(truth_rates))?;
    let fit_map = baseline.clone().with_signal(Some(rate))?;
    let view = fshape_report::render::View::fit(&[&truth_map, &fit_map], azimuth, elevation)
        .with_range_of(&[&truth_map, &fit_map]);
    for (name, s) in [("truth_rate.png", &truth_map), ("fit_rate.png", &fit_map)] {
        io::write_atomic(&dir.join(name), &fshape_report::render::picture(s, &view)?, false)?;
    }
    Ok(())
}
