//! The coarse-to-fine schedule: `[schedule]`'s arrays or `[[stage]]`'s
//! tables, each stage checked into a [`StageSpec`].

use fshape_shoot::Integrator;
use fshape_varifold::VarifoldKernel;
use serde::{Deserialize, Serialize};

use super::check::bad;
use super::{Config, PositionKernel};
use crate::MatchError;

/// `[schedule]`. The older form of the schedule, an array per key: it
/// still reads, with a warning, and a run writes it as `[[stage]]` tables.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScheduleSection {
    /// The position kernel of each stage, coarse to fine.
    pub kernel_geom: Vec<PositionKernel>,
    /// The integrator of each stage (default: `[integrator] scheme` for
    /// all); the last must be `[integrator]`'s: the model asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scheme: Option<Vec<Integrator>>,
    /// The time steps of each stage (default: `[integrator] steps` for
    /// all); the last must be `[integrator]`'s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<Vec<usize>>,
    /// The iteration limit of each stage (default: `[optimizer]
    /// max_iterations` for all): coarse stages may do most of the work.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iterations: Option<Vec<usize>>,
    /// The relative-decrease tolerance of each stage (default:
    /// `[optimizer] decrease_tolerance` for all).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decrease_tolerance: Option<Vec<f64>>,
    /// The window of each stage's decrease test (default: `[optimizer]
    /// decrease_window` for all): a short final stage needs a short window.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decrease_window: Option<Vec<usize>>,
    /// The vertex count of each stage's template but the last, which runs
    /// on the source: the source simplified to it
    /// ([`fshape_mesh::FShape::simplified`], keeping a subset of its
    /// vertices with their signal); a count at least the source's is the
    /// source. One value per stage before the last, as
    /// `--stage-templates` takes one mesh each (default: every stage on the
    /// source). Not with hand-made stage templates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertices: Option<Vec<usize>>,
    /// With `vertices`: each such stage also matches the target simplified
    /// to the same count (default true), so that a coarse stage's data
    /// term costs what its template's size calls for; the last stage
    /// always matches the target itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_targets: Option<bool>,
}

impl ScheduleSection {
    /// Stages with these position kernels, each with `[integrator]`'s
    /// scheme and steps.
    pub fn new(kernel_geom: Vec<PositionKernel>) -> ScheduleSection {
        ScheduleSection {
            kernel_geom,
            scheme: None,
            steps: None,
            max_iterations: None,
            decrease_tolerance: None,
            decrease_window: None,
            vertices: None,
            coarse_targets: None,
        }
    }
}

/// `[[stage]]`. The schedule written as one table per stage, coarse to
/// fine, instead of `[schedule]`'s arrays (not both): each stage's keys
/// together, so no array can have one value too few. A key a stage leaves
/// out takes `[integrator]`'s or `[optimizer]`'s value; errors name the
/// stage (`stage[1].vertices`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageTable {
    /// The stage's position kernel.
    pub kernel_geom: PositionKernel,
    /// Its integrator (the last stage's must be `[integrator]`'s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scheme: Option<Integrator>,
    /// Its time steps (the last stage's must be `[integrator]`'s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<usize>,
    /// Its iteration limit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iterations: Option<usize>,
    /// Its relative-decrease tolerance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decrease_tolerance: Option<f64>,
    /// The window of its decrease test.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decrease_window: Option<usize>,
    /// The vertex count of its template: every stage before the last has
    /// one, or none does; the last runs on the source.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertices: Option<usize>,
    /// With `vertices`: whether it matches the target simplified alike
    /// (default true; the same in every stage that says).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_target: Option<bool>,
}

/// One stage of the schedule: what it is called in reports and its data
/// attachment kernel.
#[derive(Clone, Debug)]
pub struct StageSpec {
    /// The stage's position kernel as written (`gaussian:0.1`).
    pub label: String,
    /// The data attachment kernel of the stage.
    pub kernel: VarifoldKernel,
    /// The stage's integrator and time steps (coarse stages may shoot
    /// more cheaply; the last stage's are the model's).
    pub integrator: (Integrator, usize),
    /// The stage's iteration limit.
    pub max_iterations: usize,
    /// The stage's relative-decrease tolerance and window.
    pub decrease: (f64, usize),
    /// The vertex count of the stage's template (`[schedule] vertices`;
    /// `None`: the source, or a hand-made stage template).
    pub vertices: Option<usize>,
    /// Whether the stage matches the target simplified to `vertices`.
    pub coarse_target: bool,
}

impl Config {
    /// The number of stages `[schedule]` asks for (1 without one), read
    /// before the plan is checked: what a caller counts stage templates
    /// against.
    pub fn stage_count(&self) -> usize {
        match (&self.schedule, &self.stage) {
            (_, Some(tables)) => tables.len(),
            (Some(s), None) => s.kernel_geom.len(),
            (None, None) => 1,
        }
    }

    /// The stages of the coarse-to-fine schedule (`[schedule] kernel_geom`
    /// with the rest of `[attachment]`), or the single `[attachment]` stage.
    pub fn schedule(&self) -> Result<Vec<StageSpec>, MatchError> {
        let from_tables;
        let schedule = match (&self.schedule, &self.stage) {
            (Some(_), Some(_)) => {
                return Err(bad(
                    "stage",
                    "the schedule is given twice: as [schedule]'s arrays and as [[stage]] tables; keep one",
                ));
            }
            (None, Some(tables)) => {
                from_tables = self.tables_as_schedule(tables)?;
                Some(&from_tables)
            }
            (schedule, None) => schedule.as_ref(),
        };
        match schedule {
            None => {
                let geom = &self.attachment_section()?.kernel_geom;
                let integrator = (self.integrator.scheme, self.integrator.steps);
                let max_iterations = self.optimizer.max_iterations;
                Ok(vec![StageSpec {
                    label: geom.text().to_string(),
                    kernel: self.attachment_kernel()?,
                    integrator,
                    max_iterations,
                    decrease: (self.optimizer.decrease_tolerance, self.optimizer.decrease_window),
                    vertices: None,
                    coarse_target: false,
                }])
            }
            Some(s) if s.kernel_geom.is_empty() => Err(bad("schedule.kernel_geom", "needs at least one kernel")),
            Some(s) => {
                let n = s.kernel_geom.len();
                // A stage's key as the file wrote it.
                let key = |name: &str, i: usize| {
                    if self.stage.is_some() { format!("stage[{i}].{name}") } else { format!("schedule.{name}[{i}]") }
                };
                let per_stage = |key: &str, len: Option<usize>| match len {
                    Some(len) if len != n => Err(bad(
                        format!("schedule.{key}"),
                        format!("{len} values for {n} stages (one per kernel_geom)"),
                    )),
                    _ => Ok(()),
                };
                per_stage("scheme", s.scheme.as_ref().map(Vec::len))?;
                per_stage("steps", s.steps.as_ref().map(Vec::len))?;
                per_stage("max_iterations", s.max_iterations.as_ref().map(Vec::len))?;
                per_stage("decrease_tolerance", s.decrease_tolerance.as_ref().map(Vec::len))?;
                per_stage("decrease_window", s.decrease_window.as_ref().map(Vec::len))?;
                let tolerance =
                    |i: usize| s.decrease_tolerance.as_ref().map_or(self.optimizer.decrease_tolerance, |v| v[i]);
                let window = |i: usize| s.decrease_window.as_ref().map_or(self.optimizer.decrease_window, |v| v[i]);
                if let Some(i) = (0..n).find(|&i| !(tolerance(i) >= 0.0 && tolerance(i).is_finite())) {
                    return Err(bad(
                        key("decrease_tolerance", i),
                        format!("must be finite and at least 0, got {}", tolerance(i)),
                    ));
                }
                let budget = |i: usize| s.max_iterations.as_ref().map_or(self.optimizer.max_iterations, |v| v[i]);
                let scheme = |i: usize| s.scheme.as_ref().map_or(self.integrator.scheme, |v| v[i]);
                let steps = |i: usize| s.steps.as_ref().map_or(self.integrator.steps, |v| v[i]);
                if scheme(n - 1) != self.integrator.scheme || steps(n - 1) != self.integrator.steps {
                    let last = if self.stage.is_some() { format!("stage[{}]", n - 1) } else { "schedule".into() };
                    return Err(bad(
                        last,
                        "the last stage must use [integrator]'s scheme and steps (the model asked for; coarser ones are for the stages before)",
                    ));
                }
                if let Some(i) = (0..n).find(|&i| steps(i) == 0) {
                    return Err(bad(key("steps", i), "must be at least 1"));
                }
                if let Some(v) = &s.vertices {
                    if v.len() + 1 != n {
                        return Err(bad(
                            "schedule.vertices",
                            format!(
                                "{} values for {n} stages: one per stage before the last, which runs on the source",
                                v.len()
                            ),
                        ));
                    }
                    if let Some(i) = v.iter().position(|&c| c < 4) {
                        return Err(bad(
                            key("vertices", i),
                            format!("a surface needs at least 4 vertices, got {}", v[i]),
                        ));
                    }
                }
                if s.coarse_targets.is_some() && s.vertices.is_none() {
                    return Err(bad("schedule.coarse_targets", "needs schedule.vertices"));
                }
                let vertices = |i: usize| s.vertices.as_ref().and_then(|v| v.get(i).copied());
                let coarse_target = s.coarse_targets.unwrap_or(true);
                (0..n)
                    .map(|i| {
                        let g = &s.kernel_geom[i];
                        let kernel = self.attachment_with(g, &key("kernel_geom", i))?;
                        Ok(StageSpec {
                            label: g.text().to_string(),
                            kernel,
                            integrator: (scheme(i), steps(i)),
                            max_iterations: budget(i),
                            decrease: (tolerance(i), window(i)),
                            vertices: vertices(i),
                            coarse_target: coarse_target && vertices(i).is_some(),
                        })
                    })
                    .collect()
            }
        }
    }

    /// `[[stage]]` tables as `[schedule]`'s arrays: a key some stages give
    /// takes, in the others, `[integrator]`'s or `[optimizer]`'s value.
    /// What arrays cannot say wrongly but tables can is refused here,
    /// naming the stage.
    fn tables_as_schedule(&self, tables: &[StageTable]) -> Result<ScheduleSection, MatchError> {
        let n = tables.len();
        if n == 0 {
            return Err(bad("stage", "needs at least one [[stage]]"));
        }
        fn column<T: Copy>(
            tables: &[StageTable],
            get: impl Fn(&StageTable) -> Option<T>,
            default: T,
        ) -> Option<Vec<T>> {
            tables.iter().any(|t| get(t).is_some()).then(|| tables.iter().map(|t| get(t).unwrap_or(default)).collect())
        }
        if tables[n - 1].vertices.is_some() {
            return Err(bad(format!("stage[{}].vertices", n - 1), "the last stage runs on the source: no vertices"));
        }
        let with_vertices = tables.iter().filter(|t| t.vertices.is_some()).count();
        if with_vertices != 0 && with_vertices != n - 1 {
            let i = tables.iter().position(|t| t.vertices.is_none()).expect("one without");
            return Err(bad(
                format!("stage[{i}].vertices"),
                "every stage before the last gives its template's vertex count, or none does",
            ));
        }
        let mut coarse = tables.iter().enumerate().filter_map(|(i, t)| t.coarse_target.map(|c| (i, c)));
        let coarse_targets = match coarse.next() {
            None => None,
            Some((i, _)) if with_vertices == 0 => {
                return Err(bad(format!("stage[{i}].coarse_target"), "needs vertices"));
            }
            Some((_, c)) => {
                if let Some((j, _)) = coarse.find(|&(_, d)| d != c) {
                    return Err(bad(
                        format!("stage[{j}].coarse_target"),
                        "must be the same in every stage that gives it (the schedule has one setting)",
                    ));
                }
                Some(c)
            }
        };
        let (i, o) = (&self.integrator, &self.optimizer);
        Ok(ScheduleSection {
            kernel_geom: tables.iter().map(|t| t.kernel_geom.clone()).collect(),
            scheme: column(tables, |t| t.scheme, i.scheme),
            steps: column(tables, |t| t.steps, i.steps),
            max_iterations: column(tables, |t| t.max_iterations, o.max_iterations),
            decrease_tolerance: column(tables, |t| t.decrease_tolerance, o.decrease_tolerance),
            decrease_window: column(tables, |t| t.decrease_window, o.decrease_window),
            vertices: (with_vertices > 0).then(|| tables[..n - 1].iter().filter_map(|t| t.vertices).collect()),
            coarse_targets,
        })
    }

    /// The same configuration with `[schedule]`'s arrays written as
    /// `[[stage]]` tables, a stage's keys together (the form the program
    /// writes); unchanged without arrays, or with arrays whose lengths do
    /// not fit (their checks then name the array).
    pub fn with_stage_tables(mut self) -> Config {
        fn at<T: Copy>(v: &Option<Vec<T>>, i: usize) -> Option<T> {
            v.as_ref().and_then(|v| v.get(i).copied())
        }
        let Some(s) = &self.schedule else { return self };
        let n = s.kernel_geom.len();
        let fits = |len: Option<usize>, want: usize| len.is_none_or(|l| l == want);
        if !(fits(s.scheme.as_ref().map(Vec::len), n)
            && fits(s.steps.as_ref().map(Vec::len), n)
            && fits(s.max_iterations.as_ref().map(Vec::len), n)
            && fits(s.decrease_tolerance.as_ref().map(Vec::len), n)
            && fits(s.decrease_window.as_ref().map(Vec::len), n)
            && fits(s.vertices.as_ref().map(Vec::len), n.saturating_sub(1))
            && (s.vertices.is_some() || s.coarse_targets.is_none())
            && self.stage.is_none())
        {
            return self;
        }
        let tables = (0..n)
            .map(|i| {
                let vertices = at(&s.vertices, i);
                StageTable {
                    kernel_geom: s.kernel_geom[i].clone(),
                    scheme: at(&s.scheme, i),
                    steps: at(&s.steps, i),
                    max_iterations: at(&s.max_iterations, i),
                    decrease_tolerance: at(&s.decrease_tolerance, i),
                    decrease_window: at(&s.decrease_window, i),
                    vertices,
                    coarse_target: s.coarse_targets.filter(|_| vertices.is_some()),
                }
            })
            .collect();
        self.schedule = None;
        self.stage = Some(tables);
        self
    }

    /// The same configuration with `[[stage]]` tables as `[schedule]`'s
    /// arrays: the one form a checkpoint's fingerprint hashes, so that a
    /// configuration rewritten from arrays to tables (as its warning
    /// advises, or as a run writes it) resumes the checkpoints of the
    /// arrays, whose fingerprints are unchanged. Unchanged when the tables
    /// do not check (the run refuses them first).
    pub(crate) fn with_schedule_arrays(mut self) -> Config {
        let Some(tables) = &self.stage else { return self };
        if self.schedule.is_some() {
            return self;
        }
        if let Ok(arrays) = self.tables_as_schedule(tables) {
            self.schedule = Some(arrays);
            self.stage = None;
        }
        self
    }

    /// What reads but is better written otherwise, a sentence each (the
    /// program prints them as warnings, Python as DeprecationWarnings):
    /// `[schedule]`'s parallel arrays, the older form of the schedule.
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.schedule.is_some() {
            out.push(
                "[schedule]: its arrays are the older form of the schedule and still read; write one [[stage]] \
                 table per stage instead, its keys together (the configuration reference shows both; the \
                 configuration a run writes is in that form)"
                    .to_string(),
            );
        }
        out
    }
}
