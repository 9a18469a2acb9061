//! Region-based PCA (`kind = "region-pca"`): segmentation of the training displacements
//! ([`crate::methods::segmentation`]), one PCA per region ([`crate::methods::region_pca`]),
//! measurement and the artefact directory.
//!
//! Representation: vertex displacements from the rest mesh only (region PCA and its posing are
//! per-vertex). Artefacts in `out`: `config.toml` (resolved), `model.json` (header) +
//! `model.bin` (arrays: `rest_positions`, `faces`, `labels` (N), and per region i
//! `region{i}_vertices` (N_i), `region{i}_mean` (3N_i), `region{i}_basis` (P_i × 3N_i)),
//! `segmentation.ply` (rest mesh coloured by cluster, scalar `region`), `metrics.json`.
//! Positions leaving this module are in the data's own units (unit-box scaling undone).

use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::Progress;
use super::linear::{TrainOutcome, rest_from_arrays, rest_to_arrays};
use super::metrics_file::Metrics;
use crate::artifact::{self, ArrayStore};
use crate::config::{Config, MethodKind, resolved_toml};
use crate::error::{Error, Result};
use crate::mesh::{self, MeshSequence, TriMesh, Vec3};
use crate::methods::DataMatrix;
use crate::methods::region_pca::{RegionBasis, RegionPcaConfig, RegionPcaModel};
use crate::methods::segmentation::{SegmentationConfig, segment};
use crate::preprocess::{self, UnitBox};
use crate::representation::roundtrip::{Alignment, erms};
use crate::representation::{Features, Representation, RepresentationKind, RepresentationOptions};

/// Header of a region PCA `model.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RegionHeader {
    /// Always `region-pca`.
    pub method: String,
    /// Always `displacement`.
    pub representation: String,
    /// Scaling applied to the data before encoding.
    pub unit_box: UnitBox,
    /// Number of components per region P_i.
    pub components: Vec<usize>,
    /// β of the coupled encoding.
    pub beta: f64,
    /// Default γ for posing.
    pub gamma: f64,
    /// Segmentation parameters used (λ, r in model units, threshold).
    pub lambda: f64,
    pub r: f64,
    pub threshold: f64,
    /// Names of the training frames.
    pub train_frames: Vec<String>,
}

/// A trained region PCA model.
pub struct RegionArtifact {
    pub header: RegionHeader,
    /// Rest mesh in model (possibly unit-box) space.
    pub rest: TriMesh,
    /// Cluster of every vertex (before boundary sharing).
    pub labels: Vec<usize>,
    pub model: RegionPcaModel,
    pub representation: Representation,
}

impl RegionArtifact {
    /// Saves `model.json` + `model.bin` into `dir`.
    pub fn save(&self, dir: &Path) -> Result<()> {
        let mut a = ArrayStore::new();
        rest_to_arrays(&self.rest, &mut a)?;
        a.insert("labels", vec![self.labels.len()], self.labels.iter().map(|&l| l as f64).collect())?;
        for (i, r) in self.model.regions.iter().enumerate() {
            let ni = r.vertices.len();
            a.insert(&format!("region{i}_vertices"), vec![ni], r.vertices.iter().map(|&v| v as f64).collect())?;
            a.insert(&format!("region{i}_mean"), vec![3 * ni], r.mean.clone())?;
            a.insert(&format!("region{i}_basis"), vec![r.n_components, 3 * ni], r.basis.clone())?;
        }
        artifact::save_model(dir, &self.header, &a)
    }

    /// Loads an artefact directory written by [`train`].
    pub fn load(dir: &Path) -> Result<Self> {
        let (header, arrays): (RegionHeader, ArrayStore) = artifact::load_model(dir)?;
        let rest = rest_from_arrays(&arrays)?;
        let n = rest.n_vertices();
        let labels: Vec<usize> = arrays.get_shaped("labels", &[n])?.iter().map(|&l| l as usize).collect();
        let mut regions = Vec::with_capacity(header.components.len());
        for (i, &p) in header.components.iter().enumerate() {
            let (shape, v) = arrays.get(&format!("region{i}_vertices"))?;
            let ni = shape.first().copied().unwrap_or(0);
            let vertices: Vec<usize> = v.iter().map(|&x| x as usize).collect();
            if let Some(&bad) = vertices.iter().find(|&&x| x >= n) {
                return Err(Error::Invalid(format!("{}: region {i} vertex {bad} out of range ({n})", dir.display())));
            }
            regions.push(RegionBasis {
                vertices,
                mean: arrays.get_shaped(&format!("region{i}_mean"), &[3 * ni])?.to_vec(),
                basis: arrays.get_shaped(&format!("region{i}_basis"), &[p, 3 * ni])?.to_vec(),
                n_components: p,
            });
        }
        let model = RegionPcaModel { n_vertices: n, regions, beta: header.beta };
        let representation =
            Representation::new(RepresentationKind::Displacement, &rest, RepresentationOptions::default())?;
        Ok(RegionArtifact { header, rest, labels, model, representation })
    }

    /// Positions (data units) of displacement rows (`n` × N·3).
    pub fn decode_rows(&self, rows: &[f64]) -> Result<Vec<Vec<Vec3>>> {
        let n = self.model.n_vertices;
        let feats = Features { n_frames: rows.len() / (3 * n).max(1), n_elements: n, width: 3, data: rows.to_vec() };
        let mut frames = self.representation.decode(&feats)?;
        for p in frames.iter_mut().flatten() {
            *p = self.header.unit_box.invert(*p);
        }
        Ok(frames)
    }

    /// Coefficients ζ (rows of P numbers) of frames given in data units (Eq. 6/7).
    pub fn encode_frames(&self, frames: &MeshSequence) -> Result<Vec<Vec<f64>>> {
        let mut scaled = frames.clone();
        for p in scaled.frames.iter_mut().flatten() {
            *p = self.header.unit_box.apply(*p);
        }
        let x = self.representation.encode(&scaled)?;
        let enc = self.model.encoder()?;
        x.data.chunks_exact(3 * self.model.n_vertices).map(|row| enc.encode(row)).collect()
    }

    /// Encode + reconstruct frames (data units).
    pub fn reconstruct_frames(&self, frames: &MeshSequence) -> Result<Vec<Vec<Vec3>>> {
        let mut rows = Vec::new();
        for z in self.encode_frames(frames)? {
            rows.extend(self.model.reconstruct(&z)?);
        }
        self.decode_rows(&rows)
    }
}

fn seg_config(cfg: &Config) -> SegmentationConfig {
    let m = &cfg.method;
    let d = SegmentationConfig::default();
    SegmentationConfig {
        lambda: m.lambda.unwrap_or(d.lambda),
        r: m.r.or(d.r),
        threshold: m.threshold.unwrap_or(d.threshold),
        regions: m.regions,
        max_regions: m.max_regions.unwrap_or(d.max_regions),
        seed: m.seed.unwrap_or(d.seed),
        min_piece: m.min_piece.unwrap_or(d.min_piece),
        keep_searching: m.keep_searching.unwrap_or(d.keep_searching),
        ..d
    }
}

fn prefix(e: Error) -> Error {
    match e {
        Error::Config { key, message } if !key.starts_with("method.") => {
            Error::config(format!("method.{key}"), message)
        }
        other => other,
    }
}

/// Trains `region-pca` as configured and writes the artefact directory `out`.
///
/// Keys: `components` (total budget, default 50), `lambda`, `r` (model units: unit-box units when
/// `data.unit_box`), `threshold`, `regions` / `max_regions`, `beta` (default 1), `gamma`
/// (posing default, 0.025), `seed`.
pub fn train(cfg: &Config, out: &Path, progress: &mut dyn Progress) -> Result<TrainOutcome> {
    if cfg.kind != MethodKind::RegionPca {
        return Err(Error::Invalid(format!("region::train does not handle kind = \"{}\"", cfg.kind.name())));
    }
    let rep_name = cfg.method.representation.as_deref().unwrap_or("displacement");
    if rep_name != "displacement" {
        return Err(Error::config(
            "method.representation",
            format!("`{rep_name}`: region-pca supports only displacement"),
        ));
    }
    progress.stage("loading", 0);
    let prep = preprocess::prepare(&cfg.data)?;
    let train_seq = prep.train_sequence();
    progress.stage("representation", 0);
    let t_rep = Instant::now();
    let representation =
        Representation::new(RepresentationKind::Displacement, &prep.rest, RepresentationOptions::default())?;
    let x = representation.encode(&train_seq)?;
    let representation_seconds = t_rep.elapsed().as_secs_f64();

    let sc = seg_config(cfg);
    sc.validate().map_err(prefix)?;
    let rc = RegionPcaConfig { components: cfg.method.components.unwrap_or(50), beta: cfg.method.beta.unwrap_or(1.0) };
    rc.validate().map_err(prefix)?;
    let gamma = cfg.method.gamma.unwrap_or(0.025);

    let t = Instant::now();
    progress.stage("segmentation", 0);
    let seg = segment(&prep.rest.positions, &prep.rest.faces, &x.data, x.n_frames, &sc)?;
    progress.stage("region pca", 1);
    let model = RegionPcaModel::fit(DataMatrix::from_features(&x)?, &seg.regions, &rc).map_err(prefix)?;
    let train_seconds = t.elapsed().as_secs_f64();
    progress.step(1, &format!("{} regions", seg.n_regions()));
    progress.finish_stage();

    let artifact = RegionArtifact {
        header: RegionHeader {
            method: "region-pca".into(),
            representation: "displacement".into(),
            unit_box: prep.unit_box,
            components: model.regions.iter().map(|r| r.n_components).collect(),
            beta: rc.beta,
            gamma,
            lambda: sc.lambda,
            r: seg.r,
            threshold: sc.threshold,
            train_frames: train_seq.names.clone(),
        },
        rest: prep.rest.clone(),
        labels: seg.labels.clone(),
        model,
        representation,
    };

    progress.stage("measuring", 0);
    let truth = |idx: &[usize]| -> MeshSequence {
        MeshSequence {
            faces: prep.sequence.faces.clone(),
            frames: idx
                .iter()
                .map(|&f| prep.sequence.frames[f].iter().map(|p| prep.unit_box.invert(*p)).collect())
                .collect(),
            names: Vec::new(),
        }
    };
    let train_truth = truth(&prep.train);
    let train_erms = erms(&train_truth.frames, &artifact.reconstruct_frames(&train_truth)?, Alignment::None)?;
    let test_erms = if prep.test.is_empty() {
        None
    } else {
        let t = truth(&prep.test);
        Some(erms(&t.frames, &artifact.reconstruct_frames(&t)?, Alignment::None)?)
    };
    let metrics = Metrics {
        method: "region-pca".into(),
        representation: "displacement".into(),
        components: artifact.model.n_components(),
        train_erms,
        test_erms,
        test_erms_fitted: None,
        erms_alignment: Alignment::None.to_string(),
        train_seconds,
        representation_seconds,
        iterations: 1,
        objective: None,
        converged: None,
        train_frames: prep.train.len(),
        test_frames: prep.test.len(),
        median_energy_share: None,
        median_support_size: None,
        locality: Vec::new(),
    };

    progress.stage("writing", 0);
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let mut tbl = toml::Table::new();
    tbl.insert("kind".into(), "region-pca".into());
    tbl.insert("representation".into(), "displacement".into());
    tbl.insert("components".into(), (rc.components as i64).into());
    tbl.insert("lambda".into(), sc.lambda.into());
    tbl.insert("r".into(), seg.r.into());
    tbl.insert("threshold".into(), sc.threshold.into());
    match sc.regions {
        Some(k) => tbl.insert("regions".into(), (k as i64).into()),
        None => tbl.insert("max_regions".into(), (sc.max_regions as i64).into()),
    };
    tbl.insert("min_piece".into(), sc.min_piece.into());
    tbl.insert("keep_searching".into(), sc.keep_searching.into());
    tbl.insert("beta".into(), rc.beta.into());
    tbl.insert("gamma".into(), gamma.into());
    tbl.insert("seed".into(), (sc.seed as i64).into());
    artifact::write_atomic(&out.join("config.toml"), resolved_toml(&cfg.name, &cfg.data, tbl).as_bytes())?;
    artifact.save(out)?;
    write_segmentation_ply(&out.join("segmentation.ply"), &artifact)?;
    artifact::write_json(&out.join("metrics.json"), &metrics)?;
    progress.finish_stage();
    Ok(TrainOutcome { out_dir: out.to_path_buf(), metrics })
}

/// Writes the rest mesh (data units) coloured by cluster, with scalar `region` = cluster index.
pub fn write_segmentation_ply(path: &Path, a: &RegionArtifact) -> Result<()> {
    let m = a.labels.iter().max().map_or(1, |&x| x + 1);
    // Spread cluster indices over the colour map; neighbours in index get distant colours.
    let spread: Vec<f64> = a.labels.iter().map(|&l| ((l * 7) % m.max(1)) as f64).collect();
    let colors = mesh::colormap_range(&spread, 0.0, (m.max(2) - 1) as f64);
    let rest =
        TriMesh::new(a.rest.positions.iter().map(|p| a.header.unit_box.invert(*p)).collect(), a.rest.faces.clone());
    let scal: Vec<f64> = a.labels.iter().map(|&l| l as f64).collect();
    mesh::write_ply(path, &rest, Some(&colors), Some(("region", &scal)))
}
