//! Reader corner cases that a plausible bug would get wrong without any other test noticing
//! (issue 33): NumPy arrays in Fortran order whose frame and vertex counts differ (a swapped
//! stride reads other numbers), and binary PLY properties of type `ushort` above 32 767 (read as
//! signed they turn negative).

mod common;

use std::path::Path;

use meshdeco::mesh::npy::{load_npy_with_faces, npy_header};
use meshdeco::mesh::ply::parse_ply;

/// A `.npy` v1.0 image: the library's header for `descr`, order and shape, then `data` (already
/// in the given order).
fn npy(descr: &str, fortran: bool, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let mut out = npy_header(descr, fortran, shape);
    out.extend_from_slice(data);
    out
}

/// The value stored for frame f, vertex v, coordinate c: distinct for every (f, v, c).
fn value(f: usize, v: usize, c: usize) -> f64 {
    100.0 * f as f64 + 10.0 * v as f64 + c as f64 + 0.5
}

#[test]
fn fortran_order_npy_with_frames_unlike_vertices_reads_every_value_in_place() {
    let d = common::fresh_dir("edge-readers", "fortran");
    // F = 2 frames, N = 5 vertices, so no two strides coincide; float32 and float64.
    let (f, n) = (2usize, 5usize);
    for descr in ["<f8", "<f4"] {
        let mut data = Vec::new();
        // Fortran order: the first index varies fastest.
        for c in 0..3 {
            for v in 0..n {
                for fi in 0..f {
                    let x = value(fi, v, c);
                    if descr == "<f8" {
                        data.extend_from_slice(&x.to_le_bytes());
                    } else {
                        data.extend_from_slice(&(x as f32).to_le_bytes());
                    }
                }
            }
        }
        let path = d.join(format!("fortran{}.npy", &descr[1..]));
        std::fs::write(&path, npy(descr, true, &[f, n, 3], &data)).unwrap();
        let seq = load_npy_with_faces(&path, None, n, vec![[0, 1, 2], [2, 3, 4]]).unwrap();
        assert_eq!((seq.frames.len(), seq.frames[0].len()), (f, n));
        for fi in 0..f {
            for v in 0..n {
                for c in 0..3 {
                    assert_eq!(
                        seq.frames[fi][v][c],
                        value(fi, v, c),
                        "{descr}: frame {fi}, vertex {v}, coordinate {c}"
                    );
                }
            }
        }
    }
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn binary_ply_ushort_values_above_32767_stay_positive() {
    // Three vertices with ushort coordinates (big values) and one face with ushort indices.
    let xs: [[u16; 3]; 3] = [[40000, 1, 65535], [32768, 2, 3], [7, 50000, 9]];
    for big_endian in [false, true] {
        let mut b = format!(
            "ply\nformat binary_{}_endian 1.0\nelement vertex 3\nproperty ushort x\nproperty ushort y\n\
             property ushort z\nelement face 1\nproperty list uchar ushort vertex_indices\nend_header\n",
            if big_endian { "big" } else { "little" }
        )
        .into_bytes();
        let put =
            |b: &mut Vec<u8>, x: u16| b.extend_from_slice(&if big_endian { x.to_be_bytes() } else { x.to_le_bytes() });
        for p in xs {
            for x in p {
                put(&mut b, x);
            }
        }
        b.push(3);
        for i in [0u16, 1, 2] {
            put(&mut b, i);
        }
        let m = parse_ply(&b, Path::new("ushort.ply")).unwrap().mesh;
        for (v, p) in xs.iter().enumerate() {
            let want = p.map(f64::from);
            assert_eq!(m.positions[v], want, "big endian {big_endian}: vertex {v}");
        }
        assert_eq!(m.faces, vec![[0, 1, 2]]);
    }
}

/// Manifest entries that name something other than a top-level file of the artefact directory —
/// a path out of it (`../x`, `..\x`), an absolute path, a subdirectory's file, a hidden file, `..`
/// or the empty name — are refused with the entry named, even when the file they point at exists
/// and has exactly the recorded length and checksum. Bug caught: a reader that joins the entry to
/// the directory without checking it would verify (and trust) a file outside the artefact.
#[test]
fn manifest_entries_that_leave_the_directory_are_refused() {
    use meshdeco::artifact::{MANIFEST_FILE, ManifestEntry, compute_manifest, crc32_hex, verify_manifest};
    let root = common::fresh_dir("edge-manifest", "names");
    let dir = root.join("model");
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    std::fs::write(dir.join("model.json"), b"{}").unwrap();
    std::fs::write(dir.join("model.bin"), b"0123456789abcdef").unwrap();
    let outside = root.join("outside.txt");
    let content = b"a file beside the artefact, not in it";
    std::fs::write(&outside, content).unwrap();
    std::fs::write(dir.join("sub/inner.txt"), content).unwrap();
    std::fs::write(dir.join(".hidden"), content).unwrap();
    let base = compute_manifest(&dir).unwrap();
    std::fs::write(dir.join(MANIFEST_FILE), serde_json::to_string(&base).unwrap()).unwrap();
    verify_manifest(&dir).expect("the untouched manifest verifies");
    let entry = ManifestEntry { bytes: content.len() as u64, crc32: crc32_hex(content) };
    let absolute = outside.to_str().unwrap().to_string();
    for name in ["../outside.txt", "..\\outside.txt", absolute.as_str(), "sub/inner.txt", ".hidden", "..", ""] {
        let mut m = base.clone();
        m.files.insert(name.to_string(), entry.clone());
        std::fs::write(dir.join(MANIFEST_FILE), serde_json::to_string(&m).unwrap()).unwrap();
        let e = verify_manifest(&dir).expect_err(&format!("entry `{name}` must be refused")).to_string();
        assert!(e.contains(MANIFEST_FILE), "entry `{name}`: the error names the manifest: {e}");
        if !name.is_empty() {
            assert!(e.contains(name), "entry `{name}`: the error names the entry: {e}");
        }
    }
    let _ = std::fs::remove_dir_all(&root);
}
