//! A progress bar for the time loop, drawn on stderr only when stderr is a terminal (or,
//! [`Progress::with_lines`], plain lines on stderr when it is not).

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

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
    /// Plain lines instead of a hidden bar ([`Self::with_lines`] without a terminal).
    lines: Option<Lines>,
}

/// The state of line progress: the label, the total, the position and the position at
/// which the next line is printed.
#[derive(Debug)]
struct Lines {
    label: String,
    len: u64,
    pos: AtomicU64,
    printed: AtomicU64,
}

impl Lines {
    /// Counts one unit; prints `label: pos/len  msg` at every tenth of the way and at the
    /// end.
    fn inc(&self, msg: impl FnOnce() -> String) {
        let pos = self.pos.fetch_add(1, Ordering::SeqCst) + 1;
        let tenth = (self.len / 10).max(1);
        let last = self.printed.load(Ordering::SeqCst);
        if pos >= last + tenth || pos == self.len {
            self.printed.store(pos, Ordering::SeqCst);
            eprintln!("{}: {pos}/{}  {}", self.label, self.len, msg());
        }
    }

    /// The closing line of a loop that stopped before its end.
    fn finish(&self) {
        let pos = self.pos.load(Ordering::SeqCst);
        if pos < self.len {
            eprintln!("{}: stopped at {pos}/{}", self.label, self.len);
        }
    }
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
            lines: None,
        }
    }

    /// Like [`Self::new`], but where stderr is not a terminal (a log file, captured
    /// output) it prints a plain line `label: k/N  message` on stderr at every tenth of
    /// the way and at the end (and `label: stopped at k/N` if the loop ends early).
    pub fn with_lines(steps: u64, label: &str) -> Self {
        let mut p = Self::new(steps, label);
        if p.bar.is_hidden() {
            p.lines = Some(Lines {
                label: label.to_string(),
                len: steps,
                pos: AtomicU64::new(0),
                printed: AtomicU64::new(0),
            });
        }
        p
    }

    /// Records one finished unit of work (a sweep member, …) with a message.
    pub fn advance(&self, msg: &str) {
        if let Some(l) = &self.lines {
            l.inc(|| msg.to_string());
        }
        if self.bar.is_hidden() {
            return;
        }
        self.bar.set_message(msg.to_string());
        self.bar.inc(1);
    }

    /// Records one finished step that reached time `t` after `newton_iters` iterations.
    pub fn step(&self, t: f64, newton_iters: usize) {
        if let Some(l) = &self.lines {
            l.inc(|| format!("t = {}  newton {newton_iters:>2}", fmt_time(t)));
        }
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
        if let Some(l) = &self.lines {
            l.finish();
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
