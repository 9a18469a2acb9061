//! Holistic PCA of a data matrix X (F × E·W): the baseline every comparison table needs.
//!
//! With [`PcaCentering::Mean`] (default) the model is `x ≈ mean + Σ_k w_k C_k` with C the K
//! leading right singular vectors of X − 1·meanᵀ (orthonormal rows) and W = (X − mean)·Cᵀ; this
//! is the best rank-K affine approximation of the training data. With [`PcaCentering::None`]
//! the SVD is of X itself (offset 0): for displacement features, PCA "about the rest shape",
//! the setting SPLOCS's own data term uses. Sign convention: each component is flipped so that
//! its entry of largest magnitude is positive (deterministic output).
//!
//! Two solvers: [`Pca::fit`] (exact: thin SVD of the whole centred matrix, which it copies) and
//! [`Pca::fit_randomized`] (randomized range finder with power iterations, Halko, Martinsson &
//! Tropp 2011, Alg. 4.4 + 5.1), which streams the data in row blocks and never holds an F × D
//! matrix: for data sets too large for the exact SVD, or held in `f32` ([`DataRef::F32`]).

use faer::linalg::matmul::matmul;
use faer::reborrow::ReborrowMut;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use serde::{Deserialize, Serialize};

use super::{DataMatrix, DataRef, LinearModel, WeightConstraint};
use crate::rng::Rng;
use crate::{Error, Result};

/// What PCA subtracts before the SVD.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum PcaCentering {
    /// Subtract the mean row (classical PCA; the model's offset is the mean).
    #[default]
    Mean,
    /// Decompose X as given (offset 0).
    None,
}

/// PCA hyperparameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PcaConfig {
    /// Number of components K (≥ 1, ≤ min(F, E·W)). Default 50.
    pub components: usize,
    /// Centring (default: mean).
    pub centering: PcaCentering,
}

impl Default for PcaConfig {
    fn default() -> Self {
        PcaConfig { components: 50, centering: PcaCentering::Mean }
    }
}

impl PcaConfig {
    /// Checks K ≥ 1 (independent of data).
    pub fn validate(&self) -> Result<()> {
        if self.components == 0 {
            return Err(Error::config("components", "components (0) must be at least 1"));
        }
        Ok(())
    }
}

/// Options of the randomized, streamed PCA solver ([`Pca::fit_randomized`]).
///
/// Cost: `2·power_iterations + 4` passes over the data (mean, sketch, two per power iteration,
/// projection, weights), each a product of the F × D data with a D × l or F × l matrix
/// (l = K + `oversample`), so about `2·F·D·l·(2q + 3)` flops. Memory: O((F + D)·l +
/// `block_rows`·D) numbers besides the data; never F × D.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RandomizedSvd {
    /// Extra sketch columns p beyond the K components (count): the range finder works with
    /// l = K + p random directions, capped at min(F, D) (where it becomes exact). Default 50
    /// (l = 100 at the default K = 50). Halko et al.'s p = 10 suffices for fast-decaying
    /// spectra, but mesh data decays slowly: on 2000 × 15 783 low-rank-plus-noise data with
    /// σ_j ∝ 0.97^j and K = 50, p = 10 / 20 / 50 left the reconstruction error 4e-5 / 2e-7 /
    /// < 1e-14 relative above the exact PCA's, for 1.9 / 2.0 / 2.7 s (exact: 14 s). The cost
    /// grows linearly in l.
    pub oversample: usize,
    /// Power (subspace) iterations q (count), each one pass with Xcᵀ and one with Xc, with
    /// re-orthonormalisation in between (so no loss of accuracy to round-off). The error in the
    /// captured subspace shrinks like (σ_{l+1}/σ_K)^(2q+1); default 4 (the measurements above
    /// use it), each further iteration costs two more passes over the data.
    pub power_iterations: usize,
    /// Seed of the Gaussian test matrix Ω (drawn with [`crate::rng::Rng`], column by column,
    /// so that a larger `oversample` extends the same sketch). Same seed ⇒ same model.
    pub seed: u64,
    /// Rows read, converted to `f64` and centred at a time (count, ≥ 1): the streaming buffer
    /// is `block_rows` × D numbers. Default 256: 256 × 15 783 × 8 B ≈ 32 MB, large enough for
    /// the matrix products to run at full speed, small beside the data. The result depends on
    /// it only through round-off.
    pub block_rows: usize,
}

impl Default for RandomizedSvd {
    fn default() -> Self {
        RandomizedSvd { oversample: 50, power_iterations: 4, seed: 0, block_rows: 256 }
    }
}

impl RandomizedSvd {
    /// Checks `block_rows` ≥ 1.
    pub fn validate(&self) -> Result<()> {
        if self.block_rows == 0 {
            return Err(Error::config("block_rows", "block_rows (0) must be at least 1"));
        }
        Ok(())
    }
}

/// Errors when K exceeds min(F, D) (the message names all three).
fn check_rank(k: usize, f: usize, d: usize) -> Result<()> {
    if k > f.min(d) {
        return Err(Error::config(
            "components",
            format!("components ({k}) must not exceed min(frames {f}, columns {d}) for PCA"),
        ));
    }
    Ok(())
}

/// Parallelism of the block products: faer's rayon split over the global pool. Measured on 2
/// cores, 256 × 15 783 block times 15 783 × 100: 14 ms (rayon) vs 26 ms (sequential); block
/// transpose times 256 × 100: 16 ms vs 24 ms.
fn block_par() -> Par {
    Par::rayon(0)
}

/// The centred data Xc = X − 1·offsetᵀ, read in row blocks: products with Xc and Xcᵀ without
/// ever holding it.
struct Streamed<'a> {
    x: DataRef<'a>,
    /// Subtracted from every row; `None` when it is zero.
    offset: Option<&'a [f64]>,
    block_rows: usize,
    buf: Vec<f64>,
}

impl Streamed<'_> {
    /// Calls `body(start, block)` for each row block of Xc (block: rows × D, row-major).
    fn for_each_block(&mut self, mut body: impl FnMut(usize, MatRef<'_, f64>, &[f64])) {
        let (f, d) = (self.x.n_rows(), self.x.n_cols());
        let mut start = 0;
        while start < f {
            let b = self.block_rows.min(f - start);
            let blk = &mut self.buf[..b * d];
            self.x.read_rows(start, b, blk);
            if let Some(offset) = self.offset {
                for row in blk.chunks_exact_mut(d) {
                    for (v, o) in row.iter_mut().zip(offset) {
                        *v -= o;
                    }
                }
            }
            body(start, MatRef::from_row_major_slice(blk, b, d), blk);
            start += b;
        }
    }

    /// `out` (F × m) = Xc · `rhs` (D × m).
    fn times(&mut self, rhs: MatRef<'_, f64>, mut out: MatMut<'_, f64>) {
        let par = block_par();
        self.for_each_block(|start, blk, _| {
            let rows = blk.nrows();
            matmul(out.rb_mut().subrows_mut(start, rows), Accum::Replace, blk, rhs, 1.0, par);
        });
    }

    /// Xcᵀ · `lhs` (F × m), a D × m matrix accumulated over the row blocks.
    fn transpose_times(&mut self, lhs: MatRef<'_, f64>) -> Mat<f64> {
        let par = block_par();
        let mut out = Mat::<f64>::zeros(self.x.n_cols(), lhs.ncols());
        self.for_each_block(|start, blk, _| {
            let rows = blk.nrows();
            matmul(out.as_mut(), Accum::Add, blk.transpose(), lhs.subrows(start, rows), 1.0, par);
        });
        out
    }
}

/// Orthonormal basis of the columns of `m` (rows ≥ columns): the thin Q of its Householder QR
/// (orthonormal even when `m` is rank-deficient).
fn orthonormalise(m: MatRef<'_, f64>) -> Result<Mat<f64>> {
    let q = m.qr().compute_thin_Q();
    if !q.is_all_finite() {
        return Err(Error::Numerical("PCA (randomized): QR produced non-finite values".into()));
    }
    Ok(q)
}

/// The first `k` columns of `u` (D × ≥k) as K × D row-major components, each flipped so that
/// its entry of largest magnitude (the first such) is positive.
fn signed_components(u: MatRef<'_, f64>, k: usize) -> Vec<f64> {
    let d = u.nrows();
    let mut components = vec![0.0; k * d];
    for c in 0..k {
        let col = u.col(c);
        let mut imax = 0;
        for i in 0..d {
            if col[i].abs() > col[imax].abs() {
                imax = i;
            }
        }
        let sign = if col[imax] < 0.0 { -1.0 } else { 1.0 };
        for i in 0..d {
            components[c * d + i] = sign * col[i];
        }
    }
    components
}

/// Holistic PCA (see the module docs).
pub struct Pca;

impl Pca {
    /// Fits K principal components. Errors when K exceeds min(F, E·W) (naming both), or when
    /// the SVD fails.
    pub fn fit(x: DataMatrix<'_>, config: &PcaConfig) -> Result<LinearModel> {
        config.validate()?;
        let f = x.n_rows();
        let d = x.n_cols();
        let k = config.components;
        check_rank(k, f, d)?;
        let mut offset = vec![0.0; d];
        if config.centering == PcaCentering::Mean {
            for r in 0..f {
                for (o, v) in offset.iter_mut().zip(x.row(r)) {
                    *o += v;
                }
            }
            for o in &mut offset {
                *o /= f as f64;
            }
        }
        let mut centred = x.data().to_vec();
        for row in centred.chunks_exact_mut(d) {
            for (v, o) in row.iter_mut().zip(&offset) {
                *v -= o;
            }
        }
        // SVD of the (d × f) transpose view, which is column-major in memory: Xcᵀ = U S Vᵀ,
        // so the components (right singular vectors of Xc) are the columns of U.
        let xt = MatRef::from_column_major_slice(&centred, d, f);
        let svd = xt.thin_svd().map_err(|e| Error::Numerical(format!("PCA: SVD failed: {e:?}")))?;
        let u = svd.U();
        let components = signed_components(u, k);
        let mut weights = vec![0.0; f * k];
        for r in 0..f {
            let row = &centred[r * d..(r + 1) * d];
            for c in 0..k {
                weights[r * k + c] = row.iter().zip(&components[c * d..(c + 1) * d]).map(|(a, b)| a * b).sum();
            }
        }
        Ok(LinearModel {
            n_elements: x.n_elements(),
            width: x.width(),
            n_components: k,
            n_frames: f,
            components,
            weights,
            offset,
            constraint: WeightConstraint::Unconstrained,
        })
    }

    /// Fits K principal components with a randomized, streamed SVD (Halko–Martinsson–Tropp
    /// range finder with `options.power_iterations` re-orthonormalised power iterations), for
    /// data too large for [`Pca::fit`]: the data (`f64` or `f32`) is read in blocks of
    /// `options.block_rows` rows and the centred matrix is never formed; memory is
    /// O((F + D)·l + block_rows·D) with l = K + oversample.
    ///
    /// Steps: mean row (one pass; summed in row order, so for [`DataRef::F64`] it equals
    /// [`Pca::fit`]'s offset bit for bit); Y = Xc·Ω with Ω a seeded D × l Gaussian; Q = qr(Y);
    /// q times { Z = qr(Xcᵀ·Q); Q = qr(Xc·Z) }; Bᵀ = Xcᵀ·Q (D × l); thin SVD Bᵀ = U S Vᵀ; the
    /// components are the first K columns of U (sign convention of [`Pca::fit`]) and the
    /// weights W = Xc·Cᵀ (a last pass), exactly the projections `fit` would give for the same
    /// components. The block products use faer's rayon parallelism (the global rayon pool).
    ///
    /// Errors as [`Pca::fit`] (K = 0, K > min(F, D)), on `block_rows` = 0, and with
    /// [`Error::Numerical`] when the QR or the SVD fails.
    pub fn fit_randomized(x: DataRef<'_>, config: &PcaConfig, options: &RandomizedSvd) -> Result<LinearModel> {
        config.validate()?;
        options.validate()?;
        let f = x.n_rows();
        let d = x.n_cols();
        let k = config.components;
        check_rank(k, f, d)?;
        let l = (k + options.oversample).min(f.min(d));
        let block_rows = options.block_rows.min(f);
        let mut stream = Streamed { x, offset: None, block_rows, buf: vec![0.0; block_rows * d] };

        let mut offset = vec![0.0; d];
        if config.centering == PcaCentering::Mean {
            stream.for_each_block(|_, _, rows| {
                for row in rows.chunks_exact(d) {
                    for (o, v) in offset.iter_mut().zip(row) {
                        *o += v;
                    }
                }
            });
            for o in &mut offset {
                *o /= f as f64;
            }
        }
        let mut stream = Streamed { offset: (config.centering == PcaCentering::Mean).then_some(&offset[..]), ..stream };

        // Gaussian test matrix, column by column.
        let mut rng = Rng::new(options.seed);
        let mut omega = Mat::<f64>::zeros(d, l);
        for j in 0..l {
            for i in 0..d {
                omega[(i, j)] = rng.normal();
            }
        }
        let mut y = Mat::<f64>::zeros(f, l);
        stream.times(omega.as_ref(), y.as_mut());
        drop(omega);
        let mut q = orthonormalise(y.as_ref())?;
        for _ in 0..options.power_iterations {
            let z = orthonormalise(stream.transpose_times(q.as_ref()).as_ref())?;
            stream.times(z.as_ref(), y.as_mut());
            q = orthonormalise(y.as_ref())?;
        }
        drop(y);
        let bt = stream.transpose_times(q.as_ref());
        drop(q);
        let svd = bt.thin_svd().map_err(|e| Error::Numerical(format!("PCA (randomized): SVD failed: {e:?}")))?;
        let u = svd.U();
        let components = signed_components(u, k);
        drop(svd);
        drop(bt);
        let mut weights = vec![0.0; f * k];
        {
            let ct = MatRef::from_column_major_slice(&components, d, k);
            stream.times(ct, MatMut::from_row_major_slice_mut(&mut weights, f, k));
        }
        drop(stream);
        Ok(LinearModel {
            n_elements: x.n_elements(),
            width: x.width(),
            n_components: k,
            n_frames: f,
            components,
            weights,
            offset,
            constraint: WeightConstraint::Unconstrained,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::methods::CompactMatrix;

    /// F rows of rank ≤ r (plus a mean), deterministic pseudo-random.
    fn low_rank(f: usize, e: usize, w: usize, r: usize) -> Vec<f64> {
        let d = e * w;
        let mut s = 12345u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let basis: Vec<f64> = (0..r * d).map(|_| rnd()).collect();
        let mean: Vec<f64> = (0..d).map(|_| rnd()).collect();
        let mut x = vec![0.0; f * d];
        for i in 0..f {
            let coef: Vec<f64> = (0..r).map(|_| rnd()).collect();
            for j in 0..d {
                x[i * d + j] = mean[j] + (0..r).map(|q| coef[q] * basis[q * d + j]).sum::<f64>();
            }
        }
        x
    }

    #[test]
    fn reconstruction_with_rank_components_is_exact() {
        let (f, e, w, r) = (12, 20, 3, 4);
        let x = low_rank(f, e, w, r);
        let m = Pca::fit(DataMatrix::new(&x, f, e, w).unwrap(), &PcaConfig { components: r, ..Default::default() })
            .unwrap();
        let rec = m.reconstruct().unwrap();
        let err = rec.iter().zip(&x).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(err < 1e-10, "max abs error {err}");
        // one component fewer cannot be exact
        let m2 =
            Pca::fit(DataMatrix::new(&x, f, e, w).unwrap(), &PcaConfig { components: r - 1, ..Default::default() })
                .unwrap();
        let err2 = m2.reconstruct().unwrap().iter().zip(&x).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(err2 > 1e-3, "rank-{} reconstruction unexpectedly exact ({err2})", r - 1);
    }

    #[test]
    fn components_orthonormal_and_encode_matches_training_weights() {
        let (f, e, w) = (10, 15, 3);
        let x = low_rank(f, e, w, 9);
        let m = Pca::fit(DataMatrix::new(&x, f, e, w).unwrap(), &PcaConfig { components: 5, ..Default::default() })
            .unwrap();
        for a in 0..5 {
            for b in 0..5 {
                let dot: f64 = m.component(a).iter().zip(m.component(b)).map(|(p, q)| p * q).sum();
                assert!((dot - if a == b { 1.0 } else { 0.0 }).abs() < 1e-10);
            }
        }
        let enc = m.encoder().unwrap();
        for r in 0..f {
            let got = enc.encode(&x[r * e * w..(r + 1) * e * w]).unwrap();
            for (g, t) in got.iter().zip(m.frame_weights(r)) {
                assert!((g - t).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn too_many_components_is_an_error_naming_the_value() {
        let x = low_rank(4, 5, 3, 2);
        let err = Pca::fit(DataMatrix::new(&x, 4, 5, 3).unwrap(), &PcaConfig { components: 7, ..Default::default() })
            .unwrap_err()
            .to_string();
        assert!(err.contains("components (7)") && err.contains("frames 4"), "{err}");
    }

    /// F × (E·W) data with singular values decaying like 0.7^q over all min(F, D) directions
    /// (full rank, no exact gap), plus a mean row; deterministic.
    fn decaying(f: usize, e: usize, w: usize) -> Vec<f64> {
        let d = e * w;
        let mut rng = Rng::new(99);
        let mean: Vec<f64> = (0..d).map(|_| rng.normal()).collect();
        let mut x: Vec<f64> = mean.iter().copied().cycle().take(f * d).collect();
        for q in 0..f.min(d) {
            let s = 0.7f64.powi(q as i32);
            let a: Vec<f64> = (0..f).map(|_| rng.normal()).collect();
            let b: Vec<f64> = (0..d).map(|_| rng.normal()).collect();
            for i in 0..f {
                for j in 0..d {
                    x[i * d + j] += s * a[i] * b[j];
                }
            }
        }
        x
    }

    fn frobenius_error(m: &LinearModel, x: &[f64]) -> f64 {
        m.reconstruct().unwrap().iter().zip(x).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt()
    }

    fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
        assert_eq!(a.len(), b.len());
        a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max)
    }

    /// Cᵀ·C (D × D, row-major): the projector onto the components' span.
    fn projector(m: &LinearModel) -> Vec<f64> {
        let d = m.n_cols();
        let mut p = vec![0.0; d * d];
        for c in 0..m.n_components {
            let v = m.component(c);
            for i in 0..d {
                for j in 0..d {
                    p[i * d + j] += v[i] * v[j];
                }
            }
        }
        p
    }

    #[test]
    fn randomized_low_rank_is_exact_and_spans_fit_subspace() {
        let (f, e, w, r) = (40, 20, 3, 4);
        let x = low_rank(f, e, w, r);
        let dm = DataMatrix::new(&x, f, e, w).unwrap();
        let cfg = PcaConfig { components: r, ..Default::default() };
        let exact = Pca::fit(dm, &cfg).unwrap();
        let rand = Pca::fit_randomized(DataRef::F64(dm), &cfg, &RandomizedSvd::default()).unwrap();
        rand.validate().unwrap();
        assert_eq!(rand.offset, exact.offset, "mean row must equal fit's bit for bit");
        let err = max_abs_diff(&rand.reconstruct().unwrap(), &x);
        assert!(err < 1e-9, "max abs reconstruction error {err}");
        let dp = max_abs_diff(&projector(&rand), &projector(&exact));
        assert!(dp < 1e-9, "projectors differ by {dp}");
        // distinct singular values: the matched components agree up to sign, and the sign
        // convention makes them equal
        for c in 0..r {
            let dot: f64 = rand.component(c).iter().zip(exact.component(c)).map(|(a, b)| a * b).sum();
            assert!((dot - 1.0).abs() < 1e-9, "component {c}: dot {dot}");
        }
        // oversampling capped at min(F, D) with a tiny matrix
        let small = low_rank(6, 3, 3, 2);
        let m = Pca::fit_randomized(
            DataRef::F64(DataMatrix::new(&small, 6, 3, 3).unwrap()),
            &PcaConfig { components: 2, ..Default::default() },
            &RandomizedSvd { oversample: 100, ..Default::default() },
        )
        .unwrap();
        assert!(max_abs_diff(&m.reconstruct().unwrap(), &small) < 1e-10);
    }

    #[test]
    fn randomized_full_rank_matches_exact_error_and_is_orthonormal() {
        let (f, e, w, k) = (60, 30, 3, 5);
        let x = decaying(f, e, w);
        let dm = DataMatrix::new(&x, f, e, w).unwrap();
        // default options (l = 55 of 60) and a narrow sketch (l = 10 of 60)
        let narrow = RandomizedSvd { oversample: 5, ..Default::default() };
        for (centering, opts) in [
            (PcaCentering::Mean, RandomizedSvd::default()),
            (PcaCentering::Mean, narrow.clone()),
            (PcaCentering::None, narrow),
        ] {
            let cfg = PcaConfig { components: k, centering };
            let exact = Pca::fit(dm, &cfg).unwrap();
            let rand = Pca::fit_randomized(DataRef::F64(dm), &cfg, &opts).unwrap();
            assert_eq!(rand.constraint, WeightConstraint::Unconstrained);
            assert_eq!((rand.n_components, rand.n_frames, rand.n_elements, rand.width), (k, f, e, w));
            if centering == PcaCentering::None {
                assert!(rand.offset.iter().all(|&o| o == 0.0));
            }
            let (ee, er) = (frobenius_error(&exact, &x), frobenius_error(&rand, &x));
            assert!(ee > 1e-3, "test data should not be rank {k} ({ee})");
            assert!((er - ee).abs() <= 1e-6 * ee, "{centering:?}, {opts:?}: randomized error {er} vs exact {ee}");
            assert!(er >= ee * (1.0 - 1e-12), "randomized beat the optimum: {er} < {ee}");
            for a in 0..k {
                for b in 0..k {
                    let dot: f64 = rand.component(a).iter().zip(rand.component(b)).map(|(p, q)| p * q).sum();
                    assert!((dot - if a == b { 1.0 } else { 0.0 }).abs() < 1e-10, "C{a}·C{b} = {dot}");
                }
            }
            // weights are the projections of the centred rows
            let enc = rand.encoder().unwrap();
            for r in [0, f / 2, f - 1] {
                let got = enc.encode(&x[r * e * w..(r + 1) * e * w]).unwrap();
                assert!(max_abs_diff(&got, rand.frame_weights(r)) < 1e-9);
            }
        }
    }

    #[test]
    fn randomized_f32_data_matches_f64() {
        let (f, e, w, k) = (60, 30, 3, 5);
        let x = decaying(f, e, w);
        let dm = DataMatrix::new(&x, f, e, w).unwrap();
        let cm = CompactMatrix::new(x.iter().map(|&v| v as f32).collect(), f, e, w).unwrap();
        let cfg = PcaConfig { components: k, ..Default::default() };
        let opts = RandomizedSvd { oversample: 5, ..Default::default() };
        let m64 = Pca::fit_randomized(DataRef::F64(dm), &cfg, &opts).unwrap();
        let m32 = Pca::fit_randomized(DataRef::F32(&cm), &cfg, &opts).unwrap();
        let (e64, e32) = (frobenius_error(&m64, &x), frobenius_error(&m32, &x));
        assert!((e32 - e64).abs() <= 1e-5 * e64, "f32 error {e32} vs f64 {e64}");
    }

    #[test]
    fn randomized_is_deterministic_and_independent_of_block_size() {
        let (f, e, w, k) = (45, 20, 3, 6);
        let x = decaying(f, e, w);
        let data = DataRef::F64(DataMatrix::new(&x, f, e, w).unwrap());
        let cfg = PcaConfig { components: k, ..Default::default() };
        let opts = RandomizedSvd { seed: 7, oversample: 4, ..Default::default() };
        let a = Pca::fit_randomized(data, &cfg, &opts).unwrap();
        let b = Pca::fit_randomized(data, &cfg, &opts).unwrap();
        assert_eq!(a.weights, b.weights);
        assert_eq!(a.components, b.components);
        let c = Pca::fit_randomized(data, &cfg, &RandomizedSvd { block_rows: 7, ..opts.clone() }).unwrap();
        assert!(max_abs_diff(&a.components, &c.components) < 1e-10);
        assert!(max_abs_diff(&a.weights, &c.weights) < 1e-10);
        assert!(max_abs_diff(&a.offset, &c.offset) < 1e-12);
        // a different seed gives the same model (to the accuracy of the method)
        let s = Pca::fit_randomized(data, &cfg, &RandomizedSvd { seed: 8, ..opts }).unwrap();
        assert!(max_abs_diff(&projector(&a), &projector(&s)) < 1e-6);
    }

    #[test]
    fn randomized_rejects_bad_component_counts_like_fit() {
        let x = low_rank(4, 5, 3, 2);
        let dm = DataMatrix::new(&x, 4, 5, 3).unwrap();
        let opts = RandomizedSvd::default();
        for k in [0, 7] {
            let cfg = PcaConfig { components: k, ..Default::default() };
            let want = Pca::fit(dm, &cfg).unwrap_err().to_string();
            let got = Pca::fit_randomized(DataRef::F64(dm), &cfg, &opts).unwrap_err().to_string();
            assert_eq!(got, want);
        }
        let err = Pca::fit_randomized(DataRef::F64(dm), &PcaConfig { components: 7, ..Default::default() }, &opts)
            .unwrap_err()
            .to_string();
        assert!(err.contains("components (7)") && err.contains("frames 4"), "{err}");
        let err = Pca::fit_randomized(
            DataRef::F64(dm),
            &PcaConfig { components: 2, ..Default::default() },
            &RandomizedSvd { block_rows: 0, ..opts },
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("block_rows"), "{err}");
    }
}
