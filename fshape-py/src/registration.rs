//! Registration, atlas estimation and regression: `match`, `atlas` and
//! `regress`.

use std::path::PathBuf;

use fshape_match::MatchError;
use fshape_match::ops::{self, AtlasRequest, Checkpointing, Labels, MatchRequest};
use fshape_mesh::FShape;
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::config::config_of;
use crate::conversions::{rows, to_py};
use crate::err;
use crate::progress::Progress;
use crate::results::{AtlasResult, MatchResult, RegressionResult, SubjectResult};
use crate::shape::PyFShape;
use crate::shape::shape_of;
use crate::shoot::{geodesic, node_times};

pub(crate) fn stage_templates(list: Option<Vec<Bound<'_, PyAny>>>) -> PyResult<Option<Vec<Option<FShape>>>> {
    let Some(list) = list else { return Ok(None) };
    let mut t = list.iter().map(|s| shape_of(s).map(Some)).collect::<PyResult<Vec<_>>>()?;
    t.push(None);
    Ok(Some(t))
}

/// Registers `source` onto `target` (both `FShape`) as `fshape match`
/// does, with `config` a `Config`, a dict of the TOML tables or a TOML path. `progress`, if
/// given, is called with a dict per event (`event`: "stage", "iteration",
/// "stage_finished"); returning True ends the run with its result so far
/// (`stopped` True: the current momenta carried to the source and shot),
/// raising ends it and re-raises.
/// `stage_templates` are coarser templates for the stages before the last.
/// `checkpoint`, a path, is written after every accepted iteration; when
/// the file exists the run resumes from it (to the bits of a run never
/// stopped), so the same call continues a run stopped by the callback,
/// Ctrl-C or a kill; on a finished run it returns the result without
/// iterating. A checkpoint of other inputs or configuration is refused.
///
/// Returns a `MatchResult`: `stopped` (whether the callback ended the run before
/// its end), `p0` (n × d), `pf` (n), `energies`, `quality` and
/// `initial_quality` (how close the matched shape and the template are to
/// the target), `alignment` (with `[prealign]`: the map T as a homogeneous
/// `matrix`, its `scale`, `rotation_degrees`, `translation`, the
/// attachment before and after; else None), `stages` (every iteration's J), `iterations`,
/// `evaluations`, `seconds`, `geodesic` (`times`, `points` T × n × d,
/// `signals` T × n, `hamiltonian`), `matched` (the FShape at t = 1),
/// `target` (the target as matched: moved when `[prealign]` moves the
/// target; `Correspondence` carries values between it and `matched`), and
/// `config` (the configuration with the weights used, for `shoot`).
#[pyfunction(name = "match")]
#[pyo3(signature = (source, target, config, progress = None, stage_templates = None, times = None, checkpoint = None))]
#[expect(clippy::too_many_arguments, reason = "one per keyword argument of the Python call")]
pub(crate) fn match_shapes<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    target: &Bound<'py, PyAny>,
    config: &Bound<'py, PyAny>,
    progress: Option<Py<PyAny>>,
    stage_templates: Option<Vec<Bound<'py, PyAny>>>,
    times: Option<Vec<f64>>,
    checkpoint: Option<PathBuf>,
) -> PyResult<Bound<'py, MatchResult>> {
    let (x, y) = (shape_of(source)?, shape_of(target)?);
    let config = config_of(config)?;
    let templates = self::stage_templates(stage_templates)?;
    let times = times.unwrap_or_else(|| vec![0.0, 0.25, 0.5, 0.75, 1.0]);
    if let Some(t) = times.iter().find(|t| !(0.0..=1.0).contains(*t)) {
        return Err(err(format!("times: {t} is outside [0, 1]")));
    }
    let mut observer = Progress::new(progress);
    let checkpointing = checkpoint.map_or(Checkpointing::None, Checkpointing::Continue);
    // A callback that returned True ends the run with its result so far;
    // one that raised (or Ctrl-C) re-raises, whatever the run returned.
    let request = MatchRequest { source: &x, target: &y, config: &config, result_when_stopped: true };
    let run = py.detach(|| ops::register(&request, templates, &checkpointing, &mut observer));
    observer.raised()?;
    let reg = run.map_err(err)?;
    let labels = Labels { source: "source", target: "target", config: "" };
    let Some(record) = reg.record(&labels, reg.result.as_ref().map_or(0.0, |r| r.seconds), Vec::new()) else {
        return Err(crate::errors::other(
            "stopped by the progress callback before the first iteration: there is no result yet",
        ));
    };
    let Some(r) = reg.result else {
        return Err(crate::errors::other(
            "stopped by the progress callback before the first iteration: there is no result yet",
        ));
    };
    let (template, matched_target, used) = (reg.template, reg.target, reg.resolved);
    let dim = template.dim();
    let channels = template.n_channels().max(1);
    let (x1, f1) = r.trajectory.at(1.0);
    let matched = template.with_points(x1).and_then(|s| s.with_signals(Some(f1), channels)).map_err(err)?;
    let any = |v: Bound<'py, PyAny>| v.unbind();
    Bound::new(
        py,
        MatchResult {
            stopped: any((!r.finished).into_pyobject(py)?.to_owned().into_any()),
            p0: any(rows(py, r.p0.clone(), dim).into_any()),
            pf: any(signal_momentum(py, &r.pf, channels)?),
            energies: any(to_py(py, &r.energies)?),
            quality: any(to_py(py, &r.quality)?),
            initial_quality: any(to_py(py, &r.initial_quality)?),
            alignment: any(to_py(py, &r.alignment)?),
            stages: any(to_py(py, &r.stages)?),
            iterations: any(r.iterations.into_pyobject(py)?.into_any()),
            evaluations: any(r.evaluations.into_pyobject(py)?.into_any()),
            seconds: any(r.seconds.into_pyobject(py)?.into_any()),
            geodesic: any(geodesic(py, &r.trajectory, dim, &times)?.into_any()),
            matched: any(Bound::new(py, PyFShape { inner: matched })?.into_any()),
            target: any(Bound::new(py, PyFShape { inner: matched_target })?.into_any()),
            config: any(to_py(py, &used)?),
            record,
            config_text: used.to_toml(),
        },
    )
}

/// A signal momentum as Python sees it: n values, or n × k with several
/// maps.
fn signal_momentum<'py>(py: Python<'py>, pf: &[f64], channels: usize) -> PyResult<Bound<'py, PyAny>> {
    Ok(if channels == 1 { PyArray1::from_slice(py, pf).into_any() } else { rows(py, pf.to_vec(), channels).into_any() })
}

/// Estimates a metamorphosis atlas of `subjects` (FShapes) as `fshape
/// atlas` does: `template` is the initial template (default: the first
/// subject; without a signal it takes the subjects' mean), `config` a
/// dict, TOML path or text, `progress` and `checkpoint` as for `match`.
///
/// Returns an `AtlasResult`: `template` (the estimated FShape), `template_momenta`
/// (hypertemplate model, else None), `subjects` (per subject: `p0`, `pf`,
/// `energies`, `quality`, `template_quality`, `initial_attachment`,
/// `alignment`, `geodesic`, `matched`: the template shot onto it),
/// `energies` (means), `stages`, `iterations`, `evaluations`,
/// `seconds`.
#[pyfunction]
#[pyo3(signature = (subjects, config, template = None, progress = None, stage_templates = None, checkpoint = None))]
pub(crate) fn atlas<'py>(
    py: Python<'py>,
    subjects: Vec<Bound<'py, PyAny>>,
    config: &Bound<'py, PyAny>,
    template: Option<&Bound<'py, PyAny>>,
    progress: Option<Py<PyAny>>,
    stage_templates: Option<Vec<Bound<'py, PyAny>>>,
    checkpoint: Option<PathBuf>,
) -> PyResult<Bound<'py, AtlasResult>> {
    let subjects: Vec<FShape> = subjects.iter().map(shape_of).collect::<PyResult<_>>()?;
    if subjects.is_empty() {
        return Err(err("atlas: no subjects"));
    }
    let start = match template {
        Some(t) => shape_of(t)?,
        None => subjects[0].clone(),
    };
    let config = config_of(config)?;
    let templates = self::stage_templates(stage_templates)?;
    let mut observer = Progress::new(progress);
    let checkpointing = checkpoint.clone().map_or(Checkpointing::None, Checkpointing::Continue);
    let run = py.detach(|| -> Result<_, MatchError> {
        let start = fshape_match::atlas::initial_template(start, &subjects)?;
        let request = AtlasRequest { template: &start, subjects: &subjects, config: &config, modes: 0, collect: true };
        ops::estimate_atlas(&request, templates, &checkpointing, None, &mut observer)
    });
    let run = run.map_err(err)?;
    observer.finish(run.outcome, checkpoint.as_deref())?;
    let steps = run.plan.model.steps();
    let Some(r) = &run.result else {
        return Err(err("the atlas ended without a result"));
    };
    let (dim, channels) = (r.template.dim(), r.template.n_channels().max(1));
    let any = |v: Bound<'py, PyAny>| v.unbind();
    let mut list = Vec::with_capacity(r.subjects.len());
    for (s, (_, matched)) in r.subjects.iter().zip(&run.subjects) {
        let subject = SubjectResult {
            p0: any(rows(py, s.p0.clone(), dim).into_any()),
            pf: any(signal_momentum(py, &s.pf, channels)?),
            energies: any(to_py(py, &s.energies)?),
            quality: any(to_py(py, &s.quality)?),
            template_quality: any(to_py(py, &s.template_quality)?),
            initial_attachment: any(s.initial_attachment.into_pyobject(py)?.into_any()),
            alignment: any(to_py(py, &s.alignment)?),
            geodesic: any(geodesic(py, &s.trajectory, dim, &node_times(steps))?.into_any()),
            matched: any(Bound::new(py, PyFShape { inner: matched.clone() })?.into_any()),
        };
        list.push(Bound::new(py, subject)?);
    }
    Bound::new(
        py,
        AtlasResult {
            template: any(Bound::new(py, PyFShape { inner: r.template.clone() })?.into_any()),
            template_momenta: any(r
                .template_momenta
                .as_ref()
                .map(|p| rows(py, p.clone(), dim))
                .into_pyobject(py)?
                .into_any()),
            subjects: any(PyList::new(py, list)?.into_any()),
            energies: any(to_py(py, &r.energies)?),
            stages: any(to_py(py, &r.stages)?),
            iterations: any(r.iterations.into_pyobject(py)?.into_any()),
            evaluations: any(r.evaluations.into_pyobject(py)?.into_any()),
            seconds: any(r.seconds.into_pyobject(py)?.into_any()),
        },
    )
}

/// Fits one geodesic to a subject's `visits` (FShapes, each its own mesh)
/// at `ages` as `fshape regress` does: the earliest visit is the baseline
/// at t = 0, the ages are mapped onto t ∈ [0, 1], and J = H + γ_W Σ w·A
/// over the visits (`weights`, default 1 each). `config`, `progress` and
/// `checkpoint` as for `match` (a callback that returns True ends the run
/// without a result: continue it from its checkpoint).
///
/// Returns a `RegressionResult`: `p0` (n × d) and `pf` (n, or n × k) on
/// the baseline, `energies` (with each visit's `attachments`), `t0` and
/// `span` (t = (age − t0)/span), `times` (each visit's t), `quality` and
/// `initial_quality` (per visit: how close the fit at its age and the
/// baseline are to it), `alignments` (per visit, with `[prealign]`),
/// `fitted` (the FShape fitted at each visit's age), `rates` (per unit
/// age at the baseline's vertices: `normal_velocity` and `signal_rate`),
/// `geodesic` (at `ages_out`, default 5 ages over the span; its `times`
/// are ages), `baseline`, `stages`, `iterations`, `evaluations`,
/// `seconds` and `config` (the weights used).
#[pyfunction]
#[pyo3(signature = (visits, ages, config, weights = None, progress = None, ages_out = None, checkpoint = None))]
#[expect(clippy::too_many_arguments, reason = "one per keyword argument of the Python call")]
pub(crate) fn regress<'py>(
    py: Python<'py>,
    visits: Vec<Bound<'py, PyAny>>,
    ages: Vec<f64>,
    config: &Bound<'py, PyAny>,
    weights: Option<Vec<f64>>,
    progress: Option<Py<PyAny>>,
    ages_out: Option<Vec<f64>>,
    checkpoint: Option<PathBuf>,
) -> PyResult<Bound<'py, RegressionResult>> {
    if ages.len() != visits.len() {
        return Err(err(format!("{} visits but {} ages", visits.len(), ages.len())));
    }
    let weights = weights.unwrap_or_else(|| vec![1.0; visits.len()]);
    if weights.len() != visits.len() {
        return Err(err(format!("{} visits but {} weights", visits.len(), weights.len())));
    }
    let mut list = Vec::with_capacity(visits.len());
    for ((v, age), weight) in visits.iter().zip(&ages).zip(&weights) {
        list.push(fshape_match::Visit { age: *age, shape: shape_of(v)?, weight: *weight });
    }
    let config = config_of(config)?;
    let mut observer = Progress::new(progress);
    let checkpointing = checkpoint.map_or(Checkpointing::None, Checkpointing::Continue);
    let run = py.detach(|| ops::regress::regress(list, &config, &checkpointing, &mut observer));
    observer.raised()?;
    let run = run.map_err(err)?;
    let rates = run.rates();
    let (Some(r), Some((normal, signal_rate))) = (run.result.as_ref(), rates) else {
        return Err(crate::errors::other(
            "stopped by the progress callback: there is no result (with a checkpoint, the same call continues the run)",
        ));
    };
    let baseline = &run.baseline;
    let (dim, channels) = (baseline.dim(), baseline.n_channels().max(1));
    let (t0, span, t1) = (r.t0, r.span, r.t1);
    let ages_out =
        ages_out.unwrap_or_else(|| (0..5).map(|k| if k == 4 { t1 } else { t0 + span * k as f64 / 4.0 }).collect());
    if let Some(a) = ages_out.iter().find(|a| !(t0..=t1).contains(*a)) {
        return Err(err(format!("ages_out: {a} is outside the visits' ages [{t0}, {t1}]")));
    }
    let normalised: Vec<f64> = ages_out.iter().map(|a| (a - t0) / span).collect();
    // The geodesic's times as ages.
    let geo = crate::shoot::geodesic_labelled(py, &r.trajectory, dim, &normalised, &ages_out)?;
    let fitted = PyList::empty(py);
    for &k in &r.nodes {
        let s = baseline
            .clone()
            .with_points(r.trajectory.points(k).to_vec())
            .and_then(|s| s.with_signals(Some(r.trajectory.signal(k).to_vec()), channels))
            .map_err(err)?;
        fitted.append(Bound::new(py, PyFShape { inner: s })?)?;
    }
    let rates = pyo3::types::PyDict::new(py);
    if !normal.is_empty() {
        rates.set_item("normal_velocity", PyArray1::from_slice(py, &normal))?;
    }
    rates.set_item("signal_rate", signal_momentum(py, &signal_rate, channels)?)?;
    let any = |v: Bound<'py, PyAny>| v.unbind();
    Bound::new(
        py,
        RegressionResult {
            p0: any(rows(py, r.p0.clone(), dim).into_any()),
            pf: any(signal_momentum(py, &r.pf, channels)?),
            energies: any(to_py(py, &r.energies)?),
            t0: any(t0.into_pyobject(py)?.into_any()),
            span: any(span.into_pyobject(py)?.into_any()),
            times: any(PyArray1::from_slice(py, &r.times).into_any()),
            quality: any(to_py(py, &r.quality)?),
            initial_quality: any(to_py(py, &r.initial_quality)?),
            alignments: any(to_py(py, &r.alignments)?),
            fitted: any(fitted.into_any()),
            rates: any(rates.into_any()),
            geodesic: any(geo.into_any()),
            baseline: any(Bound::new(py, PyFShape { inner: baseline.clone() })?.into_any()),
            stages: any(to_py(py, &r.stages)?),
            iterations: any(r.iterations.into_pyobject(py)?.into_any()),
            evaluations: any(r.evaluations.into_pyobject(py)?.into_any()),
            seconds: any(r.seconds.into_pyobject(py)?.into_any()),
            config: any(to_py(py, &run.resolved)?),
        },
    )
}
