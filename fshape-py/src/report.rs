//! `report`: a registration's report.html from its result.

use std::path::PathBuf;

use fshape_mesh::FShape;
use numpy::{PyReadonlyArray1, PyReadonlyArray3, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::err;
use crate::results::{Geodesic, MatchResult};
use crate::shape::shape_of;

/// Writes the report.html of a registration, as `fshape match` does, from
/// the source and target given to `match` and the `MatchResult` it
/// returned (its typed run record, not its attributes, gives the figures):
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
    result: &Bound<'_, MatchResult>,
    view: (f64, f64),
) -> PyResult<()> {
    let source = shape_of(source)?;
    let target = shape_of(target)?;
    let result = result.get();
    let geodesic = result.geodesic.bind(py).cast::<Geodesic>()?.get();
    let times: PyReadonlyArray1<'_, f64> = geodesic.times.bind(py).extract()?;
    let points: PyReadonlyArray3<'_, f64> = geodesic.points.bind(py).extract()?;
    // T × n, or T × n × k with k signal channels.
    let signals: PyReadonlyArrayDyn<'_, f64> = geodesic.signals.bind(py).extract()?;
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
    let (summary, text) = (&result.record, &result.config_text);
    py.detach(|| -> Result<(), fshape_report::ReportError> {
        let page = fshape_report::registration_page(&states, &target, summary, Some(text), None, view)?;
        fshape_mesh::io::write_atomic(&path, fshape_report::html(&page).as_bytes(), false)?;
        Ok(())
    })
    .map_err(err)
}
