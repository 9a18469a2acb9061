//! Posing any trained model from its artefact directory (the library side of `meshdeco pose`):
//! load the model, choose start weights (a mesh's encoding or the model's default), solve for
//! vertex targets given in data units, and measure how local the result is.
//!
//! - `pca` / `splocs` on displacements: Lewis–Anjyo posing ([`LinearPoser`], paper 002 Eq. 8),
//!   honouring the model's weight constraint (SPLOCS: w ≥ 0 when trained so).
//! - `region-pca`: paper 002 Eq. 9/10 ([`RegionPoser`]) with β and γ.
//! - `autoencoder`: latent-code optimisation through the decoder ([`AePoser`]).
//!
//! Linear models on triangle gradients (or any non per-vertex representation) are refused with
//! an error naming the model and representation: their vertices come out of a Poisson solve, so
//! the per-vertex formulation of Eq. 8 does not apply.

use std::path::Path;

use super::ae_pose::{AePoseConfig, AePoser};
use super::autoencoder::AeArtifact;
use super::linear::LinearArtifact;
use super::region::RegionArtifact;
use crate::artifact;
use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, TriMesh, Vec3};
use crate::methods::posing::{LinearPoser, PoseConfig, RegionPoser, energy_share};
use crate::representation::RepresentationKind;

/// A loaded model of any kind that can be posed.
pub enum PoseModel {
    /// `pca` or `splocs`.
    Linear(Box<LinearArtifact>),
    /// `region-pca`.
    Region(Box<RegionArtifact>),
    /// `autoencoder`.
    Autoencoder(Box<AeArtifact>),
}

/// Hyperparameters of posing: γ, β for the linear and region models, the autoencoder's
/// optimiser settings (its γ is `ae.gamma`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseOptions {
    pub linear: PoseConfig,
    pub ae: AePoseConfig,
}

/// The result of one pose.
#[derive(Debug, Clone)]
pub struct PoseResult {
    /// Start positions (N, data units).
    pub start: Vec<Vec3>,
    /// Posed positions (N, data units).
    pub positions: Vec<Vec3>,
    /// Posed weights / coefficients / latent code.
    pub weights: Vec<f64>,
}

impl PoseModel {
    /// Loads the artefact directory `dir` (or its model.json) by its `method` field.
    pub fn load(dir: &Path) -> Result<Self> {
        let json = artifact::model_dir(dir).join("model.json");
        let v: serde_json::Value = artifact::read_json(&json)?;
        let method = v.get("method").and_then(|m| m.as_str()).unwrap_or("");
        match method {
            "pca" | "splocs" => Ok(PoseModel::Linear(Box::new(LinearArtifact::load(dir)?))),
            "region-pca" => Ok(PoseModel::Region(Box::new(RegionArtifact::load(dir)?))),
            "autoencoder" => Ok(PoseModel::Autoencoder(Box::new(AeArtifact::load(dir)?))),
            other => Err(Error::Invalid(format!("{}: method `{other}` cannot be posed", json.display()))),
        }
    }

    /// The method name (`pca`, `splocs`, `region-pca`, `autoencoder`).
    pub fn method(&self) -> &str {
        match self {
            PoseModel::Linear(a) => &a.header.method,
            PoseModel::Region(a) => &a.header.method,
            PoseModel::Autoencoder(a) => &a.header.method,
        }
    }

    /// Rest mesh in data units.
    pub fn rest(&self) -> TriMesh {
        let (rest, ub) = match self {
            PoseModel::Linear(a) => (&a.rest, a.header.unit_box),
            PoseModel::Region(a) => (&a.rest, a.header.unit_box),
            PoseModel::Autoencoder(a) => (&a.rest, a.header.unit_box),
        };
        TriMesh::new(rest.positions.iter().map(|p| ub.invert(*p)).collect(), rest.faces.clone())
    }

    /// What the start weights are when no mesh is given.
    pub fn default_start_description(&self) -> &'static str {
        match self {
            PoseModel::Linear(_) => {
                "all weights 0 (the model's offset: the training mean for PCA, the rest shape for SPLOCS)"
            }
            PoseModel::Region(_) => "all coefficients 0 (the per-region training means)",
            PoseModel::Autoencoder(_) => "the code of the rest mesh",
        }
    }

    /// Start weights: the encoding of `from` (N positions, data units) or the default.
    pub fn start_weights(&self, from: Option<&[Vec3]>) -> Result<Vec<f64>> {
        let rest = self.rest();
        let seq = |p: &[Vec3]| MeshSequence {
            faces: rest.faces.clone(),
            frames: vec![p.to_vec()],
            names: vec!["from".into()],
        };
        if let Some(p) = from
            && p.len() != rest.n_vertices()
        {
            return Err(Error::Invalid(format!(
                "start mesh has {} vertices, the model {}",
                p.len(),
                rest.n_vertices()
            )));
        }
        match (self, from) {
            (PoseModel::Linear(a), None) => Ok(vec![0.0; a.model.n_components]),
            (PoseModel::Linear(a), Some(p)) => a.encode_frames(&seq(p)),
            (PoseModel::Region(a), None) => Ok(vec![0.0; a.model.n_components()]),
            (PoseModel::Region(a), Some(p)) => Ok(a.encode_frames(&seq(p))?.remove(0)),
            (PoseModel::Autoencoder(a), p) => Ok(a.encode_frames(&seq(p.unwrap_or(&rest.positions)))?.remove(0)),
        }
    }

    /// Positions (data units) of weights `w`.
    pub fn synthesize(&self, w: &[f64]) -> Result<Vec<Vec3>> {
        match self {
            PoseModel::Linear(a) => a.synthesize(w),
            PoseModel::Region(a) => Ok(a.decode_rows(&a.model.reconstruct(w)?)?.remove(0)),
            PoseModel::Autoencoder(a) => Ok(a.decode_codes(&[w.to_vec()])?.remove(0)),
        }
    }

    /// Poses: `vertices` moved to `targets` (data units) starting from weights `w0`.
    pub fn pose(&self, vertices: &[usize], targets: &[Vec3], w0: &[f64], opts: &PoseOptions) -> Result<PoseResult> {
        let start = self.synthesize(w0)?;
        let (weights, positions) = match self {
            PoseModel::Linear(a) => {
                let kind = a.representation.kind();
                if kind != RepresentationKind::Displacement {
                    return Err(Error::Invalid(format!(
                        "posing a `{}` model on the `{}` representation is not supported: only displacement models \
                         are posed per vertex (Eq. 8); train with representation = \"displacement\"",
                        a.header.method,
                        kind.name()
                    )));
                }
                let rest = &a.representation.rest().positions;
                let t = model_targets(vertices, targets, a.header.unit_box, Some(rest));
                let w = LinearPoser::new(&a.model, vertices, &opts.linear)?.solve(&t, w0)?;
                let p = a.synthesize(&w)?;
                (w, p)
            }
            PoseModel::Region(a) => {
                let rest = &a.representation.rest().positions;
                let t = model_targets(vertices, targets, a.header.unit_box, Some(rest));
                let w = RegionPoser::new(&a.model, vertices, &opts.linear)?.solve(&t, w0)?;
                let p = self.synthesize(&w)?;
                (w, p)
            }
            PoseModel::Autoencoder(a) => AePoser::new(a, vertices, &opts.ae)?.solve(targets, w0)?,
        };
        Ok(PoseResult { start, positions, weights })
    }

    /// The vertices a drag of `v` should stay in, with a name: the grown region(s) containing
    /// `v` (region PCA; several when `v` is a shared boundary vertex), the support of the component with the
    /// largest magnitude at `v` (linear models: vertices above 10⁻³ of that component's largest
    /// magnitude), or `None` (autoencoder).
    pub fn locality_set(&self, v: usize) -> Option<(String, Vec<usize>)> {
        match self {
            PoseModel::Region(a) => {
                let grown = a.model.memberships();
                let mine: Vec<usize> = grown.get(v)?.iter().map(|&(r, _)| r).collect();
                let set: Vec<usize> =
                    (0..grown.len()).filter(|&u| grown[u].iter().any(|(r, _)| mine.contains(r))).collect();
                let names: Vec<String> = mine.iter().map(|r| r.to_string()).collect();
                Some((format!("region(s) {} ({} vertices)", names.join("+"), set.len()), set))
            }
            PoseModel::Linear(a) => {
                let m = &a.model;
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
            PoseModel::Autoencoder(_) => None,
        }
    }
}

/// Model-space targets: data-unit `targets` through the unit box, minus the rest position when
/// `rest` is given (displacement models).
fn model_targets(
    vertices: &[usize],
    targets: &[Vec3],
    ub: crate::preprocess::UnitBox,
    rest: Option<&[Vec3]>,
) -> Vec<Vec3> {
    vertices
        .iter()
        .zip(targets)
        .map(|(&v, &t)| {
            let p = ub.apply(t);
            match rest.and_then(|r| r.get(v)) {
                Some(r) => [p[0] - r[0], p[1] - r[1], p[2] - r[2]],
                None => p,
            }
        })
        .collect()
}

/// Vertices of `rest` within Euclidean distance `radius` of vertex `v`.
pub fn ball(rest: &[Vec3], v: usize, radius: f64) -> Vec<usize> {
    (0..rest.len()).filter(|&u| crate::mesh::dist(rest[u], rest[v]) <= radius).collect()
}

/// Share of the displacement energy from `start` to `posed` (N positions each) on `inside`.
pub fn displacement_share(start: &[Vec3], posed: &[Vec3], inside: &[usize]) -> f64 {
    let a: Vec<f64> = start.iter().flatten().copied().collect();
    let b: Vec<f64> = posed.iter().flatten().copied().collect();
    energy_share(&a, &b, inside)
}
