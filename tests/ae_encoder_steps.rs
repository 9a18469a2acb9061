//! The autoencoder encoder's vertex steps (`encoder_steps`, issue 31): the exact decoder
//! Jacobian, the ACAP decoding's batched linear part, and the steps themselves on a trained
//! model of the synthetic tube (shapes it has not seen).

use meshdeco::config::Config;
use meshdeco::math::mat3::Mat3;
use meshdeco::mesh::Vec3;
use meshdeco::metrics::erms::{Alignment, erms};
use meshdeco::model::Model;
use meshdeco::pipeline::autoencoder::AeArtifact;
use meshdeco::pipeline::{Silent, TrainOptions, train};

fn centred(p: &[Vec3]) -> Vec<f64> {
    let n = p.len() as f64;
    let c: [f64; 3] = std::array::from_fn(|d| p.iter().map(|v| v[d]).sum::<f64>() / n);
    p.iter().flat_map(|v| (0..3).map(move |d| v[d] - c[d])).collect()
}

/// A tube autoencoder trained on every third frame (the rest unseen), with `extra` method keys.
fn trained(tag: &str, extra: &str) -> (std::path::PathBuf, Config, meshdeco::pipeline::TrainOutcome) {
    let base = std::env::temp_dir().join(format!("meshdeco-ae-steps-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let cfg = Config::from_toml(&format!(
        "name = \"tube-ae\"\n[data]\npath = \"synthetic:tube\"\ntrain = \"every:3\"\ntest = \"rest\"\n\
         [method]\nkind = \"autoencoder\"\ncomponents = 3\niterations = 400\nlearning_rate = 0.005\nseed = 1\n{extra}"
    ))
    .unwrap();
    let o = train(&cfg, &base, &TrainOptions::default(), &mut Silent).unwrap();
    (base, cfg, o)
}

/// Column k of the exact Jacobian is the central difference of the decoder along dimension k,
/// and Jᵀu is the vector–Jacobian product of u (two independent derivations agree).
#[test]
fn decoder_jacobian_matches_finite_differences_and_the_vjp() {
    for layers in [1usize, 2] {
        let (base, _, _) = trained(&format!("jac{layers}"), &format!("layers = {layers}\nfit_test = false\n"));
        let art = AeArtifact::load(&base).unwrap();
        let d = art.model.decoder_vjp().unwrap();
        let z = art.train_codes[1].clone();
        let (x, j, stride) = d.jacobian(&z).unwrap();
        assert_eq!(x, d.decode(&z).unwrap(), "the Jacobian's features are the decoding");
        let k = z.len();
        assert!(stride >= k && j.len() == x.len() * stride);
        let h = 1e-2;
        let mut worst: f64 = 0.0;
        let mut scale: f64 = 0.0;
        for kk in 0..k {
            let (mut a, mut b) = (z.clone(), z.clone());
            a[kk] += h;
            b[kk] -= h;
            let (xa, xb) = (d.decode(&a).unwrap(), d.decode(&b).unwrap());
            for (row, (pa, pb)) in xa.iter().zip(&xb).enumerate() {
                let fd = (pa - pb) / (2.0 * h);
                worst = worst.max((fd - j[row * stride + kk] as f64).abs());
                scale = scale.max(fd.abs());
            }
        }
        for row in 0..x.len() {
            assert!(j[row * stride + k..(row + 1) * stride].iter().all(|&v| v == 0.0), "padding columns are zero");
        }
        assert!(scale > 1e-3, "the decoder moves with the code");
        assert!(worst <= 2e-3 * scale, "layers {layers}: Jacobian vs central differences: {worst} (scale {scale})");
        // Jᵀu against the VJP of the same u.
        let u: Vec<f64> = (0..x.len()).map(|i| ((i * 7919) % 13) as f64 / 13.0 - 0.5).collect();
        let (_, vjp) = d.decode_vjp(&z, 1, &mut |_| Ok(vec![u.clone()])).unwrap();
        for kk in 0..k {
            let jtu: f64 = (0..x.len()).map(|row| j[row * stride + kk] as f64 * u[row]).sum();
            assert!((jtu - vjp[0][kk]).abs() <= 1e-3 * (1.0 + jtu.abs()), "Jᵀu {jtu} vs VJP {}", vjp[0][kk]);
        }
        let _ = std::fs::remove_dir_all(&base);
    }
}

/// The batched linear part of the ACAP decoding is, centred, the affine decoding minus its
/// constant part, for every set at once.
#[test]
fn batched_linear_decoding_is_the_affine_decoding_minus_its_offset() {
    let (base, _, _) = trained("linear", "fit_test = false\n");
    let art = AeArtifact::load(&base).unwrap();
    let acap = art.representation.acap().unwrap();
    let n = acap.n_vertices();
    let zero = acap.decode_transforms(&vec![[[0.0; 3]; 3]; n]).unwrap();
    let sets: Vec<Vec<Mat3>> = (0..3)
        .map(|s| {
            (0..n)
                .map(|i| {
                    let a = 0.1 * (s + 1) as f64 * ((i % 5) as f64 - 2.0);
                    [[1.0 + a, 0.2 * a, 0.0], [0.0, 1.0, -a], [0.3 * a, 0.0, 1.0 - a]]
                })
                .collect()
        })
        .collect();
    let many = acap.decode_transforms_linear_many(&sets).unwrap();
    assert_eq!(many.len(), 3);
    for (t, lin) in sets.iter().zip(&many) {
        let full = centred(&acap.decode_transforms(t).unwrap());
        let expect: Vec<f64> = full.iter().zip(centred(&zero)).map(|(a, b)| a - b).collect();
        let got = centred(lin);
        let err = got.iter().zip(&expect).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        let size = expect.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(size > 1e-3 && err <= 1e-9 * size.max(1.0), "batched linear decoding off by {err} (size {size})");
    }
    let _ = std::fs::remove_dir_all(&base);
}

/// On unseen frames the default encoder (network, then one vertex step) lands close to the
/// codes fitted to every vertex and well below the network's own codes; `metrics.json`
/// reports the network-only Erms beside; 0 steps is the network's code exactly; more steps
/// never raise the error; the key is checked by name.
#[test]
fn vertex_steps_bring_the_encoder_to_the_fitted_codes_on_unseen_shapes() {
    let (base, cfg, o) = trained("steps", "");
    let m = &o.metrics;
    let (with, network, fitted) = (m.test_erms.unwrap(), m.test_erms_network.unwrap(), m.test_erms_fitted.unwrap());
    eprintln!(
        "tube K = 3, unseen frames: test Erms network only {network:.3}, 1 vertex step {with:.3}, fitted {fitted:.3}"
    );
    assert!(with < network, "one vertex step {with} vs the network's code {network}");
    assert!(with <= 1.5 * fitted, "one vertex step {with} vs fitted codes {fitted}");
    let art = AeArtifact::load(&base).unwrap();
    assert_eq!(art.model.config().encoder_steps, 1, "the default is one step");
    assert!(art.encoder_description().contains("Gauss–Newton"), "{}", art.encoder_description());
    let prep = meshdeco::preprocess::prepare(&cfg.data).unwrap();
    let test = prep.test_sequence().unwrap();
    let by_steps: Vec<f64> = (0..4)
        .map(|s| {
            let z = art.encode_frames_with(&test, 0, s).unwrap();
            erms(&test.frames, &art.decode_codes(&z).unwrap(), Alignment::Centroid).unwrap()
        })
        .collect();
    eprintln!("test Erms by vertex steps 0..3 (no passes): {by_steps:.4?}");
    for w in by_steps.windows(2) {
        assert!(w[1] <= w[0] * (1.0 + 1e-6), "a step raised the error: {by_steps:?}");
    }
    // With residual passes the step starts from the better of the codes with and without them:
    // never above either.
    let erms_of = |passes: usize, steps: usize| {
        let z = art.encode_frames_with(&test, passes, steps).unwrap();
        erms(&test.frames, &art.decode_codes(&z).unwrap(), Alignment::Centroid).unwrap()
    };
    let (stepped, passes_only, one_pass) = (erms_of(2, 1), erms_of(2, 0), erms_of(0, 0));
    assert!(stepped <= passes_only.min(one_pass) * (1.0 + 1e-9), "{stepped} vs {passes_only} / {one_pass}");
    // 0 steps is the network's code, bit for bit; the network-only Erms is that code's.
    let z0 = art.encode_frames_with(&test, 0, 0).unwrap();
    let net = art.model.encode_with_passes(
        &art.header
            .scaling
            .apply(&art.representation.split_pieces(art.representation.encode(&test).unwrap()).unwrap().0)
            .unwrap(),
        0,
    );
    assert_eq!(z0, net.unwrap());
    let zn = art.encode_network(&test).unwrap().unwrap();
    let e = erms(&test.frames, &art.decode_codes(&zn).unwrap(), Alignment::Centroid).unwrap();
    assert!((e - network).abs() <= 1e-9 * network, "network-only Erms {e} vs metrics.json {network}");
    let _ = std::fs::remove_dir_all(&base);
    // The key is checked by name; 0 turns the steps off (no network-only number then).
    let bad = Config::from_toml(
        "name = \"t\"\n[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"autoencoder\"\ncomponents = 3\nencoder_steps = 51\n",
    );
    let msg = bad.err().map(|e| e.to_string()).unwrap_or_default();
    assert!(msg.contains("encoder_steps") && msg.contains("51"), "{msg}");
    let (base, _, o) = trained("off", "encoder_steps = 0\nfit_test = false\n");
    assert!(o.metrics.test_erms_network.is_none());
    let _ = std::fs::remove_dir_all(&base);
}
