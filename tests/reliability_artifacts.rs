//! Probe suite of issue 29, items 7–12, 14 and 15: what loaders trust behind the checksum (every
//! mutation made with the manifest re-recorded), a kill at every step of a retrain's commit, two
//! writers of one output file, 255-byte output names, manifests that list too little, a refused
//! `--resume` followed by another, readers while a training holds the lock, hand edits of
//! `config.toml`. Every case counts into the totals printed at the end of each test.

#![cfg(unix)]

use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use meshdeco::artifact;

mod common;
use common::{meshdeco, output_text};

fn tmp(tag: &str) -> PathBuf {
    common::fresh_dir("relart", tag)
}

const PCA: &str =
    "[data]\npath = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"rest\"\n[method]\nkind = \"pca\"\ncomponents = 3\n";
const PCA4: &str =
    "[data]\npath = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"rest\"\n[method]\nkind = \"pca\"\ncomponents = 4\n";
const REGION: &str = "[data]\npath = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"rest\"\n[method]\nkind = \"region-pca\"\ncomponents = 8\nmax_regions = 4\n";
const AE: &str = "[data]\npath = \"synthetic:tube\"\ntrain = \"every:4\"\ntest = \"rest\"\n[method]\nkind = \"autoencoder\"\ncomponents = 3\niterations = 30\ncheckpoint_every = 10\nfit_test = false\n";

fn train_into(d: &Path, out: &Path, name: &str, toml: &str, extra: &[&str]) -> Output {
    let cfg = d.join(format!("{name}.toml"));
    std::fs::write(&cfg, toml).unwrap();
    let mut args = vec!["train", "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    meshdeco(&args, d)
}

fn train(d: &Path, name: &str, toml: &str) -> PathBuf {
    let out = d.join(name);
    let o = train_into(d, &out, name, toml, &[]);
    assert!(o.status.success(), "{}", output_text(&o));
    out
}

/// Asserts a clean refusal: exit status 1 (not a panic's 101, not an abort's signal), every
/// needle in the message, no panic text, and a lock message said once (not nested in itself).
fn refused(o: &Output, needles: &[&str], what: &str) {
    let t = output_text(o);
    assert_eq!(o.status.code(), Some(1), "{what}: status {:?} (expected a refusal): {t}", o.status);
    assert!(!t.contains("panicked"), "{what}: {t}");
    for n in needles {
        assert!(t.contains(n), "{what}: `{n}` not in: {t}");
    }
    assert!(t.matches("being written").count() <= 1 && t.matches("reading it gave").count() <= 1, "{what}: {t}");
}

/// Re-records `dir`'s manifest after an edit, as a user "fixing" it (or another tool) would.
fn rerecord(dir: &Path) {
    let m = artifact::compute_manifest(dir).unwrap();
    std::fs::write(dir.join("manifest.json"), serde_json::to_string_pretty(&m).unwrap()).unwrap();
}

/// (offset in numbers, length in numbers) of array `name` in `dir`'s model.bin.
fn array_span(dir: &Path, name: &str) -> (usize, usize) {
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("model.json")).unwrap()).unwrap();
    let e = &v["arrays"][name];
    let shape: Vec<usize> = e["shape"].as_array().unwrap().iter().map(|x| x.as_u64().unwrap() as usize).collect();
    (e["offset"].as_u64().unwrap() as usize, shape.iter().product())
}

fn set_number(bytes: &mut [u8], index: usize, value: f64) {
    bytes[8 * index..8 * index + 8].copy_from_slice(&value.to_le_bytes());
}

/// The commands that read a model and write a file, with the file they write.
fn outputs_of(model: &Path) -> Vec<(Vec<String>, &'static str)> {
    let m = model.to_str().unwrap().to_string();
    vec![
        (
            vec!["synthesize".into(), m.clone(), "--weights".into(), "0:1".into(), "--out".into(), "s.obj".into()],
            "s.obj",
        ),
        (vec!["export".into(), m, "--out".into(), "m.glb".into()], "m.glb"),
    ]
}

/// Runs every model-reading command on `model`: each must refuse with `needles`, writing nothing.
fn all_refuse(model: &Path, d: &Path, needles: &[&str], what: &str) -> usize {
    let mut n = 0;
    for (args, out) in outputs_of(model) {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = meshdeco(&refs, d);
        refused(&o, needles, &format!("{what}, {}", args[0]));
        assert!(!d.join(out).exists(), "{what}: a refused {} wrote {out}", args[0]);
        n += 1;
    }
    n
}

fn copy_dir(from: &Path, to: &Path) {
    let _ = std::fs::remove_dir_all(to);
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &to.join(e.file_name()));
        } else {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// Item 7 (b, c): model.bin edited and the manifest re-recorded — values made non-finite or
/// huge, every array shifted by one number, truncated, extended, a block duplicated, another
/// model's model.bin, face indices made negative, fractional or out of range. Each is refused
/// by the loader itself, naming the file; no OBJ or glTF is written.
#[test]
fn rerecorded_model_bin_mutations_are_refused() {
    let d = tmp("bin");
    let models = [train(&d, "pca", PCA), train(&d, "region", REGION), train(&d, "ae", AE)];
    let other = train(&d, "pca4", PCA4);
    let mut cases = 0;
    for model in &models {
        let bin = model.join("model.bin");
        let good = std::fs::read(&bin).unwrap();
        let n = good.len() / 8;
        let mut mutations: Vec<(String, Vec<u8>, Vec<&str>)> = Vec::new();
        for (label, value) in
            [("inf", f64::INFINITY), ("-inf", f64::NEG_INFINITY), ("NaN", f64::NAN), ("1e300", 1e300), ("-1e20", -1e20)]
        {
            for at in [0, n / 2, n - 1] {
                let mut b = good.clone();
                set_number(&mut b, at, value);
                let needle = if value.is_finite() { "beyond" } else { "non-finite" };
                mutations.push((format!("{label} at number {at}"), b, vec!["model.bin", needle]));
            }
        }
        mutations.push((
            "shifted by one number".into(),
            [vec![0u8; 8], good.clone()].concat(),
            vec!["model.bin", "describes"],
        ));
        mutations.push(("last number dropped".into(), good[..good.len() - 8].to_vec(), vec!["model.bin", "describes"]));
        mutations.push((
            "one number appended".into(),
            [good.clone(), vec![0u8; 8]].concat(),
            vec!["model.bin", "describes"],
        ));
        mutations.push((
            "first block duplicated".into(),
            [good[..512].to_vec(), good.clone()].concat(),
            vec!["model.bin", "describes"],
        ));
        mutations.push((
            "another model's".into(),
            std::fs::read(other.join("model.bin")).unwrap(),
            vec!["model.bin", "describes"],
        ));
        let (faces, len) = array_span(model, "faces");
        for (label, value) in [("-1", -1.0), ("2.5", 2.5), ("1e9", 1e9)] {
            let mut b = good.clone();
            set_number(&mut b, faces + len / 2, value);
            mutations.push((format!("a face index {label}"), b, vec!["faces", "not an index"]));
        }
        for (what, bytes, needles) in mutations {
            std::fs::write(&bin, &bytes).unwrap();
            rerecord(model);
            cases += all_refuse(model, &d, &needles, &format!("{}: model.bin {what}", model.display()));
        }
        std::fs::write(&bin, &good).unwrap();
        rerecord(model);
        let o = meshdeco(&["synthesize", model.to_str().unwrap(), "--weights", "0:1", "--out", "s.obj"], &d);
        assert!(o.status.success(), "restored {}: {}", model.display(), output_text(&o));
        std::fs::remove_file(d.join("s.obj")).unwrap();
    }
    eprintln!("model.bin mutations with the manifest re-recorded: {cases} refused runs");
    assert!(cases >= 3 * 2 * 23, "{cases}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// Edits `file` (JSON) in `model` with `edit`, re-records the manifest, expects every reader to
/// refuse with `needles`, and restores the file.
fn json_case(model: &Path, d: &Path, file: &str, edit: impl Fn(&mut serde_json::Value), needles: &[&str]) -> usize {
    let path = model.join(file);
    let good = std::fs::read_to_string(&path).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    edit(&mut v);
    std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
    rerecord(model);
    let n = all_refuse(model, d, needles, &format!("{}: {file} edited", model.display()));
    std::fs::write(&path, good).unwrap();
    rerecord(model);
    n
}

/// Item 7 (a): absurd sizes and values in model.json and autoencoder.json, manifest re-recorded:
/// K = 10¹² (an abort before), 2⁶⁴−1, an array table that overflows or does not tile model.bin,
/// a huge or zero unit-box scale, a reference or centre vertex off the mesh.
#[test]
fn rerecorded_absurd_json_values_are_refused() {
    let d = tmp("json");
    let pca = train(&d, "pca", PCA);
    let region = train(&d, "region", REGION);
    let ae = train(&d, "ae", AE);
    let mut cases = 0;
    let set = |ptr: &'static str, value: serde_json::Value| {
        move |v: &mut serde_json::Value| *v.pointer_mut(ptr).unwrap_or_else(|| panic!("{ptr}")) = value.clone()
    };
    use serde_json::json;
    // The autoencoder's network file: K sizes a K × 9N allocation.
    cases += json_case(
        &ae,
        &d,
        "autoencoder.json",
        set("/config/components", json!(1_000_000_000_000u64)),
        &["autoencoder.json", "config.components", "1000000000000"],
    );
    cases += json_case(
        &ae,
        &d,
        "autoencoder.json",
        set("/config/components", json!(4)),
        &["autoencoder.json", "config.components", "different models"],
    );
    cases += json_case(
        &ae,
        &d,
        "model.json",
        set("/components", json!(1_000_000_000_000u64)),
        &["model.json", "`components` is 1000000000000"],
    );
    cases += json_case(&ae, &d, "model.json", set("/reference", json!(999)), &["model.json", "`reference` is 999"]);
    cases += json_case(
        &ae,
        &d,
        "model.json",
        set("/analysis/0/center", json!(1_000_000_000)),
        &["model.json", "analysis[0]"],
    );
    cases += json_case(
        &ae,
        &d,
        "model.json",
        set("/scaling/max/0", json!(1e300)),
        &["model.json", "scaling.max[0]", "beyond"],
    );
    for model in [&pca, &region, &ae] {
        cases += json_case(model, &d, "model.json", set("/components", json!(u64::MAX)), &["model.json", "components"]);
        cases +=
            json_case(model, &d, "model.json", set("/unit_box/scale", json!(1e300)), &["model.json", "unit_box.scale"]);
        cases += json_case(
            model,
            &d,
            "model.json",
            set("/unit_box/scale", json!(0.0)),
            &["model.json", "unit_box", "scale 0"],
        );
        cases += json_case(
            model,
            &d,
            "model.json",
            set("/arrays/faces/shape/0", json!(1_000_000_000_000u64)),
            &["model.json", "faces"],
        );
        cases += json_case(
            model,
            &d,
            "model.json",
            |v| {
                let o = v.pointer_mut("/arrays/faces/offset").unwrap();
                *o = json!(o.as_u64().unwrap() + 1);
            },
            &["model.json", "faces", "does not describe model.bin"],
        );
        cases += json_case(
            model,
            &d,
            "model.json",
            set("/arrays/rest_positions/shape", json!([4294967296u64, 4294967296u64, 3])),
            &["model.json", "rest_positions"],
        );
    }
    cases += json_case(&pca, &d, "model.json", set("/components", json!(0)), &["model.json", "`components` is 0"]);
    cases += json_case(&region, &d, "model.json", set("/components/0", json!(0)), &["model.json", "components[0]"]);
    cases += json_case(&region, &d, "model.json", set("/beta", json!(-1.0)), &["model.json", "`beta` is -1"]);
    eprintln!("absurd JSON values with the manifest re-recorded: {cases} refused runs");
    assert_eq!(cases, 2 * (6 + 3 * 6 + 3));
    std::fs::remove_dir_all(&d).unwrap();
}

/// Item 10: a manifest listing no files, one without model.bin (which is then damaged), one
/// without the autoencoder's weights: refused, naming the missing file.
#[test]
fn manifests_that_do_not_list_the_model_files_are_refused() {
    let d = tmp("manifest");
    let pca = train(&d, "pca", PCA);
    let ae = train(&d, "ae", AE);
    let mut cases = 0;
    let edit = |dir: &Path, f: &dyn Fn(&mut serde_json::Value)| {
        let p = dir.join("manifest.json");
        let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
        f(&mut v);
        std::fs::write(&p, serde_json::to_string(&v).unwrap()).unwrap();
    };
    edit(&pca, &|v| v["files"] = serde_json::json!({}));
    cases += all_refuse(&pca, &d, &["manifest.json", "does not list `model.json`", "0 files listed"], "empty manifest");
    rerecord(&pca);
    edit(&pca, &|v| {
        v["files"].as_object_mut().unwrap().remove("model.bin");
    });
    let bin = pca.join("model.bin");
    let good = std::fs::read(&bin).unwrap();
    let mut bad = good.clone();
    set_number(&mut bad, 10, 1e300);
    std::fs::write(&bin, &bad).unwrap();
    cases += all_refuse(&pca, &d, &["does not list `model.bin`"], "manifest without model.bin");
    std::fs::write(&bin, &good).unwrap();
    rerecord(&pca);
    for f in ["autoencoder.bpk", "autoencoder.json", "model.json"] {
        rerecord(&ae);
        edit(&ae, &|v| {
            v["files"].as_object_mut().unwrap().remove(f);
        });
        cases += all_refuse(&ae, &d, &[&format!("does not list `{f}`")], &format!("manifest without {f}"));
    }
    rerecord(&ae);
    for m in [&pca, &ae] {
        let o = meshdeco(&["synthesize", m.to_str().unwrap(), "--weights", "0:1", "--out", "s.obj"], &d);
        assert!(o.status.success(), "{}", output_text(&o));
    }
    eprintln!("manifests listing too little: {cases} refused runs");
    assert_eq!(cases, 10);
    std::fs::remove_dir_all(&d).unwrap();
}

/// Item 15: config.toml is for people — a comment or a changed value in it leaves the model
/// loadable (no loader reads it, the manifest does not list it), while an edit of a file the
/// loaders read is still refused.
#[test]
fn hand_edits_of_config_toml_are_accepted() {
    let d = tmp("config");
    let pca = train(&d, "pca", PCA);
    let manifest = std::fs::read_to_string(pca.join("manifest.json")).unwrap();
    assert!(!manifest.contains("config.toml"), "{manifest}");
    let cfg = pca.join("config.toml");
    let text = std::fs::read_to_string(&cfg).unwrap();
    let mut cases = 0;
    for edited in [format!("# my note\n{text}"), text.replace("components = 3", "components = 5"), String::new()] {
        std::fs::write(&cfg, &edited).unwrap();
        for (args, out) in outputs_of(&pca) {
            let refs: Vec<&str> = args.iter().map(String::as_str).collect();
            let o = meshdeco(&refs, &d);
            assert!(o.status.success(), "config.toml edited, {}: {}", args[0], output_text(&o));
            assert!(d.join(out).is_file());
            std::fs::remove_file(d.join(out)).unwrap();
            cases += 1;
        }
    }
    // An old manifest that still lists config.toml does not check it either.
    let mut v: serde_json::Value = serde_json::from_str(&manifest).unwrap();
    v["files"]["config.toml"] = serde_json::json!({"bytes": 1, "crc32": "00000000"});
    std::fs::write(pca.join("manifest.json"), serde_json::to_string(&v).unwrap()).unwrap();
    let o = meshdeco(&["synthesize", pca.to_str().unwrap(), "--weights", "0:1", "--out", "s.obj"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    std::fs::remove_file(d.join("s.obj")).unwrap();
    std::fs::write(pca.join("manifest.json"), &manifest).unwrap();
    cases += 1;
    let json = pca.join("model.json");
    let good = std::fs::read_to_string(&json).unwrap();
    std::fs::write(&json, format!("{good} ")).unwrap();
    cases += all_refuse(&pca, &d, &["model.json", "bytes"], "model.json edited");
    eprintln!("config.toml edits: {cases} cases");
    assert_eq!(cases, 9);
    std::fs::remove_dir_all(&d).unwrap();
}

/// The steps of a commit at which the crash test kills the training (`artifact::KILL_AT_ENV`).
const STEPS: [&str; 6] = ["staged", "renamed", "remove", "move", "manifest", "cleanup"];

/// Item 8: a retrain killed (SIGKILL) at every step of its commit — before the staging
/// directory becomes the commit's, after, before each removal of the old run's entries, before
/// each entry moves in, before the manifest is replaced, before the commit's directory goes —
/// leaves a directory that the next reader loads as the old model (killed before the commit
/// started) or the new one (every later kill: the reader finishes the commit), never neither.
/// A writer after the kill finishes it as well.
#[test]
fn a_kill_at_every_step_of_a_commit_leaves_the_old_or_the_new_model() {
    let d = tmp("kill");
    let views = "[output]\nviews = true\n";
    // Old: PCA K = 3 with views (components/); new: K = 4, with and without views (so the
    // commit replaces components/ or removes it).
    let old = train(&d, "old", &format!("{PCA}{views}"));
    let new_plain = train(&d, "new_plain", PCA4);
    let new_views = train(&d, "new_views", &format!("{PCA4}{views}"));
    let bin = |p: &Path| std::fs::read(p.join("model.bin")).unwrap();
    let (old_bin, new_bin) = (bin(&old), bin(&new_plain));
    assert_ne!(old_bin, new_bin);
    assert_eq!(bin(&new_views), new_bin);
    let mut kills = 0;
    for (scenario, toml) in [("plain", PCA4.to_string()), ("views", format!("{PCA4}{views}"))] {
        for step in STEPS {
            for nth in 1.. {
                let w = d.join("w");
                copy_dir(&old, &w);
                let cfg = d.join("new.toml");
                std::fs::write(&cfg, &toml).unwrap();
                let o = Command::new(env!("CARGO_BIN_EXE_meshdeco"))
                    .args(["train", "--config", cfg.to_str().unwrap(), "--out", w.to_str().unwrap()])
                    .env(artifact::KILL_AT_ENV, format!("{step}#{nth}"))
                    .current_dir(&d)
                    .output()
                    .unwrap();
                if o.status.success() {
                    assert!(nth > 1 || step == "remove", "{scenario}: step {step} never reached: {}", output_text(&o));
                    assert_eq!(bin(&w), new_bin);
                    break;
                }
                assert_eq!(o.status.signal(), Some(9), "{scenario} {step}#{nth}: {}", output_text(&o));
                kills += 1;
                let what = format!("{scenario}: killed at {step}#{nth}");
                // Even a reader is told what state the directory is in; then loads it.
                let reader = nth % 2 == 1;
                if reader {
                    let o = meshdeco(&["synthesize", w.to_str().unwrap(), "--weights", "0:1", "--out", "s.obj"], &d);
                    assert!(o.status.success(), "{what}: {}", output_text(&o));
                } else {
                    let o = meshdeco(&["train", "--config", cfg.to_str().unwrap(), "--out", w.to_str().unwrap()], &d);
                    assert!(o.status.success(), "{what}: the next training: {}", output_text(&o));
                }
                let got = bin(&w);
                let expect_old = step == "staged" && reader;
                assert!(got == old_bin || got == new_bin, "{what}: model.bin is neither the old nor the new");
                assert_eq!(
                    got == old_bin,
                    expect_old,
                    "{what}: expected the {} model",
                    if expect_old { "old" } else { "new" }
                );
                // Nothing half done is left beside it, and the directory verifies as a whole.
                let commit = artifact::commit_path(&w).unwrap();
                assert!(!commit.exists(), "{what}: {} left", commit.display());
                artifact::open_for_reading(&w).unwrap_or_else(|e| panic!("{what}: {e}"));
                let has_views = w.join("components").is_dir();
                let want_views = scenario == "views" || expect_old;
                assert_eq!(has_views, want_views, "{what}: components/");
                let _ = std::fs::remove_file(d.join("s.obj"));
            }
        }
    }
    eprintln!("kills during a commit: {kills}, each left the old or the new model");
    assert!(kills >= 16, "{kills}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// Items 9 and 14: two (four) `synthesize --out s.obj` at once each write a whole file, the
/// last rename wins, no temporary file is left; threads of one process likewise; a 255-byte
/// output name works (its temporary name fits), a 256-byte one is a clear error.
#[test]
fn concurrent_writers_and_long_names() {
    let d = tmp("writers");
    let pca = train(&d, "pca", PCA);
    let m = pca.to_str().unwrap();
    let weights = ["0:1", "0:-1", "1:2", "2:-0.5"];
    let mut expected = Vec::new();
    for (i, w) in weights.iter().enumerate() {
        let out = format!("ref{i}.obj");
        let o = meshdeco(&["synthesize", m, "--weights", w, "--out", &out], &d);
        assert!(o.status.success(), "{}", output_text(&o));
        expected.push(std::fs::read(d.join(&out)).unwrap());
    }
    let mut cases = 0;
    for round in 0..6 {
        let children: Vec<_> = weights
            .iter()
            .map(|w| {
                Command::new(env!("CARGO_BIN_EXE_meshdeco"))
                    .args(["synthesize", m, "--weights", w, "--out", "s.obj"])
                    .current_dir(&d)
                    .stdout(std::process::Stdio::piped())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        for c in children {
            let o = c.wait_with_output().unwrap();
            assert!(o.status.success(), "round {round}: {}", output_text(&o));
            cases += 1;
        }
        let got = std::fs::read(d.join("s.obj")).unwrap();
        assert!(expected.contains(&got), "round {round}: s.obj is not one writer's whole output");
        let left: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect();
        assert!(left.is_empty(), "round {round}: temporary files left: {left:?}");
    }
    // Threads of one process writing one file.
    let target = d.join("t.bin");
    std::thread::scope(|s| {
        for t in 0..8u8 {
            let target = &target;
            s.spawn(move || {
                for _ in 0..25 {
                    artifact::write_atomic_with(target, |w| std::io::Write::write_all(w, &[t; 4096])).unwrap();
                }
            });
        }
    });
    let got = std::fs::read(&target).unwrap();
    assert!(got.len() == 4096 && got.iter().all(|&b| b == got[0]), "threads interleaved a file");
    cases += 8 * 25;
    // 255-byte names (the longest a file system takes), ASCII and multi-byte.
    for name in ["a".repeat(251) + ".obj", "é".repeat(125) + "x.obj"] {
        assert_eq!(name.len(), 255);
        assert!(artifact::temp_path(&d.join(&name)).file_name().unwrap().len() <= 255);
        let o = meshdeco(&["synthesize", m, "--weights", "0:1", "--out", &name], &d);
        assert!(o.status.success(), "255-byte name: {}", output_text(&o));
        assert_eq!(std::fs::read(d.join(&name)).unwrap(), expected[0]);
        cases += 1;
    }
    let too_long = "b".repeat(252) + ".obj";
    let o = meshdeco(&["synthesize", m, "--weights", "0:1", "--out", &too_long], &d);
    refused(&o, &["File name too long"], "256-byte name");
    cases += 1;
    eprintln!("concurrent writers and long names: {cases} cases");
    assert_eq!(cases, 6 * 4 + 200 + 3);
    std::fs::remove_dir_all(&d).unwrap();
}

/// Item 11: a refused `--resume` (a damaged finished checkpoint) leaves nothing behind that a
/// later `--resume` would prefer; both messages name the user's checkpoint, never the hidden
/// staging copy; once repaired, `--resume` continues.
#[test]
fn a_refused_resume_does_not_poison_later_ones() {
    let d = tmp("resume");
    let ae = train(&d, "ae", AE);
    let staging = artifact::staging_path(&ae).unwrap();
    let ck = ae.join("checkpoint.bin");
    let good = std::fs::read(&ck).unwrap();
    let mut bad = good.clone();
    let mid = bad.len() / 2;
    bad[mid] ^= 0x40;
    std::fs::write(&ck, &bad).unwrap();
    let longer = AE.replace("iterations = 30", "iterations = 40");
    let mut cases = 0;
    for attempt in 0..3 {
        let o = train_into(&d, &ae, "ae40", &longer, &["--resume"]);
        refused(&o, &[ck.to_str().unwrap(), "checksum"], &format!("resume {attempt}"));
        assert!(!output_text(&o).contains(artifact::STAGING_SUFFIX), "names the hidden copy: {}", output_text(&o));
        assert!(!staging.exists(), "attempt {attempt} left {}", staging.display());
        assert_eq!(std::fs::read(&ck).unwrap(), bad, "the user's checkpoint was changed");
        cases += 1;
    }
    // The model itself is untouched and loads.
    let o = meshdeco(&["synthesize", ae.to_str().unwrap(), "--weights", "0:1", "--out", "s.obj"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    cases += 1;
    std::fs::write(&ck, &good).unwrap();
    let o = train_into(&d, &ae, "ae40", &longer, &["--resume"]);
    assert!(o.status.success(), "repaired resume: {}", output_text(&o));
    assert_ne!(std::fs::read(&ck).unwrap(), good, "the resumed run wrote its own checkpoint");
    let log = std::fs::read_to_string(ae.join("training.jsonl")).unwrap();
    assert_eq!(log.lines().filter(|l| l.contains("\"iteration\"")).count(), 40, "the log goes on");
    // Resuming a finished run with no steps left keeps its checkpoint.
    let o = train_into(&d, &ae, "ae40", &longer, &["--resume"]);
    assert!(o.status.success(), "{}", output_text(&o));
    assert!(ck.is_file());
    cases += 2;
    eprintln!("refused and later resumes: {cases} cases");
    assert_eq!(cases, 6);
    std::fs::remove_dir_all(&d).unwrap();
}

/// Item 12: while a training holds the lock, a reader meeting a directory it cannot read (no
/// manifest yet, a commit under way, a file changing) is told that it is being written, by
/// which process; a complete old model still loads; a second writer is refused; once the lock
/// is released, the reader finishes the interrupted commit and loads the new model.
#[test]
fn readers_while_a_training_holds_the_lock() {
    let d = tmp("readers");
    let pca = train(&d, "pca", PCA);
    let pid = std::process::id().to_string();
    let synth = |dir: &Path| meshdeco(&["synthesize", dir.to_str().unwrap(), "--weights", "0:1", "--out", "s.obj"], &d);
    let mut cases = 0;
    // A first training: the directory has no manifest yet.
    let fresh = d.join("fresh");
    std::fs::create_dir_all(&fresh).unwrap();
    std::fs::write(fresh.join("model.json"), "{}").unwrap();
    let lock = artifact::DirLock::acquire(&fresh).unwrap();
    refused(&synth(&fresh), &["being written by meshdeco process", &pid, "no manifest.json"], "no manifest yet");
    cases += 1;
    drop(lock);
    refused(&synth(&fresh), &["not a complete meshdeco artefact"], "no manifest, no writer");
    assert!(!output_text(&synth(&fresh)).contains("being written"));
    cases += 1;
    // A complete old model while a retrain runs: it loads.
    let lock = artifact::DirLock::acquire(&pca).unwrap();
    let o = synth(&pca);
    assert!(o.status.success(), "{}", output_text(&o));
    cases += 1;
    // A file changing under the reader.
    let metrics = pca.join("metrics.json");
    let good = std::fs::read(&metrics).unwrap();
    std::fs::write(&metrics, b"{}").unwrap();
    refused(&synth(&pca), &["being written by meshdeco process", &pid, "metrics.json"], "a file changing");
    std::fs::write(&metrics, &good).unwrap();
    cases += 1;
    // A second writer.
    let o = train_into(&d, &pca, "pca4", PCA4, &[]);
    refused(&o, &["being written by another meshdeco process", &pid], "second writer");
    cases += 1;
    drop(lock);
    // A commit under way: a retrain killed after its staging became the commit's, then the
    // lock taken (as by a training still committing).
    let cfg = d.join("pca4.toml");
    let o = Command::new(env!("CARGO_BIN_EXE_meshdeco"))
        .args(["train", "--config", cfg.to_str().unwrap(), "--out", pca.to_str().unwrap()])
        .env(artifact::KILL_AT_ENV, "move#2")
        .current_dir(&d)
        .output()
        .unwrap();
    assert_eq!(o.status.signal(), Some(9), "{}", output_text(&o));
    let commit = artifact::commit_path(&pca).unwrap();
    assert!(commit.is_dir());
    let lock = artifact::DirLock::acquire(&pca).unwrap();
    refused(&synth(&pca), &["being written by meshdeco process", &pid], "commit under way");
    assert!(commit.is_dir(), "a reader finished a commit while its writer held the lock");
    cases += 1;
    drop(lock);
    let o = synth(&pca);
    assert!(o.status.success(), "after the writer is gone: {}", output_text(&o));
    assert!(!commit.exists());
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(pca.join("model.json")).unwrap()).unwrap();
    assert_eq!(v["components"], 4, "the interrupted commit was finished: the new model");
    cases += 1;
    eprintln!("readers and the lock: {cases} cases");
    assert_eq!(cases, 7);
    std::fs::remove_dir_all(&d).unwrap();
}

/// The JSON header of the feature-cache file at `path`, edited by `edit` with its checksum
/// re-recorded (as the format defines it: CRC-32 of the key's length and bytes, F, E and W,
/// the frame checksums, then `<` and the minima, `>` and the maxima, each list after its
/// length), as a tool that "fixes" a cache file would. The data and the offset stay.
fn rerecord_cache_header(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let bytes = std::fs::read(path).unwrap();
    let at = u64::from_le_bytes(bytes[bytes.len() - 8..].try_into().unwrap()) as usize;
    let mut h: serde_json::Value = serde_json::from_slice(&bytes[at..bytes.len() - 8]).unwrap();
    edit(&mut h);
    if h.get("header_crc32").is_some() {
        let mut c = crc32fast::Hasher::new();
        let key = h["key"].as_str().unwrap();
        c.update(&(key.len() as u64).to_le_bytes());
        c.update(key.as_bytes());
        for n in ["n_frames", "n_elements", "width"] {
            c.update(&h[n].as_u64().unwrap().to_le_bytes());
        }
        for f in h["frame_crc32"].as_array().unwrap() {
            c.update(&(f.as_u64().unwrap() as u32).to_le_bytes());
        }
        for (list, tag) in [("min_bits", b'<'), ("max_bits", b'>')] {
            let v = h[list].as_array().unwrap();
            c.update(&[tag]);
            c.update(&(v.len() as u64).to_le_bytes());
            for b in v {
                c.update(&b.as_u64().unwrap().to_le_bytes());
            }
        }
        h["header_crc32"] = c.finalize().into();
    }
    let mut out = bytes[..at].to_vec();
    out.extend(serde_json::to_vec(&h).unwrap());
    out.extend((at as u64).to_le_bytes());
    std::fs::write(path, out).unwrap();
}

/// Issue 55, cause 2: the feature cache's per-dimension ranges (which scale the autoencoder's
/// features) changed behind a re-recorded checksum — halved, ±1e300, NaN — or a header byte
/// changed without one: the file is named, recomputed, and the autoencoder trained from it is
/// the one trained from a clean cache (before: halving the ranges trained another model, exit
/// 0; ±1e300 and NaN failed without naming the file, and it was never recomputed).
#[test]
fn feature_cache_ranges_changed_behind_a_rerecorded_checksum_are_recomputed() {
    let d = tmp("cache-ranges");
    let cache = d.join("cache");
    let toml = AE.replace("test = \"rest\"\n", &format!("test = \"rest\"\ncache = {:?}\n", cache.to_str().unwrap()));
    let clean_model = train(&d, "clean", &toml);
    let clean_bin = std::fs::read(clean_model.join("model.bin")).unwrap();
    // (autoencoder.bpk holds each parameter's random id: it differs between runs.)
    let clean_weights = std::fs::read(clean_model.join("weights.csv")).unwrap();
    let files: Vec<PathBuf> = std::fs::read_dir(&cache).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let file = files[0].clone();
    let clean = std::fs::read(&file).unwrap();
    let half = |v: &serde_json::Value| serde_json::Value::from((f64::from_bits(v.as_u64().unwrap()) / 2.0).to_bits());
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(&str, Edit)> = vec![
        (
            "halved ranges",
            Box::new(move |h| {
                for list in ["min_bits", "max_bits"] {
                    let halved: Vec<serde_json::Value> = h[list].as_array().unwrap().iter().map(half).collect();
                    h[list] = halved.into();
                }
            }),
        ),
        ("a huge maximum", Box::new(|h| h["max_bits"][4] = 1e300f64.to_bits().into())),
        ("a huge negative minimum", Box::new(|h| h["min_bits"][0] = (-1e300f64).to_bits().into())),
        ("a NaN minimum", Box::new(|h| h["min_bits"][2] = f64::NAN.to_bits().into())),
    ];
    let mut n = 0;
    for (what, edit) in &cases {
        rerecord_cache_header(&file, edit);
        let out = d.join(format!("run{n}"));
        let o = train_into(&d, &out, &format!("run{n}"), &toml, &[]);
        let t = output_text(&o);
        assert!(o.status.success(), "{what}: {t}");
        for needle in ["recomputing the cached features", file.to_str().unwrap(), "recorded range"] {
            assert!(t.contains(needle), "{what}: `{needle}` not in {t}");
        }
        assert!(std::fs::read(out.join("model.bin")).unwrap() == clean_bin, "{what}: another model was trained");
        assert!(std::fs::read(out.join("weights.csv")).unwrap() == clean_weights, "{what}: other codes");
        assert!(std::fs::read(&file).unwrap() == clean, "{what}: the cache file was not recomputed");
        n += 1;
    }
    // A header byte changed without re-recording: named and recomputed too.
    let mut bytes = clean.clone();
    let at = u64::from_le_bytes(bytes[bytes.len() - 8..].try_into().unwrap()) as usize;
    let json = String::from_utf8(bytes[at..bytes.len() - 8].to_vec()).unwrap();
    let pos = at + json.find("\"max_bits\":[").unwrap() + 12;
    bytes[pos] = if bytes[pos] == b'1' { b'2' } else { b'1' };
    std::fs::write(&file, &bytes).unwrap();
    let out = d.join("run-byte");
    let o = train_into(&d, &out, "run-byte", &toml, &[]);
    let t = output_text(&o);
    assert!(o.status.success() && t.contains(file.to_str().unwrap()) && t.contains("recomputing"), "{t}");
    assert!(std::fs::read(out.join("model.bin")).unwrap() == clean_bin, "a changed header byte trained another model");
    assert!(std::fs::read(&file).unwrap() == clean);
    n += 1;
    eprintln!("feature cache ranges: {n} cases");
    assert_eq!(n, cases.len() + 1);
    std::fs::remove_dir_all(&d).unwrap();
}

/// Issue 55, cause 6: `--resume` of a run that has no steps left writes the same `objective`
/// to the bit (its last loss comes from the checkpoint's JSON header, which now stores floats
/// exactly). With seed 3 this run's objective, 146.25613565452593, is one that serde_json's
/// default parser read back one unit in the last place off (before: 146.2561356545259; the
/// crate is now also built with serde_json's `float_roundtrip`).
#[test]
fn a_resume_after_the_last_step_keeps_the_objective_to_the_bit() {
    let d = tmp("resume-exact");
    let toml = AE.replace("fit_test = false\n", "fit_test = false\nseed = 3\n");
    let ae = train(&d, "ae", &toml);
    let objective = |dir: &Path| {
        let text = std::fs::read_to_string(dir.join("metrics.json")).unwrap();
        let at = text.find("\"objective\":").expect("objective in metrics.json");
        text[at..].split([',', '\n', '}']).next().unwrap().to_string()
    };
    let first = objective(&ae);
    for attempt in 0..2 {
        let o = train_into(&d, &ae, "ae", &toml, &["--resume"]);
        assert!(o.status.success(), "{}", output_text(&o));
        assert_eq!(objective(&ae), first, "resume {attempt}");
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// Issue 55, cause 4: autoencoder.bpk edited behind a re-recorded manifest — 8 bytes
/// duplicated inside it (at the start of the tensor data, in its middle, near its end, or
/// appended), 8 bytes cut out, or 256 bytes appended — is refused by the loader itself, naming
/// the file (before: `synthesize` read shifted parameters and exited 0). The untouched file
/// loads.
#[test]
fn rerecorded_autoencoder_bpk_with_bytes_duplicated_or_cut_is_refused() {
    let d = tmp("bpk");
    let ae = train(&d, "ae", AE);
    let bpk = ae.join("autoencoder.bpk");
    let good = std::fs::read(&bpk).unwrap();
    let len = good.len();
    // The tensor data starts at the first 256-byte boundary after the header and metadata.
    let metadata = u32::from_le_bytes(good[6..10].try_into().unwrap()) as usize;
    let data = (10 + metadata).div_ceil(256) * 256;
    assert!(data + 64 < len, "{data} {len}");
    let duplicated = |at: usize| {
        let mut b = good[..at + 8].to_vec();
        b.extend_from_slice(&good[at..]);
        b
    };
    let mut cut = good.clone();
    cut.drain(len / 2..len / 2 + 8);
    let mut appended = good.clone();
    appended.extend(std::iter::repeat_n(0u8, 256));
    let cases: Vec<(String, Vec<u8>)> = vec![
        ("8 bytes duplicated at the data's start".into(), duplicated(data)),
        ("8 bytes duplicated in the middle".into(), duplicated((data + len) / 2)),
        ("8 bytes duplicated near the end".into(), duplicated(len - 16)),
        ("the last 8 bytes appended again".into(), duplicated(len - 8)),
        ("8 bytes cut out of the middle".into(), cut),
        ("256 zero bytes appended".into(), appended),
    ];
    let mut n = 0;
    for (what, bytes) in &cases {
        std::fs::write(&bpk, bytes).unwrap();
        rerecord(&ae);
        n += all_refuse(&ae, &d, &["autoencoder.bpk"], what);
    }
    std::fs::write(&bpk, &good).unwrap();
    rerecord(&ae);
    let o = meshdeco(&["synthesize", ae.to_str().unwrap(), "--weights", "0:1", "--out", "s.obj"], &d);
    assert!(o.status.success(), "the untouched file: {}", output_text(&o));
    eprintln!("autoencoder.bpk layouts: {n} cases");
    assert_eq!(n, 2 * cases.len());
    std::fs::remove_dir_all(&d).unwrap();
}

/// Issue 55, cause 7: readers while retrains commit new models into the directory again and
/// again (PCA with K = 3 and K = 4 in turn, each a separate `meshdeco train`): every read gets
/// a whole model, the old or the new one (its K and its files agree), or an error naming the
/// writer — never "changed or damaged" for a file a commit replaced (before: 2 of 155 reads).
#[test]
fn readers_during_retrains_get_a_whole_model_or_the_writer() {
    let d = tmp("retrains");
    let pca = train(&d, "pca", PCA);
    std::fs::write(d.join("pca3.toml"), PCA).unwrap();
    std::fs::write(d.join("pca4.toml"), PCA4).unwrap();
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let writer = std::thread::spawn({
        let (d, pca, done) = (d.clone(), pca.clone(), done.clone());
        move || {
            for i in 0..12 {
                let cfg = d.join(if i % 2 == 0 { "pca4.toml" } else { "pca3.toml" });
                let o = Command::new(env!("CARGO_BIN_EXE_meshdeco"))
                    .args(["train", "--config", cfg.to_str().unwrap(), "--out", pca.to_str().unwrap()])
                    .current_dir(&d)
                    .output()
                    .unwrap();
                assert!(o.status.success(), "retrain {i}: {}", output_text(&o));
            }
            done.store(true, std::sync::atomic::Ordering::SeqCst);
        }
    });
    let (mut whole, mut named) = (0, 0);
    while !done.load(std::sync::atomic::Ordering::SeqCst) {
        match meshdeco::pipeline::load_model(&pca) {
            Ok(model) => {
                let k = model.n_components();
                assert!(k == 3 || k == 4, "K = {k}");
                // Its weights and components are one model's: decoding the first training
                // frame's weights gives a shape of the rest mesh's size.
                let w = model.train_weights().expect("a linear model's training weights");
                assert!(w.iter().all(|row| row.len() == k), "weights of K = {k}");
                assert_eq!(model.decode(&w[..1]).unwrap()[0].len(), model.rest().n_vertices());
                whole += 1;
            }
            Err(e) => {
                let t = e.to_string();
                assert!(t.contains("is being written by meshdeco process"), "a read during a retrain: {t}");
                assert_eq!(t.matches("being written").count(), 1, "{t}");
                named += 1;
            }
        }
    }
    writer.join().unwrap();
    eprintln!("reads during 12 retrains: {whole} whole models, {named} errors naming the writer");
    assert!(whole > 12, "{whole} reads");
    std::fs::remove_dir_all(&d).unwrap();
}
