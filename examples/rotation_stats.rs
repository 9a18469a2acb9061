//! Study of issue 53 (docs/ground-truth.md § "Features in which the planted deformations add"):
//! how far the training shapes of each dataset of `meshdeco eval` configs rotate, per vertex,
//! against the rest shape — the rotation R of the polar split of each vertex's 1-ring fit T = R·S
//! (the ACAP encoder's steps 1–4), its angle in degrees. Quantiles over every (training frame,
//! vertex) pair; beside them the rest mesh's largest geodesic distance (the double-sweep
//! estimate the autoencoder's support maps are divided by, heat method m = 1) ÷ its
//! bounding-box diagonal.
//!
//! `cargo run --release --example rotation_stats -- CONFIG.toml [CONFIG.toml …]`

use meshdeco::eval::config::EvalConfig;
use meshdeco::geometry::heat_geodesics::HeatGeodesics;
use meshdeco::math::mat3::{axis_angle, polar_decomposition};
use meshdeco::mesh::FrameSource;
use meshdeco::mesh::bounding_box;
use meshdeco::representation::acap::Acap;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.is_empty() {
        return Err("usage: rotation_stats CONFIG.toml [CONFIG.toml …]".into());
    }
    println!(
        "| dataset | training frames | vertices | median | 90 % | 99 % | 99.9 % | largest | largest geodesic ÷ diagonal |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for path in paths {
        let cfg = EvalConfig::from_file(std::path::Path::new(&path))?;
        let cells = cfg.cells()?;
        for (di, d) in cfg.datasets.iter().enumerate() {
            let Some(cell) = cells.iter().find(|c| c.dataset == di) else { continue };
            let prep = meshdeco::preprocess::prepare(&cell.config.data)?;
            let acap = Acap::new(&prep.rest)?;
            let mut angles = Vec::new();
            for &f in &prep.train {
                let frame = prep.sequence.frame(f)?;
                for t in acap.deformation_gradients(&frame)? {
                    let (r, _) = polar_decomposition(&t);
                    angles.push(axis_angle(&r).1.to_degrees());
                }
            }
            angles.sort_by(f64::total_cmp);
            let heat = HeatGeodesics::new(&prep.rest.positions, &prep.rest.faces, 1.0)?;
            let (lo, hi) = bounding_box(&prep.rest.positions);
            let diag = (0..3).map(|c| (hi[c] - lo[c]).powi(2)).sum::<f64>().sqrt();
            let geo = heat.max_distance_estimate()? / diag;
            let q = |p: f64| angles[((angles.len() - 1) as f64 * p).round() as usize];
            println!(
                "| {} | {} | {} | {:.1}° | {:.1}° | {:.1}° | {:.1}° | {:.1}° | {:.2} |",
                d.name,
                prep.train.len(),
                prep.rest.n_vertices(),
                q(0.5),
                q(0.9),
                q(0.99),
                q(0.999),
                q(1.0),
                geo
            );
        }
    }
    Ok(())
}
