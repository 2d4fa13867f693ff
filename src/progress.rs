//! Progress bars on stderr for long stages; silent when stderr is not a terminal, when disabled,
//! or when the crate is built without its `progress` feature (then nothing is ever drawn).

#[cfg(feature = "progress")]
use std::io::IsTerminal;

#[cfg(feature = "progress")]
use indicatif::{ProgressBar, ProgressStyle};

/// Stands in for the bar when the crate is built without progress bars.
#[cfg(not(feature = "progress"))]
struct ProgressBar;

#[cfg(not(feature = "progress"))]
impl ProgressBar {
    fn inc(&self, _n: u64) {}
    fn set_message(&self, _msg: String) {}
    fn finish_and_clear(&self) {}
}

/// A progress reporter for one stage: a bar on a terminal, nothing otherwise.
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    /// A bar labelled `stage` counting to `total`; hidden when `enabled` is false or stderr is not
    /// a terminal.
    #[cfg(not(feature = "progress"))]
    pub fn new(_stage: &str, _total: u64, _enabled: bool) -> Progress {
        Progress { bar: None }
    }

    /// A bar labelled `stage` counting to `total`; hidden when `enabled` is false or stderr is not
    /// a terminal.
    #[cfg(feature = "progress")]
    pub fn new(stage: &str, total: u64, enabled: bool) -> Progress {
        if !enabled || !std::io::stderr().is_terminal() {
            return Progress { bar: None };
        }
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template(
                "{prefix:>12} [{bar:40}] {pos}/{len} {elapsed_precise} {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        bar.set_prefix(stage.to_string());
        Progress { bar: Some(bar) }
    }

    /// A reporter that never draws (library use, tests).
    pub fn hidden() -> Progress {
        Progress { bar: None }
    }

    /// Advances by `n` steps.
    pub fn inc(&self, n: u64) {
        if let Some(bar) = &self.bar {
            bar.inc(n);
        }
    }

    /// Sets the trailing message (e.g. the current residual).
    pub fn message(&self, msg: String) {
        if let Some(bar) = &self.bar {
            bar.set_message(msg);
        }
    }

    /// Removes the bar from the terminal.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}
