//! Conversions between the library's values and Python's, in one place.

use numpy::IntoPyArray;
use numpy::ndarray::Array2;
use pyo3::prelude::*;

use crate::err;

pub(crate) fn rows<'py>(py: Python<'py>, flat: Vec<f64>, d: usize) -> Bound<'py, numpy::PyArray2<f64>> {
    Array2::from_shape_vec((flat.len() / d.max(1), d), flat).expect("whole rows").into_pyarray(py)
}

pub(crate) fn to_py<'py>(py: Python<'py>, v: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    pythonize::pythonize(py, v).map_err(|e| err(format!("converting a result: {e}")))
}
