//! The autoencoder method end to end: ACAP features of the preprocessed frames, scaling to
//! [−0.95, 0.95], training with checkpoints / resume / stop flag, measuring on vertices, the
//! component analysis, and the artefact directory; plus reloading for encode, synthesis,
//! interpolation and component export.
//!
//! Artefact directory (besides config.toml, metrics.json, weights.csv, components/):
//! - `model.json` + `model.bin`: meshdeco header (representation, scaling, unit box, training
//!   frame names, component analysis) with the rest mesh and the training codes;
//! - `autoencoder.bpk` + `autoencoder.json`: the Burn parameters and hyperparameters;
//! - `checkpoint.bin`: the last training checkpoint (model, Adam state, iteration, RNG), which
//!   `--resume` continues from;
//! - `training.jsonl`: one JSON object per iteration (loss terms, step time).
//!
//! **Meshes in several pieces.** The network reads the 9 ACAP numbers per vertex, which say how
//! each piece deforms but not where it sits. On a mesh with P ≥ 2 connected pieces the code
//! therefore has 3·(P − 1) more dimensions after the network's K: the translation `t_p` of every
//! piece but the anchor (the largest piece), in the representation's convention
//! ([`crate::representation::piece_placement`]; dimensionless, units of the rest bounding-box
//! diagonal). Encoding reads them off the shape, decoding places each piece by them, posing and
//! fitting solve for them with the network's dimensions; each is a component confined to its
//! piece (ranked after the network's, named `piece<p>_<axis>` in `components.csv`).

use std::io::{Seek, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::ae_fit::{AeFitEncoder, POINT_FIT_ITERATIONS};
use super::ae_pose::{AePoseConfig, AePoser};
use super::ae_vertex_loss::AcapVertexLoss;
use super::ae_vertex_steps::{VertexSteps, vertex_steps_apply};
use super::geodesic_support::GeodesicSupport;
use super::linear::{rest_from_arrays, rest_to_arrays};
use super::metrics_file::DialReadout;
use super::pose::single_frame;
use super::registry::{FitContext, FitStats, Fitted};
use crate::artifact::{self, ArrayStore};
use crate::config::{AeFeatures, AutoencoderMethod, DialSparsity, FeatureWeights, MethodConfig, MethodKind};
use crate::error::{Error, Result};
use crate::mesh::{self, MeshSequence, TriMesh, Vec3};
use crate::methods::sparse_dials::SparseDials;
use crate::methods::support_map::{ComponentLocality, SupportDistances, component_locality, support_ramp};
use crate::model::{Component, Model, PointFit, PoseOptions, PoseResult, RefineOptions, Refined};
use crate::nn::ComponentSummary;
use crate::nn::checkpoint::Checkpoint;
use crate::nn::{
    Autoencoder, AutoencoderConfig, CenterDistances, NeighborIndex, RunOptions, STALL_WINDOW, Trainer, TrainingData,
    stall_check_step,
};
use crate::preprocess::{Prepared, UnitBox};
use crate::representation::acap::{AcapDecoder, Consistency, FeatureMap};
use crate::representation::noise_sensitivity::{NOISE_DRAWS, NOISE_LEVEL, feature_noise_variance, noise_weights};
use crate::representation::roundtrip::Alignment;
use crate::representation::scaling::{FeatureScaling, RangeHistogram, ScalingMode};
use crate::representation::{Features, Representation, RepresentationKind, RepresentationOptions};

/// Checkpoint and per-iteration log file names (the artefact directory's work files).
pub use crate::artifact::{CHECKPOINT_FILE, LOG_FILE};
pub use crate::config::AE_GEODESIC_M;

/// Header of an autoencoder's `model.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AeHeader {
    /// Always `autoencoder`.
    pub method: String,
    /// Always `acap`.
    pub representation: String,
    /// ACAP rotation consistency (`bfs` or `global`).
    pub consistency: String,
    /// What the network's 9 numbers per vertex are (`features`: `acap` or `gradient`); absent
    /// in models trained before the key, which are `acap`.
    #[serde(default, skip_serializing_if = "AeFeatures::is_default")]
    pub features: AeFeatures,
    /// Edge weight μ of the ACAP decoder of the network's features (`decoder_edge_weight`;
    /// models trained before it get today's default,
    /// [`crate::config::AE_DECODER_EDGE_WEIGHT`]).
    #[serde(default = "default_decoder_edge_weight")]
    pub decoder_edge_weight: f64,
    /// Power of the per-vertex noise weights of that decoder's fit residual
    /// (`decoder_noise_power`; models trained before it get today's default,
    /// [`crate::config::AE_DECODER_NOISE_POWER`]).
    #[serde(default = "default_decoder_noise_power")]
    pub decoder_noise_power: f64,
    /// Feature scaling to [−0.95, 0.95] fitted on the training frames.
    pub scaling: FeatureScaling,
    /// Data scaling applied before encoding (identity unless `data.unit_box`).
    pub unit_box: UnitBox,
    /// Number of components K.
    pub components: usize,
    /// Names of the training frames (rows of `train_codes`).
    pub train_frames: Vec<String>,
    /// Index (into the training frames) of the reference shape of the component analysis (the
    /// dial origin) when `rest_code` is absent (models trained before it).
    pub reference: usize,
    /// The code of the rest mesh (`data.rest`), the encoder's with its residual passes and
    /// vertex steps: the reference code Z_r of the component analysis and of synthesis (dials
    /// 0 decode to the rest shape, whatever the training frames are).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rest_code: Option<Vec<f64>>,
    /// Component analysis: per latent dimension (index = dimension) the extreme code kept,
    /// the feature-space distance, its rank (0 = largest) and centre vertex. With a
    /// `dial_basis`, the network's K entries describe the K dial directions instead (index =
    /// dial; `z_min`, `z_max` the training dials' range, `z_extreme` 1: dial units).
    pub analysis: Vec<ComponentSummary>,
    /// The dial basis (`dial_sparsity > 0`, [`crate::methods::sparse_dials`]): K directions of
    /// K numbers (code units); dial m moves the network's code by direction m, and dials 0 are
    /// the rest code. Absent: one latent dimension per dial (the paper; models trained before
    /// it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dial_basis: Option<SparseDials>,
}

/// Heat-geodesic distances normalised by the largest geodesic distance (the trainer's
/// [`CenterDistances`]).
impl CenterDistances for GeodesicSupport {
    fn distances(&self, center: usize) -> Vec<f64> {
        SupportDistances::distances(self, &[center]).unwrap_or_else(|_| vec![f64::INFINITY; self.n_vertices()])
    }
}

fn default_decoder_edge_weight() -> f64 {
    crate::config::AE_DECODER_EDGE_WEIGHT
}

fn default_decoder_noise_power() -> f64 {
    crate::config::AE_DECODER_NOISE_POWER
}

/// The representation of an autoencoder: ACAP with its rotation consistency, the decoder edge
/// weight μ (`decoder_edge_weight`) and, for a noise power p > 0 (`decoder_noise_power`), each
/// vertex's fit residual in the decoder weighted by w_i^p, w_i the noise weight of its raw
/// features ([`noise_weights`] of [`feature_noise_variance`]
/// on the rest mesh: 1 up to the median sensitivity, below it for slivers and degenerate rings).
fn ae_representation(
    rest: &TriMesh,
    consistency: Consistency,
    map: FeatureMap,
    edge_weight: f64,
    noise_power: f64,
) -> Result<Representation> {
    let options = RepresentationOptions {
        acap_consistency: consistency,
        acap_decoder: AcapDecoder::FitInverse { edge_weight },
        acap_map: map,
        ..Default::default()
    };
    let rep = Representation::new(RepresentationKind::Acap, rest, options)?;
    if noise_power <= 0.0 {
        return Ok(rep);
    }
    let raw = |x: Features| Ok(x);
    let variance = feature_noise_variance(&rep, NOISE_LEVEL, NOISE_DRAWS, 0, &raw)?;
    let weights: Vec<f64> =
        noise_weights(&variance).iter().map(|w| w.powf(noise_power).max(f64::MIN_POSITIVE)).collect();
    rep.with_acap_fit_weights(&weights)
}

fn consistency_of(s: &str) -> Consistency {
    if s == "bfs" { Consistency::Bfs } else { Consistency::Global }
}

/// One component's summary, extreme shape (data units) and per-vertex feature change.
pub type Extreme = (ComponentSummary, Vec<Vec3>, Vec<f64>);

/// A trained autoencoder with everything needed to go from meshes to codes and back.
pub struct AeArtifact {
    pub header: AeHeader,
    /// Rest mesh in the model's (possibly unit-box) space.
    pub rest: TriMesh,
    pub representation: Representation,
    pub model: Autoencoder,
    /// Codes of the training frames (F × K).
    pub train_codes: Vec<Vec<f64>>,
}

/// The checks of an autoencoder's `model.json` header that need no network: K within the
/// vertices (before anything is sized by it), the reference a training frame, every centre
/// vertex on the mesh, the scalings sane. Errors name `json` and the key.
fn check_header(header: &AeHeader, json: &Path, n: usize) -> Result<()> {
    let bad = |m: String| Error::parse(json, None, m);
    if header.components == 0 || header.components > n {
        return Err(bad(format!(
            "`components` is {}; an autoencoder on {n} vertices has 1 to {n} (one centre vertex each)",
            header.components
        )));
    }
    let w = header.decoder_edge_weight;
    if !(0.0..=crate::config::AE_DECODER_EDGE_WEIGHT_MAX).contains(&w) {
        return Err(bad(format!(
            "`decoder_edge_weight` is {w}; it must be in [0, {}]",
            crate::config::AE_DECODER_EDGE_WEIGHT_MAX
        )));
    }
    let p = header.decoder_noise_power;
    if !(0.0..=crate::config::AE_DECODER_NOISE_POWER_MAX).contains(&p) {
        return Err(bad(format!(
            "`decoder_noise_power` is {p}; it must be in [0, {}]",
            crate::config::AE_DECODER_NOISE_POWER_MAX
        )));
    }
    let f = header.train_frames.len();
    if header.reference >= f {
        return Err(bad(format!("`reference` is {}, not one of the {f} training frames", header.reference)));
    }
    if let Some((i, c)) = header.analysis.iter().enumerate().find(|(_, c)| c.center >= n || c.support_size > n) {
        return Err(bad(format!(
            "`analysis[{i}]` has centre vertex {} and support {}; the mesh has {n} vertices",
            c.center, c.support_size
        )));
    }
    header.unit_box.validate().map_err(|m| bad(format!("`unit_box`: {m}")))?;
    let sc = &header.scaling;
    if sc.width != 9 || sc.min.len() != 9 || sc.max.len() != 9 {
        return Err(bad(format!(
            "`scaling` has width {} with {} minima and {} maxima; the network reads 9 numbers per vertex",
            sc.width,
            sc.min.len(),
            sc.max.len()
        )));
    }
    if let Some(i) = (0..9).find(|&i| sc.min[i].is_nan() || sc.max[i].is_nan() || sc.min[i] > sc.max[i]) {
        return Err(bad(format!("`scaling`: dimension {i} has minimum {} above its maximum {}", sc.min[i], sc.max[i])));
    }
    Ok(())
}

impl AeArtifact {
    /// Loads an artefact directory written by [`train`].
    pub fn load(dir: &Path) -> Result<Self> {
        let dir = artifact::model_dir(dir);
        let (header, arrays): (AeHeader, ArrayStore) = artifact::load_model(&dir)?;
        let rest = rest_from_arrays(&arrays)?;
        check_header(&header, &dir.join("model.json"), rest.n_vertices())?;
        let representation = ae_representation(
            &rest,
            consistency_of(&header.consistency),
            header.features.to_map(),
            header.decoder_edge_weight,
            header.decoder_noise_power,
        )?;
        // The network's K must be the header's, checked before the network is built with it.
        let meta = dir.join(crate::nn::inference::META_FILE);
        let meta_k =
            artifact::read_json::<serde_json::Value>(&meta)?.pointer("/config/components").and_then(|v| v.as_u64());
        if meta_k != Some(header.components as u64) {
            return Err(Error::parse(
                &meta,
                None,
                format!(
                    "`config.components` is {}, but model.json's `components` is {}: the files belong to different models",
                    meta_k.map_or("missing".to_string(), |k| k.to_string()),
                    header.components
                ),
            ));
        }
        let neighbors = NeighborIndex::new(representation.element_adjacency())?;
        let model = Autoencoder::load(&dir, neighbors)?;
        let k = header.components + 3 * translated_pieces(&representation).len();
        if header.analysis.len() != k {
            return Err(Error::Invalid(format!(
                "{}: the component analysis has {} dimensions, the model {k}",
                dir.join("model.json").display(),
                header.analysis.len()
            )));
        }
        let f = header.train_frames.len();
        let codes = arrays.get_shaped("train_codes", &[f, k])?;
        if let Some(c) = header.analysis.iter().find(|c| c.dim >= k || c.rank >= k) {
            return Err(Error::Invalid(format!(
                "{}: `analysis` has dimension {} of rank {}; the model has {k} dimensions",
                dir.join("model.json").display(),
                c.dim,
                c.rank
            )));
        }
        if let Some(z) = &header.rest_code
            && (z.len() != k || z.iter().any(|x| !x.is_finite()))
        {
            return Err(Error::parse(
                dir.join("model.json"),
                None,
                format!("`rest_code` has {} numbers (the model {k} dimensions) or a non-finite one", z.len()),
            ));
        }
        if let Some(dials) = &header.dial_basis {
            if dials.len() != header.components {
                return Err(Error::parse(
                    dir.join("model.json"),
                    None,
                    format!("`dial_basis` has {} directions; the network has {}", dials.len(), header.components),
                ));
            }
            dials.check().map_err(|e| Error::parse(dir.join("model.json"), None, format!("`dial_basis`: {e}")))?;
        }
        let train_codes = codes.chunks_exact(k.max(1)).map(<[f64]>::to_vec).collect();
        Ok(AeArtifact { header, rest, representation, model, train_codes })
    }

    /// Codes (each [`AeArtifact::n_dims`] numbers) of frames given in data units: the encoder
    /// with the model's residual passes (`encoder_passes`), then its vertex steps
    /// (`encoder_steps`, [`super::ae_vertex_steps`]).
    pub fn encode_frames(&self, frames: &MeshSequence) -> Result<Vec<Vec<f64>>> {
        let c = self.model.config();
        self.encode_frames_with(frames, c.encoder_passes, c.encoder_steps)
    }

    /// [`Self::encode_frames`] with `passes` residual passes (0: the network's one pass) and
    /// `steps` vertex steps (0: the network's code).
    pub fn encode_frames_with(&self, frames: &MeshSequence, passes: usize, steps: usize) -> Result<Vec<Vec<f64>>> {
        let mut scaled = frames.clone();
        for p in scaled.frames.iter_mut().flatten() {
            *p = self.header.unit_box.apply(*p);
        }
        let (own, translations) = self.representation.split_pieces(self.representation.encode(&scaled)?)?;
        let xs = self.header.scaling.apply(&own)?;
        let mut codes = self.model.encode_with_passes(&xs, passes)?;
        if steps > 0 && vertex_steps_apply(self) {
            // The steps start from the better of the codes with and without the passes.
            let one_pass = if passes > 0 { self.model.encode_with_passes(&xs, 0)? } else { Vec::new() };
            let stepper = VertexSteps::new(self, self.model.decoder_vjp()?, steps)?;
            for (f, (z, target)) in codes.iter_mut().zip(&scaled.frames).enumerate() {
                let starts: Vec<&[f64]> =
                    std::iter::once(z.as_slice()).chain(one_pass.get(f).map(Vec::as_slice)).collect();
                *z = stepper.refine_best(&starts, target)?.0;
            }
        }
        append_translations(&self.representation, &mut codes, &translations);
        Ok(codes)
    }

    /// Network dimensions K (the config's `components`).
    pub fn n_network(&self) -> usize {
        self.header.components
    }

    /// Every code dimension: K, plus 3 per piece but the anchor on a multi-piece mesh (module
    /// docs).
    pub fn n_dims(&self) -> usize {
        self.header.components + 3 * translated_pieces(&self.representation).len()
    }

    /// The P piece translations of a full code (anchor zero); empty on a mesh in one piece.
    fn translations_of(&self, code: &[f64]) -> Vec<Vec3> {
        let Some((placement, _)) = self.representation.pieces() else {
            return Vec::new();
        };
        let mut t = vec![[0.0; 3]; placement.n_pieces()];
        for (j, p) in translated_pieces(&self.representation).into_iter().enumerate() {
            let at = self.header.components + 3 * j;
            t[p] = [code[at], code[at + 1], code[at + 2]];
        }
        t
    }

    /// Vertex positions (data units) decoded from codes (each [`AeArtifact::n_dims`] numbers).
    pub fn decode_codes(&self, codes: &[Vec<f64>]) -> Result<Vec<Vec<Vec3>>> {
        let (k, d) = (self.header.components, self.n_dims());
        if let Some(z) = codes.iter().find(|z| z.len() != d) {
            return Err(Error::Invalid(format!("a code has {} numbers, the model {d}", z.len())));
        }
        let network: Vec<Vec<f64>> = codes.iter().map(|z| z[..k].to_vec()).collect();
        let xs = self.model.decode(&network)?;
        let own = self.header.scaling.invert(&xs)?;
        let x = if d > k {
            let t: Vec<Vec<Vec3>> = codes.iter().map(|z| self.translations_of(z)).collect();
            self.representation.join_pieces(&own, &t)?
        } else {
            own
        };
        let mut frames = self.representation.decode(&x)?;
        for p in frames.iter_mut().flatten() {
            *p = self.header.unit_box.invert(*p);
        }
        Ok(frames)
    }

    /// The reference shape's code Z_r: the rest mesh's (models trained before it was stored:
    /// the reference training frame's).
    pub fn reference_code(&self) -> &[f64] {
        match &self.header.rest_code {
            Some(z) => z,
            None => &self.train_codes[self.header.reference],
        }
    }

    /// Synthesis code for the given (dial, weight) pairs: with a dial basis, Z_r + Σ w_m·b_m
    /// over the network's dials; otherwise (and for a piece translation's dimension)
    /// z_i = Z_r,i + (Z_h,i − Z_r,i)·w_i. Other dimensions keep Z_r.
    pub fn synthesis_code(&self, weights: &[(usize, f64)]) -> Result<Vec<f64>> {
        let mut z = self.reference_code().to_vec();
        let k = self.header.components;
        for &(i, w) in weights {
            let s = self.header.analysis.get(i).ok_or_else(|| {
                Error::Invalid(format!("component {i} does not exist ({} components)", self.n_dims()))
            })?;
            match &self.header.dial_basis {
                Some(b) if i < k => {
                    for (zc, bc) in z[..k].iter_mut().zip(&b.directions[i]) {
                        *zc += w * bc;
                    }
                }
                _ => z[i] = z[i] + (s.z_extreme - z[i]) * w,
            }
        }
        Ok(z)
    }

    /// Reads the network's K dials at `sparsity` (`dial_sparsity`, [`crate::config::DialSparsity`]):
    /// 0, one latent dimension per dial; otherwise the dial basis of the training codes around
    /// the reference code at that sparsity ([`SparseDials::fit`]). Sets `header.dial_basis` and
    /// the network's summaries in `header.analysis` (the piece translations' summaries after
    /// them are kept). Decoding is unchanged. Errors when the basis cannot be fitted (the model
    /// is left as it was).
    pub fn read_dials(&mut self, sparsity: f64) -> Result<()> {
        let k = self.header.components;
        let zr = self.reference_code()[..k].to_vec();
        let network: Vec<Vec<f64>> = self.train_codes.iter().map(|z| z[..k].to_vec()).collect();
        let (basis, mut summaries) = if sparsity == 0.0 {
            let analysis = self.model.analyze_codes_around(&network, &zr)?;
            let mut s: Vec<ComponentSummary> = analysis.components.iter().map(|c| c.summary.clone()).collect();
            s.sort_by_key(|c| c.dim);
            (None, s)
        } else {
            let dials = SparseDials::fit(&network, &zr, sparsity)?;
            let training: Vec<Vec<f64>> = dials.dials_of_all(&zr, &network)?;
            let ranges: Vec<(f64, f64)> = (0..k)
                .map(|d| {
                    training.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| (lo.min(t[d]), hi.max(t[d])))
                })
                .collect();
            let summaries = self.model.analyze_directions(&zr, &dials.directions, &ranges)?;
            (Some(dials), summaries)
        };
        summaries.extend(self.header.analysis.iter().filter(|s| s.dim >= k).cloned());
        self.header.dial_basis = basis;
        self.header.analysis = summaries;
        Ok(())
    }

    /// Rest mesh in data units.
    pub fn rest_in_data_units(&self) -> TriMesh {
        self.header.unit_box.invert_mesh(&self.rest)
    }

    /// Per component in rank order: its summary, the extreme shape (data units) and the
    /// per-vertex feature change from the reference shape (the heat map).
    pub fn extremes(&self) -> Result<Vec<Extreme>> {
        let zr = self.reference_code().to_vec();
        let mut order: Vec<ComponentSummary> = self.header.analysis.clone();
        order.sort_by_key(|c| c.rank);
        let codes: Vec<Vec<f64>> = std::iter::once(zr.clone())
            .map(Ok)
            .chain(order.iter().map(|c| self.synthesis_code(&[(c.dim, 1.0)])))
            .collect::<Result<_>>()?;
        let k = self.header.components;
        let network: Vec<Vec<f64>> = codes.iter().map(|z| z[..k].to_vec()).collect();
        let feats = self.header.scaling.invert(&self.model.decode(&network)?)?;
        let mut meshes = self.decode_codes(&codes)?;
        let n = self.rest.n_vertices();
        let piece_of = self.representation.pieces().map(|(p, _)| p.piece_of_vertex().to_vec());
        Ok(order
            .into_iter()
            .enumerate()
            .map(|(j, c)| {
                // A piece translation: its change (units of the rest diagonal) on its piece.
                if let (Some([piece, _]), Some(of)) = (c.piece, &piece_of) {
                    let dz = (c.z_extreme - zr[c.dim]).abs();
                    let change = of.iter().map(|&p| if p == piece { dz } else { 0.0 }).collect();
                    return (c, std::mem::take(&mut meshes[j + 1]), change);
                }
                let change: Vec<f64> = (0..n)
                    .map(|v| {
                        let a = feats.element(j + 1, v);
                        let b = feats.element(0, v);
                        a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
                    })
                    .collect();
                (c, std::mem::take(&mut meshes[j + 1]), change)
            })
            .collect())
    }

    /// Writes, per component in rank order, `<rank>_<dim>.obj` (the extreme shape) and
    /// `<rank>_<dim>_change.ply` (rest mesh coloured by per-vertex feature change), plus
    /// `components.csv` (dimension, rank, distance, z_extreme, centre vertex, support size,
    /// and for a piece translation `piece<p>_<axis>`).
    pub fn write_components(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let rest = self.rest_in_data_units();
        let mut csv = String::from("dimension,rank,distance,z_extreme,center_vertex,support_size,piece\n");
        for (c, shape, change) in self.extremes()? {
            let stem = format!("{}_{}", c.rank, c.dim);
            mesh::write_obj(&dir.join(format!("{stem}.obj")), &TriMesh::new(shape, self.rest.faces.clone()))?;
            mesh::write_ply(
                &dir.join(format!("{stem}_change.ply")),
                &rest,
                Some(&mesh::colormap(&change)),
                Some(("change", &change)),
            )?;
            let piece = c.piece.map_or(String::new(), |[p, a]| format!("piece{p}_{}", ["x", "y", "z"][a]));
            csv.push_str(&format!(
                "{},{},{},{},{},{},{piece}\n",
                c.dim, c.rank, c.distance, c.z_extreme, c.center, c.support_size
            ));
        }
        artifact::write_atomic(&dir.join("components.csv"), csv.as_bytes())
    }

    /// Saves every model file: `autoencoder.bpk` + `autoencoder.json` (the network) and
    /// `model.json` + `model.bin` (header, rest mesh, training codes).
    pub fn save(&self, dir: &Path) -> Result<()> {
        self.model.save(dir)?;
        let mut arrays = ArrayStore::new();
        rest_to_arrays(&self.rest, &mut arrays)?;
        arrays.insert(
            "train_codes",
            vec![self.train_codes.len(), self.n_dims()],
            self.train_codes.iter().flatten().copied().collect(),
        )?;
        artifact::save_model(dir, &self.header, &arrays)
    }
}

/// Control-point fit of the autoencoder: Levenberg–Marquardt on the code from the reference
/// shape's code, at most [`POINT_FIT_ITERATIONS`] iterations.
struct AePointFit<'a> {
    artifact: &'a AeArtifact,
    fitter: AeFitEncoder<'a>,
}

impl PointFit for AePointFit<'_> {
    fn reconstruct(&self, shape: &[Vec3]) -> Result<Vec<Vec3>> {
        Ok(self.fitter.fit(shape, self.artifact.reference_code())?.1)
    }
}

impl Model for AeArtifact {
    fn kind(&self) -> MethodKind {
        MethodKind::Autoencoder
    }
    fn representation(&self) -> RepresentationKind {
        RepresentationKind::Acap
    }
    fn rest(&self) -> TriMesh {
        self.rest_in_data_units()
    }
    fn n_components(&self) -> usize {
        self.n_dims()
    }
    fn components(&self) -> Result<Vec<Component>> {
        let mut out: Vec<Component> = self
            .extremes()?
            .into_iter()
            .map(|(c, _, magnitudes)| Component {
                index: c.dim,
                rank: c.rank,
                name: format!("{}_{}", c.rank, c.dim),
                center: c.center,
                magnitudes,
            })
            .collect();
        out.sort_by_key(|c| c.index);
        Ok(out)
    }
    fn element_norms(&self) -> (Vec<Vec<f64>>, &[Vec<usize>]) {
        let c = self.model.components_matrix();
        let n = self.rest.n_vertices();
        let mut norms: Vec<Vec<f64>> = c
            .chunks_exact((9 * n).max(1))
            .map(|row| row.chunks_exact(9).map(|g| g.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt()).collect())
            .collect();
        // A piece translation moves its piece, all of it, and nothing else.
        if let Some((placement, _)) = self.representation.pieces() {
            for p in translated_pieces(&self.representation) {
                let on: Vec<f64> =
                    placement.piece_of_vertex().iter().map(|&q| if q == p { 1.0 } else { 0.0 }).collect();
                norms.extend([on.clone(), on.clone(), on]);
            }
        }
        (norms, self.representation.element_adjacency())
    }
    fn alignment(&self) -> Alignment {
        Alignment::Centroid
    }
    fn train_frames(&self) -> &[String] {
        &self.header.train_frames
    }
    fn train_weights(&self) -> Option<Vec<Vec<f64>>> {
        Some(self.train_codes.clone())
    }
    fn decode(&self, weights: &[Vec<f64>]) -> Result<Vec<Vec<Vec3>>> {
        self.decode_codes(weights)
    }
    /// `z_i = Z_r,i + (Z_h,i − Z_r,i)·w_i` (other dimensions keep the reference code Z_r).
    fn synthesis_weights(&self, dials: &[f64]) -> Result<Vec<f64>> {
        crate::model::check_len("weights", dials.len(), self.n_dims())?;
        let pairs: Vec<(usize, f64)> =
            dials.iter().enumerate().filter(|(_, w)| **w != 0.0).map(|(i, w)| (i, *w)).collect();
        self.synthesis_code(&pairs)
    }
    fn dials(&self, weights: &[f64]) -> Result<Vec<f64>> {
        crate::model::check_len("weights", weights.len(), self.n_dims())?;
        let zr = self.reference_code();
        let k = self.header.components;
        let network = match &self.header.dial_basis {
            Some(b) => Some(b.dials_of(&zr[..k], &weights[..k])?),
            None => None,
        };
        Ok(self
            .header
            .analysis
            .iter()
            .map(|s| match &network {
                Some(d) if s.dim < k => d[s.dim],
                _ => {
                    let span = s.z_extreme - zr[s.dim];
                    if span != 0.0 { (weights[s.dim] - zr[s.dim]) / span } else { 0.0 }
                }
            })
            .collect())
    }
    fn encode(&self, frames: &MeshSequence) -> Result<Vec<Vec<f64>>> {
        self.encode_frames(frames)
    }
    fn encoder_description(&self) -> String {
        let c = self.model.config();
        let network = match c.encoder_passes {
            0 => "the network encoder, one pass".to_string(),
            p => format!("the network encoder and {p} residual passes z ← z + E(x) − E(D(z))"),
        };
        match c.encoder_steps {
            0 => format!("{network}, no fitting"),
            s if vertex_steps_apply(self) => {
                format!("{network}, then up to {s} Gauss–Newton steps on the reconstructed vertices")
            }
            _ => format!("{network}, no fitting (encoder_steps apply to meshes in one piece)"),
        }
    }
    fn encode_one_pass(&self, frames: &MeshSequence) -> Result<Option<Vec<Vec<f64>>>> {
        let c = self.model.config();
        if c.encoder_passes == 0 && (c.encoder_steps == 0 || !vertex_steps_apply(self)) {
            return Ok(None);
        }
        Ok(Some(self.encode_frames_with(frames, 0, 0)?))
    }
    fn encode_network(&self, frames: &MeshSequence) -> Result<Option<Vec<Vec<f64>>>> {
        let c = self.model.config();
        if c.encoder_steps == 0 || !vertex_steps_apply(self) {
            return Ok(None);
        }
        Ok(Some(self.encode_frames_with(frames, c.encoder_passes, 0)?))
    }
    fn refine(
        &self,
        frames: &MeshSequence,
        start: &[Vec<f64>],
        options: &RefineOptions,
        done: &mut dyn FnMut(usize),
    ) -> Result<Option<Refined>> {
        let fitter = AeFitEncoder::new(self, options.points, options.gamma)?;
        Ok(Some(fitter.fit_from(frames, start, done)?))
    }
    fn start_weights(&self, from: Option<&[Vec3]>) -> Result<Vec<f64>> {
        let rest = self.rest_in_data_units();
        let p = from.unwrap_or(&rest.positions);
        // The network's code (no vertex steps): posing starts where it always has.
        let c = self.model.config();
        Ok(self.encode_frames_with(&single_frame(&rest, p)?, c.encoder_passes, 0)?.remove(0))
    }
    fn start_description(&self) -> &'static str {
        "the code of the rest mesh"
    }
    fn pose_parameters(&self) -> &'static [&'static str] {
        &["gamma", "max_iterations"]
    }
    fn pose_defaults(&self) -> PoseOptions {
        PoseOptions::autoencoder_defaults()
    }
    fn pose(&self, vertices: &[usize], targets: &[Vec3], w0: &[f64], options: &PoseOptions) -> Result<PoseResult> {
        let start = self.decode_codes(&[w0.to_vec()])?.remove(0);
        let (weights, positions) = AePoser::new(
            self,
            vertices,
            &AePoseConfig {
                gamma: options.gamma,
                max_iterations: options.max_iterations,
                time_limit: options.time_limit,
                prior: options.prior,
                ..Default::default()
            },
        )?
        .solve(targets, w0)?;
        Ok(PoseResult { start, positions, weights })
    }
    fn point_fit<'a>(&'a self, vertices: &[usize], gamma: f64) -> Result<Option<Box<dyn PointFit + 'a>>> {
        let fitter =
            AeFitEncoder::with_vertices(self, vertices.to_vec(), gamma)?.with_iterations(POINT_FIT_ITERATIONS)?;
        Ok(Some(Box::new(AePointFit { artifact: self, fitter })))
    }
    fn save(&self, dir: &Path) -> Result<()> {
        AeArtifact::save(self, dir)
    }
    fn write_views(&self, dir: &Path) -> Result<()> {
        self.write_components(&dir.join("components"))
    }
    fn write_components(&self, dir: &Path) -> Result<()> {
        AeArtifact::write_components(self, dir)
    }
}

/// The pieces whose translations are code dimensions (every piece but the anchor, ascending);
/// empty on a mesh in one piece.
pub fn translated_pieces(representation: &Representation) -> Vec<usize> {
    representation.pieces().map(|(p, _)| (0..p.n_pieces()).filter(|&q| q != p.anchor()).collect()).unwrap_or_default()
}

/// Appends to each network code its frame's translations of the translated pieces (the code
/// layout of the module docs; nothing on a mesh in one piece).
fn append_translations(representation: &Representation, codes: &mut [Vec<f64>], translations: &[Vec<Vec3>]) {
    let pieces = translated_pieces(representation);
    for (z, t) in codes.iter_mut().zip(translations) {
        z.extend(pieces.iter().flat_map(|&p| t[p]));
    }
}

/// Summaries of the piece-translation dimensions (after the K network ones): extremes over the
/// training translations, ranked after the network's, centred on the piece's vertex nearest its
/// rest centroid.
fn piece_summaries(
    representation: &Representation,
    k: usize,
    train_t: &[Vec<Vec3>],
    reference: &[f64],
) -> Vec<ComponentSummary> {
    let Some((placement, _)) = representation.pieces() else {
        return Vec::new();
    };
    let rest = &representation.rest().positions;
    let mut out = Vec::new();
    for (j, p) in translated_pieces(representation).into_iter().enumerate() {
        let members: Vec<usize> = (0..rest.len()).filter(|&v| placement.piece_of_vertex()[v] == p).collect();
        let c: Vec3 = std::array::from_fn(|a| members.iter().map(|&v| rest[v][a]).sum::<f64>() / members.len() as f64);
        let center = members
            .iter()
            .copied()
            .min_by(|&a, &b| crate::math::vec3::dist2(rest[a], c).total_cmp(&crate::math::vec3::dist2(rest[b], c)))
            .unwrap_or(0);
        for axis in 0..3 {
            let values: Vec<f64> = train_t.iter().map(|t| t[p][axis]).collect();
            let zr = reference.get(3 * j + axis).copied().unwrap_or(0.0);
            let (lo, hi) = values.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
            let (lo, hi) = if lo <= hi { (lo, hi) } else { (0.0, 0.0) };
            let extreme = if (hi - zr).abs() >= (lo - zr).abs() { hi } else { lo };
            let dim = k + 3 * j + axis;
            out.push(ComponentSummary {
                dim,
                rank: dim,
                z_min: lo,
                z_max: hi,
                z_extreme: extreme,
                distance: (extreme - zr).abs() * placement.unit(),
                center,
                support_size: members.len(),
                piece: Some([p, axis]),
            });
        }
    }
    out
}

/// Training shapes encoded at a time after training when they stream from the cache file (a
/// multiple of the encoder's batch).
const STREAM_ENCODE_RUN: usize = 256;

/// The autoencoder's training data: the feature scaling, the scaled shapes, the scaled `f64`
/// features when they are held in memory (`None`: read from the cache file), and the pieces'
/// translations per frame (multi-piece meshes; empty otherwise).
type AeTrainingData = (FeatureScaling, TrainingData, Option<Features>, Vec<Vec<Vec3>>);

/// The training features: from a cache file, read a batch at a time, when `data.cache` caches
/// them (one-piece meshes); otherwise computed into memory (or read whole from the cache) and
/// scaled in place. Both give the same scaled numbers.
fn training_data(
    representation: &Representation,
    prep: &Prepared,
    mode: ScalingMode,
    (quantile, fence): (f64, f64),
    progress: &mut dyn super::Progress,
) -> Result<AeTrainingData> {
    use crate::representation::feature_cache::{CacheUse, Opened, open_or_build};
    let own = if representation.pieces().is_none() {
        let mut on_frames = |done: usize| progress.step(done as u64, "frames");
        match open_or_build(representation, &prep.sequence, &prep.train, &prep.cache, &mut on_frames)? {
            Opened::File { file, built } => {
                let path = file.path().to_path_buf();
                let used = if built { CacheUse::Written(path) } else { CacheUse::Read(path) };
                super::note_cache_use(&used, " (training reads them a batch at a time)");
                let h = file.header();
                let mut scaling = FeatureScaling::fit_column_ranges(&h.min(), &h.max(), mode)?;
                if quantile > 0.0 {
                    // One pass over the file's frames (the training frames) for the histogram.
                    let mut hist = RangeHistogram::new(&scaling)?;
                    for f in 0..file.n_frames() {
                        hist.add(&file.frame(f)?)?;
                    }
                    scaling = hist.scaling(quantile, fence)?;
                }
                let data = TrainingData::from_feature_file(std::sync::Arc::new(file), scaling.clone())?;
                return Ok((scaling, data, None, Vec::new()));
            }
            Opened::Unavailable(why) => {
                super::note_cache_use(&CacheUse::Unavailable(why), "");
                representation.encode_selected(&prep.sequence, &prep.train)?
            }
            Opened::NotCached => representation.encode_selected(&prep.sequence, &prep.train)?,
        }
    } else {
        super::training_features(representation, prep)?
    };
    let (mut xs, train_t) = representation.split_pieces(own)?;
    let scaling = FeatureScaling::fit_quantile(&xs.data, xs.width, mode, quantile, fence)?;
    // Scaled in place: the unscaled features are not kept beside the scaled ones.
    scaling.apply_in_place(&mut xs.data)?;
    let data = TrainingData::from_features(&xs)?;
    Ok((scaling, data, Some(xs), train_t))
}

/// Trains the autoencoder (`kind = "autoencoder"`) on prepared data. Writes its checkpoints
/// (`checkpoint.bin`) and per-iteration log (`training.jsonl`) into `ctx.out` while it trains;
/// with `ctx.resume`, continues from that checkpoint (same data and hyperparameters; only
/// `iterations` and `checkpoint_every` may change). `ctx.stop` ends the run early after writing
/// a checkpoint (Ctrl-C), which is reported as an error naming the checkpoint.
pub fn fit(m: &AutoencoderMethod, prep: &Prepared, ctx: &mut FitContext<'_>) -> Result<Fitted> {
    let ae_cfg = m.network_config();
    let out = ctx.out;
    let checkpoint = out.join(CHECKPOINT_FILE);
    if let Some(from) = ctx.resume
        && !from.is_file()
    {
        return Err(Error::Invalid(format!("--resume: no checkpoint at {}", from.display())));
    }
    ctx.progress.stage("acap features", prep.train.len() as u64);
    let t_rep = Instant::now();
    let representation = ae_representation(
        &prep.rest,
        m.consistency.to_acap(),
        m.features.to_map(),
        m.decoder_edge_weight,
        m.decoder_noise_power,
    )?;
    // The network's 9 numbers per vertex, and the pieces' translations (multi-piece meshes).
    // When the features are cached in a file (large data: `data.cache`), training reads them
    // from it a batch at a time; otherwise they are computed into memory and scaled in place.
    let features = training_data(
        &representation,
        prep,
        m.scaling.mode(),
        (m.scaling_quantile, m.scaling_fence),
        &mut *ctx.progress,
    )?;
    let sc = &features.0;
    if !sc.clamped.is_empty() {
        let (lo, hi) = sc
            .min
            .iter()
            .zip(&sc.max)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (l, h)| (a.min(*l), b.max(*h)));
        eprintln!(
            "note: the feature scaling's outlier fence (scaling_quantile {}, scaling_fence {}) maps [{lo:.4}, {hi:.4}] to [-0.95, 0.95] and clamps the few training features beyond it",
            m.scaling_quantile, m.scaling_fence
        );
    }
    if let Some((placement, _)) = representation.pieces() {
        let extra = 3 * (placement.n_pieces() - 1);
        eprintln!(
            "note: the mesh has {} separate pieces: the code has the network's {} dimensions plus {extra} piece \
             translations ({} in all; components.csv names them piece<p>_<axis>)",
            placement.n_pieces(),
            ae_cfg.components,
            ae_cfg.components + extra
        );
    }
    let (scaling, all, xs_train, train_t) = features;
    // The rest shape's scaled features: the code term's lane (`lambda_code`) and the baseline of
    // the check that a run trained at all.
    let rest_features: Vec<f32> = {
        let seq = single_frame(&prep.rest, &prep.rest.positions)?;
        let (own, _) = representation.split_pieces(representation.encode(&seq)?)?;
        scaling.apply(&own)?.data.iter().map(|&x| x as f32).collect()
    };
    // `feature_weights = "noise"`: each vertex's weight from its scaled features' sensitivity to
    // position noise on the rest mesh.
    let feature_weights = match m.feature_weights {
        FeatureWeights::Uniform => None,
        FeatureWeights::Noise => {
            let map = |x: Features| {
                let (own, _) = representation.split_pieces(x)?;
                scaling.apply(&own)
            };
            let w =
                noise_weights(&feature_noise_variance(&representation, NOISE_LEVEL, NOISE_DRAWS, ae_cfg.seed, &map)?);
            let low = w.iter().filter(|&&x| x < 0.5).count();
            let least = w.iter().copied().fold(1.0f64, f64::min);
            eprintln!(
                "note: feature_weights = \"noise\": {low} of {} vertices weigh less than 1/2 in the feature error \
                 (their features are the most sensitive to position noise; the smallest weight {least:.2e})",
                w.len()
            );
            Some(w)
        }
    };
    let representation_seconds = t_rep.elapsed().as_secs_f64();

    ctx.progress.stage("geodesics", 0);
    let distances = GeodesicSupport::max_normalised(&prep.rest, m.geodesic_m)?;
    let neighbors = NeighborIndex::new(representation.element_adjacency())?;
    // With `validation = v`, v evenly spaced training shapes are held out to choose the step.
    // `all` stays whole: the codes of every training shape are computed from it after training.
    let split = if ae_cfg.validation > 0 {
        Some(all.split_validation(ae_cfg.validation).map_err(crate::config::method_key)?)
    } else {
        None
    };
    let (data, held_out) = match &split {
        Some((fit, val, _)) => (fit, Some(val)),
        None => (&all, None),
    };

    // The vertex term (`lambda_vertex`): the decoded shapes' error on the reconstructed vertices.
    let vertex_loss = if ae_cfg.lambda_vertex > 0.0 {
        let acap = representation
            .acap()
            .ok_or_else(|| Error::Invalid("lambda_vertex needs the ACAP representation".into()))?;
        Some(AcapVertexLoss::new(acap, &scaling)?)
    } else {
        None
    };

    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    // The checkpoint is read (and its checksum verified) once, here.
    let resumed = match ctx.resume {
        Some(from) => Some((from, Checkpoint::load(from)?)),
        None => None,
    };
    // A run that stalled and restarted with halved step sizes (`stall_restarts`) wrote its
    // checkpoints with the restart's rates: a resume continues that restart.
    let mut restart = 0;
    if let Some((from, ck)) = &resumed {
        // The feature weights are not part of the network's hyperparameters: a run resumes only
        // with the weighting it was trained with (the default changed with issue 53).
        if ck.header.feature_weighted != feature_weights.is_some() {
            let (was, now) = if ck.header.feature_weighted { ("noise", "uniform") } else { ("uniform", "noise") };
            return Err(Error::config(
                "feature_weights",
                format!(
                    "{}: the checkpoint was trained with feature_weights = \"{was}\", this run would use \"{now}\": \
                     set method.feature_weights = \"{was}\" to resume it",
                    from.display()
                ),
            ));
        }
        // What the features are is not a network hyperparameter either.
        let input = ck.header.input.as_deref().unwrap_or(AeFeatures::default().name());
        if input != m.features.name() {
            return Err(Error::config(
                "features",
                format!(
                    "{}: the checkpoint was trained with features = \"{input}\", this run would use \"{}\": \
                     set method.features = \"{input}\" to resume it",
                    from.display(),
                    m.features.name()
                ),
            ));
        }
        // A checkpoint written before checkpoints held the best validation step: the step kept
        // is chosen among those after the resume.
        if ae_cfg.validation > 0 && ck.best.is_none() && ck.header.iteration >= ae_cfg.validate_every.max(1) {
            eprintln!(
                "note: {} was written before checkpoints held the best validation step (method.validation = {}): \
                 the step kept is the best of those after iteration {}",
                from.display(),
                ae_cfg.validation,
                ck.header.iteration
            );
        }
        let saved = &ck.header.config;
        if let Some(r) = (1..=ae_cfg.stall_restarts).find(|&r| ae_cfg.restarted(r).check_resumable(saved).is_ok()) {
            restart = r;
        }
    }
    let make_trainer = |cfg: AutoencoderConfig, resume: Option<(&Path, Checkpoint)>| -> Result<Trainer<'_>> {
        let mut trainer = if let Some((from, ck)) = resume {
            Trainer::resume_from(ck, from, cfg, data, &neighbors, &distances)?
        } else {
            Trainer::new(cfg, data, &neighbors, &distances)?
        };
        if let Some(val) = held_out {
            trainer = trainer.with_validation(val)?;
        }
        if let Some(v) = &vertex_loss {
            trainer = trainer.with_output_loss(v);
        }
        trainer = trainer
            .with_rest(&rest_features)?
            .with_input((m.features != AeFeatures::default()).then_some(m.features.name()));
        if let Some(w) = &feature_weights {
            trainer = trainer.with_feature_weights(w)?;
        }
        Ok(trainer)
    };
    // A resumed run's training time counts the time trained before (the checkpoint's).
    let seconds_before = resumed.as_ref().map_or(0.0, |(_, ck)| ck.header.train_seconds);
    let mut trainer = make_trainer(ae_cfg.restarted(restart), resumed)?;
    let log_path = out.join(LOG_FILE);
    let mut log = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .append(ctx.resume.is_some())
        .truncate(ctx.resume.is_none())
        .open(&log_path)
        .map_err(|e| Error::io(&log_path, e))?;
    let progress = &mut *ctx.progress;
    let (feature_norm, scale) = (trainer.feature_norm(), trainer.learning_rate_scale());
    let stage = if scale < 1.0 {
        format!(
            "training (step sizes × {scale:.3}: the features are larger than learning_rate_norm {})",
            ae_cfg.learning_rate_norm
        )
    } else {
        "training".to_string()
    };
    progress.stage(&stage, ae_cfg.iterations as u64);
    progress.step(trainer.iteration() as u64, "");
    let t_train = Instant::now();
    let mut log_error: Option<std::io::Error> = None;
    // The reconstruction error of every step of the current attempt (the end-of-run check).
    let mut recs: Vec<f64> = Vec::new();
    let mut warning = None;
    let mut training_gain = None;
    // Shapes one step decodes (the batch and its synthetic shapes) × vertices: the estimate's unit.
    let batch = ae_cfg.batch_for(data.n_shapes());
    let step_shapes = batch + ae_cfg.augment;
    let mut estimate = StepEstimate::new(ESTIMATE_AFTER_STEPS);
    let summary = loop {
        let stall_check = if restart < ae_cfg.stall_restarts { stall_check_step(ae_cfg.iterations) } else { None };
        let options = RunOptions { checkpoint: Some(checkpoint.clone()), stop: ctx.stop.clone(), stall_check };
        let summary = trainer.run(&options, |r| {
        let l = &r.loss;
        recs.push(l.reconstruction);
        if let Some(per_step) = estimate.add(r.step_seconds) {
            progress.note(&estimate_text(
                per_step,
                ae_cfg.iterations.saturating_sub(r.iteration),
                step_shapes,
                data.n_vertices(),
            ));
        }
        let validation = r.validation_error.map(|v| format!(",\"validation\":{v}")).unwrap_or_default();
        let line = format!(
            "{{\"iteration\":{},\"loss\":{},\"reconstruction\":{},\"sparsity\":{},\"hinge\":{},\"orthogonality\":{},\"vertex\":{},\"code\":{},\"step_seconds\":{},\"checkpoint\":{}{validation}}}\n",
            r.iteration, l.total, l.reconstruction, l.sparsity, l.hinge, l.orthogonality, l.vertex, l.code, r.step_seconds, r.checkpointed
        );
        if let Err(e) = log.write_all(line.as_bytes()) {
            log_error.get_or_insert(e);
        }
        let mut vertex = if l.vertex > 0.0 { format!(", vertex {:.4}", l.vertex) } else { String::new() };
        if l.code > 0.0 {
            vertex.push_str(&format!(", code {:.4}", l.code));
        }
        progress.step(
            r.iteration as u64,
            &format!(
                "loss {:.4} (rec {:.4}, sparse {:.4}, hinge {:.4}{vertex})",
                l.total, l.reconstruction, l.sparsity, l.hinge
            ),
        );
        })?;
        let mut why = None;
        if summary.stalled {
            why = Some(format!(
                "training stalled (mean reconstruction error of the last {STALL_WINDOW} steps at step {} is at or \
                 above the first step's)",
                summary.iterations_done
            ));
        } else if !summary.stopped {
            // A run that ended without learning the shapes: its decoding is no better than the
            // rest shape's for every training shape.
            let (err, base, linear) = trainer.training_rest_and_linear_error(&rest_features)?;
            let share = gain_share(err, base, linear);
            training_gain = Some(share);
            let default_steps = AutoencoderConfig::default().iterations;
            let did_train = trained(err, base, linear);
            if did_train && partly_trained(share, summary.iterations_done, default_steps) {
                // Trained, but stopped too early: the step size decays to the run's end, so its
                // error has flattened by then (`still_improving` does not see it), yet longer runs
                // fit far better (SCAPE: test Erms 45 at 100 steps, 15 at 300, 4.7 at 2 000).
                let w = format!(
                    "the autoencoder trained only partly: it stopped after {} steps, {:.0} % of the default's {}, \
                     and its decoding of the training shapes makes {:.1} % of what the best {} linear components \
                     gain over the rest shape (feature error {err:.4}; rest shape {base:.4}, linear {linear:.4}; \
                     default runs: SCAPE 99 %; noisy data less): the step size decays to a run's end, so a short \
                     run ends flat but far from the fit. Raise `method.iterations`",
                    summary.iterations_done,
                    100.0 * summary.iterations_done as f64 / default_steps as f64,
                    default_steps,
                    100.0 * share,
                    ae_cfg.components,
                );
                eprintln!("warning: {w}");
                warning = Some(w);
            }
            if !did_train {
                let improving = still_improving(&recs);
                let text = format!(
                    "the autoencoder did not train: after {} steps its decoding of the training shapes has a feature \
                     error of {err:.4} against {base:.4} for decoding every shape as the rest shape and {linear:.4} \
                     for the best {} linear components: {:.0} % of their gain over the rest shape",
                    summary.iterations_done,
                    ae_cfg.components,
                    100.0 * (base - err) / (base - linear).max(f64::MIN_POSITIVE)
                );
                let line = format!(
                    "{{\"not_trained\":true,\"feature_error\":{err},\"rest_error\":{base},\"linear_error\":{linear}}}\n"
                );
                if let Err(e) = log.write_all(line.as_bytes()) {
                    log_error.get_or_insert(e);
                }
                if !improving && restart < ae_cfg.stall_restarts {
                    why = Some(text);
                } else {
                    let advice = if improving {
                        format!(
                            "its error was still falling at the last step: raise `method.iterations` (now {})",
                            ae_cfg.iterations
                        )
                    } else {
                        format!(
                            "restarts with halved step sizes did not help (`method.stall_restarts` = {}): lower \
                             `method.learning_rate` or raise `method.iterations`",
                            ae_cfg.stall_restarts
                        )
                    };
                    let w = format!("{text}; {advice}");
                    eprintln!("warning: {w}");
                    warning = Some(w);
                }
            }
        }
        let Some(why) = why else {
            break summary;
        };
        // Start again from the same initialisation with halved step sizes; the log restarts with
        // it (no checkpoint of the failed attempt was written after the check).
        restart += 1;
        recs.clear();
        let cfg = ae_cfg.restarted(restart);
        progress.finish_stage();
        eprintln!(
            "note: {why}: restart {restart} of at most {} with step sizes halved (learning_rate {:e})",
            ae_cfg.stall_restarts, cfg.learning_rate
        );
        log.set_len(0).map_err(|e| Error::io(&log_path, e))?;
        log.seek(std::io::SeekFrom::Start(0)).map_err(|e| Error::io(&log_path, e))?;
        let _ = std::fs::remove_file(&checkpoint);
        trainer = make_trainer(cfg, None)?;
        progress.stage(&format!("{stage}, restart {restart}"), ae_cfg.iterations as u64);
    };
    let train_seconds = seconds_before + t_train.elapsed().as_secs_f64();
    if let Some((it, err)) = summary.best {
        let line = format!("{{\"best_iteration\":{it},\"validation_error\":{err}}}\n");
        if let Err(e) = log.write_all(line.as_bytes()) {
            log_error.get_or_insert(e);
        }
    }
    if let Some(e) = log_error {
        return Err(Error::io(&log_path, e));
    }
    progress.finish_stage();
    // A resumed run with no steps left writes no checkpoint: the one it resumed from stays
    // the artefact's.
    if let Some(from) = ctx.resume
        && from != checkpoint
        && !checkpoint.exists()
    {
        std::fs::copy(from, &checkpoint).map_err(|e| Error::io(from, e))?;
    }
    if summary.stopped {
        return Err(Error::Invalid(format!(
            "stopped at iteration {} of {}; checkpoint written to {} (continue with --resume)",
            summary.iterations_done,
            ae_cfg.iterations,
            checkpoint.display()
        )));
    }
    let model = trainer.into_model()?;

    progress.stage("measuring", 0);
    // The training shapes' codes (in runs when the shapes stream from the cache file: the runs
    // are multiples of the encoder's batch, so the codes are those of one pass over all).
    let mut train_codes = match &xs_train {
        Some(x) => model.encode(x)?,
        None => {
            let mut codes = Vec::with_capacity(all.n_shapes());
            for start in (0..all.n_shapes()).step_by(STREAM_ENCODE_RUN) {
                let end = (start + STREAM_ENCODE_RUN).min(all.n_shapes());
                codes.extend(model.encode(&all.scaled_features(start..end)?)?);
            }
            codes
        }
    };
    // The dial origin: the rest mesh's own code (encoded as any shape is, residual passes and
    // vertex steps included), so that all dials 0 decode to the rest shape.
    let mut art = AeArtifact {
        header: AeHeader {
            method: MethodKind::Autoencoder.name().into(),
            representation: RepresentationKind::Acap.name().into(),
            consistency: m.consistency.name().into(),
            features: m.features,
            decoder_edge_weight: m.decoder_edge_weight,
            decoder_noise_power: m.decoder_noise_power,
            scaling,
            unit_box: prep.unit_box,
            components: ae_cfg.components,
            train_frames: prep.train_names(),
            reference: 0,
            rest_code: None,
            analysis: Vec::new(),
            dial_basis: None,
        },
        rest: prep.rest.clone(),
        representation,
        model,
        train_codes: Vec::new(),
    };
    let rest = art.rest_in_data_units();
    let rest_code = art.encode_frames(&single_frame(&rest, &rest.positions)?)?.remove(0);
    let k = ae_cfg.components;
    // The dials (`dial_sparsity`, issue 53): the latent dimensions, or a dial basis (K
    // directions in which the training codes are sparse), or for "auto" the most concentrated
    // of the bases at `DialSparsity::CANDIDATES` (`choose_dials`). A basis needs at least
    // DIAL_BASIS_SHAPES_PER_DIAL × K training shapes (with fewer, the sparsest basis gives each
    // shape a dial of its own: whole poses, not localized components); a basis that cannot be
    // fitted is left out, with a note.
    let mut sparsities = m.dial_sparsity.candidates();
    if m.dial_sparsity == DialSparsity::Auto && art.representation.pieces().is_some() {
        // On a mesh of several pieces a basis direction can move two pieces at once (each
        // latent dimension of the synthetic two tubes stays on one; a basis fitted there did
        // not): "auto" keeps the latent dimensions; a number still fits a basis.
        progress.note(
            "the dials are the latent dimensions: the mesh has several pieces, and a dial basis can move two at once (method.dial_sparsity = a number fits one)",
        );
        sparsities = vec![0.0];
    } else if sparsities.iter().any(|&s| s > 0.0) && train_codes.len() < DIAL_BASIS_SHAPES_PER_DIAL * k {
        progress.note(&format!(
            "the dials are the latent dimensions: a dial basis (method.dial_sparsity) needs at least {} training shapes for {k} components ({} here)",
            DIAL_BASIS_SHAPES_PER_DIAL * k,
            train_codes.len()
        ));
        sparsities = vec![0.0];
    }
    append_translations(&art.representation, &mut train_codes, &train_t);
    art.header.analysis = piece_summaries(&art.representation, ae_cfg.components, &train_t, &art_rest_t(&rest_code, k));
    art.header.rest_code = Some(rest_code);
    art.train_codes = train_codes;
    let dial_readouts = choose_dials(&mut art, &sparsities, progress)?;
    if dial_readouts.len() > 1 {
        progress.note(&describe_dial_choice(&dial_readouts));
    }
    let locality = component_locality_of(&art, &distances, [ae_cfg.d_min, ae_cfg.d_max]);
    Ok(Fitted {
        model: Box::new(art),
        stats: FitStats {
            train_seconds,
            representation_seconds,
            iterations: summary.iterations_done,
            objective: summary.last_loss.map(|l| l.total),
            converged: None,
            locality,
            refine_test: m.fit_test,
            feature_norm: Some((feature_norm, scale)),
            warning,
            training_gain,
            dial_readouts,
        },
        method: MethodConfig::Autoencoder(written_method(m, batch, data.n_shapes())),
    })
}

/// Sets `art`'s dials to the readout among `sparsities` (not empty; 0: the latent dimensions,
/// else the dial basis at that sparsity, [`AeArtifact::read_dials`]) whose K network components
/// are the most concentrated: the largest median over them of the share of each one's squared
/// displacement that its tenth of vertices moving most carry
/// ([`crate::metrics::recovery::energy_concentration`]), read around the rest shape as
/// `meshdeco eval` and `metrics.json` read components ([`crate::model::component_fields`]). A
/// tie keeps the earlier; a basis that cannot be fitted is left out with a note (the latent
/// dimensions, always readable, are the last resort). Returns every readout's score, the kept
/// one marked; nothing is scored for a single readout (an empty list).
fn choose_dials(
    art: &mut AeArtifact,
    sparsities: &[f64],
    progress: &mut dyn super::Progress,
) -> Result<Vec<DialReadout>> {
    let k = art.header.components;
    let mut scores: Vec<DialReadout> = Vec::with_capacity(sparsities.len());
    let mut best: Option<(usize, Option<SparseDials>, Vec<ComponentSummary>)> = None;
    for &sparsity in sparsities {
        if let Err(e) = art.read_dials(sparsity) {
            progress.note(&format!("no dial basis at dial_sparsity {sparsity} ({e}) (method.dial_sparsity)"));
            continue;
        }
        if sparsities.len() == 1 {
            return Ok(Vec::new());
        }
        let fields = crate::model::component_fields(art)?;
        let median_of = |score: &dyn Fn(&[Vec3]) -> f64| {
            let v: Vec<f64> = fields[..k].iter().map(|f| score(f)).collect();
            super::metrics_file::median(&v).unwrap_or(0.0)
        };
        let concentration = median_of(&crate::metrics::recovery::energy_concentration);
        let support = median_of(&|f| crate::metrics::recovery::support_size(f) as f64 / f.len().max(1) as f64);
        if best.as_ref().is_none_or(|(i, _, _)| concentration > scores[*i].median_concentration) {
            best = Some((scores.len(), art.header.dial_basis.clone(), art.header.analysis.clone()));
        }
        scores.push(DialReadout {
            dial_sparsity: sparsity,
            median_concentration: concentration,
            median_vertex_support: support,
            chosen: false,
        });
    }
    match best {
        Some((i, basis, analysis)) => {
            art.header.dial_basis = basis;
            art.header.analysis = analysis;
            scores[i].chosen = true;
            Ok(scores)
        }
        None => {
            progress.note("the dials are the latent dimensions (method.dial_sparsity)");
            art.read_dials(0.0)?;
            Ok(Vec::new())
        }
    }
}

/// The line `train` prints about the dials `"auto"` chose.
fn describe_dial_choice(scores: &[DialReadout]) -> String {
    let one = |r: &DialReadout| {
        format!(
            "{} {:.1} % (moving {:.0} % of the vertices)",
            r.dial_sparsity,
            100.0 * r.median_concentration,
            100.0 * r.median_vertex_support
        )
    };
    let tried: Vec<String> = scores.iter().map(|r| if r.chosen { format!("**{}**", one(r)) } else { one(r) }).collect();
    match scores.iter().find(|r| r.chosen) {
        Some(c) => format!(
            "dials: the dial basis at dial_sparsity {} (method.dial_sparsity = \"auto\": the most concentrated components; median share of a component's squared displacement on its tenth of vertices moving most, per sparsity tried: {})",
            c.dial_sparsity,
            tried.join(", ")
        ),
        None => String::new(),
    }
}

/// The method config the artefact's `config.toml` records: `m`, with the mini-batch the default
/// chose for `n_shapes` training shapes written out (more than
/// [`crate::nn::config::FULL_BATCH_UP_TO`]), so that the file trains the same run under any
/// later default.
fn written_method(m: &AutoencoderMethod, batch: usize, n_shapes: usize) -> AutoencoderMethod {
    let mut out = m.clone();
    if out.batch_size.is_none() && batch < n_shapes {
        out.batch_size = Some(batch);
    }
    out
}

/// Locality of the latent components: the rows C_k of the latent matrix, grouped per vertex
/// (9 numbers), centre = largest vertex norm, support region = normalised geodesic distance
/// below d_max.
fn component_locality_of(art: &AeArtifact, distances: &GeodesicSupport, support: [f64; 2]) -> Vec<ComponentLocality> {
    let c = art.model.components_matrix();
    let n = art.rest.n_vertices();
    let k = art.header.components;
    (0..k)
        .map(|kk| {
            let row = &c[kk * n * 9..(kk + 1) * n * 9];
            let norms: Vec<f64> =
                row.chunks_exact(9).map(|g| g.iter().map(|&x| (x as f64) * (x as f64)).sum::<f64>().sqrt()).collect();
            let center = norms.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i).unwrap_or(0);
            let d = CenterDistances::distances(distances, center);
            let ramp: Vec<f64> = d.iter().map(|&x| support_ramp(x, support[0], support[1])).collect();
            component_locality(center, &norms, &ramp)
        })
        .collect()
}

/// The piece translations of a full code (its values after the network's K).
fn art_rest_t(code: &[f64], k: usize) -> Vec<f64> {
    code.get(k..).map(<[f64]>::to_vec).unwrap_or_default()
}

/// The dial basis (`dial_sparsity`) is fitted only with at least this many training shapes per
/// component: with fewer, the sparsest basis of the codes gives each shape its own dial (on
/// SCAPE, 36 shapes and K 50, every dial was a whole training pose). The ground-truth sets have
/// 200 shapes for K 41.
pub const DIAL_BASIS_SHAPES_PER_DIAL: usize = 2;

/// A run trained when its encode–decode feature error on the training shapes gained at least
/// this share of what the best K linear components gain over decoding every shape as the rest
/// shape (healthy runs gain 70–95 %, also on noisy data; runs stopped after a few steps, or
/// stuck, a few per cent).
pub const NOT_TRAINED_GAIN: f64 = 0.2;

/// A run that trained ([`NOT_TRAINED_GAIN`]) but ran fewer than this share of the default's
/// steps and makes less than [`SHORT_RUN_GAIN`] of the linear gain trained only partly (a
/// warning naming `iterations`). SCAPE (seed 0): 100 steps make 54 % of the gain (test Erms
/// 45.5), 300 steps 94 % (15.1), the default 2 000 steps 99.3 % (4.67). The share alone does not
/// tell a short run from noisy data: the ground-truth validation face at 1 000 steps makes 40 %
/// (held-out Erms 6.37 against 2.62 at 2 000), the noisiest ground-truth body (1e-3) at the
/// default 2 000 steps 35 % (test Erms 3.05, better than the full batch's 3.29), the noisy test
/// face (1e-4) 81 %.
pub const PARTLY_TRAINED_STEPS: f64 = 0.25;
pub const SHORT_RUN_GAIN: f64 = 0.97;

/// Whether a run that trained stopped too early ([`PARTLY_TRAINED_STEPS`]).
fn partly_trained(share: f64, steps: usize, default_steps: usize) -> bool {
    (steps as f64) < PARTLY_TRAINED_STEPS * default_steps as f64 && share < SHORT_RUN_GAIN
}

/// The share of the linear gain `base − linear` that a decoding error `err` makes (`base`: every
/// shape decoded as the rest shape). With nothing linear to gain, 1 or 0 as [`trained`] decides
/// (within 80 % of the rest error), so `training_gain` never contradicts the warning.
fn gain_share(err: f64, base: f64, linear: f64) -> f64 {
    let gain = base - linear;
    if gain > 1e-12 * base.max(f64::MIN_POSITIVE) {
        (base - err) / gain
    } else if trained(err, base, linear) {
        1.0
    } else {
        0.0
    }
}

/// Whether a run trained ([`NOT_TRAINED_GAIN`]); without any linear gain to measure against
/// (every shape is the rest shape), whether it decodes them to within 80 % of the rest error.
fn trained(err: f64, base: f64, linear: f64) -> bool {
    let gain = base - linear;
    if gain > 1e-12 * base.max(f64::MIN_POSITIVE) {
        base - err >= NOT_TRAINED_GAIN * gain
    } else {
        err < 0.8 * base || base == 0.0
    }
}

/// Whether the reconstruction error was still falling at the end of a run: the mean of its last
/// tenth of steps is below 90 % of the tenth before.
fn still_improving(recs: &[f64]) -> bool {
    let w = (recs.len() / 10).max(1);
    if recs.len() < 2 * w {
        return true;
    }
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let n = recs.len();
    mean(&recs[n - w..]) < 0.9 * mean(&recs[n - 2 * w..n - w])
}

/// Where a stopped or finished run keeps its checkpoint.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    out.join(CHECKPOINT_FILE)
}

/// Steps timed before `train` prints its estimate (the first, which warms caches up, is not
/// counted).
pub const ESTIMATE_AFTER_STEPS: usize = 10;

/// The mean time of a run's first steps, once: `add` returns it at the `after`-th step of the
/// run (the first step left out), and `None` before and after.
#[derive(Clone, Debug)]
pub struct StepEstimate {
    after: usize,
    steps: usize,
    seconds: f64,
}

impl StepEstimate {
    pub fn new(after: usize) -> Self {
        StepEstimate { after: after.max(2), steps: 0, seconds: 0.0 }
    }

    /// Counts one step of `seconds`; the mean seconds a step (first step left out) at the
    /// `after`-th.
    pub fn add(&mut self, seconds: f64) -> Option<f64> {
        self.steps += 1;
        if self.steps > 1 {
            self.seconds += seconds;
        }
        (self.steps == self.after).then(|| self.seconds / (self.after - 1) as f64)
    }
}

/// The estimate line: time left for `steps_left` steps of `per_step` seconds, and the step's
/// cost per shape-vertex (`shapes` decoded a step, synthetic ones included, of `vertices`).
pub fn estimate_text(per_step: f64, steps_left: usize, shapes: usize, vertices: usize) -> String {
    let total = per_step * steps_left as f64;
    let per_sv = per_step / (shapes.max(1) * vertices.max(1)) as f64;
    format!(
        "training estimate: about {} for the {steps_left} steps left ({:.0} ms a step of {shapes} shapes × {vertices} \
         vertices: {:.2} µs per shape-vertex; `method.batch_size` sets the shapes a step)",
        duration_text(total),
        per_step * 1e3,
        per_sv * 1e6
    )
}

/// `45 s`, `3 min 20 s`, `2 h 05 min`.
fn duration_text(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    if s < 60 {
        format!("{s} s")
    } else if s < 3600 {
        format!("{} min {:02} s", s / 60, s % 60)
    } else {
        format!("{} h {:02} min", s / 3600, (s / 60) % 60)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gain_share_is_the_way_from_the_rest_shape_to_the_linear_components() {
        assert_eq!(gain_share(16.3, 16.3, 2.5), 0.0);
        assert!((gain_share(3.7, 16.3, 2.5) - 12.6 / 13.8).abs() < 1e-12);
        // SCAPE's runs of 100, 300 and 2 000 steps (54 %, 94 %, 99.3 %).
        assert!(partly_trained(0.54, 100, 2000) && partly_trained(0.94, 300, 2000));
        assert!(!partly_trained(0.993, 2000, 2000) && !partly_trained(0.6, 500, 2000));
        assert!(!partly_trained(0.98, 100, 2000));
        // Noisy data at the default's steps is not a short run: the body at noise 1e-3 (35 %).
        assert!(!partly_trained(0.345, 2000, 2000) && !partly_trained(0.81, 2000, 2000));
        assert_eq!((gain_share(0.5, 1.0, 1.0), gain_share(1.5, 1.0, 1.0)), (1.0, 0.0));
        // Nothing to gain: the share says what `trained` says.
        assert_eq!((gain_share(0.9, 1.0, 1.0), trained(0.9, 1.0, 1.0)), (0.0, false));
    }

    #[test]
    fn config_toml_names_the_mini_batch_the_default_chose() {
        let m = AutoencoderMethod::default();
        assert_eq!(m.batch_size, None);
        // 200 shapes: the default's 32 is written out; 36 shapes: the full batch stays implicit.
        assert_eq!(written_method(&m, 32, 200).batch_size, Some(32));
        assert_eq!(written_method(&m, 36, 36).batch_size, None);
        let own = AutoencoderMethod { batch_size: Some(8), ..m };
        assert_eq!(written_method(&own, 8, 200).batch_size, Some(8));
    }

    #[test]
    fn the_estimate_is_the_mean_of_the_first_steps_after_the_first() {
        let mut e = StepEstimate::new(4);
        // The first step (warm-up, 9 s) is left out; the 2nd–4th average 2 s; said once.
        assert_eq!(e.add(9.0), None);
        assert_eq!(e.add(1.0), None);
        assert_eq!(e.add(2.0), None);
        assert_eq!(e.add(3.0), Some(2.0));
        assert_eq!(e.add(3.0), None);
        // 0.07 s a step, 1990 steps left, 67 shapes × 4000 vertices.
        let t = estimate_text(0.07, 1990, 67, 4000);
        assert!(t.contains("about 2 min 19 s for the 1990 steps left"), "{t}");
        assert!(t.contains("70 ms a step of 67 shapes × 4000 vertices: 0.26 µs per shape-vertex"), "{t}");
        assert_eq!(duration_text(7261.0), "2 h 01 min");
        assert_eq!(duration_text(59.4), "59 s");
    }

    #[test]
    fn a_run_trained_when_it_gains_a_fifth_of_the_linear_gain() {
        // Noisy data: the rest shape leaves 44, K linear components 35; a model at 37.7 made
        // 70 % of their gain and trained, one at 43 made 11 % and did not.
        assert!(trained(37.7, 44.2, 35.0));
        assert!(!trained(43.0, 44.2, 35.0));
        assert!(trained(44.2 - 0.2 * 9.2, 44.2, 35.0) && !trained(44.2 - 0.19 * 9.2, 44.2, 35.0));
        // Clean data: healthy runs end near the linear error.
        assert!(trained(3.7, 16.3, 2.5) && !trained(15.0, 16.3, 2.5));
        // Nothing linear to gain: the ratio to the rest error decides.
        assert!(trained(0.5, 1.0, 1.0) && !trained(0.9, 1.0, 1.0));
    }

    #[test]
    fn still_improving_compares_the_last_tenth_with_the_tenth_before() {
        let falling: Vec<f64> = (0..100).map(|i| 100.0 - i as f64).collect();
        assert!(still_improving(&falling));
        assert!(!still_improving(&[5.0; 100]));
        assert!(still_improving(&[1.0]));
    }
}
