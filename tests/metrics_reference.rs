//! Every metric against a brute-force reference written from its definition (issue 33, mutation
//! testing of `src/metrics/`): STED's neighbourhoods, spatial, temporal and combined parts, Erms
//! with and without centroid alignment, support regions and edge-length distortion, on a small
//! irregular mesh with an isolated vertex, a zero-length ground-truth edge, several ring sizes and
//! parameters away from their defaults (so δ ≠ δ², c ≠ 1, weights ≠ 1). The references share no
//! code with `src/metrics/`: adjacency from the faces by sets, neighbourhoods by a plain BFS, sums
//! in the order of the formulas.

use std::collections::{BTreeSet, VecDeque};

use meshdeco::mesh::primitives::grid;
use meshdeco::mesh::{TriMesh, Vec3};
use meshdeco::metrics::erms::{alignment_shift, erms_from_squared_error, vertex_squared_error};
use meshdeco::metrics::locality::support_regions;
use meshdeco::metrics::{
    Alignment, EdgeDistortionMeter, Erms, FrameOrder, Sted, StedParams, edge_length_distortion, erms,
    frame_squared_error, sted,
};

/// A deterministic generator in [−1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

/// A 4 × 3 vertex grid ([`grid`]: 12 vertices, 12 triangles, alternating diagonals so that
/// vertex degrees differ), irregularly jittered, plus vertex 12, which no face uses (an empty
/// neighbourhood).
fn mesh() -> (usize, Vec<[usize; 3]>, Vec<Vec3>) {
    let TriMesh { positions, faces } = grid(3, 2, 3.0);
    let mut g = Lcg(7);
    let mut rest: Vec<Vec3> =
        positions.iter().map(|p| [p[0] + 0.2 * g.next(), p[1] + 0.2 * g.next(), 0.3 * g.next()]).collect();
    rest.push([9.0, 9.0, 9.0]);
    (rest.len(), faces, rest)
}

/// F frames: the rest shape bent and moved a little more each frame, each vertex jittered.
fn sequence(rest: &[Vec3], frames: usize, seed: u64, jitter: f64) -> Vec<Vec<Vec3>> {
    let mut g = Lcg(seed);
    (0..frames)
        .map(|f| {
            let t = f as f64;
            rest.iter()
                .map(|p| {
                    [
                        p[0] + 0.3 * t + jitter * g.next(),
                        p[1] + 0.1 * t * p[0] + jitter * g.next(),
                        p[2] + 0.05 * t * t * p[1] + jitter * g.next(),
                    ]
                })
                .collect()
        })
        .collect()
}

fn dist(a: Vec3, b: Vec3) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn unique_edges(faces: &[[usize; 3]]) -> BTreeSet<(usize, usize)> {
    let mut e = BTreeSet::new();
    for f in faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            e.insert((a.min(b), a.max(b)));
        }
    }
    e
}

/// Edges with at least one endpoint at topological distance < rings from v.
fn reference_neighbourhood(
    n: usize,
    edges: &BTreeSet<(usize, usize)>,
    v: usize,
    rings: usize,
) -> BTreeSet<(usize, usize)> {
    let mut depth = vec![usize::MAX; n];
    depth[v] = 0;
    let mut q = VecDeque::from([v]);
    while let Some(u) = q.pop_front() {
        for &(a, b) in edges {
            let w = if a == u {
                b
            } else if b == u {
                a
            } else {
                continue;
            };
            if depth[w] == usize::MAX {
                depth[w] = depth[u] + 1;
                q.push_back(w);
            }
        }
    }
    edges.iter().copied().filter(|&(a, b)| depth[a] < rings || depth[b] < rings).collect()
}

/// Per-vertex local deviation of one frame pair, `None` for an empty neighbourhood.
fn reference_deviations(
    n: usize,
    edges: &BTreeSet<(usize, usize)>,
    rings: usize,
    truth: &[Vec3],
    result: &[Vec3],
) -> Vec<Option<f64>> {
    (0..n)
        .map(|v| {
            let nb = reference_neighbourhood(n, edges, v, rings);
            if nb.is_empty() {
                return None;
            }
            // (weight, change) per edge; a zero-length truth edge has weight 0.
            let wd: Vec<(f64, f64)> = nb
                .iter()
                .map(|&(a, b)| {
                    let l = dist(truth[a], truth[b]);
                    if l > 0.0 { (l, (dist(result[a], result[b]) - l) / l) } else { (0.0, 0.0) }
                })
                .collect();
            let sw: f64 = wd.iter().map(|p| p.0).sum();
            if sw == 0.0 {
                return Some(0.0);
            }
            let mean = wd.iter().map(|p| p.0 * p.1).sum::<f64>() / sw;
            Some((wd.iter().map(|p| p.0 * (p.1 - mean) * (p.1 - mean)).sum::<f64>() / sw).sqrt())
        })
        .collect()
}

fn reference_spatial(
    n: usize,
    faces: &[[usize; 3]],
    rings: usize,
    truth: &[Vec<Vec3>],
    result: &[Vec<Vec3>],
) -> (f64, usize) {
    let edges = unique_edges(faces);
    let (mut sum, mut count, mut skipped) = (0.0, 0usize, 0usize);
    for (t, r) in truth.iter().zip(result) {
        for d in reference_deviations(n, &edges, rings, t, r).into_iter().flatten() {
            sum += d;
            count += 1;
        }
        skipped += edges.iter().filter(|&&(a, b)| dist(t[a], t[b]) == 0.0).count();
    }
    (sum / count as f64, skipped)
}

fn reference_temporal(faces: &[[usize; 3]], scale: f64, truth: &[Vec<Vec3>], result: &[Vec<Vec3>]) -> f64 {
    let edges = unique_edges(faces);
    let mean_edge = edges.iter().map(|&(a, b)| dist(truth[0][a], truth[0][b])).sum::<f64>() / edges.len() as f64;
    let delta = scale * mean_edge;
    let n = truth[0].len();
    let mut sum = 0.0;
    for f in 1..truth.len() {
        for v in 0..n {
            let t = (dist(truth[f][v], truth[f - 1][v]).powi(2) + delta * delta).sqrt();
            let r = (dist(result[f][v], result[f - 1][v]).powi(2) + delta * delta).sqrt();
            sum += (r - t).abs() / t;
        }
    }
    sum / (n * (truth.len() - 1)) as f64
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()))
}

/// Frames of one sequence.
type Frames = Vec<Vec<Vec3>>;

/// Truth and result sequences of the test mesh; truth frame 2 makes edge (5, 6) zero length
/// (vertex 6 moved onto vertex 5), so one (edge, frame) pair is skipped.
fn sequences() -> (usize, Vec<[usize; 3]>, Frames, Frames) {
    let (n, faces, rest) = mesh();
    let mut truth = sequence(&rest, 4, 11, 0.05);
    truth[2][6] = truth[2][5];
    let result = sequence(&rest, 4, 23, 0.08);
    (n, faces, truth, result)
}

#[test]
fn sted_neighbourhoods_match_a_plain_bfs_for_one_to_three_rings() {
    let (n, faces, _) = mesh();
    let edges = unique_edges(&faces);
    for rings in 1..=3 {
        let s = Sted::new(n, &faces, StedParams { rings, ..Default::default() }).unwrap();
        let listed: Vec<(usize, usize)> = s.edges().iter().map(|e| (e[0], e[1])).collect();
        assert_eq!(listed, edges.iter().copied().collect::<Vec<_>>(), "edges, sorted, unique");
        for v in 0..n {
            let got: Vec<(usize, usize)> = s.neighbourhood(v).iter().map(|&e| listed[e]).collect();
            let want: Vec<(usize, usize)> = reference_neighbourhood(n, &edges, v, rings).into_iter().collect();
            assert_eq!(got, want, "rings {rings}, vertex {v}");
            assert!(s.neighbourhood(v).windows(2).all(|w| w[0] < w[1]), "sorted and unique");
        }
        assert!(s.neighbourhood(n - 1).is_empty(), "the isolated vertex has no neighbourhood");
    }
    // The neighbourhoods grow with the rings (vertex 0 is a corner).
    let sizes: Vec<usize> = (1..=3)
        .map(|rings| Sted::new(n, &faces, StedParams { rings, ..Default::default() }).unwrap().neighbourhood(0).len())
        .collect();
    assert!(sizes[0] < sizes[1] && sizes[1] < sizes[2], "{sizes:?}");
}

#[test]
fn sted_parts_match_the_definitions() {
    let (n, faces, truth, result) = sequences();
    for rings in 1..=3 {
        for (scale, c) in [(0.7, 0.3), (2.5, 1.7)] {
            let params = StedParams { rings, temporal_scale: scale, c };
            let s = Sted::new(n, &faces, params).unwrap();
            let (spatial, skipped) = reference_spatial(n, &faces, rings, &truth, &result);
            assert_eq!(skipped, 1);
            let temporal = reference_temporal(&faces, scale, &truth, &result);
            let r = s.evaluate(&truth, &result, FrameOrder::Sequence).unwrap();
            let tag = format!("rings {rings}, δ scale {scale}, c {c}");
            assert!(close(r.spatial, spatial), "{tag}: spatial {} vs {spatial}", r.spatial);
            assert!(close(r.temporal.unwrap(), temporal), "{tag}: temporal {:?} vs {temporal}", r.temporal);
            let combined = (spatial * spatial + c * c * temporal * temporal).sqrt();
            assert!(close(r.combined, combined), "{tag}: combined {} vs {combined}", r.combined);
            assert_eq!(r.skipped_edges, 1, "{tag}");
            assert_eq!(r.params, params);
            assert_eq!(s.params(), &params);
            assert_eq!(s.spatial_counted(&truth, &result).unwrap(), (r.spatial, 1));
            assert_eq!(s.spatial(&truth, &result).unwrap(), r.spatial);
            assert!(close(s.temporal(&truth, &result).unwrap(), temporal));
            assert_eq!(sted(&faces, &truth, &result, params, FrameOrder::Sequence).unwrap(), r);

            // Unordered: spatial only, and STED equals it.
            let u = s.evaluate(&truth, &result, FrameOrder::Unordered).unwrap();
            assert_eq!((u.spatial, u.temporal, u.combined), (r.spatial, None, r.spatial), "{tag}");

            // One frame at a time: per-vertex deviations and the frame mean over measured vertices.
            let edges = unique_edges(&faces);
            let mut frame_sum = 0.0;
            for (f, (t, q)) in truth.iter().zip(&result).enumerate() {
                let want = reference_deviations(n, &edges, rings, t, q);
                let got = s.spatial_per_vertex(t, q).unwrap();
                for v in 0..n {
                    let w = want[v].unwrap_or(0.0);
                    assert!(close(got[v], w), "{tag}, frame {f}, vertex {v}: {} vs {w}", got[v]);
                }
                let measured: Vec<f64> = want.iter().flatten().copied().collect();
                let mean = measured.iter().sum::<f64>() / measured.len() as f64;
                let frame = s.spatial_frame(t, q).unwrap();
                assert!(close(frame, mean), "{tag}, frame {f}: {frame} vs {mean}");
                frame_sum += frame;
            }
            assert!(close(frame_sum / truth.len() as f64, r.spatial), "{tag}: spatial is the mean of the frames");
        }
    }
}

#[test]
fn sted_of_a_result_equal_to_the_truth_is_zero_and_of_a_different_one_is_not() {
    let (n, faces, truth, result) = sequences();
    let s = Sted::new(n, &faces, StedParams::default()).unwrap();
    let same = s.evaluate(&truth, &truth, FrameOrder::Sequence).unwrap();
    assert_eq!((same.spatial, same.temporal, same.combined), (0.0, Some(0.0), 0.0));
    let r = s.evaluate(&truth, &result, FrameOrder::Sequence).unwrap();
    assert!(r.spatial > 0.01 && r.temporal.unwrap() > 0.01, "{r:?}");
    // A mesh of isolated vertices only: nothing measured, every part 0.
    let lone = Sted::new(3, &[], StedParams::default()).unwrap();
    let p = vec![vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]];
    assert_eq!(lone.spatial_counted(&p, &p).unwrap(), (0.0, 0));
    assert_eq!(lone.spatial_frame(&p[0], &p[0]).unwrap(), 0.0);
    let two = vec![p[0].clone(), p[0].clone()];
    assert!(lone.temporal(&two, &two).is_err(), "no edge: δ undefined");
}

#[test]
fn sted_refuses_mismatched_and_non_finite_frames_naming_them() {
    let (n, faces, truth, result) = sequences();
    let s = Sted::new(n, &faces, StedParams::default())
        .unwrap()
        .with_frame_names((0..4).map(|f| format!("pose{f}")).collect());
    let e = s.evaluate(&truth, &result[..3], FrameOrder::Sequence).unwrap_err().to_string();
    assert!(e.contains("4 ground-truth frames, 3 result frames"), "{e}");
    let mut short = result.clone();
    short[1].pop();
    let e = s.evaluate(&truth, &short, FrameOrder::Sequence).unwrap_err().to_string();
    assert!(e.contains("result frame `pose1` (position 1) has 12 vertices, the mesh 13"), "{e}");
    let mut bad = truth.clone();
    bad[3][4][1] = f64::INFINITY;
    let e = s.evaluate(&bad, &result, FrameOrder::Sequence).unwrap_err().to_string();
    assert!(e.contains("ground-truth frame `pose3` (position 3): vertex 4"), "{e}");
    let e = s.spatial_per_vertex(&truth[0], &short[1]).unwrap_err().to_string();
    assert!(e.contains("has 12 vertices"), "{e}");
    let e = Sted::new(n, &faces, StedParams { rings: 0, ..Default::default() }).unwrap_err().to_string();
    assert!(e.contains("sted.rings"), "{e}");
    let e = Sted::new(5, &faces, StedParams::default()).unwrap_err().to_string();
    assert!(e.contains("references a vertex ≥ 5"), "{e}");
    // The parameter bounds themselves: the smallest valid values are accepted.
    assert!(StedParams { rings: 1, temporal_scale: f64::MIN_POSITIVE, c: 0.0 }.validate().is_ok());
    for (p, key) in [
        (StedParams { temporal_scale: -1.0, ..Default::default() }, "sted.temporal_scale"),
        (StedParams { temporal_scale: f64::INFINITY, ..Default::default() }, "sted.temporal_scale"),
        (StedParams { c: -0.1, ..Default::default() }, "sted.c"),
        (StedParams { c: f64::INFINITY, ..Default::default() }, "sted.c"),
    ] {
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains(key), "{p:?}: {e}");
    }
}

#[test]
fn erms_matches_its_definition_raw_and_centroid_aligned() {
    let (_, _, truth, result) = sequences();
    let (f, n) = (truth.len(), truth[0].len());
    // Raw: 1000·sqrt(Σ‖t − r‖² / (3·F·N)).
    let mut sum = 0.0;
    for (t, r) in truth.iter().zip(&result) {
        for v in 0..n {
            sum += dist(t[v], r[v]).powi(2);
        }
    }
    let raw = 1000.0 * (sum / (3 * f * n) as f64).sqrt();
    // Centroid: each result frame moved so that its centroid is the truth's.
    let mut sum_c = 0.0;
    for (t, r) in truth.iter().zip(&result) {
        let ct: Vec<f64> = (0..3).map(|k| t.iter().map(|p| p[k]).sum::<f64>() / n as f64).collect();
        let cr: Vec<f64> = (0..3).map(|k| r.iter().map(|p| p[k]).sum::<f64>() / n as f64).collect();
        let shift: Vec3 = [ct[0] - cr[0], ct[1] - cr[1], ct[2] - cr[2]];
        assert!(alignment_shift(t, r, Alignment::Centroid).iter().zip(&shift).all(|(a, b)| close(*a, *b)));
        assert_eq!(alignment_shift(t, r, Alignment::None), [0.0; 3]);
        for v in 0..n {
            let moved = [r[v][0] + shift[0], r[v][1] + shift[1], r[v][2] + shift[2]];
            sum_c += dist(t[v], moved).powi(2);
            assert!(close(vertex_squared_error(t[v], r[v], shift), dist(t[v], moved).powi(2)));
        }
    }
    let aligned = 1000.0 * (sum_c / (3 * f * n) as f64).sqrt();
    assert!(aligned < raw, "the sequences differ by a drift, so alignment helps: {aligned} vs {raw}");
    assert!(close(erms(&truth, &result, Alignment::None).unwrap(), raw));
    assert!(close(erms(&truth, &result, Alignment::Centroid).unwrap(), aligned));
    let [a, b] = Erms::raw_and_aligned(&truth, &result).unwrap();
    assert!(close(a.value, raw) && a.alignment == Alignment::None);
    assert!(close(b.value, aligned) && b.alignment == Alignment::Centroid);
    assert_eq!(Erms::measure(&truth, &result, Alignment::Centroid).unwrap(), b);
    assert_eq!(a.to_string(), format!("{raw:.6} (alignment none)"));
    assert_eq!(b.to_string(), format!("{aligned:.6} (alignment centroid)"));
    let frame0: f64 = (0..n).map(|v| dist(truth[0][v], result[0][v]).powi(2)).sum();
    assert!(close(frame_squared_error(&truth[0], &result[0], Alignment::None).unwrap(), frame0));
    assert_eq!(erms_from_squared_error(12.0, 3), 2000.0);
    assert_eq!(erms_from_squared_error(5.0, 0), 0.0);
    assert_eq!(alignment_shift(&[], &[], Alignment::Centroid), [0.0; 3]);
    // Mismatches are errors naming both counts.
    let e = erms(&truth, &result[..2], Alignment::None).unwrap_err().to_string();
    assert!(e.contains("4 ground-truth frames, 2 result frames"), "{e}");
    let e = frame_squared_error(&truth[0], &result[0][..5], Alignment::None).unwrap_err().to_string();
    assert!(e.contains("13 vertices, the result 5"), "{e}");
}

/// Connected components of {e : |norm_e| > t·max, norm_e ≠ 0} by union–find.
fn reference_regions(norms: &[f64], adjacency: &[Vec<usize>], t: f64) -> (usize, usize) {
    let max = norms.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let inside: Vec<bool> = norms.iter().map(|x| x.abs() > t * max && *x != 0.0).collect();
    let mut parent: Vec<usize> = (0..norms.len()).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            x = p[x];
        }
        x
    }
    for (a, list) in adjacency.iter().enumerate() {
        for &b in list {
            if inside[a] && inside[b] {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                parent[ra] = rb;
            }
        }
    }
    let size = inside.iter().filter(|&&b| b).count();
    let roots: BTreeSet<usize> = (0..norms.len()).filter(|&e| inside[e]).map(|e| find(&mut parent, e)).collect();
    (size, roots.len())
}

#[test]
fn support_regions_match_union_find_on_random_components() {
    let (n, faces, _) = mesh();
    let edges = unique_edges(&faces);
    let mut adjacency = vec![Vec::new(); n];
    for &(a, b) in &edges {
        adjacency[a].push(b);
        adjacency[b].push(a);
    }
    let mut g = Lcg(3);
    let mut seen_regions = BTreeSet::new();
    for trial in 0..60 {
        // Sparse, signed norms: about half exactly 0, some negative (a signed weight's size).
        let norms: Vec<f64> = (0..n).map(|_| if g.next() < 0.0 { 0.0 } else { 3.0 * g.next() }).collect();
        for t in [0.0, 0.01, 0.3, 0.6, 1.0] {
            let r = support_regions(&norms, &adjacency, t).unwrap();
            let (size, regions) = reference_regions(&norms, &adjacency, t);
            assert_eq!((r.size, r.regions), (size, regions), "trial {trial}, threshold {t}, norms {norms:?}");
            seen_regions.insert(regions);
        }
    }
    assert!(seen_regions.len() >= 4, "the trials cover 0, 1 and several regions: {seen_regions:?}");
    // Threshold exactly at a value: strictly above counts.
    let chain = vec![vec![1], vec![0, 2], vec![1]];
    let r = support_regions(&[1.0, 0.5, 1.0], &chain, 0.5).unwrap();
    assert_eq!((r.size, r.regions), (2, 2));
    let r = support_regions(&[1.0, 0.5, 1.0], &chain, 0.49).unwrap();
    assert_eq!((r.size, r.regions), (3, 1));
    // Errors name what is wrong.
    let e = support_regions(&[1.0, 1.0], &chain, 0.1).unwrap_err().to_string();
    assert!(e.contains("2 norms but 3 adjacency lists"), "{e}");
    for t in [-0.01, 1.01, f64::NAN] {
        let e = support_regions(&[1.0, 0.5, 1.0], &chain, t).unwrap_err().to_string();
        assert!(e.contains("must lie in [0, 1]"), "{t}: {e}");
    }
    let e = support_regions(&[1.0, f64::NAN, 1.0], &chain, 0.1).unwrap_err().to_string();
    assert!(e.contains("norm 1 is not finite"), "{e}");
    let e = support_regions(&[1.0, 1.0, 1.0], &[vec![1], vec![0, 3], vec![1]], 0.1).unwrap_err().to_string();
    assert!(e.contains("element 1 has neighbour 3 ≥ 3"), "{e}");
}

#[test]
fn edge_distortion_matches_its_definition() {
    let (n, faces, rest) = mesh();
    let shape = sequence(&rest, 3, 5, 0.1).pop().unwrap();
    let edges = unique_edges(&faces);
    let rel: Vec<f64> = edges
        .iter()
        .map(|&(a, b)| {
            let l = dist(rest[a], rest[b]);
            (dist(shape[a], shape[b]) - l).abs() / l
        })
        .collect();
    let mean = rel.iter().sum::<f64>() / rel.len() as f64;
    let max = rel.iter().fold(0.0f64, |a, &b| a.max(b));
    for rings in [1, 2] {
        let mesh = TriMesh::new(rest.clone(), faces.clone());
        let d = edge_length_distortion(&mesh, &shape, StedParams { rings, ..Default::default() }).unwrap();
        assert!(close(d.mean_relative, mean), "{} vs {mean}", d.mean_relative);
        assert!(close(d.max_relative, max), "{} vs {max}", d.max_relative);
        let (spatial, _) =
            reference_spatial(n, &faces, rings, std::slice::from_ref(&rest), std::slice::from_ref(&shape));
        assert!(close(d.spatial_sted, spatial), "rings {rings}: {} vs {spatial}", d.spatial_sted);
        assert!(mean > 0.01 && max > mean && spatial > 0.01);
        // The rest shape itself: all zero.
        let meter = EdgeDistortionMeter::new(&mesh, StedParams::default()).unwrap();
        let z = meter.measure(&rest).unwrap();
        assert_eq!((z.mean_relative, z.max_relative, z.spatial_sted), (0.0, 0.0, 0.0));
    }
    // A mesh without edges measures zero; bad input is refused naming it.
    let lone = TriMesh::new(vec![[0.0; 3], [1.0, 0.0, 0.0]], vec![]);
    let z = edge_length_distortion(&lone, &[[0.0; 3], [5.0, 0.0, 0.0]], StedParams::default()).unwrap();
    assert_eq!((z.mean_relative, z.max_relative, z.spatial_sted), (0.0, 0.0, 0.0));
    let mesh = TriMesh::new(rest.clone(), faces.clone());
    let e = edge_length_distortion(&mesh, &shape[..4], StedParams::default()).unwrap_err().to_string();
    assert!(e.contains("shape has 4 vertices, the rest mesh 13"), "{e}");
    let mut flat = rest.clone();
    flat[1] = flat[0];
    let e =
        EdgeDistortionMeter::new(&TriMesh::new(flat, faces.clone()), StedParams::default()).unwrap_err().to_string();
    assert!(e.contains("rest edge (0, 1) has length 0"), "{e}");
    let mut nan = rest;
    nan[2][0] = f64::NAN;
    let e = EdgeDistortionMeter::new(&TriMesh::new(nan, faces), StedParams::default()).unwrap_err().to_string();
    assert!(e.contains("rest vertex 2 has a non-finite coordinate"), "{e}");
}
