//! Times training steps of the autoencoder at SCAPE size (for profiling with `perf`).
//! Usage: cargo run --release --example ae_profile -- [steps] [obj]
use meshdeco::nn::rng::Rng;
use meshdeco::nn::{AutoencoderConfig, HopDistances, NeighborIndex, Trainer, TrainingData};
use meshdeco::representation::Features;
use std::time::Instant;

fn cpu_seconds() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let f: Vec<&str> = s.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let t = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (t(11) + t(12)) / 100.0
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(50);
    let obj = args.get(2).cloned().unwrap_or_else(|| "../shared/data/scape/1.obj".into());
    let shapes: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(36);
    let opts = tobj::LoadOptions { triangulate: true, single_index: false, ..Default::default() };
    let (models, _) = tobj::load_obj(&obj, &opts).expect("obj");
    let m = &models[0].mesh;
    let n = m.positions.len() / 3;
    let faces: Vec<[usize; 3]> = m.indices.chunks_exact(3).map(|f| [f[0] as usize, f[1] as usize, f[2] as usize]).collect();
    let nb = NeighborIndex::from_faces(n, &faces).unwrap();
    let dist = HopDistances::new(&nb);
    let mut rng = Rng::new(1);
    let mut feats = Features::zeros(shapes, n, 9);
    for v in feats.data.iter_mut() {
        *v = rng.uniform() * 1.9 - 0.95;
    }
    let data = TrainingData::from_features(&feats).unwrap();
    let cfg = AutoencoderConfig { components: 50, ..Default::default() };
    let mut t = Trainer::new(cfg, &data, &nb, &dist).unwrap();
    for _ in 0..3 {
        t.step().unwrap();
    }
    let mut sum = [0.0; 4];
    let c0 = cpu_seconds();
    let t0 = Instant::now();
    for _ in 0..steps {
        t.step().unwrap();
        let s = t.last_step_timings();
        for (a, b) in sum.iter_mut().zip([s.snapshot, s.support, s.forward_backward, s.optimizer]) {
            *a += b;
        }
    }
    let wall = t0.elapsed().as_secs_f64() / steps as f64;
    let cpu = (cpu_seconds() - c0) / steps as f64;
    let ms = |v: f64| v / steps as f64 * 1e3;
    println!(
        "N = {n}, {shapes} shapes: {:.2} ms/step wall, {:.2} ms CPU/step; snapshot {:.2}, support {:.2}, fwd/bwd {:.2}, adam {:.2}",
        wall * 1e3, cpu * 1e3, ms(sum[0]), ms(sum[1]), ms(sum[2]), ms(sum[3])
    );
}
