//! Measures on shapes: the signal norm, the data attachment and its
//! gradient, the match quality.

use fshape_mesh::FShape;
use numpy::{IntoPyArray, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::conversions::{rows, to_py};
use crate::err;
use crate::shape::shape_of;

/// The squared signal norm fᵀ D_s(x) f of the shape's signal (summed over
/// its maps when it has several): `norm` is "l2-lumped", "l2" or "h1" (P1
/// mass + length² × stiffness).
#[pyfunction]
#[pyo3(signature = (shape, norm = "h1", length = 1.0))]
pub(crate) fn signal_norm(py: Python<'_>, shape: &Bound<'_, PyAny>, norm: &str, length: f64) -> PyResult<f64> {
    let s = shape_of(shape)?;
    let norm = fshape_fem::Norm::parse(norm, length).map_err(err)?;
    let k = s.n_channels();
    let f = s.signal().ok_or_else(|| err("the shape has no signal"))?.to_vec();
    py.detach(|| {
        let n = fshape_fem::SignalNorm::try_new(&s, norm)?;
        if k == 1 {
            return n.quadratic(s.points(), &f);
        }
        (0..k).map(|c| n.quadratic(s.points(), &f.iter().skip(c).step_by(k).copied().collect::<Vec<_>>())).sum()
    })
    .map_err(err)
}

/// The attachment's inputs: the two shapes and the kernel parsed as
/// `fshape distance` parses it.
pub(crate) fn attachment_inputs(
    source: &Bound<'_, PyAny>,
    target: &Bound<'_, PyAny>,
    (geom, grass, signal): (&str, &str, Option<&str>),
) -> PyResult<(FShape, FShape, fshape_varifold::VarifoldKernel)> {
    let kernel = fshape_varifold::VarifoldKernel::parse(geom, signal, grass).map_err(err)?;
    Ok((shape_of(source)?, shape_of(target)?, kernel))
}

pub(crate) fn distance_dict<'py>(py: Python<'py>, d: &fshape_varifold::Distance) -> PyResult<Bound<'py, PyDict>> {
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
pub(crate) fn attachment<'py>(
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
/// (n × d) and signal (n, or n × k with k maps): returns (values,
/// grad_points, grad_signal).
#[pyfunction]
#[pyo3(signature = (source, target, kernel_geom, kernel_grass, kernel_signal = None))]
#[allow(clippy::type_complexity)]
pub(crate) fn attachment_grad<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    target: &Bound<'py, PyAny>,
    kernel_geom: &str,
    kernel_grass: &str,
    kernel_signal: Option<&str>,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, numpy::PyArray2<f64>>, Bound<'py, numpy::PyUntypedArray>)> {
    let (x, y, k) = attachment_inputs(source, target, (kernel_geom, kernel_grass, kernel_signal))?;
    let (d, g) = py.detach(|| fshape_varifold::Attachment::new(&y, k).and_then(|a| a.eval_grad(&x))).map_err(err)?;
    let signal = match x.n_channels() {
        0 | 1 => g.signal.into_pyarray(py).as_untyped().clone(),
        k => rows(py, g.signal, k).as_untyped().clone(),
    };
    Ok((distance_dict(py, &d)?, rows(py, g.points, x.dim()), signal))
}

/// The match quality of `shape` against `target` (as in every result):
/// closest-point distances as fractions of the target's diagonal, the share
/// of the target within 1 % of it, the signal error as a fraction of the
/// target signal's range.
#[pyfunction]
pub(crate) fn quality<'py>(
    py: Python<'py>,
    shape: &Bound<'py, PyAny>,
    target: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let (x, y) = (shape_of(shape)?, shape_of(target)?);
    let q = py.detach(|| fshape_match::quality(&x, &y)).map_err(err)?;
    to_py(py, &q)
}
