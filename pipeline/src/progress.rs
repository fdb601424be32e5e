//! The one progress display of every stage, per-scene or dataset-level: a bar on a terminal,
//! periodic lines otherwise, nothing with `--progress off` or `--quiet`, as `[run] progress`
//! says. The runner owns it; a stage only says what one unit of work is.

use std::io::IsTerminal as _;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use crate::config::ProgressMode;

/// How one unit of work ended, for the counts of the display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tick {
    /// Done (or waiting: it counts as handled).
    Done,
    /// Skipped: still done from an earlier run.
    Skipped,
    /// Failed.
    Failed,
}

/// A counter of units done out of a total, shown as a bar or as periodic lines.
#[derive(Debug)]
pub struct Progress {
    label: String,
    unit: &'static str,
    total: usize,
    bar: Option<indicatif::ProgressBar>,
    interval: Option<Duration>,
    last_line: Mutex<Instant>,
    started: Instant,
    finished: AtomicUsize,
    skipped: AtomicUsize,
    failed: AtomicUsize,
}

/// Whether what mesa writes to standard error may hold ANSI colour codes: only when it is a
/// terminal and `NO_COLOR` is unset or empty (<https://no-color.org>). The log lines use it;
/// the progress bar, drawn on a terminal only, has no colours.
pub fn colour_on_stderr() -> bool {
    colour_allowed(
        std::io::stderr().is_terminal(),
        std::env::var_os("NO_COLOR").as_deref(),
    )
}

/// [`colour_on_stderr`] for a given stream kind and `NO_COLOR` value.
fn colour_allowed(terminal: bool, no_color: Option<&std::ffi::OsStr>) -> bool {
    terminal && no_color.is_none_or(|v| v.is_empty())
}

impl Progress {
    /// A display for `total` units (`unit`, like "scenes") of the stage `label`.
    pub fn new(
        label: &str,
        unit: &'static str,
        total: usize,
        mode: ProgressMode,
        interval: Duration,
    ) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let (bar, lines) = match mode {
            ProgressMode::Off => (false, false),
            ProgressMode::Bar => (true, false),
            ProgressMode::Lines => (false, true),
            ProgressMode::Auto => (terminal, !terminal),
        };
        let bar = bar.then(|| {
            let bar = indicatif::ProgressBar::new(total as u64);
            let style = indicatif::ProgressStyle::with_template(&format!(
                "{{prefix:>8}} [{{bar:40}}] {{pos}}/{{len}} {unit} {{per_sec}} eta {{eta}} {{msg}}"
            ))
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> ");
            bar.set_style(style);
            bar.set_prefix(label.to_owned());
            bar
        });
        Self {
            label: label.to_owned(),
            unit,
            total,
            bar,
            interval: lines.then_some(interval),
            last_line: Mutex::new(Instant::now()),
            started: Instant::now(),
            finished: AtomicUsize::new(0),
            skipped: AtomicUsize::new(0),
            failed: AtomicUsize::new(0),
        }
    }

    /// Counts one unit that ended as `tick`.
    pub fn tick(&self, tick: Tick) {
        self.count(1, tick);
    }

    /// Counts `n` more units done.
    pub fn advance(&self, n: usize) {
        self.count(n, Tick::Done);
    }

    fn count(&self, n: usize, tick: Tick) {
        let finished = self.finished.fetch_add(n, Ordering::Relaxed) + n;
        match tick {
            Tick::Skipped => {
                self.skipped.fetch_add(n, Ordering::Relaxed);
            }
            Tick::Failed => {
                self.failed.fetch_add(n, Ordering::Relaxed);
            }
            Tick::Done => {}
        }
        let failed = self.failed.load(Ordering::Relaxed);
        if let Some(bar) = &self.bar {
            bar.inc(n as u64);
            if failed > 0 {
                bar.set_message(format!("{failed} failed"));
            }
        }
        if let Some(interval) = self.interval {
            let mut last = self.last_line.lock().unwrap_or_else(|e| e.into_inner());
            if last.elapsed() >= interval || finished == self.total {
                *last = Instant::now();
                let rate = finished as f64 / self.started.elapsed().as_secs_f64().max(1e-9);
                eprintln!(
                    "{}: {finished}/{} {} ({} skipped, {failed} failed), {rate:.1} {}/s",
                    self.label,
                    self.total,
                    self.unit,
                    self.skipped.load(Ordering::Relaxed),
                    self.unit,
                );
            }
        }
    }

    /// Clears the bar.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_only_on_a_terminal_without_no_color() {
        use std::ffi::OsStr;
        assert!(colour_allowed(true, None));
        assert!(colour_allowed(true, Some(OsStr::new(""))));
        assert!(!colour_allowed(true, Some(OsStr::new("1"))));
        assert!(!colour_allowed(false, None));
    }
}
