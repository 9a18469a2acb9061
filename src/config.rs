//! Experiment configuration (TOML): parsed strictly (unknown keys are errors) and validated in
//! full before any work starts. Errors name the key and the bad value.
//!
//! ```toml
//! name = "scape-ae"               # artefacts go to checkpoints/<name>/ unless --out DIR is given
//! [data]
//! path = "../shared/data/scape"   # directory, glob, or synthetic:<name>
//! train = "1-36"                  # 1-based frame ranges in natural order ("1-36,40", "every:10"); default all
//! test = "37-71"                  # same syntax, or "rest" (every frame not in train); default none
//! # validation = "auto:10%"      # held out of the training frames, reported beside train and test:
//! #                                frames ("31-36", in train) or auto:P% (seeded draw, auto:P%:SEED)
//! rest = "first"                  # first | mean | <mesh file>
//! align = "none"                  # none | rigid
//! unit_box = false                # scale into the unit box (SPLOCS's convention); outputs keep data units
//! # template = "t.obj"           # with a NumPy path (F×N×3 .npy, or .npz + array = "name"): the faces
//! # dataset = "verts"             # with an HDF5 path (.h5): the dataset (F×N×3 or N×3×F; default verts); faces: tris or template
//! # cache = "auto"              # training features cached: auto (large ones, in ~/.cache/meshdeco), off, or a folder
//! [method]
//! kind = "autoencoder"            # autoencoder | splocs | pca | region-pca
//! components = 50
//! [output]                        # optional
//! views = false                   # also write components/ and segmentation.ply at training
//! ```
//!
//! The `[method]` table is typed ([`MethodConfig`], `src/config/method.rs`): one struct per
//! kind with its defaults, parsed with `deny_unknown_fields` and validated once. Method keys
//! (all optional; each applies only to the kinds listed — a key given for another kind is an
//! error):
//!
//! | key | kinds | default | meaning |
//! |---|---|---|---|
//! | `components` | all | 50 | number of components K (region-pca: total budget) |
//! | `representation` | splocs, pca, region-pca | `displacement` | `displacement` \| `triangle-gradient` (pca and splocs also `acap`) |
//! | `sparsity` | splocs | 2.0 | λ, weight of the group-sparsity term |
//! | `support` | splocs, autoencoder | [0.1, 0.7] / [0.3, 0.7] (paper [0.2, 0.4]) | [d_min, d_max] of the support maps (normalised geodesic distance) |
//! | `weights` | splocs | `nonnegative` | `nonnegative` (Eq. 4) \| `signed` (Eq. 3) |
//! | `max_iterations` | splocs | 10 | outer iterations |
//! | `admm` | splocs | { rho = 10, iterations = 10 } | ADMM penalty and inner iterations |
//! | `tolerance` | splocs | 1e-6 | convergence: mean relative objective change over the last 5 iterations |
//! | `seed` | all | 0 | random seed |
//! | `fixed_centers` | splocs | [] | painted vertex sets fixing the first components' centres (lists of vertex indices, or file paths) |
//! | `geodesic_m` | splocs, autoencoder | 10 / 1 | heat-method time factor m (t = m·h²) |
//! | `iterations` | autoencoder | 2000 | training iterations |
//! | `learning_rate` | autoencoder | 1e-2 (paper 1e-3) | Adam step size (of the first step) |
//! | `learning_rate_norm` | autoencoder | 75 (paper: 0, never) | features of larger root-mean-square norm per shape train with every step size × this / norm |
//! | `stall_restarts` | autoencoder | 2 (paper: 0) | a run still at or above its first step's reconstruction error at 10 % of `iterations` (step ≥ 50) restarts with halved step sizes, at most this many times; in 0..=8 |
//! | `beta1`, `beta2` | autoencoder | 0.9, 0.99 (paper 0.999) | Adam's moment decay rates, each in [0, 1) |
//! | `learning_rate_final` | autoencoder | 1e-4 (paper: constant rate) | step size of the last step, reached by a cosine decay from `learning_rate` |
//! | `batch_size` | autoencoder | full batch up to 64 shapes, 32 beyond | shapes per step |
//! | `layers` | autoencoder | 1 | convolution layers L |
//! | `lambda1`, `lambda2` | autoencoder | 4 (paper 0.5), 0.5 | weights of the sparsity and max-weight terms |
//! | `theta` | autoencoder | 5.0 | hinge threshold of the max-weight term |
//! | `fit_test` | autoencoder | true | also report `test_erms_fitted`: test Erms with codes fitted to every vertex (starting from the encoder's code; `meshdeco encode --fit`) |
//! | `checkpoint_every` | autoencoder | 200 | iterations between checkpoints |
//! | `scaling` | autoencoder | `global` (paper `per-dimension`) | feature scaling to [−0.95, 0.95]: `per-dimension` (the paper) \| `grouped` (the reference code: one range for the 3 rotation dims, one for the 6 stretch dims) \| `global` (one range for all 9, so rotation and stretch errors weigh alike) |
//! | `scaling_quantile`, `scaling_fence` | autoencoder | 0.001, 1 (paper: 0, min/max) | outlier fence of the feature scaling: the q … 1 − q quantiles [a, b] of the training features (each group of `scaling`), widened by fence × (b − a) on each side, are the range mapped to [−0.95, 0.95] where they lie inside the minimum and maximum, values beyond clamped; q = 0: minimum and maximum. A few extreme features (slivers of a face stretched 70×) otherwise squeeze all others; q in [0, 0.05], fence ≥ 0 |
//! | `dial_sparsity` | autoencoder | `"auto"` (paper: 0) | how the K dials are read from the latent space after training: 0, one latent dimension per dial; λ in (0, 1), a dial basis of the training codes at that sparsity; `"auto"`, the most concentrated of the bases at 0.003, 0.01, 0.03, 0.1 (the latent dimensions with fewer than 2K training shapes or on a mesh of several pieces); [`DialSparsity`] |
//! | `decoder_edge_weight`, `decoder_noise_power` | autoencoder | 1e-4, 1 (exact, unweighted inverse: 1e-6, 0) | the ACAP decoder that turns the network's output features into vertices: the exact inverse of the features' 1-ring fit with each vertex's residual weighted by w_i^p (w_i its noise weight, `feature_weights = "noise"`'s, from the rest mesh; p = `decoder_noise_power`, 0: unweighted), plus μ = `decoder_edge_weight` × the edge least squares (÷ the mean edge length²); the network does not reproduce the features of slivers, which the unweighted inverse follows as closely as any other (chosen on the planted validation sets); inference keys stored in `model.json` (models trained before get the defaults); μ in [0, 100], p in [0, 8] |
//! | `feature_weights` | autoencoder | `uniform` (the paper) | `uniform` \| `noise`: each vertex's feature error weighted by min(1, median / its variance) of its scaled features under small position noise on the rest mesh, so vertices whose 1-ring fit amplifies noise stop dominating the loss; [`FeatureWeights`] |
//! | `engine` | autoencoder | `hand` | `hand` (hand-written CPU step, fast) \| `graph` (Burn autodiff graph on `device`) |
//! | `device` | autoencoder | `cpu` | `cpu` \| `wgpu` (needs `engine = "graph"` and a build with `--features wgpu`) |
//! | `consistency` | autoencoder, pca, splocs | `global` | ACAP rotation consistency: `bfs` \| `global` |
//! | `features` | autoencoder | `acap` | the network's 9 numbers per vertex: `acap` (log R and S) \| `gradient` (T − I of the same 1-ring fit; [`crate::representation::acap::FeatureMap`]) |
//! | `lambda`, `r`, `threshold`, `regions`, `max_regions`, `beta`, `gamma` | region-pca | see region-pca docs | segmentation and coupling |
//! | `min_piece`, `keep_searching` | region-pca | 0, false | fragment merging and search past the first non-compact k (`SegmentationConfig`) |

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
pub use crate::representation::feature_cache::CachePolicy;

mod method;
pub use method::{
    AE_DECODER_EDGE_WEIGHT, AE_DECODER_EDGE_WEIGHT_MAX, AE_DECODER_NOISE_POWER, AE_DECODER_NOISE_POWER_MAX,
    AE_GEODESIC_M, AeFeatures, AutoencoderMethod, ConsistencyName, DialSparsity, FeatureWeights, FixedCenter,
    MethodConfig, MethodKind, MethodSettings, PcaMethod, RegionPcaMethod, SPLOCS_GEODESIC_M, ScalingName, SplocsMethod,
    method_key,
};

/// Which frames belong to a split, as 0-based indices (after natural sort).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum FrameSelection {
    /// Every frame.
    All,
    /// 1-based inclusive ranges, as written (`"1-36,40"`).
    Ranges(Vec<(usize, usize)>),
    /// Frames 1, 1 + n, 1 + 2n, … (the papers' "every n-th frame").
    Every(usize),
    /// Frames not in the training split (only valid for `test`).
    Rest,
}

impl FrameSelection {
    /// Parses `"all"`, `"rest"`, `"every:N"` or comma-separated 1-based ranges `"a-b,c"`.
    pub fn parse(key: &str, s: &str) -> Result<Self> {
        let t = s.trim();
        if t == "all" {
            return Ok(FrameSelection::All);
        }
        if t == "rest" {
            return Ok(FrameSelection::Rest);
        }
        if let Some(n) = t.strip_prefix("every:") {
            let n: usize = n
                .trim()
                .parse()
                .map_err(|_| Error::config(key, format!("`{s}`: expected every:N with N a positive integer")))?;
            if n == 0 {
                return Err(Error::config(key, format!("`{s}`: N must be at least 1")));
            }
            return Ok(FrameSelection::Every(n));
        }
        let mut ranges = Vec::new();
        for part in t.split(',') {
            let part = part.trim();
            let bad = || {
                Error::config(
                    key,
                    format!(
                        "`{s}`: `{part}` is not a frame number or range a-b (1-based); other forms: all, rest, every:N"
                    ),
                )
            };
            let (a, b) = match part.split_once('-') {
                Some((a, b)) => {
                    (a.trim().parse::<usize>().map_err(|_| bad())?, b.trim().parse::<usize>().map_err(|_| bad())?)
                }
                None => {
                    let a = part.parse::<usize>().map_err(|_| bad())?;
                    (a, a)
                }
            };
            if a == 0 || b < a {
                return Err(Error::config(key, format!("`{s}`: range `{part}` must satisfy 1 <= a <= b")));
            }
            ranges.push((a, b));
        }
        Ok(FrameSelection::Ranges(ranges))
    }

    /// Resolves to sorted 0-based frame indices for a sequence of `n_frames`. `train` is needed
    /// for [`FrameSelection::Rest`].
    pub fn resolve(&self, key: &str, n_frames: usize, train: Option<&[usize]>) -> Result<Vec<usize>> {
        let mut out: Vec<usize> = match self {
            FrameSelection::All => (0..n_frames).collect(),
            FrameSelection::Every(n) => (0..n_frames).step_by(*n).collect(),
            FrameSelection::Rest => {
                let train = train.ok_or_else(|| Error::config(key, "`rest` is only valid for data.test"))?;
                (0..n_frames).filter(|i| !train.contains(i)).collect()
            }
            FrameSelection::Ranges(r) => {
                let mut v = Vec::new();
                for &(a, b) in r {
                    if b > n_frames {
                        return Err(Error::config(
                            key,
                            format!("range {a}-{b} goes past the last frame ({n_frames} frames)"),
                        ));
                    }
                    v.extend(a - 1..b);
                }
                v
            }
        };
        out.sort_unstable();
        out.dedup();
        if out.is_empty() {
            return Err(Error::config(key, "selects no frame"));
        }
        Ok(out)
    }
}

/// Frames held out of the training split to choose settings on (`data.validation`): the model
/// never fits them; `train` and `eval` report their Erms beside the training and test Erms.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Validation {
    /// These frames (1-based config syntax); each must be a training frame.
    Frames(FrameSelection),
    /// `percent` % of the training frames (at least one), drawn with `seed`; never the first
    /// training frame (with `rest = "first"` it is the rest shape).
    Share { percent: f64, seed: u64 },
}

impl Validation {
    /// Parses `"auto:P%"`, `"auto:P%:SEED"` or a frame selection (`"31-36"`, `"every:10"`).
    pub fn parse(s: &str) -> Result<Self> {
        const KEY: &str = "data.validation";
        let t = s.trim();
        if let Some(rest) = t.strip_prefix("auto:") {
            let (p, seed) = match rest.split_once(':') {
                Some((p, seed)) => (p, seed),
                None => (rest, "0"),
            };
            let bad = || Error::config(KEY, format!("`{s}`: expected auto:P% (0 < P < 100) or auto:P%:SEED"));
            let percent: f64 = p.trim().strip_suffix('%').ok_or_else(bad)?.trim().parse().map_err(|_| bad())?;
            let seed: u64 = seed.trim().parse().map_err(|_| bad())?;
            if !(percent > 0.0 && percent < 100.0) {
                return Err(bad());
            }
            return Ok(Validation::Share { percent, seed });
        }
        match FrameSelection::parse(KEY, t)? {
            FrameSelection::Rest | FrameSelection::All => {
                Err(Error::config(KEY, format!("`{s}`: expected frames out of data.train (\"31-36\") or auto:P%")))
            }
            f => Ok(Validation::Frames(f)),
        }
    }

    /// The validation frames (sorted, 0-based) out of `train` (sorted, 0-based) of a sequence
    /// of `n_frames`, and the training frames left to fit. Errors name `data.validation`.
    pub fn resolve(&self, n_frames: usize, train: &[usize]) -> Result<(Vec<usize>, Vec<usize>)> {
        const KEY: &str = "data.validation";
        let held: Vec<usize> = match self {
            Validation::Frames(f) => {
                let v = f.resolve(KEY, n_frames, None)?;
                if let Some(&x) = v.iter().find(|x| !train.contains(x)) {
                    return Err(Error::config(
                        KEY,
                        format!(
                            "frame {} is not a training frame (validation frames are held out of data.train)",
                            x + 1
                        ),
                    ));
                }
                v
            }
            Validation::Share { percent, seed } => {
                let pool = &train[1.min(train.len())..];
                let k = ((percent / 100.0 * train.len() as f64).round() as usize).max(1);
                if k > pool.len() {
                    return Err(Error::config(
                        KEY,
                        format!("{percent}% of {} training frames leaves none to train on", train.len()),
                    ));
                }
                let mut rng = crate::rng::Rng::new(*seed);
                let mut v: Vec<usize> = rng.sample_distinct(pool.len(), k).into_iter().map(|i| pool[i]).collect();
                v.sort_unstable();
                v
            }
        };
        let fit: Vec<usize> = train.iter().copied().filter(|t| !held.contains(t)).collect();
        if fit.is_empty() {
            return Err(Error::config(KEY, "holds out every training frame; none is left to train on"));
        }
        Ok((held, fit))
    }
}

/// Refuses `data.validation` (`data`: its value, as the message shows it) beside the
/// autoencoder's `method.validation` > 0: both hold frames out of the training to choose on
/// (the first reports a validation Erms on frames the model never sees, the second chooses
/// the kept step on training shapes), and which one a run's validation numbers mean would be
/// unclear. The error names both keys.
pub fn check_validation_keys(data: Option<String>, method: &MethodConfig) -> Result<()> {
    if let (Some(v), MethodConfig::Autoencoder(m)) = (data, method)
        && m.validation > 0
    {
        return Err(Error::config(
            "data.validation",
            format!(
                "{v} is given together with method.validation = {}: both hold frames out of training to choose on (data.validation: frames reported as validation Erms; method.validation: training shapes that choose the autoencoder's kept step); keep one of them",
                m.validation
            ),
        ));
    }
    Ok(())
}

impl std::fmt::Display for Validation {
    /// The config syntax that parses back to the same value.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Validation::Frames(s) => write!(f, "{s}"),
            Validation::Share { percent, seed } => write!(f, "auto:{percent}%:{seed}"),
        }
    }
}

/// Which shape the deformations are measured against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum RestShape {
    First,
    Mean,
    File(PathBuf),
}

/// Rigid alignment of frames to the rest shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Align {
    None,
    Rigid,
}

/// The `[data]` section, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct DataConfig {
    pub path: String,
    pub train: FrameSelection,
    pub test: Option<FrameSelection>,
    /// Frames held out of `train` to report a validation Erms (`data.validation`).
    pub validation: Option<Validation>,
    pub rest: RestShape,
    pub align: Align,
    pub unit_box: bool,
    /// Name of the array inside a `.npz` `path`.
    pub array: Option<String>,
    /// Mesh file whose faces a NumPy `path` uses (an HDF5 `path`: instead of its `tris`).
    pub template: Option<PathBuf>,
    /// The dataset of an HDF5 `path` (`data.dataset`; default `verts`, the SPLOCS layout).
    pub dataset: Option<String>,
    /// Where the training features are cached (`data.cache`: auto, off or a folder).
    pub cache: CachePolicy,
}

/// Raw TOML of the whole file; `deny_unknown_fields` makes typos errors.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    name: Option<String>,
    data: RawData,
    method: toml::Table,
    #[serde(default)]
    output: OutputConfig,
}

/// The `[output]` table: what training writes besides the model (all optional).
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    /// Write the views of the model at training: per-component meshes and heat maps
    /// (`components/`) and region PCA's `segmentation.ply`. Default false: the model files are
    /// the artefact, and `meshdeco components` writes the views at any time.
    #[serde(default)]
    pub views: bool,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawData {
    path: String,
    train: Option<String>,
    test: Option<String>,
    validation: Option<String>,
    rest: Option<String>,
    align: Option<String>,
    unit_box: Option<bool>,
    array: Option<String>,
    template: Option<PathBuf>,
    dataset: Option<String>,
    cache: Option<String>,
}

/// A validated experiment configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// Experiment name (artefact directory name).
    pub name: String,
    pub data: DataConfig,
    /// The validated `[method]` table, typed by its `kind`.
    pub method: MethodConfig,
    /// The `[output]` table.
    pub output: OutputConfig,
    /// The file it came from (relative data paths are resolved against the working directory,
    /// as a user types them; `rest = <file>` likewise).
    pub source: Option<PathBuf>,
}

impl Config {
    /// Reads and validates a config file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let mut c = Self::from_toml(&text).map_err(|e| match e {
            Error::Config { key, message } => Error::config(key, format!("{message} (in {})", path.display())),
            Error::Parse { line, message, .. } => Error::parse(path, line, message),
            other => other,
        })?;
        c.source = Some(path.to_path_buf());
        Ok(c)
    }

    /// Whether `self` and `other` train the same model: equal but for inference keys
    /// ([`MethodConfig::training_keys`]); the file they came from does not count.
    pub fn trains_as(&self, other: &Config) -> bool {
        self.name == other.name
            && self.data == other.data
            && self.output == other.output
            && self.method.training_keys() == other.method.training_keys()
    }

    /// Parses and validates TOML text.
    pub fn from_toml(text: &str) -> Result<Self> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
            Error::parse("<config>", line, e.message().to_string())
        })?;
        Self::validate(raw)
    }

    fn validate(raw: RawConfig) -> Result<Self> {
        let name = raw.name.unwrap_or_else(|| "experiment".to_string());
        if name.is_empty() || name.contains(['/', '\\']) || name == "." || name == ".." {
            return Err(Error::config(
                "name",
                format!("`{name}` must be a non-empty file name without path separators"),
            ));
        }
        let d = raw.data;
        if d.path.trim().is_empty() {
            return Err(Error::config("data.path", "must not be empty"));
        }
        if let Some(n) = d.path.strip_prefix(crate::synthetic::PREFIX)
            && let Err(e) = crate::synthetic::check_name(n)
        {
            return Err(Error::config("data.path", e));
        }
        let train = match &d.train {
            Some(s) => FrameSelection::parse("data.train", s)?,
            None => FrameSelection::All,
        };
        if train == FrameSelection::Rest {
            return Err(Error::config("data.train", "`rest` is only valid for data.test"));
        }
        let test = d.test.as_deref().map(|s| FrameSelection::parse("data.test", s)).transpose()?;
        let validation = d.validation.as_deref().map(Validation::parse).transpose()?;
        let rest = match d.rest.as_deref().unwrap_or("first") {
            "first" => RestShape::First,
            "mean" => RestShape::Mean,
            f => RestShape::File(PathBuf::from(f)),
        };
        let align = match d.align.as_deref().unwrap_or("none") {
            "none" => Align::None,
            "rigid" => Align::Rigid,
            other => return Err(Error::config("data.align", format!("`{other}`: expected none or rigid"))),
        };
        let data = DataConfig {
            path: d.path,
            train,
            test,
            validation,
            rest,
            align,
            unit_box: d.unit_box.unwrap_or(false),
            array: d.array,
            template: d.template,
            dataset: d.dataset,
            cache: match d.cache.as_deref().map(str::trim) {
                None => CachePolicy::Auto,
                Some("") => return Err(Error::config("data.cache", "is empty: expected auto, off or a folder")),
                Some(c) => CachePolicy::parse(c),
            },
        };
        data.numpy_template()?;

        let method = MethodConfig::from_table(&raw.method)?;
        check_validation_keys(data.validation.as_ref().map(|v| format!("`{v}`")), &method)?;
        Ok(Config { name, data, method, output: raw.output, source: None })
    }

    /// The method kind.
    pub fn kind(&self) -> MethodKind {
        self.method.kind()
    }

    /// The artefact directory: `--out` if given, else `checkpoints/<name>`.
    pub fn output_dir(&self, out: Option<&Path>) -> PathBuf {
        out.map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("checkpoints").join(&self.name))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
name = "t"
[data]
path = "synthetic:tube"
train = "1-36"
test = "rest"
[method]
kind = "splocs"
components = 5
support = [0.1, 0.7]
admm = { rho = 10, iterations = 10 }
"#;

    /// Which keys count for training (`Config::trains_as`): the autoencoder's inference keys do
    /// not — the decoder's only while the vertex term does not decode in training — every other
    /// key does, and every key of a linear method.
    #[test]
    fn training_keys_leave_out_inference_keys_only() {
        let ae = |extra: &str| {
            Config::from_toml(&format!(
                "name = \"t\"\n[data]\npath = \"synthetic:tube\"\ntrain = \"1-36\"\n[method]\nkind = \"autoencoder\"\ncomponents = 4\n{extra}"
            ))
            .unwrap()
        };
        let base = ae("");
        for inference in [
            "decoder_edge_weight = 0.5",
            "decoder_noise_power = 0",
            "encoder_passes = 0",
            "encoder_steps = 0",
            "fit_test = false",
            "dial_sparsity = 0.5",
        ] {
            assert!(ae(inference).trains_as(&base), "{inference} should be an inference key");
            assert_ne!(ae(inference), base, "{inference} changes the config");
        }
        for training in
            ["seed = 1", "lambda1 = 1.0", "iterations = 10", "feature_weights = \"uniform\"", "engine = \"graph\""]
        {
            assert!(!ae(training).trains_as(&base), "{training} should be a training key");
        }
        // With the vertex term the decoder decodes in training.
        let vertex = ae("lambda_vertex = 1.0");
        assert!(!ae("lambda_vertex = 1.0\ndecoder_edge_weight = 0.5").trains_as(&vertex));
        assert!(ae("lambda_vertex = 1.0\nencoder_steps = 0").trains_as(&vertex));
        // Other data, or a linear method's key, count.
        let other_data = Config::from_toml(&GOOD.replace("1-36", "1-30")).unwrap();
        assert!(!other_data.trains_as(&Config::from_toml(GOOD).unwrap()));
        let splocs = Config::from_toml(GOOD).unwrap();
        assert!(splocs.trains_as(&splocs.clone()));
        assert!(!Config::from_toml(&GOOD.replace("components = 5", "components = 6")).unwrap().trains_as(&splocs));
    }

    #[test]
    fn parses_a_valid_config() {
        let c = Config::from_toml(GOOD).unwrap();
        assert_eq!(c.kind(), MethodKind::Splocs);
        assert_eq!(c.method.components(), 5);
        assert_eq!(c.data.train, FrameSelection::Ranges(vec![(1, 36)]));
        let train = c.data.train.resolve("data.train", 60, None).unwrap();
        assert_eq!(train, (0..36).collect::<Vec<_>>());
        let test = c.data.test.unwrap().resolve("data.test", 60, Some(&train)).unwrap();
        assert_eq!(test, (36..60).collect::<Vec<_>>());
    }

    #[test]
    fn unknown_keys_are_rejected_with_their_name() {
        let e = Config::from_toml(&GOOD.replace("components = 5", "componets = 5")).unwrap_err().to_string();
        assert!(e.contains("componets"), "{e}");
        let e = Config::from_toml(&GOOD.replace("[method]", "[method]\nlayers = 2")).unwrap_err().to_string();
        assert!(e.contains("method.layers") && e.contains("splocs"), "{e}");
    }

    #[test]
    fn bad_values_name_key_and_value() {
        let e = Config::from_toml(&GOOD.replace("[0.1, 0.7]", "[0.8, 0.7]")).unwrap_err().to_string();
        assert!(e.contains("d_min (0.8) must be below d_max (0.7)"), "{e}");
        let e = Config::from_toml(&GOOD.replace("components = 5", "components = 0")).unwrap_err().to_string();
        assert!(e.contains("method.components"), "{e}");
        let e = Config::from_toml(&GOOD.replace("1-36", "5-3")).unwrap_err().to_string();
        assert!(e.contains("data.train") && e.contains("5-3"), "{e}");
        let e = Config::from_toml(&GOOD.replace("synthetic:tube", "synthetic:cube")).unwrap_err().to_string();
        assert!(e.contains("cube"), "{e}");
        let e = Config::from_toml(&GOOD.replace("kind = \"splocs\"", "kind = \"ica\"")).unwrap_err().to_string();
        assert!(e.contains("method.kind") && e.contains("ica"), "{e}");
    }

    #[test]
    fn frame_selection_forms() {
        assert_eq!(FrameSelection::parse("k", "every:10").unwrap().resolve("k", 25, None).unwrap(), vec![0, 10, 20]);
        assert_eq!(FrameSelection::parse("k", "1-3, 7").unwrap().resolve("k", 10, None).unwrap(), vec![0, 1, 2, 6]);
        assert!(
            FrameSelection::parse("k", "1-30")
                .unwrap()
                .resolve("k", 10, None)
                .unwrap_err()
                .to_string()
                .contains("past the last frame")
        );
        assert!(FrameSelection::parse("k", "every:0").is_err());
        assert!(FrameSelection::parse("k", "x").is_err());
    }

    #[test]
    fn engine_and_device_are_checked() {
        let base = "[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"autoencoder\"\n";
        let ok = Config::from_toml(&format!("{base}engine = \"graph\"\ndevice = \"cpu\"\n")).unwrap();
        let MethodConfig::Autoencoder(m) = &ok.method else { panic!("kind") };
        assert_eq!(m.engine, crate::nn::config::Engine::Graph);
        for (line, key) in [("engine = \"fast\"", "method.engine"), ("device = \"tpu\"", "method.device")] {
            let e = Config::from_toml(&format!("{base}{line}\n")).unwrap_err().to_string();
            assert!(e.contains(key), "{e}");
        }
        for (line, key, value) in [
            ("beta2 = 1.0", "method.beta2", "1 must be in [0, 1)"),
            ("beta1 = -0.1", "method.beta1", "-0.1 must be in [0, 1)"),
            ("scaling = \"minmax\"", "method.scaling", "`minmax`"),
            ("learning_rate_final = 0", "method.learning_rate_final", "0"),
            ("scaling_quantile = 0.2", "method.scaling_quantile", "0.2 must be in [0, 0.05]"),
            ("scaling_quantile = -0.001", "method.scaling_quantile", "-0.001"),
            ("scaling_fence = -1.0", "method.scaling_fence", "-1 must be a finite number"),
            ("decoder_edge_weight = -0.1", "method.decoder_edge_weight", "-0.1 must be a number in [0, 100]"),
            ("decoder_edge_weight = nan", "method.decoder_edge_weight", "NaN must be a number in [0, 100]"),
            ("decoder_edge_weight = 1e3", "method.decoder_edge_weight", "1000 must be a number in [0, 100]"),
            ("decoder_noise_power = -1", "method.decoder_noise_power", "-1 must be a number in [0, 8]"),
            ("decoder_noise_power = nan", "method.decoder_noise_power", "NaN must be a number in [0, 8]"),
            ("decoder_noise_power = 9", "method.decoder_noise_power", "9 must be a number in [0, 8]"),
        ] {
            let e = Config::from_toml(&format!("{base}{line}\n")).unwrap_err().to_string();
            assert!(e.contains(key) && e.contains(value), "{e}");
        }
        let ok = Config::from_toml(&format!("{base}beta2 = 0.99\nscaling = \"global\"\n")).unwrap();
        let MethodConfig::Autoencoder(m) = &ok.method else { panic!("kind") };
        assert_eq!((m.beta2, m.scaling, m.scaling_quantile, m.scaling_fence), (0.99, ScalingName::Global, 1e-3, 1.0));
        assert_eq!((m.decoder_edge_weight, m.decoder_noise_power), (AE_DECODER_EDGE_WEIGHT, AE_DECODER_NOISE_POWER));
        // The keys at their defaults are left out of a written config; other values are written.
        let written = toml::to_string(&ok.method).unwrap();
        assert!(!written.contains("decoder_edge_weight") && !written.contains("decoder_noise_power"), "{written}");
        let exact = Config::from_toml(&format!("{base}decoder_edge_weight = 1e-6\ndecoder_noise_power = 0\n")).unwrap();
        let written = toml::to_string(&exact.method).unwrap();
        assert!(written.contains("decoder_edge_weight = ") && written.contains("decoder_noise_power = "), "{written}");
        let pca = "[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"pca\"\nengine = \"graph\"\n";
        assert!(Config::from_toml(pca).unwrap_err().to_string().contains("engine"));
    }

    #[test]
    fn dial_sparsity_is_auto_or_a_number() {
        let base = "[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"autoencoder\"\n";
        let read = |line: &str| {
            let c = Config::from_toml(&format!("{base}{line}\n"))?;
            let MethodConfig::Autoencoder(m) = c.method else { panic!("kind") };
            Ok::<_, Error>(m.dial_sparsity)
        };
        assert_eq!(read("").unwrap(), DialSparsity::Auto);
        assert_eq!(read("dial_sparsity = \"auto\"").unwrap(), DialSparsity::Auto);
        assert_eq!(read("dial_sparsity = 0").unwrap(), DialSparsity::Fixed(0.0));
        assert_eq!(read("dial_sparsity = 0.03").unwrap(), DialSparsity::Fixed(0.03));
        assert_eq!(DialSparsity::Auto.candidates(), DialSparsity::CANDIDATES.to_vec());
        assert_eq!(DialSparsity::Fixed(0.1).candidates(), vec![0.1]);
        for (line, value) in [
            ("dial_sparsity = 1.0", "1 must be \"auto\""),
            ("dial_sparsity = -0.5", "-0.5"),
            ("dial_sparsity = \"often\"", "`often`"),
        ] {
            let e = read(line).unwrap_err().to_string();
            assert!(e.contains("dial_sparsity") && e.contains(value), "{line}: {e}");
        }
        // Written back as it was given (the string or the number), and read again the same.
        for v in [DialSparsity::Auto, DialSparsity::Fixed(0.0), DialSparsity::Fixed(0.01)] {
            let m = AutoencoderMethod { dial_sparsity: v, ..Default::default() };
            let table = MethodConfig::Autoencoder(m).to_table().unwrap();
            let text = toml::to_string(&table).unwrap();
            let back = Config::from_toml(&format!("[data]\npath = \"synthetic:tube\"\n[method]\n{text}")).unwrap();
            let MethodConfig::Autoencoder(m) = back.method else { panic!("kind") };
            assert_eq!(m.dial_sparsity, v, "{text}");
        }
    }

    #[test]
    fn syntax_errors_carry_a_line() {
        let e = Config::from_toml("name = \"a\"\n[data]\npath = 3\n[method]\nkind = \"pca\"\n").unwrap_err();
        match e {
            Error::Parse { line, .. } => assert_eq!(line, Some(3)),
            other => panic!("unexpected {other}"),
        }
    }
}

impl std::fmt::Display for FrameSelection {
    /// The config syntax that parses back to the same selection.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FrameSelection::All => write!(f, "all"),
            FrameSelection::Rest => write!(f, "rest"),
            FrameSelection::Every(n) => write!(f, "every:{n}"),
            FrameSelection::Ranges(r) => {
                let parts: Vec<String> =
                    r.iter().map(|&(a, b)| if a == b { a.to_string() } else { format!("{a}-{b}") }).collect();
                write!(f, "{}", parts.join(","))
            }
        }
    }
}

impl std::fmt::Display for RestShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RestShape::First => write!(f, "first"),
            RestShape::Mean => write!(f, "mean"),
            RestShape::File(p) => write!(f, "{}", p.display()),
        }
    }
}

impl DataConfig {
    /// The template mesh of a NumPy `path` (`None` for mesh files and synthetic data). Errors,
    /// naming the key, when a NumPy path has no `template`, or `template` / `array` are given
    /// for another kind of path.
    pub fn numpy_template(&self) -> Result<Option<&Path>> {
        let numpy = crate::mesh::npy::is_numpy_path(&self.path);
        if numpy && self.template.is_none() {
            return Err(Error::config(
                "data.template",
                format!("is required with a NumPy data.path (`{}`): the mesh file giving the faces", self.path),
            ));
        }
        let hdf5 = crate::mesh::hdf5::is_hdf5_path(&self.path);
        if !numpy && ((self.template.is_some() && !hdf5) || self.array.is_some()) {
            let key = if self.array.is_none() { "data.template" } else { "data.array" };
            return Err(Error::config(
                key,
                format!("applies to a NumPy data.path (.npy or .npz) only, not `{}`", self.path),
            ));
        }
        if self.dataset.is_some() && !hdf5 {
            return Err(Error::config(
                "data.dataset",
                format!("applies to an HDF5 data.path (.h5, .hdf5 or .hdf) only, not `{}`", self.path),
            ));
        }
        if let Some(d) = &self.dataset {
            if d.trim().is_empty() {
                return Err(Error::config(
                    "data.dataset",
                    "is empty: name a dataset of the HDF5 file (e.g. \"verts\")",
                ));
            }
            if matches!(crate::mesh::hdf5::split_spec(&self.path), Some((_, Some(_)))) {
                return Err(Error::config(
                    "data.dataset",
                    format!("`{d}` is given, and data.path `{}` names a dataset too: give one", self.path),
                ));
            }
        }
        Ok(if numpy { self.template.as_deref() } else { None })
    }

    /// The HDF5 source of the data: (file, dataset, template), `None` unless `path` is an HDF5
    /// file (`x.h5`, or `x.h5:dataset`). The dataset is `data.dataset`, else the path's suffix,
    /// else `verts`; the faces come from `data.template`, else the file's `tris`.
    pub fn hdf5_source(&self) -> Option<(&Path, &str, Option<&Path>)> {
        let (file, suffix) = crate::mesh::hdf5::split_spec(&self.path)?;
        let dataset = self.dataset.as_deref().or(suffix).unwrap_or(crate::mesh::hdf5::DEFAULT_DATASET);
        Some((Path::new(file), dataset, self.template.as_deref()))
    }

    /// The `[data]` table with every default written out (for the artefact's config.toml).
    pub fn to_table(&self) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("path".into(), self.path.clone().into());
        t.insert("train".into(), self.train.to_string().into());
        if let Some(test) = &self.test {
            t.insert("test".into(), test.to_string().into());
        }
        if let Some(v) = &self.validation {
            t.insert("validation".into(), v.to_string().into());
        }
        t.insert("rest".into(), self.rest.to_string().into());
        t.insert("align".into(), (if self.align == Align::Rigid { "rigid" } else { "none" }).into());
        t.insert("unit_box".into(), self.unit_box.into());
        if let Some(a) = &self.array {
            t.insert("array".into(), a.clone().into());
        }
        if let Some(p) = &self.template {
            t.insert("template".into(), p.display().to_string().into());
        }
        if let Some(d) = &self.dataset {
            t.insert("dataset".into(), d.clone().into());
        }
        t.insert("cache".into(), self.cache.to_config_string().into());
        t
    }
}

/// Renders a resolved config (name, `[data]`, and a fully specified `[method]` table) as TOML.
pub fn resolved_toml(name: &str, data: &DataConfig, method: toml::Table, output: &OutputConfig) -> String {
    let mut root = toml::Table::new();
    root.insert("name".into(), name.into());
    root.insert("data".into(), toml::Value::Table(data.to_table()));
    root.insert("method".into(), toml::Value::Table(method));
    let mut out = toml::Table::new();
    out.insert("views".into(), output.views.into());
    root.insert("output".into(), toml::Value::Table(out));
    format!(
        "# Resolved by meshdeco {}: every default written out.\n{}",
        env!("CARGO_PKG_VERSION"),
        toml::to_string(&root).unwrap_or_default()
    )
}

#[cfg(test)]
mod display_tests {
    use super::*;

    #[test]
    fn selections_print_in_their_own_syntax() {
        for s in ["all", "rest", "every:10", "1-36", "1-3,7,9-12"] {
            assert_eq!(FrameSelection::parse("k", s).unwrap().to_string(), s);
        }
    }

    #[test]
    fn resolved_config_parses_back() {
        let c = Config::from_toml("name = \"x\"\n[data]\npath = \"synthetic:tube\"\ntrain = \"every:2\"\ntest = \"rest\"\n[method]\nkind = \"pca\"\n").unwrap();
        let mut m = toml::Table::new();
        m.insert("kind".into(), "pca".into());
        m.insert("components".into(), 5.into());
        let text = resolved_toml(&c.name, &c.data, m, &OutputConfig { views: true });
        let back = Config::from_toml(&text).unwrap();
        assert_eq!(back.data, c.data);
        assert_eq!(back.method.components(), 5);
        assert!(back.output.views);
        assert!(!c.output.views, "views are written only on request");
        assert!(
            Config::from_toml("[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"pca\"\n[output]\nview = true\n")
                .is_err()
        );
    }
}
