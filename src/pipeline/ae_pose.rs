//! Direct-manipulation posing of a trained autoencoder: find a latent code z whose decoded,
//! reconstructed mesh puts a few constrained vertices at target positions.
//!
//! ```text
//! min_z  Σ_a ‖p_a(z) − t_a‖² + (z − z0)ᵀ Λ (z − z0),      Λ = γ · G   (or γ · (trace G / K) · I)
//! ```
//!
//! where p_a(z) is constrained vertex a of `ACAP-decode(unscale(decoder(z)))` in the model's
//! space (unit box when the model was trained with `data.unit_box`; targets are given in data
//! units and mapped there) and G = J_allᵀJ_all / N the shape metric of the code at the start z0
//! (J_all the Jacobian of all N decoded vertices, by forward differences of
//! [`AeArtifact::decode_codes`]): the pull is the whole shape's mean squared motion
//! ([`PosePrior::Shape`], the linear models' pull, linearised at the start), or the same
//! strength on the code itself ([`PosePrior::Weights`], the default). Either way γ is
//! dimensionless and the pull's strength does not depend on where the pins are (like
//! [`crate::methods::posing::Pull`]).
//!
//! **Gradient.** The ACAP decoder is affine in the per-vertex gradients T_i = exp(logR_i)·S_i
//! and treats the coordinates alike: p_a = Σ_i T_i g_{a,i} + κ_a with g_{a,i} ∈ R³. The weights
//! g_a (N × 3) come from one adjoint solve with the decoder's factor per constrained vertex
//! ([`Acap::decode_transforms_adjoint`]), computed once in [`AePoser::new`]; κ_a is the
//! reference centroid. Per evaluation, p_a costs O(N); its gradient with respect to the scaled
//! features is chained per vertex through T_i(f_i) (S part exact, exp part by central
//! differences of Rodrigues' formula, step 1e-6) and the feature scaling, then back through the
//! network decoder with [`DecoderVjp`] (one batched backward pass for the 3·C rows of J).
//!
//! **Pieces.** On a multi-piece mesh the code also holds the pieces' translations τ (after the
//! network's K dimensions, see [`super::autoencoder`]); placing the pieces is affine in τ, so
//! p_a gains `Σ_r ∂x_a/∂t_r · τ_r` ([`crate::representation::piece_placement::PiecePlacement::derivative`]) and J constant columns.
//!
//! **Solver.** Gauss–Newton on the K unknowns (normal equations JᵀJ + Λ, Cholesky) with
//! backtracking on the true objective; stops when the objective decreases by less than
//! `tolerance` (relative) or after `max_iterations`.
//!
//! Factor once / solve many: build an [`AePoser`] per model and constrained-vertex set (C
//! adjoint solves), then call [`AePoser::solve`] per drag event or per set of control points.

use faer::Mat;
use faer::linalg::solvers::Solve;
use serde::{Deserialize, Serialize};

use super::autoencoder::AeArtifact;
use crate::error::{Error, Result};
use crate::math::mat3::Mat3;
use crate::mesh::Vec3;
use crate::methods::posing::{PosePrior, Pull, pull_matrix};
use crate::model::Model;
use crate::nn::latent_fit::DecoderVjp;
use crate::representation::acap::{Acap, FeatureMap};

/// Hyperparameters of [`AePoser`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AePoseConfig {
    /// γ ≥ 0 (dimensionless): pull towards the start code. Default 0.025.
    pub gamma: f64,
    /// Gauss–Newton iterations at most (≥ 1). Default 30.
    pub max_iterations: usize,
    /// Stop when the objective decreases by less than this fraction in one iteration (> 0).
    /// Default 1e-6.
    pub tolerance: f64,
    /// Stop after the iteration that passes this wall time (None: no limit).
    #[serde(skip)]
    pub time_limit: Option<std::time::Duration>,
    /// What the pull measures (module docs). Default: the shape.
    #[serde(default)]
    pub prior: PosePrior,
}

impl Default for AePoseConfig {
    fn default() -> Self {
        AePoseConfig { gamma: 0.025, max_iterations: 30, tolerance: 1e-6, time_limit: None, prior: PosePrior::Shape }
    }
}

impl AePoseConfig {
    /// Checks the ranges (errors carry the bad value).
    pub fn validate(&self) -> Result<()> {
        if !(self.gamma.is_finite() && self.gamma >= 0.0) {
            return Err(Error::config("gamma", format!("gamma ({}) must be finite and non-negative", self.gamma)));
        }
        if self.max_iterations == 0 {
            return Err(Error::config("max_iterations", "max_iterations (0) must be at least 1"));
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(Error::config("tolerance", format!("tolerance ({}) must be finite and > 0", self.tolerance)));
        }
        Ok(())
    }
}

/// Outcome details of one [`AePoser::solve_report`].
#[derive(Debug, Clone, PartialEq)]
pub struct AePoseReport {
    /// Gauss–Newton iterations run.
    pub iterations: usize,
    /// Σ_a ‖p_a − t_a‖² at the start code (model units²).
    pub start_cost: f64,
    /// Σ_a ‖p_a − t_a‖² at the returned code (model units²).
    pub final_cost: f64,
}

/// Latent-code posing of an autoencoder for a fixed set of constrained vertices (see the module
/// docs). Build once per model and vertex set; [`AePoser::solve`] per drag event.
pub struct AePoser<'a> {
    artifact: &'a AeArtifact,
    decoder: DecoderVjp,
    vertices: Vec<usize>,
    /// Per constrained vertex: g_a (N × 3) of p_a = Σ_i T_i g_{a,i} + κ_a.
    g: Vec<Vec<Vec3>>,
    kappa: Vec<Vec3>,
    /// Multi-piece meshes: per constrained vertex, ∂p_a/∂τ_j (a multiple of the identity) for
    /// each translated piece j (code dimension K + 3j + c); empty otherwise.
    piece_derivatives: Vec<Vec<f64>>,
    /// Per feature dimension (9): ∂f/∂x̂ = 1/a of the scaling, and its centre c.
    unscale: [(f64, f64); 9],
    /// What the features are (how they make T_i).
    map: FeatureMap,
    config: AePoseConfig,
}

impl<'a> AePoser<'a> {
    /// Prepares posing of `artifact` with the constrained `vertices` (indices into the rest
    /// mesh, distinct or not). Runs one adjoint solve per vertex. Errors on an empty or
    /// out-of-range vertex list, a model that is not ACAP, or a bad config.
    pub fn new(artifact: &'a AeArtifact, vertices: &[usize], config: &AePoseConfig) -> Result<Self> {
        config.validate()?;
        let n = artifact.rest.n_vertices();
        if vertices.is_empty() {
            return Err(Error::Invalid("autoencoder posing: no constrained vertex given".into()));
        }
        if let Some(&v) = vertices.iter().find(|&&v| v >= n) {
            return Err(Error::Invalid(format!(
                "autoencoder posing: constrained vertex {v} out of range ({n} vertices)"
            )));
        }
        let acap: &Acap = artifact.representation.acap().ok_or_else(|| {
            Error::Invalid(format!(
                "autoencoder posing needs the ACAP representation, the model uses {}",
                artifact.representation.kind().name()
            ))
        })?;
        let decoder = DecoderVjp::new(&artifact.model)?;
        if decoder.n_vertices() != n {
            return Err(Error::Invalid(format!("autoencoder has {} vertices, rest mesh {n}", decoder.n_vertices())));
        }
        let zero_t = acap.decode_transforms(&vec![[[0.0; 3]; 3]; n])?;
        let mut g = Vec::with_capacity(vertices.len());
        let mut kappa = Vec::with_capacity(vertices.len());
        for &v in vertices {
            let mut grad = vec![[0.0; 3]; n];
            grad[v] = [1.0, 0.0, 0.0];
            let adj = acap.decode_transforms_adjoint(&grad)?;
            g.push(adj.iter().map(|t| t[0]).collect::<Vec<Vec3>>());
            kappa.push(zero_t[v]);
        }
        // Feature scaling x̂ = (f − c)·a per dimension: recover (1/a, c) from the inverse map.
        let unscale = artifact.header.scaling.inverse_affine_array::<9>()?;
        let pieces = super::autoencoder::translated_pieces(&artifact.representation);
        let piece_derivatives = match artifact.representation.pieces() {
            Some((placement, _)) => {
                let of = placement.piece_of_vertex();
                let d = |v: usize| -> Vec<f64> {
                    pieces
                        .iter()
                        .map(|&r| if of[v] == usize::MAX { 0.0 } else { placement.derivative(of[v], r) })
                        .collect()
                };
                vertices.iter().map(|&v| d(v)).collect()
            }
            None => Vec::new(),
        };
        Ok(AePoser {
            artifact,
            decoder,
            vertices: vertices.to_vec(),
            g,
            kappa,
            piece_derivatives,
            unscale,
            map: acap.map(),
            config: *config,
        })
    }

    /// The constrained vertices.
    pub fn vertices(&self) -> &[usize] {
        &self.vertices
    }

    /// Unscaled features f (N × 9) from scaled x̂.
    fn unscaled(&self, xs: &[f64]) -> Vec<f64> {
        xs.chunks_exact(9).flat_map(|v| (0..9).map(move |q| v[q] * self.unscale[q].0 + self.unscale[q].1)).collect()
    }

    /// Constrained positions (model units) from scaled features.
    fn positions(&self, xs: &[f64]) -> Vec<Vec3> {
        let f = self.unscaled(xs);
        let t: Vec<Mat3> = f.chunks_exact(9).map(|v| self.map.transform(v)).collect();
        self.g
            .iter()
            .zip(&self.kappa)
            .map(|(g, k)| {
                let mut p = *k;
                for (ti, gi) in t.iter().zip(g) {
                    for (c, pc) in p.iter_mut().enumerate() {
                        *pc += ti[c][0] * gi[0] + ti[c][1] * gi[1] + ti[c][2] * gi[2];
                    }
                }
                p
            })
            .collect()
    }

    /// Network dimensions K (the rest of a code are piece translations).
    fn k_network(&self) -> usize {
        self.decoder.n_components()
    }

    /// Adds the pieces' placement to constrained positions of the network part.
    fn place(&self, p: &mut [Vec3], z: &[f64]) {
        let tau = &z[self.k_network()..];
        for (pa, d) in p.iter_mut().zip(&self.piece_derivatives) {
            for (j, dj) in d.iter().enumerate() {
                for c in 0..3 {
                    pa[c] += dj * tau[3 * j + c];
                }
            }
        }
    }

    /// Constrained positions (model units) of code `z`.
    fn eval(&self, z: &[f64]) -> Result<Vec<Vec3>> {
        let mut p = self.positions(&self.decoder.decode(&z[..self.k_network()])?);
        self.place(&mut p, z);
        Ok(p)
    }

    /// Constrained positions (model units) and their Jacobian with respect to z (3·C rows of
    /// the code's length, row 3a + c = ∂p_a[c]/∂z).
    pub fn positions_and_jacobian(&self, z: &[f64]) -> Result<(Vec<Vec3>, Vec<Vec<f64>>)> {
        let nv = self.vertices.len();
        let mut pos = Vec::new();
        let (_, mut jac) = self.decoder.decode_vjp(&z[..self.k_network()], 3 * nv, &mut |xs: &[f64]| {
            pos = self.positions(xs);
            let f = self.unscaled(xs);
            let n = f.len() / 9;
            let mut u = vec![vec![0.0; 9 * n]; 3 * nv];
            for i in 0..n {
                let dt = self.map.transform_jacobian(&f[9 * i..9 * i + 9]);
                for (a, g) in self.g.iter().enumerate() {
                    let gi = g[i];
                    if gi == [0.0; 3] {
                        continue;
                    }
                    for (q, dtq) in dt.iter().enumerate() {
                        let s = self.unscale[q].0;
                        for c in 0..3 {
                            u[3 * a + c][9 * i + q] = s * (dtq[c][0] * gi[0] + dtq[c][1] * gi[1] + dtq[c][2] * gi[2]);
                        }
                    }
                }
            }
            Ok(u)
        })?;
        self.place(&mut pos, z);
        let n_tau = z.len() - self.k_network();
        for (row, r) in jac.iter_mut().enumerate() {
            let (a, c) = (row / 3, row % 3);
            r.extend((0..n_tau).map(|i| if i % 3 == c { self.piece_derivatives[a][i / 3] } else { 0.0 }));
        }
        Ok((pos, jac))
    }

    /// Constrained positions in data units for code `z` (cheap: no full reconstruction).
    pub fn constrained_positions(&self, z: &[f64]) -> Result<Vec<Vec3>> {
        let ub = self.artifact.header.unit_box;
        Ok(self.eval(z)?.into_iter().map(|p| ub.invert(p)).collect())
    }

    /// The shape metric G = J_allᵀJ_all / N (model units², code length squared) at the code
    /// `z0`: forward differences of every decoded vertex along each code dimension, the step
    /// 10⁻³ of that dimension's range over the training codes. Cached for the last few start
    /// codes (a drag in the viewer poses from the same start many times).
    pub fn start_metric(&self, z0: &[f64]) -> Result<Mat<f64>> {
        let a = self.artifact;
        let k = z0.len();
        let ub = a.header.unit_box;
        let x0: Vec<Vec3> = a.decode_codes(&[z0.to_vec()])?.remove(0).into_iter().map(|p| ub.apply(p)).collect();
        let key = {
            use std::hash::{Hash, Hasher};
            let mut h = std::hash::DefaultHasher::new();
            z0.iter().for_each(|x| x.to_bits().hash(&mut h));
            x0.iter().flatten().for_each(|x| x.to_bits().hash(&mut h));
            h.finish()
        };
        let cache = METRIC_CACHE.get_or_init(Default::default);
        if let Some((_, g)) = cache.lock().ok().and_then(|c| c.iter().find(|e| e.0 == key).cloned()) {
            return Ok(g);
        }
        let train = Model::train_weights(a).unwrap_or_default();
        let steps: Vec<f64> = (0..k)
            .map(|i| {
                let (lo, hi) =
                    train.iter().filter_map(|c| c.get(i)).fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
                let range = if hi > lo { hi - lo } else { 1.0 };
                1e-3 * range
            })
            .collect();
        let codes: Vec<Vec<f64>> = (0..k)
            .map(|i| {
                let mut z = z0.to_vec();
                z[i] += steps[i];
                z
            })
            .collect();
        let shapes = a.decode_codes(&codes)?;
        let cols: Vec<Vec<f64>> = shapes
            .iter()
            .zip(&steps)
            .map(|(x, h)| {
                x.iter()
                    .zip(&x0)
                    .flat_map(|(p, q)| {
                        let p = ub.apply(*p);
                        (0..3).map(move |c| (p[c] - q[c]) / h)
                    })
                    .collect()
            })
            .collect();
        let g = crate::methods::posing::shape_metric(&cols);
        if let Ok(mut c) = cache.lock() {
            c.insert(0, (key, g.clone()));
            c.truncate(4);
        }
        Ok(g)
    }

    /// Posed code and mesh: `targets` (one per constrained vertex, data units), start code `z0`
    /// (K numbers, e.g. the current pose's). Returns (code z, all N positions in data units).
    pub fn solve(&self, targets: &[Vec3], z0: &[f64]) -> Result<(Vec<f64>, Vec<Vec3>)> {
        let (z, p, _) = self.solve_report(targets, z0)?;
        Ok((z, p))
    }

    /// [`AePoser::solve`] plus iteration count and start/final constraint cost.
    pub fn solve_report(&self, targets: &[Vec3], z0: &[f64]) -> Result<(Vec<f64>, Vec<Vec3>, AePoseReport)> {
        let nv = self.vertices.len();
        let k = self.artifact.n_dims();
        if targets.len() != nv {
            return Err(Error::Invalid(format!(
                "autoencoder posing: {} targets for {nv} constrained vertices",
                targets.len()
            )));
        }
        if let Some(i) = targets.iter().position(|t| t.iter().any(|x| !x.is_finite())) {
            return Err(Error::Invalid(format!("autoencoder posing: target {i} is not finite ({:?})", targets[i])));
        }
        if z0.len() != k || z0.iter().any(|x| !x.is_finite()) {
            return Err(Error::Invalid(format!("autoencoder posing: start code must be {k} finite numbers")));
        }
        let ub = self.artifact.header.unit_box;
        let t: Vec<Vec3> = targets.iter().map(|&p| ub.apply(p)).collect();
        let data_cost = |p: &[Vec3]| -> f64 {
            p.iter().zip(&t).map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>()).sum()
        };
        let mut z = z0.to_vec();
        let g = self.start_metric(z0)?;
        let pull = match self.config.prior {
            PosePrior::Shape => Pull::Shape(&g),
            PosePrior::Weights => Pull::Weights,
            PosePrior::Data => {
                return Err(Error::Invalid(
                    "`prior` data: the autoencoder's posing measures the pull by the shape or the code; use shape or weights"
                        .into(),
                ));
            }
        };
        let mean = (0..k).map(|i| g[(i, i)]).sum::<f64>() / k as f64;
        let lam = pull_matrix(&Mat::<f64>::zeros(k, k), self.config.gamma, pull, mean)?;
        let reg = |z: &[f64]| -> f64 {
            let d: Vec<f64> = z.iter().zip(z0).map(|(a, b)| a - b).collect();
            (0..k).map(|i| d[i] * (0..k).map(|j| lam[(i, j)] * d[j]).sum::<f64>()).sum()
        };
        let mut start_cost = f64::NAN;
        let mut cost = f64::NAN;
        let mut iterations = 0;
        let mut data = None;
        let started = std::time::Instant::now();
        for it in 0..self.config.max_iterations {
            if it > 0 && self.config.time_limit.is_some_and(|l| started.elapsed() >= l) {
                break;
            }
            let (p, jac) = self.positions_and_jacobian(&z)?;
            let dc = data_cost(&p);
            if it == 0 {
                start_cost = dc;
                cost = dc + reg(&z);
            }
            // Normal equations (JᵀJ + Λ) δ = −(Jᵀr + Λ(z − z0)).
            let r: Vec<f64> = p.iter().zip(&t).flat_map(|(a, b)| (0..3).map(move |c| a[c] - b[c])).collect();
            let mut h =
                Mat::<f64>::from_fn(k, k, |i, j| jac.iter().map(|row| row[i] * row[j]).sum::<f64>() + lam[(i, j)]);
            let md = (0..k).map(|i| h[(i, i)]).fold(0.0f64, f64::max);
            for i in 0..k {
                h[(i, i)] += 1e-12 * md + 1e-300;
            }
            let mut rhs = Mat::<f64>::from_fn(k, 1, |i, _| {
                -(jac.iter().zip(&r).map(|(row, ri)| row[i] * ri).sum::<f64>()
                    + (0..k).map(|j| lam[(i, j)] * (z[j] - z0[j])).sum::<f64>())
            });
            let llt = h.llt(faer::Side::Lower).map_err(|e| Error::Numerical(format!("autoencoder posing: {e:?}")))?;
            llt.solve_in_place(rhs.as_mut());
            let delta: Vec<f64> = (0..k).map(|i| rhs[(i, 0)]).collect();
            iterations = it + 1;
            // Backtracking on the true objective.
            let mut step = 1.0;
            let mut accepted = None;
            for _ in 0..12 {
                let zn: Vec<f64> = z.iter().zip(&delta).map(|(a, d)| a + step * d).collect();
                let dn = data_cost(&self.eval(&zn)?);
                let cn = dn + reg(&zn);
                if cn < cost {
                    accepted = Some((zn, cn, dn));
                    break;
                }
                step *= 0.5;
            }
            let Some((zn, cn, dn)) = accepted else { break };
            let decrease = (cost - cn) / cost.max(f64::MIN_POSITIVE);
            z = zn;
            cost = cn;
            data = Some(dn);
            if decrease < self.config.tolerance {
                break;
            }
        }
        // The data cost of the last accepted code (the start's when no step was taken).
        let final_cost = match data {
            Some(d) => d,
            None if start_cost.is_finite() => start_cost,
            None => data_cost(&self.eval(&z)?),
        };
        let positions = self.artifact.decode_codes(std::slice::from_ref(&z))?.remove(0);
        Ok((z, positions, AePoseReport { iterations, start_cost, final_cost }))
    }
}

/// [`AePoser::start_metric`]'s last few metrics, keyed by a hash of the start code and its
/// decoded shape.
static METRIC_CACHE: std::sync::OnceLock<std::sync::Mutex<Vec<CachedMetric>>> = std::sync::OnceLock::new();

/// One entry of [`METRIC_CACHE`]: (hash of the start code and shape, metric).
type CachedMetric = (u64, Mat<f64>);

/// One-shot [`AePoser`]: posed (code, data-unit positions) meeting `targets` at `vertices` from
/// `z0`.
pub fn pose_autoencoder(
    artifact: &AeArtifact,
    vertices: &[usize],
    targets: &[Vec3],
    z0: &[f64],
    config: &AePoseConfig,
) -> Result<(Vec<f64>, Vec<Vec3>)> {
    AePoser::new(artifact, vertices, config)?.solve(targets, z0)
}
