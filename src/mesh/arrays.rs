//! Meshes and sequences from flat arrays held in memory (the Python binding's NumPy arrays, or
//! any caller that has positions and triangles without files), checked as strictly as the file
//! readers check what they read: shapes, finite positions, triangle indices in range.
//!
//! Layouts (C order): positions `F × N × 3` (`f64`, data units) flattened frame by frame, vertex
//! by vertex, then x, y, z; triangles `T × 3` (`i64`, 0-based vertex indices, counter-clockwise
//! seen from outside, as the files store them). Errors start with the caller's name of the
//! array (`what`) and name the frame, vertex, triangle and the bad value.

use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, TriMesh, Vec3};

/// Triangles `T × 3` from a flat `i64` array of length `3·T`: every index in `0..n_vertices`.
/// A triangle that repeats a vertex is accepted (the file readers keep them too).
pub fn faces_from_array(what: &str, flat: &[i64], n_vertices: usize) -> Result<Vec<[usize; 3]>> {
    if !flat.len().is_multiple_of(3) {
        return Err(Error::Invalid(format!(
            "{what}: {} indices is not a whole number of triangles (T × 3)",
            flat.len()
        )));
    }
    if flat.is_empty() {
        return Err(Error::Invalid(format!("{what}: no triangles (shape 0 × 3)")));
    }
    flat.chunks_exact(3)
        .enumerate()
        .map(|(t, c)| {
            let mut f = [0usize; 3];
            for k in 0..3 {
                let v = c[k];
                if v < 0 || v as u64 >= n_vertices as u64 {
                    return Err(Error::Invalid(format!(
                        "{what}: triangle {t} has vertex index {v} (column {k}), outside 0..{n_vertices}"
                    )));
                }
                f[k] = v as usize;
            }
            Ok(f)
        })
        .collect()
}

/// `N` positions from a flat array of length `3·N`; every coordinate finite. `frame` names the
/// frame in errors (`None` for a single mesh).
fn positions_from_array(what: &str, flat: &[f64], frame: Option<usize>) -> Result<Vec<Vec3>> {
    if let Some(i) = flat.iter().position(|x| !x.is_finite()) {
        let at = match frame {
            Some(f) => format!("frame {f}, vertex {}", i / 3),
            None => format!("vertex {}", i / 3),
        };
        return Err(Error::Invalid(format!("{what}: {at}, coordinate {} is {} (must be finite)", i % 3, flat[i])));
    }
    Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// A mesh from positions `N × 3` (flat, length `3·N`) and triangles `T × 3` (flat).
pub fn mesh_from_arrays(what: (&str, &str), positions: &[f64], faces: &[i64]) -> Result<TriMesh> {
    if !positions.len().is_multiple_of(3) || positions.is_empty() {
        return Err(Error::Invalid(format!("{}: {} numbers is not N × 3 with N ≥ 1", what.0, positions.len())));
    }
    let p = positions_from_array(what.0, positions, None)?;
    let f = faces_from_array(what.1, faces, p.len())?;
    Ok(TriMesh::new(p, f))
}

/// A sequence of `n_frames` frames of `N` vertices from positions `F × N × 3` (flat, length
/// `3·F·N`) and triangles `T × 3` (flat) shared by every frame. Frames are named `names` (one
/// per frame) or `frame_001`, `frame_002`, … (1-based, zero-padded to the count's width).
pub fn sequence_from_arrays(
    what: (&str, &str),
    positions: &[f64],
    n_frames: usize,
    faces: &[i64],
    names: Option<Vec<String>>,
) -> Result<MeshSequence> {
    if n_frames == 0 || positions.is_empty() || !positions.len().is_multiple_of(3 * n_frames) {
        return Err(Error::Invalid(format!(
            "{}: {} numbers is not F × N × 3 with F = {n_frames} ≥ 1 and N ≥ 1",
            what.0,
            positions.len()
        )));
    }
    let per_frame = positions.len() / n_frames;
    let frames = positions
        .chunks_exact(per_frame)
        .enumerate()
        .map(|(f, c)| positions_from_array(what.0, c, Some(f)))
        .collect::<Result<Vec<_>>>()?;
    let faces = faces_from_array(what.1, faces, per_frame / 3)?;
    let names = match names {
        Some(n) if n.len() != n_frames => {
            return Err(Error::Invalid(format!("{} frame names given for {n_frames} frames", n.len())));
        }
        Some(n) => n,
        None => {
            let width = n_frames.to_string().len().max(3);
            (1..=n_frames).map(|i| format!("frame_{i:0width$}")).collect()
        }
    };
    Ok(MeshSequence { faces, frames, names })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builds_a_sequence_and_names_bad_values() {
        let p = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let two: Vec<f64> = p.iter().chain(p.iter()).copied().collect();
        let s = sequence_from_arrays(("frames", "faces"), &two, 2, &[0, 1, 2], None).unwrap();
        assert_eq!((s.n_frames(), s.n_vertices(), s.n_faces()), (2, 3, 1));
        assert_eq!(s.names, ["frame_001", "frame_002"]);
        let e = sequence_from_arrays(("frames", "faces"), &two, 2, &[0, 1, 3], None).unwrap_err().to_string();
        assert!(e.starts_with("faces: triangle 0 has vertex index 3"), "{e}");
        let mut nan = two.clone();
        nan[7] = f64::NAN;
        let e = sequence_from_arrays(("frames", "faces"), &nan, 2, &[0, 1, 2], None).unwrap_err().to_string();
        assert!(e.contains("frames: frame 0, vertex 2, coordinate 1 is NaN"), "{e}");
        let e = mesh_from_arrays(("vertices", "faces"), &p, &[0, -1, 2]).unwrap_err().to_string();
        assert!(e.contains("faces") && e.contains("-1"), "{e}");
    }

    /// Every shape check with its message, on both sides of each bound: whole triangles, at
    /// least one, indices in `0..N` (N itself refused), N × 3 positions with N ≥ 1, F ≥ 1 frames
    /// dividing the positions, names one per frame, generated names padded to the count's width.
    #[test]
    fn shape_checks_and_names_at_their_bounds() {
        let err = |r: Result<Vec<[usize; 3]>>| r.unwrap_err().to_string();
        assert_eq!(faces_from_array("f", &[0, 1, 2, 2, 1, 0], 3).unwrap(), vec![[0, 1, 2], [2, 1, 0]]);
        assert!(err(faces_from_array("f", &[0, 1, 2, 0], 3)).contains("f: 4 indices is not a whole number"));
        assert!(err(faces_from_array("f", &[], 3)).contains("f: no triangles"));
        let e = err(faces_from_array("f", &[0, 1, 2, 0, 3, 1], 3));
        assert!(e.contains("f: triangle 1 has vertex index 3 (column 1), outside 0..3"), "{e}");
        assert_eq!(faces_from_array("f", &[2, 2, 0], 3).unwrap(), vec![[2, 2, 0]]);

        // A single mesh: positions N × 3, N ≥ 1; the bad coordinate named by vertex (no frame).
        let tri = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let m = mesh_from_arrays(("p", "f"), &tri, &[0, 1, 2]).unwrap();
        assert_eq!(m.positions, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert_eq!(m.faces, vec![[0, 1, 2]]);
        let merr = |p: &[f64], f: &[i64]| mesh_from_arrays(("p", "f"), p, f).unwrap_err().to_string();
        assert!(merr(&tri[..8], &[0, 1, 2]).contains("p: 8 numbers is not N × 3 with N ≥ 1"));
        assert!(merr(&[], &[0, 1, 2]).contains("p: 0 numbers"));
        let mut inf = tri;
        inf[5] = f64::INFINITY;
        let e = merr(&inf, &[0, 1, 2]);
        assert!(e.contains("p: vertex 1, coordinate 2 is inf (must be finite)") && !e.contains("frame"), "{e}");
        assert!(merr(&tri, &[0, 1, 3]).contains("f: triangle 0 has vertex index 3"));

        // Sequences: F ≥ 1 frames that divide the positions; faces checked against N, not F·N.
        let seq =
            |p: &[f64], f: usize, names: Option<Vec<String>>| sequence_from_arrays(("p", "f"), p, f, &[0, 1, 2], names);
        let six: Vec<f64> = (0..6).flat_map(|f| tri.map(|x| x + f as f64)).collect();
        let s = seq(&six, 6, None).unwrap();
        assert_eq!((s.n_frames(), s.n_vertices()), (6, 3));
        assert_eq!(s.frames[5][1], [6.0, 5.0, 5.0]);
        assert_eq!(s.names[5], "frame_006");
        assert!(sequence_from_arrays(("p", "f"), &six, 2, &[0, 1, 3], None).is_ok(), "N = 9 per frame at F = 2");
        let e = sequence_from_arrays(("p", "f"), &six, 6, &[0, 1, 3], None).unwrap_err().to_string();
        assert!(e.contains("outside 0..3"), "{e}");
        let sizes = |f: usize| format!("p: {} numbers is not F × N × 3 with F = {f} ≥ 1 and N ≥ 1", six.len());
        assert!(seq(&six, 0, None).unwrap_err().to_string().contains(&sizes(0)));
        assert!(seq(&six, 4, None).unwrap_err().to_string().contains(&sizes(4)));
        assert!(seq(&[], 1, None).unwrap_err().to_string().contains("p: 0 numbers"));
        let big: Vec<f64> = (0..1000).flat_map(|_| tri).collect();
        let s = sequence_from_arrays(("p", "f"), &big, 1000, &[0, 0, 0], None).unwrap();
        assert_eq!((s.names[0].as_str(), s.names[999].as_str()), ("frame_0001", "frame_1000"));
        let names: Vec<String> = (0..6).map(|i| format!("pose{i}")).collect();
        assert_eq!(seq(&six, 6, Some(names.clone())).unwrap().names, names);
        let e = seq(&six, 6, Some(names[..5].to_vec())).unwrap_err().to_string();
        assert!(e.contains("5 frame names given for 6 frames"), "{e}");
    }
}
