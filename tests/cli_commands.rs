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
    std::fs::write(&cfg, "name = \"bumps\"\n[data]\npath = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"rest\"\n[method]\nkind = \"splocs\"\ncomponents = 3\n[output]\nviews = true\n").unwrap();
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
    // Rank-3 data: against the mean shape of the training frames (PCA with no component) on the
    // same test frames, the reconstruction is near exact.
    let truth = meshdeco::synthetic::load("synthetic:bumps").unwrap().frames;
    let none = meshdeco::metrics::erms::Alignment::None;
    let mean_base = common::constant_shape_erms(&truth[30..], &common::mean_shape(&truth[..30]), none);
    let test = metrics["test_erms"].as_f64().unwrap();
    eprintln!("CLI SPLOCS K=3 test Erms {test:.4}; mean shape {mean_base:.4}; ratio {:.2e}", test / mean_base);
    assert!(test < RATIO_CLI_TEST * mean_base, "test Erms {test} vs the mean shape's {mean_base}");
    // The component shapes written at training: rest + 1·C_k (the model is linear in its weights).
    let rest = meshdeco::synthetic::load("synthetic:bumps").unwrap().frames[0].clone();
    let comp: Vec<Vec<[f64; 3]>> = (0..3)
        .map(|k| {
            let plus = common::obj_vertices(&model.join(format!("components/k{k:02}_plus.obj")));
            plus.iter().zip(&rest).map(|(p, r)| std::array::from_fn(|c| p[c] - r[c])).collect()
        })
        .collect();
    let combine = |w: &[f64]| -> Vec<[f64; 3]> {
        (0..rest.len())
            .map(|v| std::array::from_fn(|c| rest[v][c] + (0..3).map(|k| w[k] * comp[k][v][c]).sum::<f64>()))
            .collect()
    };

    let o = meshdeco(&["encode", "checkpoints/bumps", "synthetic:bumps", "--out", "enc"], &d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("enc/bumps040.obj").exists() && d.join("enc/weights.csv").exists());
    // Content: one row of weights per frame; each written reconstruction is rest + Σ w_k C_k of
    // its row, and it is close to the input frame.
    let csv = std::fs::read_to_string(d.join("enc/weights.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], "frame,c0,c1,c2");
    assert_eq!(rows.len(), 41, "{csv}");
    let mut recs = Vec::new();
    for (f, row) in rows[1..].iter().enumerate() {
        let mut it = row.split(',');
        let name = it.next().unwrap();
        assert_eq!(name, format!("bumps{:03}", f + 1));
        let w: Vec<f64> = it.map(|x| x.parse().unwrap()).collect();
        let rec = common::obj_vertices(&d.join(format!("enc/{name}.obj")));
        let want = combine(&w);
        let gap = rec.iter().zip(&want).map(|(a, b)| meshdeco::mesh::dist(*a, *b)).fold(0.0, f64::max);
        assert!(gap < 1e-5, "{name}: reconstruction is {gap} away from rest + Σ w·C of its weights {w:?}");
        recs.push(rec);
    }
    let enc_erms = meshdeco::metrics::erms::erms(&truth, &recs, none).unwrap();
    let mean_all = common::constant_shape_erms(&truth, &common::mean_shape(&truth), none);
    eprintln!("encode: Erms of the written reconstructions {enc_erms:.4}; mean shape {mean_all:.4}");
    assert!(enc_erms < RATIO_CLI_TEST * mean_all, "encode Erms {enc_erms} vs the mean shape's {mean_all}");

    let o = meshdeco(&["synthesize", "checkpoints/bumps", "--weights", "0:1,2:-0.5", "--out", "s.obj"], &d);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(d.join("s.obj")).unwrap();
    assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 1466);
    // Content: weight w on component k gives rest + w·C_k.
    let s = common::obj_vertices(&d.join("s.obj"));
    let want = combine(&[1.0, 0.0, -0.5]);
    let gap = s.iter().zip(&want).map(|(a, b)| meshdeco::mesh::dist(*a, *b)).fold(0.0, f64::max);
    let moved = s.iter().zip(&rest).map(|(a, b)| meshdeco::mesh::dist(*a, *b)).fold(0.0, f64::max);
    eprintln!("synthesize 0:1,2:-0.5: max distance to rest + C0 − 0.5·C2 {gap:.2e}, max displacement {moved:.4}");
    assert!(gap < 1e-5, "synthesized shape is {gap} away from rest + C0 − 0.5·C2");
    assert!(moved > 1e-3, "synthesized shape is the rest shape (max displacement {moved})");

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
    for needle in [
        "frames            60 (tube001 … tube060)",
        "vertices          1466",
        "faces             2928",
        "0 loops (closed surface)",
        "euler char.       2",
    ] {
        assert!(s.contains(needle), "`{needle}` not in:\n{s}");
    }
    let o = meshdeco(&["inspect", "synthetic:tube", "--json"], &d);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!((v["frames"].as_u64(), v["vertices"].as_u64(), v["faces"].as_u64()), (Some(60), Some(1466), Some(2928)));
    assert_eq!((v["euler_characteristic"].as_i64(), v["components"].as_u64()), (Some(2), Some(1)));
    assert_eq!(v["bbox_first"], serde_json::json!([[-0.1, -0.1, 0.0], [0.1, 0.1, 1.0]]));
    let o = meshdeco(&["geodesic", "synthetic:tube", "--source", "0", "--out", "g.ply"], &d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read_to_string(d.join("g.ply")).unwrap().contains("property float distance"));
    // Known case: from vertex 0 at (0.1, 0, 0) on the tube (radius 0.1, length 1, 24 vertices
    // around, 61 rings), the geodesic to ring r along the same generator is its height z, to the
    // opposite side of ring r it is min(√(z² + (π·0.1)²), 0.2 + z) (around, or across the
    // bottom cap) and to the top pole 1.1. Heat geodesics smooth near the source and the cut
    // locus: measured worst relative error 0.064 from ring 12 (z = 0.2) on; bound 0.1.
    let dist = common::ply_vertex_property(&d.join("g.ply"), "distance");
    assert_eq!(dist.len(), 1466);
    assert!(dist[0].abs() < 1e-6, "distance at the source {}", dist[0]);
    let mut worst: f64 = 0.0;
    for r in (12..=60).step_by(6) {
        let z = r as f64 / 60.0;
        let around = (z * z + (std::f64::consts::PI * 0.1).powi(2)).sqrt().min(0.2 + z);
        for (v, want) in [(24 * r, z), (24 * r + 12, around), (1465, 1.1)] {
            let rel = (dist[v] - want).abs() / want;
            worst = worst.max(rel);
            assert!(rel < 0.1, "vertex {v}: geodesic {} vs {want} (relative error {rel:.3})", dist[v]);
        }
    }
    eprintln!("geodesic on the tube: worst relative error {worst:.4}");
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

/// Bound on the ratio of a near-exact rank-3 reconstruction to the mean shape's Erms.
const RATIO_CLI_TEST: f64 = 0.05; // measured 0.016 (test frames), 0.016 (encode)
