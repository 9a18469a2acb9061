//! `meshdeco pose` as a user runs it, on models trained here (library pipeline, small configs)
//! on the synthetic `bumps` tube: the dragged vertex lands within 5 % of the drag distance, the
//! displacement energy stays in the region / support for region PCA and SPLOCS and spreads for
//! holistic PCA, and bad constraint files fail with messages naming the problem.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use meshdeco::config::Config;
use meshdeco::mesh::{self, Vec3};
use meshdeco::model::PoseOptions;
use meshdeco::pipeline::Silent;
use meshdeco::pipeline::load_model;
use meshdeco::pipeline::pose::{ball, displacement_share};
use meshdeco::synthetic;

fn meshdeco(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_meshdeco")).args(args).current_dir(cwd).output().expect("run meshdeco")
}

fn tmp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-pose-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn train(d: &Path, name: &str, method: &str) -> PathBuf {
    let cfg = Config::from_toml(&format!(
        "name = \"{name}\"\n[data]\npath = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"rest\"\n[method]\n{method}\n"
    ))
    .unwrap();
    let out = d.join(name);
    meshdeco::pipeline::train(&cfg, &out, &meshdeco::pipeline::TrainOptions::default(), &mut Silent).unwrap();
    out
}

/// Centre (most-moving vertex) of planted bump `b` and the bump's vertices.
fn bump(b: usize) -> (usize, Vec<usize>) {
    let seq = synthetic::load("synthetic:bumps").unwrap();
    let p = &synthetic::planted_regions("synthetic:bumps").unwrap()[b];
    let rest = &seq.frames[0];
    let v = *p
        .vertices
        .iter()
        .max_by(|&&a, &&c| {
            let m = |v: usize| seq.frames.iter().map(|f| mesh::dist(f[v], rest[v])).fold(0.0, f64::max);
            m(a).total_cmp(&m(c)).then(c.cmp(&a))
        })
        .unwrap();
    (v, p.vertices.clone())
}

fn parse_distance(stdout: &str, v: usize) -> f64 {
    let line = stdout.lines().find(|l| l.starts_with(&format!("vertex {v}:"))).expect("per-constraint line");
    line.split("distance to target ").nth(1).unwrap().split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn pose_command_lands_and_reports_locality() {
    let d = tmp("models");
    let models = [
        ("region", train(&d, "region", "kind = \"region-pca\"\ncomponents = 24\nmax_regions = 8")),
        ("splocs", train(&d, "splocs", "kind = \"splocs\"\ncomponents = 3")),
        // Two holistic components for three independent bumps: PCA must mix them (with three it
        // recovers the bumps exactly, the data being rank 3, and stays as local as SPLOCS).
        ("pca", train(&d, "pca", "kind = \"pca\"\ncomponents = 2")),
    ];
    // Bump 2 by default (POSE_BUMP=0/1 for the others; with max_regions = 8 the segmentation
    // splits bump 1 over two regions and its share in the one holding the vertex is 0.79).
    let b: usize = std::env::var("POSE_BUMP").ok().and_then(|s| s.parse().ok()).unwrap_or(2);
    let (v, planted) = bump(b);
    let mut shares = Vec::new();
    for (name, dir) in &models {
        let model = load_model(dir).unwrap();
        let w0 = model.start_weights(None).unwrap();
        let start = model.decode(std::slice::from_ref(&w0)).unwrap().remove(0);
        // Drag outward (radially in x, y) by 0.03 (the bumps are up to 0.06 high).
        let p = start[v];
        let l = (p[0] * p[0] + p[1] * p[1]).sqrt();
        let amount = 0.03;
        let t: Vec3 = [p[0] + amount * p[0] / l, p[1] + amount * p[1] / l, p[2]];
        let cons = d.join(format!("{name}.json"));
        std::fs::write(&cons, format!("{{\"{v}\": [{}, {}, {}]}}", t[0], t[1], t[2])).unwrap();
        let out = d.join(format!("{name}_posed.obj"));
        let o = meshdeco(
            &["pose", dir.to_str().unwrap(), "--constraints", cons.to_str().unwrap(), "--out", out.to_str().unwrap()],
            &d,
        );
        let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        let posed = mesh::load_mesh(&out).unwrap();
        let err = mesh::dist(posed.positions[v], t);
        assert!(err <= 0.05 * amount, "{name}: landing error {err} for a drag of {amount}\n{stdout}");
        assert!((parse_distance(&stdout, v) - err).abs() < 1e-5, "{stdout}");
        // Same pose through the library; energy shares.
        let res = model.pose(&[v], &[t], &w0, &model.pose_defaults()).unwrap();
        let (set_name, set) = model.locality_set(v).unwrap();
        let own = displacement_share(&res.start, &res.positions, &set);
        let planted_share = displacement_share(&res.start, &res.positions, &planted);
        let rest = model.rest();
        let (lo, hi) = rest.bounding_box();
        let near = displacement_share(&res.start, &res.positions, &ball(&rest.positions, v, 0.2 * mesh::dist(lo, hi)));
        eprintln!(
            "{name}: landing error {:.2}% of the drag; energy share in {set_name} {own:.3}, in the planted bump {planted_share:.3}, within 20% of the diagonal {near:.3}",
            100.0 * err / amount
        );
        shares.push((name, own, near));
    }
    let get = |n: &str| shares.iter().find(|s| *s.0 == n).unwrap();
    assert!(get("region").1 >= 0.8, "region share {:?}", get("region"));
    assert!(get("splocs").1 >= 0.8, "splocs share {:?}", get("splocs"));
    // Holistic PCA (budget below the number of bumps) spreads the drag further.
    assert!(get("pca").2 < get("splocs").2.min(get("region").2), "{shares:?}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn bad_constraint_files_fail_with_reasons() {
    let d = tmp("bad");
    let model = train(&d, "pca", "kind = \"pca\"\ncomponents = 3");
    let n = load_model(&model).unwrap().rest().n_vertices();
    let cases = [
        ("{\"3\": [0, 0", "bad.json: line 1".to_string()),
        (&*format!("{{\"{n}\": [0, 0, 0]}}"), format!("vertex {n} out of range (the model has {n} vertices")),
        ("{\"x\": [0, 0, 0]}", "`x` is not a vertex index".to_string()),
        ("{\"2\": [0, 0]}", "target of vertex 2 must be 3 finite numbers".to_string()),
        ("{}", "no constraint given".to_string()),
    ];
    for (text, needle) in cases.iter() {
        std::fs::write(d.join("bad.json"), text).unwrap();
        let o = meshdeco(&["pose", model.to_str().unwrap(), "--constraints", "bad.json", "--out", "x.obj"], &d);
        let e = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!o.status.success(), "`{text}` should fail");
        assert!(e.contains(needle.as_str()), "`{needle}` not in: {e}");
        assert!(!e.contains("panicked"), "{e}");
        assert!(!d.join("x.obj").exists());
    }
    // Linear models on triangle gradients are refused, naming method and representation.
    let tg = train(&d, "pca-tg", "kind = \"pca\"\ncomponents = 3\nrepresentation = \"triangle-gradient\"");
    std::fs::write(d.join("ok.json"), "{\"3\": [0, 0, 0]}").unwrap();
    let o = meshdeco(&["pose", tg.to_str().unwrap(), "--constraints", "ok.json", "--out", "x.obj"], &d);
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success() && e.contains("`pca` model on the `triangle-gradient` representation"), "{e}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// The drag benchmark as a user runs it, on test frames given as a NumPy `.npy` (its
/// connectivity is the model's): the printed rows parse (the max motion's median ≤ p90 ≤ max,
/// the null's columns, the README row), the landing is small and the posed Erms below the
/// neutral's with the defaults (the data prior) and the shape prior; a bad --reach or --prior is
/// refused naming it; `encode` reads the same `.npy`; a `.npz` without its array name is refused
/// with the spelling to use.
#[test]
fn drag_bench_on_numpy_test_frames() {
    let d = tmp("bench");
    let model = train(&d, "splocs", "kind = \"splocs\"\ncomponents = 6\nsupport = [0.05, 0.3]\nweights = \"signed\"");
    let seq = synthetic::load("synthetic:bumps").unwrap();
    mesh::npy::write_npy(&d.join("test.npy"), &seq.frames[30..]).unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["drag-bench", model.to_str().unwrap(), "test.npy", "--drags", "12", "--pins", "1,3"];
        args.extend_from_slice(extra);
        let o = meshdeco(&args, &d);
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(o.status.success(), "{text}{}", String::from_utf8_lossy(&o.stderr));
        // | pins | drags | landing | max motion: median / p90 / max | moved share | frame share |
        // posed | null | neutral | posed ÷ null | beats null | improved | ms |
        let rows: Vec<Vec<f64>> = text
            .lines()
            .filter(|l| l.starts_with("| 1 |") || l.starts_with("| 3 |"))
            .map(|l| {
                l.replace(" / ", " | ")
                    .split('|')
                    .map(|c| c.trim().trim_end_matches('%').trim())
                    .filter_map(|c| c.parse().ok())
                    .collect()
            })
            .collect();
        assert_eq!(rows.len(), 2, "{text}");
        assert!(rows.iter().all(|r| r.len() == 15), "{text}");
        assert!(text.lines().any(|l| l.starts_with("row: | ")), "{text}");
        rows
    };
    // The defaults (the data prior for SPLOCS); the shape and the weights prior without reach.
    let data = run(&[]);
    let shape = run(&["--prior", "shape", "--reach", "0"]);
    let weights = run(&["--prior", "weights", "--reach", "0"]);
    // One pin lands (three random pins may include vertices the data never moves).
    assert!(data[0][2] < 1.0 && shape[0][2] < 1.0, "one pin lands {} / {} % of the drag away", data[0][2], shape[0][2]);
    for r in data.iter().chain(&shape) {
        // Frozen weights are never better than the model by construction, but posed ÷ null is
        // the median of the per-drag ratios: it is finite and positive.
        assert!(r[11] > 0.0 && r[11].is_finite(), "{r:?}");
        assert!(r[8] < r[10] + 1e-9, "posed Erms {} not below the neutral shape's {}", r[8], r[10]);
        // Median ≤ p90 ≤ max of the max motion ÷ drag; posed ÷ null is the Erms ratio's median.
        assert!(r[3] <= r[4] + 1e-9 && r[4] <= r[5] + 1e-9, "{r:?}");
    }
    // Reach 1.3 bounds the model's shape; the landing correction adds at most the miss.
    assert!(data[0][5] <= 1.3 + 1.0 + 1e-9, "{:?}", data[0]);
    assert!(weights.iter().all(|r| r[3] <= r[4] + 1e-9 && r[4] <= r[5] + 1e-9), "{weights:?}");
    let o = meshdeco(&["drag-bench", model.to_str().unwrap(), "test.npy", "--reach", "0.5"], &d);
    assert!(
        !o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--reach 0.5"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = meshdeco(&["drag-bench", model.to_str().unwrap(), "test.npy", "--prior", "most"], &d);
    assert!(
        !o.status.success() && String::from_utf8_lossy(&o.stderr).contains("most"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = meshdeco(&["encode", model.to_str().unwrap(), "test.npy", "--out", "enc"], &d);
    assert!(o.status.success(), "encode test.npy: {}", String::from_utf8_lossy(&o.stderr));
    mesh::npy::write_npz(&d.join("t.npz"), &[("frames", &seq.frames[30..])]).unwrap();
    let o = meshdeco(&["encode", model.to_str().unwrap(), "t.npz", "--out", "enc2"], &d);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("t.npz:<array>"), "{}", String::from_utf8_lossy(&o.stderr));
    let o = meshdeco(&["encode", model.to_str().unwrap(), "t.npz:frames", "--out", "enc3"], &d);
    assert!(o.status.success(), "encode t.npz:frames: {}", String::from_utf8_lossy(&o.stderr));
    std::fs::remove_dir_all(&d).unwrap();
}

/// The landing correction (`--spread`): a vertex the training data never moves cannot be moved
/// by SPLOCS's components, so with `--spread 0` the drag misses by (almost) all of it; with the
/// default it lands, and only vertices within the radius along the surface differ from the
/// model's shape. A radius outside 0..1 is refused naming the flag.
#[test]
fn spread_lands_a_drag_the_components_cannot_make() {
    let d = tmp("spread");
    let dir = train(&d, "splocs", "kind = \"splocs\"\ncomponents = 3");
    let seq = synthetic::load("synthetic:bumps").unwrap();
    let rest = &seq.frames[0];
    let still = (0..rest.len())
        .min_by(|&a, &b| {
            let m = |v: usize| seq.frames.iter().map(|f| mesh::dist(f[v], rest[v])).fold(0.0, f64::max);
            m(a).total_cmp(&m(b)).then(a.cmp(&b))
        })
        .unwrap();
    let model = load_model(&dir).unwrap();
    let w0 = model.start_weights(None).unwrap();
    let start = model.decode(std::slice::from_ref(&w0)).unwrap().remove(0);
    let p = start[still];
    let amount = 0.03;
    let t: Vec3 = [p[0], p[1], p[2] + amount];
    let cons = d.join("c.json");
    std::fs::write(&cons, format!("{{\"{still}\": [{}, {}, {}]}}", t[0], t[1], t[2])).unwrap();
    let pose = |spread: &str, out: &str| {
        meshdeco(&["pose", dir.to_str().unwrap(), "-c", "c.json", "--out", out, "--spread", spread], &d)
    };
    let o = pose("0", "model.obj");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = pose("0.1", "landed.obj");
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("landing correction (--spread 0.1)"), "{stdout}");
    let own = mesh::load_mesh(&d.join("model.obj")).unwrap().positions;
    let landed = mesh::load_mesh(&d.join("landed.obj")).unwrap().positions;
    let miss = mesh::dist(own[still], t) / amount;
    assert!(miss > 0.5, "the components moved the still vertex: {:.1}% of the drag left", 100.0 * miss);
    let err = mesh::dist(landed[still], t) / amount;
    assert!(err < 1e-4, "landed {:.4}% of the drag away", 100.0 * err);
    let (lo, hi) = model.rest().bounding_box();
    let radius = 0.1 * mesh::dist(lo, hi);
    let mut near_moved = 0;
    for v in 0..own.len() {
        let moved = mesh::dist(own[v], landed[v]);
        // Along the surface is never shorter than straight through space.
        if mesh::dist(model.rest().positions[v], model.rest().positions[still]) >= radius {
            assert!(moved < 1e-6, "vertex {v} beyond the radius moved by {moved}");
        } else if moved > 1e-6 {
            near_moved += 1;
        }
        assert!(moved <= 1.0001 * amount, "vertex {v} moved {moved}, more than the drag");
    }
    assert!(near_moved >= 5, "the correction should carry the pin's neighbours ({near_moved})");
    let o = pose("2", "bad.obj");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--spread 2"), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!d.join("bad.obj").exists());
    std::fs::remove_dir_all(&d).unwrap();
}

/// The drag benchmark's null row (the same drags posed by the landing correction alone, the
/// weights frozen): on test frames the components can make (the tube's bumps, which SPLOCS
/// learned) the posed shape is far closer to the frame than the null (posed ÷ null well below 1,
/// most drags beat it); on frames they cannot make (the whole tube stretched along its axis:
/// no bump moves any vertex along the axis) the model adds nothing (posed ÷ null ≈ 1, no drag
/// beats it by more than 1 %). Frozen, the null equals the posed row.
#[test]
fn drag_bench_null_row_tells_what_the_components_add() {
    use meshdeco::eval::drag::{DragBenchConfig, drag_bench};
    use meshdeco::mesh::MeshSequence;
    let d = tmp("null");
    let dir = train(&d, "splocs", "kind = \"splocs\"\ncomponents = 3");
    let model = load_model(&dir).unwrap();
    let seq = synthetic::load("synthetic:bumps").unwrap();
    let frames = |f: Vec<Vec<Vec3>>| MeshSequence {
        faces: seq.faces.clone(),
        names: (0..f.len()).map(|i| format!("f{i}")).collect(),
        frames: f,
    };
    let can = frames(seq.frames[30..].to_vec());
    let rest = model.rest().positions;
    let (lo, hi) = model.rest().bounding_box();
    let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap();
    let cannot = frames(
        [0.03, -0.03, 0.05]
            .iter()
            .map(|s| {
                rest.iter()
                    .map(|p| {
                        let mut q = *p;
                        q[axis] = lo[axis] + (1.0 + s) * (p[axis] - lo[axis]);
                        q
                    })
                    .collect()
            })
            .collect(),
    );
    // A landing radius of 5 % of the diagonal (the null carries the pins' neighbourhoods only),
    // a weak pull and no reach: what the components can do, they do.
    let options = PoseOptions { spread: 0.05, gamma: 0.001, reach: 0.0, ..model.pose_defaults() };
    let cfg = DragBenchConfig { drags: 12, pins: vec![3, 10], seed: 0, options };
    let (_, yes) = drag_bench(model.as_ref(), &can, &cfg).unwrap();
    let (_, no) = drag_bench(model.as_ref(), &cannot, &cfg).unwrap();
    for (y, n) in yes.iter().zip(&no) {
        eprintln!(
            "{} pins: can make: posed ÷ null {:.3}, beats null {:.0} %; cannot: {:.3}, {:.0} %",
            y.pins,
            y.medians.null_ratio,
            100.0 * y.beats_null_share,
            n.medians.null_ratio,
            100.0 * n.beats_null_share
        );
        assert!(
            y.medians.null_ratio < 0.8,
            "{} pins, frames the model can make: posed ÷ null {}",
            y.pins,
            y.medians.null_ratio
        );
        assert!(y.beats_null_share >= 0.9, "{} pins: {} beat the null", y.pins, y.beats_null_share);
        assert!(
            (n.medians.null_ratio - 1.0).abs() < 0.02,
            "{} pins, frames the model cannot make: posed ÷ null {}",
            n.pins,
            n.medians.null_ratio
        );
        assert!(n.beats_null_share <= 0.1, "{} pins: {} beat the null", n.pins, n.beats_null_share);
    }
    let frozen = DragBenchConfig { options: options.frozen(), ..cfg };
    let (rows, _) = drag_bench(model.as_ref(), &can, &frozen).unwrap();
    assert!(rows.iter().all(|r| (r.measures.null_ratio - 1.0).abs() < 1e-12), "frozen: the null is the posed shape");
    std::fs::remove_dir_all(&d).unwrap();
}
