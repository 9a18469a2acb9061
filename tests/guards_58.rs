//! Guards of the newest code (issue 58), each by what a user sees:
//!
//! - the pose's landing correction reaches `spread` × the rest mesh's bounding-box diagonal in
//!   data units, on meshes of two sizes (`src/model/pose.rs`, where the option becomes a radius);
//! - the autoencoder trained from the feature cache (`data.cache`, a batch at a time) is the
//!   model trained in memory, bit for bit, with `batch_size` below the set, `data.train` named out
//!   of order and the network's own validation shapes held out (`src/nn/data.rs`: which cached
//!   frame a batch lane gets);
//! - `data.validation = "auto:P%"` holds out round(P % × the training frames) (at least one) of
//!   the training selection, never a test frame nor the first training frame, the same for the
//!   same seed and other frames for another (`src/config.rs`).

mod common;

use std::collections::BTreeSet;
use std::path::Path;

use common::{fresh_dir, meshdeco, output_text};
use meshdeco::config::Config;
use meshdeco::mesh::{self, TriMesh, Vec3};
use meshdeco::pipeline::{Silent, TrainOptions};

/// The synthetic bumps tube scaled by `scale` (all 40 frames), written as `s.npy` + `s.obj` into
/// `d`; returns the scaled frames.
fn scaled_bumps(d: &Path, scale: f64) -> (Vec<Vec<Vec3>>, Vec<[usize; 3]>) {
    let seq = meshdeco::synthetic::load("synthetic:bumps").unwrap();
    let frames: Vec<Vec<Vec3>> =
        seq.frames.iter().map(|f| f.iter().map(|p| [p[0] * scale, p[1] * scale, p[2] * scale]).collect()).collect();
    mesh::npy::write_npy(&d.join("s.npy"), &frames).unwrap();
    mesh::write::write_obj(&d.join("s.obj"), &TriMesh::new(frames[0].clone(), seq.faces.clone())).unwrap();
    (frames, seq.faces)
}

/// PCA (K 3) trained on the first 30 frames of the bumps tube scaled by `scale`, in `d/pca`;
/// returns the scaled frames and the model's directory.
fn bumps_pca(d: &Path, scale: f64) -> (Vec<Vec<Vec3>>, std::path::PathBuf) {
    let (frames, _) = scaled_bumps(d, scale);
    let cfg = Config::from_toml(&format!(
        "name = \"pca\"\n[data]\npath = \"{}\"\ntemplate = \"{}\"\ntrain = \"1-30\"\ntest = \"rest\"\n[method]\nkind = \"pca\"\ncomponents = 3\n",
        d.join("s.npy").display(),
        d.join("s.obj").display()
    ))
    .unwrap();
    let model = d.join("pca");
    meshdeco::pipeline::train(&cfg, &model, &TrainOptions::default(), &mut Silent).unwrap();
    (frames, model)
}

/// What one landed drag reaches on the bumps tube scaled by `scale`: (the largest straight-line
/// distance from the pin of a vertex the landing correction moved, the radius `spread` × the
/// rest's bounding-box diagonal, the landed pin's distance to its target / the drag).
fn landing_reach(scale: f64, spread: f64) -> (f64, f64, f64) {
    let d = fresh_dir("guards58", &format!("reach-{scale}"));
    let (frames, model) = bumps_pca(&d, scale);
    let rest = &frames[0];
    // A vertex no training frame moves: the linear model cannot move it, so the whole drag is
    // the landing correction's.
    let still = (0..rest.len())
        .min_by(|&a, &b| {
            let m = |v: usize| frames.iter().map(|f| mesh::dist(f[v], rest[v])).fold(0.0, f64::max);
            m(a).total_cmp(&m(b)).then(a.cmp(&b))
        })
        .unwrap();
    let (lo, hi) = mesh::bounding_box(rest);
    let diagonal = mesh::dist(lo, hi);
    // A drag of 1 % of the diagonal: the fold-free floor (3 × the residual) stays below the radius.
    let amount = 0.01 * diagonal;
    let p = rest[still];
    let t: Vec3 = [p[0], p[1], p[2] + amount];
    std::fs::write(d.join("c.json"), format!("{{\"{still}\": [{}, {}, {}]}}", t[0], t[1], t[2])).unwrap();
    let pose = |spread: &str, out: &str| {
        let o = meshdeco(&["pose", model.to_str().unwrap(), "-c", "c.json", "--out", out, "--spread", spread], &d);
        assert!(o.status.success(), "pose --spread {spread}: {}", output_text(&o));
        mesh::load_mesh(&d.join(out)).unwrap().positions
    };
    let own = pose("0", "own.obj");
    let landed = pose(&spread.to_string(), "landed.obj");
    let miss = mesh::dist(landed[still], t) / amount;
    let reach = (0..rest.len())
        .filter(|&v| mesh::dist(own[v], landed[v]) > 1e-9 * amount)
        .map(|v| mesh::dist(rest[v], p))
        .fold(0.0, f64::max);
    let _ = std::fs::remove_dir_all(&d);
    (reach, spread * diagonal, miss)
}

/// The landing radius is `spread` × the bounding-box diagonal in data units: on the tube at half
/// and at twenty times its size, the correction reaches most of the way to that radius and no
/// farther (straight-line distance never exceeds the distance along the surface), and the reach
/// grows with the mesh (40 × between the two sizes). A radius taken in absolute units (the scale
/// dropped) reaches the same data-unit distance on both.
#[test]
fn the_landing_radius_is_a_share_of_the_diagonal_in_data_units() {
    let spread = 0.1;
    let small = landing_reach(0.5, spread);
    let large = landing_reach(20.0, spread);
    for (name, (reach, radius, miss)) in [("half size", small), ("20 × size", large)] {
        assert!(miss < 1e-4, "{name}: the pin landed {:.4} % of the drag away", 100.0 * miss);
        assert!(
            reach <= radius * (1.0 + 1e-9),
            "{name}: the correction moved a vertex {reach} from the pin, beyond the radius {radius}"
        );
        // The mesh's edges are a few % of the diagonal: the last moved vertex is within a few
        // edges of the radius along the surface.
        assert!(reach >= 0.6 * radius, "{name}: the correction reaches {reach}, short of the radius {radius}");
    }
    let ratio = large.0 / small.0;
    assert!((ratio / 40.0 - 1.0).abs() < 1e-6, "reach at 20 × / at ½ × size: {ratio}, expected 40");
}

/// The autoencoder block of the cache test: batches of 4 out of 13 fitted shapes (16 training
/// frames, 3 held out as the network's validation shapes, so that the cached frames a batch
/// reads are not the file's frames 0, 1, 2, … in order).
const AE: &str = "kind = \"autoencoder\"\ncomponents = 4\niterations = 10\nbatch_size = 4\nvalidation = 3\nvalidate_every = 2\nseed = 5";

fn train_cli(d: &Path, name: &str, data: &str) -> String {
    let cfg = d.join(format!("{name}.toml"));
    std::fs::write(&cfg, format!("name = \"{name}\"\n[data]\n{data}\n[method]\n{AE}\n")).unwrap();
    let o = meshdeco(&["train", "--config", cfg.to_str().unwrap(), "--out", d.join(name).to_str().unwrap()], d);
    assert!(o.status.success(), "{name}: {}", output_text(&o));
    output_text(&o)
}

/// Training from the feature cache gives the in-memory model to the bit: model, weights and
/// metrics (losses, Erms) agree, with `data.train` out of order and batches smaller than the set.
#[test]
fn training_from_the_cache_is_training_from_memory_with_frames_out_of_order() {
    let d = fresh_dir("guards58", "cache");
    let data = |cache: &str| {
        format!("path = \"synthetic:bumps\"\ntrain = \"25,2,9-14,1,30-36\"\ntest = \"rest\"\ncache = \"{cache}\"")
    };
    let mem = train_cli(&d, "mem", &data("off"));
    assert!(!mem.contains("features cached") && !mem.contains("from the cache"), "{mem}");
    let cached = train_cli(&d, "cached", &data("cache"));
    assert!(cached.contains("features cached in"), "{cached}");
    let read = |p: std::path::PathBuf| std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    for f in ["model.bin", "weights.csv"] {
        assert!(
            read(d.join("mem").join(f)) == read(d.join("cached").join(f)),
            "cached/{f} differs from the in-memory run's"
        );
    }
    let metrics = |r: &str| -> serde_json::Value {
        let mut m: serde_json::Value = serde_json::from_slice(&read(d.join(r).join("metrics.json"))).unwrap();
        m.as_object_mut().unwrap().retain(|k, _| !k.contains("seconds"));
        m
    };
    let (a, b) = (metrics("mem"), metrics("cached"));
    assert_eq!(a, b);
    assert_eq!(a["train_frames"], 16, "{a}");
    // The per-step losses, the kept step included (the log's timing fields aside).
    let log = |r: &str| -> Vec<serde_json::Value> {
        String::from_utf8(read(d.join(r).join("training.jsonl")))
            .unwrap()
            .lines()
            .map(|l| {
                let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
                if let Some(o) = v.as_object_mut() {
                    o.retain(|k, _| !k.contains("seconds") && !k.contains("time"));
                }
                v
            })
            .collect()
    };
    let (la, lb) = (log("mem"), log("cached"));
    assert!(la.len() >= 5, "{la:?}");
    assert_eq!(la, lb);
    let _ = std::fs::remove_dir_all(&d);
}

/// `data.validation = "auto:P%"` on a training selection that is neither contiguous nor starts
/// at frame 1, with test frames between its frames: round(P % × training frames) (at least one)
/// held out, all of them training frames (so never a test frame), never the first training
/// frame, the fitted frames the rest; the same draw for the same seed, another for another seed.
#[test]
fn auto_validation_draws_its_share_of_the_training_selection() {
    let train_sel = "25,4,9-14,2,30-36";
    let train_1: BTreeSet<usize> = [25, 4, 9, 10, 11, 12, 13, 14, 2, 30, 31, 32, 33, 34, 35, 36].into();
    let test_1: BTreeSet<usize> = (1..=40).filter(|f| !train_1.contains(f)).collect();
    let prepare = |v: &str| {
        let cfg = Config::from_toml(&format!(
            "name = \"v\"\n[data]\npath = \"synthetic:bumps\"\ntrain = \"{train_sel}\"\ntest = \"rest\"\nvalidation = \"{v}\"\n[method]\nkind = \"pca\"\ncomponents = 3\n"
        ))
        .unwrap();
        let p = meshdeco::preprocess::prepare(&cfg.data).unwrap();
        let one = |s: &[usize]| -> BTreeSet<usize> { s.iter().map(|&f| f + 1).collect() };
        (one(&p.validation), one(&p.train), one(&p.test))
    };
    let n = train_1.len() as f64;
    let mut drawn = BTreeSet::new();
    for (percent, expected) in [(1.0, 1usize), (10.0, 2), (30.0, 5), (60.0, 10)] {
        assert_eq!(expected, ((percent / 100.0 * n).round() as usize).max(1));
        let mut draws = BTreeSet::new();
        for seed in 0..8u64 {
            let spec = format!("auto:{percent}%:{seed}");
            let (val, fit, test) = prepare(&spec);
            assert_eq!(val.len(), expected, "{spec}: {val:?}");
            assert!(val.is_subset(&train_1), "{spec}: {val:?} is not out of the training frames {train_1:?}");
            assert!(val.is_disjoint(&test_1) && val.is_disjoint(&test), "{spec}: a test frame held out: {val:?}");
            assert!(!val.contains(&2), "{spec}: the first training frame (frame 2) was held out");
            assert_eq!(fit, &train_1 - &val, "{spec}: the fitted frames are not the other training frames");
            assert_eq!(test, test_1, "{spec}");
            assert_eq!(prepare(&spec).0, val, "{spec}: another draw for the same seed");
            draws.insert(val.iter().copied().collect::<Vec<_>>());
            drawn.extend(val);
        }
        if expected < 15 {
            assert!(draws.len() > 1, "auto:{percent}%: every seed drew the same frames {draws:?}");
        }
    }
    // `auto:P%` is seed 0.
    assert_eq!(prepare("auto:30%").0, prepare("auto:30%:0").0);
    // Across the draws every training frame but the first is reachable.
    assert_eq!(drawn, &train_1 - &BTreeSet::from([2]), "frames ever drawn");
    // What a training run reports: the counts of the split.
    let cfg = Config::from_toml(&format!(
        "name = \"v\"\n[data]\npath = \"synthetic:bumps\"\ntrain = \"{train_sel}\"\ntest = \"rest\"\nvalidation = \"auto:30%:3\"\n[method]\nkind = \"pca\"\ncomponents = 3\n"
    ))
    .unwrap();
    let d = fresh_dir("guards58", "validation");
    let m = meshdeco::pipeline::train(&cfg, &d.join("v"), &TrainOptions::default(), &mut Silent).unwrap().metrics;
    assert_eq!((m.train_frames, m.validation_frames), (11, 5));
    let _ = std::fs::remove_dir_all(&d);
}

/// The pose options as the viewer offers and checks them (`PoseOptions::to_json`, `validate`):
/// the README's defaults (shape prior, γ 1, β 1e-3, 30 iterations, radius 0.2, not frozen,
/// reach 1.3), every option
/// named in its JSON, and each bound refused naming the option — `spread` from 0 (off) to 1 (the
/// whole diagonal) inclusive; the command line checks `--spread` itself, the viewer relies on
/// `validate`.
#[test]
fn pose_options_read_back_and_are_checked_at_their_bounds() {
    use meshdeco::model::{PoseOptions, PosePrior};
    let d = PoseOptions::default();
    assert_eq!(
        (d.gamma, d.beta, d.max_iterations, d.prior, d.time_limit, d.spread, d.freeze, d.reach),
        (1.0, 1e-3, 30, PosePrior::Shape, None, 0.2, false, 1.3)
    );
    let o = PoseOptions {
        gamma: 0.25,
        beta: 2.5,
        max_iterations: 7,
        prior: PosePrior::Weights,
        time_limit: None,
        spread: 0.05,
        freeze: true,
        reach: 2.0,
    };
    assert_eq!(
        o.to_json(),
        serde_json::json!({"gamma": 0.25, "beta": 2.5, "max_iterations": 7, "prior": "weights", "spread": 0.05,
            "freeze": true, "reach": 2.0})
    );
    let check = |o: PoseOptions| o.validate().map_err(|e| e.to_string());
    for ok in [
        PoseOptions { spread: 0.0, ..d },
        PoseOptions { spread: 1.0, ..d },
        PoseOptions { gamma: 0.0, beta: 0.0, ..d },
        PoseOptions { max_iterations: 1, ..d },
        PoseOptions { max_iterations: PoseOptions::MAX_ITERATIONS, ..d },
        PoseOptions { reach: 0.0, ..d },
        PoseOptions { reach: 1.0, ..d },
    ] {
        assert_eq!(check(ok), Ok(()), "{ok:?}");
    }
    for (bad, key) in [
        (PoseOptions { spread: 1.0 + 1e-9, ..d }, "`spread`"),
        (PoseOptions { spread: -1e-9, ..d }, "`spread`"),
        (PoseOptions { spread: f64::NAN, ..d }, "`spread`"),
        (PoseOptions { gamma: f64::INFINITY, ..d }, "`gamma`"),
        (PoseOptions { beta: -1e-9, ..d }, "`beta`"),
        (PoseOptions { beta: f64::NAN, ..d }, "`beta`"),
        (PoseOptions { max_iterations: 0, ..d }, "`max_iterations`"),
        (PoseOptions { max_iterations: PoseOptions::MAX_ITERATIONS + 1, ..d }, "`max_iterations`"),
        (PoseOptions { reach: 0.5, ..d }, "`reach`"),
        (PoseOptions { reach: f64::NAN, ..d }, "`reach`"),
    ] {
        let e = check(bad).expect_err(&format!("{bad:?} accepted"));
        assert!(e.contains(key), "{bad:?}: {e}");
    }
}

/// Constraints read from JSON of the wrong kind name what they got, and count what they hold.
#[test]
fn constraints_name_the_wrong_kind_and_count_their_vertices() {
    use meshdeco::model::Constraints;
    for (v, kind) in [
        (serde_json::json!(null), "got null"),
        (serde_json::json!(true), "got a boolean"),
        (serde_json::json!(3), "got a number"),
        (serde_json::json!("7"), "got a string"),
    ] {
        let e = Constraints::from_json("body", &v, 10).unwrap_err().to_string();
        assert!(e.starts_with("body: ") && e.contains(kind), "{v}: {e}");
    }
    let e = Constraints::from_json_text("c.json", "\"7\"", 10).unwrap_err().to_string();
    assert!(e.contains("expected a JSON object"), "{e}");
    let c = Constraints::from_json_text("c.json", r#"{"4": [0, 0, 0], "1": [1, 1, 1], "9": [2, 2, 2]}"#, 10).unwrap();
    assert_eq!((c.len(), c.is_empty()), (3, false));
    assert_eq!(c.vertices, [1, 4, 9]);
    assert_eq!(c.targets, [[1.0; 3], [0.0; 3], [2.0; 3]]);
    // Never empty once read; a value built empty says so.
    let none = Constraints { vertices: Vec::new(), targets: Vec::new() };
    assert_eq!((none.len(), none.is_empty()), (0, true));
}

/// The autoencoder's streamed training data (`nn::data::TrainingData` over a cache file) holds
/// the named frames: shape s is frame `frames[s]` of the sequence encoded alone and scaled, the
/// same numbers as the data held in memory, also after holding out validation shapes and in a
/// batch whose lanes name shapes out of order; bad ranges and counts are refused.
#[test]
fn streamed_shapes_are_the_cached_frames_they_name() {
    use meshdeco::nn::data::TrainingData;
    use meshdeco::representation::feature_cache::{CachePolicy, Opened, open_or_build};
    use meshdeco::representation::scaling::{FeatureScaling, ScalingMode};
    use meshdeco::representation::{Representation, RepresentationKind, RepresentationOptions};
    let d = fresh_dir("guards58", "streamed");
    let seq = meshdeco::synthetic::load("synthetic:bumps").unwrap();
    let rest = TriMesh::new(seq.frames[0].clone(), seq.faces.clone());
    let rep = Representation::new(RepresentationKind::Acap, &rest, RepresentationOptions::default()).unwrap();
    let frames = [1usize, 4, 9, 10, 11, 23, 30, 33];
    let Opened::File { file, built } =
        open_or_build(&rep, &seq, &frames, &CachePolicy::Dir(d.join("cache")), &mut |_| {}).unwrap()
    else {
        panic!("a cache folder caches")
    };
    assert!(built);
    let h = file.header();
    let scaling = FeatureScaling::fit_column_ranges(&h.min(), &h.max(), ScalingMode::PerDimension).unwrap();
    // Each frame encoded alone, scaled: what shape s must hold.
    let alone: Vec<Vec<f64>> =
        frames.iter().map(|&f| scaling.apply(&rep.encode_selected(&seq, &[f]).unwrap()).unwrap().data).collect();
    let mut all = rep.encode_selected(&seq, &frames).unwrap();
    all = scaling.apply(&all).unwrap();
    let mem = TrainingData::from_features(&all).unwrap();
    let streamed = TrainingData::from_feature_file(std::sync::Arc::new(file), scaling).unwrap();
    assert!(streamed.is_streamed() && !mem.is_streamed());
    assert_eq!((streamed.n_shapes(), streamed.n_vertices()), (frames.len(), rest.positions.len()));
    assert_eq!((mem.n_shapes(), mem.n_vertices()), (frames.len(), rest.positions.len()));
    let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    for (s, want) in alone.iter().enumerate() {
        assert_eq!(streamed.shape(s).unwrap().as_ref(), f32s(want).as_slice(), "streamed shape {s}");
        assert_eq!(mem.shape(s).unwrap().as_ref(), f32s(want).as_slice(), "in-memory shape {s}");
    }
    let sf = streamed.scaled_features(2..5).unwrap();
    assert_eq!((sf.n_frames, sf.n_elements, sf.width), (3, rest.positions.len(), 9));
    assert_eq!(sf.data, alone[2..5].concat());
    assert!(streamed.shape(frames.len()).is_err() && mem.shape(frames.len()).is_err());
    assert!(mem.scaled_features(0..1).is_err(), "in-memory data has no scaled_features");
    assert!(streamed.scaled_features(0..frames.len() + 1).is_err());
    #[allow(clippy::reversed_empty_ranges)]
    let backwards = 3..2;
    assert!(streamed.scaled_features(backwards).is_err());
    // Held out evenly: shapes ⌊(j + ½)·8/3⌋ = 1, 4, 6; the others fitted, in order.
    for data in [&mem, &streamed] {
        assert!(data.split_validation(0).is_err() && data.split_validation(frames.len()).is_err());
        let (fit, val, held) = data.split_validation(3).unwrap();
        assert_eq!(held, [1, 4, 6]);
        let keep = [0usize, 2, 3, 5, 7];
        assert_eq!((fit.n_shapes(), val.n_shapes(), fit.is_streamed()), (5, 3, data.is_streamed()));
        for (i, &s) in keep.iter().enumerate() {
            assert_eq!(fit.shape(i).unwrap().as_ref(), f32s(&alone[s]).as_slice(), "fitted shape {i}");
        }
        for (i, &s) in held.iter().enumerate() {
            assert_eq!(val.shape(i).unwrap().as_ref(), f32s(&alone[s]).as_slice(), "held-out shape {i}");
        }
        if fit.is_streamed() {
            let sf = fit.scaled_features(1..3).unwrap();
            assert_eq!(sf.data, [alone[2].clone(), alone[3].clone()].concat());
        }
        // A batch of fitted shapes 3, 0, 4 (frames 23, 1, 33): lane j holds its shape, the
        // padding lanes zero.
        let lanes = [3usize, 0, 4];
        let n9 = rest.positions.len() * 9;
        for (buf, bp) in [
            (fit.batch_vcb(&lanes).unwrap(), meshdeco::nn::kernels::padded_width(3)),
            (fit.batch_vcb_width(&lanes, 2 * meshdeco::nn::kernels::LANES).unwrap(), 2 * meshdeco::nn::kernels::LANES),
        ] {
            assert_eq!(buf.len(), n9 * bp);
            for (j, &s) in lanes.iter().enumerate() {
                let lane: Vec<f32> = (0..n9).map(|r| buf[r * bp + j]).collect();
                assert_eq!(lane, f32s(&alone[keep[s]]), "lane {j}");
            }
            assert!((3..bp).all(|j| (0..n9).all(|r| buf[r * bp + j] == 0.0)), "padding lanes");
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Each model kind's pose defaults are the ones the README states (`meshdeco pose` without
/// `--gamma`/`--prior`): PCA and SPLOCS the data prior, γ 5; region PCA the weights prior,
/// γ 0.03, β 1e-3; the autoencoder the weights prior, γ 1; all 30 iterations, landing radius 0.2,
/// reach 1.3, nothing frozen, no time limit.
#[test]
fn each_kinds_pose_defaults_are_the_documented_ones() {
    use meshdeco::model::{PoseOptions, PosePrior};
    let shared = |o: &PoseOptions| {
        assert_eq!((o.beta, o.max_iterations, o.spread, o.reach, o.freeze), (1e-3, 30, 0.2, 1.3, false), "{o:?}");
        assert!(o.time_limit.is_none(), "{o:?}");
    };
    let l = PoseOptions::linear_defaults();
    assert_eq!((l.prior, l.gamma), (PosePrior::Data, 5.0), "{l:?}");
    let r = PoseOptions::region_defaults();
    assert_eq!((r.prior, r.gamma), (PosePrior::Weights, 0.03), "{r:?}");
    let a = PoseOptions::autoencoder_defaults();
    assert_eq!((a.prior, a.gamma), (PosePrior::Weights, 1.0), "{a:?}");
    for o in [&l, &r, &a] {
        shared(o);
    }
    let d = PoseOptions::default();
    assert_eq!((d.prior, d.gamma), (PosePrior::Shape, 1.0), "{d:?}");
    shared(&d);
}

/// `--reach` only ever takes a pose back (`src/model/pose.rs`, `reach_back`): with a reach far
/// beyond the pose's motion the shape is the model's own pose (`--reach 0`) exactly, and with
/// `--reach 1` the pose that moved a vertex farther than the drag is taken back until the
/// farthest moves exactly the drag.
#[test]
fn reach_only_takes_a_pose_back() {
    let d = fresh_dir("guards58", "reach-back");
    let (frames, model) = bumps_pca(&d, 1.0);
    let rest = &frames[0];
    // A vertex the training frames move a fifth as far as the one they move most, dragged 5 %
    // of the diagonal along its own motion with a weak pull on the weights: landing it moves
    // others farther.
    let motion = |v: usize| frames.iter().map(|f| mesh::dist(f[v], rest[v])).fold(0.0, f64::max);
    let top = (0..rest.len()).map(motion).fold(0.0, f64::max);
    let moving = (0..rest.len())
        .min_by(|&a, &b| (motion(a) - 0.2 * top).abs().total_cmp(&(motion(b) - 0.2 * top).abs()).then(a.cmp(&b)))
        .unwrap();
    let (lo, hi) = mesh::bounding_box(rest);
    let drag = 0.05 * mesh::dist(lo, hi);
    let p = rest[moving];
    // Along the vertex's motion in the frame that moves it most.
    let f = frames.iter().max_by(|a, b| mesh::dist(a[moving], p).total_cmp(&mesh::dist(b[moving], p))).unwrap();
    let u = mesh::dist(f[moving], p);
    let t: Vec<f64> = (0..3).map(|c| p[c] + drag * (f[moving][c] - p[c]) / u).collect();
    std::fs::write(d.join("c.json"), format!("{{\"{moving}\": [{}, {}, {}]}}", t[0], t[1], t[2])).unwrap();
    // From the model's neutral shape (weights 0) and from a training frame's weights (not 0:
    // the line back to the start is w0 + s (w − w0), not s w).
    let faces = meshdeco::synthetic::load("synthetic:bumps").unwrap().faces;
    mesh::write::write_obj(&d.join("f.obj"), &TriMesh::new(frames[20].clone(), faces)).unwrap();
    for from in [None, Some("f.obj")] {
        let run = |extra: &[&str], out: &str| {
            let mut args = vec!["pose", model.to_str().unwrap(), "-c", "c.json", "--out", out, "--spread", "0"];
            if let Some(f) = from {
                args.extend(["--from", f]);
            }
            args.extend(extra);
            let o = meshdeco(&args, &d);
            assert!(o.status.success(), "pose {args:?}: {}", output_text(&o));
            mesh::load_mesh(&d.join(out)).unwrap().positions
        };
        let pose = |reach: &str, out: &str| run(&["--prior", "weights", "--gamma", "0.001", "--reach", reach], out);
        // The pose's start (`--freeze` with `--spread 0`: nothing moves), which the reach and
        // the drag are measured from.
        let start = run(&["--freeze"], "start.obj");
        let drag = mesh::dist(start[moving], [t[0], t[1], t[2]]);
        let most = |ps: &[Vec3]| ps.iter().zip(&start).map(|(a, b)| mesh::dist(*a, *b)).fold(0.0, f64::max);
        let free = pose("0", "free.obj");
        let far = pose("1000", "far.obj");
        assert!(
            free == far,
            "{from:?}: a reach of 1000 × the drag changed a pose that moved {} × the drag",
            most(&free) / drag
        );
        assert!(
            most(&free) > 1.05 * drag,
            "{from:?}: the unbounded pose moves {} × the drag: nothing to take back",
            most(&free) / drag
        );
        let bounded = pose("1", "bounded.obj");
        // Taken back along the straight line to the start just as far as needed (exact for a
        // linear model): the farthest vertex ends at the drag's distance.
        let r = most(&bounded) / drag;
        assert!((r - 1.0).abs() < 1e-6, "{from:?}, --reach 1: the farthest vertex moved {r} × the drag, expected 1");
        // On the line from the start to the unbounded pose: start + s (free − start).
        let s = drag / most(&free);
        let off = (0..start.len())
            .map(|v| {
                let on: Vec3 = [0, 1, 2].map(|c| start[v][c] + s * (free[v][c] - start[v][c]));
                mesh::dist(bounded[v], on)
            })
            .fold(0.0, f64::max);
        assert!(off < 1e-9 * drag, "{from:?}, --reach 1: the pose is {off} off the line back to the start");
    }
    let _ = std::fs::remove_dir_all(&d);
}
