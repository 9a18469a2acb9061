//! One training step of the mesh autoencoder at SCAPE size (N = 2161, 36 shapes, K = 50, L = 1),
//! at horse-gallop size (N = 8431, 5 shapes: every 10th of 48 frames) and at face-poses size
//! (N = 29 299, 7 shapes: the large-mesh case, where the step is dominated by `C`, 13 M numbers),
//! ndarray backend.
//!
//! Connectivity comes from `../shared/data/{scape/1.obj, horse-gallop/0001.obj,
//! face-poses/1.obj}` when present, otherwise from a subdivided icosahedron of similar size;
//! features are random in [−0.95, 0.95] (the step costs the same for any values). Distances are
//! hop counts (cheap; the command line's heat-method queries add to the support phase). Besides
//! criterion's numbers the bench prints where a step's time goes.

use std::path::Path;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use meshdeco::mesh::primitives::icosphere;
use meshdeco::nn::rng::Rng;
use meshdeco::nn::{AutoencoderConfig, HopDistances, NeighborIndex, Trainer, TrainingData};
use meshdeco::representation::Features;

/// Vertex count and triangles of a mesh file, or `None` when it is absent or unreadable.
fn load_faces(path: &Path) -> Option<(usize, Vec<[usize; 3]>)> {
    let mesh = meshdeco::mesh::load_mesh(path).ok()?;
    Some((mesh.n_vertices(), mesh.faces))
}

fn problem(obj: &str, fallback_levels: usize, shapes: usize) -> (NeighborIndex, TrainingData, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(obj);
    let (n, faces, what) = match load_faces(&path) {
        Some((n, f)) => (n, f, format!("{} ({n} vertices)", path.display())),
        None => {
            let sphere = icosphere(fallback_levels);
            let n = sphere.n_vertices();
            (n, sphere.faces, format!("icosphere ({n} vertices; {} not found)", path.display()))
        }
    };
    let nb = NeighborIndex::from_faces(n, &faces).expect("valid mesh");
    let mut rng = Rng::new(1);
    let mut feats = Features::zeros(shapes, n, 9);
    for v in feats.data.iter_mut() {
        *v = rng.uniform() * 1.9 - 0.95;
    }
    (nb, TrainingData::from_features(&feats).unwrap(), what)
}

fn bench_case(c: &mut Criterion, name: &str, obj: &str, levels: usize, shapes: usize) {
    let (nb, data, what) = problem(obj, levels, shapes);
    let dist = HopDistances::new(&nb);
    let cfg = AutoencoderConfig { components: 50, layers: 1, ..Default::default() };
    let mut trainer = Trainer::new(cfg, &data, &nb, &dist).unwrap();
    // Phase breakdown over 30 steps (after 5 warm-up steps).
    for _ in 0..5 {
        trainer.step().unwrap();
    }
    let mut sum = [0.0f64; 4];
    let steps = 30;
    let t0 = Instant::now();
    for _ in 0..steps {
        trainer.step().unwrap();
        let t = trainer.last_step_timings();
        for (s, v) in sum.iter_mut().zip([t.snapshot, t.support, t.forward_backward, t.optimizer]) {
            *s += v;
        }
    }
    let total = t0.elapsed().as_secs_f64() / steps as f64;
    let ms = |v: f64| v / steps as f64 * 1e3;
    eprintln!(
        "{name}: {what}, {} shapes, K = 50, L = 1: {:.2} ms/step = snapshot {:.2} + support maps {:.2} + forward/backward {:.2} + update {:.2}",
        data.n_shapes(),
        total * 1e3,
        ms(sum[0]),
        ms(sum[1]),
        ms(sum[2]),
        ms(sum[3])
    );
    let mut g = c.benchmark_group("autoencoder");
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(4));
    g.bench_function(name, |b| b.iter(|| trainer.step().unwrap()));
    g.finish();
}

fn benches(c: &mut Criterion) {
    bench_case(c, "train_step_scape", "scape/1.obj", 4, 36);
    bench_case(c, "train_step_horse", "horse-gallop/0001.obj", 5, 5);
    bench_case(c, "train_step_face_poses", "face-poses/1.obj", 6, 7);
}

criterion_group!(autoencoder, benches);
criterion_main!(autoencoder);
