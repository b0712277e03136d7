//! Group statistics with a known answer: two groups of ellipsoids, one
//! with a bump in its geometry at one place and a rise of its signal at
//! another, every subject turned and moved at random; an atlas with rigid
//! pre-alignment, then `fshape stats` must find each effect at its place.

use std::path::Path;

use anyhow::{Context, Result};
use fshape_match::ops::ModelKind;
use fshape_match::{AlignKind, Config, NormKind, PrealignSection};
use fshape_mesh::FShape;
use fshape_mesh::generate::{SplitMix64, icosphere};
use fshape_mesh::io::{self, Encoding, write_mesh};

use super::attachment;
use fshape_report::render::{self, View};

/// Where the geometric effect and the signal effect sit, as unit
/// directions from the centre (projected onto the ellipsoid).
const GEOMETRY_AT: [f64; 3] = [0.6, -0.64, 0.48];
const SIGNAL_AT: [f64; 3] = [-0.6, 0.64, 0.48];
/// The effects' Gaussian width (the ellipsoid's half-axes are 0.65, 0.5,
/// 0.375), the bump's height along the normal and the signal's rise.
const WIDTH: f64 = 0.12;
const BUMP: f64 = 0.04;
const RISE: f64 = 0.4;
/// The deformation kernel's width: narrow enough to fit the bump.
const SIGMA_V: f64 = 0.1;
/// The population's own variability: per subject, [`NOISE_BUMPS`]
/// Gaussian bumps of width [`NOISE_WIDTH`] at random places, along the
/// normal with amplitude of standard deviation [`NOISE_GEOMETRY`] and in
/// the signal with [`NOISE_SIGNAL`].
const NOISE_BUMPS: usize = 8;
const NOISE_WIDTH: f64 = 0.2;
const NOISE_GEOMETRY: f64 = 0.015;
const NOISE_SIGNAL: f64 = 0.15;
/// The stated distance: every vertex found must lie within this many
/// effective widths √(w² + σ_V²) of its effect's centre (the template's
/// deformations are smooth at σ_V's scale, so a bump of width w is seen
/// through that blur).
pub const FOUND_WITHIN: f64 = 3.0;

/// Settings of the experiment.
pub struct StatsSpheresArgs<'a> {
    pub out: &'a Path,
    /// Subjects per group.
    pub per_group: usize,
    pub max_iterations: usize,
    pub gamma_w: f64,
    pub permutations: usize,
    /// Icosphere level of the ellipsoid (3: 642 vertices).
    pub level: u32,
}

/// A uniform random rotation (from a uniform unit quaternion).
fn random_rotation(rng: &mut SplitMix64) -> [[f64; 3]; 3] {
    let q: [f64; 4] = std::array::from_fn(|_| rng.normal());
    let len = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|c| c / len);
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

/// The vertex of `shape` nearest the ray from the origin along `dir`.
fn vertex_towards(shape: &FShape, dir: [f64; 3]) -> usize {
    let score = |v: usize| {
        let p = shape.point(v);
        let len = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        (p[0] * dir[0] + p[1] * dir[1] + p[2] * dir[2]) / len
    };
    (0..shape.n_vertices()).max_by(|&a, &b| score(a).total_cmp(&score(b))).unwrap_or(0)
}

fn gaussian_at(shape: &FShape, centre: &[f64], v: usize, width: f64) -> f64 {
    let p = shape.point(v);
    let d2: f64 = (0..3).map(|k| (p[k] - centre[k]).powi(2)).sum();
    (-d2 / (2.0 * width * width)).exp()
}

/// The atlas's configuration: H1 metamorphosis, p_0 in the energy metric,
/// each subject pre-aligned (rigid) to the initial template.
fn atlas_config(a: &StatsSpheresArgs<'_>) -> Result<Config> {
    let mut config = Config::new(vec![SIGMA_V]);
    config.model.kind = ModelKind::Metamorphosis;
    config.model.norm = NormKind::H1;
    config.model.length = 0.3;
    config.model.gamma_w = a.gamma_w;
    config.attachment = Some(attachment(0.05, 0.5, None)?);
    config.optimizer.momentum_metric = fshape_match::Metric::Energy;
    config.optimizer.max_iterations = a.max_iterations;
    config.optimizer.decrease_tolerance = 1e-3;
    config.optimizer.decrease_window = 5;
    config.prealign = Some(PrealignSection { kind: AlignKind::Rigid, ..PrealignSection::default() });
    Ok(config)
}

/// The effects' centres on the truth: the geometric one, the signal's.
struct Effects {
    geometry: Vec<f64>,
    signal: Vec<f64>,
}

/// Writes the population into `inputs`: each subject the truth with
/// random smooth variations (the population's own), its group's effects,
/// then a random rotation and a translation of up to 0.3. Returns the
/// subjects list and the covariates table's text.
fn population(a: &StatsSpheresArgs<'_>, truth: &FShape, effects: &Effects, inputs: &Path) -> Result<(String, String)> {
    let n = truth.n_vertices();
    let normals = fshape_stats::vertex_normals(truth).context("the ellipsoid's normals")?;
    let mut list = String::from("# two groups of ellipsoids, each subject turned and moved at random\n");
    let mut table = String::from("subject,group\n");
    let mut rng = SplitMix64(2026);
    for i in 0..2 * a.per_group {
        let effect = i % 2 == 1;
        let mut points = truth.points().to_vec();
        let mut signal = truth.signal().map(<[f64]>::to_vec).unwrap_or_default();
        let mut bumps: Vec<(Vec<f64>, f64, f64, f64)> = (0..NOISE_BUMPS)
            .map(|_| {
                let at = truth.point((rng.uniform() * n as f64) as usize % n).to_vec();
                (at, NOISE_WIDTH, NOISE_GEOMETRY * rng.normal(), NOISE_SIGNAL * rng.normal())
            })
            .collect();
        if effect {
            bumps.push((effects.geometry.clone(), WIDTH, BUMP, 0.0));
            bumps.push((effects.signal.clone(), WIDTH, 0.0, RISE));
        }
        for (at, width, height, rise) in &bumps {
            for v in 0..n {
                let g = gaussian_at(truth, at, v, *width);
                for c in 0..3 {
                    points[3 * v + c] += height * g * normals[v][c];
                }
                signal[v] += rise * g;
            }
        }
        let rot = random_rotation(&mut rng);
        let shift: [f64; 3] = std::array::from_fn(|_| rng.range(-0.3, 0.3));
        let moved: Vec<f64> = points
            .chunks_exact(3)
            .flat_map(|p| {
                let r: [f64; 3] =
                    std::array::from_fn(|row| (0..3).map(|c| rot[row][c] * p[c]).sum::<f64>() + shift[row]);
                r
            })
            .collect();
        let subject = truth.clone().with_points(moved)?.with_signal(Some(signal))?;
        let name = format!("ellipsoid_{i:02}");
        write_mesh(&inputs.join(format!("{name}.ply")), &subject, Encoding::Binary)?;
        list.push_str(&format!("{name}.ply\n"));
        table.push_str(&format!("{name},{}\n", if effect { "effect" } else { "control" }));
    }
    Ok((list, table))
}

/// The stated distance in the template's units: [`FOUND_WITHIN`] effective
/// widths √(w² + σ_V²).
fn stated_distance() -> f64 {
    FOUND_WITHIN * (WIDTH * WIDTH + SIGMA_V * SIGMA_V).sqrt()
}

/// Where each map found something, against the truth: vertices with
/// corrected p ≤ 0.05 near the geometric effect (`aims.0`, a template
/// vertex), near the signal's (`aims.1`), and away from both (there the
/// groups do not differ: false positives).
fn judge(
    template: &FShape,
    stats_dir: &Path,
    aims: (usize, usize),
) -> Result<serde_json::Map<String, serde_json::Value>> {
    let (geometry_vertex, signal_vertex) = aims;
    let n = template.n_vertices();
    let within = stated_distance();
    let distance = |v: usize, c: usize| -> f64 {
        let (p, q) = (template.point(v), template.point(c));
        (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt()
    };
    let mut report = serde_json::Map::new();
    for (map, aimed) in [
        ("signal", signal_vertex),
        ("momentum", geometry_vertex),
        ("displacement", geometry_vertex),
        ("area", geometry_vertex),
    ] {
        let read = |suffix: &str| -> Result<Vec<f64>> {
            Ok(io::read_signal(&stats_dir.join(format!("{map}_{suffix}.gii")))?.values)
        };
        let (t, p_fwe, p_tfce) = (read("t")?, read("p_fwe")?, read("tfce_p_fwe")?);
        let summarise = |p: &[f64]| {
            let found: Vec<usize> = (0..n).filter(|&v| p[v] <= 0.05).collect();
            let near = |c: usize| found.iter().filter(|&&v| distance(v, c) <= within).count();
            let elsewhere = found
                .iter()
                .filter(|&&v| distance(v, geometry_vertex) > within && distance(v, signal_vertex) > within)
                .count();
            serde_json::json!({
                "vertices": found.len(),
                "near_geometry_effect": near(geometry_vertex),
                "near_signal_effect": near(signal_vertex),
                "elsewhere": elsewhere,
            })
        };
        let peak = (0..n).max_by(|&x, &y| t[x].abs().total_cmp(&t[y].abs())).unwrap_or(0);
        report.insert(
            map.into(),
            serde_json::json!({
                "aimed_at": if aimed == signal_vertex { "signal effect" } else { "geometry effect" },
                "peak_distance_to_geometry_effect": distance(peak, geometry_vertex),
                "peak_distance_to_signal_effect": distance(peak, signal_vertex),
                "peak_t": t[peak],
                "max_t": summarise(&p_fwe),
                "tfce": summarise(&p_tfce),
            }),
        );
    }
    report.insert("stated_distance".into(), within.into());
    report.insert("width".into(), WIDTH.into());
    Ok(report)
}

/// The true effects on the template, drawn as the maps are.
fn truth_pictures(dir: &Path, truth: &FShape, template: &FShape, effects: &Effects) -> Result<()> {
    let n = truth.n_vertices();
    let bumps = |centre: &[f64]| -> Vec<f64> { (0..n).map(|v| gaussian_at(truth, centre, v, WIDTH)).collect() };
    for (name, values) in
        [("truth_geometry.png", bumps(&effects.geometry)), ("truth_signal.png", bumps(&effects.signal))]
    {
        let shape = template.clone().with_signal(Some(values))?;
        let (azimuth, elevation) = crate::args::DEFAULT_CAMERA.pair();
        let tiles = [azimuth, azimuth + 180.0]
            .map(|az| render::rasterise(&shape, &View::fit(&[template], az, elevation).diverging(1.0)));
        let (rgb, width, height) = render::mosaic(tiles.into_iter(), 2, 1);
        io::write_atomic(&dir.join(name), &render::png_sized(&rgb, width, height)?, false)?;
    }
    Ok(())
}

pub fn stats_spheres(a: &StatsSpheresArgs<'_>) -> Result<()> {
    let dir = a.out.join("stats-spheres");
    let inputs = dir.join("subjects");
    std::fs::create_dir_all(&inputs).with_context(|| format!("creating {}", inputs.display()))?;
    let sphere = icosphere(a.level, 0.5);
    let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [1.3 * p[0], p[1], 0.75 * p[2]]).collect();
    // 2z + x: no rotation of the ellipsoid keeps this signal, so the
    // pre-alignment has one answer.
    let f: Vec<f64> = pts.chunks_exact(3).map(|p| 2.0 * p[2] + p[0]).collect();
    let truth = sphere.with_points(pts)?.with_signal(Some(f))?;
    let n = truth.n_vertices();
    let aims = (vertex_towards(&truth, GEOMETRY_AT), vertex_towards(&truth, SIGNAL_AT));
    let effects = Effects { geometry: truth.point(aims.0).to_vec(), signal: truth.point(aims.1).to_vec() };
    let config = atlas_config(a)?;
    let (list, table) = population(a, &truth, &effects, &inputs)?;
    let list_path = inputs.join("subjects.csv");
    io::write_atomic(&list_path, list.as_bytes(), false)?;
    let table_path = dir.join("covariates.csv");
    io::write_atomic(&table_path, table.as_bytes(), false)?;
    let start = dir.join("template_start.ply");
    write_mesh(&start, &truth, Encoding::Binary)?;
    let run = dir.join("atlas");
    std::fs::create_dir_all(&run).with_context(|| format!("creating {}", run.display()))?;
    let cfg = run.join("config.toml");
    let header = "# fshape demo stats-spheres: the atlas of two groups of ellipsoids, each subject pre-aligned\n\
                  # (rigid) to the initial template, H1 metamorphosis, p_0 in the energy metric.\n\n";
    io::write_atomic(&cfg, format!("{header}{}", config.clone().with_stage_tables().to_toml()).as_bytes(), false)?;
    eprintln!(
        "stats-spheres: {} ellipsoids of {n} vertices in two groups, turned and moved -> {}",
        2 * a.per_group,
        run.display()
    );
    super::run_atlas(&list_path, &start, &cfg, &run, crate::args::DEFAULT_CAMERA.pair())?;
    let stats_dir = dir.join("stats");
    super::run_stats(&run, &table_path, "group", &stats_dir, a.permutations, crate::args::DEFAULT_CAMERA)?;
    let template = io::read_mesh(&run.join("template.ply"), &io::ReadOptions::default())?;
    let report = judge(&template, &stats_dir, aims)?;
    io::write_atomic(&dir.join("truth.json"), serde_json::to_string_pretty(&report)?.as_bytes(), false)?;
    truth_pictures(&dir, &truth, &template, &effects)?;
    println!(
        "  p_FWE ≤ 0.05 (max-t | TFCE), vertices within {:.2} of the geometry effect, of the signal effect, elsewhere:",
        stated_distance()
    );
    for (map, r) in &report {
        if let Some(r) = r.as_object() {
            let counts = |k: &str| {
                format!("{} {} {}", r[k]["near_geometry_effect"], r[k]["near_signal_effect"], r[k]["elsewhere"])
            };
            println!("  {map:<12} {} | {}", counts("max_t"), counts("tfce"));
        }
    }
    Ok(())
}
