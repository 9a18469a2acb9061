//! Sparse dials of a latent space: a basis of K directions in which the training codes are
//! sparse, non-negative combinations (issue 53, docs/ground-truth.md).
//!
//! Input: the training codes around a reference code, Y (F × K, row f = z_f − z_r, code
//! units). Output: K directions b_m (K numbers each, code units) such that each training code
//! is close to a non-negative combination of few of them, z_f ≈ z_r + Σ_m d_fm·b_m with
//! d_fm ≥ 0, each b_m scaled so that the largest training weight of direction m is 1 (dial 1 is
//! the training extreme, as for per-dimension dials).
//!
//! Fit: a sparse non-negative dictionary, minimising ½‖Y − W·A‖² + λ·Σ W over W ≥ 0 (F × K)
//! and A (K × K, rows of unit length), λ = `sparsity` × max |Y|; alternating `ROUNDS` rounds of
//! `ISTA_STEPS` projected soft-threshold steps on W with a least-squares update of A (ridge
//! 10⁻⁶ × the mean of diag WᵀW, towards the previous A, so a direction no frame uses keeps its
//! way). Starts from the varimax rotation of Y ([`varimax`]), each axis signed so that its
//! extreme training value is positive. Deterministic.
//!
//! Why: the autoencoder's tied latent matrix is fixed only up to an orthogonal rotation by its
//! reconstruction, and its per-dimension components mix the deformations that occur separately
//! in the data; training codes of frames made of 1–4 of D deformations are sparse in the basis
//! of those deformations. Reading the dials in this basis changes no decoding: it is an
//! invertible linear map of the code ([`SparseDials::dials_of`], [`SparseDials::code_of`]).

use crate::error::{Error, Result};
use faer::Mat;
use faer::linalg::solvers::Solve;

/// Alternating rounds of the dictionary fit.
const ROUNDS: usize = 200;
/// Projected soft-threshold steps on W per round.
const ISTA_STEPS: usize = 20;
/// Most varimax iterations (stops earlier when the criterion changes by < 1e-10 relative).
const VARIMAX_ITERATIONS: usize = 500;
/// Directions whose K × K matrix has a reciprocal condition estimate below this are refused.
const MIN_RCOND: f64 = 1e-10;

/// Kaiser's raw varimax rotation of the columns of `y` (F × K): the orthogonal R (K × K) that
/// maximises Σ_k var_f((Y·R)_fk²), so that each rotated column is large in few rows.
pub fn varimax(y: &Mat<f64>) -> Result<Mat<f64>> {
    let (f, k) = (y.nrows(), y.ncols());
    let mut r = Mat::<f64>::identity(k, k);
    let mut last = 0.0;
    for _ in 0..VARIMAX_ITERATIONS {
        let l = y * &r;
        let mut target = Mat::<f64>::zeros(f, k);
        for c in 0..k {
            let m2 = (0..f).map(|i| l[(i, c)] * l[(i, c)]).sum::<f64>() / f.max(1) as f64;
            for i in 0..f {
                target[(i, c)] = l[(i, c)].powi(3) - l[(i, c)] * m2;
            }
        }
        let g = y.transpose() * &target;
        let svd = g.thin_svd().map_err(|e| Error::Numerical(format!("varimax: SVD failed: {e:?}")))?;
        r = svd.U() * svd.V().transpose();
        let obj: f64 = (0..k).map(|c| svd.S()[c]).sum();
        if (obj - last).abs() <= 1e-10 * obj.abs() {
            break;
        }
        last = obj;
    }
    Ok(r)
}

/// The K dial directions of a latent space (see the module docs). Written as its list of
/// directions (`serde(transparent)`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(transparent)]
pub struct SparseDials {
    /// K directions, K numbers each (code units): dial m moves the code by `directions[m]`.
    pub directions: Vec<Vec<f64>>,
}

impl SparseDials {
    /// Fits the directions to `codes` (F rows of K numbers) around `reference` (K numbers).
    /// `sparsity` (> 0) is λ as a share of the largest |z_f − z_r|. Errors on no codes, rows of
    /// other lengths, non-finite values, or directions that do not span the latent space.
    pub fn fit(codes: &[Vec<f64>], reference: &[f64], sparsity: f64) -> Result<Self> {
        let k = reference.len();
        if codes.is_empty() || k == 0 {
            return Err(Error::Invalid("sparse dials: no training codes".into()));
        }
        if let Some(i) = codes.iter().position(|c| c.len() != k) {
            return Err(Error::Invalid(format!("sparse dials: code {i} has {} values, not {k}", codes[i].len())));
        }
        if !(sparsity.is_finite() && sparsity > 0.0) {
            return Err(Error::Invalid(format!("sparse dials: sparsity {sparsity} must be positive")));
        }
        if codes.iter().flatten().chain(reference).any(|x| !x.is_finite()) {
            return Err(Error::Invalid("sparse dials: a code is not finite".into()));
        }
        let f = codes.len();
        let y = Mat::<f64>::from_fn(f, k, |i, c| codes[i][c] - reference[c]);
        let ymax = (0..f).flat_map(|i| (0..k).map(move |c| (i, c))).map(|(i, c)| y[(i, c)].abs()).fold(0.0, f64::max);
        if ymax == 0.0 {
            // Every training code is the reference: no direction is preferred.
            return Ok(SparseDials {
                directions: (0..k).map(|m| (0..k).map(|c| f64::from(m == c)).collect()).collect(),
            });
        }
        // Start: the varimax axes, each signed so that its extreme training value is positive.
        let r = varimax(&y)?;
        let yr = &y * &r;
        let mut a = Mat::<f64>::from_fn(k, k, |m, c| {
            let ext = (0..f).map(|i| yr[(i, m)]).max_by(|p, q| p.abs().total_cmp(&q.abs())).unwrap_or(1.0);
            r[(c, m)] * if ext < 0.0 { -1.0 } else { 1.0 }
        });
        let start = a.clone();
        // A dictionary that does not span (two atoms drawn together) gives way to the varimax
        // axes, which always do.
        if sparse_nonnegative_dictionary(&y, &mut a, sparsity * ymax).is_ok()
            && let Ok(dials) = scaled(&y, &a)
        {
            return Ok(dials);
        }
        scaled(&y, &start)
    }

    /// Number of dials (= the latent dimension K).
    pub fn len(&self) -> usize {
        self.directions.len()
    }

    /// Whether there are no dials.
    pub fn is_empty(&self) -> bool {
        self.directions.is_empty()
    }

    /// Checks K directions of K finite numbers that span the latent space (reciprocal
    /// condition estimate ≥ 10⁻¹⁰ from the singular values).
    pub fn check(&self) -> Result<()> {
        let k = self.directions.len();
        if k == 0 {
            return Err(Error::Invalid("dial directions: none".into()));
        }
        if let Some(m) = self.directions.iter().position(|d| d.len() != k || d.iter().any(|x| !x.is_finite())) {
            return Err(Error::Invalid(format!(
                "dial direction {m} has {} numbers (the latent dimension is {k}) or a non-finite one",
                self.directions[m].len()
            )));
        }
        let b = self.matrix();
        let s = b.singular_values().map_err(|e| Error::Numerical(format!("dial directions: SVD failed: {e:?}")))?;
        let (hi, lo) = (s.iter().copied().fold(0.0, f64::max), s.iter().copied().fold(f64::INFINITY, f64::min));
        if !(hi > 0.0 && lo / hi >= MIN_RCOND) {
            return Err(Error::Invalid(format!(
                "dial directions do not span the latent space (singular values {lo:e} … {hi:e})"
            )));
        }
        Ok(())
    }

    /// B (K × K): column m is direction m.
    fn matrix(&self) -> Mat<f64> {
        let k = self.directions.len();
        Mat::<f64>::from_fn(k, k, |c, m| self.directions[m][c])
    }

    /// The code `reference + Σ_m dials[m]·directions[m]` (`dials` has K numbers).
    pub fn code_of(&self, reference: &[f64], dials: &[f64]) -> Vec<f64> {
        let mut z = reference.to_vec();
        for (d, b) in dials.iter().zip(&self.directions) {
            for (zc, bc) in z.iter_mut().zip(b) {
                *zc += d * bc;
            }
        }
        z
    }

    /// The dials of a code: the solution d of `Σ_m d_m·directions[m] = code − reference`.
    pub fn dials_of(&self, reference: &[f64], code: &[f64]) -> Result<Vec<f64>> {
        Ok(self.dials_of_all(reference, std::slice::from_ref(&code.to_vec()))?.remove(0))
    }

    /// [`Self::dials_of`] for every code, with one factorisation of the directions.
    pub fn dials_of_all(&self, reference: &[f64], codes: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        let k = self.directions.len();
        if reference.len() != k {
            return Err(Error::Invalid(format!(
                "a reference code of {} numbers: the latent dimension is {k}",
                reference.len()
            )));
        }
        if let Some(code) = codes.iter().find(|c| c.len() != k) {
            return Err(Error::Invalid(format!(
                "dials of a code of {} numbers: the latent dimension is {k}",
                code.len()
            )));
        }
        let rhs = Mat::<f64>::from_fn(k, codes.len(), |c, f| codes[f][c] - reference[c]);
        let d = self.matrix().partial_piv_lu().solve(&rhs);
        Ok((0..codes.len()).map(|f| (0..k).map(|m| d[(m, f)]).collect()).collect())
    }
}

/// The directions of unit rows `a` (K × K) scaled for the codes `y` (F × K): each by its
/// training dial of largest magnitude (exact dials D = Y·A⁻¹), so that it is 1 there; a
/// direction the codes hardly use (there are fewer codes than dimensions, or a spare atom)
/// keeps at least 10⁻³ of the largest scale, so that the basis stays well conditioned.
fn scaled(y: &Mat<f64>, a: &Mat<f64>) -> Result<SparseDials> {
    let (f, k) = (y.nrows(), a.nrows());
    let d = a.transpose().partial_piv_lu().solve(y.transpose()).transpose().to_owned();
    let ext: Vec<f64> =
        (0..k).map(|m| (0..f).map(|i| d[(i, m)]).max_by(|p, q| p.abs().total_cmp(&q.abs())).unwrap_or(0.0)).collect();
    let largest = ext.iter().filter(|x| x.is_finite()).fold(0.0f64, |m, x| m.max(x.abs()));
    let floor = 1e-3 * if largest > 0.0 { largest } else { 1.0 };
    let directions = (0..k)
        .map(|m| {
            let e = ext[m];
            let s = if e.is_finite() && e.abs() >= floor { e } else { floor };
            (0..k).map(|c| a[(m, c)] * s).collect()
        })
        .collect();
    let dials = SparseDials { directions };
    dials.check()?;
    Ok(dials)
}

/// Minimises ½‖Y − W·A‖² + λ·Σ W over W ≥ 0 and A with rows of unit length, from `a`
/// (updated in place).
fn sparse_nonnegative_dictionary(y: &Mat<f64>, a: &mut Mat<f64>, lambda: f64) -> Result<()> {
    let mut w = y * a.transpose();
    for j in 0..w.ncols() {
        for i in 0..w.nrows() {
            w[(i, j)] = w[(i, j)].max(0.0);
        }
    }
    for _ in 0..ROUNDS {
        let aat = &*a * a.transpose();
        let lip = aat.norm_l2().max(1e-300) * 1.01;
        let ya = y * a.transpose();
        for _ in 0..ISTA_STEPS {
            let grad = &w * &aat - &ya;
            for j in 0..w.ncols() {
                for i in 0..w.nrows() {
                    w[(i, j)] = (w[(i, j)] - (grad[(i, j)] + lambda) / lip).max(0.0);
                }
            }
        }
        // A by ridge least squares towards the previous A.
        let mut wtw = w.transpose() * &w;
        let kk = wtw.nrows();
        let tr = (0..kk).map(|i| wtw[(i, i)]).sum::<f64>();
        let eps = (1e-6 * tr / kk as f64).max(1e-300);
        for i in 0..kk {
            wtw[(i, i)] += eps;
        }
        let rhs = w.transpose() * y + &*a * faer::Scale(eps);
        let llt = wtw
            .llt(faer::Side::Lower)
            .map_err(|e| Error::Numerical(format!("sparse dials: Cholesky of WᵀW + εI failed: {e:?}")))?;
        *a = llt.solve(&rhs);
        for m in 0..a.nrows() {
            let n = (0..a.ncols()).map(|c| a[(m, c)] * a[(m, c)]).sum::<f64>().sqrt();
            if n > 0.0 && n.is_finite() {
                for c in 0..a.ncols() {
                    a[(m, c)] /= n;
                }
                for i in 0..w.nrows() {
                    w[(i, m)] *= n;
                }
            }
        }
    }
    if a.col_iter().flat_map(|c| c.iter().copied().collect::<Vec<_>>()).any(|x| !x.is_finite()) {
        return Err(Error::Numerical("sparse dials: the fit diverged".into()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// F codes made of 1–2 of K planted non-negative directions (not orthogonal).
    fn planted(k: usize, f: usize, seed: u64) -> (Vec<Vec<f64>>, Vec<f64>, Vec<Vec<f64>>) {
        let mut rng = Rng::new(seed);
        let truth: Vec<Vec<f64>> =
            (0..k).map(|m| (0..k).map(|c| if c == m { 1.0 } else { 0.3 * (rng.uniform() - 0.5) }).collect()).collect();
        let reference: Vec<f64> = (0..k).map(|c| 0.1 * c as f64).collect();
        let codes = (0..f)
            .map(|_| {
                let mut z = reference.clone();
                for _ in 0..2 {
                    let m = (rng.uniform() * k as f64) as usize % k;
                    let w = 0.2 + 0.8 * rng.uniform();
                    for c in 0..k {
                        z[c] += w * truth[m][c];
                    }
                }
                z
            })
            .collect();
        (codes, reference, truth)
    }

    fn cos(a: &[f64], b: &[f64]) -> f64 {
        let d: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
        d / (a.iter().map(|x| x * x).sum::<f64>().sqrt() * b.iter().map(|x| x * x).sum::<f64>().sqrt())
    }

    #[test]
    fn planted_sparse_directions_are_found_and_dial_one_is_the_extreme() {
        let (codes, reference, truth) = planted(6, 300, 7);
        let dials = SparseDials::fit(&codes, &reference, 0.03).unwrap();
        assert_eq!(dials.len(), 6);
        for t in &truth {
            let best = dials.directions.iter().map(|d| cos(d, t)).fold(f64::NEG_INFINITY, f64::max);
            assert!(best > 0.98, "a planted direction is matched at cos {best}");
        }
        // Training dials are (nearly) non-negative and reach exactly 1 at their extreme.
        let all: Vec<Vec<f64>> = codes.iter().map(|z| dials.dials_of(&reference, z).unwrap()).collect();
        for m in 0..6 {
            let hi = all.iter().map(|d| d[m]).fold(f64::NEG_INFINITY, f64::max);
            let lo = all.iter().map(|d| d[m]).fold(f64::INFINITY, f64::min);
            assert!((hi - 1.0).abs() < 1e-9, "dial {m} peaks at {hi}");
            assert!(lo > -0.15, "dial {m} goes down to {lo}");
        }
    }

    #[test]
    fn fewer_codes_than_dimensions_still_give_a_basis() {
        // 36 SCAPE shapes and K 50: the codes span at most 3 of 6 dimensions here.
        let (codes, reference, _) = planted(6, 3, 11);
        let dials = SparseDials::fit(&codes, &reference, 0.03).unwrap();
        dials.check().unwrap();
        for z in &codes {
            let back = dials.code_of(&reference, &dials.dials_of(&reference, z).unwrap());
            assert!(back.iter().zip(z).all(|(a, b)| (a - b).abs() < 1e-8));
        }
        // A single code, and codes along one line.
        let one = SparseDials::fit(&codes[..1], &reference, 0.03).unwrap();
        one.check().unwrap();
        let line: Vec<Vec<f64>> = (1..5)
            .map(|t| reference.iter().enumerate().map(|(c, r)| r + t as f64 * (c as f64 - 2.0)).collect())
            .collect();
        SparseDials::fit(&line, &reference, 0.1).unwrap().check().unwrap();
    }

    #[test]
    fn dials_and_codes_invert_each_other() {
        let (codes, reference, _) = planted(5, 80, 3);
        let dials = SparseDials::fit(&codes, &reference, 0.03).unwrap();
        for z in &codes {
            let d = dials.dials_of(&reference, z).unwrap();
            let back = dials.code_of(&reference, &d);
            for (a, b) in back.iter().zip(z) {
                assert!((a - b).abs() < 1e-9 * (1.0 + b.abs()), "{a} vs {b}");
            }
        }
        assert_eq!(dials.code_of(&reference, &[0.0; 5]), reference);
        assert!(dials.dials_of(&reference, &[0.0; 4]).is_err());
    }

    #[test]
    fn varimax_is_orthogonal_and_undoes_a_rotation_of_sparse_columns() {
        // Sparse columns (each row one non-zero), mixed by a rotation: varimax unmixes them.
        let f = 60;
        let y0 = Mat::<f64>::from_fn(f, 3, |i, c| if i % 3 == c { 1.0 + (i as f64) * 0.01 } else { 0.0 });
        let (s, co) = (0.6f64.sin(), 0.6f64.cos());
        let rot = Mat::<f64>::from_fn(3, 3, |r, c| match (r, c) {
            (0, 0) | (1, 1) => co,
            (0, 1) => -s,
            (1, 0) => s,
            (2, 2) => 1.0,
            _ => 0.0,
        });
        let y = &y0 * &rot;
        let r = varimax(&y).unwrap();
        let id = r.transpose() * &r;
        for i in 0..3 {
            for j in 0..3 {
                assert!((id[(i, j)] - f64::from(i == j)).abs() < 1e-9);
            }
        }
        let back = &y * &r;
        for i in 0..f {
            let peak = (0..3).map(|c| back[(i, c)].abs()).fold(0.0, f64::max);
            let nz = (0..3).filter(|&c| back[(i, c)].abs() > 1e-3 * peak).count();
            assert_eq!(nz, 1, "row {i} of the rotated codes has {nz} non-zeros");
        }
    }

    #[test]
    fn bad_inputs_are_refused_by_name() {
        assert!(SparseDials::fit(&[], &[0.0, 0.0], 0.03).is_err());
        assert!(SparseDials::fit(&[vec![1.0]], &[0.0, 0.0], 0.03).unwrap_err().to_string().contains("code 0"));
        assert!(SparseDials::fit(&[vec![1.0, f64::NAN]], &[0.0, 0.0], 0.03).is_err());
        assert!(SparseDials::fit(&[vec![1.0, 0.0]], &[0.0, 0.0], 0.0).is_err());
        // Codes all at the reference: the identity.
        let d = SparseDials::fit(&[vec![0.5, 0.5]], &[0.5, 0.5], 0.03).unwrap();
        assert_eq!(d.directions, vec![vec![1.0, 0.0], vec![0.0, 1.0]]);
        // Directions that do not span, or of the wrong length, are refused.
        assert!(SparseDials { directions: vec![vec![1.0, 0.0], vec![2.0, 0.0]] }.check().is_err());
        assert!(SparseDials { directions: vec![vec![1.0], vec![0.0, 1.0]] }.check().is_err());
        assert!(SparseDials { directions: vec![] }.check().is_err());
        assert!(SparseDials { directions: vec![vec![1.0, 0.0], vec![0.0, 1.0]] }.check().is_ok());
    }
}
