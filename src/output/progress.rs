//! A progress bar for the time loop, drawn on stderr only when stderr is a terminal.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressFinish, ProgressStyle};

/// Progress bar of a time loop. Shown only when stderr is a terminal; otherwise every
/// method is a no-op and nothing is printed.
///
/// [`finish`](Self::finish) (or dropping the bar, e.g. on an early error return) leaves
/// the bar at the position reached and moves the cursor to the next line, so that later
/// messages start on a line of their own.
#[derive(Debug)]
pub struct Progress {
    bar: ProgressBar,
    finished: AtomicBool,
}

impl Progress {
    /// A bar over `steps` time steps, prefixed with `label` (e.g. the scene name).
    pub fn new(steps: u64, label: &str) -> Self {
        let target = if std::io::stderr().is_terminal() {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        let style = ProgressStyle::with_template(
            "{prefix} [{elapsed_precise}] {wide_bar:.cyan/blue} {pos}/{len}  {msg}  (eta {eta})",
        )
        .expect("valid progress template")
        .progress_chars("=> ");
        let bar = ProgressBar::with_draw_target(Some(steps), target)
            .with_style(style)
            .with_prefix(label.to_string())
            // Never jump to 100 % when the loop stopped early.
            .with_finish(ProgressFinish::Abandon);
        Self {
            bar,
            finished: AtomicBool::new(false),
        }
    }

    /// Records one finished step that reached time `t` after `newton_iters` iterations.
    pub fn step(&self, t: f64, newton_iters: usize) {
        if self.bar.is_hidden() {
            return;
        }
        self.bar
            .set_message(format!("t = {}  newton {newton_iters:>2}", fmt_time(t)));
        self.bar.inc(1);
    }

    /// Stops the bar, leaving it (with the position reached) on the terminal. Calling it
    /// again does nothing.
    pub fn finish(&self) {
        if self.finished.swap(true, Ordering::SeqCst) {
            return;
        }
        self.bar.abandon();
        if !self.bar.is_hidden() {
            // indicatif leaves the cursor at the end of the bar's line.
            eprintln!();
        }
    }

    /// Runs `f` (which may print to stderr/stdout) with the bar temporarily cleared, so
    /// that messages do not garble it.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        self.bar.suspend(f)
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}

fn fmt_time(t: f64) -> String {
    if t == 0.0 || (1e-3..1e5).contains(&t.abs()) {
        format!("{t:.4}")
    } else {
        format!("{t:.3e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_runs_without_terminal() {
        let p = Progress::new(10, "test");
        for i in 0..10 {
            p.step(i as f64 * 0.1, 3);
        }
        assert_eq!(p.suspend(|| 7), 7);
        p.finish();
        p.finish();
    }

    #[test]
    fn time_format() {
        assert_eq!(fmt_time(0.0), "0.0000");
        assert_eq!(fmt_time(1.25), "1.2500");
        assert_eq!(fmt_time(2.5e-5), "2.500e-5");
    }
}
