//! Where do writers' 3s and 5s differ? One atlas of both populations,
//! then `fshape stats` on the digit's class.

use anyhow::{Context, Result};
use fshape_mesh::generate::square;
use fshape_mesh::io::{self, Encoding, write_mesh};

use super::DigitsArgs;
use super::atlas_digits::{ATLAS_DIGITS_POINTS, digit_files, digits_atlas_config, write_digits};

/// Writers per class when `--subjects` is not given.
pub const STATS_DIGITS_PER_CLASS: usize = 16;

/// The first `per_class` 3s and 5s of `data/digits_population/` on the
/// atlas of digits' square, one atlas of all of them (the atlas-digits
/// configuration, the template starting from their mean image), then the
/// class compared vertex by vertex (the signal change and the log area
/// change; `permutations` permutations, TFCE) and on the momenta's
/// principal scores.
pub fn stats_digits(a: &DigitsArgs<'_>, per_class: usize, permutations: usize) -> Result<()> {
    let dir = a.out.join("stats-digits");
    let mesh = square(ATLAS_DIGITS_POINTS, 1);
    let inputs = dir.join("subjects");
    let mut list = String::from("# 28x28 MNIST 3s and 5s on one square, values 0.6 * pixel / 255\n");
    let mut table = String::from("subject,digit\n");
    for label in [3u8, 5] {
        let files = digit_files(a.data, label, per_class)?;
        for name in write_digits(&files, &mesh, &inputs)? {
            list.push_str(&format!("{name}\n"));
            let stem = name.trim_end_matches(".ply");
            table.push_str(&format!("{stem},{}\n", if label == 3 { "three" } else { "five" }));
        }
    }
    let list_path = inputs.join("subjects.csv");
    io::write_atomic(&list_path, list.as_bytes(), false)?;
    let table_path = dir.join("covariates.csv");
    io::write_atomic(&table_path, table.as_bytes(), false)?;
    let template_path = dir.join("template_start.ply");
    write_mesh(&template_path, &mesh, Encoding::Binary)?;
    let (config, header) = digits_atlas_config(a, &format!("stats-digits: {per_class} 3s and {per_class} 5s"))?;
    let run = dir.join("atlas");
    std::fs::create_dir_all(&run).with_context(|| format!("creating {}", run.display()))?;
    let cfg = run.join("config.toml");
    let comments: String = header.lines().map(|l| format!("# {l}\n")).collect();
    io::write_atomic(&cfg, format!("{comments}\n{}", config.clone().with_stage_tables().to_toml()).as_bytes(), false)?;
    eprintln!(
        "stats-digits: {per_class} writers' 3s and {per_class} writers' 5s on a square of {} vertices -> {}",
        mesh.n_vertices(),
        dir.display()
    );
    super::run_atlas(&list_path, &template_path, &cfg, &run, (0.0, 90.0))?;
    // `digit` is a factor: `five` is the reference (sorted first), so t > 0
    // where the 3s are higher.
    super::run_stats(
        &run,
        &table_path,
        "digit",
        &dir.join("stats"),
        permutations,
        crate::args::Camera { azimuth: 0.0, elevation: 90.0 },
    )
}
