//! The result classes: what `match`, `atlas`, `regress`, `shoot` and
//! `stats` return.
//!
//! Each is a frozen class whose attributes are numpy arrays, shapes and
//! plain records (the quality, energies and pre-alignment as the dicts of
//! summary.json's keys), as polars and pydantic-core return objects rather
//! than dicts. The results were dicts before they were classes, so each
//! is also a read-only mapping of its attributes by name (`result["matched"]`,
//! `keys()`, `items()`, `get()`, iteration, `len()`, `dict(result)`), and
//! code written for the dicts keeps working; only what needs a real dict
//! (`json.dumps`, assigning a key) needs `dict(result)`.

use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;

/// A result class with the named attributes (read-only, in this order),
/// indexable by their names; `hidden` fields carry what another function
/// reads back (the report's typed record) without showing it.
macro_rules! result_class {
    (
        $(#[$doc:meta])*
        $name:ident { $($field:ident),* $(,)? }
        $(hidden { $($hfield:ident : $hty:ty),* $(,)? })?
    ) => {
        $(#[$doc])*
        #[pyclass(module = "fshape", frozen)]
        pub(crate) struct $name {
            $(pub(crate) $field: Py<PyAny>,)*
            $($(pub(crate) $hfield: $hty,)*)?
        }

        #[pymethods]
        impl $name {
            $(
                #[getter]
                fn $field(&self, py: Python<'_>) -> Py<PyAny> {
                    self.$field.clone_ref(py)
                }
            )*

            /// The attribute named `key` (as the dict results read).
            fn __getitem__(&self, py: Python<'_>, key: &str) -> PyResult<Py<PyAny>> {
                match key {
                    $(stringify!($field) => Ok(self.$field.clone_ref(py)),)*
                    _ => Err(PyKeyError::new_err(format!(
                        "{:?} (a {} has {})",
                        key,
                        stringify!($name),
                        Self::KEYS.join(", ")
                    ))),
                }
            }

            fn __contains__(&self, key: &Bound<'_, PyAny>) -> bool {
                key.extract::<String>().is_ok_and(|k| Self::KEYS.contains(&k.as_str()))
            }

            fn __len__(&self) -> usize {
                Self::KEYS.len()
            }

            fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyIterator>> {
                pyo3::types::PyList::new(py, Self::KEYS)?.try_iter()
            }

            /// The attributes' names.
            fn keys(&self) -> Vec<&'static str> {
                Self::KEYS.to_vec()
            }

            /// The attributes' values, in the order of `keys()`.
            fn values(&self, py: Python<'_>) -> Vec<Py<PyAny>> {
                vec![$(self.$field.clone_ref(py)),*]
            }

            /// (name, value) pairs, in the order of `keys()`.
            fn items(&self, py: Python<'_>) -> Vec<(&'static str, Py<PyAny>)> {
                Self::KEYS.iter().copied().zip(self.values(py)).collect()
            }

            /// The attribute named `key`, or `default` without one.
            #[pyo3(signature = (key, default = None))]
            fn get(&self, py: Python<'_>, key: &str, default: Option<Py<PyAny>>) -> Py<PyAny> {
                self.__getitem__(py, key).unwrap_or_else(|_| default.unwrap_or_else(|| py.None()))
            }

            /// The attributes for Python's garbage collector (they may be
            /// dicts and lists a caller fills, so a cycle through them is
            /// found; those containers' own clearing breaks it).
            fn __traverse__(&self, visit: pyo3::PyVisit<'_>) -> Result<(), pyo3::PyTraverseError> {
                $(visit.call(&self.$field)?;)*
                Ok(())
            }

            fn __repr__(&self) -> String {
                format!("{}({})", stringify!($name), Self::KEYS.join(", "))
            }
        }

        impl $name {
            const KEYS: &'static [&'static str] = &[$(stringify!($field)),*];
        }
    };
}

result_class! {
    /// A geodesic at some times: `times` (T), `points` (T × n × d),
    /// `signals` (T × n, or T × n × k with k maps), `hamiltonian` (H at
    /// every integrator node).
    Geodesic { times, points, signals, hamiltonian }
}

result_class! {
    /// What `match` returns (see its docs).
    MatchResult {
        stopped, p0, pf, energies, quality, initial_quality, alignment, stages, iterations,
        evaluations, seconds, geodesic, matched, target, config,
    }
    hidden {
        record: fshape_match::record::MatchRecord,
        config_text: String,
    }
}

result_class! {
    /// One subject of an atlas (see `atlas`).
    SubjectResult {
        p0, pf, energies, quality, template_quality, initial_attachment, alignment, geodesic, matched,
    }
}

result_class! {
    /// What `atlas` returns (see its docs).
    AtlasResult { template, template_momenta, subjects, energies, stages, iterations, evaluations, seconds }
}

result_class! {
    /// What `regress` returns (see its docs).
    RegressionResult {
        p0, pf, energies, t0, span, times, quality, initial_quality, alignments, fitted, rates, geodesic,
        baseline, stages, iterations, evaluations, seconds, config,
    }
}

result_class! {
    /// One map's test (see `stats`).
    MapTest { kind, dof, statistic, effect, p, p_fwe, tfce, tfce_p_fwe, critical }
}

result_class! {
    /// What `stats` returns (see its docs).
    StatsResult { design, contrast, rows_not_in_the_atlas, maps, multivariate }
}

/// Adds the result classes to the module.
pub(crate) fn add(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Geodesic>()?;
    m.add_class::<MatchResult>()?;
    m.add_class::<SubjectResult>()?;
    m.add_class::<AtlasResult>()?;
    m.add_class::<RegressionResult>()?;
    m.add_class::<MapTest>()?;
    m.add_class::<StatsResult>()?;
    Ok(())
}
