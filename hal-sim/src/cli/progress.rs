//! Progress on stderr (`indicatif`), counted in simulated seconds across every run of a
//! command (a sweep's bar moves as its runs advance, not when one finishes), with elapsed
//! time and ETA. Hidden when stderr is not a terminal or with `--quiet`.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;

/// A bar over `total_s` simulated seconds (cheap to clone, shared by parallel runs).
#[derive(Clone)]
pub struct Progress {
    bar: ProgressBar,
}

impl Progress {
    pub fn new(what: &str, total_s: f64, quiet: bool) -> Progress {
        let ms = (total_s * 1e3).round().max(1.0) as u64;
        let bar = if quiet || !std::io::stderr().is_terminal() {
            ProgressBar::with_draw_target(Some(ms), ProgressDrawTarget::hidden())
        } else {
            ProgressBar::with_draw_target(Some(ms), ProgressDrawTarget::stderr())
        };
        if let Ok(style) = ProgressStyle::with_template(
            "{msg} [{bar:30}] {percent:>3} % of the simulated time, {elapsed} elapsed, ETA {eta}",
        ) {
            bar.set_style(style.progress_chars("#>-"));
        }
        bar.set_message(what.to_string());
        Progress { bar }
    }

    /// Advance by simulated seconds.
    pub fn advance(&self, seconds: f64) {
        self.bar.inc((seconds * 1e3).round() as u64);
    }

    /// A callback for [`crate::summary::run_to_end`].
    pub fn callback(&self) -> impl FnMut(f64) + '_ {
        move |s| self.advance(s)
    }

    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
