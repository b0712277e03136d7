//! How a long run reports its progress on stderr: a progress bar on a
//! terminal, a line per stage and iteration elsewhere (a batch system's
//! log, a file, a pipe) or with `--verbose`, nothing with `--quiet`.
//! `--stop-after` is an observer of its own (fshape-match's `StopAfter`),
//! beside this one in the run's `Observers`.

use std::time::Instant;

use fshape_match::{Control, Iteration, Observer, Plan, StageRecord, StageSpec};

/// The progress bar on a terminal, a line per stage and iteration
/// elsewhere (or with `--verbose`).
pub struct Progress {
    gamma_w: f64,
    bar: Option<indicatif::ProgressBar>,
    /// Never draw (`--quiet`).
    hidden: bool,
    /// Lines instead of a bar.
    lines: bool,
    /// What starts each line, e.g. "[row 3] ".
    label: String,
    /// The stage under way, as "stage k/n (kernel)".
    stage: String,
    start: Instant,
}

impl Progress {
    /// Reporting as `verbosity` says (the model's γ_W, which the iteration
    /// lines weigh the attachment by, comes with [`Observer::planned`]).
    pub(crate) fn new(verbosity: crate::args::Verbosity) -> Progress {
        use crate::args::Verbosity;
        use std::io::IsTerminal;
        let lines = match verbosity {
            Verbosity::Quiet => false,
            Verbosity::Normal => !std::io::stderr().is_terminal(),
            Verbosity::Verbose => true,
        };
        Progress {
            gamma_w: f64::NAN,
            bar: None,
            hidden: verbosity == Verbosity::Quiet,
            lines,
            label: String::new(),
            stage: String::new(),
            start: Instant::now(),
        }
    }

    /// Each line starts with `[label] `.
    pub(crate) fn labelled(mut self, label: Option<&str>) -> Progress {
        self.label = label.map(|l| format!("[{l}] ")).unwrap_or_default();
        self
    }

    /// Leaves the bar where it stopped, with `why`.
    pub(crate) fn abandon(&mut self, why: &'static str) {
        if let Some(bar) = self.bar.take() {
            bar.abandon_with_message(why);
        }
    }

    /// Says that the outputs are being written into `out`, on the run's
    /// clock (renders and the report take a while on a large surface).
    pub(crate) fn outputs(&mut self, out: &std::path::Path) {
        if !self.hidden {
            self.stage = "outputs".into();
            self.line(format_args!("writing {}", out.display()));
        }
    }

    fn line(&self, what: std::fmt::Arguments<'_>) {
        eprintln!("{}[{:8.1} s] {} {what}", self.label, self.start.elapsed().as_secs_f64(), self.stage);
    }
}

impl Observer for Progress {
    fn planned(&mut self, plan: &Plan) {
        self.gamma_w = plan.model.gamma_w();
    }

    fn stage_started(&mut self, stage: usize, stages: usize, spec: &StageSpec, done: usize) -> Control {
        self.stage = format!("stage {}/{stages} ({})", stage + 1, spec.label);
        if self.lines {
            self.line(format_args!("starts, at most {} iterations ({done} done)", spec.max_iterations));
        }
        let bar = if self.hidden || self.lines {
            indicatif::ProgressBar::hidden()
        } else {
            indicatif::ProgressBar::new(spec.max_iterations as u64)
        };
        bar.set_style(
            indicatif::ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} it, ETA {eta} | {msg}")
                .expect("a valid template")
                .progress_chars("=> "),
        );
        bar.set_prefix(self.stage.clone());
        bar.set_position(done as u64);
        self.bar = Some(bar);
        Control::Continue
    }

    fn iteration(&mut self, _stage: usize, it: &Iteration) -> Control {
        let parts = format!(
            "J {:.6e} = H {:.4e} + γ_W·A {:.4e}, step {:.2e}",
            it.value,
            it.energy,
            self.gamma_w * it.attachment,
            it.step
        );
        if self.lines {
            self.line(format_args!("iteration {}: {parts}, {} evaluations", it.iteration, it.evaluations));
        }
        if let Some(bar) = &self.bar {
            bar.set_position(it.iteration as u64);
            bar.set_message(parts);
        }
        Control::Continue
    }

    fn setup(&mut self, step: &str) {
        // Before any bar: a line on a terminal too, so that a long
        // pre-alignment is not silence.
        if !self.hidden {
            self.stage = "setup".into();
            self.line(format_args!("{step}"));
        }
    }

    fn stage_finished(&mut self, _stage: usize, record: &StageRecord) {
        if self.lines {
            self.line(format_args!("ends: {} after {} iterations", record.reason, record.iterations.len()));
        }
        if let Some(bar) = self.bar.take() {
            bar.finish_with_message(format!("{} after {} iterations", record.reason, record.iterations.len()));
        }
    }
}
