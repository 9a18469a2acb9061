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

use std::sync::OnceLock;

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
    /// [`DecoderVjp::linear_tangent`], built on first use.
    tangent: OnceLock<Vec<f32>>,
}

/// Buffers of [`DecoderVjp::jacobian_with`] (9N rows of the padded K lanes, three of them).
#[derive(Debug, Clone, Default)]
pub struct JacobianScratch {
    t: Vec<f32>,
    mean: Vec<f32>,
    next: Vec<f32>,
}

impl JacobianScratch {
    /// The Jacobian of the last [`DecoderVjp::jacobian_with`] (9N rows of `stride`).
    pub fn jacobian(&self) -> &[f32] {
        &self.t
    }
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
        Ok(DecoderVjp {
            weights: model.weights().clone(),
            neighbors: model.neighbors().clone(),
            tangent: OnceLock::new(),
        })
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
        let n = self.weights.n;
        let bp = padded_width(lanes.max(1));
        let r = 9 * bp;
        let l = self.weights.layers.len();
        // G_0 = Cᵀz (9N), the same in every used lane (one pass over C, not a GEMM over the
        // padded lanes).
        let mut g0 = vec![0.0f32; 9 * n];
        for (row, &v) in self.weights.c.chunks_exact(9 * n).zip(z) {
            let v = v as f32;
            g0.iter_mut().zip(row).for_each(|(g, &c)| *g += v * c);
        }
        let mut dec: Vec<Vec<f32>> = (0..=l).map(|_| vec![0.0f32; n * r]).collect();
        let used = lanes.max(1);
        for (out, &g) in dec[0].chunks_exact_mut(bp).zip(&g0) {
            out[..used].fill(g);
        }
        let mut mean = vec![0.0f32; n * r];
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

    /// Decodes z (K numbers) and returns (x̂, J, stride): the scaled features x̂ (N × 9,
    /// vertex-major) and the decoder Jacobian J = ∂x̂/∂z, 9N rows of `stride` numbers
    /// (row-major, column k for dimension k < K; `stride` ≥ K, the columns past K are zero),
    /// exact (forward-mode tangents through every layer, one lane per dimension), in f32.
    ///
    /// # Shapes
    /// `z`: K → x̂: 9N, J: 9N × `stride`.
    pub fn jacobian(&self, z: &[f64]) -> Result<(Vec<f64>, Vec<f32>, usize)> {
        let mut scratch = JacobianScratch::default();
        let (x, stride) = self.jacobian_with(z, &mut scratch)?;
        Ok((x, std::mem::take(&mut scratch.t), stride))
    }

    /// [`Self::jacobian`] in `scratch`'s buffers (kept between calls: no allocation after the
    /// first); J is `scratch.jacobian()`.
    pub fn jacobian_with(&self, z: &[f64], scratch: &mut JacobianScratch) -> Result<(Vec<f64>, usize)> {
        self.check_code(z)?;
        let (n, k) = (self.weights.n, self.weights.k);
        let l = self.weights.layers.len();
        let f = self.forward(z, 1);
        let bp = padded_width(k);
        let r = 9 * bp;
        let JacobianScratch { t, mean, next } = scratch;
        for b in [&mut *t, &mut *mean, &mut *next] {
            b.clear();
            b.resize(n * r, 0.0);
        }
        if l == 0 {
            t.copy_from_slice(self.linear_tangent());
        }
        for d in 0..l {
            // tanh′ = 1 − y² of this layer's output (lane 0 of the one-lane forward), times the
            // layer's linear map of the tangents; the first layer's does not depend on z.
            let y = &f.dec[d + 1];
            let source: &[f32] = if d == 0 {
                self.linear_tangent()
            } else {
                let lw = &self.weights.layers[l - 1 - d];
                mean_rows(&self.neighbors, t, mean, r);
                conv_rows(&transpose9(&lw.wp), t, &transpose9(&lw.wn), mean, &[0.0; 9], next, bp, false);
                next
            };
            let mut out = std::mem::take(mean);
            for (i, (o, row)) in out.chunks_exact_mut(bp).zip(source.chunks_exact(bp)).enumerate() {
                let yi = y[i * f.bp];
                let s = 1.0 - yi * yi;
                o.iter_mut().zip(row).for_each(|(o, &v)| *o = v * s);
            }
            *mean = std::mem::replace(t, out);
        }
        Ok((shape_from_vcb(&f.dec[l], f.bp, 0), bp))
    }

    /// The tangents (9N rows of the padded K lanes) of Cᵀ, through the first decoder layer's
    /// linear map when there is one: constant, built on first use.
    fn linear_tangent(&self) -> &[f32] {
        self.tangent.get_or_init(|| {
            let (n, k) = (self.weights.n, self.weights.k);
            let bp = padded_width(k);
            let r = 9 * bp;
            let rows = 9 * n;
            let mut t = vec![0.0f32; n * r];
            // Lane k of row i is C[k, i] (blocks of rows: contiguous reads of C).
            const BLOCK: usize = 16;
            for i0 in (0..rows).step_by(BLOCK) {
                let i1 = (i0 + BLOCK).min(rows);
                for (kk, crow) in self.weights.c.chunks_exact(rows).enumerate() {
                    for (i, &v) in (i0..i1).zip(&crow[i0..i1]) {
                        t[i * bp + kk] = v;
                    }
                }
            }
            let l = self.weights.layers.len();
            if l == 0 {
                return t;
            }
            let lw = &self.weights.layers[l - 1];
            let mut mean = vec![0.0f32; n * r];
            let mut out = vec![0.0f32; n * r];
            mean_rows(&self.neighbors, &t, &mut mean, r);
            conv_rows(&transpose9(&lw.wp), &t, &transpose9(&lw.wn), &mean, &[0.0; 9], &mut out, bp, false);
            out
        });
        self.tangent.get().map(Vec::as_slice).unwrap_or(&[])
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
