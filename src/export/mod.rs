//! Exports of trained models into other tools' formats: glTF 2.0 morph targets ([`gltf`]).

pub mod gltf;

pub use gltf::{ExportOptions, ExportReport, TargetFit, UpAxis, export_glb, read_glb};
