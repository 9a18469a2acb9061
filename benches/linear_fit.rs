//! Criterion benchmarks of the linear methods' fits that `benches/splocs.rs` does not cover:
//! holistic PCA on SCAPE (train 1–36, displacements, K = 35), and on face-poses (train 1–7)
//! the segmentation (spectral clustering with a fixed 13 regions) and the region-PCA fit
//! (K = 78) on those regions. Skipped (with a message) when `../shared/data` is absent.

use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use meshdeco::mesh::load_sequence;
use meshdeco::methods::region_pca::{RegionPcaConfig, RegionPcaModel};
use meshdeco::methods::segmentation::{SegmentationConfig, segment};
use meshdeco::methods::{DataMatrix, Pca, PcaConfig};

/// Displacements from the first frame of `frames` (F × N × 3, frame-major).
fn displacements(seq: &meshdeco::mesh::MeshSequence, frames: &[usize]) -> Vec<f64> {
    let rest = &seq.frames[0];
    frames
        .iter()
        .flat_map(|&f| seq.frames[f].iter().zip(rest).flat_map(|(p, q)| [p[0] - q[0], p[1] - q[1], p[2] - q[2]]))
        .collect()
}

fn bench(c: &mut Criterion) {
    let scape = Path::new("../shared/data/scape");
    let face = Path::new("../shared/data/face-poses");
    if !scape.is_dir() || !face.is_dir() {
        eprintln!("linear_fit bench skipped: ../shared/data/scape or face-poses not found");
        return;
    }
    let seq = load_sequence(&scape.to_string_lossy()).expect("SCAPE loads");
    let train: Vec<usize> = (0..36).collect();
    let x = displacements(&seq, &train);
    let n = seq.frames[0].len();
    c.bench_function("pca_fit_scape_36_shapes_k35", |b| {
        b.iter(|| {
            let m = DataMatrix::new(&x, train.len(), n, 3).unwrap();
            Pca::fit(m, &PcaConfig { components: 35, ..Default::default() }).unwrap()
        })
    });

    let fseq = load_sequence(&face.to_string_lossy()).expect("face-poses loads");
    let ftrain: Vec<usize> = (0..7).collect();
    let fx = displacements(&fseq, &ftrain);
    let fn_ = fseq.frames[0].len();
    let seg_cfg = SegmentationConfig { regions: Some(13), ..Default::default() };
    let mut group = c.benchmark_group("region_pca_face_poses");
    group.sample_size(10);
    group.bench_function("segmentation_13_regions", |b| {
        b.iter(|| segment(&fseq.frames[0], &fseq.faces, &fx, ftrain.len(), &seg_cfg).unwrap())
    });
    let seg = segment(&fseq.frames[0], &fseq.faces, &fx, ftrain.len(), &seg_cfg).unwrap();
    group.bench_function("region_pca_fit_k78", |b| {
        b.iter(|| {
            let m = DataMatrix::new(&fx, ftrain.len(), fn_, 3).unwrap();
            RegionPcaModel::fit(m, &seg.regions, &RegionPcaConfig { components: 78, beta: 1.0 }).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
