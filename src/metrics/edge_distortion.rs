//! Edge-length distortion of a single shape against a rest mesh with the same connectivity:
//! how much a synthesized pose (e.g. a component at weight ±1) stretches or shrinks the surface
//! locally. Rotational "shrink" artefacts of displacement-based components (Huang et al. 2014)
//! show up here as large relative edge changes.
//!
//! For rest edge lengths `l` and shape edge lengths `l'` (same edges):
//! * `mean_relative` = mean over edges of `|l' − l| / l`,
//! * `max_relative`  = the largest `|l' − l| / l`,
//! * `spatial_sted`  = the STED spatial part of the pair (rest as ground truth, the shape as
//!   result, one frame; see [`super::sted`]), which ignores locally uniform scaling.
//!
//! All three are dimensionless and 0 for the rest shape itself or any rigid motion of it.

use super::sted::{Sted, StedParams};
use crate::error::{Error, Result};
use crate::mesh::{TriMesh, Vec3, dist};

/// Edge-length distortion of one shape (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeDistortion {
    /// Mean over edges of `|l' − l| / l`.
    pub mean_relative: f64,
    /// Maximum over edges of `|l' − l| / l`.
    pub max_relative: f64,
    /// STED spatial part of (rest, shape).
    pub spatial_sted: f64,
}

/// Measures [`EdgeDistortion`] of shapes against one rest mesh: the rest edge lengths and the
/// STED neighbourhoods are computed once.
#[derive(Debug, Clone)]
pub struct EdgeDistortionMeter {
    rest: Vec<Vec3>,
    rest_lengths: Vec<f64>,
    sted: Sted,
}

impl EdgeDistortionMeter {
    /// Prepares the meter. Errors on invalid `params`, bad face indices, non-finite rest
    /// positions or a zero-length rest edge.
    pub fn new(rest: &TriMesh, params: StedParams) -> Result<Self> {
        if let Some(v) = rest.positions.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
            return Err(Error::Invalid(format!("rest vertex {v} has a non-finite coordinate {:?}", rest.positions[v])));
        }
        let sted = Sted::new(rest.n_vertices(), &rest.faces, params)?;
        let mut rest_lengths = Vec::with_capacity(sted.edges().len());
        for &[i, j] in sted.edges() {
            let l = dist(rest.positions[i], rest.positions[j]);
            if l <= 0.0 {
                return Err(Error::Numerical(format!(
                    "rest edge ({i}, {j}) has length 0; relative edge change undefined"
                )));
            }
            rest_lengths.push(l);
        }
        Ok(EdgeDistortionMeter { rest: rest.positions.clone(), rest_lengths, sted })
    }

    /// Distortion of `shape` (N positions, data units of the rest mesh). Errors on a vertex
    /// count mismatch or non-finite positions. A mesh without edges gives all zeros.
    pub fn measure(&self, shape: &[Vec3]) -> Result<EdgeDistortion> {
        if shape.len() != self.rest.len() {
            return Err(Error::Invalid(format!(
                "shape has {} vertices, the rest mesh {}",
                shape.len(),
                self.rest.len()
            )));
        }
        let spatial_sted = self.sted.spatial_frame(&self.rest, shape)?;
        let (mut sum, mut max) = (0.0f64, 0.0f64);
        for (&[i, j], &l) in self.sted.edges().iter().zip(&self.rest_lengths) {
            let r = (dist(shape[i], shape[j]) - l).abs() / l;
            sum += r;
            max = max.max(r);
        }
        let n = self.rest_lengths.len();
        Ok(EdgeDistortion { mean_relative: if n == 0 { 0.0 } else { sum / n as f64 }, max_relative: max, spatial_sted })
    }
}

/// One-shot [`EdgeDistortionMeter::measure`].
pub fn edge_length_distortion(rest: &TriMesh, shape: &[Vec3], params: StedParams) -> Result<EdgeDistortion> {
    EdgeDistortionMeter::new(rest, params)?.measure(shape)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_distortion() {
        // Unit right triangle 0=(0,0,0), 1=(1,0,0), 2=(0,1,0): edges (0,1) 1, (0,2) 1, (1,2) √2.
        // Shape: vertex 1 moved to (2,0,0): (0,1) → 2 (rel. change 1), (0,2) unchanged,
        // (1,2) → √5 (rel. change √5/√2 − 1 = 0.5811388).
        let rest = TriMesh::new(vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], vec![[0, 1, 2]]);
        let shape = vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let d = edge_length_distortion(&rest, &shape, StedParams::default()).unwrap();
        let r12 = (2.5f64).sqrt() - 1.0;
        assert!((d.mean_relative - (1.0 + r12) / 3.0).abs() < 1e-12);
        assert!((d.max_relative - 1.0).abs() < 1e-12);
        // Spatial part: every vertex of a triangle sees two edges. Vertex 0: (0,1) w 1 d 1,
        // (0,2) w 1 d 0 → dev 0.5. Vertex 1: (0,1) w 1 d 1, (1,2) w √2 d r12.
        // Vertex 2: (0,2) w 1 d 0, (1,2) w √2 d r12. For two values a, b with weights
        // wa, wb the weighted deviation is |a − b|·sqrt(wa·wb)/(wa + wb).
        let s2 = 2f64.sqrt();
        let dev2 = |a: f64, b: f64, wa: f64, wb: f64| (a - b).abs() * (wa * wb).sqrt() / (wa + wb);
        let want = (0.5 + dev2(1.0, r12, 1.0, s2) + dev2(0.0, r12, 1.0, s2)) / 3.0;
        assert!((d.spatial_sted - want).abs() < 1e-12, "{} vs {want}", d.spatial_sted);
        // Uniform scaling: every relative change 1, spatial part 0.
        let scaled: Vec<Vec3> = rest.positions.iter().map(|p| [2.0 * p[0], 2.0 * p[1], 2.0 * p[2]]).collect();
        let d = edge_length_distortion(&rest, &scaled, StedParams::default()).unwrap();
        assert!((d.mean_relative - 1.0).abs() < 1e-12 && d.spatial_sted.abs() < 1e-12);
        assert!(edge_length_distortion(&rest, &shape[..2], StedParams::default()).is_err());
    }
}
