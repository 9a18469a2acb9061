//! The one place that names every method's artefact: fitting a typed method config on prepared
//! data ([`fit`]) and loading a trained model from its artefact directory ([`load_model`]). A new
//! method adds one arm to each (and its config variant in `src/config/method.rs`).

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use super::Progress;
use super::autoencoder::{self, AeArtifact};
use super::linear::{self, LinearArtifact};
use super::region::{self, RegionArtifact};
use crate::artifact;
use crate::config::{MethodConfig, MethodKind};
use crate::error::{Error, Result};
use crate::mesh::FrameSource;
use crate::methods::support_map::ComponentLocality;
use crate::model::Model;
use crate::preprocess::Prepared;

/// What a fit may use besides the data: the artefact directory (the autoencoder writes its
/// checkpoints and training log there while it trains), resuming, a stop flag and progress.
pub struct FitContext<'a> {
    /// The artefact directory.
    pub out: &'a Path,
    /// With `--resume`: the checkpoint to continue from (autoencoder; an interrupted run's, or
    /// the finished run's in the artefact directory — read in place, never copied).
    pub resume: Option<&'a Path>,
    /// Set (e.g. by Ctrl-C) to stop early after writing a checkpoint (autoencoder).
    pub stop: Option<Arc<AtomicBool>>,
    pub progress: &'a mut dyn Progress,
}

/// What a fit reports besides the model.
#[derive(Debug, Clone, Default)]
pub struct FitStats {
    /// Wall time of the fit, seconds (see `Metrics::train_seconds`).
    pub train_seconds: f64,
    /// Wall time of the representation of the training frames, seconds.
    pub representation_seconds: f64,
    pub iterations: usize,
    pub objective: Option<f64>,
    pub converged: Option<bool>,
    /// Per-component locality (empty when not measured).
    pub locality: Vec<ComponentLocality>,
    /// Measure the test split also with refined encodings ([`Model::refine`]).
    pub refine_test: bool,
    /// Autoencoder: the training features' root-mean-square norm per shape and the factor it
    /// put on every step size (`learning_rate_norm`).
    pub feature_norm: Option<(f64, f64)>,
    /// A warning about the fit that the artefact keeps (`metrics.json`'s `training_warning`):
    /// the autoencoder's run that did not train.
    pub warning: Option<String>,
    /// Autoencoder: the share of what the best K linear components gain over decoding every
    /// training shape as the rest shape that its decoding makes (`metrics.json`'s
    /// `training_gain`; 1: as good as the linear components).
    pub training_gain: Option<f64>,
    /// Autoencoder with `dial_sparsity = "auto"`: the readouts of the dials it tried
    /// (`metrics.json`'s `dial_readouts`; empty otherwise).
    pub dial_readouts: Vec<super::metrics_file::DialReadout>,
}

/// A fitted model with its statistics and the resolved method config (every default written
/// out, data-dependent values such as region PCA's `r` filled in).
pub struct Fitted {
    pub model: Box<dyn Model>,
    pub stats: FitStats,
    pub method: MethodConfig,
}

/// Fits the configured method on prepared data.
pub fn fit(prep: &Prepared, method: &MethodConfig, ctx: &mut FitContext<'_>) -> Result<Fitted> {
    if ctx.resume.is_some() && !method.can_resume() {
        return Err(Error::Invalid(format!(
            "--resume applies to methods that train in steps (the autoencoder); {} trains in one go",
            method.kind().name()
        )));
    }
    if !prep.validation.is_empty() {
        crate::config::check_validation_keys(Some(format!("{} frames", prep.validation.len())), method)?;
    }
    check_training_data(prep, method)?;
    let fitted = match method {
        MethodConfig::Pca(m) => linear::fit_pca(m, prep, ctx),
        MethodConfig::Splocs(m) => linear::fit_splocs(m, prep, ctx),
        MethodConfig::RegionPca(m) => region::fit(m, prep, ctx),
        MethodConfig::Autoencoder(m) => autoencoder::fit(m, prep, ctx),
    }?;
    warn_zero_components(fitted.model.as_ref());
    Ok(fitted)
}

/// Relative size below which a training set "does not deform" and a component "is zero".
const ZERO_RELATIVE: f64 = 1e-9;

/// The rules every method shares (README, "How many components"), checked before fitting:
/// - the training frames must deform: some vertex of some training frame lies farther than
///   1e-9 × the rest shape's bounding-box diagonal from its mean over the training frames
///   (identical frames give zero-variance components in PCA and nothing to fit elsewhere);
/// - K is bounded by what the method can give content: PCA min(frames, 3N) (checked by PCA),
///   region PCA Σ over regions of min(frames, 3N_r) (checked after segmentation), SPLOCS the
///   number of elements it localizes on, the autoencoder the number of vertices (each
///   component has its own centre). Sparse methods may use more components than training
///   frames (the papers: K = 50 on 36 SCAPE shapes); that is said as a warning.
fn check_training_data(prep: &Prepared, method: &MethodConfig) -> Result<()> {
    let f = prep.train.len();
    let n = prep.rest.n_vertices();
    let (lo, hi) = prep.rest.bounding_box();
    let diag = crate::mesh::dist(lo, hi);
    let mut mean = vec![[0.0f64; 3]; n];
    for &t in &prep.train {
        for (m, p) in mean.iter_mut().zip(prep.sequence.frame(t)?.iter()) {
            for c in 0..3 {
                m[c] += p[c] / f.max(1) as f64;
            }
        }
    }
    let mut dev = 0.0f64;
    for &t in &prep.train {
        for (m, p) in mean.iter().zip(prep.sequence.frame(t)?.iter()) {
            dev = dev.max(crate::mesh::dist(*m, *p));
        }
    }
    if f < 2 || dev <= ZERO_RELATIVE * diag.max(f64::MIN_POSITIVE) {
        return Err(Error::config(
            "data.train",
            format!(
                "the {f} training frame(s) do not deform (largest distance of a vertex from its mean over them: {dev:.3e}; bounding-box diagonal {diag:.3e}): there is nothing to learn; select at least two different frames"
            ),
        ));
    }
    let k = method.components();
    let kind = method.kind();
    let cap = match kind {
        MethodKind::Splocs => match method.settings().representation() {
            crate::representation::RepresentationKind::TriangleGradient => prep.rest.faces.len(),
            _ => n,
        },
        MethodKind::Autoencoder => n,
        MethodKind::Pca | MethodKind::RegionPca => usize::MAX,
    };
    if k > cap {
        return Err(Error::config(
            "method.components",
            format!(
                "components ({k}) exceeds the {cap} elements a {} component can be centred on; lower it",
                kind.name()
            ),
        ));
    }
    if matches!(kind, MethodKind::Splocs | MethodKind::Autoencoder) && k > f {
        eprintln!(
            "warning: method.components ({k}) exceeds the {f} training frames: {} components are localized, so more of them than frames can carry content (the papers use K = 50 on 36 shapes), but components the data cannot support come out zero (reported after training)",
            kind.name()
        );
    }
    Ok(())
}

/// After fitting: names the components that came out zero (largest element norm below 1e-9 ×
/// the largest of all components), which the data could not support.
fn warn_zero_components(model: &dyn Model) {
    let (norms, _) = model.element_norms();
    let peaks: Vec<f64> = norms.iter().map(|c| c.iter().cloned().fold(0.0, f64::max)).collect();
    let top = peaks.iter().cloned().fold(0.0, f64::max);
    let zero: Vec<usize> = (0..peaks.len()).filter(|&k| peaks[k] <= ZERO_RELATIVE * top).collect();
    if !zero.is_empty() {
        eprintln!(
            "warning: {} of {} components are zero (indices {:?}): the training data support fewer components with this method; consider a smaller method.components",
            zero.len(),
            peaks.len(),
            zero
        );
    }
}

/// Loads the trained model in `dir` (an artefact directory or its `model.json`), by the
/// `method` field of its header, after verifying every file against `manifest.json`
/// ([`artifact::open_for_reading`]: which also finishes a commit an interrupted training left
/// half done, and says when a training is writing the directory right now).
///
/// A training that commits a new model while the files are read could leave the reader with
/// files of two models: when the directory's manifest changed during the read, or a commit is
/// under way at its end, the read is discarded and done again (up to [`READ_ATTEMPTS`] times,
/// waiting a little longer each time), so a reader gets the old model or the new one, or an
/// error naming the writer, never "changed or damaged" for a file that a commit replaced.
pub fn load_model(dir: &Path) -> Result<Box<dyn Model>> {
    crate::timing::timed("load model", || {
        let adir = artifact::model_dir(dir);
        let mut attempt = 1;
        loop {
            let before = artifact::read_state(&adir);
            let result = load_verified(&adir);
            let after = artifact::read_state(&adir);
            if before == after && !after.1 {
                return result.map_err(|e| artifact::being_written(&adir, e));
            }
            if attempt == READ_ATTEMPTS {
                let changed = Error::Invalid(format!(
                    "{} changed while it was read, {READ_ATTEMPTS} times (a training is committing new models into it); try again when it has finished",
                    adir.display()
                ));
                return Err(artifact::being_written(&adir, result.err().unwrap_or(changed)));
            }
            std::thread::sleep(std::time::Duration::from_millis(50 * attempt as u64));
            attempt += 1;
        }
    })
}

/// Reads of a model directory [`load_model`] tries while commits change it.
pub const READ_ATTEMPTS: usize = 5;

/// Files the autoencoder's loader reads besides [`artifact::MODEL_FILES`].
const AUTOENCODER_FILES: &[&str] = &[crate::nn::inference::META_FILE, crate::nn::inference::MODEL_FILE];

fn load_verified(dir: &Path) -> Result<Box<dyn Model>> {
    // Every file of the artefact is checked against the manifest (length, checksum) before
    // anything is read from it: a damaged or edited file is named, never half-used. The
    // loaders then check structure and values themselves (the manifest may have been
    // re-recorded after an edit).
    let manifest = artifact::open_for_reading(dir)?;
    let json = dir.join("model.json");
    let v: serde_json::Value = artifact::read_json(&json)?;
    let method = v.get("method").and_then(|m| m.as_str()).unwrap_or("");
    let kind = MethodKind::parse(method).ok_or_else(|| {
        Error::Invalid(format!("{}: `method` is `{method}`, not a method meshdeco knows", json.display()))
    })?;
    Ok(match kind {
        MethodKind::Pca | MethodKind::Splocs => Box::new(LinearArtifact::load(dir)?),
        MethodKind::RegionPca => Box::new(RegionArtifact::load(dir)?),
        MethodKind::Autoencoder => {
            manifest.require(dir, AUTOENCODER_FILES)?;
            Box::new(AeArtifact::load(dir)?)
        }
    })
}
