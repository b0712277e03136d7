//! Values and flag groups that several commands take, parsed once by
//! clap: the camera of the pictures, the times at which a geodesic is
//! written, a job array's shard, a long run's configuration, output and
//! resume flags, the signal files of a pair. A bad value is a usage error
//! (exit status 2) naming the flag.

use std::path::PathBuf;

use clap::Args;

/// The camera of every picture unless `--view` says otherwise (the
/// demos' too): azimuth 30°, elevation 20°.
pub const DEFAULT_CAMERA: Camera = Camera { azimuth: 30.0, elevation: 20.0 };

/// `--times`' default: five states from t = 0 to 1.
const DEFAULT_TIMES: &str = "0,0.25,0.5,0.75,1";

/// The camera of the pictures: azimuth (about z, from the −y side) and
/// elevation (90 looks down z), in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub azimuth: f64,
    pub elevation: f64,
}

impl Camera {
    /// (azimuth, elevation).
    pub fn pair(self) -> (f64, f64) {
        (self.azimuth, self.elevation)
    }
}

impl std::fmt::Display for Camera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{},{}", self.azimuth, self.elevation)
    }
}

fn camera(s: &str) -> Result<Camera, String> {
    let bad = || format!("expected azimuth,elevation (two finite degrees), got `{s}`");
    let (a, e) = s.split_once(',').ok_or_else(bad)?;
    let (azimuth, elevation): (f64, f64) = (a.trim().parse().map_err(|_| bad())?, e.trim().parse().map_err(|_| bad())?);
    if !(azimuth.is_finite() && elevation.is_finite()) {
        return Err(bad());
    }
    Ok(Camera { azimuth, elevation })
}

/// `--view AZIMUTH,ELEVATION`.
#[derive(Args, Clone, Copy, Debug)]
pub struct View {
    /// Camera of the PNG pictures: azimuth,elevation in degrees (the
    /// azimuth turns about z, from the −y side; elevation 90 looks down z).
    #[arg(
        long = "view",
        value_name = "AZIMUTH,ELEVATION",
        default_value_t = DEFAULT_CAMERA,
        allow_hyphen_values = true,
        value_parser = camera
    )]
    pub camera: Camera,
}

fn time(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(t) if (0.0..=1.0).contains(&t) => Ok(t),
        Ok(t) => Err(format!("{t} is outside [0, 1]")),
        Err(_) => Err(format!("`{s}` is not a number")),
    }
}

/// `--times T,...`.
#[derive(Args, Clone, Debug)]
pub struct Times {
    /// Times in [0, 1] at which to write the geodesic's states.
    #[arg(long = "times", value_delimiter = ',', default_value = DEFAULT_TIMES, value_parser = time)]
    pub times: Vec<f64>,
}

/// How a long run reports its progress on stderr.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Verbosity {
    /// Nothing until the result.
    Quiet,
    /// A progress bar on a terminal; elsewhere (a batch system's log, a
    /// file, a pipe) a line per stage and per iteration.
    #[default]
    Normal,
    /// A line per stage and per iteration, even on a terminal.
    Verbose,
}

/// `--quiet` / `--verbose`.
#[derive(Args, Clone, Copy, Debug)]
pub struct Report {
    /// No progress on stderr (errors and the result only).
    #[arg(long, conflicts_with = "verbose")]
    pub quiet: bool,
    /// A line per stage and per iteration (elapsed time, J and its parts,
    /// step, evaluations) even on a terminal; elsewhere, e.g. under Slurm
    /// or with stderr in a file, these lines are the default.
    #[arg(long)]
    pub verbose: bool,
}

impl Report {
    pub fn verbosity(self) -> Verbosity {
        match (self.quiet, self.verbose) {
            (true, _) => Verbosity::Quiet,
            (_, true) => Verbosity::Verbose,
            _ => Verbosity::Normal,
        }
    }
}

/// A long run's configuration, output folder and checkpoint flags
/// (`fshape match`, `fshape atlas`).
#[derive(Args, Clone, Debug)]
pub struct Run {
    /// Model, attachment, optimizer and schedule (TOML; see fshape_match::Config).
    #[arg(long)]
    pub config: PathBuf,
    /// Output directory (created if needed).
    #[arg(long)]
    pub out: PathBuf,
    /// Continue from OUT/checkpoint.bin.
    #[arg(long)]
    pub resume: bool,
    /// Stop after this many iterations in this run, leaving the checkpoint.
    #[arg(long)]
    pub stop_after: Option<usize>,
}

/// Where a pair of shapes' signals come from (`fshape match`, `distance`,
/// `quality`).
#[derive(Args, Clone, Debug)]
pub struct Signals {
    /// Vertex property of both meshes to read as the signal (default `signal`).
    #[arg(long)]
    pub signal_name: Option<String>,
    /// Per-vertex signal file for the source (CSV, GIfTI, FreeSurfer curv,
    /// MGH, or a CIFTI map as FILE.dscalar.nii:CORTEX_LEFT, with :MAP after
    /// it to pick a map). Repeated, one signal channel per file (thickness,
    /// then myelin, ...), in the same order for the target.
    #[arg(long, visible_alias = "signal")]
    pub source_signal: Vec<PathBuf>,
    /// Per-vertex signal file for the target (as --source-signal).
    #[arg(long)]
    pub target_signal: Vec<PathBuf>,
    /// The source's mask: a FreeSurfer .label (its vertices count, the
    /// rest is masked), regions of a parcellation (lh.aparc.annot:insula,
    /// also .label.gii, and parcels.dlabel.nii:CORTEX_LEFT:V1_ROI) or a per-vertex column of weights in [0, 1]. A
    /// masked vertex's signal counts nowhere; its geometry still does.
    #[arg(long)]
    pub source_mask: Option<PathBuf>,
    /// The target's mask (as --source-mask).
    #[arg(long)]
    pub target_mask: Option<PathBuf>,
    /// Accept NaN in signal files as missing values: each masks its vertex
    /// (HCP's maps are NaN on the medial wall).
    #[arg(long)]
    pub allow_missing: bool,
}

impl Signals {
    /// The source's and the target's signal files.
    pub fn files(&self) -> (&[PathBuf], &[PathBuf]) {
        (&self.source_signal, &self.target_signal)
    }

    /// The source's and the target's masking.
    pub fn masking(&self) -> (crate::inputs::Masking<'_>, crate::inputs::Masking<'_>) {
        let allow_missing = self.allow_missing;
        (
            crate::inputs::Masking { mask: self.source_mask.as_deref(), allow_missing },
            crate::inputs::Masking { mask: self.target_mask.as_deref(), allow_missing },
        )
    }
}

/// A job array's share of the rows: task `index` of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// `I/N` with 0 ≤ I < N.
pub fn shard(s: &str) -> Result<Shard, String> {
    let bad = || format!("expected I/N with 0 <= I < N, got `{s}`");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (index, count): (usize, usize) = (i.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
    if index >= count {
        return Err(bad());
    }
    Ok(Shard { index, count })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_parse_or_say_why() {
        assert_eq!(camera("-90,0"), Ok(Camera { azimuth: -90.0, elevation: 0.0 }));
        assert!(camera("30").unwrap_err().contains("azimuth,elevation"));
        assert!(camera("nan,0").is_err());
        assert_eq!(time("0.5"), Ok(0.5));
        assert!(time("2").unwrap_err().contains("outside [0, 1]"));
        assert_eq!(shard("1/3"), Ok(Shard { index: 1, count: 3 }));
        for bad in ["2/2", "x/2", "1"] {
            assert!(shard(bad).is_err(), "{bad}");
        }
    }
}
