//! Diagnostic (issues 17, 31): how far does a code chosen in *feature* space go? Prints, for the
//! test split of a config and a trained autoencoder of it, the test Erms (the model's alignment)
//! and the encoding time of the network encoder with 0–3 residual passes and then 0, 1, 2, 3, 5
//! and 10 feature-space Levenberg–Marquardt steps (`encoder_steps`, exact decoder Jacobian,
//! `nn::feature_fit`), whatever the model's own settings. `meshdeco encode --fit` fits the same
//! decoder to the vertices instead.
//!
//! `cargo run --release --example ae_feature_fit -- <config.toml> <model dir> [steps,…]`: the
//! config's `[data]` gives the test split; the model is a `meshdeco train` directory of that
//! config.
use meshdeco::config::Config;
use meshdeco::mesh::FrameSource;
use meshdeco::metrics::erms::erms;
use meshdeco::model::Model;
use meshdeco::pipeline::autoencoder::AeArtifact;
use std::path::Path;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: ae_feature_fit <config.toml> <model dir> [steps,…]");
        std::process::exit(2);
    }
    let cfg = Config::from_file(Path::new(&args[1])).expect("config");
    let prep = meshdeco::preprocess::prepare(&cfg.data).expect("data");
    let art = AeArtifact::load(Path::new(&args[2])).expect("model");
    // `AE_SPLIT=validation` encodes the config's validation frames instead of its test frames.
    let test = if std::env::var("AE_SPLIT").is_ok_and(|v| v == "validation") {
        prep.sequence.select_frames(&prep.validation).expect("validation frames")
    } else {
        prep.test_sequence().expect("test frames")
    };
    let steps: Vec<usize> = match args.get(3) {
        Some(s) => s.split(',').map(|v| v.parse().expect("steps: comma-separated integers")).collect(),
        None => vec![0, 1, 2, 3, 5, 10],
    };
    let alignment = art.alignment();
    let per_shape = |passes: usize, steps: usize| -> (f64, f64) {
        let t = Instant::now();
        let z = art.encode_frames_with(&test, passes, steps).expect("encode");
        let ms = t.elapsed().as_secs_f64() * 1e3 / test.n_frames() as f64;
        (erms(&test.frames, &art.decode_codes(&z).expect("decode"), alignment).expect("erms"), ms)
    };
    println!("{} test frames; the model's own encoder_passes {}", test.n_frames(), art.model.config().encoder_passes);
    for passes in [0, art.model.config().encoder_passes] {
        for &s in &steps {
            let (e, ms) = per_shape(passes, s);
            println!("passes {passes} steps {s:>2}: test Erms {e:.3}  ({ms:.1} ms per shape, features and encoding)");
        }
        if art.model.config().encoder_passes == 0 {
            break;
        }
    }
}
