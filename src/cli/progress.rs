//! indicatif rendering of the library's [`Progress`] hooks.

use std::time::Duration;

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use meshdeco::pipeline::Progress;

/// Draws one spinner or bar per stage on stderr (hidden when stderr is not a terminal).
pub struct Bars {
    bar: Option<ProgressBar>,
    multi: Option<MultiProgress>,
}

impl Bars {
    pub fn new() -> Self {
        Bars { bar: None, multi: None }
    }

    /// Bars drawn as lines of a shared [`MultiProgress`] (e.g. below a whole-sweep bar).
    pub fn in_multi(multi: &MultiProgress) -> Self {
        Bars { bar: None, multi: Some(multi.clone()) }
    }
}

impl Progress for Bars {
    fn stage(&mut self, name: &str, total: u64) {
        self.finish_stage();
        let bar = if total > 0 {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template("{prefix:>14} [{bar:30}] {pos}/{len} {elapsed_precise} eta {eta} {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar())
                    .progress_chars("=> "),
            );
            b
        } else {
            let b = ProgressBar::new_spinner();
            b.set_style(
                ProgressStyle::with_template("{prefix:>14} {spinner} {elapsed_precise} {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            b.enable_steady_tick(Duration::from_millis(120));
            b
        };
        let bar = match &self.multi {
            Some(m) => m.add(bar),
            None => bar,
        };
        bar.set_prefix(name.to_string());
        self.bar = Some(bar);
    }

    fn step(&mut self, i: u64, message: &str) {
        if let Some(b) = &self.bar {
            b.set_position(i);
            b.set_message(message.to_string());
        }
    }

    fn finish_stage(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish();
        }
    }
}
