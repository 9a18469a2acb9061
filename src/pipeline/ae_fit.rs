//! Encoding by fitting: the latent code of a trained autoencoder whose decoded and reconstructed
//! shape is closest, in vertex positions, to a given shape.
//!
//! The network's encoder maps features to codes in one pass and is trained on the training
//! shapes only; on unseen shapes its code can be far from the best one the decoder offers (on
//! SCAPE 37–71 the encoder's codes reconstruct at test Erms 24.8, while codes fitted to 200
//! vertices reach 10.5 — README, "Evaluation tables"). [`AeFitEncoder`] starts from the encoder's
//! code and runs the Gauss–Newton of [`AePoser`] on `points` vertices spread by farthest-point
//! sampling (all vertices when `points` ≥ N), alternating with the best global translation
//! (the ACAP decoding fixes the centroid). Positions are in data units.

use super::ae_pose::{AePoseConfig, AePoser};
use super::autoencoder::AeArtifact;
use crate::error::{Error, Result};
use crate::geometry::farthest_point_sampling::FarthestPointSampler;
use crate::geometry::graph_distance::EdgeGraph;
use crate::mesh::{MeshSequence, Vec3};

/// Code/translation alternations per shape.
const TRANSLATION_ROUNDS: usize = 2;

/// Codes (one K-vector per frame) and reconstructions (N positions per frame, data units).
pub type FittedFrames = (Vec<Vec<f64>>, Vec<Vec<Vec3>>);

/// Default γ of the fit (dimensionless pull towards the encoder's code).
pub const DEFAULT_FIT_GAMMA: f64 = 1e-3;

/// Fits latent codes to whole shapes (see the module docs). Build once per model; the set-up
/// runs one ACAP adjoint solve per fitted vertex.
pub struct AeFitEncoder<'a> {
    artifact: &'a AeArtifact,
    poser: AePoser<'a>,
    vertices: Vec<usize>,
}

impl<'a> AeFitEncoder<'a> {
    /// Prepares fitting on `points` vertices (farthest-point sampling from vertex 0 in edge-path
    /// distance; every vertex when `points` ≥ N). `points` must be at least 1.
    pub fn new(artifact: &'a AeArtifact, points: usize, gamma: f64) -> Result<Self> {
        if points == 0 {
            return Err(Error::config("fit_points", "fit_points (0) must be at least 1"));
        }
        let rest = &artifact.rest;
        let n = rest.n_vertices();
        let vertices: Vec<usize> = if points >= n {
            (0..n).collect()
        } else {
            let graph = EdgeGraph::new(&rest.positions, &rest.faces);
            FarthestPointSampler::new(&graph).sample(points, 0)?
        };
        let poser = AePoser::new(artifact, &vertices, &AePoseConfig { gamma, ..Default::default() })?;
        Ok(AeFitEncoder { artifact, poser, vertices })
    }

    /// The fitted vertices.
    pub fn vertices(&self) -> &[usize] {
        &self.vertices
    }

    /// Code and reconstruction (N positions, data units) of one shape (N positions, data units),
    /// starting from code `z0`.
    pub fn fit(&self, shape: &[Vec3], z0: &[f64]) -> Result<(Vec<f64>, Vec<Vec3>)> {
        let n = self.artifact.rest.n_vertices();
        if shape.len() != n {
            return Err(Error::Invalid(format!("shape has {} vertices, the model {n}", shape.len())));
        }
        let targets: Vec<Vec3> = self.vertices.iter().map(|&v| shape[v]).collect();
        let m = targets.len() as f64;
        let (mut z, mut t) = (z0.to_vec(), [0.0; 3]);
        let mut positions = Vec::new();
        for _ in 0..TRANSLATION_ROUNDS {
            let shifted: Vec<Vec3> = targets.iter().map(|p| [p[0] - t[0], p[1] - t[1], p[2] - t[2]]).collect();
            let (z_new, pos) = self.poser.solve(&shifted, &z)?;
            z = z_new;
            t = std::array::from_fn(|k| {
                self.vertices.iter().zip(&targets).map(|(&v, p)| p[k] - pos[v][k]).sum::<f64>() / m
            });
            positions = pos;
        }
        let out: Vec<Vec3> = positions.into_iter().map(|p| [p[0] + t[0], p[1] + t[1], p[2] + t[2]]).collect();
        if out.iter().flatten().any(|v| !v.is_finite()) || z.iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical("the fitted code or shape is not finite".into()));
        }
        Ok((z, out))
    }

    /// Codes and reconstructions of every frame: the encoder's code, then [`Self::fit`].
    pub fn fit_frames(&self, frames: &MeshSequence) -> Result<FittedFrames> {
        let start = self.artifact.encode_frames(frames)?;
        let mut codes = Vec::with_capacity(frames.n_frames());
        let mut shapes = Vec::with_capacity(frames.n_frames());
        for (shape, z0) in frames.frames.iter().zip(&start) {
            let (z, p) = self.fit(shape, z0)?;
            codes.push(z);
            shapes.push(p);
        }
        Ok((codes, shapes))
    }
}
