//! Holistic PCA of a data matrix X (F × E·W): the baseline every comparison table needs.
//!
//! With [`PcaCentering::Mean`] (default) the model is `x ≈ mean + Σ_k w_k C_k` with C the K
//! leading right singular vectors of X − 1·meanᵀ (orthonormal rows) and W = (X − mean)·Cᵀ; this
//! is the best rank-K affine approximation of the training data. With [`PcaCentering::None`]
//! the SVD is of X itself (offset 0): for displacement features, PCA "about the rest shape",
//! the setting SPLOCS's own data term uses. Sign convention: each component is flipped so that
//! its entry of largest magnitude is positive (deterministic output).

use faer::MatRef;
use serde::{Deserialize, Serialize};

use super::{DataMatrix, LinearModel, WeightConstraint};
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
        if k > f.min(d) {
            return Err(Error::config(
                "components",
                format!("components ({k}) must not exceed min(frames {f}, columns {d}) for PCA"),
            ));
        }
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
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
