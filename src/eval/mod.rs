//! `meshdeco eval`: trains every (dataset, method, K) cell of an evaluation config through the
//! normal training pipeline, measures it on the test split and writes the comparison tables and
//! plots the papers show (Neumann et al. 2013 Fig. 4/5, Huang et al. 2014 Fig. 13, Tan et al.
//! 2018 Table 1 / Fig. 3 / Fig. 6).
//!
//! Output directory `DIR`:
//! - `cells/<dataset>/<method label>/K<k>/`: the cell's normal artefact directory (as written by
//!   `meshdeco train`), plus `cell.json` (the cell's measured [`CellResult`] and the train
//!   config text it was made from) and, for the largest K of a method with control points,
//!   `control_points.json`;
//! - `results.csv`: one row per cell (columns in [`report::RESULTS_HEADER`]);
//! - `control_points.csv`: Erms versus number of control points (if `[control_points]`);
//! - `erms_<dataset>.png`, `sted_<dataset>.png`, `control_points_<dataset>.png`: the plots;
//! - `report.md`: one table per dataset with the plots embedded.
//!
//! Measurements per cell (test split unless said otherwise):
//! - train and test Erms ([`crate::metrics::erms`]); representations that drop translation
//!   (triangle gradients, ACAP) are centroid-aligned, the `alignment` column says which. Train
//!   Erms uses the stored training weights/codes; test Erms encodes each test shape with the
//!   model's own encoder (linear models: constrained least squares; autoencoder: its encoder);
//! - STED ([`crate::metrics::sted`], default parameters: 1-ring, c = 0.5): the spatial part, and
//!   for datasets marked `ordered = true` the temporal part over the test frames in order (after
//!   the same alignment as Erms, since per-frame translations change the temporal part);
//! - locality: median over components of the in-support energy share (as measured by training,
//!   `metrics.json`; none for region PCA), and of the support size and number of connected
//!   support regions at 1 % of each component's peak ([`crate::metrics::locality`]);
//! - seconds: the fit time reported by training (`train_seconds` of `metrics.json`).
//!
//! Caching: a cell whose `cell.json` holds the same train config text is reused without loading
//! any data; otherwise it is (re)trained. `cell.json` is written last, atomically, so an
//! interrupted cell is never taken as finished. An interrupted autoencoder cell resumes from its
//! checkpoint when its config is unchanged. A trained autoencoder cell whose config changed
//! only in inference keys ([`crate::config::AutoencoderMethod::training_keys`]: the decoder's and
//! the encoder's keys, `fit_test`, `dial_sparsity`) is measured again from its finished
//! checkpoint instead of trained again; its `seconds` stay the training's. `cell.json` records
//! the method's resolved keys, so a default changed since is seen as a changed key. Training is
//! seeded, so a rerun from scratch gives the same numbers (except seconds).

pub mod config;
pub mod control_points;
pub mod drag;
pub mod planted;
pub mod plots;
pub mod report;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use serde::{Deserialize, Serialize};

pub use config::{Cell, ControlPointsConfig, EvalConfig, EvalDataset, EvalMethod};
use control_points::{ControlPointErms, erms_curve};

use crate::artifact;
use crate::error::{Error, Result};
use crate::mesh::{FrameSource, Vec3};
use crate::metrics::erms::Alignment;
use crate::metrics::locality::{SUPPORT_THRESHOLD, support_regions};
use crate::metrics::sted::{FrameOrder, Sted, StedParams};
use crate::pipeline::load_model;
use crate::pipeline::metrics_file::median;
use crate::pipeline::train::{TrainOptions, TrainOutcome, frames_in_data_units, train_prepared};
use crate::pipeline::{Progress, Silent};
use crate::preprocess::{self, Prepared};

/// File name of a cell's measured result.
pub const CELL_FILE: &str = "cell.json";
/// File name of the pending marker (the train config text of a cell being trained).
pub const PENDING_FILE: &str = "eval_cell.toml";
/// File of a cell whose last attempt failed (its error); removed when the cell succeeds.
pub const FAILED_FILE: &str = "cell_failed.json";
/// File name of a cell's cached control-point curve.
pub const CONTROL_POINTS_FILE: &str = "control_points.json";

/// The measured result of one (dataset, method, K) cell; one row of `results.csv`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellResult {
    /// The cell's train config text (cache key).
    pub config_text: String,
    pub dataset: String,
    /// Method label of the eval config.
    pub method: String,
    /// Method kind (`pca`, `splocs`, `region-pca`, `autoencoder`).
    pub kind: String,
    /// Representation the method ran on.
    pub representation: String,
    /// Number of components K requested (region PCA: the total budget).
    #[serde(rename = "K")]
    pub k: usize,
    /// Erms over the training frames (data units × 1000).
    pub train_erms: f64,
    /// Erms over the test frames.
    pub test_erms: f64,
    /// Alignment of both Erms values (`none` or `centroid`).
    pub alignment: String,
    /// STED spatial part over the test frames.
    pub sted_spatial: f64,
    /// STED temporal part over the test frames (ordered datasets only).
    pub sted_temporal: Option<f64>,
    /// Median in-support energy share of the components (training's measure).
    pub in_support_share: Option<f64>,
    /// Median support size (elements above 1 % of the component's peak).
    pub support_size: Option<f64>,
    /// Median number of connected support regions.
    pub support_regions: Option<f64>,
    /// Fit time of training, seconds.
    pub seconds: f64,
    /// Autoencoder only: test Erms with codes fitted to every vertex (`metrics.json`'s
    /// `test_erms_fitted`; `fit_test = false` leaves it out).
    #[serde(default)]
    pub test_erms_fitted: Option<f64>,
    pub train_frames: usize,
    pub test_frames: usize,
    /// (edge, frame) pairs STED left out: zero-length edges of the ground truth.
    #[serde(default)]
    pub sted_skipped_edges: usize,
    /// Autoencoder only: STED spatial part of the test frames decoded from fitted codes (the
    /// counterpart of `test_erms_fitted`; `sted_spatial` is the network encoder's).
    #[serde(default)]
    pub sted_spatial_fitted: Option<f64>,
    /// Autoencoder only: STED temporal part with fitted codes (ordered datasets).
    #[serde(default)]
    pub sted_temporal_fitted: Option<f64>,
    /// Autoencoder with `encoder_passes > 0` only: test Erms of the plain one-pass encoder
    /// (`metrics.json`'s `test_erms_one_pass`; `test_erms` has the residual passes).
    #[serde(default)]
    pub test_erms_one_pass: Option<f64>,
    /// Autoencoder whose encoder takes vertex steps only: test Erms of the network's own codes
    /// (`metrics.json`'s `test_erms_network`; `test_erms` has the steps).
    #[serde(default)]
    pub test_erms_network: Option<f64>,
    /// Erms over the validation frames (`data.validation`), encoded as the test frames are.
    #[serde(default)]
    pub validation_erms: Option<f64>,
    /// Median over the components of the share of vertices each moves by more than 5 % of its
    /// peak, read in vertex space around the rest shape ([`crate::model::component_fields`]).
    #[serde(default)]
    pub vertex_support: Option<f64>,
    /// Recovery of the true deformations of a planted dataset (`truth = "DIR"`).
    #[serde(default)]
    pub recovery: Option<CellRecovery>,
    /// The method's every key as it was resolved when the cell was made, defaults included
    /// ([`resolved_keys`]): a key left out of the config text whose default changed since no
    /// longer matches. Absent in cells made before it was recorded (those are matched by their
    /// text alone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub method_keys: Option<String>,
    /// The same for the keys that change training ([`crate::config::MethodConfig::training_keys`]):
    /// what decides whether a changed cell is measured again or trained again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training_keys: Option<String>,
    /// Version of the autoencoder's encoding the numbers were measured with
    /// ([`ENCODER_VERSION`]); a cached autoencoder cell of an older one is trained and measured again.
    #[serde(default)]
    pub encoder_version: u32,
}

/// Version of the autoencoder's training defaults and encoding in [`CellResult`]: 2 with its
/// vertex steps (`encoder_steps`), 3 since they start from the better of the network's codes with
/// and without the residual passes, 4 since the keys a cell leaves out mean
/// [`crate::nn::config::AutoencoderConfig::recommended`] (before: the paper's settings), 5 since
/// the default scaling range is the 0.1 % … 99.9 % quantiles widened by their width each side (`scaling_quantile`, `scaling_fence`) and the vertex
/// steps (up to 5 by default) stop when a step's last chord step gains < 0.5 %, and a training run
/// that stalls restarts with halved step sizes (`stall_restarts`), 6 since a set of more than 64
/// training shapes trains on mini-batches of 32 by default (issue 57); cells cached with
/// another version are trained and measured again.
pub const ENCODER_VERSION: u32 = 6;

/// How a cell's components recover the true deformations of a planted dataset
/// ([`crate::metrics::recovery`]; per deformation in the cell's `recovery.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellRecovery {
    /// Identifiable true deformations (the ones counted), and all.
    pub counted: usize,
    pub total: usize,
    /// Identifiable ones with a component of |cos| ≥ 0.9, and of all.
    pub found: usize,
    pub found_all: usize,
    /// Medians over the identifiable ones of the best |cos| and of its support IoU.
    pub median_abs_cos: f64,
    pub median_iou: f64,
    /// Share of the identifiable ones whose best component's dial moves the right way (cos > 0).
    pub positive: f64,
    /// The planted set the numbers belong to ([`truth_key`]).
    pub truth_key: String,
}

/// One true deformation's best match (a row of a cell's `recovery.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeformationMatch {
    pub name: String,
    pub kind: String,
    pub identifiable: bool,
    #[serde(flatten)]
    pub best: crate::metrics::recovery::Match,
}

/// File of a cell's per-deformation recovery.
pub const RECOVERY_FILE: &str = "recovery.json";

/// The key of a planted set's data and truth: the checksums of its frames and fields as its
/// manifest records them (a set planted again gives another key; its cells are measured again).
pub fn truth_key(dir: &Path) -> Result<String> {
    let m: artifact::Manifest = artifact::read_json(&dir.join(artifact::MANIFEST_FILE))?;
    let crc = |n: &str| {
        m.files.get(n).map(|e| e.crc32.clone()).ok_or_else(|| {
            Error::Invalid(format!("{}: does not list `{n}`", dir.join(artifact::MANIFEST_FILE).display()))
        })
    };
    Ok(format!("frames {} fields {}", crc("frames.npy")?, crc(planted::FIELDS_FILE)?))
}

/// Scores a model's components against a planted set's true deformations.
pub fn recovery_of(
    model: &dyn crate::model::Model,
    truth: &planted::Truth,
) -> Result<(CellRecovery, Vec<DeformationMatch>)> {
    use crate::metrics::recovery::{best_matches, summarize};
    let fields = crate::model::component_fields(model)?;
    let matches = best_matches(&truth.fields, &fields)?;
    let counted = truth.counted();
    let s = summarize(&matches, &counted);
    let all = summarize(&matches, &[]);
    let positive =
        matches.iter().zip(&counted).filter(|(m, c)| **c && m.cos > 0.0).count() as f64 / s.counted.max(1) as f64;
    let rows = matches
        .into_iter()
        .zip(&truth.file.deformations)
        .map(|(best, d)| DeformationMatch {
            name: d.name.clone(),
            kind: format!("{:?}", d.kind).to_lowercase(),
            identifiable: d.identifiable,
            best,
        })
        .collect();
    Ok((
        CellRecovery {
            counted: s.counted,
            total: all.counted,
            found: s.found,
            found_all: all.found,
            median_abs_cos: s.median_abs_cos,
            median_iou: s.median_iou,
            positive,
            truth_key: truth_key(&truth.dir)?,
        },
        rows,
    ))
}

/// A cell whose training or measuring failed: recorded, shown in the tables and the report,
/// retried by the next run; the cells after it still run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FailedCell {
    pub dataset: String,
    pub method: String,
    #[serde(rename = "K")]
    pub k: usize,
    /// The error, with its whole chain.
    pub error: String,
}

/// Cached control-point curve of a cell.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct ControlPointsCache {
    key: String,
    rows: Vec<ControlPointErms>,
}

/// One row of `control_points.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlPointRow {
    pub dataset: String,
    pub method: String,
    pub k: usize,
    pub erms: ControlPointErms,
}

/// Options of [`run`].
#[derive(Debug, Clone, Default)]
pub struct EvalOptions {
    /// Only re-read finished cells and redraw; error if a cell is missing.
    pub replot: bool,
    /// Set (e.g. by Ctrl-C) to stop after the current cell (the autoencoder stops at once,
    /// keeping its checkpoint).
    pub stop: Option<Arc<AtomicBool>>,
}

/// What [`run`] did.
#[derive(Debug, Clone)]
pub struct EvalOutcome {
    pub results: Vec<CellResult>,
    /// Cells that failed (the run went on with the others).
    pub failed: Vec<FailedCell>,
    pub control_points: Vec<ControlPointRow>,
    /// Cells trained in this run.
    pub trained: usize,
    /// Cells reused from an earlier run.
    pub reused: usize,
    /// Trained autoencoder cells measured again (only inference keys changed; not trained).
    pub remeasured: usize,
    /// Files written (results, report, plots).
    pub files: Vec<PathBuf>,
}

/// Artefact directory of a cell.
pub fn cell_dir(out: &Path, dataset: &str, method: &str, k: usize) -> PathBuf {
    out.join("cells").join(dataset).join(method).join(format!("K{k}"))
}

/// The preprocessed data of one dataset (loaded once per evaluation), its test frames in data
/// units and the STED operator of its mesh.
struct DatasetData {
    prep: Prepared,
    test: Vec<Vec<Vec3>>,
    sted: Sted,
    /// The true deformations of a planted dataset.
    truth: Option<planted::Truth>,
}

impl DatasetData {
    /// The data set in `slot`, loaded on first use.
    fn cached<'s>(slot: &'s mut Option<DatasetData>, d: &EvalDataset) -> Result<&'s DatasetData> {
        if slot.is_none() {
            *slot = Some(DatasetData::load(d)?);
        }
        Ok(slot.as_ref().expect("loaded above"))
    }

    fn load(d: &EvalDataset) -> Result<Self> {
        let prep = preprocess::prepare(&d.data)?;
        let test = frames_in_data_units(&prep, &prep.test)?;
        let names = prep.test.iter().map(|&f| prep.sequence.name(f).to_string()).collect();
        let sted = Sted::new(prep.rest.n_vertices(), &prep.rest.faces, StedParams::default())?.with_frame_names(names);
        let truth = d.truth.as_deref().map(planted::Truth::load).transpose()?;
        if let Some(t) = &truth
            && t.file.n_vertices != prep.rest.n_vertices()
        {
            return Err(Error::Invalid(format!(
                "dataset {}: truth {} has {} vertices, the data {}",
                d.name,
                t.dir.display(),
                t.file.n_vertices,
                prep.rest.n_vertices()
            )));
        }
        Ok(DatasetData { prep, test, sted, truth })
    }
}

/// Translates `result` so that its vertex centroid equals that of `truth`.
pub(crate) fn centroid_align(result: &mut [Vec3], truth: &[Vec3]) {
    let n = truth.len().max(1) as f64;
    let shift: Vec3 =
        std::array::from_fn(|k| truth.iter().zip(result.iter()).map(|(t, r)| t[k] - r[k]).sum::<f64>() / n);
    for p in result.iter_mut() {
        for k in 0..3 {
            p[k] += shift[k];
        }
    }
}

fn check_finite(what: &str, cell: &str, x: f64) -> Result<f64> {
    if x.is_finite() { Ok(x) } else { Err(Error::Numerical(format!("{cell}: {what} is not finite ({x})"))) }
}

/// Measures a trained cell on its dataset: Erms and locality as training measured them (the
/// same numbers as `metrics.json`), STED of the training's test reconstruction, support sizes
/// and regions of the model's components.
fn measure(
    cell: &Cell,
    cfg: &EvalConfig,
    ds: &DatasetData,
    trained: &TrainOutcome,
) -> Result<(CellResult, Option<Vec<DeformationMatch>>)> {
    let d = &cfg.datasets[cell.dataset];
    let m = &cfg.methods[cell.method];
    let name = format!("{}/{}/K{}", d.name, m.label, cell.k);
    let metrics = &trained.metrics;
    let model = trained.model.as_ref();
    let alignment = model.alignment();
    let test_erms =
        metrics.test_erms.ok_or_else(|| Error::Invalid(format!("{name}: training measured no test split")))?;
    let order = if d.ordered { FrameOrder::Sequence } else { FrameOrder::Unordered };
    // STED of a test reconstruction, with the alignment of Erms (its temporal part sees
    // per-frame translations).
    let sted_of = |rec: &[Vec<Vec3>]| {
        let mut rec = rec.to_vec();
        if alignment == Alignment::Centroid {
            for (r, t) in rec.iter_mut().zip(&ds.test) {
                centroid_align(r, t);
            }
        }
        ds.sted.evaluate(&ds.test, &rec, order)
    };
    let sted = sted_of(&trained.test_reconstruction)?;
    // The fitted codes' reconstruction, measured the same way (side by side in the tables).
    let fitted = &trained.test_reconstruction_fitted;
    let sted_fitted = if fitted.is_empty() { None } else { Some(sted_of(fitted)?) };
    let (norms, adjacency) = model.element_norms();
    let mut sizes = Vec::new();
    let mut regions = Vec::new();
    for n in &norms {
        let s = support_regions(n, adjacency, SUPPORT_THRESHOLD)?;
        sizes.push(s.size as f64);
        regions.push(s.regions as f64);
    }
    let (recovery, matches) = match &ds.truth {
        Some(t) => {
            let (r, m) = recovery_of(model, t)?;
            (Some(r), Some(m))
        }
        None => (None, None),
    };
    let result = CellResult {
        config_text: cell.config_text.clone(),
        dataset: d.name.clone(),
        method: m.label.clone(),
        kind: cell.config.kind().name().to_string(),
        representation: model.representation().name().to_string(),
        k: cell.k,
        train_erms: check_finite("train Erms", &name, metrics.train_erms)?,
        test_erms: check_finite("test Erms", &name, test_erms)?,
        alignment: alignment.to_string(),
        sted_spatial: check_finite("STED", &name, sted.spatial)?,
        sted_temporal: sted.temporal.map(|t| check_finite("temporal STED", &name, t)).transpose()?,
        in_support_share: metrics.median_energy_share.filter(|x| x.is_finite()),
        support_size: median(&sizes),
        support_regions: median(&regions),
        seconds: metrics.train_seconds,
        test_erms_fitted: metrics.test_erms_fitted.map(|x| check_finite("fitted test Erms", &name, x)).transpose()?,
        test_erms_one_pass: metrics
            .test_erms_one_pass
            .map(|x| check_finite("one-pass test Erms", &name, x))
            .transpose()?,
        test_erms_network: metrics
            .test_erms_network
            .map(|x| check_finite("network-only test Erms", &name, x))
            .transpose()?,
        validation_erms: metrics.validation_erms.map(|x| check_finite("validation Erms", &name, x)).transpose()?,
        encoder_version: ENCODER_VERSION,
        train_frames: ds.prep.train.len(),
        test_frames: ds.test.len(),
        sted_skipped_edges: sted.skipped_edges,
        sted_spatial_fitted: sted_fitted.map(|s| check_finite("fitted STED", &name, s.spatial)).transpose()?,
        sted_temporal_fitted: sted_fitted
            .and_then(|s| s.temporal)
            .map(|t| check_finite("fitted temporal STED", &name, t))
            .transpose()?,
        vertex_support: metrics.median_vertex_support,
        recovery,
        method_keys: Some(resolved_keys(&cell.config.method)),
        training_keys: Some(resolved_keys(&cell.config.method.training_keys())),
    };
    Ok((result, matches))
}

/// Every key of a method as resolved, defaults included (its `Debug` text: every field, numbers
/// in the shortest text that reads back to the same value), except the keys added since the
/// record began ([`KEYS_ADDED_SINCE`]) while at their default, so that the cells recorded
/// before them still match.
pub fn resolved_keys(method: &crate::config::MethodConfig) -> String {
    let mut text = format!("{method:?}");
    for (key, default) in KEYS_ADDED_SINCE {
        text = text.replacen(&format!(", {key}: {default}"), "", 1);
    }
    text
}

/// Keys added to a method after [`resolved_keys`] began to be recorded, with their default's
/// `Debug` text.
const KEYS_ADDED_SINCE: [(&str, &str); 1] = [("features", "Acap")];

/// The finished result stored in a cell's folder (`cell.json`), if one reads.
fn read_cell(dir: &Path) -> Option<CellResult> {
    let path = dir.join(CELL_FILE);
    if !path.is_file() {
        return None;
    }
    artifact::read_json::<CellResult>(&path).ok()
}

/// Whether stored result `r` is `cell`'s: made from the same config text, with the same resolved
/// keys (where recorded) and, for the autoencoder, today's encoding version.
fn is_cached(r: &CellResult, cell: &Cell) -> bool {
    r.config_text == cell.config_text
        && r.method_keys.as_ref().is_none_or(|k| *k == resolved_keys(&cell.config.method))
        && (r.kind != "autoencoder" || r.encoder_version == ENCODER_VERSION)
}

/// Whether stored result `earlier` is of a trained autoencoder cell that `cell` measures again
/// instead of training it again: made from a config that trains the same network
/// ([`crate::config::Config::trains_as`]: only inference keys differ), with today's encoding
/// version, and its finished checkpoint is there. A run that held out validation shapes keeps
/// its best step's parameters: only a checkpoint that stores them (version 4) will do.
fn remeasurable(dir: &Path, cell: &Cell, earlier: &CellResult) -> bool {
    let crate::config::MethodConfig::Autoencoder(m) = &cell.config.method else {
        return false;
    };
    let checkpoint = dir.join(artifact::CHECKPOINT_FILE);
    if !checkpoint.is_file() || (m.validation > 0 && !crate::nn::checkpoint::stores_best_step(&checkpoint)) {
        return false;
    }
    // The earlier text read with today's defaults; its recorded training keys (where there are
    // any) say whether a default of a training key changed since.
    let Ok(trained_with) = crate::config::Config::from_toml(&earlier.config_text) else {
        return false;
    };
    let training_keys_held =
        earlier.training_keys.as_ref().is_none_or(|k| *k == resolved_keys(&cell.config.method.training_keys()));
    earlier.kind == "autoencoder"
        && earlier.encoder_version == ENCODER_VERSION
        && training_keys_held
        && trained_with.trains_as(&cell.config)
}

/// Measures a trained autoencoder cell again ([`remeasurable`]): resumes its finished
/// checkpoint with the cell's config (no steps left, so only the measuring runs, with the new
/// inference keys). The earlier `cell.json` stays until the new one replaces it, so an
/// interrupted measurement is measured again on the rerun. `None` when the resume is refused
/// (the cell is then trained afresh).
fn remeasure_cell(
    cell: &Cell,
    prep: &Prepared,
    dir: &Path,
    opts: &EvalOptions,
    inner: &mut dyn Progress,
) -> Result<Option<TrainOutcome>> {
    match train_prepared(&cell.config, prep, dir, &TrainOptions { resume: true, stop: opts.stop.clone() }, inner) {
        Ok(o) => Ok(Some(o)),
        Err(e) if stopped(opts) => Err(e),
        Err(_) => Ok(None),
    }
}

fn stopped(opts: &EvalOptions) -> bool {
    opts.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst))
}

fn interrupted() -> Error {
    Error::Invalid("interrupted: finished cells are kept; rerun the same command to continue".into())
}

/// Trains a cell into `dir` on its prepared data (resuming an interrupted autoencoder with the
/// same config).
fn train_cell(
    cell: &Cell,
    prep: &Prepared,
    dir: &Path,
    opts: &EvalOptions,
    inner: &mut dyn Progress,
) -> Result<TrainOutcome> {
    let pending = dir.join(PENDING_FILE);
    let same_pending = std::fs::read_to_string(&pending).is_ok_and(|t| t == cell.config_text);
    // A stale result must never survive a retrain.
    let stale = dir.join(CELL_FILE);
    if stale.exists() {
        std::fs::remove_file(&stale).map_err(|e| Error::io(&stale, e))?;
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    artifact::write_atomic(&pending, cell.config_text.as_bytes())?;
    let c = &cell.config;
    // Only the autoencoder writes checkpoints.
    let resume = same_pending && artifact::resumable_checkpoint(dir).is_some();
    let fresh = TrainOptions { resume: false, stop: opts.stop.clone() };
    if resume {
        match train_prepared(c, prep, dir, &TrainOptions { resume: true, stop: opts.stop.clone() }, inner) {
            Ok(o) => return Ok(o),
            Err(e) if stopped(opts) => return Err(e),
            Err(_) => {}
        }
    }
    train_prepared(c, prep, dir, &fresh, inner)
}

/// Control-point key of a cell (its config text plus the control-point settings).
fn control_key(cell: &Cell, cp: &ControlPointsConfig) -> String {
    format!(
        "{}\n# control points: counts {:?}, trials {}, autoencoder trials {}, gamma {}, seed {}\n",
        cell.config_text, cp.counts, cp.trials, cp.autoencoder_trials, cp.gamma, cp.seed
    )
}

/// Whether a method can be driven by control points here (displacement-based linear models and
/// the autoencoder).
pub fn control_points_supported(m: &EvalMethod) -> bool {
    m.method.settings().supports_control_points()
}

/// Runs the evaluation into `out` (see the module docs). `sweep` reports one step per cell,
/// `inner` the stages of the cell being trained.
pub fn run(
    cfg: &EvalConfig,
    out: &Path,
    opts: &EvalOptions,
    sweep: &mut dyn Progress,
    inner: &mut dyn Progress,
) -> Result<EvalOutcome> {
    let cells = cfg.cells()?;
    let mut data: Vec<Option<DatasetData>> = cfg.datasets.iter().map(|_| None).collect();
    let mut results = Vec::with_capacity(cells.len());
    let mut failed = Vec::new();
    let (mut trained, mut reused, mut remeasured) = (0, 0, 0);
    sweep.stage("eval", cells.len() as u64);
    for (i, cell) in cells.iter().enumerate() {
        let d = &cfg.datasets[cell.dataset];
        let m = &cfg.methods[cell.method];
        let label = format!("{}/{}/K{}", d.name, m.label, cell.k);
        sweep.step(i as u64, &label);
        let dir = cell_dir(out, &d.name, &m.label, cell.k);
        // The folder's stored result, read once: reused when it is this cell's, else perhaps
        // measured again (below).
        let stored = read_cell(&dir);
        if let Some(mut r) = stored.as_ref().filter(|r| is_cached(r, cell)).cloned() {
            // A planted dataset's truth added or planted again since: score the cached model.
            if let Some(truth_dir) = &d.truth {
                let key = truth_key(truth_dir)?;
                if r.recovery.as_ref().is_none_or(|x| x.truth_key != key) {
                    if opts.replot {
                        return Err(Error::Invalid(format!(
                            "--replot: cell {label} has no recovery scores for {} (run without --replot)",
                            truth_dir.display()
                        )));
                    }
                    let truth = planted::Truth::load(truth_dir)?;
                    let (rec, rows) = recovery_of(load_model(&dir)?.as_ref(), &truth)?;
                    r.recovery = Some(rec);
                    artifact::write_json(&dir.join(RECOVERY_FILE), &rows)?;
                    artifact::write_json(&dir.join(CELL_FILE), &r)?;
                    r = artifact::read_json(&dir.join(CELL_FILE))?;
                }
            }
            results.push(r);
            reused += 1;
            continue;
        }
        if opts.replot {
            return Err(Error::Invalid(format!(
                "--replot: cell {label} has no result in {} (run without --replot to train it)",
                dir.display()
            )));
        }
        if stopped(opts) {
            return Err(interrupted());
        }
        // A trained autoencoder cell whose config changed only in inference keys is measured
        // again from its checkpoint; its `seconds` stay the training's.
        let earlier = stored.filter(|r| remeasurable(&dir, cell, r));
        let mut again = false;
        let attempt = DatasetData::cached(&mut data[cell.dataset], d).and_then(|ds| {
            let remeasured = match &earlier {
                Some(_) => remeasure_cell(cell, &ds.prep, &dir, opts, inner)?,
                None => None,
            };
            again = remeasured.is_some();
            let outcome = match remeasured {
                Some(o) => o,
                None => train_cell(cell, &ds.prep, &dir, opts, inner)?,
            };
            measure(cell, cfg, ds, &outcome)
        });
        let r = match attempt {
            Ok((mut r, rows)) => {
                if again && let Some(e) = &earlier {
                    r.seconds = e.seconds;
                }
                match rows {
                    Some(rows) => artifact::write_json(&dir.join(RECOVERY_FILE), &rows)?,
                    None => {
                        let _ = std::fs::remove_file(dir.join(RECOVERY_FILE));
                    }
                }
                r
            }
            Err(_) if stopped(opts) => return Err(interrupted()),
            Err(e) => {
                // Record the failure in the cell and go on with the next cell.
                let f =
                    FailedCell { dataset: d.name.clone(), method: m.label.clone(), k: cell.k, error: e.to_string() };
                std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
                artifact::write_json(&dir.join(FAILED_FILE), &f)?;
                sweep.step(i as u64 + 1, &format!("{label} failed: {e}"));
                failed.push(f);
                continue;
            }
        };
        let _ = std::fs::remove_file(dir.join(FAILED_FILE));
        artifact::write_json(&dir.join(CELL_FILE), &r)?;
        // Use the values as stored (JSON text round trip), so a first run and a rerun that
        // reuses the cell write identical tables.
        let r: CellResult = artifact::read_json(&dir.join(CELL_FILE))?;
        let pending = dir.join(PENDING_FILE);
        let _ = std::fs::remove_file(&pending);
        results.push(r);
        if again {
            remeasured += 1;
        } else {
            trained += 1;
        }
    }
    sweep.step(cells.len() as u64, "done");
    sweep.finish_stage();

    let mut cp_rows = Vec::new();
    if let Some(cp) = &cfg.control_points {
        let jobs: Vec<&Cell> = cells
            .iter()
            .filter(|c| control_points_supported(&cfg.methods[c.method]))
            .filter(|c| cp.methods.as_ref().is_none_or(|l| l.contains(&cfg.methods[c.method].label)))
            .filter(|c| cfg.ks(c.method).last() == Some(&c.k))
            .collect();
        sweep.stage("control points", jobs.len() as u64);
        for (i, cell) in jobs.into_iter().enumerate() {
            let d = &cfg.datasets[cell.dataset];
            let m = &cfg.methods[cell.method];
            sweep.step(i as u64, &format!("{}/{}/K{}", d.name, m.label, cell.k));
            let dir = cell_dir(out, &d.name, &m.label, cell.k);
            let path = dir.join(CONTROL_POINTS_FILE);
            let key = control_key(cell, cp);
            let cached = artifact::read_json::<ControlPointsCache>(&path).ok().filter(|c| c.key == key);
            let rows = match cached {
                Some(c) => c.rows,
                None => {
                    if opts.replot {
                        return Err(Error::Invalid(format!(
                            "--replot: no control-point result in {} (run without --replot)",
                            dir.display()
                        )));
                    }
                    if stopped(opts) {
                        return Err(interrupted());
                    }
                    let ds = DatasetData::cached(&mut data[cell.dataset], d)?;
                    let model = load_model(&dir)?;
                    let trials = if cell.config.method.settings().iterative_point_fit() {
                        cp.autoencoder_trials
                    } else {
                        cp.trials
                    };
                    let rows = erms_curve(model.as_ref(), &ds.test, &cp.counts, trials, cp.gamma, cp.seed)?;
                    if let Some(r) = rows.iter().find(|r| !r.erms_mean.is_finite()) {
                        return Err(Error::Numerical(format!(
                            "{}/{}: control-point Erms for n = {} is not finite",
                            d.name, m.label, r.n
                        )));
                    }
                    artifact::write_json(&path, &ControlPointsCache { key, rows })?;
                    artifact::read_json::<ControlPointsCache>(&path)?.rows
                }
            };
            for r in rows {
                cp_rows.push(ControlPointRow { dataset: d.name.clone(), method: m.label.clone(), k: cell.k, erms: r });
            }
        }
        sweep.finish_stage();
    }

    let files = report::write_all(cfg, out, &results, &failed, &cp_rows)?;
    Ok(EvalOutcome { results, failed, control_points: cp_rows, trained, reused, remeasured, files })
}

/// [`run`] without progress reporting.
pub fn run_silent(cfg: &EvalConfig, out: &Path, opts: &EvalOptions) -> Result<EvalOutcome> {
    run(cfg, out, opts, &mut Silent, &mut Silent)
}

#[cfg(test)]
mod tests {
    use super::resolved_keys;
    use crate::config::{AeFeatures, AutoencoderMethod, MethodConfig};

    /// A key added after the record began is left out at its default (the cells recorded before
    /// it still match) and recorded when set.
    #[test]
    fn keys_added_since_are_recorded_only_when_set() {
        let plain = MethodConfig::Autoencoder(AutoencoderMethod::default());
        let text = resolved_keys(&plain);
        assert!(!text.contains("features"), "{text}");
        assert!(text.contains("consistency: Global, engine"), "the neighbours close up: {text}");
        let set = MethodConfig::Autoencoder(AutoencoderMethod { features: AeFeatures::Gradient, ..Default::default() });
        assert!(resolved_keys(&set).contains("features: Gradient"));
        assert_ne!(resolved_keys(&set), text);
    }
}
