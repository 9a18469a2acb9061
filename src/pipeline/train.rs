//! The one path from a config to an artefact directory, used by `meshdeco train` and by
//! `meshdeco eval`: prepare the data → fit the method ([`crate::pipeline::fit`]) → measure on
//! vertices in data units (train Erms, test Erms with the model's own encoding and, where the
//! model has one, with refined encodings; locality) → write.
//!
//! Artefact directory (every method): `config.toml` (the resolved config: every default written
//! out; it trains again as is), the model files ([`Model::save`]), `weights.csv` (training
//! weights, where stored), `metrics.json` ([`Metrics`]), `manifest.json` (length and checksum of
//! each file, written last) and, with `[output] views = true`, the method's views
//! ([`Model::write_views`]: `components/`, `segmentation.ply`). Everything is written into a
//! staging directory and committed at the end ([`artifact::Staging`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use super::Progress;
use super::ae_fit::DEFAULT_FIT_GAMMA;
use super::metrics_file::{Metrics, median};
use crate::artifact;
use crate::config::{Config, resolved_toml};
use crate::error::{Error, Result};
use crate::mesh::{FrameSource, MeshSequence, Vec3};
use crate::metrics::erms::{erms, erms_from_squared_error, frame_squared_error};
use crate::model::{Model, RefineOptions, reconstruct};
use crate::pipeline::FitContext;
use crate::preprocess::{self, Prepared};

/// Training frames measured at a time (a multiple of the autoencoder's inference batch, so its
/// codes decode with the same batch-mates as in one pass over all).
const MEASURE_RUN: usize = 256;

/// Options of [`train`] besides the config.
#[derive(Debug, Clone, Default)]
pub struct TrainOptions {
    /// Continue from the checkpoint in the artefact directory (autoencoder).
    pub resume: bool,
    /// Set (e.g. by Ctrl-C) to stop early, keeping a checkpoint (autoencoder).
    pub stop: Option<Arc<AtomicBool>>,
}

/// Result of training: where the artefacts are, the measured metrics, the model and its
/// reconstruction of the test frames (data units; empty without a test split).
pub struct TrainOutcome {
    pub out_dir: PathBuf,
    pub metrics: Metrics,
    pub model: Box<dyn Model>,
    pub test_reconstruction: Vec<Vec<Vec3>>,
    /// The test frames decoded from refined codes ([`Model::refine`], the autoencoder's fitted
    /// codes); empty when the model has none or `fit_test = false`.
    pub test_reconstruction_fitted: Vec<Vec<Vec3>>,
}

/// Loads and prepares `cfg.data`, then [`train_prepared`].
pub fn train(cfg: &Config, out: &Path, options: &TrainOptions, progress: &mut dyn Progress) -> Result<TrainOutcome> {
    progress.stage("loading", 0);
    let prep = crate::timing::timed("load", || preprocess::prepare(&cfg.data))?;
    train_prepared(cfg, &prep, out, options, progress)
}

/// The frames of `idx` in data units.
pub fn frames_in_data_units(prep: &Prepared, idx: &[usize]) -> Result<Vec<Vec<Vec3>>> {
    idx.iter().map(|&f| Ok(prep.sequence.frame(f)?.iter().map(|p| prep.unit_box.invert(*p)).collect())).collect()
}

/// Fits `cfg.method` on prepared data, measures, and writes the artefact directory `out`.
pub fn train_prepared(
    cfg: &Config,
    prep: &Prepared,
    out: &Path,
    options: &TrainOptions,
    progress: &mut dyn Progress,
) -> Result<TrainOutcome> {
    // One writer per artefact directory (a second run into the same directory is refused at
    // once); everything is written into a staging directory beside `out` and moved into `out`
    // only when complete, so a failed run leaves `out` as it was (see `artifact::Staging`).
    let staging = artifact::Staging::begin(out, options.resume)?;
    let scope = crate::timing::scope();
    let mut outcome = fit_measure_write(cfg, prep, staging.dir(), staging.resume_from(), options, progress)?;
    drop(scope);
    crate::timing::timed("write", || staging.commit())?;
    outcome.out_dir = out.to_path_buf();
    Ok(outcome)
}

fn fit_measure_write(
    cfg: &Config,
    prep: &Prepared,
    out: &Path,
    resume: Option<&Path>,
    options: &TrainOptions,
    progress: &mut dyn Progress,
) -> Result<TrainOutcome> {
    let mut ctx = FitContext { out, resume, stop: options.stop.clone(), progress };
    let t = std::time::Instant::now();
    let fitted = crate::pipeline::fit(prep, &cfg.method, &mut ctx)?;
    let progress = ctx.progress;
    let model = fitted.model;
    let stats = fitted.stats;
    crate::timing::record("features", stats.representation_seconds);
    crate::timing::record("fit", (t.elapsed().as_secs_f64() - stats.representation_seconds).max(0.0));
    let t = std::time::Instant::now();

    progress.stage("measuring", 0);
    let alignment = model.alignment();
    let faces = prep.sequence.faces().to_vec();
    // The training Erms, measured MEASURE_RUN frames at a time (one run's frames and
    // reconstructions in memory, not the data's); the sum runs in frame order, as `erms` does.
    let train_weights = model.train_weights();
    let (mut squared, mut coords) = (0.0, 0usize);
    for (run, idx) in prep.train.chunks(MEASURE_RUN).enumerate() {
        let truth = frames_in_data_units(prep, idx)?;
        let rec = match &train_weights {
            Some(w) => {
                let first = run * MEASURE_RUN;
                let w = w.get(first..first + idx.len()).ok_or_else(|| {
                    Error::Invalid(format!(
                        "the model holds {} training weights, expected {}",
                        w.len(),
                        prep.train.len()
                    ))
                })?;
                model.decode(w)?
            }
            None => reconstruct(
                model.as_ref(),
                &MeshSequence { faces: faces.clone(), frames: truth.clone(), names: Vec::new() },
            )?,
        };
        if rec.len() != truth.len() {
            return Err(Error::Invalid(format!("{} reconstructions of {} training frames", rec.len(), truth.len())));
        }
        for (t, r) in truth.iter().zip(&rec) {
            squared += frame_squared_error(t, r, alignment)?;
            coords += 3 * t.len();
        }
    }
    let train_erms = erms_from_squared_error(squared, coords);
    let (mut test_erms, mut test_erms_fitted, mut test_reconstruction) = (None, None, Vec::new());
    let mut test_reconstruction_fitted = Vec::new();
    let mut test_erms_one_pass = None;
    let mut test_erms_network = None;
    if !prep.test.is_empty() {
        let test = MeshSequence { faces, frames: frames_in_data_units(prep, &prep.test)?, names: Vec::new() };
        let codes = model.encode(&test)?;
        test_reconstruction = model.decode(&codes)?;
        test_erms = Some(erms(&test.frames, &test_reconstruction, alignment)?);
        if let Some(plain) = model.encode_one_pass(&test)? {
            test_erms_one_pass = Some(erms(&test.frames, &model.decode(&plain)?, alignment)?);
        }
        if let Some(network) = model.encode_network(&test)? {
            test_erms_network = Some(erms(&test.frames, &model.decode(&network)?, alignment)?);
        }
        if stats.refine_test {
            progress.stage("fitting test codes", test.n_frames() as u64);
            let opts = RefineOptions { points: usize::MAX, gamma: DEFAULT_FIT_GAMMA };
            let refined = model.refine(&test, &codes, &opts, &mut |i| progress.step(i as u64 + 1, ""))?;
            if let Some((_, rec)) = refined {
                test_erms_fitted = Some(erms(&test.frames, &rec, alignment)?);
                test_reconstruction_fitted = rec;
            }
        }
    }
    // Validation frames: held out of the fit, encoded as the test frames are.
    let validation_erms = if prep.validation.is_empty() {
        None
    } else {
        let v = MeshSequence {
            faces: prep.sequence.faces().to_vec(),
            frames: frames_in_data_units(prep, &prep.validation)?,
            names: Vec::new(),
        };
        let codes = model.encode(&v)?;
        Some(erms(&v.frames, &model.decode(&codes)?, alignment)?)
    };
    // Vertex-space locality: each component's field around the rest shape.
    let vertex_support: Vec<usize> = crate::model::component_fields(model.as_ref())?
        .iter()
        .map(|f| crate::metrics::recovery::support_size(f))
        .collect();
    let n_vertices = prep.rest.n_vertices().max(1) as f64;
    let vertex_shares: Vec<f64> = vertex_support.iter().map(|&s| s as f64 / n_vertices).collect();
    let shares: Vec<f64> = stats.locality.iter().map(|l| l.energy_share).collect();
    let sizes: Vec<f64> = stats.locality.iter().map(|l| l.support_size as f64).collect();
    let metrics = Metrics {
        method: model.kind().name().to_string(),
        representation: model.representation().name().to_string(),
        components: model.n_components(),
        train_erms,
        test_erms,
        test_erms_fitted,
        test_erms_one_pass,
        test_erms_network,
        validation_erms,
        validation_frames: prep.validation.len(),
        erms_alignment: alignment.to_string(),
        train_seconds: stats.train_seconds,
        representation_seconds: stats.representation_seconds,
        iterations: stats.iterations,
        objective: stats.objective,
        converged: stats.converged,
        train_frames: prep.train.len(),
        test_frames: prep.test.len(),
        median_energy_share: median(&shares),
        median_support_size: median(&sizes),
        locality: stats.locality,
        vertex_support,
        median_vertex_support: median(&vertex_shares),
        feature_norm: stats.feature_norm.map(|(n, _)| n),
        learning_rate_scale: stats.feature_norm.map(|(_, s)| s),
        training_warning: stats.warning.clone(),
        training_gain: stats.training_gain,
        dial_readouts: stats.dial_readouts.clone(),
    };

    crate::timing::record("measure", t.elapsed().as_secs_f64());

    progress.stage("writing", 0);
    let t = std::time::Instant::now();
    let method_table = fitted.method.to_table()?;
    // Files of the staging directory are synced once, when it is committed.
    artifact::deferred_sync(|| -> Result<()> {
        let text = resolved_toml(&cfg.name, &cfg.data, method_table, &cfg.output);
        artifact::write_atomic(&out.join("config.toml"), text.as_bytes())?;
        model.save(out)?;
        if let Some(w) = model.train_weights() {
            let flat: Vec<f64> = w.iter().flatten().copied().collect();
            artifact::write_weights_csv(&out.join("weights.csv"), model.train_frames(), &flat, model.n_components())?;
        }
        artifact::write_json(&out.join("metrics.json"), &metrics)?;
        if cfg.output.views {
            model.write_views(out)?;
        }
        Ok(())
    })?;
    crate::timing::record("write", t.elapsed().as_secs_f64());
    progress.finish_stage();
    Ok(TrainOutcome { out_dir: out.to_path_buf(), metrics, model, test_reconstruction, test_reconstruction_fitted })
}
