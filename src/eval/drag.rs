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

#[cfg(test)]
mod tests {
    //! The benchmark on a scripted model (no weights; its neutral shape is its rest mesh and its
    //! pose is a given rule), on 2 × 2 grids, so that every measure follows by hand from the
    //! module docs.

    use std::path::Path;

    use super::*;
    use crate::config::MethodKind;
    use crate::mesh::TriMesh;
    use crate::model::{Component, PointFit, PoseResult};
    use crate::representation::RepresentationKind;

    /// The scripted pose: (pinned vertices, their targets) → the posed positions.
    type PoseRule = Box<dyn Fn(&[usize], &[Vec3]) -> Vec<Vec3>>;

    /// A model without weights: every weight vector decodes to the rest positions (so the neutral
    /// shape P0 and the frozen null's start are the rest mesh) and a pose is `rule`'s.
    struct Scripted {
        rest: TriMesh,
        alignment: Alignment,
        rule: PoseRule,
    }

    impl Model for Scripted {
        fn kind(&self) -> MethodKind {
            MethodKind::Pca
        }
        fn representation(&self) -> RepresentationKind {
            RepresentationKind::Displacement
        }
        fn rest(&self) -> TriMesh {
            self.rest.clone()
        }
        fn n_components(&self) -> usize {
            0
        }
        fn components(&self) -> Result<Vec<Component>> {
            Ok(Vec::new())
        }
        fn element_norms(&self) -> (Vec<Vec<f64>>, &[Vec<usize>]) {
            (Vec::new(), &[])
        }
        fn alignment(&self) -> Alignment {
            self.alignment
        }
        fn train_frames(&self) -> &[String] {
            &[]
        }
        fn train_weights(&self) -> Option<Vec<Vec<f64>>> {
            None
        }
        fn decode(&self, weights: &[Vec<f64>]) -> Result<Vec<Vec<Vec3>>> {
            Ok(weights.iter().map(|_| self.rest.positions.clone()).collect())
        }
        fn encode(&self, frames: &MeshSequence) -> Result<Vec<Vec<f64>>> {
            Ok(vec![Vec::new(); frames.n_frames()])
        }
        fn start_weights(&self, _from: Option<&[Vec3]>) -> Result<Vec<f64>> {
            Ok(Vec::new())
        }
        fn start_description(&self) -> &'static str {
            "the rest shape"
        }
        fn pose(&self, vertices: &[usize], targets: &[Vec3], w0: &[f64], _options: &PoseOptions) -> Result<PoseResult> {
            Ok(PoseResult {
                start: self.rest.positions.clone(),
                positions: (self.rule)(vertices, targets),
                weights: w0.to_vec(),
            })
        }
        fn point_fit<'a>(&'a self, _vertices: &[usize], _gamma: f64) -> Result<Option<Box<dyn PointFit + 'a>>> {
            Ok(None)
        }
        fn save(&self, _dir: &Path) -> Result<()> {
            Ok(())
        }
        fn write_views(&self, _dir: &Path) -> Result<()> {
            Ok(())
        }
        fn write_components(&self, _dir: &Path) -> Result<()> {
            Ok(())
        }
    }

    /// The 2 × 2 grid `side` apart in the z = 0 plane (vertices (0, 0), (s, 0), (0, s), (s, s);
    /// two triangles).
    fn square(side: f64) -> TriMesh {
        TriMesh {
            positions: vec![[0.0, 0.0, 0.0], [side, 0.0, 0.0], [0.0, side, 0.0], [side, side, 0.0]],
            faces: vec![[0, 1, 3], [0, 3, 2]],
        }
    }

    /// `p` with vertex v moved by `dx[v]` along x.
    fn shifted(p: &[Vec3], dx: &[f64]) -> Vec<Vec3> {
        p.iter().zip(dx).map(|(q, d)| [q[0] + d, q[1], q[2]]).collect()
    }

    /// The rule that moves each pinned vertex the fraction `share(drag)` of the way from its rest
    /// position to its target (the drag: the distance between the two) and leaves every other
    /// vertex at rest.
    fn part_way(rest: &[Vec3], share: fn(f64) -> f64) -> PoseRule {
        let rest = rest.to_vec();
        Box::new(move |vertices: &[usize], targets: &[Vec3]| {
            let mut p = rest.clone();
            for (&v, t) in vertices.iter().zip(targets) {
                let s = share(crate::mesh::dist(*t, rest[v]));
                p[v] = std::array::from_fn(|k| rest[v][k] + s * (t[k] - rest[v][k]));
            }
            p
        })
    }

    fn model(rest: TriMesh, alignment: Alignment, rule: fn(&[Vec3]) -> PoseRule) -> Scripted {
        let rule = rule(&rest.positions);
        Scripted { rest, alignment, rule }
    }

    fn halfway(rest: &[Vec3]) -> PoseRule {
        part_way(rest, |_| 0.5)
    }

    fn frames(m: &Scripted, f: Vec<Vec<Vec3>>) -> MeshSequence {
        MeshSequence { faces: m.rest.faces.clone(), names: (0..f.len()).map(|i| format!("f{i}")).collect(), frames: f }
    }

    /// Pose options with landing radius `spread` (0: the model's shape only) and no reach.
    fn config(drags: usize, pins: Vec<usize>, seed: u64, spread: f64) -> DragBenchConfig {
        DragBenchConfig { drags, pins, seed, options: PoseOptions { spread, reach: 0.0, ..PoseOptions::default() } }
    }

    /// The benchmark's first `attempts` draws with `seed` as (frame, sorted pins): a frame, then
    /// the pins, as [`drag_bench`] draws them.
    fn draws(seed: u64, n_frames: usize, n: usize, pins: usize, attempts: usize) -> Vec<(usize, Vec<usize>)> {
        let mut rng = Rng::new(seed);
        (0..attempts)
            .map(|_| {
                let f = rng.below(n_frames);
                let mut v = rng.sample_distinct(n, pins);
                v.sort_unstable();
                (f, v)
            })
            .collect()
    }

    fn near(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs().max(1.0)
    }

    #[test]
    fn quantile_interpolates_between_order_statistics() {
        // Sorted 0, 10, 20: the q quantile sits at q × 2 in the order.
        let v = [20.0, 0.0, 10.0];
        for (q, want) in [(0.0, 0.0), (0.25, 5.0), (0.5, 10.0), (0.9, 18.0), (1.0, 20.0), (-1.0, 0.0), (1.5, 20.0)] {
            assert!(near(quantile(&v, q), want), "q {q}: {} (want {want})", quantile(&v, q));
        }
        assert!(near(quantile(&[4.0, 1.0, 3.0, 2.0], 0.5), 2.5));
        assert_eq!(quantile(&[7.0], 0.9), 7.0);
    }

    /// The frame moves the four vertices 0, 0.5, 2 and 5.5 along x (mean drag 2, largest 5.5);
    /// the model moves each pin half way, so each pin misses by half its drag and vertex v moves
    /// 0, 0.25, 1, 2.75.
    #[test]
    fn measures_of_a_hand_computed_drag() {
        let m = model(square(10.0), Alignment::None, halfway);
        let p0 = m.rest.positions.clone();
        let seq = frames(&m, vec![shifted(&p0, &[0.0, 0.5, 2.0, 5.5])]);
        let (rows, summaries) = drag_bench(&m, &seq, &config(3, vec![1, 4], 0, 0.0)).unwrap();
        assert_eq!(rows.len(), 6);
        assert_eq!(summaries.iter().map(|s| (s.pins, s.drags)).collect::<Vec<_>>(), [(1, 3), (4, 3)]);
        // One pin: vertex 0 does not move in the frame, so it is never kept; the pin misses by half.
        for r in &rows[..3] {
            assert_eq!((r.pins, r.frame, r.vertices.len()), (1, 0, 1));
            assert_ne!(r.vertices[0], 0, "a pin that does not move is redrawn");
            assert!(near(r.measures.landing_percent, 50.0), "{r:?}");
            assert!(near(r.measures.max_motion_ratio, 0.5), "{r:?}");
        }
        let posed = 1000.0 * (8.625f64 / 12.0).sqrt(); // misses² 0 + 0.0625 + 1 + 7.5625
        let neutral = 1000.0 * (34.5f64 / 12.0).sqrt(); // drags² 0 + 0.25 + 4 + 30.25
        for r in &rows[3..] {
            assert_eq!((r.pins, r.frame, r.vertices.as_slice()), (4, 0, &[0, 1, 2, 3][..]));
            let d = r.measures;
            // Landing: the still pin counts 0, the others ½ each: (0 + 3 × ½) / 4.
            assert_eq!(d.landing_percent, 37.5, "{d:?}");
            assert_eq!(d.max_motion_ratio, 2.75 / 5.5, "{d:?}");
            // Half the mean drag is 1: only vertex 3 moved more (vertex 2 moved exactly 1); the
            // frame moved vertices 2 and 3 more.
            assert_eq!(d.moved_share, 0.25, "{d:?}");
            assert_eq!(d.frame_moved_share, 0.5, "{d:?}");
            assert!(near(d.posed_erms, posed) && near(d.neutral_erms, neutral), "{d:?}");
            // Frozen with no landing correction the null is the neutral shape.
            assert_eq!(d.null_erms, d.neutral_erms, "{d:?}");
            assert_eq!(d.null_max_motion_ratio, 0.0, "{d:?}");
            assert!(near(d.null_ratio, 0.5), "{d:?}");
            assert!(d.seconds >= 0.0 && d.seconds.is_finite(), "{d:?}");
        }
        let s = &summaries[1];
        let (med, one) = (s.medians, rows[3].measures);
        let fields = |d: &DragMeasures| {
            [
                d.landing_percent,
                d.max_motion_ratio,
                d.moved_share,
                d.frame_moved_share,
                d.posed_erms,
                d.neutral_erms,
                d.null_erms,
                d.null_ratio,
                d.null_max_motion_ratio,
            ]
        };
        // Every drag alike: the medians are its measures.
        assert_eq!(fields(&med), fields(&one), "{s:?}");
        assert_eq!((s.improved_share, s.beats_null_share), (1.0, 1.0), "{s:?}");
        assert_eq!((s.max_motion_p90, s.max_motion_max), (0.5, 0.5), "{s:?}");
    }

    /// The frame: the neutral shape moved by 0, 0, −2, 2 along x, then all of it by 10. A model
    /// measured centroid-aligned is dragged towards the frame translated onto its centroid (drags
    /// 0, 0, 2, 2: half the mean is 0.5, two vertices move more); one measured as it stands
    /// towards the frame itself (drags 10, 10, 8, 12: all four move more than 5).
    #[test]
    fn centroid_models_are_dragged_towards_the_aligned_frame() {
        for (alignment, share) in [(Alignment::Centroid, 0.5), (Alignment::None, 1.0)] {
            let m = model(square(10.0), alignment, halfway);
            let seq = frames(&m, vec![shifted(&m.rest.positions, &[10.0, 10.0, 8.0, 12.0])]);
            let (rows, _) = drag_bench(&m, &seq, &config(1, vec![4], 0, 0.0)).unwrap();
            let d = rows[0].measures;
            assert_eq!(d.frame_moved_share, share, "{alignment}: {d:?}");
            // The model moves the pins half way: the largest motion is half the largest drag.
            assert!(near(d.max_motion_ratio, 0.5), "{alignment}: {d:?}");
            let neutral = match alignment {
                Alignment::Centroid => 1000.0 * (8.0f64 / 12.0).sqrt(),
                Alignment::None => 1000.0 * (408.0f64 / 12.0).sqrt(),
            };
            assert!(near(d.neutral_erms, neutral), "{alignment}: {d:?}");
        }
    }

    #[test]
    fn refuses_frames_and_counts_it_cannot_run() {
        let m = model(square(10.0), Alignment::None, halfway);
        let t = shifted(&m.rest.positions, &[1.0; 4]);
        let ok = frames(&m, vec![t.clone()]);
        let run =
            |seq: &MeshSequence, drags: usize, pins: Vec<usize>| drag_bench(&m, seq, &config(drags, pins, 0, 0.0));
        assert!(run(&ok, 1, vec![1, 4]).is_ok());
        // Frames of 3 vertices (the model has 4), and no frames.
        for seq in [frames(&m, vec![t[..3].to_vec()]), frames(&m, Vec::new())] {
            let e = run(&seq, 1, vec![4]).unwrap_err().to_string();
            assert!(e.contains("the model has 4 vertices"), "{e}");
        }
        // No drag, no pin count, a pin count of 0 or above the vertex count.
        for (drags, pins) in [(0, vec![1]), (1, vec![]), (1, vec![0]), (1, vec![5]), (1, vec![1, 5]), (1, vec![0, 1])] {
            let e = run(&ok, drags, pins.clone()).unwrap_err().to_string();
            assert!(e.contains("pin counts from 1 to 4"), "{drags} drags of {pins:?}: {e}");
        }
    }

    /// The diagonal is 14.1, so a drag of 10⁻⁶ (below 10⁻⁶ × the diagonal) says nothing: frame 0
    /// moves every vertex that much and is never kept; frame 1 moves them 1.
    #[test]
    fn drags_below_a_millionth_of_the_diagonal_are_redrawn() {
        let m = model(square(10.0), Alignment::None, halfway);
        let p0 = m.rest.positions.clone();
        let seq = frames(&m, vec![shifted(&p0, &[1e-6; 4]), shifted(&p0, &[1.0; 4])]);
        let (rows, _) = drag_bench(&m, &seq, &config(8, vec![1], 0, 0.0)).unwrap();
        assert!(rows.iter().all(|r| r.frame == 1), "{rows:?}");
        // The draws did pick frame 0 on the way.
        assert!(draws(0, 2, 4, 1, 8).iter().any(|(f, _)| *f == 0));
    }

    /// Twenty frames of which only frame 0 moves (by 1 at every vertex): a draw is kept when it
    /// picks frame 0. Two drags may take 20 × 2 = 40 draws: a seed whose second kept draw is the
    /// 40th runs, one with fewer than two kept among the first 40 is refused.
    #[test]
    fn gives_up_after_twenty_draws_per_drag() {
        let m = model(square(10.0), Alignment::None, halfway);
        let p0 = m.rest.positions.clone();
        let mut f = vec![p0.clone(); 20];
        f[0] = shifted(&p0, &[1.0; 4]);
        let seq = frames(&m, f);
        // The 1-based draws that pick frame 0 among the first 60.
        let kept = |seed: u64| -> Vec<usize> {
            draws(seed, 20, 4, 1, 60).iter().enumerate().filter(|(_, (f, _))| *f == 0).map(|(i, _)| i + 1).collect()
        };
        let last = (0..100_000).find(|&s| kept(s).get(1) == Some(&40)).unwrap();
        let short = (0..100_000).find(|&s| kept(s).iter().filter(|&&a| a <= 40).count() < 2).unwrap();
        let (rows, _) = drag_bench(&m, &seq, &config(2, vec![1], last, 0.0)).unwrap();
        // The rows are the kept draws (the same draws as the benchmark's).
        let want: Vec<(usize, Vec<usize>)> = draws(last, 20, 4, 1, 40).into_iter().filter(|(f, _)| *f == 0).collect();
        assert_eq!(rows.iter().map(|r| (r.frame, r.vertices.clone())).collect::<Vec<_>>(), want);
        let e = drag_bench(&m, &seq, &config(2, vec![1], short, 0.0)).unwrap_err().to_string();
        assert!(e.contains("do not move the drawn pins"), "{e}");
    }

    /// Two frames moving every vertex 1 and 2 along x; the model leaves 98.5 % of the error of a
    /// drag of 1 and 99.5 % of a drag of 2 (all four pinned), so posed ÷ neutral is 0.985 or
    /// 0.995, and so is posed ÷ null (the null is the neutral shape without a landing radius): only
    /// frame 0's drags improve on either by more than [`GAIN_TOLERANCE`].
    #[test]
    fn a_gain_within_the_tolerance_is_no_gain() {
        let m = model(square(10.0), Alignment::None, |rest| part_way(rest, |d| if d < 1.5 { 0.015 } else { 0.005 }));
        let p0 = m.rest.positions.clone();
        let seq = frames(&m, vec![shifted(&p0, &[1.0; 4]), shifted(&p0, &[2.0; 4])]);
        let (rows, summaries) = drag_bench(&m, &seq, &config(5, vec![4], 0, 0.0)).unwrap();
        let first = rows.iter().filter(|r| r.frame == 0).count();
        assert!(first > 0 && first < 5, "both frames drawn: {rows:?}");
        for r in &rows {
            let want = [0.985, 0.995][r.frame];
            let d = r.measures;
            assert!((d.posed_erms / d.neutral_erms - want).abs() < 1e-9, "{r:?}");
            assert!((d.null_ratio - want).abs() < 1e-9, "{r:?}");
        }
        let s = &summaries[0];
        assert_eq!((s.improved_share, s.beats_null_share), (first as f64 / 5.0, first as f64 / 5.0), "{s:?}");
    }

    /// A square 10⁻¹⁶⁰ across and a drag of 2 × 10⁻¹⁶² at vertex 0 (the model does not move): the
    /// drag is positive, but its square spread over the 12 coordinates underflows, so the
    /// posed, neutral and null Erms are all exactly 0. Equal Erms is no gain ("below" is strict)
    /// and posed ÷ null is 1, not 0 ÷ 0.
    #[test]
    fn equal_erms_is_no_gain_and_a_zero_null_gives_ratio_one() {
        let m = model(square(1e-160), Alignment::None, |rest| part_way(rest, |_| 0.0));
        let p0 = m.rest.positions.clone();
        let seq = frames(&m, vec![shifted(&p0, &[2e-162, 0.0, 0.0, 0.0])]);
        let (rows, summaries) = drag_bench(&m, &seq, &config(2, vec![1], 0, 0.0)).unwrap();
        for r in &rows {
            let d = r.measures;
            assert_eq!(r.vertices, [0], "{r:?}");
            assert_eq!((d.posed_erms, d.neutral_erms, d.null_erms), (0.0, 0.0, 0.0), "{r:?}");
            assert_eq!(d.landing_percent, 100.0, "{r:?}");
            assert_eq!(d.null_ratio, 1.0, "{r:?}");
        }
        assert_eq!((summaries[0].improved_share, summaries[0].beats_null_share), (0.0, 0.0), "{:?}", summaries[0]);
    }

    /// The frame moves vertex 0 by 2 along x; landing radius 5 % of the diagonal (0.71, widened
    /// to 3 × a pin's residual, at most 6: below the edges' 10), so the landing correction moves
    /// the pin alone. The null (the correction alone, from the neutral shape) moves the pin by its
    /// drag and nothing else: its max motion ÷ drag is 1; the posed shape (the model half way, the
    /// correction the rest) lands as well.
    #[test]
    fn the_null_moves_the_pin_by_its_drag() {
        let m = model(square(10.0), Alignment::None, halfway);
        let p0 = m.rest.positions.clone();
        let seq = frames(&m, vec![shifted(&p0, &[2.0, 0.0, 0.0, 0.0])]);
        let (rows, _) = drag_bench(&m, &seq, &config(2, vec![1], 0, 0.05)).unwrap();
        for r in &rows {
            let d = r.measures;
            assert_eq!(r.vertices, [0], "{r:?}");
            assert!((d.null_max_motion_ratio - 1.0).abs() < 1e-6, "{r:?}");
            assert!((d.max_motion_ratio - 1.0).abs() < 1e-6, "{r:?}");
            assert!(d.landing_percent < 1e-4, "{r:?}");
            assert!(d.null_erms < 1e-3 && d.posed_erms < 1e-3, "{r:?}");
        }
    }
}
