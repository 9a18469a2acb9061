//! Hyperparameters of the mesh autoencoder (model, loss and training) in one struct, validated
//! once.

use serde::{Deserialize, Serialize};

use super::augment::AugmentMix;
use crate::error::{Error, Result};

/// Every hyperparameter of the autoencoder method. [`Default`] is the reference implementation's
/// (Tan et al. 2018; docs/design.md § Mesh autoencoder), which a model file written before a
/// field existed was trained with; [`AutoencoderConfig::recommended`] is meshdeco's default of
/// `kind = "autoencoder"` in a config file, chosen on validation frames across the shared
/// datasets (docs/autoencoder-default-candidates.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutoencoderConfig {
    /// Latent dimension K (number of deformation components).
    pub components: usize,
    /// Number L of 9 → 9 mesh-convolution layers in the encoder (mirrored in the decoder).
    pub layers: usize,
    /// Initial biases of the first layer: [`InitBias::Zero`] (the paper) or [`InitBias::Mean`]
    /// (the network starts at the training shapes' mean features).
    pub init_bias: InitBias,
    /// Standard deviation of the normal initialisation of the convolution weights and of C.
    pub init_std: f64,
    /// Adam learning rate (of the first step).
    pub learning_rate: f64,
    /// Learning rate of the last step: `None` keeps `learning_rate` throughout (the paper);
    /// otherwise the rate follows a cosine from `learning_rate` at step 1 down to this value at
    /// step `iterations` (a function of the step number only, so `--resume` is unaffected).
    pub learning_rate_final: Option<f64>,
    /// Training sets whose scaled features are larger than this (root-mean-square over the
    /// training shapes of each shape's Euclidean norm, in the scaled units of `scaling`) train
    /// with every step size (`learning_rate` and `learning_rate_final`) multiplied by
    /// `learning_rate_norm / norm`; 0: never scaled. The tied encoder's code `C·f` and its
    /// change under one Adam step grow with the features, so one rate does not hold across
    /// datasets: 1e-2 trains SCAPE (norm 28) and horse gallop (68–74) and diverges on cactus
    /// frames 1–10 (107) and face poses (233), which train at the scaled rate
    /// (docs/autoencoder-default-candidates.md).
    pub learning_rate_norm: f64,
    /// Restarts of a stalled run: when the mean reconstruction error of the last
    /// [`crate::nn::STALL_WINDOW`] steps at 10 % of `iterations` (at the earliest step 50) is still at or above
    /// the first step's, training starts again from the same initialisation with every step size
    /// halved, at most this many times (0: never; the paper). An early step too large for the
    /// data can saturate the decoder's tanh for hundreds of steps (cactus, seed 2: the error rose
    /// from 4 788 to 27 000 and stayed there for 1 000 of 2 000 steps); healthy runs on the
    /// shared datasets are at 0.4–4 % of the first step's error by then, so the check does not
    /// touch them.
    pub stall_restarts: usize,
    /// Adam β1.
    pub beta1: f64,
    /// Adam β2.
    pub beta2: f64,
    /// Adam ε.
    pub epsilon: f64,
    /// Number of optimisation steps.
    pub iterations: usize,
    /// Shapes per step; a number ≥ the number of shapes means full batch; `None`: full batch up
    /// to [`FULL_BATCH_UP_TO`] shapes, mini-batches of [`DEFAULT_MINI_BATCH`] beyond
    /// ([`AutoencoderConfig::batch_for`]). Mini-batches are drawn without replacement from the
    /// seeded generator, a shuffled pass over the shapes per epoch.
    pub batch_size: Option<usize>,
    /// Weight λ1 of the geodesic-weighted ℓ2,1 sparsity term on C.
    pub lambda1: f64,
    /// Weight λ2 of the hinge term on the latent codes.
    pub lambda2: f64,
    /// Threshold θ of the hinge `max(max_m |Z_km| − θ, 0)`.
    pub theta: f64,
    /// Normalised geodesic distance below which Λ = 0.
    pub d_min: f64,
    /// Normalised geodesic distance above which Λ = 1.
    pub d_max: f64,
    /// Write a checkpoint every this many iterations (0: only at the end / on stop).
    pub checkpoint_every: usize,
    /// Seed of the initialisation and of the mini-batch draws.
    pub seed: u64,
    /// How the loss and its gradients are computed (same mathematics either way).
    pub engine: Engine,
    /// Where the [`Engine::Graph`] computation runs.
    pub device: ComputeDevice,
    /// Synthetic shapes added to every step's batch ([`super::augment`]); 0: none (the paper).
    pub augment: usize,
    /// How the synthetic shapes are made.
    pub augment_mix: AugmentMix,
    /// [r_min, r_max] of the radius of a local mix's region (normalised geodesic distance).
    pub augment_radius: [f64; 2],
    /// Standard deviation σ of Gaussian noise added, afresh every step, to the encoder's input
    /// (the scaled features of every real and synthetic shape of the batch) while the decoding
    /// is compared with the clean shapes: a denoising autoencoder (0: none, the paper).
    pub input_noise: f64,
    /// Training shapes held out (evenly spaced) to choose the step whose parameters are kept:
    /// the one with the lowest encode–decode feature error on them; 0: none (the last step's).
    pub validation: usize,
    /// Steps between validation measurements (with `validation > 0`).
    pub validate_every: usize,
    /// The encoder's last map from the flattened features to the code.
    pub encoder: EncoderKind,
    /// Weight λo of the decorrelation term `(1/K) Σ_{k≠l} cos²(C_k, C_l)` on the rows of `C`
    /// (0: none, the paper). With near-orthogonal rows the tied encoder `z = C·f` inverts the
    /// decoder `f̂ = Cᵀz` for every code, not only the training shapes' codes.
    pub lambda_orthogonal: f64,
    /// Weight λc of the code term `(1/B) Σ_b Σ_k |z_bk − z_rest,k|`: the ℓ1 distance of every
    /// training shape's code from the rest shape's code (0: none, the paper). The rest shape
    /// (`data.rest`) rides along in every step as one more lane (reconstructed like a training
    /// shape), and the term pulls every other code towards it: each shape is explained by few
    /// components, which singles out the deformations that occur separately in the data from
    /// the rotations of them that reconstruct equally well. The trainer needs the rest shape's
    /// features for it ([`super::Trainer::with_rest`]).
    pub lambda_code: f64,
    /// Weight λv of the vertex term: the squared distance between the ACAP reconstructions of
    /// each decoded shape and of its input, summed over the vertices, in units of the rest
    /// bounding-box diagonal (0: none, the paper, which measures the error in feature space
    /// only). The trainer needs an [`super::output_loss::OutputLoss`] for it
    /// ([`super::Trainer::with_output_loss`]); only the hand engine computes it.
    pub lambda_vertex: f64,
    /// Shapes of each step's batch (synthetic ones included) that the vertex term sees, drawn
    /// afresh every step (its cost is two sparse solves per shape); 0 or at least the batch:
    /// all of them.
    pub vertex_batch: usize,
    /// Fraction of `iterations` over which the vertex term's weight rises linearly from 0 to
    /// `lambda_vertex` (in [0, 1]; 0: the full weight from the first step). Early decodings are
    /// far from any shape, and their vertex error can swamp the feature error.
    pub vertex_warmup: f64,
    /// Cap on the vertex term's gradient (with respect to the decoded features, in norm over the
    /// batch): at most this many times the feature error's (≥ 0; 0: no cap). The term is stiff
    /// (a rotation error at a joint moves a whole limb) and can take over the step and run away
    /// (horse gallop, 5 shapes, λv = 3: the loss rose from 2 to 33 000 in 25 steps); on SCAPE
    /// a cap of 2 binds often and costs accuracy.
    pub vertex_clip: f64,
    /// Residual passes of the encoder at inference (0: the paper's one pass `z = E(x)`): each
    /// pass sets `z ← z + E(x) − E(D(z))`, re-encoding what the decoding of the current code
    /// misses, with the network's own encoder and decoder (no fitting, no vertices; each pass
    /// costs one decode and one encode). Training does not use it.
    pub encoder_passes: usize,
    /// Gauss–Newton steps on the reconstructed vertices after the encoder and its passes (the
    /// pipeline's `ae_vertex_steps`: the decoder's exact Jacobian and the ACAP decoding's
    /// linearisation, each step moving the code towards the decoding closest to the shape in
    /// centroid-aligned vertex error). At most this many Jacobians: the steps stop earlier once
    /// a step converges or its last chord step lowers the error by less than
    /// `ae_vertex_steps::JACOBIAN_TOLERANCE` (0.5 %). 0: the network's code alone. Training does
    /// not use it.
    pub encoder_steps: usize,
}

/// How a training step computes the loss and the gradients.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Engine {
    /// Hand-written `f32` forward and backward pass on the CPU (SIMD, rayon): the fast default.
    #[default]
    Hand,
    /// Burn's autodiff graph of the same model and loss ([`super::loss::reference_loss`]) on
    /// [`AutoencoderConfig::device`]: the way onto a GPU, about 20–40× slower on the CPU.
    Graph,
}

impl Engine {
    /// Parses `hand` | `graph`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "hand" => Some(Engine::Hand),
            "graph" => Some(Engine::Graph),
            _ => None,
        }
    }
}

/// The encoder's map from the flattened features `f` to the code `z` (the decoder is
/// `f̂ = Cᵀz` either way).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EncoderKind {
    /// `z = C·f` (the paper: the decoder's matrix, transposed).
    #[default]
    Tied,
    /// `z = (C·Cᵀ + εI)⁻¹·C·f`: the code whose `Cᵀz` is closest to `f` (least squares), i.e.
    /// the exact inverse of the decoder's linear map for every code (ε = 10⁻⁶ × the mean
    /// diagonal). Same parameters as `tied`.
    LeastSquares,
}

/// Initial biases of the first mesh-convolution layer (the encoder's first, the decoder's last);
/// the other layers' biases start at 0 either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InitBias {
    /// 0 (the paper): a code of 0 decodes to features of 0, which in the scaled units are the
    /// middle of the training range, not the rest shape; the network must first learn the
    /// features' mean through `C`, whose curvature the mean's size makes large.
    #[default]
    Zero,
    /// Set from the mean `μ` of every feature channel over the training shapes' vertices:
    /// encoder `b = −(W_point + W_nb)·μ`, decoder `b_dec = atanh(μ)`: the encoder sees the
    /// deviations from the mean and a code of 0 decodes to the mean. On the planted body it
    /// leaves the rest-shape plateau of small deformations at once; on the planted face it
    /// finds fewer deformations (docs/ground-truth.md), hence not the default.
    Mean,
}

/// The Burn device of the [`Engine::Graph`] computation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ComputeDevice {
    /// Burn's ndarray backend on the CPU.
    #[default]
    Cpu,
    /// Burn's wgpu backend on the default GPU adapter (needs a build with `--features wgpu`).
    Wgpu,
}

impl ComputeDevice {
    /// Parses `cpu` | `wgpu`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "cpu" => Some(ComputeDevice::Cpu),
            "wgpu" => Some(ComputeDevice::Wgpu),
            _ => None,
        }
    }
}

impl Default for AutoencoderConfig {
    fn default() -> Self {
        AutoencoderConfig {
            components: 50,
            layers: 1,
            init_bias: InitBias::Zero,
            init_std: 0.02,
            learning_rate: 1e-3,
            learning_rate_final: None,
            learning_rate_norm: 0.0,
            stall_restarts: 0,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
            iterations: 2000,
            batch_size: None,
            lambda1: 0.5,
            lambda2: 0.5,
            theta: 5.0,
            d_min: 0.2,
            d_max: 0.4,
            checkpoint_every: 200,
            seed: 0,
            engine: Engine::Hand,
            device: ComputeDevice::Cpu,
            augment: 0,
            augment_mix: AugmentMix::Local,
            augment_radius: [0.1, 0.3],
            input_noise: 0.0,
            validation: 0,
            validate_every: 50,
            lambda_orthogonal: 0.0,
            lambda_code: 0.0,
            lambda_vertex: 0.0,
            vertex_batch: 0,
            vertex_warmup: 0.0,
            vertex_clip: 0.0,
            encoder_passes: 0,
            encoder_steps: 1,
            encoder: EncoderKind::Tied,
        }
    }
}

/// Training sets of up to this many shapes train on the full batch unless `batch_size` says
/// otherwise (SCAPE 36, horse, cactus and the face poses: the step the README's table measured).
pub const FULL_BATCH_UP_TO: usize = 64;

/// The default mini-batch of larger sets: chosen on the ground-truth face's validation set
/// (200 shapes × 4 000 vertices, docs/training-budget.md).
pub const DEFAULT_MINI_BATCH: usize = 32;

impl AutoencoderConfig {
    /// Shapes per step for a training set of `n_shapes` (see [`AutoencoderConfig::batch_size`]).
    pub fn batch_for(&self, n_shapes: usize) -> usize {
        match self.batch_size {
            Some(b) => b.min(n_shapes),
            None if n_shapes <= FULL_BATCH_UP_TO => n_shapes,
            None => DEFAULT_MINI_BATCH,
        }
    }

    /// meshdeco's default setting of `kind = "autoencoder"` (issue 31; chosen on validation
    /// frames of SCAPE, horse gallop, cactus, face poses and Spacetime faces:
    /// docs/autoencoder-default-candidates.md): the paper's model and loss, trained with a step
    /// size 1e-2 decaying to 1e-4 (scaled down on large features: `learning_rate_norm` 75),
    /// Adam β2 0.99, sparsity λ1 4, three synthetic shapes per step (`augment`), decorrelated
    /// components (`lambda_orthogonal` 10), and an encoder with two residual passes and up to
    /// five vertex steps (`encoder_steps`; they stop once a step's last chord step gains less
    /// than 0.5 %: one on SCAPE, two or three on the cactus); a run that stalls restarts with
    /// halved step sizes (`stall_restarts` 2). Since issue 53 (the recovery setting, chosen on
    /// the ground-truth validation sets: docs/ground-truth.md) the first layer's biases start at
    /// the training features' channel means (`init_bias` mean) and the step size starts at 5e-3
    /// (was 1e-2), with the method key `feature_weights = "noise"`, and the support maps' ramp
    /// runs from 0.3 to 0.7 of the largest geodesic distance (`support`; the paper's [0.2, 0.4]
    /// left deformations wider than a fifth of the mesh out of reach: docs/ground-truth.md
    /// § "The reconstruction gap"). The method's own keys
    /// `scaling`, `scaling_quantile` and `scaling_fence` default to `global`, 0.001 and 1 with it.
    pub fn recommended() -> Self {
        AutoencoderConfig {
            init_bias: InitBias::Mean,
            learning_rate: 5e-3,
            learning_rate_final: Some(1e-4),
            learning_rate_norm: 75.0,
            stall_restarts: 2,
            beta2: 0.99,
            lambda1: 4.0,
            augment: 3,
            lambda_orthogonal: 10.0,
            encoder_passes: 2,
            encoder_steps: 5,
            d_min: 0.3,
            d_max: 0.7,
            ..AutoencoderConfig::default()
        }
    }

    /// The configuration of the `restart`-th restart of a stalled run
    /// ([`AutoencoderConfig::stall_restarts`]): `learning_rate` and `learning_rate_final` times
    /// 2^−restart, everything else unchanged.
    pub fn restarted(&self, restart: usize) -> Self {
        let f = 0.5f64.powi(restart as i32);
        AutoencoderConfig {
            learning_rate: self.learning_rate * f,
            learning_rate_final: self.learning_rate_final.map(|r| r * f),
            ..self.clone()
        }
    }

    /// Weight of the vertex term at 0-based step `t`: `lambda_vertex`, ramped up linearly over
    /// the first `vertex_warmup · iterations` steps (a function of the step number only, so
    /// `--resume` is unaffected).
    pub fn lambda_vertex_at(&self, t: usize) -> f64 {
        let ramp = self.vertex_warmup * self.iterations as f64;
        if ramp <= 0.0 { self.lambda_vertex } else { self.lambda_vertex * ((t + 1) as f64 / ramp).min(1.0) }
    }

    /// Factor on every step size for training features of root-mean-square norm `norm` (see
    /// [`AutoencoderConfig::learning_rate_norm`]): `min(1, learning_rate_norm / norm)`, 1 when
    /// `learning_rate_norm` is 0 or `norm` is not positive.
    pub fn learning_rate_scale(&self, norm: f64) -> f64 {
        if self.learning_rate_norm > 0.0 && norm > self.learning_rate_norm {
            self.learning_rate_norm / norm
        } else {
            1.0
        }
    }

    /// Adam step size of 0-based step `t` before the data's factor (see
    /// [`AutoencoderConfig::learning_rate_final`] and [`Self::learning_rate_scale`]).
    pub fn learning_rate_at(&self, t: usize) -> f64 {
        match self.learning_rate_final {
            None => self.learning_rate,
            Some(last) => {
                let span = self.iterations.saturating_sub(1).max(1) as f64;
                let u = (t as f64 / span).min(1.0);
                last + (self.learning_rate - last) * 0.5 * (1.0 + (std::f64::consts::PI * u).cos())
            }
        }
    }
}

fn bad(key: &str, message: String) -> Error {
    Error::config(key, message)
}

impl AutoencoderConfig {
    /// Checks every value; the error names the key and the bad value.
    pub fn validate(&self) -> Result<()> {
        if self.components == 0 {
            return Err(bad("components", "0 must be at least 1".into()));
        }
        if self.layers == 0 || self.layers > 16 {
            return Err(bad("layers", format!("{} must be in 1..=16", self.layers)));
        }
        let pos = |key: &str, v: f64| -> Result<()> {
            if v.is_finite() && v > 0.0 { Ok(()) } else { Err(bad(key, format!("{v} must be a positive number"))) }
        };
        let nonneg = |key: &str, v: f64| -> Result<()> {
            if v.is_finite() && v >= 0.0 { Ok(()) } else { Err(bad(key, format!("{v} must be a finite number ≥ 0"))) }
        };
        pos("init_std", self.init_std)?;
        pos("learning_rate", self.learning_rate)?;
        nonneg("learning_rate_norm", self.learning_rate_norm)?;
        if let Some(f) = self.learning_rate_final {
            pos("learning_rate_final", f)?;
            if f > self.learning_rate {
                return Err(bad(
                    "learning_rate_final",
                    format!("learning_rate_final ({f}) must not exceed learning_rate ({})", self.learning_rate),
                ));
            }
        }
        pos("epsilon", self.epsilon)?;
        for (k, v) in [("beta1", self.beta1), ("beta2", self.beta2)] {
            if !(v.is_finite() && (0.0..1.0).contains(&v)) {
                return Err(bad(k, format!("{v} must be in [0, 1)")));
            }
        }
        if self.batch_size == Some(0) {
            return Err(bad("batch_size", "0 must be at least 1".into()));
        }
        nonneg("lambda1", self.lambda1)?;
        nonneg("lambda2", self.lambda2)?;
        nonneg("lambda_orthogonal", self.lambda_orthogonal)?;
        nonneg("lambda_code", self.lambda_code)?;
        nonneg("lambda_vertex", self.lambda_vertex)?;
        nonneg("vertex_clip", self.vertex_clip)?;
        nonneg("input_noise", self.input_noise)?;
        if self.stall_restarts > 8 {
            return Err(bad("stall_restarts", format!("{} must be in 0..=8", self.stall_restarts)));
        }
        if self.encoder_steps > 50 {
            return Err(bad("encoder_steps", format!("{} must be in 0..=50", self.encoder_steps)));
        }
        if self.encoder_passes > 16 {
            return Err(bad("encoder_passes", format!("{} must be in 0..=16", self.encoder_passes)));
        }
        if !(self.vertex_warmup.is_finite() && (0.0..=1.0).contains(&self.vertex_warmup)) {
            return Err(bad("vertex_warmup", format!("{} must be in [0, 1]", self.vertex_warmup)));
        }
        nonneg("theta", self.theta)?;
        nonneg("d_min", self.d_min)?;
        nonneg("d_max", self.d_max)?;
        if self.d_min >= self.d_max {
            return Err(bad("d_min", format!("d_min ({}) must be below d_max ({})", self.d_min, self.d_max)));
        }
        let [r0, r1] = self.augment_radius;
        if !(r0.is_finite() && r1.is_finite() && r0 > 0.0 && r0 <= r1) {
            return Err(bad(
                "augment_radius",
                format!("[{r0}, {r1}] must be two positive numbers, the first ≤ the second"),
            ));
        }
        if self.validation > 0 && self.validate_every == 0 {
            return Err(bad("validate_every", "0 must be at least 1 when validation > 0".into()));
        }
        if self.encoder == EncoderKind::LeastSquares && self.engine == Engine::Graph {
            return Err(bad(
                "encoder",
                "encoder = \"least-squares\" needs engine = \"hand\" (the graph engine has the tied encoder only)"
                    .into(),
            ));
        }
        if self.lambda_vertex > 0.0 && self.engine == Engine::Graph {
            return Err(bad(
                "lambda_vertex",
                format!("{} needs engine = \"hand\" (the graph engine has no vertex term)", self.lambda_vertex),
            ));
        }
        if self.input_noise > 0.0 && self.engine == Engine::Graph {
            return Err(bad(
                "input_noise",
                format!("{} needs engine = \"hand\" (the graph engine has no input noise)", self.input_noise),
            ));
        }
        if self.device == ComputeDevice::Wgpu {
            if self.engine != Engine::Graph {
                return Err(bad(
                    "device",
                    "device = \"wgpu\" needs engine = \"graph\" (the hand engine is CPU code)".into(),
                ));
            }
            if !cfg!(feature = "wgpu") {
                return Err(bad(
                    "device",
                    "device = \"wgpu\" needs a build with the wgpu feature (cargo build --release --features wgpu)"
                        .into(),
                ));
            }
        }
        Ok(())
    }

    /// Checks that `other` describes the same model and loss (what a checkpoint must agree on to
    /// be resumed; `iterations` and `checkpoint_every` may differ).
    pub fn check_resumable(&self, other: &AutoencoderConfig) -> Result<()> {
        let mut a = self.clone();
        let mut b = other.clone();
        a.iterations = 0;
        b.iterations = 0;
        a.checkpoint_every = 0;
        b.checkpoint_every = 0;
        // Compared as the batch each resolves to, by `Trainer::resume_from` (a checkpoint's
        // header records it): `None` meant the full batch before issue 57.
        a.batch_size = None;
        b.batch_size = None;
        // Inference only.
        a.encoder_passes = 0;
        b.encoder_passes = 0;
        a.encoder_steps = 0;
        b.encoder_steps = 0;
        // Both engines compute the same step; a run may switch between them.
        (a.engine, a.device) = (Engine::Hand, ComputeDevice::Cpu);
        (b.engine, b.device) = (Engine::Hand, ComputeDevice::Cpu);
        if a != b {
            let sa = serde_json::to_string(&a).unwrap_or_default();
            let sb = serde_json::to_string(&b).unwrap_or_default();
            return Err(Error::Invalid(format!(
                "the checkpoint was written with different hyperparameters: checkpoint {sb}, now {sa}"
            )));
        }
        Ok(())
    }

    /// The Λ ramp: 0 below `d_min`, 1 above `d_max`, linear between (non-finite d gives 1).
    pub fn support_weight(&self, d: f64) -> f64 {
        if !d.is_finite() || d > self.d_max {
            1.0
        } else if d < self.d_min {
            0.0
        } else {
            (d - self.d_min) / (self.d_max - self.d_min)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_batch_is_full_up_to_64_shapes_then_32() {
        let d = AutoencoderConfig::default();
        assert_eq!((d.batch_for(36), d.batch_for(64), d.batch_for(65), d.batch_for(20_000)), (36, 64, 32, 32));
        let b = AutoencoderConfig { batch_size: Some(100), ..Default::default() };
        assert_eq!((b.batch_for(36), b.batch_for(200)), (36, 100));
    }

    #[test]
    fn learning_rate_norm_scales_only_larger_features() {
        let off = AutoencoderConfig { learning_rate_norm: 0.0, ..Default::default() };
        assert_eq!(off.learning_rate_scale(1e6), 1.0);
        let c = AutoencoderConfig { learning_rate_norm: 75.0, ..Default::default() };
        assert_eq!(c.learning_rate_scale(28.0), 1.0);
        assert_eq!(c.learning_rate_scale(75.0), 1.0);
        assert!((c.learning_rate_scale(150.0) - 0.5).abs() < 1e-15);
        assert_eq!(c.learning_rate_scale(0.0), 1.0);
        let bad = AutoencoderConfig { learning_rate_norm: -1.0, ..Default::default() };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("learning_rate_norm") && e.contains("-1"), "{e}");
        // The recommended setting validates and differs from the paper's where documented.
        let r = AutoencoderConfig::recommended();
        r.validate().unwrap();
        assert_eq!((r.learning_rate, r.learning_rate_final, r.learning_rate_norm), (5e-3, Some(1e-4), 75.0));
        assert_eq!((r.init_bias, AutoencoderConfig::default().init_bias), (InitBias::Mean, InitBias::Zero));
        assert_eq!((r.beta2, r.lambda1, r.augment, r.lambda_orthogonal, r.encoder_passes), (0.99, 4.0, 3, 10.0, 2));
        assert_eq!((r.encoder_steps, AutoencoderConfig::default().encoder_steps), (5, 1));
        assert_eq!((r.stall_restarts, AutoencoderConfig::default().stall_restarts), (2, 0));
        let paper = AutoencoderConfig::default();
        assert_eq!((r.d_min, r.d_max, paper.d_min, paper.d_max), (0.3, 0.7, 0.2, 0.4));
        let h = r.restarted(2);
        assert_eq!((h.learning_rate, h.learning_rate_final, h.beta2), (1.25e-3, Some(2.5e-5), r.beta2));
        assert_eq!(r.restarted(0), r);
        assert_eq!(AutoencoderConfig { ..r.clone() }.iterations, AutoencoderConfig::default().iterations);
    }

    #[test]
    fn cosine_schedule_runs_from_first_to_final_rate() {
        let constant = AutoencoderConfig { learning_rate: 3e-3, ..Default::default() };
        assert_eq!(constant.learning_rate_at(0), 3e-3);
        assert_eq!(constant.learning_rate_at(1999), 3e-3);
        let c = AutoencoderConfig {
            learning_rate: 1e-2,
            learning_rate_final: Some(1e-4),
            iterations: 101,
            ..Default::default()
        };
        assert!((c.learning_rate_at(0) - 1e-2).abs() < 1e-15);
        assert!((c.learning_rate_at(100) - 1e-4).abs() < 1e-15);
        assert!((c.learning_rate_at(50) - 0.5 * (1e-2 + 1e-4)).abs() < 1e-12);
        for t in 0..100 {
            assert!(c.learning_rate_at(t + 1) <= c.learning_rate_at(t), "not decreasing at {t}");
        }
        let bad = AutoencoderConfig { learning_rate: 1e-3, learning_rate_final: Some(1e-2), ..Default::default() };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("learning_rate_final (0.01) must not exceed learning_rate (0.001)"), "{e}");
    }

    #[test]
    fn validation_names_key_and_value() {
        assert!(AutoencoderConfig::default().validate().is_ok());
        let c = AutoencoderConfig { d_min: 0.8, d_max: 0.7, ..Default::default() };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("d_min (0.8) must be below d_max (0.7)"), "{e}");
        let c = AutoencoderConfig { learning_rate: -1.0, ..Default::default() };
        assert!(c.validate().unwrap_err().to_string().contains("learning_rate"));
        let c: AutoencoderConfig = serde_json::from_str(r#"{"components": 7}"#).unwrap();
        assert_eq!(c.components, 7);
        assert_eq!(c.iterations, 2000);
        assert!(serde_json::from_str::<AutoencoderConfig>(r#"{"componets": 7}"#).is_err());
        let cfg = AutoencoderConfig::default();
        assert_eq!(cfg.support_weight(0.1), 0.0);
        assert_eq!(cfg.support_weight(0.5), 1.0);
        assert!((cfg.support_weight(0.3) - 0.5).abs() < 1e-12);
        assert_eq!(cfg.support_weight(f64::INFINITY), 1.0);
    }
}
