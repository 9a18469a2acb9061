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

use super::linear::{rest_from_arrays, rest_to_arrays};
use super::pose::{control_targets, model_targets, single_frame};
use super::registry::{FitContext, FitStats, Fitted};
use crate::artifact::{self, ArrayStore};
use crate::config::{MethodConfig, MethodKind, RegionPcaMethod, method_key};
use crate::error::{Error, Result};
use crate::mesh::{self, MeshSequence, TriMesh, Vec3};
use crate::methods::DataMatrix;
use crate::methods::posing::{PoseConfig, RegionPoser, region_shape_metric};
use crate::methods::region_pca::{RegionBasis, RegionPcaModel};
use crate::methods::segmentation::segment;
use crate::model::{Component, Model, PointFit, PoseOptions, PosePrior, PoseResult, argmax};
use crate::preprocess::{Prepared, UnitBox};
use crate::representation::roundtrip::Alignment;
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
    /// Coefficients ζ of the training frames (P each; empty for artefacts written before they
    /// were stored).
    pub train_weights: Vec<Vec<f64>>,
    /// The posing shape metric ([`crate::methods::posing::region_shape_metric`]), computed on
    /// the first pose.
    pub shape_metric: std::sync::OnceLock<faer::Mat<f64>>,
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
        if !self.train_weights.is_empty() {
            a.insert(
                "train_weights",
                vec![self.train_weights.len(), self.model.n_components()],
                self.train_weights.iter().flatten().copied().collect(),
            )?;
        }
        artifact::save_model(dir, &self.header, &a)
    }

    /// Loads an artefact directory written by [`train`].
    pub fn load(dir: &Path) -> Result<Self> {
        let (header, arrays): (RegionHeader, ArrayStore) = artifact::load_model(dir)?;
        let rest = rest_from_arrays(&arrays)?;
        let n = rest.n_vertices();
        let json = artifact::model_dir(dir).join("model.json");
        let bad = |m: String| Error::parse(&json, None, m);
        // Bounds before anything is sized by them: one region per vertex at most, per region
        // at most 3 × its vertices components (checked with its vertices below).
        let regions_n = header.components.len();
        if regions_n == 0 || regions_n > n {
            return Err(bad(format!("`components` lists {regions_n} regions; a mesh of {n} vertices has 1 to {n}")));
        }
        header.unit_box.validate().map_err(|m| bad(format!("`unit_box`: {m}")))?;
        for (key, v) in [("beta", header.beta), ("gamma", header.gamma), ("lambda", header.lambda), ("r", header.r)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(format!("`{key}` is {v}, not a number ≥ 0")));
            }
        }
        let labels = super::linear::index_array("labels", arrays.get_shaped("labels", &[n])?, regions_n)?;
        let mut regions = Vec::with_capacity(regions_n);
        for (i, &p) in header.components.iter().enumerate() {
            let (shape, v) = arrays.get(&format!("region{i}_vertices"))?;
            let ni = shape.first().copied().unwrap_or(0);
            if shape.len() != 1 || ni == 0 || ni > n {
                return Err(bad(format!(
                    "region {i}: `region{i}_vertices` has shape {shape:?}; expected 1 to {n} vertices"
                )));
            }
            if p == 0 || p > 3 * ni {
                return Err(bad(format!("`components[{i}]` is {p}; region {i} of {ni} vertices has 1 to {}", 3 * ni)));
            }
            let vertices = super::linear::index_array(&format!("region{i}_vertices"), v, n)?;
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
        let p = model.n_components();
        let f = header.train_frames.len();
        let train_weights = if arrays.names().any(|n| n == "train_weights") {
            arrays.get_shaped("train_weights", &[f, p])?.chunks_exact(p.max(1)).map(<[f64]>::to_vec).collect()
        } else {
            Vec::new()
        };
        Ok(RegionArtifact {
            header,
            rest,
            labels,
            model,
            representation,
            train_weights,
            shape_metric: Default::default(),
        })
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
}

/// Fits region PCA (`kind = "region-pca"`): segmentation of the training displacements, one
/// PCA per region. The resolved config records the `r` used (0.1 × the rest mesh's diagonal
/// when not given).
pub fn fit(m: &RegionPcaMethod, prep: &Prepared, ctx: &mut FitContext<'_>) -> Result<Fitted> {
    ctx.progress.stage("representation", 0);
    let t_rep = Instant::now();
    let representation =
        Representation::new(RepresentationKind::Displacement, &prep.rest, RepresentationOptions::default())?;
    let x = super::training_features(&representation, prep)?;
    let representation_seconds = t_rep.elapsed().as_secs_f64();

    let sc = m.segmentation();
    let rc = m.region_pca();
    let t = Instant::now();
    ctx.progress.stage("segmentation", 0);
    let seg = segment(&prep.rest.positions, &prep.rest.faces, &x.data, x.n_frames, &sc)?;
    ctx.progress.stage("region pca", 1);
    let model = RegionPcaModel::fit(DataMatrix::from_features(&x)?, &seg.regions, &rc).map_err(method_key)?;
    let train_seconds = t.elapsed().as_secs_f64();
    ctx.progress.step(1, &format!("{} regions", seg.n_regions()));
    ctx.progress.finish_stage();
    let how = match (sc.regions, seg.searched_on) {
        (Some(k), _) => format!("the `regions` = {k} asked for"),
        (None, false) if sc.keep_searching => {
            format!("the largest compact k up to `max_regions` = {}", sc.max_regions)
        }
        (None, false) => format!("k grew until a region was not compact, at most `max_regions` = {}", sc.max_regions),
        (None, true) => format!(
            "k = 2 was not compact, so the search went on to `max_regions` = {} and kept the largest compact k",
            sc.max_regions
        ),
    };
    eprintln!("note: region-pca segmented the mesh into {} regions ({how})", seg.n_regions());
    if seg.n_regions() == 1 && sc.regions.is_none() {
        eprintln!(
            "warning: region-pca found a single region, which is holistic PCA: no k up to `max_regions` = {} gave \
             compact regions on these training frames. Set `method.regions` to a count, raise `method.max_regions`, \
             or loosen the segmentation (`method.min_piece` 0.3, `method.threshold`, `method.lambda`, `method.r`)",
            sc.max_regions
        );
    }

    let mut artifact = RegionArtifact {
        header: RegionHeader {
            method: MethodKind::RegionPca.name().into(),
            representation: RepresentationKind::Displacement.name().into(),
            unit_box: prep.unit_box,
            components: model.regions.iter().map(|r| r.n_components).collect(),
            beta: rc.beta,
            gamma: m.gamma,
            lambda: sc.lambda,
            r: seg.r,
            threshold: sc.threshold,
            train_frames: prep.train_names(),
        },
        rest: prep.rest.clone(),
        labels: seg.labels.clone(),
        model,
        representation,
        train_weights: Vec::new(),
        shape_metric: Default::default(),
    };
    let train_truth = MeshSequence {
        faces: prep.rest.faces.clone(),
        frames: super::train::frames_in_data_units(prep, &prep.train)?,
        names: Vec::new(),
    };
    artifact.train_weights = artifact.encode_frames(&train_truth)?;
    let mut resolved = m.clone();
    resolved.r = Some(seg.r);
    if resolved.regions.is_none() {
        resolved.max_regions = Some(sc.max_regions);
    }
    Ok(Fitted {
        model: Box::new(artifact),
        stats: FitStats { train_seconds, representation_seconds, iterations: 1, ..Default::default() },
        method: MethodConfig::RegionPca(resolved),
    })
}

/// Writes the rest mesh (data units) coloured by cluster, with scalar `region` = cluster index.
pub fn write_segmentation_ply(path: &Path, a: &RegionArtifact) -> Result<()> {
    let m = a.labels.iter().max().map_or(1, |&x| x + 1);
    // Spread cluster indices over the colour map; neighbours in index get distant colours.
    let spread: Vec<f64> = a.labels.iter().map(|&l| ((l * 7) % m.max(1)) as f64).collect();
    let colors = mesh::colormap_range(&spread, 0.0, (m.max(2) - 1) as f64);
    let rest = a.header.unit_box.invert_mesh(&a.rest);
    let scal: Vec<f64> = a.labels.iter().map(|&l| l as f64).collect();
    mesh::write_ply(path, &rest, Some(&colors), Some(("region", &scal)))
}

/// Control-point fit of region PCA: Eq. 9/10 with the model's β and ζ0 = 0.
struct RegionPointFit<'a> {
    artifact: &'a RegionArtifact,
    vertices: Vec<usize>,
    poser: RegionPoser<'a>,
}

impl PointFit for RegionPointFit<'_> {
    fn reconstruct(&self, shape: &[Vec3]) -> Result<Vec<Vec3>> {
        let a = self.artifact;
        let t = control_targets(&self.vertices, shape, a.header.unit_box, &a.rest.positions);
        let z = self.poser.solve(&t, &vec![0.0; a.model.n_components()])?;
        Ok(a.decode(&[z])?.remove(0))
    }
}

impl RegionArtifact {
    /// Per (region, component): the region index, the component within it, and the per-vertex
    /// norm of its basis vector (zero outside the region).
    fn basis_norms(&self) -> Vec<(usize, usize, Vec<f64>)> {
        let n = self.model.n_vertices;
        let mut out = Vec::new();
        for (i, r) in self.model.regions.iter().enumerate() {
            for p in 0..r.n_components {
                let mut norms = vec![0.0; n];
                for (l, &v) in r.vertices.iter().enumerate() {
                    norms[v] = (0..3).map(|c| r.at(p, l, c).powi(2)).sum::<f64>().sqrt();
                }
                out.push((i, p, norms));
            }
        }
        out
    }
}

impl Model for RegionArtifact {
    fn kind(&self) -> MethodKind {
        MethodKind::RegionPca
    }
    fn representation(&self) -> RepresentationKind {
        RepresentationKind::Displacement
    }
    fn rest(&self) -> TriMesh {
        self.header.unit_box.invert_mesh(&self.rest)
    }
    fn n_components(&self) -> usize {
        self.model.n_components()
    }
    fn components(&self) -> Result<Vec<Component>> {
        Ok(self
            .basis_norms()
            .into_iter()
            .enumerate()
            .map(|(k, (i, p, magnitudes))| Component {
                index: k,
                rank: k,
                name: format!("r{i:02}_c{p:02}"),
                center: argmax(&magnitudes),
                magnitudes,
            })
            .collect())
    }
    fn element_norms(&self) -> (Vec<Vec<f64>>, &[Vec<usize>]) {
        (self.basis_norms().into_iter().map(|(_, _, n)| n).collect(), self.representation.element_adjacency())
    }
    fn alignment(&self) -> Alignment {
        Alignment::None
    }
    fn train_frames(&self) -> &[String] {
        &self.header.train_frames
    }
    fn train_weights(&self) -> Option<Vec<Vec<f64>>> {
        (!self.train_weights.is_empty()).then(|| self.train_weights.clone())
    }
    fn decode(&self, weights: &[Vec<f64>]) -> Result<Vec<Vec<Vec3>>> {
        let mut rows = Vec::with_capacity(weights.len() * 3 * self.model.n_vertices);
        for z in weights {
            rows.extend(self.model.reconstruct(z)?);
        }
        self.decode_rows(&rows)
    }
    fn encode(&self, frames: &MeshSequence) -> Result<Vec<Vec<f64>>> {
        self.encode_frames(frames)
    }
    fn encoder_description(&self) -> String {
        "region weights by least squares (Eq. 6/7)".into()
    }
    fn start_weights(&self, from: Option<&[Vec3]>) -> Result<Vec<f64>> {
        match from {
            None => Ok(vec![0.0; self.model.n_components()]),
            Some(p) => Ok(self.encode_frames(&single_frame(&self.rest, p)?)?.remove(0)),
        }
    }
    fn start_description(&self) -> &'static str {
        "all coefficients 0 (the per-region training means)"
    }
    fn pose_parameters(&self) -> &'static [&'static str] {
        &["gamma", "beta"]
    }
    fn pose_defaults(&self) -> PoseOptions {
        PoseOptions::region_defaults()
    }
    fn pose(&self, vertices: &[usize], targets: &[Vec3], w0: &[f64], options: &PoseOptions) -> Result<PoseResult> {
        let start = self.decode(&[w0.to_vec()])?.remove(0);
        let t = model_targets(vertices, targets, self.header.unit_box, Some(&self.rest.positions));
        let metric = match options.prior {
            PosePrior::Shape => {
                if self.shape_metric.get().is_none() {
                    let _ = self.shape_metric.set(region_shape_metric(&self.model)?);
                }
                self.shape_metric.get()
            }
            PosePrior::Weights => None,
            PosePrior::Data => {
                return Err(Error::Invalid(
                    "`prior` data: region PCA keeps no training coefficients to measure; use shape or weights".into(),
                ));
            }
        };
        let config = PoseConfig { gamma: options.gamma, beta: options.beta };
        let weights = RegionPoser::with_metric(&self.model, vertices, &config, metric)?.solve(&t, w0)?;
        let positions = self.decode(std::slice::from_ref(&weights))?.remove(0);
        Ok(PoseResult { start, positions, weights })
    }
    /// The grown region(s) containing `v` (several when `v` is a shared boundary vertex).
    fn locality_set(&self, v: usize) -> Option<(String, Vec<usize>)> {
        let grown = self.model.memberships();
        let mine: Vec<usize> = grown.get(v)?.iter().map(|&(r, _)| r).collect();
        let set: Vec<usize> = (0..grown.len()).filter(|&u| grown[u].iter().any(|(r, _)| mine.contains(r))).collect();
        let names: Vec<String> = mine.iter().map(|r| r.to_string()).collect();
        Some((format!("region(s) {} ({} vertices)", names.join("+"), set.len()), set))
    }
    fn point_fit<'a>(&'a self, vertices: &[usize], gamma: f64) -> Result<Option<Box<dyn PointFit + 'a>>> {
        let poser = RegionPoser::new(&self.model, vertices, &PoseConfig { gamma, beta: self.header.beta })?;
        Ok(Some(Box::new(RegionPointFit { artifact: self, vertices: vertices.to_vec(), poser })))
    }
    fn save(&self, dir: &Path) -> Result<()> {
        RegionArtifact::save(self, dir)
    }
    fn write_views(&self, dir: &Path) -> Result<()> {
        write_segmentation_ply(&dir.join("segmentation.ply"), self)
    }
    fn write_components(&self, dir: &Path) -> Result<()> {
        crate::model::write_component_meshes(self, dir)?;
        crate::model::write_components_csv(self, dir)?;
        write_segmentation_ply(&dir.join("segmentation.ply"), self)
    }
}
