//! Group statistics on an atlas: `stats`.

use fshape_match::ops::{Scores, StatsRequest, StatsRun, StatsSubject, group_stats};
use fshape_stats::{Inference, Map, StatKind, Tail, TfceParams};
use numpy::{PyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::BoundObject;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

use crate::conversions::to_py;
use crate::err;
use crate::results::{MapTest, StatsResult};
use crate::shape::shape_of;

/// The covariates as a table's text: a path's contents, or a mapping
/// {column: values, one per subject in the atlas's order} written with
/// the subjects' indices as their names.
fn covariates_text(covariates: &Bound<'_, PyAny>, n: usize) -> PyResult<(String, String)> {
    if let Ok(map) = covariates.cast::<PyDict>() {
        let mut columns: Vec<(String, Vec<String>)> = Vec::new();
        for (key, values) in map.iter() {
            let name: String = key.extract().map_err(|_| err("covariates: column names must be strings"))?;
            let cells: Vec<String> = values
                .try_iter()
                .map_err(|_| err(format!("covariates: column `{name}` is not a sequence")))?
                .map(|v| v.and_then(|v| v.str().map(|s| s.to_string())))
                .collect::<PyResult<_>>()?;
            if cells.len() != n {
                return Err(err(format!("covariates: column `{name}` has {} values for {n} subjects", cells.len())));
            }
            if let Some(c) = cells.iter().find(|c| c.contains(['\n', '\r'])) {
                return Err(err(format!("covariates: column `{name}`: `{c}` holds a line break")));
            }
            columns.push((name, cells));
        }
        // Written through the table writer: a comma or a quote in a level
        // (`Smith, J`) is quoted, and reads back as it was.
        let mut rows =
            vec![std::iter::once("subject".to_string()).chain(columns.iter().map(|c| c.0.clone())).collect()];
        rows.extend(
            (0..n).map(|i| std::iter::once(i.to_string()).chain(columns.iter().map(|c| c.1[i].clone())).collect()),
        );
        let text = fshape_mesh::io::table::table_text(&rows, false);
        return Ok((text, "covariates".into()));
    }
    let path: std::path::PathBuf = covariates
        .extract()
        .map_err(|_| err("covariates: expected a path to a CSV table or a dict {column: values}"))?;
    // Bounded like every input: a device or folder is refused.
    let bytes = fshape_mesh::io::read_bytes(&path).map_err(|e| err(e.to_string()))?;
    let text = String::from_utf8(bytes).map_err(|_| err(format!("{}: not UTF-8 text", path.display())))?;
    Ok((text, path.display().to_string()))
}

/// Tests a contrast on an atlas (the `AtlasResult` `atlas` returns), vertex
/// by vertex on the template, as `fshape stats` does. Returns a
/// `StatsResult`: `design` (columns, terms), `contrast`, `maps` ({name:
/// `MapTest` with statistic, effect, p, p_fwe, tfce, tfce_p_fwe, kind,
/// dof, critical}) and `multivariate` (when `scores` is given:
/// Hotelling–Lawley on its rows).
#[pyfunction]
#[pyo3(signature = (atlas, covariates, contrast, maps = None, columns = None, permutations = 5000, seed = 0, tfce = false, one_sided = false, scores = None, alpha = 0.05))]
#[expect(clippy::too_many_arguments, reason = "Python keyword arguments")]
pub(crate) fn stats<'py>(
    py: Python<'py>,
    atlas: &Bound<'py, PyAny>,
    covariates: &Bound<'py, PyAny>,
    contrast: &str,
    maps: Option<Vec<String>>,
    columns: Option<Vec<String>>,
    permutations: usize,
    seed: u64,
    tfce: bool,
    one_sided: bool,
    scores: Option<PyReadonlyArray2<'py, f64>>,
    alpha: f64,
) -> PyResult<Bound<'py, StatsResult>> {
    let template = shape_of(
        &atlas.get_item("template").map_err(|_| err("atlas: no `template` (pass what fshape.atlas returns)"))?,
    )?;
    let subjects = atlas.get_item("subjects").map_err(|_| err("atlas: no `subjects`"))?;
    let mut inputs: Vec<StatsSubject> = Vec::new();
    for (i, s) in subjects.try_iter()?.enumerate() {
        let s = s?;
        let p0: PyReadonlyArray2<'py, f64> = s
            .get_item("p0")
            .and_then(|p| p.extract())
            .map_err(|_| err(format!("atlas: subject {i}: no `p0` array")))?;
        let matched =
            shape_of(&s.get_item("matched").map_err(|_| err(format!("atlas: subject {i}: no `matched` shape")))?)?;
        let names = vec![i.to_string(), format!("subject_{i:03}")];
        inputs.push(StatsSubject { names, p0: p0.as_slice().map_err(err)?.to_vec(), matched });
    }
    let (text, source) = covariates_text(covariates, inputs.len())?;
    let maps: Option<Vec<Map>> = maps
        .map(|names| {
            names
                .iter()
                .map(|m| {
                    Map::from_name(m).ok_or_else(|| {
                        err(format!("maps: `{m}` is not signal, signal_2, …, momentum, displacement or area"))
                    })
                })
                .collect::<PyResult<_>>()
        })
        .transpose()?;
    let scores: Option<(Vec<f64>, usize)> = match scores {
        None => None,
        Some(a) => Some((a.as_slice().map_err(err)?.to_vec(), a.shape()[1])),
    };
    let request = StatsRequest {
        template: &template,
        subjects: &inputs,
        covariates: (&text, &source),
        columns: columns.as_deref(),
        contrast,
        maps: maps.as_deref(),
        // Every column of the scores given.
        scores: scores.as_ref().map(|(values, k)| Scores { values, available: *k, modes: Some(*k), source: "scores" }),
        inference: Inference {
            permutations,
            seed,
            tail: if one_sided { Tail::Positive } else { Tail::TwoSided },
            tfce: tfce.then(TfceParams::default),
        },
        alpha,
    };
    let run = py.detach(|| group_stats(&request)).map_err(err)?;
    let StatsRun { design, contrast, unused, maps: tests, multivariate, .. } = run;
    let multivariate = multivariate.map(|(_, m)| m);
    fn any<'py, T: IntoPyObject<'py>>(py: Python<'py>, v: T) -> PyResult<Py<PyAny>> {
        Ok(v.into_pyobject(py).map_err(Into::into)?.into_any().unbind())
    }
    let out = PyDict::new(py);
    for (kind, t) in &tests {
        let test = MapTest {
            kind: any(py, PyString::new(py, if t.kind == StatKind::T { "t" } else { "F" }))?,
            dof: any(py, t.dof)?,
            statistic: any(py, PyArray1::from_slice(py, &t.statistic))?,
            effect: any(py, PyArray1::from_slice(py, &t.effect))?,
            p: any(py, PyArray1::from_slice(py, &t.p_uncorrected))?,
            p_fwe: any(py, PyArray1::from_slice(py, &t.p_fwe))?,
            tfce: any(py, t.tfce.as_deref().map(|v| PyArray1::from_slice(py, v)))?,
            tfce_p_fwe: any(py, t.tfce_p_fwe.as_deref().map(|v| PyArray1::from_slice(py, v)))?,
            critical: any(py, t.critical(alpha))?,
        };
        out.set_item(kind.name(), Bound::new(py, test)?)?;
    }
    Bound::new(
        py,
        StatsResult {
            design: to_py(py, &design)?.unbind(),
            contrast: to_py(py, &contrast)?.unbind(),
            rows_not_in_the_atlas: any(py, unused)?,
            maps: out.into_any().unbind(),
            multivariate: to_py(py, &multivariate)?.unbind(),
        },
    )
}
