//! Hand-written forward and backward pass of the whole training loss (the hot path).
//!
//! Computes exactly the function of [`super::model::AutoencoderModule::forward`] and
//! [`super::loss::reference_loss`], in `f32` on the VCB layout of [`super::kernels`], with the
//! latent products as GEMMs (faer) and everything else in vectorised loops. The gradients go
//! back to Burn's optimizer (see [`super::training`]); a test checks them against Burn autodiff.

use burn::tensor::Tensor;
use faer::linalg::matmul::matmul;
use faer::prelude::ReborrowMut;
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;
use std::sync::Arc;

use super::config::AutoencoderConfig;
use super::kernels::{self, Acc9, Mat9, transpose9};
use super::loss::{LossTerms, NORM_EPS, SupportMaps, sparsity_with_grad_checked};
use super::model::{AutoencoderModule, COMPONENT_BLOCK};
use super::neighbors::NeighborIndex;
use super::output_loss::OutputTerm;
use crate::error::{Error, Result};

/// Weights of one layer as plain arrays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LayerWeights {
    /// `W_point` `[out][in]`.
    pub wp: Mat9,
    /// `W_nb` `[out][in]`.
    pub wn: Mat9,
    /// Encoder bias.
    pub b: [f32; 9],
    /// Decoder bias.
    pub bd: [f32; 9],
}

/// A snapshot of the module's parameters as plain `f32` arrays.
#[derive(Debug, Clone)]
pub struct Weights {
    /// Encoder layers in forward order.
    pub layers: Vec<LayerWeights>,
    /// `C`, `[K, 9N]` row-major, vertex-major columns.
    pub c: Vec<f32>,
    /// K.
    pub k: usize,
    /// N.
    pub n: usize,
    /// Least-squares encoder `z = (C·Cᵀ + εI)⁻¹·C·f` ([`super::config::EncoderKind`]).
    pub least_squares: bool,
}

/// Copies a float tensor's values out of Burn.
///
/// A parameter's tensor is shared with its `Param`, and burn-ndarray's `into_data` of a shared
/// array copies element by element through a dynamic-rank iterator (≈ 80 ms for the 1M values
/// of C at SCAPE size). A trivial elementwise op (× 1) first makes a fresh, uniquely owned
/// array (a vectorised copy), whose `into_data` then hands over its buffer without copying.
pub(crate) fn tensor_to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.inner().mul_scalar(1.0).into_data().try_into_vec_as::<f32>().expect("float tensor data converts to f32")
}

fn mat9(v: &[f32]) -> Mat9 {
    let mut m = [[0.0; 9]; 9];
    for o in 0..9 {
        m[o].copy_from_slice(&v[o * 9..o * 9 + 9]);
    }
    m
}

fn check_finite(name: &str, v: &[f32]) -> Result<()> {
    if let Some(i) = kernels::first_non_finite(v) {
        return Err(Error::Numerical(format!(
            "parameter `{name}` has a non-finite value ({}) at flat index {i}",
            v[i]
        )));
    }
    Ok(())
}

impl Weights {
    /// Reads the module's parameters; errors if any is non-finite.
    pub fn from_module(m: &AutoencoderModule) -> Result<Self> {
        let mut w = Weights { layers: Vec::new(), c: Vec::new(), k: 0, n: 0, least_squares: false };
        w.read_module(m)?;
        Ok(w)
    }

    /// Re-reads the module's parameters into this snapshot (reusing the buffer of `C`); errors
    /// if any is non-finite.
    pub fn read_module(&mut self, m: &AutoencoderModule) -> Result<()> {
        self.read_layers(&m.layers)?;
        let [k, nc] = m.components_shape();
        self.k = k;
        self.n = nc / 9;
        self.c.resize(k * nc, 0.0);
        // Blocks in parallel, each an elementwise copy out of Burn plus a copy into place.
        self.c
            .par_chunks_mut(COMPONENT_BLOCK * nc.max(1))
            .zip(m.components.par_iter())
            .for_each(|(dst, p)| dst.copy_from_slice(&tensor_to_vec(p.val())));
        check_finite("components", &self.c)
    }

    fn read_layers(&mut self, layers: &[super::model::MeshConv]) -> Result<()> {
        self.layers = layer_weights(layers);
        self.check_layers()
    }

    /// Errors if a layer parameter is not finite (naming it).
    pub fn check_layers(&self) -> Result<()> {
        for (l, lw) in self.layers.iter().enumerate() {
            check_finite(&format!("layers.{l}.weight_point"), lw.wp.as_flattened())?;
            check_finite(&format!("layers.{l}.weight_neighbor"), lw.wn.as_flattened())?;
            check_finite(&format!("layers.{l}.bias"), &lw.b)?;
            check_finite(&format!("layers.{l}.decoder_bias"), &lw.bd)?;
        }
        Ok(())
    }

    /// Errors if an entry of `C` is not finite (naming the first).
    pub fn check_components(&self) -> Result<()> {
        check_finite("components", &self.c)
    }

    /// A snapshot from the layers' parameters and `C` (`[K, 9N]` row-major, taken over without
    /// a copy); errors if a parameter is not finite or `C` does not hold whole rows of `9N`.
    pub fn from_parts(layers: &[super::model::MeshConv], c: Vec<f32>, n: usize) -> Result<Self> {
        if n == 0 || !c.len().is_multiple_of(9 * n) {
            return Err(Error::Invalid(format!("components hold {} numbers, not whole rows of 9 × {n}", c.len())));
        }
        let w = Weights { layers: layer_weights(layers), k: c.len() / (9 * n), n, c, least_squares: false };
        w.check_layers()?;
        w.check_components()?;
        Ok(w)
    }
}

/// The layers' parameters as plain arrays (copied out of Burn; no checks).
pub fn layer_weights(layers: &[super::model::MeshConv]) -> Vec<LayerWeights> {
    layers
        .iter()
        .map(|layer| {
            let b = tensor_to_vec(layer.bias.val());
            let bd = tensor_to_vec(layer.decoder_bias.val());
            LayerWeights {
                wp: mat9(&tensor_to_vec(layer.weight_point.val())),
                wn: mat9(&tensor_to_vec(layer.weight_neighbor.val())),
                b: b.try_into().expect("bias of 9"),
                bd: bd.try_into().expect("bias of 9"),
            }
        })
        .collect()
}

/// Gradients of one layer (`f64` accumulators).
#[derive(Debug, Clone, Copy)]
pub struct LayerGrads {
    /// ∂L/∂W_point `[out][in]`.
    pub wp: Acc9,
    /// ∂L/∂W_nb `[out][in]`.
    pub wn: Acc9,
    /// ∂L/∂b.
    pub b: [f64; 9],
    /// ∂L/∂b_dec.
    pub bd: [f64; 9],
}

/// Gradients of the loss with respect to every parameter.
#[derive(Debug, Clone, Default)]
pub struct Grads {
    /// Per layer, encoder order.
    pub layers: Vec<LayerGrads>,
    /// ∂L/∂C, `[K, 9N]` row-major (one buffer: per-block GEMMs would re-pack the shared
    /// operand once per block, which costs more than copying the blocks out).
    pub c: Vec<f32>,
}

impl Grads {
    /// First non-finite gradient entry, as a parameter name and index.
    pub fn first_non_finite(&self) -> Option<String> {
        self.first_non_finite_layer().or_else(|| kernels::first_non_finite(&self.c).map(|i| format!("components[{i}]")))
    }

    /// First layer with a non-finite gradient entry, as a parameter name.
    pub fn first_non_finite_layer(&self) -> Option<String> {
        for (l, g) in self.layers.iter().enumerate() {
            let all = g.wp.iter().flatten().chain(g.wn.iter().flatten()).chain(&g.b).chain(&g.bd);
            if all.clone().any(|v| !v.is_finite()) {
                return Some(format!("layers.{l}"));
            }
        }
        None
    }
}

/// Reusable buffers of one batch width.
#[derive(Debug)]
pub struct Workspace {
    n: usize,
    k: usize,
    bp: usize,
    /// Encoder outputs A_1..A_L (A_L = F).
    enc_out: Vec<Vec<f32>>,
    /// Encoder neighbour means M_0..M_{L−1}.
    enc_mean: Vec<Vec<f32>>,
    /// Decoder activations G_0 = F̂ .. G_L = X̂.
    dec: Vec<Vec<f32>>,
    /// Decoder neighbour means.
    dec_mean: Vec<Vec<f32>>,
    zt: Vec<f32>,
    dzt: Vec<f32>,
    /// Cholesky factor (lower, row-major, `f64`) of `C·Cᵀ + εI` of the last least-squares encode.
    chol: Vec<f64>,
    d_a: Vec<f32>,
    d_b: Vec<f32>,
    mask: Vec<f32>,
    /// Whether every entry of the last [`loss_and_grad`]'s `∂L/∂C` is finite.
    grad_c_finite: bool,
    /// Real lanes of the last [`loss_and_layer_grads`].
    b_real: usize,
    /// Lanes `0..dirty` of the buffers that served as `dec[0]` may be non-zero (the decoder GEMM
    /// writes the real lanes only; the backward pass needs zero padding lanes).
    dirty: usize,
    /// Per-vertex weights of the feature error (`[N]`; `feature_weights = "noise"`), or none
    /// (every vertex 1).
    feature_weights: Option<Arc<[f32]>>,
}

impl Workspace {
    /// Buffers for `n` vertices, `k` components, `layers` layers and batch width `bp` (a
    /// multiple of [`kernels::LANES`]).
    pub fn new(n: usize, k: usize, layers: usize, bp: usize) -> Self {
        assert!(bp.is_multiple_of(kernels::LANES) && bp > 0);
        let sz = n * 9 * bp;
        let z = || vec![0.0f32; sz];
        Workspace {
            n,
            k,
            bp,
            enc_out: (0..layers).map(|_| z()).collect(),
            enc_mean: (0..layers).map(|_| z()).collect(),
            dec: (0..=layers).map(|_| z()).collect(),
            dec_mean: (0..layers).map(|_| z()).collect(),
            zt: vec![0.0; k * bp],
            dzt: vec![0.0; k * bp],
            chol: Vec::new(),
            d_a: Vec::new(),
            d_b: Vec::new(),
            mask: vec![0.0; bp],
            grad_c_finite: true,
            b_real: 0,
            dirty: 0,
            feature_weights: None,
        }
    }

    /// Weights the feature error of every vertex `i` (its 9 rows) by `w[i]` in
    /// [`loss_and_grad`], [`loss_and_layer_grads`] and [`crate::nn::training::feature_error`]
    /// (none: every vertex 1). Panics unless `w` has one weight per vertex.
    pub fn set_feature_weights(&mut self, w: Option<Arc<[f32]>>) {
        if let Some(w) = &w {
            assert_eq!(w.len(), self.n, "one feature weight per vertex");
        }
        self.feature_weights = w;
    }

    /// The per-vertex feature-error weights ([`Self::set_feature_weights`]).
    pub fn feature_weights(&self) -> Option<&[f32]> {
        self.feature_weights.as_deref()
    }

    /// Padded batch width.
    pub fn width(&self) -> usize {
        self.bp
    }

    fn ensure_backward(&mut self) {
        let sz = self.n * 9 * self.bp;
        for b in [&mut self.d_a, &mut self.d_b] {
            if b.len() != sz {
                *b = vec![0.0; sz];
            }
        }
    }

    /// Whether every entry of `∂L/∂C` of the last [`loss_and_grad`] is finite (checked while it
    /// was computed, so [`Grads::first_non_finite`] need not scan `C`'s gradient again).
    pub fn gradient_c_finite(&self) -> bool {
        self.grad_c_finite
    }

    /// Latent codes of the last forward pass: `Zᵀ`, `[K, bp]` row-major.
    pub fn latent_t(&self) -> &[f32] {
        &self.zt
    }

    /// Mutable latent codes (set before [`decode`]).
    pub fn latent_t_mut(&mut self) -> &mut [f32] {
        &mut self.zt
    }

    /// Output of the last decoder pass (VCB layout).
    pub fn output(&self) -> &[f32] {
        self.dec.last().unwrap()
    }
}

/// `dst (+)= lhs · rhs` on the rayon pool: the larger output dimension is split in halves
/// (recursively, one part per thread), each part a sequential faer GEMM. (faer's own parallel
/// mode spin-waits, which wastes the shared cores.)
fn gemm_mat(dst: MatMut<'_, f32>, add: bool, lhs: MatRef<'_, f32>, rhs: MatRef<'_, f32>, parts: usize) {
    let (m, n) = (dst.nrows(), dst.ncols());
    if parts <= 1 || m.max(n) < 64 {
        matmul(dst, if add { Accum::Add } else { Accum::Replace }, lhs, rhs, 1.0f32, Par::Seq);
        return;
    }
    let (p1, p2) = (parts / 2, parts - parts / 2);
    if m >= n {
        let mid = m * p1 / parts;
        let (d1, d2) = dst.split_at_row_mut(mid);
        let (l1, l2) = lhs.split_at_row(mid);
        rayon::join(|| gemm_mat(d1, add, l1, rhs, p1), || gemm_mat(d2, add, l2, rhs, p2));
    } else {
        let mid = n * p1 / parts;
        let (d1, d2) = dst.split_at_col_mut(mid);
        let (r1, r2) = rhs.split_at_col(mid);
        rayon::join(|| gemm_mat(d1, add, lhs, r1, p1), || gemm_mat(d2, add, lhs, r2, p2));
    }
}

fn gemm(dst: MatMut<'_, f32>, add: bool, lhs: MatRef<'_, f32>, rhs: MatRef<'_, f32>) {
    gemm_mat(dst, add, lhs, rhs, rayon::current_num_threads());
}

/// `dst = Cᵀ·Y` on the first `b` lanes of `dst` (`[cols, bp]`, VCB) for `C` `[k, cols]` and
/// `Y` `[k, bp]` (row-major): [`kernels::ct_times`] where it is faster than the GEMM (one SIMD
/// block of lanes) and computes the same bits (`3 ≤ k ≤ 512`), the GEMM otherwise.
fn ct_times(dst: &mut [f32], c: &[f32], k: usize, cols_c: usize, y: &[f32], bp: usize, b: usize) {
    if bp == kernels::LANES && (3..=512).contains(&k) {
        kernels::ct_times(c, k, cols_c, y, bp, b, dst);
    } else {
        gemm(
            cols_mut(dst, cols_c, bp, b),
            false,
            MatRef::from_row_major_slice(c, k, cols_c).transpose(),
            cols(y, k, bp, b),
        );
    }
}

/// The first `b` columns of a row-major `rows × bp` buffer (the real shapes of a batch; the GEMMs
/// skip the padding lanes, which the kernels keep at zero gradient).
fn cols(buf: &[f32], rows: usize, bp: usize, b: usize) -> MatRef<'_, f32> {
    MatRef::from_row_major_slice(buf, rows, bp).subcols(0, b)
}

fn cols_mut(buf: &mut [f32], rows: usize, bp: usize, b: usize) -> MatMut<'_, f32> {
    MatMut::from_row_major_slice_mut(buf, rows, bp).subcols_mut(0, b)
}

/// Encoder pass: fills the encoder buffers and `Zᵀ = C·Fᵀ` (for the first `b` lanes).
///
/// # Shapes
/// `x`: VCB, N rows of `9·bp`.
pub fn encode(ws: &mut Workspace, w: &Weights, nb: &NeighborIndex, x: &[f32], b: usize) {
    let (n, bp, k) = (ws.n, ws.bp, ws.k);
    let r = 9 * bp;
    let l = w.layers.len();
    debug_assert_eq!(x.len(), n * r);
    for (i, lw) in w.layers.iter().enumerate() {
        let tanh = !(l > 1 && i == l - 1);
        let (prev, rest) = ws.enc_out.split_at_mut(i);
        let input: &[f32] = if i == 0 { x } else { &prev[i - 1] };
        kernels::mean_rows(nb, input, &mut ws.enc_mean[i], r);
        kernels::conv_rows(&lw.wp, input, &lw.wn, &ws.enc_mean[i], &lw.b, &mut rest[0], bp, tanh);
    }
    let f = &ws.enc_out[l - 1];
    gemm(cols_mut(&mut ws.zt, k, bp, b), false, MatRef::from_row_major_slice(&w.c, k, 9 * n), cols(f, 9 * n, bp, b));
    if w.least_squares {
        ws.chol = gram_cholesky(&w.c, k, 9 * n);
        cholesky_solve_lanes(&ws.chol, k, &mut ws.zt, bp, b);
    }
}

/// Cholesky factor (lower, row-major, `f64`) of `P = C·Cᵀ + εI`, ε = 10⁻⁶ × mean diagonal.
fn gram_cholesky(c: &[f32], k: usize, cols: usize) -> Vec<f64> {
    let cm = MatRef::from_row_major_slice(c, k, cols);
    let mut g = vec![0.0f32; k * k];
    gemm(MatMut::from_row_major_slice_mut(&mut g, k, k), false, cm, cm.transpose());
    let mean_diag = (0..k).map(|i| g[i * k + i] as f64).sum::<f64>() / k.max(1) as f64;
    let eps = 1e-6 * mean_diag.max(1e-30);
    let mut a: Vec<f64> = g.iter().map(|&x| x as f64).collect();
    // Symmetrise (the f32 GEMM is not exactly symmetric) and add the ridge.
    for i in 0..k {
        for j in 0..i {
            let v = 0.5 * (a[i * k + j] + a[j * k + i]);
            a[i * k + j] = v;
            a[j * k + i] = v;
        }
        a[i * k + i] += eps;
    }
    for j in 0..k {
        let mut d = a[j * k + j];
        for p in 0..j {
            d -= a[j * k + p] * a[j * k + p];
        }
        let d = d.max(eps).sqrt();
        a[j * k + j] = d;
        for i in j + 1..k {
            let mut s = a[i * k + j];
            for p in 0..j {
                s -= a[i * k + p] * a[j * k + p];
            }
            a[i * k + j] = s / d;
        }
    }
    for i in 0..k {
        for j in i + 1..k {
            a[i * k + j] = 0.0;
        }
    }
    a
}

/// Solves `L·Lᵀ·y = r` in place for each of the first `b` lanes of `r` (`[K, bp]` row-major).
fn cholesky_solve_lanes(l: &[f64], k: usize, r: &mut [f32], bp: usize, b: usize) {
    let mut y = vec![0.0f64; k];
    for j in 0..b {
        for i in 0..k {
            let mut s = r[i * bp + j] as f64;
            for p in 0..i {
                s -= l[i * k + p] * y[p];
            }
            y[i] = s / l[i * k + i];
        }
        for i in (0..k).rev() {
            let mut s = y[i];
            for p in i + 1..k {
                s -= l[p * k + i] * y[p];
            }
            y[i] = s / l[i * k + i];
        }
        for i in 0..k {
            r[i * bp + j] = y[i] as f32;
        }
    }
}

/// Decoder pass from the codes in the workspace (`Zᵀ`, `[K, bp]`, first `b` lanes):
/// `F̂ᵀ = Cᵀ·Zᵀ`, then the tied convolutions. The result is [`Workspace::output`].
pub fn decode(ws: &mut Workspace, w: &Weights, nb: &NeighborIndex, b: usize) {
    let (n, bp, k) = (ws.n, ws.bp, ws.k);
    let r = 9 * bp;
    let l = w.layers.len();
    ws.dirty = ws.dirty.max(b);
    ct_times(&mut ws.dec[0], &w.c, k, 9 * n, &ws.zt, bp, b);
    for d in 0..l {
        let lw = &w.layers[l - 1 - d];
        let (prev, rest) = ws.dec.split_at_mut(d + 1);
        kernels::mean_rows(nb, &prev[d], &mut ws.dec_mean[d], r);
        kernels::conv_rows(
            &transpose9(&lw.wp),
            &prev[d],
            &transpose9(&lw.wn),
            &ws.dec_mean[d],
            &lw.bd,
            &mut rest[0],
            bp,
            true,
        );
    }
}

fn acc9_add_transposed(dst: &mut Acc9, src: &Acc9) {
    for p in 0..9 {
        for q in 0..9 {
            dst[p][q] += src[q][p];
        }
    }
}

/// What [`backward_except_components`] leaves for the gradient of `C`.
struct Partial {
    reconstruction: f64,
    hinge: f64,
    /// The [`OutputLoss`] term (0 without one) and its weight this step.
    vertex: f64,
    vertex_weight: f64,
    /// The least-squares encoder's `−(u·zᵀ + z·uᵀ)` (`[K, K]`), whose product with `C` is part
    /// of `∂L/∂C`.
    sym: Option<Vec<f32>>,
    /// The code term (0 unless `lambda_code > 0`).
    code: f64,
}

/// The loss and every gradient except `∂L/∂C`, in the order of the reference: forward pass,
/// reconstruction, decoder backward, `dZᵀ`, hinge, `dF = Cᵀ·dZᵀ` and the encoder backward.
/// `grads.layers` is overwritten. Afterwards the workspace holds what `∂L/∂C = Zᵀ·dF̂ + dZᵀ·F
/// (+ sym·C)` needs: `Zᵀ` (`zt`), `dZᵀ` (`dzt`), `dF̂ᵀ` (`dec[0]`, the decoder input's buffer,
/// free by then) and `Fᵀ` (the last encoder output); none of it reads `C` again.
#[allow(clippy::too_many_arguments)]
fn backward_except_components(
    ws: &mut Workspace,
    w: &Weights,
    nb: &NeighborIndex,
    x: &[f32],
    target: Option<&[f32]>,
    b_real: usize,
    cfg: &AutoencoderConfig,
    grads: &mut Grads,
    encoded: bool,
    output_term: Option<OutputTerm<'_>>,
) -> Partial {
    // The encoder reads `x`; the reconstruction and output terms compare with `target` (the
    // clean shapes when `x` carries input noise).
    let target = target.unwrap_or(x);
    let (n, bp, k) = (ws.n, ws.bp, ws.k);
    let r = 9 * bp;
    let l = w.layers.len();
    assert!(b_real >= 1 && b_real <= bp);
    if !encoded {
        encode(ws, w, nb, x, b_real);
    }
    decode(ws, w, nb, b_real);
    ws.ensure_backward();
    for (j, m) in ws.mask.iter_mut().enumerate() {
        *m = if j < b_real { 1.0 } else { 0.0 };
    }
    let inv_b = 1.0 / b_real as f64;

    // Reconstruction: dG_L = (2/B)(X̂ − X) on real lanes.
    let sse = kernels::squared_error(
        &ws.dec[l],
        target,
        &ws.mask,
        ws.feature_weights.as_deref(),
        (2.0 * inv_b) as f32,
        &mut ws.d_a,
    );
    let reconstruction = sse * inv_b;
    // The caller's term on the decoded shapes (the vertex term): the mean over the lanes it
    // sees (all, or a sample of them), with this step's weight. With `vertex_clip`, its
    // gradient goes through ws.d_b (free until the decoder backward) so that its norm can be
    // capped at that many times the feature error's; otherwise straight into ws.d_a.
    let (vertex, vertex_weight) = match output_term {
        Some((o, lanes, weight)) if weight > 0.0 && !lanes.is_empty() => {
            assert!(lanes.iter().all(|&j| j < b_real), "output-loss lanes beyond the batch");
            let inv = 1.0 / lanes.len() as f64;
            let scale = (weight * inv) as f32;
            let v = if cfg.vertex_clip > 0.0 {
                ws.d_b.fill(0.0);
                let v = o.add_loss_and_grad(target, &ws.dec[l], bp, lanes, scale, &mut ws.d_b);
                let norm = |a: &[f32]| a.iter().map(|&g| g as f64 * g as f64).sum::<f64>().sqrt();
                let (f, g) = (norm(&ws.d_a), norm(&ws.d_b));
                let c = if g > cfg.vertex_clip * f { (cfg.vertex_clip * f / g) as f32 } else { 1.0 };
                for (a, b) in ws.d_a.iter_mut().zip(&ws.d_b) {
                    *a += c * b;
                }
                v
            } else {
                o.add_loss_and_grad(target, &ws.dec[l], bp, lanes, scale, &mut ws.d_a)
            };
            (v * inv, weight)
        }
        _ => (0.0, 0.0),
    };

    // Decoder backward. ws.d_a holds ∂L/∂G_{d+1}.
    grads.layers.resize(l, LayerGrads { wp: [[0.0; 9]; 9], wn: [[0.0; 9]; 9], b: [0.0; 9], bd: [0.0; 9] });
    for g in grads.layers.iter_mut() {
        *g = LayerGrads { wp: [[0.0; 9]; 9], wn: [[0.0; 9]; 9], b: [0.0; 9], bd: [0.0; 9] };
    }
    for d in (0..l).rev() {
        let li = l - 1 - d;
        let lw = &w.layers[li];
        kernels::tanh_backward(&ws.dec[d + 1], &mut ws.d_a);
        // Oriented weights of the decoder conv are ws = W_pointᵀ, wn = W_nbᵀ.
        let g = kernels::weight_grad_rows(&ws.d_a, &ws.dec[d], &ws.dec_mean[d], bp);
        acc9_add_transposed(&mut grads.layers[li].wp, &g.ws);
        acc9_add_transposed(&mut grads.layers[li].wn, &g.wn);
        grads.layers[li].bd = g.bias;
        // Input gradient: dG_d = W_point·dH + meanᵀ(W_nb·dH).
        // dec_mean[d] is free once its weight gradient is taken: it holds W_nb·dH.
        kernels::input_grad_rows(&lw.wp, &lw.wn, &ws.d_a, &mut ws.d_b, &mut ws.dec_mean[d], bp);
        kernels::mean_rows_transpose_add(nb, &ws.dec_mean[d], &mut ws.d_b, r);
        std::mem::swap(&mut ws.d_a, &mut ws.d_b);
    }
    // ws.d_a = ∂L/∂F̂ᵀ (9N × bp). It moves to dec[0] (F̂ is no longer needed; the padding lanes
    // of both buffers are zero), and ws.d_a takes dF below.
    std::mem::swap(&mut ws.d_a, &mut ws.dec[0]);
    if ws.dirty > b_real {
        // A wider batch decoded earlier left values in lanes this batch does not write.
        for row in ws.d_a.chunks_exact_mut(bp) {
            row[b_real..ws.dirty].fill(0.0);
        }
    }
    let c_ref = MatRef::from_row_major_slice(&w.c, k, 9 * n);
    // dZᵀ = C·dF̂ᵀ.
    gemm(cols_mut(&mut ws.dzt, k, bp, b_real), false, c_ref, cols(&ws.dec[0], 9 * n, bp, b_real));
    // Hinge on the real lanes.
    let mut hinge = 0.0f64;
    let hscale = (cfg.lambda2 / k as f64) as f32;
    for kk in 0..k {
        let row = &ws.zt[kk * bp..kk * bp + b_real];
        let (mut m, mut best) = (0usize, -1.0f32);
        for (j, v) in row.iter().enumerate() {
            if v.abs() > best {
                best = v.abs();
                m = j;
            }
        }
        let excess = best as f64 - cfg.theta;
        if excess > 0.0 {
            hinge += excess;
            ws.dzt[kk * bp + m] += hscale * row[m].signum();
        }
    }
    hinge /= k as f64;
    // Code term (`lambda_code`): the last lane is the rest shape; every other lane's code is
    // pulled towards its code, and its code towards theirs.
    let mut code = 0.0f64;
    if cfg.lambda_code > 0.0 && b_real > 1 {
        let rest = b_real - 1;
        let g = (cfg.lambda_code / rest as f64) as f32;
        for kk in 0..k {
            let (zrow, drow) = (&ws.zt[kk * bp..kk * bp + b_real], &mut ws.dzt[kk * bp..kk * bp + b_real]);
            let zr = zrow[rest];
            let mut pull = 0.0f32;
            for j in 0..rest {
                let d = zrow[j] - zr;
                code += d.abs() as f64;
                let s = g * if d > 0.0 {
                    1.0
                } else if d < 0.0 {
                    -1.0
                } else {
                    0.0
                };
                drow[j] += s;
                pull += s;
            }
            drow[rest] -= pull;
        }
        code /= rest as f64;
    }
    // Least-squares encoder z = P⁻¹·C·f (P = C·Cᵀ + εI): with u = P⁻¹·dz, the encoder's part of
    // dC is u·fᵀ − (u·zᵀ + z·uᵀ)·C and dF = Cᵀ·u. ws.dzt becomes u; the −(…)·C part is
    // added with the rest of dC.
    let mut sym: Option<Vec<f32>> = None;
    if w.least_squares {
        cholesky_solve_lanes(&ws.chol, k, &mut ws.dzt, bp, b_real);
        let mut m = vec![0.0f32; k * k];
        for a in 0..k {
            for c in 0..k {
                let (ua, za) = (&ws.dzt[a * bp..a * bp + b_real], &ws.zt[a * bp..a * bp + b_real]);
                let (uc, zc) = (&ws.dzt[c * bp..c * bp + b_real], &ws.zt[c * bp..c * bp + b_real]);
                let mut s = 0.0f64;
                for j in 0..b_real {
                    s += ua[j] as f64 * zc[j] as f64 + za[j] as f64 * uc[j] as f64;
                }
                m[a * k + c] = -s as f32;
            }
        }
        sym = Some(m);
    }
    // dFᵀ = Cᵀ·dZᵀ (the padding lanes of ws.d_a are zero: it held F̂, whose padding lanes the
    // decoder GEMM never writes).
    ct_times(&mut ws.d_a, &w.c, k, 9 * n, &ws.dzt, bp, b_real);

    // Encoder backward.
    for li in (0..l).rev() {
        let lw = &w.layers[li];
        let tanh = !(l > 1 && li == l - 1);
        if tanh {
            kernels::tanh_backward(&ws.enc_out[li], &mut ws.d_a);
        }
        let input: &[f32] = if li == 0 { x } else { &ws.enc_out[li - 1] };
        let g = kernels::weight_grad_rows(&ws.d_a, input, &ws.enc_mean[li], bp);
        for p in 0..9 {
            for q in 0..9 {
                grads.layers[li].wp[p][q] += g.ws[p][q];
                grads.layers[li].wn[p][q] += g.wn[p][q];
            }
        }
        grads.layers[li].b = g.bias;
        if li > 0 {
            // enc_mean[li] is free once its weight gradient is taken.
            let (wst, wnt) = (transpose9(&lw.wp), transpose9(&lw.wn));
            kernels::input_grad_rows(&wst, &wnt, &ws.d_a, &mut ws.d_b, &mut ws.enc_mean[li], bp);
            kernels::mean_rows_transpose_add(nb, &ws.enc_mean[li], &mut ws.d_b, r);
            std::mem::swap(&mut ws.d_a, &mut ws.d_b);
        }
    }
    Partial { reconstruction, hinge, vertex, vertex_weight, sym, code }
}

/// Loss and gradients for one batch.
///
/// `x` is the batch in VCB layout with `b_real` real shapes in lanes `0..b_real` (the rest zero);
/// `target` (same layout) is what the decoding is compared with, `x` itself when `None` (a
/// denoising step passes the clean shapes there and noisy ones as `x`); `maps` must already be
/// updated for `w.c`. Returns the loss terms; `grads` is overwritten.
#[allow(clippy::too_many_arguments)]
pub fn loss_and_grad(
    ws: &mut Workspace,
    w: &Weights,
    nb: &NeighborIndex,
    x: &[f32],
    target: Option<&[f32]>,
    b_real: usize,
    maps: &SupportMaps,
    cfg: &AutoencoderConfig,
    grads: &mut Grads,
    output_term: Option<OutputTerm<'_>>,
) -> LossTerms {
    let part = backward_except_components(ws, w, nb, x, target, b_real, cfg, grads, false, output_term);
    component_gradient(ws, w, b_real, part.sym.as_deref(), grads);
    let (sparsity, orthogonality) = component_penalties(ws, w, maps, cfg, grads);
    terms(cfg, &part, sparsity, orthogonality)
}

fn terms(cfg: &AutoencoderConfig, part: &Partial, sparsity: f64, orthogonality: f64) -> LossTerms {
    LossTerms {
        total: part.reconstruction
            + cfg.lambda1 * sparsity
            + cfg.lambda2 * part.hinge
            + cfg.lambda_orthogonal * orthogonality
            + part.vertex_weight * part.vertex
            + cfg.lambda_code * part.code,
        reconstruction: part.reconstruction,
        sparsity,
        hinge: part.hinge,
        orthogonality,
        vertex: part.vertex,
        code: part.code,
    }
}

/// The dense part of `∂L/∂C` into `grads.c`: `Zᵀ·dF̂ + dZᵀ·F (+ sym·C)`.
fn component_gradient(ws: &Workspace, w: &Weights, b_real: usize, sym: Option<&[f32]>, grads: &mut Grads) {
    let (n, bp, k) = (ws.n, ws.bp, ws.k);
    let l = w.layers.len();
    grads.c.resize(w.c.len(), 0.0);
    gemm(
        MatMut::from_row_major_slice_mut(&mut grads.c, k, 9 * n),
        false,
        cols(&ws.zt, k, bp, b_real),
        cols(&ws.dec[0], 9 * n, bp, b_real).transpose(),
    );
    gemm(
        MatMut::from_row_major_slice_mut(&mut grads.c, k, 9 * n),
        true,
        cols(&ws.dzt, k, bp, b_real),
        cols(&ws.enc_out[l - 1], 9 * n, bp, b_real).transpose(),
    );
    if let Some(m) = sym {
        gemm(
            MatMut::from_row_major_slice_mut(&mut grads.c, k, 9 * n),
            true,
            MatRef::from_row_major_slice(m, k, k),
            MatRef::from_row_major_slice(&w.c, k, 9 * n),
        );
    }
}

/// Sparsity (and decorrelation) of `C`: their gradients are added to `grads.c`, whose finiteness
/// is recorded in the workspace. Returns the unweighted terms.
fn component_penalties(
    ws: &mut Workspace,
    w: &Weights,
    maps: &SupportMaps,
    cfg: &AutoencoderConfig,
    grads: &mut Grads,
) -> (f64, f64) {
    let (n, k) = (ws.n, ws.k);
    let (sparsity, finite) = sparsity_with_grad_checked(&w.c, maps, (cfg.lambda1 / k as f64) as f32, &mut grads.c);
    ws.grad_c_finite = finite;
    let orthogonality = if cfg.lambda_orthogonal > 0.0 {
        let o = orthogonality_with_grad(&w.c, k, 9 * n, (cfg.lambda_orthogonal / k as f64) as f32, &mut grads.c);
        ws.grad_c_finite = kernels::first_non_finite(&grads.c).is_none();
        o
    } else {
        0.0
    };
    (sparsity, orthogonality)
}

/// Reconstruction and hinge terms of [`loss_and_layer_grads`]; [`finish_loss`] adds the
/// sparsity term.
#[derive(Debug, Clone, Copy)]
pub struct PartialLoss {
    reconstruction: f64,
    hinge: f64,
    vertex: f64,
    vertex_weight: f64,
    code: f64,
}

/// The loss of one batch (but its sparsity term) and the gradients of the layers, with `∂L/∂C`
/// left to [`update_components`] (or to [`components_gradient`]). Only for
/// `lambda_orthogonal = 0` and the linear encoder ([`fused_update_applies`]). It does not read
/// the support maps, so their distance queries may run beside it; [`finish_loss`] then gives
/// the same loss terms as [`loss_and_grad`] (`target` as there). With `encoded`, the encoder
/// outputs and `Zᵀ` of `x` are already in the workspace (computed by the last
/// [`update_components`] with `encode_next`, for this same `x` and these parameters).
#[allow(clippy::too_many_arguments)]
pub fn loss_and_layer_grads(
    ws: &mut Workspace,
    w: &Weights,
    nb: &NeighborIndex,
    x: &[f32],
    target: Option<&[f32]>,
    b_real: usize,
    cfg: &AutoencoderConfig,
    grads: &mut Grads,
    encoded: bool,
    output_term: Option<OutputTerm<'_>>,
) -> PartialLoss {
    assert!(fused_update_applies(w, cfg), "the fused update needs the linear encoder and lambda_orthogonal = 0");
    assert!(!encoded || b_real == ws.b_real, "the batch encoded ahead has another width");
    let part = backward_except_components(ws, w, nb, x, target, b_real, cfg, grads, encoded, output_term);
    ws.b_real = b_real;
    PartialLoss {
        reconstruction: part.reconstruction,
        hinge: part.hinge,
        vertex: part.vertex,
        vertex_weight: part.vertex_weight,
        code: part.code,
    }
}

/// The loss terms of [`loss_and_layer_grads`] with the sparsity term from the squared vertex
/// norms in `maps` (updated for the current `C`).
pub fn finish_loss(p: PartialLoss, maps: &SupportMaps, cfg: &AutoencoderConfig) -> LossTerms {
    let part = Partial {
        reconstruction: p.reconstruction,
        hinge: p.hinge,
        vertex: p.vertex,
        vertex_weight: p.vertex_weight,
        sym: None,
        code: p.code,
    };
    terms(cfg, &part, sparsity_from_norms(maps), 0.0)
}

/// Whether [`loss_and_layer_grads`] + [`update_components`] apply (linear encoder, no
/// decorrelation term).
pub fn fused_update_applies(w: &Weights, cfg: &AutoencoderConfig) -> bool {
    !w.least_squares && cfg.lambda_orthogonal == 0.0
}

/// After [`loss_and_layer_grads`]: `∂L/∂C` into `grads.c` as [`loss_and_grad`] computes it
/// (dense part, then the sparsity gradient), with its finiteness recorded
/// ([`Workspace::gradient_c_finite`]). The fallback of [`update_components`].
pub fn components_gradient(
    ws: &mut Workspace,
    w: &Weights,
    maps: &SupportMaps,
    cfg: &AutoencoderConfig,
    grads: &mut Grads,
) {
    component_gradient(ws, w, ws.b_real, None, grads);
    component_penalties(ws, w, maps, cfg, grads);
}

/// Largest magnitude a finite `f32` bound may reach for [`update_components`] to apply: far
/// below `f32::MAX`, so that no sum of the bounded terms can overflow.
const GRADIENT_BOUND: f64 = 1e30;

/// Upper bound of `|∂L/∂C|` over all entries (dense part plus sparsity gradient) from the
/// factors left by [`loss_and_layer_grads`], or infinity when a factor is not finite. Below
/// `1e30` every entry of `∂L/∂C` is finite (so [`update_components`] may update `C` as it
/// computes the gradient: it cannot meet a non-finite entry half-way).
pub fn components_gradient_bound(ws: &Workspace, w: &Weights, cfg: &AutoencoderConfig) -> f64 {
    let (n, bp, k) = (ws.n, ws.bp, ws.k);
    let l = w.layers.len();
    let b = ws.b_real;
    // max |v| < 2^(e − 126) for the largest exponent field e (an upper bound, also for
    // subnormals and zero); infinity for a non-finite entry.
    let bound = |v: &[f32]| -> f64 {
        let e = kernels::max_exponent_of(v);
        if e == kernels::NON_FINITE_EXPONENT { f64::INFINITY } else { 2f64.powi((e >> 23) as i32 - 126) }
    };
    let lanes =
        |buf: &[f32], rows: usize| -> f64 { (0..rows).map(|r| bound(&buf[r * bp..r * bp + b])).fold(0.0, f64::max) };
    let z = lanes(&ws.zt, k);
    let dz = lanes(&ws.dzt, k);
    let dfh = bound(&ws.dec[0][..9 * n * bp]);
    // One layer ends in tanh: |F| ≤ 1, and F is finite (from finite data and checked weights).
    let f = if l == 1 { 1.0 } else { bound(&ws.enc_out[l - 1]) };
    // Each entry is a sum of 2b products (FMA: one rounding each, |rounding| ≤ 2⁻²⁴ relative),
    // plus scale·Λ·c/‖c‖ with |c_q| ≤ ‖c‖ and Λ ≤ 1.
    let dense = b as f64 * (z * dfh + dz * f) * 2.0;
    let sparse = (cfg.lambda1 / k as f64).abs() * 2.0;
    let total = dense + sparse;
    if total.is_finite() && total < GRADIENT_BOUND { total } else { f64::INFINITY }
}

/// Whether [`update_components`] should encode the next step's batch (`encode_next`): one
/// convolution layer (its output comes from the batch and the layer alone), and a batch of one
/// SIMD block of lanes (for wider batches faer's separate GEMM is faster than the chains inside
/// the update: measured at SCAPE size, 36 shapes).
pub fn encode_next_applies(ws: &Workspace, w: &Weights) -> bool {
    // (And at least 3 components: the blocked sums of [`kernels::block_chains`] are what faer
    // computes for every shape measured, K ≥ 3.)
    w.layers.len() == 1 && ws.bp == kernels::LANES && w.k >= 3
}

/// Applies Adam to `C` in place with the gradient `∂L/∂C = Zᵀ·dF̂ + dZᵀ·F + sparsity`, computed
/// tile by tile (columns of `C`) from what [`loss_and_layer_grads`] left in the workspace and
/// never stored whole. Each tile's dense part is a GEMM into a small buffer; the sparsity
/// gradient (from the squared vertex norms in `maps`, those of the `C` before the update), the
/// Adam update ([`kernels::AdamScalars`]) and the squared vertex norms of the new `C` (written
/// into `maps` for the next step) follow while the tile is in cache. Bit-identical to
/// [`loss_and_grad`]'s gradient followed by Burn's Adam. Returns whether the new `C` is
/// finite.
///
/// With `encode_next` (see [`encode_next_applies`]; `w` holds the updated layers and `x` is the
/// next step's batch, of the same width), the next step's encoder pass is done as well: the
/// convolution of `x` before the tiles, and `Zᵀ = C·Fᵀ` of the new `C` from each tile while it
/// is in cache ([`kernels::block_chains`], faer's summation order), so that the next
/// [`loss_and_layer_grads`] may skip its encoder (`encoded`) and `C` is read once less per step.
///
/// The caller must have checked [`components_gradient_bound`] (a finite bound).
#[allow(clippy::too_many_arguments)]
pub fn update_components(
    ws: &mut Workspace,
    w: &Weights,
    c: &mut [f32],
    moment_1: &mut [f32],
    moment_2: &mut [f32],
    adam: &kernels::AdamScalars,
    maps: &mut SupportMaps,
    cfg: &AutoencoderConfig,
    next: Option<&[f32]>,
) -> bool {
    let (n, bp, k) = (ws.n, ws.bp, ws.k);
    let b = ws.b_real;
    let nc = 9 * n;
    let l = w.layers.len();
    assert_eq!(c.len(), k * nc);
    if next.is_some() {
        assert!(encode_next_applies(ws, w));
    }
    // The next batch's encoder output into d_b (free after the backward pass): enc_mean[0]
    // holds the neighbour means of the batch, which is the same.
    if let Some(x) = next {
        let lw = &w.layers[0];
        kernels::conv_rows(&lw.wp, x, &lw.wn, &ws.enc_mean[0], &lw.b, &mut ws.d_b, bp, true);
    }
    let scale = (cfg.lambda1 / k as f64) as f32;
    let (sq_norms, lambda) = maps.norms_and_weights();
    let tv = kernels::FUSED_TILE_VERTICES;
    let n_tiles = n.div_ceil(tv);
    let inner = kernels::GEMM_INNER_BLOCK;
    let blocks = nc.div_ceil(inner);
    let blocks_per_tile = 9 * tv / inner;
    let mut z_parts = if next.is_some() { vec![0.0f32; blocks * k * bp] } else { Vec::new() };
    // Regroup the row-major arrays into column tiles (each tile: one slice per row).
    struct Tile<'a> {
        c: Vec<&'a mut [f32]>,
        m: Vec<&'a mut [f32]>,
        v: Vec<&'a mut [f32]>,
        sq: Vec<&'a mut [f32]>,
        lambda: Vec<&'a [f32]>,
        z_parts: &'a mut [f32],
    }
    let mut z_chunks = z_parts.chunks_mut(blocks_per_tile * k * bp);
    let mut tiles: Vec<Tile<'_>> = (0..n_tiles)
        .map(|_| Tile {
            c: Vec::with_capacity(k),
            m: Vec::with_capacity(k),
            v: Vec::with_capacity(k),
            sq: Vec::with_capacity(k),
            lambda: Vec::with_capacity(k),
            z_parts: z_chunks.next().unwrap_or_default(),
        })
        .collect();
    for ((((c_row, m_row), v_row), sq_row), l_row) in c
        .chunks_mut(nc)
        .zip(moment_1.chunks_mut(nc))
        .zip(moment_2.chunks_mut(nc))
        .zip(sq_norms.chunks_mut(n))
        .zip(lambda)
    {
        for (ti, ((((cp, mp), vp), sp), lp)) in c_row
            .chunks_mut(9 * tv)
            .zip(m_row.chunks_mut(9 * tv))
            .zip(v_row.chunks_mut(9 * tv))
            .zip(sq_row.chunks_mut(tv))
            .zip(l_row.chunks(tv))
            .enumerate()
        {
            let t = &mut tiles[ti];
            t.c.push(cp);
            t.m.push(mp);
            t.v.push(vp);
            t.sq.push(sp);
            t.lambda.push(lp);
        }
    }
    let zt = cols(&ws.zt, k, bp, b);
    let dzt = cols(&ws.dzt, k, bp, b);
    let dfh = cols(&ws.dec[0], nc, bp, b);
    let f = cols(&ws.enc_out[l - 1], nc, bp, b);
    let f_next: Option<&[f32]> = next.map(|_| &ws.d_b[..]);
    let exps: Vec<u32> = tiles
        .into_par_iter()
        .enumerate()
        .map_init(
            || vec![0.0f32; k * 9 * tv],
            |buf, (ti, t)| {
                let (j0, tw) = (ti * 9 * tv, t.c[0].len());
                let g = &mut buf[..k * tw];
                let mut gm = MatMut::from_row_major_slice_mut(g, k, tw);
                matmul(gm.rb_mut(), Accum::Replace, zt, dfh.subrows(j0, tw).transpose(), 1.0f32, Par::Seq);
                matmul(gm.rb_mut(), Accum::Add, dzt, f.subrows(j0, tw).transpose(), 1.0f32, Par::Seq);
                let Tile { mut c, m, v, sq, lambda, z_parts } = t;
                let mut exp = 0u32;
                let mut rows = m.into_iter().zip(v).zip(sq).zip(lambda).zip(g.chunks_mut(tw)).enumerate();
                // Rows in groups of 8: updated, then (encoding ahead) their partial products with
                // the next F while they are in cache.
                for g0 in (0..k).step_by(8) {
                    let g1 = (g0 + 8).min(k);
                    for (kk, ((((m, v), sq), lambda), g_row)) in rows.by_ref().take(g1 - g0) {
                        let e = kernels::sparse_adam_norms(
                            &mut *c[kk],
                            g_row,
                            m,
                            v,
                            adam,
                            sq,
                            lambda,
                            NORM_EPS * NORM_EPS,
                            scale,
                        );
                        exp = exp.max(e);
                    }
                    if let Some(fx) = f_next {
                        let views: Vec<&[f32]> = c[g0..g1].iter().map(|r| &**r).collect();
                        kernels::block_chains(&views, &fx[j0 * bp..(j0 + tw) * bp], g0, k, z_parts, bp);
                    }
                }
                c.clear();
                exp
            },
        )
        .collect();
    if next.is_some() {
        // Zᵀ of the next step: the blocks added in order, as the GEMM does.
        for (kk, zrow) in ws.zt.chunks_exact_mut(bp).take(k).enumerate() {
            for (lane, z) in zrow.iter_mut().enumerate().take(b) {
                let mut t = z_parts[kk * bp + lane];
                for bi in 1..blocks {
                    t += z_parts[(bi * k + kk) * bp + lane];
                }
                *z = t;
            }
        }
        std::mem::swap(&mut ws.enc_out[l - 1], &mut ws.d_b);
    }
    exps.into_iter().max().unwrap_or(0) != kernels::NON_FINITE_EXPONENT
}

/// The sparsity term `(1/K) Σ_k Σ_i Λ_ik ‖C_k,i‖_ε` from the squared vertex norms in `maps`
/// (the same sums, in the same order, as [`sparsity_with_grad_checked`]).
fn sparsity_from_norms(maps: &SupportMaps) -> f64 {
    let k = maps.centers().len();
    let n = maps.sq_norms().len() / k.max(1);
    let eps2 = NORM_EPS * NORM_EPS;
    let sums: Vec<f64> = maps
        .sq_norms()
        .par_chunks(n.max(1))
        .enumerate()
        .map(|(kk, sq)| {
            let mut total = 0.0f64;
            for (&s, &l) in sq.iter().zip(maps.weights(kk)) {
                if l == 0.0 {
                    continue;
                }
                total += (l * s.max(eps2).sqrt()) as f64;
            }
            total
        })
        .collect();
    sums.iter().sum::<f64>() / k as f64
}

/// Decorrelation of the rows of `C`: returns `S = (1/K) Σ_{k≠l} G_kl² / (G_kk G_ll)` with
/// `G = C·Cᵀ`, and adds `scale·K·∂S/∂C = scale · M·C` to `grad`, where `M_kl = 4 G_kl /
/// (G_kk G_ll)` (k ≠ l) and `M_kk = −4 Σ_{l≠k} G_kl² / (G_kk² G_ll)`.
///
/// # Shapes
/// `c`, `grad`: `[K, cols]` row-major.
pub fn orthogonality_with_grad(c: &[f32], k: usize, cols: usize, scale: f32, grad: &mut [f32]) -> f64 {
    let cm = MatRef::from_row_major_slice(c, k, cols);
    let mut g = vec![0.0f32; k * k];
    gemm(MatMut::from_row_major_slice_mut(&mut g, k, k), false, cm, cm.transpose());
    let eps = super::loss::ORTHO_EPS as f64;
    let diag: Vec<f64> = (0..k).map(|i| (g[i * k + i] as f64).max(eps)).collect();
    let mut s = 0.0f64;
    let mut m = vec![0.0f32; k * k];
    for a in 0..k {
        let mut mkk = 0.0f64;
        for b in 0..k {
            if a == b {
                continue;
            }
            let gab = g[a * k + b] as f64;
            let q = gab * gab / (diag[a] * diag[b]);
            s += q;
            m[a * k + b] = (2.0 * 2.0 * gab / (diag[a] * diag[b]) * scale as f64) as f32;
            mkk -= 2.0 * q / diag[a];
        }
        m[a * k + a] = (2.0 * mkk * scale as f64) as f32;
    }
    gemm(MatMut::from_row_major_slice_mut(grad, k, cols), true, MatRef::from_row_major_slice(&m, k, k), cm);
    s / k as f64
}
