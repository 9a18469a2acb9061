//! The mesh-convolutional autoencoder of Tan et al. (2018) on ACAP features, in Burn.
//!
//! - [`config`]: every hyperparameter in [`AutoencoderConfig`] (validated once).
//! - [`model`]: the Burn [`Module`](burn::module::Module) holding the parameters, its
//!   initialisation and a pure-Burn forward pass (the autodiff reference).
//! - [`loss`]: the loss terms, the support maps Λ and the [`CenterDistances`] trait.
//! - [`engine`] + [`kernels`]: the hand-written forward and backward pass used for training and
//!   inference (f32, SIMD, rayon; checked against Burn autodiff in the tests).
//! - [`data`]: training data and batching; [`neighbors`]: the 1-ring index.
//! - [`training`]: [`Trainer`] (Burn's Adam, checkpoints, resume, stop flag).
//! - [`inference`]: [`Autoencoder`] (encode/decode, component analysis, synthesis,
//!   interpolation, save/load).
//!
//! Burn appears only in this module.

pub mod checkpoint;
pub mod config;
pub mod data;
pub mod engine;
pub mod inference;
pub mod kernels;
pub mod loss;
pub mod model;
pub mod neighbors;
pub mod rng;
pub mod training;

pub use config::AutoencoderConfig;
pub use data::TrainingData;
pub use inference::{Autoencoder, ComponentAnalysis, ComponentExtreme};
pub use loss::{CenterDistances, EuclideanDistances, HopDistances, LossTerms};
pub use model::AutoencoderModule;
pub use neighbors::NeighborIndex;
pub use training::{IterationReport, RunOptions, RunSummary, StepTimings, Trainer};
