//! Bad input and concurrent use end in a clear error, a non-zero exit and nothing written
//! (issue 15, cases 3, 4, 5, 9 and the duplicate-key part of 10).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

mod common;
use common::{meshdeco, output_text};
use std::time::{Duration, Instant};

fn tmp(tag: &str) -> PathBuf {
    common::fresh_dir("reliability", tag)
}

fn fails_with(o: &Output, needle: &str) {
    let t = output_text(o);
    assert!(!o.status.success(), "expected a failure: {t}");
    assert!(t.contains(needle), "`{needle}` not in: {t}");
    assert!(!t.contains("panicked") && !t.contains("NaN") && !t.contains(" inf"), "{t}");
}

fn train_pca(d: &Path) -> PathBuf {
    let cfg = d.join("pca.toml");
    std::fs::write(
        &cfg,
        "[data]\npath = \"synthetic:bumps\"\ntrain = \"1-30\"\n[method]\nkind = \"pca\"\ncomponents = 3\n",
    )
    .unwrap();
    let out = d.join("pca");
    let o = meshdeco(&["train", "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()], d);
    assert!(o.status.success(), "{}", output_text(&o));
    out
}

#[test]
fn pose_refuses_absurd_targets_bad_flags_and_duplicate_keys() {
    let d = tmp("pose");
    let model = train_pca(&d);
    let m = model.to_str().unwrap();
    let out = d.join("posed.obj");
    let o = out.to_str().unwrap();
    for (i, (json, flags, needle)) in [
        (r#"{"5": [1e300, 0, 0]}"#, vec![], "1000 × its bounding-box diagonal"),
        (r#"{"5": [0.1, 0, 0], "5": [0.2, 0, 0]}"#, vec![], "vertex 5 is constrained twice"),
        (r#"{"5": [0.1, 0, 0], "05": [0.2, 0, 0]}"#, vec![], "vertex 5 is constrained twice"),
        (r#"{"5": [0.1, 0, 0]}"#, vec!["--local-radius=-1"], "--local-radius -1"),
        (r#"{"5": [0.1, 0, 0]}"#, vec!["--gamma=-1"], "--gamma -1"),
        (r#"{"5": [0.1, 0, 0]}"#, vec!["--beta=-0.5"], "--beta -0.5"),
        (r#"{"5": [0.1, 0, 0]}"#, vec!["--max-iterations", "0"], "--max-iterations"),
    ]
    .into_iter()
    .enumerate()
    {
        let c = d.join(format!("c{i}.json"));
        std::fs::write(&c, json).unwrap();
        let mut args = vec!["pose", m, "--constraints", c.to_str().unwrap(), "--out", o];
        args.extend(flags);
        let r = meshdeco(&args, &d);
        fails_with(&r, needle);
        assert!(!out.exists(), "case {i} wrote {o}");
        assert!(
            !output_text(&r).contains("config key"),
            "case {i}: a flag is reported as a config key: {}",
            output_text(&r)
        );
    }
    // A sane drag still works.
    let c = d.join("ok.json");
    std::fs::write(&c, r#"{"5": [0.1, 0.0, 0.0]}"#).unwrap();
    let r = meshdeco(&["pose", m, "--constraints", c.to_str().unwrap(), "--out", o], &d);
    assert!(r.status.success() && out.exists(), "{}", output_text(&r));
    // `encode`'s refinement flags are named as flags too, and nothing is written.
    let enc = d.join("enc");
    for (flags, needle) in [(vec!["--fit", "0"], "--fit 0"), (vec!["--fit", "10", "--fit-gamma=-1"], "--fit-gamma -1")]
    {
        let mut args = vec!["encode", m, "synthetic:tube", "--out", enc.to_str().unwrap()];
        args.extend(flags);
        let r = meshdeco(&args, &d);
        fails_with(&r, needle);
        assert!(!output_text(&r).contains("config key"), "{}", output_text(&r));
        assert!(!enc.exists());
    }
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_second_writer_of_an_artefact_directory_is_refused_at_once() {
    let d = tmp("lock");
    let cfg = d.join("ae.toml");
    std::fs::write(
        &cfg,
        "[data]\npath = \"synthetic:tube\"\ntrain = \"every:2\"\ntest = \"rest\"\n[method]\nkind = \"autoencoder\"\ncomponents = 4\niterations = 400\ncheckpoint_every = 100\nfit_test = false\n",
    )
    .unwrap();
    let out = d.join("run");
    let args = ["train", "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let mut first = Command::new(env!("CARGO_BIN_EXE_meshdeco"))
        .args(args)
        .current_dir(&d)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the first run holds the directory (its lock file appears).
    let lock = meshdeco::artifact::lock_path(&out).unwrap();
    let t0 = Instant::now();
    while !lock.exists() {
        assert!(t0.elapsed() < Duration::from_secs(60), "the first run never locked {}", out.display());
        std::thread::sleep(Duration::from_millis(20));
    }
    let t = Instant::now();
    let second = meshdeco(&args, &d);
    let waited = t.elapsed();
    let first_done = first.try_wait().unwrap().is_some();
    let status = first.wait().unwrap();
    if !first_done {
        // The second run was refused while the first was still training.
        fails_with(&second, "is being written by another meshdeco process (pid");
        assert!(output_text(&second).contains(&out.display().to_string()), "{}", output_text(&second));
        assert!(waited < Duration::from_secs(10), "the second run waited {waited:?}");
    }
    assert!(status.success(), "the first run failed");
    // The first run's log is intact: one JSON object per line, iterations 1..=400 once each.
    let log = std::fs::read_to_string(out.join("training.jsonl")).unwrap();
    let its: Vec<u64> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["iteration"].as_u64().unwrap())
        .collect();
    assert_eq!(its, (1..=400).collect::<Vec<u64>>());
    assert!(!lock.exists(), "the lock file outlived the run");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn non_regular_files_are_named_as_such() {
    let d = tmp("special");
    let fifo = d.join("pipe.obj");
    let made = Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
    let link = d.join("zero.obj");
    std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
    let mut cases =
        vec![("/dev/zero".to_string(), "character device"), (link.display().to_string(), "character device")];
    if made {
        cases.push((fifo.display().to_string(), "FIFO"));
    }
    for (path, kind) in cases {
        let o = meshdeco(&["inspect", &path], &d);
        fails_with(&o, "not a regular file");
        assert!(output_text(&o).contains(kind) && output_text(&o).contains(&path), "{}", output_text(&o));
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// Runs the binary with `args` in `cwd` under an address-space limit of `bytes` (as
/// `prlimit --as`).
#[cfg(unix)]
fn meshdeco_within(bytes: u64, args: &[&str], cwd: &Path) -> Output {
    use std::os::unix::process::CommandExt;
    let mut c = Command::new(env!("CARGO_BIN_EXE_meshdeco"));
    c.args(args).current_dir(cwd).stdin(Stdio::null());
    // SAFETY: only setrlimit, which is async-signal-safe, runs between fork and exec.
    unsafe {
        c.pre_exec(move || {
            let limit = libc::rlimit { rlim_cur: bytes, rlim_max: bytes };
            if libc::setrlimit(libc::RLIMIT_AS, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    c.output().unwrap()
}

/// Issue 55, cause 1: `pose` with 20 000 pins on a 22 801-vertex grid under a 4 GB address
/// space. Overlapping pins (the default spread) are refused at once with a clear error naming
/// the constraints file and the bound (before: a dense 20 000² system, an allocation failure,
/// exit 101); pins whose corrections do not overlap (a tiny spread and residual) are answered,
/// each landing.
#[cfg(unix)]
#[test]
fn pose_with_20000_pins_under_4_gb_is_refused_or_answered_never_a_crash() {
    let d = tmp("many-pins");
    let (nx, ny) = (151, 151);
    let (rest, faces) = common::unit_grid(nx, ny);
    let bump = |p: &[f64; 3], cx: f64, cy: f64| (-((p[0] - cx).powi(2) + (p[1] - cy).powi(2)) / 0.02).exp();
    let data = d.join("grid");
    std::fs::create_dir_all(&data).unwrap();
    for f in 0..3 {
        let frame: Vec<[f64; 3]> =
            rest.iter().map(|p| [p[0], p[1], [0.0, 0.1 * bump(p, 0.3, 0.3), 0.1 * bump(p, 0.7, 0.6)][f]]).collect();
        meshdeco::mesh::write_obj(
            &data.join(format!("{}.obj", f + 1)),
            &meshdeco::mesh::TriMesh::new(frame, faces.clone()),
        )
        .unwrap();
    }
    let model = common::train_cli(
        &d,
        "grid-pca",
        &format!("path = {:?}", data.to_str().unwrap()),
        "kind = \"pca\"\ncomponents = 1",
    );
    let n = nx * ny;
    // 20 000 distinct vertices (7919 is prime to 151²).
    let pins: Vec<usize> = (0..20_000).map(|i| i * 7919 % n).collect();
    // Targets: the training mean (PCA's start, which its one component cannot leave by much
    // for such small moves) lifted by up to 6 × `lift`.
    let target = |v: usize, lift: f64| {
        let p = &rest[v];
        [p[0], p[1], 0.1 * (bump(p, 0.3, 0.3) + bump(p, 0.7, 0.6)) / 3.0 + lift * ((v % 13) as f64 - 6.0)]
    };
    let write_pins = |name: &str, lift: f64| {
        let map: serde_json::Map<String, serde_json::Value> =
            pins.iter().map(|&v| (v.to_string(), serde_json::json!(target(v, lift)))).collect();
        let path = d.join(name);
        std::fs::write(&path, serde_json::Value::Object(map).to_string()).unwrap();
        path
    };
    let m = model.to_str().unwrap();
    let out = d.join("posed.obj");
    let o = out.to_str().unwrap();
    let overlapping = write_pins("overlapping.json", 1e-3);
    let r =
        meshdeco_within(4_000_000_000, &["pose", m, "--constraints", overlapping.to_str().unwrap(), "--out", o], &d);
    let t = output_text(&r);
    assert_eq!(r.status.code(), Some(1), "{t}");
    for needle in ["more than 10000 of them", "overlapping.json", "--spread 0.2", "spread 0"] {
        assert!(t.contains(needle), "`{needle}` not in: {t}");
    }
    assert!(!t.contains("panicked") && !t.contains("memory allocation"), "{t}");
    assert!(!out.exists(), "a refused pose wrote {o}");
    // Far apart (a radius below the edge length, residuals of at most 6e-5): one group per pin.
    let apart = write_pins("apart.json", 1e-5);
    let r = meshdeco_within(
        4_000_000_000,
        &[
            "pose",
            m,
            "--constraints",
            apart.to_str().unwrap(),
            "--out",
            o,
            "--spread",
            "0.001",
            "--local-radius",
            "0.01",
        ],
        &d,
    );
    assert!(r.status.success(), "{}", output_text(&r));
    let posed = common::obj_vertices(&out);
    for &v in pins.iter().step_by(97) {
        let target = target(v, 1e-5);
        let miss = (0..3).map(|k| (posed[v][k] - target[k]).powi(2)).sum::<f64>().sqrt();
        assert!(miss < 1e-6, "pin {v} missed its target by {miss}");
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// Issue 55, cause 3: `meshdeco generate` never writes over its own output or an input, never
/// adds a frame to its source, writes the template in the format its extension names (or
/// refuses it), and leaves nothing behind when it fails.
#[test]
fn generate_never_overwrites_an_input_or_itself_and_is_all_or_nothing() {
    let d = tmp("generate");
    // A source folder of six frames.
    let src = d.join("c");
    std::fs::create_dir_all(&src).unwrap();
    let seq = meshdeco::synthetic::load("synthetic:bumps").unwrap();
    for f in 0..6 {
        let m = meshdeco::mesh::TriMesh::new(seq.frames[f].clone(), seq.faces.clone());
        meshdeco::mesh::write_obj(&src.join(format!("{}.obj", f + 1)), &m).unwrap();
    }
    let frame5 = std::fs::read(src.join("5.obj")).unwrap();
    std::fs::create_dir_all(d.join("sub")).unwrap();
    std::fs::create_dir_all(d.join("dir.obj")).unwrap();
    std::fs::write(d.join("t.obj"), "v 0 0 0\n").unwrap();
    std::os::unix::fs::symlink("t.obj", d.join("link.npy")).unwrap();
    let abs = d.join("y.npy");
    let listing = |dir: &Path| {
        let mut v: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    };
    let before = listing(&d);
    let cases: Vec<(Vec<&str>, &str)> = vec![
        // Its own output, spelt two ways (the template is never a .npy), or reached by a link.
        (vec!["synthetic:tube", "--out", "x.npy", "--template", "sub/../x.npy"], "--template sub/../x.npy"),
        (vec!["synthetic:tube", "--out", "y.npy", "--template", abs.to_str().unwrap()], "as .obj, .ply or .off"),
        (vec!["synthetic:tube", "--out", "link.npy", "--template", "sub/../t.obj"], "the same file as --out link.npy"),
        // A frame of the source (the default template beside the output), or a new one.
        (vec!["c", "--out", "c/5.npy"], "a frame of the source c"),
        (vec!["c/*.obj", "--out", "z.npy", "--template", "c/../c/3.obj"], "a frame of the source c/*.obj"),
        (vec!["c", "--out", "z.npy", "--template", "c/new.ply"], "would read it as one more frame"),
        (vec!["c/*.obj", "--out", "z.npy", "--template", "c/new.obj"], "would read it as one more frame"),
        // Formats the template cannot be written in.
        (vec!["synthetic:tube", "--out", "z.npy", "--template", "t.stl"], "--template t.stl"),
        (vec!["synthetic:tube", "--out", "z.npy", "--template", "t"], "--template t:"),
        (vec!["synthetic:tube", "--out", "z.stl.npy", "--template", "z.stl"], "as .obj, .ply or .off"),
        // A template that cannot be written: nothing is left, not even the frames.
        (vec!["synthetic:tube", "--out", "z.npy", "--template", "dir.obj"], "dir.obj"),
        (vec!["synthetic:tube", "--out", "z.npy", "--template", "no/such/t.obj"], "no/such"),
    ];
    for (args, says) in &cases {
        let mut a = vec!["generate"];
        a.extend(args);
        a.extend(["--frames", "5"]);
        let o = meshdeco(&a, &d);
        fails_with(&o, says);
        assert_eq!(listing(&d), before, "{a:?} left files behind");
        assert_eq!(listing(&src), ["1.obj", "2.obj", "3.obj", "4.obj", "5.obj", "6.obj"], "{a:?}");
        assert_eq!(std::fs::read(src.join("5.obj")).unwrap(), frame5, "{a:?} changed a frame");
        assert_eq!(std::fs::read(d.join("t.obj")).unwrap(), b"v 0 0 0\n", "{a:?} changed t.obj");
    }
    // The template in the format its extension names, read back as the source's first frame.
    for (name, head) in [("t.ply", "ply\n"), ("t.off", "OFF"), ("t.OBJ", "v ")] {
        let o = meshdeco(&["generate", "c", "--frames", "5", "--out", "g.npy", "--template", name], &d);
        assert!(o.status.success(), "{}", output_text(&o));
        let text = String::from_utf8_lossy(&std::fs::read(d.join(name)).unwrap()).into_owned();
        assert!(
            text.starts_with(head) || (head == "v " && text.lines().any(|l| l.starts_with(head))),
            "{name}: {text:.60}"
        );
        let back = meshdeco::mesh::load_mesh(&d.join(name)).unwrap();
        assert_eq!(back.faces, seq.faces, "{name}");
        let moved =
            back.positions.iter().zip(&seq.frames[0]).map(|(p, q)| meshdeco::mesh::dist(*p, *q)).fold(0.0, f64::max);
        assert!(moved < 1e-6, "{name}: {moved}");
    }
    assert!(d.join("g.npy").is_file());
    eprintln!("generate cases: {}", cases.len() + 3);
    std::fs::remove_dir_all(&d).unwrap();
}

/// Issue 55, cause 7: `data.validation` beside the autoencoder's `method.validation` is
/// refused before any work, naming both keys (before: both accepted without a word); each
/// alone is accepted.
#[test]
fn data_and_method_validation_together_are_refused_naming_both() {
    let d = tmp("validation");
    let data = "[data]\npath = \"synthetic:tube\"\ntrain = \"1-30\"\n";
    let ae = "[method]\nkind = \"autoencoder\"\ncomponents = 3\niterations = 10\n";
    let both = format!("{data}validation = \"28-30\"\n{ae}validation = 2\n");
    let cfg = d.join("both.toml");
    std::fs::write(&cfg, &both).unwrap();
    let out = d.join("out");
    let o = meshdeco(&["train", "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()], &d);
    fails_with(&o, "data.validation");
    for needle in ["method.validation = 2", "`28-30`", "keep one", "both.toml"] {
        assert!(output_text(&o).contains(needle), "`{needle}` not in {}", output_text(&o));
    }
    assert!(!out.exists(), "a refused config created {}", out.display());
    assert!(meshdeco::config::Config::from_toml(&format!("{data}validation = \"28-30\"\n{ae}")).is_ok());
    assert!(meshdeco::config::Config::from_toml(&format!("{data}{ae}validation = 2\n")).is_ok());
    // Another method has no method.validation: data.validation is its only one.
    let pca = format!("{data}validation = \"28-30\"\n[method]\nkind = \"pca\"\ncomponents = 3\n");
    assert!(meshdeco::config::Config::from_toml(&pca).is_ok());
    std::fs::remove_dir_all(&d).unwrap();
}
