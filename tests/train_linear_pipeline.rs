//! End to end through the library pipeline on the built-in synthetic data: SPLOCS finds the
//! planted bumps, PCA reconstructs exactly with enough components, the artefact directory
//! reloads, and encoding the training frames reproduces the stored weights' reconstructions.

mod common;

use std::collections::HashSet;
use std::path::PathBuf;

use meshdeco::config::Config;
use meshdeco::pipeline::Silent;
use meshdeco::pipeline::linear::{LinearArtifact, vertex_magnitudes};
use meshdeco::representation::Element;
use meshdeco::synthetic;

fn out_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-test-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn iou(a: &HashSet<usize>, b: &HashSet<usize>) -> f64 {
    a.intersection(b).count() as f64 / a.union(b).count().max(1) as f64
}

#[test]
fn splocs_recovers_each_planted_bump() {
    let cfg = Config::from_toml(
        r#"
name = "bumps"
[data]
path = "synthetic:bumps"
[method]
kind = "splocs"
components = 3
max_iterations = 20
[output]
views = true
"#,
    )
    .unwrap();
    let out = out_dir("splocs-bumps");
    let o = meshdeco::pipeline::train(&cfg, &out, &meshdeco::pipeline::TrainOptions::default(), &mut Silent).unwrap();
    let a = LinearArtifact::load(&out).unwrap();
    assert_eq!(a.model.n_components, 3);
    let regions = synthetic::planted_regions("synthetic:bumps").unwrap();
    let supports: Vec<HashSet<usize>> = (0..3)
        .map(|k| {
            let m = vertex_magnitudes(&a.model, k, Element::Vertex, &a.rest);
            let max = m.iter().cloned().fold(0.0, f64::max);
            m.iter().enumerate().filter(|(_, v)| **v > 0.05 * max).map(|(i, _)| i).collect()
        })
        .collect();
    for r in &regions {
        let planted: HashSet<usize> = r.vertices.iter().copied().collect();
        let best = supports.iter().map(|s| iou(s, &planted)).fold(0.0, f64::max);
        assert!(best >= 0.7, "{}: best IoU {best:.3} < 0.7", r.name);
    }
    // The data are exactly three bumps: the reconstruction is near exact (data units: the
    // tube is 1 long, Erms is 1000 × RMS).
    assert!(o.metrics.train_erms < 1.0, "train Erms {}", o.metrics.train_erms);
    // Relative to what learning nothing gives: the mean shape of the training frames (PCA with
    // no component) and the rest shape (all weights zero).
    let frames = synthetic::load("synthetic:bumps").unwrap().frames;
    let none = meshdeco::metrics::erms::Alignment::None;
    let mean = common::constant_shape_erms(&frames, &common::mean_shape(&frames), none);
    let rest = common::constant_shape_erms(&frames, &frames[0], none);
    let ratio = o.metrics.train_erms / mean;
    eprintln!(
        "SPLOCS K=3 train Erms {:.4}; mean shape {mean:.4}, rest shape {rest:.4}; ratio to mean {ratio:.2e}",
        o.metrics.train_erms
    );
    assert!(
        ratio < RATIO_SPLOCS_TRAIN,
        "SPLOCS train Erms {} is {ratio:.3e} of the mean shape's {mean}",
        o.metrics.train_erms
    );
    // Artefacts exist and reload consistently.
    for f in ["config.toml", "model.json", "model.bin", "weights.csv", "metrics.json", "components/k00_plus.obj"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let again = Config::from_file(&out.join("config.toml")).unwrap();
    assert_eq!(again.method.components(), 3);
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn pca_with_full_rank_is_exact_and_encode_matches_training_weights() {
    let cfg = Config::from_toml(
        r#"
name = "pca"
[data]
path = "synthetic:bumps"
train = "1-20"
test = "rest"
[method]
kind = "pca"
components = 3
"#,
    )
    .unwrap();
    let out = out_dir("pca-bumps");
    let o = meshdeco::pipeline::train(&cfg, &out, &meshdeco::pipeline::TrainOptions::default(), &mut Silent).unwrap();
    // Bump amplitudes are 3 independent scalars but the bumps are nonlinear in the radial
    // push only through the profile, which is linear in amplitude: rank 3 exactly.
    assert!(o.metrics.train_erms < 1e-6, "train {}", o.metrics.train_erms);
    assert!(o.metrics.test_erms.unwrap() < 1e-6, "test {:?}", o.metrics.test_erms);
    let a = LinearArtifact::load(&out).unwrap();
    let seq = synthetic::load("synthetic:bumps").unwrap().select(&(0..20).collect::<Vec<_>>());
    let w = a.encode_frames(&seq).unwrap();
    for (x, y) in w.iter().zip(&a.model.weights) {
        assert!((x - y).abs() < 1e-6 * (1.0 + y.abs()), "encoded {x} vs stored {y}");
    }
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn splocs_on_acap_features_keeps_the_rest_shape_as_offset_and_finds_the_bumps() {
    let cfg = Config::from_toml(
        r#"
name = "splocs-acap"
[data]
path = "synthetic:bumps"
train = "1-20"
test = "rest"
[method]
kind = "splocs"
representation = "acap"
components = 3
weights = "signed"
max_iterations = 20
"#,
    )
    .unwrap();
    let out = out_dir("splocs-acap-bumps");
    let o = meshdeco::pipeline::train(&cfg, &out, &meshdeco::pipeline::TrainOptions::default(), &mut Silent).unwrap();
    assert_eq!(o.metrics.representation, "acap");
    let a = LinearArtifact::load(&out).unwrap();
    // SPLOCS models deformations of the rest shape: the offset is the rest shape's own ACAP
    // features, logR = 0 and S = I at every vertex.
    let identity = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0];
    for (i, v) in a.model.offset.iter().enumerate() {
        assert!((v - identity[i % 9]).abs() < 1e-9, "offset[{i}] = {v}");
    }
    // Zero weights decode to the rest shape.
    let rest = a.synthesize(&[0.0; 3]).unwrap();
    let truth = synthetic::load("synthetic:bumps").unwrap();
    let e = meshdeco::representation::roundtrip::erms(
        &[truth.frames[0].clone()],
        &[rest],
        meshdeco::representation::roundtrip::Alignment::Centroid,
    )
    .unwrap();
    assert!(e < 1e-6, "rest shape from zero weights: Erms {e}");
    // Each planted bump holds most of one component's energy (feature magnitude per vertex;
    // rotations spill a little past the bump's rim, so overlap is measured by energy).
    let regions = synthetic::planted_regions("synthetic:bumps").unwrap();
    let mut owners = HashSet::new();
    for r in &regions {
        let planted: HashSet<usize> = r.vertices.iter().copied().collect();
        let (best, share) = (0..3)
            .map(|k| {
                let m = vertex_magnitudes(&a.model, k, Element::Vertex, &a.rest);
                let total: f64 = m.iter().map(|v| v * v).sum();
                let inside: f64 = planted.iter().map(|&i| m[i] * m[i]).sum();
                (k, inside / total)
            })
            .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        eprintln!("{}: component {best} has {share:.3} of its energy inside", r.name);
        assert!(share >= 0.8, "{}: best in-region energy share {share:.3} < 0.8", r.name);
        owners.insert(best);
    }
    assert_eq!(owners.len(), regions.len(), "one component per bump");
    // Bumps are not linear in ACAP features, but three local components still generalise.
    let test = o.metrics.test_erms.unwrap();
    assert!(test.is_finite() && test < 5.0, "test Erms {test}");
    // Against the rest shape (all weights zero) on the same test frames, with the same alignment
    // (ACAP is translation free: centroid) and against PCA on displacements with the same K,
    // which is exact on these data (rank 3): what the data allow.
    let test_frames = truth.frames[20..].to_vec();
    let centroid = meshdeco::representation::roundtrip::Alignment::Centroid;
    let rest_base = common::constant_shape_erms(&test_frames, &truth.frames[0], centroid);
    let ratio = test / rest_base;
    eprintln!("SPLOCS-ACAP K=3 test Erms {test:.4}; rest shape {rest_base:.4}; ratio {ratio:.3}");
    assert!(ratio < RATIO_ACAP_TEST, "SPLOCS-ACAP test Erms {test} is {ratio:.3} of the rest shape's {rest_base}");
    std::fs::remove_dir_all(&out).unwrap();
}

/// Bounds on Erms ratios to the baselines (measured values in the comments, ~20 % margin or more).
const RATIO_SPLOCS_TRAIN: f64 = 0.005; // measured 4.6e-4 of the mean shape (2.04)
const RATIO_ACAP_TEST: f64 = 0.1; // measured 0.063 of the rest shape (3.88)
