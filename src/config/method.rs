//! The `[method]` table, typed: one struct per method with its keys, its defaults (in its
//! `Default`) and its validation, gathered in [`MethodConfig`], a serde enum tagged by `kind`.
//!
//! Each struct is parsed with `deny_unknown_fields` and validated once, where it is parsed
//! ([`MethodConfig::from_table`]); errors name `method.<key>` and the bad value. Serialising a
//! parsed struct writes every key with its resolved value (the artefact's `config.toml`), and
//! that text parses back to the same struct.
//!
//! The defaults come from the methods' own hyperparameter structs ([`SplocsConfig`],
//! [`SegmentationConfig`], [`RegionPcaConfig`], [`AutoencoderConfig`]), and the value checks are
//! theirs too ([`MethodSettings::validate`] builds the method's struct and calls its
//! `validate`), so a rule is written once.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::methods::WeightConstraint;
use crate::methods::region_pca::RegionPcaConfig;
use crate::methods::segmentation::SegmentationConfig;
use crate::methods::splocs::{AdmmConfig, SplocsConfig};
use crate::nn::augment::AugmentMix;
use crate::nn::config::{AutoencoderConfig, ComputeDevice, EncoderKind, Engine, InitBias};
use crate::representation::RepresentationKind;
use crate::representation::acap::{Consistency, FeatureMap};
use crate::representation::scaling::ScalingMode;

/// Method kinds (the `kind` key).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MethodKind {
    Pca,
    Splocs,
    RegionPca,
    Autoencoder,
}

impl MethodKind {
    /// Name as written in configs and model headers.
    pub fn name(self) -> &'static str {
        match self {
            MethodKind::Pca => "pca",
            MethodKind::Splocs => "splocs",
            MethodKind::RegionPca => "region-pca",
            MethodKind::Autoencoder => "autoencoder",
        }
    }

    /// Every kind, in the order the docs list them.
    pub const ALL: [MethodKind; 4] =
        [MethodKind::Autoencoder, MethodKind::Splocs, MethodKind::Pca, MethodKind::RegionPca];

    /// Parses a config name.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }
}

/// What the autoencoder's 9 numbers per vertex are (`features` key): `acap` (the paper's logR
/// and S, the default) | `gradient` (the 1-ring deformation gradient minus the identity,
/// T − I: deformations that add in positions add in it). See
/// [`crate::representation::acap::FeatureMap`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AeFeatures {
    #[default]
    Acap,
    Gradient,
}

impl AeFeatures {
    /// The representation's feature map.
    pub fn to_map(self) -> FeatureMap {
        match self {
            AeFeatures::Acap => FeatureMap::RotationStretch,
            AeFeatures::Gradient => FeatureMap::Gradient,
        }
    }

    /// Name as written in configs and headers (the feature map's).
    pub fn name(self) -> &'static str {
        self.to_map().name()
    }

    /// Whether this is the default (`skip_serializing_if`: configs and model headers that leave
    /// it out read back alike).
    pub fn is_default(&self) -> bool {
        *self == AeFeatures::default()
    }
}

/// ACAP rotation consistency (`consistency` key): `bfs` | `global`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ConsistencyName {
    Bfs,
    #[default]
    Global,
}

impl ConsistencyName {
    /// The representation's option.
    pub fn to_acap(self) -> Consistency {
        match self {
            ConsistencyName::Bfs => Consistency::Bfs,
            ConsistencyName::Global => Consistency::Global,
        }
    }
    /// Name as written in configs and headers.
    pub fn name(self) -> &'static str {
        match self {
            ConsistencyName::Bfs => "bfs",
            ConsistencyName::Global => "global",
        }
    }
}

/// Feature scaling of the autoencoder (`scaling` key).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ScalingName {
    /// One range per feature dimension (the paper).
    #[default]
    PerDimension,
    /// The reference code's: one range for the 3 rotation dims, one for the 6 stretch dims.
    Grouped,
    /// One range for all 9 dimensions.
    Global,
}

impl ScalingName {
    /// The scaling mode of [`crate::representation::scaling`].
    pub fn mode(self) -> ScalingMode {
        match self {
            ScalingName::PerDimension => ScalingMode::PerDimension,
            ScalingName::Grouped => ScalingMode::reference_grouped(),
            ScalingName::Global => ScalingMode::Grouped { groups: vec![(0..9).collect()] },
        }
    }
}

/// A painted vertex set: inline indices or a file of whitespace/comma-separated indices.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum FixedCenter {
    Vertices(Vec<usize>),
    File(PathBuf),
}

impl FixedCenter {
    /// The vertex indices (reading the file for [`FixedCenter::File`]).
    pub fn read(&self) -> Result<Vec<usize>> {
        match self {
            FixedCenter::Vertices(v) => Ok(v.clone()),
            FixedCenter::File(p) => {
                let text = std::fs::read_to_string(p).map_err(|e| Error::io(p, e))?;
                text.split(|ch: char| ch.is_whitespace() || ch == ',')
                    .filter(|t| !t.is_empty())
                    .enumerate()
                    .map(|(i, t)| {
                        t.parse::<usize>().map_err(|_| {
                            Error::parse(p, None, format!("entry {} (`{t}`) is not a vertex index", i + 1))
                        })
                    })
                    .collect()
            }
        }
    }
}

/// Default heat-method factor for SPLOCS support maps (the reference's m = 10).
pub const SPLOCS_GEODESIC_M: f64 = 10.0;
/// Default heat-method factor for the autoencoder's support maps (Crane et al.'s m = 1).
pub const AE_GEODESIC_M: f64 = 1.0;

/// `kind = "pca"`: holistic PCA of the training features.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PcaMethod {
    /// Number of components K (≤ the number of training frames).
    pub components: usize,
    /// `displacement` | `triangle-gradient` | `acap`.
    pub representation: RepresentationKind,
    /// Accepted for a uniform configuration; PCA is deterministic.
    pub seed: u64,
    /// ACAP rotation consistency (acap only).
    pub consistency: ConsistencyName,
}

impl Default for PcaMethod {
    fn default() -> Self {
        PcaMethod {
            components: 50,
            representation: RepresentationKind::Displacement,
            seed: 0,
            consistency: ConsistencyName::Global,
        }
    }
}

/// `kind = "splocs"`: sparse localized deformation components (Neumann et al. 2013).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SplocsMethod {
    pub components: usize,
    /// `displacement` | `triangle-gradient` | `acap`.
    pub representation: RepresentationKind,
    /// λ, weight of the group-sparsity term.
    pub sparsity: f64,
    /// [d_min, d_max] of the support maps (unit-box geodesic distance).
    pub support: [f64; 2],
    /// `nonnegative` (Eq. 4) | `signed` (Eq. 3).
    pub weights: WeightConstraint,
    /// Relative soft threshold of the weights (0: none, the reference).
    #[serde(skip_serializing_if = "is_zero_f64")]
    pub weight_sparsity: f64,
    pub max_iterations: usize,
    pub admm: AdmmConfig,
    /// Convergence: mean relative objective change over the last 5 iterations (0: never stop early).
    pub tolerance: f64,
    pub seed: u64,
    /// Painted vertex sets fixing the first components' centres.
    pub fixed_centers: Vec<FixedCenter>,
    /// Heat-method time factor m (t = m·h²) of the support maps.
    pub geodesic_m: f64,
    /// ACAP rotation consistency (acap only).
    pub consistency: ConsistencyName,
    /// Threads of the component update: 0 (default) as many as the machine has, 1 sequential.
    #[serde(skip_serializing_if = "is_zero")]
    pub threads: usize,
}

/// The one map between [`SplocsMethod`]'s keys and [`SplocsConfig`]'s fields (same names;
/// `fixed_centers` are read from files on the way in). Both directions name every field (no
/// `..`), so a solver field without a key is a compile error.
macro_rules! splocs_keys {
    ($($field:ident),* $(,)?) => {
        impl SplocsMethod {
            fn from_solver(c: SplocsConfig, representation: RepresentationKind, geodesic_m: f64, consistency: ConsistencyName) -> Self {
                let SplocsConfig { fixed_centers, $($field),* } = c;
                SplocsMethod {
                    representation,
                    geodesic_m,
                    consistency,
                    fixed_centers: fixed_centers.into_iter().map(FixedCenter::Vertices).collect(),
                    $($field),*
                }
            }

            fn solver_config_with(&self, fixed_centers: Vec<Vec<usize>>) -> SplocsConfig {
                let SplocsMethod {
                    representation: _,
                    geodesic_m: _,
                    consistency: _,
                    fixed_centers: _,
                    $($field),*
                } = self.clone();
                SplocsConfig { fixed_centers, $($field),* }
            }
        }
    };
}

splocs_keys!(components, sparsity, support, weights, weight_sparsity, max_iterations, admm, tolerance, seed, threads);

fn is_zero_f64(x: &f64) -> bool {
    *x == 0.0
}

impl Default for SplocsMethod {
    fn default() -> Self {
        let solver = SplocsConfig { threads: 0, ..SplocsConfig::default() };
        SplocsMethod::from_solver(solver, RepresentationKind::Displacement, SPLOCS_GEODESIC_M, ConsistencyName::Global)
    }
}

impl SplocsMethod {
    /// The solver's hyperparameters, with the painted sets read (files are read here).
    pub fn solver_config(&self) -> Result<SplocsConfig> {
        let fixed_centers = self.fixed_centers.iter().map(FixedCenter::read).collect::<Result<Vec<_>>>()?;
        Ok(self.solver_config_with(fixed_centers))
    }
}

/// `kind = "region-pca"`: segmentation + one PCA per region (Tena et al. 2011).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegionPcaMethod {
    /// Total component budget K over the regions.
    pub components: usize,
    /// Only `displacement`.
    pub representation: RepresentationKind,
    pub seed: u64,
    /// λ ∈ [0, 1]: weight of the correlation term.
    pub lambda: f64,
    /// Decay length of exp(−G/r) in model units; absent: 0.1 × the rest mesh's diagonal (the
    /// trained model's `config.toml` records the value used).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub r: Option<f64>,
    /// Correlation threshold in [−1, 1].
    pub threshold: f64,
    /// Fixed number of regions (skips the automatic search).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub regions: Option<usize>,
    /// Largest k of the automatic search (default 20).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_regions: Option<usize>,
    /// Fragment merging fraction in [0, 1).
    pub min_piece: f64,
    /// Try every k up to `max_regions` and keep the largest compact one.
    pub keep_searching: bool,
    /// β of the coupled encoding.
    pub beta: f64,
    /// Default γ of posing.
    pub gamma: f64,
}

impl Default for RegionPcaMethod {
    fn default() -> Self {
        let s = SegmentationConfig::default();
        let r = RegionPcaConfig::default();
        RegionPcaMethod {
            components: r.components,
            representation: RepresentationKind::Displacement,
            seed: s.seed,
            lambda: s.lambda,
            r: s.r,
            threshold: s.threshold,
            regions: s.regions,
            max_regions: None,
            min_piece: s.min_piece,
            keep_searching: s.keep_searching,
            beta: r.beta,
            gamma: crate::methods::posing::PoseConfig::default().gamma,
        }
    }
}

impl RegionPcaMethod {
    /// The segmentation's hyperparameters.
    pub fn segmentation(&self) -> SegmentationConfig {
        let d = SegmentationConfig::default();
        SegmentationConfig {
            lambda: self.lambda,
            r: self.r,
            threshold: self.threshold,
            regions: self.regions,
            max_regions: self.max_regions.unwrap_or(d.max_regions),
            seed: self.seed,
            min_piece: self.min_piece,
            keep_searching: self.keep_searching,
            ..d
        }
    }
    /// The per-region PCA's hyperparameters.
    pub fn region_pca(&self) -> RegionPcaConfig {
        RegionPcaConfig { components: self.components, beta: self.beta }
    }
}

/// `kind = "autoencoder"`: the mesh-convolutional autoencoder (Tan et al. 2018).
///
/// Every field of the network's [`AutoencoderConfig`] is a key here, under the same name
/// (except `d_min`/`d_max`, written `support = [d_min, d_max]`), with its meaning documented
/// there; [`network_keys!`] maps the two both ways, naming every field, so a new network field
/// does not compile until it is a key. The method's own keys: `geodesic_m`, `scaling`,
/// `scaling_quantile`, `scaling_fence`, `consistency`, `fit_test`, `dial_sparsity`, `feature_weights`,
/// `decoder_edge_weight`. Keys at their default that older configs did not have are left out
/// of a written `config.toml` (`skip_serializing_if`); they parse back to the same value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AutoencoderMethod {
    pub components: usize,
    /// [d_min, d_max] of the support maps (geodesic distance / its maximum).
    pub support: [f64; 2],
    pub seed: u64,
    /// Heat-method time factor m of the support maps.
    pub geodesic_m: f64,
    pub iterations: usize,
    pub learning_rate: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub learning_rate_final: Option<f64>,
    /// Feature norm above which the step sizes are scaled down by this / norm (0: never).
    pub learning_rate_norm: f64,
    /// Restarts with halved step sizes of a run that stalls (0: never).
    pub stall_restarts: usize,
    pub beta1: f64,
    pub beta2: f64,
    /// Adam ε (default 1e-8).
    #[serde(skip_serializing_if = "network_default::epsilon")]
    pub epsilon: f64,
    /// Standard deviation of the normal initialisation (default 0.02).
    #[serde(skip_serializing_if = "network_default::init_std")]
    pub init_std: f64,
    /// `zero` (the paper) | `mean` (the default since issue 53): the first layer's initial
    /// biases ([`InitBias`]). Always written: configs written before issue 53 left out `zero`,
    /// then the default.
    pub init_bias: InitBias,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub batch_size: Option<usize>,
    pub layers: usize,
    pub lambda1: f64,
    pub lambda2: f64,
    pub theta: f64,
    pub checkpoint_every: usize,
    /// `per-dimension` | `grouped` | `global`.
    pub scaling: ScalingName,
    /// Quantile q of the outlier fence: the training features' q … 1 − q range [a, b], widened
    /// by `scaling_fence` × (b − a) each side, is what the scaling maps to [−0.95, 0.95] where it
    /// lies inside the minimum and maximum, values beyond clamped (0: the minimum and maximum,
    /// the paper; in [0, 0.05]; [`crate::representation::scaling`]).
    pub scaling_quantile: f64,
    /// Width of the outlier fence beyond the quantile range, in multiples of it (≥ 0).
    pub scaling_fence: f64,
    pub consistency: ConsistencyName,
    /// `acap` | `gradient`: what the network's 9 numbers per vertex are ([`AeFeatures`]).
    #[serde(skip_serializing_if = "AeFeatures::is_default")]
    pub features: AeFeatures,
    /// `hand` | `graph`.
    pub engine: Engine,
    /// `cpu` | `wgpu`.
    pub device: ComputeDevice,
    /// Also report `test_erms_fitted`.
    pub fit_test: bool,
    /// How the dials are read from the latent space after training: `"auto"` (the default) or
    /// a sparsity λ in [0, 1) ([`DialSparsity`]).
    pub dial_sparsity: DialSparsity,
    /// `uniform` | `noise`: how each vertex's feature error counts in the loss
    /// ([`FeatureWeights`]).
    pub feature_weights: FeatureWeights,
    /// Edge weight μ of the ACAP decoder that turns the network's output features into vertices
    /// ([`crate::representation::acap::AcapDecoder::FitInverse`]; default
    /// [`AE_DECODER_EDGE_WEIGHT`]). An inference key: stored in `model.json`, models trained
    /// before it get the default.
    #[serde(skip_serializing_if = "is_default_decoder_edge_weight")]
    pub decoder_edge_weight: f64,
    /// Power p of the per-vertex weights of that decoder's fit residual: vertex i's residual
    /// counts ω_i = w_i^p, w_i its noise weight ([`crate::representation::noise_sensitivity::noise_weights`]
    /// of the raw ACAP features); 0: every vertex alike (the paper's decoding; default
    /// [`AE_DECODER_NOISE_POWER`]). An inference key like `decoder_edge_weight`.
    #[serde(skip_serializing_if = "is_default_decoder_noise_power")]
    pub decoder_noise_power: f64,
    /// Synthetic shapes per training step (augmentation in feature space; 0: none).
    pub augment: usize,
    /// `local` | `blend` | `mixed` (default `local`).
    #[serde(skip_serializing_if = "network_default::augment_mix")]
    pub augment_mix: AugmentMix,
    /// [r_min, r_max] of a local mix's region radius (default [0.1, 0.3]).
    #[serde(skip_serializing_if = "network_default::augment_radius")]
    pub augment_radius: [f64; 2],
    /// Standard deviation of Gaussian noise added to the encoder's input features (scaled
    /// units) while the decoding is compared with the clean shapes (0: none).
    #[serde(skip_serializing_if = "network_default::input_noise")]
    pub input_noise: f64,
    /// Training shapes held out to choose the kept step (0: none).
    #[serde(skip_serializing_if = "network_default::validation")]
    pub validation: usize,
    /// Steps between validation measurements (default 50).
    #[serde(skip_serializing_if = "network_default::validate_every")]
    pub validate_every: usize,
    /// `tied` (the paper) | `least-squares`.
    #[serde(skip_serializing_if = "network_default::encoder")]
    pub encoder: EncoderKind,
    /// Weight of the decorrelation term on the rows of C (0: none).
    pub lambda_orthogonal: f64,
    /// Weight of the code term: ℓ1 distance of the training codes from the rest shape's (0: none).
    #[serde(skip_serializing_if = "network_default::lambda_code")]
    pub lambda_code: f64,
    /// Weight of the vertex term (0: none).
    #[serde(skip_serializing_if = "network_default::lambda_vertex")]
    pub lambda_vertex: f64,
    /// Shapes per step the vertex term sees (default 0: all).
    #[serde(skip_serializing_if = "network_default::vertex_batch")]
    pub vertex_batch: usize,
    /// Fraction of the iterations over which the vertex term's weight ramps up (default 0).
    #[serde(skip_serializing_if = "network_default::vertex_warmup")]
    pub vertex_warmup: f64,
    /// Cap on the vertex term's gradient, in multiples of the feature error's (default 0: none).
    #[serde(skip_serializing_if = "network_default::vertex_clip")]
    pub vertex_clip: f64,
    /// Residual passes of the encoder at inference (0: the paper's one pass).
    pub encoder_passes: usize,
    /// Gauss–Newton steps of the encoder on the reconstructed vertices at inference (0: none).
    #[serde(skip_serializing_if = "network_default::encoder_steps")]
    pub encoder_steps: usize,
}

fn is_default_decoder_edge_weight(w: &f64) -> bool {
    *w == AE_DECODER_EDGE_WEIGHT
}

fn is_default_decoder_noise_power(p: &f64) -> bool {
    *p == AE_DECODER_NOISE_POWER
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// `skip_serializing_if` predicates: the value equals [`AutoencoderConfig::recommended`]'s (the
/// default of a config file's keys).
mod network_default {
    use crate::nn::config::AutoencoderConfig;
    macro_rules! is_default {
        ($($field:ident: $t:ty),* $(,)?) => {$(
            pub fn $field(v: &$t) -> bool {
                *v == AutoencoderConfig::recommended().$field
            }
        )*};
    }
    is_default!(
        epsilon: f64,
        init_std: f64,
        augment_mix: crate::nn::augment::AugmentMix,
        augment_radius: [f64; 2],
        input_noise: f64,
        validation: usize,
        validate_every: usize,
        encoder: crate::nn::config::EncoderKind,
        lambda_vertex: f64,
        lambda_code: f64,
        vertex_batch: usize,
        vertex_warmup: f64,
        vertex_clip: f64,
        encoder_steps: usize,
    );
}

/// The one map between [`AutoencoderMethod`]'s keys and [`AutoencoderConfig`]'s fields: the
/// listed fields carry the same name on both sides, `support` is `[d_min, d_max]`. Both
/// directions name every field of both structs (no `..`), so a field added to either and not
/// listed here is a compile error.
macro_rules! network_keys {
    ($($field:ident),* $(,)?) => {
        impl AutoencoderMethod {
            /// The method whose network keys are `c`'s and whose own keys are `own`'s.
            fn from_network(c: AutoencoderConfig, own: AutoencoderOwnKeys) -> Self {
                let AutoencoderConfig { d_min, d_max, $($field),* } = c;
                let AutoencoderOwnKeys {
                    geodesic_m,
                    scaling,
                    scaling_quantile,
                    scaling_fence,
                    consistency,
                    features,
                    fit_test,
                    dial_sparsity,
                    feature_weights,
                    decoder_edge_weight,
                    decoder_noise_power,
                } = own;
                AutoencoderMethod {
                    support: [d_min, d_max],
                    geodesic_m,
                    scaling,
                    scaling_quantile,
                    scaling_fence,
                    consistency,
                    features,
                    fit_test,
                    dial_sparsity,
                    feature_weights,
                    decoder_edge_weight,
                    decoder_noise_power,
                    $($field),*
                }
            }

            /// The network's hyperparameters.
            pub fn network_config(&self) -> AutoencoderConfig {
                let AutoencoderMethod {
                    support,
                    geodesic_m: _,
                    scaling: _,
                    scaling_quantile: _,
                    scaling_fence: _,
                    consistency: _,
                    features: _,
                    fit_test: _,
                    dial_sparsity: _,
                    feature_weights: _,
                    decoder_edge_weight: _,
                    decoder_noise_power: _,
                    $($field),*
                } = self.clone();
                AutoencoderConfig { d_min: support[0], d_max: support[1], $($field),* }
            }
        }
    };
}

network_keys!(
    components,
    layers,
    init_std,
    init_bias,
    learning_rate,
    learning_rate_final,
    learning_rate_norm,
    stall_restarts,
    beta1,
    beta2,
    epsilon,
    iterations,
    batch_size,
    lambda1,
    lambda2,
    theta,
    checkpoint_every,
    seed,
    engine,
    device,
    augment,
    augment_mix,
    augment_radius,
    input_noise,
    validation,
    validate_every,
    encoder,
    lambda_orthogonal,
    lambda_code,
    lambda_vertex,
    vertex_batch,
    vertex_warmup,
    vertex_clip,
    encoder_passes,
    encoder_steps,
);

/// The autoencoder method's keys that are not the network's.
struct AutoencoderOwnKeys {
    geodesic_m: f64,
    scaling: ScalingName,
    scaling_quantile: f64,
    scaling_fence: f64,
    consistency: ConsistencyName,
    features: AeFeatures,
    fit_test: bool,
    dial_sparsity: DialSparsity,
    feature_weights: FeatureWeights,
    decoder_edge_weight: f64,
    decoder_noise_power: f64,
}

/// Default `scaling_quantile` of a config file (the paper's is 0: minimum and maximum).
pub const AE_SCALING_QUANTILE: f64 = 1e-3;

/// Default `dial_sparsity` of a config file: `"auto"`, chosen on the ground-truth validation
/// sets (docs/ground-truth.md). The paper's readout, one latent dimension per dial, is
/// `dial_sparsity = 0`.
pub const AE_DIAL_SPARSITY: DialSparsity = DialSparsity::Auto;

/// The autoencoder's `dial_sparsity`: how its K dials are read from the latent space after
/// training (decoding never changes: every readout is an invertible linear map of the code).
///
/// A number λ in (0, 1) fits the dial basis of [`crate::methods::sparse_dials`] at that
/// sparsity (λ as a share of the largest training code's distance from the rest code): K
/// directions in which the training codes are sparse non-negative combinations, fitted only
/// with at least 2K training shapes. 0: one latent dimension per dial (the paper). `"auto"`:
/// the dial basis at each sparsity of [`DialSparsity::CANDIDATES`] is fitted and the one whose
/// components are the most concentrated is kept: the largest median over the K components of
/// the share of each component's squared displacement that its tenth of vertices moving most
/// carry ([`crate::metrics::recovery::energy_concentration`]), read around the rest shape as
/// `meshdeco eval` reads them. It needs no ground truth; with fewer than 2K training shapes, or
/// on a mesh of several pieces (a direction can move two pieces), the dials are the latent
/// dimensions. Written as the number or the string `"auto"`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DialSparsity {
    /// Fit the basis at each of [`DialSparsity::CANDIDATES`] and keep the most concentrated.
    Auto,
    /// This λ (0: one latent dimension per dial).
    Fixed(f64),
}

impl DialSparsity {
    /// The sparsities `"auto"` tries, in order (a tie keeps the earlier): four, a factor of about
    /// 3 apart. (The latent dimensions are not among them: on the validation body their
    /// components are more concentrated than any basis' and find 4 of 30 against the chosen
    /// basis' 11; docs/ground-truth.md.)
    pub const CANDIDATES: [f64; 4] = [0.003, 0.01, 0.03, 0.1];

    /// The sparsities to try: the candidates for `"auto"`, else the one value.
    pub fn candidates(self) -> Vec<f64> {
        match self {
            DialSparsity::Auto => Self::CANDIDATES.to_vec(),
            DialSparsity::Fixed(s) => vec![s],
        }
    }
}

impl Serialize for DialSparsity {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            DialSparsity::Auto => s.serialize_str("auto"),
            DialSparsity::Fixed(x) => s.serialize_f64(*x),
        }
    }
}

impl<'de> Deserialize<'de> for DialSparsity {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = DialSparsity;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("\"auto\" or a number in [0, 1)")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<DialSparsity, E> {
                match v {
                    "auto" => Ok(DialSparsity::Auto),
                    _ => Err(E::custom(format!("`{v}` is not \"auto\" or a number in [0, 1)"))),
                }
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> std::result::Result<DialSparsity, E> {
                Ok(DialSparsity::Fixed(v))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> std::result::Result<DialSparsity, E> {
                Ok(DialSparsity::Fixed(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> std::result::Result<DialSparsity, E> {
                Ok(DialSparsity::Fixed(v as f64))
            }
        }
        d.deserialize_any(Visitor)
    }
}

/// Default `feature_weights` of a config file: `noise` since issue 53 (with the recommended
/// setting's `init_bias = "mean"` and `learning_rate = 5e-3`: the recovery setting, chosen on the
/// ground-truth validation sets, docs/ground-truth.md). The paper: `uniform`.
pub const AE_FEATURE_WEIGHTS: FeatureWeights = FeatureWeights::Noise;

/// The autoencoder's `feature_weights`: how each vertex's feature error counts in the training
/// loss (and in the validation error and the did-it-train check, which measure the same error).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FeatureWeights {
    /// Every vertex 1 (the paper).
    #[default]
    Uniform,
    /// Each vertex weighted by `min(1, m / v_i)`, `v_i` the variance of its scaled features
    /// under small isotropic position noise on the rest mesh and `m` the median variance
    /// ([`crate::representation::noise_sensitivity`]): vertices whose 1-ring fit turns position
    /// noise into large feature noise (slivers, degenerate rings of decimated meshes) stop
    /// dominating the loss. Needs only the rest mesh; 8 noisy copies are encoded once.
    Noise,
}

/// Default `decoder_edge_weight` of a config file: 1e-4, chosen on the ground-truth validation
/// sets with [`AE_DECODER_NOISE_POWER`] (docs/ground-truth.md § "Weighting the decoder by the
/// features' reliability"). With the decoder's fit unweighted, 0.1 was best (§ "Decoding the
/// network's features": the edge term then smoothed over the slivers' wrong features); with
/// each vertex's fit weighted by its reliability, a small share keeps the solve definite and
/// lets the reliable features decide. The representation's own 1e-6
/// ([`crate::representation::acap::DEFAULT_EDGE_WEIGHT`], which keeps exact features' round
/// trips exact) is the decoding before issue 53 and the `paper` setting.
pub const AE_DECODER_EDGE_WEIGHT: f64 = 1e-4;

/// Largest accepted `decoder_edge_weight` (beyond it the edge least squares alone, which the
/// exact inverse is meant to beat, decides).
pub const AE_DECODER_EDGE_WEIGHT_MAX: f64 = 100.0;

/// Default `decoder_noise_power` of a config file: 1, the inverse of each vertex's feature noise
/// variance above the median (the weights of `feature_weights = "noise"`), chosen on the
/// ground-truth validation sets together with [`AE_DECODER_EDGE_WEIGHT`] (docs/ground-truth.md
/// § "Weighting the decoder by the features' reliability"): a sliver's 1-ring fit turns a few
/// per cent of deformation into a rotation of a radian, which the network, trained with the
/// noise weights, does not reproduce; unweighted, the decoder follows those features as
/// closely as any other. (2 was 1.2 points better there and put the Spacetime faces 6.8 %
/// above issue 53's bar.)
pub const AE_DECODER_NOISE_POWER: f64 = 1.0;

/// Largest accepted `decoder_noise_power`.
pub const AE_DECODER_NOISE_POWER_MAX: f64 = 8.0;

/// Default `scaling_fence` of a config file.
pub const AE_SCALING_FENCE: f64 = 1.0;

impl Default for AutoencoderMethod {
    fn default() -> Self {
        AutoencoderMethod::from_network(
            AutoencoderConfig::recommended(),
            AutoencoderOwnKeys {
                geodesic_m: AE_GEODESIC_M,
                scaling: ScalingName::Global,
                scaling_quantile: AE_SCALING_QUANTILE,
                scaling_fence: AE_SCALING_FENCE,
                consistency: ConsistencyName::Global,
                features: AeFeatures::Acap,
                fit_test: true,
                dial_sparsity: AE_DIAL_SPARSITY,
                feature_weights: AE_FEATURE_WEIGHTS,
                decoder_edge_weight: AE_DECODER_EDGE_WEIGHT,
                decoder_noise_power: AE_DECODER_NOISE_POWER,
            },
        )
    }
}

impl AutoencoderMethod {
    /// This method with its inference keys at their defaults: the keys that change only how a
    /// trained network is measured and read, not what training computes — the encoder's passes
    /// and vertex steps (`encoder_passes`, `encoder_steps`), `fit_test`, `dial_sparsity`, and the
    /// ACAP decoder's `decoder_edge_weight` and `decoder_noise_power` unless the vertex term
    /// (`lambda_vertex` > 0) decodes while training. Two methods with equal training keys train
    /// the same network (same seed, same steps), so `meshdeco eval` measures a trained cell again
    /// instead of training it again when only inference keys changed.
    pub fn training_keys(&self) -> AutoencoderMethod {
        let d = AutoencoderMethod::default();
        let mut t = self.clone();
        t.encoder_passes = d.encoder_passes;
        t.encoder_steps = d.encoder_steps;
        t.fit_test = d.fit_test;
        t.dial_sparsity = d.dial_sparsity;
        if t.lambda_vertex == 0.0 {
            t.decoder_edge_weight = d.decoder_edge_weight;
            t.decoder_noise_power = d.decoder_noise_power;
        }
        t
    }
}

/// The `[method]` table: one variant per method, tagged by `kind`.
// The autoencoder's keys make its variant the largest by some 200 bytes; a config is built once
// per run and matched by value everywhere, so it is not boxed.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum MethodConfig {
    Pca(PcaMethod),
    Splocs(SplocsMethod),
    RegionPca(RegionPcaMethod),
    Autoencoder(AutoencoderMethod),
}

/// What every method's config answers (implemented by each variant's struct).
pub trait MethodSettings {
    /// The method kind.
    fn kind(&self) -> MethodKind;
    /// Number of components K requested.
    fn components(&self) -> usize;
    /// The representation the method runs on.
    fn representation(&self) -> RepresentationKind;
    /// Checks every value that does not depend on the data; errors name `method.<key>`.
    fn validate(&self) -> Result<()>;
    /// Whether the trained model can be fitted to sparse control points (`meshdeco eval`'s
    /// `[control_points]`): per-vertex models and the autoencoder.
    fn supports_control_points(&self) -> bool {
        self.representation() == RepresentationKind::Displacement
    }
    /// Whether training runs in steps that a checkpoint can resume (`meshdeco train --resume`,
    /// and Ctrl-C stops it after writing one).
    fn can_resume(&self) -> bool {
        false
    }
    /// Whether fitting the trained model to control points iterates through a nonlinear
    /// decoder (the evaluation then runs `control_points.autoencoder_trials` trials, fewer than
    /// the closed-form fits' `control_points.trials`).
    fn iterative_point_fit(&self) -> bool {
        false
    }
}

/// Renames a method struct's error key `k` to `method.k` (and `d_min`/`d_max`, the autoencoder
/// network's names, to `support`, the config key); keys already under `method.` stay.
pub fn method_key(e: Error) -> Error {
    match e {
        Error::Config { key, message } if !key.starts_with("method.") => {
            let key = match key.as_str() {
                "d_min" | "d_max" => "support".to_string(),
                _ => key,
            };
            Error::config(format!("method.{key}"), message)
        }
        other => other,
    }
}

fn positive(key: &str, x: f64) -> Result<()> {
    if x.is_finite() && x > 0.0 { Ok(()) } else { Err(Error::config(key, format!("{x} must be a positive number"))) }
}

impl MethodSettings for PcaMethod {
    fn kind(&self) -> MethodKind {
        MethodKind::Pca
    }
    fn components(&self) -> usize {
        self.components
    }
    fn representation(&self) -> RepresentationKind {
        self.representation
    }
    fn validate(&self) -> Result<()> {
        crate::methods::PcaConfig { components: self.components, ..Default::default() }.validate().map_err(method_key)
    }
}

impl MethodSettings for SplocsMethod {
    fn kind(&self) -> MethodKind {
        MethodKind::Splocs
    }
    fn components(&self) -> usize {
        self.components
    }
    fn representation(&self) -> RepresentationKind {
        self.representation
    }
    fn validate(&self) -> Result<()> {
        // Painted sets given as files are read (and checked) when training starts.
        let inline: Vec<Vec<usize>> = self
            .fixed_centers
            .iter()
            .map(|c| match c {
                FixedCenter::Vertices(v) => v.clone(),
                FixedCenter::File(_) => vec![0],
            })
            .collect();
        if self.max_iterations == 0 {
            return Err(Error::config("method.max_iterations", "0 must be at least 1"));
        }
        self.solver_config_with(inline).validate().map_err(method_key)?;
        positive("method.geodesic_m", self.geodesic_m)
    }
}

impl MethodSettings for RegionPcaMethod {
    fn kind(&self) -> MethodKind {
        MethodKind::RegionPca
    }
    fn components(&self) -> usize {
        self.components
    }
    fn representation(&self) -> RepresentationKind {
        self.representation
    }
    fn validate(&self) -> Result<()> {
        if self.representation != RepresentationKind::Displacement {
            return Err(Error::config(
                "method.representation",
                format!(
                    "`{}` is not available for kind = \"region-pca\" (only displacement)",
                    self.representation.name()
                ),
            ));
        }
        if self.regions.is_some() && self.max_regions.is_some() {
            return Err(Error::config(
                "method.regions",
                "give either regions (fixed) or max_regions (automatic), not both",
            ));
        }
        self.segmentation().validate().map_err(method_key)?;
        self.region_pca().validate().map_err(method_key)?;
        if !(self.gamma.is_finite() && self.gamma >= 0.0) {
            return Err(Error::config("method.gamma", format!("{} must be a non-negative number", self.gamma)));
        }
        Ok(())
    }
}

impl MethodSettings for AutoencoderMethod {
    fn kind(&self) -> MethodKind {
        MethodKind::Autoencoder
    }
    fn components(&self) -> usize {
        self.components
    }
    fn representation(&self) -> RepresentationKind {
        RepresentationKind::Acap
    }
    fn supports_control_points(&self) -> bool {
        true
    }
    fn can_resume(&self) -> bool {
        true
    }
    fn iterative_point_fit(&self) -> bool {
        true
    }
    fn validate(&self) -> Result<()> {
        if self.iterations == 0 {
            return Err(Error::config("method.iterations", "0 must be at least 1"));
        }
        if self.checkpoint_every == 0 {
            return Err(Error::config("method.checkpoint_every", "0 must be at least 1"));
        }
        self.network_config().validate().map_err(method_key)?;
        let q = self.scaling_quantile;
        if !(0.0..=crate::representation::scaling::MAX_QUANTILE).contains(&q) {
            return Err(Error::config(
                "method.scaling_quantile",
                format!("{q} must be in [0, {}]", crate::representation::scaling::MAX_QUANTILE),
            ));
        }
        if !(self.scaling_fence >= 0.0 && self.scaling_fence.is_finite()) {
            return Err(Error::config(
                "method.scaling_fence",
                format!("{} must be a finite number ≥ 0", self.scaling_fence),
            ));
        }
        if !(0.0..=AE_DECODER_EDGE_WEIGHT_MAX).contains(&self.decoder_edge_weight) {
            return Err(Error::config(
                "method.decoder_edge_weight",
                format!(
                    "{} must be a number in [0, {AE_DECODER_EDGE_WEIGHT_MAX}] (1e-6: the exact inverse of the features' 1-ring fit)",
                    self.decoder_edge_weight
                ),
            ));
        }
        if !(0.0..=AE_DECODER_NOISE_POWER_MAX).contains(&self.decoder_noise_power) {
            return Err(Error::config(
                "method.decoder_noise_power",
                format!(
                    "{} must be a number in [0, {AE_DECODER_NOISE_POWER_MAX}] (0: every vertex's fit alike)",
                    self.decoder_noise_power
                ),
            ));
        }
        if let DialSparsity::Fixed(s) = self.dial_sparsity
            && !(0.0..1.0).contains(&s)
        {
            return Err(Error::config(
                "method.dial_sparsity",
                format!("{s} must be \"auto\" or in [0, 1) (0: one latent dimension per dial)"),
            ));
        }
        positive("method.geodesic_m", self.geodesic_m)
    }
}

impl MethodConfig {
    /// The variant's settings (the one `match` over the variants).
    pub fn settings(&self) -> &dyn MethodSettings {
        match self {
            MethodConfig::Pca(m) => m,
            MethodConfig::Splocs(m) => m,
            MethodConfig::RegionPca(m) => m,
            MethodConfig::Autoencoder(m) => m,
        }
    }

    /// The method kind.
    pub fn kind(&self) -> MethodKind {
        self.settings().kind()
    }

    /// Number of components K requested.
    pub fn components(&self) -> usize {
        self.settings().components()
    }

    /// The representation the method runs on.
    pub fn representation(&self) -> RepresentationKind {
        self.settings().representation()
    }

    /// See [`MethodSettings::can_resume`].
    pub fn can_resume(&self) -> bool {
        self.settings().can_resume()
    }

    /// The method with the keys that do not change training at their defaults (the
    /// autoencoder's [`AutoencoderMethod::training_keys`]; every key of a linear method, which
    /// fits in one go, counts).
    pub fn training_keys(&self) -> MethodConfig {
        match self {
            MethodConfig::Autoencoder(m) => MethodConfig::Autoencoder(m.training_keys()),
            other => other.clone(),
        }
    }

    /// Parses and validates a `[method]` table. Errors name `method.<key>`: an unknown key, a
    /// key of another kind, a value of the wrong type or out of range.
    pub fn from_table(table: &toml::Table) -> Result<Self> {
        let kind_name = match table.get("kind") {
            Some(toml::Value::String(s)) => s.clone(),
            Some(other) => return Err(Error::config("method.kind", format!("`{other}` must be a string"))),
            None => return Err(Error::config("method.kind", "is required (autoencoder, splocs, pca or region-pca)")),
        };
        let Some(kind) = MethodKind::parse(&kind_name) else {
            return Err(Error::config(
                "method.kind",
                format!("`{kind_name}`: expected autoencoder, splocs, pca or region-pca"),
            ));
        };
        let parsed: std::result::Result<MethodConfig, _> = toml::Value::Table(table.clone()).try_into();
        let m = match parsed {
            Ok(m) => m,
            Err(e) => return Err(Self::name_the_key(table, kind, &e.to_string())),
        };
        m.settings().validate()?;
        Ok(m)
    }

    /// Turns a serde error into one naming the key: an unknown field becomes "does not apply to
    /// kind = …" (with the accepted keys), any other error is pinned on the first key whose value
    /// alone fails to parse.
    fn name_the_key(table: &toml::Table, kind: MethodKind, message: &str) -> Error {
        let message = message.trim();
        if let Some(rest) = message.strip_prefix("unknown field `")
            && let Some((field, expected)) = rest.split_once('`')
        {
            let expected = expected.lines().next().unwrap_or_default().trim_start_matches(',').trim();
            let accepted = expected.replace("expected one of ", "").replace("expected ", "");
            let Some(value) = table.get(field) else {
                // Not a key of `[method]` itself: a key of one of its tables (`admm = { … }`).
                let path = nested_key_path(table, field).unwrap_or_else(|| field.to_string());
                let parent = path.rsplit_once('.').map_or("method", |(p, _)| p);
                return Error::config(
                    format!("method.{path}"),
                    format!("is not a key of method.{parent} (it accepts: {accepted})"),
                );
            };
            // A key of another kind parses there, or fails there for its value, not its name.
            let unknown_there = format!("unknown field `{field}`");
            let known_elsewhere = MethodKind::ALL.into_iter().any(|k| {
                let mut t = toml::Table::new();
                t.insert("kind".into(), k.name().into());
                t.insert(field.to_string(), value.clone());
                match toml::Value::Table(t).try_into::<MethodConfig>() {
                    Ok(_) => true,
                    Err(e) => !e.to_string().trim().starts_with(&unknown_there),
                }
            });
            let what = if known_elsewhere { "does not apply to" } else { "is not a key of" };
            return Error::config(
                format!("method.{field}"),
                format!("{what} kind = \"{}\" (it accepts: {accepted})", kind.name()),
            );
        }
        for (key, value) in table {
            if key == "kind" {
                continue;
            }
            let mut t = toml::Table::new();
            t.insert("kind".into(), kind.name().into());
            t.insert(key.clone(), value.clone());
            if let Err(e) = toml::Value::Table(t).try_into::<MethodConfig>() {
                return Error::config(format!("method.{key}"), format!("`{value}`: {}", e.to_string().trim()));
            }
        }
        Error::config("method", message.to_string())
    }

    /// The resolved table: every key with its value (what `config.toml` of an artefact holds).
    pub fn to_table(&self) -> Result<toml::Table> {
        toml::Table::try_from(self).map_err(|e| Error::Invalid(format!("serialising the method config: {e}")))
    }
}

/// The dotted path (`admm.iters`) of the first key named `field` inside a table value of `table`
/// (depth first, in key order), `None` when no nested table holds it.
fn nested_key_path(table: &toml::Table, field: &str) -> Option<String> {
    table.iter().find_map(|(key, value)| match value {
        toml::Value::Table(t) if t.contains_key(field) => Some(format!("{key}.{field}")),
        toml::Value::Table(t) => nested_key_path(t, field).map(|p| format!("{key}.{p}")),
        _ => None,
    })
}
