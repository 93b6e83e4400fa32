//! A progress bar on stderr for `bouncewear run`, drawn only when stderr is a terminal.

use bouncewear_model::montecarlo::Observer;
use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Redraws at most every 100 ms, from whichever worker thread reports.
pub struct ProgressBar {
    started: Instant,
    last_drawn_ms: AtomicU64,
    enabled: bool,
}

impl ProgressBar {
    pub fn for_stderr() -> Self {
        Self {
            started: Instant::now(),
            last_drawn_ms: AtomicU64::new(0),
            enabled: std::io::stderr().is_terminal(),
        }
    }

    pub fn finish(&self) {
        if self.enabled {
            eprintln!();
        }
    }
}

impl Observer for ProgressBar {
    fn progress(&self, done: u64, total: u64) {
        if !self.enabled {
            return;
        }
        let elapsed = self.started.elapsed();
        let now_ms = u64::try_from(elapsed.as_millis()).unwrap_or(u64::MAX);
        let last = self.last_drawn_ms.load(Ordering::Relaxed);
        let is_last = done >= total;
        if !is_last && now_ms < last + 100 {
            return;
        }
        if self
            .last_drawn_ms
            .compare_exchange(last, now_ms, Ordering::Relaxed, Ordering::Relaxed)
            .is_err()
            && !is_last
        {
            return;
        }
        let fraction = if total == 0 {
            1.0
        } else {
            done as f64 / total as f64
        };
        let filled = (fraction * 30.0) as usize;
        let rate = done as f64 / elapsed.as_secs_f64().max(1e-9);
        let mut stderr = std::io::stderr().lock();
        let _ = write!(
            stderr,
            "\r[{}{}] {:5.1}%  {done}/{total} operations  {:.2} M/s ",
            "#".repeat(filled),
            " ".repeat(30 - filled.min(30)),
            100.0 * fraction,
            rate / 1e6
        );
        let _ = stderr.flush();
    }
}
