//! The progress callback of `match` and `atlas` as an observer of the run.

use std::path::Path;

use fshape_match::{Control, Iteration, Observer, Outcome, StageRecord, StageSpec};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::other;

/// Calls the Python progress callback with a dict per event; a callback
/// returning True stops the run (as scipy.optimize's callbacks), one
/// raising stops it and re-raises.
pub(crate) struct Progress {
    callback: Option<Py<PyAny>>,
    pub(crate) error: Option<PyErr>,
    stopped: bool,
}

impl Progress {
    pub(crate) fn new(callback: Option<Py<PyAny>>) -> Progress {
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
    pub(crate) fn finish(self, outcome: Outcome, checkpoint: Option<&Path>) -> PyResult<()> {
        if let Some(e) = self.error {
            return Err(e);
        }
        if outcome == Outcome::Interrupted || self.stopped {
            let resume = match checkpoint {
                Some(path) => format!("; the same call with checkpoint={} resumes it", path.display()),
                None => String::new(),
            };
            return Err(other(format!("stopped by the progress callback (it returned True){resume}")));
        }
        Ok(())
    }

    /// The callback's exception or Ctrl-C, re-raised.
    pub(crate) fn raised(&mut self) -> PyResult<()> {
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
