//! Edge-length distortion of SPLOCS components' extreme poses: displacement SPLOCS (Neumann et
//! al. 2013) versus SPLOCS on triangle deformation gradients (Huang et al. 2014) on the horse
//! gallop (issue 4: the gradient version should not show the rotational shrink artefacts).
//!
//! Trains both models through the library pipeline from `configs/horse-splocs.toml` and
//! `configs/horse-splocs-gradient.toml` (K 50, λ 2, support [0.1, 0.7], 10 iterations, rest =
//! first frame, unit box), reloads each artefact, synthesizes every component at weight −1 and
//! +1 (other weights 0) and measures each pose against the rest mesh (in data units) with
//! [`meshdeco::metrics::EdgeDistortionMeter`]: mean relative edge-length change
//! `mean |l' − l| / l`, its maximum, and the STED spatial part (1-ring, edge-length weighted).
//! Also printed: the RMS vertex displacement of the poses from the rest (data units), so that a
//! lower distortion can be told apart from a smaller deformation.
//!
//! ```text
//! cargo run --release --example splocs_distortion -- [--out DIR]   # default /tmp/meshdeco-splocs-distortion
//! ```
//! Run from the repository root (the configs' data path is `../shared/data/horse-gallop`); skips
//! with a message when the data folder is absent.

use std::path::{Path, PathBuf};
use std::time::Instant;

use meshdeco::Result;
use meshdeco::config::Config;
use meshdeco::mesh::{TriMesh, Vec3, dist};
use meshdeco::metrics::{EdgeDistortionMeter, StedParams};
use meshdeco::pipeline::Silent;
use meshdeco::pipeline::linear::LinearArtifact;
use meshdeco::pipeline::{TrainOptions, train};

/// Summary over all ±1 poses of one model.
struct Summary {
    name: String,
    representation: String,
    train_erms: f64,
    poses: usize,
    mean_relative: Vec<f64>,
    max_relative: Vec<f64>,
    spatial_sted: Vec<f64>,
    rms_displacement: Vec<f64>,
    zero_pose: [f64; 2],
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        f64::NAN
    } else if s.len() % 2 == 1 {
        s[s.len() / 2]
    } else {
        0.5 * (s[s.len() / 2 - 1] + s[s.len() / 2])
    }
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

fn measure(config: &Path, out_root: &Path) -> Result<Summary> {
    let text = std::fs::read_to_string(config).map_err(|e| meshdeco::Error::io(config, e))?;
    let cfg = Config::from_toml(&text)?;
    let out = out_root.join(&cfg.name);
    let t = Instant::now();
    let outcome = train(&cfg, &out, &TrainOptions::default(), &mut Silent)?;
    println!(
        "{}: trained {} ({}) in {:.2} s wall, {} iterations, train Erms {:.3} ({})",
        cfg.name,
        outcome.metrics.method,
        outcome.metrics.representation,
        t.elapsed().as_secs_f64(),
        outcome.metrics.iterations,
        outcome.metrics.train_erms,
        outcome.metrics.erms_alignment
    );

    let a = LinearArtifact::load(&out)?;
    let rest =
        TriMesh::new(a.rest.positions.iter().map(|p| a.header.unit_box.invert(*p)).collect(), a.rest.faces.clone());
    let meter = EdgeDistortionMeter::new(&rest, StedParams::default())?;
    let k = a.model.n_components;
    let rms = |p: &[Vec3]| {
        (p.iter().zip(&rest.positions).map(|(a, b)| dist(*a, *b).powi(2)).sum::<f64>() / p.len() as f64).sqrt()
    };
    let zero = meter.measure(&a.synthesize(&vec![0.0; k])?)?;
    let mut s = Summary {
        name: cfg.name.clone(),
        representation: a.header.representation.clone(),
        train_erms: outcome.metrics.train_erms,
        poses: 0,
        mean_relative: Vec::new(),
        max_relative: Vec::new(),
        spatial_sted: Vec::new(),
        rms_displacement: Vec::new(),
        zero_pose: [zero.mean_relative, zero.spatial_sted],
    };
    for c in 0..k {
        for sign in [-1.0, 1.0] {
            let mut w = vec![0.0; k];
            w[c] = sign;
            let p = a.synthesize(&w)?;
            let d = meter.measure(&p)?;
            s.poses += 1;
            s.mean_relative.push(d.mean_relative);
            s.max_relative.push(d.max_relative);
            s.spatial_sted.push(d.spatial_sted);
            s.rms_displacement.push(rms(&p));
        }
    }
    Ok(s)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut out_root = PathBuf::from("/tmp/meshdeco-splocs-distortion");
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--out" if i + 1 < args.len() => {
                out_root = PathBuf::from(&args[i + 1]);
                i += 1;
            }
            other => {
                eprintln!("unknown argument `{other}`; usage: splocs_distortion [--out DIR]");
                std::process::exit(2);
            }
        }
        i += 1;
    }
    let data = Path::new("../shared/data/horse-gallop");
    if !data.is_dir() {
        println!("{} absent (run from the repository root with ../shared/data present): skipped", data.display());
        return Ok(());
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut rows = Vec::new();
    for cfg in ["configs/horse-splocs.toml", "configs/horse-splocs-gradient.toml"] {
        rows.push(measure(&root.join(cfg), &out_root)?);
    }
    println!();
    println!("±1 poses of every component against the rest mesh (STED: rings 1, edge-length weighted)");
    println!(
        "{:<24} {:<18} {:>6} {:>9} {:>11} {:>11} {:>10} {:>11} {:>11} {:>12} {:>10}",
        "model",
        "representation",
        "poses",
        "train Erms",
        "mean|dl|/l",
        "median",
        "max |dl|/l",
        "STED_s mean",
        "STED_s med",
        "RMS disp.",
        "rest pose"
    );
    for s in &rows {
        println!(
            "{:<24} {:<18} {:>6} {:>9.3} {:>11.5} {:>11.5} {:>10.4} {:>11.5} {:>11.5} {:>12.5} {:>10.1e}",
            s.name,
            s.representation,
            s.poses,
            s.train_erms,
            mean(&s.mean_relative),
            median(&s.mean_relative),
            max(&s.max_relative),
            mean(&s.spatial_sted),
            median(&s.spatial_sted),
            mean(&s.rms_displacement),
            s.zero_pose[0].max(s.zero_pose[1]),
        );
    }
    if let [d, g] = &rows[..] {
        let per = |s: &Summary| mean(&s.mean_relative) / mean(&s.rms_displacement).max(f64::MIN_POSITIVE);
        println!(
            "gradient / displacement: mean |dl|/l ×{:.3}, STED_s ×{:.3}, RMS displacement ×{:.3}, distortion per unit displacement ×{:.3}",
            mean(&g.mean_relative) / mean(&d.mean_relative),
            mean(&g.spatial_sted) / mean(&d.spatial_sted),
            mean(&g.rms_displacement) / mean(&d.rms_displacement),
            per(g) / per(d)
        );
    }
    Ok(())
}
