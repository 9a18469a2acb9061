//! Helpers shared by the integration tests (`mod common;` in each test file).
//!
//! `shared_or_skip` is the one way a test reaches the external references in `../shared`
//! (real datasets, the ACAP reference fixtures). In CI (`CI` set in the environment) a missing
//! path is a failure: `../shared` is always beside the clone there. Locally a missing path skips
//! the test with a reason on stderr and a line in [`skip_log`], which `.ci/run` and
//! `scripts/skipped` count at the end of a run (`cargo test` hides a passing test's output).
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};

/// `../shared` beside the repository.
pub fn shared_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared")
}

/// The file that records skipped tests, one line per skip: `<test>\t<missing path>`.
/// `$CARGO_TARGET_DIR/tmp/meshdeco-skipped-tests.txt` (Cargo's scratch folder for integration
/// tests); `.ci/run` and `scripts/skipped` read it.
pub fn skip_log() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("meshdeco-skipped-tests.txt")
}

/// `../shared/<rel>` when it exists. Otherwise: panics when `CI` is set (naming the path), else
/// prints the reason, records the skip and returns `None`.
pub fn shared_or_skip(rel: &str) -> Option<PathBuf> {
    let p = shared_root().join(rel);
    if p.exists() {
        return Some(p);
    }
    let test = std::thread::current().name().unwrap_or("?").to_string();
    if std::env::var_os("CI").is_some() {
        panic!("CI is set but the external reference {} is missing (needed by {test})", p.display());
    }
    eprintln!("SKIPPED {test}: {} is absent", p.display());
    let log = skip_log();
    if let Some(dir) = log.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    if let Ok(mut f) = std::fs::OpenOptions::new().create(true).append(true).open(&log) {
        let _ = writeln!(f, "{}\t{test}\t{}", env!("CARGO_CRATE_NAME"), p.display());
    }
    None
}
