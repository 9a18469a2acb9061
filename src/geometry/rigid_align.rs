//! Rigid alignment of corresponding point sets (Kabsch / orthogonal Procrustes).
//!
//! Finds the proper rotation `R` (det R = +1) and translation `t` minimising
//! `Σ_i w_i ‖R·s_i + t − q_i‖²` for sources `s_i` and targets `q_i`:
//!
//! 1. weighted centroids `s̄`, `q̄`;
//! 2. cross-covariance `H = Σ w_i (s_i − s̄)(q_i − q̄)ᵀ = U Σ Vᵀ` (SVD);
//! 3. `R = V D Uᵀ` with `D = diag(1, 1, d)` where `d = sign det(V Uᵀ)`, the `d` placed on the
//!    singular vector of the **smallest** singular value. When the best orthogonal matrix would be
//!    a reflection, this flips the sign of that last singular vector only (the optimal proper
//!    rotation); it does not negate the whole matrix;
//! 4. `t = q̄ − R s̄`.
//!
//! Degenerate configurations (fewer than three non-collinear points) have no unique rotation;
//! a proper rotation that attains the minimum is still returned.

use nalgebra::{Matrix3, Vector3};

use crate::math::mat3::transpose;
use crate::math::vec3::dot;
use crate::mesh::Vec3;
use crate::{Error, Result};

/// A rigid motion `p ↦ R·p + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidTransform {
    /// Rotation matrix, row-major: `rotation[r][c]` is row r, column c. Proper (det = +1).
    pub rotation: [[f64; 3]; 3],
    /// Translation, applied after the rotation (length units).
    pub translation: Vec3,
}

impl RigidTransform {
    /// The identity motion.
    pub fn identity() -> Self {
        RigidTransform { rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation: [0.0; 3] }
    }

    /// `R·p + t`.
    pub fn apply(&self, p: Vec3) -> Vec3 {
        let r = &self.rotation;
        let mut out = self.translation;
        for (k, o) in out.iter_mut().enumerate() {
            *o += dot(r[k], p);
        }
        out
    }

    /// Applies the motion to every point.
    pub fn apply_all(&self, points: &[Vec3]) -> Vec<Vec3> {
        points.iter().map(|&p| self.apply(p)).collect()
    }

    /// The inverse motion `q ↦ Rᵀ(q − t)`.
    pub fn inverse(&self) -> Self {
        let r = &self.rotation;
        let rt = transpose(r);
        let t = self.translation;
        let mut tt = [0.0; 3];
        for k in 0..3 {
            tt[k] = -dot(rt[k], t);
        }
        RigidTransform { rotation: rt, translation: tt }
    }
}

/// Least-squares rigid motion mapping `source[i]` onto `target[i]` (all weights 1). Returns the
/// identity for empty input.
///
/// # Panics
/// If `source.len() != target.len()` (a caller bug: both come from frames of one sequence). Use
/// [`kabsch_weighted`] for a checked variant.
pub fn kabsch(source: &[Vec3], target: &[Vec3]) -> RigidTransform {
    assert_eq!(source.len(), target.len(), "kabsch: source and target must have the same number of points");
    solve(source, target, None)
}

/// Weighted least-squares rigid motion: minimises `Σ w_i ‖R·s_i + t − q_i‖²`.
///
/// Errors ([`Error::Invalid`]) when the lengths differ, a weight is negative or not finite, the
/// weights sum to zero, or a point is not finite.
pub fn kabsch_weighted(source: &[Vec3], target: &[Vec3], weights: &[f64]) -> Result<RigidTransform> {
    if source.len() != target.len() || source.len() != weights.len() {
        return Err(Error::Invalid(format!(
            "kabsch: {} source points, {} target points and {} weights must have equal lengths",
            source.len(),
            target.len(),
            weights.len()
        )));
    }
    if let Some((i, w)) = weights.iter().enumerate().find(|(_, w)| !(w.is_finite() && **w >= 0.0)) {
        return Err(Error::Invalid(format!("kabsch: weight {i} ({w}) must be finite and ≥ 0")));
    }
    let total: f64 = weights.iter().sum();
    if total <= 0.0 || !total.is_finite() {
        return Err(Error::Invalid(format!("kabsch: the weights sum to {total}, not a positive finite number")));
    }
    for (name, pts) in [("source", source), ("target", target)] {
        if let Some((i, p)) = pts.iter().enumerate().find(|(_, p)| p.iter().any(|c| !c.is_finite())) {
            return Err(Error::Invalid(format!("kabsch: {name} point {i} {p:?} is not finite")));
        }
    }
    Ok(solve(source, target, Some(weights)))
}

fn solve(source: &[Vec3], target: &[Vec3], weights: Option<&[f64]>) -> RigidTransform {
    if source.is_empty() {
        return RigidTransform::identity();
    }
    let w = |i: usize| weights.map_or(1.0, |w| w[i]);
    let total: f64 = (0..source.len()).map(w).sum();
    let mut cs = [0.0; 3];
    let mut ct = [0.0; 3];
    for i in 0..source.len() {
        for k in 0..3 {
            cs[k] += w(i) * source[i][k];
            ct[k] += w(i) * target[i][k];
        }
    }
    for k in 0..3 {
        cs[k] /= total;
        ct[k] /= total;
    }
    let mut h = Matrix3::<f64>::zeros();
    for i in 0..source.len() {
        let a = Vector3::new(source[i][0] - cs[0], source[i][1] - cs[1], source[i][2] - cs[2]);
        let b = Vector3::new(target[i][0] - ct[0], target[i][1] - ct[1], target[i][2] - ct[2]);
        h += (a * b.transpose()) * w(i);
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return RigidTransform::identity();
    };
    let v = v_t.transpose();
    let mut d = Matrix3::<f64>::identity();
    if (v * u.transpose()).determinant() < 0.0 {
        // Flip the singular vector of the smallest singular value.
        let s = svd.singular_values;
        let k = (0..3).min_by(|&a, &b| s[a].total_cmp(&s[b])).unwrap_or(2);
        d[(k, k)] = -1.0;
    }
    let r = v * d * u.transpose();
    let rotation =
        [[r[(0, 0)], r[(0, 1)], r[(0, 2)]], [r[(1, 0)], r[(1, 1)], r[(1, 2)]], [r[(2, 0)], r[(2, 1)], r[(2, 2)]]];
    let mut translation = ct;
    for k in 0..3 {
        translation[k] -= dot(rotation[k], cs);
    }
    RigidTransform { rotation, translation }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-random numbers in [−1, 1).
    fn rng(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            2.0 * ((s >> 11) as f64 / (1u64 << 53) as f64) - 1.0
        }
    }

    /// Rotation from a unit quaternion built from 4 random numbers.
    fn random_rotation(r: &mut impl FnMut() -> f64) -> [[f64; 3]; 3] {
        let (mut w, mut x, mut y, mut z) = (r(), r(), r(), r());
        let n = (w * w + x * x + y * y + z * z).sqrt();
        w /= n;
        x /= n;
        y /= n;
        z /= n;
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ]
    }

    fn det(r: &[[f64; 3]; 3]) -> f64 {
        r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0])
    }

    #[test]
    fn recovers_random_rigid_motions_exactly() {
        let mut r = rng(7);
        for trial in 0..20 {
            let pts: Vec<Vec3> = (0..30).map(|_| [r(), 2.0 * r(), 0.5 * r()]).collect();
            let truth =
                RigidTransform { rotation: random_rotation(&mut r), translation: [10.0 * r(), r(), -3.0 * r()] };
            let moved = truth.apply_all(&pts);
            let est = kabsch(&pts, &moved);
            for a in 0..3 {
                for b in 0..3 {
                    assert!((est.rotation[a][b] - truth.rotation[a][b]).abs() < 1e-12, "trial {trial}");
                }
                assert!((est.translation[a] - truth.translation[a]).abs() < 1e-12);
            }
            // Weighted variant with arbitrary positive weights gives the same exact motion, and the
            // inverse maps back.
            let w: Vec<f64> = (0..30).map(|_| 1.5 + r()).collect();
            let est = kabsch_weighted(&pts, &moved, &w).unwrap();
            let back = est.inverse().apply_all(&moved);
            for (p, q) in pts.iter().zip(&back) {
                for k in 0..3 {
                    assert!((p[k] - q[k]).abs() < 1e-11);
                }
            }
        }
    }

    #[test]
    fn reflected_target_still_gives_a_proper_rotation() {
        let mut r = rng(11);
        // Sign-symmetric point set: the covariance is exactly diagonal, z has the smallest spread.
        let base: Vec<Vec3> = (0..5).map(|_| [3.0 * r(), 2.0 * r(), 0.3 * r()]).collect();
        let pts: Vec<Vec3> = base
            .iter()
            .flat_map(|p| {
                (0..8).map(move |s| {
                    [
                        if s & 1 == 0 { p[0] } else { -p[0] },
                        if s & 2 == 0 { p[1] } else { -p[1] },
                        if s & 4 == 0 { p[2] } else { -p[2] },
                    ]
                })
            })
            .collect();
        // Mirror z (the axis of smallest spread), then rotate and translate.
        let truth = RigidTransform { rotation: random_rotation(&mut r), translation: [1.0, -2.0, 0.5] };
        let target: Vec<Vec3> = pts.iter().map(|p| truth.apply([p[0], p[1], -p[2]])).collect();
        let est = kabsch(&pts, &target);
        assert!((det(&est.rotation) - 1.0).abs() < 1e-12, "det {}", det(&est.rotation));
        // Orthonormal rows.
        for a in 0..3 {
            for b in 0..3 {
                let d: f64 = (0..3).map(|k| est.rotation[a][k] * est.rotation[b][k]).sum();
                assert!((d - if a == b { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
        // Flipping the last singular vector keeps x and y right and only folds the thin z spread:
        // the best proper rotation here is the true rotation itself (residual = 4 Σ z²).
        for a in 0..3 {
            for b in 0..2 {
                assert!((est.rotation[a][b] - truth.rotation[a][b]).abs() < 1e-9, "column {b}");
            }
        }
        // Negating the whole matrix instead would be much worse than the returned solution.
        let cost = |t: &RigidTransform| -> f64 {
            pts.iter().zip(&target).map(|(p, q)| crate::mesh::dist(t.apply(*p), *q).powi(2)).sum()
        };
        let mut negated = est;
        for row in &mut negated.rotation {
            for x in row.iter_mut() {
                *x = -*x;
            }
        }
        let c_est = cost(&est);
        assert!(c_est < cost(&negated));
        assert!((c_est - 4.0 * pts.iter().map(|p| p[2] * p[2]).sum::<f64>()).abs() < 1e-9);
    }

    #[test]
    fn weighted_input_is_validated() {
        let p = vec![[0.0; 3]; 3];
        assert!(kabsch_weighted(&p, &p[..2], &[1.0; 3]).is_err());
        assert!(kabsch_weighted(&p, &p, &[1.0, -1.0, 1.0]).is_err());
        assert!(kabsch_weighted(&p, &p, &[0.0; 3]).is_err());
        assert_eq!(kabsch(&[], &[]), RigidTransform::identity());
    }
}
