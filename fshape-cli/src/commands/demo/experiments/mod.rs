//! `fshape demo`: the paper's experiments on data shipped in the
//! repository, one module per experiment, and the helpers they share. Each
//! demo writes its inputs (meshes and one TOML config per run) next to its
//! results, so every run can be repeated or varied with `fshape match`
//! alone.

mod atlas_digits;
mod atlas_spheres;
mod bunny;
mod cortex;
mod digits;
mod regress_spheres;
mod stats_digits;
mod stats_spheres;

pub use atlas_digits::atlas_digits;
pub use atlas_spheres::atlas_spheres;
pub use bunny::bunny;
pub use cortex::cortex;
pub use digits::digits;
pub use regress_spheres::regress_spheres;
pub use stats_digits::{STATS_DIGITS_PER_CLASS, stats_digits};
pub use stats_spheres::{StatsSpheresArgs, stats_spheres};

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fshape_match::{AttachmentSection, Config, GrassKernelSpec, PositionKernel, ScheduleSection, SignalKernelSpec};
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

/// Creates DIR and writes the demo's inputs there as binary PLY: the paths
/// of DIR/source.ply and DIR/target.ply.
fn write_inputs(dir: &Path, source: &fshape_mesh::FShape, target: &fshape_mesh::FShape) -> Result<(PathBuf, PathBuf)> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let (sp, tp) = (dir.join("source.ply"), dir.join("target.ply"));
    write_mesh(&sp, source, Encoding::Binary)?;
    write_mesh(&tp, target, Encoding::Binary)?;
    Ok((sp, tp))
}

/// A position kernel `gaussian:σ` (σ written in Rust's shortest form).
fn gaussian(sigma: f64) -> Result<PositionKernel> {
    Ok(PositionKernel::parse(&format!("gaussian:{sigma}"))?)
}

/// `[attachment]` with a Gaussian k_p of width `geom`, a Gaussian k_f of
/// width `signal`, the Binet k_t, truncated at `tolerance`.
fn attachment(geom: f64, signal: f64, tolerance: Option<f64>) -> Result<AttachmentSection> {
    Ok(AttachmentSection {
        kernel_geom: gaussian(geom)?,
        kernel_signal: Some(SignalKernelSpec::parse(&format!("gaussian:{signal}"))?),
        kernel_grass: GrassKernelSpec::parse("binet")?,
        tolerance,
        masked_geometry: true,
    })
}

/// `[schedule]` of Gaussian position kernels, coarse to fine, each stage
/// ending when J fell by less than its tolerance over
/// [`BUNNY_DECREASE`]'s window, or at its iteration limit.
fn schedule(widths: &[f64], tolerances: Vec<f64>, limits: Vec<usize>) -> Result<ScheduleSection> {
    let mut stages = ScheduleSection::new(widths.iter().map(|&w| gaussian(w)).collect::<Result<_>>()?);
    stages.decrease_tolerance = Some(tolerances);
    stages.decrease_window = Some(vec![BUNNY_DECREASE.1; widths.len()]);
    stages.max_iterations = Some(limits);
    Ok(stages)
}

/// Writes `config` (after the comment lines of `header`) to
/// RUN/config.toml, creating RUN, and runs `fshape match` with it into RUN,
/// writing the geodesic at t = 0, 0.2, …, 1 seen from `view` (azimuth,
/// elevation in degrees), with coarser templates for the stages before the
/// last (`--stage-templates`).
fn run_match(
    source: &Path,
    target: &Path,
    header: &str,
    config: &Config,
    run: &Path,
    view: (f64, f64),
    stage_templates: &[PathBuf],
) -> Result<()> {
    std::fs::create_dir_all(run).with_context(|| format!("creating {}", run.display()))?;
    let cfg = run.join("config.toml");
    let comments: String = header.lines().map(|l| format!("# {l}\n")).collect();
    io::write_atomic(&cfg, format!("{comments}\n{}", config.clone().with_stage_tables().to_toml()).as_bytes(), false)?;
    crate::commands::matching::run_with(&crate::commands::matching::MatchArgs {
        masking: Default::default(),
        source,
        target,
        signals: (&[], &[]),
        config: &cfg,
        out: run,
        resume: false,
        stop_after: None,
        signal_name: None,
        times: &[0.0, 0.2, 0.4, 0.6, 0.8, 1.0],
        view,
        stage_templates,
        verbosity: crate::args::Verbosity::Normal,
        label: None,
    })
}

/// `fshape atlas` as the atlas demos run it: the subjects of `list` from
/// `template`, the configuration file `config`, outputs in `out`, the
/// pictures from `view` (azimuth, elevation).
fn run_atlas(list: &Path, template: &Path, config: &Path, out: &Path, view: (f64, f64)) -> Result<()> {
    crate::commands::atlas::run_with(&crate::commands::atlas::AtlasArgs {
        subjects: &[],
        list: Some(list),
        template: Some(template),
        template_mask: None,
        allow_missing: false,
        config,
        out,
        resume: false,
        stop_after: None,
        signal_name: None,
        view,
        stage_templates: &[],
        verbosity: crate::args::Verbosity::Normal,
    })
}

/// `fshape stats` as the statistics demos run it: every map the template
/// allows, TFCE, seed 0, two-sided, α = 0.05.
fn run_stats(
    atlas: &Path,
    covariates: &Path,
    contrast: &str,
    out: &Path,
    permutations: usize,
    camera: crate::args::Camera,
) -> Result<()> {
    crate::commands::stats::run(crate::commands::stats::Args {
        atlas: atlas.to_path_buf(),
        covariates: covariates.to_path_buf(),
        contrast: contrast.into(),
        out: out.to_path_buf(),
        columns: Vec::new(),
        maps: Vec::new(),
        permutations,
        seed: 0,
        tfce: true,
        one_sided: false,
        alpha: 0.05,
        modes: None,
        view: crate::args::View { camera },
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

/// The stages' convergence test of the bunny and digits demos: J fell by
/// less than this fraction over this many iterations.
pub const BUNNY_DECREASE: (f64, usize) = (1e-2, 5);

/// Settings of the bunny and cortex runs.
pub struct RunArgs<'a> {
    pub out: &'a Path,
    pub data: &'a Path,
    pub max_iterations: usize,
    pub gamma_w: f64,
    /// Bunny: the level-3 template, three stages on it.
    pub quick: bool,
}
