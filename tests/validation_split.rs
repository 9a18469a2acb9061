//! `data.validation` (issue 31): frames held out of the training split are not fitted and are
//! reported beside the training and test Erms; the held-out frames are resolved once, the same
//! for the same seed, and bad values fail naming the key.

use meshdeco::config::{Config, Validation};
use meshdeco::pipeline::{Silent, TrainOptions, train};

fn cfg(validation: &str) -> Result<Config, meshdeco::Error> {
    Config::from_toml(&format!(
        "name = \"v\"\n[data]\npath = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"31-40\"\n{validation}\n[method]\nkind = \"pca\"\ncomponents = 3\n"
    ))
}

#[test]
fn validation_frames_are_held_out_and_reported() {
    let d = std::env::temp_dir().join(format!("meshdeco-validation-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    let run = |v: &str, out: &str| {
        let c = cfg(v).unwrap();
        train(&c, &d.join(out), &TrainOptions::default(), &mut Silent).unwrap().metrics
    };
    let held = run("validation = \"25-30\"", "held");
    assert_eq!(held.train_frames, 24);
    assert_eq!(held.validation_frames, 6);
    let v = held.validation_erms.expect("validation Erms");
    assert!(v.is_finite() && v >= 0.0);
    // The model fitted without frames 25-30 is the model trained on 1-24: same training Erms,
    // and its validation Erms is its error on 25-30 (the test Erms of a 1-24 / 25-30 split).
    let c = Config::from_toml(
        "name = \"v\"\n[data]\npath = \"synthetic:bumps\"\ntrain = \"1-24\"\ntest = \"25-30\"\n[method]\nkind = \"pca\"\ncomponents = 3\n",
    )
    .unwrap();
    let plain = train(&c, &d.join("plain"), &TrainOptions::default(), &mut Silent).unwrap().metrics;
    assert_eq!(held.train_erms, plain.train_erms);
    assert_eq!(Some(v), plain.test_erms);
    // The resolved config.toml names the split; metrics.json carries the number.
    let text = std::fs::read_to_string(d.join("held/config.toml")).unwrap();
    assert!(text.contains("validation = \"25-30\""), "{text}");
    let json = std::fs::read_to_string(d.join("held/metrics.json")).unwrap();
    assert!(json.contains("\"validation_erms\""), "{json}");
    // auto:P%: 10 % of 30 frames = 3, the same for the same seed, never frame 1 (the rest).
    let a = run("validation = \"auto:10%:7\"", "auto");
    assert_eq!((a.train_frames, a.validation_frames), (27, 3));
    let share = Validation::parse("auto:10%:7").unwrap();
    let train_idx: Vec<usize> = (0..30).collect();
    let (v1, fit1) = share.resolve(40, &train_idx).unwrap();
    let (v2, _) = share.resolve(40, &train_idx).unwrap();
    assert_eq!(v1, v2);
    assert_eq!(v1.len(), 3);
    assert!(!v1.contains(&0) && fit1.len() == 27 && v1.iter().all(|x| !fit1.contains(x)));
    let (v3, _) = Validation::parse("auto:10%:8").unwrap().resolve(40, &train_idx).unwrap();
    assert_ne!(v1, v3, "another seed draws other frames");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn bad_validation_values_name_the_key() {
    for (v, want) in [
        ("validation = \"auto:0%\"", "auto:P%"),
        ("validation = \"auto:100%\"", "auto:P%"),
        ("validation = \"auto:10\"", "auto:P%"),
        ("validation = \"rest\"", "out of data.train"),
        ("validation = \"auto:10%:x\"", "auto:P%"),
    ] {
        let e = cfg(v).unwrap_err().to_string();
        assert!(e.contains("data.validation") && e.contains(want), "{v}: {e}");
    }
    // Just inside the open interval (0, 100) is a share.
    for p in [0.5, 99.5] {
        assert_eq!(Validation::parse(&format!("auto:{p}%")).unwrap(), Validation::Share { percent: p, seed: 0 });
    }
    // Frames outside data.train, or all of them, fail when the data are split.
    let d = std::env::temp_dir().join(format!("meshdeco-validation-bad-{}", std::process::id()));
    for (v, want) in
        [("validation = \"31\"", "frame 31 is not a training frame"), ("validation = \"1-30\"", "none is left")]
    {
        let c = cfg(v).unwrap();
        let e = train(&c, &d, &TrainOptions::default(), &mut Silent).err().expect("the split fails").to_string();
        assert!(e.contains("data.validation") && e.contains(want), "{v}: {e}");
        assert!(!d.exists(), "no artefact after a failed split");
    }
}

/// The share's bound (issue 58's mutants): a share may hold out every training frame but the
/// first (which stays to train on); one frame more is refused naming the key.
#[test]
fn a_share_may_leave_only_the_first_frame() {
    let train: Vec<usize> = (0..10).collect();
    // 90 % of 10 = 9 frames: all but the first.
    let (held, fit) = Validation::parse("auto:90%").unwrap().resolve(20, &train).unwrap();
    assert_eq!((held, fit), ((1..10).collect::<Vec<_>>(), vec![0]));
    // 95 % of 10 rounds to 10: none would be left.
    let e = Validation::parse("auto:95%").unwrap().resolve(20, &train).unwrap_err().to_string();
    assert!(e.contains("data.validation") && e.contains("leaves none to train on"), "{e}");
}

/// `data.validation` beside the autoencoder's `method.validation` is refused when the config is
/// read, naming both keys; each alone is accepted (issue 58's mutants; the command line's
/// refusal: `reliability.rs::data_and_method_validation_together_are_refused_naming_both`).
#[test]
fn data_and_method_validation_are_not_read_together() {
    let data = "[data]\npath = \"synthetic:tube\"\ntrain = \"1-30\"\n";
    let ae = "[method]\nkind = \"autoencoder\"\ncomponents = 3\n";
    let e = Config::from_toml(&format!("{data}validation = \"28-30\"\n{ae}validation = 2\n")).unwrap_err().to_string();
    assert!(e.contains("data.validation") && e.contains("method.validation = 2"), "{e}");
    assert!(Config::from_toml(&format!("{data}validation = \"28-30\"\n{ae}validation = 0\n")).is_ok());
    assert!(Config::from_toml(&format!("{data}{ae}validation = 2\n")).is_ok());
}
