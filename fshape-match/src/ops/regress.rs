//! Geodesic regression (`fshape regress`): the visits table read into
//! subjects, one subject's regression set up, run and collected, its
//! rates of change and its run record. The caller reads each visit's
//! files (the table gives their paths) and writes the outputs
//! (fshape-report's `outputs::write_regression`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use fshape_mesh::FShape;
use fshape_mesh::io::table::{self, Record};

use super::{Checkpointing, prepared};
use crate::record::{self, RegressionRecord, VisitRecord};
use crate::regression::{Regress, RegressionResult, Visit};
use crate::{Config, MatchError, Observer, Outcome, Plan};

/// The columns a visits table may name.
pub const COLUMNS: [&str; 6] = ["subject", "age", "mesh", "signal", "mask", "weight"];

/// One row of a visits table, its paths relative to the table's folder
/// made whole.
#[derive(Clone, Debug, PartialEq)]
pub struct VisitRow {
    /// Its line in the table, from 1.
    pub line: usize,
    /// The visit's age (any unit, the same for every row).
    pub age: f64,
    /// The mesh.
    pub mesh: PathBuf,
    /// One file per signal channel (none: the mesh's own signal).
    pub signal: Vec<PathBuf>,
    /// The mask file, if any.
    pub mask: Option<PathBuf>,
    /// Its weight (1 unless given).
    pub weight: f64,
}

/// One subject's visits, in the table's order.
#[derive(Clone, Debug, PartialEq)]
pub struct SubjectVisits {
    /// Its name (the `subject` column; `subject` without one), a plain
    /// folder name.
    pub subject: String,
    /// Its visits.
    pub visits: Vec<VisitRow>,
}

/// Reads a visits table: `#` comments and blank lines skipped, a header
/// naming its columns ([`COLUMNS`]: `age` and `mesh` required, the others
/// optional, in any order), then one visit per line, paths relative to the
/// table, several maps as files separated by `;`. Rows with the same
/// `subject` are one subject's visits, subjects in the order they first
/// appear. A malformed header or row is an error naming its line.
pub fn read_visits(path: &Path) -> Result<Vec<SubjectVisits>, MatchError> {
    let records = table::read_table(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let at = |line: Option<usize>, message: String| MatchError::Table { path: path.to_path_buf(), line, message };
    let mut lines = records.into_iter();
    let Some(Record { line: header_line, fields: columns }) = lines.next() else {
        return Err(at(None, "no header (expected a line naming the columns, such as `subject,age,mesh`)".into()));
    };
    for (k, c) in columns.iter().enumerate() {
        if !COLUMNS.contains(&c.as_str()) {
            return Err(at(
                Some(header_line),
                format!("unknown column `{c}` (the columns are {})", COLUMNS.join(", ")),
            ));
        }
        if columns[..k].contains(c) {
            return Err(at(Some(header_line), format!("column `{c}` twice")));
        }
    }
    let col = |name: &str| columns.iter().position(|c| *c == name);
    let (Some(age), Some(mesh)) = (col("age"), col("mesh")) else {
        return Err(at(Some(header_line), "the header must name an `age` and a `mesh` column".into()));
    };
    let mut subjects: Vec<SubjectVisits> = Vec::new();
    for Record { line, fields } in lines {
        if fields.len() != columns.len() {
            return Err(at(
                Some(line),
                format!("expected {} fields ({}), found {}", columns.len(), columns.join(","), fields.len()),
            ));
        }
        let field = |k: Option<usize>| k.map(|k| fields[k].trim()).filter(|f| !f.is_empty());
        let number = |k: usize, what: &str| -> Result<f64, MatchError> {
            let text = field(Some(k)).ok_or_else(|| at(Some(line), format!("no {what}")))?;
            text.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| at(Some(line), format!("{what} `{text}` is not a finite number")))
        };
        let weight = match col("weight") {
            Some(k) if field(Some(k)).is_some() => number(k, "weight")?,
            _ => 1.0,
        };
        if weight < 0.0 {
            return Err(at(Some(line), format!("weight {weight} is negative")));
        }
        let subject = field(col("subject")).unwrap_or("subject").to_string();
        if subject.starts_with('.') || subject.contains(['/', '\\']) {
            return Err(at(Some(line), format!("subject `{subject}` is not a plain folder name")));
        }
        let row = VisitRow {
            line,
            age: number(age, "age")?,
            mesh: base.join(field(Some(mesh)).ok_or_else(|| at(Some(line), "no mesh".into()))?),
            signal: field(col("signal"))
                .into_iter()
                .flat_map(|f| f.split(';'))
                .map(str::trim)
                .filter(|f| !f.is_empty())
                .map(|f| base.join(f))
                .collect(),
            mask: field(col("mask")).map(|f| base.join(f)),
            weight,
        };
        match subjects.iter_mut().find(|s| s.subject == subject) {
            Some(s) => s.visits.push(row),
            None => subjects.push(SubjectVisits { subject, visits: vec![row] }),
        }
    }
    if subjects.is_empty() {
        return Err(at(None, "no visits after the header".into()));
    }
    Ok(subjects)
}

/// A regression as it ended.
#[derive(Clone, Debug)]
pub struct RegressionRun {
    /// Finished, or stopped by an observer.
    pub outcome: Outcome,
    /// The result, once finished.
    pub result: Option<RegressionResult>,
    /// The baseline (the earliest visit's mesh).
    pub baseline: FShape,
    /// The visits as fitted (moved onto the baseline with `[prealign]`).
    pub visits: Vec<Visit>,
    /// The configuration as given.
    pub config: Config,
    /// The configuration with the weights the model used.
    pub resolved: Config,
    /// The checked plan.
    pub plan: Plan,
    /// When the stages ended.
    pub stages_ended: Instant,
}

/// Regresses one subject's `visits` with `config`: sets the regression up
/// (the stages' simplified baselines reported to `observer`), runs its
/// stages with the checkpoint `checkpointing` asks for, and collects the
/// result once finished.
pub fn regress(
    visits: Vec<Visit>,
    config: &Config,
    checkpointing: &Checkpointing,
    observer: &mut impl Observer,
) -> Result<RegressionRun, MatchError> {
    let runner = Regress::new_observed(visits, config, observer)?;
    let mut runner = prepared(runner, None, checkpointing)?;
    observer.planned(runner.plan());
    let outcome = runner.run(observer)?;
    let stages_ended = Instant::now();
    let result = match outcome {
        Outcome::Finished => Some(runner.result()?),
        Outcome::Interrupted => None,
    };
    let plan = runner.plan().clone();
    Ok(RegressionRun {
        outcome,
        result,
        baseline: runner.baseline().clone(),
        visits: runner.visits().to_vec(),
        config: config.clone(),
        resolved: config.resolved(plan.scales.as_ref()),
        plan,
        stages_ended,
    })
}

/// What a regression's run record says its inputs were called.
#[derive(Clone, Copy, Debug)]
pub struct RegressionLabels<'a> {
    /// The subject.
    pub subject: &'a str,
    /// The visits table.
    pub table: &'a str,
    /// Each visit's mesh file, in the visits' order.
    pub visits: &'a [String],
    /// The configuration.
    pub config: &'a str,
}

impl RegressionRun {
    /// The rates of change per unit age at the baseline's vertices: the
    /// initial velocity's component along the vertex normal (surfaces in
    /// space and plane curves; empty for the others) and each signal channel's rate (P × k),
    /// each the geodesic's velocity at t = 0 divided by the span.
    pub fn rates(&self) -> Option<(Vec<f64>, Vec<f64>)> {
        let result = self.result.as_ref()?;
        let (v, f) = result.trajectory.velocity(0);
        let dim = self.baseline.dim();
        let normal = match fshape_stats::maps::vertex_normals(&self.baseline) {
            Some(n) => n
                .iter()
                .zip(v.chunks_exact(dim))
                .map(|(n, v)| v.iter().zip(n).map(|(v, n)| v * n).sum::<f64>() / result.span)
                .collect(),
            None => Vec::new(),
        };
        Some((normal, f.iter().map(|r| r / result.span).collect()))
    }

    /// The run record once finished (`None` without a result): `seconds`
    /// of wall time in all, `files` the folder's files.
    pub fn record(&self, labels: &RegressionLabels<'_>, seconds: f64, files: Vec<String>) -> Option<RegressionRecord> {
        let result = self.result.as_ref()?;
        let (model, e) = (&self.plan.model, &result.energies);
        let visits = self
            .visits
            .iter()
            .enumerate()
            .map(|(i, v)| VisitRecord {
                file: labels.visits.get(i).cloned().unwrap_or_default(),
                age: v.age,
                time: result.times[i],
                weight: v.weight,
                attachment: e.attachments[i],
                quality: result.quality[i].clone(),
                quality_before: result.initial_quality[i].clone(),
                prealign: result.alignments[i].clone(),
            })
            .collect();
        Some(RegressionRecord {
            kind: record::Kind::Regression,
            format: record::FORMAT,
            subject: labels.subject.to_string(),
            visits_table: labels.table.to_string(),
            config: labels.config.to_string(),
            model: model.kind().name().into(),
            norm: model.norm().name().into(),
            gamma_v: self.config.model.gamma_v,
            gamma_f: self.config.model.gamma_f,
            gamma_w: self.config.model.gamma_w,
            scales: self.plan.scales.clone(),
            effective_weights: [model.gamma_v(), model.gamma_f(), model.gamma_w()],
            steps: model.steps(),
            metrics: self.plan.metrics,
            t0: result.t0,
            span: result.span,
            t1: result.t1,
            visits,
            stages: result.stages.clone(),
            final_value: e.value,
            final_energy: e.energy,
            final_attachment: e.data,
            geodesic_distance: e.energy.max(0.0).sqrt(),
            hamiltonian: result.trajectory.hamiltonian.clone(),
            iterations: result.iterations,
            evaluations: result.evaluations,
            seconds,
            files,
        })
    }
}
