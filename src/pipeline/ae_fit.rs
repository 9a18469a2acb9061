//! Encoding by fitting: the latent code of a trained autoencoder whose decoded and reconstructed
//! shape is closest, in vertex positions, to a given shape.
//!
//! The network's encoder maps features to codes in one pass and is trained on the training
//! shapes only; on unseen shapes its code can be far from the best one the decoder offers.
//! [`AeFitEncoder`] starts from the encoder's code z0 and minimises, over the code z,
//!
//! ```text
//! E(z) = Σ_a ‖(p_a(z) − p̄(z)) − (t_a − t̄)‖² + λ‖z − z0‖²,   λ = γ · trace(J(z0)ᵀJ(z0)) / K
//! ```
//!
//! over `points` vertices a (farthest-point spread; all vertices when `points` ≥ N), where
//! p(z) is the decoded, ACAP-reconstructed shape in data units, t the target, bars the means
//! over the fitted vertices (the best translation is applied in closed form: the ACAP decoding
//! fixes only the centroid), J the Jacobian of the centred positions and γ dimensionless. With
//! every vertex fitted and γ → 0 this is exactly the centroid-aligned Erms of the shape, i.e. the
//! projection of the shape onto the decoder's output set, the nonlinear counterpart of the
//! least-squares weights with which the linear models encode unseen shapes.
//!
//! **Solver.** Levenberg–Marquardt on the K unknowns. J is formed from K + 1 decodes per
//! iteration (one-sided differences with step [`FD_STEP`] in code units; codes are O(1–10)),
//! batched through the network and the ACAP decoding, so an iteration costs the same for 20 or
//! for all vertices (SCAPE, K = 50: about 50 ms). Only steps that lower E are taken; the loop
//! stops after `max_iterations` or when E falls by less than `tolerance` (relative).

use nalgebra::{DMatrix, DVector};

use super::autoencoder::AeArtifact;
use crate::error::{Error, Result};
use crate::geometry::farthest_point_sampling::FarthestPointSampler;
use crate::geometry::graph_distance::EdgeGraph;
use crate::mesh::{MeshSequence, Vec3};

/// Levenberg–Marquardt iterations of the autoencoder's control-point fit ([`crate::model::Model::point_fit`]:
/// it starts from the reference shape's code, farther from the target than an encoder's code).
pub const POINT_FIT_ITERATIONS: usize = 30;

/// Codes (one K-vector per frame) and reconstructions (N positions per frame, data units).
pub type FittedFrames = (Vec<Vec<f64>>, Vec<Vec<Vec3>>);

/// Decoded shapes (N positions each) and their centred fitted vertices (3·M numbers each).
type Decoded = (Vec<Vec<Vec3>>, Vec<Vec<f64>>);

/// Default γ of the fit (dimensionless pull towards the encoder's code).
pub const DEFAULT_FIT_GAMMA: f64 = 1e-3;

/// Default Levenberg–Marquardt iterations per shape.
pub const DEFAULT_FIT_ITERATIONS: usize = 10;

/// Finite-difference step of the Jacobian, in code units.
pub const FD_STEP: f64 = 1e-2;

/// Relative objective decrease below which the fit stops.
const TOLERANCE: f64 = 1e-6;

/// One Levenberg–Marquardt step of the fits: solves (JᵀJ + λI + μ·diag(JᵀJ)) δ = `g` and offers
/// z + δ to `trial`, which returns its objective (and what the caller keeps of it) or `None` to
/// reject it. μ grows ×10 while the matrix is not positive definite or the objective is not a
/// finite value below `e0`, and shrinks to max(0.3μ, 10⁻⁹) on success; `None` once μ exceeds
/// `mu_max`. Returns the accepted code, its objective and the trial's payload.
#[allow(clippy::too_many_arguments)]
pub(crate) fn damped_step<T>(
    jtj: &DMatrix<f64>,
    g: &DVector<f64>,
    lam: f64,
    z: &[f64],
    e0: f64,
    mu: &mut f64,
    mu_max: f64,
    mut trial: impl FnMut(&[f64]) -> Result<Option<(f64, T)>>,
) -> Result<Option<(Vec<f64>, f64, T)>> {
    let k = z.len();
    while *mu <= mu_max {
        let mut a = jtj.clone();
        for j in 0..k {
            a[(j, j)] += lam + *mu * (jtj[(j, j)] + 1e-12);
        }
        let Some(chol) = a.cholesky() else {
            *mu *= 10.0;
            continue;
        };
        let step = chol.solve(g);
        let zn: Vec<f64> = z.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
        if let Some((en, kept)) = trial(&zn)?
            && en.is_finite()
            && en < e0
        {
            *mu = (*mu * 0.3).max(1e-9);
            return Ok(Some((zn, en, kept)));
        }
        *mu *= 10.0;
    }
    Ok(None)
}

/// Fits latent codes to whole shapes (see the module docs). Build once per model.
pub struct AeFitEncoder<'a> {
    artifact: &'a AeArtifact,
    vertices: Vec<usize>,
    gamma: f64,
    max_iterations: usize,
}

impl<'a> AeFitEncoder<'a> {
    /// Prepares fitting on `points` vertices (farthest-point sampling from vertex 0 in edge-path
    /// distance; every vertex when `points` ≥ N). `points` must be at least 1 and `gamma`
    /// finite and ≥ 0.
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
        Self::with_vertices(artifact, vertices, gamma)
    }

    /// Prepares fitting on the given vertices (each below N, at least one).
    pub fn with_vertices(artifact: &'a AeArtifact, vertices: Vec<usize>, gamma: f64) -> Result<Self> {
        let n = artifact.rest.n_vertices();
        if vertices.is_empty() {
            return Err(Error::config("fit_points", "no vertices to fit"));
        }
        if let Some(v) = vertices.iter().find(|&&v| v >= n) {
            return Err(Error::Invalid(format!("fitted vertex {v} does not exist (the model has {n} vertices)")));
        }
        if !(gamma.is_finite() && gamma >= 0.0) {
            return Err(Error::config("fit_gamma", format!("fit_gamma ({gamma}) must be finite and non-negative")));
        }
        Ok(AeFitEncoder { artifact, vertices, gamma, max_iterations: DEFAULT_FIT_ITERATIONS })
    }

    /// Sets the Levenberg–Marquardt iteration limit (at least 1).
    pub fn with_iterations(mut self, max_iterations: usize) -> Result<Self> {
        if max_iterations == 0 {
            return Err(Error::config("fit_iterations", "fit_iterations (0) must be at least 1"));
        }
        self.max_iterations = max_iterations;
        Ok(self)
    }

    /// The fitted vertices.
    pub fn vertices(&self) -> &[usize] {
        &self.vertices
    }

    /// Decoded shapes (N positions each, data units) and their fitted vertices centred on
    /// their mean (3·M numbers per code).
    fn decode(&self, codes: &[Vec<f64>]) -> Result<Decoded> {
        let shapes = self.artifact.decode_codes(codes)?;
        let centred = shapes.iter().map(|s| centre(&self.vertices, s)).collect();
        Ok((shapes, centred))
    }

    /// Code and reconstruction (N positions, data units) of one shape (N positions, data units),
    /// starting from code `z0`. The reconstruction includes the fitted translation.
    pub fn fit(&self, shape: &[Vec3], z0: &[f64]) -> Result<(Vec<f64>, Vec<Vec3>)> {
        let n = self.artifact.rest.n_vertices();
        if shape.len() != n {
            return Err(Error::Invalid(format!("shape has {} vertices, the model {n}", shape.len())));
        }
        let k = self.artifact.n_dims();
        if z0.len() != k {
            return Err(Error::Invalid(format!("start code has {} numbers, the model K = {k}", z0.len())));
        }
        if let Some(p) = shape.iter().flatten().position(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!("target vertex {} is not finite", p / 3)));
        }
        let target = centre(&self.vertices, shape);
        let m = target.len();
        let mut z = z0.to_vec();
        // The decoded shape of the current code (kept, so the result needs no extra decode).
        let mut decoded = Vec::new();
        let mut lambda = None;
        let mut mu = 1e-3;
        let objective = |p: &[f64], z: &[f64], lambda: f64| -> f64 {
            let data: f64 = p.iter().zip(&target).map(|(a, b)| (a - b) * (a - b)).sum();
            data + lambda * z.iter().zip(z0).map(|(a, b)| (a - b) * (a - b)).sum::<f64>()
        };
        for _ in 0..self.max_iterations {
            let mut batch = Vec::with_capacity(k + 1);
            batch.push(z.clone());
            for j in 0..k {
                let mut zj = z.clone();
                zj[j] += FD_STEP;
                batch.push(zj);
            }
            let (mut shapes, p) = self.decode(&batch)?;
            decoded = shapes.swap_remove(0);
            let jac = DMatrix::from_fn(m, k, |i, j| (p[j + 1][i] - p[0][i]) / FD_STEP);
            let jtj = jac.transpose() * &jac;
            let lam = *lambda.get_or_insert_with(|| self.gamma * jtj.trace() / k as f64);
            let r = DVector::from_fn(m, |i, _| target[i] - p[0][i]);
            let dz = DVector::from_fn(k, |j, _| z0[j] - z[j]);
            let g = jac.transpose() * r + lam * dz;
            let e0 = objective(&p[0], &z, lam);
            let improved = damped_step(&jtj, &g, lam, &z, e0, &mut mu, 1e8, |zn| {
                let (mut trial, pn) = self.decode(&[zn.to_vec()])?;
                Ok(Some((objective(&pn[0], zn, lam), trial.swap_remove(0))))
            })?;
            match improved {
                Some((zn, en, shape_n)) => {
                    z = zn;
                    decoded = shape_n;
                    if e0 - en <= TOLERANCE * e0 {
                        break;
                    }
                }
                None => break,
            }
        }
        let mean =
            |s: &[Vec3], c: usize| self.vertices.iter().map(|&v| s[v][c]).sum::<f64>() / self.vertices.len() as f64;
        let t: [f64; 3] = std::array::from_fn(|c| mean(shape, c) - mean(&decoded, c));
        let out: Vec<Vec3> = decoded.into_iter().map(|p| [p[0] + t[0], p[1] + t[1], p[2] + t[2]]).collect();
        if out.iter().flatten().any(|v| !v.is_finite()) || z.iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical("the fitted code or shape is not finite".into()));
        }
        Ok((z, out))
    }

    /// Codes and reconstructions of every frame: the encoder's code, then [`Self::fit`].
    pub fn fit_frames(&self, frames: &MeshSequence) -> Result<FittedFrames> {
        let start = self.artifact.encode_frames(frames)?;
        self.fit_from(frames, &start, |_| {})
    }

    /// [`Self::fit`] of every frame from the given start codes (one per frame); `done(i)` is
    /// called after frame i.
    pub fn fit_from(
        &self,
        frames: &MeshSequence,
        start: &[Vec<f64>],
        mut done: impl FnMut(usize),
    ) -> Result<FittedFrames> {
        if start.len() != frames.n_frames() {
            return Err(Error::Invalid(format!("{} start codes for {} frames", start.len(), frames.n_frames())));
        }
        let mut codes = Vec::with_capacity(frames.n_frames());
        let mut shapes = Vec::with_capacity(frames.n_frames());
        for (i, (shape, z0)) in frames.frames.iter().zip(start).enumerate() {
            let (z, p) = self.fit(shape, z0)?;
            codes.push(z);
            shapes.push(p);
            done(i);
        }
        Ok((codes, shapes))
    }
}

/// Positions of `vertices` of `shape`, minus their mean, flattened (3 per vertex).
fn centre(vertices: &[usize], shape: &[Vec3]) -> Vec<f64> {
    let m = vertices.len() as f64;
    let c: [f64; 3] = std::array::from_fn(|d| vertices.iter().map(|&v| shape[v][d]).sum::<f64>() / m);
    vertices.iter().flat_map(|&v| (0..3).map(move |d| shape[v][d] - c[d])).collect()
}
