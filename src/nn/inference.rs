//! A trained autoencoder: encode, decode, component analysis, synthesis, interpolation, and
//! saving/loading (Burn burnpack record + JSON hyperparameters).
//!
//! Inference runs the same hand-written kernels as training ([`super::engine`]); the codes `Z`
//! and features are `f64` at the interface (`N × 9` per shape, vertex-major).

use std::path::Path;
use std::sync::OnceLock;

use super::latent_fit::DecoderVjp;

use burn::module::Module;
use burn::store::ModuleRecord;
use burn::tensor::Bytes;
use serde::{Deserialize, Serialize};

use super::checkpoint::Checkpoint;
use super::config::AutoencoderConfig;
use super::data::{WIDTH, shape_from_vcb, vcb_from_shapes};
use super::engine::{self, Weights, Workspace};
use super::kernels::padded_width;
use super::model::{AutoencoderModule, MeshConv};
use super::neighbors::NeighborIndex;
use super::training::{default_device, load_layers};
use crate::artifact::write_atomic;
use crate::error::{Error, Result};
use crate::representation::Features;

/// File name of the parameters inside a model directory.
pub const MODEL_FILE: &str = "autoencoder.bpk";
/// File name of the hyperparameters inside a model directory.
pub const META_FILE: &str = "autoencoder.json";

/// Hyperparameters and mesh identity stored next to the parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    /// Format tag.
    pub format: String,
    /// Hyperparameters of the training run.
    pub config: AutoencoderConfig,
    /// Number of vertices N.
    pub n_vertices: usize,
    /// [`NeighborIndex::fingerprint`] of the rest mesh.
    pub neighbor_fingerprint: u64,
}

const FORMAT: &str = "meshdeco-autoencoder-1";

/// Shapes processed per inference pass.
const INFER_BATCH: usize = 32;

/// Frames per run of [`Autoencoder::encode_with_passes`] (8 inference batches).
const ENCODE_RUN: usize = 8 * INFER_BATCH;

/// Codes decoded per pass of [`Autoencoder::analyze_components`] (few: it keeps only what it
/// returns, and a pass's buffers grow with the number of codes).
const ANALYSIS_BATCH: usize = 8;

/// A trained mesh autoencoder.
///
/// The parameters are held once, as the plain arrays the kernels run on; the Burn module is
/// built only when asked for ([`Self::module`]) or saved.
#[derive(Debug)]
pub struct Autoencoder {
    config: AutoencoderConfig,
    neighbors: NeighborIndex,
    weights: Weights,
    module: OnceLock<AutoencoderModule>,
    /// The decoder's Jacobian products (built on first use: a copy of the parameters).
    decoder: OnceLock<DecoderVjp>,
}

/// One latent dimension of the component analysis (see [`Autoencoder::analyze_components`]):
/// its range over the data, the extreme kept, how far that moves the shape, its rank and centre.
/// The trained artefact stores these (`autoencoder.json`'s `analysis`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComponentSummary {
    /// Latent dimension k.
    pub dim: usize,
    /// Rank by `distance` (0 = largest).
    pub rank: usize,
    /// Minimum of `Z_k` over the data.
    pub z_min: f64,
    /// Maximum of `Z_k` over the data.
    pub z_max: f64,
    /// The extreme kept (`z_min` or `z_max`), i.e. `Z_h,k`.
    pub z_extreme: f64,
    /// Feature-space distance ‖decode(z_h) − decode(z_r)‖ (Frobenius over N × 9); for a piece
    /// translation, the translation's length in data units.
    pub distance: f64,
    /// Centre vertex `argmax_i ‖C_k,i‖` (a piece translation: the piece's vertex nearest its
    /// rest centroid).
    pub center: usize,
    /// Number of vertices whose change is at least 10 % of the largest change.
    pub support_size: usize,
    /// For a dimension after the network's K (a piece translation of a multi-piece mesh):
    /// `[piece, axis]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub piece: Option<[usize; 2]>,
}

/// One latent dimension's extreme shape: its summary, decoded features and per-vertex change.
#[derive(Debug, Clone, Serialize)]
pub struct ComponentExtreme {
    #[serde(flatten)]
    pub summary: ComponentSummary,
    /// Decoded features of the extreme shape, `N × 9` vertex-major.
    pub features: Vec<f64>,
    /// Per-vertex feature change ‖Δx_i‖ against the decoded reference (N values).
    pub vertex_change: Vec<f64>,
}

/// Result of the component analysis.
#[derive(Debug, Clone, Serialize)]
pub struct ComponentAnalysis {
    /// Index of the reference shape in the analysed data (`usize::MAX`: a code given by the caller,
    /// [`Autoencoder::analyze_codes_around`]).
    pub reference: usize,
    /// Code of the reference shape `Z_r` (K values).
    pub z_reference: Vec<f64>,
    /// Decoded reference features, `N × 9`.
    pub reference_features: Vec<f64>,
    /// Components ordered by rank (largest distance first).
    pub components: Vec<ComponentExtreme>,
}

impl ComponentAnalysis {
    /// The extreme code `Z_h,k` of every dimension k (K values, indexed by dimension).
    pub fn extremes_by_dim(&self) -> Vec<f64> {
        let mut v = vec![0.0; self.z_reference.len()];
        for c in &self.components {
            v[c.summary.dim] = c.summary.z_extreme;
        }
        v
    }
}

impl Autoencoder {
    /// Wraps trained parameters (errors if a parameter is not finite or sizes disagree).
    pub fn new(config: AutoencoderConfig, module: AutoencoderModule, neighbors: NeighborIndex) -> Result<Self> {
        let weights = Weights::from_module(&module)?;
        Self::from_weights(config, weights, neighbors)
    }

    /// Wraps trained parameters given as plain arrays (errors if a parameter is not finite or
    /// sizes disagree).
    pub fn from_weights(config: AutoencoderConfig, mut weights: Weights, neighbors: NeighborIndex) -> Result<Self> {
        weights.least_squares = config.encoder == super::config::EncoderKind::LeastSquares;
        if weights.n != neighbors.n_vertices()
            || weights.k != config.components
            || weights.layers.len() != config.layers
            || weights.c.len() != weights.k * 9 * weights.n
        {
            return Err(Error::Invalid(format!(
                "model parameters (N = {}, K = {}, L = {}) do not match the mesh (N = {}) / config (K = {}, L = {})",
                weights.n,
                weights.k,
                weights.layers.len(),
                neighbors.n_vertices(),
                config.components,
                config.layers
            )));
        }
        weights.check_layers()?;
        weights.check_components()?;
        Ok(Autoencoder { config, neighbors, weights, module: OnceLock::new(), decoder: OnceLock::new() })
    }

    /// Hyperparameters.
    pub fn config(&self) -> &AutoencoderConfig {
        &self.config
    }

    /// The parameters as a Burn module (built on first use: a copy of the parameters).
    pub fn module(&self) -> &AutoencoderModule {
        self.module.get_or_init(|| self.build_module())
    }

    fn build_module(&self) -> AutoencoderModule {
        let device = default_device();
        let w = &self.weights;
        AutoencoderModule {
            layers: w
                .layers
                .iter()
                .map(|l| MeshConv::from_arrays(l.wp.as_flattened(), l.wn.as_flattened(), &l.b, &l.bd, &device))
                .collect(),
            components: AutoencoderModule::component_blocks(&w.c, w.n, &device),
        }
    }

    /// The parameters as the plain arrays the kernels run on.
    pub fn weights(&self) -> &Weights {
        &self.weights
    }

    /// The neighbour index.
    pub fn neighbors(&self) -> &NeighborIndex {
        &self.neighbors
    }

    /// Latent dimension K.
    pub fn n_components(&self) -> usize {
        self.weights.k
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.weights.n
    }

    /// Latent map `C` as `[K, 9N]` row-major (vertex-major columns).
    pub fn components_matrix(&self) -> &[f32] {
        &self.weights.c
    }

    /// Centre vertex `argmax_i ‖C_k,i‖` of every component.
    pub fn centers(&self) -> Vec<usize> {
        let n = self.weights.n;
        self.weights
            .c
            .chunks_exact(9 * n)
            .map(|row| {
                let mut best = (0, -1.0f32);
                for (i, v) in row.chunks_exact(9).enumerate() {
                    let s: f32 = v.iter().map(|x| x * x).sum();
                    if s > best.1 {
                        best = (i, s);
                    }
                }
                best.0
            })
            .collect()
    }

    fn check_features(&self, f: &Features) -> Result<()> {
        if f.width != WIDTH || f.n_elements != self.weights.n || f.data.len() != f.n_frames * f.n_elements * f.width {
            return Err(Error::Invalid(format!(
                "features are {} frames × {} elements × {} (len {}), the model needs N = {} × 9",
                f.n_frames,
                f.n_elements,
                f.width,
                f.data.len(),
                self.weights.n
            )));
        }
        if let Some(p) = f.data.iter().position(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!("features are not finite at flat index {p} ({})", f.data[p])));
        }
        Ok(())
    }

    /// Latent codes of every frame: the encoder with the model's
    /// [`AutoencoderConfig::encoder_passes`] residual passes.
    ///
    /// # Shapes
    /// `features`: F × N × 9 → output F codes of K values.
    pub fn encode(&self, features: &Features) -> Result<Vec<Vec<f64>>> {
        self.encode_with_passes(features, self.config.encoder_passes)
    }

    /// The decoder's Jacobian products ([`DecoderVjp`]: decode, vector–Jacobian products, the
    /// exact Jacobian), built on first use (a copy of the parameters) and kept.
    pub fn decoder_vjp(&self) -> Result<&DecoderVjp> {
        if let Some(d) = self.decoder.get() {
            return Ok(d);
        }
        let d = DecoderVjp::new(self)?;
        Ok(self.decoder.get_or_init(|| d))
    }

    /// Latent codes with `passes` residual passes: `z₀ = E(x)`, then `passes` times
    /// `z ← z + E(x) − E(D(z))` (0: the paper's one-pass encoder).
    ///
    /// # Shapes
    /// `features`: F × N × 9 → output F codes of K values.
    ///
    /// Frames go through in runs of [`ENCODE_RUN`] (a multiple of the inference batch, so every
    /// frame meets the same batch-mates as in one run over all): memory is one run's, not the
    /// data's.
    pub fn encode_with_passes(&self, features: &Features, passes: usize) -> Result<Vec<Vec<f64>>> {
        self.check_features(features)?;
        let per = features.n_elements * features.width;
        let mut out = Vec::with_capacity(features.n_frames);
        for start in (0..features.n_frames).step_by(ENCODE_RUN) {
            let end = (start + ENCODE_RUN).min(features.n_frames);
            let run = Features {
                n_frames: end - start,
                n_elements: features.n_elements,
                width: features.width,
                data: features.data[start * per..end * per].to_vec(),
            };
            let ex = self.encode_once(&run)?;
            let mut z = ex.clone();
            for _ in 0..passes {
                let ed = self.encode_once(&self.decode(&z)?)?;
                for ((zf, a), b) in z.iter_mut().zip(&ex).zip(&ed) {
                    for ((v, x), y) in zf.iter_mut().zip(a).zip(b) {
                        *v += x - y;
                    }
                }
            }
            out.extend(z);
        }
        Ok(out)
    }

    /// The network encoder's one pass `z = C·f(x)`.
    fn encode_once(&self, features: &Features) -> Result<Vec<Vec<f64>>> {
        self.check_features(features)?;
        let n = self.weights.n;
        let k = self.weights.k;
        let mut out = Vec::with_capacity(features.n_frames);
        let shapes: Vec<Vec<f32>> =
            (0..features.n_frames).map(|f| features.frame(f).iter().map(|&v| v as f32).collect()).collect();
        for chunk in shapes.chunks(INFER_BATCH) {
            let b = chunk.len();
            let bp = padded_width(b);
            let mut ws = Workspace::new(n, k, self.weights.layers.len(), bp);
            let x = vcb_from_shapes(chunk.iter().map(|s| s.as_slice()), b, n);
            engine::encode(&mut ws, &self.weights, &self.neighbors, &x, b);
            let zt = ws.latent_t();
            for j in 0..b {
                out.push((0..k).map(|kk| zt[kk * bp + j] as f64).collect());
            }
        }
        Ok(out)
    }

    /// Features decoded from latent codes.
    ///
    /// # Shapes
    /// `codes`: F codes of K values → F × N × 9.
    pub fn decode(&self, codes: &[Vec<f64>]) -> Result<Features> {
        let mut out = Features::zeros(codes.len(), self.weights.n, WIDTH);
        self.decode_each(codes, INFER_BATCH, |f, v| out.frame_mut(f).copy_from_slice(&v))?;
        Ok(out)
    }

    /// Decodes `codes` in passes of `batch` codes, handing each decoded frame (`N × 9`) to `each`
    /// in order (so that no more than one pass's frames exist at a time).
    fn decode_each(&self, codes: &[Vec<f64>], batch: usize, mut each: impl FnMut(usize, Vec<f64>)) -> Result<()> {
        let n = self.weights.n;
        let k = self.weights.k;
        if let Some((i, z)) = codes.iter().enumerate().find(|(_, z)| z.len() != k || z.iter().any(|v| !v.is_finite())) {
            return Err(Error::Invalid(format!("latent code {i} must be {k} finite numbers (got {} values)", z.len())));
        }
        for (ci, chunk) in codes.chunks(batch).enumerate() {
            let b = chunk.len();
            let bp = padded_width(b);
            let mut ws = Workspace::new(n, k, self.weights.layers.len(), bp);
            {
                let zt = ws.latent_t_mut();
                zt.fill(0.0);
                for (j, z) in chunk.iter().enumerate() {
                    for kk in 0..k {
                        zt[kk * bp + j] = z[kk] as f32;
                    }
                }
            }
            engine::decode(&mut ws, &self.weights, &self.neighbors, b);
            for j in 0..b {
                each(ci * batch + j, shape_from_vcb(ws.output(), bp, j));
            }
        }
        Ok(())
    }

    /// Encode then decode.
    pub fn reconstruct(&self, features: &Features) -> Result<Features> {
        self.decode(&self.encode(features)?)
    }

    /// Component analysis (Tan et al.): for each latent dimension k, the min and max of `Z_k`
    /// over `data` are put in turn into the code of the reference frame `reference`, both are
    /// decoded, and the one farther (Frobenius distance in feature space) from the decoded
    /// reference is kept; components are ranked by that distance, largest first.
    pub fn analyze_components(&self, data: &Features, reference: usize) -> Result<ComponentAnalysis> {
        if reference >= data.n_frames {
            return Err(Error::Invalid(format!(
                "reference frame {reference} is out of range (the data have {} frames)",
                data.n_frames
            )));
        }
        self.analyze_codes(&self.encode(data)?, reference)
    }

    /// [`Autoencoder::analyze_components`] from the training shapes' codes (what
    /// [`Autoencoder::encode`] gives), so that a caller who has them does not encode again.
    pub fn analyze_codes(&self, z: &[Vec<f64>], reference: usize) -> Result<ComponentAnalysis> {
        if reference >= z.len() {
            return Err(Error::Invalid(format!("reference frame {reference} is out of range ({} codes)", z.len())));
        }
        let mut a = self.analyze_codes_around(z, &z[reference])?;
        a.reference = reference;
        Ok(a)
    }

    /// [`Autoencoder::analyze_codes`] around a given reference code `zr` (K values: e.g. the
    /// code of a rest shape that is not one of the analysed shapes; `reference` is then
    /// `usize::MAX`). The extremes are still the codes' per-dimension minima and maxima.
    pub fn analyze_codes_around(&self, z: &[Vec<f64>], zr: &[f64]) -> Result<ComponentAnalysis> {
        let k = self.weights.k;
        let n = self.weights.n;
        let reference = usize::MAX;
        if z.is_empty() {
            return Err(Error::Invalid("component analysis: no codes".into()));
        }
        if let Some(i) = z.iter().position(|c| c.len() != k) {
            return Err(Error::Invalid(format!("code {i} has {} values, the model has {k} components", z[i].len())));
        }
        if zr.len() != k || zr.iter().any(|x| !x.is_finite()) {
            return Err(Error::Invalid(format!(
                "the reference code has {} values (the model {k}) or is not finite",
                zr.len()
            )));
        }
        let zr = zr.to_vec();
        let mut codes = vec![zr.clone()];
        let mut ranges = Vec::with_capacity(k);
        for kk in 0..k {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for zf in z {
                lo = lo.min(zf[kk]);
                hi = hi.max(zf[kk]);
            }
            ranges.push((lo, hi));
            for v in [lo, hi] {
                let mut c = zr.clone();
                c[kk] = v;
                codes.push(c);
            }
        }
        // Decoded a few codes at a time (codes[0] is the reference, then lo and hi of every
        // dimension): only the kept extremes' features are held, not all 2K + 1 decoded frames.
        let norm = |c: &[f64]| c.iter().map(|v| v * v).sum::<f64>().sqrt();
        let centers = self.centers();
        let mut reference_features = Vec::new();
        let mut lo_frame: Option<(Vec<f64>, Vec<f64>)> = None;
        let mut comps = Vec::with_capacity(k);
        self.decode_each(&codes, ANALYSIS_BATCH, |i, frame| {
            if i == 0 {
                reference_features = frame;
                return;
            }
            let c = vertex_change(&frame, &reference_features);
            if i % 2 == 1 {
                lo_frame = Some((frame, c));
                return;
            }
            let kk = (i - 2) / 2;
            let (lo, hi) = ranges[kk];
            let (f_lo, c_lo) = lo_frame.take().expect("lo decoded before hi");
            let (d_lo, d_hi) = (norm(&c_lo), norm(&c));
            let (z_extreme, distance, features, vertex_change) =
                if d_hi >= d_lo { (hi, d_hi, frame, c) } else { (lo, d_lo, f_lo, c_lo) };
            let support_size = support_size(&vertex_change);
            debug_assert_eq!(vertex_change.len(), n);
            comps.push(ComponentExtreme {
                summary: ComponentSummary {
                    dim: kk,
                    rank: 0,
                    z_min: lo,
                    z_max: hi,
                    z_extreme,
                    distance,
                    center: centers[kk],
                    support_size,
                    piece: None,
                },
                features,
                vertex_change,
            });
        })?;
        comps.sort_by(|a, b| b.summary.distance.total_cmp(&a.summary.distance).then(a.summary.dim.cmp(&b.summary.dim)));
        for (r, c) in comps.iter_mut().enumerate() {
            c.summary.rank = r;
        }
        Ok(ComponentAnalysis { reference, z_reference: zr, reference_features, components: comps })
    }

    /// Component analysis of dial directions (a dial basis, [`crate::methods::sparse_dials`]):
    /// per direction m the decoding of `zr + directions[m]` against that of `zr` — distance,
    /// centre (the vertex of largest feature change), support (vertices changing ≥ 10 % of the
    /// peak) and rank. `dial_ranges[m]` is the training dials' (min, max) of direction m; the
    /// summaries are in dial units (`z_min`, `z_max` that range, `z_extreme` 1).
    pub fn analyze_directions(
        &self,
        zr: &[f64],
        directions: &[Vec<f64>],
        dial_ranges: &[(f64, f64)],
    ) -> Result<Vec<ComponentSummary>> {
        let k = self.weights.k;
        if zr.len() != k || directions.len() != k || dial_ranges.len() != k || directions.iter().any(|d| d.len() != k) {
            return Err(Error::Invalid(format!(
                "component analysis of dial directions: {} directions and a reference of {} numbers for {k} dimensions",
                directions.len(),
                zr.len()
            )));
        }
        let codes: Vec<Vec<f64>> = std::iter::once(zr.to_vec())
            .chain(directions.iter().map(|d| zr.iter().zip(d).map(|(a, b)| a + b).collect()))
            .collect();
        let mut reference_features = Vec::new();
        let mut comps = Vec::with_capacity(k);
        self.decode_each(&codes, ANALYSIS_BATCH, |i, frame| {
            if i == 0 {
                reference_features = frame;
                return;
            }
            let m = i - 1;
            let change = vertex_change(&frame, &reference_features);
            let distance = change.iter().map(|v| v * v).sum::<f64>().sqrt();
            let (mut center, mut peak) = (0, 0.0);
            for (v, &c) in change.iter().enumerate() {
                if c > peak {
                    (center, peak) = (v, c);
                }
            }
            let support_size = support_size(&change);
            comps.push(ComponentSummary {
                dim: m,
                rank: 0,
                z_min: dial_ranges[m].0,
                z_max: dial_ranges[m].1,
                z_extreme: 1.0,
                distance,
                center,
                support_size,
                piece: None,
            });
        })?;
        let mut order: Vec<usize> = (0..comps.len()).collect();
        order.sort_by(|&a, &b| comps[b].distance.total_cmp(&comps[a].distance).then(a.cmp(&b)));
        for (r, &m) in order.iter().enumerate() {
            comps[m].rank = r;
        }
        Ok(comps)
    }

    /// Synthesis code `z_k = Z_r,k + (Z_h,k − Z_r,k)·w_k` for the given `(dimension, weight)`
    /// pairs (other dimensions keep the reference's value).
    pub fn synthesis_code(&self, analysis: &ComponentAnalysis, weights: &[(usize, f64)]) -> Result<Vec<f64>> {
        let k = self.weights.k;
        let zh = analysis.extremes_by_dim();
        let mut z = analysis.z_reference.clone();
        for &(d, w) in weights {
            if d >= k || !w.is_finite() {
                return Err(Error::Invalid(format!(
                    "synthesis weight {d}:{w}: the dimension must be below {k} and the weight finite"
                )));
            }
            z[d] = analysis.z_reference[d] + (zh[d] - analysis.z_reference[d]) * w;
        }
        Ok(z)
    }

    /// Decoded synthesis (see [`Self::synthesis_code`]); one frame `N × 9`.
    pub fn synthesize(&self, analysis: &ComponentAnalysis, weights: &[(usize, f64)]) -> Result<Features> {
        let z = self.synthesis_code(analysis, weights)?;
        self.decode(&[z])
    }

    /// Linear interpolation in latent space from `za` to `zb` in `steps` frames (both ends
    /// included, `steps ≥ 2`), decoded.
    pub fn interpolate(&self, za: &[f64], zb: &[f64], steps: usize) -> Result<Features> {
        if steps < 2 {
            return Err(Error::Invalid(format!("interpolation needs at least 2 steps (got {steps})")));
        }
        if za.len() != zb.len() {
            return Err(Error::Invalid(format!("latent codes differ in length ({} vs {})", za.len(), zb.len())));
        }
        let codes: Vec<Vec<f64>> = (0..steps)
            .map(|s| {
                let t = s as f64 / (steps - 1) as f64;
                za.iter().zip(zb).map(|(a, b)| a + (b - a) * t).collect()
            })
            .collect();
        self.decode(&codes)
    }

    /// Saves `autoencoder.bpk` (Burn burnpack record of the parameters) and `autoencoder.json`
    /// (hyperparameters and mesh fingerprint) into `dir` (created if needed), atomically.
    pub fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        // A module built for the record is dropped right after (not kept beside the weights).
        let module = match self.module.get() {
            Some(m) => m.clone(),
            None => self.build_module(),
        };
        let bytes = module.into_record().into_bytes().map_err(|e| Error::Invalid(format!("module record: {e}")))?;
        let meta = ModelMeta {
            format: FORMAT.into(),
            config: self.config.clone(),
            n_vertices: self.weights.n,
            neighbor_fingerprint: self.neighbors.fingerprint(),
        };
        let json = serde_json::to_vec_pretty(&meta).map_err(|e| Error::Invalid(format!("model metadata: {e}")))?;
        write_atomic(&dir.join(MODEL_FILE), &bytes)?;
        write_atomic(&dir.join(META_FILE), &json)
    }

    /// Loads a model saved by [`Self::save`]; `neighbors` must be rebuilt from the stored rest
    /// mesh (checked against the saved fingerprint).
    pub fn load(dir: &Path, neighbors: NeighborIndex) -> Result<Self> {
        let meta_path = dir.join(META_FILE);
        let text = std::fs::read(&meta_path).map_err(|e| Error::io(&meta_path, e))?;
        let meta: ModelMeta =
            serde_json::from_slice(&text).map_err(|e| Error::parse(&meta_path, None, e.to_string()))?;
        if meta.format != FORMAT {
            return Err(Error::parse(&meta_path, None, format!("unknown model format `{}`", meta.format)));
        }
        meta.config.validate()?;
        Self::check_mesh(&meta_path, meta.n_vertices, meta.neighbor_fingerprint, &neighbors)?;
        // K sizes the components [K, 9N] the network is built with: bounded before allocating.
        let n = neighbors.n_vertices();
        if meta.config.components > n {
            return Err(Error::parse(
                &meta_path,
                None,
                format!(
                    "`config.components` is {}; a model of {n} vertices has at most {n} (one centre vertex each)",
                    meta.config.components
                ),
            ));
        }
        let path = dir.join(MODEL_FILE);
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        let model = Self::from_record_bytes(&path, meta.config, bytes, neighbors)?;
        model.check_magnitudes(&path)?;
        Ok(model)
    }

    /// Errors (naming `path` and the parameter) when a parameter's magnitude exceeds
    /// [`crate::artifact::MAX_MODEL_VALUE`]: damage, not training.
    fn check_magnitudes(&self, path: &Path) -> Result<()> {
        let max = crate::artifact::MAX_MODEL_VALUE;
        let w = &self.weights;
        let mut arrays: Vec<(String, &[f32])> = vec![("components".into(), &w.c)];
        for (l, lw) in w.layers.iter().enumerate() {
            arrays.push((format!("layers.{l}.weight_point"), lw.wp.as_flattened()));
            arrays.push((format!("layers.{l}.weight_neighbor"), lw.wn.as_flattened()));
            arrays.push((format!("layers.{l}.bias"), &lw.b));
            arrays.push((format!("layers.{l}.decoder_bias"), &lw.bd));
        }
        for (name, v) in arrays {
            if let Some(x) = v.iter().find(|x| !x.is_finite() || f64::from(x.abs()) > max) {
                return Err(Error::parse(
                    path,
                    None,
                    format!("parameter `{name}` holds {x:e}, beyond the ±{max:e} a model stores"),
                ));
            }
        }
        Ok(())
    }

    /// The model stored in a training checkpoint: its last step's parameters (a run with
    /// `validation` > 0 keeps its best step's instead, which the checkpoint holds beside them:
    /// [`Checkpoint::best`]).
    pub fn from_checkpoint(path: &Path, neighbors: NeighborIndex) -> Result<Self> {
        let ck = Checkpoint::load(path)?;
        Self::check_mesh(path, ck.header.n_vertices, ck.header.neighbor_fingerprint, &neighbors)?;
        let n = neighbors.n_vertices();
        let layers = load_layers(path, &ck.header.config, n, ck.layers, &default_device())?;
        let weights = Weights::from_parts(&layers, ck.components, n)?;
        Self::from_weights(ck.header.config, weights, neighbors)
    }

    fn check_mesh(path: &Path, n: usize, fp: u64, neighbors: &NeighborIndex) -> Result<()> {
        if n != neighbors.n_vertices() || fp != neighbors.fingerprint() {
            return Err(Error::Invalid(format!(
                "{}: the model was trained on a mesh with {n} vertices and other connectivity than the given rest mesh ({} vertices)",
                path.display(),
                neighbors.n_vertices()
            )));
        }
        Ok(())
    }

    fn from_record_bytes(
        path: &Path,
        config: AutoencoderConfig,
        bytes: Vec<u8>,
        neighbors: NeighborIndex,
    ) -> Result<Self> {
        let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(bytes.clone()))
            .map_err(|e| Error::parse(path, None, format!("module record: {e}")))?;
        let module = config
            .init(neighbors.n_vertices(), &default_device())
            .try_load_record(record)
            .map_err(|e| Error::parse(path, None, format!("module record: {e}")))?;
        // Every tensor is there with its shape (checked by the record), and the file is exactly
        // what saving those tensors writes: no byte inserted, moved or left over (a reader that
        // only checks that a tensor's bytes lie inside the file would read shifted values).
        let again = module
            .clone()
            .into_record()
            .into_bytes()
            .map_err(|e| Error::parse(path, None, format!("module record: {e}")))?;
        if again[..] != bytes[..] {
            let at = again.iter().zip(&bytes).position(|(a, b)| a != b).unwrap_or(again.len().min(bytes.len()));
            return Err(Error::parse(
                path,
                None,
                format!(
                    "{} bytes, where the model's parameter tensors take {} in the layout meshdeco writes (the first difference at byte {at}): the file was changed after training",
                    bytes.len(),
                    again.len()
                ),
            ));
        }
        Self::new(config, module, neighbors)
    }
}

/// Per vertex, the Euclidean length of the change of its 9 features from `reference` to
/// `frame` (both `N × 9`).
fn vertex_change(frame: &[f64], reference: &[f64]) -> Vec<f64> {
    frame
        .chunks_exact(WIDTH)
        .zip(reference.chunks_exact(WIDTH))
        .map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt())
        .collect()
}

/// Vertices whose change is at least 10 % of the largest (0 when nothing changes).
fn support_size(change: &[f64]) -> usize {
    let peak = change.iter().copied().fold(0.0, f64::max);
    if peak > 0.0 { change.iter().filter(|&&v| v >= 0.1 * peak).count() } else { 0 }
}
