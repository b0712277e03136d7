//! `fshape stats`: where an atlas's subjects differ with a covariate.
//! Reads an `fshape atlas` output folder and a covariates table, builds
//! the per-vertex maps of fshape-stats on the template, tests a contrast
//! at every vertex with permutations (FWE-corrected by the maximum
//! statistic, TFCE as an option) and on the momenta's principal scores
//! (Hotelling–Lawley), and writes the maps (GIfTI, PLY), pictures, a
//! table and summary.json. The template's masked vertices (its mask's
//! zeros: a medial wall) are left out of every test: NaN in the maps,
//! grey in the pictures, outside TFCE's graph.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fshape_match::record::{self, AtlasRecord, RunRecord};
use fshape_mesh::FShape;
use fshape_mesh::io::{self, Encoding, ReadOptions};
use fshape_stats::{Covariates, Inference, Map, MapKind, MapTest, MeshGraph, StatKind, Tail, TfceParams};
use serde::Serialize;

use fshape_report::render::{self, View};

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

/// One subject of the atlas: the names a table row may use, its momenta
/// and the template shot onto it.
struct Subject {
    names: Vec<String>,
    p0: Vec<f64>,
    matched: FShape,
}

/// An atlas folder's contents: the template, the subjects and, from
/// pca.csv, the scores' names and values (subject-major).
struct AtlasFolder {
    template: FShape,
    subjects: Vec<Subject>,
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
        subjects.push(Subject { names, p0, matched });
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

#[derive(Serialize)]
struct Peak {
    vertex: usize,
    position: Vec<f64>,
    statistic: f64,
    effect: f64,
    p_uncorrected: f64,
    p_fwe: f64,
}

#[derive(Serialize)]
struct Found {
    /// Vertices with corrected p ≤ alpha.
    vertices: usize,
    /// Their share of the template's area (length for a curve).
    area_share: f64,
    /// The smallest corrected p.
    min_p_fwe: f64,
}

#[derive(Serialize)]
struct MapSummary {
    map: String,
    description: String,
    statistic: &'static str,
    dof: (usize, usize),
    /// The tested value (|t| when two-sided) that reaches p_FWE ≤ alpha.
    critical: f64,
    peak: Peak,
    found: Found,
    tfce: Option<Found>,
    files: Vec<String>,
}

#[derive(Serialize)]
struct ScoresSummary {
    test: &'static str,
    modes: usize,
    statistic: f64,
    p: f64,
}

#[derive(Serialize)]
struct Summary<'a> {
    /// [`record::Kind::Stats`] and [`record::FORMAT`], as every run record
    /// starts (nothing reads this one back: it holds fshape-stats' results,
    /// which fshape-match's records do not know).
    kind: record::Kind,
    format: u32,
    atlas: String,
    covariates: String,
    subjects: usize,
    rows_not_in_the_atlas: Vec<String>,
    design: &'a fshape_stats::Design,
    contrast: &'a fshape_stats::Contrast,
    inference: &'a Inference,
    alpha: f64,
    /// The template's masked vertices, left out of every test.
    masked_vertices: usize,
    maps: Vec<MapSummary>,
    multivariate: Option<ScoresSummary>,
    seconds: f64,
}

pub fn run(a: Args) -> Result<()> {
    let start = std::time::Instant::now();
    if !(a.alpha > 0.0 && a.alpha < 1.0) {
        bail!("--alpha: {} is not in (0, 1)", a.alpha);
    }
    let AtlasFolder { template, subjects, scores } = read_atlas(&a.atlas)?;
    let bytes = io::read_bytes(&a.covariates)?;
    let text = String::from_utf8(bytes).with_context(|| format!("{}: not UTF-8 text", a.covariates.display()))?;
    let table = Covariates::parse(&text, &a.covariates.display().to_string())?;
    let names: Vec<Vec<String>> = subjects.iter().map(|s| s.names.clone()).collect();
    let columns = (!a.columns.is_empty()).then_some(a.columns.as_slice());
    let (design, unused) = table.design(&names, columns)?;
    let contrast = design.contrast(&a.contrast)?;
    let inference = Inference {
        permutations: a.permutations,
        seed: a.seed,
        tail: if a.one_sided { Tail::Positive } else { Tail::TwoSided },
        tfce: a.tfce.then(TfceParams::default),
    };
    let kinds: Vec<Map> = if a.maps.is_empty() {
        Map::every(&template)
    } else {
        for k in &a.maps {
            if !k.available(&template) {
                bail!(
                    "--maps {}: not defined on this template ({}s in R^{}{})",
                    k.name(),
                    template.kind().name(),
                    template.dim(),
                    match (k.kind, template.n_channels()) {
                        (MapKind::Signal, 0) => ", without a signal".to_string(),
                        (MapKind::Signal, c) => format!(", with {c} signal map(s)"),
                        _ => String::new(),
                    }
                );
            }
        }
        a.maps.clone()
    };
    if !unused.is_empty() {
        eprintln!(
            "note: {} row(s) of {} name no subject of the atlas: {}",
            unused.len(),
            a.covariates.display(),
            unused.join(", ")
        );
    }
    let graph = MeshGraph::new(&template);
    let areas = template.vertex_volumes();
    let n = subjects.len();
    let m = template.n_vertices();
    // The template's masked vertices (weight 0: a medial wall) are outside
    // every test, geometric maps included: the region a study is about is
    // the one its maps have values on.
    let tested: Vec<bool> = template.mask().map_or_else(|| vec![true; m], |w| w.iter().map(|&w| w > 0.0).collect());
    let masked_vertices = tested.iter().filter(|t| !**t).count();
    let total_area: f64 = areas.iter().zip(&tested).filter(|(_, t)| **t).map(|(a, _)| a).sum();
    let mut outputs: Vec<(String, Vec<u8>)> = Vec::new();
    let mut map_summaries = Vec::new();
    let (azimuth, elevation) = a.view.camera.pair();
    for kind in &kinds {
        let mut maps = Vec::with_capacity(n * m);
        for (i, s) in subjects.iter().enumerate() {
            let map = fshape_stats::subject_map(*kind, &template, &s.p0, &s.matched)
                .with_context(|| format!("subject {i} ({})", s.names[1]))?;
            maps.extend(map);
        }
        let test = fshape_stats::test_maps_within(&design, &contrast, &maps, &tested, Some(&graph), &inference)?;
        let name = kind.name();
        let name = name.as_str();
        let stat_name = if test.kind == StatKind::T { "t" } else { "f" };
        let mut files = Vec::new();
        let mut gifti = |suffix: &str, values: &[f64]| -> Result<()> {
            let file = format!("{name}_{suffix}.gii");
            let mut bytes = Vec::new();
            io::gifti::write_arrays(
                &mut bytes,
                &[io::gifti::signal_array(&format!("{name} {suffix}"), values)],
                io::gifti::WriteOptions::default(),
            )?;
            outputs.push((file.clone(), bytes));
            files.push(file);
            Ok(())
        };
        gifti(stat_name, &test.statistic)?;
        gifti("effect", &test.effect)?;
        gifti("p", &test.p_uncorrected)?;
        gifti("p_fwe", &test.p_fwe)?;
        if let (Some(t), Some(p)) = (&test.tfce, &test.tfce_p_fwe) {
            gifti("tfce", t)?;
            gifti("tfce_p_fwe", p)?;
        }
        let with_stat = template.clone().with_signal(Some(test.statistic.clone()))?;
        let mut ply = Vec::new();
        io::write_to(&mut ply, &with_stat, io::Format::Ply, Encoding::Binary)?;
        let file = format!("{name}_{stat_name}.ply");
        outputs.push((file.clone(), ply));
        files.push(file);
        let significant = test.tfce_p_fwe.as_ref().unwrap_or(&test.p_fwe);
        let png = picture(&template, &test, significant, a.alpha, azimuth, elevation)?;
        let file = format!("{name}.png");
        outputs.push((file.clone(), png));
        files.push(file);
        let found = |p: &[f64]| Found {
            vertices: p.iter().filter(|&&q| q <= a.alpha).count(),
            area_share: p.iter().zip(&areas).filter(|(q, _)| **q <= a.alpha).map(|(_, w)| w).fold(0.0, |a, b| a + b)
                / total_area,
            min_p_fwe: p.iter().copied().fold(1.0, f64::min),
        };
        let tested = |v: f64| if test.kind == StatKind::T && !a.one_sided { v.abs() } else { v };
        let peak = (0..m)
            .filter(|&v| !test.statistic[v].is_nan())
            .max_by(|&x, &y| tested(test.statistic[x]).total_cmp(&tested(test.statistic[y])))
            .unwrap_or(0);
        map_summaries.push(MapSummary {
            map: name.to_string(),
            description: kind.describe(),
            statistic: if test.kind == StatKind::T { "t" } else { "F" },
            dof: test.dof,
            critical: test.critical(a.alpha),
            peak: Peak {
                vertex: peak,
                position: template.point(peak).to_vec(),
                statistic: test.statistic[peak],
                effect: test.effect[peak],
                p_uncorrected: test.p_uncorrected[peak],
                p_fwe: test.p_fwe[peak],
            },
            found: found(&test.p_fwe),
            tfce: test.tfce_p_fwe.as_deref().map(found),
            files,
        });
    }
    // The multivariate test on the momenta's principal scores.
    let multivariate = match &scores {
        Some((header, values)) if !header.is_empty() => {
            let available = header.len();
            let most = n.saturating_sub(design.p() + 1);
            let k = a.modes.unwrap_or(available.min(most));
            if k > available {
                bail!("--modes {k}: {} holds {available} scores", a.atlas.join("pca.csv").display());
            }
            if k == 0 {
                None
            } else {
                let picked: Vec<f64> = (0..n).flat_map(|i| values[i * available..i * available + k].to_vec()).collect();
                let test = fshape_stats::test_scores(&design, &contrast, &picked, k, &inference)?;
                Some(ScoresSummary {
                    test: if contrast.rank == 1 { "Hotelling T²" } else { "Hotelling–Lawley trace × (n − p)" },
                    modes: k,
                    statistic: test.statistic,
                    p: test.p,
                })
            }
        }
        _ => None,
    };
    if let Some(s) = &multivariate {
        outputs.push((
            "multivariate.csv".into(),
            format!(
                "test,modes,statistic,p,permutations\n{},{},{:e},{},{}\n",
                s.test, s.modes, s.statistic, s.p, a.permutations
            )
            .into_bytes(),
        ));
    }
    let summary = Summary {
        kind: record::Kind::Stats,
        format: record::FORMAT,
        atlas: a.atlas.display().to_string(),
        covariates: a.covariates.display().to_string(),
        subjects: n,
        rows_not_in_the_atlas: unused,
        design: &design,
        contrast: &contrast,
        inference: &inference,
        alpha: a.alpha,
        masked_vertices,
        maps: map_summaries,
        multivariate,
        seconds: start.elapsed().as_secs_f64(),
    };
    outputs.push(("summary.json".into(), serde_json::to_vec_pretty(&summary)?));
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    for (name, bytes) in &outputs {
        io::write_atomic(&a.out.join(name), bytes, false)?;
    }
    println!(
        "{} subjects, contrast `{}` ({}), {} permutations; wrote {} files to {}",
        n,
        contrast.name,
        if contrast.rank == 1 { "t" } else { "F" },
        a.permutations,
        outputs.len(),
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

/// The statistic on the template, blue (negative) to red: above, every
/// vertex; below, only where the corrected p ≤ alpha. Surfaces in R³ are
/// seen from the camera and from behind.
fn picture(template: &FShape, test: &MapTest, p: &[f64], alpha: f64, azimuth: f64, elevation: f64) -> Result<Vec<u8>> {
    let bound = test.statistic.iter().fold(0.0f64, |b, v| b.max(v.abs()));
    // Masked vertices stay NaN (drawn grey) in both rows.
    let shown: Vec<f64> =
        test.statistic.iter().zip(p).map(|(t, q)| if *q <= alpha || t.is_nan() { *t } else { 0.0 }).collect();
    let all = template.clone().with_signal(Some(test.statistic.clone()))?;
    let thresholded = template.clone().with_signal(Some(shown))?;
    let azimuths: &[f64] = if template.dim() == 3 { &[azimuth, azimuth + 180.0] } else { &[azimuth] };
    let views: Vec<View> = azimuths.iter().map(|&az| View::fit(&[template], az, elevation).diverging(bound)).collect();
    // A column per view: every vertex above, the thresholded map below.
    let tiles: Vec<(&FShape, &View)> =
        [&all, &thresholded].into_iter().flat_map(|s| views.iter().map(move |v| (s, v))).collect();
    let (rgb, width, height) =
        render::mosaic(tiles.iter().map(|(shape, view)| render::rasterise(shape, view)), views.len(), 1);
    Ok(render::png_sized(&rgb, width, height)?)
}
