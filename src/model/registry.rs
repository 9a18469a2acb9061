//! The one place that names every method kind: fitting a typed method config on prepared data
//! ([`fit`]) and loading a trained model from its artefact directory ([`load_model`]). A new
//! method adds one arm to each.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use super::Model;
use crate::artifact;
use crate::config::{MethodConfig, MethodKind};
use crate::error::{Error, Result};
use crate::methods::support_map::ComponentLocality;
use crate::pipeline::Progress;
use crate::pipeline::autoencoder::AeArtifact;
use crate::pipeline::linear::LinearArtifact;
use crate::pipeline::region::RegionArtifact;
use crate::pipeline::{autoencoder, linear, region};
use crate::preprocess::Prepared;

/// What a fit may use besides the data: the artefact directory (the autoencoder writes its
/// checkpoints and training log there while it trains), resuming, a stop flag and progress.
pub struct FitContext<'a> {
    /// The artefact directory.
    pub out: &'a Path,
    /// Continue from `out`'s checkpoint (autoencoder).
    pub resume: bool,
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
    if ctx.resume && method.kind() != MethodKind::Autoencoder {
        return Err(Error::Invalid(format!(
            "--resume applies to the autoencoder only; {} trains in one go",
            method.kind().name()
        )));
    }
    match method {
        MethodConfig::Pca(m) => linear::fit_pca(m, prep, ctx),
        MethodConfig::Splocs(m) => linear::fit_splocs(m, prep, ctx),
        MethodConfig::RegionPca(m) => region::fit(m, prep, ctx),
        MethodConfig::Autoencoder(m) => autoencoder::fit(m, prep, ctx),
    }
}

/// Loads the trained model in `dir` (an artefact directory or its `model.json`), by the
/// `method` field of its header.
pub fn load_model(dir: &Path) -> Result<Box<dyn Model>> {
    let json = artifact::model_dir(dir).join("model.json");
    let v: serde_json::Value = artifact::read_json(&json)?;
    let method = v.get("method").and_then(|m| m.as_str()).unwrap_or("");
    let kind = MethodKind::parse(method).ok_or_else(|| {
        Error::Invalid(format!("{}: `method` is `{method}`, not a method meshdeco knows", json.display()))
    })?;
    Ok(match kind {
        MethodKind::Pca | MethodKind::Splocs => Box::new(LinearArtifact::load(dir)?),
        MethodKind::RegionPca => Box::new(RegionArtifact::load(dir)?),
        MethodKind::Autoencoder => Box::new(AeArtifact::load(dir)?),
    })
}
