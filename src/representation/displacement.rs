//! Vertex displacements (SPLOCS, Neumann et al. 2013): 3 numbers per vertex, `x_f − x_rest`, in
//! the data's own units. Decoding adds the rest positions back, so it keeps translation and is
//! exact up to one rounding per coordinate.
//!
//! (SPLOCS additionally divides the whole data matrix by its standard deviation; that global
//! scale belongs to the method, not to this representation.)

#![warn(missing_docs)]

use crate::error::{Error, Result};
use crate::mesh::Vec3;

/// Numbers per vertex.
pub const WIDTH: usize = 3;

/// Displacements against fixed rest positions.
#[derive(Debug, Clone)]
pub struct Displacement {
    rest: Vec<Vec3>,
}

impl Displacement {
    /// Stores the rest positions (N). Errors on a non-finite position.
    pub fn new(rest: &[Vec3]) -> Result<Self> {
        check(rest, rest.len(), "rest")?;
        Ok(Displacement { rest: rest.to_vec() })
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.rest.len()
    }

    /// N × 3 numbers `x − x_rest` of one frame. Errors when the vertex count differs or a
    /// position is not finite.
    pub fn encode_frame(&self, positions: &[Vec3]) -> Result<Vec<f64>> {
        check(positions, self.rest.len(), "frame")?;
        let mut out = Vec::with_capacity(positions.len() * 3);
        for (p, r) in positions.iter().zip(&self.rest) {
            out.extend_from_slice(&[p[0] - r[0], p[1] - r[1], p[2] - r[2]]);
        }
        Ok(out)
    }

    /// Positions `x_rest + d` from N × 3 displacements. Errors on a length mismatch or a
    /// non-finite number.
    pub fn decode_frame(&self, features: &[f64]) -> Result<Vec<Vec3>> {
        if features.len() != self.rest.len() * WIDTH {
            return Err(Error::Invalid(format!(
                "displacement features have {} numbers, expected {} vertices × 3",
                features.len(),
                self.rest.len()
            )));
        }
        if let Some(i) = features.iter().position(|x| !x.is_finite()) {
            return Err(Error::Invalid(format!("displacement {i} (vertex {}) is not finite: {}", i / 3, features[i])));
        }
        Ok(self
            .rest
            .iter()
            .zip(features.chunks_exact(3))
            .map(|(r, d)| [r[0] + d[0], r[1] + d[1], r[2] + d[2]])
            .collect())
    }
}

fn check(positions: &[Vec3], n: usize, what: &str) -> Result<()> {
    if positions.len() != n {
        return Err(Error::Invalid(format!("{what} has {} vertices, expected {n}", positions.len())));
    }
    if let Some(i) = positions.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        return Err(Error::Invalid(format!("{what} vertex {i} has a non-finite position {:?}", positions[i])));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_exact_and_rest_is_zero() {
        let rest = vec![[0.1, 0.2, 0.3], [1.0, -2.0, 3.5], [1e3, 1e-3, -7.25]];
        let frame = vec![[0.5, 0.25, 0.125], [1.0, -2.0, 3.5], [-3.0, 2.0, 1.0]];
        let d = Displacement::new(&rest).unwrap();
        assert!(d.encode_frame(&rest).unwrap().iter().all(|&x| x == 0.0));
        let q = d.encode_frame(&frame).unwrap();
        for (v, (p, r)) in frame.iter().zip(&rest).enumerate() {
            for k in 0..3 {
                assert_eq!(q[v * 3 + k], p[k] - r[k]);
            }
        }
        // (p − r) + r differs from p by at most one rounding of the larger magnitude.
        let back = d.decode_frame(&q).unwrap();
        for ((a, p), r) in back.iter().zip(&frame).zip(&rest) {
            for k in 0..3 {
                assert!((a[k] - p[k]).abs() <= f64::EPSILON * p[k].abs().max(r[k].abs()));
            }
        }
        assert!(d.decode_frame(&q[1..]).is_err());
        assert!(d.encode_frame(&frame[1..]).is_err());
    }
}
