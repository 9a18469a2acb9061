//! Why does the automatic region search stop early? For each k, segments with a fixed region
//! count and reports per cluster the vertex-connected pieces of its triangles and the vertices
//! in no all-inside triangle (the compactness test of `methods::segmentation`).
//!
//! `cargo run --release --example segmentation_study -- DATA TRAIN LAMBDA R THRESHOLD KMAX [min_piece]`
//! (R = 0 for the default 0.1 × bounding-box diagonal; min_piece = fragment fraction merged away,
//! 0 to disable), e.g. `../shared/data/face-poses 1-7 0.7 0 0.7 16`.

use meshdeco::config::Config;
use meshdeco::methods::segmentation::{SegmentationConfig, all_compact, cluster_pieces, segment};
use meshdeco::representation::{Representation, RepresentationKind, RepresentationOptions};

fn main() -> anyhow::Result<()> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 7 {
        anyhow::bail!("usage: segmentation_study DATA TRAIN LAMBDA R THRESHOLD KMAX [min_piece]");
    }
    let cfg = Config::from_toml(&format!(
        "name = \"study\"\n[data]\npath = {:?}\ntrain = {:?}\n[method]\nkind = \"region-pca\"\n",
        a[1], a[2]
    ))?;
    let prep = meshdeco::preprocess::prepare(&cfg.data)?;
    let seq = prep.train_sequence()?;
    let rep = Representation::new(RepresentationKind::Displacement, &prep.rest, RepresentationOptions::default())?;
    let x = rep.encode(&seq)?;
    let lambda: f64 = a[3].parse()?;
    let r: f64 = a[4].parse()?;
    let threshold: f64 = a[5].parse()?;
    let kmax: usize = a[6].parse()?;
    let min_piece: f64 = a.get(7).map(|s| s.parse()).transpose()?.unwrap_or(0.0);
    println!(
        "{} training frames, {} vertices; lambda {lambda}, r {}, threshold {threshold}, min_piece {min_piece}",
        x.n_frames,
        prep.rest.n_vertices(),
        if r > 0.0 { r.to_string() } else { "default".into() }
    );
    for k in 2..=kmax {
        let cfg = SegmentationConfig {
            lambda,
            r: (r > 0.0).then_some(r),
            threshold,
            regions: Some(k),
            restarts: 8,
            min_piece,
            ..Default::default()
        };
        let t = std::time::Instant::now();
        let seg = segment(&prep.rest.positions, &prep.rest.faces, &x.data, x.n_frames, &cfg)?;
        let m = seg.n_regions();
        let ok = all_compact(&seg.labels, m, &prep.rest.faces);
        let mut bad = Vec::new();
        for c in 0..m {
            let (p, u) = cluster_pieces(&seg.labels, c, &prep.rest.faces);
            if p.len() != 1 || u > 0 {
                bad.push(format!("c{c}: pieces {:?} uncovered {u}", &p[..p.len().min(5)]));
            }
        }
        let sizes: Vec<usize> = (0..m).map(|c| seg.labels.iter().filter(|&&l| l == c).count()).collect();
        println!(
            "k = {k}: {m} clusters, compact {ok}, sizes {sizes:?} ({:.1} s){}",
            t.elapsed().as_secs_f64(),
            if bad.is_empty() { String::new() } else { format!("\n    not compact: {}", bad.join("; ")) }
        );
    }
    Ok(())
}
