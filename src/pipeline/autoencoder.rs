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

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::Progress;
use super::ae_fit::{AeFitEncoder, DEFAULT_FIT_GAMMA};
use super::geodesic_support::GeodesicSupport;
use super::linear::{TrainOutcome, rest_from_arrays, rest_to_arrays};
use super::metrics_file::{Metrics, median};
use crate::artifact::{self, ArrayStore};
use crate::config::{Config, MethodKind, resolved_toml};
use crate::error::{Error, Result};
use crate::mesh::{self, MeshSequence, TriMesh, Vec3};
use crate::methods::support_map::{ComponentLocality, SupportDistances, component_locality, support_ramp};
use crate::nn::{Autoencoder, AutoencoderConfig, CenterDistances, NeighborIndex, RunOptions, Trainer, TrainingData};
use crate::preprocess::{self, UnitBox};
use crate::representation::acap::Consistency;
use crate::representation::roundtrip::{Alignment, erms, frame_squared_error};
use crate::representation::scaling::{FeatureScaling, ScalingMode};
use crate::representation::{Representation, RepresentationKind, RepresentationOptions};

/// Checkpoint file name inside the artefact directory.
pub const CHECKPOINT_FILE: &str = "checkpoint.bin";
/// Per-iteration log file name.
pub const LOG_FILE: &str = "training.jsonl";
/// Default heat-method factor for the autoencoder's support maps (Crane et al.'s m = 1).
pub const AE_GEODESIC_M: f64 = 1.0;

/// Header of an autoencoder's `model.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AeHeader {
    /// Always `autoencoder`.
    pub method: String,
    /// Always `acap`.
    pub representation: String,
    /// ACAP rotation consistency (`bfs` or `global`).
    pub consistency: String,
    /// Feature scaling to [−0.95, 0.95] fitted on the training frames.
    pub scaling: FeatureScaling,
    /// Data scaling applied before encoding (identity unless `data.unit_box`).
    pub unit_box: UnitBox,
    /// Number of components K.
    pub components: usize,
    /// Names of the training frames (rows of `train_codes`).
    pub train_frames: Vec<String>,
    /// Index (into the training frames) of the reference shape of the component analysis.
    pub reference: usize,
    /// Component analysis: per latent dimension (index = dimension) the extreme code kept,
    /// the feature-space distance, its rank (0 = largest) and centre vertex.
    pub analysis: Vec<ComponentSummary>,
}

/// One latent dimension of the component analysis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComponentSummary {
    pub dim: usize,
    pub rank: usize,
    pub z_min: f64,
    pub z_max: f64,
    pub z_extreme: f64,
    pub distance: f64,
    pub center: usize,
    pub support_size: usize,
}

/// Heat-geodesic distances normalised by the largest geodesic distance (the trainer's
/// [`CenterDistances`]).
impl CenterDistances for GeodesicSupport {
    fn distances(&self, center: usize) -> Vec<f64> {
        SupportDistances::distances(self, &[center]).unwrap_or_else(|_| vec![f64::INFINITY; self.n_vertices()])
    }
}

fn consistency_of(s: Option<&str>) -> Consistency {
    if s == Some("bfs") { Consistency::Bfs } else { Consistency::Global }
}

/// The autoencoder hyperparameters from a validated config (defaults: the reference's).
pub fn autoencoder_config(cfg: &Config) -> Result<AutoencoderConfig> {
    let m = &cfg.method;
    let d = AutoencoderConfig::default();
    let [d_min, d_max] = m.support.unwrap_or([d.d_min, d.d_max]);
    let c = AutoencoderConfig {
        components: m.components.unwrap_or(d.components),
        layers: m.layers.unwrap_or(d.layers),
        learning_rate: m.learning_rate.unwrap_or(d.learning_rate),
        learning_rate_final: m.learning_rate_final,
        beta1: m.beta1.unwrap_or(d.beta1),
        beta2: m.beta2.unwrap_or(d.beta2),
        iterations: m.iterations.unwrap_or(d.iterations),
        batch_size: m.batch_size,
        lambda1: m.lambda1.unwrap_or(d.lambda1),
        lambda2: m.lambda2.unwrap_or(d.lambda2),
        theta: m.theta.unwrap_or(d.theta),
        d_min,
        d_max,
        checkpoint_every: m.checkpoint_every.unwrap_or(d.checkpoint_every),
        seed: m.seed.unwrap_or(d.seed),
        engine: m.engine.as_deref().and_then(crate::nn::config::Engine::parse).unwrap_or(d.engine),
        device: m.device.as_deref().and_then(crate::nn::config::ComputeDevice::parse).unwrap_or(d.device),
        ..d
    };
    c.validate().map_err(|e| match e {
        Error::Config { key, message } => Error::config(format!("method.{key}"), message),
        other => other,
    })?;
    Ok(c)
}

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

impl AeArtifact {
    /// Loads an artefact directory written by [`train`].
    pub fn load(dir: &Path) -> Result<Self> {
        let dir = artifact::model_dir(dir);
        let (header, arrays): (AeHeader, ArrayStore) = artifact::load_model(&dir)?;
        let rest = rest_from_arrays(&arrays)?;
        let options =
            RepresentationOptions { acap_consistency: consistency_of(Some(&header.consistency)), ..Default::default() };
        let representation = Representation::new(RepresentationKind::Acap, &rest, options)?;
        let neighbors = NeighborIndex::new(representation.element_adjacency())?;
        let model = Autoencoder::load(&dir, neighbors)?;
        let k = header.components;
        let f = header.train_frames.len();
        let codes = arrays.get_shaped("train_codes", &[f, k])?;
        let train_codes = codes.chunks_exact(k.max(1)).map(<[f64]>::to_vec).collect();
        Ok(AeArtifact { header, rest, representation, model, train_codes })
    }

    /// Codes (K each) of frames given in data units.
    pub fn encode_frames(&self, frames: &MeshSequence) -> Result<Vec<Vec<f64>>> {
        let mut scaled = frames.clone();
        for p in scaled.frames.iter_mut().flatten() {
            *p = self.header.unit_box.apply(*p);
        }
        let x = self.representation.encode(&scaled)?;
        let xs = self.header.scaling.apply(&x)?;
        self.model.encode(&xs)
    }

    /// Vertex positions (data units) decoded from codes.
    pub fn decode_codes(&self, codes: &[Vec<f64>]) -> Result<Vec<Vec<Vec3>>> {
        let xs = self.model.decode(codes)?;
        let x = self.header.scaling.invert(&xs)?;
        let mut frames = self.representation.decode(&x)?;
        for p in frames.iter_mut().flatten() {
            *p = self.header.unit_box.invert(*p);
        }
        Ok(frames)
    }

    /// The reference shape's code Z_r.
    pub fn reference_code(&self) -> &[f64] {
        &self.train_codes[self.header.reference]
    }

    /// Synthesis code: z_i = Z_r,i + (Z_h,i − Z_r,i)·w_i for the given (dimension, weight)
    /// pairs; other dimensions keep Z_r.
    pub fn synthesis_code(&self, weights: &[(usize, f64)]) -> Result<Vec<f64>> {
        let mut z = self.reference_code().to_vec();
        for &(i, w) in weights {
            let s = self.header.analysis.get(i).ok_or_else(|| {
                Error::Invalid(format!("component {i} does not exist (K = {})", self.header.components))
            })?;
            z[i] = z[i] + (s.z_extreme - z[i]) * w;
        }
        Ok(z)
    }

    /// Rest mesh in data units.
    pub fn rest_in_data_units(&self) -> TriMesh {
        TriMesh::new(
            self.rest.positions.iter().map(|p| self.header.unit_box.invert(*p)).collect(),
            self.rest.faces.clone(),
        )
    }

    /// Writes, per component in rank order, `<rank>_<dim>.obj` (the extreme shape) and
    /// `<rank>_<dim>_change.ply` (rest mesh coloured by per-vertex feature change), plus
    /// `components.csv` (dimension, rank, distance, z_extreme, centre vertex, support size).
    pub fn write_components(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let zr = self.reference_code().to_vec();
        let mut order: Vec<&ComponentSummary> = self.header.analysis.iter().collect();
        order.sort_by_key(|c| c.rank);
        let codes: Vec<Vec<f64>> = std::iter::once(zr.clone())
            .chain(order.iter().map(|c| {
                let mut z = zr.clone();
                z[c.dim] = c.z_extreme;
                z
            }))
            .collect();
        let feats = self.header.scaling.invert(&self.model.decode(&codes)?)?;
        let meshes = self.decode_codes(&codes)?;
        let rest = self.rest_in_data_units();
        let n = self.rest.n_vertices();
        let mut csv = String::from("dimension,rank,distance,z_extreme,center_vertex,support_size\n");
        for (j, c) in order.iter().enumerate() {
            let change: Vec<f64> = (0..n)
                .map(|v| {
                    let a = feats.element(j + 1, v);
                    let b = feats.element(0, v);
                    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
                })
                .collect();
            let stem = format!("{}_{}", c.rank, c.dim);
            mesh::write_obj(
                &dir.join(format!("{stem}.obj")),
                &TriMesh::new(meshes[j + 1].clone(), self.rest.faces.clone()),
            )?;
            mesh::write_ply(
                &dir.join(format!("{stem}_change.ply")),
                &rest,
                Some(&mesh::colormap(&change)),
                Some(("change", &change)),
            )?;
            csv.push_str(&format!(
                "{},{},{},{},{},{}\n",
                c.dim, c.rank, c.distance, c.z_extreme, c.center, c.support_size
            ));
        }
        artifact::write_atomic(&dir.join("components.csv"), csv.as_bytes())
    }
}

/// Trains the autoencoder as configured and writes the artefact directory `out`. With
/// `resume`, continues from `out/checkpoint.bin` (same data and hyperparameters; only
/// `iterations` and `checkpoint_every` may change). `stop` ends the run early after writing a
/// checkpoint (Ctrl-C).
pub fn train(
    cfg: &Config,
    out: &Path,
    resume: bool,
    stop: Option<Arc<AtomicBool>>,
    progress: &mut dyn Progress,
) -> Result<TrainOutcome> {
    if cfg.kind != MethodKind::Autoencoder {
        return Err(Error::Invalid(format!("autoencoder::train does not handle kind = \"{}\"", cfg.kind.name())));
    }
    let ae_cfg = autoencoder_config(cfg)?;
    let scaling_mode = match cfg.method.scaling.as_deref() {
        Some("grouped") => ScalingMode::reference_grouped(),
        Some("global") => ScalingMode::Grouped { groups: vec![(0..9).collect()] },
        _ => ScalingMode::PerDimension,
    };
    let consistency_name = cfg.method.consistency.clone().unwrap_or_else(|| "global".into());
    let checkpoint = out.join(CHECKPOINT_FILE);
    if resume && !checkpoint.exists() {
        return Err(Error::Invalid(format!("--resume: no checkpoint at {}", checkpoint.display())));
    }

    progress.stage("loading", 0);
    let prep = preprocess::prepare(&cfg.data)?;
    progress.stage("acap features", 0);
    let t_rep = Instant::now();
    let options =
        RepresentationOptions { acap_consistency: consistency_of(Some(&consistency_name)), ..Default::default() };
    let representation = Representation::new(RepresentationKind::Acap, &prep.rest, options)?;
    let train_seq = prep.train_sequence();
    let x_train = representation.encode(&train_seq)?;
    let scaling = FeatureScaling::fit(&x_train, scaling_mode)?;
    let xs_train = scaling.apply(&x_train)?;
    let representation_seconds = t_rep.elapsed().as_secs_f64();

    progress.stage("geodesics", 0);
    let distances = GeodesicSupport::max_normalised(&prep.rest, cfg.method.geodesic_m.unwrap_or(AE_GEODESIC_M))?;
    let neighbors = NeighborIndex::new(representation.element_adjacency())?;
    let data = TrainingData::from_features(&xs_train)?;

    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let mut trainer = if resume {
        Trainer::resume(&checkpoint, ae_cfg.clone(), &data, &neighbors, &distances)?
    } else {
        Trainer::new(ae_cfg.clone(), &data, &neighbors, &distances)?
    };
    let log_path = out.join(LOG_FILE);
    let mut log = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .append(resume)
        .truncate(!resume)
        .open(&log_path)
        .map_err(|e| Error::io(&log_path, e))?;
    progress.stage("training", ae_cfg.iterations as u64);
    progress.step(trainer.iteration() as u64, "");
    let t_train = Instant::now();
    let mut log_error: Option<std::io::Error> = None;
    let summary = trainer.run(&RunOptions { checkpoint: Some(checkpoint.clone()), stop }, |r| {
        let l = &r.loss;
        let line = format!(
            "{{\"iteration\":{},\"loss\":{},\"reconstruction\":{},\"sparsity\":{},\"hinge\":{},\"step_seconds\":{},\"checkpoint\":{}}}\n",
            r.iteration, l.total, l.reconstruction, l.sparsity, l.hinge, r.step_seconds, r.checkpointed
        );
        if let Err(e) = log.write_all(line.as_bytes()) {
            log_error.get_or_insert(e);
        }
        progress.step(r.iteration as u64, &format!("loss {:.4} (rec {:.4}, sparse {:.4}, hinge {:.4})", l.total, l.reconstruction, l.sparsity, l.hinge));
    })?;
    let train_seconds = t_train.elapsed().as_secs_f64();
    if let Some(e) = log_error {
        return Err(Error::io(&log_path, e));
    }
    progress.finish_stage();
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
    let train_codes = model.encode(&xs_train)?;
    let analysis = model.analyze_components(&xs_train, 0)?;
    let mut summaries: Vec<ComponentSummary> = analysis
        .components
        .iter()
        .map(|c| ComponentSummary {
            dim: c.dim,
            rank: c.rank,
            z_min: c.z_min,
            z_max: c.z_max,
            z_extreme: c.z_extreme,
            distance: c.distance,
            center: c.center,
            support_size: c.support_size,
        })
        .collect();
    summaries.sort_by_key(|c| c.dim);
    let header = AeHeader {
        method: "autoencoder".into(),
        representation: "acap".into(),
        consistency: consistency_name.clone(),
        scaling,
        unit_box: prep.unit_box,
        components: ae_cfg.components,
        train_frames: train_seq.names.clone(),
        reference: 0,
        analysis: summaries,
    };
    let art = AeArtifact { header, rest: prep.rest.clone(), representation, model, train_codes };

    let truth = |idx: &[usize]| -> Vec<Vec<Vec3>> {
        idx.iter().map(|&f| prep.sequence.frames[f].iter().map(|p| prep.unit_box.invert(*p)).collect()).collect()
    };
    let train_rec = art.decode_codes(&art.train_codes)?;
    let train_erms = erms(&truth(&prep.train), &train_rec, Alignment::Centroid)?;
    let (test_erms, test_erms_fitted) = if prep.test.is_empty() {
        (None, None)
    } else {
        let test = MeshSequence { faces: prep.sequence.faces.clone(), frames: truth(&prep.test), names: Vec::new() };
        let codes = art.encode_frames(&test)?;
        let rec = art.decode_codes(&codes)?;
        let forward = erms(&test.frames, &rec, Alignment::Centroid)?;
        let fitted = if cfg.method.fit_test.unwrap_or(true) {
            progress.stage("fitting test codes", test.n_frames() as u64);
            let fitter = AeFitEncoder::new(&art, usize::MAX, DEFAULT_FIT_GAMMA)?;
            let (_, rec) = fitter.fit_from(&test, &codes, |i| progress.step(i as u64 + 1, ""))?;
            Some(erms(&test.frames, &rec, Alignment::Centroid)?)
        } else {
            None
        };
        (Some(forward), fitted)
    };
    let locality = component_locality_of(&art, &distances, [ae_cfg.d_min, ae_cfg.d_max]);
    let shares: Vec<f64> = locality.iter().map(|l| l.energy_share).collect();
    let sizes: Vec<f64> = locality.iter().map(|l| l.support_size as f64).collect();
    let metrics = Metrics {
        method: "autoencoder".into(),
        representation: "acap".into(),
        components: ae_cfg.components,
        train_erms,
        test_erms,
        test_erms_fitted,
        erms_alignment: Alignment::Centroid.to_string(),
        train_seconds,
        representation_seconds,
        iterations: summary.iterations_done,
        objective: summary.last_loss.map(|l| l.total),
        converged: None,
        train_frames: prep.train.len(),
        test_frames: prep.test.len(),
        median_energy_share: median(&shares),
        median_support_size: median(&sizes),
        locality,
    };

    progress.stage("writing", 0);
    let mut method_table = toml::Table::try_from(&ae_cfg).map_err(|e| Error::Invalid(e.to_string()))?;
    for k in ["init_std", "epsilon"] {
        method_table.remove(k);
    }
    let support = [ae_cfg.d_min, ae_cfg.d_max];
    method_table.remove("d_min");
    method_table.remove("d_max");
    method_table.insert("support".into(), toml::Value::try_from(support).map_err(|e| Error::Invalid(e.to_string()))?);
    method_table.insert("kind".into(), "autoencoder".into());
    method_table.insert("consistency".into(), consistency_name.into());
    method_table.insert("scaling".into(), cfg.method.scaling.as_deref().unwrap_or("per-dimension").into());
    if let Some(f) = cfg.method.fit_test {
        method_table.insert("fit_test".into(), f.into());
    }
    method_table.insert("geodesic_m".into(), cfg.method.geodesic_m.unwrap_or(AE_GEODESIC_M).into());
    artifact::write_atomic(&out.join("config.toml"), resolved_toml(&cfg.name, &cfg.data, method_table).as_bytes())?;
    art.model.save(out)?;
    let mut arrays = ArrayStore::new();
    rest_to_arrays(&art.rest, &mut arrays)?;
    let k = ae_cfg.components;
    arrays.insert(
        "train_codes",
        vec![art.train_codes.len(), k],
        art.train_codes.iter().flatten().copied().collect(),
    )?;
    artifact::save_model(out, &art.header, &arrays)?;
    let flat: Vec<f64> = art.train_codes.iter().flatten().copied().collect();
    artifact::write_weights_csv(&out.join("weights.csv"), &train_seq.names, &flat, k)?;
    artifact::write_json(&out.join("metrics.json"), &metrics)?;
    art.write_components(&out.join("components"))?;
    progress.finish_stage();
    Ok(TrainOutcome { out_dir: out.to_path_buf(), metrics })
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

/// Per-frame Erms (centroid-aligned) of reconstructions against frames.
pub fn frame_erms(truth: &[Vec<Vec3>], rec: &[Vec<Vec3>]) -> Result<Vec<f64>> {
    truth
        .iter()
        .zip(rec)
        .map(|(t, r)| Ok(1000.0 * (frame_squared_error(t, r, Alignment::Centroid)? / (3.0 * t.len() as f64)).sqrt()))
        .collect()
}

/// Where a stopped or finished run keeps its checkpoint.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    out.join(CHECKPOINT_FILE)
}
