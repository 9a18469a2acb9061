//! The 3×3 matrix and rotation helpers of ACAP now live in [`crate::math::mat3`]; this module
//! re-exports them under their former paths for existing callers. New code should use
//! `crate::math::mat3` directly.

pub use crate::math::mat3::{
    IDENTITY, Mat3, ZERO, axis_angle, det, exp_so3, inverse, mat_mul, mat_vec, polar_decomposition, skew, transpose,
    unskew,
};
