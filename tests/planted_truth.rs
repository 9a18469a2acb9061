//! Ground truth for the components (issue 53): `meshdeco plant` writes a set with known
//! localized deformations, `meshdeco eval` scores every cell's components against them, the
//! autoencoder's dials start at the rest shape's code, region PCA says how many regions it found.

mod common;

use std::path::{Path, PathBuf};

use common::{fresh_dir, meshdeco, output_text, png_ink};

/// A capped-free tube (open cylinder) written as OBJ: the mesh the deformations are planted on.
fn tube(dir: &Path) -> PathBuf {
    let m = meshdeco::mesh::primitives::cylinder(32, 40, 0.3, 2.0);
    let p = dir.join("tube.obj");
    meshdeco::mesh::write_obj(&p, &m).unwrap();
    p
}

fn plant(dir: &Path, out: &str, extra: &[&str]) -> std::process::Output {
    let t = tube(dir);
    let mut args = vec!["plant", t.to_str().unwrap(), "--out", out];
    args.extend_from_slice(extra);
    meshdeco(&args, dir)
}

/// Plants 4 deformations on the tube in `d/set` (40 training, 10 test frames, no noise) and
/// returns the `[data]` keys that train on it with its template as the rest shape.
fn small_set(d: &Path) -> &'static str {
    let o = plant(d, "set", &["--deformations", "4", "--train", "40", "--test", "10", "--noise", "0"]);
    assert!(o.status.success(), "{}", output_text(&o));
    "path = \"set/frames.npy\"\ntemplate = \"set/template.obj\"\nrest = \"set/template.obj\"\ntrain = \"1-40\"\ntest = \"41-50\""
}

fn csv_rows(path: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let head: Vec<String> = lines.next().unwrap().split(',').map(str::to_string).collect();
    lines.map(|l| head.iter().cloned().zip(l.split(',').map(str::to_string)).collect()).collect()
}

#[test]
fn eval_scores_the_components_against_the_planted_deformations() {
    let d = fresh_dir("planted", "eval");
    let o = plant(
        &d,
        "set",
        &["--deformations", "6", "--train", "80", "--test", "20", "--noise", "0", "--radius", "0.1,0.2", "--seed", "3"],
    );
    assert!(o.status.success(), "{}", output_text(&o));
    let text = output_text(&o);
    assert!(text.contains("6 deformations") && text.contains("identifiable"), "{text}");
    for f in ["frames.npy", "template.obj", "fields.npy", "weights.csv", "truth.json", "eval.toml", "manifest.json"] {
        assert!(d.join("set").join(f).is_file(), "{f} missing");
    }
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("set/truth.json")).unwrap()).unwrap();
    assert_eq!(truth["deformations"].as_array().unwrap().len(), 6);
    assert_eq!(truth["train"], 80);
    // Without noise, the true fields reconstruct every pull and stretch exactly; hinges are arcs.
    let oracle = truth["oracle_test_erms"].as_f64().unwrap();
    assert!(oracle < 0.5 * truth["rest_test_erms"].as_f64().unwrap(), "oracle {oracle}");

    std::fs::write(
        d.join("eval.toml"),
        "name = \"planted\"\n[[dataset]]\nname = \"tube\"\ntruth = \"set\"\n\
         [[method]]\nlabel = \"pca\"\nkind = \"pca\"\n\
         [[method]]\nlabel = \"splocs\"\nkind = \"splocs\"\n\
         [sweep]\ncomponents = [7]\n",
    )
    .unwrap();
    let o = meshdeco(&["eval", "--config", "eval.toml", "--out", "ev"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let rows = csv_rows(&d.join("ev/results.csv"));
    let get = |m: &str, col: &str| -> f64 {
        rows.iter().find(|r| r["method"] == m).unwrap()[col].parse().unwrap_or_else(|_| panic!("{m} {col}"))
    };
    // Localized components find the planted deformations; PCA's global ones do not.
    let (found_s, found_p) = (get("splocs", "recovery_found"), get("pca", "recovery_found"));
    assert_eq!(get("splocs", "recovery_total"), 6.0);
    assert!(found_s >= 4.0, "SPLOCS found {found_s} of 6");
    assert!(found_s > found_p, "SPLOCS {found_s} vs PCA {found_p}");
    assert!(get("splocs", "recovery_median_abs_cos") > get("pca", "recovery_median_abs_cos"));
    assert!(get("splocs", "vertex_support") < get("pca", "vertex_support"), "SPLOCS components should be local");
    // Per deformation, in the cell; the report's table and plot.
    let rec: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(d.join("ev/cells/tube/splocs/K7/recovery.json")).unwrap())
            .unwrap();
    assert_eq!(rec.len(), 6);
    assert!(rec.iter().all(|r| r["abs_cos"].as_f64().unwrap() <= 1.0 + 1e-12 && r["component"].as_u64().unwrap() < 7));
    let report = std::fs::read_to_string(d.join("ev/report.md")).unwrap();
    assert!(report.contains("recovery of the planted deformations"), "{report}");
    let (_, _, ink, _) = png_ink(&d.join("ev/recovery_tube.png"));
    assert!(ink > 0.01);
    // metrics.json of every cell has the vertex-space locality.
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("ev/cells/tube/pca/K7/metrics.json")).unwrap()).unwrap();
    assert_eq!(m["vertex_support"].as_array().unwrap().len(), 7);

    // Planting again (another seed) changes the truth: the cached cells are scored again.
    let o = plant(&d, "set", &["--deformations", "6", "--train", "80", "--test", "20", "--seed", "4"]);
    assert!(o.status.success(), "{}", output_text(&o));
    let o = meshdeco(&["eval", "--config", "eval.toml", "--out", "ev"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let key = |s: &str| s.to_string();
    let cell: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("ev/cells/tube/pca/K7/cell.json")).unwrap()).unwrap();
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("set/manifest.json")).unwrap()).unwrap();
    assert!(
        cell["recovery"]["truth_key"]
            .as_str()
            .unwrap()
            .contains(&key(m["files"]["fields.npy"]["crc32"].as_str().unwrap())),
        "the cell was not scored against the new truth"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn plant_refuses_bad_flags_and_a_damaged_truth() {
    let d = fresh_dir("planted", "bad");
    for (args, flag) in [
        (vec!["--noise=-1"], "--noise"),
        (vec!["--max-active", "0"], "--max-active"),
        (vec!["--radius", "0.3,0.1"], "--radius"),
        (vec!["--radius", "x"], "--radius"),
        (vec!["--deformations", "0"], "--deformations"),
        (vec!["--mirror", "w"], "--mirror"),
        (vec!["--vertices", "10"], "--vertices"),
    ] {
        let o = plant(&d, "bad", &args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", output_text(&o));
        assert!(output_text(&o).contains(flag), "{args:?}: {}", output_text(&o));
        assert!(!d.join("bad").exists(), "{args:?} left an output behind");
    }
    let o = plant(&d, "set", &["--deformations", "4", "--train", "30", "--test", "10"]);
    assert!(o.status.success(), "{}", output_text(&o));
    let f = d.join("set/fields.npy");
    let mut bytes = std::fs::read(&f).unwrap();
    let at = bytes.len() - 3;
    bytes[at] ^= 0x20;
    std::fs::write(&f, bytes).unwrap();
    std::fs::write(
        d.join("eval.toml"),
        "name = \"x\"\n[[dataset]]\nname = \"t\"\ntruth = \"set\"\n[[method]]\nlabel = \"pca\"\nkind = \"pca\"\n[sweep]\ncomponents = [3]\n",
    )
    .unwrap();
    let o = meshdeco(&["eval", "--config", "eval.toml", "--out", "ev"], &d);
    let text = output_text(&o);
    assert!(text.contains("fields.npy") && text.contains("changed or damaged"), "{text}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn the_autoencoders_dials_start_at_the_rest_shape_and_region_pca_names_its_regions() {
    let d = fresh_dir("planted", "origin");
    let data = small_set(&d);
    let model = common::train_cli(
        &d,
        "ae",
        data,
        "kind = \"autoencoder\"\ncomponents = 5\niterations = 40\nfit_test = false\nencoder_steps = 1",
    );
    // All dials 0 decode the rest shape's own code: the model's encoding of the rest mesh.
    let o = meshdeco(&["synthesize", model.to_str().unwrap(), "--weights", "0:0", "--out", "zero.obj"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let o = meshdeco(&["encode", model.to_str().unwrap(), "set/template.obj", "--out", "enc"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let zero = common::obj_vertices(&d.join("zero.obj"));
    let enc_dir = d.join("enc");
    let rec_file = std::fs::read_dir(&enc_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "obj"))
        .expect("a reconstruction");
    let enc = common::obj_vertices(&rec_file);
    let gap = zero.iter().zip(&enc).map(|(a, b)| meshdeco::mesh::dist(*a, *b)).fold(0.0, f64::max);
    assert!(gap < 1e-6, "dials 0 decode {gap} away from the rest mesh's encoding");
    // Region PCA says how many regions it segmented the mesh into.
    let cfg = d.join("region.toml");
    std::fs::write(&cfg, format!("name = \"r\"\n[data]\n{data}\n[method]\nkind = \"region-pca\"\ncomponents = 8\n"))
        .unwrap();
    let o = meshdeco(&["train", "--config", "region.toml", "--out", "region"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    assert!(output_text(&o).contains("region-pca segmented the mesh into"), "{}", output_text(&o));
    let _ = std::fs::remove_dir_all(&d);
}

/// A run that ends before it learned the shapes says so (issue 53): its decoding is no better
/// than the rest shape's, `meshdeco train` warns, naming the key to change, and `metrics.json`
/// keeps the warning; a run stopped long before the default's steps says it trained only partly
/// (issue 57); a run long enough to train does not warn.
#[test]
fn a_run_stopped_too_early_says_it_did_not_train() {
    let d = fresh_dir("planted", "untrained");
    let data = "path = \"synthetic:tube\"\ntrain = \"every:3\"\ntest = \"rest\"";
    let run = |name: &str, iterations: usize| {
        let cfg = d.join(format!("{name}.toml"));
        std::fs::write(
            &cfg,
            format!(
                "name = \"{name}\"\n[data]\n{data}\n[method]\nkind = \"autoencoder\"\ncomponents = 8\n\
                 iterations = {iterations}\nfit_test = false\n"
            ),
        )
        .unwrap();
        let o = meshdeco(&["train", "--config", cfg.to_str().unwrap(), "--out", name], &d);
        assert!(o.status.success(), "{}", output_text(&o));
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join(name).join("metrics.json")).unwrap()).unwrap();
        (output_text(&o), m)
    };
    let (text, m) = run("early", 5);
    assert!(text.contains("warning: the autoencoder did not train") && text.contains("method.iterations"), "{text}");
    assert!(m["training_warning"].as_str().is_some_and(|w| w.contains("did not train")), "{m}");
    // Issue 57: 100 steps train, but only partly (test Erms 44 against 4.6 at 600 steps):
    // the step size has decayed by the end, so the error is flat, and the warning says what
    // happened and which key to raise.
    let (text, m) = run("partly", 100);
    assert!(
        text.contains("warning: the autoencoder trained only partly") && text.contains("method.iterations"),
        "{text}"
    );
    assert!(m["training_warning"].as_str().is_some_and(|w| w.contains("stopped after 100 steps")), "{m}");
    let partly = m["training_gain"].as_f64().unwrap();
    let (text, m) = run("trained", 600);
    assert!(!text.contains("did not train") && !text.contains("only partly"), "{text}");
    assert!(m.get("training_warning").is_none(), "{m}");
    // The share of the linear gain, in metrics.json, grows with the steps; the estimate is
    // printed after the first steps.
    let trained = m["training_gain"].as_f64().unwrap();
    assert!(partly < 0.97 && trained > 0.9 && trained <= 1.05, "training_gain {partly} at 100 steps, {trained} at 600");
    assert!(text.contains("note: training estimate: about") && text.contains("µs per shape-vertex"), "{text}");
    let _ = std::fs::remove_dir_all(&d);
}

/// The autoencoder's dials are a basis of its latent space fitted to the training codes
/// (`dial_sparsity`, issue 53): dials and codes map into each other exactly, dials 0 are the
/// rest code, each dial reaches about 1 on the training frames and the training dials are
/// nearly non-negative; with `dial_sparsity = 0` the dials are the latent dimensions (the
/// paper); the default `"auto"` keeps the most concentrated of its candidate bases. A damaged
/// basis in `model.json` (its checksum re-recorded) is refused by name.
#[test]
fn the_autoencoders_dials_are_a_sparse_basis_of_its_training_codes() {
    use meshdeco::pipeline::registry::load_model;
    let d = fresh_dir("planted", "dials");
    let data = small_set(&d);
    // The paper's support range: the bounds below were set on the network it trains (with the
    // default's wider [0.3, 0.7] this small set's dials are 14.5 % below −0.2 instead of < 10 %).
    let method = "kind = \"autoencoder\"\ncomponents = 5\niterations = 300\nfit_test = false\nencoder_steps = 0\n\
                  support = [0.2, 0.4]";
    let with = common::train_cli(&d, "ae", data, &format!("{method}\ndial_sparsity = 0.03"));
    let header: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(with.join("model.json")).unwrap()).unwrap();
    let basis = header["dial_basis"].as_array().expect("a dial basis with dial_sparsity > 0");
    assert_eq!(basis.len(), 5);
    let model = load_model(&with).unwrap();
    let k = model.n_components();
    assert_eq!(k, 5);
    // Dials ↔ codes, both ways.
    for dials in [vec![0.0; 5], vec![1.0, 0.0, 0.0, 0.0, 0.0], vec![0.3, -0.7, 1.2, 0.0, 0.5]] {
        let w = model.synthesis_weights(&dials).unwrap();
        let back = model.dials(&w).unwrap();
        for (a, b) in back.iter().zip(&dials) {
            assert!((a - b).abs() < 1e-8, "dials {dials:?} came back as {back:?}");
        }
    }
    // Dials 0 are the rest code (the model's start), and a dial moves the code along its
    // direction: the code of dial m at 1 minus the rest code is basis[m].
    let rest = model.synthesis_weights(&[0.0; 5]).unwrap();
    let start = model.start_weights(None).unwrap();
    assert!(rest.iter().zip(&start).all(|(a, b)| (a - b).abs() < 1e-9), "{rest:?} vs the start {start:?}");
    let one = model.synthesis_weights(&[0.0, 0.0, 1.0, 0.0, 0.0]).unwrap();
    for (c, b) in basis[2].as_array().unwrap().iter().enumerate() {
        assert!((one[c] - rest[c] - b.as_f64().unwrap()).abs() < 1e-12);
    }
    // The training frames' dials: each used one is 1 at its extreme (the largest in magnitude;
    // a spare direction the codes hardly use, kept at 10⁻³ of the largest scale, stays below),
    // at least one per planted deformation; and few are negative.
    let train: Vec<Vec<f64>> = model.train_weights().unwrap().iter().map(|w| model.dials(w).unwrap()).collect();
    let extremes: Vec<f64> =
        (0..k).map(|m| train.iter().map(|t| t[m]).max_by(|a, b| a.abs().total_cmp(&b.abs())).unwrap()).collect();
    assert!(extremes.iter().all(|&e| e.abs() <= 1.0 + 1e-6), "{extremes:?}");
    assert!(extremes.iter().filter(|&&e| (e - 1.0).abs() < 1e-6).count() >= 4, "{extremes:?}");
    let negative = train.iter().flatten().filter(|&&x| x < -0.2).count();
    assert!(negative * 10 <= train.len() * k, "{negative} of {} training dials below −0.2", train.len() * k);
    // `dial_sparsity = 0`: the paper's per-dimension dials.
    let without = common::train_cli(&d, "ae0", data, &format!("{method}\ndial_sparsity = 0"));
    let header0 = std::fs::read_to_string(without.join("model.json")).unwrap();
    assert!(!header0.contains("dial_basis"), "dial_sparsity = 0 wrote a basis");
    // The default, "auto": the basis at each candidate sparsity, the most concentrated kept
    // (metrics.json's dial_readouts); the stored model's components read that score again.
    let auto = common::train_cli(&d, "auto", data, method);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(auto.join("metrics.json")).unwrap()).unwrap();
    let readouts = m["dial_readouts"].as_array().expect("dial_readouts in metrics.json");
    let tried: Vec<f64> = readouts.iter().map(|r| r["dial_sparsity"].as_f64().unwrap()).collect();
    assert_eq!(tried, meshdeco::config::DialSparsity::CANDIDATES.to_vec(), "{m}");
    let score = |r: &serde_json::Value| r["median_concentration"].as_f64().unwrap();
    let chosen: Vec<&serde_json::Value> = readouts.iter().filter(|r| r["chosen"] == true).collect();
    assert_eq!(chosen.len(), 1, "{m}");
    assert!(readouts.iter().all(|r| score(r) <= score(chosen[0])), "{m}");
    assert!(readouts.iter().all(|r| (0.1 - 1e-9..=1.0 + 1e-9).contains(&score(r))), "{m}");
    let model = load_model(&auto).unwrap();
    assert!(std::fs::read_to_string(auto.join("model.json")).unwrap().contains("dial_basis"));
    let fields = meshdeco::model::component_fields(model.as_ref()).unwrap();
    let mut c: Vec<f64> = fields[..5].iter().map(|f| meshdeco::metrics::recovery::energy_concentration(f)).collect();
    c.sort_by(|a, b| a.total_cmp(b));
    assert!(
        (c[2] - score(chosen[0])).abs() < 1e-9,
        "stored components' median {} vs the chosen {}",
        c[2],
        score(chosen[0])
    );
    // A damaged basis is refused, naming it.
    let mut v = header.clone();
    v["dial_basis"][1] = v["dial_basis"][0].clone();
    std::fs::write(with.join("model.json"), serde_json::to_string_pretty(&v).unwrap()).unwrap();
    let m = meshdeco::artifact::compute_manifest(&with).unwrap();
    std::fs::write(with.join("manifest.json"), serde_json::to_string_pretty(&m).unwrap()).unwrap();
    let err = load_model(&with).err().expect("a basis that does not span is refused").to_string();
    assert!(err.contains("dial_basis") && err.contains("model.json"), "{err}");
    v["dial_basis"][1] = serde_json::json!([1.0, 2.0]);
    std::fs::write(with.join("model.json"), serde_json::to_string_pretty(&v).unwrap()).unwrap();
    let m = meshdeco::artifact::compute_manifest(&with).unwrap();
    std::fs::write(with.join("manifest.json"), serde_json::to_string_pretty(&m).unwrap()).unwrap();
    let err = load_model(&with).err().expect("a short direction is refused").to_string();
    assert!(err.contains("dial_basis"), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `feature_weights = "noise"` reaches training from the command line: `train` says how many
/// vertices weigh less than ½, the artefact's `config.toml` keeps the key, and the first step's
/// feature error (same seed, so the same start) is the weighted one — below the uniform run's,
/// since every weight is at most 1 and the noisier half of the vertices weigh less.
#[test]
fn noise_feature_weights_reach_training() {
    let d = fresh_dir("planted", "feature-weights");
    let train = |name: &str, weights: &str, iterations: usize, extra: &[&str]| {
        let cfg = d.join(format!("{name}-{weights}-{iterations}.toml"));
        std::fs::write(
            &cfg,
            format!(
                "name = \"{name}\"\n[data]\npath = \"synthetic:tube\"\ntrain = \"every:3\"\ntest = \"rest\"\n\
                 [method]\nkind = \"autoencoder\"\ncomponents = 4\niterations = {iterations}\nfit_test = false\n\
                 feature_weights = \"{weights}\"\n"
            ),
        )
        .unwrap();
        let mut args = vec!["train", "--config", cfg.to_str().unwrap(), "--out", name];
        args.extend_from_slice(extra);
        meshdeco(&args, &d)
    };
    let run = |name: &str, weights: &str| {
        let o = train(name, weights, 3, &[]);
        assert!(o.status.success(), "{}", output_text(&o));
        let log = std::fs::read_to_string(d.join(name).join("training.jsonl")).unwrap();
        let first: serde_json::Value = serde_json::from_str(log.lines().next().unwrap()).unwrap();
        let config = std::fs::read_to_string(d.join(name).join("config.toml")).unwrap();
        (output_text(&o), first["reconstruction"].as_f64().unwrap(), config)
    };
    let (text_u, rec_u, config_u) = run("uniform", "uniform");
    let (text_n, rec_n, config_n) = run("noise", "noise");
    assert!(!text_u.contains("feature_weights"), "{text_u}");
    assert!(
        text_n.contains("note: feature_weights = \"noise\":") && text_n.contains("weigh less than 1/2"),
        "{text_n}"
    );
    assert!(config_u.contains("feature_weights = \"uniform\""), "{config_u}");
    assert!(config_n.contains("feature_weights = \"noise\""), "{config_n}");
    assert!(rec_n < rec_u, "first step's feature error: weighted {rec_n}, uniform {rec_u}");
    // A run resumes only with the weighting it was trained with (the checkpoint records it; the
    // default changed with issue 53): the other is refused naming the key and the checkpoint.
    for (name, other) in [("noise", "uniform"), ("uniform", "noise")] {
        let o = train(name, other, 5, &["--resume"]);
        let text = output_text(&o);
        assert!(!o.status.success(), "{name} resumed as {other}: {text}");
        assert!(
            text.contains("feature_weights")
                && text.contains("checkpoint.bin")
                && text.contains(&format!("= \"{name}\"")),
            "{text}"
        );
        let o = train(name, name, 5, &["--resume"]);
        assert!(o.status.success(), "{name} resumed as {name}: {}", output_text(&o));
    }
    let _ = std::fs::remove_dir_all(&d);
}
