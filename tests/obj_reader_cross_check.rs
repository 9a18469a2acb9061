//! Cross-check of meshdeco's own OBJ reader (`meshdeco::mesh::load_mesh`) against `tobj` 4
//! (`single_index: false`, `triangulate: true`) on every valid OBJ of `tests/data`, the ACAP
//! fixtures (`../shared/fixtures/acap/*.obj`) and SCAPE (`../shared/data/scape/*.obj`); the
//! shared folders fail in CI when absent and are recorded skips locally (`tests/common`).
//!
//! What "identical" means here: tobj renumbers vertices by first use in the faces and drops
//! unreferenced ones, and stores positions as `f32`. So the check is that
//! - both readers produce the same number of triangles, in the same order;
//! - corner by corner, meshdeco's vertex index and tobj's index correspond one to one (the same
//!   face list up to tobj's relabelling), and every tobj vertex is used;
//! - the corresponding positions agree to `f32` rounding;
//! - when meshdeco reports no unreferenced vertex, both have the same vertex count.

mod common;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use meshdeco::mesh::load_mesh;

/// OBJ files of `tests/data` that are malformed on purpose (checked by `malformed_inputs.rs`).
const INVALID: [&str; 3] = ["index_out_of_range.obj", "nan.obj", "truncated.obj"];

/// Loads `path` with both readers and asserts that they agree (see the module docs). Returns the
/// number of vertices compared.
fn cross_check(path: &Path) -> usize {
    let p = path.display();
    let ours = load_mesh(path).unwrap_or_else(|e| panic!("meshdeco: {e}"));
    let opts = tobj::LoadOptions { single_index: false, triangulate: true, ..Default::default() };
    let (models, _) = tobj::load_obj(path, &opts).unwrap_or_else(|e| panic!("tobj: {p}: {e}"));

    // tobj's triangles as (model, index) corners, models in file order.
    let theirs: Vec<[(usize, usize); 3]> = models
        .iter()
        .enumerate()
        .flat_map(|(m, model)| {
            let idx = &model.mesh.indices;
            assert_eq!(idx.len() % 3, 0, "{p}: tobj model {m}: index count {} not a multiple of 3", idx.len());
            idx.chunks_exact(3).map(move |t| [(m, t[0] as usize), (m, t[1] as usize), (m, t[2] as usize)])
        })
        .collect();
    assert_eq!(ours.faces.len(), theirs.len(), "{p}: triangle count (meshdeco vs tobj)");

    let mut to_theirs: HashMap<usize, (usize, usize)> = HashMap::new();
    let mut to_ours: HashMap<(usize, usize), usize> = HashMap::new();
    for (k, (of, tf)) in ours.faces.iter().zip(&theirs).enumerate() {
        for c in 0..3 {
            let (v, t) = (of[c], tf[c]);
            let seen_t = *to_theirs.entry(v).or_insert(t);
            assert_eq!(seen_t, t, "{p}: face {k} corner {c}: meshdeco vertex {v} is tobj vertex {seen_t:?} elsewhere");
            let seen_v = *to_ours.entry(t).or_insert(v);
            assert_eq!(seen_v, v, "{p}: face {k} corner {c}: tobj vertex {t:?} is meshdeco vertex {seen_v} elsewhere");
        }
    }

    let n_theirs: usize = models.iter().map(|m| m.mesh.positions.len() / 3).sum();
    assert_eq!(to_ours.len(), n_theirs, "{p}: tobj has vertices no face uses");
    for (&v, &(m, t)) in &to_theirs {
        let q = &models[m].mesh.positions[3 * t..3 * t + 3];
        for (axis, (&x, &b)) in ours.positions[v].iter().zip(q).enumerate() {
            assert!(
                (x as f32 - b).abs() <= f32::EPSILON * b.abs().max(f32::MIN_POSITIVE),
                "{p}: vertex {v} axis {axis}: meshdeco {x} vs tobj {b}"
            );
        }
    }
    let unreferenced = ours.n_vertices() - to_theirs.len();
    if unreferenced == 0 {
        assert_eq!(ours.n_vertices(), n_theirs, "{p}: vertex count (meshdeco vs tobj)");
    } else {
        println!("{p}: {unreferenced} vertices referenced by no face (tobj drops them)");
    }
    to_theirs.len()
}

/// The `*.obj` files of `dir`, sorted, or `None` (with a printed reason) when `dir` is absent.
fn obj_files(dir: &Path) -> Option<Vec<PathBuf>> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        println!("skipping: {} is absent", dir.display());
        return None;
    };
    let mut files: Vec<PathBuf> = entries
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")))
        .collect();
    files.sort();
    Some(files)
}

#[test]
fn agrees_with_tobj_on_test_data() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let mut files = Vec::new();
    for dir in [root.clone(), root.join("mismatch"), root.join("quads")] {
        files.extend(obj_files(&dir).expect("tests/data is part of the repository"));
    }
    let valid: Vec<&PathBuf> =
        files.iter().filter(|f| !INVALID.iter().any(|bad| f.file_name().is_some_and(|n| n == *bad))).collect();
    // cube.obj, mismatch/{1,2,10}.obj, quads/frame{1,2}.obj (the quads exercise triangulation).
    assert!(valid.len() >= 6, "expected at least 6 valid OBJ files in tests/data, found {valid:?}");
    for f in valid {
        assert_eq!(cross_check(f), 8, "{}", f.display());
    }
}

#[test]
fn agrees_with_tobj_on_acap_fixtures() {
    let Some(dir) = common::shared_or_skip("fixtures/acap") else { return };
    let files = obj_files(&dir).unwrap();
    assert_eq!(files.len(), 3, "{}: expected 1.obj, 2.obj, 3.obj", dir.display());
    for f in &files {
        cross_check(f);
    }
}

#[test]
fn agrees_with_tobj_on_scape() {
    let Some(dir) = common::shared_or_skip("data/scape") else { return };
    let files = obj_files(&dir).unwrap();
    assert_eq!(files.len(), 71, "{}: expected 71 poses", dir.display());
    for f in &files {
        assert_eq!(cross_check(f), 2161, "{}", f.display());
    }
}
