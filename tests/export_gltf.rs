//! `meshdeco export` (glTF 2.0 morph targets) and NumPy data, as a user meets them: the Khronos
//! validator on an export of every model kind, the morph targets replayed against `meshdeco
//! synthesize`, the animation against the model's reconstruction of its training frames, and a
//! sequence written as `.npy` / `.npz` training to the same metrics as the mesh files.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{json_lines, meshdeco, output_text, train_cli as train};

use meshdeco::export::read_glb;
use meshdeco::mesh::{self, Vec3};
use meshdeco::model;
use meshdeco::pipeline::load_model;

fn tmp(tag: &str) -> PathBuf {
    common::fresh_dir("export", tag)
}

const BUMPS: &str = "path = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"rest\"";

const KINDS: [(&str, &str); 6] = [
    ("pca", "kind = \"pca\"\ncomponents = 4"),
    ("splocs", "kind = \"splocs\"\ncomponents = 3"),
    ("splocs-acap", "kind = \"splocs\"\ncomponents = 3\nrepresentation = \"acap\""),
    ("splocs-gradient", "kind = \"splocs\"\ncomponents = 3\nrepresentation = \"triangle-gradient\""),
    ("region", "kind = \"region-pca\"\ncomponents = 12\nregions = 3"),
    ("ae", "kind = \"autoencoder\"\ncomponents = 4\niterations = 100\ncheckpoint_every = 100\nfit_test = false"),
];

fn max_dist(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter().zip(b).map(|(p, q)| mesh::dist(*p, *q)).fold(0.0, f64::max)
}

/// The directory holding `node_modules/gltf-validator` (the Khronos validator).
fn validator_dir() -> Option<PathBuf> {
    common::npm_package("gltf-validator", "gltf-validator", "gltf-validator@2.0.0-dev.3.10")
        .map(|p| p.parent().unwrap().parent().unwrap().to_path_buf())
}

#[test]
fn every_kind_exports_valid_gltf_that_replays_the_model() {
    let d = tmp("kinds");
    let mut files = Vec::new();
    for (name, method) in KINDS {
        let dir = train(&d, name, BUMPS, method);
        let glb = d.join(format!("{name}.glb"));
        let o =
            meshdeco(&["export", dir.to_str().unwrap(), "--out", glb.to_str().unwrap(), "--animation", "--colors"], &d);
        assert!(o.status.success(), "{name}: {}", output_text(&o));
        let out = output_text(&o);
        assert!(out.contains("additivity error"), "{out}");
        files.push(glb.clone());

        let m = load_model(&dir).unwrap();
        let k = m.n_components();
        let file = read_glb(&glb).unwrap();
        // The file is Y-up: the rest mesh's tallest bounding-box axis is Y (the tube lies along
        // z in its data), every target carries its normals' change, keys sit at i / fps.
        let (lo, hi) = mesh::bounding_box(&file.base);
        let tallest = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap();
        assert_eq!((tallest, file.up_axis.as_str()), (1, "+z"), "{name}: tallest axis of the file's base");
        assert_eq!(file.target_normals.len(), k, "{name}: morph target normals");
        // The base normals are the unit area-weighted vertex normals of the file's base, and
        // the material is the matte grey one, double-sided exactly when the mesh has a boundary
        // (the synthetic sets are closed, so only the single-sided case is met here).
        let (json, bin) = glb_chunks(&glb);
        let prim = &json["meshes"][0]["primitives"][0];
        let normals = accessor_f32(&json, &bin, prim["attributes"]["NORMAL"].as_u64().unwrap() as usize);
        let want = mesh::normals::vertex_normals(&file.base, &m.rest().faces, mesh::normals::NormalWeighting::Area);
        assert_eq!(normals.len(), 3 * want.len(), "{name}");
        for (v, n) in want.iter().enumerate() {
            for c in 0..3 {
                assert!((normals[3 * v + c] as f64 - n[c]).abs() < 1e-5, "{name}: normal of vertex {v}: {n:?}");
            }
        }
        // One node named "model" holding the mesh, whose default weights are K zeros.
        assert_eq!(json["nodes"][0]["name"], "model", "{name}");
        assert_eq!(json["meshes"][0]["weights"], serde_json::json!(vec![0.0; k]), "{name}");
        let material = &json["materials"][prim["material"].as_u64().unwrap() as usize];
        let mut edges = std::collections::HashMap::new();
        for f in &m.rest().faces {
            for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let open = edges.values().any(|&n| n == 1);
        assert_eq!(material["doubleSided"], serde_json::json!(open), "{name}: open {open}, {material}");
        let pbr = &material["pbrMetallicRoughness"];
        assert_eq!(pbr["baseColorFactor"], serde_json::json!([0.8, 0.8, 0.8, 1.0]), "{name}: {material}");
        assert_eq!((pbr["metallicFactor"].as_f64(), pbr["roughnessFactor"].as_f64()), (Some(0.0), Some(0.8)), "{name}");
        for (i, t) in file.times.iter().enumerate() {
            assert!((t - i as f64 / 30.0).abs() < 1e-6, "{name}: key {i} at {t} s");
        }
        let g = file.in_data_axes();
        assert_eq!(g.targets.len(), k, "{name}");
        assert_eq!(g.names.len(), k, "{name}");
        assert_eq!(g.faces, m.rest().faces, "{name}");
        // Targets are in rank order, named by rank, index and centre.
        let ranked = model::ranked(m.as_ref()).unwrap();
        for (t, c) in ranked.iter().enumerate() {
            assert_eq!(g.names[t], format!("r{} k{} v{}", c.rank, c.index, c.center), "{name}");
        }
        // Weights w on the morph targets against `meshdeco synthesize` with the same weights.
        let dials: Vec<f64> = (0..k).map(|i| [0.7, -0.4, 1.1, 0.3][i % 4]).collect();
        let spec: Vec<String> = dials.iter().enumerate().map(|(i, w)| format!("{i}:{w}")).collect();
        let synth = d.join(format!("{name}-synth.obj"));
        let o = meshdeco(
            &["synthesize", dir.to_str().unwrap(), "--weights", &spec.join(","), "--out", synth.to_str().unwrap()],
            &d,
        );
        assert!(o.status.success(), "{name}: {}", output_text(&o));
        let want = mesh::load_mesh(&synth).unwrap().positions;
        let file_order: Vec<f64> = ranked.iter().map(|c| dials[c.index]).collect();
        let err = max_dist(&g.blend(&file_order), &want);
        let linear = ["pca", "splocs", "region"].contains(&name);
        println!("{name}: blended targets vs synthesize: max distance {err:.3e}");
        if linear {
            assert!(err < 1e-5, "{name}: blended morph targets differ from synthesize by {err}");
        }
        // The file's targets are in rank order; for the autoencoder that differs from the index
        // order. Read with the index order instead (dial i on target i), the blend must be worse:
        // a writer or reader that mixes the two orders fails here even where blending is
        // approximate.
        let index_order: Vec<usize> = ranked.iter().map(|c| c.index).collect();
        let reordered = index_order.windows(2).any(|w| w[0] > w[1]);
        // K = 4, seed 0: the autoencoder ranks its components 3, 1, 0, 2 (this check must run).
        assert!(reordered || name != "ae", "{name}: rank order {index_order:?} equals the index order");
        if reordered {
            let wrong = max_dist(&g.blend(&dials), &want);
            println!("{name}: the same dials in index order: max distance {wrong:.3e}");
            assert!(err < 0.5 * wrong, "{name}: rank-order blend {err} is not clearly better than index order {wrong}");
        }
        // The animation replays the training frames: frame i of a linear model equals the model's
        // reconstruction of training frame i.
        let train = m.train_weights().unwrap();
        assert_eq!(g.animation.len(), train.len(), "{name}");
        // Every kind: key i holds training frame i's dials, target t the dial of rank t.
        for (i, (keys, w)) in g.animation.iter().zip(&train).enumerate() {
            let d = m.dials(w).unwrap();
            for (t, c) in ranked.iter().enumerate() {
                assert!(
                    (keys[t] - d[c.index]).abs() <= 1e-6 * (1.0 + d[c.index].abs()),
                    "{name}: key {i}, target {t}: {} vs dial {}",
                    keys[t],
                    d[c.index]
                );
            }
        }
        if linear {
            let rec = m.decode(&train).unwrap();
            for (i, (keys, r)) in g.animation.iter().zip(&rec).enumerate() {
                let err = max_dist(&g.blend(keys), r);
                assert!(err < 1e-5, "{name}: animation frame {i} differs from the reconstruction by {err}");
            }
        }
    }
    // The Khronos validator: zero errors and zero warnings on every kind.
    if let Some(dir) = validator_dir() {
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/js/validate_gltf.js");
        let mut args = vec![script.to_string()];
        args.extend(files.iter().map(|f| f.display().to_string()));
        let o = Command::new("node").args(&args).env("NODE_PATH", dir.join("node_modules")).output().unwrap();
        assert!(o.status.success(), "validator: {}", output_text(&o));
        let lines = json_lines(&o);
        assert_eq!(lines.len(), files.len());
        for r in &lines {
            println!("validator: {r}");
            assert_eq!((r["errors"].as_u64(), r["warnings"].as_u64()), (Some(0), Some(0)), "{r}");
        }
    }
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn additivity_error_is_zero_for_displacement_models_and_measured_for_nonlinear_ones() {
    let d = tmp("additivity");
    for (name, method, exact) in [("splocs", KINDS[1].1, true), ("splocs-acap", KINDS[2].1, false)] {
        let dir = train(&d, name, BUMPS, method);
        let m = load_model(&dir).unwrap();
        let r = meshdeco::export::export_glb(m.as_ref(), &d.join(format!("{name}.glb")), &Default::default()).unwrap();
        let e = r.additivity_erms.unwrap();
        println!("{name}: additivity error {e:.4e}");
        assert!(e.is_finite() && e >= 0.0);
        if exact {
            assert!(e < 1e-9, "{name}: a displacement model blends exactly, got {e}");
        } else {
            assert!(
                e > 1e-9,
                "{name}: ACAP decoding is nonlinear; an additivity error of {e} means it was not measured"
            );
        }
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// The autoencoder's blendshapes, honestly: fitted targets blend closer to the model's own
/// shapes than the dial-1 shapes do, the printed additivity is in the Erms unit with a warning
/// when it exceeds the train Erms, `--bake` replays the training frames exactly, and `--up`
/// picks the axis that becomes +Y.
#[test]
fn autoencoder_exports_fitted_targets_and_bakes_exact_frames() {
    let d = tmp("ae-bake");
    let dir = train(&d, "ae", BUMPS, KINDS[5].1);
    let m = load_model(&dir).unwrap();
    let opts = |targets| meshdeco::export::ExportOptions { targets, ..Default::default() };
    let fitted =
        meshdeco::export::export_glb(m.as_ref(), &d.join("f.glb"), &opts(meshdeco::export::TargetFit::Fitted)).unwrap();
    let extreme =
        meshdeco::export::export_glb(m.as_ref(), &d.join("e.glb"), &opts(meshdeco::export::TargetFit::Extreme))
            .unwrap();
    let (ef, ee) = (fitted.additivity_erms.unwrap(), extreme.additivity_erms.unwrap());
    println!("autoencoder additivity: fitted {ef:.4}, dial-1 targets {ee:.4}");
    assert!(fitted.targets_fitted && ef < ee, "fitted {ef} vs extreme {ee}");
    assert_eq!(fitted.additivity_extreme_erms, Some(ee));
    // The fitted file replays what it reports.
    let g = read_glb(&d.join("f.glb")).unwrap().in_data_axes();
    let train = m.train_weights().unwrap();
    let truth = m.decode(&train).unwrap();
    let ranked = model::ranked(m.as_ref()).unwrap();
    let blends: Vec<Vec<Vec3>> = train
        .iter()
        .map(|w| {
            let dials = m.dials(w).unwrap();
            g.blend(&ranked.iter().map(|c| dials[c.index]).collect::<Vec<_>>())
        })
        .collect();
    let from_file = meshdeco::metrics::erms::erms(&truth, &blends, m.alignment()).unwrap();
    assert!((from_file - ef).abs() < 1e-3 * ef.max(1.0), "file blends {from_file} vs reported {ef}");
    // The command prints the additivity in the Erms unit and warns above the train Erms.
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    let train_erms = metrics["train_erms"].as_f64().unwrap();
    let o = meshdeco(&["export", dir.to_str().unwrap(), "--out", "x.glb", "--targets", "extreme"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let text = output_text(&o);
    assert!(text.contains("additivity error: Erms"), "{text}");
    assert_eq!(text.contains("warning: the blendshapes miss"), ee > train_erms, "train Erms {train_erms}: {text}");
    // --bake: one target per training frame; the blend at each key is the model's decoding.
    let o = meshdeco(&["export", dir.to_str().unwrap(), "--out", "b.glb", "--bake", "--up", "-y"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let file = read_glb(&d.join("b.glb")).unwrap();
    assert_eq!(file.up_axis, "-y");
    assert_eq!(meshdeco::math::mat3::mat_vec(&file.rotation, [0.0, -1.0, 0.0]), [0.0, 1.0, 0.0]);
    let b = file.in_data_axes();
    assert_eq!((b.targets.len(), b.animation.len()), (train.len(), train.len()));
    let keyed: Vec<Vec<Vec3>> = b.animation.iter().map(|keys| b.blend(keys)).collect();
    let e = meshdeco::metrics::erms::erms(&truth, &keyed, m.alignment()).unwrap();
    println!("--bake: keyed blends vs the model's decoding: Erms {e:.2e}");
    assert!(e <= 1e-4, "--bake playback differs from the model's decoding by Erms {e}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn export_refuses_bad_arguments() {
    let d = tmp("bad");
    let dir = train(&d, "pca", BUMPS, KINDS[0].1);
    for (args, needle) in [
        (vec!["--out", "x.gltf"], ".glb"),
        (vec!["--out", "x.glb", "--animation", "--fps", "0"], "--fps"),
        (vec!["--out", "x.glb", "--up", "w"], "--up"),
        (vec!["--out", "x.glb", "--fit-regularisation", "0"], "--fit-regularisation"),
    ] {
        let mut all = vec!["export", dir.to_str().unwrap()];
        all.extend(args);
        let o = meshdeco(&all, &d);
        assert!(!o.status.success() && output_text(&o).contains(needle), "{}", output_text(&o));
    }
    assert!(!d.join("x.glb").exists());
    // The library checks the frame rate itself (the command line checks it first) whenever
    // keys are written: with `animation` or with `bake` alone.
    let m = load_model(&dir).unwrap();
    for (animation, bake) in [(true, false), (false, true)] {
        let opts = meshdeco::export::ExportOptions { animation, bake, fps: 0.0, ..Default::default() };
        let e = meshdeco::export::gltf::prepare(m.as_ref(), &opts).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("--fps 0.0"), "animation {animation}, bake {bake}: {e:?}");
    }
    let still = meshdeco::export::ExportOptions { fps: 0.0, ..Default::default() };
    assert!(meshdeco::export::gltf::prepare(m.as_ref(), &still).is_ok(), "no keys, so no frame rate to check");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn numpy_sequences_train_like_mesh_files() {
    let d = tmp("npy");
    let seq = meshdeco::preprocess::load_frames("synthetic:bumps").unwrap();
    mesh::write_obj(&d.join("template.obj"), &seq.mesh(0)).unwrap();
    mesh::npy::write_npy(&d.join("bumps.npy"), &seq.frames).unwrap();
    mesh::npy::write_npz(&d.join("bumps.npz"), &[("other", &seq.frames[..2]), ("verts", &seq.frames)]).unwrap();
    let method = "kind = \"splocs\"\ncomponents = 3";
    let reference = train(&d, "mesh", BUMPS, method);
    let split = "train = \"1-30\"\ntest = \"rest\"\ntemplate = \"template.obj\"";
    let a = train(&d, "npy", &format!("path = \"bumps.npy\"\n{split}"), method);
    let b = train(&d, "npz", &format!("path = \"bumps.npz\"\narray = \"verts\"\n{split}"), method);
    let metrics = |p: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p.join("metrics.json")).unwrap()).unwrap()
    };
    let m0 = metrics(&reference);
    for dir in [&a, &b] {
        let m = metrics(dir);
        // SPLOCS adds partial sums in parallel: equal up to round-off.
        for key in ["train_erms", "test_erms", "objective", "median_energy_share"] {
            let (x, y) = (m[key].as_f64().unwrap(), m0[key].as_f64().unwrap());
            assert!((x - y).abs() <= 1e-9 * y.abs(), "{}: {key} {x} vs {y}", dir.display());
        }
        assert_eq!(m["train_frames"], m0["train_frames"]);
        assert_eq!(m["test_frames"], m0["test_frames"]);
    }
    // Errors name the file, the array and the shape.
    let cases = [
        (format!("path = \"bumps.npz\"\n{split}"), "data.array"),
        (format!("path = \"bumps.npz\"\narray = \"nope\"\n{split}"), "no array `nope` (it holds: "),
        ("path = \"bumps.npy\"\ntrain = \"1-30\"".to_string(), "data.template"),
        (format!("path = \"bumps.npy\"\n{}", split.replace("template.obj", "small.obj")), "template mesh has 3"),
    ];
    mesh::write_obj(
        &d.join("small.obj"),
        &mesh::TriMesh::new(vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], vec![[0, 1, 2]]),
    )
    .unwrap();
    for (i, (data, needle)) in cases.iter().enumerate() {
        let cfg = d.join(format!("bad{i}.toml"));
        std::fs::write(&cfg, format!("[data]\n{data}\n[method]\n{method}\n")).unwrap();
        let out = d.join(format!("bad{i}"));
        let o = meshdeco(&["train", "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()], &d);
        assert!(
            !o.status.success() && output_text(&o).contains(needle),
            "case {i}: `{needle}` not in {}",
            output_text(&o)
        );
        assert!(!output_text(&o).contains("panicked"), "{}", output_text(&o));
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// A mesh with a boundary (the bumps with one triangle taken out of the template) is drawn from
/// both sides: glTF's material and USD's mesh say double-sided (the closed meshes of
/// `every_kind_exports_valid_gltf_that_replays_the_model` say single-sided).
#[test]
fn open_meshes_export_double_sided() {
    let d = tmp("open");
    let seq = meshdeco::preprocess::load_frames("synthetic:bumps").unwrap();
    let mut template = seq.mesh(0);
    template.faces.pop();
    mesh::write_obj(&d.join("open.obj"), &template).unwrap();
    mesh::npy::write_npy(&d.join("bumps.npy"), &seq.frames).unwrap();
    let data = "path = \"bumps.npy\"\ntrain = \"1-30\"\ntest = \"rest\"\ntemplate = \"open.obj\"";
    let dir = train(&d, "open", data, "kind = \"pca\"\ncomponents = 2");
    let (glb, usda) = (d.join("open.glb"), d.join("open.usda"));
    for f in [&glb, &usda] {
        let o = meshdeco(&["export", dir.to_str().unwrap(), "--out", f.to_str().unwrap()], &d);
        assert!(o.status.success(), "{}", output_text(&o));
    }
    let (json, _) = glb_chunks(&glb);
    let material = json["meshes"][0]["primitives"][0]["material"].as_u64().unwrap() as usize;
    assert_eq!(json["materials"][material]["doubleSided"], serde_json::json!(true), "{json}");
    let text = std::fs::read_to_string(&usda).unwrap();
    assert!(text.contains("uniform bool doubleSided = true\n"), "{text}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// SCAPE (lying along +x in its data) and face-poses exports as Blender imports them: the rest
/// mesh's tallest bounding-box axis is Z (Blender's up), with K + 1 shape keys. (three.js:
/// `tests/view_browser.rs::exports_stand_up_in_three_js_in_chromium`.)
#[test]
fn real_exports_stand_up_in_blender() {
    let (Some(scape), Some(face)) = (common::shared_or_skip("data/scape"), common::shared_or_skip("data/face-poses"))
    else {
        return;
    };
    let d = tmp("three");
    let mut files = Vec::new();
    for (name, path, train_sel) in [("scape", &scape, "1-36"), ("face", &face, "1-7")] {
        let data = format!("path = \"{}\"\ntrain = \"{train_sel}\"\ntest = \"rest\"", path.display());
        let dir = train(&d, name, &data, "kind = \"pca\"\ncomponents = 6");
        let glb = d.join(format!("{name}.glb"));
        let o = meshdeco(&["export", dir.to_str().unwrap(), "--out", glb.to_str().unwrap(), "--animation"], &d);
        assert!(o.status.success(), "{name}: {}", output_text(&o));
        println!("{name}: {}", output_text(&o).lines().find(|l| l.starts_with("up axis")).unwrap_or(""));
        files.push(glb);
    }
    // Blender (Z-up): the import stands along Z with K + 1 shape keys (Basis included).
    let blender = Command::new("blender").arg("--version").output().is_ok_and(|o| o.status.success());
    if blender {
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/blender/import_glb.py");
        let mut cmd = Command::new("blender");
        cmd.args(["--background", "--factory-startup", "--python", script, "--"]).args(&files);
        let o = cmd.output().unwrap();
        let text = output_text(&o);
        let lines: Vec<serde_json::Value> =
            text.lines().filter_map(|l| l.strip_prefix("BLENDER ")).map(|l| serde_json::from_str(l).unwrap()).collect();
        assert_eq!(lines.len(), files.len(), "blender: {text}");
        for r in &lines {
            println!("blender: {r}");
            assert_eq!(r["meshes"][0]["shape_keys"].as_u64(), Some(7), "{r}");
            assert_eq!(r["meshes"][0]["tallest"], "Z", "{r}");
        }
    } else {
        assert!(std::env::var_os("CI").is_none(), "CI: blender is not on the PATH (.ci/run installs Debian's)");
        eprintln!("SKIP Blender check: no `blender` on the PATH (apt-get install blender python3-numpy)");
        common::record_skip("blender");
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// The JSON and BIN chunks of a binary glTF file (read here, independently of `read_glb`).
fn glb_chunks(path: &Path) -> (serde_json::Value, Vec<u8>) {
    let b = std::fs::read(path).unwrap();
    let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap()) as usize;
    assert_eq!(&b[..4], b"glTF");
    let json_len = u32_at(12);
    assert_eq!(&b[16..20], b"JSON");
    let json = serde_json::from_slice(&b[20..20 + json_len]).unwrap();
    let at = 20 + json_len;
    assert_eq!(&b[at + 4..at + 8], b"BIN\0");
    (json, b[at + 8..at + 8 + u32_at(at)].to_vec())
}

/// The `f32` values of accessor `i` (tightly packed).
fn accessor_f32(json: &serde_json::Value, bin: &[u8], i: usize) -> Vec<f32> {
    let a = &json["accessors"][i];
    assert_eq!(a["componentType"].as_u64(), Some(5126), "{a}");
    let n = a["count"].as_u64().unwrap() as usize * if a["type"] == "VEC3" { 3 } else { 1 };
    let view = &json["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
    let start = view["byteOffset"].as_u64().unwrap_or(0) as usize + a["byteOffset"].as_u64().unwrap_or(0) as usize;
    bin[start..start + 4 * n].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
}
