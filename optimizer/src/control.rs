//! Observing and stopping long work: a run reports its progress through
//! [`Event`]s and stops at the next check once its cancel flag is set.
//! The library draws nothing; the CLI turns events into progress bars, the
//! HTTP service into its job status.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::{Error, Result};

/// What a run reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event<'a> {
    /// Work advanced: the stage (named as in the stats), the fraction of the
    /// whole run done, in `[0, 1]`, and a line for people.
    Progress {
        /// Stage name.
        stage: &'a str,
        /// Fraction of the whole run done.
        fraction: f64,
        /// What is being done, for a progress line.
        message: &'a str,
    },
    /// A stage finished after `seconds` of wall time.
    StageDone {
        /// Stage name.
        stage: &'a str,
        /// Wall time, seconds.
        seconds: f64,
    },
}

/// Receives the events of a run (from any thread).
pub type Observer<'a> = &'a (dyn Fn(Event<'_>) + Sync);

/// Observes a run and may stop it. `Control::default()` observes nothing
/// and never cancels.
#[derive(Clone, Copy, Default)]
pub struct Control<'a> {
    /// When set to true, the run stops at its next check with
    /// [`Error::Cancelled`].
    pub cancel: Option<&'a AtomicBool>,
    /// Called with every event.
    pub observer: Option<Observer<'a>>,
}

impl<'a> Control<'a> {
    /// A control that reports to `observer`.
    pub fn observed(observer: Observer<'a>) -> Self {
        Control {
            cancel: None,
            observer: Some(observer),
        }
    }

    /// True once the run was cancelled.
    pub fn cancelled(&self) -> bool {
        self.cancel.is_some_and(|c| c.load(Ordering::Relaxed))
    }

    /// `Err(Error::Cancelled)` once the run was cancelled.
    pub fn check(&self) -> Result<()> {
        if self.cancelled() {
            Err(Error::Cancelled)
        } else {
            Ok(())
        }
    }

    /// Reports progress (the fraction is clamped to `[0, 1]`).
    pub fn progress(&self, stage: &str, fraction: f64, message: &str) {
        if let Some(f) = self.observer {
            f(Event::Progress {
                stage,
                fraction: fraction.clamp(0.0, 1.0),
                message,
            });
        }
    }

    /// Reports the end of a stage.
    pub fn stage_done(&self, stage: &str, seconds: f64) {
        if let Some(f) = self.observer {
            f(Event::StageDone { stage, seconds });
        }
    }
}
