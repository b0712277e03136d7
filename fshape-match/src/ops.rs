//! The operations the program, its demos and the Python package run, as
//! library functions: a typed request in, a typed result out (cargo keeps
//! its commands' work in `cargo::ops` the same way). The callers read
//! their inputs and report; the operation sets up, runs and collects.
//! Files are not written here: fshape-report's `outputs` writes a
//! registration's folder from a [`Registration`].

use std::path::PathBuf;
use std::time::Instant;

use fshape_mesh::FShape;

use crate::record::{self, MatchRecord};
use crate::{Config, MatchError, MatchResult, Observer, Outcome, Plan, Session};

/// Where a registration keeps its checkpoint, written after every accepted
/// iteration.
#[derive(Clone, Debug, Default)]
pub enum Checkpointing {
    /// Nowhere: a stopped run cannot be continued.
    #[default]
    None,
    /// To this file, starting afresh (a file already there is replaced).
    Start(PathBuf),
    /// Continuing from this file, which must exist and belong to these
    /// inputs (the program's `--resume`), then writing to it.
    Resume(PathBuf),
    /// Continuing from this file when it exists, else starting (the Python
    /// package's policy: the same call continues a stopped run).
    Continue(PathBuf),
}

/// What a registration needs.
#[derive(Clone, Copy, Debug)]
pub struct MatchRequest<'a> {
    /// The template (its signal, if any, is f₀; else 0).
    pub source: &'a FShape,
    /// The shape to reach.
    pub target: &'a FShape,
    /// The configuration as the user gave it.
    pub config: &'a Config,
    /// When an observer stops the run before its end: shoot the momenta
    /// reached so far and return them ([`Session::result_so_far`]), or
    /// return no result (the checkpoint holds the run).
    pub result_when_stopped: bool,
}

/// A registration as it ended.
#[derive(Clone, Debug)]
pub struct Registration {
    /// Finished, or stopped by an observer.
    pub outcome: Outcome,
    /// The result: always once finished; when stopped, the result so far
    /// if the request asked for it and an iteration was made.
    pub result: Option<MatchResult>,
    /// The template of the last stage: the source, pre-aligned with
    /// `[prealign]`.
    pub template: FShape,
    /// The target as matched (moved with `[prealign] move = "target"`).
    pub target: FShape,
    /// The configuration as given.
    pub config: Config,
    /// The configuration with the weights the model used (`normalize =
    /// false`): the momenta shoot with it.
    pub resolved: Config,
    /// The checked plan: the model with its effective weights, the scales,
    /// the stages and the metrics.
    pub plan: Plan,
    /// When the stages ended: the result's `seconds` count the run until
    /// then; what follows (the result's shooting, the files) counts from
    /// here.
    pub stages_ended: Instant,
}

/// Registers `request.source` onto `request.target`: sets the session up
/// (pre-alignment, the stages' simplified shapes: reported to `observer`),
/// runs its stages on `stage_templates` (coarser sources of the stages
/// before the last, `None` where a stage runs on the source) with the
/// checkpoint `checkpointing` asks for, and collects the result.
pub fn register(
    request: &MatchRequest<'_>,
    stage_templates: Option<Vec<Option<FShape>>>,
    checkpointing: &Checkpointing,
    observer: &mut impl Observer,
) -> Result<Registration, MatchError> {
    let session = Session::new_observed(request.source, request.target, request.config, observer)?;
    let session = match stage_templates {
        Some(templates) => session.with_stage_templates(templates)?,
        None => session,
    };
    // The checkpoint's folder is made once the setup has succeeded.
    if let Checkpointing::Start(path) | Checkpointing::Resume(path) | Checkpointing::Continue(path) = checkpointing
        && let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
    {
        std::fs::create_dir_all(dir)
            .map_err(|e| MatchError::File { path: dir.to_path_buf(), message: format!("creating the folder: {e}") })?;
    }
    let mut session = match checkpointing {
        Checkpointing::None => session,
        Checkpointing::Start(path) => session.with_checkpoint_file(path),
        Checkpointing::Resume(path) => session.resume_from_file(path)?.with_checkpoint_file(path),
        Checkpointing::Continue(path) => session.continuing_from(path)?,
    };
    observer.planned(session.plan());
    let outcome = session.run(observer)?;
    let stages_ended = Instant::now();
    let result = match outcome {
        Outcome::Finished => Some(session.result()?),
        Outcome::Interrupted if request.result_when_stopped => session.result_so_far()?,
        Outcome::Interrupted => None,
    };
    let plan = session.plan().clone();
    Ok(Registration {
        outcome,
        result,
        template: session.problem().template().clone(),
        target: session.target().clone(),
        config: request.config.clone(),
        resolved: request.config.resolved(plan.scales.as_ref()),
        plan,
        stages_ended,
    })
}

/// What a run record says the inputs were called (paths as the user gave
/// them, or names a library caller chooses).
#[derive(Clone, Copy, Debug)]
pub struct Labels<'a> {
    /// The source.
    pub source: &'a str,
    /// The target.
    pub target: &'a str,
    /// The configuration.
    pub config: &'a str,
}

impl Registration {
    /// The run record of a registration with a result (`None` without one):
    /// `seconds` of wall time in all, `files` the folder's files.
    pub fn record(&self, labels: &Labels<'_>, seconds: f64, files: Vec<String>) -> Option<MatchRecord> {
        let result = self.result.as_ref()?;
        let (model, e) = (&self.plan.model, &result.energies);
        Some(MatchRecord {
            kind: record::Kind::Match,
            format: record::FORMAT,
            source: labels.source.to_string(),
            target: labels.target.to_string(),
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
            stages: result.stages.clone(),
            final_value: e.value,
            final_energy: e.energy,
            final_attachment: e.attachment,
            geodesic_distance: e.energy.max(0.0).sqrt(),
            hamiltonian: result.trajectory.hamiltonian.clone(),
            quality: Some(result.quality.clone()),
            quality_before: Some(result.initial_quality.clone()),
            prealign: result.alignment.clone(),
            iterations: result.iterations,
            evaluations: result.evaluations,
            seconds,
            files,
        })
    }
}

impl MatchError {
    /// Whether the error is the data term's "the target has no signal":
    /// the caller knows the target by a name the library does not.
    pub fn is_missing_target_signal(&self) -> bool {
        matches!(
            self,
            MatchError::Shoot(fshape_shoot::ShootError::Varifold(fshape_varifold::VarifoldError::MissingSignal {
                which: "target"
            }))
        )
    }
}
