//! The atlas of 64 writers' 3s.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fshape_match::ops::ModelKind;
use fshape_match::{Config, NormKind};
use fshape_mesh::FShape;
use fshape_mesh::generate::{sample_image, square};
use fshape_mesh::io::image::read_image;
use fshape_mesh::io::{self, Encoding, write_mesh};

use super::{BUNNY_DECREASE, DigitsArgs, attachment, from_fshapestk, schedule};

/// Points asked of `generate::square` for the atlas of digits: a mesh
/// about as fine as the 28 × 28 images.
pub const ATLAS_DIGITS_POINTS: usize = 700;

/// γ_V/γ_f of the atlas of digits: the middle of the paper's three ratios,
/// where the deformation and the signal change share the work (the
/// digits demo: 29 % and 71 % of the energy).
pub const ATLAS_DIGITS_RATIO: f64 = 20.0;

/// The files of the first `count` digits `label` of
/// `DATA/digits_population/labelL/`, in name order (0: all).
pub(super) fn digit_files(data: &Path, label: u8, count: usize) -> Result<Vec<PathBuf>> {
    let population = data.join("digits_population").join(format!("label{label}"));
    let mut files: Vec<PathBuf> = std::fs::read_dir(&population)
        .with_context(|| format!("reading {}", population.display()))?
        .map(|e| e.map(|e| e.path()))
        .collect::<std::io::Result<_>>()
        .with_context(|| format!("reading {}", population.display()))?;
    files.retain(|p| p.extension().is_some_and(|e| e == "csv"));
    files.sort();
    if count > 0 {
        files.truncate(count);
    }
    anyhow::ensure!(!files.is_empty(), "{}: no digit files (*.csv)", population.display());
    Ok(files)
}

/// Writes each digit image sampled on `mesh` (values 0.6 × pixel / 255)
/// to INPUTS/STEM.ply; the file names, in order.
pub(super) fn write_digits(files: &[PathBuf], mesh: &FShape, inputs: &Path) -> Result<Vec<String>> {
    std::fs::create_dir_all(inputs).with_context(|| format!("creating {}", inputs.display()))?;
    let mut names = Vec::with_capacity(files.len());
    for path in files {
        let image = read_image(path, None)?;
        let values: Vec<f64> = sample_image(&image, mesh).iter().map(|v| 0.6 * v / 255.0).collect();
        let stem = path.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        let name = format!("{stem}.ply");
        write_mesh(&inputs.join(&name), &mesh.clone().with_signal(Some(values))?, Encoding::Binary)?;
        names.push(name);
    }
    Ok(names)
}

/// The configuration of the atlases of digits (see [`atlas_digits`]) and
/// the header of its file; `what` names the demo and its population.
pub(super) fn digits_atlas_config(a: &DigitsArgs<'_>, what: &str) -> Result<(Config, String)> {
    let (v1, v2) = (from_fshapestk(0.2), from_fshapestk(0.1));
    let (p1, p2, f) = (from_fshapestk(0.2), from_fshapestk(0.1), from_fshapestk(0.7));
    let n = a.max_iterations;
    let mut config = Config::new(vec![v1, v2]);
    config.model.kind = ModelKind::Metamorphosis;
    config.model.norm = NormKind::L2Lumped;
    config.model.gamma_f = 1.0 / ATLAS_DIGITS_RATIO;
    config.model.gamma_w = a.gamma_w;
    config.deformation.tolerance = Some(1e-6);
    config.attachment = Some(attachment(p2, f, Some(1e-6))?);
    config.optimizer.momentum_metric = fshape_match::Metric::Energy;
    config.schedule = Some(schedule(&[p1, p2], vec![BUNNY_DECREASE.0; 2], vec![4 * n, 4 * n])?);
    let header = format!(
        "fshape demo {what}, lumped L2 metamorphosis, gamma_V / gamma_f = {ATLAS_DIGITS_RATIO},\n\
         scale-free weights (gamma_w {}), p_0 in the energy metric; k_p 0.141 then 0.071, each\n\
         stage ending when the mean J fell by less than {} over {} iterations.",
        a.gamma_w, BUNNY_DECREASE.0, BUNNY_DECREASE.1
    );
    Ok((config, header))
}

/// The atlas of digits: the 64 handwritten 3s of
/// `data/digits_population/label3/` (values rescaled to [0, 0.6]) on one
/// Delaunay square of [`ATLAS_DIGITS_POINTS`] points, the template starting
/// as that square with the population's mean image; lumped L²
/// metamorphosis at γ_V/γ_f = [`ATLAS_DIGITS_RATIO`], the digits demo's
/// kernels and scale-free weights, p_0 in the energy metric, two stages
/// (k_p 0.141 then 0.071), each ending on [`BUNNY_DECREASE`] (limits 4
/// times `max_iterations`). `subjects` limits the population to its first
/// files (0: all).
pub fn atlas_digits(a: &DigitsArgs<'_>, subjects: usize) -> Result<()> {
    let dir = a.out.join("atlas-digits");
    let files = digit_files(a.data, 3, subjects)?;
    let mesh = square(ATLAS_DIGITS_POINTS, 1);
    let inputs = dir.join("subjects");
    let mut list = String::from("# the population: 28x28 MNIST 3s on one square, values 0.6 * pixel / 255\n");
    for name in write_digits(&files, &mesh, &inputs)? {
        list.push_str(&format!("{name}\n"));
    }
    let list_path = inputs.join("subjects.csv");
    io::write_atomic(&list_path, list.as_bytes(), false)?;
    let template_path = dir.join("template_start.ply");
    write_mesh(&template_path, &mesh, Encoding::Binary)?;
    eprintln!(
        "atlas-digits: {} writers' 3s on a square of {} vertices, template from their mean image",
        files.len(),
        mesh.n_vertices()
    );
    let (config, header) = digits_atlas_config(a, &format!("atlas-digits: {} 3s", files.len()))?;
    let run = dir.join("atlas");
    std::fs::create_dir_all(&run).with_context(|| format!("creating {}", run.display()))?;
    let cfg = run.join("config.toml");
    let comments: String = header.lines().map(|l| format!("# {l}\n")).collect();
    io::write_atomic(&cfg, format!("{comments}\n{}", config.clone().with_stage_tables().to_toml()).as_bytes(), false)?;
    super::run_atlas(&list_path, &template_path, &cfg, &run, (0.0, 90.0))
}
