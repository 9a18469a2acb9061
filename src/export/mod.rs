//! Exports of trained models into other tools' formats: glTF 2.0 morph targets ([`gltf`]) and
//! USD blend shapes ([`usd`]), both from the same prepared blendshapes ([`gltf::prepare`]).

pub mod gltf;
pub mod usd;

pub use gltf::{ExportOptions, ExportReport, TargetFit, UpAxis, export_glb, read_glb};
pub use usd::export_usda;
