//! Progress of long commands (experiments, training; docs/design.md §4.9): on a terminal an
//! `indicatif` bar with the elapsed time and ETA under the progress lines; otherwise (a file,
//! a pipe, CI) the same lines alone, plain, on stderr.

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A count of `total` units of work, with its progress lines.
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    /// `total` units called `unit` (e.g. "iterations", "runs"); a bar only when stderr is a
    /// terminal.
    pub fn new(total: u64, unit: &str) -> Self {
        Self::with_bar(total, unit, std::io::stderr().is_terminal())
    }

    /// [`Progress::new`] with the choice of a bar made by the caller (tests).
    pub fn with_bar(total: u64, unit: &str, bar: bool) -> Self {
        let bar = bar.then(|| {
            let b = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
            b.set_style(
                ProgressStyle::with_template(&format!(
                    "{{bar:40}} {{pos}}/{{len}} {unit}, {{elapsed}} elapsed, ETA {{eta}}"
                ))
                .expect("a valid template"),
            );
            b.enable_steady_tick(Duration::from_millis(500));
            b
        });
        Self { bar }
    }

    /// Prints `line` (above the bar on a terminal) and counts one unit done.
    pub fn done_one(&self, line: &str) {
        match &self.bar {
            Some(b) => {
                b.println(line);
                b.inc(1);
            }
            None => eprintln!("{line}"),
        }
    }

    /// Counts `n` units done without a line (a bar moves; plain output shows nothing: the
    /// caller's own lines tell the progress there).
    pub fn inc(&self, n: u64) {
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }

    /// Prints `line` without counting.
    pub fn println(&self, line: &str) {
        match &self.bar {
            Some(b) => b.println(line),
            None => eprintln!("{line}"),
        }
    }

    /// Whether a bar is drawn.
    pub fn has_bar(&self) -> bool {
        self.bar.is_some()
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}
