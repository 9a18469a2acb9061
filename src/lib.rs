//! # meshdeco
//!
//! Sparse, localized deformation components from collections of meshes that share one
//! connectivity: SPLOCS on vertex displacements and on triangle deformation gradients,
//! region-based PCA with posing, holistic PCA, and a mesh-convolutional autoencoder on ACAP
//! features (Burn).
//!
//! Geometry (mesh, operators, representations, linear methods, metrics) is plain `f64` with
//! faer and does not depend on Burn; Burn lives only in [`nn`].

pub mod artifact;
pub mod config;
pub mod error;
pub mod geometry;
pub mod math;
pub mod mesh;
pub mod methods;
pub mod model;
pub mod nn;
pub mod pipeline;
pub mod preprocess;
pub mod representation;
pub mod rng;
pub mod synthetic;
pub mod timing;
pub mod view;

pub use error::{Error, Result};
pub mod eval;
pub mod export;
pub mod metrics;
