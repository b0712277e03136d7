//! Reading and writing meshes and signals in every format the library
//! reads.

use std::path::PathBuf;

use fshape_mesh::io::{self, Encoding, ReadOptions};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArrayLike1};
use pyo3::prelude::*;

use crate::err;
use crate::shape::PyFShape;
use crate::shape::shape_of;

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
/// .mgh/.mgz. Returns (name, values). With `allow_missing`, NaN (HCP's
/// medial wall) is accepted as a missing value.
#[pyfunction]
#[pyo3(signature = (path, allow_missing = false))]
pub(crate) fn read_signal<'py>(
    py: Python<'py>,
    path: PathBuf,
    allow_missing: bool,
) -> PyResult<(String, Bound<'py, PyArray1<f64>>)> {
    let c = py.detach(|| io::read_signal_for(&path, None, allow_missing)).map_err(err)?;
    Ok((c.name, c.values.into_pyarray(py)))
}

/// Reads a mask for a surface of `n_vertices` vertices: a FreeSurfer
/// .label (its vertices 1, the rest 0) or a per-vertex column of weights
/// in [0, 1] (CSV, GIfTI, curv, MGH).
#[pyfunction]
pub(crate) fn read_mask<'py>(py: Python<'py>, path: PathBuf, n_vertices: usize) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let m = py.detach(|| io::read_mask(&path, n_vertices)).map_err(err)?;
    Ok(m.into_pyarray(py))
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

/// Reads a FreeSurfer label file: (vertices, points, values), the
/// vertices as listed (indices from 0), their coordinates (k × 3) and
/// their values, as nibabel's `read_label(path, read_scalars=True)` reads
/// the first and last.
#[pyfunction]
#[expect(clippy::type_complexity, reason = "the three arrays of a label, as Python returns them")]
pub(crate) fn read_label<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyArray1<i64>>, Bound<'py, numpy::PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
    let l = py.detach(|| io::label::read_label(&path)).map_err(err)?;
    let vertices: Vec<i64> = l.vertices.iter().map(|&v| v as i64).collect();
    Ok((vertices.into_pyarray(py), crate::conversions::rows(py, l.points, 3), l.values.into_pyarray(py)))
}

/// Writes a FreeSurfer label file: its vertices (indices from 0), their
/// coordinates (k × 3, default 0) and values (default 0); `subject` goes
/// in the comment line.
#[pyfunction]
#[pyo3(signature = (path, vertices, points = None, values = None, subject = ""))]
pub(crate) fn write_label(
    py: Python<'_>,
    path: PathBuf,
    vertices: PyArrayLike1<'_, i64, AllowTypeChange>,
    points: Option<numpy::PyArrayLike2<'_, f64, AllowTypeChange>>,
    values: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
    subject: &str,
) -> PyResult<()> {
    let mut list = Vec::with_capacity(vertices.as_array().len());
    for (k, &v) in vertices.as_array().iter().enumerate() {
        list.push(usize::try_from(v).map_err(|_| err(format!("vertices: entry {k} is the negative index {v}")))?);
    }
    let k = list.len();
    let points: Vec<f64> = match points {
        Some(p) if p.as_array().dim() != (k, 3) => {
            return Err(err(format!("points: {:?} for {k} vertices (expected {k} x 3)", p.as_array().dim())));
        }
        Some(p) => p.as_array().iter().copied().collect(),
        None => vec![0.0; 3 * k],
    };
    let values: Vec<f64> = match values {
        Some(v) if v.as_array().len() != k => {
            return Err(err(format!("values: {} for {k} vertices", v.as_array().len())));
        }
        Some(v) => v.as_array().iter().copied().collect(),
        None => vec![0.0; k],
    };
    if let Some(x) = points.iter().chain(&values).find(|x| !x.is_finite()) {
        return Err(err(format!("a label's coordinates and values must be finite (found {x})")));
    }
    let label = io::label::Label { vertices: list, points, values };
    py.detach(|| io::label::write_label(&path, &label, subject)).map_err(err)
}

/// Reads a parcellation: a FreeSurfer .annot, a GIfTI label array
/// (.label.gii) or a structure of a CIFTI-2 label file
/// (`FILE.dlabel.nii:CORTEX_LEFT[:MAP]`). Returns (keys, regions): a key
/// per vertex (for .annot the colour table's row, -1 without a region, as
/// nibabel's `read_annot` gives them; for GIfTI and CIFTI the label key)
/// and the table as a list of
/// (key, name, (red, green, blue, alpha)) with colours in [0, 1].
#[pyfunction]
#[expect(clippy::type_complexity, reason = "a parcellation's keys and table, as Python returns them")]
pub(crate) fn read_parcellation<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyArray1<i32>>, Vec<(i32, String, (f64, f64, f64, f64))>)> {
    let p = py.detach(|| io::read_parcellation(&path)).map_err(err)?;
    let regions =
        p.regions.into_iter().map(|r| (r.key, r.name, (r.rgba[0], r.rgba[1], r.rgba[2], r.rgba[3]))).collect();
    Ok((p.keys.into_pyarray(py), regions))
}

/// Writes a parcellation in the format the path names: `.annot`
/// (FreeSurfer: keys become the table's rows), `.label.gii` (GIfTI: keys
/// and table kept; vertices in no region, -1, take the table's `???`) or
/// `.csv`. `keys` as `read_parcellation` returns them, `regions` as a list
/// of (key, name, (red, green, blue, alpha)) with colours in [0, 1].
#[pyfunction]
#[expect(clippy::type_complexity, reason = "a parcellation's table, as Python gives it")]
pub(crate) fn write_parcellation(
    py: Python<'_>,
    path: PathBuf,
    keys: PyArrayLike1<'_, i64, AllowTypeChange>,
    regions: Vec<(i64, String, (f64, f64, f64, f64))>,
) -> PyResult<()> {
    let key = |what: String, k: i64| i32::try_from(k).map_err(|_| err(format!("{what}: {k} is outside int32")));
    let keys: Vec<i32> = keys
        .as_array()
        .iter()
        .enumerate()
        .map(|(v, &k)| key(format!("keys: vertex {v}"), k))
        .collect::<PyResult<_>>()?;
    let mut table = Vec::with_capacity(regions.len());
    for (i, (k, name, (r, g, b, a))) in regions.into_iter().enumerate() {
        let rgba = [r, g, b, a];
        if let Some(c) = rgba.iter().find(|c| !(0.0..=1.0).contains(*c)) {
            return Err(err(format!("regions: entry {i} ({name}): the colour {c} is not in [0, 1]")));
        }
        table.push(io::parcellation::Region { key: key(format!("regions: entry {i}"), k)?, name, rgba });
    }
    if let Some((v, k)) = keys.iter().enumerate().find(|(_, k)| **k != -1 && !table.iter().any(|r| r.key == **k)) {
        return Err(err(format!("keys: vertex {v} has the key {k}, which no region has (-1: no region)")));
    }
    let p = io::parcellation::Parcellation { keys, regions: table };
    py.detach(|| io::write_parcellation(&path, &p)).map_err(err)
}

/// Reads one map of a surface structure (`CORTEX_LEFT`) of a CIFTI-2
/// dense file (.dscalar.nii, .dtseries.nii) on a surface of `n_vertices`
/// vertices: the file's values at the structure's vertices, NaN at the
/// others (the medial wall). `map` is the map's name or its number from 1;
/// it may be left out when the file has one map. A structure of another
/// vertex count is refused. Returns (map name, values).
#[pyfunction]
#[pyo3(signature = (path, structure, n_vertices, map = None))]
pub(crate) fn read_cifti<'py>(
    py: Python<'py>,
    path: PathBuf,
    structure: &str,
    n_vertices: usize,
    map: Option<&str>,
) -> PyResult<(String, Bound<'py, PyArray1<f64>>)> {
    let (name, values) = py
        .detach(|| {
            let c = io::read_cifti_file(&path)?;
            let select = |source| io::ReadError::Select { path: path.clone(), source };
            let k = c.map_index(map).map_err(select)?;
            let values = c.surface(structure, map, n_vertices).map_err(select)?;
            Ok::<_, io::ReadError>((c.maps[k].clone(), values))
        })
        .map_err(err)?;
    Ok((name, values.into_pyarray(py)))
}

/// Writes `values` (one per vertex of the structure's surface) as one map
/// of a surface structure into a copy of the CIFTI-2 file `like`, saved at
/// `path`: the other structures, the other maps, the header and the XML
/// are `like`'s, byte for byte; values off the structure (the medial wall)
/// have no place in the file and are dropped. The write is atomic.
#[pyfunction]
#[pyo3(signature = (path, like, structure, values, map = None))]
pub(crate) fn write_cifti(
    py: Python<'_>,
    path: PathBuf,
    like: PathBuf,
    structure: &str,
    values: PyArrayLike1<'_, f64, AllowTypeChange>,
    map: Option<&str>,
) -> PyResult<()> {
    let v: Vec<f64> = values.as_array().iter().copied().collect();
    py.detach(|| {
        let c = io::read_cifti_file(&like).map_err(|e| e.to_string())?;
        let bytes = c.with_surface(structure, map, &v).map_err(|e| format!("{}: {e}", like.display()))?;
        io::write_atomic(&path, &bytes, false).map_err(|e| e.to_string())
    })
    .map_err(err)
}
