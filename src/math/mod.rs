//! Basic math written once, at the bottom of the crate: 3-vectors, 3×3 matrices and rotations,
//! disjoint sets. Everything here is plain `f64` / `usize` and depends on nothing else in the
//! crate (only on nalgebra, for the 3×3 SVD); every other module may use it.
//!
//! * [`vec3`]: `Vec3 = [f64; 3]` helpers (sum, difference, scaling, dot and cross products,
//!   norms, distances).
//! * [`mat3`]: `Mat3 = [[f64; 3]; 3]` helpers (row-major, `m[row][col]`), polar decomposition,
//!   exp/log of so(3).
//! * [`disjoint_set`]: union–find over `0..n`.

pub mod disjoint_set;
pub mod mat3;
pub mod vec3;

pub use disjoint_set::DisjointSet;
pub use mat3::Mat3;
pub use vec3::Vec3;
