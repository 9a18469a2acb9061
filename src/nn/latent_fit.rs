//! Decoder vector–Jacobian products for fitting latent codes (autoencoder posing, sparse
//! control points).
//!
//! [`DecoderVjp`] decodes one latent code z (K numbers) to scaled ACAP features x̂ (N × 9,
//! vertex-major, the same numbers as [`super::Autoencoder::decode`]) and back-propagates any
//! number of cotangent vectors u_m (N × 9 each) to ∂⟨u_m, x̂(z)⟩/∂z = J(z)ᵀ u_m, where J is the
//! decoder Jacobian (9N × K). The cotangents may depend on the decoded features (they are asked
//! for after the forward pass), which is what a chain rule through a nonlinear feature → vertex
//! map needs. With 3 cotangents per constrained vertex this yields the full Jacobian of the
//! constrained positions in one batched forward + backward pass (the M lanes share the code).
//!
//! Same hand-written f32 kernels as training and inference ([`super::kernels`]); the code and
//! features are f64 at the interface.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

use super::data::{WIDTH, shape_from_vcb};
use super::engine::Weights;
use super::inference::Autoencoder;
use super::kernels::{
    conv_rows, input_grad_rows, mean_rows, mean_rows_transpose_add, padded_width, tanh_backward, transpose9,
};
use super::neighbors::NeighborIndex;
use crate::error::{Error, Result};

/// Callback of [`DecoderVjp::decode_vjp`]: decoded features (N × 9) → M cotangents (N × 9 each).
pub type Cotangents<'c> = &'c mut dyn FnMut(&[f64]) -> Result<Vec<Vec<f64>>>;

/// Decoder forward pass plus vector–Jacobian products for one code at a time. Build once per
/// model ([`DecoderVjp::new`] copies the parameters), then call per evaluation.
#[derive(Debug, Clone)]
pub struct DecoderVjp {
    weights: Weights,
    neighbors: NeighborIndex,
}

/// Decoder activations of one batched forward pass (VCB layout, `bp` lanes).
struct Forward {
    bp: usize,
    /// G_0 = Cᵀz … G_L = x̂.
    dec: Vec<Vec<f32>>,
}

impl DecoderVjp {
    /// Copies the parameters and neighbour index of a trained model.
    pub fn new(model: &Autoencoder) -> Result<Self> {
        Ok(DecoderVjp { weights: model.weights().clone(), neighbors: model.neighbors().clone() })
    }

    /// Latent dimension K.
    pub fn n_components(&self) -> usize {
        self.weights.k
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.weights.n
    }

    fn check_code(&self, z: &[f64]) -> Result<()> {
        let k = self.weights.k;
        if z.len() != k || z.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!("latent code must be {k} finite numbers (got {} values)", z.len())));
        }
        Ok(())
    }

    fn forward(&self, z: &[f64], lanes: usize) -> Forward {
        let (n, k) = (self.weights.n, self.weights.k);
        let bp = padded_width(lanes.max(1));
        let r = 9 * bp;
        let l = self.weights.layers.len();
        let mut zt = vec![0.0f32; k * bp];
        for (kk, &v) in z.iter().enumerate() {
            zt[kk * bp..kk * bp + lanes.max(1)].fill(v as f32);
        }
        let mut dec: Vec<Vec<f32>> = (0..=l).map(|_| vec![0.0f32; n * r]).collect();
        let mut mean = vec![0.0f32; n * r];
        matmul(
            MatMut::from_row_major_slice_mut(&mut dec[0], 9 * n, bp),
            Accum::Replace,
            MatRef::from_row_major_slice(&self.weights.c, k, 9 * n).transpose(),
            MatRef::from_row_major_slice(&zt, k, bp),
            1.0f32,
            Par::Seq,
        );
        for d in 0..l {
            let lw = &self.weights.layers[l - 1 - d];
            let (prev, rest) = dec.split_at_mut(d + 1);
            mean_rows(&self.neighbors, &prev[d], &mut mean, r);
            conv_rows(&transpose9(&lw.wp), &prev[d], &transpose9(&lw.wn), &mean, &lw.bd, &mut rest[0], bp, true);
        }
        Forward { bp, dec }
    }

    /// Scaled features x̂(z) (N × 9, vertex-major) of one code z (K numbers).
    pub fn decode(&self, z: &[f64]) -> Result<Vec<f64>> {
        self.check_code(z)?;
        let f = self.forward(z, 1);
        Ok(shape_from_vcb(f.dec.last().unwrap(), f.bp, 0))
    }

    /// Decodes z (K numbers), asks `cotangents` for M vectors u_m (N × 9 each, given the decoded
    /// features x̂, N × 9) and returns (x̂, [J(z)ᵀ u_m for every m], K numbers each).
    ///
    /// `m` is the number of cotangents `cotangents` will return (it sizes the batch).
    pub fn decode_vjp(&self, z: &[f64], m: usize, cotangents: Cotangents<'_>) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
        self.check_code(z)?;
        let (n, k) = (self.weights.n, self.weights.k);
        let l = self.weights.layers.len();
        let Forward { bp, dec } = self.forward(z, m);
        let r = 9 * bp;
        let features = shape_from_vcb(&dec[l], bp, 0);
        let u = cotangents(&features)?;
        if u.len() != m {
            return Err(Error::Invalid(format!("decode_vjp: {} cotangents, {m} announced", u.len())));
        }
        let mut d_a = vec![0.0f32; n * r];
        for (j, uj) in u.iter().enumerate() {
            if uj.len() != n * WIDTH {
                return Err(Error::Invalid(format!("decode_vjp: cotangent {j} has {} values, need {n} × 9", uj.len())));
            }
            if let Some(p) = uj.iter().position(|v| !v.is_finite()) {
                return Err(Error::Numerical(format!("decode_vjp: cotangent {j} is not finite at {p}")));
            }
            for (row, &v) in uj.iter().enumerate() {
                d_a[row * bp + j] = v as f32;
            }
        }
        let mut d_b = vec![0.0f32; n * r];
        let mut d_m = vec![0.0f32; n * r];
        for d in (0..l).rev() {
            let lw = &self.weights.layers[l - 1 - d];
            tanh_backward(&dec[d + 1], &mut d_a);
            // The decoder conv uses W_pointᵀ, W_nbᵀ; its input gradient uses their transposes.
            input_grad_rows(&lw.wp, &lw.wn, &d_a, &mut d_b, &mut d_m, bp);
            mean_rows_transpose_add(&self.neighbors, &d_m, &mut d_b, r);
            std::mem::swap(&mut d_a, &mut d_b);
        }
        // dZᵀ = C·dG_0.
        let mut dzt = vec![0.0f32; k * bp];
        matmul(
            MatMut::from_row_major_slice_mut(&mut dzt, k, bp),
            Accum::Replace,
            MatRef::from_row_major_slice(&self.weights.c, k, 9 * n),
            MatRef::from_row_major_slice(&d_a, 9 * n, bp),
            1.0f32,
            Par::Seq,
        );
        let grads = (0..m).map(|j| (0..k).map(|kk| dzt[kk * bp + j] as f64).collect()).collect();
        Ok((features, grads))
    }
}
