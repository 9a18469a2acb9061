//! Integration tests of the mesh autoencoder: hand-written gradients against Burn autodiff,
//! training on a synthetic problem with planted local deformations, resume equivalence,
//! NaN safety and save/load.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use burn::tensor::{Device, Tensor};
use meshdeco::nn::engine::{self, Grads, Weights, Workspace};
use meshdeco::nn::kernels::padded_width;
use meshdeco::nn::loss::{SupportMaps, reference_loss};
use meshdeco::nn::model::NeighborTensors;
use meshdeco::nn::rng::Rng;
use meshdeco::nn::training::feature_error;
use meshdeco::nn::{Autoencoder, AutoencoderConfig, HopDistances, NeighborIndex, RunOptions, Trainer, TrainingData};
use meshdeco::representation::Features;

mod common;
use common::unit_grid as grid;

fn random_features(n_frames: usize, n: usize, amp: f64, seed: u64) -> Features {
    let mut rng = Rng::new(seed);
    let mut f = Features::zeros(n_frames, n, 9);
    for v in f.data.iter_mut() {
        *v = (rng.uniform() * 2.0 - 1.0) * amp;
    }
    f
}

/// Ten shapes: two planted localized bumps (around vertices `c1`, `c2`) whose amplitudes vary
/// independently across the shapes ([`common::planted_bumps`]).
fn planted(nx: usize, ny: usize) -> common::PlantedBumps {
    common::planted_bumps(nx, ny, 10, 11)
}

fn rel_err(a: &[f32], b: &[f32]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>().sqrt();
    let den: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum::<f64>().sqrt();
    num / den.max(1e-30)
}

fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_into_vec_as::<f32>().unwrap()
}

fn flat9(a: &[[f64; 9]; 9]) -> Vec<f32> {
    a.iter().flatten().map(|&v| v as f32).collect()
}

fn gradient_check(layers: usize, lambda_code: f64) {
    gradient_check_weighted(layers, lambda_code, false);
}

/// With `weighted`, every vertex's feature error is weighted (`feature_weights`): 0.05 to 1,
/// unevenly, in both the hand pass and Burn's graph.
fn gradient_check_weighted(layers: usize, lambda_code: f64, weighted: bool) {
    let (_, faces) = grid(7, 6);
    let n = 42;
    let nb = NeighborIndex::from_faces(n, &faces).unwrap();
    let dist = HopDistances::new(&nb);
    let feats = random_features(3, n, 0.9, 5);
    let data = TrainingData::from_features(&feats).unwrap();
    // Larger init and a small θ so that every term and every activation regime is exercised.
    let cfg = AutoencoderConfig {
        components: 4,
        layers,
        init_std: 0.35,
        theta: 0.05,
        d_min: 0.2,
        d_max: 0.6,
        seed: 3,
        lambda_code,
        ..Default::default()
    };
    cfg.validate().unwrap();
    #[allow(deprecated)]
    let device = Device::ndarray().autodiff();
    let module = cfg.init(n, &device);

    // Hand-written pass.
    let w = Weights::from_module(&module).unwrap();
    let mut maps = SupportMaps::new(cfg.components, n);
    maps.update(&w.c, &cfg, &dist).unwrap();
    let idx: Vec<usize> = (0..3).collect();
    let x = data.batch_vcb(&idx).unwrap();
    let mut ws = Workspace::new(n, cfg.components, layers, padded_width(3));
    let vertex_w: Option<Vec<f32>> =
        weighted.then(|| (0..n).map(|i| 0.05 + 0.95 * ((i * 7) % 11) as f32 / 10.0).collect());
    ws.set_feature_weights(vertex_w.as_ref().map(|v| v.as_slice().into()));
    let mut g = Grads { layers: Vec::new(), c: Vec::new() };
    let terms = engine::loss_and_grad(&mut ws, &w, &nb, &x, None, 3, &maps, &cfg, &mut g, None);
    if let Some(v) = &vertex_w {
        // The weighted error is the weighted sum of the per-vertex errors of the decoding, in the
        // loss and in `feature_error` (the validation error).
        let mut plain = Workspace::new(n, cfg.components, layers, padded_width(3));
        let unweighted = feature_error(&mut plain, &w, &nb, &x, 3);
        let bp = plain.width();
        let mut want = 0.0f64;
        for (row, (o, t)) in plain.output().chunks_exact(bp).zip(x.chunks_exact(bp)).enumerate() {
            want += (0..3).map(|j| f64::from(v[row / 9]) * f64::from(o[j] - t[j]).powi(2)).sum::<f64>();
        }
        want /= 3.0;
        assert!(want < 0.9 * unweighted, "the weights change the error: {want} vs {unweighted}");
        assert!((terms.reconstruction - want).abs() <= 1e-5 * want, "{} vs {want}", terms.reconstruction);
        let mut weighted = Workspace::new(n, cfg.components, layers, padded_width(3));
        weighted.set_feature_weights(Some(v.as_slice().into()));
        let fe = feature_error(&mut weighted, &w, &nb, &x, 3);
        assert!((fe - want).abs() <= 1e-5 * want, "feature_error {fe} vs {want}");
    }
    assert!(terms.hinge > 0.0 && terms.sparsity > 0.0 && terms.reconstruction > 0.0, "{terms:?}");
    // The code term (`lambda_code`): the last lane plays the rest shape.
    assert_eq!(terms.code > 0.0, lambda_code > 0.0, "{terms:?}");

    // Burn autodiff reference.
    let nbt = NeighborTensors::new(&nb, &device);
    let xt = data.batch_tensor(&idx, &device).unwrap();
    let (loss, ref_terms) = reference_loss(&module, xt, &nbt, &maps, &cfg, vertex_w.as_deref());
    let grads = loss.backward();
    for (a, b) in [
        (terms.total, ref_terms.total),
        (terms.reconstruction, ref_terms.reconstruction),
        (terms.sparsity, ref_terms.sparsity),
        (terms.hinge, ref_terms.hinge),
        (terms.code, ref_terms.code),
    ] {
        assert!((a - b).abs() <= 1e-5 * b.abs().max(1e-3), "loss terms differ: hand {terms:?} vs burn {ref_terms:?}");
    }
    let gc: Vec<f32> = module.components.iter().flat_map(|p| to_vec(p.val().grad(&grads).unwrap())).collect();
    let e = rel_err(&g.c, &gc);
    eprintln!("L = {layers}: loss {terms:?}; C gradient relative error {e:.2e}");
    assert!(e <= 1e-4, "components gradient relative error {e}");
    for (l, layer) in module.layers.iter().enumerate() {
        let checks = [
            ("weight_point", flat9(&g.layers[l].wp), to_vec(layer.weight_point.val().grad(&grads).unwrap())),
            ("weight_neighbor", flat9(&g.layers[l].wn), to_vec(layer.weight_neighbor.val().grad(&grads).unwrap())),
            ("bias", g.layers[l].b.iter().map(|&v| v as f32).collect(), to_vec(layer.bias.val().grad(&grads).unwrap())),
            (
                "decoder_bias",
                g.layers[l].bd.iter().map(|&v| v as f32).collect(),
                to_vec(layer.decoder_bias.val().grad(&grads).unwrap()),
            ),
        ];
        for (name, hand, burn) in checks {
            let e = rel_err(&hand, &burn);
            eprintln!("L = {layers}: layer {l} {name} gradient relative error {e:.2e}");
            assert!(e <= 1e-4, "layer {l} {name}: relative error {e}\nhand {hand:?}\nburn {burn:?}");
        }
    }
}

#[test]
fn hand_gradients_match_burn_autodiff_one_layer() {
    gradient_check(1, 0.0);
}

#[test]
fn hand_gradients_match_burn_autodiff_three_layers() {
    gradient_check(3, 0.0);
}

/// The code term's gradient (`lambda_code`: every code pulled towards the last lane's, the
/// rest shape's, and that one towards them) against Burn autodiff of the same loss.
#[test]
fn hand_gradients_match_burn_autodiff_with_the_code_term() {
    gradient_check(1, 0.7);
}

/// `feature_weights`: the hand engine's weighted feature error and its gradients are Burn's.
#[test]
fn hand_gradients_match_burn_autodiff_with_feature_weights() {
    gradient_check_weighted(2, 0.0, true);
}

#[test]
fn hand_inference_matches_burn_forward() {
    let (_, faces) = grid(6, 5);
    let n = 30;
    let nb = NeighborIndex::from_faces(n, &faces).unwrap();
    let feats = random_features(5, n, 0.9, 8);
    let cfg = AutoencoderConfig { components: 3, layers: 2, init_std: 0.3, seed: 4, ..Default::default() };
    #[allow(deprecated)]
    let device = Device::ndarray();
    let module = cfg.init(n, &device);
    let data = TrainingData::from_features(&feats).unwrap();
    let nbt = NeighborTensors::new(&nb, &device);
    let (xh, z) = module.forward(data.batch_tensor(&[0, 1, 2, 3, 4], &device).unwrap(), &nbt);
    let (xh, z) = (to_vec(xh), to_vec(z));
    let ae = Autoencoder::new(cfg, module, nb).unwrap();
    let codes = ae.encode(&feats).unwrap();
    let zf: Vec<f32> = codes.iter().flatten().map(|&v| v as f32).collect();
    assert!(rel_err(&zf, &z) < 1e-5, "codes differ");
    let rec = ae.decode(&codes).unwrap();
    let rf: Vec<f32> = rec.data.iter().map(|&v| v as f32).collect();
    assert!(rel_err(&rf, &xh) < 1e-5, "reconstructions differ");
}

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-ae-{}-{}", name, std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn training_recovers_planted_local_deformations() {
    let (p, faces, feats, centres) = planted(15, 14);
    let n = p.len();
    let nb = NeighborIndex::from_faces(n, &faces).unwrap();
    let dist = HopDistances::new(&nb);
    let data = TrainingData::from_features(&feats).unwrap();
    let cfg = AutoencoderConfig { components: 4, iterations: 1500, learning_rate: 1e-2, seed: 1, ..Default::default() };
    let energy: f64 = feats.data.iter().map(|v| v * v).sum::<f64>() / feats.n_frames as f64;
    let mut trainer = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
    let mut losses = Vec::new();
    let summary = trainer.run(&RunOptions::default(), |r| losses.push(r.loss)).unwrap();
    assert_eq!(summary.iterations_done, 1500);
    assert!(!summary.stopped);
    let first = losses[0];
    let last = *losses.last().unwrap();
    assert!(last.total < 0.2 * first.total, "loss did not decrease enough: {first:?} → {last:?}");
    let rel = last.reconstruction / energy;
    eprintln!("planted: loss {:.4} → {:.4}, relative reconstruction error {rel:.5}", first.total, last.total);
    assert!(rel < 0.05, "relative reconstruction error {rel} (energy per shape {energy})");

    // The two strongest components sit on the two planted regions.
    let ae = trainer.into_model().unwrap();
    let analysis = ae.analyze_components(&feats, 0).unwrap();
    let mut hit = [false; 2];
    for comp in analysis.components.iter().take(2) {
        let peak = comp.vertex_change.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i).unwrap();
        for (j, &c) in centres.iter().enumerate() {
            if meshdeco::mesh::dist(p[peak], p[c]) < 0.2 {
                hit[j] = true;
            }
        }
    }
    assert!(
        hit[0] && hit[1],
        "top components do not localize on the planted bumps: {:?}",
        analysis.components.iter().map(|c| (c.summary.dim, c.summary.distance, c.summary.center)).collect::<Vec<_>>()
    );

    // Synthesis with weight 1 on a dimension decodes its extreme shape; weight 0 the reference.
    let top = &analysis.components[0];
    let s1 = ae.synthesize(&analysis, &[(top.summary.dim, 1.0)]).unwrap();
    let d1: f64 = s1.data.iter().zip(&top.features).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(d1 < 1e-6, "synthesis at weight 1 differs from the extreme by {d1}");
    let s0 = ae.synthesize(&analysis, &[(top.summary.dim, 0.0)]).unwrap();
    let d0: f64 = s0.data.iter().zip(&analysis.reference_features).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(d0 < 1e-6);
    // Interpolation ends at the decoded end codes.
    let z = ae.encode(&feats).unwrap();
    let interp = ae.interpolate(&z[1], &z[2], 5).unwrap();
    let ends = ae.decode(&[z[1].clone(), z[2].clone()]).unwrap();
    assert_eq!(interp.frame(0), ends.frame(0));
    assert_eq!(interp.frame(4), ends.frame(1));

    // Save / load round trip; a different mesh is refused.
    let dir = tmp_dir("saveload");
    ae.save(&dir).unwrap();
    let loaded = Autoencoder::load(&dir, nb.clone()).unwrap();
    assert_eq!(loaded.encode(&feats).unwrap(), z);
    let (_, other_faces) = grid(14, 15);
    let other = NeighborIndex::from_faces(n, &other_faces).unwrap();
    assert!(Autoencoder::load(&dir, other).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every parameter as one vector: `C`, then each layer's point and neighbour weights and biases.
fn flat_weights(w: &Weights) -> Vec<f32> {
    let mut v = w.c.clone();
    for l in &w.layers {
        v.extend(l.wp.iter().flatten());
        v.extend(l.wn.iter().flatten());
        v.extend(l.b);
        v.extend(l.bd);
    }
    v
}

fn params(t: &Trainer) -> Vec<f32> {
    flat_weights(&Weights::from_module(t.module()).unwrap())
}

/// The planted 9 × 8 grid problem: neighbour index, hop distances, training data.
fn planted_problem() -> (NeighborIndex, HopDistances, TrainingData) {
    let (_, faces, feats, _) = planted(9, 8);
    let nb = NeighborIndex::from_faces(72, &faces).unwrap();
    let dist = HopDistances::new(&nb);
    (nb, dist, TrainingData::from_features(&feats).unwrap())
}

/// Mini-batches so that the generator state matters too; K = 10 makes two row blocks of C (two
/// Adam instances for them).
fn resume_config() -> AutoencoderConfig {
    AutoencoderConfig {
        components: 10,
        layers: 2,
        iterations: 40,
        batch_size: Some(6),
        checkpoint_every: 7,
        learning_rate: 5e-3,
        // A decaying step size and a non-default β2: resume must reproduce both.
        learning_rate_final: Some(5e-4),
        beta2: 0.99,
        seed: 9,
        ..Default::default()
    }
}

/// `learning_rate_norm`: a training set whose features are larger than it trains as if every
/// step size (first and last) were multiplied by `learning_rate_norm / norm`, and one whose
/// features are smaller trains as without it.
#[test]
fn learning_rate_norm_scales_every_step_size_by_the_features_norm() {
    let (nb, dist, data) = planted_problem();
    let norm = meshdeco::nn::training::feature_norm(&data).unwrap();
    let mut sum = 0.0;
    for s in 0..data.n_shapes() {
        sum += data.shape(s).unwrap().iter().map(|&x| f64::from(x) * f64::from(x)).sum::<f64>();
    }
    let expected = (sum / data.n_shapes() as f64).sqrt();
    assert!((norm - expected).abs() <= 1e-9 * expected, "feature norm {norm} vs {expected}");
    let base = AutoencoderConfig { iterations: 12, checkpoint_every: 0, ..resume_config() };
    let run = |cfg: AutoencoderConfig| {
        let mut t = Trainer::new(cfg, &data, &nb, &dist).unwrap();
        let scale = t.learning_rate_scale();
        t.run(&RunOptions::default(), |_| {}).unwrap();
        (scale, params(&t))
    };
    let (s_scaled, scaled) = run(AutoencoderConfig { learning_rate_norm: norm / 4.0, ..base.clone() });
    assert!((s_scaled - 0.25).abs() < 1e-12, "scale {s_scaled}");
    let (s_plain, by_hand) = run(AutoencoderConfig {
        learning_rate: base.learning_rate * 0.25,
        learning_rate_final: base.learning_rate_final.map(|f| f * 0.25),
        learning_rate_norm: 0.0,
        ..base.clone()
    });
    assert_eq!(s_plain, 1.0);
    let diff = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(diff(&scaled, &by_hand) <= 1e-6, "scaled run vs quarter rates: {}", diff(&scaled, &by_hand));
    let (s_small, small) = run(AutoencoderConfig { learning_rate_norm: norm * 2.0, ..base.clone() });
    assert_eq!(s_small, 1.0);
    let (_, unscaled) = run(AutoencoderConfig { learning_rate_norm: 0.0, ..base });
    assert_eq!(small, unscaled, "features below learning_rate_norm: the run is the unscaled one");
    assert!(diff(&scaled, &unscaled) > 1e-4, "the scaled run must differ: {}", diff(&scaled, &unscaled));
}

/// The optimiser's settings reach both Adams (Burn's, for the layers, and the fused one, for
/// `C`) and the schedule's step size reaches every step, for both engines. With β1 = β2 = 0,
/// Adam's step is `lr_t·g/(|g| + ε)` whatever the gradient, so with ε = 10⁻²⁰ every parameter
/// moves by exactly the step size of its step, or not at all where its gradient is 0. A β left
/// at Burn's default would mix in an earlier step's gradient (mini-batches of 2 of the 10
/// shapes make consecutive gradients differ); a step size off by a step of the cosine schedule,
/// or a scale, moves every parameter by the wrong amount. With ε = 10³ (far above any gradient
/// here) every move is well below the step size, which an ε left at its default would not give.
#[test]
fn adam_settings_and_step_sizes_reach_every_parameter() {
    use meshdeco::nn::config::Engine;
    let (nb, dist, data) = planted_problem();
    let base = AutoencoderConfig {
        components: 10,
        layers: 2,
        iterations: 6,
        batch_size: Some(2),
        learning_rate: 2e-3,
        learning_rate_final: Some(2e-4),
        beta1: 0.0,
        beta2: 0.0,
        epsilon: 1e-20,
        seed: 4,
        checkpoint_every: 0,
        ..Default::default()
    };
    for engine in [Engine::Hand, Engine::Graph] {
        let cfg = AutoencoderConfig { engine, ..base.clone() };
        let mut t = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
        assert_eq!(t.learning_rate_scale(), 1.0);
        let n_c = t.weights().c.len();
        assert_eq!(n_c, 10 * 9 * 72);
        let mut before = flat_weights(t.weights());
        assert_eq!(before.len() - n_c, 2 * (81 + 81 + 9 + 9));
        for step in 0..cfg.iterations {
            let lr = cfg.learning_rate_at(step);
            t.step().unwrap();
            let after = flat_weights(t.weights());
            let (mut moved, mut still) = ([0usize; 2], [0usize; 2]);
            for (i, (&a, &b)) in before.iter().zip(&after).enumerate() {
                let d = (f64::from(b) - f64::from(a)).abs();
                let part = usize::from(i >= n_c);
                if d == 0.0 {
                    still[part] += 1;
                    continue;
                }
                let tol = 1e-4 * lr + 2.0 * f64::from(f32::EPSILON) * f64::from(a.abs().max(b.abs()));
                assert!(
                    (d - lr).abs() <= tol,
                    "{engine:?}, step {step}: parameter {i} ({}) moved {d:.6e}, not the step size {lr:.6e}",
                    if part == 0 { "C" } else { "a layer's" }
                );
                moved[part] += 1;
            }
            eprintln!(
                "{engine:?}, step {step}: step size {lr:.3e}; C {} moved, {} still; layers {} moved, {} still",
                moved[0], still[0], moved[1], still[1]
            );
            assert!(moved[0] > still[0] && moved[1] > still[1], "{engine:?}, step {step}: most parameters must move");
            before = after;
        }
        // ε well above every gradient: every move is a small fraction of the step size.
        let mut t = Trainer::new(AutoencoderConfig { epsilon: 1e3, ..cfg.clone() }, &data, &nb, &dist).unwrap();
        let before = flat_weights(t.weights());
        t.step().unwrap();
        let largest =
            before.iter().zip(&flat_weights(t.weights())).map(|(a, b)| f64::from((b - a).abs())).fold(0.0, f64::max);
        eprintln!("{engine:?}, ε = 1e3: largest move {largest:.3e} against the step size {:.3e}", cfg.learning_rate);
        assert!(
            largest > 0.0 && largest < 0.1 * cfg.learning_rate,
            "{engine:?}: ε = 1e3 must shrink every move: {largest:e}"
        );
    }
}

#[test]
fn resume_reproduces_the_uninterrupted_run() {
    let (nb, dist, data) = planted_problem();
    let cfg = resume_config();
    let mut full = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
    full.run(&RunOptions::default(), |_| {}).unwrap();
    let expected = params(&full);

    let dir = tmp_dir("resume");
    let ck = dir.join("checkpoint.mdae");
    let stop = Arc::new(AtomicBool::new(false));
    let opts = RunOptions { checkpoint: Some(ck.clone()), stop: Some(stop.clone()), ..Default::default() };
    let mut first = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
    let s = first
        .run(&opts, |r| {
            if r.iteration == 20 {
                stop.store(true, Ordering::SeqCst);
            }
        })
        .unwrap();
    assert!(s.stopped);
    assert_eq!(s.iterations_done, 20);
    drop(first);
    assert!(ck.exists());
    assert!(!dir.join("checkpoint.mdae.tmp").exists());
    stop.store(false, Ordering::SeqCst);
    let mut resumed = Trainer::resume(&ck, cfg.clone(), &data, &nb, &dist).unwrap();
    assert_eq!(resumed.iteration(), 20);
    let s = resumed.run(&opts, |_| {}).unwrap();
    assert_eq!(s.iterations_done, 40);
    let got = params(&resumed);
    let max_diff = expected.iter().zip(&got).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    eprintln!("resume: max parameter difference {max_diff}");
    assert!(max_diff <= 1e-6, "resumed run differs by {max_diff}");

    // A checkpoint with other hyperparameters is refused.
    let other = AutoencoderConfig { components: 11, ..cfg };
    assert!(Trainer::resume(&ck, other, &data, &nb, &dist).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A run holding out validation shapes keeps its best validation step; the checkpoint holds that
/// step, so a run interrupted after it and resumed keeps the same step and ends with the same
/// model as the uninterrupted run (before checkpoints held it, the resumed run chose among the
/// steps after the interruption).
#[test]
fn resume_keeps_the_best_validation_step_from_before_the_interruption() {
    let (nb, dist, data) = planted_problem();
    // Held-out shapes unlike the training shapes: their error is lowest early.
    let val = TrainingData::from_features(&random_features(4, 72, 0.5, 17)).unwrap();
    let cfg = AutoencoderConfig { validation: 4, validate_every: 2, ..resume_config() };
    let mut full = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap().with_validation(&val).unwrap();
    let s_full = full.run(&RunOptions::default(), |_| {}).unwrap();
    let (best_it, best_err) = s_full.best.expect("a best validation step");
    eprintln!("uninterrupted: best validation step {best_it} (error {best_err})");
    assert!(best_it < 20, "the fixture's best step ({best_it}) must come before the interruption at 20");
    let expected = flat_weights(full.into_model().unwrap().weights());

    let dir = tmp_dir("resume-best");
    let ck = dir.join("checkpoint.mdae");
    let stop = Arc::new(AtomicBool::new(false));
    let opts = RunOptions { checkpoint: Some(ck.clone()), stop: Some(stop.clone()), ..Default::default() };
    let mut first = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap().with_validation(&val).unwrap();
    first
        .run(&opts, |r| {
            if r.iteration == 20 {
                stop.store(true, Ordering::SeqCst);
            }
        })
        .unwrap();
    drop(first);
    stop.store(false, Ordering::SeqCst);
    let mut resumed = Trainer::resume(&ck, cfg.clone(), &data, &nb, &dist).unwrap().with_validation(&val).unwrap();
    let s = resumed.run(&opts, |_| {}).unwrap();
    assert_eq!(s.iterations_done, 40);
    assert_eq!(s.best.map(|b| b.0), Some(best_it), "the resumed run's best step");
    let got = flat_weights(resumed.into_model().unwrap().weights());
    let max_diff = expected.iter().zip(&got).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(max_diff <= 1e-6, "the resumed run's kept model differs by {max_diff}");
    // Resumed once more with no step left (the finished checkpoint): the same kept model.
    let done = Trainer::resume(&ck, cfg, &data, &nb, &dist).unwrap().with_validation(&val).unwrap();
    let again = flat_weights(done.into_model().unwrap().weights());
    assert_eq!(again, got);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn nan_never_reaches_a_checkpoint() {
    let (_, faces) = grid(6, 6);
    let n = 36;
    let nb = NeighborIndex::from_faces(n, &faces).unwrap();
    let dist = HopDistances::new(&nb);

    // Non-finite input: a clear error naming the location.
    let mut feats = random_features(4, n, 0.9, 2);
    feats.data[(2 * n + 7) * 9 + 4] = f64::NAN;
    let err = TrainingData::from_features(&feats).unwrap_err().to_string();
    assert!(err.contains("frame 2") && err.contains("vertex 7") && err.contains("channel 4"), "{err}");

    // Finite but absurd input overflows the loss: the run stops before writing anything.
    let mut feats = random_features(4, n, 0.9, 2);
    feats.data[5] = 1e30;
    let data = TrainingData::from_features(&feats).unwrap();
    let dir = tmp_dir("nan");
    let ck = dir.join("checkpoint.mdae");
    let cfg = AutoencoderConfig { components: 3, iterations: 5, checkpoint_every: 1, ..Default::default() };
    let mut t = Trainer::new(cfg, &data, &nb, &dist).unwrap();
    let opts = RunOptions { checkpoint: Some(ck.clone()), stop: None, ..Default::default() };
    let err = t.run(&opts, |_| {}).unwrap_err().to_string();
    assert!(err.contains("not finite") && err.contains("iteration 1"), "{err}");
    assert!(!ck.exists(), "a checkpoint was written for a diverged run");

    // A diverging run (absurd learning rate) errors; whatever checkpoint is on disk is finite.
    let feats = random_features(4, n, 0.9, 3);
    let data = TrainingData::from_features(&feats).unwrap();
    let cfg = AutoencoderConfig {
        components: 3,
        iterations: 50,
        checkpoint_every: 1,
        learning_rate: 1e30,
        ..Default::default()
    };
    let mut t = Trainer::new(cfg, &data, &nb, &dist).unwrap();
    let res = t.run(&opts, |_| {});
    assert!(res.is_err(), "expected divergence, got {res:?}");
    eprintln!("divergence: {} (checkpoint on disk: {})", res.unwrap_err(), ck.exists());
    if ck.exists() {
        let ae = Autoencoder::from_checkpoint(&ck, nb.clone()).unwrap();
        assert!(ae.components_matrix().iter().all(|v| v.is_finite()));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn graph_engine_follows_the_hand_engine() {
    use meshdeco::nn::config::{ComputeDevice, Engine};
    let (nb, dist, data) = planted_problem();
    let cfg = AutoencoderConfig { iterations: 5, seed: 3, ..resume_config() };
    let mut hand = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
    let graph_cfg = AutoencoderConfig { engine: Engine::Graph, ..cfg.clone() };
    let mut graph = Trainer::new(graph_cfg.clone(), &data, &nb, &dist).unwrap();
    assert_eq!(params(&hand), params(&graph), "same seed, same initial parameters");
    for step in 0..5 {
        let a = hand.step().unwrap();
        let b = graph.step().unwrap();
        let rel = (a.total - b.total).abs() / a.total.abs().max(1e-12);
        assert!(rel < 1e-4, "step {step}: hand loss {} vs graph loss {}", a.total, b.total);
    }
    let (pa, pb) = (params(&hand), params(&graph));
    let scale = pa.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let diff = pa.iter().zip(&pb).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    eprintln!("graph vs hand after 5 steps: max parameter difference {diff} (max |p| {scale})");
    assert!(diff <= 1e-4 * scale.max(1.0), "engines diverged by {diff}");
    // A checkpoint of one engine resumes with the other.
    let dir = tmp_dir("graph-engine");
    let ck = dir.join("checkpoint.mdae");
    graph.save_checkpoint(&ck).unwrap();
    let resumed = Trainer::resume(&ck, cfg.clone(), &data, &nb, &dist).unwrap();
    assert_eq!(params(&resumed), pb);
    let _ = std::fs::remove_dir_all(&dir);
    // wgpu is refused with a message naming the key (this build has no wgpu feature, or the
    // hand engine was asked to run on it).
    let bad = AutoencoderConfig { device: ComputeDevice::Wgpu, ..cfg };
    let err = Trainer::new(bad, &data, &nb, &dist).err().expect("hand engine on wgpu must be refused").to_string();
    assert!(err.contains("device"), "{err}");
}

/// `stall_restarts`: a step size too large for the data (0.2 on the tube) saturates the decoder
/// and the error stays above the first step's; without restarts the run ends there (train Erms
/// ~480), with the default two it starts again at 0.1 and then 0.05, trains (~28), keeps one
/// log of the run that counted and stores the rate it used; `--resume` continues that run.
#[test]
fn a_stalled_run_restarts_with_halved_step_sizes() {
    use meshdeco::config::Config;
    use meshdeco::pipeline::{Silent, TrainOptions, train};
    let cfg = |restarts: &str, iterations: usize| {
        Config::from_toml(&format!(
            "name = \"tube-stall\"\n[data]\npath = \"synthetic:tube\"\ntrain = \"every:3\"\ntest = \"rest\"\n\
             [method]\nkind = \"autoencoder\"\ncomponents = 3\niterations = {iterations}\nfit_test = false\n\
             learning_rate = 0.2\nlearning_rate_final = 0.001\n{restarts}"
        ))
        .unwrap()
    };
    let (stuck_dir, dir) = (tmp_dir("stall-off"), tmp_dir("stall-default"));
    let stuck = train(&cfg("stall_restarts = 0\n", 300), &stuck_dir, &TrainOptions::default(), &mut Silent).unwrap();
    let run = train(&cfg("", 300), &dir, &TrainOptions::default(), &mut Silent).unwrap();
    let (e_stuck, e) = (stuck.metrics.train_erms, run.metrics.train_erms);
    eprintln!("tube, learning_rate 0.2: train Erms without restarts {e_stuck:.2}, with the default {e:.2}");
    assert!(e < 0.2 * e_stuck, "restarted {e} vs stalled {e_stuck}");
    let lr = |d: &std::path::Path| {
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("autoencoder.json")).unwrap()).unwrap();
        j["config"]["learning_rate"].as_f64().unwrap()
    };
    assert_eq!((lr(&stuck_dir), lr(&dir)), (0.2, 0.05), "two restarts halve the rate twice");
    let log = std::fs::read_to_string(dir.join("training.jsonl")).unwrap();
    assert_eq!(log.lines().filter(|l| l.contains("\"iteration\"")).count(), 300, "one log of the run that counted");
    let more = TrainOptions { resume: true, ..Default::default() };
    let resumed = train(&cfg("", 320), &dir, &more, &mut Silent).unwrap();
    assert!(resumed.metrics.train_erms < 0.2 * e_stuck, "{:?}", resumed.metrics.train_erms);
    assert_eq!(lr(&dir), 0.05, "the resumed run keeps the restart's rate");
    let bad = Config::from_toml(
        "[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"autoencoder\"\ncomponents = 3\nstall_restarts = 9\n",
    );
    assert!(bad.is_err_and(|e| e.to_string().contains("stall_restarts")));
    let _ = (std::fs::remove_dir_all(&stuck_dir), std::fs::remove_dir_all(&dir));
}

/// `feature_weights`: the trainer takes one weight in [0, 1] per vertex and refuses anything
/// else, naming what is wrong; with every weight 1 a run is the unweighted run, step for step;
/// with weights below 1 it is another run.
#[test]
fn feature_weights_reach_the_run_and_are_checked() {
    let (nb, dist, data) = planted_problem();
    let cfg = AutoencoderConfig { components: 4, iterations: 6, seed: 1, ..Default::default() };
    let fresh = || Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
    let e = fresh().with_feature_weights(&[1.0; 5]).err().expect("5 weights for 72 vertices").to_string();
    assert!(e.contains("5 feature weights") && e.contains("72"), "{e}");
    let mut bad = vec![1.0; 72];
    bad[9] = 1.5;
    let e = fresh().with_feature_weights(&bad).err().expect("a weight above 1").to_string();
    assert!(e.contains("vertex 9") && e.contains("1.5"), "{e}");
    bad[9] = f64::NAN;
    assert!(fresh().with_feature_weights(&bad).is_err(), "a NaN weight");
    let run = |w: Option<Vec<f64>>| {
        let mut t = fresh();
        if let Some(w) = w {
            t = t.with_feature_weights(&w).unwrap();
        }
        (0..6).map(|_| t.step().unwrap().reconstruction).collect::<Vec<f64>>()
    };
    let plain = run(None);
    assert_eq!(run(Some(vec![1.0; 72])), plain, "weights of 1 are the unweighted run");
    let half: Vec<f64> = (0..72).map(|i| if i % 2 == 0 { 0.5 } else { 1.0 }).collect();
    let weighted = run(Some(half));
    assert!(weighted[0] < 0.95 * plain[0], "the first step's error is weighted: {} vs {}", weighted[0], plain[0]);
}
