//! Exports of trained models into other tools' formats: glTF 2.0 morph targets ([`gltf`]) and
//! USD blend shapes ([`usd`]), both from the same prepared blendshapes ([`gltf::prepare`]), and
//! the SPLOCS reference implementation's HDF5 layout of a linear model ([`hdf5`]). (The
//! standalone viewer page, which embeds the same blendshapes, is the viewer's:
//! `view::standalone`.)

pub mod gltf;
pub mod hdf5;
pub mod usd;

pub use gltf::{ExportOptions, ExportReport, TargetFit, UpAxis, export_glb, read_glb};
pub use usd::export_usda;
