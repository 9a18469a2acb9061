//! Diagnostic (issue 17): how far can a code chosen in *feature* space go? Prints the test Erms
//! (centroid-aligned) and the mean squared feature error of the network encoder's codes and of
//! codes fitted to the test shapes' scaled ACAP features through the decoder (min_z ‖D(z) − x‖²,
//! Levenberg–Marquardt from the encoder's code, Jacobian by forward differences, 15
//! iterations). `meshdeco encode --fit` fits the same decoder to the vertices instead.
//!
//! `cargo run --release --example ae_feature_fit -- <config.toml> <model dir>`: the config's
//! `[data]` gives the test split; the model is a `meshdeco train` directory of that config.
use meshdeco::config::Config;
use meshdeco::metrics::erms::{Alignment, erms};
use meshdeco::pipeline::autoencoder::AeArtifact;
use nalgebra::{DMatrix, DVector};
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cfg = Config::from_file(Path::new(&args[1])).expect("config");
    let prep = meshdeco::preprocess::prepare(&cfg.data).expect("data");
    let art = AeArtifact::load(Path::new(&args[2])).expect("model");
    let test = prep.test_sequence().expect("test frames");
    // The one-pass encoder's codes (whatever `encoder_passes` the model was trained with).
    let z0 = art.encode_frames_with_passes(&test, 0).expect("encode");
    let mut scaled = test.clone();
    for p in scaled.frames.iter_mut().flatten() {
        *p = art.header.unit_box.apply(*p);
    }
    let xs = art.header.scaling.apply(&art.representation.encode(&scaled).unwrap()).unwrap();
    let k = z0[0].len();
    let h = 1e-2;
    let mut zf = Vec::new();
    for (t, z) in z0.iter().enumerate() {
        let target = DVector::from_column_slice(xs.frame(t));
        let mut z = z.clone();
        let mut mu = 1e-3;
        for _ in 0..15 {
            let mut batch = vec![z.clone()];
            for j in 0..k {
                let mut zj = z.clone();
                zj[j] += h;
                batch.push(zj);
            }
            let d = art.model.decode(&batch).unwrap();
            let f0 = DVector::from_column_slice(d.frame(0));
            let jac = DMatrix::from_fn(f0.len(), k, |i, j| (d.frame(j + 1)[i] - f0[i]) / h);
            let r = &target - &f0;
            let e0 = r.norm_squared();
            let jtj = jac.transpose() * &jac;
            let g = jac.transpose() * r;
            loop {
                let mut a = jtj.clone();
                for j in 0..k {
                    a[(j, j)] += mu * (jtj[(j, j)] + 1e-9);
                }
                let step = a.cholesky().unwrap().solve(&g);
                let zn: Vec<f64> = z.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
                let dn = art.model.decode(std::slice::from_ref(&zn)).unwrap();
                let en = (&target - DVector::from_column_slice(dn.frame(0))).norm_squared();
                if en < e0 {
                    z = zn;
                    mu *= 0.3;
                    break;
                }
                mu *= 10.0;
                if mu > 1e8 {
                    break;
                }
            }
        }
        zf.push(z);
    }
    // Residual re-encoding: z ← z + E(x) − E(D(z)) (the network's own passes, no fitting).
    let passes: Vec<f64> = (1..=3)
        .map(|p| {
            let z = art.encode_frames_with_passes(&test, p).unwrap();
            erms(&test.frames, &art.decode_codes(&z).unwrap(), Alignment::Centroid).unwrap()
        })
        .collect();
    println!("re-encoded residual, 1-3 passes: {passes:.3?}");
    let truth = &test.frames;
    let enc = art.decode_codes(&z0).unwrap();
    let fit = art.decode_codes(&zf).unwrap();
    let fe = |codes: &[Vec<f64>]| -> f64 {
        let d = art.model.decode(codes).unwrap();
        (0..codes.len())
            .map(|t| d.frame(t).iter().zip(xs.frame(t)).map(|(a, b)| (a - b) * (a - b)).sum::<f64>())
            .sum::<f64>()
            / codes.len() as f64
    };
    println!(
        "encoder: Erms {:.3} feature err {:.3} | feature-fitted: Erms {:.3} feature err {:.3}",
        erms(truth, &enc, Alignment::Centroid).unwrap(),
        fe(&z0),
        erms(truth, &fit, Alignment::Centroid).unwrap(),
        fe(&zf)
    );
}
