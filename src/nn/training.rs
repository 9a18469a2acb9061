//! Training loop: hand-written loss and gradients ([`super::engine`]), Burn's Adam
//! ([`burn::optim::AdamConfig`]) for the update, checkpoints, resume and a stop flag.
//!
//! The gradients are handed to Burn through [`GradientsParams::register`] keyed by each
//! parameter's [`burn::module::ParamId`], so the optimizer state lives in Burn and is saved with
//! Burn's records. A run is deterministic for a given seed (fixed-order reductions), and a run
//! resumed from a checkpoint reproduces the uninterrupted run.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device, Tensor, TensorData};
use serde::Serialize;

use super::augment::Augmenter;
use super::checkpoint::{Checkpoint, CheckpointHeader};
use super::config::{AutoencoderConfig, ComputeDevice, EncoderKind, Engine};
use super::data::TrainingData;
use super::engine::{self, Grads, Weights, Workspace};
use super::inference::Autoencoder;
use super::kernels::padded_width;
use super::loss::reference_loss;
use super::loss::{CenterDistances, LossTerms, SupportMaps};
use super::model::{AutoencoderModule, COMPONENT_BLOCK, NeighborTensors};
use super::neighbors::NeighborIndex;
use super::rng::Rng;
use crate::error::{Error, Result};
use rayon::prelude::*;

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
}

/// Wall time of the phases of the last step, seconds.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct StepTimings {
    /// Reading the parameters out of Burn (and checking them).
    pub snapshot: f64,
    /// Centres and support maps Λ (including distance queries).
    pub support: f64,
    /// Hand-written forward and backward pass.
    pub forward_backward: f64,
    /// Gradients into Burn and Burn's Adam update.
    pub optimizer: f64,
}

/// Where to checkpoint and when to stop.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Checkpoint file (written atomically every `checkpoint_every` steps, at the end and on stop).
    pub checkpoint: Option<PathBuf>,
    /// Checked every step; when set, the run writes a checkpoint and returns.
    pub stop: Option<Arc<AtomicBool>>,
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
}

/// Held-out shapes and the best parameters seen on them (see
/// [`AutoencoderConfig::validation`]).
struct Validation<'a> {
    data: &'a TrainingData,
    /// The shapes in VCB layout.
    x: Vec<f32>,
    workspace: Workspace,
    /// (step, error, parameters) of the lowest validation error so far.
    best: Option<(usize, f64, AutoencoderModule)>,
}

/// Mean over the `b` real lanes of the squared error between encode–decode of `x` and `x`.
pub fn feature_error(ws: &mut Workspace, w: &Weights, nb: &NeighborIndex, x: &[f32], b: usize) -> f64 {
    engine::encode(ws, w, nb, x, b);
    engine::decode(ws, w, nb, b);
    let bp = ws.width();
    let out = ws.output();
    let mut sse = 0.0f64;
    for (ro, rx) in out.chunks_exact(bp).zip(x.chunks_exact(bp)) {
        for j in 0..b {
            let d = (ro[j] - rx[j]) as f64;
            sse += d * d;
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
    module: Option<AutoencoderModule>,
    /// Adam for the convolution layers, and one Adam per row block of `C` (run in parallel).
    optimizer: ModuleOptimizer,
    block_optimizers: Vec<ModuleOptimizer>,
    weights: Weights,
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
    validation: Option<Validation<'a>>,
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

impl<'a> Trainer<'a> {
    /// A fresh run: validates the configuration and the sizes, initialises the parameters from
    /// `config.seed`.
    pub fn new(
        config: AutoencoderConfig,
        data: &'a TrainingData,
        neighbors: &'a NeighborIndex,
        distances: &'a dyn CenterDistances,
    ) -> Result<Self> {
        config.validate()?;
        if data.n_vertices() != neighbors.n_vertices() {
            return Err(Error::Invalid(format!(
                "training features have {} vertices but the mesh has {}",
                data.n_vertices(),
                neighbors.n_vertices()
            )));
        }
        let device = training_device(config.device)?;
        let module = config.init(data.n_vertices(), &device);
        let b = config.batch_size.unwrap_or(data.n_shapes()).min(data.n_shapes());
        let bp = padded_width(b + config.augment);
        let workspace = Workspace::new(data.n_vertices(), config.components, config.layers, bp);
        let full_batch = (b == data.n_shapes()).then(|| data.batch_vcb_width(&(0..b).collect::<Vec<_>>(), bp));
        let augmenter = if config.augment > 0 {
            Some(Augmenter::new(config.augment_mix, config.augment_radius, data.n_vertices(), distances, config.seed)?)
        } else {
            None
        };
        let n_blocks = module.components.len();
        Ok(Trainer {
            optimizer: adam(&config),
            block_optimizers: (0..n_blocks).map(|_| adam(&config)).collect(),
            weights: Weights { layers: Vec::new(), c: Vec::new(), k: 0, n: 0, least_squares: false },
            rng: batch_rng(config.seed),
            maps: SupportMaps::new(config.components, data.n_vertices()),
            grads: Grads { layers: Vec::new(), c: Vec::new() },
            config,
            data,
            neighbors,
            distances,
            device,
            module: Some(module),
            iteration: 0,
            workspace,
            full_batch,
            graph_neighbors: None,
            last_loss: None,
            timings: StepTimings::default(),
            augmenter,
            batch_buf: Vec::new(),
            validation: None,
        })
    }

    /// Gives the run held-out shapes (`config.validation > 0`): every `validate_every` steps
    /// and at the end, the encode–decode feature error on them is measured and the parameters
    /// of the lowest one are what [`Self::into_model`] returns. (A resumed run starts the
    /// search afresh.)
    pub fn with_validation(mut self, data: &'a TrainingData) -> Result<Self> {
        if data.n_vertices() != self.data.n_vertices() {
            return Err(Error::Invalid(format!(
                "validation shapes have {} vertices, the training shapes {}",
                data.n_vertices(),
                self.data.n_vertices()
            )));
        }
        let b = data.n_shapes();
        let bp = padded_width(b);
        self.validation = Some(Validation {
            data,
            x: data.batch_vcb_width(&(0..b).collect::<Vec<_>>(), bp),
            workspace: Workspace::new(data.n_vertices(), self.config.components, self.config.layers, bp),
            best: None,
        });
        Ok(self)
    }

    /// Measures the validation error of the current parameters and keeps them if best.
    fn validate(&mut self) -> Result<Option<f64>> {
        let Some(v) = self.validation.as_mut() else { return Ok(None) };
        let module = self.module.as_ref().expect("module present between steps");
        let mut w = Weights::from_module(module)?;
        w.least_squares = self.config.encoder == EncoderKind::LeastSquares;
        let err = feature_error(&mut v.workspace, &w, self.neighbors, &v.x, v.data.n_shapes());
        if v.best.as_ref().is_none_or(|b| err < b.1) {
            v.best = Some((self.iteration, err, module.clone()));
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
        let ck = Checkpoint::load(checkpoint)?;
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
        let mut t = Trainer::new(config, data, neighbors, distances)?;
        let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(ck.module))
            .map_err(|e| Error::parse(checkpoint, None, format!("module record: {e}")))?;
        let module = t
            .module
            .take()
            .unwrap()
            .try_load_record(record)
            .map_err(|e| Error::parse(checkpoint, None, format!("module record: {e}")))?;
        t.module = Some(module);
        if ck.optimizers.len() != 1 + t.block_optimizers.len() {
            return Err(Error::parse(
                checkpoint,
                None,
                format!("expected {} optimizer records, found {}", 1 + t.block_optimizers.len(), ck.optimizers.len()),
            ));
        }
        let mut records = ck.optimizers.into_iter();
        let load = |bytes: Vec<u8>, cfg: &AutoencoderConfig| {
            adam(cfg)
                .from_bytes(Bytes::from_bytes_vec(bytes))
                .map_err(|e| Error::parse(checkpoint, None, format!("optimizer record: {e}")))
        };
        t.optimizer = load(records.next().unwrap(), &t.config)?;
        for (o, r) in t.block_optimizers.iter_mut().zip(records) {
            *o = load(r, &t.config)?;
        }
        t.iteration = ck.header.iteration;
        t.rng = Rng { state: ck.header.rng_state };
        t.last_loss = ck.header.last_loss;
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

    /// The current parameters.
    pub fn module(&self) -> &AutoencoderModule {
        self.module.as_ref().expect("module present between steps")
    }

    /// Current component centres (after at least one step).
    pub fn centers(&self) -> &[usize] {
        self.maps.centers()
    }

    /// One optimisation step. Errors (and leaves the parameters untouched) when the loss or a
    /// gradient is not finite.
    pub fn step(&mut self) -> Result<LossTerms> {
        let t0 = Instant::now();
        let mut w = std::mem::replace(
            &mut self.weights,
            Weights { layers: Vec::new(), c: Vec::new(), k: 0, n: 0, least_squares: false },
        );
        w.least_squares = self.config.encoder == EncoderKind::LeastSquares;
        let (module, read) = w.read_module_owned(self.module.take().expect("module present between steps"));
        self.module = Some(module);
        read.map_err(|e| Error::Numerical(format!("before iteration {}: {e}", self.iteration + 1)))?;
        let t1 = Instant::now();
        self.maps.update(&w.c, &self.config, self.distances)?;
        let t2 = Instant::now();
        let n_shapes = self.data.n_shapes();
        let b = self.config.batch_size.unwrap_or(n_shapes).min(n_shapes);
        if self.config.engine == Engine::Graph {
            let idx: Vec<usize> =
                if b == n_shapes { (0..n_shapes).collect() } else { self.rng.sample_distinct(n_shapes, b) };
            self.weights = w;
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
            return Ok(terms);
        }
        let bp = self.workspace.width();
        if self.full_batch.is_none() {
            let idx = self.rng.sample_distinct(n_shapes, b);
            self.batch_buf = self.data.batch_vcb_width(&idx, bp);
        }
        let x: &mut [f32] = match &mut self.full_batch {
            Some(x) => x,
            None => &mut self.batch_buf,
        };
        let m = self.config.augment;
        if let Some(aug) = &self.augmenter {
            let data = self.data;
            for j in 0..m {
                aug.draw(&|s| data.shape(s), n_shapes, &mut self.rng, |row, v| x[row * bp + b + j] = v);
            }
        }
        let terms = engine::loss_and_grad(
            &mut self.workspace,
            &w,
            self.neighbors,
            x,
            b + m,
            &self.maps,
            &self.config,
            &mut self.grads,
        );
        let t3 = Instant::now();
        if !terms.is_finite() {
            return Err(non_finite_loss(self.iteration + 1, &terms));
        }
        if let Some(p) = self.grads.first_non_finite() {
            return Err(Error::Numerical(format!(
                "a gradient is not finite at iteration {} ({p}); training stopped and no checkpoint was written for it",
                self.iteration + 1
            )));
        }
        self.weights = w;
        self.apply_gradients();
        self.iteration += 1;
        self.last_loss = Some(terms);
        let t4 = Instant::now();
        self.timings = StepTimings {
            snapshot: (t1 - t0).as_secs_f64(),
            support: (t2 - t1).as_secs_f64(),
            forward_backward: (t3 - t2).as_secs_f64(),
            optimizer: (t4 - t3).as_secs_f64(),
        };
        Ok(terms)
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
        let module = self.module.take().expect("module present between steps");
        let x = match &self.augmenter {
            None => self.data.batch_tensor(idx, &self.device),
            Some(aug) => {
                let (n, m) = (self.data.n_vertices(), self.config.augment);
                let mut v = Vec::with_capacity((idx.len() + m) * n * 9);
                for &s in idx {
                    v.extend_from_slice(self.data.shape(s));
                }
                let data = self.data;
                for _ in 0..m {
                    let start = v.len();
                    v.resize(start + n * 9, 0.0);
                    let dst = &mut v[start..];
                    aug.draw(&|s| data.shape(s), data.n_shapes(), &mut self.rng, |row, x| dst[row] = x);
                }
                Tensor::from_data(TensorData::new(v, [idx.len() + m, n, 9]), &self.device)
            }
        };
        let (loss, terms) = reference_loss(&module, x, nb, &self.maps, &self.config);
        if !terms.is_finite() {
            self.module = Some(module);
            return Err(non_finite_loss(self.iteration + 1, &terms));
        }
        let mut grads = GradientsParams::from_grads(loss.backward(), &module);
        let AutoencoderModule { layers, components } = module;
        let lr = self.config.learning_rate_at(self.iteration);
        let mut blocks = Vec::with_capacity(components.len());
        for (p, o) in components.into_iter().zip(self.block_optimizers.iter_mut()) {
            match grads.remove::<2>(p.id) {
                Some(g) => {
                    let mut gp = GradientsParams::new();
                    gp.register(p.id, g);
                    blocks.push(o.step(lr, p, gp));
                }
                None => blocks.push(p),
            }
        }
        let layers = self.optimizer.step(lr, layers, grads);
        self.module = Some(AutoencoderModule { layers, components: blocks });
        Ok(terms)
    }

    /// Registers the hand-computed gradients with Burn and runs Burn's Adam: the layers and
    /// every row block of `C` are separate modules for separate optimizers, stepped in parallel.
    fn apply_gradients(&mut self) {
        let dev = self.device.clone().inner();
        let lr = self.config.learning_rate_at(self.iteration);
        let AutoencoderModule { layers, components } = self.module.take().expect("module present between steps");
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
        let nc = 9 * self.neighbors.n_vertices();
        let grad_c = &self.grads.c;
        let opt = &mut self.optimizer;
        let (layers, components) = rayon::join(
            || opt.step(lr, layers, gp),
            || {
                components
                    .into_par_iter()
                    .zip(self.block_optimizers.par_iter_mut())
                    .enumerate()
                    .map(|(j, (p, o))| {
                        let rows = p.lazy_shape().dims::<2>()[0];
                        let start = j * COMPONENT_BLOCK * nc;
                        let g = grad_c[start..start + rows * nc].to_vec();
                        let mut gp = GradientsParams::new();
                        gp.register(p.id, Tensor::<2>::from_data(TensorData::new(g, [rows, nc]), &dev));
                        o.step(lr, p, gp)
                    })
                    .collect::<Vec<_>>()
            },
        );
        self.module = Some(AutoencoderModule { layers, components });
    }

    /// The current state as a checkpoint (errors if a parameter is not finite).
    pub fn checkpoint(&self) -> Result<Checkpoint> {
        // Never write NaN: the snapshot check covers every parameter.
        Weights::from_module(self.module())
            .map_err(|e| Error::Numerical(format!("refusing to write a checkpoint: {e}")))?;
        let module = self
            .module()
            .clone()
            .into_record()
            .into_bytes()
            .map_err(|e| Error::Invalid(format!("module record: {e}")))?;
        let mut optimizers = Vec::with_capacity(1 + self.block_optimizers.len());
        for o in std::iter::once(&self.optimizer).chain(&self.block_optimizers) {
            let b = o.into_bytes().map_err(|e| Error::Invalid(format!("optimizer record: {e}")))?;
            optimizers.push(b.to_vec());
        }
        Ok(Checkpoint {
            header: CheckpointHeader {
                iteration: self.iteration,
                rng_state: self.rng.state,
                config: self.config.clone(),
                n_vertices: self.neighbors.n_vertices(),
                n_shapes: self.data.n_shapes(),
                neighbor_fingerprint: self.neighbors.fingerprint(),
                last_loss: self.last_loss,
            },
            module: module.to_vec(),
            optimizers,
        })
    }

    /// Writes a checkpoint atomically to `path`.
    pub fn save_checkpoint(&self, path: &Path) -> Result<()> {
        self.checkpoint()?.save(path)
    }

    /// Runs until `config.iterations` steps are done or the stop flag is set, calling
    /// `on_iteration` after every step. Checkpoints every `checkpoint_every` steps, at the end,
    /// and when stopped. On a numerical error the run returns it and writes nothing.
    pub fn run(&mut self, options: &RunOptions, mut on_iteration: impl FnMut(&IterationReport)) -> Result<RunSummary> {
        let total = self.config.iterations;
        let mut steps = 0usize;
        let mut time = 0.0f64;
        let mut stopped = false;
        while self.iteration < total {
            if options.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst)) {
                stopped = true;
                break;
            }
            let t0 = Instant::now();
            let loss = self.step()?;
            let dt = t0.elapsed().as_secs_f64();
            time += dt;
            steps += 1;
            let ve = self.config.validate_every.max(1);
            if self.iteration.is_multiple_of(ve) || self.iteration == total {
                self.validate()?;
            }
            let every = self.config.checkpoint_every;
            let mut checkpointed = false;
            if let Some(path) = &options.checkpoint
                && ((every > 0 && self.iteration.is_multiple_of(every)) || self.iteration == total)
            {
                self.save_checkpoint(path)?;
                checkpointed = true;
            }
            on_iteration(&IterationReport {
                iteration: self.iteration,
                iterations: total,
                loss,
                step_seconds: dt,
                checkpointed,
            });
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
        })
    }

    /// The trained model for inference.
    pub fn into_model(self) -> Result<Autoencoder> {
        let module = match self.validation.and_then(|v| v.best) {
            Some((_, _, best)) => best,
            None => self.module.unwrap(),
        };
        let module = module.to_device(&default_device());
        Autoencoder::new(self.config, module, self.neighbors.clone())
    }
}
