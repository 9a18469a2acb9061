//! indicatif rendering of the library's [`Progress`] hooks, and plain progress lines for batch
//! jobs.
//!
//! On a terminal each stage is a bar (or a spinner when its length is unknown). When stderr is
//! not a terminal (a batch job, `2> log`, a pipe) indicatif draws nothing, so a ticker thread
//! prints one plain line per stage start and end and, while a stage runs, one line every
//! `MESHDECO_PROGRESS_SECONDS` (default 5; 0 turns the lines off) — also when no step finished in
//! that time, so a log shows that a long step is still running:
//!
//! ```text
//! [meshdeco 00:01:05] training: 120/600 (20.0 %), 1.84/s, eta 00:04:21 — loss 0.0123
//! ```

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use meshdeco::pipeline::Progress;

/// Seconds between plain progress lines unless `MESHDECO_PROGRESS_SECONDS` says otherwise.
pub const DEFAULT_LINE_SECONDS: f64 = 5.0;

/// Draws one spinner or bar per stage on stderr; plain lines when stderr is not a terminal.
pub struct Bars {
    bar: Option<ProgressBar>,
    multi: Option<MultiProgress>,
    lines: Option<Lines>,
}

impl Bars {
    pub fn new() -> Self {
        Bars { bar: None, multi: None, lines: Lines::for_stderr() }
    }

    /// Bars drawn as lines of a shared [`MultiProgress`] (e.g. below a whole-sweep bar).
    pub fn in_multi(multi: &MultiProgress) -> Self {
        Bars { bar: None, multi: Some(multi.clone()), lines: Lines::for_stderr() }
    }
}

impl Progress for Bars {
    fn stage(&mut self, name: &str, total: u64) {
        self.finish_stage();
        if let Some(l) = &self.lines {
            l.stage(name, total);
            return;
        }
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
        if let Some(l) = &self.lines {
            l.step(i, message);
        }
        if let Some(b) = &self.bar {
            b.set_position(i);
            b.set_message(message.to_string());
        }
    }

    fn note(&mut self, text: &str) {
        match &self.bar {
            Some(b) => b.println(format!("note: {text}")),
            None => eprintln!("note: {text}"),
        }
    }

    fn finish_stage(&mut self) {
        if let Some(l) = &self.lines {
            l.finish();
        }
        if let Some(b) = self.bar.take() {
            b.finish();
        }
    }
}

/// The stage a [`Lines`] ticker reports on.
struct Stage {
    name: String,
    total: u64,
    done: u64,
    message: String,
    started: Instant,
}

#[derive(Default)]
struct LineState {
    stage: Option<Stage>,
    stop: bool,
}

/// Plain progress lines on stderr, printed by a ticker thread at a steady interval.
struct Lines {
    state: Arc<(Mutex<LineState>, Condvar)>,
    ticker: Option<JoinHandle<()>>,
    start: Instant,
    closed: Arc<AtomicBool>,
}

impl Lines {
    /// Lines when stderr is not a terminal and the interval is not 0; `None` otherwise.
    fn for_stderr() -> Option<Lines> {
        if std::io::stderr().is_terminal() {
            return None;
        }
        let every = line_interval();
        (every > 0.0).then(|| Lines::start(Duration::from_secs_f64(every)))
    }

    fn start(every: Duration) -> Lines {
        let state = Arc::new((Mutex::new(LineState::default()), Condvar::new()));
        let start = Instant::now();
        let closed = Arc::new(AtomicBool::new(false));
        let ticker = {
            let state = state.clone();
            let closed = closed.clone();
            std::thread::Builder::new()
                .name("progress-lines".into())
                .spawn(move || {
                    let (lock, cv) = &*state;
                    let Ok(mut g) = lock.lock() else { return };
                    loop {
                        let Ok((ng, _)) = cv.wait_timeout(g, every) else { return };
                        g = ng;
                        if g.stop || closed.load(Ordering::Relaxed) {
                            return;
                        }
                        if let Some(s) = &g.stage {
                            emit(start, &running_line(s));
                        }
                    }
                })
                .ok()
        };
        Lines { state, ticker, start, closed }
    }

    fn with<R>(&self, f: impl FnOnce(&mut LineState) -> R) -> Option<R> {
        self.state.0.lock().ok().map(|mut g| f(&mut g))
    }

    fn stage(&self, name: &str, total: u64) {
        let of = if total > 0 { format!(" ({total} steps)") } else { String::new() };
        emit(self.start, &format!("{name}: started{of}"));
        self.with(|g| {
            g.stage =
                Some(Stage { name: name.to_string(), total, done: 0, message: String::new(), started: Instant::now() })
        });
    }

    fn step(&self, i: u64, message: &str) {
        self.with(|g| {
            if let Some(s) = &mut g.stage {
                s.done = i;
                s.message.clear();
                s.message.push_str(message);
            }
        });
    }

    fn finish(&self) {
        if let Some(Some(s)) = self.with(|g| g.stage.take()) {
            let msg = if s.message.is_empty() { String::new() } else { format!(" — {}", s.message) };
            emit(self.start, &format!("{}: done in {}{msg}", s.name, clock(s.started.elapsed().as_secs_f64())));
        }
    }
}

impl Drop for Lines {
    fn drop(&mut self) {
        self.finish();
        self.closed.store(true, Ordering::Relaxed);
        self.with(|g| g.stop = true);
        self.state.1.notify_all();
        if let Some(t) = self.ticker.take() {
            let _ = t.join();
        }
    }
}

/// `MESHDECO_PROGRESS_SECONDS` as a number of seconds (the default when unset or not a
/// non-negative number).
fn line_interval() -> f64 {
    std::env::var("MESHDECO_PROGRESS_SECONDS")
        .ok()
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|v| v.is_finite() && *v >= 0.0)
        .unwrap_or(DEFAULT_LINE_SECONDS)
}

/// The line of a running stage: done/total, share, rate and ETA when the total is known.
fn running_line(s: &Stage) -> String {
    let t = s.started.elapsed().as_secs_f64();
    let mut line = format!("{}: ", s.name);
    if s.total > 0 {
        let rate = s.done as f64 / t.max(1e-9);
        line += &format!("{}/{} ({:.1} %)", s.done, s.total, 100.0 * s.done as f64 / s.total as f64);
        if s.done > 0 {
            let eta = (s.total.saturating_sub(s.done)) as f64 / rate;
            line += &format!(", {}, eta {}", rate_text(rate), clock(eta));
        } else {
            line += &format!(", running for {}", clock(t));
        }
    } else {
        line += &format!("running for {}", clock(t));
    }
    if !s.message.is_empty() {
        line += &format!(" — {}", s.message);
    }
    line
}

fn rate_text(per_second: f64) -> String {
    if per_second >= 1.0 { format!("{per_second:.2}/s") } else { format!("{:.1} s each", 1.0 / per_second) }
}

/// `hh:mm:ss`.
fn clock(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    format!("{:02}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
}

fn emit(start: Instant, line: &str) {
    let mut err = std::io::stderr().lock();
    let _ = writeln!(err, "[meshdeco {}] {line}", clock(start.elapsed().as_secs_f64()));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_line_has_count_share_rate_and_eta() {
        let s = Stage {
            name: "training".into(),
            total: 600,
            done: 120,
            message: "loss 0.5".into(),
            started: Instant::now() - Duration::from_secs(60),
        };
        let l = running_line(&s);
        assert!(l.starts_with("training: 120/600 (20.0 %), 2.00/s, eta 00:04:00 — loss 0.5"), "{l}");
        let s = Stage { total: 0, done: 0, message: String::new(), ..s };
        assert_eq!(running_line(&s), "training: running for 00:01:00");
        assert_eq!(clock(3725.0), "01:02:05");
        assert_eq!(rate_text(0.25), "4.0 s each");
    }
}
