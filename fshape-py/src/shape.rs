//! `fshape.FShape`: a functional shape as numpy arrays.

use fshape_mesh::{CellKind, FShape};
use numpy::ndarray::Array2;
use numpy::{
    AllowTypeChange, IntoPyArray, PyArray1, PyArrayLike1, PyArrayLike2, PyArrayLikeDyn, PyArrayMethods, PyUntypedArray,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::conversions::rows;
use crate::err;

/// A functional shape: vertices (n × d, d = 2 or 3), cells (m × 2
/// segments or m × 3 triangles, vertex indices), an optional signal (one
/// value per vertex, or n × k for k maps per vertex) and an optional mask
/// (a weight in [0, 1] per vertex: where it is 0 the signal has no value
/// and is NaN, in every map). Immutable; every value is checked on
/// creation.
#[pyclass(name = "FShape", module = "fshape", frozen)]
#[derive(Clone)]
pub(crate) struct PyFShape {
    pub(crate) inner: FShape,
}

#[pymethods]
impl PyFShape {
    #[new]
    #[pyo3(signature = (points, cells, signal = None, mask = None))]
    fn new(
        points: PyArrayLike2<'_, f64, AllowTypeChange>,
        cells: PyArrayLike2<'_, i64, AllowTypeChange>,
        signal: Option<PyArrayLikeDyn<'_, f64, AllowTypeChange>>,
        mask: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
    ) -> PyResult<Self> {
        let p = points.as_array();
        let c = cells.as_array();
        let dim = p.ncols();
        let kind = match c.ncols() {
            2 => CellKind::Segment,
            3 => CellKind::Triangle,
            k => return Err(err(format!("cells: {k} columns; fshape takes segments (2) or triangles (3)"))),
        };
        let mut flat_cells = Vec::with_capacity(c.len());
        for ((t, _), &v) in c.indexed_iter() {
            flat_cells
                .push(usize::try_from(v).map_err(|_| err(format!("cells: cell {t} has the negative index {v}")))?);
        }
        let (signal, channels) = channels(signal)?;
        let mask = mask.map(|m| m.as_array().iter().copied().collect());
        let inner = FShape::try_new(dim, kind, p.iter().copied().collect(), flat_cells, None)
            .and_then(|s| s.with_signals_and_mask(signal, channels, mask))
            .map_err(err)?;
        Ok(PyFShape { inner })
    }

    /// The vertex coordinates, n × d (a copy).
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray2<f64>> {
        rows(py, self.inner.points().to_vec(), self.inner.dim())
    }

    /// The cells, m × 2 or m × 3 vertex indices (a copy).
    #[getter]
    fn cells<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray2<i64>> {
        let k = self.inner.kind().n_corners();
        let c: Vec<i64> = self.inner.cells().iter().map(|&v| v as i64).collect();
        Array2::from_shape_vec((c.len() / k, k), c).expect("whole cells").into_pyarray(py)
    }

    /// The signal (one value per vertex, or n × k with k maps), or None.
    #[getter]
    fn signal<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyUntypedArray>> {
        let k = self.inner.n_channels();
        self.inner.signal().map(|f| match k {
            1 => PyArray1::from_slice(py, f).as_untyped().clone(),
            _ => rows(py, f.to_vec(), k).as_untyped().clone(),
        })
    }

    /// The number of maps per vertex (0 without a signal).
    #[getter]
    fn n_channels(&self) -> usize {
        self.inner.n_channels()
    }

    /// The mask (one weight in [0, 1] per vertex), or None.
    #[getter]
    fn mask<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.inner.mask().map(|m| PyArray1::from_slice(py, m))
    }

    /// The ambient dimension (2 or 3).
    #[getter]
    fn dim(&self) -> usize {
        self.inner.dim()
    }

    /// "triangle" or "segment".
    #[getter]
    fn kind(&self) -> &'static str {
        self.inner.kind().name()
    }

    /// The number of vertices.
    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.n_vertices()
    }

    /// The number of cells.
    #[getter]
    fn n_cells(&self) -> usize {
        self.inner.n_cells()
    }

    /// The same shape with another mask (or none); the signal is NaN
    /// where the mask is 0 and must be finite elsewhere.
    #[pyo3(signature = (mask))]
    fn with_mask(&self, mask: Option<PyArrayLike1<'_, f64, AllowTypeChange>>) -> PyResult<Self> {
        let m = mask.map(|s| s.as_array().iter().copied().collect());
        Ok(PyFShape { inner: self.inner.clone().with_mask(m).map_err(err)? })
    }

    /// The same shape with another signal (n values, n × k, or none); a
    /// mask is kept.
    #[pyo3(signature = (signal))]
    fn with_signal(&self, signal: Option<PyArrayLikeDyn<'_, f64, AllowTypeChange>>) -> PyResult<Self> {
        let (f, channels) = channels(signal)?;
        Ok(PyFShape { inner: self.inner.clone().with_signals(f, channels).map_err(err)? })
    }

    /// The validation report: `{"errors": [...], "warnings": [...]}`, each
    /// finding a dict with its `code` and `message` (which names the
    /// vertex or cell). A shape that exists has no errors; warnings
    /// (unused vertices, zero-area cells, boundaries, …) still allow
    /// computing.
    fn validate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let v = self.inner.validate();
        let list = |it: &mut dyn Iterator<Item = &fshape_mesh::Finding>| -> PyResult<Bound<'py, PyList>> {
            let l = PyList::empty(py);
            for f in it {
                let d = PyDict::new(py);
                d.set_item("code", f.code())?;
                d.set_item("message", f.to_string())?;
                l.append(d)?;
            }
            Ok(l)
        };
        let d = PyDict::new(py);
        d.set_item("errors", list(&mut v.errors())?)?;
        d.set_item("warnings", list(&mut v.warnings())?)?;
        Ok(d)
    }

    /// One level of icosahedral subdivision undone (icospheres,
    /// FreeSurfer's fsaverage meshes: their first vertices are the coarser
    /// mesh's); signal values kept at the kept vertices.
    fn coarsened(&self) -> PyResult<Self> {
        Ok(PyFShape { inner: self.inner.coarsened().map_err(err)? })
    }

    /// The total area (or length) of the cells.
    fn total_volume(&self) -> f64 {
        self.inner.total_volume()
    }

    fn __repr__(&self) -> String {
        format!(
            "FShape({} vertices, {} {}s in {}-D, {})",
            self.inner.n_vertices(),
            self.inner.n_cells(),
            self.inner.kind().name(),
            self.inner.dim(),
            match (self.inner.n_channels(), self.inner.mask()) {
                (1, Some(_)) => "with a signal and a mask".to_string(),
                (1, None) => "with a signal".to_string(),
                (0, Some(_)) => "no signal, a mask".to_string(),
                (0, None) => "no signal".to_string(),
                (k, m) => format!("with {k} signal channels{}", if m.is_some() { " and a mask" } else { "" }),
            }
        )
    }

    fn __eq__(&self, other: &Self) -> bool {
        self.inner == other.inner
    }
}

/// A signal given as n values (one channel) or n × k (k channels), flat
/// vertex by vertex.
fn channels(signal: Option<PyArrayLikeDyn<'_, f64, AllowTypeChange>>) -> PyResult<(Option<Vec<f64>>, usize)> {
    let Some(s) = signal else { return Ok((None, 1)) };
    let a = s.as_array();
    let k = match a.shape() {
        [_] => 1,
        [_, k] => *k,
        other => return Err(err(format!("signal: {} dimensions; give n values or n x k (k maps)", other.len()))),
    };
    // Row-major order: vertex by vertex, whatever the array's strides.
    Ok((Some(a.iter().copied().collect()), k))
}

/// The Rust shape inside a Python `fshape.FShape`.
pub(crate) fn shape_of(s: &Bound<'_, PyAny>) -> PyResult<FShape> {
    Ok(s.cast::<PyFShape>().map_err(|_| err("expected an fshape.FShape"))?.get().inner.clone())
}
