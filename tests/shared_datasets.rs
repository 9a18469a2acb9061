//! Loading and inspecting the real datasets in `../shared/data` (counts from its README).
//! A missing folder fails in CI and is a recorded skip locally (`tests/common`); the synthetic
//! counterparts are the unit tests of `src/mesh/*` and `tests/malformed_inputs.rs`.

mod common;

use std::path::{Path, PathBuf};
use std::time::Instant;

use meshdeco::mesh::{LoadedSequence, WarningKind, inspect, read_mesh, read_sequence, write_obj, write_ply};

fn dataset(name: &str) -> Option<PathBuf> {
    common::shared_or_skip(&format!("data/{name}"))
}

/// Loads a dataset, printing the load time, and checks the README's counts.
fn load(dir: &Path, frames: usize, vertices: usize, faces: usize) -> LoadedSequence {
    let start = Instant::now();
    let loaded = read_sequence(dir.to_str().unwrap()).unwrap();
    println!("loaded {} in {:.1} ms", dir.display(), start.elapsed().as_secs_f64() * 1e3);
    let s = &loaded.sequence;
    assert_eq!((s.n_frames(), s.n_vertices(), s.n_faces()), (frames, vertices, faces));
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    loaded
}

/// The README states: triangles only, valid indices, no degenerate faces, no non-manifold edges.
/// The only warnings inspect may give are therefore about boundaries and components.
fn assert_clean(report: &meshdeco::mesh::InspectReport) {
    for w in &report.warnings {
        assert!(matches!(w.kind, WarningKind::BoundaryLoops | WarningKind::Components), "unexpected warning: {w}");
    }
}

#[test]
fn scape_71_closed_frames_in_natural_order() {
    let Some(dir) = dataset("scape") else { return };
    let loaded = load(&dir, 71, 2161, 4318);
    let expected: Vec<String> = (1..=71).map(|i| i.to_string()).collect();
    assert_eq!(loaded.sequence.names, expected);
    let report = inspect(&loaded.sequence);
    println!("{report}");
    assert!(report.boundary_loops.is_empty());
    assert_eq!(report.euler_characteristic, 2);
    assert_clean(&report);
}

#[test]
fn horse_gallop_has_19_boundary_edges_in_two_loops() {
    let Some(dir) = dataset("horse-gallop") else { return };
    let loaded = load(&dir, 48, 8431, 16843);
    let s = &loaded.sequence;
    assert_eq!(s.names[0], "0001");
    assert_eq!(s.names[47], "0048");
    // README: frame 28 repeats frame 4 exactly (1-based), which also checks the frame order.
    assert_eq!(s.frames[27], s.frames[3]);
    assert_ne!(s.frames[27], s.frames[4]);
    let report = inspect(s);
    println!("{report}");
    // The README's "19 boundary edges" form two disjoint loops: a 16-edge slit at a hoof and a
    // missing triangle (3 edges) at the head; every boundary vertex has exactly two boundary edges.
    let mut loops = report.boundary_loops.clone();
    loops.sort_unstable();
    assert_eq!(loops, vec![3, 16]);
    assert_eq!(report.boundary_edges, 19);
    assert_eq!(report.euler_characteristic, 0);
    assert_clean(&report);
}

#[test]
fn stfaces_ply_loads() {
    let Some(dir) = dataset("stfaces") else { return };
    let loaded = load(&dir, 4, 7118, 14037);
    assert_eq!(loaded.sequence.names, vec!["disgust", "neutral", "smile", "surprise"]);
    let report = inspect(&loaded.sequence);
    println!("{report}");
    assert!(!report.boundary_loops.is_empty(), "stfaces is an open surface");
    assert_clean(&report);
}

#[test]
fn cactus_ply_loads_closed() {
    let Some(dir) = dataset("cactus") else { return };
    let loaded = load(&dir, 19, 5261, 10518);
    let expected: Vec<String> = (0..19).map(|i| format!("cactus{i}")).collect();
    assert_eq!(loaded.sequence.names, expected);
    let report = inspect(&loaded.sequence);
    println!("{report}");
    assert!(report.boundary_loops.is_empty());
    assert_clean(&report);
}

#[test]
fn face_poses_load() {
    let Some(dir) = dataset("face-poses") else { return };
    let loaded = load(&dir, 9, 29299, 57836);
    let report = inspect(&loaded.sequence);
    println!("{report}");
    assert!(!report.boundary_loops.is_empty(), "face-poses is an open surface");
    assert_clean(&report);
}

#[test]
fn scape_frame_round_trips_through_obj_and_ply() {
    let Some(dir) = dataset("scape") else { return };
    let mesh = read_mesh(&dir.join("1.obj")).unwrap().mesh;
    let out = std::env::temp_dir().join(format!("meshdeco-scape-rt-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    write_obj(&out.join("1.obj"), &mesh).unwrap();
    let heights: Vec<f64> = mesh.positions.iter().map(|p| p[1]).collect();
    let colors = meshdeco::mesh::colormap(&heights);
    write_ply(&out.join("1.ply"), &mesh, Some(&colors), Some(("height", &heights))).unwrap();
    assert_eq!(read_mesh(&out.join("1.obj")).unwrap().mesh, mesh);
    assert_eq!(read_mesh(&out.join("1.ply")).unwrap().mesh, mesh);
    std::fs::remove_dir_all(&out).unwrap();
}

/// `render --view auto`, the page and the glTF export see SCAPE from the front (issue 25: it
/// opened seen from behind) and the face-poses mask from outside. The front is checked
/// independently of the normals rule the view uses: a standing person's toes reach forward of the
/// ankles, so the feet (the lowest 3 % of the height) lie on the front side of the shins (5–12 %).
#[test]
fn scape_and_the_face_are_seen_from_the_front() {
    use meshdeco::mesh::render::View;
    let Some(dir) = dataset("scape") else { return };
    let m = read_mesh(&dir.join("1.obj")).unwrap().mesh;
    let View::Axes { up, view, negative } = View::auto(&m) else { panic!("auto gives axes") };
    assert_eq!((up, view), (0, 1), "SCAPE stands along x, its depth is y");
    let (lo, hi) = m.bounding_box();
    let h = hi[up] - lo[up];
    let mean_depth = |a: f64, b: f64| {
        let d: Vec<f64> =
            m.positions.iter().filter(|p| p[up] >= lo[up] + a * h && p[up] < lo[up] + b * h).map(|p| p[view]).collect();
        d.iter().sum::<f64>() / d.len() as f64
    };
    let (feet, shins) = (mean_depth(0.0, 0.03), mean_depth(0.05, 0.12));
    println!("SCAPE feet depth {feet:.4}, shins {shins:.4}, camera on the {} side", if negative { "−" } else { "+" });
    assert_eq!(negative, feet < shins, "the camera must sit on the toes' side");
    let Some(dir) = dataset("face-poses") else { return };
    let f = read_mesh(&dir.join("1.obj")).unwrap().mesh;
    assert_eq!(View::auto(&f), View::Axes { up: 1, view: 2, negative: false });
}
