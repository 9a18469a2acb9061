//! Throughput of `Model::decode` on a trained model: 1000 weight vectors decoded in one batched
//! call, best of `--repeats` runs. The Python binding's counterpart is
//! `examples/python/decode_throughput.py` (same weights, `meshdeco.Model.decode`); the two are
//! compared in docs/python.md.
//!
//! Weights: row i is the stored training weights of frame `i mod F` scaled by
//! `0.5 + (i mod 7) / 7` (the Python script builds the same rows).
//!
//! ```text
//! meshdeco train --config configs/scape-splocs.toml --out target/tmp/scape-splocs
//! cargo run --release --example decode_throughput -- target/tmp/scape-splocs [--repeats 5]
//! ```

use std::path::PathBuf;
use std::time::Instant;

fn main() -> meshdeco::Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().unwrap_or_else(|| "target/tmp/scape-splocs".into()));
    let mut repeats = 5usize;
    while let Some(a) = args.next() {
        if a == "--repeats" {
            repeats = args.next().and_then(|r| r.parse().ok()).unwrap_or(repeats);
        }
    }
    let model = meshdeco::pipeline::load_model(&dir)?;
    let train = match model.train_weights() {
        Some(w) if !w.is_empty() => w,
        _ => return Err(meshdeco::Error::Invalid(format!("{}: the model stores no training weights", dir.display()))),
    };
    let weights: Vec<Vec<f64>> = (0..1000)
        .map(|i| {
            let s = 0.5 + (i % 7) as f64 / 7.0;
            train[i % train.len()].iter().map(|w| w * s).collect()
        })
        .collect();
    let mut best = f64::INFINITY;
    let mut checksum = 0.0;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let frames = model.decode(&weights)?;
        best = best.min(t.elapsed().as_secs_f64());
        checksum = frames.iter().flatten().map(|p| p[0] + p[1] + p[2]).sum::<f64>();
    }
    println!(
        "rust decode: {} weight vectors (K {}, N {}) in {:.4} s (best of {repeats}): {:.0} shapes/s; checksum {checksum:.9e}",
        weights.len(),
        model.n_components(),
        model.rest().n_vertices(),
        best,
        weights.len() as f64 / best
    );
    Ok(())
}
