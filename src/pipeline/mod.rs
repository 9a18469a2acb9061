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

/// The representation's features of the prepared training frames, through the feature cache
/// (`data.cache`, [`crate::representation::feature_cache`]); says on stderr when it read or wrote
/// a cache file, or could not use its folder.
pub fn training_features(
    representation: &crate::representation::Representation,
    prep: &crate::preprocess::Prepared,
) -> crate::error::Result<crate::representation::Features> {
    use crate::representation::feature_cache::encode_cached;
    let (features, used) = encode_cached(representation, &prep.sequence, &prep.train, &prep.cache)?;
    note_cache_use(&used, "");
    Ok(features)
}

/// Says on stderr what the feature cache did (nothing when it was not used); `suffix` follows
/// the file's name.
fn note_cache_use(used: &crate::representation::feature_cache::CacheUse, suffix: &str) {
    use crate::representation::feature_cache::CacheUse;
    match used {
        CacheUse::Computed => {}
        CacheUse::Read(p) => eprintln!("note: features read from the cache {}{suffix}", p.display()),
        CacheUse::Written(p) => eprintln!("note: features cached in {}{suffix}", p.display()),
        CacheUse::Unavailable(why) => eprintln!("note: features not cached: {why}"),
    }
}

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
