//! The drag benchmark: what one, three or ten pins dragged in the viewer do to a model's shape.
//!
//! A drag: from the model's neutral shape P0 (the decoding of [`Model::start_weights`]`(None)`),
//! pick `pins` distinct random vertices and move each to its position in a *test* frame T
//! (aligned as the model aligns: for centroid alignment T is translated so that its centroid is
//! P0's), pose ([`crate::model::landed_pose`] with the given [`PoseOptions`]: the model's pose and,
//! with `spread` > 0, the landing correction) and measure, with P the posed
//! shape, `d_a = ‖T_a − P0_a‖` the drag of pin a and `d̄` the mean drag (data units):
//!
//! - **landing**: mean over the pins of `‖P_a − T_a‖ / d_a`, in % of the drag;
//! - **max motion ÷ drag**: `max_v ‖P_v − P0_v‖ / max_a d_a`;
//! - **moved share**: the share of vertices with `‖P_v − P0_v‖ > d̄ / 2`, and beside it the same
//!   share for the test frame itself (`‖T_v − P0_v‖ > d̄ / 2`): a drag towards a frame that moves
//!   much may move much;
//! - **Erms** of P and of P0 against T (the model's alignment).
//!
//! **The null.** Every drag is also posed with the weights frozen at the start
//! ([`PoseOptions::frozen`]: P0 plus the landing correction alone, the same radius), giving the
//! null shape Q: its Erms against T and its max motion ÷ drag. `posed ÷ null` is P's Erms ÷ Q's:
//! what the model's components add to what the correction does anyway (below 1: the model
//! helps).
//!
//! Drags whose mean drag is below 1e-6 × the bounding-box diagonal are redrawn (a pin that does
//! not move says nothing). Each row of the report is the median over the drags, with the share
//! of drags that improve on the neutral shape and that beat the null, each by more than
//! [`GAIN_TOLERANCE`], and the tail of the max motion ÷ drag (90th percentile and maximum).

use serde::Serialize;

use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, Vec3};
use crate::metrics::erms::{Alignment, erms};
use crate::model::{Model, PoseOptions};
use crate::rng::Rng;

/// A drag counts as improving on the neutral shape (beating the null) when its posed Erms is
/// below (1 − this) × the neutral's (the null's): 1 %, so that a gain of rounding size is none.
pub const GAIN_TOLERANCE: f64 = 0.01;

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

/// What one drag measures (module docs); a summary holds their medians.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct DragMeasures {
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
    /// Erms of the null shape (weights frozen, the landing correction alone) against the frame.
    pub null_erms: f64,
    /// Posed Erms ÷ null Erms (below 1: the model's components help).
    pub null_ratio: f64,
    /// Largest motion of any vertex of the null shape ÷ the largest drag.
    pub null_max_motion_ratio: f64,
    /// Wall time of the pose, seconds.
    pub seconds: f64,
}

impl DragMeasures {
    /// Each measure's median over `all`.
    fn medians(all: &[DragMeasures]) -> DragMeasures {
        // `all` is never empty: a summary has at least one drag.
        let col = |g: fn(&DragMeasures) -> f64| {
            crate::pipeline::metrics_file::median(&all.iter().map(g).collect::<Vec<_>>()).unwrap_or(0.0)
        };
        DragMeasures {
            landing_percent: col(|m| m.landing_percent),
            max_motion_ratio: col(|m| m.max_motion_ratio),
            moved_share: col(|m| m.moved_share),
            frame_moved_share: col(|m| m.frame_moved_share),
            posed_erms: col(|m| m.posed_erms),
            neutral_erms: col(|m| m.neutral_erms),
            null_erms: col(|m| m.null_erms),
            null_ratio: col(|m| m.null_ratio),
            null_max_motion_ratio: col(|m| m.null_max_motion_ratio),
            seconds: col(|m| m.seconds),
        }
    }
}

/// One drag.
#[derive(Debug, Clone, Serialize)]
pub struct DragResult {
    pub pins: usize,
    pub frame: usize,
    pub vertices: Vec<usize>,
    #[serde(flatten)]
    pub measures: DragMeasures,
}

/// Medians over the drags of one pin count.
#[derive(Debug, Clone, Serialize)]
pub struct DragSummary {
    pub pins: usize,
    pub drags: usize,
    #[serde(flatten)]
    pub medians: DragMeasures,
    /// Share of drags whose posed Erms is below (1 − [`GAIN_TOLERANCE`]) × the neutral shape's.
    pub improved_share: f64,
    /// Share of drags whose posed Erms is below (1 − [`GAIN_TOLERANCE`]) × the null's.
    pub beats_null_share: f64,
    /// 90th percentile and maximum over the drags of the max motion ÷ drag.
    pub max_motion_p90: f64,
    pub max_motion_max: f64,
}

/// The `q` quantile (0 ..= 1) of `values`, linear between order statistics (`values` not empty).
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let x = q.clamp(0.0, 1.0) * (v.len().saturating_sub(1)) as f64;
    let (i, f) = (x.floor() as usize, x.fract());
    match v.get(i + 1) {
        Some(&next) => v[i] + f * (next - v[i]),
        None => v.get(i).copied().unwrap_or(0.0),
    }
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
    let null_options = cfg.options.frozen();
    let w0 = model.start_weights(None)?;
    let p0 = model.decode(std::slice::from_ref(&w0))?.remove(0);
    let (lo, hi) = rest.bounding_box();
    let diag = crate::mesh::dist(lo, hi);
    let alignment = model.alignment();
    let spreader = crate::model::spreader(model);
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
                super::centroid_align(&mut t, &p0);
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
            let r = crate::model::landed_pose(model, &spreader, &vertices, &targets, &w0, &cfg.options)?;
            let seconds = t0.elapsed().as_secs_f64();
            let p = r.positions;
            let q = crate::model::landed_pose(model, &spreader, &vertices, &targets, &w0, &null_options)?.positions;
            let landing = vertices
                .iter()
                .zip(&drags)
                .map(|(&v, &d)| if d > 0.0 { crate::mesh::dist(p[v], t[v]) / d } else { 0.0 })
                .sum::<f64>()
                / pins as f64;
            let motion: Vec<f64> = p.iter().zip(&p0).map(|(a, b)| crate::mesh::dist(*a, *b)).collect();
            let max_drag = drags.iter().cloned().fold(0.0, f64::max);
            let largest = |s: &[Vec3]| s.iter().zip(&p0).map(|(a, b)| crate::mesh::dist(*a, *b)).fold(0.0, f64::max);
            let share = |m: &dyn Fn(usize) -> f64| (0..n).filter(|&v| m(v) > 0.5 * mean_drag).count() as f64 / n as f64;
            let against = |s: &[Vec3]| erms(std::slice::from_ref(&t), &[s.to_vec()], alignment);
            let (posed_erms, null_erms) = (against(&p)?, against(&q)?);
            let measures = DragMeasures {
                landing_percent: 100.0 * landing,
                max_motion_ratio: largest(&p) / max_drag,
                moved_share: share(&|v| motion[v]),
                frame_moved_share: share(&|v| crate::mesh::dist(t[v], p0[v])),
                posed_erms,
                neutral_erms: against(&p0)?,
                null_erms,
                null_ratio: if null_erms > 0.0 { posed_erms / null_erms } else { 1.0 },
                null_max_motion_ratio: largest(&q) / max_drag,
                seconds,
            };
            rows.push(DragResult { pins, frame: f, vertices, measures });
        }
        let measures: Vec<DragMeasures> = rows.iter().map(|r| r.measures).collect();
        let share = |beats: fn(&DragMeasures) -> bool| {
            measures.iter().filter(|m| beats(m)).count() as f64 / measures.len() as f64
        };
        let ratios: Vec<f64> = measures.iter().map(|m| m.max_motion_ratio).collect();
        summaries.push(DragSummary {
            pins,
            drags: rows.len(),
            medians: DragMeasures::medians(&measures),
            improved_share: share(|m| m.posed_erms < (1.0 - GAIN_TOLERANCE) * m.neutral_erms),
            beats_null_share: share(|m| m.posed_erms < (1.0 - GAIN_TOLERANCE) * m.null_erms),
            max_motion_p90: quantile(&ratios, 0.9),
            max_motion_max: quantile(&ratios, 1.0),
        });
        all.extend(rows);
    }
    Ok((all, summaries))
}
