//! Progress bars on stderr for `bouncewear run` and `bench` (indicatif, with the time left), drawn
//! only when stderr is a terminal and `--quiet` was not given: a pipe or a log file gets nothing.

use bouncewear_model::montecarlo::Observer;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};

pub struct Progress {
    bar: ProgressBar,
    /// The length last given to the bar: setting it takes a lock, so only a change does.
    total: AtomicU64,
}

impl Progress {
    /// A job's operations: how many are done, their rate, and the time left.
    pub fn operations(quiet: bool) -> Self {
        Self::new(
            quiet,
            0,
            "{wide_bar} {percent:>3}%  {human_pos}/{human_len} operations  {rate}  ETA {eta}",
        )
    }

    /// `steps` measurements, each named while it runs.
    pub fn steps(quiet: bool, steps: u64) -> Self {
        Self::new(
            quiet,
            steps,
            "{wide_bar} {pos}/{len} measurements  ETA {eta}  {msg}",
        )
    }

    fn new(quiet: bool, total: u64, template: &str) -> Self {
        let target = if quiet || !std::io::stderr().is_terminal() {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
        };
        let style = ProgressStyle::with_template(template)
            .expect("the templates are valid")
            .with_key(
                "rate",
                |state: &ProgressState, out: &mut dyn std::fmt::Write| {
                    let _ = write!(out, "{:.2} M/s", state.per_sec() / 1e6);
                },
            );
        Self {
            bar: ProgressBar::with_draw_target(Some(total), target).with_style(style),
            total: AtomicU64::new(total),
        }
    }

    /// Runs one measurement under its name, and counts it.
    pub fn measure<T>(&self, name: impl Into<String>, work: impl FnOnce() -> T) -> T {
        self.bar.set_message(name.into());
        let value = work();
        self.bar.inc(1);
        value
    }

    /// Takes the bar off the terminal.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Observer for Progress {
    fn progress(&self, done: u64, total: u64) {
        if self.total.swap(total, Ordering::Relaxed) != total {
            self.bar.set_length(total);
        }
        self.bar.set_position(done);
    }
}
