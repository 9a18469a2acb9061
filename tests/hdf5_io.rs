//! HDF5 in and out, against files written by h5py (the field's tools write theirs with it):
//!
//! - the SPLOCS reference's layout (`verts` F × N × 3 float32, gzip, with `tris`) and DFAUST's
//!   (`50002_jumping_jacks` N × 3 × F, chunked, gzip + shuffle, faces from `data.template`) train
//!   the same model as the same frames from a `.npy`: train Erms and every training weight equal
//!   to 1e-12 relative (synthetic tube always; SCAPE from ../shared);
//! - `meshdeco export --out m.h5` read back by h5py: `weights` equals `weights.csv`, `comp<k>`
//!   equals `meshdeco synthesize --weights k:1`, `default` the neutral shape, `verts` the model's
//!   reconstruction, `tris` the faces;
//! - bad files (missing dataset, wrong rank, NaN, integer coordinates, a truncated file, a
//!   10⁹-frame header chunked or contiguous, never written, chunks missing) are refused with exit status 1 and a
//!   message naming the file and the dataset, and nothing is written.
//!
//! h5py comes from `$MESHDECO_PYTHON` or the venv `.ci/run` makes (`target/tmp/py-venv`); without
//! one the tests are skipped with a printed reason, with `CI` set they fail.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{fresh_dir, json_lines, meshdeco, output_text, weights_csv};
use meshdeco::mesh::MeshSequence;
use serde_json::Value;

fn h5py_python() -> Option<PathBuf> {
    common::python_with("MESHDECO_PYTHON", "py-venv", "h5py, numpy")
}

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/hdf5_files.py");

fn python(py: &Path, args: &[&str]) -> Value {
    let o = Command::new(py).arg(SCRIPT).args(args).output().unwrap();
    assert!(o.status.success(), "hdf5_files.py {args:?}: {}", output_text(&o));
    json_lines(&o).pop().unwrap()
}

/// A little-endian `.npy` of `dims` with `descr` (`<f8`, `<i8`) and the raw bytes.
fn write_npy(path: &Path, descr: &str, dims: &[usize], data: &[u8]) {
    let shape = dims.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ");
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({shape},), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((header.len() as u16).to_le_bytes());
    b.extend(header.as_bytes());
    b.extend(data);
    std::fs::write(path, b).unwrap();
}

/// Writes `seq` as frames.npy (f64), faces.npy (i64) and template.obj, then h5py's files.
fn write_inputs(py: &Path, d: &Path, seq: &MeshSequence) -> Value {
    let (f, n) = (seq.n_frames(), seq.n_vertices());
    let frames: Vec<u8> = seq.frames.iter().flatten().flatten().flat_map(|x| x.to_le_bytes()).collect();
    write_npy(&d.join("frames.npy"), "<f8", &[f, n, 3], &frames);
    let faces: Vec<u8> = seq.faces.iter().flatten().flat_map(|&i| (i as i64).to_le_bytes()).collect();
    write_npy(&d.join("faces.npy"), "<i8", &[seq.faces.len(), 3], &faces);
    let template = meshdeco::mesh::TriMesh::new(seq.frames[0].clone(), seq.faces.clone());
    meshdeco::mesh::write_obj(&d.join("template.obj"), &template).unwrap();
    let d_str = d.to_str().unwrap();
    python(py, &["write", &format!("{d_str}/frames.npy"), &format!("{d_str}/faces.npy"), d_str])
}

fn train(d: &Path, name: &str, data: &str, method: &str) -> std::process::Output {
    let cfg = d.join(format!("{name}.toml"));
    std::fs::write(&cfg, format!("name = \"{name}\"\n[data]\n{data}\n[method]\n{method}\n")).unwrap();
    meshdeco(&["train", "--config", cfg.to_str().unwrap(), "--out", d.join(name).to_str().unwrap()], d)
}

fn train_erms(model: &Path) -> f64 {
    let m: Value = serde_json::from_str(&std::fs::read_to_string(model.join("metrics.json")).unwrap()).unwrap();
    m["train_erms"].as_f64().unwrap()
}

/// Asserts that `a` and `b` agree to 1e-12 of their largest magnitude (at least 1).
fn close(a: &[f64], b: &[f64], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let scale = b.iter().fold(1.0f64, |m, x| m.max(x.abs()));
    let worst = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    assert!(worst <= 1e-12 * scale, "{what}: differs by {worst}");
}

fn relative(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE)
}

/// Trains `method` on the `.npy`, the SPLOCS-layout and the DFAUST-layout file of `d` and checks
/// that the three agree to 1e-12 relative.
fn same_model_from_npy_and_hdf5(d: &Path, method: &str) {
    let t = d.join("template.obj");
    let t = t.to_str().unwrap();
    let runs = [
        ("npy", format!("path = \"frames32.npy\"\ntemplate = \"{t}\"")),
        ("splocs_h5", "path = \"splocs.h5\"".to_string()),
        ("dfaust_h5", format!("path = \"dfaust.h5\"\ndataset = \"50002_jumping_jacks\"\ntemplate = \"{t}\"")),
    ];
    let mut results = Vec::new();
    for (name, data) in &runs {
        let o = train(d, name, data, method);
        assert!(o.status.success(), "{name}: {}", output_text(&o));
        results.push((name, train_erms(&d.join(name)), weights_csv(&d.join(name))));
    }
    let (_, erms0, w0) = &results[0];
    for (name, erms, w) in &results[1..] {
        assert!(relative(*erms0, *erms) <= 1e-12, "{name}: train Erms {erms} vs the .npy's {erms0}");
        assert_eq!(w.len(), w0.len(), "{name}: frames");
        let scale = w0.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let worst = w.iter().flatten().zip(w0.iter().flatten()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst <= 1e-12 * scale, "{name}: weights differ from the .npy's by {worst} (largest weight {scale})");
        eprintln!(
            "{}: {name}: train Erms {erms} (npy {erms0}); weights within {:.1e} relative",
            d.display(),
            worst / scale
        );
    }
    // Frame names follow the dataset.
    let names = std::fs::read_to_string(d.join("dfaust_h5/weights.csv")).unwrap();
    assert!(names.lines().nth(1).unwrap().starts_with("50002_jumping_jacks_"), "{names}");
}

#[test]
fn h5py_splocs_and_dfaust_layouts_train_as_the_same_frames_from_npy() {
    let Some(py) = h5py_python() else { return };
    let d = fresh_dir("hdf5", "tube");
    let seq = meshdeco::preprocess::load_frames("synthetic:tube").unwrap();
    let info = write_inputs(&py, &d, &seq);
    eprintln!("h5py files: {info}");
    same_model_from_npy_and_hdf5(&d, "kind = \"splocs\"\ncomponents = 8\nmax_iterations = 5");
    same_model_from_npy_and_hdf5(&d, "kind = \"pca\"\ncomponents = 6");
    // `inspect` and `encode` read the same paths.
    let o = meshdeco(&["inspect", "splocs.h5", "--json"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["frames"].as_u64(), Some(seq.n_frames() as u64), "{r}");
    let o = meshdeco(&["encode", "npy", "dfaust.h5:50002_punching", "--out", "enc"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    assert_eq!(weights_csv(&d.join("enc")).len(), seq.n_frames());
}

#[test]
fn h5py_scape_trains_as_the_same_frames_from_npy() {
    let Some(py) = h5py_python() else { return };
    let Some(scape) = common::shared_or_skip("data/scape") else { return };
    let d = fresh_dir("hdf5", "scape");
    let seq = meshdeco::preprocess::load_frames(scape.to_str().unwrap()).unwrap();
    write_inputs(&py, &d, &seq);
    same_model_from_npy_and_hdf5(
        &d,
        "kind = \"splocs\"\ncomponents = 50\nmax_iterations = 10\nsupport = [0.1, 0.7]\nsparsity = 2.0",
    );
}

#[test]
fn splocs_layout_export_reads_back_in_h5py_as_the_model() {
    let Some(py) = h5py_python() else { return };
    let d = fresh_dir("hdf5", "export");
    let model = common::train_tube(&d, "tube-splocs", "kind = \"splocs\"\ncomponents = 6\nmax_iterations = 3");
    let o = meshdeco(&["export", model.to_str().unwrap(), "--out", "m.h5"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let h = python(&py, &["read-export", d.join("m.h5").to_str().unwrap()]);
    let k = 6;
    let mut names: Vec<&String> = h.as_object().unwrap().keys().collect();
    names.sort();
    let mut expected: Vec<String> = (0..k).map(|i| format!("comp{i:03}")).collect();
    expected.extend(["default", "tris", "verts", "weights"].map(String::from));
    expected.sort();
    assert_eq!(names.into_iter().cloned().collect::<Vec<_>>(), expected);
    let nums = |v: &Value| -> Vec<f64> {
        fn walk(v: &Value, out: &mut Vec<f64>) {
            match v {
                Value::Array(a) => a.iter().for_each(|x| walk(x, out)),
                x => out.push(x.as_f64().unwrap()),
            }
        }
        let mut out = Vec::new();
        walk(v, &mut out);
        out
    };
    // weights == weights.csv
    let csv = weights_csv(&model);
    assert_eq!(h["weights"]["shape"], serde_json::json!([csv.len(), k]));
    assert_eq!(h["weights"]["dtype"], "float64");
    let w = nums(&h["weights"]["values"]);
    for (a, b) in w.iter().zip(csv.iter().flatten()) {
        assert!(relative(*a, *b) <= 1e-12, "weights: h5 {a}, weights.csv {b}");
    }
    // comp<k> == synthesize k:1; default == synthesize with every weight 0.
    let flat = |p: &[[f64; 3]]| p.iter().flatten().copied().collect::<Vec<f64>>();
    let o = meshdeco(&["synthesize", model.to_str().unwrap(), "--weights", "0:0", "--out", "neutral.obj"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let neutral = flat(&common::obj_vertices(&d.join("neutral.obj")));
    close(&nums(&h["default"]["values"]), &neutral, "default");
    let mut comps = Vec::new();
    for i in 0..k {
        let out = format!("c{i}.obj");
        let o = meshdeco(&["synthesize", model.to_str().unwrap(), "--weights", &format!("{i}:1"), "--out", &out], &d);
        assert!(o.status.success(), "{}", output_text(&o));
        let c = nums(&h[format!("comp{i:03}")]["values"]);
        close(&c, &flat(&common::obj_vertices(&d.join(&out))), &format!("comp{i:03}"));
        comps.push(c);
    }
    // verts == default + Σ w (comp − default), the model's reconstruction of each frame.
    let verts = nums(&h["verts"]["values"]);
    let n3 = neutral.len();
    assert_eq!(verts.len(), csv.len() * n3);
    let mut worst = 0.0f64;
    for (fi, row) in csv.iter().enumerate() {
        for j in 0..n3 {
            let blend = neutral[j] + (0..k).map(|c| row[c] * (comps[c][j] - neutral[j])).sum::<f64>();
            worst = worst.max((blend - verts[fi * n3 + j]).abs());
        }
    }
    assert!(worst <= 1e-12, "verts differ from default + weights × components by {worst}");
    // tris == the model's faces.
    let seq = meshdeco::preprocess::load_frames("synthetic:tube").unwrap();
    let tris: Vec<usize> = nums(&h["tris"]["values"]).iter().map(|&x| x as usize).collect();
    assert_eq!(tris, seq.faces.iter().flatten().copied().collect::<Vec<_>>());

    // A model that is not linear in vertex positions is refused, nothing written.
    let grad = common::train_tube(
        &d,
        "tube-grad",
        "kind = \"splocs\"\nrepresentation = \"triangle-gradient\"\ncomponents = 4\nmax_iterations = 2",
    );
    let o = meshdeco(&["export", grad.to_str().unwrap(), "--out", "g.h5"], &d);
    assert_eq!(o.status.code(), Some(1), "{}", output_text(&o));
    assert!(output_text(&o).contains("triangle-gradient"), "{}", output_text(&o));
    assert!(!d.join("g.h5").exists());
}

#[test]
fn bad_hdf5_files_are_refused_naming_file_and_dataset() {
    let Some(py) = h5py_python() else { return };
    let d = fresh_dir("hdf5", "bad");
    let seq = meshdeco::preprocess::load_frames("synthetic:tube").unwrap();
    write_inputs(&py, &d, &seq);
    let cases = [
        ("bad_missing.h5", "no dataset `verts` (datasets: tris, vertices)"),
        ("bad_rank.h5", "rank 2"),
        ("bad_nan.h5", "frame 3 (0-based 2), vertex 5, coordinate 1 is not finite"),
        ("bad_int.h5", "expected float32 or float64"),
        ("bad_truncated.h5", "truncated"),
        ("bad_huge_chunked.h5", "more than the file's"),
        ("bad_huge.h5", "more than the file's"),
        ("bad_partial.h5", "chunks its shape needs"),
        ("dfaust.h5", "no dataset `verts`"),
    ];
    for (file, says) in cases {
        let name = file.trim_end_matches(".h5");
        let o = train(&d, name, &format!("path = \"{file}\""), "kind = \"pca\"\ncomponents = 3");
        let text = output_text(&o);
        assert_eq!(o.status.code(), Some(1), "{file}: {text}");
        assert!(text.contains(file) && text.contains("verts") && text.contains(says), "{file}: {text}");
        assert!(!text.contains("panicked"), "{file}: {text}");
        assert!(!d.join(name).exists(), "{file}: an artefact directory was left");
        eprintln!("{file}: {}", text.lines().find(|l| l.contains("error")).unwrap_or(&text));
    }
    // A DFAUST file has no faces: the error names data.template.
    let o = train(
        &d,
        "nofaces",
        "path = \"dfaust.h5\"\ndataset = \"50002_jumping_jacks\"",
        "kind = \"pca\"\ncomponents = 3",
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(output_text(&o).contains("data.template") && output_text(&o).contains("dfaust.h5"), "{}", output_text(&o));
    // data.dataset on a non-HDF5 path, and twice.
    let o = train(&d, "k1", "path = \"synthetic:tube\"\ndataset = \"verts\"", "kind = \"pca\"\ncomponents = 3");
    assert!(output_text(&o).contains("data.dataset"), "{}", output_text(&o));
    let o = train(&d, "k2", "path = \"splocs.h5:verts\"\ndataset = \"verts\"", "kind = \"pca\"\ncomponents = 3");
    assert!(output_text(&o).contains("data.dataset") && o.status.code() == Some(1), "{}", output_text(&o));
    // `inspect` and `encode` refuse the same way.
    let o = meshdeco(&["inspect", "bad_nan.h5"], &d);
    assert_eq!(o.status.code(), Some(1));
    assert!(output_text(&o).contains("bad_nan.h5") && output_text(&o).contains("not finite"), "{}", output_text(&o));
}
