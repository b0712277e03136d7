//! `fshape demo`: the paper's experiments on data shipped in the
//! repository. Each demo writes its inputs (meshes and one TOML config per
//! run) next to its results, so every run can be repeated or varied with
//! `fshape match` alone.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fshape_mesh::generate::{sample_image, square};
use fshape_mesh::io::image::read_image;
use fshape_mesh::io::{self, Encoding, write_mesh};

/// fshapesTk writes Gaussians as exp(−u/σ²), fshape as exp(−u/(2σ²)): the
/// paper's widths (fshapesTk's) are ours × √2, so ours = theirs / √2.
fn from_fshapestk(sigma: f64) -> f64 {
    sigma / std::f64::consts::SQRT_2
}

/// The data directory of the repository this binary was built from.
pub fn default_data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data")
}

/// Writes `config` to RUN/config.toml and runs `fshape match` with it into
/// RUN, writing the geodesic at t = 0, 0.2, …, 1 seen from +z.
fn run_match(source: &Path, target: &Path, config: &str, run: &Path) -> Result<()> {
    let cfg = run.join("config.toml");
    io::write_atomic(&cfg, config.as_bytes(), false)?;
    crate::match_cmd::run(&crate::match_cmd::MatchArgs {
        source,
        target,
        config: &cfg,
        out: run,
        resume: false,
        stop_after: None,
        signal_name: None,
        times: &[0.0, 0.2, 0.4, 0.6, 0.8, 1.0],
        view: (0.0, 90.0),
    })
}

/// Settings shared by the digits runs.
pub struct DigitsArgs<'a> {
    pub out: &'a Path,
    pub data: &'a Path,
    pub ratios: &'a [f64],
    pub max_iterations: usize,
    pub gamma_w: f64,
}

/// Digits (paper section 5.1): a handwritten 2 onto a handwritten 3 (MNIST,
/// values rescaled to [0, 0.6]) on two different Delaunay squares of about
/// 4900 vertices, L² (lumped) metamorphosis for each γ_V/γ_f.
pub fn digits(a: &DigitsArgs<'_>) -> Result<()> {
    let dir = a.out.join("digits");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let shape = |file: &str, seed: u64| -> Result<fshape_mesh::FShape> {
        let path = a.data.join("digits").join(file);
        let image = read_image(&path, None)?;
        let mesh = square(4250, seed);
        let values: Vec<f64> = sample_image(&image, &mesh).iter().map(|v| 0.6 * v / 255.0).collect();
        Ok(mesh.with_signal(Some(values))?)
    };
    let (source, target) = (shape("mnist5k_1000_label2.csv", 1)?, shape("mnist5k_1500_label3.csv", 2)?);
    let (sp, tp) = (dir.join("source.ply"), dir.join("target.ply"));
    write_mesh(&sp, &source, Encoding::Binary)?;
    write_mesh(&tp, &target, Encoding::Binary)?;
    eprintln!(
        "digits: source {} vertices, target {} vertices (a 2 onto a 3, signal in [0, 0.6])",
        source.n_vertices(),
        target.n_vertices()
    );
    let (v1, v2) = (from_fshapestk(0.2), from_fshapestk(0.1));
    let (p1, p2, p3, f) = (from_fshapestk(0.2), from_fshapestk(0.1), from_fshapestk(0.05), from_fshapestk(0.7));
    for &ratio in a.ratios {
        let run = dir.join(format!("ratio_{ratio}"));
        std::fs::create_dir_all(&run).with_context(|| format!("creating {}", run.display()))?;
        let config = format!(
            "# fshape demo digits: gamma_V / gamma_f = {ratio}. Widths are the paper's\n\
             # (fshapesTk's exp(-u/s^2)) divided by sqrt(2) for fshape's exp(-u/(2 s^2)).\n\
             [model]\nkind = \"metamorphosis\"\nnorm = \"l2-lumped\"\ngamma_v = 1.0\ngamma_f = {gf}\ngamma_w = {gw}\n\
             [deformation]\nwidths = [{v1}, {v2}]\ntolerance = 1e-6\n\
             [integrator]\nscheme = \"rk4\"\nsteps = 10\n\
             [attachment]\nkernel_geom = \"gaussian:{p3}\"\nkernel_signal = \"gaussian:{f}\"\nkernel_grass = \"binet\"\ntolerance = 1e-6\n\
             [optimizer]\nmax_iterations = {it}\n\
             [schedule]\nkernel_geom = [\"gaussian:{p1}\", \"gaussian:{p2}\", \"gaussian:{p3}\"]\n",
            gf = 1.0 / ratio,
            gw = a.gamma_w,
            it = a.max_iterations,
        );
        eprintln!("digits: gamma_V/gamma_f = {ratio} -> {}", run.display());
        run_match(&sp, &tp, &config, &run).with_context(|| format!("digits, gamma_V/gamma_f = {ratio}"))?;
    }
    Ok(())
}

/// Settings of the bunny runs.
pub struct BunnyArgs<'a> {
    pub out: &'a Path,
    pub data: &'a Path,
    pub max_iterations: usize,
    pub gamma_w: f64,
}

/// The bunny (paper section 5.1): the level-5 sphere with signal 0 onto the
/// textured 2581-vertex Stanford bunny, H¹ against lumped L², the shipped
/// `data/configs/bunny.toml` with γ_W and a coarse-to-fine schedule of k_p
/// (0.2, 0.1, 0.05) added.
pub fn bunny(a: &BunnyArgs<'_>) -> Result<()> {
    let dir = a.out.join("bunny");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let bunny = io::read_mesh(&a.data.join("stanford_bunny/bunny_qslim_2581v.ply.gz"), &io::ReadOptions::default())?;
    let (template, target) = fshape_shoot::paper::bunny_setting(&bunny)?;
    let (sp, tp) = (dir.join("source.ply"), dir.join("target.ply"));
    write_mesh(&sp, &template, Encoding::Binary)?;
    write_mesh(&tp, &target, Encoding::Binary)?;
    let shipped = std::fs::read_to_string(a.data.join("configs/bunny.toml"))
        .with_context(|| format!("reading {}", a.data.join("configs/bunny.toml").display()))?;
    for norm in ["h1", "l2-lumped"] {
        let run = dir.join(norm);
        std::fs::create_dir_all(&run).with_context(|| format!("creating {}", run.display()))?;
        let config = shipped
            .replace("norm = \"h1\"", &format!("norm = \"{norm}\""))
            .replace("gamma_w = 1.0", &format!("gamma_w = {}", a.gamma_w))
            + &format!(
                "\n[optimizer]\nmax_iterations = {}\n\n[schedule]\nkernel_geom = [\"gaussian:0.2\", \"gaussian:0.1\", \"gaussian:0.05\"]\n",
                a.max_iterations
            );
        eprintln!("bunny: {norm} -> {}", run.display());
        run_match(&sp, &tp, &config, &run).with_context(|| format!("bunny, {norm}"))?;
    }
    Ok(())
}
