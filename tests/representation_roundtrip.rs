//! Encode → decode round trips on real data (`../shared/data`): SCAPE (rest = 1.obj),
//! horse-gallop and cactus, plus a synthetic counterpart that always runs.
//!
//! Meshes are read with `meshdeco::mesh::load_sequence`. Data tests fail in CI when the folder is absent and are recorded skips locally. Run with `--nocapture` to see
//! the per-dataset Erms.

mod common;

use std::path::{Path, PathBuf};

use meshdeco::mesh::{MeshSequence, Vec3, load_sequence};
use meshdeco::representation::roundtrip::{Alignment, roundtrip};
use meshdeco::representation::{Representation, RepresentationKind, RepresentationOptions};

fn data_dir(name: &str) -> Option<PathBuf> {
    common::shared_or_skip(&format!("data/{name}"))
}

/// Every `*.{ext}` file of `dir` in natural order, read with meshdeco's reader (which checks that
/// all frames share the first frame's connectivity).
fn load_dir(dir: &Path, ext: &str) -> MeshSequence {
    let spec = format!("{}/*.{ext}", dir.display());
    load_sequence(&spec).unwrap_or_else(|e| panic!("{spec}: {e}"))
}

/// Round trips of displacement and triangle-gradient on `seq` with frame 0 as rest; returns the
/// two totals (Erms, data units × 1000).
fn round_trips(label: &str, seq: &MeshSequence) -> (f64, f64) {
    let rest = seq.mesh(0);
    let mut totals = [0.0; 2];
    for (i, kind) in [RepresentationKind::Displacement, RepresentationKind::TriangleGradient].into_iter().enumerate() {
        let rep = Representation::new(kind, &rest, RepresentationOptions::default()).unwrap();
        let report = roundtrip(&rep, seq).unwrap();
        let worst = report.frames.iter().map(|(_, e)| *e).fold(0.0, f64::max);
        println!(
            "{label}: {} frames × {} vertices, {}: total Erms {:.3e} (alignment {}), worst frame {:.3e}, max vertex distance {:.3e}",
            seq.n_frames(),
            seq.n_vertices(),
            kind.name(),
            report.total,
            report.alignment,
            worst,
            report.max_distance
        );
        let want = if rep.translation_free() { Alignment::Centroid } else { Alignment::None };
        assert_eq!(report.alignment, want);
        assert_eq!(report.frames.len(), seq.n_frames());
        totals[i] = report.total;
    }
    (totals[0], totals[1])
}

#[test]
fn scape_round_trip() {
    let Some(dir) = data_dir("scape") else { return };
    let seq = load_dir(&dir, "obj");
    assert_eq!((seq.n_frames(), seq.n_vertices(), seq.n_faces()), (71, 2161, 4318));
    assert_eq!(seq.names[0], "1");
    let (disp, grad) = round_trips("scape", &seq);
    assert!(disp < 1e-9, "displacement Erms {disp}");
    assert!(grad <= 1.0, "triangle-gradient Erms {grad} above the 1.0 target");
}

#[test]
fn horse_gallop_round_trip() {
    let Some(dir) = data_dir("horse-gallop") else { return };
    let seq = load_dir(&dir, "obj");
    assert_eq!((seq.n_frames(), seq.n_vertices()), (48, 8431));
    let (disp, grad) = round_trips("horse-gallop", &seq);
    assert!(disp < 1e-9, "displacement Erms {disp}");
    assert!(grad <= 1.0, "triangle-gradient Erms {grad}");
}

#[test]
fn cactus_round_trip() {
    let Some(dir) = data_dir("cactus") else { return };
    let seq = load_dir(&dir, "ply");
    assert_eq!((seq.n_frames(), seq.n_vertices()), (19, 5261));
    assert_eq!(seq.names[0], "cactus0");
    let (disp, grad) = round_trips("cactus", &seq);
    assert!(disp < 1e-9, "displacement Erms {disp}");
    assert!(grad <= 1.0, "triangle-gradient Erms {grad}");
}

/// Synthetic counterpart: a subdivided octahedron sphere bent and twisted over 8 frames (up to
/// ~300° of twist, so rotations pass π), always available.
#[test]
fn synthetic_bent_sphere_round_trip() {
    let mut p: Vec<Vec3> = vec![[1., 0., 0.], [-1., 0., 0.], [0., 1., 0.], [0., -1., 0.], [0., 0., 1.], [0., 0., -1.]];
    let mut f: Vec<[usize; 3]> =
        vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    for _ in 0..4 {
        let mut mid = std::collections::HashMap::new();
        let mut nf = Vec::new();
        for t in &f {
            let mut m = [0; 3];
            for k in 0..3 {
                let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                m[k] = *mid.entry((a, b)).or_insert_with(|| {
                    p.push(std::array::from_fn(|c| 0.5 * (p[a][c] + p[b][c])));
                    p.len() - 1
                });
            }
            nf.extend([[t[0], m[0], m[2]], [m[0], t[1], m[1]], [m[2], m[1], t[2]], [m[0], m[1], m[2]]]);
        }
        f = nf;
    }
    for q in &mut p {
        let l = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
        *q = [q[0] / l, 2.0 * q[1] / l, q[2] / l]; // an ellipsoid, 4 units tall
    }
    let frames: Vec<Vec<Vec3>> = (0..8)
        .map(|fr| {
            let t = fr as f64 / 7.0;
            p.iter()
                .map(|q| {
                    let a = 2.6 * t * q[1]; // twist about y, up to ±5.2 rad at the poles
                    let (s, c) = a.sin_cos();
                    [c * q[0] - s * q[2] + 0.4 * t * q[1] * q[1], q[1] * (1.0 + 0.2 * t), s * q[0] + c * q[2]]
                })
                .collect()
        })
        .collect();
    let seq = MeshSequence { faces: f, names: (0..8).map(|i| format!("s{i}")).collect(), frames };
    let (disp, grad) = round_trips("synthetic", &seq);
    assert!(disp < 1e-9, "displacement Erms {disp}");
    assert!(grad < 1e-6, "triangle-gradient Erms {grad}");
}
