//! A progress bar for the time loop, drawn on stderr only when stderr is a terminal.

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressFinish, ProgressStyle};

/// Progress bar of a time loop. Shown only when stderr is a terminal; otherwise every
/// method is a no-op and nothing is printed.
#[derive(Debug)]
pub struct Progress {
    bar: ProgressBar,
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
            "{prefix} [{elapsed_precise}] {wide_bar:.cyan/blue} {pos}/{len} {msg} (eta {eta})",
        )
        .expect("valid progress template")
        .progress_chars("=> ");
        let bar = ProgressBar::with_draw_target(Some(steps), target)
            .with_style(style)
            .with_prefix(label.to_string())
            // Dropping the bar without `finish` (early return on error) keeps the position
            // reached instead of jumping to 100 %.
            .with_finish(ProgressFinish::Abandon);
        Self { bar }
    }

    /// Records one finished step that reached time `t` after `newton_iters` iterations.
    pub fn step(&self, t: f64, newton_iters: usize) {
        if self.bar.is_hidden() {
            return;
        }
        self.bar
            .set_message(format!("t = {t:.4e}  newton {newton_iters:>2}"));
        self.bar.inc(1);
    }

    /// Stops the bar, leaving it (with the position reached) on the terminal.
    pub fn finish(&self) {
        self.bar.abandon();
    }

    /// Runs `f` (which may print to stderr/stdout) with the bar temporarily cleared, so
    /// that messages do not garble it.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        self.bar.suspend(f)
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
    }
}
