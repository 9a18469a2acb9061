//! Hand-written numeric kernels of the autoencoder's training step (plain Rust, `f32`).
//!
//! # Layout ("VCB")
//! Per-vertex activations of a batch are stored vertex-major, then channel, then shape:
//! element `(i, c, b)` at `(i * 9 + c) * bp + b`, where `bp` is the batch width padded to a
//! multiple of [`LANES`]. One vertex is one row of `9 * bp` numbers. Read as a matrix, a buffer
//! is `Fᵀ ∈ R^{9N × bp}` with rows in the vertex-major flatten order `i * 9 + c` of the
//! reference implementation, so the latent product `Zᵀ = C·Fᵀ` is a plain GEMM.
//!
//! Every kernel works on the `bp` lanes of a channel in blocks of [`LANES`] with fixed-size
//! arrays, which the compiler turns into SIMD; each kernel is compiled twice (baseline and
//! AVX2+FMA) and picks one at run time. Reductions use a fixed chunking of the vertices, so
//! results do not depend on the number of threads or on scheduling (bit-reproducible runs).

use rayon::prelude::*;

use super::neighbors::NeighborIndex;

/// SIMD block width (f32 lanes of an AVX2 register). The padded batch width is a multiple.
pub const LANES: usize = 8;
/// Vertices per parallel work item (fixed, so that reductions are deterministic).
pub const ROW_CHUNK: usize = 64;

/// A 9 × 9 weight matrix, row-major `[out][in]`.
pub type Mat9 = [[f32; 9]; 9];
/// A 9 × 9 accumulator in `f64`.
pub type Acc9 = [[f64; 9]; 9];

/// Rounds a batch size up to a multiple of [`LANES`].
pub fn padded_width(b: usize) -> usize {
    b.div_ceil(LANES).max(1) * LANES
}

/// Transpose of a 9 × 9 matrix.
pub fn transpose9(w: &Mat9) -> Mat9 {
    let mut t = [[0.0; 9]; 9];
    for (o, row) in w.iter().enumerate() {
        for (a, &v) in row.iter().enumerate() {
            t[a][o] = v;
        }
    }
    t
}

#[cfg(target_arch = "x86_64")]
#[inline]
fn avx2_available() -> bool {
    std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
}

/// Multiply-add policy of a kernel instance: fused (`vfmadd`, in the AVX2+FMA build) or plain
/// `a·b + c` (baseline build, where a fused multiply-add would be a slow library call).
pub trait MulAdd {
    /// `a·b + c`.
    fn mul_add(a: f32, b: f32, c: f32) -> f32;
}

/// Fused multiply-add (one rounding).
pub struct Fused;
impl MulAdd for Fused {
    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
}

/// Separate multiply and add.
pub struct Plain;
impl MulAdd for Plain {
    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a * b + c
    }
}

/// Defines `$name` as a run-time dispatcher to `$imp::<Fused>` compiled for AVX2+FMA, or to
/// `$imp::<Plain>` for the baseline target.
macro_rules! dispatch {
    ($(#[$attr:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? => $imp:ident) => {
        $(#[$attr])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2,fma")]
                fn fast($($arg: $ty),*) $(-> $ret)? {
                    $imp::<Fused>($($arg),*)
                }
                if avx2_available() {
                    // SAFETY: the CPU supports the features `fast` was compiled for.
                    return unsafe { fast($($arg),*) };
                }
            }
            $imp::<Plain>($($arg),*)
        }
    };
}

/// One SIMD block.
type V = [f32; LANES];

#[inline(always)]
fn axpy<M: MulAdd>(acc: &mut V, w: f32, x: &V) {
    for l in 0..LANES {
        acc[l] = M::mul_add(w, x[l], acc[l]);
    }
}

// ---------------------------------------------------------------------------------------------
// tanh
// ---------------------------------------------------------------------------------------------

/// tanh of one value, branch-free so that blocks of it vectorise. Relative error ≲ 5e-7 in f32;
/// NaN propagates (the training loop relies on it to detect divergence).
///
/// |x| < 0.25: odd Taylor series of tanh up to x⁹ (truncation < 3e-9 relative). Otherwise
/// tanh|x| = 1 − 2/(e^{2|x|} + 1) with e^y = 2ⁿ·e^r, n = round(y/ln2), |r| ≤ ln2/2, e^r by its
/// degree-7 Taylor polynomial (error < 5e-9); |x| is clamped at 10 (tanh 10 rounds to 1 in f32).
#[inline(always)]
pub fn tanh_f32(x: f32) -> f32 {
    let ax = x.abs();
    let ax = if ax > 10.0 { 10.0 } else { ax }; // keeps NaN
    // Small-argument branch.
    let x2 = ax * ax;
    let small = ax * (1.0 + x2 * (-1.0 / 3.0 + x2 * (2.0 / 15.0 + x2 * (-17.0 / 315.0 + x2 * (62.0 / 2835.0)))));
    // e^{2|x|} by range reduction.
    let y = 2.0 * ax;
    const MAGIC: f32 = 12_582_912.0; // 1.5·2²³: adding it rounds to an integer in the low bits
    let t = y * std::f32::consts::LOG2_E + MAGIC;
    let n = t - MAGIC;
    let ni = (t.to_bits() as i32).wrapping_sub(MAGIC.to_bits() as i32);
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let r = (y - n * LN2_HI) - n * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    let scale = f32::from_bits((ni.wrapping_add(127) as u32) << 23);
    let e = p * scale;
    let large = 1.0 - 2.0 / (e + 1.0);
    let v = if ax < 0.25 { small } else { large };
    v.copysign(x)
}

#[inline(always)]
fn tanh_in_place(v: &mut [f32]) {
    // A plain loop over a slice: the loop vectoriser turns it into straight SIMD code.
    for x in v.iter_mut() {
        *x = tanh_f32(*x);
    }
}

#[inline(always)]
#[allow(clippy::extra_unused_type_parameters)]
fn tanh_slice_impl<M: MulAdd>(v: &mut [f32]) {
    tanh_in_place(v);
}

dispatch! {
    /// Applies [`tanh_f32`] in place.
    pub fn tanh_slice(v: &mut [f32]) => tanh_slice_impl
}

// ---------------------------------------------------------------------------------------------
// Neighbour means
// ---------------------------------------------------------------------------------------------

#[inline(always)]
fn add_row(dst: &mut [V], src: &[V]) {
    debug_assert_eq!(dst.len(), src.len());
    for (d, s) in dst.iter_mut().zip(src) {
        for l in 0..LANES {
            d[l] += s[l];
        }
    }
}

#[inline(always)]
fn add_scaled_row<M: MulAdd>(dst: &mut [V], src: &[V], w: f32) {
    debug_assert_eq!(dst.len(), src.len());
    for (d, s) in dst.iter_mut().zip(src) {
        axpy::<M>(d, w, s);
    }
}

#[inline(always)]
#[allow(clippy::extra_unused_type_parameters)]
fn mean_rows_impl<M: MulAdd>(nb: &NeighborIndex, src: &[f32], dst: &mut [f32], first_row: usize, r: usize) {
    let (sv, _) = src.as_chunks::<LANES>();
    let rv = r / LANES;
    for (k, out) in dst.chunks_exact_mut(r).enumerate() {
        let (out, _) = out.as_chunks_mut::<LANES>();
        let i = first_row + k;
        out.fill([0.0; LANES]);
        for &j in nb.neighbors(i) {
            let j = j as usize;
            add_row(out, &sv[j * rv..(j + 1) * rv]);
        }
        let w = nb.inv_degree(i);
        for v in out.iter_mut() {
            for x in v.iter_mut() {
                *x *= w;
            }
        }
    }
}

dispatch! {
    fn mean_rows_chunk(nb: &NeighborIndex, src: &[f32], dst: &mut [f32], first_row: usize, r: usize) => mean_rows_impl
}

#[inline(always)]
fn mean_rows_t_add_impl<M: MulAdd>(nb: &NeighborIndex, src: &[f32], dst: &mut [f32], first_row: usize, r: usize) {
    let (sv, _) = src.as_chunks::<LANES>();
    let rv = r / LANES;
    for (k, out) in dst.chunks_exact_mut(r).enumerate() {
        let (out, _) = out.as_chunks_mut::<LANES>();
        let j = first_row + k;
        let (idx, w) = nb.transposed(j);
        for (&i, &w) in idx.iter().zip(w) {
            let i = i as usize;
            add_scaled_row::<M>(out, &sv[i * rv..(i + 1) * rv], w);
        }
    }
}

dispatch! {
    fn mean_rows_t_add_chunk(nb: &NeighborIndex, src: &[f32], dst: &mut [f32], first_row: usize, r: usize) => mean_rows_t_add_impl
}

/// Neighbour mean `dst_i = (1/|N(i)|) Σ_{j∈N(i)} src_j` (zero for a vertex without neighbours).
///
/// # Shapes
/// `src`, `dst`: N rows of `r` numbers (`r` a multiple of [`LANES`]).
pub fn mean_rows(nb: &NeighborIndex, src: &[f32], dst: &mut [f32], r: usize) {
    debug_assert_eq!(src.len(), nb.n_vertices() * r);
    debug_assert_eq!(dst.len(), src.len());
    dst.par_chunks_mut(ROW_CHUNK * r)
        .enumerate()
        .for_each(|(ci, chunk)| mean_rows_chunk(nb, src, chunk, ci * ROW_CHUNK, r));
}

/// Adds the transpose of [`mean_rows`]: `dst_j += Σ_{i : j∈N(i)} src_i / |N(i)|` (the
/// back-propagation of a neighbour mean).
///
/// # Shapes
/// `src`, `dst`: N rows of `r` numbers.
pub fn mean_rows_transpose_add(nb: &NeighborIndex, src: &[f32], dst: &mut [f32], r: usize) {
    debug_assert_eq!(src.len(), nb.n_vertices() * r);
    debug_assert_eq!(dst.len(), src.len());
    dst.par_chunks_mut(ROW_CHUNK * r)
        .enumerate()
        .for_each(|(ci, chunk)| mean_rows_t_add_chunk(nb, src, chunk, ci * ROW_CHUNK, r));
}

// ---------------------------------------------------------------------------------------------
// Per-vertex 9 → 9 maps
// ---------------------------------------------------------------------------------------------

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn conv_rows_impl<M: MulAdd>(
    ws: &Mat9,
    x: &[f32],
    wn: &Mat9,
    m: &[f32],
    bias: &[f32; 9],
    out: &mut [f32],
    bp: usize,
    tanh: bool,
) {
    let r = 9 * bp;
    let nb = bp / LANES;
    for ((xr, mr), or) in x.chunks_exact(r).zip(m.chunks_exact(r)).zip(out.chunks_exact_mut(r)) {
        let (xv, _) = xr.as_chunks::<LANES>();
        let (mv, _) = mr.as_chunks::<LANES>();
        let (ov, _) = or.as_chunks_mut::<LANES>();
        for j in 0..nb {
            // Nine independent accumulators (one per output channel) keep the FMA pipes busy.
            let mut acc = [[0.0f32; LANES]; 9];
            for (o, a) in acc.iter_mut().enumerate() {
                *a = [bias[o]; LANES];
            }
            for a in 0..9 {
                let xa = &xv[a * nb + j];
                let ma = &mv[a * nb + j];
                for (o, acc_o) in acc.iter_mut().enumerate() {
                    axpy::<M>(acc_o, ws[o][a], xa);
                    axpy::<M>(acc_o, wn[o][a], ma);
                }
            }
            for (o, acc_o) in acc.iter().enumerate() {
                ov[o * nb + j] = *acc_o;
            }
        }
        if tanh {
            tanh_in_place(or);
        }
    }
}

dispatch! {
    #[allow(clippy::too_many_arguments)]
    fn conv_rows_chunk(ws: &Mat9, x: &[f32], wn: &Mat9, m: &[f32], bias: &[f32; 9], out: &mut [f32], bp: usize, tanh: bool) => conv_rows_impl
}

/// Mesh convolution on rows: `out_i = act(ws·x_i + wn·m_i + bias)` per shape, where `m` is the
/// neighbour mean of `x` and act is tanh or the identity.
///
/// # Shapes
/// `x`, `m`, `out`: N rows of `9·bp` (VCB layout); `ws`, `wn`: `[out][in]`.
#[allow(clippy::too_many_arguments)]
pub fn conv_rows(ws: &Mat9, x: &[f32], wn: &Mat9, m: &[f32], bias: &[f32; 9], out: &mut [f32], bp: usize, tanh: bool) {
    let r = 9 * bp;
    out.par_chunks_mut(ROW_CHUNK * r).enumerate().for_each(|(ci, chunk)| {
        let s = ci * ROW_CHUNK * r;
        let e = s + chunk.len();
        conv_rows_chunk(ws, &x[s..e], wn, &m[s..e], bias, chunk, bp, tanh);
    });
}

#[inline(always)]
fn mat_rows<M: MulAdd>(wt: &Mat9, dyv: &[V], outv: &mut [V], nb: usize) {
    for j in 0..nb {
        let mut acc = [[0.0f32; LANES]; 9];
        for o in 0..9 {
            let d = &dyv[o * nb + j];
            for (a, acc_a) in acc.iter_mut().enumerate() {
                axpy::<M>(acc_a, wt[a][o], d);
            }
        }
        for (a, acc_a) in acc.iter().enumerate() {
            outv[a * nb + j] = *acc_a;
        }
    }
}

#[inline(always)]
fn input_grad_rows_impl<M: MulAdd>(wst: &Mat9, wnt: &Mat9, dy: &[f32], dx: &mut [f32], dm: &mut [f32], bp: usize) {
    let r = 9 * bp;
    let nb = bp / LANES;
    for ((dyr, dxr), dmr) in dy.chunks_exact(r).zip(dx.chunks_exact_mut(r)).zip(dm.chunks_exact_mut(r)) {
        let (dyv, _) = dyr.as_chunks::<LANES>();
        mat_rows::<M>(wst, dyv, dxr.as_chunks_mut::<LANES>().0, nb);
        mat_rows::<M>(wnt, dyv, dmr.as_chunks_mut::<LANES>().0, nb);
    }
}

dispatch! {
    fn input_grad_rows_chunk(wst: &Mat9, wnt: &Mat9, dy: &[f32], dx: &mut [f32], dm: &mut [f32], bp: usize) => input_grad_rows_impl
}

/// Back-propagation of [`conv_rows`] to its inputs: `dx_i = wsᵀ·dy_i`, `dm_i = wnᵀ·dy_i`
/// (`wst`, `wnt` are the transposes, passed pre-transposed). The caller adds the transposed
/// neighbour mean of `dm` to `dx`.
///
/// # Shapes
/// `dy`, `dx`, `dm`: N rows of `9·bp`.
pub fn input_grad_rows(wst: &Mat9, wnt: &Mat9, dy: &[f32], dx: &mut [f32], dm: &mut [f32], bp: usize) {
    let r = 9 * bp;
    dx.par_chunks_mut(ROW_CHUNK * r).zip(dm.par_chunks_mut(ROW_CHUNK * r)).enumerate().for_each(|(ci, (cx, cm))| {
        let s = ci * ROW_CHUNK * r;
        input_grad_rows_chunk(wst, wnt, &dy[s..s + cx.len()], cx, cm, bp);
    });
}

/// Gradient accumulators of one convolution (oriented like the matrices it was run with).
#[derive(Debug, Clone, Copy)]
pub struct ConvGrad {
    /// ∂L/∂ws, `[out][in]`.
    pub ws: Acc9,
    /// ∂L/∂wn, `[out][in]`.
    pub wn: Acc9,
    /// ∂L/∂bias.
    pub bias: [f64; 9],
}

impl ConvGrad {
    fn zero() -> Self {
        ConvGrad { ws: [[0.0; 9]; 9], wn: [[0.0; 9]; 9], bias: [0.0; 9] }
    }
    fn add(&mut self, o: &ConvGrad) {
        for p in 0..9 {
            for q in 0..9 {
                self.ws[p][q] += o.ws[p][q];
                self.wn[p][q] += o.wn[p][q];
            }
            self.bias[p] += o.bias[p];
        }
    }
}

#[inline(always)]
fn outer_acc<M: MulAdd>(dy: &[f32], x: &[f32], bp: usize, out: &mut Acc9) {
    let r = 9 * bp;
    let nb = bp / LANES;
    for (o, out_o) in out.iter_mut().enumerate() {
        let mut acc = [[0.0f32; LANES]; 9];
        for (dyr, xr) in dy.chunks_exact(r).zip(x.chunks_exact(r)) {
            let (dyv, _) = dyr.as_chunks::<LANES>();
            let (xv, _) = xr.as_chunks::<LANES>();
            for j in 0..nb {
                let d = &dyv[o * nb + j];
                for (a, acc_a) in acc.iter_mut().enumerate() {
                    let xa = &xv[a * nb + j];
                    for l in 0..LANES {
                        acc_a[l] = M::mul_add(d[l], xa[l], acc_a[l]);
                    }
                }
            }
        }
        for (a, acc_a) in acc.iter().enumerate() {
            out_o[a] += acc_a.iter().map(|&v| v as f64).sum::<f64>();
        }
    }
}

#[inline(always)]
fn weight_grad_rows_impl<M: MulAdd>(dy: &[f32], x: &[f32], m: &[f32], bp: usize, g: &mut ConvGrad) {
    outer_acc::<M>(dy, x, bp, &mut g.ws);
    outer_acc::<M>(dy, m, bp, &mut g.wn);
    let r = 9 * bp;
    let nb = bp / LANES;
    for o in 0..9 {
        let mut acc = [0.0f32; LANES];
        for dyr in dy.chunks_exact(r) {
            let (dyv, _) = dyr.as_chunks::<LANES>();
            for d in &dyv[o * nb..(o + 1) * nb] {
                for l in 0..LANES {
                    acc[l] += d[l];
                }
            }
        }
        g.bias[o] += acc.iter().map(|&v| v as f64).sum::<f64>();
    }
}

dispatch! {
    fn weight_grad_rows_chunk(dy: &[f32], x: &[f32], m: &[f32], bp: usize, g: &mut ConvGrad) => weight_grad_rows_impl
}

/// Weight gradients of [`conv_rows`]: `∂ws = Σ_i dy_i x_iᵀ`, `∂wn = Σ_i dy_i m_iᵀ`,
/// `∂bias = Σ_i dy_i` (sums over vertices and shapes). Padded lanes must hold `dy = 0`.
///
/// # Shapes
/// `dy`, `x`, `m`: N rows of `9·bp`.
pub fn weight_grad_rows(dy: &[f32], x: &[f32], m: &[f32], bp: usize) -> ConvGrad {
    let r = 9 * bp;
    let parts: Vec<ConvGrad> = dy
        .par_chunks(ROW_CHUNK * r)
        .enumerate()
        .map(|(ci, cdy)| {
            let s = ci * ROW_CHUNK * r;
            let mut g = ConvGrad::zero();
            weight_grad_rows_chunk(cdy, &x[s..s + cdy.len()], &m[s..s + cdy.len()], bp, &mut g);
            g
        })
        .collect();
    let mut g = ConvGrad::zero();
    for p in &parts {
        g.add(p);
    }
    g
}

// ---------------------------------------------------------------------------------------------
// Latent products with a short inner dimension
// ---------------------------------------------------------------------------------------------

/// Output rows per register block of [`ct_times`].
const CT_ROWS: usize = 8;

#[inline(always)]
fn ct_times_impl<M: MulAdd>(c: &[f32], stride: usize, k: usize, y: &[f32], out: &mut [f32], j0: usize, bp: usize) {
    let nb = bp / LANES;
    let (yv, _) = y.as_chunks::<LANES>();
    let rows = out.len() / bp;
    let mut j = 0;
    while j < rows {
        let t_n = CT_ROWS.min(rows - j);
        for v in 0..nb {
            let mut acc = [[0.0f32; LANES]; CT_ROWS];
            if t_n == CT_ROWS {
                for kk in 0..k {
                    let yk = &yv[kk * nb + v];
                    let s = kk * stride + j0 + j;
                    let cr: &[f32; CT_ROWS] = c[s..s + CT_ROWS].try_into().unwrap();
                    for (a, &w) in acc.iter_mut().zip(cr) {
                        axpy::<M>(a, w, yk);
                    }
                }
            } else {
                for kk in 0..k {
                    let yk = &yv[kk * nb + v];
                    let s = kk * stride + j0 + j;
                    for (a, &w) in acc.iter_mut().zip(&c[s..s + t_n]) {
                        axpy::<M>(a, w, yk);
                    }
                }
            }
            for (t, a) in acc.iter().take(t_n).enumerate() {
                let o = (j + t) * bp + v * LANES;
                out[o..o + LANES].copy_from_slice(a);
            }
        }
        j += t_n;
    }
}

dispatch! {
    fn ct_times_chunk(c: &[f32], stride: usize, k: usize, y: &[f32], out: &mut [f32], j0: usize, bp: usize) => ct_times_impl
}

/// `out = Cᵀ·Y` for `C` `[k, cols]` row-major and `Y` `[k, bp]` (row-major, lanes `b..bp`
/// taken as zero): `out` is `[cols, bp]` row-major (VCB), every lane written (`+0` in lanes
/// `b..bp`). Each entry is the multiply-add chain over `k` in ascending order from zero, which is
/// what faer's GEMM computes for this shape when `3 ≤ k ≤ 512` (so the result is
/// bit-identical); this kernel streams `C` once, in parallel over blocks of rows of `out`, and
/// is faster than the GEMM for one SIMD block of lanes (`bp = LANES`).
pub fn ct_times(c: &[f32], k: usize, cols: usize, y: &[f32], bp: usize, b: usize, out: &mut [f32]) {
    assert!(bp.is_multiple_of(LANES) && b <= bp && c.len() == k * cols && y.len() >= k * bp && out.len() == cols * bp);
    let mut yl = y[..k * bp].to_vec();
    for row in yl.chunks_exact_mut(bp) {
        row[b..].fill(0.0);
    }
    const CH: usize = 512;
    out.par_chunks_mut(CH * bp).enumerate().for_each(|(ci, o)| ct_times_chunk(c, cols, k, &yl, o, ci * CH, bp));
}

/// Inner-dimension block of a GEMM with a long inner dimension: faer sums such a product in
/// blocks of this many terms (one multiply-add chain each, from zero) and adds the blocks in
/// order (measured for every shape the engine uses; [`block_chains`] reproduces it).
pub const GEMM_INNER_BLOCK: usize = 512;

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn block_chains_rows<M: MulAdd, const R: usize>(
    rows: &[&[f32]],
    y: &[V],
    nb: usize,
    k0: usize,
    k: usize,
    parts: &mut [f32],
    bp: usize,
) {
    let tw = rows[0].len();
    let rows: [&[f32]; R] = std::array::from_fn(|r| &rows[r][..tw]);
    for (bi, b0) in (0..tw).step_by(GEMM_INNER_BLOCK).enumerate() {
        let bn = GEMM_INNER_BLOCK.min(tw - b0);
        let rb: [&[f32]; R] = std::array::from_fn(|r| &rows[r][b0..b0 + bn]);
        let yb = &y[b0 * nb..(b0 + bn) * nb];
        for v in 0..nb {
            let mut acc = [[0.0f32; LANES]; R];
            for j in 0..bn {
                let yj = &yb[j * nb + v];
                for (a, row) in acc.iter_mut().zip(&rb) {
                    axpy::<M>(a, row[j], yj);
                }
            }
            for (r, a) in acc.iter().enumerate() {
                let o = (bi * k + k0 + r) * bp + v * LANES;
                parts[o..o + LANES].copy_from_slice(a);
            }
        }
    }
}

#[inline(always)]
fn block_chains_impl<M: MulAdd>(rows: &[&[f32]], y: &[f32], k0: usize, k: usize, parts: &mut [f32], bp: usize) {
    let nb = bp / LANES;
    let (yv, _) = y.as_chunks::<LANES>();
    let mut r0 = 0;
    while r0 + 8 <= rows.len() {
        block_chains_rows::<M, 8>(&rows[r0..r0 + 8], yv, nb, k0 + r0, k, parts, bp);
        r0 += 8;
    }
    while r0 + 2 <= rows.len() {
        block_chains_rows::<M, 2>(&rows[r0..r0 + 2], yv, nb, k0 + r0, k, parts, bp);
        r0 += 2;
    }
    while r0 < rows.len() {
        block_chains_rows::<M, 1>(&rows[r0..r0 + 1], yv, nb, k0 + r0, k, parts, bp);
        r0 += 1;
    }
}

dispatch! {
    /// Partial products of rows `k0..k0 + rows.len()` of `C·Y` over a range of the inner
    /// dimension: `rows` are those rows' slices of `C` over the range (equal lengths), `y` the
    /// range's rows of `Y` (VCB, `bp` lanes); for every [`GEMM_INNER_BLOCK`] of the range, the
    /// multiply-add chain from zero goes to `parts[block][k][lane]` (`k` rows per block). Adding
    /// the blocks of the whole inner dimension in order gives faer's GEMM result.
    pub fn block_chains(rows: &[&[f32]], y: &[f32], k0: usize, k: usize, parts: &mut [f32], bp: usize) => block_chains_impl
}

// ---------------------------------------------------------------------------------------------
// Elementwise
// ---------------------------------------------------------------------------------------------

#[inline(always)]
#[allow(clippy::extra_unused_type_parameters)]
fn tanh_backward_impl<M: MulAdd>(y: &[f32], dy: &mut [f32]) {
    for (d, v) in dy.chunks_exact_mut(LANES).zip(y.chunks_exact(LANES)) {
        let d: &mut [f32; LANES] = d.try_into().unwrap();
        let v: &[f32; LANES] = v.try_into().unwrap();
        for l in 0..LANES {
            d[l] *= 1.0 - v[l] * v[l];
        }
    }
}

dispatch! {
    fn tanh_backward_chunk(y: &[f32], dy: &mut [f32]) => tanh_backward_impl
}

/// `dy ⊙= 1 − y²` (back-propagation through `y = tanh(h)`).
pub fn tanh_backward(y: &[f32], dy: &mut [f32]) {
    const CH: usize = 1 << 14;
    dy.par_chunks_mut(CH).enumerate().for_each(|(ci, c)| {
        let s = ci * CH;
        tanh_backward_chunk(&y[s..s + c.len()], c);
    });
}

#[inline(always)]
#[allow(clippy::extra_unused_type_parameters)]
fn sq_err_impl<M: MulAdd>(xhat: &[f32], x: &[f32], mask: &[f32], scale: f32, grad: &mut [f32]) -> f64 {
    let bp = mask.len();
    let mut total = 0.0f64;
    for ((xh, xr), gr) in xhat.chunks_exact(bp).zip(x.chunks_exact(bp)).zip(grad.chunks_exact_mut(bp)) {
        let mut acc = [0.0f32; LANES];
        for c in (0..bp).step_by(LANES) {
            for l in 0..LANES {
                let d = (xh[c + l] - xr[c + l]) * mask[c + l];
                acc[l] += d * d;
                gr[c + l] = scale * d;
            }
        }
        total += acc.iter().map(|&v| v as f64).sum::<f64>();
    }
    total
}

dispatch! {
    fn sq_err_chunk(xhat: &[f32], x: &[f32], mask: &[f32], scale: f32, grad: &mut [f32]) -> f64 => sq_err_impl
}

/// [`sq_err_impl`] with row `r` of the chunk weighted by `vertex_w[(row0 + r) / 9]`.
#[inline(always)]
#[allow(clippy::extra_unused_type_parameters)]
fn sq_err_weighted_impl<M: MulAdd>(
    xhat: &[f32],
    x: &[f32],
    mask: &[f32],
    vertex_w: &[f32],
    row0: usize,
    scale: f32,
    grad: &mut [f32],
) -> f64 {
    let bp = mask.len();
    let mut total = 0.0f64;
    for (r, ((xh, xr), gr)) in xhat.chunks_exact(bp).zip(x.chunks_exact(bp)).zip(grad.chunks_exact_mut(bp)).enumerate()
    {
        let w = vertex_w[(row0 + r) / 9];
        let mut acc = [0.0f32; LANES];
        for c in (0..bp).step_by(LANES) {
            for l in 0..LANES {
                let d = (xh[c + l] - xr[c + l]) * mask[c + l];
                acc[l] += d * d;
                gr[c + l] = scale * w * d;
            }
        }
        total += w as f64 * acc.iter().map(|&v| v as f64).sum::<f64>();
    }
    total
}

dispatch! {
    fn sq_err_weighted_chunk(xhat: &[f32], x: &[f32], mask: &[f32], vertex_w: &[f32], row0: usize, scale: f32, grad: &mut [f32]) -> f64 => sq_err_weighted_impl
}

/// Sum of squared errors over the real lanes (`mask` 1 for real shapes, 0 for padding), each
/// row weighted by its vertex's weight when `vertex_w` is given (row `i·9 + c` by
/// `vertex_w[i]`; `feature_weights`), and its gradient scaled: `grad = scale·w·mask·(xhat − x)`.
/// Returns Σ w·mask·(xhat − x)².
///
/// # Shapes
/// `xhat`, `x`, `grad`: rows of `bp = mask.len()` numbers (9N rows, VCB); `vertex_w`: `[N]`.
pub fn squared_error(
    xhat: &[f32],
    x: &[f32],
    mask: &[f32],
    vertex_w: Option<&[f32]>,
    scale: f32,
    grad: &mut [f32],
) -> f64 {
    let bp = mask.len();
    let ch = 512 * bp;
    if let Some(w) = vertex_w {
        assert_eq!(w.len() * 9 * bp, grad.len(), "one weight per vertex");
    }
    let parts: Vec<f64> = grad
        .par_chunks_mut(ch)
        .enumerate()
        .map(|(ci, g)| {
            let s = ci * ch;
            match vertex_w {
                Some(w) => sq_err_weighted_chunk(&xhat[s..s + g.len()], &x[s..s + g.len()], mask, w, s / bp, scale, g),
                None => sq_err_chunk(&xhat[s..s + g.len()], &x[s..s + g.len()], mask, scale, g),
            }
        })
        .collect();
    parts.iter().sum()
}

#[inline(always)]
fn vertex_sq_norms_impl<M: MulAdd>(row: &[f32], out: &mut [f32]) {
    for (v, o) in row.chunks_exact(9).zip(out.iter_mut()) {
        let mut s = 0.0f32;
        for &x in v {
            s = M::mul_add(x, x, s);
        }
        *o = s;
    }
}

dispatch! {
    /// Squared norms of consecutive 9-vectors: `out[i] = ‖row[9i..9i+9]‖²`.
    pub fn vertex_sq_norms(row: &[f32], out: &mut [f32]) => vertex_sq_norms_impl
}

#[inline(always)]
fn group_sparsity_acc<M: MulAdd>(
    row: &[f32],
    sq_norms: &[f32],
    lambda: &[f32],
    eps2: f32,
    scale: f32,
    grad: &mut [f32],
    total: &mut f64,
) {
    for (((v, g), &s), &l) in row.chunks_exact(9).zip(grad.chunks_exact_mut(9)).zip(sq_norms).zip(lambda) {
        if l == 0.0 {
            continue;
        }
        let nrm = s.max(eps2).sqrt();
        *total += (l * nrm) as f64;
        if s > eps2 {
            let f = scale * l / nrm;
            for (gq, &vq) in g.iter_mut().zip(v) {
                *gq = M::mul_add(f, vq, *gq);
            }
        }
    }
}

#[inline(always)]
fn group_sparsity_impl<M: MulAdd>(
    row: &[f32],
    sq_norms: &[f32],
    lambda: &[f32],
    eps2: f32,
    scale: f32,
    grad: &mut [f32],
) -> f64 {
    let mut total = 0.0f64;
    group_sparsity_acc::<M>(row, sq_norms, lambda, eps2, scale, grad, &mut total);
    total
}

dispatch! {
    /// One component's weighted group norm `Σ_i Λ_i ‖v_i‖_ε` (returned) and its gradient
    /// `grad_i += scale·Λ_i·v_i/‖v_i‖` (zero where `‖v_i‖² ≤ eps2`), for 9-vectors `v_i`.
    pub fn group_sparsity(row: &[f32], sq_norms: &[f32], lambda: &[f32], eps2: f32, scale: f32, grad: &mut [f32]) -> f64 => group_sparsity_impl
}

/// Vertices per block of the fused passes over `C` (the block's numbers stay in L1 between the
/// update and the scan that follows it).
const FUSED_VERTICES: usize = 128;

#[inline(always)]
fn group_sparsity_checked_impl<M: MulAdd>(
    row: &[f32],
    sq_norms: &[f32],
    lambda: &[f32],
    eps2: f32,
    scale: f32,
    grad: &mut [f32],
) -> (f64, u32) {
    let mut total = 0.0f64;
    let mut exp = 0u32;
    let w = 9 * FUSED_VERTICES;
    for (((v, g), s), l) in
        row.chunks(w).zip(grad.chunks_mut(w)).zip(sq_norms.chunks(FUSED_VERTICES)).zip(lambda.chunks(FUSED_VERTICES))
    {
        group_sparsity_acc::<M>(v, s, l, eps2, scale, g, &mut total);
        exp = exp.max(max_exponent_impl::<M>(g));
    }
    (total, exp)
}

dispatch! {
    /// [`group_sparsity`], and the largest exponent field of the updated `grad` (as
    /// [`first_non_finite`] scans it: `0x7f80_0000` iff some entry is infinite or NaN), in the
    /// same pass.
    pub fn group_sparsity_checked(row: &[f32], sq_norms: &[f32], lambda: &[f32], eps2: f32, scale: f32, grad: &mut [f32]) -> (f64, u32) => group_sparsity_checked_impl
}

/// The exponent field of an `f32` that is infinite or NaN.
pub const NON_FINITE_EXPONENT: u32 = 0x7f80_0000;

/// Scalars of one Adam step with Burn's arithmetic ([`burn::optim::AdamConfig`], no weight
/// decay, no AMSGrad), all in `f32`:
/// `m ← β1·m + (1−β1)·g`, `v ← β2·v + (1−β2)·g²` (at the first step `m = (1−β1)·g`,
/// `v = (1−β2)·g²`), `p ← p − lr·(m·c)/(√v + ε·s)` with `s = √(1 − β2ᵗ)`, `c = s/(1 − β1ᵗ)`.
#[derive(Debug, Clone, Copy)]
pub struct AdamScalars {
    /// β1.
    pub beta1: f32,
    /// β2.
    pub beta2: f32,
    /// 1 − β1.
    pub one_minus_beta1: f32,
    /// 1 − β2.
    pub one_minus_beta2: f32,
    /// `c = √(1 − β2ᵗ)/(1 − β1ᵗ)`.
    pub combined: f32,
    /// `ε·√(1 − β2ᵗ)`.
    pub eps: f32,
    /// Step size.
    pub lr: f32,
    /// Whether this is the first step (the moments are then written, not read).
    pub first: bool,
}

impl AdamScalars {
    /// The scalars of step `time` (1-based), computed exactly as Burn's `AdaptiveMomentum` does.
    pub fn new(beta1: f32, beta2: f32, epsilon: f32, lr: f64, time: usize) -> Self {
        let t = time as i32;
        let bias_correction2_sqrt = (1.0 - beta2.powi(t)).sqrt();
        AdamScalars {
            beta1,
            beta2,
            one_minus_beta1: 1.0 - beta1,
            one_minus_beta2: 1.0 - beta2,
            combined: bias_correction2_sqrt / (1.0 - beta1.powi(t)),
            eps: epsilon * bias_correction2_sqrt,
            lr: lr as f32,
            first: time == 1,
        }
    }
}

#[inline(always)]
fn adam_block(p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], a: &AdamScalars) {
    // Same operations in the same order as Burn's tensor ops (no fused multiply-add), so the
    // result is bit-identical to Burn's Adam.
    if a.first {
        for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
            *m = g * a.one_minus_beta1;
            *v = (g * g) * a.one_minus_beta2;
            *p -= ((*m * a.combined) / (v.sqrt() + a.eps)) * a.lr;
        }
    } else {
        for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
            *m = *m * a.beta1 + g * a.one_minus_beta1;
            *v = *v * a.beta2 + (g * g) * a.one_minus_beta2;
            *p -= ((*m * a.combined) / (v.sqrt() + a.eps)) * a.lr;
        }
    }
}

#[inline(always)]
fn adam_norms_impl<M: MulAdd>(
    p: &mut [f32],
    g: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    a: &AdamScalars,
    sq_norms: &mut [f32],
) -> u32 {
    let w = 9 * FUSED_VERTICES;
    let mut exp = 0u32;
    for ((((p, g), m), v), sq) in p
        .chunks_mut(w)
        .zip(g.chunks(w))
        .zip(m.chunks_mut(w))
        .zip(v.chunks_mut(w))
        .zip(sq_norms.chunks_mut(FUSED_VERTICES))
    {
        adam_block(p, g, m, v, a);
        vertex_sq_norms_impl::<M>(p, sq);
        exp = exp.max(max_exponent_impl::<M>(p));
    }
    exp
}

dispatch! {
    fn adam_norms_chunk(p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], a: &AdamScalars, sq_norms: &mut [f32]) -> u32 => adam_norms_impl
}

/// Vertices per column tile of [`crate::nn::engine::update_components`]: the tile's gradient
/// (`K × 9·512` numbers) stays in L2 between its GEMM and its update.
pub const FUSED_TILE_VERTICES: usize = 512;
const _: () = assert!((9 * FUSED_TILE_VERTICES).is_multiple_of(GEMM_INNER_BLOCK), "tiles hold whole inner blocks");

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn sparse_adam_norms_impl<M: MulAdd>(
    p: &mut [f32],
    g: &mut [f32],
    m: &mut [f32],
    v: &mut [f32],
    a: &AdamScalars,
    sq_norms: &mut [f32],
    lambda: &[f32],
    eps2: f32,
    scale: f32,
) -> u32 {
    let w = 9 * FUSED_VERTICES;
    let mut exp = 0u32;
    for (((((p, g), m), v), sq), lam) in p
        .chunks_mut(w)
        .zip(g.chunks_mut(w))
        .zip(m.chunks_mut(w))
        .zip(v.chunks_mut(w))
        .zip(sq_norms.chunks_mut(FUSED_VERTICES))
        .zip(lambda.chunks(FUSED_VERTICES))
    {
        // The sparsity gradient from the norms of the C before the update (as group_sparsity):
        // the factors of a block first (a loop over vertices that vectorises), then the
        // multiply-adds of the vertices it applies to.
        let mut f = [0.0f32; FUSED_VERTICES];
        let mut on = [false; FUSED_VERTICES];
        for (((f, on), &s), &l) in f.iter_mut().zip(on.iter_mut()).zip(sq.iter()).zip(lam) {
            *f = scale * l / s.max(eps2).sqrt();
            *on = l != 0.0 && s > eps2;
        }
        for (((pv, gv), &f), &on) in p.chunks_exact(9).zip(g.chunks_exact_mut(9)).zip(&f).zip(&on) {
            if on {
                for (gq, &vq) in gv.iter_mut().zip(pv) {
                    *gq = M::mul_add(f, vq, *gq);
                }
            }
        }
        adam_block(p, g, m, v, a);
        vertex_sq_norms_impl::<M>(p, sq);
        exp = exp.max(max_exponent_impl::<M>(p));
    }
    exp
}

dispatch! {
    /// One row of a column tile of `C`: adds the sparsity gradient `scale·Λ_i·c_i/‖c_i‖` (from the
    /// squared norms `sq_norms` of the current `c`, as [`group_sparsity`]) to the dense gradient
    /// `g`, applies one Adam step ([`AdamScalars`]) to `p`, then overwrites `sq_norms` with the
    /// squared vertex norms of the new `p`. Returns the largest exponent field of the new `p`
    /// ([`NON_FINITE_EXPONENT`] iff an entry is not finite).
    #[allow(clippy::too_many_arguments)]
    pub fn sparse_adam_norms(p: &mut [f32], g: &mut [f32], m: &mut [f32], v: &mut [f32], a: &AdamScalars, sq_norms: &mut [f32], lambda: &[f32], eps2: f32, scale: f32) -> u32 => sparse_adam_norms_impl
}

/// Largest exponent field of the values, in place (`NON_FINITE_EXPONENT` iff some value is
/// infinite or NaN); parallel for long slices.
pub fn max_exponent_of(v: &[f32]) -> u32 {
    const CH: usize = 1 << 15;
    if v.len() <= CH {
        return max_exponent(v);
    }
    v.par_chunks(CH).map(max_exponent).max().unwrap_or(0)
}

/// One Adam step in place over `p` (see [`AdamScalars`]; `m`, `v` are the moments, same length
/// as `p`), fused with [`vertex_sq_norms`] of the updated `p` into `sq_norms` (`p.len() / 9`
/// values) and a finiteness scan of it. Returns whether every updated entry is finite.
/// Bit-identical to Burn's Adam followed by [`vertex_sq_norms`].
pub fn adam_step(
    p: &mut [f32],
    g: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    a: &AdamScalars,
    sq_norms: &mut [f32],
) -> bool {
    assert!(p.len().is_multiple_of(9) && g.len() == p.len() && m.len() == p.len() && v.len() == p.len());
    assert_eq!(sq_norms.len(), p.len() / 9);
    // Parallel chunks of whole vertices.
    const CH: usize = 9 * 4096;
    let exps: Vec<u32> = p
        .par_chunks_mut(CH)
        .zip(m.par_chunks_mut(CH))
        .zip(v.par_chunks_mut(CH))
        .zip(sq_norms.par_chunks_mut(CH / 9))
        .enumerate()
        .map(|(ci, (((p, m), v), sq))| {
            let s = ci * CH;
            adam_norms_chunk(p, &g[s..s + p.len()], m, v, a, sq)
        })
        .collect();
    exps.into_iter().max().unwrap_or(0) != NON_FINITE_EXPONENT
}

#[inline(always)]
#[allow(clippy::extra_unused_type_parameters)]
fn max_exponent_impl<M: MulAdd>(v: &[f32]) -> u32 {
    const EXP: u32 = 0x7f80_0000;
    let (blocks, rest) = v.as_chunks::<LANES>();
    let mut acc = [0u32; LANES];
    for b in blocks {
        for l in 0..LANES {
            acc[l] = acc[l].max(b[l].to_bits() & EXP);
        }
    }
    let mut m = acc.iter().copied().max().unwrap_or(0);
    for x in rest {
        m = m.max(x.to_bits() & EXP);
    }
    m
}

dispatch! {
    /// Largest exponent field (bits 23..31, in place) of the values: `0x7f80_0000` iff some
    /// value is infinite or NaN.
    fn max_exponent(v: &[f32]) -> u32 => max_exponent_impl
}

/// Returns the first non-finite value's index, if any (vectorised parallel scan; the exact
/// position is searched only when there is one).
pub fn first_non_finite(v: &[f32]) -> Option<usize> {
    const CH: usize = 1 << 15;
    let bad = v.par_chunks(CH).any(|c| max_exponent(c) == NON_FINITE_EXPONENT);
    if !bad {
        return None;
    }
    v.iter().position(|x| !x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::rng::Rng;

    fn rand_vec(rng: &mut Rng, n: usize) -> Vec<f32> {
        (0..n).map(|_| rng.uniform() as f32 * 2.0 - 1.0).collect()
    }

    fn rand_mat(rng: &mut Rng) -> Mat9 {
        let mut m = [[0.0; 9]; 9];
        for row in m.iter_mut() {
            for v in row.iter_mut() {
                *v = rng.uniform() as f32 - 0.5;
            }
        }
        m
    }

    fn ring_index(n: usize) -> NeighborIndex {
        // A ring with chords and one isolated vertex (n − 1) and one asymmetric list.
        let mut rings: Vec<Vec<usize>> = (0..n - 1).map(|i| vec![(i + 1) % (n - 1), (i + n - 2) % (n - 1)]).collect();
        rings[0].push(5);
        rings.push(vec![]);
        NeighborIndex::new(&rings).unwrap()
    }

    #[test]
    fn neighbour_mean_and_its_transpose_are_adjoint() {
        let n = 70; // more than two row chunks
        let bp = 16;
        let r = 9 * bp;
        let nb = ring_index(n);
        let mut rng = Rng::new(3);
        let x = rand_vec(&mut rng, n * r);
        let y = rand_vec(&mut rng, n * r);
        let mut mx = vec![0.0; n * r];
        mean_rows(&nb, &x, &mut mx, r);
        // Naive check of one entry per vertex.
        for i in 0..n {
            let deg = nb.neighbors(i).len();
            let want: f32 = if deg == 0 {
                0.0
            } else {
                nb.neighbors(i).iter().map(|&j| x[j as usize * r + 7]).sum::<f32>() / deg as f32
            };
            assert!((mx[i * r + 7] - want).abs() < 1e-6);
        }
        let mut mty = vec![0.0; n * r];
        mean_rows_transpose_add(&nb, &y, &mut mty, r);
        let a: f64 = mx.iter().zip(&y).map(|(p, q)| (*p as f64) * (*q as f64)).sum();
        let b: f64 = x.iter().zip(&mty).map(|(p, q)| (*p as f64) * (*q as f64)).sum();
        assert!((a - b).abs() < 1e-4 * a.abs().max(1.0), "<Mx, y> = {a}, <x, Mᵀy> = {b}");
    }

    #[test]
    fn conv_and_its_gradients_match_naive_loops() {
        let n = 40;
        let bp = 16;
        let r = 9 * bp;
        let mut rng = Rng::new(4);
        let (ws, wn) = (rand_mat(&mut rng), rand_mat(&mut rng));
        let bias: [f32; 9] = std::array::from_fn(|i| i as f32 * 0.1 - 0.4);
        let x = rand_vec(&mut rng, n * r);
        let m = rand_vec(&mut rng, n * r);
        let dy = rand_vec(&mut rng, n * r);
        let at = |v: &[f32], i: usize, c: usize, b: usize| v[(i * 9 + c) * bp + b];
        for tanh in [false, true] {
            let mut out = vec![0.0; n * r];
            conv_rows(&ws, &x, &wn, &m, &bias, &mut out, bp, tanh);
            for (i, c, b) in [(0, 0, 0), (17, 4, 9), (39, 8, 15)] {
                let mut h = bias[c];
                for a in 0..9 {
                    h += ws[c][a] * at(&x, i, a, b) + wn[c][a] * at(&m, i, a, b);
                }
                let want = if tanh { h.tanh() } else { h };
                assert!((at(&out, i, c, b) - want).abs() < 1e-5);
            }
        }
        let (mut dx, mut dm) = (vec![0.0; n * r], vec![0.0; n * r]);
        input_grad_rows(&transpose9(&ws), &transpose9(&wn), &dy, &mut dx, &mut dm, bp);
        let g = weight_grad_rows(&dy, &x, &m, bp);
        for (i, a, b) in [(3, 2, 5), (38, 7, 12)] {
            let want_x: f32 = (0..9).map(|o| ws[o][a] * at(&dy, i, o, b)).sum();
            let want_m: f32 = (0..9).map(|o| wn[o][a] * at(&dy, i, o, b)).sum();
            assert!((at(&dx, i, a, b) - want_x).abs() < 1e-5);
            assert!((at(&dm, i, a, b) - want_m).abs() < 1e-5);
        }
        for (o, a) in [(0, 0), (4, 7), (8, 8)] {
            let mut sx = 0.0f64;
            let mut sm = 0.0f64;
            let mut sb = 0.0f64;
            for i in 0..n {
                for b in 0..bp {
                    sx += (at(&dy, i, o, b) * at(&x, i, a, b)) as f64;
                    sm += (at(&dy, i, o, b) * at(&m, i, a, b)) as f64;
                    sb += at(&dy, i, o, b) as f64;
                }
            }
            assert!((g.ws[o][a] - sx).abs() < 1e-4, "{} vs {sx}", g.ws[o][a]);
            assert!((g.wn[o][a] - sm).abs() < 1e-4);
            assert!((g.bias[o] - sb).abs() < 1e-4);
        }
    }

    /// The multiply-add chain of [`ct_times`], one entry at a time.
    fn ct_reference(c: &[f32], k: usize, cols: usize, y: &[f32], bp: usize, b: usize) -> Vec<f32> {
        let mut out = vec![0.0f32; cols * bp];
        for j in 0..cols {
            for l in 0..b {
                let mut a = 0.0f32;
                for kk in 0..k {
                    a = c[kk * cols + j].mul_add(y[kk * bp + l], a);
                }
                out[j * bp + l] = a;
            }
        }
        out
    }

    #[test]
    fn ct_times_is_the_ordered_multiply_add_chain_and_equals_faer() {
        let mut rng = Rng::new(12);
        for (k, cols, bp, b) in [(3, 50, 8, 7), (50, 1203, 8, 7), (50, 1203, 8, 8), (17, 300, 16, 11), (64, 77, 40, 36)]
        {
            let mut c = rand_vec(&mut rng, k * cols);
            let mut y = rand_vec(&mut rng, k * bp);
            // Exact zeros (signs of zero must come out as faer's).
            for i in (0..c.len()).step_by(7) {
                c[i] = 0.0;
            }
            y[1] = -0.0;
            let mut got = vec![f32::NAN; cols * bp];
            ct_times(&c, k, cols, &y, bp, b, &mut got);
            let want = ct_reference(&c, k, cols, &y, bp, b);
            assert!(
                got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()),
                "k {k} bp {bp}: differs from the chain"
            );
            // faer's GEMM on the real lanes (the padding lanes stay as they were: zero).
            let mut faer = vec![0.0f32; cols * bp];
            faer::linalg::matmul::matmul(
                faer::MatMut::from_row_major_slice_mut(&mut faer, cols, bp).subcols_mut(0, b),
                faer::Accum::Replace,
                faer::MatRef::from_row_major_slice(&c, k, cols).transpose(),
                faer::MatRef::from_row_major_slice(&y, k, bp).subcols(0, b),
                1.0f32,
                faer::Par::Seq,
            );
            assert!(
                got.iter().zip(&faer).all(|(a, b)| a.to_bits() == b.to_bits()),
                "k {k} bp {bp}: differs from faer's GEMM (the engine's results would change)"
            );
        }
    }

    #[test]
    fn non_finite_values_are_located() {
        let mut v = vec![1.5f32; 100_003];
        assert_eq!(first_non_finite(&v), None);
        v[70_001] = f32::NAN;
        v[99_999] = f32::INFINITY;
        assert_eq!(first_non_finite(&v), Some(70_001));
        v[70_001] = f32::MAX;
        assert_eq!(first_non_finite(&v), Some(99_999));
        v[99_999] = 0.0;
        v[100_002] = f32::NEG_INFINITY; // in the unaligned tail
        assert_eq!(first_non_finite(&v), Some(100_002));
    }

    #[test]
    fn tanh_matches_std_to_f32_precision() {
        let mut worst = 0.0f64;
        let mut x = -12.0f32;
        while x < 12.0 {
            let a = tanh_f32(x) as f64;
            let b = (x as f64).tanh();
            let err = (a - b).abs() / b.abs().max(1e-30);
            worst = worst.max(err);
            x += 0.000_37;
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
        assert_eq!(tanh_f32(0.0), 0.0);
        assert!(tanh_f32(f32::NAN).is_nan());
        assert_eq!(tanh_f32(1e30), 1.0);
        assert_eq!(tanh_f32(-1e30), -1.0);
        let mut v: Vec<f32> = (0..37).map(|i| i as f32 * 0.1 - 1.8).collect();
        let w: Vec<f32> = v.iter().map(|&x| tanh_f32(x)).collect();
        tanh_slice(&mut v);
        assert_eq!(v, w);
    }
}
