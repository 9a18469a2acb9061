//! The trained-model interface: what every method's artefact offers once trained, whatever the
//! method — the rest mesh, the components (ranked, named, with centres and per-vertex heat
//! maps), decoding weights to vertices, encoding frames to weights (the model's own encoder, and
//! a refined encoding where the method has one), posing from vertex constraints, fitting to
//! sparse control points and writing its artefacts.
//!
//! **A trait, not an enum.** Each method implements [`Model`] in its own file
//! (`pipeline/linear.rs` for pca and splocs, `pipeline/region.rs`, `pipeline/autoencoder.rs`),
//! so commands (`encode`, `synthesize`, `components`, `interpolate`, `pose`), the evaluation and
//! later front ends are written once against `dyn Model`. The one place that names each method
//! kind is the registry above this layer (`pipeline/registry.rs`: `fit` and `load_model`); a new
//! method adds its files and one arm there (ARCHITECTURE.md, "Where a change goes"). An enum
//! would put a `match` in every operation of every caller.
//!
//! Units and conventions: every position that enters or leaves a [`Model`] is in the data's own
//! units (the unit-box scaling of `data.unit_box` is applied and undone inside); weights are the
//! model's own coordinates (linear models: component weights; region PCA: the concatenated
//! per-region coefficients ζ; the autoencoder: the latent code z). Synthesis "dials"
//! ([`Model::synthesis_weights`]) are the user-facing weights of `meshdeco synthesize`: equal to
//! the weights for linear models; for the autoencoder `z = Z_r + Σ_m w_m·b_m` with its dial basis
//! (`dial_sparsity`, the default) or `z_i = Z_r,i + (Z_h,i − Z_r,i)·w_i` without one.

pub mod pose;

use std::path::Path;

use crate::config::MethodKind;
use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, TriMesh, Vec3};
use crate::metrics::erms::{Alignment, erms};
use crate::representation::RepresentationKind;

pub use pose::{Constraints, PoseOptions, PosePrior, PoseResult, landed_pose, spreader};

/// One component of a trained model, as shown to a person.
#[derive(Debug, Clone, PartialEq)]
pub struct Component {
    /// Index of the component in the model's weight vector (0-based).
    pub index: usize,
    /// Rank (0 = first shown): by index for linear and region models (PCA: by variance; SPLOCS:
    /// in extraction order), by the feature-space distance of the extreme shape for the
    /// autoencoder (the ranking of `meshdeco components`).
    pub rank: usize,
    /// Display name and file stem: `k03` (linear), `r02_c01` (region 2, component 1), `0_12`
    /// (autoencoder: rank 0, latent dimension 12).
    pub name: String,
    /// Centre vertex (largest magnitude).
    pub center: usize,
    /// Per-vertex magnitude (heat map, ≥ 0; N numbers): the component's group norm per vertex
    /// (triangle elements: mean over a vertex's triangles; autoencoder: feature change of the
    /// extreme shape).
    pub magnitudes: Vec<f64>,
}

/// Weights (one vector per frame) and the shapes they decode to (data units).
pub type Refined = (Vec<Vec<f64>>, Vec<Vec<Vec3>>);

/// Refined encoding options ([`Model::refine`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineOptions {
    /// Vertices fitted per frame (farthest-point spread; ≥ N: every vertex).
    pub points: usize,
    /// Dimensionless pull towards the start weights.
    pub gamma: f64,
}

/// Fits a model to a shape from its positions at a fixed set of control vertices
/// ([`Model::point_fit`]): factor once, fit many shapes.
pub trait PointFit {
    /// The whole shape (N positions, data units) reconstructed from `shape`'s positions at the
    /// control vertices (only those are read).
    fn reconstruct(&self, shape: &[Vec3]) -> Result<Vec<Vec3>>;
}

/// A trained model of any method (see the module docs).
pub trait Model {
    /// The method kind.
    fn kind(&self) -> MethodKind;
    /// The representation the method ran on.
    fn representation(&self) -> RepresentationKind;
    /// Rest mesh in data units.
    fn rest(&self) -> TriMesh;
    /// Number of weights of a shape (K; region PCA: the total over regions).
    fn n_components(&self) -> usize;
    /// The components in index order (see [`Component`]; [`ranked`] sorts them by rank).
    fn components(&self) -> Result<Vec<Component>>;
    /// Per component, the group norm of every element (vertex or triangle), and the element
    /// adjacency — what the locality metrics measure.
    fn element_norms(&self) -> (Vec<Vec<f64>>, &[Vec<usize>]);
    /// How Erms is aligned for this model: representations that drop translation are measured
    /// centroid-aligned.
    fn alignment(&self) -> Alignment;
    /// Names of the training frames.
    fn train_frames(&self) -> &[String];
    /// Weights of the training frames as stored at training time (`None`: re-encode them).
    fn train_weights(&self) -> Option<Vec<Vec<f64>>>;
    /// Vertex positions (data units) of weight vectors (one per shape, K each).
    fn decode(&self, weights: &[Vec<f64>]) -> Result<Vec<Vec<Vec3>>>;
    /// The weights `meshdeco synthesize --weights` dials map to (see the module docs).
    fn synthesis_weights(&self, dials: &[f64]) -> Result<Vec<f64>> {
        check_len("weights", dials.len(), self.n_components())?;
        Ok(dials.to_vec())
    }
    /// The dials whose [`Model::synthesis_weights`] are `weights` (its inverse; the identity for
    /// linear and region models; the autoencoder: the solution of `Σ_m w_m·b_m = z − Z_r` with a
    /// dial basis, `(z_i − Z_r,i) / (Z_h,i − Z_r,i)` without).
    fn dials(&self, weights: &[f64]) -> Result<Vec<f64>> {
        check_len("weights", weights.len(), self.n_components())?;
        Ok(weights.to_vec())
    }
    /// The model's own encoding of frames (data units) into weights (linear models:
    /// least squares honouring the weight constraint; region PCA: Eq. 6/7; the autoencoder: its
    /// encoder network).
    fn encode(&self, frames: &MeshSequence) -> Result<Vec<Vec<f64>>>;
    /// How [`Model::encode`] encodes, in words (printed by `meshdeco encode`).
    fn encoder_description(&self) -> String {
        "least-squares weights".into()
    }
    /// The encoder's plain one-pass encoding, where [`Model::encode`] does more (the
    /// autoencoder with `encoder_passes > 0` or `encoder_steps > 0`); `None` otherwise.
    /// Reported beside it.
    fn encode_one_pass(&self, frames: &MeshSequence) -> Result<Option<Vec<Vec<f64>>>> {
        let _ = frames;
        Ok(None)
    }
    /// The network's own encoding, where [`Model::encode`] also takes vertex steps after it (the autoencoder with `encoder_steps > 0`); `None` otherwise. Reported beside
    /// it ("network only").
    fn encode_network(&self, frames: &MeshSequence) -> Result<Option<Vec<Vec<f64>>>> {
        let _ = frames;
        Ok(None)
    }
    /// A refined encoding from `start` weights, with its reconstructions, where the method has
    /// one (the autoencoder's codes fitted through the decoder); `None` when the own encoding is
    /// already the best fit (linear least squares). `done(i)` is called after frame i.
    fn refine(
        &self,
        frames: &MeshSequence,
        start: &[Vec<f64>],
        options: &RefineOptions,
        done: &mut dyn FnMut(usize),
    ) -> Result<Option<Refined>> {
        let _ = (frames, start, options, done);
        Ok(None)
    }
    /// Start weights of posing: the encoding of `from` (N positions, data units) or the model's
    /// default ([`Model::start_description`]).
    fn start_weights(&self, from: Option<&[Vec3]>) -> Result<Vec<f64>>;
    /// What the default start weights are, in words.
    fn start_description(&self) -> &'static str;
    /// Poses: `vertices` moved to `targets` (data units) starting from weights `w0`.
    /// `options` is checked by the caller ([`PoseOptions::validate`]); the model reads those of
    /// [`Model::pose_parameters`].
    fn pose(&self, vertices: &[usize], targets: &[Vec3], w0: &[f64], options: &PoseOptions) -> Result<PoseResult>;
    /// The pose options a front end starts from: the model kind's, chosen on validation drags
    /// ([`PoseOptions::linear_defaults`] and its siblings); [`PoseOptions::default`] unless the
    /// kind names its own.
    fn pose_defaults(&self) -> PoseOptions {
        PoseOptions::default()
    }
    /// The [`PoseOptions`] this model's [`Model::pose`] reads (`gamma`, `beta`,
    /// `max_iterations`): what a front end offers to set.
    fn pose_parameters(&self) -> &'static [&'static str] {
        &["gamma"]
    }
    /// The vertices a drag of `v` should stay in, with a name (region, component support), if
    /// the model has such a notion.
    fn locality_set(&self, v: usize) -> Option<(String, Vec<usize>)> {
        let _ = v;
        None
    }
    /// A control-point fitter for `vertices` with Tikhonov weight `gamma`, or `None` when the
    /// model cannot be fitted to points (linear models on non-vertex representations).
    fn point_fit<'a>(&'a self, vertices: &[usize], gamma: f64) -> Result<Option<Box<dyn PointFit + 'a>>>;
    /// Writes the model files (`model.json`, `model.bin`, and the method's own) into `dir`.
    fn save(&self, dir: &Path) -> Result<()>;
    /// Writes the views of the model that training writes beside it (component meshes and heat
    /// maps, a segmentation picture); `meshdeco components` calls [`Model::write_components`].
    fn write_views(&self, dir: &Path) -> Result<()>;
    /// Writes every component's shapes and heat map, and `components.csv`, into `dir`.
    fn write_components(&self, dir: &Path) -> Result<()>;
}

/// Errors unless `got == want`, naming `what`.
pub fn check_len(what: &str, got: usize, want: usize) -> Result<()> {
    if got != want {
        return Err(Error::Invalid(format!("{got} {what} given, the model has {want} components")));
    }
    Ok(())
}

/// The components sorted by rank.
pub fn ranked(model: &dyn Model) -> Result<Vec<Component>> {
    let mut c = model.components()?;
    c.sort_by_key(|c| c.rank);
    Ok(c)
}

/// Errors (naming `source`) unless `frames` have the model's connectivity.
pub fn check_connectivity(model: &dyn Model, frames: &MeshSequence, source: &str) -> Result<()> {
    let rest = model.rest();
    if frames.n_vertices() != rest.n_vertices() || frames.faces != rest.faces {
        return Err(Error::Invalid(format!(
            "{source}: connectivity differs from the model's rest mesh ({} vertices and {} faces, the model {} and {}{})",
            frames.n_vertices(),
            frames.n_faces(),
            rest.n_vertices(),
            rest.n_faces(),
            if frames.n_faces() == rest.n_faces() { "; the face lists differ" } else { "" }
        )));
    }
    Ok(())
}

/// Encode then decode (the model's own encoding).
pub fn reconstruct(model: &dyn Model, frames: &MeshSequence) -> Result<Vec<Vec<Vec3>>> {
    model.decode(&model.encode(frames)?)
}

/// The shape of synthesis dials (see [`Model::synthesis_weights`]).
pub fn synthesize(model: &dyn Model, dials: &[f64]) -> Result<Vec<Vec3>> {
    let w = model.synthesis_weights(dials)?;
    Ok(model.decode(&[w])?.remove(0))
}

/// Every component as a vertex displacement field (N × 3, data units) around the rest shape:
/// the shape of the rest mesh's own weights ([`Model::start_weights`] of the rest positions:
/// for the autoencoder the rest shape's code) with the component's dial raised by 1, minus the
/// shape of those weights alone. Linear models on displacements give their components exactly;
/// nonlinear ones their change of shape at dial 1 (the autoencoder: its extreme code's offset,
/// `Z_h − Z_r`, added to the rest code). Models that drop translation (centroid-aligned Erms)
/// have each field's median translation removed
/// ([`crate::metrics::recovery::remove_median_translation`]), so a local change reads as local.
/// Index order.
pub fn component_fields(model: &dyn Model) -> Result<Vec<Vec<Vec3>>> {
    let rest = model.rest();
    let w0 = model.start_weights(Some(&rest.positions))?;
    let k = model.n_components();
    let base = model.decode(std::slice::from_ref(&w0))?.remove(0);
    let mut fields = Vec::with_capacity(k);
    let moved = component_weights(model, &w0, 1.0)?;
    // A few components at a time: the decoded shapes of all K are never held at once.
    for codes in moved.chunks(16) {
        for shape in model.decode(codes)? {
            let mut f: Vec<Vec3> = shape.iter().zip(&base).map(|(a, b)| crate::math::vec3::sub(*a, *b)).collect();
            if model.alignment() == Alignment::Centroid {
                crate::metrics::recovery::remove_median_translation(&mut f);
            }
            fields.push(f);
        }
    }
    Ok(fields)
}

/// Per component i (index order), the weights `w0` moved by dial i turned by `step` from the
/// dials of `w0`: the weights move by what the dial adds (the dials map to weights affinely:
/// dimension by dimension, or through the autoencoder's dial basis).
pub fn component_weights(model: &dyn Model, w0: &[f64], step: f64) -> Result<Vec<Vec<f64>>> {
    let d0 = model.dials(w0)?;
    let s0 = model.synthesis_weights(&d0)?;
    (0..model.n_components())
        .map(|i| {
            let mut d = d0.clone();
            d[i] += step;
            let s1 = model.synthesis_weights(&d)?;
            Ok(w0.iter().zip(s1.iter().zip(&s0)).map(|(w, (a, b))| w + (a - b)).collect())
        })
        .collect()
}

/// `steps` shapes (≥ 2, both ends included) along the straight line between the weights of two
/// shapes (data units): encoded, interpolated linearly, decoded.
pub fn interpolate(model: &dyn Model, from: &[Vec3], to: &[Vec3], steps: usize) -> Result<Vec<Vec<Vec3>>> {
    if steps < 2 {
        return Err(Error::Invalid(format!("steps ({steps}) must be at least 2")));
    }
    let rest = model.rest();
    let seq = MeshSequence { faces: rest.faces, frames: vec![from.to_vec(), to.to_vec()], names: vec![] };
    let w = model.encode(&seq)?;
    let codes: Vec<Vec<f64>> = (0..steps)
        .map(|s| {
            let t = s as f64 / (steps - 1) as f64;
            w[0].iter().zip(&w[1]).map(|(a, b)| a + (b - a) * t).collect()
        })
        .collect();
    model.decode(&codes)
}

/// Encodings of frames with their reconstructions and Erms (see [`encode_frames`]).
#[derive(Debug, Clone)]
pub struct Encoded {
    /// Weights per frame.
    pub weights: Vec<Vec<f64>>,
    /// Reconstructions (data units).
    pub reconstructions: Vec<Vec<Vec3>>,
    /// Erms per frame, and over all frames.
    pub frame_erms: Vec<f64>,
    pub total_erms: f64,
    /// Alignment of the Erms values.
    pub alignment: Alignment,
    /// Whether the weights were refined ([`Model::refine`]).
    pub refined: bool,
}

/// Encodes frames (checking their connectivity) with the model's own encoder, refined when
/// `refine` is given and the model has a refinement; measures Erms per frame and in total.
pub fn encode_frames(
    model: &dyn Model,
    frames: &MeshSequence,
    source: &str,
    refine: Option<&RefineOptions>,
) -> Result<Encoded> {
    check_connectivity(model, frames, source)?;
    let own = model.encode(frames)?;
    let refined = match refine {
        Some(o) => model.refine(frames, &own, o, &mut |_| {})?,
        None => None,
    };
    let is_refined = refined.is_some();
    let (weights, reconstructions) = match refined {
        Some(r) => r,
        None => {
            let rec = model.decode(&own)?;
            (own, rec)
        }
    };
    let alignment = model.alignment();
    let frame_erms = frames
        .frames
        .iter()
        .zip(&reconstructions)
        .map(|(t, r)| erms(std::slice::from_ref(t), std::slice::from_ref(r), alignment))
        .collect::<Result<Vec<f64>>>()?;
    let total_erms = erms(&frames.frames, &reconstructions, alignment)?;
    Ok(Encoded { weights, reconstructions, frame_erms, total_erms, alignment, refined: is_refined })
}

/// Parses synthesis dials `"i:w,j:v"` into a dense vector of length `k` (unlisted: 0). Errors
/// name `flag`, the bad pair, and the valid index range.
pub fn parse_dials(flag: &str, s: &str, k: usize) -> Result<Vec<f64>> {
    let mut w = vec![0.0; k];
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (i, v) =
            part.split_once(':').ok_or_else(|| Error::Invalid(format!("{flag}: `{part}` is not index:weight")))?;
        let i: usize = i
            .trim()
            .parse()
            .map_err(|_| Error::Invalid(format!("{flag}: `{i}` in `{part}` is not a component index")))?;
        let v: f64 =
            v.trim().parse().map_err(|_| Error::Invalid(format!("{flag}: `{v}` in `{part}` is not a number")))?;
        if i >= k {
            return Err(Error::Invalid(format!(
                "{flag}: component {i} does not exist (the model has {k} components, 0..{})",
                k.saturating_sub(1)
            )));
        }
        if !v.is_finite() {
            return Err(Error::Invalid(format!("{flag}: weight of component {i} is {v}")));
        }
        w[i] = v;
    }
    Ok(w)
}

/// Parses synthesis dials from JSON text `{"dials": [w0, …]}` (all `k`) or `{"dials": {"i": w}}`
/// (unlisted: 0), as `meshdeco view` saves them. Errors name `source` and the bad entry.
pub fn parse_dials_json(source: &str, text: &str, k: usize) -> Result<Vec<f64>> {
    let v: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| Error::Invalid(format!("{source}: line {} column {}: {e}", e.line(), e.column())))?;
    let num = |x: &serde_json::Value, what: String| -> Result<f64> {
        match x.as_f64() {
            Some(f) if f.is_finite() => Ok(f),
            _ => Err(Error::Invalid(format!("{source}: {what} is not a finite number ({x})"))),
        }
    };
    match v.get("dials") {
        Some(serde_json::Value::Array(a)) => {
            if a.len() != k {
                return Err(Error::Invalid(format!(
                    "{source}: `dials` has {} numbers, the model has {k} components",
                    a.len()
                )));
            }
            a.iter().enumerate().map(|(i, x)| num(x, format!("dials[{i}]"))).collect()
        }
        Some(serde_json::Value::Object(o)) => {
            let mut w = vec![0.0; k];
            for (key, x) in o {
                let i: usize = key.trim().parse().map_err(|_| {
                    Error::Invalid(format!("{source}: key `{key}` of `dials` is not a component index"))
                })?;
                if i >= k {
                    return Err(Error::Invalid(format!(
                        "{source}: component {i} does not exist (the model has {k} components, 0..{})",
                        k.saturating_sub(1)
                    )));
                }
                w[i] = num(x, format!("dials[\"{key}\"]"))?;
            }
            Ok(w)
        }
        _ => Err(Error::Invalid(format!(
            "{source}: expected a JSON object with `dials`: an array of {k} numbers or {{\"index\": weight}}"
        ))),
    }
}

/// Index of the largest value (0 when empty).
pub fn argmax(values: &[f64]) -> usize {
    values.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i).unwrap_or(0)
}

/// Writes `components.csv` into `dir`: one row per component in rank order (index, rank, name,
/// centre vertex, peak per-vertex magnitude).
pub fn write_components_csv(model: &dyn Model, dir: &Path) -> Result<()> {
    let mut csv = String::from("index,rank,name,center_vertex,peak_magnitude\n");
    for c in ranked(model)? {
        let peak = c.magnitudes.iter().cloned().fold(0.0, f64::max);
        csv.push_str(&format!("{},{},{},{},{}\n", c.index, c.rank, c.name, c.center, peak));
    }
    crate::artifact::write_atomic(&dir.join("components.csv"), csv.as_bytes())
}

/// Writes, per component (file stem = its name), `<name>_magnitude.ply` (the rest mesh
/// coloured by the per-vertex magnitude, with a `magnitude` column) and the shapes at dial −1
/// and +1 (`<name>_minus.obj`, `<name>_plus.obj`; other dials 0), all in data units.
pub fn write_component_meshes(model: &dyn Model, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let rest = model.rest();
    let k = model.n_components();
    for c in model.components()? {
        let colors = crate::mesh::colormap(&c.magnitudes);
        crate::mesh::write_ply(
            &dir.join(format!("{}_magnitude.ply", c.name)),
            &rest,
            Some(&colors),
            Some(("magnitude", &c.magnitudes)),
        )?;
        for (sign, tag) in [(-1.0, "minus"), (1.0, "plus")] {
            let mut w = vec![0.0; k];
            w[c.index] = sign;
            let p = synthesize(model, &w)?;
            crate::mesh::write_obj(&dir.join(format!("{}_{tag}.obj", c.name)), &TriMesh::new(p, rest.faces.clone()))?;
        }
    }
    Ok(())
}
