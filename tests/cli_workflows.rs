//! Commands through the command line that `cli_commands.rs` does not cover, each checked by
//! content: `train --resume` (and its error without a checkpoint), `pose` on an autoencoder,
//! `interpolate` (every step, not only the ends), `components` ranking, `eval --replot`,
//! `features`, `roundtrip` and `render`.

mod common;

use std::path::{Path, PathBuf};

use common::meshdeco;
use meshdeco::mesh::Vec3;

fn tmp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-cliwf-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn ok(o: &std::process::Output) -> String {
    assert!(o.status.success(), "exit {:?}: {}", o.status.code(), String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A constant step size (`learning_rate_final` = `learning_rate`): the resume test extends a
/// 20-iteration run to 40, and a decaying rate's schedule depends on `iterations`.
fn ae_config(name: &str, iterations: usize, k: usize) -> String {
    format!(
        "name = \"{name}\"\n[data]\npath = \"synthetic:bumps\"\ntrain = \"1-20\"\ntest = \"rest\"\n[method]\nkind = \"autoencoder\"\n\
         components = {k}\nlayers = 1\niterations = {iterations}\ncheckpoint_every = 10\nlearning_rate = 0.005\n\
         learning_rate_final = 0.005\nseed = 1\n"
    )
}

fn metrics(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap()
}

fn max_dist(a: &[Vec3], b: &[Vec3]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(p, q)| meshdeco::mesh::dist(*p, *q)).fold(0.0, f64::max)
}

/// 20 iterations, then `--resume` to 40, equals 40 uninterrupted iterations (seeded), and the
/// training log holds each iteration once; `--resume` without a checkpoint names the file.
#[test]
fn train_resume_continues_where_the_run_stopped() {
    let d = tmp("resume");
    std::fs::write(d.join("a20.toml"), ae_config("a", 20, 3)).unwrap();
    std::fs::write(d.join("a40.toml"), ae_config("a", 40, 3)).unwrap();
    ok(&meshdeco(&["train", "--config", "a40.toml", "--out", "full"], &d));
    ok(&meshdeco(&["train", "--config", "a20.toml", "--out", "part"], &d));
    let m20 = metrics(&d.join("part"));
    ok(&meshdeco(&["train", "--config", "a40.toml", "--out", "part", "--resume"], &d));
    let (full, part) = (metrics(&d.join("full")), metrics(&d.join("part")));
    eprintln!(
        "resume: train Erms after 20 {}, 40 uninterrupted {}, 20 + resumed 20 {}",
        m20["train_erms"], full["train_erms"], part["train_erms"]
    );
    assert_eq!(part["iterations"], 40);
    for key in ["train_erms", "test_erms", "test_erms_fitted"] {
        let (a, b) = (full[key].as_f64().unwrap(), part[key].as_f64().unwrap());
        assert!((a - b).abs() <= 1e-9 * a.abs(), "{key}: uninterrupted {a}, resumed {b}");
    }
    assert_ne!(m20["train_erms"], full["train_erms"], "20 more iterations changed nothing");
    let log = std::fs::read_to_string(d.join("part/training.jsonl")).unwrap();
    // Step lines carry `iteration`; a run stopped after 20 steps may also log that it did not
    // train yet (`not_trained`), which the resumed run keeps.
    let lines: Vec<serde_json::Value> = log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert!(lines.iter().all(|l| l.get("iteration").is_some() || l.get("not_trained").is_some()), "{log}");
    let its: Vec<u64> = lines.iter().filter_map(|l| l["iteration"].as_u64()).collect();
    assert_eq!(its, (1..=40).collect::<Vec<u64>>(), "training.jsonl iterations after resuming");
    // No checkpoint: a clear error, no panic.
    let o = meshdeco(&["train", "--config", "a40.toml", "--out", "empty", "--resume"], &d);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "--resume without a checkpoint succeeded");
    assert!(e.contains("--resume") && e.contains("no checkpoint") && e.contains("checkpoint.bin"), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `pose` on an autoencoder: a vertex dragged half-way towards its farthest decoded training
/// position lands near the target (the start is the code of the rest mesh, as documented).
#[test]
fn pose_on_an_autoencoder() {
    let d = tmp("aepose");
    std::fs::write(d.join("ae.toml"), ae_config("ae", 150, 6)).unwrap();
    ok(&meshdeco(&["train", "--config", "ae.toml", "--out", "ae"], &d));
    let model = meshdeco::pipeline::load_model(&d.join("ae")).unwrap();
    let start = model.decode(&[model.start_weights(None).unwrap()]).unwrap().remove(0);
    let mut best = (0, 0.0, [0.0; 3]);
    for p in model.decode(&model.train_weights().unwrap()).unwrap() {
        for (v, q) in p.iter().enumerate() {
            let dv = meshdeco::mesh::dist(*q, start[v]);
            if dv > best.1 {
                best = (v, dv, *q);
            }
        }
    }
    let (v, _, far) = best;
    let target: Vec3 = std::array::from_fn(|c| 0.5 * (start[v][c] + far[c]));
    let json = format!(
        "{{\"{v}\": [{}, {}, {}], \"0\": [{}, {}, {}]}}",
        target[0], target[1], target[2], start[0][0], start[0][1], start[0][2]
    );
    std::fs::write(d.join("c.json"), json).unwrap();
    let out = ok(&meshdeco(&["pose", "ae", "--constraints", "c.json", "--out", "posed.obj"], &d));
    let posed = common::obj_vertices(&d.join("posed.obj"));
    let (e0, e) = (meshdeco::mesh::dist(start[v], target), meshdeco::mesh::dist(posed[v], target));
    eprintln!("AE pose via the CLI: vertex {v}, error {e0:.4} → {e:.4}\n{out}");
    assert!(e <= 0.2 * e0, "dragged vertex {v}: error {e0} → {e}");
    assert!(max_dist(&posed, &start) >= 0.5 * e0, "the posed mesh barely moved");
    let _ = std::fs::remove_dir_all(&d);
}

/// `interpolate` on PCA with full rank (exact on the bumps): step s of n is the straight blend
/// (1 − t)·A + t·B, t = s/(n − 1), at every step.
#[test]
fn interpolate_blends_every_step() {
    let d = tmp("interp");
    std::fs::write(
        d.join("pca.toml"),
        "name = \"p\"\n[data]\npath = \"synthetic:bumps\"\n[method]\nkind = \"pca\"\ncomponents = 3\n",
    )
    .unwrap();
    ok(&meshdeco(&["train", "--config", "pca.toml", "--out", "pca"], &d));
    let seq = meshdeco::synthetic::load("synthetic:bumps").unwrap();
    for (name, f) in [("a.obj", 2), ("b.obj", 30)] {
        meshdeco::mesh::write_obj(&d.join(name), &seq.mesh(f)).unwrap();
    }
    ok(&meshdeco(&["interpolate", "pca", "--from", "a.obj", "--to", "b.obj", "--steps", "5", "--out", "interp"], &d));
    let (a, b) = (&seq.frames[2], &seq.frames[30]);
    for s in 0..5 {
        let t = s as f64 / 4.0;
        let want: Vec<Vec3> =
            a.iter().zip(b).map(|(p, q)| std::array::from_fn(|c| (1.0 - t) * p[c] + t * q[c])).collect();
        let got = common::obj_vertices(&d.join(format!("interp/interp_{s:03}.obj")));
        let gap = max_dist(&got, &want);
        assert!(gap < 1e-5, "step {s} (t = {t}): {gap} from the blend");
    }
    assert!(!d.join("interp/interp_005.obj").exists());
    assert!(max_dist(a, b) > 0.01, "the two ends are the same shape");
    let _ = std::fs::remove_dir_all(&d);
}

/// `components` writes a ranked components.csv: ranks 0..K once each; the autoencoder's rank
/// orders dimensions by decreasing extreme distance and names the files by rank.
#[test]
fn components_are_ranked() {
    let d = tmp("comps");
    std::fs::write(d.join("ae.toml"), ae_config("ae", 40, 3)).unwrap();
    ok(&meshdeco(&["train", "--config", "ae.toml", "--out", "ae"], &d));
    ok(&meshdeco(&["components", "ae", "--out", "c"], &d));
    let csv = std::fs::read_to_string(d.join("c/components.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).unwrap_or_else(|| panic!("no column {n} in {csv}"));
    let (dim, rank, dist) = (col("dimension"), col("rank"), col("distance"));
    let rows: Vec<Vec<String>> = lines.map(|l| l.split(',').map(String::from).collect()).collect();
    assert_eq!(rows.len(), 3, "{csv}");
    let mut ranks: Vec<usize> = rows.iter().map(|r| r[rank].parse().unwrap()).collect();
    let mut by_rank: Vec<(usize, f64, String)> =
        rows.iter().map(|r| (r[rank].parse().unwrap(), r[dist].parse().unwrap(), r[dim].clone())).collect();
    by_rank.sort_by_key(|x| x.0);
    for w in by_rank.windows(2) {
        assert!(
            w[0].1 >= w[1].1,
            "rank {} (distance {}) before rank {} (distance {}): {csv}",
            w[0].0,
            w[0].1,
            w[1].0,
            w[1].1
        );
    }
    for (r, _, dm) in &by_rank {
        assert!(d.join(format!("c/{r}_{dm}.obj")).is_file(), "c/{r}_{dm}.obj missing");
    }
    ranks.sort();
    assert_eq!(ranks, vec![0, 1, 2]);
    let _ = std::fs::remove_dir_all(&d);
}

const EVAL: &str = r#"
name = "replot"
[[dataset]]
name = "tube"
path = "synthetic:tube"
train = "every:3"
test = "rest"
ordered = true

[[method]]
label = "pca"
kind = "pca"

[sweep]
components = [2, 4]
"#;

/// `eval --replot` through the command line: the plots come back from the cached cells alone,
/// drawn (pixels other than the background), and the table is unchanged.
#[test]
fn eval_replot_redraws_from_the_cache() {
    let d = tmp("replot");
    std::fs::write(d.join("e.toml"), EVAL).unwrap();
    ok(&meshdeco(&["eval", "--config", "e.toml", "--out", "ev"], &d));
    let csv = std::fs::read_to_string(d.join("ev/results.csv")).unwrap();
    let pngs: Vec<PathBuf> = std::fs::read_dir(d.join("ev"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    assert!(pngs.len() >= 2, "{pngs:?}");
    for p in &pngs {
        std::fs::remove_file(p).unwrap();
    }
    let out = ok(&meshdeco(&["eval", "--config", "e.toml", "--out", "ev", "--replot"], &d));
    eprintln!("{out}");
    assert_eq!(std::fs::read_to_string(d.join("ev/results.csv")).unwrap(), csv);
    for p in &pngs {
        let (w, h, ink, colours) = common::png_ink(p);
        eprintln!("{}: {w}×{h}, {:.1} % ink, {colours} colours", p.display(), 100.0 * ink);
        assert!(ink > 0.01 && colours > 2, "{}: {:.4} of the pixels drawn, {colours} colours", p.display(), ink);
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// `features` writes one row per shape in the reference's layout, equal to the library's ACAP
/// encoding; `roundtrip` reports a near-zero total; `render` draws a picture of the asked size.
#[test]
fn features_roundtrip_and_render() {
    use meshdeco::representation::acap::{Acap, Consistency};
    let d = tmp("feat");
    ok(&meshdeco(&["features", "synthetic:bumps", "--out", "f"], &d));
    let seq = meshdeco::synthetic::load("synthetic:bumps").unwrap();
    let acap = Acap::new(&seq.mesh(0)).unwrap();
    for (file, logr) in [("LOGRNEW.txt", true), ("S.txt", false)] {
        let text = std::fs::read_to_string(d.join("f").join(file)).unwrap();
        let rows: Vec<&str> = text.lines().collect();
        assert_eq!(rows.len(), 40, "{file}");
        for f in [0, 7, 25] {
            let got: Vec<f64> = rows[f].split_whitespace().map(|x| x.parse().unwrap()).collect();
            assert_eq!(got.len(), 1466 * 9, "{file} row {}", f + 1);
            let fr = acap.encode_frame(&seq.frames[f], Consistency::Bfs).unwrap();
            let want = if logr { &fr.log_r } else { &fr.s };
            let worst = want
                .iter()
                .enumerate()
                .flat_map(|(v, m)| (0..9).map(move |i| (v, i, m[i / 3][i % 3])))
                .map(|(v, i, x)| (got[9 * v + i] - x).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-9, "{file} row {}: max difference {worst} from the library's encoding", f + 1);
        }
        let row7: Vec<f64> = rows[7].split_whitespace().map(|x| x.parse().unwrap()).collect();
        let identity = [
            if logr { 0.0 } else { 1.0 },
            0.0,
            0.0,
            0.0,
            if logr { 0.0 } else { 1.0 },
            0.0,
            0.0,
            0.0,
            if logr { 0.0 } else { 1.0 },
        ];
        let off = row7.iter().enumerate().map(|(i, x)| (x - identity[i % 9]).abs()).fold(0.0, f64::max);
        assert!(off > 1e-3, "{file} row 8 is the rest shape's features ({off})");
    }
    for rep in ["acap", "displacement", "triangle-gradient"] {
        let out = ok(&meshdeco(&["roundtrip", "synthetic:bumps", "-r", rep], &d));
        let total: f64 = out
            .lines()
            .find(|l| l.trim_start().starts_with("total"))
            .and_then(|l| l.split_whitespace().nth(1))
            .unwrap_or_else(|| panic!("no total line: {out}"))
            .parse()
            .unwrap();
        eprintln!("roundtrip {rep}: total Erms {total:e}");
        assert!(total < 1e-3, "roundtrip {rep}: total Erms {total}");
        assert_eq!(out.lines().filter(|l| l.contains("bumps0")).count(), 40, "{out}");
    }
    meshdeco::mesh::write_obj(&d.join("m.obj"), &seq.mesh(10)).unwrap();
    ok(&meshdeco(&["render", "m.obj", "--out", "m.png", "--size", "200x150"], &d));
    let (w, h, ink, colours) = common::png_ink(&d.join("m.png"));
    eprintln!("render: {w}×{h}, {:.1} % ink, {colours} colours", 100.0 * ink);
    assert_eq!((w, h), (200, 150));
    assert!(ink > 0.02 && colours > 8, "render drew {ink} of the pixels, {colours} colours");
    let _ = std::fs::remove_dir_all(&d);
}
