//! The `fshape` Python package: the library's workflow on numpy arrays.
//!
//! Every function takes and returns numpy arrays (`float64` coordinates
//! and signals, `int64` cells), raises `fshape.FShapeError` with the
//! library's own message on bad input, and releases the GIL while it
//! computes, so other Python threads run meanwhile. The type stubs are in
//! `fshape.pyi` beside this crate.

use std::path::{Path, PathBuf};

use fshape_match::{Config, Control, Iteration, MatchError, Observer, Outcome, StageRecord, StageSpec};
use fshape_mesh::io::{self, Encoding, ReadOptions};
use fshape_mesh::{CellKind, FShape};
use numpy::ndarray::{Array2, Array3};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArrayLike1, PyArrayLike2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

pyo3::create_exception!(
    fshape,
    FShapeError,
    PyValueError,
    "Bad input or a failed computation; the message says what and where."
);

fn err(e: impl std::fmt::Display) -> PyErr {
    FShapeError::new_err(e.to_string())
}

/// A functional shape: vertices (n × d, d = 2 or 3), cells (m × 2
/// segments or m × 3 triangles, vertex indices) and an optional signal
/// (one value per vertex). Immutable; every value is checked on creation.
#[pyclass(name = "FShape", module = "fshape", frozen)]
#[derive(Clone)]
struct PyFShape {
    inner: FShape,
}

#[pymethods]
impl PyFShape {
    #[new]
    #[pyo3(signature = (points, cells, signal = None))]
    fn new(
        points: PyArrayLike2<'_, f64, AllowTypeChange>,
        cells: PyArrayLike2<'_, i64, AllowTypeChange>,
        signal: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
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
        let signal = signal.map(|s| s.as_array().iter().copied().collect());
        let inner = FShape::try_new(dim, kind, p.iter().copied().collect(), flat_cells, signal).map_err(err)?;
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

    /// The signal (one value per vertex), or None.
    #[getter]
    fn signal<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.inner.signal().map(|f| PyArray1::from_slice(py, f))
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

    /// The same shape with another signal (or none).
    #[pyo3(signature = (signal))]
    fn with_signal(&self, signal: Option<PyArrayLike1<'_, f64, AllowTypeChange>>) -> PyResult<Self> {
        let f = signal.map(|s| s.as_array().iter().copied().collect());
        Ok(PyFShape { inner: self.inner.clone().with_signal(f).map_err(err)? })
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
            if self.inner.signal().is_some() { "with a signal" } else { "no signal" }
        )
    }

    fn __eq__(&self, other: &Self) -> bool {
        self.inner == other.inner
    }
}

fn rows<'py>(py: Python<'py>, flat: Vec<f64>, d: usize) -> Bound<'py, numpy::PyArray2<f64>> {
    Array2::from_shape_vec((flat.len() / d.max(1), d), flat).expect("whole rows").into_pyarray(py)
}

fn shape_of(s: &Bound<'_, PyAny>) -> PyResult<FShape> {
    Ok(s.cast::<PyFShape>().map_err(|_| err("expected an fshape.FShape"))?.get().inner.clone())
}

/// Reads a mesh: PLY, OBJ, VTK legacy, GIfTI (.gii) or a FreeSurfer
/// surface (lh.pial…), optionally gzipped. The signal is the per-vertex
/// scalar named `signal_name` (default: `signal`, if present).
#[pyfunction]
#[pyo3(signature = (path, signal_name = None))]
fn read_mesh(py: Python<'_>, path: PathBuf, signal_name: Option<String>) -> PyResult<PyFShape> {
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
fn write_mesh(
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
fn read_signal<'py>(py: Python<'py>, path: PathBuf) -> PyResult<(String, Bound<'py, PyArray1<f64>>)> {
    let c = py.detach(|| io::read_signal(&path)).map_err(err)?;
    Ok((c.name, c.values.into_pyarray(py)))
}

/// Writes a per-vertex signal in the format its name says (.csv, .gii,
/// .mgh/.mgz, or a FreeSurfer name such as lh.thickness, which records the
/// surface's triangle count `faces`).
#[pyfunction]
#[pyo3(signature = (path, values, name = "signal", faces = 0))]
fn write_signal(
    py: Python<'_>,
    path: PathBuf,
    values: PyArrayLike1<'_, f64, AllowTypeChange>,
    name: &str,
    faces: usize,
) -> PyResult<()> {
    let v: Vec<f64> = values.as_array().iter().copied().collect();
    py.detach(|| io::write_signal(&path, name, &v, faces)).map_err(err)
}

/// The squared signal norm fᵀ D_s(x) f of the shape's signal: `norm` is
/// "l2-lumped", "l2" or "h1" (P1 mass + length² × stiffness).
#[pyfunction]
#[pyo3(signature = (shape, norm = "h1", length = 1.0))]
fn signal_norm(py: Python<'_>, shape: &Bound<'_, PyAny>, norm: &str, length: f64) -> PyResult<f64> {
    let s = shape_of(shape)?;
    let norm = fshape_fem::Norm::parse(norm, length).map_err(err)?;
    let f = s.signal().ok_or_else(|| err("the shape has no signal"))?.to_vec();
    py.detach(|| fshape_fem::SignalNorm::try_new(&s, norm).and_then(|n| n.quadratic(s.points(), &f))).map_err(err)
}

/// The attachment's inputs: the two shapes and the kernel parsed as
/// `fshape distance` parses it.
fn attachment_inputs(
    source: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    (geom, grass, signal): (&str, &str, Option<&str>),
) -> PyResult<(FShape, FShape, fshape_varifold::VarifoldKernel)> {
    let kernel = fshape_varifold::VarifoldKernel::parse(geom, signal, grass).map_err(err)?;
    Ok((shape_of(source)?, shape_of(target)?, kernel))
}

fn distance_dict<'py>(py: Python<'py>, d: &fshape_varifold::Distance) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("value", d.value)?;
    out.set_item("xx", d.xx)?;
    out.set_item("xy", d.xy)?;
    out.set_item("yy", d.yy)?;
    Ok(out)
}

/// The data attachment A(X, Y) = <X,X> - 2<X,Y> + <Y,Y> (a squared
/// distance) and its inner products, as `fshape distance` computes it:
/// kernels as there ("gaussian:0.1", "gaussian:0.5", "binet"…).
#[pyfunction]
#[pyo3(signature = (source, target, kernel_geom, kernel_grass, kernel_signal = None))]
fn attachment<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    target: &Bound<'py, PyAny>,
    kernel_geom: &str,
    kernel_grass: &str,
    kernel_signal: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let (x, y, k) = attachment_inputs(source, target, (kernel_geom, kernel_grass, kernel_signal))?;
    let d = py.detach(|| fshape_varifold::Attachment::new(&y, k).and_then(|a| a.eval(&x))).map_err(err)?;
    distance_dict(py, &d)
}

/// A(X, Y) as `attachment`, with its gradient in the source's vertices
/// (n × d) and signal (n): returns (values, grad_points, grad_signal).
#[pyfunction]
#[pyo3(signature = (source, target, kernel_geom, kernel_grass, kernel_signal = None))]
#[allow(clippy::type_complexity)]
fn attachment_grad<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    target: &Bound<'py, PyAny>,
    kernel_geom: &str,
    kernel_grass: &str,
    kernel_signal: Option<&str>,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, numpy::PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
    let (x, y, k) = attachment_inputs(source, target, (kernel_geom, kernel_grass, kernel_signal))?;
    let (d, g) = py.detach(|| fshape_varifold::Attachment::new(&y, k).and_then(|a| a.eval_grad(&x))).map_err(err)?;
    Ok((distance_dict(py, &d)?, rows(py, g.points, x.dim()), g.signal.into_pyarray(py)))
}

/// The match quality of `shape` against `target` (as in every result):
/// closest-point distances as fractions of the target's diagonal, the share
/// of the target within 1 % of it, the signal error as a fraction of the
/// target signal's range.
#[pyfunction]
fn quality<'py>(py: Python<'py>, shape: &Bound<'py, PyAny>, target: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let (x, y) = (shape_of(shape)?, shape_of(target)?);
    let q = py.detach(|| fshape_match::quality(&x, &y)).map_err(err)?;
    to_py(py, &q)
}

fn to_py<'py>(py: Python<'py>, v: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    pythonize::pythonize(py, v).map_err(|e| err(format!("converting a result: {e}")))
}

/// A checked configuration, as a `fshape match` TOML file holds it:
/// `Config(tables)` from the tables as nested dicts, `Config.from_toml(text)`
/// from TOML text, `Config.read(path)` from a file.
#[pyclass(name = "Config", module = "fshape", frozen)]
struct PyConfig {
    inner: Config,
}

#[pymethods]
impl PyConfig {
    #[new]
    fn new(tables: &Bound<'_, PyDict>) -> PyResult<PyConfig> {
        let value: serde_json::Value =
            pythonize::depythonize(tables.as_any()).map_err(|e| err(format!("configuration: {e}")))?;
        let inner = serde_path_to_error::deserialize(value).map_err(|e| {
            let key = e.path().to_string();
            err(MatchError::ConfigSyntax {
                key: if key == "." { String::new() } else { key },
                message: e.into_inner().to_string(),
            })
        })?;
        Ok(PyConfig { inner })
    }

    /// The configuration in TOML text (errors name the key and line).
    #[staticmethod]
    fn from_toml(text: &str) -> PyResult<PyConfig> {
        Ok(PyConfig { inner: Config::parse(text).map_err(err)? })
    }

    /// The configuration in a TOML file (errors name the file).
    #[staticmethod]
    fn read(path: PathBuf) -> PyResult<PyConfig> {
        Ok(PyConfig { inner: Config::read(&path).map_err(err)? })
    }

    /// Every key, defaults included, as TOML text.
    fn to_toml(&self) -> String {
        self.inner.to_toml()
    }

    /// Every key, defaults included, as nested dicts.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &self.inner)
    }

    fn __repr__(&self) -> String {
        format!("fshape.Config.from_toml({:?})", self.inner.to_toml())
    }
}

/// A configuration from a `Config`, a dict (the TOML file's tables as
/// nested dicts) or a path to a TOML file. A string is always a path: TOML
/// text goes through `Config.from_toml`, never guessed.
fn config_of(obj: &Bound<'_, PyAny>) -> PyResult<Config> {
    if let Ok(c) = obj.cast::<PyConfig>() {
        return Ok(c.get().inner.clone());
    }
    if let Ok(d) = obj.cast::<PyDict>() {
        return Ok(PyConfig::new(d)?.inner);
    }
    if let Ok(p) = obj.extract::<PathBuf>() {
        if !p.exists() {
            let text = p.to_string_lossy();
            let hint = if text.contains('\n') || text.contains('[') {
                "; TOML text goes through fshape.Config.from_toml(text)"
            } else {
                ""
            };
            let shown: String = text.chars().take(60).collect();
            return Err(err(format!("config: no file {shown:?}{hint}")));
        }
        return Config::read(&p).map_err(err);
    }
    Err(err("config: expected a fshape.Config, a dict of the TOML tables or a path to a TOML file"))
}

/// The geodesic as arrays: points (T × n × d), signals (T × n) at `times`.
fn geodesic<'py>(
    py: Python<'py>,
    traj: &fshape_shoot::Trajectory,
    dim: usize,
    times: &[f64],
) -> PyResult<Bound<'py, PyDict>> {
    let mut points = Vec::new();
    let mut signals = Vec::new();
    let mut n = 0;
    for &t in times {
        let (x, f) = traj.at(t);
        n = f.len();
        points.extend(x);
        signals.extend(f);
    }
    let d = PyDict::new(py);
    d.set_item("times", PyArray1::from_slice(py, times))?;
    d.set_item("points", Array3::from_shape_vec((times.len(), n, dim), points).map_err(err)?.into_pyarray(py))?;
    d.set_item("signals", Array2::from_shape_vec((times.len(), n), signals).map_err(err)?.into_pyarray(py))?;
    d.set_item("hamiltonian", PyArray1::from_slice(py, &traj.hamiltonian))?;
    Ok(d)
}

fn node_times(steps: usize) -> Vec<f64> {
    (0..=steps).map(|k| k as f64 / steps as f64).collect()
}

/// Shoots the geodesic from `shape` with momenta `p0` (n × d) and `pf` (n;
/// zeros if None) under the model of `config` (a dict, a TOML path or
/// text; `normalize` must be false, as for `fshape shoot`). Returns the
/// states at every time step.
#[pyfunction]
#[pyo3(signature = (shape, p0, config, pf = None))]
fn shoot<'py>(
    py: Python<'py>,
    shape: &Bound<'py, PyAny>,
    p0: PyArrayLike2<'py, f64, AllowTypeChange>,
    config: &Bound<'py, PyAny>,
    pf: Option<PyArrayLike1<'py, f64, AllowTypeChange>>,
) -> PyResult<Bound<'py, PyDict>> {
    let s = shape_of(shape)?;
    let config = config_of(config)?;
    if config.model.normalize {
        return Err(err(
            "config: [model] normalize = true makes the weights relative to a registration's target, and shooting has \
             none: set normalize = false, or shoot with the weights a registration used (its result's config)",
        ));
    }
    let (n, dim) = (s.n_vertices(), s.dim());
    let p0a = p0.as_array();
    if p0a.shape() != [n, dim] {
        return Err(err(format!("p0: shape {:?}, but the shape has {n} vertices in {dim}-D", p0a.shape())));
    }
    let p0: Vec<f64> = p0a.iter().copied().collect();
    let pf: Vec<f64> = match pf {
        Some(a) => {
            let v: Vec<f64> = a.as_array().iter().copied().collect();
            if v.len() != n {
                return Err(err(format!("pf: {} values, but the shape has {n} vertices", v.len())));
            }
            v
        }
        None => vec![0.0; n],
    };
    let model = config.model().map_err(err)?;
    let steps = model.steps();
    let traj = py.detach(|| fshape_shoot::Problem::new(&s, model).and_then(|p| p.shoot(&p0, &pf))).map_err(err)?;
    geodesic(py, &traj, dim, &node_times(steps))
}

/// Calls the Python progress callback with a dict per event; a callback
/// returning True stops the run (as scipy.optimize's callbacks), one
/// raising stops it and re-raises.
struct Progress {
    callback: Option<Py<PyAny>>,
    error: Option<PyErr>,
    stopped: bool,
}

impl Progress {
    fn new(callback: Option<Py<PyAny>>) -> Progress {
        Progress { callback, error: None, stopped: false }
    }

    fn send(&mut self, fill: impl FnOnce(&Bound<'_, PyDict>) -> PyResult<()>) -> Control {
        Python::attach(|py| {
            // Ctrl-C reaches Python between iterations.
            if let Err(e) = py.check_signals() {
                self.error = Some(e);
                return Control::Stop;
            }
            let Some(cb) = &self.callback else { return Control::Continue };
            let event = PyDict::new(py);
            let r = fill(&event).and_then(|()| cb.call1(py, (event,)));
            match r {
                Ok(v) if v.bind(py).extract::<bool>().ok() == Some(true) => {
                    self.stopped = true;
                    Control::Stop
                }
                Ok(_) => Control::Continue,
                Err(e) => {
                    self.error = Some(e);
                    Control::Stop
                }
            }
        })
    }

    /// An atlas's outcome as Python sees it: an error if the callback
    /// raised or stopped it (naming the checkpoint that resumes it).
    fn finish(self, outcome: Outcome, checkpoint: Option<&Path>) -> PyResult<()> {
        if let Some(e) = self.error {
            return Err(e);
        }
        if outcome == Outcome::Interrupted || self.stopped {
            let resume = match checkpoint {
                Some(path) => format!("; the same call with checkpoint={} resumes it", path.display()),
                None => String::new(),
            };
            return Err(err(format!("stopped by the progress callback (it returned True){resume}")));
        }
        Ok(())
    }

    /// The callback's exception or Ctrl-C, re-raised.
    fn raised(&mut self) -> PyResult<()> {
        match self.error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

impl Observer for Progress {
    fn stage_started(&mut self, stage: usize, stages: usize, spec: &StageSpec, done: usize) -> Control {
        let kernel = spec.label.clone();
        self.send(|d| {
            d.set_item("event", "stage")?;
            d.set_item("stage", stage)?;
            d.set_item("stages", stages)?;
            d.set_item("kernel_geom", kernel)?;
            d.set_item("done", done)
        })
    }

    fn iteration(&mut self, stage: usize, record: &Iteration) -> Control {
        let r = record.clone();
        self.send(|d| {
            d.set_item("event", "iteration")?;
            d.set_item("stage", stage)?;
            d.set_item("iteration", r.iteration)?;
            d.set_item("value", r.value)?;
            d.set_item("energy", r.energy)?;
            d.set_item("attachment", r.attachment)?;
            d.set_item("step", r.step)
        })
    }

    fn stage_finished(&mut self, stage: usize, record: &StageRecord) {
        let reason = record.reason.clone();
        self.send(|d| {
            d.set_item("event", "stage_finished")?;
            d.set_item("stage", stage)?;
            d.set_item("reason", reason)
        });
    }
}

fn stage_templates(list: Option<Vec<Bound<'_, PyAny>>>) -> PyResult<Option<Vec<Option<FShape>>>> {
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
/// Returns a dict: `stopped` (whether the callback ended the run before
/// its end), `p0` (n × d), `pf` (n), `energies`, `quality` and
/// `initial_quality` (how close the matched shape and the template are to
/// the target), `stages` (every iteration's J), `iterations`,
/// `evaluations`, `seconds`, `geodesic` (`times`, `points` T × n × d,
/// `signals` T × n, `hamiltonian`), `matched` (the FShape at t = 1), and
/// `config` (the configuration with the weights used, for `shoot`).
#[pyfunction(name = "match")]
#[pyo3(signature = (source, target, config, progress = None, stage_templates = None, times = None, checkpoint = None))]
#[expect(clippy::too_many_arguments, reason = "one per keyword argument of the Python call")]
fn match_shapes<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    target: &Bound<'py, PyAny>,
    config: &Bound<'py, PyAny>,
    progress: Option<Py<PyAny>>,
    stage_templates: Option<Vec<Bound<'py, PyAny>>>,
    times: Option<Vec<f64>>,
    checkpoint: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let (x, y) = (shape_of(source)?, shape_of(target)?);
    let config = config_of(config)?;
    let templates = self::stage_templates(stage_templates)?;
    let times = times.unwrap_or_else(|| vec![0.0, 0.25, 0.5, 0.75, 1.0]);
    if let Some(t) = times.iter().find(|t| !(0.0..=1.0).contains(*t)) {
        return Err(err(format!("times: {t} is outside [0, 1]")));
    }
    let mut observer = Progress::new(progress);
    let run = py.detach(|| -> Result<_, MatchError> {
        let mut session = fshape_match::Session::new(&x, &y, &config)?;
        if let Some(t) = templates {
            session = session.with_stage_templates(t)?;
        }
        if let Some(path) = &checkpoint {
            // The same call continues a stopped run.
            if path.exists() {
                session = session.resume_from_file(path)?;
            }
            session = session.with_checkpoint_file(path);
        }
        let outcome = session.run(&mut observer)?;
        // A callback that returned True ends the run with its result so
        // far; one that raised (or Ctrl-C) gets no result.
        let result = match outcome {
            Outcome::Finished => Some(session.result()?),
            Outcome::Interrupted if observer.error.is_none() => session.result_so_far()?,
            Outcome::Interrupted => None,
        };
        let used = config.resolved(session.plan().scales);
        let template = session.problem().template().clone();
        Ok((result, used, template))
    });
    let (result, used, template) = run.map_err(err)?;
    observer.raised()?;
    let Some(r) = result else {
        return Err(err("stopped by the progress callback before the first iteration: there is no result yet"));
    };
    let d = PyDict::new(py);
    d.set_item("stopped", !r.finished)?;
    let dim = template.dim();
    d.set_item("p0", rows(py, r.p0.clone(), dim))?;
    d.set_item("pf", PyArray1::from_slice(py, &r.pf))?;
    d.set_item("energies", to_py(py, &r.energies)?)?;
    d.set_item("quality", to_py(py, &r.quality)?)?;
    d.set_item("initial_quality", to_py(py, &r.initial_quality)?)?;
    d.set_item("stages", to_py(py, &r.stages)?)?;
    d.set_item("iterations", r.iterations)?;
    d.set_item("evaluations", r.evaluations)?;
    d.set_item("seconds", r.seconds)?;
    d.set_item("geodesic", geodesic(py, &r.trajectory, dim, &times)?)?;
    let (x1, f1) = r.trajectory.at(1.0);
    let matched = template.with_points(x1).and_then(|s| s.with_signal(Some(f1))).map_err(err)?;
    d.set_item("matched", PyFShape { inner: matched })?;
    d.set_item("config", to_py(py, &used)?)?;
    Ok(d)
}

/// Estimates a metamorphosis atlas of `subjects` (FShapes) as `fshape
/// atlas` does: `template` is the initial template (default: the first
/// subject; without a signal it takes the subjects' mean), `config` a
/// dict, TOML path or text, `progress` and `checkpoint` as for `match`.
///
/// Returns a dict: `template` (the estimated FShape), `template_momenta`
/// (hypertemplate model, else None), `subjects` (per subject: `p0`, `pf`,
/// `energies`, `quality`, `template_quality`, `initial_attachment`,
/// `geodesic`), `energies` (means), `stages`, `iterations`, `evaluations`,
/// `seconds`.
#[pyfunction]
#[pyo3(signature = (subjects, config, template = None, progress = None, stage_templates = None, checkpoint = None))]
fn atlas<'py>(
    py: Python<'py>,
    subjects: Vec<Bound<'py, PyAny>>,
    config: &Bound<'py, PyAny>,
    template: Option<&Bound<'py, PyAny>>,
    progress: Option<Py<PyAny>>,
    stage_templates: Option<Vec<Bound<'py, PyAny>>>,
    checkpoint: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
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
    let run = py.detach(|| -> Result<_, MatchError> {
        let start = fshape_match::atlas::initial_template(start, &subjects)?;
        let mut atlas = fshape_match::Atlas::new(&start, &subjects, &config)?;
        if let Some(t) = templates {
            atlas = atlas.with_stage_templates(t)?;
        }
        if let Some(path) = &checkpoint {
            // The same call continues a stopped run.
            if path.exists() {
                atlas = atlas.resume_from_file(path)?;
            }
            atlas = atlas.with_checkpoint_file(path);
        }
        let outcome = atlas.run(&mut observer)?;
        let result = if outcome == Outcome::Finished { Some(atlas.result()?) } else { None };
        let steps = atlas.plan().model.steps();
        Ok((outcome, result, steps))
    });
    let (outcome, result, steps) = run.map_err(err)?;
    observer.finish(outcome, checkpoint.as_deref())?;
    let r = result.expect("a finished run has a result");
    let dim = r.template.dim();
    let d = PyDict::new(py);
    d.set_item("template", PyFShape { inner: r.template.clone() })?;
    d.set_item("template_momenta", r.template_momenta.as_ref().map(|p| rows(py, p.clone(), dim)))?;
    let list = PyList::empty(py);
    for s in &r.subjects {
        let e = PyDict::new(py);
        e.set_item("p0", rows(py, s.p0.clone(), dim))?;
        e.set_item("pf", PyArray1::from_slice(py, &s.pf))?;
        e.set_item("energies", to_py(py, &s.energies)?)?;
        e.set_item("quality", to_py(py, &s.quality)?)?;
        e.set_item("template_quality", to_py(py, &s.template_quality)?)?;
        e.set_item("initial_attachment", s.initial_attachment)?;
        e.set_item("geodesic", geodesic(py, &s.trajectory, dim, &node_times(steps))?)?;
        list.append(e)?;
    }
    d.set_item("subjects", list)?;
    d.set_item("energies", to_py(py, &r.energies)?)?;
    d.set_item("stages", to_py(py, &r.stages)?)?;
    d.set_item("iterations", r.iterations)?;
    d.set_item("evaluations", r.evaluations)?;
    d.set_item("seconds", r.seconds)?;
    Ok(d)
}

/// Functional shapes and their metamorphoses (Charon, Charlier & Trouvé).
#[pymodule]
fn fshape(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FShapeError", m.py().get_type::<FShapeError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<PyFShape>()?;
    m.add_class::<PyConfig>()?;
    m.add_function(wrap_pyfunction!(read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(write_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(read_signal, m)?)?;
    m.add_function(wrap_pyfunction!(write_signal, m)?)?;
    m.add_function(wrap_pyfunction!(signal_norm, m)?)?;
    m.add_function(wrap_pyfunction!(attachment, m)?)?;
    m.add_function(wrap_pyfunction!(attachment_grad, m)?)?;
    m.add_function(wrap_pyfunction!(quality, m)?)?;
    m.add_function(wrap_pyfunction!(shoot, m)?)?;
    m.add_function(wrap_pyfunction!(match_shapes, m)?)?;
    m.add_function(wrap_pyfunction!(atlas, m)?)?;
    Ok(())
}
