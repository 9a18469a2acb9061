//! Training loop: hand-written loss and gradients ([`super::engine`]), Adam for the update,
//! checkpoints, resume and a stop flag.
//!
//! The trainer owns the latent map `C` as one plain `[K, 9N]` buffer (the only copy while it
//! trains; the engine reads it in place) and updates it with [`ComponentAdam`], a fused in-place
//! pass with Burn's Adam arithmetic. The small convolution layers stay Burn parameters: their
//! hand-computed gradients are handed to Burn's Adam ([`burn::optim::AdamConfig`]) through
//! [`GradientsParams::register`] keyed by each parameter's [`burn::module::ParamId`]. A Burn
//! module holding every parameter is built only when asked for ([`Trainer::module`],
//! [`Trainer::into_model`]). A run is deterministic for a given seed (fixed-order reductions),
//! and a run resumed from a checkpoint reproduces the uninterrupted run.

use std::cell::OnceCell;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device, Tensor, TensorData};
use serde::Serialize;

use super::adam::ComponentAdam;
use super::augment::Augmenter;
use super::checkpoint::{self, Checkpoint, CheckpointHeader, CheckpointParts};
use super::config::{
    AutoencoderConfig, ComputeDevice, DEFAULT_MINI_BATCH, EncoderKind, Engine, FULL_BATCH_UP_TO, InitBias,
};
use super::data::TrainingData;
use super::engine::{self, Grads, Weights, Workspace, layer_weights, tensor_to_vec};
use super::inference::Autoencoder;
use super::kernels::padded_width;
use super::loss::reference_loss;
use super::loss::{CenterDistances, LossTerms, SupportMaps};
use super::model::{AutoencoderModule, COMPONENT_BLOCK, MeshConv, NeighborTensors};
use super::neighbors::NeighborIndex;
use super::output_loss::OutputLoss;
use super::rng::Rng;
use crate::error::{Error, Result};

/// The CPU device the parameters live on: Burn's ndarray backend (the project's default) with
/// autodiff enabled, which Burn's optimizer requires of the parameters it updates. The
/// gradients themselves are computed by hand and registered on the inner (plain) device.
#[allow(deprecated)]
pub fn default_device() -> Device {
    Device::ndarray().autodiff()
}

/// The autodiff device a run's parameters live on: the CPU device, or with
/// [`ComputeDevice::Wgpu`] (a build with the `wgpu` feature) Burn's wgpu backend on the default
/// adapter.
pub fn training_device(device: ComputeDevice) -> Result<Device> {
    match device {
        ComputeDevice::Cpu => Ok(default_device()),
        #[cfg(feature = "wgpu")]
        ComputeDevice::Wgpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice).autodiff()),
        #[cfg(not(feature = "wgpu"))]
        ComputeDevice::Wgpu => Err(Error::config(
            "method.device",
            "device = \"wgpu\" needs a build with the wgpu feature (cargo build --release --features wgpu)",
        )),
    }
}

/// What a run reports after every step (for a progress bar and a JSONL log).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct IterationReport {
    /// Completed steps (1-based: 1 after the first step).
    pub iteration: usize,
    /// Total steps of the run.
    pub iterations: usize,
    /// Loss terms of this step (evaluated before the update).
    pub loss: LossTerms,
    /// Wall time of this step in seconds.
    pub step_seconds: f64,
    /// Whether a checkpoint was written after this step.
    pub checkpointed: bool,
    /// The encode–decode feature error on the validation shapes, on the steps that measured it
    /// (every `validate_every` and the last; `None` without validation shapes).
    pub validation_error: Option<f64>,
}

/// Wall time of the phases of the last step, seconds.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct StepTimings {
    /// Checking the parameters (the layers; `C` only when its last update did not).
    pub snapshot: f64,
    /// Centres and support maps Λ. On the default (fused) path the distance queries of the
    /// centres that moved run beside the forward and backward pass and count there.
    pub support: f64,
    /// Hand-written forward and backward pass (all but `∂L/∂C` on the fused path).
    pub forward_backward: f64,
    /// The update: Burn's Adam on the layers, Adam on `C` (on the fused path with `∂L/∂C`
    /// computed tile by tile, and the next step's encoder pass).
    pub optimizer: f64,
}

/// Where to checkpoint and when to stop.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Checkpoint file (written atomically every `checkpoint_every` steps, at the end and on stop).
    pub checkpoint: Option<PathBuf>,
    /// Checked every step; when set, the run writes a checkpoint and returns.
    pub stop: Option<Arc<AtomicBool>>,
    /// Step at which to check for a stalled run ([`AutoencoderConfig::stall_restarts`]): when
    /// the mean reconstruction error of the last [`STALL_WINDOW`] steps is at or above the first
    /// step's, the run returns at once with [`RunSummary::stalled`] set (no checkpoint of that
    /// step is written). Runs resumed past the first step are not checked. `None`: never.
    pub stall_check: Option<usize>,
}

/// Shapes per encode–decode run of [`Trainer::training_rest_and_linear_error`].
const TRAINING_ERROR_RUN: usize = 64;

/// Training shapes whose best K-dimensional linear fit is the reference of
/// [`Trainer::training_rest_and_linear_error`] (at most; evenly spread over the set).
pub const LINEAR_CHECK_SHAPES: usize = 128;

/// Steps whose mean reconstruction error the stall check compares with the first step's.
pub const STALL_WINDOW: usize = 10;

/// Earliest step of a stall check: the first steps' error can rise far above the first step's
/// in runs that train well (40 × in the first 200 steps on face poses).
pub const STALL_EARLIEST: usize = 50;

/// The step at which a run of `iterations` steps is checked for a stall: 10 % of them, at the
/// earliest [`STALL_EARLIEST`]; none for runs that end by then.
pub fn stall_check_step(iterations: usize) -> Option<usize> {
    let at = (iterations / 10).max(STALL_EARLIEST);
    (at < iterations).then_some(at)
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RunSummary {
    /// Completed steps in total (including those before a resume).
    pub iterations_done: usize,
    /// Whether the stop flag ended the run early.
    pub stopped: bool,
    /// Loss of the last step, if any step ran.
    pub last_loss: Option<LossTerms>,
    /// Mean wall time per step of this run, seconds.
    pub mean_step_seconds: f64,
    /// With validation shapes: the step whose parameters are kept and its validation error
    /// (mean squared feature error of encode–decode per shape).
    pub best: Option<(usize, f64)>,
    /// Whether the run ended at [`RunOptions::stall_check`] because it had stalled.
    pub stalled: bool,
}

/// Held-out shapes and the best parameters seen on them (see
/// [`AutoencoderConfig::validation`]).
struct Validation<'a> {
    data: &'a TrainingData,
    /// The shapes in VCB layout.
    x: Vec<f32>,
    workspace: Workspace,
    /// (step, error, parameters) of the lowest validation error so far.
    best: Option<(usize, f64, Weights)>,
}

/// Mean over the `b` real lanes of the squared error between encode–decode of `x` and `x`,
/// each vertex's rows weighted by the workspace's feature weights (if any).
pub fn feature_error(ws: &mut Workspace, w: &Weights, nb: &NeighborIndex, x: &[f32], b: usize) -> f64 {
    engine::encode(ws, w, nb, x, b);
    engine::decode(ws, w, nb, b);
    let bp = ws.width();
    let weights = ws.feature_weights();
    let out = ws.output();
    let mut sse = 0.0f64;
    for (row, (ro, rx)) in out.chunks_exact(bp).zip(x.chunks_exact(bp)).enumerate() {
        let wr = weights.map_or(1.0, |v| f64::from(v[row / 9]));
        for j in 0..b {
            let d = (ro[j] - rx[j]) as f64;
            sse += wr * d * d;
        }
    }
    sse / b as f64
}

/// Trains the autoencoder on one data set.
pub struct Trainer<'a> {
    config: AutoencoderConfig,
    data: &'a TrainingData,
    neighbors: &'a NeighborIndex,
    distances: &'a dyn CenterDistances,
    device: Device,
    /// The convolution layers as Burn parameters (updated by `optimizer`, Burn's Adam).
    layers: Option<Vec<MeshConv>>,
    optimizer: ModuleOptimizer,
    /// Every parameter as plain arrays: `weights.c` is `C` itself (updated in place by `adam`),
    /// `weights.layers` mirrors `layers`.
    weights: Weights,
    /// Adam's state for `C`.
    adam: ComponentAdam,
    /// Whether every entry of `weights.c` is known to be finite (the fused update checks it;
    /// otherwise it is scanned before it is used).
    c_finite: bool,
    /// Whether `maps` holds the squared vertex norms of the current `C` (written by the fused
    /// update).
    norms_current: bool,
    /// Whether the workspace already holds the encoder pass of the next step's batch (done by
    /// the last fused update; see [`engine::update_components`]).
    encoded_ahead: bool,
    /// All parameters as a Burn module, built on demand by [`Self::module`] (reset by a step).
    module_view: OnceCell<AutoencoderModule>,
    /// Never take the fused path (tests compare the two).
    plain_updates: bool,
    iteration: usize,
    rng: Rng,
    maps: SupportMaps,
    workspace: Workspace,
    grads: Grads,
    full_batch: Option<Vec<f32>>,
    /// Neighbour index tensors of the [`Engine::Graph`] step (built on its first step).
    graph_neighbors: Option<NeighborTensors>,
    last_loss: Option<LossTerms>,
    timings: StepTimings,
    /// Synthetic shapes of every step (`augment > 0`).
    augmenter: Option<Augmenter>,
    /// The mini-batch buffer (VCB, padded width of batch + synthetic shapes).
    batch_buf: Vec<f32>,
    /// The encoder's noisy input of a step with `input_noise > 0` (same layout as the batch).
    noisy_buf: Vec<f32>,
    validation: Option<Validation<'a>>,
    /// The best validation step of the checkpoint this run resumed from, until
    /// [`Self::with_validation`] takes it.
    resumed_best: Option<checkpoint::BestStep>,
    /// Seconds trained so far (the steps, their validation and checkpoints; a resumed run starts
    /// from its checkpoint's).
    train_seconds: f64,
    /// The caller's term on the decoded shapes (`lambda_vertex`).
    output_loss: Option<&'a dyn OutputLoss>,
    /// The lanes the vertex term sees this step (all, or `vertex_batch` drawn each step).
    vertex_lanes: Vec<usize>,
    /// The shuffled order of the current epoch (mini-batches): (epoch, order).
    epoch_order: Option<(usize, Vec<usize>)>,
    /// [`feature_norm`] of the training data (sets [`Self::learning_rate_scale`]).
    feature_norm: f64,
    /// The rest shape's scaled features (`9N`, vertex-major), the last lane of every batch when
    /// `lambda_code > 0` ([`Self::with_rest`]).
    rest: Option<Vec<f32>>,
    /// Per-vertex weights of the feature error ([`Self::with_feature_weights`]).
    feature_weights: Option<Arc<[f32]>>,
    /// The caller's name of the input features, recorded in checkpoints ([`Trainer::with_input`]).
    input: Option<String>,
}

/// Lanes a batch has besides its shapes and synthetic shapes: the rest shape's, when the code
/// term needs it.
fn rest_lanes(config: &AutoencoderConfig) -> usize {
    usize::from(config.lambda_code > 0.0)
}

/// The training shapes the trainer's statistics ([`feature_norm`], [`channel_means`]) read:
/// every shape of a set held in memory, at most 256 evenly spaced ones of a streamed set.
pub fn sampled_shapes(data: &TrainingData) -> Vec<usize> {
    let n = data.n_shapes();
    let take = if data.is_streamed() { n.min(256) } else { n };
    (0..take).map(|i| i * n / take).collect()
}

/// Statistics of the scaled training features over [`sampled_shapes`], read in one pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeatureStats {
    /// Root-mean-square over the shapes of each shape's Euclidean norm.
    pub norm: f64,
    /// Mean of every feature channel over the vertices of the shapes.
    pub channel_means: [f64; 9],
}

/// [`FeatureStats`] of the training data (all zero for a set without shapes).
pub fn feature_stats(data: &TrainingData) -> Result<FeatureStats> {
    let shapes = sampled_shapes(data);
    let mut sq = 0.0f64;
    let mut sum = [0.0f64; 9];
    let mut count = 0usize;
    for &s in &shapes {
        let x = data.shape(s)?;
        // Each shape's squared norm summed on its own first (the order the norm always used).
        let mut shape_sq = 0.0f64;
        for v in x.chunks_exact(9) {
            for (a, &b) in sum.iter_mut().zip(v) {
                *a += f64::from(b);
                shape_sq += f64::from(b) * f64::from(b);
            }
            count += 1;
        }
        sq += shape_sq;
    }
    let norm = if shapes.is_empty() { 0.0 } else { (sq / shapes.len() as f64).sqrt() };
    Ok(FeatureStats { norm, channel_means: sum.map(|a| if count > 0 { a / count as f64 } else { 0.0 }) })
}

/// Root-mean-square over the training shapes of each shape's Euclidean norm of its scaled
/// features ([`feature_stats`]).
pub fn feature_norm(data: &TrainingData) -> Result<f64> {
    Ok(feature_stats(data)?.norm)
}

fn adam(cfg: &AutoencoderConfig) -> ModuleOptimizer {
    AdamConfig::new()
        .with_beta_1(cfg.beta1 as f32)
        .with_beta_2(cfg.beta2 as f32)
        .with_epsilon(cfg.epsilon as f32)
        .init()
}

/// The error of a step whose loss is not finite (nothing is updated or written).
fn non_finite_loss(iteration: usize, terms: &LossTerms) -> Error {
    Error::Numerical(format!(
        "the loss is not finite at iteration {iteration} (reconstruction {}, sparsity {}, hinge {}); \
         training stopped and no checkpoint was written for it",
        terms.reconstruction, terms.sparsity, terms.hinge
    ))
}

/// Seed of the mini-batch stream (distinct from the initialisation stream of the same seed).
fn batch_rng(seed: u64) -> Rng {
    Rng::new(seed ^ 0xB47C_4000_0000_0001)
}

/// The shapes of step `iteration` with mini-batches of `b` of `n_shapes` (b < n_shapes): epoch
/// e = iteration / ⌊S/b⌋ visits the shapes in an order shuffled by a generator seeded with
/// (seed, e) alone, b at a time (the S mod b left over sit out that epoch), so each shape is seen
/// once per epoch and a run resumed at any step draws the same batches as one that was not
/// stopped. `order` caches the current epoch's order.
pub fn epoch_batch(
    seed: u64,
    iteration: usize,
    n_shapes: usize,
    b: usize,
    order: &mut Option<(usize, Vec<usize>)>,
) -> Vec<usize> {
    let b = b.clamp(1, n_shapes.max(1));
    let per_epoch = (n_shapes / b).max(1);
    let (epoch, slot) = (iteration / per_epoch, iteration % per_epoch);
    if order.as_ref().map(|(e, _)| *e) != Some(epoch) {
        let mut rng = Rng::new(seed ^ 0x5EED_E90C_0000_0000 ^ (epoch as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let mut p: Vec<usize> = (0..n_shapes).collect();
        for i in (1..n_shapes).rev() {
            p.swap(i, rng.below(i + 1));
        }
        *order = Some((epoch, p));
    }
    let p = &order.as_ref().map(|(_, p)| p.as_slice()).unwrap_or(&[]);
    p[slot * b..(slot * b + b).min(p.len())].to_vec()
}

/// Mean of every feature channel over the vertices of the training shapes, in the scaled units
/// the network sees ([`feature_stats`]).
pub fn channel_means(data: &TrainingData) -> Result<[f64; 9]> {
    Ok(feature_stats(data)?.channel_means)
}

/// The biases of the first layer for [`InitBias::Mean`]: the encoder bias `b = −(W_point + W_nb)·μ`
/// (a field equal to the channel means `μ` everywhere convolves to 0 at every vertex with
/// neighbours) and the decoder bias `b_dec = atanh(μ)` (clamped to ±0.999), so that a code of 0
/// decodes to `μ`: the network starts at the training shapes' mean features instead of at 0.
pub fn mean_biases(wp: &[f32], wn: &[f32], mu: &[f64; 9]) -> ([f32; 9], [f32; 9]) {
    let mut b = [0.0f32; 9];
    let mut bd = [0.0f32; 9];
    for o in 0..9 {
        b[o] = -(0..9).map(|i| f64::from(wp[o * 9 + i] + wn[o * 9 + i]) * mu[i]).sum::<f64>() as f32;
        bd[o] = mu[o].clamp(-0.999, 0.999).atanh() as f32;
    }
    (b, bd)
}

/// A Burn module of the layers only (no component blocks): what checkpoints record of them.
fn layers_module(layers: Vec<MeshConv>) -> AutoencoderModule {
    AutoencoderModule { layers, components: Vec::new() }
}

impl<'a> Trainer<'a> {
    /// A fresh run: validates the configuration and the sizes, initialises the parameters from
    /// `config.seed`.
    pub fn new(
        config: AutoencoderConfig,
        data: &'a TrainingData,
        neighbors: &'a NeighborIndex,
        distances: &'a dyn CenterDistances,
    ) -> Result<Self> {
        Self::check_sizes(&config, data, neighbors)?;
        let device = training_device(config.device)?;
        let (layers, c) = config.init_arrays(data.n_vertices());
        let stats = feature_stats(data)?;
        let mu = match config.init_bias {
            InitBias::Zero => None,
            InitBias::Mean => Some(stats.channel_means),
        };
        let layers = layers
            .iter()
            .enumerate()
            .map(|(l, [wp, wn])| {
                // Layer 0 is the encoder's first and the decoder's last.
                let (b, bd) = match &mu {
                    Some(mu) if l == 0 => mean_biases(wp, wn, mu),
                    _ => ([0.0; 9], [0.0; 9]),
                };
                MeshConv::from_arrays(wp, wn, &b, &bd, &device)
            })
            .collect();
        Self::with_parameters(config, data, neighbors, distances, device, layers, c, stats.norm)
    }

    fn check_sizes(config: &AutoencoderConfig, data: &TrainingData, neighbors: &NeighborIndex) -> Result<()> {
        config.validate()?;
        if data.n_vertices() != neighbors.n_vertices() {
            return Err(Error::Invalid(format!(
                "training features have {} vertices but the mesh has {}",
                data.n_vertices(),
                neighbors.n_vertices()
            )));
        }
        Ok(())
    }

    /// A run at step 0 with the given parameters (`c`: `[K, 9N]`) on data whose
    /// [`feature_norm`] is `norm`.
    #[allow(clippy::too_many_arguments)]
    fn with_parameters(
        config: AutoencoderConfig,
        data: &'a TrainingData,
        neighbors: &'a NeighborIndex,
        distances: &'a dyn CenterDistances,
        device: Device,
        layers: Vec<MeshConv>,
        c: Vec<f32>,
        norm: f64,
    ) -> Result<Self> {
        let n = data.n_vertices();
        let b = config.batch_for(data.n_shapes());
        let bp = padded_width(b + config.augment + rest_lanes(&config));
        let workspace = Workspace::new(n, config.components, config.layers, bp);
        let full_batch =
            if b == data.n_shapes() { Some(data.batch_vcb_width(&(0..b).collect::<Vec<_>>(), bp)?) } else { None };
        let augmenter = if config.augment > 0 {
            Some(Augmenter::new(config.augment_mix, config.augment_radius, n, distances, config.seed)?)
        } else {
            None
        };
        let weights = Weights {
            layers: layer_weights(&layers),
            k: config.components,
            n,
            c,
            least_squares: config.encoder == EncoderKind::LeastSquares,
        };
        Ok(Trainer {
            optimizer: adam(&config),
            layers: Some(layers),
            weights,
            adam: ComponentAdam::default(),
            c_finite: false,
            norms_current: false,
            encoded_ahead: false,
            module_view: OnceCell::new(),
            plain_updates: false,
            rng: batch_rng(config.seed),
            maps: SupportMaps::new(config.components, n),
            grads: Grads { layers: Vec::new(), c: Vec::new() },
            config,
            data,
            neighbors,
            distances,
            device,
            iteration: 0,
            workspace,
            full_batch,
            graph_neighbors: None,
            last_loss: None,
            timings: StepTimings::default(),
            augmenter,
            batch_buf: Vec::new(),
            noisy_buf: Vec::new(),
            validation: None,
            resumed_best: None,
            train_seconds: 0.0,
            output_loss: None,
            vertex_lanes: Vec::new(),
            epoch_order: None,
            feature_norm: norm,
            rest: None,
            feature_weights: None,
            input: None,
        })
    }

    /// Factor on every step size for this training set (1 unless its features are larger than
    /// [`AutoencoderConfig::learning_rate_norm`]).
    pub fn learning_rate_scale(&self) -> f64 {
        self.config.learning_rate_scale(self.feature_norm)
    }

    /// Adam step size of the current step: the schedule's rate times
    /// [`Self::learning_rate_scale`].
    fn step_size(&self) -> f64 {
        self.config.learning_rate_at(self.iteration) * self.learning_rate_scale()
    }

    /// The training features' size ([`feature_norm`]), which sets [`Self::learning_rate_scale`].
    pub fn feature_norm(&self) -> f64 {
        self.feature_norm
    }

    /// Weights every vertex's feature error by `weights[i]` (`[N]`, each finite and in [0, 1];
    /// `feature_weights = "noise"`: [`crate::representation::noise_sensitivity`]) in the loss,
    /// the validation error and the did-it-train check. Errors on a wrong length or a weight
    /// out of range.
    pub fn with_feature_weights(mut self, weights: &[f64]) -> Result<Self> {
        let n = self.data.n_vertices();
        if weights.len() != n {
            return Err(Error::Invalid(format!("{} feature weights for {n} vertices", weights.len())));
        }
        if let Some((i, w)) = weights.iter().enumerate().find(|(_, w)| !(0.0..=1.0).contains(*w)) {
            return Err(Error::Invalid(format!("feature weight {w} of vertex {i} is not in [0, 1]")));
        }
        let w: Arc<[f32]> = weights.iter().map(|&x| x as f32).collect();
        self.workspace.set_feature_weights(Some(w.clone()));
        if let Some(v) = self.validation.as_mut() {
            v.workspace.set_feature_weights(Some(w.clone()));
        }
        self.feature_weights = Some(w);
        Ok(self)
    }

    /// Names what the input features are (`None`: the default), recorded in every checkpoint
    /// ([`super::checkpoint::CheckpointHeader::input`]) so that a resume can check it.
    pub fn with_input(mut self, name: Option<&str>) -> Self {
        self.input = name.map(str::to_string);
        self
    }

    /// Gives the run the vertex term's loss (`lambda_vertex > 0` needs one; it is weighted by
    /// `lambda_vertex` and sees the same lanes as the feature error, synthetic shapes included).
    pub fn with_output_loss(mut self, loss: &'a dyn OutputLoss) -> Self {
        self.output_loss = Some(loss);
        self
    }

    /// Gives the run the rest shape's scaled features (`9N`, vertex-major, as
    /// [`TrainingData::shape`] gives a shape), which every batch carries as its last lane when
    /// `lambda_code > 0` ([`AutoencoderConfig::lambda_code`]).
    pub fn with_rest(mut self, features: &[f32]) -> Result<Self> {
        let n = self.data.n_vertices();
        if features.len() != 9 * n || features.iter().any(|x| !x.is_finite()) {
            return Err(Error::Invalid(format!(
                "the rest shape's features have {} values (the mesh {}) or a non-finite one",
                features.len(),
                9 * n
            )));
        }
        self.rest = Some(features.to_vec());
        if let Some(x) = self.full_batch.as_mut()
            && rest_lanes(&self.config) > 0
        {
            let bp = self.workspace.width();
            let lane = self.config.batch_for(self.data.n_shapes()) + self.config.augment;
            for (row, &v) in features.iter().enumerate() {
                x[row * bp + lane] = v;
            }
        }
        Ok(self)
    }

    /// The encode–decode feature error of the current parameters on the training shapes, the
    /// error of decoding every shape as the rest shape (`features`, as [`Self::with_rest`] takes
    /// them), and the error the best K linear components around the rest shape leave (K the
    /// run's components; measured on up to [`LINEAR_CHECK_SHAPES`] evenly spread training
    /// shapes and scaled to the whole set by its share of the rest error there): means over the
    /// shapes of the squared error, in scaled units. A run whose decoding gains little of what
    /// K linear components gain over the rest shape did not train. (The linear reference keeps
    /// the check fair on noisy data, where no model gets far below the rest shape's error.)
    pub fn training_rest_and_linear_error(&mut self, rest: &[f32]) -> Result<(f64, f64, f64)> {
        let n_shapes = self.data.n_shapes();
        let bp = padded_width(TRAINING_ERROR_RUN.min(n_shapes));
        let mut ws = Workspace::new(self.data.n_vertices(), self.config.components, self.config.layers, bp);
        ws.set_feature_weights(self.feature_weights.clone());
        // Row weights (each vertex's, or 1): the three errors are measured in the loss's terms.
        let fw = self.feature_weights.clone();
        let row_w = |row: usize| fw.as_ref().map_or(1.0, |v| f64::from(v[row / 9]));
        self.check_parameters()?;
        let (mut model, mut base) = (0.0f64, 0.0f64);
        for start in (0..n_shapes).step_by(TRAINING_ERROR_RUN) {
            let idx: Vec<usize> = (start..(start + TRAINING_ERROR_RUN).min(n_shapes)).collect();
            let x = self.data.batch_vcb_width(&idx, bp)?;
            model += feature_error(&mut ws, &self.weights, self.neighbors, &x, idx.len()) * idx.len() as f64;
            for (row, &r) in rest.iter().enumerate() {
                let w = row_w(row);
                for j in 0..idx.len() {
                    let d = (x[row * bp + j] - r) as f64;
                    base += w * d * d;
                }
            }
        }
        let n = n_shapes.max(1) as f64;
        let (model, base) = (model / n, base / n);
        // Gram matrix of the sampled shapes' differences from the rest shape: its eigenvalues
        // beyond the K largest are what the best K-dimensional subspace leaves.
        let m = n_shapes.min(LINEAR_CHECK_SHAPES);
        let idx: Vec<usize> = (0..m).map(|j| j * n_shapes / m.max(1)).collect();
        let bm = padded_width(m.max(1));
        let x = self.data.batch_vcb_width(&idx, bm)?;
        let mut gram = faer::Mat::<f64>::zeros(m, m);
        let mut d = vec![0.0f64; m];
        for (row, &r) in rest.iter().enumerate() {
            let w = row_w(row).sqrt();
            for (j, dj) in d.iter_mut().enumerate() {
                *dj = w * (x[row * bm + j] - r) as f64;
            }
            for i in 0..m {
                if d[i] != 0.0 {
                    for j in i..m {
                        gram[(i, j)] += d[i] * d[j];
                    }
                }
            }
        }
        for i in 0..m {
            for j in 0..i {
                gram[(i, j)] = gram[(j, i)];
            }
        }
        let total: f64 = (0..m).map(|i| gram[(i, i)]).sum();
        let eig = gram
            .self_adjoint_eigenvalues(faer::Side::Lower)
            .map_err(|e| Error::Numerical(format!("linear reference of the training check: {e:?}")))?;
        let kept: f64 = eig.iter().rev().take(self.config.components).map(|v| v.max(0.0)).sum();
        let share = if total > 0.0 { ((total - kept) / total).clamp(0.0, 1.0) } else { 0.0 };
        Ok((model, base, share * base))
    }

    /// Gives the run held-out shapes (`config.validation > 0`): every `validate_every` steps
    /// and at the end, the encode–decode feature error on them is measured and the parameters
    /// of the lowest one are what [`Self::into_model`] returns. (A resumed run starts from the
    /// best step its checkpoint holds, if any.)
    pub fn with_validation(mut self, data: &'a TrainingData) -> Result<Self> {
        if data.n_vertices() != self.data.n_vertices() {
            return Err(Error::Invalid(format!(
                "validation shapes have {} vertices, the training shapes {}",
                data.n_vertices(),
                self.data.n_vertices()
            )));
        }
        // A resumed run keeps the best step from before the interruption.
        let best = match self.resumed_best.take() {
            None => None,
            Some(b) => {
                if b.layers.len() != self.weights.layers.len() || b.components.len() != self.weights.c.len() {
                    return Err(Error::Invalid(format!(
                        "the checkpoint's best validation step has {} layers and {} numbers of C, the run {} and {}",
                        b.layers.len(),
                        b.components.len(),
                        self.weights.layers.len(),
                        self.weights.c.len()
                    )));
                }
                let Weights { k, n, least_squares, .. } = self.weights;
                Some((b.iteration, b.error, Weights { layers: b.layers, c: b.components, k, n, least_squares }))
            }
        };
        let b = data.n_shapes();
        let bp = padded_width(b);
        self.validation = Some(Validation {
            data,
            x: data.batch_vcb_width(&(0..b).collect::<Vec<_>>(), bp)?,
            workspace: {
                let mut ws = Workspace::new(data.n_vertices(), self.config.components, self.config.layers, bp);
                ws.set_feature_weights(self.feature_weights.clone());
                ws
            },
            best,
        });
        Ok(self)
    }

    /// Errors (naming the first) if a parameter is not finite; `C` is scanned only when the
    /// last update did not already check it.
    fn check_parameters(&self) -> Result<()> {
        self.weights.check_layers()?;
        if !self.c_finite {
            self.weights.check_components()?;
        }
        Ok(())
    }

    /// Measures the validation error of the current parameters and keeps them if best.
    fn validate(&mut self) -> Result<Option<f64>> {
        if self.validation.is_none() {
            return Ok(None);
        }
        self.check_parameters()?;
        self.c_finite = true;
        let v = self.validation.as_mut().expect("validation present");
        let err = feature_error(&mut v.workspace, &self.weights, self.neighbors, &v.x, v.data.n_shapes());
        if v.best.as_ref().is_none_or(|b| err < b.1) {
            v.best = Some((self.iteration, err, self.weights.clone()));
        }
        Ok(Some(err))
    }

    /// Continues the run saved in `checkpoint`. `config` must describe the same model and loss
    /// (only `iterations` and `checkpoint_every` may change); data and mesh must match.
    pub fn resume(
        checkpoint: &Path,
        config: AutoencoderConfig,
        data: &'a TrainingData,
        neighbors: &'a NeighborIndex,
        distances: &'a dyn CenterDistances,
    ) -> Result<Self> {
        Self::resume_from(Checkpoint::load(checkpoint)?, checkpoint, config, data, neighbors, distances)
    }

    /// [`Self::resume`] from a checkpoint already read (and verified) by [`Checkpoint::load`]
    /// from `checkpoint`, the path its errors name: a caller that looked at the header first
    /// does not read a large file twice.
    pub fn resume_from(
        ck: Checkpoint,
        checkpoint: &Path,
        config: AutoencoderConfig,
        data: &'a TrainingData,
        neighbors: &'a NeighborIndex,
        distances: &'a dyn CenterDistances,
    ) -> Result<Self> {
        config.check_resumable(&ck.header.config)?;
        if ck.header.n_vertices != neighbors.n_vertices() || ck.header.neighbor_fingerprint != neighbors.fingerprint() {
            return Err(Error::Invalid(format!(
                "{}: the checkpoint was trained on a different mesh ({} vertices)",
                checkpoint.display(),
                ck.header.n_vertices
            )));
        }
        if ck.header.n_shapes != data.n_shapes() {
            return Err(Error::Invalid(format!(
                "{}: the checkpoint was trained on {} shapes, the data has {}",
                checkpoint.display(),
                ck.header.n_shapes,
                data.n_shapes()
            )));
        }
        // The default batch depends on the set's size since issue 57: a checkpoint of a run on
        // another batch (an older full-batch run of more than 64 shapes) resumes only with its own.
        let (saved, now) = (ck.header.batch(), config.batch_for(data.n_shapes()));
        if saved != now {
            return Err(Error::config(
                "batch_size",
                format!(
                    "{}: the checkpoint was trained with {saved} shapes a step, this run would take {now} \
                     (the default is the full batch up to {FULL_BATCH_UP_TO} shapes, {DEFAULT_MINI_BATCH} beyond): \
                     set method.batch_size = {saved} to resume it",
                    checkpoint.display()
                ),
            ));
        }
        Self::check_sizes(&config, data, neighbors)?;
        let n = neighbors.n_vertices();
        if ck.columns != 9 * n || ck.components.len() != config.components * 9 * n {
            return Err(Error::parse(
                checkpoint,
                None,
                format!(
                    "components: {} numbers in rows of {}, expected {} × {}",
                    ck.components.len(),
                    ck.columns,
                    config.components,
                    9 * n
                ),
            ));
        }
        let device = training_device(config.device)?;
        let layers = load_layers(checkpoint, &config, n, ck.layers, &device)?;
        let optimizer = adam(&config)
            .from_bytes(Bytes::from_bytes_vec(ck.layers_optimizer))
            .map_err(|e| Error::parse(checkpoint, None, format!("optimizer record: {e}")))?;
        let norm = feature_norm(data)?;
        let mut t = Self::with_parameters(config, data, neighbors, distances, device, layers, ck.components, norm)?;
        t.optimizer = optimizer;
        t.adam = ck.adam;
        t.iteration = ck.header.iteration;
        t.rng = Rng { state: ck.header.rng_state };
        t.last_loss = ck.header.last_loss;
        t.resumed_best = ck.best;
        t.train_seconds = ck.header.train_seconds;
        Ok(t)
    }

    /// Completed steps.
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// The hyperparameters.
    pub fn config(&self) -> &AutoencoderConfig {
        &self.config
    }

    /// The current parameters as a Burn module (built on first use after a step: a copy of `C`).
    pub fn module(&self) -> &AutoencoderModule {
        self.module_view.get_or_init(|| AutoencoderModule {
            layers: self.layers().clone(),
            components: AutoencoderModule::component_blocks(&self.weights.c, self.weights.n, &self.device),
        })
    }

    /// The current parameters as plain arrays (`C` is the trainer's own buffer).
    pub fn weights(&self) -> &Weights {
        &self.weights
    }

    fn layers(&self) -> &Vec<MeshConv> {
        self.layers.as_ref().expect("layers present between steps")
    }

    /// Current component centres (after at least one step).
    pub fn centers(&self) -> &[usize] {
        self.maps.centers()
    }

    /// One optimisation step. Errors (and leaves the parameters untouched) when the loss or a
    /// gradient is not finite.
    pub fn step(&mut self) -> Result<LossTerms> {
        let t0 = Instant::now();
        if self.config.lambda_vertex > 0.0 && self.output_loss.is_none() {
            return Err(Error::config(
                "lambda_vertex",
                format!(
                    "{} needs the vertex loss of the representation (Trainer::with_output_loss)",
                    self.config.lambda_vertex
                ),
            ));
        }
        self.weights.least_squares = self.config.encoder == EncoderKind::LeastSquares;
        self.check_parameters()
            .map_err(|e| Error::Numerical(format!("before iteration {}: {e}", self.iteration + 1)))?;
        self.c_finite = true;
        let t1 = Instant::now();
        let queries = self.maps.distance_queries();
        if !self.norms_current {
            self.maps.set_norms_from(&self.weights.c);
            self.norms_current = true;
        }
        let plan = self.maps.plan_update();
        let fused = self.config.engine == Engine::Hand
            && engine::fused_update_applies(&self.weights, &self.config)
            && !self.plain_updates;
        // The fused path runs the distance queries beside the forward/backward pass (which does
        // not read the maps); otherwise the maps are complete before it.
        let mut plan = Some(plan);
        if !fused {
            let plan = plan.take().expect("plan");
            let rows = SupportMaps::query_rows(&plan, self.maps.n_vertices(), &self.config, self.distances);
            self.maps.apply_update(plan, rows)?;
        }
        let t2 = Instant::now();
        let n_shapes = self.data.n_shapes();
        let b = self.config.batch_for(n_shapes);
        if self.config.engine == Engine::Graph {
            let idx: Vec<usize> = if b == n_shapes {
                (0..n_shapes).collect()
            } else {
                epoch_batch(self.config.seed, self.iteration, n_shapes, b, &mut self.epoch_order)
            };
            let terms = self.graph_step(&idx)?;
            self.iteration += 1;
            self.last_loss = Some(terms);
            let t3 = Instant::now();
            self.timings = StepTimings {
                snapshot: (t1 - t0).as_secs_f64(),
                support: (t2 - t1).as_secs_f64(),
                forward_backward: (t3 - t2).as_secs_f64(),
                optimizer: 0.0,
            };
            self.count_step(queries);
            return Ok(terms);
        }
        let bp = self.workspace.width();
        if self.full_batch.is_none() {
            let idx = epoch_batch(self.config.seed, self.iteration, n_shapes, b, &mut self.epoch_order);
            self.batch_buf = self.data.batch_vcb_width(&idx, bp)?;
        }
        let x: &mut [f32] = match &mut self.full_batch {
            Some(x) => x,
            None => &mut self.batch_buf,
        };
        let m = self.config.augment;
        if let Some(aug) = &self.augmenter {
            let data = self.data;
            for j in 0..m {
                aug.draw(&|s| data.shape(s), n_shapes, &mut self.rng, |row, v| x[row * bp + b + j] = v)?;
            }
        }
        let r = rest_lanes(&self.config);
        if r > 0 {
            let rest = self.rest.as_ref().ok_or_else(|| {
                Error::config("lambda_code", "needs the rest shape's features (Trainer::with_rest)".to_string())
            })?;
            for (row, &v) in rest.iter().enumerate() {
                x[row * bp + b + m] = v;
            }
        }
        // Denoising: the encoder reads the batch plus fresh Gaussian noise on its real lanes; the
        // decoding is compared with the clean batch.
        let sigma = self.config.input_noise;
        if sigma > 0.0 {
            self.noisy_buf.clear();
            self.noisy_buf.extend_from_slice(x);
            for row in self.noisy_buf.chunks_exact_mut(bp) {
                for v in &mut row[..b + m] {
                    *v += (sigma * self.rng.normal()) as f32;
                }
            }
        }
        let (x, target): (&[f32], Option<&[f32]>) =
            if sigma > 0.0 { (&self.noisy_buf, Some(&*x)) } else { (&*x, None) };
        if self.output_loss.is_some() {
            let lanes = b + m;
            let v = self.config.vertex_batch;
            self.vertex_lanes = if v == 0 || v >= lanes {
                (0..lanes).collect()
            } else {
                let mut l = self.rng.sample_distinct(lanes, v);
                l.sort_unstable();
                l
            };
        }
        let terms = match plan {
            Some(plan) => {
                let (ws, w, nb, grads, cfg) =
                    (&mut self.workspace, &self.weights, self.neighbors, &mut self.grads, &self.config);
                let weight = self.config.lambda_vertex_at(self.iteration);
                let output_term = self.output_loss.map(|o| (o, &self.vertex_lanes[..], weight));
                let (dist, n) = (self.distances, self.maps.n_vertices());
                let encoded = std::mem::take(&mut self.encoded_ahead);
                let (rows, partial) = rayon::join(
                    || SupportMaps::query_rows(&plan, n, cfg, dist),
                    || engine::loss_and_layer_grads(ws, w, nb, x, target, b + m + r, cfg, grads, encoded, output_term),
                );
                self.maps.apply_update(plan, rows)?;
                engine::finish_loss(partial, &self.maps, &self.config)
            }
            None => engine::loss_and_grad(
                &mut self.workspace,
                &self.weights,
                self.neighbors,
                x,
                target,
                b + m + r,
                &self.maps,
                &self.config,
                &mut self.grads,
                self.output_loss.map(|o| (o, &self.vertex_lanes[..], self.config.lambda_vertex_at(self.iteration))),
            ),
        };
        if !terms.is_finite() {
            return Err(non_finite_loss(self.iteration + 1, &terms));
        }
        // With the fused update, ∂L/∂C is never stored: it is computed while C is updated, which
        // is safe when a bound proves every entry finite; otherwise it is stored and checked.
        let stream =
            fused && engine::components_gradient_bound(&self.workspace, &self.weights, &self.config).is_finite();
        if fused && !stream {
            engine::components_gradient(&mut self.workspace, &self.weights, &self.maps, &self.config, &mut self.grads);
        }
        let bad = if stream || self.workspace.gradient_c_finite() {
            // Only the layers' gradients are left to check.
            self.grads.first_non_finite_layer()
        } else {
            self.grads.first_non_finite()
        };
        if let Some(p) = bad {
            return Err(Error::Numerical(format!(
                "a gradient is not finite at iteration {} ({p}); training stopped and no checkpoint was written for it",
                self.iteration + 1
            )));
        }
        let t3 = Instant::now();
        self.apply_gradients(stream);
        if stream {
            // Nothing keeps the full gradient of C.
            self.grads.c = Vec::new();
        }
        self.iteration += 1;
        self.last_loss = Some(terms);
        let t4 = Instant::now();
        self.timings = StepTimings {
            snapshot: (t1 - t0).as_secs_f64(),
            support: (t2 - t1).as_secs_f64(),
            forward_backward: (t3 - t2).as_secs_f64(),
            optimizer: (t4 - t3).as_secs_f64(),
        };
        self.count_step(queries);
        Ok(terms)
    }

    /// Adds the last step's phases to the command's counters (printed with `-v`).
    fn count_step(&self, queries_before: u64) {
        let us = |s: f64| (s * 1e6).round() as u64;
        let t = &self.timings;
        crate::timing::count("autoencoder steps", 1);
        crate::timing::count("autoencoder step µs, snapshot", us(t.snapshot));
        crate::timing::count("autoencoder step µs, support maps", us(t.support));
        crate::timing::count("autoencoder step µs, forward/backward", us(t.forward_backward));
        crate::timing::count("autoencoder step µs, optimizer", us(t.optimizer));
        crate::timing::count("autoencoder distance queries", self.maps.distance_queries() - queries_before);
    }

    /// Phase timings of the last completed step.
    pub fn last_step_timings(&self) -> StepTimings {
        self.timings
    }

    /// One step of [`Engine::Graph`]: Burn autodiff of [`reference_loss`] on the run's device,
    /// then the same optimizers as the hand engine (so checkpoints are interchangeable). Errors
    /// and leaves the parameters untouched when the loss is not finite.
    fn graph_step(&mut self, idx: &[usize]) -> Result<LossTerms> {
        let nb = self.graph_neighbors.get_or_insert_with(|| NeighborTensors::new(self.neighbors, &self.device));
        let layers = self.layers.take().expect("layers present between steps");
        let components = AutoencoderModule::component_blocks(&self.weights.c, self.weights.n, &self.device);
        let module = AutoencoderModule { layers, components };
        let rest = if rest_lanes(&self.config) > 0 {
            Some(self.rest.clone().ok_or_else(|| {
                Error::config("lambda_code", "needs the rest shape's features (Trainer::with_rest)".to_string())
            })?)
        } else {
            None
        };
        let x = match (&self.augmenter, rest) {
            (None, None) => self.data.batch_tensor(idx, &self.device)?,
            (aug, rest) => {
                let n = self.data.n_vertices();
                let m = if aug.is_some() { self.config.augment } else { 0 };
                let lanes = idx.len() + m + usize::from(rest.is_some());
                let mut v = Vec::with_capacity(lanes * n * 9);
                for &s in idx {
                    v.extend_from_slice(&self.data.shape(s)?);
                }
                let data = self.data;
                if let Some(aug) = aug {
                    for _ in 0..m {
                        let start = v.len();
                        v.resize(start + n * 9, 0.0);
                        let dst = &mut v[start..];
                        aug.draw(&|s| data.shape(s), data.n_shapes(), &mut self.rng, |row, x| dst[row] = x)?;
                    }
                }
                if let Some(r) = rest {
                    v.extend_from_slice(&r);
                }
                Tensor::from_data(TensorData::new(v, [lanes, n, 9]), &self.device)
            }
        };
        let (loss, terms) = reference_loss(&module, x, nb, &self.maps, &self.config, self.feature_weights.as_deref());
        if !terms.is_finite() {
            self.layers = Some(module.layers);
            return Err(non_finite_loss(self.iteration + 1, &terms));
        }
        let mut grads = GradientsParams::from_grads(loss.backward(), &module);
        let AutoencoderModule { layers, components } = module;
        // C's gradient into the flat buffer the fused update reads.
        let nc = 9 * self.weights.n;
        self.grads.c.resize(self.weights.c.len(), 0.0);
        for (p, dst) in components.iter().zip(self.grads.c.chunks_mut(COMPONENT_BLOCK * nc.max(1))) {
            match grads.remove::<2>(p.id) {
                Some(g) => dst.copy_from_slice(&tensor_to_vec(g)),
                None => dst.fill(0.0),
            }
        }
        drop(components);
        let lr = self.step_size();
        let layers = self.optimizer.step(lr, layers, grads);
        self.set_layers(layers);
        self.update_components(lr);
        Ok(terms)
    }

    /// The layers from Burn's optimizer: kept, and mirrored into the plain weights.
    fn set_layers(&mut self, layers: Vec<MeshConv>) {
        self.weights.layers = layer_weights(&layers);
        self.layers = Some(layers);
    }

    /// Adam on `C` from `self.grads.c`, in place, with the squared vertex norms of the result
    /// written for the next step's support maps.
    fn update_components(&mut self, lr: f64) {
        self.c_finite = self.adam.step(&self.config, lr, &mut self.weights.c, &self.grads.c, self.maps.sq_norms_mut());
        self.norms_current = true;
        self.module_view = OnceCell::new();
    }

    /// Registers the hand-computed gradients of the layers with Burn and runs Burn's Adam on
    /// them; then Adam on `C`: from `grads.c`, or with `stream` computing `∂L/∂C` tile by tile
    /// as it updates ([`engine::update_components`]).
    fn apply_gradients(&mut self, stream: bool) {
        let dev = self.device.clone().inner();
        let lr = self.step_size();
        let layers = self.layers.take().expect("layers present between steps");
        let mut gp = GradientsParams::new();
        let t9x9 = |a: &[[f64; 9]; 9]| -> Tensor<2> {
            let v: Vec<f32> = a.iter().flatten().map(|&x| x as f32).collect();
            Tensor::from_data(TensorData::new(v, [9, 9]), &dev)
        };
        let t9 = |a: &[f64; 9]| -> Tensor<1> {
            Tensor::from_data(TensorData::new(a.iter().map(|&x| x as f32).collect::<Vec<f32>>(), [9]), &dev)
        };
        for (layer, g) in layers.iter().zip(&self.grads.layers) {
            gp.register(layer.weight_point.id, t9x9(&g.wp));
            gp.register(layer.weight_neighbor.id, t9x9(&g.wn));
            gp.register(layer.bias.id, t9(&g.b));
            gp.register(layer.decoder_bias.id, t9(&g.bd));
        }
        let layers = self.optimizer.step(lr, layers, gp);
        self.set_layers(layers);
        if stream {
            let a = self.adam.begin_step(&self.config, lr, self.weights.c.len());
            // The next step's batch is this one (full batch, nothing synthetic): encode it with
            // the new parameters during the update.
            let next = self.full_batch.as_deref().filter(|_| {
                self.config.augment == 0
                    && self.config.input_noise == 0.0
                    && engine::encode_next_applies(&self.workspace, &self.weights)
            });
            let mut c = std::mem::take(&mut self.weights.c);
            self.c_finite = engine::update_components(
                &mut self.workspace,
                &self.weights,
                &mut c,
                &mut self.adam.moment_1,
                &mut self.adam.moment_2,
                &a,
                &mut self.maps,
                &self.config,
                next,
            );
            self.weights.c = c;
            self.encoded_ahead = next.is_some();
            self.norms_current = true;
            self.module_view = OnceCell::new();
        } else {
            self.update_components(lr);
        }
    }

    fn header(&self) -> CheckpointHeader {
        CheckpointHeader {
            iteration: self.iteration,
            rng_state: self.rng.state,
            config: self.config.clone(),
            n_vertices: self.neighbors.n_vertices(),
            n_shapes: self.data.n_shapes(),
            neighbor_fingerprint: self.neighbors.fingerprint(),
            last_loss: self.last_loss,
            batch: Some(self.config.batch_for(self.data.n_shapes())),
            feature_weighted: self.feature_weights.is_some(),
            train_seconds: self.train_seconds,
            input: self.input.clone(),
        }
    }

    /// The layers' module and optimizer records (burnpack bytes), after checking that every
    /// parameter is finite (never write NaN).
    fn layer_records(&self) -> Result<(Vec<u8>, Vec<u8>)> {
        self.check_parameters().map_err(|e| Error::Numerical(format!("refusing to write a checkpoint: {e}")))?;
        let layers = layers_module(self.layers().clone())
            .into_record()
            .into_bytes()
            .map_err(|e| Error::Invalid(format!("module record: {e}")))?;
        let optimizer = self.optimizer.into_bytes().map_err(|e| Error::Invalid(format!("optimizer record: {e}")))?;
        Ok((layers.to_vec(), optimizer.to_vec()))
    }

    /// The current state as a checkpoint (errors if a parameter is not finite). This copies `C`
    /// and Adam's moments; [`Self::save_checkpoint`] writes them without a copy.
    pub fn checkpoint(&self) -> Result<Checkpoint> {
        let (layers, layers_optimizer) = self.layer_records()?;
        Ok(Checkpoint {
            header: self.header(),
            layers,
            layers_optimizer,
            components: self.weights.c.clone(),
            columns: 9 * self.weights.n,
            adam: self.adam.clone(),
            best: self.best_step().map(|b| b.to_owned()),
        })
    }

    /// Writes a checkpoint atomically to `path` (streamed from the trainer's buffers).
    pub fn save_checkpoint(&self, path: &Path) -> Result<()> {
        let (layers, layers_optimizer) = self.layer_records()?;
        checkpoint::write(
            path,
            &CheckpointParts {
                header: &self.header(),
                layers: &layers,
                layers_optimizer: &layers_optimizer,
                components: &self.weights.c,
                columns: 9 * self.weights.n,
                adam: &self.adam,
                best: self.best_step(),
            },
        )
    }

    /// The best validation step so far (runs with `validation > 0`), as a checkpoint stores it.
    fn best_step(&self) -> Option<checkpoint::BestStepParts<'_>> {
        let (iteration, error, w) = self.validation.as_ref()?.best.as_ref()?;
        Some(checkpoint::BestStepParts { iteration: *iteration, error: *error, layers: &w.layers, components: &w.c })
    }

    /// Runs until `config.iterations` steps are done or the stop flag is set, calling
    /// `on_iteration` after every step. Checkpoints every `checkpoint_every` steps, at the end,
    /// and when stopped. On a numerical error the run returns it and writes nothing.
    pub fn run(&mut self, options: &RunOptions, mut on_iteration: impl FnMut(&IterationReport)) -> Result<RunSummary> {
        let total = self.config.iterations;
        let mut steps = 0usize;
        let mut time = 0.0f64;
        let mut stopped = false;
        let mut stalled = false;
        // The first step's reconstruction error (known only when this run made that step) and
        // the last STALL_WINDOW steps' (the stall check).
        let mut first: Option<f64> = None;
        let mut recent = std::collections::VecDeque::with_capacity(STALL_WINDOW);
        while self.iteration < total {
            if options.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst)) {
                stopped = true;
                break;
            }
            let t0 = Instant::now();
            let seconds_before = self.train_seconds;
            let loss = self.step()?;
            let dt = t0.elapsed().as_secs_f64();
            time += dt;
            steps += 1;
            if self.iteration == 1 {
                first = Some(loss.reconstruction);
            }
            if recent.len() == STALL_WINDOW {
                recent.pop_front();
            }
            recent.push_back(loss.reconstruction);
            stalled = options.stall_check == Some(self.iteration)
                && first.is_some_and(|f| recent.iter().sum::<f64>() / recent.len() as f64 >= f);
            // A stalled step is reported, but neither validated nor checkpointed.
            let mut checkpointed = false;
            let mut validation_error = None;
            if !stalled {
                let ve = self.config.validate_every.max(1);
                if self.iteration.is_multiple_of(ve) || self.iteration == total {
                    validation_error = self.validate()?;
                }
                let every = self.config.checkpoint_every;
                if let Some(path) = &options.checkpoint
                    && ((every > 0 && self.iteration.is_multiple_of(every)) || self.iteration == total)
                {
                    self.train_seconds = seconds_before + t0.elapsed().as_secs_f64();
                    self.save_checkpoint(path)?;
                    checkpointed = true;
                }
            }
            self.train_seconds = seconds_before + t0.elapsed().as_secs_f64();
            on_iteration(&IterationReport {
                iteration: self.iteration,
                iterations: total,
                loss,
                step_seconds: dt,
                checkpointed,
                validation_error,
            });
            if stalled {
                break;
            }
        }
        if stopped && let Some(path) = &options.checkpoint {
            self.save_checkpoint(path)?;
        }
        Ok(RunSummary {
            iterations_done: self.iteration,
            stopped,
            last_loss: self.last_loss,
            mean_step_seconds: if steps > 0 { time / steps as f64 } else { 0.0 },
            best: self.validation.as_ref().and_then(|v| v.best.as_ref().map(|b| (b.0, b.1))),
            stalled,
        })
    }

    /// The trained model for inference (the parameters of the best validation step, if any).
    pub fn into_model(self) -> Result<Autoencoder> {
        let Trainer { config, neighbors, weights, validation, .. } = self;
        // Everything else of the run (Adam's moments, gradients, buffers) is freed here.
        let weights = match validation.and_then(|v| v.best) {
            Some((_, _, best)) => best,
            None => weights,
        };
        Autoencoder::from_weights(config, weights, neighbors.clone())
    }
}

/// The layers stored in a checkpoint's module record.
pub(crate) fn load_layers(
    path: &Path,
    config: &AutoencoderConfig,
    n_vertices: usize,
    bytes: Vec<u8>,
    device: &Device,
) -> Result<Vec<MeshConv>> {
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(bytes))
        .map_err(|e| Error::parse(path, None, format!("module record: {e}")))?;
    let (init, _) = AutoencoderConfig { components: 0, ..config.clone() }.init_arrays(n_vertices);
    let layers = init.iter().map(|[wp, wn]| MeshConv::from_arrays(wp, wn, &[0.0; 9], &[0.0; 9], device)).collect();
    let module = layers_module(layers)
        .try_load_record(record)
        .map_err(|e| Error::parse(path, None, format!("module record: {e}")))?;
    Ok(module.layers)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::loss::HopDistances;
    use crate::representation::Features;

    /// `nx × ny` vertices (the library's criss-cross grid): vertex count and faces.
    fn grid(nx: usize, ny: usize) -> (usize, Vec<[usize; 3]>) {
        let m = crate::mesh::primitives::grid(nx - 1, ny - 1, 1.0);
        (m.n_vertices(), m.faces)
    }

    /// The default step (∂L/∂C streamed into the update, the next encoder pass done ahead, the
    /// distance queries beside the backward pass) gives the same bits as the plain one (the
    /// stored gradient of `loss_and_grad`, then Adam): loss terms, parameters and Adam's state.
    #[test]
    fn fused_steps_equal_plain_steps_bit_for_bit() {
        let (n, faces) = grid(13, 11);
        let nb = NeighborIndex::from_faces(n, &faces).unwrap();
        let dist = HopDistances::new(&nb);
        // Full batch of one SIMD block (encoded ahead), of two, and mini-batches.
        for (shapes, batch_size) in [(6, None), (11, None), (9, Some(4))] {
            let mut rng = Rng::new(shapes as u64);
            let mut feats = Features::zeros(shapes, n, 9);
            for v in feats.data.iter_mut() {
                *v = rng.uniform() * 1.8 - 0.9;
            }
            let data = TrainingData::from_features(&feats).unwrap();
            let cfg = AutoencoderConfig { components: 6, iterations: 8, batch_size, seed: 5, ..Default::default() };
            let mut fused = Trainer::new(cfg.clone(), &data, &nb, &dist).unwrap();
            let mut plain = Trainer::new(cfg, &data, &nb, &dist).unwrap();
            plain.plain_updates = true;
            for step in 0..8 {
                let (a, b) = (fused.step().unwrap(), plain.step().unwrap());
                assert_eq!(a, b, "{shapes} shapes, step {step}: loss terms differ");
            }
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fused.weights.c), bits(&plain.weights.c), "{shapes} shapes: C differs");
            assert_eq!(bits(&fused.adam.moment_1), bits(&plain.adam.moment_1));
            assert_eq!(bits(&fused.adam.moment_2), bits(&plain.adam.moment_2));
            for (la, lb) in fused.weights.layers.iter().zip(&plain.weights.layers) {
                assert_eq!(bits(la.wp.as_flattened()), bits(lb.wp.as_flattened()));
                assert_eq!(bits(la.wn.as_flattened()), bits(lb.wn.as_flattened()));
                assert_eq!(bits(&la.b), bits(&lb.b));
                assert_eq!(bits(&la.bd), bits(&lb.bd));
            }
            assert_eq!(fused.centers(), plain.centers());
            assert!(fused.grads.c.is_empty(), "the fused path stored the gradient of C");
        }
    }

    /// `init_bias = "mean"`: the channel means are the training features' own; a field equal to
    /// them everywhere convolves to 0 through the first layer (the encoder sees deviations) and
    /// a code of 0 decodes to them; on features far from 0 the first step's reconstruction error
    /// is that of the deviations, not of the whole features as with the paper's zero biases.
    #[test]
    fn mean_biases_start_the_network_at_the_mean_features() {
        let (n, faces) = grid(13, 11);
        let nb = NeighborIndex::from_faces(n, &faces).unwrap();
        let dist = HopDistances::new(&nb);
        let offsets = [0.7, -0.5, 0.1, 0.6, -0.2, 0.0, 0.65, 0.3, -0.8];
        let mut rng = Rng::new(3);
        let mut feats = Features::zeros(6, n, 9);
        for (i, v) in feats.data.iter_mut().enumerate() {
            *v = offsets[i % 9] + rng.uniform() * 0.04 - 0.02;
        }
        let data = TrainingData::from_features(&feats).unwrap();
        let mu = channel_means(&data).unwrap();
        for (c, m) in mu.iter().enumerate() {
            let exact = feats.data.iter().skip(c).step_by(9).sum::<f64>() / (6 * n) as f64;
            assert!((m - exact).abs() < 1e-6, "channel {c}: {m} vs {exact}");
        }
        let (wp, wn) = (rng.normal_vec(81, 0.3), rng.normal_vec(81, 0.3));
        let (b, bd) = mean_biases(&wp, &wn, &mu);
        for o in 0..9 {
            let pre: f64 =
                (0..9).map(|i| f64::from(wp[o * 9 + i] + wn[o * 9 + i]) * mu[i]).sum::<f64>() + f64::from(b[o]);
            assert!(pre.abs() < 1e-5, "output {o}: the mean field convolves to {pre}");
            assert!((f64::from(bd[o]).tanh() - mu[o]).abs() < 1e-5, "output {o}: code 0 decodes to {}", bd[o]);
        }
        let first = |init_bias| {
            let cfg = AutoencoderConfig { components: 4, iterations: 5, init_bias, seed: 2, ..Default::default() };
            Trainer::new(cfg, &data, &nb, &dist).unwrap().step().unwrap().reconstruction
        };
        let (zero, mean) = (first(InitBias::Zero), first(InitBias::Mean));
        let whole: f64 = offsets.iter().map(|o| o * o).sum::<f64>() * n as f64;
        assert!(zero > 0.5 * whole, "zero biases start near features of 0: {zero} vs {whole}");
        assert!(mean < 0.02 * whole, "mean biases start near the mean: {mean} vs {whole}");
    }

    /// A checkpoint resumes only on the batch it was trained with: one of a full-batch run of
    /// 70 shapes (as every run of more than 64 shapes was before issue 57) is refused under the
    /// default, which would take 32, naming `batch_size`; with `batch_size = 70` it resumes.
    #[test]
    fn a_checkpoint_resumes_only_on_its_own_batch() {
        let (n, faces) = grid(5, 4);
        let nb = NeighborIndex::from_faces(n, &faces).unwrap();
        let dist = HopDistances::new(&nb);
        let mut rng = Rng::new(3);
        let mut feats = Features::zeros(70, n, 9);
        for v in feats.data.iter_mut() {
            *v = rng.uniform() * 1.8 - 0.9;
        }
        let data = TrainingData::from_features(&feats).unwrap();
        let full = AutoencoderConfig { components: 3, iterations: 2, batch_size: Some(70), ..Default::default() };
        let mut t = Trainer::new(full.clone(), &data, &nb, &dist).unwrap();
        t.step().unwrap();
        let dir = std::env::temp_dir().join(format!("meshdeco-batch-resume-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ck = dir.join("checkpoint.bin");
        t.save_checkpoint(&ck).unwrap();
        let default = AutoencoderConfig { batch_size: None, ..full.clone() };
        let err = Trainer::resume(&ck, default, &data, &nb, &dist).err().expect("refused").to_string();
        assert!(err.contains("batch_size") && err.contains("70 shapes a step") && err.contains("take 32"), "{err}");
        assert_eq!(Trainer::resume(&ck, full, &data, &nb, &dist).unwrap().iteration(), 1);
        // A checkpoint from before the batch was recorded: `batch_size`, else the full batch.
        let mut h = Checkpoint::load(&ck).unwrap().header;
        h.batch = None;
        assert_eq!(h.batch(), 70);
        h.config.batch_size = None;
        assert_eq!(h.batch(), 70);
        h.config.batch_size = Some(8);
        assert_eq!(h.batch(), 8);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn epoch_batches_visit_every_shape_once_and_resume_alike() {
        let (s, b) = (23, 5);
        let per_epoch = s / b;
        let mut order = None;
        let mut seen_epochs = Vec::new();
        for epoch in 0..3 {
            let mut seen = Vec::new();
            for slot in 0..per_epoch {
                let it = epoch * per_epoch + slot;
                let batch = epoch_batch(7, it, s, b, &mut order);
                assert_eq!(batch.len(), b);
                // A resumed run (no cached order) draws the same batch.
                assert_eq!(batch, epoch_batch(7, it, s, b, &mut None), "iteration {it}");
                seen.extend(batch);
            }
            let mut sorted = seen.clone();
            sorted.sort_unstable();
            sorted.dedup();
            assert_eq!(sorted.len(), per_epoch * b, "epoch {epoch}: a shape came twice");
            assert!(sorted.iter().all(|&i| i < s));
            seen_epochs.push(seen);
        }
        assert_ne!(seen_epochs[0], seen_epochs[1], "each epoch is shuffled anew");
        assert_ne!(epoch_batch(7, 0, s, b, &mut None), epoch_batch(8, 0, s, b, &mut None), "the seed matters");
        assert_eq!(epoch_batch(7, 3, 4, 9, &mut None).len(), 4, "a batch larger than the data is the data");
    }
}
