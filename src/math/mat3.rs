//! Helpers on 3×3 matrices `Mat3 = [[f64; 3]; 3]`, polar decomposition and the exponential and
//! logarithm of rotations (so(3) ↔ SO(3)).
//!
//! # Conventions
//! * **Row-major**: `m[row][col]`; the first index is the row. Matrices act on column vectors,
//!   `(m·v)[i] = Σ_j m[i][j]·v[j]` ([`mat_vec`]).
//! * The skew matrix of a vector ω = (x, y, z) is
//!
//!   ```text
//!   [ω]× = [[ 0, -z,  y],
//!           [ z,  0, -x],
//!           [-y,  x,  0]]
//!   ```
//!
//!   so that `[ω]× v = ω × v` ([`skew`], inverse [`unskew`]).
//! * Rotations follow the right-hand rule: the rotation by angle θ (radians) about the unit axis
//!   `a` is `exp(θ [a]×)`; its rotation vector (axis–angle vector) is `u = θ·a`.
//! * Angles are radians.

#![allow(clippy::needless_range_loop)] // index loops over 3×3 matrices read like the formulas
use super::vec3::{Vec3, dot, norm, scale};
use nalgebra::Matrix3;

/// A 3×3 matrix, row-major (`m[row][col]`), acting on column vectors.
pub type Mat3 = [[f64; 3]; 3];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The zero matrix.
pub const ZERO: Mat3 = [[0.0; 3]; 3];

/// Below this rotation angle ‖ω‖ (radians) [`exp_so3`] evaluates Rodrigues' coefficients
/// `sin θ / θ` and `(1 − cos θ) / θ²` by their second-order Taylor series `1 − θ²/6` and
/// `1/2 − θ²/24` instead of the closed forms.
///
/// At 1e-6 the series' truncation errors (θ⁴/120 and θ⁴/720, about 1e-26) are far below one
/// rounding unit, whereas the closed form `(1 − cos θ)/θ²` loses digits to cancellation there;
/// its contribution to R is scaled by θ², so either choice changes R by at most about one
/// rounding unit of its entries (see the tests, which compare with both former thresholds,
/// 1e-6 and 1e-8).
pub const RODRIGUES_SERIES_ANGLE: f64 = 1e-6;

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

/// Matrix–vector product m·v (v a column vector).
#[inline]
pub fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// Transpose mᵀ.
#[inline]
pub fn transpose(m: &Mat3) -> Mat3 {
    [[m[0][0], m[1][0], m[2][0]], [m[0][1], m[1][1], m[2][1]], [m[0][2], m[1][2], m[2][2]]]
}

/// m += s·a·bᵀ (outer product: `m[i][j] += (s·a[i])·b[j]`).
#[inline]
pub fn add_outer(m: &mut Mat3, a: Vec3, b: Vec3, s: f64) {
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] += s * a[i] * b[j];
        }
    }
}

/// Determinant (cofactor expansion along the first row).
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

/// The vector ω of a skew matrix: `(m[2][1], m[0][2], m[1][0])` (exact inverse of [`skew`]; the
/// other three entries are not read).
#[inline]
pub fn unskew(m: &Mat3) -> Vec3 {
    [m[2][1], m[0][2], m[1][0]]
}

/// Which singular value [`polar_svd`] negates when `U·Vᵀ` is a reflection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReflectionFix {
    /// The smallest singular value, the first index among equal ones (the ACAP reference
    /// implementation's rule).
    Smallest,
    /// Always index 2 of the descending singular values (a smallest one; the last index among
    /// equal ones). Differs from [`ReflectionFix::Smallest`] only on ties.
    Last,
}

/// Polar decomposition T = R·S by the SVD T = U Σ Vᵀ (nalgebra, singular values sorted
/// descending): R = U Vᵀ, S = V Σ Vᵀ. When det(U Vᵀ) < 0 the column of U of the singular value
/// chosen by `fix` and that singular value are negated first, so R is always a proper rotation
/// (det +1) and S is symmetric with one negative eigenvalue. S is symmetric up to rounding only
/// (see [`polar_decomposition`] for the exactly symmetric one). Returns `(R, S)`; if the SVD
/// fails, `(I, T)`.
pub fn polar_svd(t: &Mat3, fix: ReflectionFix) -> (Mat3, Mat3) {
    let m = Matrix3::new(t[0][0], t[0][1], t[0][2], t[1][0], t[1][1], t[1][2], t[2][0], t[2][1], t[2][2]);
    // `svd` sorts the singular values in descending order, so index 2 is the smallest.
    let svd = m.svd(true, true);
    let (Some(mut u), Some(v_t)) = (svd.u, svd.v_t) else {
        return (IDENTITY, *t);
    };
    let mut sv = svd.singular_values;
    if (u * v_t).determinant() < 0.0 {
        let min = match fix {
            ReflectionFix::Last => 2,
            ReflectionFix::Smallest => {
                let mut min = 0;
                if sv[1] < sv[min] {
                    min = 1;
                }
                if sv[2] < sv[min] {
                    min = 2;
                }
                min
            }
        };
        u.column_mut(min).neg_mut();
        sv[min] = -sv[min];
    }
    let r = u * v_t;
    let s = v_t.transpose() * Matrix3::from_diagonal(&sv) * v_t;
    let to = |a: &Matrix3<f64>| -> Mat3 { std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)])) };
    (to(&r), to(&s))
}

/// Polar decomposition T = R·S of the ACAP reference implementation: [`polar_svd`] with
/// [`ReflectionFix::Smallest`], then S made exactly symmetric (`s_ij = s_ji = (s_ij + s_ji)/2`).
/// Returns `(R, S)`.
pub fn polar_decomposition(t: &Mat3) -> (Mat3, Mat3) {
    let (r, mut s) = polar_svd(t, ReflectionFix::Smallest);
    for i in 0..3 {
        for j in i + 1..3 {
            let a = 0.5 * (s[i][j] + s[j][i]);
            s[i][j] = a;
            s[j][i] = a;
        }
    }
    (r, s)
}

/// Rodrigues' formula: the rotation exp(\[ω\]×) for a rotation vector ω (angle ‖ω‖ radians, any
/// size, about ω/‖ω‖, right-hand rule): `R = I + a·[ω]× + b·[ω]×²` with `a = sin θ/θ`,
/// `b = (1 − cos θ)/θ²`, evaluated by their Taylor series below [`RODRIGUES_SERIES_ANGLE`].
pub fn exp_so3(w: Vec3) -> Mat3 {
    let t2 = dot(w, w);
    let t = t2.sqrt();
    let (a, b) = if t < RODRIGUES_SERIES_ANGLE {
        (1.0 - t2 / 6.0, 0.5 - t2 / 24.0)
    } else {
        (t.sin() / t, (1.0 - t.cos()) / t2)
    };
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

/// Axis–angle of a rotation matrix: `(axis, θ)` with θ ∈ [0, π] and a unit axis, such that
/// `R = exp(θ [axis]×)`; the axis is `[0, 0, 0]` when θ = 0 exactly. Accurate near 0 (axis from
/// the skew part, θ by `atan2`) and near π (axis from the symmetric part, its sign from the skew
/// part; at θ = π exactly both signs describe R and the sign is arbitrary). Used by ACAP.
pub fn axis_angle(r: &Mat3) -> (Vec3, f64) {
    // w = vee(R − Rᵀ) = 2 sin θ · axis;  c = (tr R − 1)/2 = cos θ.
    let w = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    let wn = norm(w);
    let c = ((r[0][0] + r[1][1] + r[2][2] - 1.0) * 0.5).clamp(-1.0, 1.0);
    let theta = (0.5 * wn).atan2(c);
    if c > -0.5 {
        if wn == 0.0 {
            return ([0.0; 3], 0.0);
        }
        return ([w[0] / wn, w[1] / wn, w[2] / wn], theta);
    }
    // θ > 2π/3: (R + Rᵀ)/2 − cos θ·I = (1 − cos θ)·a aᵀ; take its largest column.
    let mut b = ZERO;
    for i in 0..3 {
        for j in 0..3 {
            b[i][j] = 0.5 * (r[i][j] + r[j][i]) - if i == j { c } else { 0.0 };
        }
    }
    let k = (0..3).fold(0, |k, i| if b[i][i] > b[k][k] { i } else { k });
    let col = [b[0][k], b[1][k], b[2][k]];
    let n = norm(col);
    if n == 0.0 || !n.is_finite() {
        return ([0.0; 3], theta);
    }
    let mut a = [col[0] / n, col[1] / n, col[2] / n];
    if dot(a, w) < 0.0 {
        a = [-a[0], -a[1], -a[2]];
    }
    (a, theta)
}

/// The rotation vector `u` of a rotation `r` (`r = exp([u]×)`), angle θ = ‖u‖ ∈ [0, π], through
/// the unit quaternion (Shepperd's method), so it is accurate near 0 and near π; at exactly
/// θ = π the sign of the axis is the one the quaternion extraction yields. Used by the triangle
/// deformation gradients. (Same rotation vector as `θ·axis` of [`axis_angle`], up to rounding.)
pub fn log_so3(r: &Mat3) -> Vec3 {
    let tr = r[0][0] + r[1][1] + r[2][2];
    // Quaternion (w, x, y, z) from the largest of 4 candidate pivots.
    let (w, x, y, z);
    if tr >= r[0][0] && tr >= r[1][1] && tr >= r[2][2] {
        let s = (1.0 + tr).max(0.0).sqrt() * 2.0; // 4w
        w = 0.25 * s;
        x = (r[2][1] - r[1][2]) / s;
        y = (r[0][2] - r[2][0]) / s;
        z = (r[1][0] - r[0][1]) / s;
    } else if r[0][0] >= r[1][1] && r[0][0] >= r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).max(0.0).sqrt() * 2.0; // 4x
        w = (r[2][1] - r[1][2]) / s;
        x = 0.25 * s;
        y = (r[0][1] + r[1][0]) / s;
        z = (r[0][2] + r[2][0]) / s;
    } else if r[1][1] >= r[2][2] {
        let s = (1.0 - r[0][0] + r[1][1] - r[2][2]).max(0.0).sqrt() * 2.0; // 4y
        w = (r[0][2] - r[2][0]) / s;
        x = (r[0][1] + r[1][0]) / s;
        y = 0.25 * s;
        z = (r[1][2] + r[2][1]) / s;
    } else {
        let s = (1.0 - r[0][0] - r[1][1] + r[2][2]).max(0.0).sqrt() * 2.0; // 4z
        w = (r[1][0] - r[0][1]) / s;
        x = (r[0][2] + r[2][0]) / s;
        y = (r[1][2] + r[2][1]) / s;
        z = 0.25 * s;
    }
    let (w, v) = if w < 0.0 { (-w, [-x, -y, -z]) } else { (w, [x, y, z]) };
    let sv = norm(v);
    // θ = 2·atan2(‖v‖, w); u = θ·v/‖v‖, with the limit 2/w for tiny ‖v‖.
    let f = if sv < 1e-12 { 2.0 / w } else { 2.0 * sv.atan2(w) / sv };
    scale(v, f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::vec3::sub;

    fn close(a: &Mat3, b: &Mat3, tol: f64) -> bool {
        (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
    }

    fn max_abs_diff(a: &Mat3, b: &Mat3) -> f64 {
        (0..3).flat_map(|i| (0..3).map(move |j| (a[i][j] - b[i][j]).abs())).fold(0.0, f64::max)
    }

    /// The former ACAP `exp_so3` (series below 1e-6, `I + (a·K + b·K²)`).
    fn old_acap_exp(w: Vec3) -> Mat3 {
        let t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
        let t = t2.sqrt();
        let (a, b) = if t < 1e-6 { (1.0 - t2 / 6.0, 0.5 - t2 / 24.0) } else { (t.sin() / t, (1.0 - t.cos()) / t2) };
        let (k, k2) = (skew(w), mat_mul(&skew(w), &skew(w)));
        std::array::from_fn(|i| std::array::from_fn(|j| IDENTITY[i][j] + (a * k[i][j] + b * k2[i][j])))
    }

    /// The former triangle-gradient `rotation_exp` (series below 1e-8, `(δ + a·K) + b·K²`).
    fn old_gradient_exp(u: Vec3) -> Mat3 {
        let t2 = dot(u, u);
        let t = t2.sqrt();
        let (a, b) = if t < 1e-8 { (1.0 - t2 / 6.0, 0.5 - t2 / 24.0) } else { (t.sin() / t, (1.0 - t.cos()) / t2) };
        let k = [[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]];
        let k2 = mat_mul(&k, &k);
        let mut r = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                r[i][j] = if i == j { 1.0 } else { 0.0 } + a * k[i][j] + b * k2[i][j];
            }
        }
        r
    }

    #[test]
    fn rodrigues_matches_both_former_thresholds_from_zero_to_pi() {
        let axes: [Vec3; 4] = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.3, -0.5, 0.8], [-0.7, 0.1, 0.2]];
        let mut angles = vec![0.0];
        for e in -12..=-4 {
            for m in [1.0, 2.5, 5.0, 9.9] {
                angles.push(m * 10f64.powi(e));
            }
        }
        angles.extend([1e-6 * (1.0 - 1e-12), 1e-6, 1e-8 * (1.0 - 1e-12), 1e-8]);
        angles.extend((0..=100).map(|i| std::f64::consts::PI * i as f64 / 100.0));
        let mut worst: f64 = 0.0;
        for axis in axes {
            let axis = scale(axis, 1.0 / norm(axis));
            for &theta in &angles {
                let w = scale(axis, theta);
                let r = exp_so3(w);
                // The ACAP formula is kept bit for bit.
                assert_eq!(r, old_acap_exp(w), "theta {theta}");
                // The triangle-gradient one (other threshold, other summation order) agrees to
                // within a couple of rounding units of the entries (which are at most 1).
                let d = max_abs_diff(&r, &old_gradient_exp(w));
                worst = worst.max(d);
                assert!(d <= 2.0 * f64::EPSILON, "theta {theta}: {d:e}");
                // And R is a rotation by θ.
                assert!(close(&mat_mul(&transpose(&r), &r), &IDENTITY, 4.0 * f64::EPSILON));
                assert!((det(&r) - 1.0).abs() <= 4.0 * f64::EPSILON);
            }
        }
        assert!(worst <= 2.0 * f64::EPSILON, "{worst:e}");
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
            // Without ties both reflection rules agree.
            let (r2, s2) = polar_svd(t, ReflectionFix::Last);
            assert!(close(&r, &r2, 1e-15) && close(&s, &s2, 1e-15));
        }
        // Reflection: S has exactly one negative eigenvalue, so det S < 0.
        let (_, s) = polar_decomposition(&ts[1]);
        assert!(det(&s) < 0.0);
        // Ties: a pure reflection has three equal singular values; both rules give proper
        // rotations that reproduce T.
        let t = [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        for fix in [ReflectionFix::Smallest, ReflectionFix::Last] {
            let (r, s) = polar_svd(&t, fix);
            assert!(close(&mat_mul(&r, &s), &t, 1e-12));
            assert!((det(&r) - 1.0).abs() < 1e-12);
        }
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
    fn exp_log_round_trip_including_near_pi() {
        for (axis, angle) in [
            ([1.0, 2.0, 3.0], 0.7),
            ([0.0, 0.0, 1.0], 1e-10),
            ([-1.0, 0.5, 0.2], 3.0),
            ([0.3, -0.4, 0.9], std::f64::consts::PI - 1e-9),
            ([0.0, 1.0, 0.0], 2.5),
        ] {
            let u = scale(axis, angle / norm(axis));
            let r = exp_so3(u);
            let back = log_so3(&r);
            let err = norm(sub(back, u));
            assert!(err < 1e-7 * angle.max(1e-3), "axis {axis:?} angle {angle}: got {back:?}");
            // Orthonormal with det +1.
            let rtr = mat_mul(&transpose(&r), &r);
            for (i, row) in rtr.iter().enumerate() {
                for (j, x) in row.iter().enumerate() {
                    assert!((x - if i == j { 1.0 } else { 0.0 }).abs() < 1e-14);
                }
            }
            assert!((nalgebra::Matrix3::from_fn(|a, b| r[a][b]).determinant() - 1.0).abs() < 1e-14);
            // The two logarithms agree.
            let (a, t) = axis_angle(&r);
            assert!(norm(sub(scale(a, t), back)) < 1e-12);
        }
        // Angle above π maps back into [0, π] with the opposite axis.
        let u = [0.0, 0.0, 4.0];
        let back = log_so3(&exp_so3(u));
        assert!(norm(sub(back, [0.0, 0.0, 4.0 - 2.0 * std::f64::consts::PI])) < 1e-12, "{back:?}");
    }

    #[test]
    fn skew_inverse_and_inverse_matrix() {
        let w = [0.1, -0.2, 0.3];
        assert_eq!(unskew(&skew(w)), w);
        assert_eq!(mat_vec(&skew(w), [1.0, 2.0, 3.0]), crate::math::vec3::cross(w, [1.0, 2.0, 3.0]));
        let m = [[2.0, 0.5, 0.0], [0.1, 1.0, 0.3], [0.0, 0.2, 3.0]];
        let inv = inverse(&m).unwrap();
        assert!(close(&mat_mul(&m, &inv), &IDENTITY, 1e-14));
        assert!(inverse(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
        let mut o = ZERO;
        add_outer(&mut o, [1.0, 2.0, 3.0], [0.0, 1.0, -1.0], 2.0);
        assert_eq!(o, [[0.0, 2.0, -2.0], [0.0, 4.0, -4.0], [0.0, 6.0, -6.0]]);
    }
}
