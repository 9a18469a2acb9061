//! Per-face and per-vertex normals.
//!
//! Face normal of triangle (a, b, c): (b − a) × (c − a), whose length is twice the area; the
//! direction follows the counter-clockwise vertex order (right-hand rule). Positions are in
//! data units; unit normals are dimensionless.

use crate::math::vec3::{Vec3, cross, normalize, sub};

/// How face normals are combined into a vertex normal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NormalWeighting {
    /// Sum of unit face normals (every incident face counts the same).
    Uniform,
    /// Sum of area-weighted face normals (the raw cross products).
    Area,
}

/// Unnormalised face normals (length = 2 × area), one per face.
pub fn face_normals_raw(positions: &[Vec3], faces: &[[usize; 3]]) -> Vec<Vec3> {
    faces
        .iter()
        .map(|f| {
            let (a, b, c) = (positions[f[0]], positions[f[1]], positions[f[2]]);
            cross(sub(b, a), sub(c, a))
        })
        .collect()
}

/// Unit vertex normals; a vertex on no (non-degenerate) face gets `[0, 0, 0]`.
pub fn vertex_normals(positions: &[Vec3], faces: &[[usize; 3]], weighting: NormalWeighting) -> Vec<Vec3> {
    let mut acc = vec![[0.0; 3]; positions.len()];
    for (f, n) in faces.iter().zip(face_normals_raw(positions, faces)) {
        let n = match weighting {
            NormalWeighting::Area => n,
            NormalWeighting::Uniform => normalize(n),
        };
        for &v in f {
            for k in 0..3 {
                acc[v][k] += n[k];
            }
        }
    }
    acc.into_iter().map(normalize).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::vec3::norm;

    #[test]
    fn flat_square_normals_point_up() {
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let f = vec![[0, 1, 2], [0, 2, 3]];
        for w in [NormalWeighting::Uniform, NormalWeighting::Area] {
            for n in vertex_normals(&p, &f, w) {
                assert!((n[2] - 1.0).abs() < 1e-12 && n[0].abs() < 1e-12 && n[1].abs() < 1e-12);
            }
        }
        let raw = face_normals_raw(&p, &f);
        assert!((norm(raw[0]) - 1.0).abs() < 1e-12); // twice the area 0.5
    }
}
