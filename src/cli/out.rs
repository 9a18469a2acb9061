//! The commands' standard output. `println!` panics when stdout is a closed pipe
//! (`meshdeco inspect --json DIR | head -1`: "failed printing to stdout: Broken pipe", exit 101);
//! [`outln!`] and [`out!`] write through [`write`] instead, which never panics:
//!
//! - a closed pipe (`EPIPE`) is remembered and everything printed after it is dropped, so the
//!   command still finishes its work (an artefact it writes is written and committed whole);
//!   `main` then exits quietly with status [`BROKEN_PIPE_STATUS`] (141 = 128 + SIGPIPE, what a
//!   shell reports for `cat`, `grep` and other programs stopped by a closed pipe, so `set -o
//!   pipefail` scripts see the same status);
//! - any other write error (`> /dev/full`) is remembered too, and `main` reports it and exits
//!   with status 1 once the command has finished.

use std::fmt;
use std::io::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// Exit status after a command whose standard output was a closed pipe (128 + SIGPIPE).
pub const BROKEN_PIPE_STATUS: u8 = 141;

/// Standard output was a closed pipe; nothing more is written to it.
static CLOSED: AtomicBool = AtomicBool::new(false);
/// The first other error writing standard output.
static FAILED: Mutex<Option<String>> = Mutex::new(None);

/// Writes `args` to standard output (and flushes it), remembering instead of panicking when it
/// fails (see the module docs).
pub fn write(args: fmt::Arguments) {
    if CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout.write_fmt(args).and_then(|()| stdout.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            CLOSED.store(true, Ordering::Relaxed);
        } else if let Ok(mut failed) = FAILED.lock() {
            failed.get_or_insert_with(|| e.to_string());
        }
    }
}

/// How writing standard output went.
pub enum Status {
    /// Everything was written (or nothing was).
    Written,
    /// Standard output was a closed pipe.
    Closed,
    /// Another error (the first one's message).
    Failed(String),
}

/// How writing standard output went so far.
pub fn status() -> Status {
    if CLOSED.load(Ordering::Relaxed) {
        return Status::Closed;
    }
    match FAILED.lock().ok().and_then(|f| f.clone()) {
        Some(e) => Status::Failed(e),
        None => Status::Written,
    }
}

/// `println!` to standard output through [`write`]: never panics on a closed pipe.
macro_rules! outln {
    () => {
        $crate::cli::out::write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::cli::out::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` to standard output through [`write`]: never panics on a closed pipe.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::out::write(format_args!($($arg)*))
    };
}
