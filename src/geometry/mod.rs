//! Geometry operators on triangle meshes, in `f64` with faer; one operator per file.

pub mod cotan_laplacian;
pub mod decimate;
pub mod farthest_point_sampling;
pub mod graph_distance;
pub mod heat_geodesics;
pub mod intrinsic_delaunay;
pub mod mass_matrix;
pub mod pin_spread;
pub mod rigid_align;
pub mod sparse_cholesky;
pub mod touching_pieces;
