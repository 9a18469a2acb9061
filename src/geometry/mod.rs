//! Geometry operators on triangle meshes, in `f64` with faer; one operator per file.

pub mod normals;
