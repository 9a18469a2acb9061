//! Factor-once / solve-many sparse Cholesky (`A = L·Lᵀ`) of a symmetric positive definite
//! matrix, a thin wrapper over faer's sparse Cholesky that always runs sequentially
//! (`Par::Seq`: on a 2-core machine the parallel code paths are slower) and reads only the
//! lower triangle of the matrix it is given.
//!
//! The symbolic analysis (AMD fill-reducing ordering + elimination structure) can be shared by
//! matrices with the same pattern ([`SparseCholesky::factor_with_symbolic`]).

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::SparseColMatRef;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::{Conj, MatMut, Par, Side};

use crate::{Error, Result};

/// Symbolic analysis shared between factorisations of matrices with one sparsity pattern.
pub type CholeskySymbolic = Arc<SymbolicCholesky<usize>>;

/// Which storage faer's symbolic analysis chooses for the factor.
///
/// faer picks a supernodal factor (dense blocks: fast factorisation) when the flop count per
/// factor entry exceeds a threshold, a simplicial one (column lists) otherwise. On mesh Laplacians
/// the simplicial factor solves about twice as fast (measured, one core: horse-gallop 8k vertices
/// 0.7 vs 1.6 ms, icosphere 10k 1.7–2.4 vs 2.0–4.2 ms, face 29k 5.7 vs 14 ms per solve) but
/// factors more slowly (icosphere 10k 67–98 vs 17–38 ms, face 29k 175 vs 108 ms).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FactorLayout {
    /// faer's default threshold.
    #[default]
    Auto,
    /// Twice faer's threshold: simplicial up to roughly 30k-vertex meshes, so that repeated
    /// solves are fast, while very large meshes stay supernodal (icosphere 41k: 0.2 s instead of
    /// 1.1 s to factor).
    PreferSimplicial,
}

/// A numeric sparse Cholesky factorisation of an N×N SPD matrix.
#[derive(Debug, Clone)]
pub struct SparseCholesky {
    symbolic: CholeskySymbolic,
    values: Vec<f64>,
}

impl SparseCholesky {
    /// Symbolic analysis (AMD ordering) of the lower triangle of `matrix`'s pattern, with
    /// [`FactorLayout::Auto`].
    pub fn analyze(matrix: SparseColMatRef<'_, usize, f64>) -> Result<CholeskySymbolic> {
        Self::analyze_with(matrix, FactorLayout::Auto)
    }

    /// Symbolic analysis (AMD ordering) of the lower triangle of `matrix`'s pattern.
    pub fn analyze_with(matrix: SparseColMatRef<'_, usize, f64>, layout: FactorLayout) -> Result<CholeskySymbolic> {
        if matrix.nrows() != matrix.ncols() {
            return Err(Error::Invalid(format!(
                "Cholesky of a non-square {}×{} matrix",
                matrix.nrows(),
                matrix.ncols()
            )));
        }
        let threshold = match layout {
            FactorLayout::Auto => SupernodalThreshold::AUTO,
            FactorLayout::PreferSimplicial => SupernodalThreshold(2.0 * SupernodalThreshold::AUTO.0),
        };
        let params = CholeskySymbolicParams { supernodal_flop_ratio_threshold: threshold, ..Default::default() };
        let s = factorize_symbolic_cholesky(matrix.symbolic(), Side::Lower, SymmetricOrdering::Amd, params)
            .map_err(|e| Error::Numerical(format!("symbolic Cholesky analysis failed: {e:?}")))?;
        Ok(Arc::new(s))
    }

    /// `true` when the factor uses faer's simplicial (column list) storage.
    pub fn is_simplicial(&self) -> bool {
        matches!(self.symbolic.raw(), SymbolicCholeskyRaw::Simplicial(_))
    }

    /// Analyses and factors `matrix` (lower triangle read). `what` names the matrix in errors.
    pub fn factor(matrix: SparseColMatRef<'_, usize, f64>, what: &str) -> Result<Self> {
        let symbolic = Self::analyze(matrix)?;
        Self::factor_with_symbolic(symbolic, matrix, what)
    }

    /// Factors `matrix`, whose pattern must be the one `symbolic` was computed from.
    /// Fails with [`Error::Numerical`] (naming `what`) when the matrix is not numerically
    /// positive definite.
    pub fn factor_with_symbolic(
        symbolic: CholeskySymbolic,
        matrix: SparseColMatRef<'_, usize, f64>,
        what: &str,
    ) -> Result<Self> {
        if matrix.nrows() != symbolic.nrows() || matrix.ncols() != symbolic.nrows() {
            return Err(Error::Invalid(format!(
                "{what}: matrix is {}×{}, symbolic factorisation is for {}",
                matrix.nrows(),
                matrix.ncols(),
                symbolic.nrows()
            )));
        }
        if let Some(bad) = matrix.val().iter().find(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!("{what}: matrix has a non-finite entry ({bad})")));
        }
        let mut values = vec![0.0; symbolic.len_val()];
        let req = symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
        let mut mem = MemBuffer::new(req);
        symbolic
            .factorize_numeric_llt(
                &mut values,
                matrix,
                Side::Lower,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| {
                Error::Numerical(format!("{what}: Cholesky factorisation failed, matrix not positive definite ({e:?})"))
            })?;
        Ok(SparseCholesky { symbolic, values })
    }

    /// The shared symbolic analysis.
    pub fn symbolic(&self) -> &CholeskySymbolic {
        &self.symbolic
    }

    /// N.
    pub fn n(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Solves `A x = b` in place: `rhs` holds b (N values) on entry and x on exit.
    ///
    /// # Panics
    /// If `rhs.len() != N`.
    pub fn solve_in_place(&self, rhs: &mut [f64]) {
        self.solve_columns_in_place(rhs, 1);
    }

    /// Solves `A X = B` in place for `ncols` right-hand sides stored column-major in `rhs`
    /// (N·ncols values).
    ///
    /// # Panics
    /// If `rhs.len() != N·ncols`.
    pub fn solve_columns_in_place(&self, rhs: &mut [f64], ncols: usize) {
        let n = self.n();
        assert_eq!(rhs.len(), n * ncols, "right-hand side length");
        if n == 0 || ncols == 0 {
            return;
        }
        let req = self.symbolic.solve_in_place_scratch::<f64>(ncols, Par::Seq);
        let mut mem = MemBuffer::new(req);
        let llt = LltRef::new(&self.symbolic, &self.values);
        let x = MatMut::from_column_major_slice_mut(rhs, n, ncols);
        llt.solve_in_place_with_conj(Conj::No, x, Par::Seq, MemStack::new(&mut mem));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::{SparseColMat, Triplet};

    #[test]
    fn solves_a_small_spd_system_and_rejects_indefinite() {
        // Tridiagonal [2 -1; -1 2 -1; -1 2], full storage.
        let t = vec![
            Triplet::new(0, 0, 2.0),
            Triplet::new(1, 1, 2.0),
            Triplet::new(2, 2, 2.0),
            Triplet::new(0, 1, -1.0),
            Triplet::new(1, 0, -1.0),
            Triplet::new(1, 2, -1.0),
            Triplet::new(2, 1, -1.0),
        ];
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(3, 3, &t).unwrap();
        let llt = SparseCholesky::factor(a.as_ref(), "test").unwrap();
        assert!(llt.is_simplicial());
        let mut x = vec![1.0, 0.0, 1.0, 0.0, 1.0, 0.0];
        llt.solve_columns_in_place(&mut x, 2);
        // A·[1,1,1] = [1,0,1]; A·[0.75,0.5,0.25]... check residuals directly.
        let ax = |x: &[f64]| [2.0 * x[0] - x[1], -x[0] + 2.0 * x[1] - x[2], -x[1] + 2.0 * x[2]];
        let r0 = ax(&x[0..3]);
        let r1 = ax(&x[3..6]);
        for (a, b) in r0.iter().chain(&r1).zip([1.0, 0.0, 1.0, 0.0, 1.0, 0.0]) {
            assert!((a - b).abs() < 1e-14);
        }
        let t = vec![Triplet::new(0, 0, 1.0), Triplet::new(1, 1, -1.0)];
        let b = SparseColMat::<usize, f64>::try_new_from_triplets(2, 2, &t).unwrap();
        assert!(matches!(SparseCholesky::factor(b.as_ref(), "indefinite"), Err(Error::Numerical(_))));
    }
}
