//! Study of issue 53 (docs/ground-truth.md § "The face's noisy features"): where does position
//! noise land in the ACAP features of a planted set, and how much of it do the weights of
//! `feature_weights = "noise"` remove?
//!
//! Per vertex: the noise energy of the training frames' features (noisy frame − the same frame
//! rebuilt without noise from the true fields and weights) and their signal energy (clean frame
//! − rest), summed over the frames and the 9 channels; then the share of each carried by the
//! noisiest vertices, and the noise ÷ signal ratio of the whole set unweighted, weighted by the
//! library's truth-free weights (`representation::noise_sensitivity`, from the rest mesh alone),
//! and weighted by each vertex's measured noise (the oracle).
//!
//! `cargo run --release --example feature_noise_study -- TRUTH_DIR [FRAMES]`
use meshdeco::eval::planted::Truth;
use meshdeco::mesh::npy::NpyFrames;
use meshdeco::representation::noise_sensitivity::{NOISE_DRAWS, NOISE_LEVEL, feature_noise_variance, noise_weights};
use meshdeco::representation::{Features, Representation, RepresentationKind, RepresentationOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 2 {
        return Err("usage: feature_noise_study TRUTH_DIR [FRAMES]".into());
    }
    let dir = std::path::Path::new(&a[1]);
    let truth = Truth::load(dir)?;
    let rest = meshdeco::mesh::load_mesh(&dir.join("template.obj"))?;
    let n = rest.positions.len();
    let npy = NpyFrames::open(&dir.join("frames.npy"), n)?.ok_or("frames.npy: not in C order")?;
    let weights = truth.weights()?;
    let frames = match a.get(2) {
        Some(s) => s.parse::<usize>().map_err(|_| format!("FRAMES `{s}` is not a count"))?,
        None => truth.file.train,
    }
    .min(truth.file.train);
    // The autoencoder's representation (ACAP, its default consistency).
    let rep = Representation::new(RepresentationKind::Acap, &rest, RepresentationOptions::default())?;
    let rest_f = rep.encode_frame(&rest.positions)?;
    let (mut noise, mut signal) = (vec![0.0f64; n], vec![0.0f64; n]);
    for (f, frame_weights) in weights.iter().enumerate().take(frames) {
        let noisy = npy.read_frame(f)?;
        let mut clean = rest.positions.clone();
        for (d, &w) in frame_weights.iter().enumerate().filter(|(_, w)| **w != 0.0) {
            for (p, q) in clean.iter_mut().zip(&truth.fields[d]) {
                for c in 0..3 {
                    p[c] += w * q[c];
                }
            }
        }
        let (fn_, fc) = (rep.encode_frame(&noisy)?, rep.encode_frame(&clean)?);
        for i in 0..n {
            for c in 0..9 {
                let k = i * 9 + c;
                noise[i] += (fn_[k] - fc[k]).powi(2);
                signal[i] += (fc[k] - rest_f[k]).powi(2);
            }
        }
    }
    let (tot_n, tot_s) = (noise.iter().sum::<f64>(), signal.iter().sum::<f64>());
    println!("{}: {n} vertices, {frames} training frames", dir.display());
    println!("noise ÷ signal (RMS), unweighted: {:.3}", (tot_n / tot_s).sqrt());
    let mut idx: Vec<usize> = (0..n).collect();
    idx.sort_by(|&x, &y| noise[y].total_cmp(&noise[x]));
    for frac in [0.01, 0.05, 0.1, 0.5] {
        let m = ((n as f64) * frac).ceil() as usize;
        let (sn, ss): (f64, f64) =
            idx[..m].iter().map(|&i| (noise[i], signal[i])).fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        println!(
            "the {:>2.0} % noisiest vertices carry {:.1} % of the noise, {:.1} % of the signal",
            frac * 100.0,
            100.0 * sn / tot_n,
            100.0 * ss / tot_s
        );
    }
    let id = |x: Features| Ok(x);
    let var = feature_noise_variance(&rep, NOISE_LEVEL, NOISE_DRAWS, 0, &id)?;
    let ln = |v: &[f64]| v.iter().map(|x| x.max(1e-300).ln()).collect::<Vec<f64>>();
    println!("correlation of log noise with log noise sensitivity (truth-free): {:.3}", corr(&ln(&noise), &ln(&var)));
    let ratio = |w: &[f64]| {
        let wn: f64 = noise.iter().zip(w).map(|(a, b)| a * b).sum();
        let ws: f64 = signal.iter().zip(w).map(|(a, b)| a * b).sum();
        (wn / ws).sqrt()
    };
    let w = noise_weights(&var);
    println!(
        "noise ÷ signal (RMS), weighted by feature_weights = \"noise\": {:.3} ({} vertices below 1/2)",
        ratio(&w),
        w.iter().filter(|&&x| x < 0.5).count()
    );
    let oracle: Vec<f64> = noise.iter().map(|v| 1.0 / v.max(1e-300)).collect();
    println!("noise ÷ signal (RMS), weighted by 1 / each vertex's measured noise (oracle): {:.3}", ratio(&oracle));
    Ok(())
}

/// Pearson correlation of two equally long samples.
fn corr(x: &[f64], y: &[f64]) -> f64 {
    let m = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / m, y.iter().sum::<f64>() / m);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    sxy / (sxx * syy).sqrt()
}
