//! The autoencoder encoder's vertex steps (`encoder_steps`): after the network's code z₀ (its
//! encoder and residual passes), a few Gauss–Newton / Levenberg–Marquardt steps on
//!
//! ```text
//! E(z) = ‖c(p(z)) − c(t)‖² + λ‖z − z₀‖²,    λ = γ · tr(JᵀJ)/K at z₀,  γ = STEP_GAMMA
//! ```
//!
//! where p(z) is the decoded, ACAP-reconstructed shape (N × 3, the model's space), t the shape
//! being encoded, c(·) the centring on the mean (Erms' centroid alignment) and J = ∂c(p)/∂z
//! (3N × K). That is the centroid-aligned vertex error the user measures, the same objective as
//! `encode --fit` with every vertex ([`super::ae_fit::AeFitEncoder`]), but each step is cheap:
//!
//! - the decoder's Jacobian ∂x̂/∂z (9N × K) is exact, one forward-mode pass with one lane per
//!   dimension ([`crate::nn::latent_fit::DecoderVjp::jacobian`]), not K + 1 decodes;
//! - the ACAP decoding is affine in the per-vertex transforms T_i = exp(logR_i)·S_i
//!   ([`crate::representation::acap::Acap::decode_transforms`]), so column k of J is the
//!   decoding's linear part ([`crate::representation::acap::Acap::decode_transforms_linear_many`],
//!   the K columns in one batched solve with the decoder's factor) of the transforms' tangent δT_i = Σ_q ∂T_i/∂f_q · ∂f_q/∂x̂ ·
//!   J_x[i, q; k], where ∂T/∂f is closed form (S) and central differences (R), per vertex;
//! - a trial step costs one decode of one code and one solve.
//!
//! A step is taken only when it lowers E, so the result is never worse than the network's code
//! on the objective. Another Jacobian is evaluated only while the previous one's last chord step
//! still lowered E by [`JACOBIAN_TOLERANCE`] (0.5 %) or more: where the linearisation holds
//! (SCAPE) one Jacobian is all, where it does not (the cactus) two or three; `encoder_steps`
//! caps them. Why it is needed: the network is trained on ACAP features, where a small
//! rotation error at a joint weighs as much as one at a fingertip but moves the whole limb; on
//! shapes it has not seen, its code (and the best code in feature space, measured: within 1 %
//! of it on SCAPE and horse gallop) reconstructs about twice as far from the shape as the best
//! code in vertex space (docs/autoencoder-encoder-steps.md).
//!
//! Meshes in several pieces: each piece's translation is read off the shape (module docs of
//! [`super::autoencoder`]); the steps change the network's K dimensions only and measure the
//! error of the whole shape, each piece centred by the decoder's placement. Only one-piece
//! meshes take the steps at present ([`vertex_steps_apply`]).

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::ae_fit::damped_step;
use super::autoencoder::AeArtifact;
use crate::error::{Error, Result};
use crate::math::mat3::Mat3;
use crate::mesh::Vec3;
use crate::nn::latent_fit::{DecoderVjp, JacobianScratch};
use crate::representation::acap::Acap;

/// Dimensionless pull towards the network's code (λ = γ · tr(JᵀJ)/K).
pub const STEP_GAMMA: f64 = 1e-3;

/// Relative decrease of E below which the steps stop early.
const TOLERANCE: f64 = 1e-4;

/// Relative decrease of E by the last chord step below which no further Jacobian is evaluated:
/// the linearisation still holds and one more Gauss–Newton step would move E by less than this
/// (validation frames, docs/autoencoder-encoder-steps.md: the last chord step lowers E by at most
/// 0.11 % on SCAPE 31–36, where a second Jacobian buys 0.03 % of Erms, and by at least 0.93 % on
/// the cactus, where it buys 4 %).
pub const JACOBIAN_TOLERANCE: f64 = 5e-3;

/// Steps that reuse a Jacobian (with the residual of the new code) before the next is
/// evaluated: a chord step costs one decode and one solve, a Jacobian K solves.
pub const CHORD_STEPS: usize = 2;

/// Whether a model's encoder takes vertex steps: the ACAP representation on a mesh in one piece.
pub fn vertex_steps_apply(artifact: &AeArtifact) -> bool {
    artifact.representation.acap().is_some() && artifact.representation.pieces().is_none()
}

/// Vertex steps of one model (see the module docs). Build once per encoding call.
pub struct VertexSteps<'a> {
    acap: &'a Acap,
    decoder: &'a DecoderVjp,
    /// Per feature dimension: (∂f/∂x̂, centre) of the scaling's inverse.
    unscale: [(f64, f64); 9],
    steps: usize,
}

/// What [`VertexSteps::refine`] did to one code.
#[derive(Debug, Clone, PartialEq)]
pub struct StepReport {
    /// Centroid-aligned squared vertex error Σ‖·‖² of the start code (model space).
    pub start_error: f64,
    /// The same of the returned code.
    pub error: f64,
    /// Jacobians evaluated.
    pub steps: usize,
    /// Per Jacobian: the relative decrease of E by its last accepted (chord) step, what decides
    /// whether another Jacobian is evaluated ([`JACOBIAN_TOLERANCE`]).
    pub gains: Vec<f64>,
}

impl<'a> VertexSteps<'a> {
    /// The steps of `artifact` (which must take them: [`vertex_steps_apply`]), at most `steps`
    /// Jacobians per code.
    pub fn new(artifact: &'a AeArtifact, decoder: &'a DecoderVjp, steps: usize) -> Result<Self> {
        let acap = artifact
            .representation
            .acap()
            .filter(|_| artifact.representation.pieces().is_none())
            .ok_or_else(|| Error::Invalid("encoder steps: the model is not ACAP on a mesh in one piece".into()))?;
        let unscale = artifact.header.scaling.inverse_affine_array::<9>()?;
        Ok(VertexSteps { acap, decoder, unscale, steps })
    }

    /// Per-vertex transforms T_i of scaled features x̂ (9N).
    fn transforms(&self, xh: &[f64]) -> Vec<Mat3> {
        let map = self.acap.map();
        xh.chunks_exact(9).map(|v| map.transform(&self.unscaled(v))).collect()
    }

    fn unscaled(&self, v: &[f64]) -> [f64; 9] {
        std::array::from_fn(|q| v[q] * self.unscale[q].0 + self.unscale[q].1)
    }

    /// Centred reconstruction (3N, vertex-major) of a code.
    fn centred_shape(&self, z: &[f64]) -> Result<Vec<f64>> {
        let xh = self.decoder.decode(z)?;
        Ok(centred(&self.acap.decode_transforms(&self.transforms(&xh))?))
    }

    /// [`Self::refine`] from whichever of `starts` (codes of K numbers, at least one)
    /// reconstructs `target` with the lowest centroid-aligned error (one decode and one solve
    /// each): the network's code with and without its residual passes, which on a shape far
    /// from the training set can make it worse.
    pub fn refine_best(&self, starts: &[&[f64]], target: &[Vec3]) -> Result<(Vec<f64>, StepReport)> {
        let goal = centred(target);
        let mut best: Option<(f64, &[f64])> = None;
        for &z in starts {
            let p = self.centred_shape(z)?;
            if p.len() != goal.len() {
                return Err(Error::Invalid(format!(
                    "encoder steps: {} target vertices, the model has {}",
                    target.len(),
                    p.len() / 3
                )));
            }
            let e = squared_distance(&p, &goal);
            if best.is_none_or(|(b, _)| e < b) {
                best = Some((e, z));
            }
        }
        let (_, z0) = best.ok_or_else(|| Error::Invalid("encoder steps: no start code".into()))?;
        self.refine(z0, target)
    }

    /// The code after at most `steps` Gauss–Newton steps from `z0` towards `target` (N
    /// positions in the model's space, i.e. after the unit box), and what happened.
    pub fn refine(&self, z0: &[f64], target: &[Vec3]) -> Result<(Vec<f64>, StepReport)> {
        let n = self.acap.n_vertices();
        let k = self.decoder.n_components();
        if target.len() != n || z0.len() != k {
            return Err(Error::Invalid(format!(
                "encoder steps: {} target vertices and a code of {} numbers; the model has {n} and {k}",
                target.len(),
                z0.len()
            )));
        }
        let goal = centred(target);
        let error = |p: &[f64]| squared_distance(p, &goal);
        let mut z = z0.to_vec();
        let mut lambda: Option<f64> = None;
        let mut mu = 1e-3;
        let mut start_error = None;
        let mut current_error = f64::NAN;
        let mut steps = 0;
        let mut scratch = JacobianScratch::default();
        let mut gains = Vec::new();
        while steps < self.steps {
            steps += 1;
            let (xh, stride) = self.decoder.jacobian_with(&z, &mut scratch)?;
            let jx = scratch.jacobian();
            let fs: Vec<[f64; 9]> = xh.chunks_exact(9).map(|v| self.unscaled(v)).collect();
            let map = self.acap.map();
            let t: Vec<Mat3> = fs.iter().map(|f| map.transform(f)).collect();
            let p = centred(&self.acap.decode_transforms(&t)?);
            let data = error(&p);
            start_error.get_or_insert(data);
            current_error = data;
            // ∂T_i/∂x̂_q per vertex.
            let dt: Vec<[Mat3; 9]> = fs
                .iter()
                .map(|f| {
                    let mut m = map.transform_jacobian(f);
                    for (q, mq) in m.iter_mut().enumerate() {
                        mq.iter_mut().flatten().for_each(|v| *v *= self.unscale[q].0);
                    }
                    m
                })
                .collect();
            // Column k of J: the linear part of the decoding of δT = Σ_q ∂T/∂x̂_q · J_x[·, q; k],
            // centred; the K solves batched (one per half of the columns, on the rayon pool).
            let tangents: Vec<Vec<Mat3>> = (0..k)
                .into_par_iter()
                .map(|kk| {
                    dt.iter()
                        .enumerate()
                        .map(|(i, m)| {
                            let mut o = [[0.0; 3]; 3];
                            for (q, mq) in m.iter().enumerate() {
                                let s = jx[(9 * i + q) * stride + kk] as f64;
                                if s != 0.0 {
                                    for a in 0..3 {
                                        for b in 0..3 {
                                            o[a][b] += mq[a][b] * s;
                                        }
                                    }
                                }
                            }
                            o
                        })
                        .collect()
                })
                .collect();
            let half = k.div_ceil(2).max(1);
            let solved: Vec<Vec<Vec<Vec3>>> = tangents
                .par_chunks(half)
                .map(|sets| self.acap.decode_transforms_linear_many(sets))
                .collect::<Result<_>>()?;
            let columns: Vec<Vec<f64>> = solved.into_iter().flatten().map(|dp| centred(&dp)).collect();
            // JᵀJ and Jᵀr (J: 3N × K, column-major as the columns above).
            let flat: Vec<f64> = columns.concat();
            let jm = MatRef::from_column_major_slice(&flat, 3 * n, k);
            let mut gram = vec![0.0f64; k * k];
            matmul(
                MatMut::from_column_major_slice_mut(&mut gram, k, k),
                Accum::Replace,
                jm.transpose(),
                jm,
                1.0,
                Par::Seq,
            );
            let jtj = DMatrix::from_column_slice(k, k, &gram);
            let lam = *lambda.get_or_insert_with(|| STEP_GAMMA * jtj.trace() / k as f64);
            let pull = |z: &[f64]| lam * z.iter().zip(z0).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
            // Levenberg–Marquardt from z with this Jacobian, then up to CHORD_STEPS more steps
            // with the same Jacobian and the new residual (each costs one trial decode).
            let mut here = (z.clone(), p, data + pull(&z));
            let mut improved = false;
            let mut converged = false;
            // Relative decrease of E by the last accepted chord step (1: none taken yet).
            let mut last_decrease = 1.0;
            for _ in 0..=CHORD_STEPS {
                let (zc, pc, e0) = &here;
                let g = DVector::from_fn(k, |kk, _| {
                    let col = &columns[kk];
                    -col.iter().zip(pc.iter().zip(&goal)).map(|(j, (a, b))| j * (a - b)).sum::<f64>()
                        - lam * (zc[kk] - z0[kk])
                });
                // A code the decoder cannot take (not finite) is a rejected step, not an error.
                let accepted = damped_step(&jtj, &g, lam, zc, *e0, &mut mu, 1e6, |zn| {
                    Ok(
                        if zn.iter().all(|v| v.is_finite())
                            && let Ok(pn) = self.centred_shape(zn)
                        {
                            Some((error(&pn) + pull(zn), pn))
                        } else {
                            None
                        },
                    )
                })?;
                let Some((zn, en, pn)) = accepted else { break };
                last_decrease = (e0 - en) / e0;
                converged = e0 - en <= TOLERANCE * e0;
                here = (zn, pn, en);
                improved = true;
                if converged {
                    break;
                }
            }
            if !improved {
                gains.push(0.0);
                break;
            }
            current_error = error(&here.1);
            z = here.0;
            gains.push(last_decrease);
            if converged || last_decrease < JACOBIAN_TOLERANCE {
                break;
            }
        }
        let start_error = start_error.unwrap_or(f64::NAN);
        Ok((z, StepReport { start_error, error: current_error, steps, gains }))
    }
}

/// Σ (a_i − b_i)².
fn squared_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Positions (N) centred on their mean, flattened (3N, vertex-major).
fn centred(p: &[Vec3]) -> Vec<f64> {
    let n = p.len().max(1) as f64;
    let c: [f64; 3] = std::array::from_fn(|d| p.iter().map(|v| v[d]).sum::<f64>() / n);
    p.iter().flat_map(|v| (0..3).map(move |d| v[d] - c[d])).collect()
}
