//! Posing helpers shared by the models' [`crate::model::Model::pose`] implementations and the
//! `pose` command: model-space targets, target checks, and the locality measures of a drag (the
//! options, constraints and result of a pose are [`crate::model::pose`]'s).
//!
//! - `pca` / `splocs` on displacements: Lewis–Anjyo posing ([`crate::methods::posing::LinearPoser`],
//!   paper 002 Eq. 8), honouring the model's weight constraint (SPLOCS: w ≥ 0 when trained so).
//! - `region-pca`: paper 002 Eq. 9/10 ([`crate::methods::posing::RegionPoser`]) with β and γ.
//! - `autoencoder`: latent-code optimisation through the decoder ([`super::ae_pose::AePoser`]).
//!
//! Linear models on triangle gradients (or any non per-vertex representation) are refused with
//! an error naming the model and representation: their vertices come out of a Poisson solve, so
//! the per-vertex formulation of Eq. 8 does not apply.

use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, TriMesh, Vec3};
use crate::methods::posing::energy_share;

/// `positions` as a one-frame sequence with `rest`'s faces (errors when it does not have one
/// position per vertex of `rest`).
pub fn single_frame(rest: &TriMesh, positions: &[Vec3]) -> Result<MeshSequence> {
    if positions.len() != rest.n_vertices() {
        return Err(Error::Invalid(format!(
            "start mesh has {} vertices, the model {}",
            positions.len(),
            rest.n_vertices()
        )));
    }
    Ok(MeshSequence { faces: rest.faces.clone(), frames: vec![positions.to_vec()], names: vec!["from".into()] })
}

/// Model-space targets: data-unit `targets` through the unit box, minus the rest position when
/// `rest` is given (displacement models).
pub fn model_targets(
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

/// Model-space displacement targets of the control `vertices` of a whole shape (data units):
/// [`model_targets`] of `shape`'s positions at those vertices, minus the rest positions.
pub fn control_targets(vertices: &[usize], shape: &[Vec3], ub: crate::preprocess::UnitBox, rest: &[Vec3]) -> Vec<Vec3> {
    let targets: Vec<Vec3> = vertices.iter().map(|&v| shape[v]).collect();
    model_targets(vertices, &targets, ub, Some(rest))
}

/// Errors unless every target (data units) is finite and within 1000 × the bounding-box diagonal
/// of `rest` from its centre (a drag farther than that is a typo or an overflow, and would
/// only produce coordinates of that size).
pub fn check_targets(rest: &TriMesh, vertices: &[usize], targets: &[Vec3]) -> Result<()> {
    let (lo, hi) = rest.bounding_box();
    let diag = crate::mesh::dist(lo, hi).max(f64::MIN_POSITIVE);
    let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])];
    for (&v, t) in vertices.iter().zip(targets) {
        if t.iter().any(|x| !x.is_finite()) {
            return Err(Error::Invalid(format!("target of vertex {v} is not finite: {t:?}")));
        }
        // Largest coordinate offset (no squares: they overflow for targets like 1e300).
        let d = (0..3).map(|k| (t[k] - centre[k]).abs()).fold(0.0, f64::max);
        if d > 1e3 * diag {
            return Err(Error::Invalid(format!(
                "target of vertex {v} {t:?} lies {d:.3e} from the mesh's centre along an axis, more than 1000 × its bounding-box diagonal ({diag:.3e})"
            )));
        }
    }
    Ok(())
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
