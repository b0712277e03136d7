//! `fshape.Correspondence`: maps and labels carried between two surfaces
//! in one space, as `fshape transfer` carries them through a registration.

use fshape_match::transfer;
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArrayLike1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::err;
use crate::shape::shape_of;

/// Every vertex of `onto` at its closest point on `source` (the surface the
/// values come from), computed once: `map` and `labels` then carry any
/// number of per-vertex values of `source` onto `onto`'s vertices. For a
/// registration's result `r`, `Correspondence(r["matched"], r["target"])`
/// carries the source's maps onto the target, and
/// `Correspondence(r["target"], r["matched"])` the target's back onto the
/// source's vertices.
#[pyclass(name = "Correspondence", module = "fshape", frozen)]
pub(crate) struct PyCorrespondence {
    inner: transfer::Correspondence,
}

#[pymethods]
impl PyCorrespondence {
    #[new]
    fn new(py: Python<'_>, source: &Bound<'_, PyAny>, onto: &Bound<'_, PyAny>) -> PyResult<Self> {
        let (from, onto) = (shape_of(source)?, shape_of(onto)?);
        let inner = py.detach(|| transfer::Correspondence::new(&from, &onto)).map_err(err)?;
        Ok(PyCorrespondence { inner })
    }

    /// A map on the source's vertices (NaN where it has no value) on
    /// `onto`'s vertices: the barycentric mean at the closest point,
    /// corners without a value left out while those with one carry at least
    /// half the weight, else NaN; NaN farther than `max_distance`. Returns
    /// (values, counts) with counts' `vertices`, `beyond`, `missing`.
    #[pyo3(signature = (values, max_distance = f64::INFINITY))]
    fn map<'py>(
        &self,
        py: Python<'py>,
        values: PyArrayLike1<'_, f64, AllowTypeChange>,
        max_distance: f64,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyDict>)> {
        let values: Vec<f64> = values.as_array().iter().copied().collect();
        let (out, carried) = py.detach(|| self.inner.map(&values, max_distance)).map_err(err)?;
        let counts = PyDict::new(py);
        counts.set_item("vertices", carried.vertices)?;
        counts.set_item("beyond", carried.beyond)?;
        counts.set_item("missing", carried.missing)?;
        Ok((out.into_pyarray(py), counts))
    }

    /// Integer labels on the source's vertices (-1: no region) on `onto`'s
    /// vertices: the key whose corners carry the largest barycentric weight
    /// at the closest point (ties to the smaller key); -1 farther than
    /// `max_distance`. Keys are int32.
    #[pyo3(signature = (keys, max_distance = f64::INFINITY))]
    fn labels<'py>(
        &self,
        py: Python<'py>,
        keys: PyArrayLike1<'_, i64, AllowTypeChange>,
        max_distance: f64,
    ) -> PyResult<Bound<'py, PyArray1<i32>>> {
        let keys = keys
            .as_array()
            .iter()
            .enumerate()
            .map(|(v, &k)| i32::try_from(k).map_err(|_| err(format!("keys: vertex {v} has {k}, outside int32"))))
            .collect::<PyResult<Vec<i32>>>()?;
        let out = py.detach(|| self.inner.labels(&keys, max_distance)).map_err(err)?;
        Ok(out.into_pyarray(py))
    }

    /// The distance of every vertex of `onto` to the source (a copy).
    #[getter]
    fn distances<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.distances())
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    fn __repr__(&self) -> String {
        format!("Correspondence(onto {} vertices)", self.inner.len())
    }
}
