//! The autoencoder encoder's vertex steps (`encoder_steps`, issue 31): the exact decoder
//! Jacobian, the ACAP decoding's batched linear part, and the steps themselves on a trained
//! model of the synthetic tube (shapes it has not seen).

use meshdeco::config::Config;
use meshdeco::math::mat3::Mat3;
use meshdeco::mesh::Vec3;
use meshdeco::metrics::erms::{Alignment, erms};
use meshdeco::model::Model;
use meshdeco::pipeline::ae_vertex_steps::{JACOBIAN_TOLERANCE, VertexSteps};
use meshdeco::pipeline::autoencoder::AeArtifact;
use meshdeco::pipeline::{Silent, TrainOptions, train};
use meshdeco::representation::scaling::FeatureScaling;

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

/// On unseen frames the default encoder (network, then its vertex steps) lands close to the
/// codes fitted to every vertex and well below the network's own codes; `metrics.json`
/// reports the network-only Erms beside; 0 steps is the network's code exactly; more steps
/// never raise the error; the key is checked by name.
#[test]
fn vertex_steps_bring_the_encoder_to_the_fitted_codes_on_unseen_shapes() {
    let (base, cfg, o) = trained("steps", "");
    let m = &o.metrics;
    let (with, network, fitted) = (m.test_erms.unwrap(), m.test_erms_network.unwrap(), m.test_erms_fitted.unwrap());
    eprintln!(
        "tube K = 3, unseen frames: test Erms network only {network:.3}, default vertex steps {with:.3}, fitted {fitted:.3}"
    );
    assert!(with < network, "vertex steps {with} vs the network's code {network}");
    assert!(with <= 1.5 * fitted, "vertex steps {with} vs fitted codes {fitted}");
    let art = AeArtifact::load(&base).unwrap();
    assert_eq!(art.model.config().encoder_steps, 5, "the default is at most five steps");
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
    // Up to 50 steps from each network code: another Jacobian is evaluated only while the
    // previous one's last chord step still lowered the error by JACOBIAN_TOLERANCE or more, so
    // every gain but the last is at least that; the steps stop before the cap.
    let decoder = art.model.decoder_vjp().unwrap();
    let stepper = VertexSteps::new(&art, decoder, 50).unwrap();
    let one = VertexSteps::new(&art, decoder, 1).unwrap();
    let mut taken = Vec::new();
    for (target, z0) in test.frames.iter().zip(&z0) {
        let t: Vec<Vec3> = target.iter().map(|&p| art.header.unit_box.apply(p)).collect();
        let (_, r) = stepper.refine(z0, &t).unwrap();
        let (_, r1) = one.refine(z0, &t).unwrap();
        assert_eq!(r.gains.len(), r.steps, "{r:?}");
        assert!(r.steps < 50 && r.error <= r1.error * (1.0 + 1e-12), "{r:?} vs one step {r1:?}");
        let (last, before) = r.gains.split_last().unwrap();
        assert!(before.iter().all(|&g| g >= JACOBIAN_TOLERANCE), "a Jacobian after a gain below the tolerance: {r:?}");
        assert!(*last < JACOBIAN_TOLERANCE, "stopped with a gain of {last} (not the rule): {r:?}");
        taken.push(r.steps);
    }
    eprintln!("Jacobians per unseen tube shape, at most 50 allowed: {taken:?}");
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

/// The feature scaling's outlier fence (`scaling_quantile`, issue 31): one vertex of one training
/// frame pulled far out (a sliver that stretches many times over, as on the face-poses mesh)
/// sets the minimum/maximum range alone; the default fence (the 0.1 % … 99.9 % range widened by
/// its width each side) ignores it, the model stores which ends it clamps, and encoding that
/// frame clamps the outlier's features into [−0.95, 0.95]; on the tube without the outlier the
/// default is the minimum and maximum exactly.
#[test]
fn an_outlier_feature_does_not_set_the_scaling_range() {
    let mut seq = meshdeco::synthetic::load("synthetic:tube").unwrap();
    let p = &seq.frames[3];
    let (lo, hi) = p.iter().fold(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), |(mut a, mut b), v| {
        for d in 0..3 {
            a[d] = a[d].min(v[d]);
            b[d] = b[d].max(v[d]);
        }
        (a, b)
    });
    let diagonal = (0..3).map(|d| (hi[d] - lo[d]).powi(2)).sum::<f64>().sqrt();
    seq.frames[3][40][0] += 0.5 * diagonal;
    let mut ranges = Vec::new();
    for (q, tag) in [(0.0, "minmax"), (1e-3, "fenced")] {
        let base = std::env::temp_dir().join(format!("meshdeco-ae-fence-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        let cfg = Config::from_toml(&format!(
            "name = \"tube-fence\"\n[data]\npath = \"synthetic:tube\"\ntrain = \"every:3\"\ntest = \"rest\"\n\
             [method]\nkind = \"autoencoder\"\ncomponents = 3\niterations = 30\nseed = 1\nfit_test = false\n\
             scaling_quantile = {q}\n"
        ))
        .unwrap();
        let prep = meshdeco::preprocess::prepare_sequence(seq.clone(), &cfg.data).unwrap();
        let o = meshdeco::pipeline::train_prepared(&cfg, &prep, &base, &TrainOptions::default(), &mut Silent).unwrap();
        assert!(o.metrics.train_erms.is_finite() && o.metrics.test_erms.is_some_and(f64::is_finite));
        let art = AeArtifact::load(&base).unwrap();
        let s = art.header.scaling.clone();
        // What the encoder sees of the frame with the outlier.
        let frame = seq.select(&[3]);
        let own = art.representation.split_pieces(art.representation.encode(&frame).unwrap()).unwrap().0;
        let scaled = s.apply(&own).unwrap();
        let top = scaled.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        ranges.push((s.max[0] - s.min[0], s.clamped.len(), top));
        if q > 0.0 {
            // The tube without the outlier has no far tail: the default fence (the quantile range
            // widened by its width each side) reaches its minimum and maximum and clamps nothing,
            // where the bare quantile range (fence 0) would cut its largest bends.
            let d = meshdeco::config::AutoencoderMethod::default();
            let clean = meshdeco::synthetic::load("synthetic:tube").unwrap();
            let every3: Vec<usize> = (0..clean.frames.len()).step_by(3).collect();
            let f = art.representation.split_pieces(art.representation.encode(&clean.select(&every3)).unwrap());
            let f = f.unwrap().0;
            let mode = d.scaling.mode();
            let fenced =
                FeatureScaling::fit_quantile(&f.data, f.width, mode.clone(), d.scaling_quantile, d.scaling_fence);
            assert_eq!(fenced.unwrap(), FeatureScaling::fit_slice(&f.data, f.width, mode.clone()).unwrap());
            let bare = FeatureScaling::fit_quantile(&f.data, f.width, mode, d.scaling_quantile, 0.0).unwrap();
            assert!(!bare.clamped.is_empty(), "fence 0 keeps the tube's extremes: {bare:?}");
        }
        let _ = std::fs::remove_dir_all(&base);
    }
    eprintln!(
        "tube with an outlier: (range width, clamp flags, largest scaled feature) min/max {:?}, fenced {:?}",
        ranges[0], ranges[1]
    );
    let ((wide, none, top_minmax), (narrow, flags, top_fenced)) = (ranges[0], ranges[1]);
    assert_eq!((none, flags), (0, 9), "the min/max scaling clamps nothing; the fenced one names its ends");
    assert!(narrow < 0.25 * wide, "the fenced range {narrow} vs min/max {wide}");
    assert!(top_minmax <= 0.95 + 1e-9 && top_fenced <= 0.95 + 1e-9, "{top_minmax} / {top_fenced}");
}
