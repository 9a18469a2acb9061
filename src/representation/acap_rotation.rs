//! 3×3 matrix helpers of the ACAP representation: polar decomposition with the reference
//! implementation's reflection fix, rotation logarithm as axis–angle, and Rodrigues' exponential.
//!
//! Conventions: matrices are row-major `[[f64; 3]; 3]` (`m[row][col]`). The skew matrix of a
//! vector ω = (x, y, z) is
//!
//! ```text
//! [ω]× = [[ 0, -z,  y],
//!         [ z,  0, -x],
//!         [-y,  x,  0]]
//! ```
//!
//! so that `[ω]× v = ω × v`; a rotation by angle θ (right-hand rule) about the unit axis `a` is
//! `exp(θ [a]×)`.

#![allow(clippy::needless_range_loop)] // index loops over 3-vectors read like the formulas
use crate::mesh::Vec3;
use nalgebra::Matrix3;

/// A 3×3 matrix, row-major.
pub type Mat3 = [[f64; 3]; 3];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The zero matrix.
pub const ZERO: Mat3 = [[0.0; 3]; 3];

/// Matrix product a·b.
#[inline]
pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut c = ZERO;
    for (i, row) in c.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    c
}

/// Matrix–vector product m·v.
#[inline]
pub fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// Transpose.
#[inline]
pub fn transpose(m: &Mat3) -> Mat3 {
    [[m[0][0], m[1][0], m[2][0]], [m[0][1], m[1][1], m[2][1]], [m[0][2], m[1][2], m[2][2]]]
}

/// Determinant.
#[inline]
pub fn det(m: &Mat3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Inverse by the adjugate; `None` when the determinant is zero, not finite, or tiny relative to
/// the entries (relative threshold 1e-14 on |det| / max|m_ij|³).
pub fn inverse(m: &Mat3) -> Option<Mat3> {
    let d = det(m);
    let scale = m.iter().flatten().fold(0.0f64, |a, &v| a.max(v.abs()));
    if !d.is_finite() || scale == 0.0 || d.abs() <= 1e-14 * scale * scale * scale {
        return None;
    }
    let inv_d = 1.0 / d;
    let mut r = ZERO;
    r[0][0] = (m[1][1] * m[2][2] - m[1][2] * m[2][1]) * inv_d;
    r[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv_d;
    r[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv_d;
    r[1][0] = (m[1][2] * m[2][0] - m[1][0] * m[2][2]) * inv_d;
    r[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv_d;
    r[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * inv_d;
    r[2][0] = (m[1][0] * m[2][1] - m[1][1] * m[2][0]) * inv_d;
    r[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * inv_d;
    r[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * inv_d;
    Some(r)
}

/// The skew matrix \[ω\]× (see the module docs).
#[inline]
pub fn skew(w: Vec3) -> Mat3 {
    [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
}

/// The vector ω of a skew matrix: `(m[2][1], m[0][2], m[1][0])` (exact inverse of [`skew`]).
#[inline]
pub fn unskew(m: &Mat3) -> Vec3 {
    [m[2][1], m[0][2], m[1][0]]
}

/// Polar decomposition T = R·S of the reference implementation, by SVD T = U Σ Vᵀ:
/// R = U Vᵀ, S = V Σ Vᵀ; when det R < 0 the column of U of the smallest singular value and that
/// singular value are negated, then R and S are rebuilt (R is then a proper rotation and S is
/// symmetric with one negative eigenvalue). Returns `(R, S)`.
pub fn polar_decomposition(t: &Mat3) -> (Mat3, Mat3) {
    let m = Matrix3::new(t[0][0], t[0][1], t[0][2], t[1][0], t[1][1], t[1][2], t[2][0], t[2][1], t[2][2]);
    // `svd` sorts the singular values in descending order, so index 2 is the smallest.
    let svd = m.svd(true, true);
    let (Some(mut u), Some(v_t)) = (svd.u, svd.v_t) else {
        return (IDENTITY, *t);
    };
    let mut sv = svd.singular_values;
    if (u * v_t).determinant() < 0.0 {
        let mut min = 0;
        if sv[1] < sv[min] {
            min = 1;
        }
        if sv[2] < sv[min] {
            min = 2;
        }
        u.column_mut(min).neg_mut();
        sv[min] = -sv[min];
    }
    let r = u * v_t;
    let s = v_t.transpose() * Matrix3::from_diagonal(&sv) * v_t;
    let to = |a: &Matrix3<f64>| -> Mat3 {
        [[a[(0, 0)], a[(0, 1)], a[(0, 2)]], [a[(1, 0)], a[(1, 1)], a[(1, 2)]], [a[(2, 0)], a[(2, 1)], a[(2, 2)]]]
    };
    let mut s = to(&s);
    // Exact symmetry (the product above is symmetric up to rounding only).
    for i in 0..3 {
        for j in i + 1..3 {
            let a = 0.5 * (s[i][j] + s[j][i]);
            s[i][j] = a;
            s[j][i] = a;
        }
    }
    (to(&r), s)
}

/// Axis–angle of a rotation matrix: `(axis, θ)` with θ ∈ [0, π] and a unit axis, such that
/// `R = exp(θ [axis]×)`; the axis is `[0, 0, 0]` when θ = 0 exactly. Accurate near 0 (axis from
/// the skew part, θ by `atan2`) and near π (axis from the symmetric part, its sign from the skew
/// part; at θ = π exactly both signs describe R and the sign is arbitrary).
pub fn axis_angle(r: &Mat3) -> (Vec3, f64) {
    // w = vee(R − Rᵀ) = 2 sin θ · axis;  c = (tr R − 1)/2 = cos θ.
    let w = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    let wn = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    let c = ((r[0][0] + r[1][1] + r[2][2] - 1.0) * 0.5).clamp(-1.0, 1.0);
    let theta = (0.5 * wn).atan2(c);
    if c > -0.5 {
        if wn == 0.0 {
            return ([0.0; 3], 0.0);
        }
        return ([w[0] / wn, w[1] / wn, w[2] / wn], theta);
    }
    // θ > 2π/3: (R + Rᵀ)/2 − cos θ·I = (1 − cos θ)·a aᵀ; take its largest column.
    let mut b = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            b[i][j] = 0.5 * (r[i][j] + r[j][i]) - if i == j { c } else { 0.0 };
        }
    }
    let k = (0..3).fold(0, |k, i| if b[i][i] > b[k][k] { i } else { k });
    let col = [b[0][k], b[1][k], b[2][k]];
    let n = (col[0] * col[0] + col[1] * col[1] + col[2] * col[2]).sqrt();
    if n == 0.0 || !n.is_finite() {
        return ([0.0; 3], theta);
    }
    let mut a = [col[0] / n, col[1] / n, col[2] / n];
    if a[0] * w[0] + a[1] * w[1] + a[2] * w[2] < 0.0 {
        a = [-a[0], -a[1], -a[2]];
    }
    (a, theta)
}

/// Rodrigues' formula: exp(\[ω\]×) for a rotation vector ω (angle ‖ω‖, any size, about ω/‖ω‖).
/// Uses the Taylor series below ‖ω‖ = 1e-6.
pub fn exp_so3(w: Vec3) -> Mat3 {
    let t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    let t = t2.sqrt();
    let (a, b) = if t < 1e-6 { (1.0 - t2 / 6.0, 0.5 - t2 / 24.0) } else { (t.sin() / t, (1.0 - t.cos()) / t2) };
    let k = skew(w);
    let k2 = mat_mul(&k, &k);
    let mut r = IDENTITY;
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] += a * k[i][j] + b * k2[i][j];
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Mat3, b: &Mat3, tol: f64) -> bool {
        (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
    }

    #[test]
    fn polar_reconstructs_and_rotation_is_proper() {
        let ts: [Mat3; 3] = [
            [[1.1, 0.2, -0.3], [0.05, 0.9, 0.4], [0.3, -0.2, 1.3]],
            // Negative determinant: reflection fix applies.
            [[-1.0, 0.1, 0.0], [0.0, 1.2, 0.1], [0.2, 0.0, 0.8]],
            [[0.0, -2.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.5]],
        ];
        for t in &ts {
            let (r, s) = polar_decomposition(t);
            assert!(close(&mat_mul(&r, &s), t, 1e-12), "R S != T for {t:?}");
            assert!((det(&r) - 1.0).abs() < 1e-12);
            assert!(close(&mat_mul(&transpose(&r), &r), &IDENTITY, 1e-12));
            assert!(close(&s, &transpose(&s), 0.0));
        }
        // Reflection: S has exactly one negative eigenvalue, so det S < 0.
        let (_, s) = polar_decomposition(&ts[1]);
        assert!(det(&s) < 0.0);
    }

    #[test]
    fn axis_angle_inverts_exp_everywhere() {
        let axis = {
            let a: [f64; 3] = [0.3, -0.5, 0.8];
            let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            [a[0] / n, a[1] / n, a[2] / n]
        };
        for &theta in &[1e-9, 1e-4, 0.3, 1.5, 2.2, 3.0, std::f64::consts::PI - 1e-7, std::f64::consts::PI - 1e-3] {
            let r = exp_so3([axis[0] * theta, axis[1] * theta, axis[2] * theta]);
            let (a, t) = axis_angle(&r);
            assert!((t - theta).abs() < 1e-9, "theta {theta} -> {t}");
            let back = exp_so3([a[0] * t, a[1] * t, a[2] * t]);
            assert!(close(&back, &r, 1e-12), "theta {theta}");
            if theta > 1e-6 {
                let d = a[0] * axis[0] + a[1] * axis[1] + a[2] * axis[2];
                assert!((d - 1.0).abs() < 1e-6, "axis at theta {theta}: {a:?}");
            }
        }
        let (a, t) = axis_angle(&IDENTITY);
        assert_eq!((a, t), ([0.0; 3], 0.0));
    }

    #[test]
    fn skew_inverse_and_inverse_matrix() {
        let w = [0.1, -0.2, 0.3];
        assert_eq!(unskew(&skew(w)), w);
        let m = [[2.0, 0.5, 0.0], [0.1, 1.0, 0.3], [0.0, 0.2, 3.0]];
        let inv = inverse(&m).unwrap();
        assert!(close(&mat_mul(&m, &inv), &IDENTITY, 1e-14));
        assert!(inverse(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
    }
}
