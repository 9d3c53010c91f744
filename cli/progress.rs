//! Progress on the terminal: the library's events as a spinner (or a bar
//! for reports) on standard error, hidden when it is not a terminal, and
//! each stage's wall time with `--verbose`.

use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};
use optimizer::control::Event;

/// Draws the events of one run.
pub struct Progress {
    bar: ProgressBar,
    verbose: bool,
}

impl Progress {
    /// A spinner with the stage's message.
    pub fn spinner(verbose: bool) -> Self {
        let bar = ProgressBar::new_spinner();
        bar.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
                .expect("valid template"),
        );
        bar.enable_steady_tick(Duration::from_millis(120));
        Progress { bar, verbose }
    }

    /// A bar over the fraction of the run done, in thousandths.
    pub fn bar(what: &str) -> Self {
        let bar = ProgressBar::new(1000);
        bar.set_style(
            ProgressStyle::with_template(&format!(
                "{{bar:30}} {{percent}}% {what} [{{elapsed_precise}}] {{msg}}"
            ))
            .expect("valid template"),
        );
        Progress {
            bar,
            verbose: false,
        }
    }

    /// Shows one event.
    pub fn event(&self, e: Event<'_>) {
        match e {
            Event::Progress {
                fraction, message, ..
            } => {
                self.bar.set_position((fraction * 1000.0) as u64);
                self.bar.set_message(message.to_string());
            }
            Event::StageDone { stage, seconds } if self.verbose => {
                let line = format!("{stage}: {seconds:.2} s");
                if self.bar.is_hidden() {
                    eprintln!("{line}");
                } else {
                    self.bar.println(line);
                }
            }
            Event::StageDone { .. } => {}
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
