//! Demo and timing harness of the mesh autoencoder (library only, no CLI).
//!
//! ```text
//! cargo run --release --example ae_synthetic                 # train on a synthetic grid
//! cargo run --release --example ae_synthetic -- 3000         # … for 3000 iterations
//! cargo run --release --example ae_synthetic -- --profile ../shared/data/scape/1.obj 36 50
//! ```
//! The demo plants three localized deformations (random amplitudes per shape) on a 30 × 30 grid,
//! trains K = 8 components and prints the loss, the time per iteration and the strongest
//! components with their centres. `--profile OBJ SHAPES STEPS` times training steps on the
//! connectivity of OBJ with random features (K = 50, L = 1) and prints where the time goes.

use std::time::Instant;

use meshdeco::nn::rng::Rng;
use meshdeco::nn::{AutoencoderConfig, HopDistances, NeighborIndex, RunOptions, Trainer, TrainingData};
use meshdeco::representation::Features;

fn grid(nx: usize, ny: usize) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let mut p = Vec::new();
    for y in 0..ny {
        for x in 0..nx {
            p.push([x as f64 / (nx - 1) as f64, y as f64 / (ny - 1) as f64, 0.0]);
        }
    }
    let mut f = Vec::new();
    for y in 0..ny - 1 {
        for x in 0..nx - 1 {
            let v = y * nx + x;
            f.push([v, v + 1, v + nx + 1]);
            f.push([v, v + nx + 1, v + nx]);
        }
    }
    (p, f)
}

fn demo(iterations: usize) {
    let (p, faces) = grid(30, 30);
    let n = p.len();
    let centres = [[0.25, 0.25], [0.75, 0.3], [0.5, 0.75]];
    let mut rng = Rng::new(5);
    let shapes = 20;
    let mut feats = Features::zeros(shapes, n, 9);
    for s in 0..shapes {
        let amps: Vec<f64> = (0..3).map(|_| rng.uniform() * 1.6 - 0.8).collect();
        for (i, pi) in p.iter().enumerate() {
            for (k, c) in centres.iter().enumerate() {
                let d2 = (pi[0] - c[0]).powi(2) + (pi[1] - c[1]).powi(2);
                let bump = amps[k] * (-d2 / (2.0 * 0.1f64.powi(2))).exp();
                for ch in 0..9 {
                    let pattern = ((k * 9 + ch) as f64 * 0.7).sin();
                    let v = &mut feats.data[(s * n + i) * 9 + ch];
                    *v = (*v + bump * pattern).clamp(-0.95, 0.95);
                }
            }
        }
    }
    let nb = NeighborIndex::from_faces(n, &faces).expect("grid");
    let dist = HopDistances::new(&nb);
    let data = TrainingData::from_features(&feats).expect("finite");
    let cfg = AutoencoderConfig { components: 8, iterations, learning_rate: 5e-3, ..Default::default() };
    let mut trainer = Trainer::new(cfg, &data, &nb, &dist).expect("valid config");
    let t0 = Instant::now();
    let summary = trainer
        .run(&RunOptions::default(), |r| {
            if r.iteration % 100 == 0 || r.iteration == 1 {
                println!(
                    "iteration {:5}: loss {:.5} (reconstruction {:.5}, sparsity {:.4}, hinge {:.4}), {:.2} ms",
                    r.iteration,
                    r.loss.total,
                    r.loss.reconstruction,
                    r.loss.sparsity,
                    r.loss.hinge,
                    r.step_seconds * 1e3
                );
            }
        })
        .expect("training");
    println!(
        "{} iterations in {:.2} s ({:.2} ms/iteration)",
        summary.iterations_done,
        t0.elapsed().as_secs_f64(),
        summary.mean_step_seconds * 1e3
    );
    let ae = trainer.into_model().expect("finite model");
    let analysis = ae.analyze_components(&feats, 0).expect("analysis");
    println!("planted centres: {centres:?}");
    for c in analysis.components.iter().take(4) {
        let peak = c.vertex_change.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i).unwrap();
        println!(
            "rank {} dim {}: distance {:.3}, largest change at ({:.2}, {:.2}), C centre at ({:.2}, {:.2}), support {} vertices",
            c.summary.rank,
            c.summary.dim,
            c.summary.distance,
            p[peak][0],
            p[peak][1],
            p[c.summary.center][0],
            p[c.summary.center][1],
            c.summary.support_size
        );
    }
}

fn profile(obj: &str, shapes: usize, steps: usize) {
    let mesh = meshdeco::mesh::load_mesh(std::path::Path::new(obj)).unwrap_or_else(|e| panic!("{obj}: {e}"));
    let (n, faces) = (mesh.n_vertices(), mesh.faces);
    let nb = NeighborIndex::from_faces(n, &faces).expect("mesh");
    let dist = HopDistances::new(&nb);
    let mut rng = Rng::new(1);
    let mut feats = Features::zeros(shapes, n, 9);
    for v in feats.data.iter_mut() {
        *v = rng.uniform() * 1.9 - 0.95;
    }
    let data = TrainingData::from_features(&feats).expect("finite");
    let cfg = AutoencoderConfig { components: 50, ..Default::default() };
    let mut t = Trainer::new(cfg, &data, &nb, &dist).expect("valid config");
    for _ in 0..3 {
        t.step().expect("step");
    }
    let mut sum = [0.0; 4];
    let t0 = Instant::now();
    for _ in 0..steps {
        t.step().expect("step");
        let s = t.last_step_timings();
        for (a, b) in sum.iter_mut().zip([s.snapshot, s.support, s.forward_backward, s.optimizer]) {
            *a += b;
        }
    }
    let per_step = t0.elapsed().as_secs_f64() / steps as f64;
    let ms = |v: f64| v / steps as f64 * 1e3;
    println!(
        "N = {n}, {shapes} shapes, K = 50: {:.2} ms/step (snapshot {:.2}, support maps {:.2}, forward/backward {:.2}, update: Adam and the streamed ∂L/∂C {:.2})",
        per_step * 1e3,
        ms(sum[0]),
        ms(sum[1]),
        ms(sum[2]),
        ms(sum[3])
    );
    let ck = std::env::temp_dir().join(format!("ae_profile_{}.mdae", std::process::id()));
    let t1 = Instant::now();
    t.save_checkpoint(&ck).expect("checkpoint");
    println!(
        "checkpoint: {:.1} ms, {:.1} MB",
        t1.elapsed().as_secs_f64() * 1e3,
        std::fs::metadata(&ck).map(|m| m.len()).unwrap_or(0) as f64 / 1e6
    );
    let t1 = Instant::now();
    let _ = Trainer::resume(&ck, t.config().clone(), &data, &nb, &dist).expect("resume");
    println!("resume: {:.1} ms", t1.elapsed().as_secs_f64() * 1e3);
    let _ = std::fs::remove_file(&ck);
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--profile") {
        let obj = args.get(1).cloned().unwrap_or_else(|| "../shared/data/scape/1.obj".into());
        let shapes = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(36);
        let steps = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(50);
        profile(&obj, shapes, steps);
    } else {
        demo(args.first().and_then(|s| s.parse().ok()).unwrap_or(1500));
    }
}
