//! `fshape demo`: the paper's experiments on the repository's data (the
//! experiments themselves are in `experiments`, one module each).

use std::path::PathBuf;

use anyhow::{Result, bail};

mod experiments;
use experiments as demo;

/// The experiments `fshape demo` runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Experiment {
    Digits,
    Bunny,
    Cortex,
    AtlasDigits,
    AtlasSpheres,
    StatsSpheres,
    StatsDigits,
    RegressSpheres,
}

/// `fshape demo`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// Which experiment: digits, bunny, cortex, atlas-digits (an atlas
    /// of 64 writers' 3s), atlas-spheres (an atlas with a known answer),
    /// stats-spheres (group statistics with a known answer: two groups
    /// of turned and moved ellipsoids, effects at known places) or
    /// stats-digits (where writers' 3s and 5s differ) or regress-spheres
    /// (a regression with a known answer: a thinning ellipsoid's visits);
    /// the atlases write `fshape atlas` outputs, the statistics `fshape
    /// stats` outputs, the regression `fshape regress` outputs.
    pub name: Experiment,
    /// Output directory.
    #[arg(long, default_value = "demo-output")]
    pub out: PathBuf,
    /// The repository's data directory.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Iteration limit per schedule stage.
    #[arg(long, default_value_t = 100)]
    pub max_iterations: usize,
    /// Digits: the ratios γ_V/γ_f to run.
    #[arg(long, value_delimiter = ',', default_value = "1,20,100")]
    pub ratios: Vec<f64>,
    /// Weight γ_W of the data attachment (scale-free: the demos
    /// normalise lengths and signals).
    #[arg(long, default_value_t = 1e3)]
    pub gamma_w: f64,
    /// Bunny: the 642-vertex sphere as template and the first three
    /// stages on it (about a minute per norm) instead of the paper's
    /// 10242 vertices.
    #[arg(long)]
    pub quick: bool,
    /// atlas-digits: only the first N subjects (0: all 64);
    /// stats-spheres: subjects per group (0: 10); stats-digits: writers
    /// per class (0: 16).
    #[arg(long, default_value_t = 0)]
    pub subjects: usize,
    /// stats-spheres, stats-digits: permutations of the group test.
    #[arg(long, default_value_t = 2000)]
    pub permutations: usize,
}

pub fn run(a: Args) -> Result<()> {
    if a.quick && !matches!(a.name, Experiment::Bunny | Experiment::StatsSpheres) {
        bail!("--quick: only the bunny and stats-spheres demos have a quick variant");
    }
    let data = a.data.unwrap_or_else(demo::default_data);
    let (out, max_iterations, gamma_w, quick) = (&a.out, a.max_iterations, a.gamma_w, a.quick);
    let run = demo::RunArgs { out, data: &data, max_iterations, gamma_w, quick };
    let digits = demo::DigitsArgs { out, data: &data, ratios: &a.ratios, max_iterations, gamma_w };
    match a.name {
        Experiment::Bunny => demo::bunny(&run),
        Experiment::Cortex => demo::cortex(&run),
        Experiment::AtlasSpheres => demo::atlas_spheres(out, max_iterations, gamma_w),
        Experiment::RegressSpheres => demo::regress_spheres(out, max_iterations, gamma_w),
        Experiment::AtlasDigits => demo::atlas_digits(&digits, a.subjects),
        Experiment::Digits => demo::digits(&digits),
        Experiment::StatsDigits => demo::stats_digits(
            &digits,
            if a.subjects == 0 { demo::STATS_DIGITS_PER_CLASS } else { a.subjects },
            a.permutations,
        ),
        Experiment::StatsSpheres => demo::stats_spheres(&demo::StatsSpheresArgs {
            out,
            per_group: if a.subjects == 0 { 10 } else { a.subjects },
            max_iterations,
            gamma_w,
            permutations: a.permutations,
            level: if quick { 2 } else { 3 },
        }),
    }
}
