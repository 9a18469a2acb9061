//! The pipeline behind `meshdeco train`, `encode` and `synthesize`: load and preprocess data,
//! compute the representation, fit the method, measure, and write the artefact directory
//! (see [`crate::artifact`]).

pub mod ae_fit;
pub mod ae_pose;
pub mod ae_vertex_loss;
pub mod autoencoder;
pub mod geodesic_support;
pub mod linear;
pub mod metrics_file;
pub mod pose;
pub mod region;
pub mod registry;
pub mod train;

pub use registry::{FitContext, FitStats, Fitted, fit, load_model};
pub use train::{TrainOptions, TrainOutcome, train, train_prepared};

/// Progress reporting hooks of long jobs (the CLI draws them with indicatif).
pub trait Progress {
    /// A new stage begins (`total` steps, 0 if unknown).
    fn stage(&mut self, name: &str, total: u64);
    /// Step `i` of the current stage finished; `message` summarises it (e.g. the objective).
    fn step(&mut self, i: u64, message: &str);
    /// The current stage finished.
    fn finish_stage(&mut self) {}
}

/// A [`Progress`] that reports nothing (tests, library use).
pub struct Silent;

impl Progress for Silent {
    fn stage(&mut self, _: &str, _: u64) {}
    fn step(&mut self, _: u64, _: &str) {}
}
