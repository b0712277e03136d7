//! The `fshape` Python package: the library's workflow on numpy arrays.
//!
//! Every function takes and returns numpy arrays (`float64` coordinates
//! and signals, `int64` cells), raises `fshape.FShapeError` with the
//! library's own message (a subclass by kind: `InputError`, `ConfigError`,
//! `CheckpointError`, `DivergenceError`; see `errors`), and releases the GIL while it
//! computes, so other Python threads run meanwhile. This crate is the
//! compiled module `fshape._fshape`; the package around it
//! (`python/fshape/__init__.py`) re-exports it with the annotations'
//! aliases, and its stub is `python/fshape/__init__.pyi`.

mod config;
mod conversions;
mod errors;
mod io;
mod measures;
mod progress;
mod registration;
mod report;
mod results;
mod shape;
mod shoot;
mod stats;
mod transfer;

use pyo3::prelude::*;

use errors::err;

/// Functional shapes and their metamorphoses (Charon, Charlier & Trouvé).
#[pymodule]
#[pyo3(name = "_fshape")]
fn fshape(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FShapeError", m.py().get_type::<errors::FShapeError>())?;
    m.add("InputError", m.py().get_type::<errors::InputError>())?;
    m.add("ConfigError", m.py().get_type::<errors::ConfigError>())?;
    m.add("CheckpointError", m.py().get_type::<errors::CheckpointError>())?;
    m.add("DivergenceError", m.py().get_type::<errors::DivergenceError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<shape::PyFShape>()?;
    m.add_class::<config::PyConfig>()?;
    m.add_class::<transfer::PyCorrespondence>()?;
    results::add(m)?;
    m.add_function(wrap_pyfunction!(io::read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_signal, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_mask, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_label, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_label, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_signal, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_parcellation, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_parcellation, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_cifti, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_cifti, m)?)?;
    m.add_function(wrap_pyfunction!(measures::signal_norm, m)?)?;
    m.add_function(wrap_pyfunction!(measures::attachment, m)?)?;
    m.add_function(wrap_pyfunction!(measures::attachment_grad, m)?)?;
    m.add_function(wrap_pyfunction!(measures::quality, m)?)?;
    m.add_function(wrap_pyfunction!(shoot::shoot, m)?)?;
    m.add_function(wrap_pyfunction!(shoot::transport, m)?)?;
    m.add_function(wrap_pyfunction!(registration::match_shapes, m)?)?;
    m.add_function(wrap_pyfunction!(registration::atlas, m)?)?;
    m.add_function(wrap_pyfunction!(registration::regress, m)?)?;
    m.add_function(wrap_pyfunction!(stats::stats, m)?)?;
    m.add_function(wrap_pyfunction!(report::report, m)?)?;
    Ok(())
}
