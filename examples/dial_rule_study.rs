//! Issue 53: truth-free scores of the autoencoder's dial readouts (`dial_sparsity`) beside the
//! recovery they cannot see, to choose the rule `dial_sparsity = "auto"` keeps by.
//!
//! `cargo run --release --example dial_rule_study -- TRUTH_DIR MODEL_DIR…` (TRUTH_DIR `-`: no
//! truth, the scores only)
//! prints one line per model and readout (the dial basis at each sparsity `"auto"` tries), read as
//! the trainer reads them (`AeArtifact::read_dials`); `top10` is the score it keeps by
//! (`energy_concentration`).
use meshdeco::config::DialSparsity;
use meshdeco::eval::planted::Truth;
use meshdeco::metrics::recovery::{best_matches, energy_concentration, summarize, support, support_size};
use meshdeco::model::Model;
use meshdeco::pipeline::autoencoder::AeArtifact;
type V = [f64; 3];

/// The median the trainer takes (mean of the two middle values for an even count).
fn median(v: Vec<f64>) -> f64 {
    meshdeco::pipeline::metrics_file::median(&v).unwrap_or(f64::NAN)
}

/// Share of vertices above `frac` of the field's peak.
fn support_at(f: &[V], frac: f64) -> f64 {
    support(f, frac).into_iter().filter(|&b| b).count() as f64 / f.len().max(1) as f64
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        return Err("usage: dial_rule_study TRUTH_DIR MODEL_DIR…".into());
    }
    let truth = if a[1] == "-" { None } else { Some(Truth::load(std::path::Path::new(&a[1]))?) };
    println!("model\treadout\tfound\tmedcos\tsupp5\tsupp20\ttop10\tactive\tneg\tmaxcorr\tkurt");
    for dir in &a[2..] {
        let mut art = match AeArtifact::load(std::path::Path::new(dir)) {
            Ok(m) => m,
            Err(e) => {
                println!("{dir}\t(not loaded: {e})");
                continue;
            }
        };
        let k = art.header.components;
        for s in DialSparsity::CANDIDATES {
            if let Err(e) = art.read_dials(s) {
                println!("{dir}\t{s}\t(no readout: {e})");
                continue;
            }
            let mut fields = meshdeco::model::component_fields(&art)?;
            fields.truncate(k);
            let (found, medcos) = match &truth {
                Some(t) => {
                    let sm = summarize(&best_matches(&t.fields, &fields)?, &t.counted());
                    (sm.found, sm.median_abs_cos)
                }
                None => (0, f64::NAN),
            };
            let s5 = median(fields.iter().map(|f| support_size(f) as f64 / f.len() as f64).collect());
            let s20 = median(fields.iter().map(|f| support_at(f, 0.2)).collect());
            let te = median(fields.iter().map(|f| energy_concentration(f)).collect());
            // Training dials: how many per shape are active (> 0.1 of the dial's extreme), and
            // the share of their magnitude that is negative.
            let (mut active, mut neg, mut tot) = (0.0, 0.0, 0.0);
            let mut dm: Vec<Vec<f64>> = Vec::new();
            for z in &art.train_codes {
                let d = art.dials(z)?;
                dm.push(d[..k].to_vec());
                active += d[..k].iter().filter(|x| x.abs() > 0.1).count() as f64;
                neg += d[..k].iter().filter(|x| **x < 0.0).map(|x| -x).sum::<f64>();
                tot += d[..k].iter().map(|x| x.abs()).sum::<f64>();
            }
            let n = art.train_codes.len() as f64;
            // Per dial: its largest |correlation| with another dial over the training shapes,
            // and its excess kurtosis.
            let cols: Vec<Vec<f64>> = (0..k)
                .map(|c| {
                    let v: Vec<f64> = dm.iter().map(|r| r[c]).collect();
                    let m = v.iter().sum::<f64>() / n;
                    let sd = (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n).sqrt().max(1e-300);
                    v.iter().map(|x| (x - m) / sd).collect()
                })
                .collect();
            let maxcorr = median(
                (0..k)
                    .map(|i| {
                        (0..k)
                            .filter(|&j| j != i)
                            .map(|j| (cols[i].iter().zip(&cols[j]).map(|(a, b)| a * b).sum::<f64>() / n).abs())
                            .fold(0.0, f64::max)
                    })
                    .collect(),
            );
            let kurt = median(cols.iter().map(|c| c.iter().map(|x| x.powi(4)).sum::<f64>() / n - 3.0).collect());
            println!(
                "{dir}\t{s}\t{}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.2}\t{:.3}\t{:.3}\t{:.1}",
                found,
                medcos,
                s5,
                s20,
                te,
                active / n,
                neg / tot.max(1e-300),
                maxcorr,
                kurt
            );
        }
    }
    Ok(())
}
