//! The pipeline behind `meshdeco train`, `encode` and `synthesize`: load and preprocess data,
//! compute the representation, fit the method, measure, and write the artefact directory
//! (see [`crate::artifact`]).

pub mod ae_fit;
pub mod ae_pose;
pub mod ae_vertex_loss;
pub mod ae_vertex_steps;
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

/// The representation's features of the prepared training frames in `f32`
/// ([`crate::methods::CompactMatrix`]), for a data set whose `f64` features would be too large
/// to hold (`prep.limits.compact_bytes`): read from the cache file a frame at a time (built
/// first when `data.cache` caches them), else computed [`FEATURE_RUN`] frames at a time; each
/// row is passed through `transform` (in `f64`) before it is rounded. `on_frames(done)` reports
/// the frames computed for a new cache file.
pub fn training_features_f32(
    representation: &crate::representation::Representation,
    prep: &crate::preprocess::Prepared,
    transform: &dyn Fn(&mut [f64]),
    on_frames: &mut dyn FnMut(usize),
) -> crate::error::Result<crate::methods::CompactMatrix> {
    use crate::representation::feature_cache::{CacheUse, Opened, open_or_build};
    let (e, w) = (representation.n_elements(), representation.width());
    let d = e * w;
    let mut data = vec![0f32; prep.train.len() * d];
    let round = |row: &mut [f64], out: &mut [f32]| {
        transform(row);
        out.iter_mut().zip(row.iter()).for_each(|(o, &v)| *o = v as f32);
    };
    match open_or_build(representation, &prep.sequence, &prep.train, &prep.cache, on_frames)? {
        Opened::File { file, built } => {
            let path = file.path().to_path_buf();
            note_cache_use(
                &if built { CacheUse::Written(path) } else { CacheUse::Read(path) },
                " (read a frame at a time)",
            );
            let (mut row, mut bytes) = (Vec::new(), Vec::new());
            for (i, out) in data.chunks_exact_mut(d).enumerate() {
                file.frame_into(i, &mut row, &mut bytes)?;
                round(&mut row, out);
            }
        }
        other => {
            if let Opened::Unavailable(why) = other {
                note_cache_use(&CacheUse::Unavailable(why), "");
            }
            for (run, out) in prep.train.chunks(FEATURE_RUN).zip(data.chunks_mut(FEATURE_RUN * d)) {
                let mut x = representation.encode_selected(&prep.sequence, run)?;
                for (row, o) in x.data.chunks_exact_mut(d).zip(out.chunks_exact_mut(d)) {
                    round(row, o);
                }
            }
        }
    }
    crate::methods::CompactMatrix::new(data, prep.train.len(), e, w)
}

/// Frames whose features are computed at a time when they are not cached
/// ([`training_features_f32`]).
const FEATURE_RUN: usize = 256;

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
    /// A line for the person running the command (printed above a bar; `note: ` prefixed).
    fn note(&mut self, text: &str) {
        eprintln!("note: {text}");
    }
}

/// A [`Progress`] that reports nothing (tests, library use).
pub struct Silent;

impl Progress for Silent {
    fn stage(&mut self, _: &str, _: u64) {}
    fn step(&mut self, _: u64, _: &str) {}
    fn note(&mut self, _: &str) {}
}
