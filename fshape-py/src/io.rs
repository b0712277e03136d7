//! Reading and writing meshes and signals in every format the library
//! reads.

use std::path::PathBuf;

use fshape_mesh::io::{self, Encoding, ReadOptions};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArrayLike1};
use pyo3::prelude::*;

use crate::conversions::shape_of;
use crate::err;
use crate::shape::PyFShape;

/// Reads a mesh: PLY, OBJ, VTK legacy, GIfTI (.gii) or a FreeSurfer
/// surface (lh.pial…), optionally gzipped. The signal is the per-vertex
/// scalar named `signal_name` (default: `signal`, if present).
#[pyfunction]
#[pyo3(signature = (path, signal_name = None))]
pub(crate) fn read_mesh(py: Python<'_>, path: PathBuf, signal_name: Option<String>) -> PyResult<PyFShape> {
    let inner = py.detach(|| io::read_mesh(&path, &ReadOptions { signal_name })).map_err(err)?;
    Ok(PyFShape { inner })
}

/// Writes a mesh in the format its name says (.ply, .obj, .vtk, .gii, each
/// optionally .gz, or a FreeSurfer name such as lh.pial); binary unless
/// `ascii`. The write is atomic. GIfTI files may also choose
/// `gifti_encoding` ("ascii", "base64", "gzip-base64": the default for
/// binary), `big_endian` and `column_major`.
#[pyfunction]
#[pyo3(signature = (path, shape, ascii = false, *, gifti_encoding = None, big_endian = false, column_major = false))]
pub(crate) fn write_mesh(
    py: Python<'_>,
    path: PathBuf,
    shape: &Bound<'_, PyAny>,
    ascii: bool,
    gifti_encoding: Option<&str>,
    big_endian: bool,
    column_major: bool,
) -> PyResult<()> {
    let s = shape_of(shape)?;
    let encoding = if ascii { Encoding::Ascii } else { Encoding::Binary };
    if gifti_encoding.is_none() && !big_endian && !column_major {
        return py.detach(|| io::write_mesh(&path, &s, encoding)).map_err(err);
    }
    use io::gifti::{GiftiEncoding, WriteOptions};
    let encoding = match gifti_encoding {
        None if ascii => GiftiEncoding::Ascii,
        None => GiftiEncoding::GzipBase64,
        Some("ascii") => GiftiEncoding::Ascii,
        Some("base64") => GiftiEncoding::Base64,
        Some("gzip-base64") => GiftiEncoding::GzipBase64,
        Some(other) => {
            return Err(err(format!("gifti_encoding: `{other}` (expected ascii, base64 or gzip-base64)")));
        }
    };
    let opts = WriteOptions { encoding, big_endian, column_major };
    py.detach(|| io::gifti::write_file(&path, &s, opts)).map_err(err)
}

/// Reads a per-vertex signal: a one-column CSV, a GIfTI data file
/// (.shape.gii, .func.gii), a FreeSurfer curv file (lh.thickness) or
/// .mgh/.mgz. Returns (name, values).
#[pyfunction]
pub(crate) fn read_signal<'py>(py: Python<'py>, path: PathBuf) -> PyResult<(String, Bound<'py, PyArray1<f64>>)> {
    let c = py.detach(|| io::read_signal(&path)).map_err(err)?;
    Ok((c.name, c.values.into_pyarray(py)))
}

/// Writes a per-vertex signal in the format its name says (.csv, .gii,
/// .mgh/.mgz, or a FreeSurfer name such as lh.thickness, which records the
/// surface's triangle count `faces`).
#[pyfunction]
#[pyo3(signature = (path, values, name = "signal", faces = 0))]
pub(crate) fn write_signal(
    py: Python<'_>,
    path: PathBuf,
    values: PyArrayLike1<'_, f64, AllowTypeChange>,
    name: &str,
    faces: usize,
) -> PyResult<()> {
    let v: Vec<f64> = values.as_array().iter().copied().collect();
    py.detach(|| io::write_signal(&path, name, &v, faces)).map_err(err)
}
