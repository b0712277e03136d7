//! An atlas with a known answer: spheres deformed around a known template.

use std::path::Path;

use anyhow::{Context, Result};
use fshape_match::ops::ModelKind;
use fshape_match::{Config, NormKind};
use fshape_mesh::FShape;
use fshape_mesh::io::{self, Encoding, write_mesh};

use super::{BUNNY_DECREASE, attachment};

/// Subjects of the atlas with a known answer.
pub const ATLAS_SPHERES_SUBJECTS: usize = 10;

/// An atlas with a known answer: the truth is an ellipsoid (the level-3
/// icosphere of radius 0.5 stretched by 1.3, 1, 0.75; 642 vertices)
/// carrying 2z; [`ATLAS_SPHERES_SUBJECTS`] subjects are the truth shot by
/// seeded random momenta and signal momenta (H¹ metamorphosis, deformation
/// width 0.4); the atlas starts from the sphere with the subjects' mean
/// signal and must come back to the truth. Prints the distance of the
/// estimated template to the truth against its bound: the subjects' mean
/// displacement (the first-order bias of any estimate from this sample)
/// plus the atlas's residual (the subjects' mean distance after matching).
/// The population's mean displacement from the truth, vertex by vertex:
/// its length averaged over the vertices, as a fraction of the truth's
/// diagonal (what an atlas of these subjects cannot tell from the truth).
fn mean_displacement(subjects: &[FShape], truth: &FShape) -> f64 {
    let n = truth.n_vertices();
    let count = subjects.len() as f64;
    let mut bias = vec![0.0; 3 * n];
    for s in subjects {
        for (b, (x, y)) in bias.iter_mut().zip(s.points().iter().zip(truth.points())) {
            *b += (x - y) / count;
        }
    }
    let diag = truth.bounding_box().diagonal();
    bias.chunks_exact(3).map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()).sum::<f64>() / n as f64 / diag
}

pub fn atlas_spheres(out: &Path, max_iterations: usize, gamma_w: f64) -> Result<()> {
    use fshape_mesh::generate::{SplitMix64, icosphere};
    let random_vector_field = |n: usize, dim: usize, scale: f64, seed: u64| -> Vec<f64> {
        let mut rng = SplitMix64(seed);
        (0..n * dim).map(|_| rng.range(-scale, scale)).collect()
    };
    let dir = out.join("atlas-spheres");
    let inputs = dir.join("subjects");
    std::fs::create_dir_all(&inputs).with_context(|| format!("creating {}", inputs.display()))?;
    let sphere = icosphere(3, 0.5);
    let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [1.3 * p[0], p[1], 0.75 * p[2]]).collect();
    let f: Vec<f64> = pts.chunks_exact(3).map(|p| 2.0 * p[2]).collect();
    let truth = sphere.clone().with_points(pts)?.with_signal(Some(f))?;
    let mut config = Config::new(vec![0.4]);
    config.model.kind = ModelKind::Metamorphosis;
    config.model.norm = NormKind::H1;
    config.model.length = 0.3;
    config.model.gamma_w = gamma_w;
    config.attachment = Some(attachment(0.1, 0.5, None)?);
    config.optimizer.momentum_metric = fshape_match::Metric::Energy;
    config.optimizer.max_iterations = 3 * max_iterations;
    config.optimizer.decrease_tolerance = 1e-3;
    config.optimizer.decrease_window = BUNNY_DECREASE.1;
    let plan = config.plan(&truth, &truth)?;
    let n = truth.n_vertices();
    let mut list = String::from("# the truth shot by seeded random momenta\n");
    let mut subjects = Vec::new();
    for i in 0..ATLAS_SPHERES_SUBJECTS as u64 {
        let (p0, pf) = (random_vector_field(n, 3, 0.002, 100 + i), random_vector_field(n, 1, 0.002, 200 + i));
        let traj = fshape_match::ops::shoot(&truth, &plan.model, &p0, &pf)?.trajectory;
        let k = traj.steps();
        let subject = truth.clone().with_points(traj.points(k).to_vec())?.with_signal(Some(traj.signal(k).to_vec()))?;
        let name = format!("subject_{i:02}.ply");
        write_mesh(&inputs.join(&name), &subject, Encoding::Binary)?;
        list.push_str(&format!("{name}\n"));
        subjects.push(subject);
    }
    let list_path = inputs.join("subjects.csv");
    io::write_atomic(&list_path, list.as_bytes(), false)?;
    write_mesh(&dir.join("truth.ply"), &truth, Encoding::Binary)?;
    let start = dir.join("template_start.ply");
    write_mesh(&start, &sphere, Encoding::Binary)?;
    let run = dir.join("atlas");
    std::fs::create_dir_all(&run).with_context(|| format!("creating {}", run.display()))?;
    let cfg = run.join("config.toml");
    let header = "# fshape demo atlas-spheres: an atlas with a known answer (truth.ply), H1 metamorphosis,\n\
                  # scale-free weights, p_0 in the energy metric, one stage ending when the mean J fell\n\
                  # by less than 1e-3 over 5 iterations.\n\n";
    io::write_atomic(&cfg, format!("{header}{}", config.clone().with_stage_tables().to_toml()).as_bytes(), false)?;
    eprintln!("atlas-spheres: {} subjects shot from an ellipsoid of {n} vertices -> {}", subjects.len(), run.display());
    super::run_atlas(&list_path, &start, &cfg, &run, crate::args::DEFAULT_CAMERA.pair())?;
    // The estimate against the truth, and the bound.
    let estimate = io::read_mesh(&run.join("template.ply"), &io::ReadOptions::default())?;
    let got = fshape_match::quality(&estimate, &truth)?;
    let before = fshape_match::quality(&sphere.clone().with_signal(Some(vec![0.0; n]))?, &truth)?;
    let bias = mean_displacement(&subjects, &truth);
    use fshape_match::record::{AtlasRecord, RunRecord};
    let residual = AtlasRecord::read(&run.join("summary.json"))?.mean_distance;
    let report = serde_json::json!({
        "truth_distance_start": before.mean_distance,
        "truth_distance": got.mean_distance,
        "bound": bias + residual,
        "bias": bias,
        "residual": residual,
        "truth_signal_rms": got.signal_rms,
        "quality": got,
    });
    io::write_atomic(&dir.join("truth.json"), serde_json::to_string_pretty(&report)?.as_bytes(), false)?;
    let (azimuth, elevation) = crate::args::DEFAULT_CAMERA.pair();
    let view = fshape_report::render::View::fit(&[&truth, &estimate, &sphere], azimuth, elevation);
    for (name, shape) in [("truth.png", &truth), ("estimate.png", &estimate)] {
        io::write_atomic(&dir.join(name), &fshape_report::render::picture(shape, &view)?, false)?;
    }
    println!(
        "  the template against the truth: mean distance {:.3}% of the diagonal (start {:.3}%; bound {:.3}% = mean displacement {:.3}% + residual {:.3}%)",
        100.0 * got.mean_distance,
        100.0 * before.mean_distance,
        100.0 * (bias + residual),
        100.0 * bias,
        100.0 * residual
    );
    Ok(())
}
