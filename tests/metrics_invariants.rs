//! Invariants of the metrics (issue 7 "Metric tests"): Erms and STED vanish for identical
//! sequences; STED is invariant to a rigid motion of a whole sequence while raw Erms is not;
//! STED's scale behaviour; and a tiny case computed by hand.

use meshdeco::mesh::Vec3;
use meshdeco::mesh::primitives::{cylinder, icosphere};
use meshdeco::metrics::{Alignment, Erms, FrameOrder, Sted, StedParams, edge_length_distortion, erms};

/// A non-rigidly deforming, travelling sphere: F frames of a subdivided icosphere.
fn synthetic_truth(frames: usize) -> (Vec<[usize; 3]>, Vec<Vec<Vec3>>) {
    let m = icosphere(2);
    let seq = (0..frames)
        .map(|f| {
            let t = f as f64 * 0.3;
            m.positions
                .iter()
                .map(|p| {
                    let bump = 1.0 + 0.15 * (3.0 * p[0] + t).sin() * p[2];
                    [bump * p[0] + 0.2 * t, bump * p[1], (1.0 + 0.1 * t.sin()) * p[2]]
                })
                .collect()
        })
        .collect();
    (m.faces, seq)
}

/// A deterministic, non-rigid perturbation of `truth` (a stand-in for a reconstruction).
fn perturbed(truth: &[Vec<Vec3>]) -> Vec<Vec<Vec3>> {
    truth
        .iter()
        .enumerate()
        .map(|(f, fr)| {
            fr.iter()
                .enumerate()
                .map(|(v, p)| {
                    let s = ((v * 7 + f * 13) % 11) as f64 / 11.0 - 0.5;
                    [p[0] + 0.01 * s, p[1] - 0.008 * s * s, p[2] + 0.005 * (v as f64).sin()]
                })
                .collect()
        })
        .collect()
}

/// Rotation about the unit axis `a` by `angle` (Rodrigues), then translation `t`.
fn rigid(a: Vec3, angle: f64, t: Vec3) -> impl Fn(Vec3) -> Vec3 {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let k = [a[0] / n, a[1] / n, a[2] / n];
    let (s, c) = angle.sin_cos();
    move |p: Vec3| {
        let kxp = [k[1] * p[2] - k[2] * p[1], k[2] * p[0] - k[0] * p[2], k[0] * p[1] - k[1] * p[0]];
        let kdp = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
        std::array::from_fn(|i| p[i] * c + kxp[i] * s + k[i] * kdp * (1.0 - c) + t[i])
    }
}

fn map_seq(seq: &[Vec<Vec3>], g: impl Fn(usize, Vec3) -> Vec3) -> Vec<Vec<Vec3>> {
    seq.iter().enumerate().map(|(f, fr)| fr.iter().map(|&p| g(f, p)).collect()).collect()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

#[test]
fn identical_sequences_score_zero() {
    let (faces, truth) = synthetic_truth(6);
    for a in [Alignment::None, Alignment::Centroid] {
        assert_eq!(erms(&truth, &truth, a).unwrap(), 0.0);
    }
    for rings in [1, 2, 3] {
        let s = Sted::new(truth[0].len(), &faces, StedParams { rings, ..Default::default() }).unwrap();
        let r = s.evaluate(&truth, &truth, FrameOrder::Sequence).unwrap();
        assert_eq!(r.spatial, 0.0);
        assert_eq!(r.temporal, Some(0.0));
        assert_eq!(r.combined, 0.0);
    }
    // And a perturbed result is measured as non-zero, so the zeros above are not vacuous.
    let s = Sted::new(truth[0].len(), &faces, StedParams::default()).unwrap();
    let r = s.evaluate(&truth, &perturbed(&truth), FrameOrder::Sequence).unwrap();
    assert!(r.spatial > 1e-4 && r.temporal.unwrap() > 1e-5, "{r:?}");
}

#[test]
fn sted_invariant_to_rigid_motion_erms_not() {
    let (faces, truth) = synthetic_truth(6);
    let result = perturbed(&truth);
    let g = rigid([0.3, -1.0, 0.5], 1.1, [2.0, -0.5, 3.0]);
    let moved = map_seq(&result, |_, p| g(p));
    let s = Sted::new(truth[0].len(), &faces, StedParams::default()).unwrap();
    let base = s.evaluate(&truth, &result, FrameOrder::Sequence).unwrap();
    let after = s.evaluate(&truth, &moved, FrameOrder::Sequence).unwrap();
    assert!(close(base.spatial, after.spatial, 1e-10), "{base:?} vs {after:?}");
    assert!(close(base.temporal.unwrap(), after.temporal.unwrap(), 1e-10), "{base:?} vs {after:?}");
    assert!(close(base.combined, after.combined, 1e-10));
    // Moving both sequences by the same rigid motion changes nothing either.
    let both = s.evaluate(&map_seq(&truth, |_, p| g(p)), &moved, FrameOrder::Sequence).unwrap();
    assert!(close(base.combined, both.combined, 1e-10));
    // A rigidly moved copy of the truth has STED 0 but a large raw Erms.
    let copy = map_seq(&truth, |_, p| g(p));
    let r = s.evaluate(&truth, &copy, FrameOrder::Sequence).unwrap();
    assert!(r.combined < 1e-12, "{r:?}");
    let e_raw = erms(&truth, &copy, Alignment::None).unwrap();
    assert!(e_raw > 1000.0, "raw Erms {e_raw} should see a motion of several units");
    let e0 = erms(&truth, &result, Alignment::None).unwrap();
    let e1 = erms(&truth, &moved, Alignment::None).unwrap();
    assert!(e1 > 10.0 * e0, "raw Erms {e0} → {e1} after the rigid motion");
}

#[test]
fn per_frame_rigid_motion_keeps_spatial_changes_temporal() {
    let (faces, truth) = synthetic_truth(5);
    let result = perturbed(&truth);
    // A different rigid motion in every frame: edge lengths per frame are unchanged.
    let moved = map_seq(&result, |f, p| rigid([1.0, 0.2, 0.1], 0.4 * f as f64, [0.1 * f as f64, 0.0, 0.0])(p));
    let s = Sted::new(truth[0].len(), &faces, StedParams::default()).unwrap();
    let a = s.evaluate(&truth, &result, FrameOrder::Sequence).unwrap();
    let b = s.evaluate(&truth, &moved, FrameOrder::Sequence).unwrap();
    assert!(close(a.spatial, b.spatial, 1e-10));
    assert!(b.temporal.unwrap() > 2.0 * a.temporal.unwrap(), "{a:?} vs {b:?}");
}

#[test]
fn sted_scale_behaviour() {
    let (faces, truth) = synthetic_truth(5);
    let result = perturbed(&truth);
    let s = Sted::new(truth[0].len(), &faces, StedParams::default()).unwrap();
    let base = s.evaluate(&truth, &result, FrameOrder::Sequence).unwrap();
    // 1. Scaling both sequences by k leaves every part unchanged (δ scales with the truth's
    //    mean edge length), while Erms scales by k.
    for k in [0.01, 3.0, 250.0] {
        let sc = |seq: &[Vec<Vec3>]| map_seq(seq, |_, p| [k * p[0], k * p[1], k * p[2]]);
        let r = s.evaluate(&sc(&truth), &sc(&result), FrameOrder::Sequence).unwrap();
        assert!(
            close(r.spatial, base.spatial, 1e-9) && close(r.temporal.unwrap(), base.temporal.unwrap(), 1e-9),
            "k {k}: {r:?}"
        );
        let e = erms(&sc(&truth), &sc(&result), Alignment::None).unwrap();
        assert!(close(e, k * erms(&truth, &result, Alignment::None).unwrap(), 1e-9));
    }
    // 2. A result that is the truth scaled by k about the origin: every relative edge change is
    //    k − 1, so the spatial part (a local deviation) is 0; the temporal part is not, and grows
    //    with |k − 1|.
    let mut last = 0.0;
    for k in [1.05, 1.2, 1.5] {
        let r =
            s.evaluate(&truth, &map_seq(&truth, |_, p| [k * p[0], k * p[1], k * p[2]]), FrameOrder::Sequence).unwrap();
        assert!(r.spatial < 1e-12, "k {k}: {r:?}");
        let t = r.temporal.unwrap();
        assert!(t > last, "k {k}: temporal {t} should grow past {last}");
        last = t;
    }
}

#[test]
fn unordered_collections_report_spatial_only() {
    let (faces, truth) = synthetic_truth(4);
    let result = perturbed(&truth);
    let s = Sted::new(truth[0].len(), &faces, StedParams::default()).unwrap();
    let r = s.evaluate(&truth, &result, FrameOrder::Unordered).unwrap();
    assert_eq!(r.temporal, None);
    assert_eq!(r.combined, r.spatial);
    // The spatial part does not depend on the frame order.
    let perm = [2, 0, 3, 1];
    let pt: Vec<_> = perm.iter().map(|&i| truth[i].clone()).collect();
    let pr: Vec<_> = perm.iter().map(|&i| result[i].clone()).collect();
    assert!(close(s.spatial(&pt, &pr).unwrap(), r.spatial, 1e-12));
    // It is the mean of the per-frame spatial parts.
    let mean = (0..4).map(|f| s.spatial_frame(&truth[f], &result[f]).unwrap()).sum::<f64>() / 4.0;
    assert!(close(mean, r.spatial, 1e-12));
}

/// Two equilateral triangles with unit edges sharing edge (0, 1) (faces [0,1,2], [1,0,3]),
/// 2 frames. Edges (sorted): 01, 02, 03, 12, 13, all of length 1 in the truth.
///
/// Truth: frame 0 = the flat rhombus 0 = (0,0,0), 1 = (1,0,0), 2 = (½, √3/2, 0),
/// 3 = (½, −√3/2, 0); frame 1 = frame 0 moved by (0, 0, 1).
/// Result: frame 0 = truth frame 0 with vertex 2 lifted to z = ¾, so edges 02 and 12 have length
/// sqrt(1 + 9/16) = 5/4 (relative change ¼); frame 1 = truth frame 1.
///
/// Spatial part, rings = 1 (unit weights):
///   frame 0: v0 sees (0, ¼, 0): mean 1/12, variance (2·(1/12)² + (1/6)²)/3 = 1/72 → 1/√72;
///            v1 the same; v2 sees (¼, ¼) → 0; v3 sees (0, 0) → 0. Frame mean 1/(2√72).
///   frame 1: identical → 0.  STED_s = 1/(4√72) = 0.0294628.
/// Spatial part, rings = 2: every neighbourhood is all 5 edges (0, ¼, 0, ¼, 0): mean 0.1,
///   variance (3·0.01 + 2·0.0225)/5 = 0.015 → √0.015 in frame 0, 0 in frame 1: STED_s = √0.015/2.
/// Temporal part: mean truth edge length 1, δ = 1. Truth: every vertex moves by 1, t = √2.
///   Result: v2 moves by ¼ (z ¾ → 1), t' = sqrt(1/16 + 1) = √17/4; the others as the truth.
///   |√17/4 − √2|/√2 = 1 − √34/8 for v2, 0 for the others: STED_t = (1 − √34/8)/4 = 0.0677828.
/// Combined with c = ½: sqrt(STED_s² + ¼·STED_t²).
/// Erms (raw): one coordinate off by ¾ among 3·4·2 = 24: 1000·sqrt((9/16)/24) = 153.0931.
#[test]
fn hand_computed_two_triangles_two_frames() {
    let h = 3f64.sqrt() / 2.0;
    let faces = vec![[0, 1, 2], [1, 0, 3]];
    let f0 = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, h, 0.0], [0.5, -h, 0.0]];
    let f1: Vec<Vec3> = f0.iter().map(|p| [p[0], p[1], p[2] + 1.0]).collect();
    let truth = vec![f0.clone(), f1.clone()];
    let mut r0 = f0.clone();
    r0[2][2] = 0.75;
    let result = vec![r0, f1];

    let s1 = Sted::new(4, &faces, StedParams::default()).unwrap();
    let r = s1.evaluate(&truth, &result, FrameOrder::Sequence).unwrap();
    let want_s = 1.0 / (4.0 * 72f64.sqrt());
    let want_t = (1.0 - 34f64.sqrt() / 8.0) / 4.0;
    assert!((r.spatial - want_s).abs() < 1e-12, "{} vs {want_s}", r.spatial);
    assert!((r.spatial - 0.0294628).abs() < 1e-7);
    assert!((r.temporal.unwrap() - want_t).abs() < 1e-12, "{:?} vs {want_t}", r.temporal);
    assert!((r.temporal.unwrap() - 0.0677828).abs() < 1e-7);
    assert!((r.combined - (want_s * want_s + 0.25 * want_t * want_t).sqrt()).abs() < 1e-12);

    let s2 = Sted::new(4, &faces, StedParams { rings: 2, ..Default::default() }).unwrap();
    assert!((s2.spatial(&truth, &result).unwrap() - 0.015f64.sqrt() / 2.0).abs() < 1e-12);

    // c only weights the temporal part.
    let s0 = Sted::new(4, &faces, StedParams { c: 0.0, ..Default::default() }).unwrap();
    assert!((s0.evaluate(&truth, &result, FrameOrder::Sequence).unwrap().combined - want_s).abs() < 1e-12);

    let e = Erms::measure(&truth, &result, Alignment::None).unwrap();
    assert!((e.value - 1000.0 * (9.0f64 / 16.0 / 24.0).sqrt()).abs() < 1e-9 && (e.value - 153.0931).abs() < 1e-4);
    assert_eq!(e.alignment, Alignment::None);
}

#[test]
fn edge_distortion_of_rigid_and_stretched_shapes() {
    let rest = cylinder(16, 6, 1.0, 3.0);
    // A rigid motion of the rest mesh is undistorted.
    let g = rigid([0.0, 1.0, 1.0], 0.7, [5.0, 0.0, -1.0]);
    let moved: Vec<Vec3> = rest.positions.iter().map(|&p| g(p)).collect();
    let d = edge_length_distortion(&rest, &moved, StedParams::default()).unwrap();
    assert!(d.mean_relative < 1e-12 && d.max_relative < 1e-12 && d.spatial_sted < 1e-12, "{d:?}");
    // Stretching one vertex changes only its incident edges: a positive, local distortion that
    // grows with the stretch.
    let mut last = 0.0;
    for amount in [0.1, 0.3, 0.9] {
        let mut s = rest.positions.clone();
        s[20] = [s[20][0] * (1.0 + amount), s[20][1] * (1.0 + amount), s[20][2]];
        let d = edge_length_distortion(&rest, &s, StedParams::default()).unwrap();
        assert!(d.mean_relative > last && d.spatial_sted > 0.0, "{d:?}");
        last = d.mean_relative;
    }
}
