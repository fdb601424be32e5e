//! Progress of a dataset-level stage (`records`): a bar on a terminal, periodic lines
//! otherwise, nothing with `--progress off`, as `[run] progress` says.

use std::io::IsTerminal as _;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use crate::config::ProgressMode;

/// A counter of items done out of a total.
#[derive(Debug)]
pub struct Progress {
    label: &'static str,
    unit: &'static str,
    total: usize,
    done: AtomicUsize,
    bar: Option<indicatif::ProgressBar>,
    interval: Option<Duration>,
    last: Mutex<Instant>,
    started: Instant,
}

impl Progress {
    /// A display for `total` items (`unit`, like "scenes") of the stage `label`.
    pub fn new(
        label: &'static str,
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
            if let Ok(style) = indicatif::ProgressStyle::with_template(&format!(
                "{{prefix:>8}} [{{bar:40}}] {{pos}}/{{len}} {unit} {{per_sec}} eta {{eta}}"
            )) {
                bar.set_style(style.progress_chars("=> "));
            }
            bar.set_prefix(label);
            bar
        });
        Self {
            label,
            unit,
            total,
            done: AtomicUsize::new(0),
            bar,
            interval: lines.then_some(interval),
            last: Mutex::new(Instant::now()),
            started: Instant::now(),
        }
    }

    /// Counts `n` more items done.
    pub fn advance(&self, n: usize) {
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        if let Some(bar) = &self.bar {
            bar.inc(n as u64);
        }
        if let Some(interval) = self.interval {
            let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
            if last.elapsed() >= interval || done == self.total {
                *last = Instant::now();
                let rate = done as f64 / self.started.elapsed().as_secs_f64().max(1e-9);
                eprintln!(
                    "{}: {done}/{} {}, {rate:.0} {}/s",
                    self.label, self.total, self.unit, self.unit
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
