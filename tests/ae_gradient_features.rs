//! The autoencoder on deformation-gradient features (`features = "gradient"`, issue 53): the
//! key reaches the model (`model.json`, the written `config.toml`, the checkpoint), a loaded
//! model decodes what training measured, the encoder's vertex steps and posing run on it, a
//! resume with other features is refused naming the key, and a bad value names the key and the
//! choices.

use meshdeco::config::Config;
use meshdeco::pipeline::autoencoder::AeArtifact;
use meshdeco::pipeline::{Silent, TrainOptions, load_model, train};

fn config(extra: &str, iterations: usize) -> Config {
    Config::from_toml(&format!(
        "name = \"tube-gradient\"\n[data]\npath = \"synthetic:tube\"\ntrain = \"every:3\"\ntest = \"rest\"\n\
         [method]\nkind = \"autoencoder\"\ncomponents = 3\niterations = {iterations}\nlearning_rate = 0.005\n\
         checkpoint_every = 50\nseed = 1\n{extra}"
    ))
    .unwrap()
}

fn tmp(tag: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-ae-gradient-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn gradient_features_train_load_encode_and_refuse_a_mixed_resume() {
    let dir = tmp("run");
    let o = train(&config("features = \"gradient\"\n", 300), &dir, &TrainOptions::default(), &mut Silent).unwrap();
    let m = &o.metrics;
    let test = m.test_erms.expect("a test split");
    eprintln!("tube, features = gradient: train Erms {:.4}, test {test:.4}", m.train_erms);
    assert!(m.train_erms.is_finite() && test.is_finite());

    // The key is recorded where the model and a resume read it.
    let header: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("model.json")).unwrap()).unwrap();
    assert_eq!(header["features"], "gradient", "model.json records the features");
    let written = std::fs::read_to_string(dir.join("config.toml")).unwrap();
    assert!(written.contains("features = \"gradient\""), "{written}");
    let art = AeArtifact::load(&dir).unwrap();
    assert_eq!(art.representation.acap().unwrap().map(), meshdeco::representation::acap::FeatureMap::Gradient);

    // A loaded model encodes and decodes the test frames to what training measured.
    let model = load_model(&dir).unwrap();
    assert!(!o.test_reconstruction.is_empty());
    let enc = meshdeco::model::encode_frames(model.as_ref(), &test_frames(), "test", None).unwrap();
    assert!((enc.total_erms - test).abs() <= 1e-9 * test.max(1.0), "reloaded {} vs trained {test}", enc.total_erms);

    // Posing runs on the model: a drag of one vertex moves it towards the target.
    let rest = model.rest().positions.clone();
    let start = model.start_weights(None).unwrap();
    let v = rest.len() / 2;
    let target = [rest[v][0] + 0.05, rest[v][1], rest[v][2]];
    let posed = model.pose(&[v], &[target], &start, &model.pose_defaults()).unwrap();
    let before = dist(&posed.start[v], &target);
    let after = dist(&posed.positions[v], &target);
    assert!(after < before, "posing moved vertex {v} from {before} to {after} of the target");

    // A resume with the default features is refused, naming the key and the way out.
    let more = TrainOptions { resume: true, ..Default::default() };
    let e = train(&config("", 350), &dir, &more, &mut Silent).err().expect("a mixed resume is refused").to_string();
    assert!(e.contains("features") && e.contains("gradient"), "{e}");
    // With the same features it continues.
    let resumed = train(&config("features = \"gradient\"\n", 350), &dir, &more, &mut Silent).unwrap();
    assert!(resumed.metrics.train_erms.is_finite());

    // The default writes nothing new: configs and models of ACAP features read as before.
    let plain = tmp("plain");
    train(&config("", 20), &plain, &TrainOptions::default(), &mut Silent).unwrap();
    let header: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(plain.join("model.json")).unwrap()).unwrap();
    assert!(header.get("features").is_none(), "the default is left out of model.json");
    assert!(!std::fs::read_to_string(plain.join("config.toml")).unwrap().contains("features"));
    let _ = (std::fs::remove_dir_all(&dir), std::fs::remove_dir_all(&plain));
}

#[test]
fn a_bad_features_value_names_the_key_and_the_choices() {
    let e = Config::from_toml(
        "[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"autoencoder\"\ncomponents = 3\nfeatures = \"logr\"\n",
    )
    .expect_err("refused")
    .to_string();
    assert!(e.contains("features") && e.contains("acap") && e.contains("gradient"), "{e}");
}

fn test_frames() -> meshdeco::mesh::MeshSequence {
    let cfg = config("", 1);
    let prep = meshdeco::preprocess::prepare(&cfg.data).unwrap();
    prep.test_sequence().unwrap()
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}
