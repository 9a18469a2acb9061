//! Lumped (diagonal) mass matrix.
//!
//! Barycentric lumping: every triangle gives a third of its area to each of its three corners,
//! so `m_i = Σ_{faces f ∋ i} area(f) / 3` and `Σ_i m_i` is the total surface area. Units: the
//! data's length unit squared; scaling the mesh by `s` scales every entry by `s²`. All entries
//! are ≥ 0; a vertex on no face (or only on zero-area faces) gets 0. A degenerate triangle
//! contributes its (tiny, finite) area like any other.

use crate::math::vec3::{cross, norm, sub};
use crate::mesh::Vec3;

/// Area of every face (half the length of the cross product of two edges), in length².
/// Face indices must be valid.
pub fn face_areas(positions: &[Vec3], faces: &[[usize; 3]]) -> Vec<f64> {
    faces
        .iter()
        .map(|f| {
            let (a, b, c) = (positions[f[0]], positions[f[1]], positions[f[2]]);
            0.5 * norm(cross(sub(b, a), sub(c, a)))
        })
        .collect()
}

/// Diagonal of the barycentric lumped mass matrix: N values (N = `positions.len()`),
/// `m_i = Σ_{f ∋ i} area(f)/3`, in length². Face indices must be valid.
pub fn lumped_mass(positions: &[Vec3], faces: &[[usize; 3]]) -> Vec<f64> {
    let mut m = vec![0.0; positions.len()];
    for (f, a) in faces.iter().zip(face_areas(positions, faces)) {
        for &v in f {
            m[v] += a / 3.0;
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives::{grid, icosphere};

    #[test]
    fn total_mass_is_area_and_scales_quadratically() {
        let g = grid(5, 4, 3.0);
        let m = lumped_mass(&g.positions, &g.faces);
        assert!((m.iter().sum::<f64>() - 9.0).abs() < 1e-12);
        // Interior vertex of the criss-cross grid with 4 or 8 incident triangles, each of area
        // (0.6·0.75)/2: the corner (0,0) touches one or two faces.
        assert!(m.iter().all(|&x| x > 0.0));
        for s in [1e-6, 1e6] {
            let p: Vec<Vec3> = g.positions.iter().map(|p| [p[0] * s, p[1] * s, p[2] * s]).collect();
            let ms = lumped_mass(&p, &g.faces);
            for (a, b) in m.iter().zip(&ms) {
                assert!((b / (s * s) - a).abs() <= 1e-12 * a);
            }
        }
        // The icosphere's area approaches 4π from below.
        let s = icosphere(4);
        let total: f64 = lumped_mass(&s.positions, &s.faces).iter().sum();
        assert!(total < 4.0 * std::f64::consts::PI && total > 0.99 * 4.0 * std::f64::consts::PI);
    }

    #[test]
    fn single_triangle_and_isolated_vertex() {
        let p = vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0], [5.0, 5.0, 5.0]];
        let m = lumped_mass(&p, &[[0, 1, 2]]);
        assert_eq!(m[3], 0.0);
        for &x in &m[..3] {
            assert!((x - 1.0).abs() < 1e-15);
        }
    }
}
