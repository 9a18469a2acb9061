//! Linear models (holistic PCA, SPLOCS on displacements or triangle gradients): training from a
//! config, the artefact directory, reloading, encoding new frames and synthesis.
//!
//! A linear model reconstructs the representation's features of a frame as
//! `x ≈ offset + Σ_k w_k C_k` and decodes them to vertex positions with the representation
//! bound to the stored rest mesh. All positions that leave this module are in the data's own
//! units (the unit-box scaling, if any, is undone).

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::Progress;
use super::geodesic_support::GeodesicSupport;
use super::metrics_file::{Metrics, median};
use crate::artifact::{self, ArrayStore};
use crate::config::{Config, MethodKind, resolved_toml};
use crate::error::{Error, Result};
use crate::mesh::{self, MeshSequence, TriMesh, Vec3};
use crate::methods::pca::{Pca, PcaConfig};
use crate::methods::splocs::{AdmmConfig, SplocsConfig, SplocsSolver};
use crate::methods::support_map::{
    ComponentLocality, SupportDistances, TriangleSupport, component_locality, support_ramp,
};
use crate::methods::{DataMatrix, LinearModel, WeightConstraint};
use crate::preprocess::{self, UnitBox};
use crate::representation::acap::Consistency;
use crate::representation::roundtrip::{Alignment, erms};
use crate::representation::{Element, Features, Representation, RepresentationKind, RepresentationOptions};

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
        Ok(LinearArtifact { header, rest, model, representation })
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
        let x = self.representation.encode(&scaled)?;
        self.model.encoder()?.encode_rows(&x.data)
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
    let positions: Vec<Vec3> = p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let faces: Vec<[usize; 3]> = f.chunks_exact(3).map(|c| [c[0] as usize, c[1] as usize, c[2] as usize]).collect();
    let rest = TriMesh::new(positions, faces);
    if let Some((i, face)) = rest.first_bad_index() {
        return Err(Error::Invalid(format!("model rest mesh face {i} {face:?} refers to a missing vertex")));
    }
    Ok(rest)
}

/// Builds the SPLOCS hyperparameters from a validated config (defaults: the reference's).
pub fn splocs_config(cfg: &Config) -> Result<SplocsConfig> {
    let m = &cfg.method;
    let d = SplocsConfig::default();
    let fixed_centers = match &m.fixed_centers {
        None => Vec::new(),
        Some(list) => list.iter().map(read_fixed_center).collect::<Result<Vec<_>>>()?,
    };
    let c = SplocsConfig {
        components: m.components.unwrap_or(d.components),
        sparsity: m.sparsity.unwrap_or(d.sparsity),
        support: m.support.unwrap_or(d.support),
        weights: match m.weights.as_deref() {
            Some(w) => WeightConstraint::parse(w).ok_or_else(|| Error::config("method.weights", format!("`{w}`")))?,
            None => d.weights,
        },
        max_iterations: m.max_iterations.unwrap_or(d.max_iterations),
        admm: m.admm.map(|a| AdmmConfig { rho: a.rho, iterations: a.iterations }).unwrap_or(d.admm),
        tolerance: m.tolerance.unwrap_or(d.tolerance),
        seed: m.seed.unwrap_or(d.seed),
        fixed_centers,
        threads: 0,
    };
    c.validate().map_err(|e| match e {
        Error::Config { key, message } => Error::config(format!("method.{key}"), message),
        other => other,
    })?;
    Ok(c)
}

fn read_fixed_center(c: &crate::config::FixedCenter) -> Result<Vec<usize>> {
    match c {
        crate::config::FixedCenter::Vertices(v) => Ok(v.clone()),
        crate::config::FixedCenter::File(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| Error::io(p, e))?;
            text.split(|ch: char| ch.is_whitespace() || ch == ',')
                .filter(|t| !t.is_empty())
                .enumerate()
                .map(|(i, t)| {
                    t.parse::<usize>()
                        .map_err(|_| Error::parse(p, None, format!("entry {} (`{t}`) is not a vertex index", i + 1)))
                })
                .collect()
        }
    }
}

/// Default heat-method factor for SPLOCS support maps (the reference's m = 10).
pub const SPLOCS_GEODESIC_M: f64 = 10.0;

/// Result of training: where the artefacts are and the measured metrics.
pub struct TrainOutcome {
    pub out_dir: PathBuf,
    pub metrics: Metrics,
}

/// Trains `pca` or `splocs` as configured and writes the artefact directory `out`.
pub fn train(cfg: &Config, out: &Path, progress: &mut dyn Progress) -> Result<TrainOutcome> {
    if !matches!(cfg.kind, MethodKind::Pca | MethodKind::Splocs) {
        return Err(Error::Invalid(format!("linear::train does not handle kind = \"{}\"", cfg.kind.name())));
    }
    progress.stage("loading", 0);
    let prep = preprocess::prepare(&cfg.data)?;
    let kind_name = cfg.method.representation.as_deref().unwrap_or("displacement");
    let kind = RepresentationKind::parse(kind_name)
        .ok_or_else(|| Error::config("method.representation", format!("`{kind_name}`")))?;
    let consistency = cfg.method.consistency.as_deref();
    let options = RepresentationOptions { acap_consistency: parse_consistency(consistency), ..Default::default() };
    let train_seq = prep.train_sequence();

    progress.stage("representation", 0);
    let t_rep = Instant::now();
    let representation = Representation::new(kind, &prep.rest, options)?;
    let mut x = representation.encode(&train_seq)?;
    // SPLOCS models deformations from the rest shape (offset zero): subtract the rest shape's
    // own features (zero for displacements and triangle gradients; logR = 0, S = I for ACAP)
    // and keep them as the model's offset.
    let rest_row = if cfg.kind == MethodKind::Splocs {
        let rest_seq = MeshSequence {
            faces: prep.rest.faces.clone(),
            frames: vec![prep.rest.positions.clone()],
            names: Vec::new(),
        };
        let r = representation.encode(&rest_seq)?.data;
        for row in x.data.chunks_exact_mut(r.len()) {
            row.iter_mut().zip(&r).for_each(|(v, o)| *v -= o);
        }
        Some(r)
    } else {
        None
    };
    let representation_seconds = t_rep.elapsed().as_secs_f64();
    let data = DataMatrix::from_features(&x)?;

    let (model, method_table, iterations, objective, converged, locality, train_seconds);
    match cfg.kind {
        MethodKind::Pca => {
            let pc = PcaConfig { components: cfg.method.components.unwrap_or(50), ..Default::default() };
            progress.stage("pca", 1);
            let t = Instant::now();
            model = Pca::fit(data, &pc).map_err(|e| prefix_components(e, cfg))?;
            train_seconds = t.elapsed().as_secs_f64();
            progress.step(1, "done");
            let mut tbl = toml::Table::try_from(&pc).map_err(|e| Error::Invalid(e.to_string()))?;
            tbl.insert("kind".into(), "pca".into());
            tbl.insert("representation".into(), kind.name().into());
            method_table = tbl;
            iterations = 1;
            objective = None;
            converged = None;
            locality = measure_locality(&model, &representation, &prep.rest, [0.1, 0.7])?;
        }
        MethodKind::Splocs => {
            let sc = splocs_config(cfg)?;
            let m = cfg.method.geodesic_m.unwrap_or(SPLOCS_GEODESIC_M);
            // The timer includes the heat-method factorisation of the support maps.
            let t = Instant::now();
            progress.stage("geodesics", 0);
            let vertex_support = GeodesicSupport::unit_box(&prep.rest, m)?;
            progress.stage("splocs", sc.max_iterations as u64 + 1);
            let mut report = |i: usize, e: f64| progress.step(i as u64 + 1, &format!("objective {e:.6e}"));
            let fit = match representation.element() {
                Element::Vertex => SplocsSolver::fit(data, &vertex_support, &sc, &mut report)?,
                Element::Triangle => {
                    let tri = TriangleSupport::new(&vertex_support, &prep.rest.faces)?;
                    SplocsSolver::fit(data, &tri, &sc, &mut report)?
                }
            };
            train_seconds = t.elapsed().as_secs_f64();
            let mut tbl = toml::Table::try_from(&sc).map_err(|e| Error::Invalid(e.to_string()))?;
            tbl.remove("threads");
            tbl.insert("kind".into(), "splocs".into());
            tbl.insert("representation".into(), kind.name().into());
            tbl.insert("geodesic_m".into(), m.into());
            method_table = tbl;
            iterations = fit.iterations;
            objective = fit.objective_history.last().copied();
            converged = Some(fit.converged);
            locality = fit.locality.clone();
            model = {
                let mut m = fit.model;
                if let Some(r) = rest_row {
                    m.offset = r;
                }
                m
            };
        }
        _ => unreachable!("checked above"),
    }
    progress.finish_stage();

    let artifact = LinearArtifact {
        header: LinearHeader {
            method: cfg.kind.name().to_string(),
            representation: kind.name().to_string(),
            consistency: (kind == RepresentationKind::Acap).then(|| consistency.unwrap_or("global").to_string()),
            unit_box: prep.unit_box,
            components: model.n_components,
            constraint: model.constraint,
            train_frames: train_seq.names.clone(),
        },
        rest: prep.rest.clone(),
        model,
        representation,
    };

    progress.stage("measuring", 0);
    let alignment = artifact.alignment();
    let truth = |idx: &[usize]| -> Vec<Vec<Vec3>> {
        idx.iter().map(|&f| prep.sequence.frames[f].iter().map(|p| prep.unit_box.invert(*p)).collect()).collect()
    };
    let train_rec = artifact.decode_rows(&artifact.model.reconstruct()?)?;
    let train_erms = erms(&truth(&prep.train), &train_rec, alignment)?;
    let test_erms = if prep.test.is_empty() {
        None
    } else {
        let test_seq =
            MeshSequence { faces: prep.sequence.faces.clone(), frames: truth(&prep.test), names: Vec::new() };
        let w = artifact.encode_frames(&test_seq)?;
        let k = artifact.model.n_components;
        let mut rows = Vec::with_capacity(prep.test.len() * artifact.model.n_cols());
        for f in 0..prep.test.len() {
            rows.extend(artifact.model.synthesize(&w[f * k..(f + 1) * k])?);
        }
        let rec = artifact.decode_rows(&rows)?;
        Some(erms(&test_seq.frames, &rec, alignment)?)
    };

    let shares: Vec<f64> = locality.iter().map(|l| l.energy_share).collect();
    let sizes: Vec<f64> = locality.iter().map(|l| l.support_size as f64).collect();
    let metrics = Metrics {
        method: cfg.kind.name().to_string(),
        representation: kind.name().to_string(),
        components: artifact.model.n_components,
        train_erms,
        test_erms,
        test_erms_fitted: None,
        erms_alignment: alignment.to_string(),
        train_seconds,
        representation_seconds,
        iterations,
        objective,
        converged,
        train_frames: prep.train.len(),
        test_frames: prep.test.len(),
        median_energy_share: median(&shares),
        median_support_size: median(&sizes),
        locality,
    };

    progress.stage("writing", 0);
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    artifact::write_atomic(&out.join("config.toml"), resolved_toml(&cfg.name, &cfg.data, method_table).as_bytes())?;
    artifact.save(out)?;
    artifact::write_weights_csv(
        &out.join("weights.csv"),
        &train_seq.names,
        &artifact.model.weights,
        artifact.model.n_components,
    )?;
    artifact::write_json(&out.join("metrics.json"), &metrics)?;
    write_components(&artifact, &out.join("components"))?;
    progress.finish_stage();
    Ok(TrainOutcome { out_dir: out.to_path_buf(), metrics })
}

fn prefix_components(e: Error, _cfg: &Config) -> Error {
    match e {
        Error::Config { key, message } => Error::config(format!("method.{key}"), message),
        other => other,
    }
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

/// Writes, per component k, `kKK_magnitude.ply` (rest mesh coloured by magnitude, with a
/// `magnitude` column) and the shapes at weight −1 and +1 (`kKK_minus.obj`, `kKK_plus.obj`;
/// other weights 0), all in data units.
pub fn write_components(a: &LinearArtifact, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let k = a.model.n_components;
    let rest_data =
        TriMesh::new(a.rest.positions.iter().map(|p| a.header.unit_box.invert(*p)).collect(), a.rest.faces.clone());
    let width = (k.max(1) - 1).to_string().len().max(2);
    for c in 0..k {
        let mag = vertex_magnitudes(&a.model, c, a.representation.element(), &a.rest);
        let colors = mesh::colormap(&mag);
        mesh::write_ply(
            &dir.join(format!("k{c:0width$}_magnitude.ply")),
            &rest_data,
            Some(&colors),
            Some(("magnitude", &mag)),
        )?;
        for (sign, tag) in [(-1.0, "minus"), (1.0, "plus")] {
            let mut w = vec![0.0; k];
            w[c] = sign;
            let p = a.synthesize(&w)?;
            mesh::write_obj(&dir.join(format!("k{c:0width$}_{tag}.obj")), &TriMesh::new(p, a.rest.faces.clone()))?;
        }
    }
    Ok(())
}
