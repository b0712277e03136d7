//! `fshape stats`: where an atlas's subjects differ with a covariate.
//! Reads an `fshape atlas` output folder and a covariates table; the
//! operation ([`fshape_match::ops::group_stats`]) builds the per-vertex
//! maps of fshape-stats on the template, tests a contrast at every vertex
//! with permutations (FWE-corrected by the maximum statistic, TFCE as an
//! option) and on the momenta's principal scores (Hotelling–Lawley);
//! fshape-report writes the maps (GIfTI, PLY), pictures, a table and
//! summary.json. The template's masked vertices (its mask's
//! zeros: a medial wall) are left out of every test: NaN in the maps,
//! grey in the pictures, outside TFCE's graph.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fshape_match::MatchError;
use fshape_match::ops::{Scores, StatsLabels, StatsRequest, StatsSubject, group_stats};
use fshape_match::record::{AtlasRecord, RunRecord};
use fshape_mesh::FShape;
use fshape_mesh::io::{self, ReadOptions};
use fshape_report::outputs;
use fshape_stats::{Inference, Map, Tail, TfceParams};

/// `fshape stats`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The folder `fshape atlas` wrote (template.ply, subject_*/,
    /// pca.csv, summary.json).
    pub atlas: PathBuf,
    /// The covariates table (CSV or tab-separated, with a header): the
    /// first column names each subject (its index, its folder
    /// `subject_003`, its mesh file's path or name, or that name without
    /// extensions), the others are numbers or group names.
    #[arg(long)]
    pub covariates: PathBuf,
    /// The contrast: a column's name (`group`, `age`; a factor of more
    /// than two levels gives an F test), a design column
    /// (`group[patient]`) or weights on the design's columns, intercept
    /// first (`0,1,0`; rows separated by `;` for an F test).
    #[arg(long, allow_hyphen_values = true)]
    pub contrast: String,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// The covariates to enter (default: every column of the table).
    #[arg(long, value_delimiter = ',')]
    pub columns: Vec<String>,
    /// Maps to test: signal, momentum, displacement, area; with several
    /// signal maps per vertex, signal_2, signal_3, … after the first
    /// (default: every one the template allows).
    #[arg(long, value_delimiter = ',', value_parser = map_of)]
    pub maps: Vec<Map>,
    /// Permutations, the observed labelling included.
    #[arg(long, default_value_t = 5000)]
    pub permutations: usize,
    /// Seed of the permutations (the same seed gives the same bits).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Also threshold-free cluster enhancement (E = 1, H = 2, as FSL and
    /// PALM for surfaces), with its own FWE-corrected p.
    #[arg(long)]
    pub tfce: bool,
    /// t tests count positive t only (FSL's convention; test the negated
    /// contrast for the other sign). Default: both signs.
    #[arg(long)]
    pub one_sided: bool,
    /// Level of the thresholded pictures and of the counts in the summary.
    #[arg(long, default_value_t = 0.05)]
    pub alpha: f64,
    /// Principal scores of the momenta in the multivariate test (default:
    /// those of pca.csv, at most n − p − 1).
    #[arg(long)]
    pub modes: Option<usize>,
    #[command(flatten)]
    pub view: crate::args::View,
}

fn map_of(s: &str) -> Result<Map, String> {
    Map::from_name(s.trim())
        .ok_or_else(|| format!("`{s}` is not a map (expected signal, signal_2, …, momentum, displacement or area)"))
}

/// An atlas folder's contents: the template, the subjects and, from
/// pca.csv, the scores' names and values (subject-major).
struct AtlasFolder {
    template: FShape,
    subjects: Vec<StatsSubject>,
    scores: Option<(Vec<String>, Vec<f64>)>,
}

/// The atlas folder's template, subjects and principal scores.
fn read_atlas(dir: &Path) -> Result<AtlasFolder> {
    let summary_path = dir.join("summary.json");
    if !summary_path.exists() {
        bail!("{}: not an `fshape atlas` output folder (no summary.json)", dir.display());
    }
    let entries = AtlasRecord::read(&summary_path)?.subjects;
    let template = io::read_mesh(&dir.join("template.ply"), &ReadOptions::default())?;
    let dim = template.dim();
    let mut subjects = Vec::with_capacity(entries.len());
    for (i, entry) in entries.iter().enumerate() {
        let folder = entry.directory.clone();
        let mut names = vec![i.to_string(), folder.clone(), entry.file.clone()];
        if let Some(base) = Path::new(&entry.file).file_name().and_then(|n| n.to_str()) {
            names.push(base.to_string());
            names.push(base.split('.').next().unwrap_or(base).to_string());
        }
        names.dedup();
        let sub = dir.join(&folder);
        let p0 = io::csv::read_vectors(&sub.join("p0.csv"), dim)?;
        let matched = io::read_mesh(&sub.join("matched.ply"), &ReadOptions::default())?;
        subjects.push(StatsSubject { names, p0, matched });
    }
    if subjects.is_empty() {
        bail!("{}: the atlas has no subjects", summary_path.display());
    }
    let pca_path = dir.join("pca.csv");
    let scores = if pca_path.exists() {
        let mut lines = io::table::read_table(&pca_path)?.into_iter();
        let header: Vec<String> = lines.next().map(|r| r.fields.into_iter().skip(1).collect()).unwrap_or_default();
        let mut values = Vec::new();
        for io::table::Record { line, fields } in lines {
            let cells = &fields[1.min(fields.len())..];
            if cells.len() != header.len() {
                bail!("{}:{line}: {} scores, the header names {}", pca_path.display(), cells.len(), header.len());
            }
            for (k, c) in cells.iter().enumerate() {
                values.push(c.parse::<f64>().map_err(|_| {
                    anyhow::anyhow!("{}:{line}: column {}: `{c}` is not a number", pca_path.display(), k + 2)
                })?);
            }
        }
        if values.len() != header.len() * subjects.len() {
            bail!(
                "{}: {} rows for {} subjects",
                pca_path.display(),
                values.len() / header.len().max(1),
                subjects.len()
            );
        }
        Some((header, values))
    } else {
        None
    };
    Ok(AtlasFolder { template, subjects, scores })
}

pub fn run(a: Args) -> Result<()> {
    let started = std::time::Instant::now();
    let AtlasFolder { template, subjects, scores } = read_atlas(&a.atlas)?;
    let bytes = io::read_bytes(&a.covariates)?;
    let text = String::from_utf8(bytes).with_context(|| format!("{}: not UTF-8 text", a.covariates.display()))?;
    let (atlas, covariates) = (a.atlas.display().to_string(), a.covariates.display().to_string());
    let pca = a.atlas.join("pca.csv").display().to_string();
    let request = StatsRequest {
        template: &template,
        subjects: &subjects,
        covariates: (&text, &covariates),
        columns: (!a.columns.is_empty()).then_some(a.columns.as_slice()),
        contrast: &a.contrast,
        maps: (!a.maps.is_empty()).then_some(a.maps.as_slice()),
        scores: scores.as_ref().map(|(header, values)| Scores {
            values,
            available: header.len(),
            modes: a.modes,
            source: &pca,
        }),
        inference: Inference {
            permutations: a.permutations,
            seed: a.seed,
            tail: if a.one_sided { Tail::Positive } else { Tail::TwoSided },
            tfce: a.tfce.then(TfceParams::default),
        },
        alpha: a.alpha,
    };
    let run = group_stats(&request).map_err(|e| match e {
        // The request's fields are the options' names.
        MatchError::InvalidInput(m) if ["alpha", "maps", "modes"].iter().any(|o| m.starts_with(o)) => {
            anyhow::anyhow!("--{m}")
        }
        e => e.into(),
    })?;
    if !run.unused.is_empty() {
        eprintln!(
            "note: {} row(s) of {covariates} name no subject of the atlas: {}",
            run.unused.len(),
            run.unused.join(", ")
        );
    }
    let labels = StatsLabels { atlas: &atlas, covariates: &covariates };
    let (summary, files) = outputs::write_stats(&run, labels, &a.out, a.view.camera.pair(), started)?;
    println!(
        "{} subjects, contrast `{}` ({}), {} permutations; wrote {files} files to {}",
        summary.subjects,
        run.contrast.name,
        if run.contrast.rank == 1 { "t" } else { "F" },
        a.permutations,
        a.out.display()
    );
    for s in &summary.maps {
        let tfce =
            s.tfce.as_ref().map_or(String::new(), |f| format!("; TFCE: {:.1} % of the area", 100.0 * f.area_share));
        println!(
            "  {:<12} peak {} = {:.2} (p_FWE {:.4}); p_FWE ≤ {}: {:.1} % of the area{tfce}",
            s.map,
            s.statistic,
            s.peak.statistic,
            s.peak.p_fwe,
            a.alpha,
            100.0 * s.found.area_share
        );
    }
    if let Some(s) = &summary.multivariate {
        println!("  momenta's first {} principal scores: {} = {:.3}, p = {:.4}", s.modes, s.test, s.statistic, s.p);
    }
    Ok(())
}
