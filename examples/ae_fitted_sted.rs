//! STED (spatial and temporal) and Erms of a trained autoencoder's test reconstructions, both
//! with the network encoder's codes and with codes fitted through the decoder (issue 17: the
//! two side by side; `meshdeco eval` reports the same per cell).
//!
//! `cargo run --release --example ae_fitted_sted -- <config.toml> <model dir> [--no-fit]`: the
//! config's `[data]` gives the test split (frames in order: temporal STED); the model is a
//! `meshdeco train` directory of that config. Also prints the components' locality as `meshdeco
//! eval` measures it (median support size and connected support regions).

use std::path::Path;

use meshdeco::config::Config;
use meshdeco::mesh::{MeshSequence, Vec3};
use meshdeco::metrics::erms::{Alignment, erms};
use meshdeco::metrics::locality::{SUPPORT_THRESHOLD, support_regions};
use meshdeco::metrics::sted::{FrameOrder, Sted, StedParams};
use meshdeco::model::RefineOptions;
use meshdeco::pipeline::load_model;

fn centroid_align(r: &mut [Vec3], t: &[Vec3]) {
    let n = r.len() as f64;
    let mut d = [0.0; 3];
    for (a, b) in r.iter().zip(t) {
        for c in 0..3 {
            d[c] += (b[c] - a[c]) / n;
        }
    }
    for a in r.iter_mut() {
        for c in 0..3 {
            a[c] += d[c];
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 3 && !(args.len() == 4 && args[3] == "--no-fit") {
        eprintln!("usage: ae_fitted_sted <config.toml> <model dir> [--no-fit]");
        std::process::exit(2);
    }
    let cfg = Config::from_file(Path::new(&args[1])).expect("config");
    let prep = meshdeco::preprocess::prepare(&cfg.data).expect("data");
    let model = load_model(Path::new(&args[2])).expect("model");
    let test = MeshSequence {
        faces: prep.rest.faces.clone(),
        frames: meshdeco::pipeline::train::frames_in_data_units(&prep, &prep.test).expect("test frames"),
        names: Vec::new(),
    };
    let (norms, adjacency) = model.element_norms();
    let mut sizes = Vec::new();
    let mut regions = Vec::new();
    for n in &norms {
        let r = support_regions(n, adjacency, SUPPORT_THRESHOLD).expect("support regions");
        sizes.push(r.size as f64);
        regions.push(r.regions as f64);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let m = v.len() / 2;
        if v.len().is_multiple_of(2) { 0.5 * (v[m - 1] + v[m]) } else { v[m] }
    };
    println!("components: median support size {}, median support regions {}", median(&mut sizes), median(&mut regions));
    let sted = Sted::new(prep.rest.n_vertices(), &prep.rest.faces, StedParams::default()).expect("sted");
    let t0 = std::time::Instant::now();
    let codes = model.encode(&test).expect("encode");
    let enc = model.decode(&codes).expect("decode");
    let t_enc = t0.elapsed().as_secs_f64();
    let mut runs = vec![("network encoder", enc, t_enc)];
    if args.len() == 3 {
        let t1 = std::time::Instant::now();
        let opts = RefineOptions { points: usize::MAX, gamma: meshdeco::pipeline::ae_fit::DEFAULT_FIT_GAMMA };
        let (_, fit) = model.refine(&test, &codes, &opts, &mut |_| {}).expect("refine").expect("a refinement");
        runs.push(("fitted codes", fit, t1.elapsed().as_secs_f64()));
    }
    for (name, mut rec, secs) in runs {
        let rec = &mut rec;
        let e = erms(&test.frames, rec, Alignment::Centroid).expect("erms");
        for (r, t) in rec.iter_mut().zip(&test.frames) {
            centroid_align(r, t);
        }
        let s = sted.evaluate(&test.frames, rec, FrameOrder::Sequence).expect("sted");
        println!(
            "{name}: test Erms {e:.3} (centroid), STED spatial {:.4}, temporal {}, {secs:.1} s for {} frames",
            s.spatial,
            s.temporal.map(|t| format!("{t:.4}")).unwrap_or_else(|| "–".into()),
            test.frames.len()
        );
    }
}
