//! `report`: a registration's report.html from its result.

use std::path::PathBuf;

use fshape_match::record::{self, MatchRecord};
use fshape_mesh::FShape;
use numpy::{PyReadonlyArray1, PyReadonlyArray3, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::config::config_of;
use crate::err;
use crate::shape::shape_of;

fn value(result: &Bound<'_, PyDict>, key: &str) -> PyResult<serde_json::Value> {
    match result.get_item(key)? {
        None => Ok(serde_json::Value::Null),
        Some(v) if v.is_none() => Ok(serde_json::Value::Null),
        Some(v) => pythonize::depythonize(&v).map_err(|e| err(format!("report: result[{key:?}]: {e}"))),
    }
}

/// Writes the report.html of a registration, as `fshape match` does, from
/// the source and target given to `match` and the dict it returned:
/// the geodesic under a time slider with the target beside it, the match
/// quality before and after, the stages and the configuration. One file,
/// viewable offline.
#[pyfunction]
#[pyo3(signature = (path, source, target, result, view = (30.0, 20.0)), text_signature = "(path, source, target, result, view=(30.0, 20.0))")]
pub(crate) fn report(
    py: Python<'_>,
    path: PathBuf,
    source: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    result: &Bound<'_, PyDict>,
    view: (f64, f64),
) -> PyResult<()> {
    let source = shape_of(source)?;
    let target = shape_of(target)?;
    let geodesic = result
        .get_item("geodesic")?
        .ok_or_else(|| err("report: the result has no `geodesic` (pass what fshape.match returns)"))?;
    let times: PyReadonlyArray1<'_, f64> = geodesic.get_item("times")?.extract()?;
    let points: PyReadonlyArray3<'_, f64> = geodesic.get_item("points")?.extract()?;
    // T × n, or T × n × k with k signal channels.
    let signals: PyReadonlyArrayDyn<'_, f64> = geodesic.get_item("signals")?.extract()?;
    let (t, n, d) = (points.shape()[0], points.shape()[1], points.shape()[2]);
    let k = match signals.shape() {
        [ts, ns] if *ts == t && *ns == n => 1,
        [ts, ns, k] if *ts == t && *ns == n && *k > 0 => *k,
        other => {
            return Err(err(format!(
                "report: the geodesic's signals have shape {other:?} for {t} times of {n} vertices"
            )));
        }
    };
    if n != source.n_vertices() || d != source.dim() {
        return Err(err(format!(
            "report: the geodesic has {n} vertices in R^{d}, the source {} in R^{}",
            source.n_vertices(),
            source.dim()
        )));
    }
    let (times, points, signals) =
        (times.as_slice().map_err(err)?, points.as_slice().map_err(err)?, signals.as_slice().map_err(err)?);
    let states: Vec<(f64, FShape)> = (0..t)
        .map(|i| {
            let s = source
                .clone()
                .with_points(points[i * n * d..(i + 1) * n * d].to_vec())
                .and_then(|s| s.with_signals(Some(signals[i * n * k..(i + 1) * n * k].to_vec()), k))
                .map_err(err)?;
            Ok((times[i], s))
        })
        .collect::<PyResult<_>>()?;
    let config = match result.get_item("config")? {
        Some(c) if !c.is_none() => Some(config_of(&c)?),
        _ => None,
    };
    // The record `fshape match` would write, from what the dict holds: the
    // parts the dict does not carry (the files, H along the geodesic, the
    // scales) are left empty.
    fn from<T: serde::de::DeserializeOwned>(key: &str, v: serde_json::Value) -> PyResult<T> {
        serde_path_to_error::deserialize(v)
            .map_err(|e| err(format!("report: result[{key:?}].{}: {}", e.path(), e.inner())))
    }
    let energies = value(result, "energies")?;
    let number = |key: &str| energies[key].as_f64().unwrap_or(f64::NAN);
    let (model, norm, gamma, steps, metrics) = match &config {
        Some(c) => (
            c.model.kind.name().to_string(),
            serde_json::to_value(c.model.norm).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default(),
            [c.model.gamma_v, c.model.gamma_f, c.model.gamma_w],
            c.integrator.steps,
            c.optimizer().map(|(_, m)| m).unwrap_or_default(),
        ),
        None => (String::new(), String::new(), [f64::NAN; 3], 0, fshape_match::Metrics::default()),
    };
    let summary = MatchRecord {
        kind: record::Kind::Match,
        format: record::FORMAT,
        source: "source".into(),
        target: "target".into(),
        config: String::new(),
        model,
        norm,
        gamma_v: gamma[0],
        gamma_f: gamma[1],
        gamma_w: gamma[2],
        scales: None,
        effective_weights: gamma,
        steps,
        metrics,
        stages: from("stages", value(result, "stages")?)?,
        final_value: number("value"),
        final_energy: number("energy"),
        final_attachment: number("attachment"),
        geodesic_distance: number("energy").max(0.0).sqrt(),
        hamiltonian: Vec::new(),
        quality: from("quality", value(result, "quality")?)?,
        quality_before: from("initial_quality", value(result, "initial_quality")?)?,
        prealign: from("alignment", value(result, "alignment")?)?,
        iterations: from("iterations", value(result, "iterations")?)?,
        evaluations: from("evaluations", value(result, "evaluations")?)?,
        seconds: from("seconds", value(result, "seconds")?)?,
        files: Vec::new(),
    };
    let text = config.map(|c| c.to_toml());
    py.detach(|| -> Result<(), fshape_report::ReportError> {
        let page = fshape_report::registration_page(&states, &target, &summary, text.as_deref(), None, view)?;
        fshape_mesh::io::write_atomic(&path, fshape_report::html(&page).as_bytes(), false)?;
        Ok(())
    })
    .map_err(err)
}
