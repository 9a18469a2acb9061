//! ACAP benchmarks: features with global consistency for all 71 SCAPE shapes (rayon over frames),
//! and decoding one horse-gallop frame (8431 vertices) after factorisation, with the default
//! fit-inverse decoder and with the edge least squares. Without `../shared/data` the same
//! benchmarks run on synthetic twisted tubes of similar sizes (and say so).
//!
//! Run: `cargo bench --bench acap`.

use criterion::{Criterion, criterion_group, criterion_main};
use meshdeco::mesh::{TriMesh, Vec3};
use meshdeco::representation::acap::{Acap, AcapDecoder, AcapOptions, Consistency};
use std::f64::consts::PI;
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

/// All OBJ files of `../shared/data/<name>` in natural (numeric) order, or `None` when the folder
/// is absent or unreadable.
fn load_folder(name: &str) -> Option<Vec<TriMesh>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(name);
    let seq = meshdeco::mesh::load_sequence(&format!("{}/*.obj", dir.display())).ok()?;
    Some(seq.frames.into_iter().map(|p| TriMesh::new(p, seq.faces.clone())).collect())
}

/// A closed tube along x (`rings` × `m` vertices + 2 cap centres).
fn tube(rings: usize, m: usize) -> TriMesh {
    let (r, len) = (0.1, 6.0);
    let mut p = Vec::new();
    for i in 0..rings {
        for k in 0..m {
            let a = 2.0 * PI * k as f64 / m as f64;
            p.push([len * i as f64 / (rings - 1) as f64, r * a.cos(), r * a.sin()]);
        }
    }
    let (c0, c1) = (p.len(), p.len() + 1);
    p.push([0.0; 3]);
    p.push([len, 0.0, 0.0]);
    let id = |i: usize, k: usize| i * m + (k % m);
    let mut f = Vec::new();
    for i in 0..rings - 1 {
        for k in 0..m {
            f.push([id(i, k), id(i + 1, k), id(i + 1, k + 1)]);
            f.push([id(i, k), id(i + 1, k + 1), id(i, k + 1)]);
        }
    }
    for k in 0..m {
        f.push([c0, id(0, k), id(0, k + 1)]);
        f.push([c1, id(rings - 1, k + 1), id(rings - 1, k)]);
    }
    TriMesh::new(p, f)
}

fn twisted(mesh: &TriMesh, total: f64) -> Vec<Vec3> {
    mesh.positions
        .iter()
        .map(|p| {
            let a = total * p[0] / 6.0;
            [p[0], a.cos() * p[1] - a.sin() * p[2], a.sin() * p[1] + a.cos() * p[2]]
        })
        .collect()
}

fn bench_acap(c: &mut Criterion) {
    // Encoding: SCAPE (71 × 2161), or 71 twisted tubes of 2162 vertices.
    let (reference, frames, what) = match load_folder("scape") {
        Some(m) if !m.is_empty() => {
            let frames: Vec<Vec<Vec3>> = m.iter().map(|x| x.positions.clone()).collect();
            (m[0].clone(), frames, "SCAPE")
        }
        _ => {
            println!("../shared/data/scape not found: benchmarking 71 synthetic twisted tubes instead");
            let t = tube(180, 12);
            let frames = (0..71).map(|k| twisted(&t, 0.1 * k as f64)).collect();
            (t, frames, "synthetic")
        }
    };
    let acap = Acap::new(&reference).unwrap();
    c.bench_function(&format!("acap_features_global_{what}_{}_frames", frames.len()), |b| {
        b.iter(|| black_box(acap.encode_sequence(black_box(&frames), Consistency::Global).unwrap()))
    });
    c.bench_function(&format!("acap_features_bfs_{what}_{}_frames", frames.len()), |b| {
        b.iter(|| black_box(acap.encode_sequence(black_box(&frames), Consistency::Bfs).unwrap()))
    });

    // Decoding one frame: horse-gallop (8431 vertices), or a tube of 8402 vertices.
    let (reference, frame, what) = match load_folder("horse-gallop") {
        Some(m) if m.len() > 1 => (m[0].clone(), m[10].positions.clone(), "horse"),
        _ => {
            println!("../shared/data/horse-gallop not found: benchmarking a synthetic tube instead");
            let t = tube(700, 12);
            let x = twisted(&t, 1.5 * PI);
            (t, x, "synthetic")
        }
    };
    for (name, decoder) in [
        ("fit_inverse", AcapDecoder::FitInverse { edge_weight: meshdeco::representation::acap::DEFAULT_EDGE_WEIGHT }),
        ("edge_lsq", AcapDecoder::EdgeLeastSquares),
    ] {
        let acap = Acap::with_options(&reference, AcapOptions { decoder, ..Default::default() }).unwrap();
        let features = acap.encode_frame(&frame, Consistency::Global).unwrap().features();
        c.bench_function(&format!("acap_decode_{what}_{}_vertices_{name}", reference.n_vertices()), |b| {
            b.iter(|| black_box(acap.decode_frame(black_box(&features)).unwrap()))
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(5));
    targets = bench_acap
}
criterion_main!(benches);
