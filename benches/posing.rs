//! Posing benchmarks: one drag solve (one constrained vertex, factorised poser) for holistic PCA
//! and region PCA on `../shared/data/face-poses` (29 299 vertices; trained on poses 1–7), and
//! building the poser (once per constraint set). Without the data the same benchmarks run on
//! the synthetic `bumps` tube (and say so).
//!
//! Run: `cargo bench --bench posing`.

use criterion::{Criterion, criterion_group, criterion_main};
use meshdeco::mesh::MeshSequence;
use meshdeco::methods::posing::{LinearPoser, PoseConfig, RegionPoser};
use meshdeco::methods::region_pca::{RegionPcaConfig, RegionPcaModel};
use meshdeco::methods::segmentation::{SegmentationConfig, segment};
use meshdeco::methods::{DataMatrix, Pca, PcaCentering, PcaConfig};
use std::hint::black_box;
use std::path::Path;

fn data() -> (MeshSequence, &'static str) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/face-poses");
    if dir.exists()
        && let Ok(s) = meshdeco::mesh::load_sequence(&dir.display().to_string())
    {
        let n = s.frames.len().min(7);
        return (s.select(&(0..n).collect::<Vec<_>>()), "face-poses");
    }
    eprintln!("../shared/data/face-poses absent: benchmarking on synthetic:bumps");
    (meshdeco::synthetic::load("synthetic:bumps").unwrap(), "bumps")
}

fn bench(c: &mut Criterion) {
    let (seq, name) = data();
    let rest = &seq.frames[0];
    let n = rest.len();
    let f = seq.frames.len();
    let mut d = Vec::with_capacity(f * n * 3);
    for fr in &seq.frames {
        for (p, q) in fr.iter().zip(rest) {
            d.extend_from_slice(&[p[0] - q[0], p[1] - q[1], p[2] - q[2]]);
        }
    }
    let x = DataMatrix::new(&d, f, n, 3).unwrap();
    let k = (f - 1).min(6);
    let pca = Pca::fit(x, &PcaConfig { components: k, centering: PcaCentering::Mean }).unwrap();
    let seg =
        segment(rest, &seq.faces, &d, f, &SegmentationConfig { regions: Some(6), restarts: 5, ..Default::default() })
            .unwrap();
    let region = RegionPcaModel::fit(x, &seg.regions, &RegionPcaConfig { components: 6 * k, beta: 1.0 }).unwrap();
    let v = n / 2;
    let cfg = PoseConfig::default();
    let w0 = vec![0.0; k];
    let z0 = region.encode(&d[..3 * n]).unwrap();
    let target = [[0.01, 0.02, 0.0]];
    let lp = LinearPoser::new(&pca, &[v], &cfg).unwrap();
    c.bench_function(&format!("pose_solve_pca_{name}"), |b| b.iter(|| black_box(lp.solve(&target, &w0).unwrap())));
    let rp = RegionPoser::new(&region, &[v], &cfg).unwrap();
    c.bench_function(&format!("pose_solve_region_pca_{name}"), |b| {
        b.iter(|| black_box(region.reconstruct(&rp.solve(&target, &z0).unwrap()).unwrap()))
    });
    c.bench_function(&format!("pose_build_region_pca_{name}"), |b| {
        b.iter(|| black_box(RegionPoser::new(&region, &[v], &cfg).unwrap()))
    });
}

/// One autoencoder drag solve on SCAPE (2161 vertices, K = 50): the model from
/// `MESHDECO_AE_MODEL` (an artefact directory of `meshdeco train` on SCAPE), else a small model
/// trained here for 30 iterations (the solve's cost does not depend on training quality).
/// Skips, saying why, when `../shared/data/scape` is absent.
fn bench_ae(c: &mut Criterion) {
    use meshdeco::pipeline::ae_pose::{AePoseConfig, AePoser};
    use meshdeco::pipeline::autoencoder::AeArtifact;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/scape");
    if !dir.exists() {
        eprintln!("skipping pose_solve_autoencoder_scape: {} absent", dir.display());
        return;
    }
    let model_dir = match std::env::var("MESHDECO_AE_MODEL") {
        Ok(p) => std::path::PathBuf::from(p),
        Err(_) => {
            let out = std::env::temp_dir().join(format!("meshdeco-bench-ae-pose-{}", std::process::id()));
            let cfg = meshdeco::config::Config::from_toml(&format!(
                "name = \"scape-bench\"\n[data]\npath = \"{}\"\ntrain = \"1-36\"\n[method]\nkind = \"autoencoder\"\ncomponents = 50\niterations = 30\n",
                dir.display()
            ))
            .unwrap();
            eprintln!(
                "training a 30-iteration SCAPE autoencoder for the posing benchmark (set MESHDECO_AE_MODEL to skip)"
            );
            meshdeco::pipeline::train(
                &cfg,
                &out,
                &meshdeco::pipeline::TrainOptions::default(),
                &mut meshdeco::pipeline::Silent,
            )
            .unwrap();
            out
        }
    };
    let a = AeArtifact::load(&model_dir).unwrap();
    let z0 = a.reference_code().to_vec();
    let start = a.decode_codes(std::slice::from_ref(&z0)).unwrap().remove(0);
    let v = 412.min(start.len() - 1);
    let t = [start[v][0] + 0.02, start[v][1] + 0.03, start[v][2]];
    let poser = AePoser::new(&a, &[v], &AePoseConfig::default()).unwrap();
    let (_, p, rep) = poser.solve_report(&[t], &z0).unwrap();
    eprintln!(
        "SCAPE autoencoder drag of vertex {v} by {:.4}: landing error {:.4}, {} Gauss-Newton iterations",
        meshdeco::mesh::dist(start[v], t),
        meshdeco::mesh::dist(p[v], t),
        rep.iterations
    );
    c.bench_function("pose_solve_autoencoder_scape", |b| b.iter(|| black_box(poser.solve(&[t], &z0).unwrap())));
    c.bench_function("pose_build_autoencoder_scape", |b| {
        b.iter(|| black_box(AePoser::new(&a, &[v], &AePoseConfig::default()).unwrap()))
    });
}

criterion_group! {
    name = ae_benches;
    config = Criterion::default().sample_size(10).measurement_time(std::time::Duration::from_secs(5));
    targets = bench_ae
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(3));
    targets = bench
}
criterion_main!(benches, ae_benches);
