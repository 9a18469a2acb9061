//! The command line as a user runs it: exit codes, error messages that name the file/key,
//! and the train → encode → synthesize chain on built-in synthetic data.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn meshdeco(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_meshdeco")).args(args).current_dir(cwd).output().expect("run meshdeco")
}

fn tmp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn bad_configs_fail_with_key_and_value() {
    let d = tmp("badcfg");
    let cases = [
        (
            "[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"splocs\"\nsupport = [0.8, 0.7]\n",
            "d_min (0.8) must be below d_max (0.7)",
        ),
        ("[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"splocs\"\nlayers = 2\n", "method.layers"),
        ("[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"pca\"\ncomponnts = 3\n", "componnts"),
        ("[data]\npath = \"synthetic:tube\"\ntrain = \"1-500\"\n[method]\nkind = \"pca\"\n", "data.train"),
        ("[data]\npath = \"no/such/dir\"\n[method]\nkind = \"pca\"\n", "no/such/dir"),
    ];
    for (i, (text, needle)) in cases.iter().enumerate() {
        let f = d.join(format!("c{i}.toml"));
        std::fs::write(&f, text).unwrap();
        let o = meshdeco(&["train", "--config", f.to_str().unwrap(), "--out", d.join("out").to_str().unwrap()], &d);
        assert!(!o.status.success(), "case {i} should fail");
        let e = stderr(&o);
        assert!(e.contains(needle), "case {i}: `{needle}` not in: {e}");
        assert!(!e.contains("panicked"), "case {i} panicked: {e}");
    }
    let o = meshdeco(&["train", "--config", "missing.toml"], &d);
    assert!(!o.status.success() && stderr(&o).contains("missing.toml"));
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn train_encode_synthesize_chain() {
    let d = tmp("chain");
    let cfg = d.join("bumps.toml");
    std::fs::write(&cfg, "name = \"bumps\"\n[data]\npath = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"rest\"\n[method]\nkind = \"splocs\"\ncomponents = 3\n").unwrap();
    let o = meshdeco(&["train", "--config", "bumps.toml"], &d);
    assert!(o.status.success(), "{}", stderr(&o));
    let model = d.join("checkpoints/bumps");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(model.join("metrics.json")).unwrap()).unwrap();
    for key in [
        "method",
        "representation",
        "components",
        "train_erms",
        "test_erms",
        "train_seconds",
        "iterations",
        "objective",
    ] {
        assert!(metrics.get(key).is_some(), "metrics.json lacks {key}");
    }
    assert!(metrics["test_erms"].as_f64().unwrap() < 1.0);

    let o = meshdeco(&["encode", "checkpoints/bumps", "synthetic:bumps", "--out", "enc"], &d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("enc/bumps040.obj").exists() && d.join("enc/weights.csv").exists());

    let o = meshdeco(&["synthesize", "checkpoints/bumps", "--weights", "0:1,2:-0.5", "--out", "s.obj"], &d);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(d.join("s.obj")).unwrap();
    assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 1466);

    let o = meshdeco(&["synthesize", "checkpoints/bumps", "--weights", "7:1", "--out", "s.obj"], &d);
    assert!(!o.status.success() && stderr(&o).contains("component 7 does not exist"));
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn inspect_and_geodesic() {
    let d = tmp("inspect");
    let o = meshdeco(&["inspect", "synthetic:tube"], &d);
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(s.contains("1466") && s.contains("60"), "{s}");
    let o = meshdeco(&["geodesic", "synthetic:tube", "--source", "0", "--out", "g.ply"], &d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read_to_string(d.join("g.ply")).unwrap().contains("property float distance"));
    let o = meshdeco(&["inspect", "does-not-exist"], &d);
    assert!(!o.status.success() && stderr(&o).contains("does-not-exist"));
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn shared_scape_inspect_counts() {
    let Some(scape) = common::shared_or_skip("data/scape") else { return };
    let o = meshdeco(&["inspect", scape.to_str().unwrap(), "--json"], Path::new(env!("CARGO_MANIFEST_DIR")));
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["frames"], 71);
    assert_eq!(v["vertices"], 2161);
    assert_eq!(v["faces"], 4318);
    assert_eq!(v["boundary_loops"].as_array().unwrap().len(), 0);
}
