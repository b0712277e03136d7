//! The operations the program, its demos and the Python package run, as
//! library functions: a typed request in, a typed result out (cargo keeps
//! its commands' work in `cargo::ops` the same way). The callers read
//! their inputs and report; the operation sets up, runs and collects.
//! Files are not written here: fshape-report's `outputs` writes a
//! registration's folder from a [`Registration`]. A [`batch`] is the one
//! exception: its rows' folders are its state, so it makes them and writes
//! a failed row's error file.

use std::path::PathBuf;
use std::time::Instant;

use fshape_mesh::FShape;

pub use fshape_fem::Norm;
pub use fshape_shoot::{Model, ModelKind, Trajectory};
pub use fshape_varifold::{Distance, VarifoldKernel};
pub use stats::{Scores, StatsLabels, StatsRequest, StatsRun, StatsSubject, group_stats};
pub use transfer::{TransferRequest, TransferRun, TransferValues, transfer};

pub mod batch;
pub mod regress;
mod stats;
mod transfer;

use fshape_shoot::ShootError;

use crate::atlas::{Atlas, AtlasResult, Cluster, Modes};
use crate::record::{self, MatchRecord};
use crate::{Config, MatchError, MatchResult, Observer, Outcome, Plan, Runner, Session, Staged};

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
    /// Continuing from this file, which must exist, never writing it: the
    /// processes of an MPI run other than process 0, which writes.
    ReadOnly(PathBuf),
}

impl Checkpointing {
    /// The checkpoint's folder, made once the setup has succeeded (none
    /// for a checkpoint only read).
    fn make_folder(&self) -> Result<(), MatchError> {
        if let Checkpointing::Start(path) | Checkpointing::Resume(path) | Checkpointing::Continue(path) = self
            && let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
        {
            std::fs::create_dir_all(dir).map_err(|e| MatchError::File {
                path: dir.to_path_buf(),
                message: format!("creating the folder: {e}"),
            })?;
        }
        Ok(())
    }

    /// `runner` with this checkpointing.
    fn apply<S: Staged>(&self, runner: Runner<S>) -> Result<Runner<S>, MatchError> {
        self.make_folder()?;
        Ok(match self {
            Checkpointing::None => runner,
            Checkpointing::Start(path) => runner.with_checkpoint_file(path),
            Checkpointing::Resume(path) => runner.resume_from_file(path)?.with_checkpoint_file(path),
            Checkpointing::Continue(path) => runner.continuing_from(path)?,
            Checkpointing::ReadOnly(path) => runner.resume_from_file(path)?,
        })
    }
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
    let mut session = prepared(session, stage_templates, checkpointing)?;
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

/// A set-up run with its stage templates (the templates enter the
/// checkpoint's fingerprint, so they come first) and its checkpointing.
fn prepared<S: Staged>(
    runner: Runner<S>,
    stage_templates: Option<Vec<Option<FShape>>>,
    checkpointing: &Checkpointing,
) -> Result<Runner<S>, MatchError> {
    let runner = match stage_templates {
        Some(templates) => runner.with_stage_templates(templates)?,
        None => runner,
    };
    checkpointing.apply(runner)
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
            MatchError::Shoot(ShootError::Varifold(fshape_varifold::VarifoldError::MissingSignal { which: "target" }))
        )
    }
}

/// What an atlas estimation needs.
#[derive(Clone, Copy, Debug)]
pub struct AtlasRequest<'a> {
    /// The initial template ([`crate::atlas::initial_template`] makes one
    /// from a subject or the subjects' mean signal).
    pub template: &'a FShape,
    /// The population.
    pub subjects: &'a [FShape],
    /// The configuration as the user gave it.
    pub config: &'a Config,
    /// The principal modes of the momenta to compute (at most).
    pub modes: usize,
    /// Whether to collect the result once the run ends: `false` for the
    /// processes of an MPI run other than process 0, which only take their
    /// share of every evaluation.
    pub collect: bool,
}

/// An atlas estimation as it ended.
#[derive(Clone, Debug)]
pub struct AtlasRun {
    /// Finished, or stopped by an observer.
    pub outcome: Outcome,
    /// The result, once finished and collected.
    pub result: Option<AtlasResult>,
    /// The initial template as the atlas set it up.
    pub start: FShape,
    /// With a result: each subject as the atlas saw it (pre-aligned with
    /// `[prealign]`), and the estimated template shot onto it.
    pub subjects: Vec<(FShape, FShape)>,
    /// With a result: the principal modes of the initial momenta, and
    /// the template shot to −2, 0 and +2 standard deviations along each.
    pub modes: Option<(Modes, Vec<[FShape; 3]>)>,
    /// The configuration as given.
    pub config: Config,
    /// The checked plan.
    pub plan: Plan,
    /// When the stages ended (as [`Registration::stages_ended`]).
    pub stages_ended: Instant,
}

/// What an atlas's run record says its inputs were called.
#[derive(Clone, Copy, Debug)]
pub struct AtlasLabels<'a> {
    /// The initial template.
    pub template: &'a str,
    /// The configuration.
    pub config: &'a str,
    /// Each subject (its file).
    pub subjects: &'a [String],
}

/// The folder of subject `i` (from 0) in an atlas's outputs.
pub fn subject_directory(i: usize) -> String {
    format!("subject_{i:03}")
}

impl AtlasRun {
    /// The run record of an atlas with a result (`None` without one):
    /// per subject its energies, data term before and after, quality and
    /// pre-alignment; the means over subjects; the modes' standard
    /// deviations and shares; `seconds` of wall time in all, `files` the
    /// folder's files.
    pub fn record(&self, labels: &AtlasLabels<'_>, seconds: f64, files: Vec<String>) -> Option<record::AtlasRecord> {
        let result = self.result.as_ref()?;
        let model = &self.plan.model;
        let subjects = result
            .subjects
            .iter()
            .zip(labels.subjects)
            .enumerate()
            .map(|(i, (s, file))| record::SubjectRecord {
                file: file.clone(),
                value: s.energies.value,
                energy: s.energies.energy,
                attachment: s.energies.attachment,
                attachment_start: s.initial_attachment,
                attachment_fall: (s.initial_attachment > 0.0)
                    .then(|| 1.0 - s.energies.attachment / s.initial_attachment),
                quality: s.quality.clone(),
                template_quality: s.template_quality.clone(),
                prealign: s.alignment.clone(),
                directory: subject_directory(i),
            })
            .collect();
        let n = result.subjects.len() as f64;
        let rms: Vec<f64> = result.subjects.iter().filter_map(|s| s.quality.signal_rms).collect();
        let modes = self.modes.as_ref().map_or(&[][..], |(pca, _)| &pca.modes[..]);
        let e = result.energies;
        Some(record::AtlasRecord {
            kind: record::Kind::Atlas,
            format: record::FORMAT,
            template_start: labels.template.to_string(),
            config: labels.config.to_string(),
            model: model.kind().name().into(),
            norm: model.norm().name().into(),
            gamma_v: self.config.model.gamma_v,
            gamma_f: self.config.model.gamma_f,
            gamma_w: self.config.model.gamma_w,
            scales: self.plan.scales.clone(),
            effective_weights: [model.gamma_v(), model.gamma_f(), model.gamma_w()],
            stages: result.stages.clone(),
            final_value: e.value,
            final_energy: e.energy,
            final_attachment: e.attachment,
            subjects,
            mean_distance: result.subjects.iter().map(|s| s.quality.mean_distance).sum::<f64>() / n,
            mean_signal_rms: (rms.len() == result.subjects.len()).then(|| rms.iter().sum::<f64>() / n),
            mean_signal_rms_per_channel: per_channel_mean_rms(&result.subjects),
            min_attachment_fall: result
                .subjects
                .iter()
                .filter(|s| s.initial_attachment > 0.0)
                .map(|s| 1.0 - s.energies.attachment / s.initial_attachment)
                .reduce(f64::min),
            modes: modes.iter().map(|m| record::ModeRecord { sd: m.sd, share: m.share }).collect(),
            iterations: result.iterations,
            evaluations: result.evaluations,
            seconds,
            files,
        })
    }
}

/// Estimates the atlas of `request.subjects` from `request.template`:
/// sets it up (the subjects' pre-alignments, reported to `observer`), runs
/// its stages on `stage_templates` (coarser initial templates of the
/// stages before the last) over `cluster`'s processes (none: this one)
/// with the checkpoint `checkpointing` asks for, then collects the
/// result: the subjects as seen and matched, the principal modes and
/// their shapes.
pub fn estimate_atlas(
    request: &AtlasRequest<'_>,
    stage_templates: Option<Vec<Option<FShape>>>,
    checkpointing: &Checkpointing,
    cluster: Option<Box<dyn Cluster>>,
    observer: &mut impl Observer,
) -> Result<AtlasRun, MatchError> {
    let atlas = Atlas::new_observed(request.template, request.subjects, request.config, observer)?;
    let atlas = prepared(atlas, stage_templates, checkpointing)?;
    let mut atlas = match cluster {
        Some(c) => atlas.with_cluster(c),
        None => atlas,
    };
    observer.planned(atlas.plan());
    let outcome = atlas.run(observer)?;
    let stages_ended = Instant::now();
    let mut run = AtlasRun {
        outcome,
        result: None,
        start: atlas.initial_template().clone(),
        subjects: Vec::new(),
        modes: None,
        config: request.config.clone(),
        plan: atlas.plan().clone(),
        stages_ended,
    };
    if outcome == Outcome::Interrupted || !request.collect {
        return Ok(run);
    }
    let result = atlas.result()?;
    for (i, (subject, r)) in request.subjects.iter().zip(&result.subjects).enumerate() {
        let seen = r.alignment.as_ref().map_or_else(|| Ok(subject.clone()), |a| a.apply(subject))?;
        run.subjects.push((seen, result.matched(i)?));
    }
    if request.modes > 0 {
        let pca = atlas.principal_modes(&result, request.modes)?;
        let mut shapes = Vec::with_capacity(pca.modes.len());
        for mode in &pca.modes {
            let mut at = |c: f64| {
                let p0: Vec<f64> = pca.mean_p0.iter().zip(&mode.p0).map(|(m, e)| m + c * mode.sd * e).collect();
                let pf: Vec<f64> = pca.mean_pf.iter().zip(&mode.pf).map(|(m, e)| m + c * mode.sd * e).collect();
                atlas.shoot_template(&result, &p0, &pf)
            };
            shapes.push([at(-2.0)?, at(0.0)?, at(2.0)?]);
        }
        run.modes = Some((pca, shapes));
    }
    run.result = Some(result);
    Ok(run)
}

/// A geodesic shot from a template.
#[derive(Clone, Debug)]
pub struct Shot {
    /// The template as the model holds it (its signal f₀, 0 without one).
    pub template: FShape,
    /// The geodesic.
    pub trajectory: Trajectory,
    /// The model it was shot with.
    pub model: Model,
}

impl Shot {
    /// The run record of `fshape shoot`: what the template (`source`) and
    /// the configuration are called, the model, the Hamiltonian along the
    /// geodesic and its drift, how far the end state moved, `seconds` of
    /// wall time in all, the states written at `times` as `files`.
    pub fn record(
        &self,
        (source, config): (&str, &str),
        times: &[f64],
        files: Vec<String>,
        seconds: f64,
    ) -> record::ShootRecord {
        let (traj, dim, steps) = (&self.trajectory, self.template.dim(), self.model.steps());
        let (x0, x1) = (self.template.points(), traj.points(steps));
        let disp: Vec<f64> = x0
            .chunks_exact(dim)
            .zip(x1.chunks_exact(dim))
            .map(|(p, q)| p.iter().zip(q).map(|(u, v)| (u - v).powi(2)).sum::<f64>().sqrt())
            .collect();
        let norm_rows =
            |v: &[f64]| v.chunks_exact(dim).map(|r| r.iter().map(|u| u * u).sum::<f64>().sqrt()).fold(0.0, f64::max);
        record::ShootRecord {
            kind: record::Kind::Shoot,
            format: record::FORMAT,
            source: source.to_string(),
            config: config.to_string(),
            model: self.model.kind().name().to_string(),
            norm: self.model.norm().name().into(),
            integrator: self.model.integrator().name().to_string(),
            steps,
            hamiltonian_drift: traj.drift().0,
            hamiltonian: traj.hamiltonian.clone(),
            times: times.to_vec(),
            files,
            final_state: record::FinalState {
                max_displacement: disp.iter().copied().fold(0.0, f64::max),
                rms_displacement: (disp.iter().map(|d| d * d).sum::<f64>() / disp.len().max(1) as f64).sqrt(),
                max_signal_change: traj
                    .signal(steps)
                    .iter()
                    .zip(self.template.signal().unwrap_or(&[]))
                    .map(|(u, v)| (u - v).abs())
                    .fold(0.0, f64::max),
                max_momentum: norm_rows(traj.momenta(steps)),
            },
            seconds: record::ShootTiming { total: seconds, kernels: traj.timings.kernels, fem: traj.timings.fem },
        }
    }
}

/// With several maps, each map's signal error averaged over the subjects
/// (`None` for a map unless every subject has its error); empty with one.
fn per_channel_mean_rms(subjects: &[crate::atlas::SubjectResult]) -> Vec<Option<f64>> {
    let k = subjects.first().map_or(0, |s| s.quality.channels.len());
    (0..k)
        .map(|c| {
            let rms: Vec<f64> = subjects.iter().filter_map(|s| s.quality.channels.get(c)?.signal_rms).collect();
            (rms.len() == subjects.len()).then(|| rms.iter().sum::<f64>() / subjects.len() as f64)
        })
        .collect()
}

/// Shoots `template` with the initial momenta `p0` (n × d) and `pf` (the
/// signal momentum, n × channels; ζ for the tangential model) under
/// `model` (`Config::model`: the weights as written).
pub fn shoot(template: &FShape, model: &Model, p0: &[f64], pf: &[f64]) -> Result<Shot, MatchError> {
    let problem = fshape_shoot::Problem::new(template, model.clone())?;
    let trajectory = problem.shoot(p0, pf)?;
    Ok(Shot { template: problem.template().clone(), trajectory, model: model.clone() })
}

/// The varifold kernel of a data attachment from its parts as the
/// configuration and the program write them: a position kernel
/// (`gaussian:σ`, a sum `gaussian:σ1,σ2,…`, `cauchy:σ`), an optional
/// signal kernel (`gaussian:σ_f`) and a direction kernel (`linear`,
/// `binet`, `gaussian-oriented:σ_t`, `gaussian-unoriented:σ_t`),
/// truncated at `tolerance` if given (each inner product then moves by at
/// most τ·k(0)·mass(X)·mass(Y)).
pub fn attachment_kernel(
    geom: &str,
    signal: Option<&str>,
    grass: &str,
    tolerance: Option<f64>,
) -> Result<VarifoldKernel, MatchError> {
    let parse = || -> Result<VarifoldKernel, fshape_varifold::VarifoldError> {
        let kernel = VarifoldKernel::parse(geom, signal, grass)?;
        match tolerance {
            Some(tol) => kernel.truncated(tol),
            None => Ok(kernel),
        }
    };
    Ok(parse().map_err(ShootError::from)?)
}

/// The data attachment A(X, Y) = ‖X − Y‖² between `source` and `target`
/// with `kernel`, and its three inner products.
pub fn attachment(source: &FShape, target: &FShape, kernel: &VarifoldKernel) -> Result<Distance, MatchError> {
    let eval = || fshape_varifold::Attachment::new(target, kernel.clone())?.eval(source);
    Ok(eval().map_err(ShootError::from)?)
}

/// A signal norm's matrix D_s on a mesh: its lower triangle in compressed
/// columns.
#[derive(Clone, Debug)]
pub struct NormMatrix {
    /// Its order: the mesh's vertices.
    pub n: usize,
    /// Where each column starts in `row_index` and `values` (n + 1).
    pub column_start: Vec<usize>,
    /// The row of each stored entry.
    pub row_index: Vec<usize>,
    /// The stored entries (row ≥ column).
    pub values: Vec<f64>,
    /// Its trace.
    pub trace: f64,
}

/// Assembles the matrix of the signal norm `norm` on `shape`.
pub fn signal_norm_matrix(shape: &FShape, norm: Norm) -> Result<NormMatrix, MatchError> {
    let d = fshape_fem::SignalNorm::try_new(shape, norm).map_err(ShootError::from)?;
    let values = d.assemble(shape.points()).map_err(ShootError::from)?;
    let (column_start, row_index) = d.pattern();
    let n = d.n_vertices();
    let trace = (0..n)
        .flat_map(|c| (column_start[c]..column_start[c + 1]).filter(move |&e| row_index[e] == c))
        .map(|e| values[e])
        .sum();
    Ok(NormMatrix { n, column_start: column_start.to_vec(), row_index: row_index.to_vec(), values, trace })
}

/// Checks the environment the kernel sums read (`FSHAPE_SIMD`, which caps
/// their instruction set): an error naming the variable when its value is
/// not one the library knows, so that a program can refuse it before any
/// work rather than have it ignored.
pub fn check_environment() -> Result<(), String> {
    fshape_kernels::simd::Cap::from_env().map(|_| ())
}
