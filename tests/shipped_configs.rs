//! Every config shipped in `configs/` parses and validates, so a user's first run never fails
//! on a typo of ours.

use meshdeco::config::Config;

#[test]
fn every_shipped_config_validates() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let mut files: Vec<_> = walk(&dir);
    files.sort();
    assert!(files.len() >= 7, "expected the shipped configs, found {files:?}");
    for f in files.iter().filter(|f| !f.starts_with(dir.join("eval"))) {
        let c = Config::from_file(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert!(!c.name.is_empty());
    }
    // The paper's dataset configs for the autoencoder exist.
    for name in ["demo", "scape", "horse", "swing", "jumping", "face", "humanoid"] {
        assert!(dir.join(format!("{name}.toml")).exists(), "configs/{name}.toml missing");
    }
}

#[test]
fn every_shipped_eval_config_validates() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs").join("eval");
    for name in ["demo", "scape", "horse"] {
        let f = dir.join(format!("{name}.toml"));
        let c = meshdeco::eval::EvalConfig::from_file(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let cells = c.cells().unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert!(!cells.is_empty());
    }
    for f in walk(&dir) {
        match meshdeco::eval::EvalConfig::from_file(&f) {
            Ok(_) => {}
            // Configs on the ground-truth sets (a `truth = ` key) read their planted sets
            // (`scripts/ground-truth` writes them under checkpoints/, which a clean clone lacks):
            // without them the error names the key and the file.
            Err(e) if reads_planted_truth(&f) => {
                let msg = e.to_string();
                assert!(msg.contains(".truth") && msg.contains(&*f.to_string_lossy()), "{}: {msg}", f.display());
            }
            Err(e) => panic!("{}: {e}", f.display()),
        }
    }
}

/// Whether an eval config names a planted ground-truth set (`truth = "…"` in a `[[dataset]]`).
fn reads_planted_truth(f: &std::path::Path) -> bool {
    std::fs::read_to_string(f).unwrap().lines().any(|l| l.trim_start().starts_with("truth"))
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else if p.extension().is_some_and(|x| x == "toml") {
            out.push(p);
        }
    }
    out
}
