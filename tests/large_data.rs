//! Large datasets (issue 28), as a user meets them at a size CI can run: `meshdeco generate`
//! writes a big float32 `.npy`; training with `data.cache` computes the features once into a
//! checksummed file, reads them back on the next run, and trains the autoencoder from that file
//! a batch at a time with exactly the model of the in-memory run; a batch job's stderr (not a
//! terminal) gets plain progress lines.

mod common;

use std::path::Path;

use common::{fresh_dir, meshdeco, output_text};

/// The autoencoder block of the tests: small, mini-batches of 16.
const AE: &str =
    "kind = \"autoencoder\"\ncomponents = 6\niterations = 12\nbatch_size = 16\nlambda_vertex = 1.0\nseed = 3";

fn train(d: &Path, name: &str, data: &str, method: &str, env: &[(&str, &str)]) -> std::process::Output {
    let cfg = d.join(format!("{name}.toml"));
    std::fs::write(&cfg, format!("name = \"{name}\"\n[data]\n{data}\n[method]\n{method}\n")).unwrap();
    let o = run_train(d, name, name, env);
    assert!(o.status.success(), "{name}: {}", output_text(&o));
    o
}

/// `meshdeco train --config <d>/<config>.toml --out <d>/<out>` in `d` with `env` added.
fn run_train(d: &Path, config: &str, out: &str, env: &[(&str, &str)]) -> std::process::Output {
    let (cfg, out) = (d.join(format!("{config}.toml")), d.join(out));
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_meshdeco"));
    cmd.args(["train", "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()]).current_dir(d);
    cmd.envs(env.iter().copied()).output().expect("run meshdeco")
}

/// Trains `<d>/<config>.toml` into `<d>/bad`, which must fail (`what`: the bad input, for the
/// message) and leave no artefact directory; returns stdout and stderr.
fn train_fails(d: &Path, config: &str, env: &[(&str, &str)], what: &str) -> String {
    let o = run_train(d, config, "bad", env);
    let text = output_text(&o);
    assert!(!o.status.success(), "{what} trained: {text}");
    assert!(!d.join("bad").exists(), "a failed run ({what}) left its artefact directory");
    text
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn generate_writes_a_float32_npy_deterministically_and_refuses_bad_arguments() {
    let d = fresh_dir("large", "generate");
    let o = meshdeco(&["generate", "synthetic:tube", "--frames", "300", "--out", "big.npy", "--seed", "4"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let bytes = read(&d.join("big.npy"));
    let header = String::from_utf8_lossy(&bytes[..128]);
    assert!(header.contains("'descr': '<f4'") && header.contains("(300, 1466, 3"), "{header}");
    assert_eq!(bytes.len() % 64, (300 * 1466 * 3 * 4) % 64);
    assert!(d.join("big.obj").is_file(), "the template is written beside it");
    // The same arguments give the same file; another seed another.
    let o = meshdeco(&["generate", "synthetic:tube", "--frames", "300", "--out", "again.npy", "--seed", "4"], &d);
    assert!(o.status.success());
    assert_eq!(read(&d.join("again.npy")), bytes);
    let o = meshdeco(&["generate", "synthetic:tube", "--frames", "300", "--out", "other.npy", "--seed", "5"], &d);
    assert!(o.status.success());
    assert_ne!(read(&d.join("other.npy")), bytes);
    // It trains as NumPy input.
    let data = "path = \"big.npy\"\ntemplate = \"big.obj\"\ntrain = \"1-250\"\ntest = \"rest\"";
    let o = train(&d, "pca", data, "kind = \"pca\"\ncomponents = 5", &[]);
    assert!(output_text(&o).contains("train Erms"), "{}", output_text(&o));
    // Bad arguments: a message naming the flag, a non-zero exit, nothing written.
    for (args, says) in [
        (vec!["--frames", "0", "--out", "z.npy"], "--frames 0"),
        (vec!["--frames", "10", "--out", "z.txt"], "--out"),
        (vec!["--frames", "10", "--out", "z.npy", "--template", "z.npy"], "--template"),
    ] {
        let mut a = vec!["generate", "synthetic:tube"];
        a.extend(args);
        let o = meshdeco(&a, &d);
        assert!(!o.status.success(), "{a:?} succeeded");
        assert!(output_text(&o).contains(says), "{a:?}: {}", output_text(&o));
        assert!(!d.join("z.npy").exists() && !d.join("z.txt").exists(), "{a:?} left a file");
    }
    let o = meshdeco(&["generate", "no/such/dir", "--frames", "3", "--out", "z.npy"], &d);
    assert!(!o.status.success() && output_text(&o).contains("no/such/dir"), "{}", output_text(&o));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn cached_features_train_the_same_autoencoder_a_batch_at_a_time() {
    let d = fresh_dir("large", "cache");
    let o = meshdeco(&["generate", "synthetic:bumps", "--frames", "120", "--out", "b.npy", "--seed", "1"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let data = |cache: &str| {
        format!("path = \"b.npy\"\ntemplate = \"b.obj\"\ntrain = \"1-100\"\ntest = \"rest\"\ncache = \"{cache}\"")
    };
    // In memory (no cache) …
    let mem = train(&d, "mem", &data("off"), AE, &[]);
    assert!(
        !output_text(&mem).contains("features cached") && !output_text(&mem).contains("from the cache"),
        "{}",
        output_text(&mem)
    );
    // … computed into the cache and streamed from it …
    let first = train(&d, "first", &data("cache"), AE, &[]);
    assert!(output_text(&first).contains("features cached in"), "{}", output_text(&first));
    let files: Vec<_> = std::fs::read_dir(d.join("cache")).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(files.len(), 1, "{files:?}");
    // … and read back from it: one model, bit for bit, and the same numbers.
    let second = train(&d, "second", &data("cache"), AE, &[]);
    assert!(output_text(&second).contains("features read from the cache"), "{}", output_text(&second));
    for run in ["first", "second"] {
        for f in ["model.bin", "weights.csv"] {
            assert!(
                read(&d.join("mem").join(f)) == read(&d.join(run).join(f)),
                "{run}/{f} differs from the in-memory run's"
            );
        }
        let metrics = |r: &str| -> serde_json::Value {
            let mut m: serde_json::Value = serde_json::from_slice(&read(&d.join(r).join("metrics.json"))).unwrap();
            m.as_object_mut().unwrap().retain(|k, _| !k.contains("seconds"));
            m
        };
        assert_eq!(metrics("mem"), metrics(run), "{run}");
    }
    // A cache file changed on disk: found when the file is opened (every reused file is read
    // once, issue 55), named with the frame, and recomputed: the same model as in memory, and
    // the file as it was written.
    let clean = read(&files[0]);
    let mut bytes = clean.clone();
    bytes[200] ^= 0x10;
    std::fs::write(&files[0], &bytes).unwrap();
    let third = train(&d, "third", &data("cache"), AE, &[]);
    let text = output_text(&third);
    let name = files[0].file_name().unwrap().to_str().unwrap();
    for needle in ["recomputing the cached features", name, "fails its checksum"] {
        assert!(text.contains(needle), "`{needle}` not in {text}");
    }
    for f in ["model.bin", "weights.csv"] {
        assert!(
            read(&d.join("mem").join(f)) == read(&d.join("third").join(f)),
            "third/{f} differs from the in-memory run's"
        );
    }
    assert!(read(&files[0]) == clean, "the damaged cache file was not recomputed");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_batch_job_gets_plain_progress_lines() {
    let d = fresh_dir("large", "progress");
    // stderr is a pipe here, not a terminal: lines at the interval, stage starts and ends.
    let o = train(
        &d,
        "demo",
        "path = \"synthetic:tube\"\ntrain = \"every:2\"",
        AE,
        &[("MESHDECO_PROGRESS_SECONDS", "0.05")],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("[meshdeco ")).collect();
    assert!(lines.iter().any(|l| l.contains("training: started (12 steps)")), "{err}");
    assert!(lines.iter().any(|l| l.contains("training: done in")), "{err}");
    assert!(lines.iter().any(|l| l.contains("acap features: started")), "{err}");
    // While a stage runs: done/total, share, rate and ETA, or how long it has run.
    assert!(
        lines.iter().any(|l| l.contains("running for") || (l.contains("/12 (") && l.contains("eta"))),
        "no line while a stage ran: {err}"
    );
    // Off with 0.
    let o =
        train(&d, "quiet", "path = \"synthetic:tube\"\ntrain = \"every:2\"", AE, &[("MESHDECO_PROGRESS_SECONDS", "0")]);
    assert!(!String::from_utf8_lossy(&o.stderr).contains("[meshdeco "), "{}", output_text(&o));
    let _ = std::fs::remove_dir_all(&d);
}

/// `train Erms` and `test Erms` of a run's metrics.json.
fn erms(d: &Path, run: &str) -> (f64, f64) {
    let m: serde_json::Value = serde_json::from_slice(&read(&d.join(run).join("metrics.json"))).unwrap();
    (m["train_erms"].as_f64().unwrap(), m["test_erms"].as_f64().unwrap())
}

/// A large `.npy` read a frame at a time (`MESHDECO_STREAM_BYTES`), aligned and scaled on the
/// way, trains the same model bit for bit as the same file held in memory; a bad value is
/// found before training, naming the file and the frame. Catches a frame read from the wrong
/// offset, an alignment or unit box applied twice or not at all, and the rest shape taken from
/// other frames.
#[test]
fn a_large_npy_read_a_frame_at_a_time_trains_the_same_model() {
    let d = fresh_dir("large", "stream");
    let o = meshdeco(&["generate", "synthetic:bumps", "--frames", "90", "--out", "s.npy", "--seed", "2"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let data = "path = \"s.npy\"\ntemplate = \"s.obj\"\ntrain = \"1-70\"\ntest = \"rest\"\nrest = \"mean\"\nalign = \"rigid\"\nunit_box = true\ncache = \"off\"";
    let pca = "kind = \"pca\"\ncomponents = 6";
    train(&d, "mem", data, pca, &[]);
    train(&d, "streamed", data, pca, &[("MESHDECO_STREAM_BYTES", "0")]);
    for f in ["model.bin", "weights.csv"] {
        assert!(read(&d.join("mem").join(f)) == read(&d.join("streamed").join(f)), "{f} differs");
    }
    assert_eq!(erms(&d, "mem"), erms(&d, "streamed"));
    // A NaN in frame 40 (1-based 41): refused when the data is prepared.
    let mut bytes = read(&d.join("s.npy"));
    let header = 10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let frame_bytes = (bytes.len() - header) / 90;
    assert_eq!(frame_bytes, 1466 * 3 * 4, "frames of 1 466 float32 vertices");
    let at = header + 40 * frame_bytes + 8;
    bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(d.join("s.npy"), &bytes).unwrap();
    let text = train_fails(&d, "streamed", &[("MESHDECO_STREAM_BYTES", "0")], "a NaN");
    assert!(text.contains("s.npy") && text.contains("frame 41") && text.contains("not finite"), "{text}");
    let _ = std::fs::remove_dir_all(&d);
}

/// Features held in `f32` (`MESHDECO_COMPACT_BYTES`): PCA by the randomized SVD and SPLOCS with
/// the implicit-residual start give the exact path's Erms to 1e-6 (relative), with the features
/// computed in runs or read from the cache file a frame at a time. Catches a randomized SVD that
/// loses a direction, a rest row or piece weight not applied to the rows in `f32`, and SPLOCS
/// reading its `f32` data at the wrong rows or columns.
#[test]
fn features_in_f32_give_the_exact_erms() {
    let d = fresh_dir("large", "compact");
    let o = meshdeco(&["generate", "synthetic:bumps", "--frames", "90", "--out", "c.npy", "--seed", "5"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let data = |cache: &str| {
        format!("path = \"c.npy\"\ntemplate = \"c.obj\"\ntrain = \"1-70\"\ntest = \"rest\"\ncache = \"{cache}\"")
    };
    let small = [("MESHDECO_COMPACT_BYTES", "0")];
    for (name, method) in [
        ("pca", "kind = \"pca\"\ncomponents = 8"),
        ("splocs", "kind = \"splocs\"\ncomponents = 6\nmax_iterations = 8"),
        // a representation whose rest row is not zero (ACAP: S = I)
        ("splocs-acap", "kind = \"splocs\"\nrepresentation = \"acap\"\ncomponents = 6\nmax_iterations = 8"),
    ] {
        train(&d, &format!("{name}-exact"), &data("off"), method, &[]);
        let runs = [(format!("{name}-f32"), data("off")), (format!("{name}-f32-cached"), data("cache"))];
        for (run, data) in &runs {
            let o = train(&d, run, data, method, &small);
            if run.ends_with("cached") {
                // written by the first method, read by the second
                let text = output_text(&o);
                assert!(text.contains("(read a frame at a time)"), "{text}");
            }
            let (a, b) = (erms(&d, &format!("{name}-exact")), erms(&d, run));
            for (x, y) in [(a.0, b.0), (a.1, b.1)] {
                assert!((x - y).abs() <= 1e-6 * x, "{run}: Erms {y} vs the exact {x}");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// A folder of mesh files too large to hold (`MESHDECO_STREAM_BYTES`) is read a frame at a time:
/// the same model bit for bit as the folder loaded whole, and a frame whose faces differ from
/// the first frame's is refused when the data is prepared, naming its file. Catches frames
/// read out of natural order, a frame's connectivity not checked, and names not the file stems.
#[test]
fn a_large_folder_of_meshes_read_a_frame_at_a_time_trains_the_same_model() {
    let d = fresh_dir("large", "folder");
    let seq = meshdeco::synthetic::load("synthetic:bumps").unwrap();
    std::fs::create_dir_all(d.join("frames")).unwrap();
    for (i, frame) in seq.frames.iter().enumerate() {
        let m = meshdeco::mesh::TriMesh::new(frame.clone(), seq.faces.clone());
        meshdeco::mesh::write_obj(&d.join("frames").join(format!("f{}.obj", i + 1)), &m).unwrap();
    }
    let data = "path = \"frames\"\ntrain = \"every:2\"\ntest = \"rest\"\nalign = \"rigid\"\ncache = \"off\"";
    let pca = "kind = \"pca\"\ncomponents = 5";
    train(&d, "mem", data, pca, &[]);
    train(&d, "streamed", data, pca, &[("MESHDECO_STREAM_BYTES", "0")]);
    for f in ["model.bin", "weights.csv"] {
        assert!(read(&d.join("mem").join(f)) == read(&d.join("streamed").join(f)), "{f} differs");
    }
    assert_eq!(erms(&d, "mem"), erms(&d, "streamed"));
    let names = String::from_utf8(read(&d.join("streamed").join("weights.csv"))).unwrap();
    assert!(names.contains("f1,") && names.contains("f3,") && !names.contains("f2,"), "{names}");
    // Frame 12 with two faces swapped: refused before training, naming the file.
    let mut m = meshdeco::mesh::TriMesh::new(seq.frames[11].clone(), seq.faces.clone());
    m.faces.swap(0, 1);
    meshdeco::mesh::write_obj(&d.join("frames").join("f12.obj"), &m).unwrap();
    let text = train_fails(&d, "streamed", &[("MESHDECO_STREAM_BYTES", "0")], "a frame with other faces");
    assert!(text.contains("f12.obj") && text.contains("face list differs"), "{text}");
    let _ = std::fs::remove_dir_all(&d);
}
