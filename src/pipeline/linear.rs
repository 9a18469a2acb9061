//! Linear models (holistic PCA, SPLOCS on displacements or triangle gradients): training from a
//! config, the artefact directory, reloading, encoding new frames and synthesis.
//!
//! A linear model reconstructs the representation's features of a frame as
//! `x ≈ offset + Σ_k w_k C_k` and decodes them to vertex positions with the representation
//! bound to the stored rest mesh. All positions that leave this module are in the data's own
//! units (the unit-box scaling, if any, is undone).

use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::geodesic_support::GeodesicSupport;
use super::pose::{control_targets, model_targets};
use super::registry::{FitContext, FitStats, Fitted};
use crate::artifact::{self, ArrayStore};
use crate::config::{ConsistencyName, MethodConfig, MethodKind, PcaMethod, SplocsMethod, method_key};
use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, TriMesh, Vec3};
use crate::methods::pca::{Pca, PcaConfig, RandomizedSvd};
use crate::methods::posing::{LinearPoser, PoseConfig, data_metric, linear_mean_response, linear_shape_metric};
use crate::methods::splocs::SplocsSolver;
use crate::methods::support_map::{
    ComponentLocality, SupportDistances, TriangleSupport, component_locality, support_ramp,
};
use crate::methods::{DataMatrix, DataRef, LinearModel, WeightConstraint};
use crate::model::{Component, Model, PointFit, PoseOptions, PosePrior, PoseResult, argmax};
use crate::preprocess::{Prepared, UnitBox};
use crate::representation::acap::Consistency;
use crate::representation::roundtrip::Alignment;
use crate::representation::{Element, Features, Representation, RepresentationKind, RepresentationOptions};

pub use crate::config::SPLOCS_GEODESIC_M;

/// Header of a linear model's `model.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LinearHeader {
    /// `pca` or `splocs`.
    pub method: String,
    /// Representation name (`displacement`, `triangle-gradient`, `acap`).
    pub representation: String,
    /// ACAP rotation consistency used (`bfs` or `global`), if the representation is acap.
    pub consistency: Option<String>,
    /// Scaling applied to the data before encoding (identity unless `data.unit_box`).
    pub unit_box: UnitBox,
    /// Number of components K.
    pub components: usize,
    /// Weight constraint the model honours when encoding.
    pub constraint: WeightConstraint,
    /// Names of the training frames (rows of `weights`).
    pub train_frames: Vec<String>,
}

/// A trained linear model, ready to encode, reconstruct and synthesize.
pub struct LinearArtifact {
    pub header: LinearHeader,
    /// Rest mesh in the model's (possibly unit-box) space.
    pub rest: TriMesh,
    pub model: LinearModel,
    pub representation: Representation,
    /// The posing shape metric ([`crate::methods::posing::linear_shape_metric`]), computed on
    /// the first pose.
    pub shape_metric: std::sync::OnceLock<faer::Mat<f64>>,
    /// The posing data metric ([`crate::methods::posing::data_metric`]), computed on the first
    /// pose with [`PosePrior::Data`].
    pub data_metric: std::sync::OnceLock<faer::Mat<f64>>,
}

fn parse_consistency(s: Option<&str>) -> Consistency {
    match s {
        Some("bfs") => Consistency::Bfs,
        _ => Consistency::Global,
    }
}

impl LinearArtifact {
    /// Loads `<dir>/model.json` + `model.bin` and rebuilds the representation.
    pub fn load(dir: &Path) -> Result<Self> {
        let (header, arrays): (LinearHeader, ArrayStore) = artifact::load_model(dir)?;
        let rest = rest_from_arrays(&arrays)?;
        let kind = RepresentationKind::parse(&header.representation).ok_or_else(|| {
            Error::Invalid(format!("{}: unknown representation `{}`", dir.display(), header.representation))
        })?;
        let options = RepresentationOptions {
            acap_consistency: parse_consistency(header.consistency.as_deref()),
            ..Default::default()
        };
        let representation = Representation::new(kind, &rest, options)?;
        let e = representation.n_elements();
        let w = representation.width();
        let k = header.components;
        let f = header.train_frames.len();
        let json = artifact::model_dir(dir).join("model.json");
        if k == 0 || k > e * w {
            return Err(Error::parse(
                &json,
                None,
                format!("`components` is {k}; a model on {e} elements of {w} numbers has 1 to {}", e * w),
            ));
        }
        header.unit_box.validate().map_err(|m| Error::parse(&json, None, format!("`unit_box`: {m}")))?;
        let model = LinearModel {
            n_elements: e,
            width: w,
            n_components: k,
            n_frames: f,
            components: arrays.get_shaped("components", &[k, e * w])?.to_vec(),
            weights: arrays.get_shaped("weights", &[f, k])?.to_vec(),
            offset: arrays.get_shaped("offset", &[e * w])?.to_vec(),
            constraint: header.constraint,
        };
        model.validate()?;
        Ok(LinearArtifact {
            header,
            rest,
            model,
            representation,
            shape_metric: Default::default(),
            data_metric: Default::default(),
        })
    }

    /// Saves the model into `dir` (model.json + model.bin).
    pub fn save(&self, dir: &Path) -> Result<()> {
        let mut a = ArrayStore::new();
        rest_to_arrays(&self.rest, &mut a)?;
        let m = &self.model;
        a.insert("components", vec![m.n_components, m.n_cols()], m.components.clone())?;
        a.insert("weights", vec![m.n_frames, m.n_components], m.weights.clone())?;
        a.insert("offset", vec![m.n_cols()], m.offset.clone())?;
        artifact::save_model(dir, &self.header, &a)
    }

    /// Decodes feature rows (`n` × E·W) to vertex positions in data units.
    pub fn decode_rows(&self, rows: &[f64]) -> Result<Vec<Vec<Vec3>>> {
        let n = rows.len() / self.model.n_cols().max(1);
        let feats =
            Features { n_frames: n, n_elements: self.model.n_elements, width: self.model.width, data: rows.to_vec() };
        let mut frames = self.representation.decode(&feats)?;
        for p in frames.iter_mut().flatten() {
            *p = self.header.unit_box.invert(*p);
        }
        Ok(frames)
    }

    /// Least-squares weights (honouring the model's constraint) of frames given in data units.
    pub fn encode_frames(&self, frames: &MeshSequence) -> Result<Vec<f64>> {
        let mut scaled = frames.clone();
        for p in scaled.frames.iter_mut().flatten() {
            *p = self.header.unit_box.apply(*p);
        }
        let mut x = self.representation.encode(&scaled)?;
        // SPLOCS on a multi-piece mesh: the least squares its fit minimised (the pieces'
        // translation columns weighted, `PIECE_TRANSLATION_WEIGHT`).
        let columns = if self.header.method == MethodKind::Splocs.name() {
            piece_translation_columns(&self.representation)
        } else {
            Vec::new()
        };
        if columns.is_empty() {
            return self.model.encoder()?.encode_rows(&x.data);
        }
        let mut weighted = self.model.clone();
        scale_model(&mut weighted, &columns, false);
        scale_rows(&mut x.data, weighted.n_cols(), &columns, false);
        weighted.encoder()?.encode_rows(&x.data)
    }

    /// Positions (data units) for a weight vector (K numbers).
    pub fn synthesize(&self, weights: &[f64]) -> Result<Vec<Vec3>> {
        let row = self.model.synthesize(weights)?;
        Ok(self.decode_rows(&row)?.remove(0))
    }

    /// How Erms is aligned for this model's representation.
    pub fn alignment(&self) -> Alignment {
        if self.representation.translation_free() { Alignment::Centroid } else { Alignment::None }
    }
}

/// Stores the rest mesh as `rest_positions` (N × 3) and `faces` (T × 3, as f64).
pub fn rest_to_arrays(rest: &TriMesh, a: &mut ArrayStore) -> Result<()> {
    a.insert("rest_positions", vec![rest.n_vertices(), 3], rest.positions.iter().flatten().copied().collect())?;
    a.insert("faces", vec![rest.n_faces(), 3], rest.faces.iter().flatten().map(|&i| i as f64).collect())
}

/// Inverse of [`rest_to_arrays`], validating the face indices.
pub fn rest_from_arrays(a: &ArrayStore) -> Result<TriMesh> {
    let (ps, p) = a.get("rest_positions")?;
    let (fs, f) = a.get("faces")?;
    if ps.len() != 2 || ps[1] != 3 || fs.len() != 2 || fs[1] != 3 {
        return Err(Error::Invalid(format!(
            "model rest mesh arrays have shapes {ps:?} and {fs:?}, expected N×3 and T×3"
        )));
    }
    if ps[0] < 3 || fs[0] == 0 {
        return Err(Error::Invalid(format!(
            "model rest mesh has {} vertices and {} faces; a mesh needs at least 3 and 1",
            ps[0], fs[0]
        )));
    }
    let positions: Vec<Vec3> = p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let faces = index_array("faces", f, ps[0])?;
    let faces: Vec<[usize; 3]> = faces.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let rest = TriMesh::new(positions, faces);
    if let Some((i, face)) = rest.first_bad_index() {
        return Err(Error::Invalid(format!("model rest mesh face {i} {face:?} refers to a missing vertex")));
    }
    Ok(rest)
}

/// The indices stored (as f64) in model array `name`: each must be a whole number in
/// `0..bound`, else the error names the array, the element and the value.
pub fn index_array(name: &str, values: &[f64], bound: usize) -> Result<Vec<usize>> {
    values
        .iter()
        .enumerate()
        .map(|(i, &x)| {
            if x.fract() == 0.0 && x >= 0.0 && x < bound as f64 {
                Ok(x as usize)
            } else {
                Err(Error::Invalid(format!(
                    "model.bin: array `{name}`: element {i} is {x}, not an index in 0..{bound}"
                )))
            }
        })
        .collect()
}

/// The representation bound to the prepared rest mesh.
fn representation_of(
    kind: RepresentationKind,
    consistency: ConsistencyName,
    prep: &Prepared,
) -> Result<Representation> {
    let options = RepresentationOptions { acap_consistency: consistency.to_acap(), ..Default::default() };
    Representation::new(kind, &prep.rest, options)
}

/// The rest shape's own features (one row): SPLOCS models deformations from the rest shape
/// (zero for displacements and triangle gradients; logR = 0, S = I for ACAP), so they are
/// subtracted from every training row and become the model's offset.
fn rest_features(representation: &Representation, prep: &Prepared) -> Result<Vec<f64>> {
    let rest_seq =
        MeshSequence { faces: prep.rest.faces.clone(), frames: vec![prep.rest.positions.clone()], names: Vec::new() };
    Ok(representation.encode(&rest_seq)?.data)
}

/// Whether the training features of `representation` take more than
/// `prep.limits.compact_bytes` in `f64`: PCA and SPLOCS then hold them in `f32`.
fn compact(representation: &Representation, prep: &Prepared) -> bool {
    let bytes = prep.train.len() as u64 * (representation.n_elements() * representation.width()) as u64 * 8;
    bytes > prep.limits.compact_bytes
}

fn artifact_of(
    kind: MethodKind,
    representation: Representation,
    consistency: ConsistencyName,
    prep: &Prepared,
    model: LinearModel,
) -> LinearArtifact {
    let rk = representation.kind();
    LinearArtifact {
        header: LinearHeader {
            method: kind.name().to_string(),
            representation: rk.name().to_string(),
            consistency: (rk == RepresentationKind::Acap).then(|| consistency.name().to_string()),
            unit_box: prep.unit_box,
            components: model.n_components,
            constraint: model.constraint,
            train_frames: prep.train_names(),
        },
        rest: prep.rest.clone(),
        model,
        representation,
        shape_metric: Default::default(),
        data_metric: Default::default(),
    }
}

/// Fits holistic PCA (`kind = "pca"`).
pub fn fit_pca(m: &PcaMethod, prep: &Prepared, ctx: &mut FitContext<'_>) -> Result<Fitted> {
    let pc = PcaConfig { components: m.components, ..Default::default() };
    let t = Instant::now();
    let representation = representation_of(m.representation, m.consistency, prep)?;
    let (model, representation_seconds, train_seconds) = if compact(&representation, prep) {
        // Large data: the features in f32, a randomized SVD streamed over them.
        ctx.progress.stage("representation", prep.train.len() as u64);
        let progress = &mut *ctx.progress;
        let x = super::training_features_f32(&representation, prep, &|_| {}, &mut |done| {
            progress.step(done as u64, "frames")
        })?;
        let representation_seconds = t.elapsed().as_secs_f64();
        ctx.progress.stage(MethodKind::Pca.name(), 1);
        let t = Instant::now();
        let model = Pca::fit_randomized(DataRef::F32(&x), &pc, &RandomizedSvd::default()).map_err(method_key)?;
        (model, representation_seconds, t.elapsed().as_secs_f64())
    } else {
        ctx.progress.stage("representation", 0);
        let x = super::training_features(&representation, prep)?;
        let representation_seconds = t.elapsed().as_secs_f64();
        ctx.progress.stage(MethodKind::Pca.name(), 1);
        let t = Instant::now();
        let model = Pca::fit(DataMatrix::from_features(&x)?, &pc).map_err(method_key)?;
        (model, representation_seconds, t.elapsed().as_secs_f64())
    };
    ctx.progress.step(1, "done");
    ctx.progress.finish_stage();
    let locality = measure_locality(&model, &representation, &prep.rest, [0.1, 0.7])?;
    let artifact = artifact_of(MethodKind::Pca, representation, m.consistency, prep, model);
    Ok(Fitted {
        model: Box::new(artifact),
        stats: FitStats { train_seconds, representation_seconds, iterations: 1, locality, ..Default::default() },
        method: MethodConfig::Pca(m.clone()),
    })
}

/// Largest weight of a piece's translation columns in SPLOCS's data matrix (translation-free
/// representations of a mesh in several pieces, issue 32). A piece's translation `t_p` is in
/// units of the rest bounding-box diagonal, so an error of ε in it moves the piece by ε times the
/// whole model's size, while the same error in a small piece's gradient features moves its
/// vertices by about ε times the piece's own size: SPLOCS's least squares on features found a
/// small part's position far cheaper to get wrong than its shape. Piece p's three columns are
/// weighted by ρ_a / ρ_p (ρ: RMS distance of a piece's rest vertices from their centroid, a the
/// anchor piece), clamped to [1, this]; pieces as large as the anchor keep weight 1 (the
/// two-tube set of issue 15 is unchanged). The fit and the encoder minimise the same weighted
/// least squares; the components are stored in the representation's units. The cap was chosen
/// on the training frames of `synthetic:pieces:40` (rigidly aligned, K 30, every piece at one
/// uniform weight): train Erms at weight 1 / 10 / 30, triangle gradients 5.84 / 3.60 / 6.26,
/// ACAP 6.37 / 3.97 / 7.27 (rest shape 42.30).
pub const PIECE_TRANSLATION_WEIGHT: f64 = 10.0;

/// (column, weight) of one data-matrix row (E·W numbers) for the pieces' translation columns
/// weighted above 1 ([`PIECE_TRANSLATION_WEIGHT`]); empty without pieces.
fn piece_translation_columns(representation: &Representation) -> Vec<(usize, f64)> {
    let Some((placement, element_piece)) = representation.pieces() else {
        return Vec::new();
    };
    let rho = placement.rms_radii(&representation.rest().positions);
    let weight: Vec<f64> = rho
        .iter()
        .map(|&r| {
            if r > 0.0 {
                (rho[placement.anchor()] / r).clamp(1.0, PIECE_TRANSLATION_WEIGHT)
            } else {
                PIECE_TRANSLATION_WEIGHT
            }
        })
        .collect();
    let (w0, w) = (representation.kind().width(), representation.width());
    element_piece
        .iter()
        .enumerate()
        .filter(|&(_, &p)| p != usize::MAX && weight[p] > 1.0)
        .flat_map(|(e, &p)| {
            let wp = weight[p];
            (w0..w).map(move |k| (e * w + k, wp))
        })
        .collect()
}

/// Multiplies (`invert`: divides) the (column, weight) entries of every row of the row-major
/// `rows` (rows of `n_cols` numbers).
fn scale_rows(rows: &mut [f64], n_cols: usize, columns: &[(usize, f64)], invert: bool) {
    for row in rows.chunks_exact_mut(n_cols) {
        for &(c, w) in columns {
            if invert { row[c] /= w } else { row[c] *= w }
        }
    }
}

/// [`scale_rows`] on a linear model's components and offset (its weights are unchanged).
fn scale_model(model: &mut LinearModel, columns: &[(usize, f64)], invert: bool) {
    let n_cols = model.n_cols();
    scale_rows(&mut model.components, n_cols, columns, invert);
    scale_rows(&mut model.offset, n_cols, columns, invert);
}

/// SPLOCS's training features, in the precision they are held in.
enum Held {
    F64(Features),
    F32(crate::methods::CompactMatrix),
}

/// Fits SPLOCS (`kind = "splocs"`) on the configured representation.
pub fn fit_splocs(m: &SplocsMethod, prep: &Prepared, ctx: &mut FitContext<'_>) -> Result<Fitted> {
    let t = Instant::now();
    let representation = representation_of(m.representation, m.consistency, prep)?;
    let translation_columns = piece_translation_columns(&representation);
    let n_cols = representation.n_elements() * representation.width();
    // Every row: the rest row subtracted, the pieces' translation columns weighted (in f64).
    let rest = rest_features(&representation, prep)?;
    let transform = |row: &mut [f64]| {
        row.iter_mut().zip(&rest).for_each(|(v, o)| *v -= o);
        scale_rows(row, n_cols, &translation_columns, false);
    };
    // Large data: the features in f32; otherwise in f64, the exact path.
    let held = if compact(&representation, prep) {
        ctx.progress.stage("representation", prep.train.len() as u64);
        let progress = &mut *ctx.progress;
        Held::F32(super::training_features_f32(&representation, prep, &transform, &mut |done| {
            progress.step(done as u64, "frames")
        })?)
    } else {
        ctx.progress.stage("representation", 0);
        let mut x = super::training_features(&representation, prep)?;
        x.data.chunks_exact_mut(n_cols).for_each(transform);
        Held::F64(x)
    };
    let representation_seconds = t.elapsed().as_secs_f64();
    let data = match &held {
        Held::F64(x) => DataRef::F64(DataMatrix::from_features(x)?),
        Held::F32(x) => DataRef::F32(x),
    };
    let sc = m.solver_config()?;
    sc.validate().map_err(method_key)?;
    // The timer includes the heat-method factorisation of the support maps.
    let t = Instant::now();
    ctx.progress.stage("geodesics", 0);
    let vertex_support = GeodesicSupport::unit_box(&prep.rest, m.geodesic_m)?;
    ctx.progress.stage(MethodKind::Splocs.name(), sc.max_iterations as u64 + 1);
    let progress = &mut *ctx.progress;
    let mut report = |i: usize, e: f64| progress.step(i as u64 + 1, &format!("objective {e:.6e}"));
    let fit = match representation.element() {
        Element::Vertex => SplocsSolver::fit(data, &vertex_support, &sc, &mut report)?,
        Element::Triangle => {
            let tri = TriangleSupport::new(&vertex_support, &prep.rest.faces)?;
            SplocsSolver::fit(data, &tri, &sc, &mut report)?
        }
    };
    let train_seconds = t.elapsed().as_secs_f64();
    ctx.progress.finish_stage();
    let mut model = fit.model;
    // Back to the representation's units (the weights W are unchanged).
    scale_model(&mut model, &translation_columns, true);
    model.offset = rest;
    let artifact = artifact_of(MethodKind::Splocs, representation, m.consistency, prep, model);
    Ok(Fitted {
        model: Box::new(artifact),
        stats: FitStats {
            train_seconds,
            representation_seconds,
            iterations: fit.iterations,
            objective: fit.objective_history.last().copied(),
            converged: Some(fit.converged),
            locality: fit.locality,
            refine_test: false,
            feature_norm: None,
            warning: None,
            training_gain: None,
            dial_readouts: Vec::new(),
        },
        method: MethodConfig::Splocs(m.clone()),
    })
}

/// Locality of arbitrary linear components (e.g. PCA): centre = the element of largest group
/// norm, support region from unit-box geodesics with `support` = [d_min, d_max].
pub fn measure_locality(
    model: &LinearModel,
    rep: &Representation,
    rest: &TriMesh,
    support: [f64; 2],
) -> Result<Vec<ComponentLocality>> {
    let vertex_support = GeodesicSupport::unit_box(rest, SPLOCS_GEODESIC_M)?;
    let norms: Vec<Vec<f64>> = (0..model.n_components).map(|k| model.component_group_norms(k)).collect();
    let centers: Vec<Vec<usize>> = norms
        .iter()
        .map(|n| vec![n.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i).unwrap_or(0)])
        .collect();
    let dists = match rep.element() {
        Element::Vertex => vertex_support.distances_many(&centers)?,
        Element::Triangle => TriangleSupport::new(&vertex_support, &rest.faces)?.distances_many(&centers)?,
    };
    Ok(norms
        .iter()
        .zip(&centers)
        .zip(&dists)
        .map(|((n, c), d)| {
            let ramp: Vec<f64> = d.iter().map(|&x| support_ramp(x, support[0], support[1])).collect();
            component_locality(c[0], n, &ramp)
        })
        .collect())
}

/// Per-vertex magnitude of a component: group norm per vertex, or for triangle elements the
/// mean over a vertex's incident triangles.
pub fn vertex_magnitudes(model: &LinearModel, k: usize, element: Element, rest: &TriMesh) -> Vec<f64> {
    let norms = model.component_group_norms(k);
    match element {
        Element::Vertex => norms,
        Element::Triangle => {
            let mut sum = vec![0.0; rest.n_vertices()];
            let mut count = vec![0usize; rest.n_vertices()];
            for (t, f) in rest.faces.iter().enumerate() {
                for &v in f {
                    sum[v] += norms[t];
                    count[v] += 1;
                }
            }
            sum.iter().zip(&count).map(|(s, &c)| if c > 0 { s / c as f64 } else { 0.0 }).collect()
        }
    }
}

impl LinearArtifact {
    /// Whether posing and control points apply (per-vertex displacement models only).
    fn per_vertex(&self) -> bool {
        self.representation.kind() == RepresentationKind::Displacement
    }
}

/// Control-point fit of a displacement model: Lewis–Anjyo with w0 = 0 (see
/// `eval::control_points`).
struct LinearPointFit<'a> {
    artifact: &'a LinearArtifact,
    vertices: Vec<usize>,
    poser: LinearPoser<'a>,
}

impl PointFit for LinearPointFit<'_> {
    fn reconstruct(&self, shape: &[Vec3]) -> Result<Vec<Vec3>> {
        let a = self.artifact;
        let t = control_targets(&self.vertices, shape, a.header.unit_box, &a.rest.positions);
        let w = self.poser.solve(&t, &vec![0.0; a.model.n_components])?;
        a.synthesize(&w)
    }
}

impl Model for LinearArtifact {
    fn kind(&self) -> MethodKind {
        if self.header.method == MethodKind::Pca.name() { MethodKind::Pca } else { MethodKind::Splocs }
    }
    fn representation(&self) -> RepresentationKind {
        self.representation.kind()
    }
    fn rest(&self) -> TriMesh {
        self.header.unit_box.invert_mesh(&self.rest)
    }
    fn n_components(&self) -> usize {
        self.model.n_components
    }
    fn components(&self) -> Result<Vec<Component>> {
        let width = (self.model.n_components.max(1) - 1).to_string().len().max(2);
        Ok((0..self.model.n_components)
            .map(|k| {
                let magnitudes = vertex_magnitudes(&self.model, k, self.representation.element(), &self.rest);
                Component { index: k, rank: k, name: format!("k{k:0width$}"), center: argmax(&magnitudes), magnitudes }
            })
            .collect())
    }
    fn element_norms(&self) -> (Vec<Vec<f64>>, &[Vec<usize>]) {
        (
            (0..self.model.n_components).map(|k| self.model.component_group_norms(k)).collect(),
            self.representation.element_adjacency(),
        )
    }
    fn alignment(&self) -> Alignment {
        LinearArtifact::alignment(self)
    }
    fn train_frames(&self) -> &[String] {
        &self.header.train_frames
    }
    fn train_weights(&self) -> Option<Vec<Vec<f64>>> {
        Some(self.model.weights.chunks_exact(self.model.n_components.max(1)).map(<[f64]>::to_vec).collect())
    }
    fn decode(&self, weights: &[Vec<f64>]) -> Result<Vec<Vec<Vec3>>> {
        let mut rows = Vec::with_capacity(weights.len() * self.model.n_cols());
        for w in weights {
            rows.extend(self.model.synthesize(w)?);
        }
        self.decode_rows(&rows)
    }
    fn encode(&self, frames: &MeshSequence) -> Result<Vec<Vec<f64>>> {
        let w = self.encode_frames(frames)?;
        Ok(w.chunks_exact(self.model.n_components.max(1)).map(<[f64]>::to_vec).collect())
    }
    fn start_weights(&self, from: Option<&[Vec3]>) -> Result<Vec<f64>> {
        match from {
            None => Ok(vec![0.0; self.model.n_components]),
            Some(p) => Ok(Model::encode(self, &super::pose::single_frame(&self.rest, p)?)?.remove(0)),
        }
    }
    fn start_description(&self) -> &'static str {
        "all weights 0 (the model's offset: the training mean for PCA, the rest shape for SPLOCS)"
    }
    fn pose_defaults(&self) -> PoseOptions {
        PoseOptions::linear_defaults()
    }
    fn pose(&self, vertices: &[usize], targets: &[Vec3], w0: &[f64], options: &PoseOptions) -> Result<PoseResult> {
        if !self.per_vertex() {
            return Err(Error::Invalid(format!(
                "posing a `{}` model on the `{}` representation is not supported: only displacement models \
                 are posed per vertex (Eq. 8); train with representation = \"displacement\"",
                self.header.method,
                self.representation.kind().name()
            )));
        }
        let start = self.synthesize(w0)?;
        let t = model_targets(vertices, targets, self.header.unit_box, Some(&self.rest.positions));
        let metric = match options.prior {
            PosePrior::Shape => Some(self.shape_metric.get_or_init(|| linear_shape_metric(&self.model))),
            PosePrior::Weights => None,
            PosePrior::Data => {
                if self.data_metric.get().is_none() {
                    let m =
                        data_metric(&self.model.weights, self.model.n_components, linear_mean_response(&self.model))?;
                    let _ = self.data_metric.set(m);
                }
                self.data_metric.get()
            }
        };
        let config = PoseConfig { gamma: options.gamma, beta: options.beta };
        let weights = LinearPoser::with_metric(&self.model, vertices, &config, metric)?.solve(&t, w0)?;
        let positions = self.synthesize(&weights)?;
        Ok(PoseResult { start, positions, weights })
    }
    /// The support of the component with the largest magnitude at `v` (vertices above 10⁻³ of
    /// that component's largest magnitude).
    fn locality_set(&self, v: usize) -> Option<(String, Vec<usize>)> {
        let m = &self.model;
        if m.width != 3 || v >= m.n_elements {
            return None;
        }
        let k = (0..m.n_components)
            .max_by(|&p, &q| m.component_group_norms(p)[v].total_cmp(&m.component_group_norms(q)[v]))?;
        let norms = m.component_group_norms(k);
        let top = norms.iter().cloned().fold(0.0, f64::max);
        let set: Vec<usize> = (0..m.n_elements).filter(|&u| norms[u] > 1e-3 * top).collect();
        Some((format!("support of component {k} ({} vertices)", set.len()), set))
    }
    fn point_fit<'a>(&'a self, vertices: &[usize], gamma: f64) -> Result<Option<Box<dyn PointFit + 'a>>> {
        if !self.per_vertex() {
            return Ok(None);
        }
        let poser = LinearPoser::new(&self.model, vertices, &PoseConfig { gamma, beta: 0.0 })?;
        Ok(Some(Box::new(LinearPointFit { artifact: self, vertices: vertices.to_vec(), poser })))
    }
    fn save(&self, dir: &Path) -> Result<()> {
        LinearArtifact::save(self, dir)
    }
    fn write_views(&self, dir: &Path) -> Result<()> {
        crate::model::write_component_meshes(self, &dir.join("components"))
    }
    fn write_components(&self, dir: &Path) -> Result<()> {
        crate::model::write_component_meshes(self, dir)?;
        crate::model::write_components_csv(self, dir)
    }
}
