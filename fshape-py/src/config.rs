//! `fshape.Config`: a checked configuration, and how a call's `config`
//! argument becomes one.

use std::path::PathBuf;

use fshape_match::{Config, MatchError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::conversions::to_py;
use crate::err;

/// A checked configuration, as a `fshape match` TOML file holds it:
/// `Config(tables)` from the tables as nested dicts, `Config.from_toml(text)`
/// from TOML text, `Config.read(path)` from a file.
#[pyclass(name = "Config", module = "fshape", frozen)]
pub(crate) struct PyConfig {
    pub(crate) inner: Config,
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
        Ok(PyConfig { inner: warned(tables.py(), inner)? })
    }

    /// The configuration in TOML text (errors name the key and line).
    #[staticmethod]
    fn from_toml(py: Python<'_>, text: &str) -> PyResult<PyConfig> {
        Ok(PyConfig { inner: warned(py, Config::parse(text).map_err(err)?)? })
    }

    /// The configuration in a TOML file (errors name the file).
    #[staticmethod]
    fn read(py: Python<'_>, path: PathBuf) -> PyResult<PyConfig> {
        Ok(PyConfig { inner: warned(py, Config::read(&path).map_err(err)?)? })
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
pub(crate) fn config_of(obj: &Bound<'_, PyAny>) -> PyResult<Config> {
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
        return warned(obj.py(), Config::read(&p).map_err(err)?);
    }
    Err(err("config: expected a fshape.Config, a dict of the TOML tables or a path to a TOML file"))
}

/// `config`, after a DeprecationWarning for each form it uses that reads
/// but is better written otherwise ([`Config::warnings`]: `[schedule]`'s
/// arrays), at the caller's line (stack level 1: the native call's caller,
/// so that Python's default filter for `__main__` shows it).
fn warned(py: Python<'_>, config: Config) -> PyResult<Config> {
    for warning in config.warnings() {
        // (The sentences are ours: no NUL byte to refuse.)
        let message = std::ffi::CString::new(warning.replace('\0', "")).unwrap_or_default();
        PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyDeprecationWarning>(), &message, 1)?;
    }
    Ok(config)
}
