//! Helpers on 3-vectors `Vec3 = [f64; 3]` (`[x, y, z]`, in whatever units the caller uses:
//! positions and differences are in data units, products in units², …).
//!
//! All functions are pure, take vectors by value (`Vec3` is `Copy`) and evaluate their sums in
//! index order `0, 1, 2` (so `dot(a, b) = (a₀b₀ + a₁b₁) + a₂b₂` exactly, with no fused
//! multiply–add): results are reproducible bit for bit.

/// A 3-vector `[x, y, z]`; also the type of vertex positions ([`crate::mesh::Vec3`] is this
/// type).
pub type Vec3 = [f64; 3];

/// The zero vector.
pub const ZERO: Vec3 = [0.0; 3];

/// a + b.
#[inline]
pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// a − b (the vector from `b` to `a`).
#[inline]
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// s·a.
#[inline]
pub fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// −a.
#[inline]
pub fn neg(a: Vec3) -> Vec3 {
    [-a[0], -a[1], -a[2]]
}

/// a · b.
#[inline]
pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a × b (right-handed: `cross([1,0,0], [0,1,0]) = [0,0,1]`).
#[inline]
pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// ‖a‖² = a · a.
#[inline]
pub fn norm2(a: Vec3) -> f64 {
    dot(a, a)
}

/// ‖a‖ (Euclidean length).
#[inline]
pub fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

/// a / ‖a‖, or the zero vector when ‖a‖ is zero or not finite.
#[inline]
pub fn normalize(a: Vec3) -> Vec3 {
    let l = norm(a);
    if l > 0.0 && l.is_finite() { [a[0] / l, a[1] / l, a[2] / l] } else { ZERO }
}

/// Squared Euclidean distance ‖a − b‖².
#[inline]
pub fn dist2(a: Vec3, b: Vec3) -> f64 {
    norm2(sub(a, b))
}

/// Euclidean distance ‖a − b‖.
#[inline]
pub fn dist(a: Vec3, b: Vec3) -> f64 {
    norm(sub(a, b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_and_norms() {
        let (a, b) = ([1.0, 2.0, 3.0], [-2.0, 0.5, 4.0]);
        assert_eq!(add(a, b), [-1.0, 2.5, 7.0]);
        assert_eq!(sub(a, b), [3.0, 1.5, -1.0]);
        assert_eq!(scale(a, 2.0), [2.0, 4.0, 6.0]);
        assert_eq!(neg(a), [-1.0, -2.0, -3.0]);
        assert_eq!(dot(a, b), 11.0);
        assert_eq!(cross([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]), [0.0, 0.0, 1.0]);
        let c = cross(a, b);
        assert_eq!((dot(c, a), dot(c, b)), (0.0, 0.0));
        assert_eq!(norm([3.0, 4.0, 12.0]), 13.0);
        assert_eq!(norm2([3.0, 4.0, 12.0]), 169.0);
        assert_eq!(dist([1.0, 1.0, 1.0], [4.0, 5.0, 13.0]), 13.0);
        assert_eq!(dist2([1.0, 1.0, 1.0], [4.0, 5.0, 13.0]), 169.0);
        assert_eq!(normalize([0.0, 0.0, 2.0]), [0.0, 0.0, 1.0]);
        assert_eq!(normalize(ZERO), ZERO);
        assert_eq!(normalize([f64::INFINITY, 0.0, 0.0]), ZERO);
    }
}
