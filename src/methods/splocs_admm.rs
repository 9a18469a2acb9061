//! Inner kernels of SPLOCS: the weight projections (Eqs. 3, 4), the block-coordinate weight
//! update in component space, and the fused group-ℓ1/ℓ2 proximal + dual update of one ADMM
//! iteration. Buffers are row-major K × (E·W) (components, dual, ...) or F × K (weights).

use super::WeightConstraint;

/// Projects one weight column onto the constraint set in place: `Nonnegative` →
/// max(0,w)/max(w) (all zero stays zero), `Signed` → w/max|w|.
pub(crate) fn project_weights(w: &mut [f64], constraint: WeightConstraint) {
    match constraint {
        WeightConstraint::Nonnegative => {
            let mut m = 0.0f64;
            for v in w.iter_mut() {
                *v = v.max(0.0);
                m = m.max(*v);
            }
            if m > 0.0 {
                for v in w.iter_mut() {
                    *v /= m;
                }
            }
        }
        WeightConstraint::Signed => {
            let m = w.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            if m > 0.0 {
                for v in w.iter_mut() {
                    *v /= m;
                }
            }
        }
        WeightConstraint::Unconstrained => {}
    }
}

/// Soft-thresholds one weight column relative to its peak (`weight_sparsity` of SPLOCS): every
/// weight moves `shrink` × the column's largest magnitude towards 0 (non-negative weights: the
/// largest positive one), stopping at 0; `shrink` = 0 changes nothing. Before the projection,
/// which scales the peak back to 1: a component is left active only in the frames where it
/// carries more than that share of its peak.
pub(crate) fn shrink_relative(w: &mut [f64], shrink: f64, constraint: WeightConstraint) {
    if shrink <= 0.0 {
        return;
    }
    let peak = match constraint {
        WeightConstraint::Nonnegative => w.iter().fold(0.0f64, |a, v| a.max(*v)),
        _ => w.iter().fold(0.0f64, |a, v| a.max(v.abs())),
    };
    let t = shrink * peak;
    for v in w.iter_mut() {
        *v = v.signum() * (v.abs() - t).max(0.0);
    }
}

/// One sweep of block-coordinate descent on the weights (F × K, row-major), each component in
/// turn, exactly the reference's sequential update but in K-space: with A = X·Cᵀ (F × K) and
/// G = C·Cᵀ (K × K), the residual product is R·C_k = A[:,k] − W·G[:,k], so
/// `opt = (A[:,k] − W·G[:,k]) / G_kk + W[:,k]`, then W[:,k] = P(opt). Components with
/// G_kk ≤ `zero_norm` get zero weights. `col` is an F-sized scratch buffer.
#[allow(clippy::too_many_arguments)]
pub(crate) fn update_weights(
    weights: &mut [f64],
    xct: &[f64],
    cct: &[f64],
    f: usize,
    k: usize,
    constraint: WeightConstraint,
    zero_norm: f64,
    col: &mut [f64],
    shrink: f64,
) {
    for c in 0..k {
        let g = cct[c * k + c];
        if g <= zero_norm {
            for r in 0..f {
                weights[r * k + c] = 0.0;
            }
            continue;
        }
        for r in 0..f {
            let wr = &weights[r * k..(r + 1) * k];
            let mut s = 0.0;
            for (j, wj) in wr.iter().enumerate() {
                s += wj * cct[j * k + c];
            }
            col[r] = (xct[r * k + c] - s) / g + wr[c];
        }
        shrink_relative(&mut col[..f], shrink, constraint);
        project_weights(&mut col[..f], constraint);
        for r in 0..f {
            weights[r * k + c] = col[r];
        }
    }
}

/// Column blocks of whole elements. SPLOCS's component update is independent across
/// columns (the C-step mixes components, not columns; the prox acts per element), so all ADMM
/// iterations of one block run while the block sits in cache, and blocks run in parallel.
/// Blocked storage of a K × D matrix: block b (columns `cols(b)`) occupies
/// `offset(b) .. offset(b) + K·ncols(b)` as a row-major K × ncols(b) matrix.
pub(crate) struct Blocks {
    starts: Vec<usize>,
    width: usize,
    k: usize,
}

impl Blocks {
    /// Blocks of about `target_cols` columns, a multiple of 16 elements each (so that, with
    /// W = 3 or 9, a block's column count is a multiple of the 48-row GEMM micro-kernel).
    pub(crate) fn new(n_elements: usize, width: usize, k: usize, target_cols: usize) -> Self {
        let per = ((target_cols as f64 / width as f64 / 16.0).round() as usize).max(1) * 16;
        let mut starts: Vec<usize> = (0..n_elements).step_by(per).collect();
        starts.push(n_elements);
        Blocks { starts, width, k }
    }
    pub(crate) fn len(&self) -> usize {
        self.starts.len() - 1
    }
    pub(crate) fn elems(&self, b: usize) -> std::ops::Range<usize> {
        self.starts[b]..self.starts[b + 1]
    }
    pub(crate) fn cols(&self, b: usize) -> std::ops::Range<usize> {
        self.starts[b] * self.width..self.starts[b + 1] * self.width
    }
    fn offset(&self, b: usize) -> usize {
        self.k * self.starts[b] * self.width
    }
    /// Row-major K × D → blocked.
    pub(crate) fn to_blocked(&self, row_major: &[f64], out: &mut [f64]) {
        let d = self.starts[self.len()] * self.width;
        for b in 0..self.len() {
            let cols = self.cols(b);
            let nc = cols.len();
            let o = self.offset(b);
            for k in 0..self.k {
                out[o + k * nc..o + (k + 1) * nc].copy_from_slice(&row_major[k * d + cols.start..k * d + cols.end]);
            }
        }
    }
    /// Blocked → row-major K × D.
    pub(crate) fn to_row_major(&self, blocked: &[f64], out: &mut [f64]) {
        let d = self.starts[self.len()] * self.width;
        for b in 0..self.len() {
            let cols = self.cols(b);
            let nc = cols.len();
            let o = self.offset(b);
            for k in 0..self.k {
                out[k * d + cols.start..k * d + cols.end].copy_from_slice(&blocked[o + k * nc..o + (k + 1) * nc]);
            }
        }
    }
    /// Disjoint mutable views of the blocks of a blocked K × D buffer.
    pub(crate) fn split_mut<'a>(&self, mut v: &'a mut [f64]) -> Vec<&'a mut [f64]> {
        let mut out = Vec::with_capacity(self.len());
        for b in 0..self.len() {
            let (head, tail) = v.split_at_mut(self.k * self.cols(b).len());
            out.push(head);
            v = tail;
        }
        out
    }
    /// For every component, the element with the largest group norm² and that norm² (first
    /// maximum on ties, like `numpy.argmax`).
    pub(crate) fn argmax_groups(&self, blocked: &[f64]) -> Vec<(usize, f64)> {
        let w = self.width;
        let mut best = vec![(0usize, f64::NEG_INFINITY); self.k];
        for b in 0..self.len() {
            let e0 = self.starts[b];
            let nc = self.cols(b).len();
            let o = self.offset(b);
            for (k, bk) in best.iter_mut().enumerate() {
                let row = &blocked[o + k * nc..o + (k + 1) * nc];
                for (j, g) in row.chunks_exact(w).enumerate() {
                    let n2: f64 = g.iter().map(|v| v * v).sum();
                    if n2 > bk.1 {
                        *bk = (e0 + j, n2);
                    }
                }
            }
        }
        best
    }
}

/// Read-only inputs of the blocked ADMM of one outer iteration.
pub(crate) struct AdmmShared<'a> {
    /// F × D data (unscaled) and its scale 1/s.
    pub x: super::DataRef<'a>,
    pub inv_scale: f64,
    /// F × K weights.
    pub weights: &'a [f64],
    /// (WᵀW + ρI)⁻¹, K × K.
    pub minv: faer::MatRef<'a, f64>,
    /// K × E regularisation weights Λ.
    pub lambda: &'a [f64],
    pub rho: f64,
    pub iterations: usize,
    pub f: usize,
    pub d: usize,
    pub e: usize,
    pub k: usize,
    pub width: usize,
}

/// Per-thread accumulators (X·Cᵀ/s, C·Cᵀ, Ω) and scratch of the blocked ADMM.
pub(crate) struct AdmmAcc {
    pub xct: Vec<f64>,
    pub cct: Vec<f64>,
    pub sparsity: f64,
    wx: Vec<f64>,
    t: Vec<f64>,
    nrm: Vec<f64>,
    xc: Vec<f64>,
    g: Vec<f64>,
    rows: Vec<usize>,
    /// F × (block columns) of the data in `f64`, when it is held in `f32`.
    xcols: Vec<f64>,
}

impl AdmmAcc {
    /// `compact`: the data is in `f32` (each block's columns are converted into a buffer).
    pub(crate) fn new(f: usize, k: usize, max_cols: usize, compact: bool) -> Self {
        AdmmAcc {
            xct: vec![0.0; f * k],
            cct: vec![0.0; k * k],
            sparsity: 0.0,
            wx: vec![0.0; k * max_cols],
            t: vec![0.0; k * max_cols],
            nrm: vec![0.0; max_cols],
            xc: vec![0.0; f * k],
            g: vec![0.0; k * k],
            rows: Vec::with_capacity(k),
            xcols: if compact { vec![0.0; f * max_cols] } else { Vec::new() },
        }
    }
    pub(crate) fn merge(mut self, o: AdmmAcc) -> AdmmAcc {
        self.xct.iter_mut().zip(&o.xct).for_each(|(a, b)| *a += b);
        self.cct.iter_mut().zip(&o.cct).for_each(|(a, b)| *a += b);
        self.sparsity += o.sparsity;
        self
    }
}

/// All ADMM iterations on block `b` (its components `c` and scaled dual `u`, blocked
/// layout): C ← (WᵀW+ρI)⁻¹(WᵀX + ρ(Z − U)); Z ← prox(C + U); U ← U + C − Z; with Z
/// initialised to the incoming C, and finally C ← Z. The right-hand side S = WᵀX + ρ(Z − U)
/// is assembled by the prox step itself, so each ADMM iteration is one K × K product. Adds the
/// block's X·Cᵀ/s, C·Cᵀ and Ω(C) to `acc`.
pub(crate) fn admm_block(
    sh: &AdmmShared<'_>,
    blocks: &Blocks,
    b: usize,
    c: &mut [f64],
    u: &mut [f64],
    acc: &mut AdmmAcc,
) {
    use faer::linalg::matmul::matmul;
    use faer::{Accum, MatMut, MatRef, Par};
    let (f, k, w) = (sh.f, sh.k, sh.width);
    let cols = blocks.cols(b);
    let elems = blocks.elems(b);
    let nc = cols.len();
    let ne = elems.len();
    let xb = match sh.x {
        super::DataRef::F64(x) => MatRef::from_row_major_slice(x.data(), f, sh.d).subcols(cols.start, nc),
        super::DataRef::F32(_) => {
            sh.x.read_cols(cols.clone(), &mut acc.xcols[..f * nc]);
            MatRef::from_row_major_slice(&acc.xcols[..f * nc], f, nc)
        }
    };
    let wm = MatRef::from_row_major_slice(sh.weights, f, k);
    let wx = &mut acc.wx[..k * nc];
    let s = &mut acc.t[..k * nc];
    matmul(MatMut::from_row_major_slice_mut(wx, k, nc), Accum::Replace, wm.transpose(), xb, sh.inv_scale, Par::Seq);
    // Z = C: S = WᵀX + ρ(C − U)
    for (((sv, cv), uv), xv) in s.iter_mut().zip(c.iter()).zip(u.iter()).zip(wx.iter()) {
        *sv = xv + sh.rho * (cv - uv);
    }
    let inv_rho = 1.0 / sh.rho;
    let mut sparsity = 0.0;
    for it in 0..sh.iterations {
        let last = it + 1 == sh.iterations;
        matmul(
            MatMut::from_row_major_slice_mut(c, k, nc),
            Accum::Replace,
            sh.minv,
            MatRef::from_row_major_slice(s, k, nc),
            1.0,
            Par::Seq,
        );
        for kk in 0..k {
            let r = kk * nc..(kk + 1) * nc;
            let lam = &sh.lambda[kk * sh.e + elems.start..kk * sh.e + elems.end];
            sparsity += prox_segment(
                &mut c[r.clone()],
                &mut u[r.clone()],
                &mut s[r.clone()],
                &wx[r],
                lam,
                sh.rho,
                inv_rho,
                w,
                &mut acc.nrm[..ne],
                last,
            );
        }
    }
    acc.sparsity += sparsity;
    // X·Cᵀ/s and C·Cᵀ of the block, over the components that are non-zero in it (Z is sparse)
    acc.rows.clear();
    acc.rows.extend((0..k).filter(|&kk| c[kk * nc..(kk + 1) * nc].iter().any(|&v| v != 0.0)));
    let r = acc.rows.len();
    if r == k {
        let cb = MatRef::from_row_major_slice(c, k, nc);
        matmul(
            MatMut::from_row_major_slice_mut(&mut acc.xct, f, k),
            Accum::Add,
            xb,
            cb.transpose(),
            sh.inv_scale,
            Par::Seq,
        );
        matmul(MatMut::from_row_major_slice_mut(&mut acc.cct, k, k), Accum::Add, cb, cb.transpose(), 1.0, Par::Seq);
    } else if r > 0 {
        let compact = &mut acc.wx[..r * nc];
        for (j, &kk) in acc.rows.iter().enumerate() {
            compact[j * nc..(j + 1) * nc].copy_from_slice(&c[kk * nc..(kk + 1) * nc]);
        }
        let cb = MatRef::from_row_major_slice(compact, r, nc);
        let xc = &mut acc.xc[..f * r];
        let g = &mut acc.g[..r * r];
        matmul(MatMut::from_row_major_slice_mut(xc, f, r), Accum::Replace, xb, cb.transpose(), sh.inv_scale, Par::Seq);
        matmul(MatMut::from_row_major_slice_mut(g, r, r), Accum::Replace, cb, cb.transpose(), 1.0, Par::Seq);
        for row in 0..f {
            for (j, &kk) in acc.rows.iter().enumerate() {
                acc.xct[row * k + kk] += xc[row * r + j];
            }
        }
        for (a, &ka) in acc.rows.iter().enumerate() {
            for (b, &kb) in acc.rows.iter().enumerate() {
                acc.cct[ka * k + kb] += g[a * r + b];
            }
        }
    }
}

/// Fused step after the C-update of one ADMM iteration on one row segment (one component,
/// consecutive elements), per group g: p = C + U; z = prox(p) = max(0, 1 − thr/‖p‖)·p with
/// thr = Λ_g/ρ; U ← p − z; S ← WX + ρ(z − U) (the right-hand side WᵀX + ρ(Z − U) of the next
/// C-update, `wx` holding WᵀX); C ← z. `nrm` is scratch (one value per group). Returns
/// Σ_g Λ_g‖z_g‖ (the sparsity term) when `want_sparsity`, else 0.
///
/// On x86-64 with AVX2 + FMA (checked at run time) the same code is compiled for those
/// features, so the square roots and divisions of the shrink factors run 4 lanes wide.
#[allow(clippy::too_many_arguments)]
pub(crate) fn prox_segment(
    c: &mut [f64],
    u: &mut [f64],
    s: &mut [f64],
    wx: &[f64],
    lambda: &[f64],
    rho: f64,
    inv_rho: f64,
    width: usize,
    nrm: &mut [f64],
    want_sparsity: bool,
) -> f64 {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the target features the function is compiled for.
            return unsafe { prox_segment_avx2(c, u, s, wx, lambda, rho, inv_rho, width, nrm, want_sparsity) };
        }
    }
    prox_segment_impl(c, u, s, wx, lambda, rho, inv_rho, width, nrm, want_sparsity)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
fn prox_segment_avx2(
    c: &mut [f64],
    u: &mut [f64],
    s: &mut [f64],
    wx: &[f64],
    lambda: &[f64],
    rho: f64,
    inv_rho: f64,
    width: usize,
    nrm: &mut [f64],
    want_sparsity: bool,
) -> f64 {
    prox_segment_impl(c, u, s, wx, lambda, rho, inv_rho, width, nrm, want_sparsity)
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn prox_segment_impl(
    c: &mut [f64],
    u: &mut [f64],
    s: &mut [f64],
    wx: &[f64],
    lambda: &[f64],
    rho: f64,
    inv_rho: f64,
    width: usize,
    nrm: &mut [f64],
    want_sparsity: bool,
) -> f64 {
    match width {
        3 => group_norms_fixed::<3>(c, u, nrm),
        9 => group_norms_fixed::<9>(c, u, nrm),
        _ => group_norms_dyn(c, u, nrm, width),
    }
    let mut sparsity = 0.0;
    if want_sparsity {
        // Ω(z) = Σ Λ·max(‖p‖ − thr, 0), four partial sums so the loop vectorises
        let mut acc = [0.0f64; 4];
        let mut chunks = nrm.chunks_exact(4).zip(lambda.chunks_exact(4));
        for (n4, l4) in &mut chunks {
            for q in 0..4 {
                acc[q] += l4[q] * (n4[q].sqrt() - l4[q] * inv_rho).max(0.0);
            }
        }
        let done = nrm.len() / 4 * 4;
        for (n, l) in nrm[done..].iter().zip(&lambda[done..]) {
            acc[0] += l * (n.sqrt() - l * inv_rho).max(0.0);
        }
        sparsity = acc[0] + acc[1] + acc[2] + acc[3];
    }
    // shrink factors, branch-free: s = 1 − thr/‖p‖ if ‖p‖ > thr else 0
    for (s, &lam) in nrm.iter_mut().zip(lambda) {
        let n = s.sqrt();
        let thr = lam * inv_rho;
        let v = 1.0 - thr / n;
        *s = if n > thr { v } else { 0.0 };
    }
    match width {
        3 => apply_fixed::<3>(c, u, s, wx, nrm, rho),
        9 => apply_fixed::<9>(c, u, s, wx, nrm, rho),
        _ => apply_dyn(c, u, s, wx, nrm, rho, width),
    }
    sparsity
}

/// p = c + u stored in c; nrm[g] = ‖p_g‖².
#[inline(always)]
fn group_norms_fixed<const W: usize>(c: &mut [f64], u: &[f64], nrm: &mut [f64]) {
    for ((cg, ug), n) in c.chunks_exact_mut(W).zip(u.chunks_exact(W)).zip(nrm.iter_mut()) {
        let mut n2 = 0.0;
        for q in 0..W {
            let p = cg[q] + ug[q];
            cg[q] = p;
            n2 += p * p;
        }
        *n = n2;
    }
}

#[inline(always)]
fn group_norms_dyn(c: &mut [f64], u: &[f64], nrm: &mut [f64], w: usize) {
    for ((cg, ug), n) in c.chunks_exact_mut(w).zip(u.chunks_exact(w)).zip(nrm.iter_mut()) {
        let mut n2 = 0.0;
        for (cv, uv) in cg.iter_mut().zip(ug) {
            let p = *cv + uv;
            *cv = p;
            n2 += p * p;
        }
        *n = n2;
    }
}

#[inline(always)]
fn apply_fixed<const W: usize>(c: &mut [f64], u: &mut [f64], s: &mut [f64], wx: &[f64], shrink: &[f64], rho: f64) {
    for ((((cg, ug), sg), xg), &f) in
        c.chunks_exact_mut(W).zip(u.chunks_exact_mut(W)).zip(s.chunks_exact_mut(W)).zip(wx.chunks_exact(W)).zip(shrink)
    {
        for q in 0..W {
            let p = cg[q];
            let z = f * p;
            let du = p - z;
            ug[q] = du;
            sg[q] = xg[q] + rho * (z - du);
            cg[q] = z;
        }
    }
}

#[inline(always)]
fn apply_dyn(c: &mut [f64], u: &mut [f64], s: &mut [f64], wx: &[f64], shrink: &[f64], rho: f64, w: usize) {
    for ((((cg, ug), sg), xg), &f) in
        c.chunks_exact_mut(w).zip(u.chunks_exact_mut(w)).zip(s.chunks_exact_mut(w)).zip(wx.chunks_exact(w)).zip(shrink)
    {
        for q in 0..w {
            let p = cg[q];
            let z = f * p;
            let du = p - z;
            ug[q] = du;
            sg[q] = xg[q] + rho * (z - du);
            cg[q] = z;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_shrinkage_zeroes_the_small_weights_of_a_component() {
        let close = |a: &[f64], b: &[f64]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
        // Non-negative: the peak is the largest positive weight; 10 % of it moves every weight.
        let mut w = vec![-1.0, 2.0, 0.5, 0.1, 1.0];
        shrink_relative(&mut w, 0.1, WeightConstraint::Nonnegative);
        assert!(close(&w, &[-0.8, 1.8, 0.3, 0.0, 0.8]), "{w:?}");
        project_weights(&mut w, WeightConstraint::Nonnegative);
        assert!(close(&w, &[0.0, 1.0, 0.3 / 1.8, 0.0, 0.8 / 1.8]), "{w:?}");
        // Signed: the peak is the largest magnitude, both signs shrink towards 0.
        let mut w = vec![-4.0, 2.0, -0.3, 0.3];
        shrink_relative(&mut w, 0.1, WeightConstraint::Signed);
        assert!(close(&w, &[-3.6, 1.6, 0.0, 0.0]), "{w:?}");
        // 0 changes nothing.
        let mut w = vec![-4.0, 2.0, 0.01];
        shrink_relative(&mut w, 0.0, WeightConstraint::Signed);
        assert_eq!(w, vec![-4.0, 2.0, 0.01]);
    }

    #[test]
    fn projections() {
        let mut w = vec![-1.0, 2.0, 0.5];
        project_weights(&mut w, WeightConstraint::Nonnegative);
        assert_eq!(w, vec![0.0, 1.0, 0.25]);
        let mut w = vec![-4.0, 2.0, 0.5];
        project_weights(&mut w, WeightConstraint::Signed);
        assert_eq!(w, vec![-1.0, 0.5, 0.125]);
        let mut w = vec![-4.0, -2.0];
        project_weights(&mut w, WeightConstraint::Nonnegative);
        assert_eq!(w, vec![0.0, 0.0]);
    }

    #[test]
    fn prox_matches_closed_form() {
        // groups of width 3: one inside (Λ=0), one shrunk, one killed
        let mut c = vec![1.0, 0.0, 0.0, 3.0, 4.0, 0.0, 0.1, 0.0, 0.0];
        let mut u = vec![0.0; 9];
        let mut t = vec![0.0; 9];
        let lambda = [0.0, 10.0, 10.0];
        let mut nrm = vec![0.0; 3];
        let wx = vec![0.5; 9];
        let s = prox_segment(&mut c, &mut u, &mut t, &wx, &lambda, 10.0, 0.1, 3, &mut nrm, true);
        // group 2: ‖p‖ = 5, thr = 1 → z = 0.8 p
        assert_eq!(&c[0..3], &[1.0, 0.0, 0.0]);
        assert!((c[3] - 2.4).abs() < 1e-15 && (c[4] - 3.2).abs() < 1e-15);
        assert_eq!(&c[6..9], &[0.0, 0.0, 0.0]);
        assert!((u[3] - 0.6).abs() < 1e-15 && (u[6] - 0.1).abs() < 1e-15);
        assert!((t[3] - (0.5 + 10.0 * (2.4 - 0.6))).abs() < 1e-12);
        assert!((s - 10.0 * 4.0).abs() < 1e-12);
        // dynamic width (as width 3 through the generic path) agrees
        let mut c2 = vec![1.0, 0.0, 0.0, 3.0, 4.0, 0.0, 0.1, 0.0, 0.0];
        let (mut u2, mut t2) = (vec![0.0; 9], vec![0.0; 9]);
        group_norms_dyn(&mut c2, &u2.clone(), &mut nrm, 3);
        let mut c3 = vec![1.0, 0.0, 0.0, 3.0, 4.0, 0.0, 0.1, 0.0, 0.0];
        let mut nrm3 = vec![0.0; 3];
        group_norms_fixed::<3>(&mut c3, &[0.0; 9], &mut nrm3);
        assert_eq!((&c2, &nrm), (&c3, &nrm3));
        apply_dyn(&mut c2, &mut u2, &mut t2, &wx, &[1.0, 0.8, 0.0], 10.0, 3);
        assert_eq!((c2, u2, t2), (c, u, t));
    }

    #[test]
    fn blocked_layout_round_trip() {
        let (e, w, k) = (7, 3, 2);
        let b = Blocks::new(e, w, k, 6);
        assert_eq!(b.len(), 1);
        let b = Blocks::new(40, w, k, 48);
        assert_eq!((b.len(), b.cols(1), b.elems(2)), (3, 48..96, 32..40));
        let b = Blocks { starts: vec![0, 2, 4, 6, 7], width: w, k };
        let rm: Vec<f64> = (0..k * e * w).map(|i| i as f64).collect();
        let mut bl = vec![0.0; rm.len()];
        b.to_blocked(&rm, &mut bl);
        assert_eq!(&bl[..4], &[0.0, 1.0, 2.0, 3.0]);
        let mut back = vec![0.0; rm.len()];
        b.to_row_major(&bl, &mut back);
        assert_eq!(back, rm);
        let am = b.argmax_groups(&bl);
        assert_eq!(am[0].0, 6);
        assert_eq!(am[1].0, 6);
    }

    #[test]
    fn weight_sweep_matches_residual_form() {
        // F=3, K=2, D=4
        let x = [1.0, 2.0, 0.0, -1.0, 0.5, 0.0, 1.0, 1.0, -2.0, 1.0, 0.0, 0.0];
        let c = [1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, -1.0];
        let (f, k, d) = (3, 2, 4);
        let mut w_res = vec![0.3, 0.2, 0.1, 0.9, 0.5, 0.5];
        let mut w_gram = w_res.clone();
        // residual form, as in the reference
        for kk in 0..k {
            let ck = &c[kk * d..(kk + 1) * d];
            let n: f64 = ck.iter().map(|v| v * v).sum();
            let mut col = vec![0.0; f];
            for r in 0..f {
                let mut rc = 0.0;
                for j in 0..d {
                    let mut res = x[r * d + j];
                    for q in 0..k {
                        if q != kk {
                            res -= w_res[r * k + q] * c[q * d + j];
                        }
                    }
                    rc += res * ck[j];
                }
                col[r] = rc / n;
            }
            project_weights(&mut col, WeightConstraint::Signed);
            for r in 0..f {
                w_res[r * k + kk] = col[r];
            }
        }
        let mut xct = vec![0.0; f * k];
        let mut cct = vec![0.0; k * k];
        for r in 0..f {
            for q in 0..k {
                xct[r * k + q] = (0..d).map(|j| x[r * d + j] * c[q * d + j]).sum();
            }
        }
        for a in 0..k {
            for b in 0..k {
                cct[a * k + b] = (0..d).map(|j| c[a * d + j] * c[b * d + j]).sum();
            }
        }
        let mut col = vec![0.0; f];
        update_weights(&mut w_gram, &xct, &cct, f, k, WeightConstraint::Signed, 1e-8, &mut col, 0.0);
        for (a, b) in w_res.iter().zip(&w_gram) {
            assert!((a - b).abs() < 1e-12, "{w_res:?} vs {w_gram:?}");
        }
    }
}
