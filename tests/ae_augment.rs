//! The autoencoder's generalisation mechanisms (issue 17): augmentation in feature space
//! (`augment`, `augment_mix`, `augment_radius`) and the validation split that chooses the kept
//! step (`validation`, `validate_every`).

use meshdeco::nn::augment::{AugmentMix, Augmenter, mask};
use meshdeco::nn::config::Engine;
use meshdeco::nn::engine::{Weights, Workspace};
use meshdeco::nn::kernels::padded_width;
use meshdeco::nn::rng::Rng;
use meshdeco::nn::training::feature_error;
use meshdeco::nn::{AutoencoderConfig, HopDistances, NeighborIndex, RunOptions, Trainer, TrainingData};
use meshdeco::representation::Features;

mod common;

/// `frames` shapes on an `nx × ny` grid: two localized bumps with independent amplitudes.
fn planted(nx: usize, ny: usize, frames: usize, seed: u64) -> (NeighborIndex, Features) {
    let (p, f, feat, _) = common::planted_bumps(nx, ny, frames, seed);
    (NeighborIndex::from_faces(p.len(), &f).unwrap(), feat)
}

fn random_shapes(frames: usize, n: usize, seed: u64) -> TrainingData {
    let mut rng = Rng::new(seed);
    let mut f = Features::zeros(frames, n, 9);
    for v in f.data.iter_mut() {
        *v = rng.uniform() * 1.9 - 0.95;
    }
    TrainingData::from_features(&f).unwrap()
}

/// Per vertex, the blend parameter t with y = a + t (b − a) on all 9 channels, if one exists
/// (channels where a = b must have y = a).
fn blend_parameter(y: &[f32], a: &[f32], b: &[f32]) -> Option<f32> {
    let mut t: Option<f32> = None;
    for c in 0..9 {
        let d = b[c] - a[c];
        if d.abs() < 1e-2 {
            // Too close to tell t; y must still lie between a and b.
            if (y[c] - a[c]).abs() > d.abs() + 1e-5 {
                return None;
            }
            continue;
        }
        let tc = (y[c] - a[c]) / d;
        match t {
            None => t = Some(tc),
            Some(t0) if (t0 - tc).abs() > 1e-3 => return None,
            _ => {}
        }
    }
    Some(t.unwrap_or(0.0))
}

/// Finds the pair (a, b) of training shapes a synthetic shape blends, with its per-vertex t.
fn explain(y: &[f32], data: &TrainingData) -> Option<(usize, usize, Vec<f32>)> {
    let n = data.n_vertices();
    for a in 0..data.n_shapes() {
        for b in 0..data.n_shapes() {
            if a == b {
                continue;
            }
            let (xa, xb) = (data.shape(a).unwrap(), data.shape(b).unwrap());
            let ts: Option<Vec<f32>> = (0..n)
                .map(|i| blend_parameter(&y[i * 9..i * 9 + 9], &xa[i * 9..i * 9 + 9], &xb[i * 9..i * 9 + 9]))
                .collect();
            if let Some(ts) = ts {
                return Some((a, b, ts));
            }
        }
    }
    None
}

#[test]
fn mask_is_one_inside_zero_outside_and_monotone() {
    let (r, w) = (0.2f32, 0.1f32);
    assert_eq!(mask(0.0, r, w), 1.0);
    assert_eq!(mask(0.2, r, w), 1.0);
    assert_eq!(mask(0.3, r, w), 0.0);
    assert_eq!(mask(f32::INFINITY, r, w), 0.0);
    let mut prev = 1.0;
    for i in 0..=100 {
        let m = mask(0.2 + 0.1 * i as f32 / 100.0, r, w);
        assert!((0.0..=1.0).contains(&m) && m <= prev + 1e-7, "mask not monotone at step {i}: {m} after {prev}");
        prev = m;
    }
    assert!((mask(0.25, r, w) - 0.5).abs() < 1e-6, "smoothstep midpoint");
}

#[test]
fn synthetic_shapes_are_valid_blends_of_two_training_shapes() {
    let (nb, _) = planted(20, 20, 1, 1);
    let n = nb.n_vertices();
    let dist = HopDistances::new(&nb);
    let data = random_shapes(5, n, 3);
    let mut rng = Rng::new(4);
    for mix in [AugmentMix::Local, AugmentMix::Blend, AugmentMix::Mixed] {
        let aug = Augmenter::new(mix, [0.1, 0.3], n, &dist, 7).unwrap();
        let (mut inside, mut outside) = (0usize, 0usize);
        let (mut wholes, mut locals) = (0usize, 0usize);
        for draw in 0..40 {
            let mut y = vec![f32::NAN; n * 9];
            aug.draw(&|s| data.shape(s), data.n_shapes(), &mut rng, |row, v| y[row] = v).unwrap();
            assert!(y.iter().all(|v| v.is_finite() && v.abs() <= 0.95 + 1e-6), "{mix:?} draw {draw}: out of range");
            let (a, b, ts) =
                explain(&y, &data).unwrap_or_else(|| panic!("{mix:?} draw {draw}: not a blend of two shapes"));
            assert_ne!(a, b);
            assert!(ts.iter().all(|t| (-1e-3..=1.0 + 1e-3).contains(t)), "{mix:?}: blend outside [0, 1]");
            let spread = ts.iter().fold(0.0f32, |m, t| m.max((t - ts[0]).abs()));
            match mix {
                AugmentMix::Blend => {
                    assert!(spread < 1e-3, "a convex blend uses one t for all vertices (spread {spread})");
                }
                AugmentMix::Mixed => {
                    // Either kind: one t everywhere, or a transplanted region (t = 1) in t = 0.
                    let local = ts.iter().any(|t| (*t - 1.0).abs() < 1e-4) && ts.iter().any(|t| t.abs() < 1e-4);
                    assert!(spread < 1e-3 || local, "mixed draw {draw}: neither a blend nor a local mix");
                    if spread < 1e-3 {
                        wholes += 1;
                    } else {
                        locals += 1;
                    }
                }
                AugmentMix::Local => {
                    // A region of b (t = 1) inside the rest of a (t = 0).
                    inside += ts.iter().filter(|t| (**t - 1.0).abs() < 1e-4).count();
                    outside += ts.iter().filter(|t| t.abs() < 1e-4).count();
                    assert!(ts.iter().any(|t| (*t - 1.0).abs() < 1e-4), "local mix without a transplanted region");
                    assert!(ts.iter().any(|t| t.abs() < 1e-4), "local mix transplanted the whole shape");
                }
            }
        }
        if mix == AugmentMix::Mixed {
            assert!(wholes >= 8 && locals >= 8, "mixed: {wholes} blends and {locals} local mixes in 40 draws");
        }
        if mix == AugmentMix::Local {
            eprintln!("local mixes: {inside} vertices transplanted, {outside} kept (40 draws, {n} vertices)");
            assert!(inside < 40 * n && outside < 40 * n, "regions should be local: {inside} in, {outside} out");
        }
    }
}

#[test]
fn graph_engine_follows_the_hand_engine_with_augmentation() {
    let (nb, feats) = planted(9, 8, 10, 11);
    let dist = HopDistances::new(&nb);
    let data = TrainingData::from_features(&feats).unwrap();
    for batch_size in [None, Some(6)] {
        let cfg = AutoencoderConfig {
            components: 10,
            iterations: 5,
            learning_rate: 5e-3,
            batch_size,
            augment: 5,
            // The decorrelation term too (its hand gradient against Burn autodiff).
            lambda_orthogonal: 0.5,
            seed: 3,
            ..Default::default()
        };
        let mut hand = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
        let mut graph =
            Trainer::new(AutoencoderConfig { engine: Engine::Graph, ..cfg.clone() }, &data, &nb, &dist).unwrap();
        for step in 0..5 {
            let a = hand.step().unwrap();
            let b = graph.step().unwrap();
            let rel = (a.total - b.total).abs() / a.total.abs().max(1e-12);
            assert!(rel < 1e-4, "batch {batch_size:?} step {step}: hand loss {} vs graph loss {}", a.total, b.total);
        }
        // Augmentation changes the run (the synthetic shapes enter the loss).
        let mut plain = Trainer::new(AutoencoderConfig { augment: 0, ..cfg }, &data, &nb, &dist).unwrap();
        let mut differs = false;
        let mut again = Trainer::new(hand.config().clone(), &data, &nb, &dist).unwrap();
        for _ in 0..5 {
            let (p, q) = (plain.step().unwrap(), again.step().unwrap());
            differs |= (p.reconstruction - q.reconstruction).abs() > 1e-9;
        }
        assert!(differs, "augment = 5 gave the same losses as augment = 0");
    }
}

/// Validation error of the current parameters of a trainer.
fn val_error(t: &Trainer, nb: &NeighborIndex, val: &TrainingData) -> f64 {
    let w = Weights::from_module(t.module()).unwrap();
    let b = val.n_shapes();
    let mut ws = Workspace::new(nb.n_vertices(), t.config().components, t.config().layers, padded_width(b));
    feature_error(&mut ws, &w, nb, &val.batch_vcb_width(&(0..b).collect::<Vec<_>>(), padded_width(b)).unwrap(), b)
}

#[test]
fn validation_keeps_the_step_with_the_lowest_validation_error() {
    let (nb, feats) = planted(9, 8, 12, 5);
    let dist = HopDistances::new(&nb);
    let all = TrainingData::from_features(&feats).unwrap();
    let (fit, val, held) = all.split_validation(3).unwrap();
    assert_eq!(held, vec![2, 6, 10], "evenly spaced held-out shapes");
    assert_eq!((fit.n_shapes(), val.n_shapes()), (9, 3));
    assert_eq!(val.shape(1).unwrap(), all.shape(6).unwrap());
    assert!(all.split_validation(12).is_err() && all.split_validation(0).is_err());
    // A large constant step makes the validation error go up and down.
    let cfg = AutoencoderConfig {
        components: 6,
        iterations: 110,
        learning_rate: 3e-2,
        beta2: 0.99,
        validation: 3,
        validate_every: 10,
        seed: 2,
        ..Default::default()
    };
    // The same run stepped by hand, measuring where `run` measures.
    let mut manual = Trainer::new(cfg.clone(), &fit, &nb, &dist).unwrap();
    let mut history = Vec::new();
    for it in 1..=cfg.iterations {
        manual.step().unwrap();
        if it % cfg.validate_every == 0 {
            history.push((it, val_error(&manual, &nb, &val)));
        }
    }
    let last = history.last().unwrap().1;
    let best = history.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    eprintln!("validation errors: {history:?}; best {best:?}");

    let mut t = Trainer::new(cfg.clone(), &fit, &nb, &dist).unwrap().with_validation(&val).unwrap();
    let summary = t.run(&RunOptions::default(), |_| {}).unwrap();
    let (it, err) = summary.best.expect("a run with validation reports its best step");
    assert_eq!(it, best.0, "kept step");
    assert!((err - best.1).abs() <= 1e-9 * best.1.max(1.0), "kept error {err} vs {}", best.1);
    assert!(err <= last);
    // The returned model is the kept step's.
    let model = t.into_model().unwrap();
    let vf = Features {
        n_frames: 3,
        n_elements: nb.n_vertices(),
        width: 9,
        data: held.iter().flat_map(|&s| feats.frame(s).to_vec()).collect(),
    };
    let rec = model.reconstruct(&vf).unwrap();
    let sse: f64 = rec.data.iter().zip(&vf.data).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / 3.0;
    assert!((sse - err).abs() <= 1e-3 * err.max(1e-9), "model's validation error {sse} vs kept {err}");
    // On this run the last step is not the best (measured: 100 is), so keeping matters.
    assert_ne!(best.0, cfg.iterations, "the test needs a run whose last step is not its best");
    assert!(sse < last, "the kept model ({sse}) should beat the last step ({last})");
}

/// Central finite differences of `loss` against the analytic gradients `g` at `w`: the `top`
/// entries of C with the largest gradients, and W_point[0][0] of the first layer (5 %).
fn check_against_finite_differences(
    w: &Weights,
    g: &meshdeco::nn::engine::Grads,
    top: usize,
    loss: &mut dyn FnMut(&Weights) -> f64,
) {
    let mut order: Vec<usize> = (0..g.c.len()).collect();
    order.sort_by(|&i, &j| g.c[j].abs().total_cmp(&g.c[i].abs()));
    assert!(order.len() >= top, "only {} entries of C", order.len());
    for &i in order.iter().take(top) {
        let h = 1e-2 * w.c[i].abs().max(1e-2);
        let (mut wp, mut wm) = (w.clone(), w.clone());
        wp.c[i] += h;
        wm.c[i] -= h;
        let fd = (loss(&wp) - loss(&wm)) / (2.0 * h as f64);
        let an = g.c[i] as f64;
        assert!((fd - an).abs() <= 0.05 * an.abs().max(1e-3), "dL/dC[{i}]: analytic {an}, finite difference {fd}");
    }
    let h = 1e-3f32;
    let (mut wp, mut wm) = (w.clone(), w.clone());
    wp.layers[0].wp[0][0] += h;
    wm.layers[0].wp[0][0] -= h;
    let fd = (loss(&wp) - loss(&wm)) / (2.0 * h as f64);
    let an = g.layers[0].wp[0][0];
    assert!((fd - an).abs() <= 0.05 * an.abs().max(1e-3), "dL/dW_point[0][0]: analytic {an}, finite difference {fd}");
}

#[test]
fn least_squares_encoder_gradients_match_finite_differences() {
    use meshdeco::nn::config::EncoderKind;
    use meshdeco::nn::engine::{self, Grads};
    use meshdeco::nn::loss::SupportMaps;
    let (nb, feats) = planted(9, 8, 10, 11);
    let dist = HopDistances::new(&nb);
    let data = TrainingData::from_features(&feats).unwrap();
    // Reconstruction only (the encoder enters only there); a few steps away from the start.
    let cfg = AutoencoderConfig {
        components: 6,
        encoder: EncoderKind::LeastSquares,
        lambda1: 0.0,
        lambda2: 0.0,
        learning_rate: 1e-2,
        seed: 4,
        ..Default::default()
    };
    let mut t = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
    for _ in 0..30 {
        t.step().unwrap();
    }
    let mut w = Weights::from_module(t.module()).unwrap();
    w.least_squares = true;
    let (n, k, b) = (nb.n_vertices(), cfg.components, data.n_shapes());
    let bp = padded_width(b);
    let x = data.batch_vcb_width(&(0..b).collect::<Vec<_>>(), bp).unwrap();
    let mut maps = SupportMaps::new(k, n);
    maps.update(&w.c, &cfg, &dist).unwrap();
    let mut ws = Workspace::new(n, k, 1, bp);
    let mut g = Grads::default();
    let loss = |w: &Weights, ws: &mut Workspace| {
        let mut scratch = Grads::default();
        engine::loss_and_grad(ws, w, &nb, &x, None, b, &maps, &cfg, &mut scratch, None).total
    };
    engine::loss_and_grad(&mut ws, &w, &nb, &x, None, b, &maps, &cfg, &mut g, None);
    check_against_finite_differences(&w, &g, 8, &mut |w| loss(w, &mut ws));
    // The graph engine has only the tied encoder: refused by name.
    let bad = AutoencoderConfig { engine: Engine::Graph, ..cfg };
    assert!(bad.validate().unwrap_err().to_string().contains("encoder"));
}

#[test]
fn new_keys_are_checked_by_name_and_default_to_the_recommended_setting() {
    use meshdeco::config::{Config, MethodConfig};
    let base = "[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"autoencoder\"\n";
    let c = Config::from_toml(base).unwrap();
    let MethodConfig::Autoencoder(m) = &c.method else { panic!("kind") };
    let n = m.network_config();
    // A config file's default is meshdeco's recommended setting (issue 31): three synthetic
    // shapes and the decorrelation term on; validation off.
    assert_eq!((n.augment, n.validation, n.lambda_orthogonal), (3, 0, 10.0), "the recommended setting");
    assert_eq!(n, meshdeco::nn::config::AutoencoderConfig::recommended());
    let c = Config::from_toml(&format!(
        "{base}augment = 0
lambda_orthogonal = 0.0
"
    ))
    .unwrap();
    let MethodConfig::Autoencoder(m0) = &c.method else { panic!("kind") };
    assert_eq!((m0.network_config().augment, m0.network_config().lambda_orthogonal), (0, 0.0), "switched off");
    // Written out and read back, an explicit 0 stays 0 (not the default 3).
    let text = meshdeco::config::resolved_toml(&c.name, &c.data, c.method.to_table().unwrap(), &c.output);
    let back = Config::from_toml(&text).unwrap();
    let MethodConfig::Autoencoder(m1) = &back.method else { panic!("kind") };
    assert_eq!(m1.network_config().augment, 0, "{text}");
    assert_eq!(n.encoder, meshdeco::nn::config::EncoderKind::Tied);
    for (body, needle) in [
        ("augment_radius = [0.3, 0.1]", "method.augment_radius"),
        ("augment_radius = [0.0, 0.1]", "method.augment_radius"),
        ("lambda_orthogonal = -1.0", "method.lambda_orthogonal"),
        ("augment_mix = \"swap\"", "augment_mix"),
        ("input_noise = -0.1", "method.input_noise"),
        ("input_noise = 0.05\nengine = \"graph\"", "method.input_noise"),
        ("encoder = \"untied\"", "encoder"),
        ("validation = 2\nvalidate_every = 0", "method.validate_every"),
    ] {
        let e = Config::from_toml(&format!("{base}{body}\n")).unwrap_err().to_string();
        assert!(e.contains(needle), "`{needle}` not in `{e}`");
    }
    let c = Config::from_toml(&format!(
        "{base}augment = 3\naugment_mix = \"mixed\"\nvalidation = 2\nlambda_orthogonal = 10.0\nencoder = \"least-squares\"\ninput_noise = 0.05\n"
    ))
    .unwrap();
    let MethodConfig::Autoencoder(m) = &c.method else { panic!("kind") };
    let n = m.network_config();
    assert_eq!((n.augment, n.augment_mix, n.validation), (3, AugmentMix::Mixed, 2));
    assert_eq!(n.input_noise, 0.05);
    assert_eq!((n.lambda_orthogonal, n.validate_every), (10.0, 50));
}

/// `input_noise`: the encoder reads the noisy shapes, the loss compares the decoding with the
/// clean ones, and the gradients are those of that loss.
#[test]
fn denoising_compares_with_the_clean_shapes_and_its_gradients_match_finite_differences() {
    use meshdeco::nn::engine::{self, Grads};
    use meshdeco::nn::loss::SupportMaps;
    let (nb, feats) = planted(9, 8, 10, 11);
    let dist = HopDistances::new(&nb);
    let data = TrainingData::from_features(&feats).unwrap();
    let cfg = AutoencoderConfig {
        components: 6,
        lambda1: 0.0,
        lambda2: 0.0,
        learning_rate: 1e-2,
        input_noise: 0.05,
        seed: 4,
        ..Default::default()
    };
    let mut t = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
    let mut plain = Trainer::new(AutoencoderConfig { input_noise: 0.0, ..cfg.clone() }, &data, &nb, &dist).unwrap();
    let mut differs = false;
    for _ in 0..30 {
        let (a, b) = (t.step().unwrap(), plain.step().unwrap());
        assert!(a.total.is_finite());
        differs |= (a.reconstruction - b.reconstruction).abs() > 1e-9;
    }
    assert!(differs, "input_noise = 0.05 gave the same losses as no noise");
    let w = Weights::from_module(t.module()).unwrap();
    let (n, k, b) = (nb.n_vertices(), cfg.components, data.n_shapes());
    let bp = padded_width(b);
    let clean = data.batch_vcb_width(&(0..b).collect::<Vec<_>>(), bp).unwrap();
    let mut rng = Rng::new(9);
    let mut noisy = clean.clone();
    for row in noisy.chunks_exact_mut(bp) {
        for v in &mut row[..b] {
            *v += (0.05 * rng.normal()) as f32;
        }
    }
    let mut maps = SupportMaps::new(k, n);
    maps.update(&w.c, &cfg, &dist).unwrap();
    let mut ws = Workspace::new(n, k, 1, bp);
    let mut g = Grads::default();
    let terms = engine::loss_and_grad(&mut ws, &w, &nb, &noisy, Some(&clean), b, &maps, &cfg, &mut g, None);
    // The reconstruction term is the mean squared distance of the decoding to the clean shapes.
    let out = ws.output();
    let mut sse = 0.0f64;
    for (ro, rc) in out.chunks_exact(bp).zip(clean.chunks_exact(bp)) {
        for j in 0..b {
            sse += ((ro[j] - rc[j]) as f64).powi(2);
        }
    }
    let expect = sse / b as f64;
    assert!((terms.reconstruction - expect).abs() <= 1e-4 * expect, "{} vs {expect}", terms.reconstruction);
    // Not the noisy shapes': comparing with the input gives another value.
    let mut scratch = Grads::default();
    let self_target = engine::loss_and_grad(&mut ws, &w, &nb, &noisy, None, b, &maps, &cfg, &mut scratch, None);
    assert!((self_target.reconstruction - expect).abs() > 1e-3 * expect, "the target did not matter");
    let loss = |w: &Weights, ws: &mut Workspace| {
        let mut scratch = Grads::default();
        engine::loss_and_grad(ws, w, &nb, &noisy, Some(&clean), b, &maps, &cfg, &mut scratch, None).total
    };
    check_against_finite_differences(&w, &g, 6, &mut |w| loss(w, &mut ws));
}
