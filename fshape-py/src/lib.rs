//! The `fshape` Python package: the library's workflow on numpy arrays.
//!
//! Every function takes and returns numpy arrays (`float64` coordinates
//! and signals, `int64` cells), raises `fshape.FShapeError` with the
//! library's own message on bad input, and releases the GIL while it
//! computes, so other Python threads run meanwhile. The type stubs are in
//! `fshape.pyi` beside this crate.

mod config;
mod conversions;
mod io;
mod measures;
mod progress;
mod registration;
mod report;
mod shape;
mod shoot;
mod stats;
mod transfer;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

pyo3::create_exception!(
    fshape,
    FShapeError,
    PyValueError,
    "Bad input or a failed computation; the message says what and where."
);

fn err(e: impl std::fmt::Display) -> PyErr {
    FShapeError::new_err(e.to_string())
}

/// Functional shapes and their metamorphoses (Charon, Charlier & Trouvé).
#[pymodule]
fn fshape(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FShapeError", m.py().get_type::<FShapeError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<shape::PyFShape>()?;
    m.add_class::<config::PyConfig>()?;
    m.add_class::<transfer::PyCorrespondence>()?;
    m.add_function(wrap_pyfunction!(io::read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_signal, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_mask, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_label, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_label, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_signal, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_parcellation, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_cifti, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_cifti, m)?)?;
    m.add_function(wrap_pyfunction!(measures::signal_norm, m)?)?;
    m.add_function(wrap_pyfunction!(measures::attachment, m)?)?;
    m.add_function(wrap_pyfunction!(measures::attachment_grad, m)?)?;
    m.add_function(wrap_pyfunction!(measures::quality, m)?)?;
    m.add_function(wrap_pyfunction!(shoot::shoot, m)?)?;
    m.add_function(wrap_pyfunction!(registration::match_shapes, m)?)?;
    m.add_function(wrap_pyfunction!(registration::atlas, m)?)?;
    m.add_function(wrap_pyfunction!(stats::stats, m)?)?;
    m.add_function(wrap_pyfunction!(report::report, m)?)?;
    Ok(())
}
