//! The result classes: what `match`, `atlas`, `shoot` and `stats` return.
//!
//! Each is a frozen class whose attributes are numpy arrays, shapes and
//! plain records (the quality, energies and pre-alignment as the dicts of
//! summary.json's keys), as polars and pydantic-core return objects rather
//! than dicts. The results were dicts before they were classes, so
//! `result["matched"]` still reads the attribute (with `keys()`), and
//! code written for either keeps working.

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

            fn __contains__(&self, key: &str) -> bool {
                Self::KEYS.contains(&key)
            }

            /// The attributes' names.
            fn keys(&self) -> Vec<&'static str> {
                Self::KEYS.to_vec()
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
    m.add_class::<MapTest>()?;
    m.add_class::<StatsResult>()?;
    Ok(())
}
