//! The group test on an atlas (`fshape stats`, Python's `stats`): each
//! subject's maps on the template ([`fshape_stats::subject_map`]), a
//! contrast tested at every vertex the template does not mask, and the
//! momenta's principal scores tested together. The caller reads the atlas
//! (a folder, or Python's result) and writes or returns what this finds.

use fshape_mesh::FShape;
use fshape_stats::{Contrast, Covariates, Design, Inference, Map, MapTest, MeshGraph, ScoresTest, StatKind, Tail};

use crate::MatchError;
use crate::record::{self, StatsRecord};

/// One subject of an atlas as a group test sees it.
#[derive(Clone, Debug)]
pub struct StatsSubject {
    /// The names a covariates row may give it (its index, its folder, its
    /// file, …), the first its index.
    pub names: Vec<String>,
    /// Its initial momenta p_0 (d per template vertex).
    pub p0: Vec<f64>,
    /// The template shot onto it (the template's cells and maps).
    pub matched: FShape,
}

/// The momenta's principal scores, subject by subject.
#[derive(Clone, Copy, Debug)]
pub struct Scores<'a> {
    /// `available` scores per subject, subject-major.
    pub values: &'a [f64],
    /// Scores per subject.
    pub available: usize,
    /// How many to test, the first ones (`None`: as many as the design
    /// leaves degrees of freedom for, at most `available`).
    pub modes: Option<usize>,
    /// Where they come from, for messages (`pca.csv`).
    pub source: &'a str,
}

/// What to test and how.
#[derive(Clone, Copy, Debug)]
pub struct StatsRequest<'a> {
    /// The atlas's estimated template (its mask's zeros are left out).
    pub template: &'a FShape,
    /// Its subjects, in its order.
    pub subjects: &'a [StatsSubject],
    /// The covariates table's text, and its name for messages.
    pub covariates: (&'a str, &'a str),
    /// The columns to enter (`None`: every one).
    pub columns: Option<&'a [String]>,
    /// The contrast: a column, a design column or weights.
    pub contrast: &'a str,
    /// The maps (`None`: every one the template allows).
    pub maps: Option<&'a [Map]>,
    /// The momenta's principal scores, for the multivariate test.
    pub scores: Option<Scores<'a>>,
    /// Permutations, seed, tail, TFCE.
    pub inference: Inference,
    /// The level of the counts in the record (corrected p ≤ alpha).
    pub alpha: f64,
}

/// A group test's results.
#[derive(Clone, Debug)]
pub struct StatsRun {
    /// The design the covariates gave.
    pub design: Design,
    /// The contrast tested.
    pub contrast: Contrast,
    /// Covariates rows that name no subject of the atlas.
    pub unused: Vec<String>,
    /// Per template vertex, whether it was tested (its mask's zeros not).
    pub tested: Vec<bool>,
    /// Each map and its test (NaN at the vertices not tested).
    pub maps: Vec<(Map, MapTest)>,
    /// The multivariate test on the scores, and how many it took.
    pub multivariate: Option<(usize, ScoresTest)>,
    /// The request's inference.
    pub inference: Inference,
    /// The request's level.
    pub alpha: f64,
    /// The template tested on.
    pub template: FShape,
}

/// Tests the request's contrast on every map and, given scores, on them.
pub fn group_stats(request: &StatsRequest<'_>) -> Result<StatsRun, MatchError> {
    let StatsRequest { template, subjects, .. } = *request;
    if !(request.alpha > 0.0 && request.alpha < 1.0) {
        return Err(MatchError::InvalidInput(format!("alpha: {} is not in (0, 1)", request.alpha)));
    }
    if subjects.is_empty() {
        return Err(MatchError::InvalidInput("the atlas has no subjects".into()));
    }
    let maps: Vec<Map> = match request.maps {
        None => Map::every(template),
        Some(maps) => {
            if let Some(m) = maps.iter().find(|m| !m.available(template)) {
                return Err(MatchError::InvalidInput(format!(
                    "maps {}: not defined on this template ({}s in R^{}{})",
                    m.name(),
                    template.kind().name(),
                    template.dim(),
                    match (m.kind, template.n_channels()) {
                        (fshape_stats::MapKind::Signal, 0) => ", without a signal".to_string(),
                        (fshape_stats::MapKind::Signal, c) => format!(", with {c} signal map(s)"),
                        _ => String::new(),
                    }
                )));
            }
            maps.to_vec()
        }
    };
    let (text, source) = request.covariates;
    let table = Covariates::parse(text, source)?;
    let names: Vec<Vec<String>> = subjects.iter().map(|s| s.names.clone()).collect();
    let (design, unused) = table.design(&names, request.columns)?;
    let contrast = design.contrast(request.contrast)?;
    let graph = MeshGraph::new(template);
    let (n, m) = (subjects.len(), template.n_vertices());
    // The template's masked vertices (weight 0: a medial wall) are outside
    // every test, geometric maps included: the region a study is about is
    // the one its maps have values on.
    let tested: Vec<bool> = template.mask().map_or_else(|| vec![true; m], |w| w.iter().map(|&w| w > 0.0).collect());
    let mut tests = Vec::with_capacity(maps.len());
    for map in maps {
        let mut values = Vec::with_capacity(n * m);
        for (i, s) in subjects.iter().enumerate() {
            let one = fshape_stats::subject_map(map, template, &s.p0, &s.matched).map_err(|e| {
                let name = s.names.get(1).map_or(String::new(), |n| format!(" ({n})"));
                MatchError::InvalidInput(format!("subject {i}{name}: {e}"))
            })?;
            values.extend(one);
        }
        let test =
            fshape_stats::test_maps_within(&design, &contrast, &values, &tested, Some(&graph), &request.inference)?;
        tests.push((map, test));
    }
    let multivariate = match request.scores {
        Some(s) if s.available > 0 => {
            let most = n.saturating_sub(design.p() + 1);
            let k = s.modes.unwrap_or(s.available.min(most));
            if k > s.available {
                return Err(MatchError::InvalidInput(format!("modes {k}: {} holds {} scores", s.source, s.available)));
            }
            if s.values.len() != n * s.available {
                return Err(MatchError::InvalidInput(format!(
                    "{}: {} scores for {n} subjects of {} each",
                    s.source,
                    s.values.len(),
                    s.available
                )));
            }
            if k == 0 {
                None
            } else {
                let picked: Vec<f64> = s.values.chunks_exact(s.available).flat_map(|row| row[..k].to_vec()).collect();
                Some((k, fshape_stats::test_scores(&design, &contrast, &picked, k, &request.inference)?))
            }
        }
        _ => None,
    };
    Ok(StatsRun {
        design,
        contrast,
        unused,
        tested,
        maps: tests,
        multivariate,
        inference: request.inference,
        alpha: request.alpha,
        template: template.clone(),
    })
}

/// The names a stats record gives its inputs.
#[derive(Clone, Copy, Debug)]
pub struct StatsLabels<'a> {
    /// The atlas, as given.
    pub atlas: &'a str,
    /// The covariates table, as given.
    pub covariates: &'a str,
}

impl StatsRun {
    /// The file names of map `k`'s outputs: its statistic, effect, p and
    /// corrected p (GIfTI), TFCE's two with TFCE, the statistic on the
    /// template (PLY) and its picture, in that order.
    pub fn files(&self, k: usize) -> Vec<String> {
        let (map, test) = &self.maps[k];
        let name = map.name();
        let mut files: Vec<String> = self.arrays(k).iter().map(|(s, _)| format!("{name}_{s}.gii")).collect();
        files.push(format!("{name}_{}.ply", stat_name(test)));
        files.push(format!("{name}.png"));
        files
    }

    /// Map `k`'s per-vertex results as its files name them: the statistic
    /// (`t` or `f`), `effect`, `p`, `p_fwe`, and with TFCE `tfce` and
    /// `tfce_p_fwe`.
    pub fn arrays(&self, k: usize) -> Vec<(&'static str, &[f64])> {
        let test = &self.maps[k].1;
        let mut arrays: Vec<(&'static str, &[f64])> = vec![
            (stat_name(test), &test.statistic),
            ("effect", &test.effect),
            ("p", &test.p_uncorrected),
            ("p_fwe", &test.p_fwe),
        ];
        if let (Some(t), Some(p)) = (&test.tfce, &test.tfce_p_fwe) {
            arrays.extend([("tfce", &t[..]), ("tfce_p_fwe", &p[..])]);
        }
        arrays
    }

    /// The run's record (summary.json): per map its peak, what reaches
    /// the level and its files; the multivariate test.
    pub fn record(&self, labels: StatsLabels<'_>, seconds: f64) -> StatsRecord {
        let areas = self.template.vertex_volumes();
        let total: f64 = areas.iter().zip(&self.tested).filter(|(_, t)| **t).map(|(a, _)| a).sum();
        let found = |p: &[f64]| record::Found {
            vertices: p.iter().filter(|&&q| q <= self.alpha).count(),
            area_share: p.iter().zip(&areas).filter(|(q, _)| **q <= self.alpha).map(|(_, w)| w).fold(0.0, |a, b| a + b)
                / total,
            min_p_fwe: p.iter().copied().fold(1.0, f64::min),
        };
        let two_sided = self.inference.tail == Tail::TwoSided;
        let maps = self
            .maps
            .iter()
            .enumerate()
            .map(|(k, (map, test))| {
                let tested = |v: f64| if test.kind == StatKind::T && two_sided { v.abs() } else { v };
                let peak = (0..test.statistic.len())
                    .filter(|&v| !test.statistic[v].is_nan())
                    .max_by(|&x, &y| tested(test.statistic[x]).total_cmp(&tested(test.statistic[y])))
                    .unwrap_or(0);
                record::MapRecord {
                    map: map.name(),
                    description: map.describe(),
                    statistic: if test.kind == StatKind::T { "t" } else { "F" }.into(),
                    dof: test.dof,
                    critical: test.critical(self.alpha),
                    peak: record::Peak {
                        vertex: peak,
                        position: self.template.point(peak).to_vec(),
                        statistic: test.statistic[peak],
                        effect: test.effect[peak],
                        p_uncorrected: test.p_uncorrected[peak],
                        p_fwe: test.p_fwe[peak],
                    },
                    found: found(&test.p_fwe),
                    tfce: test.tfce_p_fwe.as_deref().map(found),
                    files: self.files(k),
                }
            })
            .collect();
        let multivariate = self.multivariate.as_ref().map(|(modes, t)| record::ScoresRecord {
            test: if self.contrast.rank == 1 { "Hotelling T²" } else { "Hotelling–Lawley trace × (n − p)" }.into(),
            modes: *modes,
            statistic: t.statistic,
            p: t.p,
        });
        StatsRecord {
            kind: record::Kind::Stats,
            format: record::FORMAT,
            atlas: labels.atlas.into(),
            covariates: labels.covariates.into(),
            subjects: self.design.n,
            rows_not_in_the_atlas: self.unused.clone(),
            design: self.design.clone(),
            contrast: self.contrast.clone(),
            inference: self.inference,
            alpha: self.alpha,
            masked_vertices: self.tested.iter().filter(|t| !**t).count(),
            maps,
            multivariate,
            seconds,
        }
    }
}

/// A test's statistic as file names write it: `t` or `f`.
fn stat_name(test: &MapTest) -> &'static str {
    if test.kind == StatKind::T { "t" } else { "f" }
}
