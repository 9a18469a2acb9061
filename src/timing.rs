//! Phase timings of one command (load, features, fit, measure, write, …), recorded by the
//! library as it works and printed by the command line with `-v`.

use std::sync::Mutex;

static PHASES: Mutex<Vec<(String, f64)>> = Mutex::new(Vec::new());
static COUNTS: Mutex<Vec<(String, u64)>> = Mutex::new(Vec::new());

/// Adds `n` to counter `name` (e.g. bytes read), printed with the phases.
pub fn count(name: &str, n: u64) {
    add(&COUNTS, name, n);
}

/// The counters recorded so far, in order.
pub fn counts() -> Vec<(String, u64)> {
    COUNTS.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Adds `seconds` to phase `name` (phases keep the order in which they first appear).
pub fn record(name: &str, seconds: f64) {
    if !seconds.is_finite() {
        return;
    }
    add(&PHASES, name, seconds);
}

/// Adds `v` to entry `name` of `list` (appended when new, so entries keep their first order).
fn add<T: std::ops::AddAssign + Copy>(list: &Mutex<Vec<(String, T)>>, name: &str, v: T) {
    let mut l = list.lock().unwrap_or_else(|e| e.into_inner());
    match l.iter_mut().find(|(n, _)| n == name) {
        Some((_, s)) => *s += v,
        None => l.push((name.to_string(), v)),
    }
}

thread_local! {
    static DEPTH: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// While alive, [`timed`] phases on this thread are not recorded: the enclosing code records its
/// own phases explicitly (so nothing is counted twice).
pub struct Scope(());

impl Drop for Scope {
    fn drop(&mut self) {
        DEPTH.with(|d| d.set(d.get().saturating_sub(1)));
    }
}

/// Opens a [`Scope`].
pub fn scope() -> Scope {
    DEPTH.with(|d| d.set(d.get() + 1));
    Scope(())
}

/// Runs `f`, adding its wall time to phase `name` — unless it runs inside another timed phase
/// or [`Scope`] on this thread, which then counts it.
pub fn timed<R>(name: &str, f: impl FnOnce() -> R) -> R {
    if DEPTH.with(|d| d.get()) > 0 {
        return f();
    }
    let _scope = scope();
    let t = std::time::Instant::now();
    let r = f();
    record(name, t.elapsed().as_secs_f64());
    r
}

/// The phases recorded so far, in order, with their total seconds.
pub fn phases() -> Vec<(String, f64)> {
    PHASES.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

#[cfg(test)]
mod tests {
    #[test]
    fn phases_accumulate_in_first_seen_order() {
        super::record("test-a", 1.0);
        super::record("test-b", 0.5);
        super::record("test-a", 2.0);
        super::record("test-c", f64::NAN);
        // A timed phase inside another is counted by the outer one only.
        super::timed("test-outer", || {
            super::timed("test-inner", || std::thread::sleep(std::time::Duration::from_millis(2)))
        });
        let p: Vec<_> = super::phases().into_iter().filter(|(n, _)| n.starts_with("test-")).collect();
        assert_eq!(&p[..2], &[("test-a".to_string(), 3.0), ("test-b".to_string(), 0.5)]);
        assert_eq!(p.len(), 3, "{p:?}");
        assert!(p[2].0 == "test-outer" && p[2].1 >= 0.002, "{p:?}");
    }
}
