//! The mesh-convolutional autoencoder of Tan et al. (2018) on ACAP features, in Burn.
//!
//! - [`config`]: every hyperparameter in [`AutoencoderConfig`] (validated once).
//! - [`model`]: the Burn [`Module`](burn::module::Module) holding the parameters, its
//!   initialisation and a pure-Burn forward pass (the autodiff reference).
//! - [`loss`]: the loss terms, the support maps Λ and the [`CenterDistances`] trait.
//! - [`engine`] + [`kernels`]: the hand-written forward and backward pass used for training and
//!   inference (f32, SIMD, rayon; checked against Burn autodiff in the tests).
//! - [`output_loss`]: [`OutputLoss`], a caller's loss on the decoded features (the vertex
//!   term).
//! - [`data`]: training data and batching; [`neighbors`]: the 1-ring index.
//! - [`training`]: [`Trainer`] (Adam, checkpoints, resume, stop flag); [`adam`]: Adam for `C`.
//! - [`inference`]: [`Autoencoder`] (encode/decode, component analysis, synthesis,
//!   interpolation, save/load).
//!
//! Burn appears only in this module.
//!
//! # Use
//! ```rust,ignore
//! use meshdeco::nn::{AutoencoderConfig, NeighborIndex, RunOptions, Trainer, TrainingData};
//! let nb = NeighborIndex::from_faces(rest.n_vertices(), &rest.faces)?;  // 1-rings of the rest mesh
//! let data = TrainingData::from_features(&scaled_acap)?;                 // F × N × 9, in [−0.95, 0.95]
//! let dist = /* impl CenterDistances: normalised geodesic distance rows */;
//! let mut trainer = Trainer::new(config, &data, &nb, &dist)?;            // or Trainer::resume(path, …)
//! let opts = RunOptions { checkpoint: Some(dir.join("checkpoint.mdae")), stop: Some(stop_flag), ..Default::default() };
//! let summary = trainer.run(&opts, |r| { /* progress bar, JSONL line: serde_json::to_string(r) */ })?;
//! let model = trainer.into_model()?;
//! model.save(&dir)?;                                          // autoencoder.bpk + autoencoder.json
//! let model = Autoencoder::load(&dir, nb)?;                   // nb rebuilt from the stored rest mesh
//! let z = model.encode(&features)?;                           // codes, F × K
//! let x = model.decode(&z)?;                                  // features, F × N × 9 (scaled)
//! let analysis = model.analyze_components(&scaled_acap, 0)?;  // ranked extremes per dimension
//! let synth = model.synthesize(&analysis, &[(3, 1.0), (7, 0.5)])?;
//! let frames = model.interpolate(&z[a], &z[b], 10)?;
//! ```
//!
//! # Speed
//! One training step is a hand-written forward and backward pass (kernels in VCB layout, latent
//! products as faer GEMMs or equivalent hand kernels on the rayon pool), then Adam. The trainer
//! holds `C` (`K × 9N`, by far the largest parameter) as one plain buffer, the only copy while it
//! trains: its gradient is never stored whole but computed tile by tile, each tile followed at
//! once by the sparsity gradient, Adam ([`adam`], Burn's arithmetic), the squared vertex norms of
//! the new `C` (the next step's support centres) and, for a fixed full batch, the next step's
//! latent product — one pass over `C` and its moments ([`engine::update_components`]). The
//! distance queries of centres that moved run beside the forward and backward pass, and a
//! support row is kept per centre vertex. A Burn module of the parameters is built only for
//! checkpoints of the layers, the graph engine and the trained model. Every result is
//! bit-identical to the straightforward computation (Burn's Adam on the stored gradient).
//! `cargo bench --bench autoencoder` times a step at SCAPE, horse and face-poses size and prints
//! where the time goes; `cargo run --release --example ae_synthetic -- --profile OBJ SHAPES
//! STEPS` does the same for any mesh.

pub mod adam;
pub mod augment;
pub mod checkpoint;
pub mod config;
pub mod data;
pub mod engine;
pub mod inference;
pub mod kernels;
pub mod latent_fit;
pub mod loss;
pub mod model;
pub mod neighbors;
pub mod output_loss;
pub use crate::rng;
pub mod training;

pub use config::AutoencoderConfig;
pub use data::TrainingData;
pub use inference::{Autoencoder, ComponentAnalysis, ComponentExtreme, ComponentSummary};
pub use loss::{CenterDistances, EuclideanDistances, HopDistances, LossTerms};
pub use model::AutoencoderModule;
pub use neighbors::NeighborIndex;
pub use output_loss::OutputLoss;
pub use training::{IterationReport, RunOptions, RunSummary, STALL_WINDOW, StepTimings, Trainer, stall_check_step};
