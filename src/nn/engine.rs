//! Hand-written forward and backward pass of the whole training loss (the hot path).
//!
//! Computes exactly the function of [`super::model::AutoencoderModule::forward`] and
//! [`super::loss::reference_loss`], in `f32` on the VCB layout of [`super::kernels`], with the
//! latent products as GEMMs (faer) and everything else in vectorised loops. The gradients go
//! back to Burn's optimizer (see [`super::training`]); a test checks them against Burn autodiff.

use burn::tensor::Tensor;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use super::config::AutoencoderConfig;
use super::kernels::{self, Acc9, Mat9, transpose9};
use super::loss::{LossTerms, SupportMaps, sparsity_with_grad};
use super::model::{AutoencoderModule, COMPONENT_BLOCK};
use super::neighbors::NeighborIndex;
use crate::error::{Error, Result};

/// Weights of one layer as plain arrays.
#[derive(Debug, Clone, Copy)]
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
        self.layers.clear();
        for (l, layer) in layers.iter().enumerate() {
            let wp = tensor_to_vec(layer.weight_point.val());
            let wn = tensor_to_vec(layer.weight_neighbor.val());
            let b = tensor_to_vec(layer.bias.val());
            let bd = tensor_to_vec(layer.decoder_bias.val());
            check_finite(&format!("layers.{l}.weight_point"), &wp)?;
            check_finite(&format!("layers.{l}.weight_neighbor"), &wn)?;
            check_finite(&format!("layers.{l}.bias"), &b)?;
            check_finite(&format!("layers.{l}.decoder_bias"), &bd)?;
            self.layers.push(LayerWeights {
                wp: mat9(&wp),
                wn: mat9(&wn),
                b: b.try_into().expect("bias of 9"),
                bd: bd.try_into().expect("bias of 9"),
            });
        }
        Ok(())
    }

    /// Like [`Self::read_module`], but takes the module by value: each block of `C` is taken out
    /// of its `Param` (then uniquely owned, so Burn hands its buffer over without a copy),
    /// copied into the snapshot, and put back with the same id. Saves a pass and an allocation
    /// per block. Returns the module in every case.
    pub fn read_module_owned(&mut self, m: AutoencoderModule) -> (AutoencoderModule, Result<()>) {
        let AutoencoderModule { layers, components } = m;
        if let Err(e) = self.read_layers(&layers) {
            return (AutoencoderModule { layers, components }, Err(e));
        }
        let shapes: Vec<[usize; 2]> = components.iter().map(|p| p.lazy_shape().dims::<2>()).collect();
        let k: usize = shapes.iter().map(|s| s[0]).sum();
        let nc = shapes.first().map(|s| s[1]).unwrap_or(0);
        self.k = k;
        self.n = nc / 9;
        self.c.resize(k * nc, 0.0);
        let components: Vec<_> = components
            .into_par_iter()
            .zip(self.c.par_chunks_mut(COMPONENT_BLOCK * nc.max(1)))
            .map(|(p, dst)| {
                p.map(|t| {
                    let device = t.device();
                    let require_grad = t.is_require_grad();
                    let data = t.inner().into_data();
                    match data.as_slice::<f32>() {
                        Ok(v) => dst.copy_from_slice(v),
                        Err(_) => {
                            dst.copy_from_slice(&data.clone().convert::<f32>().try_into_vec_as::<f32>().expect("f32"))
                        }
                    }
                    let back = Tensor::from_data(data, &device);
                    if require_grad { back.require_grad() } else { back }
                })
            })
            .collect();
        let m = AutoencoderModule { layers, components };
        let r = check_finite("components", &self.c);
        (m, r)
    }
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
        for (l, g) in self.layers.iter().enumerate() {
            let all = g.wp.iter().flatten().chain(g.wn.iter().flatten()).chain(&g.b).chain(&g.bd);
            if all.clone().any(|v| !v.is_finite()) {
                return Some(format!("layers.{l}"));
            }
        }
        kernels::first_non_finite(&self.c).map(|i| format!("components[{i}]"))
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
    d_m: Vec<f32>,
    mask: Vec<f32>,
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
            d_m: Vec::new(),
            mask: vec![0.0; bp],
        }
    }

    /// Padded batch width.
    pub fn width(&self) -> usize {
        self.bp
    }

    fn ensure_backward(&mut self) {
        let sz = self.n * 9 * self.bp;
        for b in [&mut self.d_a, &mut self.d_b, &mut self.d_m] {
            if b.len() != sz {
                *b = vec![0.0; sz];
            }
        }
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
    gemm(
        cols_mut(&mut ws.dec[0], 9 * n, bp, b),
        false,
        MatRef::from_row_major_slice(&w.c, k, 9 * n).transpose(),
        cols(&ws.zt, k, bp, b),
    );
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

/// Loss and gradients for one batch.
///
/// `x` is the batch in VCB layout with `b_real` real shapes in lanes `0..b_real` (the rest zero);
/// `maps` must already be updated for `w.c`. Returns the loss terms; `grads` is overwritten.
#[allow(clippy::too_many_arguments)]
pub fn loss_and_grad(
    ws: &mut Workspace,
    w: &Weights,
    nb: &NeighborIndex,
    x: &[f32],
    b_real: usize,
    maps: &SupportMaps,
    cfg: &AutoencoderConfig,
    grads: &mut Grads,
) -> LossTerms {
    let (n, bp, k) = (ws.n, ws.bp, ws.k);
    let r = 9 * bp;
    let l = w.layers.len();
    assert!(b_real >= 1 && b_real <= bp);
    encode(ws, w, nb, x, b_real);
    decode(ws, w, nb, b_real);
    ws.ensure_backward();
    for (j, m) in ws.mask.iter_mut().enumerate() {
        *m = if j < b_real { 1.0 } else { 0.0 };
    }
    let inv_b = 1.0 / b_real as f64;

    // Reconstruction: dG_L = (2/B)(X̂ − X) on real lanes.
    let sse = kernels::squared_error(&ws.dec[l], x, &ws.mask, (2.0 * inv_b) as f32, &mut ws.d_a);
    let reconstruction = sse * inv_b;

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
        kernels::input_grad_rows(&lw.wp, &lw.wn, &ws.d_a, &mut ws.d_b, &mut ws.d_m, bp);
        kernels::mean_rows_transpose_add(nb, &ws.d_m, &mut ws.d_b, r);
        std::mem::swap(&mut ws.d_a, &mut ws.d_b);
    }
    // ws.d_a = ∂L/∂F̂ᵀ (9N × bp).
    let c_ref = MatRef::from_row_major_slice(&w.c, k, 9 * n);
    // dZᵀ = C·dF̂ᵀ.
    gemm(cols_mut(&mut ws.dzt, k, bp, b_real), false, c_ref, cols(&ws.d_a, 9 * n, bp, b_real));
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
    // Least-squares encoder z = P⁻¹·C·f (P = C·Cᵀ + εI): with u = P⁻¹·dz, the encoder's part of
    // dC is u·fᵀ − (u·zᵀ + z·uᵀ)·C and dF = Cᵀ·u. ws.dzt becomes u; the −(…)·C part is
    // added below.
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
    // dC = Zᵀ·dF̂ + dZᵀ·F.
    grads.c.resize(w.c.len(), 0.0);
    gemm(
        MatMut::from_row_major_slice_mut(&mut grads.c, k, 9 * n),
        false,
        cols(&ws.zt, k, bp, b_real),
        cols(&ws.d_a, 9 * n, bp, b_real).transpose(),
    );
    let f = &ws.enc_out[l - 1];
    gemm(
        MatMut::from_row_major_slice_mut(&mut grads.c, k, 9 * n),
        true,
        cols(&ws.dzt, k, bp, b_real),
        cols(f, 9 * n, bp, b_real).transpose(),
    );
    if let Some(m) = &sym {
        gemm(
            MatMut::from_row_major_slice_mut(&mut grads.c, k, 9 * n),
            true,
            MatRef::from_row_major_slice(m, k, k),
            c_ref,
        );
    }
    // dFᵀ = Cᵀ·dZᵀ (the padding lanes of ws.d_a stay zero from the decoder pass).
    gemm(cols_mut(&mut ws.d_a, 9 * n, bp, b_real), false, c_ref.transpose(), cols(&ws.dzt, k, bp, b_real));

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
            kernels::input_grad_rows(&transpose9(&lw.wp), &transpose9(&lw.wn), &ws.d_a, &mut ws.d_b, &mut ws.d_m, bp);
            kernels::mean_rows_transpose_add(nb, &ws.d_m, &mut ws.d_b, r);
            std::mem::swap(&mut ws.d_a, &mut ws.d_b);
        }
    }

    // Sparsity on C.
    let sparsity = sparsity_with_grad(&w.c, maps, (cfg.lambda1 / k as f64) as f32, &mut grads.c);
    let orthogonality = if cfg.lambda_orthogonal > 0.0 {
        orthogonality_with_grad(&w.c, k, 9 * n, (cfg.lambda_orthogonal / k as f64) as f32, &mut grads.c)
    } else {
        0.0
    };

    LossTerms {
        total: reconstruction + cfg.lambda1 * sparsity + cfg.lambda2 * hinge + cfg.lambda_orthogonal * orthogonality,
        reconstruction,
        sparsity,
        hinge,
        orthogonality,
    }
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
