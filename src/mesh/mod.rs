//! Triangle meshes, mesh sequences that share one connectivity, their topology, and file I/O.
//!
//! Conventions: positions are `f64` in the data's own units; faces are triangles given as
//! 0-based vertex indices, counter-clockwise when seen from outside (the file's order is kept).

pub mod arrays;
pub mod hdf5;
pub mod inspect;
pub mod load;
pub mod normals;
pub mod npy;
pub mod obj;
pub mod off;
pub mod ply;
pub mod render;
pub mod sequence;
pub mod topology;
pub mod write;

pub use inspect::{InspectReport, Warning, WarningKind, inspect, inspect_path};
pub use load::{LoadedMesh, MeshFormat, load_mesh, read_mesh};
pub use sequence::{LoadedSequence, load_sequence, read_sequence};
pub use topology::Topology;
pub use write::{colormap, colormap_range, obj_bytes, ply_bytes, write_mesh, write_obj, write_off, write_ply};

/// One vertex position, `[x, y, z]` (the 3-vector type of [`crate::math::vec3`]).
pub use crate::math::Vec3;
/// Euclidean distance of two points (see [`crate::math::vec3::dist`]).
pub use crate::math::vec3::dist;

/// A triangle mesh: positions (N) and triangles (T) as 0-based vertex indices.
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    /// N vertex positions.
    pub positions: Vec<Vec3>,
    /// T triangles, vertex indices into `positions`.
    pub faces: Vec<[usize; 3]>,
}

impl TriMesh {
    /// Builds a mesh; does not validate (see [`TriMesh::validate_indices`]).
    pub fn new(positions: Vec<Vec3>, faces: Vec<[usize; 3]>) -> Self {
        TriMesh { positions, faces }
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles T.
    pub fn n_faces(&self) -> usize {
        self.faces.len()
    }

    /// Returns the first face (index, face) that refers to a vertex index ≥ N, if any.
    pub fn first_bad_index(&self) -> Option<(usize, [usize; 3])> {
        let n = self.positions.len();
        self.faces.iter().enumerate().find(|(_, f)| f.iter().any(|&v| v >= n)).map(|(i, f)| (i, *f))
    }

    /// Mean edge length over the faces' edges (each interior edge counted twice).
    pub fn mean_edge_length(&self) -> f64 {
        let mut sum = 0.0;
        let mut count = 0usize;
        for f in &self.faces {
            for k in 0..3 {
                sum += dist(self.positions[f[k]], self.positions[f[(k + 1) % 3]]);
                count += 1;
            }
        }
        if count == 0 { 0.0 } else { sum / count as f64 }
    }

    /// Axis-aligned bounding box `(min, max)`.
    pub fn bounding_box(&self) -> (Vec3, Vec3) {
        bounding_box(&self.positions)
    }
}

/// Frames that share one connectivity: the template faces plus F × N positions.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshSequence {
    /// Triangles shared by every frame.
    pub faces: Vec<[usize; 3]>,
    /// F frames of N positions each.
    pub frames: Vec<Vec<Vec3>>,
    /// One name per frame (file stem, or a generated name for synthetic data).
    pub names: Vec<String>,
}

impl MeshSequence {
    /// Number of frames F.
    pub fn n_frames(&self) -> usize {
        self.frames.len()
    }

    /// Number of vertices N (0 when there is no frame).
    pub fn n_vertices(&self) -> usize {
        self.frames.first().map_or(0, |f| f.len())
    }

    /// Number of triangles T.
    pub fn n_faces(&self) -> usize {
        self.faces.len()
    }

    /// Frame `f` as a standalone mesh (copies positions and faces).
    pub fn mesh(&self, f: usize) -> TriMesh {
        TriMesh::new(self.frames[f].clone(), self.faces.clone())
    }

    /// A sequence with the frames whose 0-based indices are given, in that order.
    pub fn select(&self, indices: &[usize]) -> MeshSequence {
        MeshSequence {
            faces: self.faces.clone(),
            frames: indices.iter().map(|&i| self.frames[i].clone()).collect(),
            names: indices.iter().map(|&i| self.names[i].clone()).collect(),
        }
    }
}

/// Read access to the frames of a sequence, held in memory ([`MeshSequence`]) or read on demand
/// (a prepared data set too large to hold: `preprocess::PreparedFrames`). A frame comes back in
/// the data's positions, `f64`, N of them; reading one may fail (a file read on demand).
pub trait FrameSource: Sync {
    /// Triangles shared by every frame.
    fn faces(&self) -> &[[usize; 3]];
    /// Number of frames F.
    fn n_frames(&self) -> usize;
    /// Number of vertices N.
    fn n_vertices(&self) -> usize;
    /// The name of frame `f` (`"?"` out of range).
    fn name(&self, f: usize) -> &str;
    /// Frame `f` (0-based); an index out of range is an error naming it.
    fn frame(&self, f: usize) -> crate::Result<std::borrow::Cow<'_, [Vec3]>>;
    /// The frames `indices` (0-based, in that order) as their own sequence.
    fn select_frames(&self, indices: &[usize]) -> crate::Result<MeshSequence> {
        Ok(MeshSequence {
            faces: self.faces().to_vec(),
            frames: indices
                .iter()
                .map(|&i| self.frame(i).map(std::borrow::Cow::into_owned))
                .collect::<crate::Result<_>>()?,
            names: indices.iter().map(|&i| self.name(i).to_string()).collect(),
        })
    }
}

impl FrameSource for MeshSequence {
    fn faces(&self) -> &[[usize; 3]] {
        &self.faces
    }
    fn n_frames(&self) -> usize {
        self.frames.len()
    }
    fn n_vertices(&self) -> usize {
        MeshSequence::n_vertices(self)
    }
    fn name(&self, f: usize) -> &str {
        self.names.get(f).map_or("?", String::as_str)
    }
    fn frame(&self, f: usize) -> crate::Result<std::borrow::Cow<'_, [Vec3]>> {
        self.frames.get(f).map(|v| std::borrow::Cow::Borrowed(v.as_slice())).ok_or_else(|| {
            crate::Error::Invalid(format!("frame index {f} is out of range ({} frames)", self.frames.len()))
        })
    }
}

/// Axis-aligned bounding box `(min, max)` of points; `([0;3],[0;3])` for none.
pub fn bounding_box(points: &[Vec3]) -> (Vec3, Vec3) {
    if points.is_empty() {
        return ([0.0; 3], [0.0; 3]);
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

pub mod primitives;

#[cfg(test)]
mod tests {
    use super::*;

    /// The mean over every face's three edges: a right triangle with legs 2 has edges 2, 2 and
    /// 2√2; a second face on one of its edges counts that edge twice.
    #[test]
    fn mean_edge_length_averages_each_faces_edges() {
        let mut m =
            TriMesh { positions: vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]], faces: vec![[0, 1, 2]] };
        assert!((m.mean_edge_length() - (4.0 + 8f64.sqrt()) / 3.0).abs() < 1e-12);
        m.positions.push([2.0, 2.0, 0.0]);
        m.faces.push([1, 3, 2]);
        assert!((m.mean_edge_length() - (8.0 + 2.0 * 8f64.sqrt()) / 6.0).abs() < 1e-12);
    }

    /// A sequence as a `FrameSource`: frames and names by index, `"?"` and an error naming the
    /// index out of range, and `select_frames` keeping each chosen frame's name.
    #[test]
    fn frame_source_of_a_sequence_names_and_selects_frames() {
        let seq = MeshSequence {
            faces: vec![[0, 1, 2]],
            frames: (0..3).map(|f| vec![[f as f64, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]).collect(),
            names: vec!["rest".into(), "bend".into(), "twist".into()],
        };
        let src: &dyn FrameSource = &seq;
        assert_eq!((src.n_frames(), src.n_vertices(), src.faces()), (3, 3, &[[0, 1, 2]][..]));
        assert_eq!((src.name(0), src.name(2), src.name(3)), ("rest", "twist", "?"));
        assert_eq!(src.frame(1).unwrap()[0], [1.0, 0.0, 0.0]);
        assert!(src.frame(3).unwrap_err().to_string().contains("frame index 3 is out of range (3 frames)"));
        let picked = src.select_frames(&[2, 0]).unwrap();
        assert_eq!(picked.names, ["twist", "rest"]);
        assert_eq!(picked.frames, vec![seq.frames[2].clone(), seq.frames[0].clone()]);
        assert_eq!(picked, seq.select(&[2, 0]));
    }
}
