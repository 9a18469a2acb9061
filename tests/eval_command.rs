//! `meshdeco eval` on built-in synthetic data: the results table has one row per (dataset,
//! method, K) cell with finite numbers, a rerun reuses every cell and reproduces the table byte
//! for byte, a fresh run reproduces the numbers (seeded training), a changed method block
//! retrains only its cells, interrupted or stale cells are never taken as finished, and bad
//! config keys are named in the error.

mod common;

use meshdeco::metrics::erms::Alignment;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use meshdeco::eval::{CELL_FILE, EvalConfig, EvalOptions, cell_dir, report::RESULTS_HEADER, run_silent};

const CONFIG: &str = r#"
name = "tiny"
[[dataset]]
name = "tube"
path = "synthetic:tube"
align = "none"
train = "every:3"
test = "rest"
ordered = true

[[method]]
label = "pca"
kind = "pca"

[[method]]
label = "splocs"
kind = "splocs"
components = [3]
max_iterations = 2
sparsity = 2.0

[[method]]
label = "ae"
kind = "autoencoder"
components = [3]
iterations = 8
checkpoint_every = 4
seed = 3

[sweep]
components = [2, 4]

[control_points]
counts = [3, 6]
trials = 2
"#;

fn tmp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-eval-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Rows of results.csv without the seconds column (wall time differs between fresh runs).
fn without_seconds(csv: &str) -> Vec<String> {
    let col = RESULTS_HEADER.split(',').position(|c| c == "seconds").unwrap();
    csv.lines()
        .map(|l| l.split(',').enumerate().filter(|(i, _)| *i != col).map(|(_, f)| f).collect::<Vec<_>>().join(","))
        .collect()
}

/// Same rows, same text fields, numbers equal to a relative 1e-9.
/// The autoencoder cell's row of `results.csv` in `dir`, without its seconds.
fn ae_row(dir: &Path) -> String {
    without_seconds(&read(&dir.join("results.csv"))).into_iter().find(|l| l.starts_with("tube,ae,")).unwrap()
}

fn assert_same_numbers(a: &[String], b: &[String]) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        for (u, v) in x.split(',').zip(y.split(',')) {
            match (u.parse::<f64>(), v.parse::<f64>()) {
                (Ok(p), Ok(q)) => assert!((p - q).abs() <= 1e-9 * p.abs().max(q.abs()), "{x}\nvs\n{y}"),
                _ => assert_eq!(u, v, "{x}\nvs\n{y}"),
            }
        }
    }
}

#[test]
fn sweep_table_reuse_reproducibility_and_retraining() {
    let cfg = EvalConfig::from_toml(CONFIG).unwrap();
    let a = tmp("a");
    let o = run_silent(&cfg, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused), (4, 0));
    let csv = read(&a.join("results.csv"));
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], RESULTS_HEADER);
    assert_eq!(lines.len(), 1 + 4, "{csv}");
    let n_cols = RESULTS_HEADER.split(',').count();
    let mut keys = Vec::new();
    for l in &lines[1..] {
        let f: Vec<&str> = l.split(',').collect();
        assert_eq!(f.len(), n_cols, "{l}");
        keys.push((f[1].to_string(), f[3].to_string()));
        // train_erms, test_erms, sted_spatial, sted_temporal (ordered), seconds: finite numbers.
        for i in [4, 5, 7, 8, 12] {
            let v: f64 = f[i].parse().unwrap_or_else(|_| panic!("column {i} of `{l}`"));
            assert!(v.is_finite() && v >= 0.0, "column {i} of `{l}`");
        }
        let regions: f64 = f[11].parse().unwrap();
        assert!(regions >= 1.0, "{l}");
        // Fitted-code test Erms: the autoencoder only, never above its encoder's.
        if f[1] == "ae" {
            let fitted: f64 = f[13].parse().unwrap_or_else(|_| panic!("fitted column of `{l}`"));
            assert!(fitted.is_finite() && fitted <= f[5].parse::<f64>().unwrap(), "{l}");
            // STED of the fitted codes' reconstruction beside the encoder's (ordered: both parts).
            for i in [14, 15] {
                let v: f64 = f[i].parse().unwrap_or_else(|_| panic!("fitted STED column {i} of `{l}`"));
                assert!(v.is_finite() && v >= 0.0, "{l}");
            }
        } else {
            assert!(f[13].is_empty() && f[14].is_empty() && f[15].is_empty(), "{l}");
        }
    }
    let want: Vec<(String, String)> = [("pca", "2"), ("pca", "4"), ("splocs", "3"), ("ae", "3")]
        .iter()
        .map(|(m, k)| (m.to_string(), k.to_string()))
        .collect();
    assert_eq!(keys, want);
    // Translation-free ACAP is centroid-aligned, displacements are not.
    assert!(lines[4].contains(",acap,3,") && lines[4].contains(",centroid,"), "{}", lines[4]);
    assert!(lines[1].contains(",displacement,2,") && lines[1].contains(",none,"), "{}", lines[1]);
    // The linear cells' test Erms against the rest shape (all weights zero) on the same test
    // frames and with the cell's alignment. Measured ratios: pca K2 0.252, pca K4 0.043, splocs
    // K3 (2 iterations) 0.138; bounds with ≥ 20 % margin. The autoencoder cell trains 8
    // iterations (it is here for the cache), 1.84 × the rest shape: its Erms is bounded in
    // tests/ae_erms_bounds.rs.
    let prepared = meshdeco::preprocess::prepare(&cfg.datasets[0].data).unwrap();
    let test_frames: Vec<_> = prepared.test_sequence().unwrap().frames;
    for (l, bound) in lines[1..4].iter().zip([0.35, 0.06, 0.2]) {
        let f: Vec<&str> = l.split(',').collect();
        let alignment = if l.contains(",centroid,") { Alignment::Centroid } else { Alignment::None };
        let rest = common::constant_shape_erms(&test_frames, &prepared.rest.positions, alignment);
        let test: f64 = f[5].parse().unwrap();
        eprintln!("{} K {}: test Erms {test:.3}, rest shape {rest:.3}, ratio {:.3}", f[1], f[3], test / rest);
        assert!(test < bound * rest, "{l}: test Erms {test} not below {bound} × the rest shape's {rest}");
    }
    // More PCA components fit the training set better.
    let e = |l: &str| l.split(',').nth(4).unwrap().parse::<f64>().unwrap();
    assert!(e(lines[2]) < e(lines[1]));
    // Control points for the displacement models at their largest K; report and plots exist.
    let cp = read(&a.join("control_points.csv"));
    assert_eq!(cp.lines().count(), 1 + 3 * 2, "{cp}");
    assert!(
        cp.lines().skip(1).all(|l| ["tube,pca,4,", "tube,splocs,3,", "tube,ae,3,"].iter().any(|p| l.starts_with(p))),
        "{cp}"
    );
    for l in cp.lines().skip(1) {
        let mean: f64 = l.split(',').nth(4).unwrap().parse().unwrap();
        assert!(mean.is_finite() && mean > 0.0, "{l}");
    }
    for f in ["report.md", "erms_tube.png", "sted_tube.png", "sted_temporal_tube.png", "control_points_tube.png"] {
        assert!(a.join(f).is_file(), "{f} missing");
        if f.ends_with(".png") {
            let (w, h, ink, colours) = common::png_ink(&a.join(f));
            eprintln!("{f}: {w}×{h}, {:.1} % drawn, {colours} colours", 100.0 * ink);
            assert!(ink > 0.01 && colours > 2, "{f}: {ink} of the pixels drawn, {colours} colours");
        }
    }
    assert!(read(&a.join("report.md")).contains("| splocs | displacement | 3 |"));

    // Rerun into the same directory: everything reused, identical table.
    let o = run_silent(&cfg, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused), (0, 4));
    assert_eq!(read(&a.join("results.csv")), csv);
    assert_eq!(read(&a.join("control_points.csv")), cp);
    // --replot works from the cached cells alone.
    let o = run_silent(&cfg, &a, &EvalOptions { replot: true, stop: None }).unwrap();
    assert_eq!(o.reused, 4);

    // A fresh directory gives the same numbers (seeded), apart from the wall time; up to
    // round-off, since SPLOCS sums in parallel (order of floating-point additions).
    let b = tmp("b");
    run_silent(&cfg, &b, &EvalOptions::default()).unwrap();
    assert_same_numbers(&without_seconds(&read(&b.join("results.csv"))), &without_seconds(&csv));
    assert_same_numbers(
        &read(&b.join("control_points.csv")).lines().map(String::from).collect::<Vec<_>>(),
        &cp.lines().map(String::from).collect::<Vec<_>>(),
    );
    std::fs::remove_dir_all(&b).unwrap();

    // A changed method block retrains only that method's cell.
    let changed = EvalConfig::from_toml(&CONFIG.replace("sparsity = 2.0", "sparsity = 4.0")).unwrap();
    let o = run_silent(&changed, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused), (1, 3));
    let new_csv = read(&a.join("results.csv"));
    let (old, new) = (without_seconds(&csv), without_seconds(&new_csv));
    assert_eq!(old[..3], new[..3]);
    assert_eq!(old[4], new[4]);
    assert_ne!(old[3].split(',').nth(4), new[3].split(',').nth(4));

    // A damaged (partial) cell result is not taken as finished: that cell is retrained.
    let dir = cell_dir(&a, "tube", "pca", 4);
    std::fs::write(dir.join(CELL_FILE), "{ \"config_text\": ").unwrap();
    let o = run_silent(&changed, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused), (1, 3));
    assert_same_numbers(&without_seconds(&read(&a.join("results.csv"))), &new);
    std::fs::remove_dir_all(&a).unwrap();
}

#[test]
fn interrupted_and_replot_without_cells_leave_nothing_finished() {
    let cfg = EvalConfig::from_toml(CONFIG).unwrap();
    let d = tmp("stop");
    let stop = Arc::new(AtomicBool::new(true));
    let e = run_silent(&cfg, &d, &EvalOptions { replot: false, stop: Some(stop) }).unwrap_err().to_string();
    assert!(e.contains("interrupted"), "{e}");
    assert!(!cell_dir(&d, "tube", "pca", 2).join(CELL_FILE).exists());
    let e = run_silent(&cfg, &d, &EvalOptions { replot: true, stop: None }).unwrap_err().to_string();
    assert!(e.contains("--replot") && e.contains("tube/pca/K2"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// A bad key through the command line: non-zero exit, the key and the file in the message, no
/// panic, nothing written. (Which keys are caught, with which names, is the unit test
/// `eval::config::tests::errors_name_the_key`.)
#[test]
fn bad_keys_are_named() {
    let bad = CONFIG.replace("trials = 2", "trails = 2");
    let d = tmp("badkey");
    std::fs::create_dir_all(&d).unwrap();
    let f = d.join("bad.toml");
    std::fs::write(&f, &bad).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_meshdeco"))
        .args(["eval", "--config", f.to_str().unwrap(), "--out", d.join("out").to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("control_points.trails") && err.contains("bad.toml") && !err.contains("panicked"), "{err}");
    assert!(!d.join("out").exists());
    std::fs::remove_dir_all(&d).unwrap();
}

/// Stops the sweep once the autoencoder's training stage (8 iterations) has passed `at` steps,
/// and records the steps it sees.
struct StopDuringAe {
    stop: Arc<AtomicBool>,
    at: u64,
    in_ae: bool,
    steps: Vec<u64>,
}

impl meshdeco::pipeline::Progress for StopDuringAe {
    fn stage(&mut self, _: &str, total: u64) {
        self.in_ae = total == 8;
    }
    fn step(&mut self, i: u64, _: &str) {
        if self.in_ae {
            self.steps.push(i);
            if i >= self.at {
                self.stop.store(true, std::sync::atomic::Ordering::SeqCst);
            }
        }
    }
}

/// An autoencoder cell interrupted mid-training (after its checkpoint at iteration 4) resumes
/// from that checkpoint on the rerun (its first step is past 4) and ends with the numbers of an
/// uninterrupted run.
#[test]
fn interrupted_autoencoder_cell_resumes_from_its_checkpoint() {
    let cfg = EvalConfig::from_toml(CONFIG).unwrap();
    let whole = tmp("ae-whole");
    run_silent(&cfg, &whole, &EvalOptions::default()).unwrap();
    let d = tmp("ae-resume");
    let stop = Arc::new(AtomicBool::new(false));
    let mut p = StopDuringAe { stop: stop.clone(), at: 6, in_ae: false, steps: Vec::new() };
    let opts = EvalOptions { replot: false, stop: Some(stop.clone()) };
    let e = meshdeco::eval::run(&cfg, &d, &opts, &mut meshdeco::pipeline::Silent, &mut p).unwrap_err().to_string();
    eprintln!("interrupted after AE steps {:?}: {e}", p.steps);
    assert!(e.contains("interrupted"), "{e}");
    assert!(!cell_dir(&d, "tube", "ae", 3).join(CELL_FILE).exists());
    assert!(cell_dir(&d, "tube", "pca", 2).join(CELL_FILE).exists(), "finished cells are kept");
    let mut p = StopDuringAe { stop: Arc::new(AtomicBool::new(false)), at: u64::MAX, in_ae: false, steps: Vec::new() };
    let o = meshdeco::eval::run(&cfg, &d, &EvalOptions::default(), &mut meshdeco::pipeline::Silent, &mut p).unwrap();
    eprintln!("rerun: trained {}, reused {}, AE steps {:?}", o.trained, o.reused, p.steps);
    assert_eq!((o.trained, o.reused), (1, 3));
    let first = *p.steps.first().expect("the autoencoder cell trained");
    assert!(first > 4, "the rerun started at step {first}, not after the checkpoint at 4: {:?}", p.steps);
    assert_same_numbers(&[ae_row(&d)], &[ae_row(&whole)]);
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::remove_dir_all(&whole);
}

/// A trained autoencoder cell whose config changes only in an inference key
/// (`decoder_edge_weight`) is measured again from its finished checkpoint, not trained again:
/// no training step runs, the checkpoint and the training log stay byte for byte, the cell's
/// seconds stay the training's, the model records the new key, and the numbers equal a fresh
/// run of the changed config. A training key (`seed`) trains it again.
#[test]
fn an_inference_key_change_measures_the_trained_cell_again() {
    let cfg = EvalConfig::from_toml(CONFIG).unwrap();
    let a = tmp("remeasure");
    run_silent(&cfg, &a, &EvalOptions::default()).unwrap();
    let ae = cell_dir(&a, "tube", "ae", 3);
    let bytes = |f: &str| std::fs::read(ae.join(f)).unwrap();
    let (checkpoint, log) = (bytes("checkpoint.bin"), bytes("training.jsonl"));
    let cell = |dir: &Path| -> serde_json::Value {
        serde_json::from_str(&read(&cell_dir(dir, "tube", "ae", 3).join(CELL_FILE))).unwrap()
    };
    let before = cell(&a);

    let changed_text = CONFIG.replace("seed = 3\n", "seed = 3\ndecoder_edge_weight = 0.5\n");
    let changed = EvalConfig::from_toml(&changed_text).unwrap();
    let mut p = StopDuringAe { stop: Arc::new(AtomicBool::new(false)), at: u64::MAX, in_ae: false, steps: Vec::new() };
    let o =
        meshdeco::eval::run(&changed, &a, &EvalOptions::default(), &mut meshdeco::pipeline::Silent, &mut p).unwrap();
    eprintln!("trained {}, reused {}, measured again {}, AE steps {:?}", o.trained, o.reused, o.remeasured, p.steps);
    assert_eq!((o.trained, o.reused, o.remeasured), (0, 3, 1));
    assert!(p.steps.iter().all(|&s| s == 8), "training steps ran: {:?}", p.steps);
    assert!(bytes("checkpoint.bin") == checkpoint, "the checkpoint changed");
    // The log keeps every step; the measuring run adds no step (only the end-of-run check's line).
    let new_log = String::from_utf8(bytes("training.jsonl")).unwrap();
    let added = new_log.strip_prefix(std::str::from_utf8(&log).unwrap()).expect("the training log was rewritten");
    assert!(!added.contains("\"iteration\""), "steps were logged: {added}");
    let after = cell(&a);
    assert_eq!(after["seconds"], before["seconds"], "the seconds stay the training's");
    // The model folder's training time: the checkpoint's, plus the measuring run's (no step).
    let trained_for =
        meshdeco::nn::checkpoint::Checkpoint::load(&ae.join("checkpoint.bin")).unwrap().header.train_seconds;
    let metrics: serde_json::Value = serde_json::from_str(&read(&ae.join("metrics.json"))).unwrap();
    let seconds = metrics["train_seconds"].as_f64().unwrap();
    eprintln!("checkpoint: trained {trained_for} s; metrics.json after measuring again: {seconds} s");
    assert!(trained_for > 0.0 && seconds >= trained_for, "{seconds} s against the checkpoint's {trained_for} s");
    assert_ne!(after["config_text"], before["config_text"]);
    assert_ne!(after["test_erms"], before["test_erms"], "the new decoder weight decodes otherwise");
    let model: serde_json::Value = serde_json::from_str(&read(&ae.join("model.json"))).unwrap();
    assert_eq!(model["decoder_edge_weight"], serde_json::json!(0.5));
    // Rerun: reused as is.
    let o = run_silent(&changed, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused, o.remeasured), (0, 4, 0));
    // A default that changed since the cell was made, though the text is the same: as recorded in
    // cell.json, the method's resolved keys differ. An inference key's: measured again; a
    // training key's: trained again.
    let cell_file = ae.join(CELL_FILE);
    let edit = |key: &str| {
        let mut v: serde_json::Value = serde_json::from_str(&read(&cell_file)).unwrap();
        let k = v[key].as_str().expect("the resolved keys are recorded").replace("seed: 3", "seed: 99");
        v[key] = serde_json::json!(k);
        std::fs::write(&cell_file, serde_json::to_string(&v).unwrap()).unwrap();
    };
    edit("method_keys");
    let o = run_silent(&changed, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused, o.remeasured), (0, 3, 1), "an inference default changed");
    assert!(bytes("checkpoint.bin") == checkpoint);
    edit("method_keys");
    edit("training_keys");
    let o = run_silent(&changed, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused, o.remeasured), (1, 3, 0), "a training default changed");

    // The same numbers as training the changed config afresh.
    let b = tmp("remeasure-fresh");
    run_silent(&changed, &b, &EvalOptions::default()).unwrap();
    assert_same_numbers(&[ae_row(&a)], &[ae_row(&b)]);
    std::fs::remove_dir_all(&b).unwrap();

    // A training key trains the cell again.
    let reseeded = EvalConfig::from_toml(&changed_text.replace("seed = 3\n", "seed = 4\n")).unwrap();
    let o = run_silent(&reseeded, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused, o.remeasured), (1, 3, 0));
    assert!(bytes("checkpoint.bin") != checkpoint, "a new seed trains a new network");
    std::fs::remove_dir_all(&a).unwrap();
}

/// An autoencoder cell that held out validation shapes keeps its best validation step's model;
/// its checkpoint holds that step, so it too is measured again (not trained) on an inference key
/// change, to the numbers of a fresh run of the changed config.
#[test]
fn a_cell_with_held_out_validation_shapes_is_measured_again_with_its_best_step() {
    let held = CONFIG.replace("seed = 3\n", "seed = 3\nvalidation = 2\nvalidate_every = 2\n");
    let a = tmp("remeasure-val");
    run_silent(&EvalConfig::from_toml(&held).unwrap(), &a, &EvalOptions::default()).unwrap();
    let changed_text = held.replace("seed = 3\n", "seed = 3\ndecoder_edge_weight = 0.5\n");
    let changed = EvalConfig::from_toml(&changed_text).unwrap();
    let o = run_silent(&changed, &a, &EvalOptions::default()).unwrap();
    assert_eq!((o.trained, o.reused, o.remeasured), (0, 3, 1));
    let b = tmp("remeasure-val-fresh");
    run_silent(&changed, &b, &EvalOptions::default()).unwrap();
    assert_same_numbers(&[ae_row(&a)], &[ae_row(&b)]);
    std::fs::remove_dir_all(&a).unwrap();
    std::fs::remove_dir_all(&b).unwrap();
}

/// `sweep.select = "validation"` (issue 31): per dataset the report marks the cell of lowest
/// validation Erms — the argmin of the `validation_erms` column, whatever the test column says —
/// and `selection.csv` names it; without a validation split in every dataset, or with another
/// value, the config is refused naming the key.
#[test]
fn eval_selects_on_validation_and_marks_the_choice() {
    let text = r#"
name = "select"
[[dataset]]
name = "tube"
path = "synthetic:tube"
align = "none"
train = "every:2"
validation = "auto:30%"
test = "rest"
ordered = true

[[method]]
label = "pca"
kind = "pca"

[sweep]
components = [1, 2, 4]
select = "validation"
"#;
    let cfg = EvalConfig::from_toml(text).unwrap();
    let out = tmp("select");
    run_silent(&cfg, &out, &EvalOptions::default()).unwrap();
    let csv = read(&out.join("results.csv"));
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let (kc, vc) = (col("K"), col("validation_erms"));
    let rows: Vec<(String, f64)> = csv
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[kc].to_string(), f[vc].parse::<f64>().expect("every cell has a validation Erms"))
        })
        .collect();
    assert_eq!(rows.len(), 3);
    let best = rows.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    let selection = read(&out.join("selection.csv"));
    let line: Vec<&str> = selection.lines().nth(1).expect("one chosen cell").split(',').collect();
    assert_eq!((line[0], line[1], line[2]), ("tube", "pca", best.0.as_str()), "{selection}");
    let report = read(&out.join("report.md"));
    assert_eq!(report.matches("(chosen on validation)").count(), 1, "{report}");
    assert!(report.contains("lowest *validation* Erms"));
    let _ = std::fs::remove_dir_all(&out);

    let no_validation = text.replace("validation = \"auto:30%\"\n", "");
    let e = EvalConfig::from_toml(&no_validation).unwrap_err().to_string();
    assert!(e.contains("dataset.tube.validation"), "{e}");
    let e =
        EvalConfig::from_toml(&text.replace("select = \"validation\"", "select = \"test\"")).unwrap_err().to_string();
    assert!(e.contains("sweep.select") && e.contains("test"), "{e}");
}
