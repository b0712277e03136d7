//! Shooting a geodesic from momenta, and a geodesic as arrays.

use numpy::ndarray::{Array2, Array3};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArrayLike2};
use pyo3::prelude::*;

use crate::config::config_of;
use crate::err;
use crate::results::Geodesic;
use crate::shape::shape_of;

/// The geodesic as arrays: points (T × n × d), signals (T × n, or T × n × k
/// with k signal channels) at `times`.
pub(crate) fn geodesic<'py>(
    py: Python<'py>,
    traj: &fshape_shoot::Trajectory,
    dim: usize,
    times: &[f64],
) -> PyResult<Bound<'py, Geodesic>> {
    geodesic_labelled(py, traj, dim, times, times)
}

/// [`geodesic`] with `labels` (one per time, e.g. ages) as its `times`.
pub(crate) fn geodesic_labelled<'py>(
    py: Python<'py>,
    traj: &fshape_shoot::Trajectory,
    dim: usize,
    times: &[f64],
    labels: &[f64],
) -> PyResult<Bound<'py, Geodesic>> {
    let mut points = Vec::new();
    let mut signals = Vec::new();
    let (mut n, mut k) = (0, 1);
    for &t in times {
        let (x, f) = traj.at(t);
        n = x.len() / dim.max(1);
        k = f.len().checked_div(n).unwrap_or(1).max(1);
        points.extend(x);
        signals.extend(f);
    }
    // T × n, or T × n × k with several signal channels.
    let signals = if k == 1 {
        Array2::from_shape_vec((times.len(), n), signals).map_err(err)?.into_pyarray(py).into_any()
    } else {
        Array3::from_shape_vec((times.len(), n, k), signals).map_err(err)?.into_pyarray(py).into_any()
    };
    Bound::new(
        py,
        Geodesic {
            times: PyArray1::from_slice(py, labels).into_any().unbind(),
            points: Array3::from_shape_vec((times.len(), n, dim), points)
                .map_err(err)?
                .into_pyarray(py)
                .into_any()
                .unbind(),
            signals: signals.unbind(),
            hamiltonian: PyArray1::from_slice(py, &traj.hamiltonian).into_any().unbind(),
        },
    )
}

pub(crate) fn node_times(steps: usize) -> Vec<f64> {
    (0..=steps).map(|k| k as f64 / steps as f64).collect()
}

/// The n × d array `a` named `what` as a flat vector, for `shape`.
fn vector_field(what: &str, s: &fshape_mesh::FShape, a: PyArrayLike2<'_, f64, AllowTypeChange>) -> PyResult<Vec<f64>> {
    let (n, dim) = (s.n_vertices(), s.dim());
    let a = a.as_array();
    if a.shape() != [n, dim] {
        return Err(err(format!("{what}: shape {:?}, but the shape has {n} vertices in {dim}-D", a.shape())));
    }
    Ok(a.iter().copied().collect())
}

/// The array `a` named `what` of n values, or n × k for a shape of k
/// signal channels (row by row), as a flat vector; zeros if None.
fn signal_field(
    what: &str,
    s: &fshape_mesh::FShape,
    a: Option<numpy::PyArrayLikeDyn<'_, f64, AllowTypeChange>>,
) -> PyResult<Vec<f64>> {
    let (n, k) = (s.n_vertices(), s.n_channels().max(1));
    let Some(a) = a else { return Ok(vec![0.0; n * k]) };
    let a = a.as_array();
    let fits = match a.shape() {
        [m] => k == 1 && *m == n,
        [m, c] => *m == n && *c == k,
        _ => false,
    };
    if !fits {
        let want = if k == 1 { format!("({n},)") } else { format!("({n}, {k})") };
        return Err(err(format!("{what}: shape {:?}, but the shape wants {want}", a.shape())));
    }
    Ok(a.iter().copied().collect())
}

/// Shoots the geodesic from `shape` with momenta `p0` (n × d) and `pf` (n,
/// or n × k for a shape of k maps; zeros if None) under the model of `config` (a dict, a TOML path or
/// text; `normalize` must be false, as for `fshape shoot`). Returns the
/// states at every time step.
#[pyfunction]
#[pyo3(signature = (shape, p0, config, pf = None))]
pub(crate) fn shoot<'py>(
    py: Python<'py>,
    shape: &Bound<'py, PyAny>,
    p0: PyArrayLike2<'py, f64, AllowTypeChange>,
    config: &Bound<'py, PyAny>,
    pf: Option<numpy::PyArrayLikeDyn<'py, f64, AllowTypeChange>>,
) -> PyResult<Bound<'py, Geodesic>> {
    let s = shape_of(shape)?;
    let config = config_of(config)?;
    if config.model.normalize {
        return Err(err(
            "config: [model] normalize = true makes the weights relative to a registration's target, and shooting has \
             none: set normalize = false, or shoot with the weights a registration used (its result's config)",
        ));
    }
    let dim = s.dim();
    let p0 = vector_field("p0", &s, p0)?;
    let pf = signal_field("pf", &s, pf)?;
    let model = config.model().map_err(err)?;
    let steps = model.steps();
    let traj = py.detach(|| fshape_shoot::Problem::new(&s, model).and_then(|p| p.shoot(&p0, &pf))).map_err(err)?;
    geodesic(py, &traj, dim, &node_times(steps))
}

/// Carries the momenta `beta` (n × d) and `beta_f` (n, or n × k; zeros if
/// None) along the geodesic from `shape` with momenta `p0` and `pf`, by
/// parallel transport (fshape-shoot's fanning scheme, first order in the
/// step): from its start to its end, or with `back` from its end to its
/// start. Returns the carried (beta, beta_f), beta_f of n values for one
/// map, n × k for k.
#[pyfunction]
#[pyo3(signature = (shape, p0, config, beta, pf = None, beta_f = None, back = false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn transport<'py>(
    py: Python<'py>,
    shape: &Bound<'py, PyAny>,
    p0: PyArrayLike2<'py, f64, AllowTypeChange>,
    config: &Bound<'py, PyAny>,
    beta: PyArrayLike2<'py, f64, AllowTypeChange>,
    pf: Option<numpy::PyArrayLikeDyn<'py, f64, AllowTypeChange>>,
    beta_f: Option<numpy::PyArrayLikeDyn<'py, f64, AllowTypeChange>>,
    back: bool,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let s = shape_of(shape)?;
    let config = config_of(config)?;
    if config.model.normalize {
        return Err(err(
            "config: [model] normalize = true makes the weights relative to a registration's target, and transport \
             has none: set normalize = false, or use the weights a registration used (its result's config)",
        ));
    }
    let p0 = vector_field("p0", &s, p0)?;
    let pf = signal_field("pf", &s, pf)?;
    let beta = vector_field("beta", &s, beta)?;
    let beta_f = signal_field("beta_f", &s, beta_f)?;
    let model = config.model().map_err(err)?;
    let carried = py
        .detach(|| {
            let problem = fshape_shoot::Problem::new(&s, model)?;
            let traj = problem.shoot(&p0, &pf)?;
            if back { problem.transport_back(&traj, &beta, &beta_f) } else { problem.transport(&traj, &beta, &beta_f) }
        })
        .map_err(err)?;
    let (n, dim, k) = (s.n_vertices(), s.dim(), s.n_channels().max(1));
    let momentum = Array2::from_shape_vec((n, dim), carried.momentum).map_err(err)?.into_pyarray(py).into_any();
    let signal = if k == 1 {
        PyArray1::from_vec(py, carried.signal_momentum).into_any()
    } else {
        Array2::from_shape_vec((n, k), carried.signal_momentum).map_err(err)?.into_pyarray(py).into_any()
    };
    Ok((momentum, signal))
}
