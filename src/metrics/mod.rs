//! Evaluation metrics (plain `f64`, no Burn; docs/design.md § Metrics and protocol):
//!
//! * [`erms`]: Erms, raw or centroid-aligned, the alignment kept with the number;
//! * [`sted`]: STED (Váša & Skala 2011), spatial and temporal parts, spatial only for unordered
//!   collections;
//! * [`edge_distortion`]: edge-length distortion of one shape against a rest mesh (used to compare
//!   the extreme poses of displacement and deformation-gradient SPLOCS components).

pub mod edge_distortion;
pub mod erms;
pub mod sted;

pub use edge_distortion::{EdgeDistortion, EdgeDistortionMeter, edge_length_distortion};
pub use erms::{Alignment, Erms, erms, frame_squared_error};
pub use sted::{FrameOrder, Sted, StedParams, StedReport, sted};
pub mod locality;
pub mod recovery;
