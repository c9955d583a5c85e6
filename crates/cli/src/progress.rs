//! Progress of long runs: a bar on a terminal, plain periodic lines otherwise, nothing when quiet.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::time::Instant;

/// Reports progress of a run of `total` steps.
pub struct Progress {
    bar: Option<ProgressBar>,
    plain: bool,
    total: u64,
    start: Instant,
    next_line: u64,
}

impl Progress {
    /// A bar if stderr is a terminal (and not quiet), else plain lines every ~10 %.
    pub fn new(total: u64, quiet: bool) -> Self {
        let tty = std::io::stderr().is_terminal() && std::env::var_os("CI").is_none();
        let bar = (tty && !quiet).then(|| {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(
                    "{bar:30} {pos}/{len} steps  {per_sec}  ETA {eta}  {msg}",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b
        });
        Progress {
            bar,
            plain: !tty && !quiet,
            total,
            start: Instant::now(),
            next_line: 0,
        }
    }

    /// Called after each step.
    pub fn update(&mut self, step: u64, time: f64, contacts: usize, iterations: usize) {
        if let Some(b) = &self.bar {
            b.set_position(step);
            b.set_message(format!(
                "t = {time:.4} s  contacts {contacts}  iters {iterations}"
            ));
        } else if self.plain && (step >= self.next_line || step == self.total) {
            let el = self.start.elapsed().as_secs_f64();
            let rate = step as f64 / el.max(1e-9);
            let eta = (self.total - step) as f64 / rate.max(1e-9);
            eprintln!(
                "step {step}/{}  t = {time:.4} s  {rate:.1} steps/s  contacts {contacts}  iters {iterations}  ETA {eta:.0} s",
                self.total
            );
            self.next_line = step + (self.total / 10).max(1);
        }
    }

    /// Removes the bar.
    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}
