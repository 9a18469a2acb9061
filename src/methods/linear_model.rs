//! The fitted linear model shared by PCA, SPLOCS and region PCA:
//! `x ≈ offset + Σ_k w_k · C_k`, with components C (K × E·W), per-frame weights W (F × K) and an
//! offset (E·W) in the units of the data matrix the model was fitted to.
//!
//! Encoding a new row honours the model's [`WeightConstraint`] (see [`Encoder`]).

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// Constraint on the weights of a model.
///
/// For training, SPLOCS normalises each weight *column* (one component over all frames):
/// `Nonnegative` is the paper's Eq. (4) (`max(W[:,k]) = 1, W ≥ 0`, projection
/// `max(0,w)/max(w)`), `Signed` its Eq. (3) (`max|W[:,k]| = 1`, projection `w/max|w|`).
/// The column maximum is a property of a whole training set; when a *single* new row is
/// encoded ([`Encoder`]) only the sign part applies: `Nonnegative` → w ≥ 0 (non-negative least
/// squares), `Signed` and `Unconstrained` → plain least squares.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WeightConstraint {
    /// w ≥ 0 (SPLOCS Eq. 4).
    Nonnegative,
    /// Any sign, columns normalised to max |w| = 1 in training (SPLOCS Eq. 3).
    Signed,
    /// No constraint (PCA).
    Unconstrained,
}

impl WeightConstraint {
    /// Name used in configs: `nonnegative`, `signed`, `unconstrained`.
    pub fn name(self) -> &'static str {
        match self {
            WeightConstraint::Nonnegative => "nonnegative",
            WeightConstraint::Signed => "signed",
            WeightConstraint::Unconstrained => "unconstrained",
        }
    }
    /// Parses a config name (see [`WeightConstraint::name`]).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "nonnegative" => Some(WeightConstraint::Nonnegative),
            "signed" => Some(WeightConstraint::Signed),
            "unconstrained" => Some(WeightConstraint::Unconstrained),
            _ => None,
        }
    }
}

/// A fitted linear model `x ≈ offset + wᵀ·C`.
///
/// Shapes (all row-major `Vec<f64>`): `components` K × (E·W), `weights` F × K (the training
/// frames' weights), `offset` E·W. Element `e` of a row occupies columns `e·W .. e·W+W`.
/// Units are those of the data matrix the model was fitted to (SPLOCS undoes its internal
/// standardisation before returning the model).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearModel {
    /// Number of elements E.
    pub n_elements: usize,
    /// Group width W (numbers per element).
    pub width: usize,
    /// Number of components K.
    pub n_components: usize,
    /// Number of training frames F (rows of `weights`).
    pub n_frames: usize,
    /// K × (E·W) components, row-major.
    pub components: Vec<f64>,
    /// F × K training weights, row-major.
    pub weights: Vec<f64>,
    /// E·W offset added to every reconstruction (PCA: the mean row; SPLOCS: zeros, the data
    /// already being displacements from the rest shape).
    pub offset: Vec<f64>,
    /// Constraint the weights obey (and that [`Encoder`] honours).
    pub constraint: WeightConstraint,
}

impl LinearModel {
    /// Number of columns E·W.
    pub fn n_cols(&self) -> usize {
        self.n_elements * self.width
    }

    /// Checks that the stored arrays have the declared shapes and are finite (use after
    /// deserialising a model).
    pub fn validate(&self) -> Result<()> {
        let d = self.n_cols();
        let checks = [
            ("components", self.components.len(), self.n_components * d),
            ("weights", self.weights.len(), self.n_frames * self.n_components),
            ("offset", self.offset.len(), d),
        ];
        for (name, got, want) in checks {
            if got != want {
                return Err(Error::Invalid(format!(
                    "linear model: `{name}` has {got} values, expected {want} (K {}, F {}, E {}, W {})",
                    self.n_components, self.n_frames, self.n_elements, self.width
                )));
            }
        }
        for (name, v) in [("components", &self.components), ("weights", &self.weights), ("offset", &self.offset)] {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(Error::Invalid(format!("linear model: `{name}`[{i}] is not finite ({})", v[i])));
            }
        }
        Ok(())
    }

    /// Component `k` (E·W numbers).
    pub fn component(&self, k: usize) -> &[f64] {
        let d = self.n_cols();
        &self.components[k * d..(k + 1) * d]
    }

    /// Weights of training frame `f` (K numbers).
    pub fn frame_weights(&self, f: usize) -> &[f64] {
        &self.weights[f * self.n_components..(f + 1) * self.n_components]
    }

    /// Group norms of component `k`: E values ‖C_k,e‖₂.
    pub fn component_group_norms(&self, k: usize) -> Vec<f64> {
        self.component(k).chunks_exact(self.width).map(|g| g.iter().map(|v| v * v).sum::<f64>().sqrt()).collect()
    }

    /// Reconstruction of every training frame: F × (E·W), row-major, `offset + W·C`. Errors
    /// when the model's arrays are inconsistent (see [`LinearModel::validate`]).
    pub fn reconstruct(&self) -> Result<Vec<f64>> {
        self.reconstruct_weights(&self.weights, self.n_frames)
    }

    /// `offset + weights·C` for `n_rows` rows of weights (`n_rows` × K, row-major); returns
    /// `n_rows` × (E·W), row-major. Errors on inconsistent shapes or non-finite weights.
    pub fn reconstruct_weights(&self, weights: &[f64], n_rows: usize) -> Result<Vec<f64>> {
        self.validate()?;
        let d = self.n_cols();
        let k = self.n_components;
        if weights.len() != n_rows * k {
            return Err(Error::Invalid(format!(
                "reconstruct: {} weights given for {n_rows} rows of {k} components",
                weights.len()
            )));
        }
        if let Some(i) = weights.iter().position(|w| !w.is_finite()) {
            return Err(Error::Invalid(format!("reconstruct: weight {i} is not finite ({})", weights[i])));
        }
        let mut out = Vec::with_capacity(n_rows * d);
        for _ in 0..n_rows {
            out.extend_from_slice(&self.offset);
        }
        faer::linalg::matmul::matmul(
            faer::MatMut::from_row_major_slice_mut(&mut out, n_rows, d),
            faer::Accum::Add,
            faer::MatRef::from_row_major_slice(weights, n_rows, k),
            faer::MatRef::from_row_major_slice(&self.components, k, d),
            1.0,
            faer::Par::Seq,
        );
        Ok(out)
    }

    /// `offset + Σ_k weights[k]·C_k` (E·W numbers). Errors when `weights` does not have K
    /// entries or holds a non-finite value.
    pub fn synthesize(&self, weights: &[f64]) -> Result<Vec<f64>> {
        if weights.len() != self.n_components {
            return Err(Error::Invalid(format!(
                "synthesize: {} weights given, the model has {} components",
                weights.len(),
                self.n_components
            )));
        }
        if let Some(i) = weights.iter().position(|w| !w.is_finite()) {
            return Err(Error::Invalid(format!("synthesize: weight {i} is not finite ({})", weights[i])));
        }
        let mut out = vec![0.0; self.n_cols()];
        self.synthesize_into(weights, &mut out);
        Ok(out)
    }

    fn synthesize_into(&self, weights: &[f64], out: &mut [f64]) {
        out.copy_from_slice(&self.offset);
        for (k, &w) in weights.iter().enumerate() {
            if w != 0.0 {
                for (o, c) in out.iter_mut().zip(self.component(k)) {
                    *o += w * c;
                }
            }
        }
    }

    /// Factorises the components' Gram matrix once for repeated [`Encoder::encode`] calls.
    pub fn encoder(&self) -> Result<Encoder<'_>> {
        Encoder::new(self)
    }

    /// One-shot [`Encoder::encode`]: least-squares weights of one new row `x` (E·W numbers).
    pub fn encode(&self, x: &[f64]) -> Result<Vec<f64>> {
        self.encoder()?.encode(x)
    }
}

/// Least-squares encoder of new rows for a [`LinearModel`]: minimises ‖x − offset − wᵀC‖²
/// subject to the model's constraint (`Nonnegative`: w ≥ 0, solved exactly by the
/// Lawson–Hanson active-set method on the normal equations; `Signed`, `Unconstrained`: plain
/// least squares). The Gram matrix G = C·Cᵀ (K × K) gets a relative ridge of 1e-12·max(diag G)
/// so that all-zero or collinear components (SPLOCS can return zero components) get a
/// well-defined, minimum-norm-like answer (weight 0 for a zero component).
pub struct Encoder<'a> {
    model: &'a LinearModel,
    gram: Mat<f64>,
    llt: faer::linalg::solvers::Llt<f64>,
}

impl<'a> Encoder<'a> {
    /// Builds G = C·Cᵀ + ridge·I and its Cholesky factor.
    pub fn new(model: &'a LinearModel) -> Result<Self> {
        model.validate()?;
        let k = model.n_components;
        let d = model.n_cols();
        let c = faer::MatRef::from_row_major_slice(&model.components, k, d);
        let mut gram = Mat::<f64>::zeros(k, k);
        faer::linalg::matmul::matmul(gram.as_mut(), faer::Accum::Replace, c, c.transpose(), 1.0, faer::Par::Seq);
        let max_diag = (0..k).map(|i| gram[(i, i)]).fold(0.0f64, f64::max);
        let ridge = 1e-12 * max_diag.max(f64::MIN_POSITIVE) + 1e-300;
        for i in 0..k {
            gram[(i, i)] += ridge;
        }
        let llt = gram
            .llt(Side::Lower)
            .map_err(|e| Error::Numerical(format!("encoder: Cholesky of the component Gram matrix failed: {e:?}")))?;
        Ok(Encoder { model, gram, llt })
    }

    /// Weights (K numbers) of one new row `x` (E·W numbers, same units as the model).
    pub fn encode(&self, x: &[f64]) -> Result<Vec<f64>> {
        let m = self.model;
        let d = m.n_cols();
        if x.len() != d {
            return Err(Error::Invalid(format!("encode: row has {} values, the model expects {d}", x.len())));
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!("encode: value {i} is not finite ({})", x[i])));
        }
        let k = m.n_components;
        // b = C (x − offset)
        let mut b = vec![0.0; k];
        for (j, bj) in b.iter_mut().enumerate() {
            *bj = m.component(j).iter().zip(x).zip(&m.offset).map(|((c, xv), o)| c * (xv - o)).sum();
        }
        match m.constraint {
            WeightConstraint::Nonnegative => nnls_gram(&self.gram, &b),
            WeightConstraint::Signed | WeightConstraint::Unconstrained => {
                let mut rhs = Mat::<f64>::from_fn(k, 1, |i, _| b[i]);
                self.llt.solve_in_place(rhs.as_mut());
                Ok((0..k).map(|i| rhs[(i, 0)]).collect())
            }
        }
    }

    /// Encodes every row of a row-major matrix (`n_rows` × E·W); returns `n_rows` × K.
    pub fn encode_rows(&self, rows: &[f64]) -> Result<Vec<f64>> {
        let d = self.model.n_cols();
        if !rows.len().is_multiple_of(d) {
            return Err(Error::Invalid(format!(
                "encode: {} values is not a multiple of the row length {d}",
                rows.len()
            )));
        }
        let mut out = Vec::with_capacity(rows.len() / d * self.model.n_components);
        for r in rows.chunks_exact(d) {
            out.extend(self.encode(r)?);
        }
        Ok(out)
    }
}

/// Non-negative least squares in normal-equation form: argmin_{w ≥ 0} ½wᵀGw − bᵀw with G
/// symmetric positive definite (Lawson–Hanson active set). Exact up to round-off; at most
/// 3K + 10 outer steps.
pub(crate) fn nnls_gram(g: &Mat<f64>, b: &[f64]) -> Result<Vec<f64>> {
    let k = b.len();
    let scale = b.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(f64::MIN_POSITIVE);
    let tol = 1e-12 * scale * (k as f64).max(1.0);
    let mut w = vec![0.0; k];
    let mut passive = vec![false; k];
    let solve_passive = |passive: &[bool]| -> Result<Vec<f64>> {
        let idx: Vec<usize> = (0..k).filter(|&i| passive[i]).collect();
        let p = idx.len();
        let sub = Mat::<f64>::from_fn(p, p, |i, j| g[(idx[i], idx[j])]);
        let llt = sub
            .llt(Side::Lower)
            .map_err(|e| Error::Numerical(format!("nnls: Cholesky of a {p}×{p} sub-Gram failed: {e:?}")))?;
        let mut rhs = Mat::<f64>::from_fn(p, 1, |i, _| b[idx[i]]);
        llt.solve_in_place(rhs.as_mut());
        let mut s = vec![0.0; k];
        for (i, &j) in idx.iter().enumerate() {
            s[j] = rhs[(i, 0)];
        }
        Ok(s)
    };
    for _ in 0..(3 * k + 10) {
        // negative gradient b − G w
        let grad: Vec<f64> = (0..k).map(|i| b[i] - (0..k).map(|j| g[(i, j)] * w[j]).sum::<f64>()).collect();
        let cand = (0..k).filter(|&i| !passive[i]).max_by(|&a, &c| grad[a].total_cmp(&grad[c]));
        let Some(j) = cand else { break };
        if grad[j] <= tol {
            break;
        }
        passive[j] = true;
        loop {
            let s = solve_passive(&passive)?;
            let bad: Vec<usize> = (0..k).filter(|&i| passive[i] && s[i] <= 0.0).collect();
            if bad.is_empty() {
                w = s;
                break;
            }
            let alpha = bad.iter().map(|&i| w[i] / (w[i] - s[i])).fold(f64::INFINITY, f64::min);
            for i in 0..k {
                if passive[i] {
                    w[i] += alpha * (s[i] - w[i]);
                }
            }
            for i in 0..k {
                if passive[i] && w[i] <= tol {
                    passive[i] = false;
                    w[i] = 0.0;
                }
            }
            if !passive.iter().any(|&p| p) {
                break;
            }
        }
    }
    Ok(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(constraint: WeightConstraint) -> LinearModel {
        // 3 components over 4 elements of width 2, 2 frames
        let components = vec![
            1.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, //
            0.0, 0.3, 0.0, 0.0, 0.0, 0.0, 1.0, -1.0,
        ];
        LinearModel {
            n_elements: 4,
            width: 2,
            n_components: 3,
            n_frames: 2,
            components,
            weights: vec![1.0, 0.5, 0.0, 0.2, 0.0, 1.0],
            offset: vec![0.1, -0.2, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0],
            constraint,
        }
    }

    #[test]
    fn encode_inverts_synthesize() {
        for c in [WeightConstraint::Signed, WeightConstraint::Unconstrained, WeightConstraint::Nonnegative] {
            let m = model(c);
            let w = [0.7, 1.3, 0.4];
            let x = m.synthesize(&w).unwrap();
            let got = m.encode(&x).unwrap();
            for (a, b) in got.iter().zip(&w) {
                assert!((a - b).abs() < 1e-10, "{c:?}: {got:?} vs {w:?}");
            }
        }
    }

    #[test]
    fn nonnegative_encode_matches_brute_force() {
        let m = model(WeightConstraint::Nonnegative);
        let x = m.synthesize(&[0.7, -1.3, 0.4]).unwrap();
        let got = m.encode(&x).unwrap();
        assert!(got.iter().all(|&w| w >= 0.0));
        // brute force over active sets: best feasible unconstrained-LS on every subset
        let err = |w: &[f64]| -> f64 {
            let r = m.synthesize(w).unwrap();
            r.iter().zip(&x).map(|(a, b)| (a - b) * (a - b)).sum()
        };
        let mut best = f64::INFINITY;
        for mask in 0u32..8 {
            let sub = LinearModel {
                components: (0..3)
                    .flat_map(|k| {
                        let on = mask & (1 << k) != 0;
                        m.component(k).iter().map(move |&v| if on { v } else { 0.0 })
                    })
                    .collect(),
                constraint: WeightConstraint::Unconstrained,
                ..m.clone()
            };
            let w = sub.encode(&x).unwrap();
            if w.iter().all(|&v| v >= -1e-12) {
                best = best.min(err(&w));
            }
        }
        assert!((err(&got) - best).abs() < 1e-10, "nnls {} vs brute force {}", err(&got), best);
    }

    #[test]
    fn signed_encode_allows_negative_weights() {
        let m = model(WeightConstraint::Signed);
        let w = [0.7, -1.3, 0.4];
        let got = m.encode(&m.synthesize(&w).unwrap()).unwrap();
        assert!((got[1] + 1.3).abs() < 1e-10);
    }

    #[test]
    fn zero_component_gets_zero_weight() {
        let mut m = model(WeightConstraint::Signed);
        for v in &mut m.components[8..16] {
            *v = 0.0;
        }
        let got = m.encode(&m.synthesize(&[0.7, 0.0, 0.4]).unwrap()).unwrap();
        assert!(got.iter().all(|w| w.is_finite()));
        assert!(got[1].abs() < 1e-9 && (got[0] - 0.7).abs() < 1e-9);
    }

    #[test]
    fn reconstruct_and_validate() {
        let m = model(WeightConstraint::Signed);
        let r = m.reconstruct().unwrap();
        assert_eq!(r.len(), 2 * 8);
        assert_eq!(&r[8..], &m.synthesize(&[0.2, 0.0, 1.0]).unwrap()[..]);
        let mut bad = m.clone();
        bad.offset.pop();
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("offset") && e.contains("7"), "{e}");
        assert!(m.synthesize(&[1.0]).unwrap_err().to_string().contains("1 weights"));
        let json = serde_json::to_string(&m).unwrap();
        let back: LinearModel = serde_json::from_str(&json).unwrap();
        assert_eq!(back, m);
    }
}
