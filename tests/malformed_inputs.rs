//! Malformed inputs must give a one-line error that names the file (and the line where the
//! reader knows it), never a panic. Uses the small hand-made files in `tests/data/`.

use std::path::{Path, PathBuf};

use meshdeco::mesh::{load_mesh, load_sequence, read_mesh, read_sequence};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

/// The error of loading `name` both as a single mesh and as a one-frame sequence; both must be
/// the same one-line message starting with `<path><suffix>`.
fn error_for(name: &str, suffix: &str) -> String {
    let path = data(name);
    let single = load_mesh(&path).unwrap_err().to_string();
    let as_sequence = load_sequence(path.to_str().unwrap()).unwrap_err().to_string();
    assert_eq!(single, as_sequence);
    let expected_start = format!("{}{suffix}", path.display());
    assert!(single.starts_with(&expected_start), "expected '{expected_start}…', got '{single}'");
    assert!(!single.contains('\n'), "not one line: {single}");
    single
}

#[test]
fn truncated_obj_names_file_and_line() {
    // The file ends in the middle of line 20 ("f 4 ").
    let e = error_for("truncated.obj", ":20: ");
    assert!(e.contains("face with 1 vertex"), "{e}");
}

#[test]
fn index_out_of_range_names_file_and_line() {
    let e = error_for("index_out_of_range.obj", ":21: ");
    assert!(e.contains("vertex index 9 out of range (the file has 8 vertices)"), "{e}");
}

#[test]
fn nan_coordinate_names_file_and_line() {
    let e = error_for("nan.obj", ":8: ");
    assert!(e.contains("non-finite y coordinate 'nan'"), "{e}");
    let e = error_for("nan.ply", ":16: ");
    assert!(e.contains("non-finite z coordinate"), "{e}");
}

#[test]
fn truncated_ply_names_file() {
    let e = error_for("truncated.ply", ": ");
    assert!(e.contains("unexpected end of file") && e.contains("'vertex'"), "{e}");
}

#[test]
fn frame_with_different_face_list_is_named() {
    let dir = data("mismatch");
    let e = load_sequence(dir.to_str().unwrap()).unwrap_err().to_string();
    // Natural order is 1, 2, 10: the first frame is 1.obj and the odd one out is 10.obj.
    let odd = dir.join("10.obj");
    assert!(e.starts_with(&format!("{}: ", odd.display())), "{e}");
    assert!(e.contains(&format!("first frame {}", dir.join("1.obj").display())), "{e}");
    assert!(e.contains("face 7 (0-based): [1, 5, 6] here, [1, 6, 5] in the first frame"), "{e}");
    assert!(!e.contains('\n'));
    // Without the odd frame the others load, in natural order.
    let ok = read_sequence(dir.join("?.obj").to_str().unwrap()).unwrap();
    assert_eq!(ok.sequence.names, vec!["1", "2"]);
}

#[test]
fn empty_folder_is_named() {
    let dir = std::env::temp_dir().join(format!("meshdeco-empty-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("README.txt"), "not a mesh").unwrap();
    let e = load_sequence(dir.to_str().unwrap()).unwrap_err().to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(e.starts_with(&format!("{}: no mesh files", dir.display())), "{e}");
    assert!(e.contains("zero frames"), "{e}");
    // A glob that matches nothing names the pattern.
    let pattern = data("*.stl");
    let e = load_sequence(pattern.to_str().unwrap()).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}: no mesh files", pattern.display())), "{e}");
}

#[test]
fn unreadable_and_missing_files_are_named() {
    // A directory with a mesh extension cannot be read as a file.
    let dir = std::env::temp_dir().join(format!("meshdeco-unreadable-{}.obj", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let e = load_mesh(&dir).unwrap_err().to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(e.starts_with(&format!("{}: ", dir.display())), "{e}");
    let missing = data("missing.obj");
    let e = load_sequence(missing.to_str().unwrap()).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}: ", missing.display())), "{e}");
}

#[test]
fn the_same_cube_reads_alike_from_every_format() {
    let obj = read_mesh(&data("cube.obj")).unwrap();
    let off = read_mesh(&data("cube.off")).unwrap();
    assert!(obj.warnings.is_empty() && off.warnings.is_empty());
    assert_eq!(obj.mesh, off.mesh);
    assert_eq!((obj.mesh.n_vertices(), obj.mesh.n_faces()), (8, 12));
    let report = meshdeco::mesh::inspect_path(data("cube.obj").to_str().unwrap()).unwrap();
    assert_eq!((report.edges, report.components, report.euler_characteristic), (18, 1, 2));
    assert!(report.warnings.is_empty(), "{report}");
}

#[test]
fn quads_are_triangulated_and_reported() {
    let loaded = read_sequence(data("quads").to_str().unwrap()).unwrap();
    assert_eq!(loaded.sequence.n_faces(), 12);
    assert_eq!(loaded.sequence.names, vec!["frame1", "frame2"]);
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    let w = &loaded.warnings[0];
    assert!(w.contains("frame1.obj:10: 6 polygons with more than 3 vertices triangulated as fans"), "{w}");
    assert!(w.ends_with("(and the same in 1 other frame)"), "{w}");
    // The fans tile the cube: a closed surface with consistent orientation.
    let report = meshdeco::mesh::inspect_path(data("quads").to_str().unwrap()).unwrap();
    assert!(report.boundary_loops.is_empty());
    assert_eq!(report.warnings.len(), 1, "only the reader's warning: {report}");
    assert_eq!(report.bbox_all, ([0.0; 3], [2.0, 1.0, 1.0]));
}
