//! The drag benchmark: what one, three or ten pins dragged in the viewer do to a model's shape.
//!
//! A drag: from the model's neutral shape P0 (the decoding of [`Model::start_weights`]`(None)`),
//! pick `pins` distinct random vertices and move each to its position in a *test* frame T
//! (aligned as the model aligns: for centroid alignment T is translated so that its centroid is
//! P0's), pose ([`Model::pose`] with the given [`PoseOptions`]) and measure, with P the posed
//! shape, `d_a = ‖T_a − P0_a‖` the drag of pin a and `d̄` the mean drag (data units):
//!
//! - **landing**: mean over the pins of `‖P_a − T_a‖ / d_a`, in % of the drag;
//! - **max motion ÷ drag**: `max_v ‖P_v − P0_v‖ / max_a d_a`;
//! - **moved share**: the share of vertices with `‖P_v − P0_v‖ > d̄ / 2`, and beside it the same
//!   share for the test frame itself (`‖T_v − P0_v‖ > d̄ / 2`): a drag towards a frame that moves
//!   much may move much;
//! - **Erms** of P and of P0 against T (the model's alignment).
//!
//! Drags whose mean drag is below 1e-6 × the bounding-box diagonal are redrawn (a pin that does
//! not move says nothing). Each row of the report is the median over the drags.

use serde::Serialize;

use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, Vec3};
use crate::metrics::erms::{Alignment, erms};
use crate::model::{Model, PoseOptions};
use crate::rng::Rng;

/// What to run.
#[derive(Debug, Clone)]
pub struct DragBenchConfig {
    /// Drags per pin count.
    pub drags: usize,
    /// Pin counts (e.g. 1, 3, 10).
    pub pins: Vec<usize>,
    /// Seed of the draws (frame and vertices).
    pub seed: u64,
    /// The pose options (the defaults of `meshdeco pose` and the viewer unless overridden).
    pub options: PoseOptions,
}

/// One drag's measures.
#[derive(Debug, Clone, Serialize)]
pub struct DragResult {
    pub pins: usize,
    pub frame: usize,
    pub vertices: Vec<usize>,
    /// Mean landing error, % of the drag.
    pub landing_percent: f64,
    /// Largest motion of any vertex ÷ the largest drag.
    pub max_motion_ratio: f64,
    /// Share of vertices moved more than half the mean drag.
    pub moved_share: f64,
    /// The same share for the test frame against the neutral shape.
    pub frame_moved_share: f64,
    /// Erms of the posed shape and of the neutral shape against the test frame.
    pub posed_erms: f64,
    pub neutral_erms: f64,
    /// Wall time of the pose, seconds.
    pub seconds: f64,
}

/// Medians over the drags of one pin count.
#[derive(Debug, Clone, Serialize)]
pub struct DragSummary {
    pub pins: usize,
    pub drags: usize,
    pub landing_percent: f64,
    pub max_motion_ratio: f64,
    pub moved_share: f64,
    pub frame_moved_share: f64,
    pub posed_erms: f64,
    pub neutral_erms: f64,
    /// Share of drags whose posed Erms is below the neutral shape's.
    pub improved_share: f64,
    pub seconds: f64,
}

/// The median of `v` (NaN-free), 0 for none.
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

fn centroid(p: &[Vec3]) -> Vec3 {
    let n = p.len().max(1) as f64;
    std::array::from_fn(|k| p.iter().map(|q| q[k]).sum::<f64>() / n)
}

/// Runs the benchmark on `test` frames (the model's connectivity). Returns every drag and the
/// medians per pin count.
pub fn drag_bench(
    model: &dyn Model,
    test: &MeshSequence,
    cfg: &DragBenchConfig,
) -> Result<(Vec<DragResult>, Vec<DragSummary>)> {
    let rest = model.rest();
    let n = rest.n_vertices();
    if test.n_vertices() != n || test.n_frames() == 0 {
        return Err(Error::Invalid(format!(
            "drag benchmark: {} test frames of {} vertices, the model has {n} vertices",
            test.n_frames(),
            test.n_vertices()
        )));
    }
    if cfg.drags == 0 || cfg.pins.is_empty() || cfg.pins.iter().any(|&p| p == 0 || p > n) {
        return Err(Error::Invalid(format!(
            "drag benchmark: {} drags of {:?} pins: need at least one drag and pin counts from 1 to {n}",
            cfg.drags, cfg.pins
        )));
    }
    cfg.options.validate()?;
    let w0 = model.start_weights(None)?;
    let p0 = model.decode(std::slice::from_ref(&w0))?.remove(0);
    let (lo, hi) = rest.bounding_box();
    let diag = crate::mesh::dist(lo, hi);
    let alignment = model.alignment();
    let c0 = centroid(&p0);
    let mut rng = Rng::new(cfg.seed);
    let mut all = Vec::new();
    let mut summaries = Vec::new();
    for &pins in &cfg.pins {
        let mut rows = Vec::new();
        let mut attempts = 0;
        while rows.len() < cfg.drags {
            attempts += 1;
            if attempts > 20 * cfg.drags {
                return Err(Error::Invalid("drag benchmark: the test frames do not move the drawn pins".into()));
            }
            let f = rng.below(test.n_frames());
            let mut t = test.frames[f].clone();
            if alignment == Alignment::Centroid {
                let ct = centroid(&t);
                for q in &mut t {
                    for k in 0..3 {
                        q[k] += c0[k] - ct[k];
                    }
                }
            }
            let vertices = {
                let mut v = rng.sample_distinct(n, pins);
                v.sort_unstable();
                v
            };
            let drags: Vec<f64> = vertices.iter().map(|&v| crate::mesh::dist(t[v], p0[v])).collect();
            let mean_drag = drags.iter().sum::<f64>() / pins as f64;
            if mean_drag <= 1e-6 * diag {
                continue;
            }
            let targets: Vec<Vec3> = vertices.iter().map(|&v| t[v]).collect();
            let t0 = std::time::Instant::now();
            let r = model.pose(&vertices, &targets, &w0, &cfg.options)?;
            let seconds = t0.elapsed().as_secs_f64();
            let p = r.positions;
            let landing = vertices
                .iter()
                .zip(&drags)
                .map(|(&v, &d)| if d > 0.0 { crate::mesh::dist(p[v], t[v]) / d } else { 0.0 })
                .sum::<f64>()
                / pins as f64;
            let motion: Vec<f64> = p.iter().zip(&p0).map(|(a, b)| crate::mesh::dist(*a, *b)).collect();
            let max_drag = drags.iter().cloned().fold(0.0, f64::max);
            let share = |m: &dyn Fn(usize) -> f64| (0..n).filter(|&v| m(v) > 0.5 * mean_drag).count() as f64 / n as f64;
            rows.push(DragResult {
                pins,
                frame: f,
                vertices,
                landing_percent: 100.0 * landing,
                max_motion_ratio: motion.iter().cloned().fold(0.0, f64::max) / max_drag,
                moved_share: share(&|v| motion[v]),
                frame_moved_share: share(&|v| crate::mesh::dist(t[v], p0[v])),
                posed_erms: erms(std::slice::from_ref(&t), std::slice::from_ref(&p), alignment)?,
                neutral_erms: erms(std::slice::from_ref(&t), std::slice::from_ref(&p0), alignment)?,
                seconds,
            });
        }
        let col = |g: &dyn Fn(&DragResult) -> f64| median(rows.iter().map(g).collect());
        summaries.push(DragSummary {
            pins,
            drags: rows.len(),
            landing_percent: col(&|r| r.landing_percent),
            max_motion_ratio: col(&|r| r.max_motion_ratio),
            moved_share: col(&|r| r.moved_share),
            frame_moved_share: col(&|r| r.frame_moved_share),
            posed_erms: col(&|r| r.posed_erms),
            neutral_erms: col(&|r| r.neutral_erms),
            improved_share: rows.iter().filter(|r| r.posed_erms < r.neutral_erms).count() as f64 / rows.len() as f64,
            seconds: col(&|r| r.seconds),
        });
        all.extend(rows);
    }
    Ok((all, summaries))
}
