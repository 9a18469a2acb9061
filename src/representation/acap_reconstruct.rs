//! Vertex positions from per-vertex deformation gradients T_i (ACAP decoding, docs/design.md
//! § acap "Reconstruction").
//!
//! Solves
//!
//! ```text
//! min_p  Σ_{edges (i,j)} c_ij ‖(p_i − p_j) − ½(T_i + T_j)(q_i − q_j)‖²
//! ```
//!
//! with q the reference positions and c_ij > 0 edge weights of the reference mesh. (This is also
//! the minimiser of Σ_i Σ_{j∈N(i)} c_ij ‖(p_j − p_i) − T_i (q_j − q_i)‖², each vertex fitting
//! its own 1-ring, since both differ by a constant.) The normal equations are L p = b with
//! L = Σ c_ij (e_i − e_j)(e_i − e_j)ᵀ the weighted graph Laplacian and
//! b_i = Σ_j c_ij ½(T_i + T_j)(q_i − q_j), one right-hand side per coordinate.
//!
//! Translation: L is singular (constants per connected component). One vertex per component
//! (its smallest index) is pinned at the origin, the reduced SPD system is factorised once
//! (sparse Cholesky, faer, sequential), and after each solve every component is translated so
//! that its centroid equals that component's centroid in the reference mesh.

#![allow(clippy::needless_range_loop)] // index loops over 3-vectors read like the formulas
use crate::math::DisjointSet;
use crate::math::mat3::Mat3;
use crate::math::vec3::sub;
use crate::mesh::Vec3;
use crate::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{CholeskySymbolicParams, LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, MatMut, Par, Side};

/// Reduced systems with fewer unknowns use a simplicial Cholesky factor.
const SIMPLICIAL_BELOW: usize = 50_000;

/// A sparse symmetric positive semi-definite system on the vertices whose null space is the
/// translations of each connected component (a graph Laplacian or a Gram matrix of
/// difference operators). One vertex per component (its smallest index) is pinned at the origin,
/// the reduced SPD matrix is factorised once (sparse Cholesky, faer, `Par::Seq`), and every
/// solution is translated so that each component's centroid equals its reference centroid.
#[derive(Debug)]
pub(crate) struct PinnedSystem {
    /// Row of each vertex in the reduced system (`usize::MAX` for pinned vertices).
    reduced: Vec<usize>,
    /// Component label per vertex.
    component: Vec<usize>,
    /// Reference centroid and vertex count per component.
    centroids: Vec<(Vec3, usize)>,
    symbolic: Option<SymbolicCholesky<usize>>,
    values: Vec<f64>,
}

impl PinnedSystem {
    /// Components from `edges`; `entries` are the matrix entries `(i, j, value)` in full vertex
    /// indices, both triangles (duplicates are summed; only the upper triangle of the reduced
    /// matrix is used). `what` names the system in error messages.
    pub(crate) fn new(
        rest: &[Vec3],
        edges: &[[usize; 2]],
        entries: impl Iterator<Item = (usize, usize, f64)>,
        what: &str,
    ) -> Result<Self> {
        let n = rest.len();
        // Components by union–find; the smallest vertex of each is pinned.
        // (DisjointSet keeps the smallest element of every set as its root.)
        let mut uf = DisjointSet::new(n);
        for &[i, j] in edges {
            uf.union(i, j);
        }
        let mut component = vec![usize::MAX; n];
        let mut comp_of_root = vec![usize::MAX; n];
        let mut centroids: Vec<(Vec3, usize)> = Vec::new();
        let mut reduced = vec![usize::MAX; n];
        let mut n_free = 0;
        for v in 0..n {
            let r = uf.find(v);
            if comp_of_root[r] == usize::MAX {
                comp_of_root[r] = centroids.len();
                centroids.push(([0.0; 3], 0));
            }
            let c = comp_of_root[r];
            component[v] = c;
            for k in 0..3 {
                centroids[c].0[k] += rest[v][k];
            }
            centroids[c].1 += 1;
            if r != v {
                reduced[v] = n_free;
                n_free += 1;
            }
        }
        for (sum, cnt) in centroids.iter_mut() {
            for s in sum.iter_mut() {
                *s /= *cnt as f64;
            }
        }
        let mut this = PinnedSystem { reduced, component, centroids, symbolic: None, values: Vec::new() };
        if n_free == 0 {
            return Ok(this);
        }
        let trip: Vec<Triplet<usize, usize, f64>> = entries
            .filter_map(|(i, j, v)| {
                let (ri, rj) = (this.reduced[i], this.reduced[j]);
                (ri != usize::MAX && rj != usize::MAX && ri <= rj).then(|| Triplet::new(ri, rj, v))
            })
            .collect();
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n_free, n_free, &trip)
            .map_err(|e| Error::Numerical(format!("{what} matrix: {e:?}")))?;
        // Simplicial factors solve faster than supernodal ones at these sizes (horse, 8431
        // vertices, 2-ring fit-inverse matrix: 2.6 ms against 3.9 ms CPU time per decode);
        // larger systems keep faer's automatic choice.
        let mut params: CholeskySymbolicParams = Default::default();
        if n_free < SIMPLICIAL_BELOW {
            params.supernodal_flop_ratio_threshold = SupernodalThreshold::FORCE_SIMPLICIAL;
        }
        let symbolic = factorize_symbolic_cholesky(a.symbolic(), Side::Upper, Default::default(), params)
            .map_err(|e| Error::Numerical(format!("{what}: symbolic factorisation: {e:?}")))?;
        let mut values = vec![0.0; symbolic.len_val()];
        let mut mem = MemBuffer::try_new(symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()))
            .map_err(|e| Error::Numerical(format!("{what}: workspace: {e:?}")))?;
        symbolic
            .factorize_numeric_llt::<f64>(
                &mut values,
                a.as_ref(),
                Side::Upper,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| Error::Numerical(format!("{what}: Cholesky factorisation failed: {e:?}")))?;
        this.symbolic = Some(symbolic);
        this.values = values;
        Ok(this)
    }

    /// Number of unknowns of the reduced system (rows of a right-hand-side column).
    pub(crate) fn n_reduced(&self) -> usize {
        self.symbolic.as_ref().map_or(0, |s| s.nrows())
    }

    /// Reduced row of vertex `v` (`usize::MAX` when pinned).
    #[inline]
    pub(crate) fn row(&self, v: usize) -> usize {
        self.reduced[v]
    }

    /// Adjoint of [`Self::solve_from`]: for a gradient `grad` (N × 3) with respect to the returned
    /// positions, the gradient with respect to the right-hand side (3 × [`Self::n_reduced`],
    /// column-major). The centring is a symmetric projection and the reduced matrix is
    /// symmetric, so this is one solve with the same factor.
    pub(crate) fn solve_adjoint(&self, grad: &[Vec3]) -> Result<Vec<f64>> {
        let n = self.reduced.len();
        let mut sums = vec![[0.0; 3]; self.centroids.len()];
        for v in 0..n {
            for k in 0..3 {
                sums[self.component[v]][k] += grad[v][k];
            }
        }
        let m = self.n_reduced();
        let mut rhs = vec![0.0; 3 * m];
        for v in 0..n {
            let r = self.reduced[v];
            if r == usize::MAX {
                continue;
            }
            let c = self.component[v];
            let cnt = self.centroids[c].1 as f64;
            for k in 0..3 {
                rhs[k * m + r] = grad[v][k] - sums[c][k] / cnt;
            }
        }
        if let Some(symbolic) = &self.symbolic {
            if rhs.iter().any(|v| !v.is_finite()) {
                return Err(Error::Numerical("reconstruction adjoint: non-finite gradient".into()));
            }
            solve_columns(symbolic, &self.values, &mut rhs[..3 * m], m, 3);
        }
        Ok(rhs)
    }

    /// Solves for the three right-hand sides `rhs_of` writes (column-major, 3 ×
    /// [`Self::n_reduced`], into zeros) and returns the N positions, each component centred on
    /// its reference centroid.
    pub(crate) fn solve_from(&self, rhs_of: impl FnOnce(&mut [f64]) -> Result<()>) -> Result<Vec<Vec3>> {
        let mut rhs = vec![0.0; 3 * self.n_reduced()];
        rhs_of(&mut rhs)?;
        let mut p = self.solve_linear_many(&mut rhs, 1)?.remove(0);
        // Move each component's centroid onto the reference's.
        let n = p.len();
        let mut sums = vec![[0.0; 3]; self.centroids.len()];
        for v in 0..n {
            for k in 0..3 {
                sums[self.component[v]][k] += p[v][k];
            }
        }
        for v in 0..n {
            let c = self.component[v];
            let (target, cnt) = self.centroids[c];
            for k in 0..3 {
                p[v][k] += target[k] - sums[c][k] / cnt as f64;
            }
        }
        Ok(p)
    }

    /// [`Self::solve_linear_many`] of one right-hand side per set of transforms, as `rhs_of`
    /// writes it (into zeros).
    pub(crate) fn solve_linear_sets(
        &self,
        sets: &[Vec<Mat3>],
        rhs_of: impl Fn(&[Mat3], &mut [f64]) -> Result<()>,
    ) -> Result<Vec<Vec<Vec3>>> {
        let m = self.n_reduced();
        let mut rhs = vec![0.0; 3 * m * sets.len()];
        for (t, block) in sets.iter().zip(rhs.chunks_exact_mut(3 * m.max(1))) {
            rhs_of(t, block)?;
        }
        self.solve_linear_many(&mut rhs, sets.len())
    }

    /// Solves for `sets` × 3 right-hand sides given column-major in `rhs` (3·`sets` ×
    /// [`Self::n_reduced`], overwritten) in one solve and returns per set the N positions with
    /// the pinned vertices at the origin: the solution of [`Self::solve_from`] up to one
    /// translation per component (none is applied: for the linear part of an affine decoding,
    /// where the caller centres).
    pub(crate) fn solve_linear_many(&self, rhs: &mut [f64], sets: usize) -> Result<Vec<Vec<Vec3>>> {
        let n = self.reduced.len();
        let m = self.n_reduced();
        if rhs.len() != 3 * m * sets {
            return Err(Error::Invalid(format!("reconstruction: {} right-hand values for {sets} sets", rhs.len())));
        }
        if let Some(symbolic) = &self.symbolic {
            if rhs.iter().any(|v| !v.is_finite()) {
                return Err(Error::Numerical("reconstruction: non-finite right-hand side (bad features?)".into()));
            }
            solve_columns(symbolic, &self.values, rhs, m, 3 * sets);
        }
        Ok(rhs
            .chunks_exact(3 * m.max(1))
            .take(sets)
            .map(|b| {
                (0..n)
                    .map(|v| {
                        let r = self.reduced[v];
                        if r == usize::MAX || m == 0 { [0.0; 3] } else { [b[r], b[m + r], b[2 * m + r]] }
                    })
                    .collect()
            })
            .collect())
    }
}

/// Factorised reconstruction for one reference mesh: build once, [`AcapReconstruction::solve`]
/// for every frame.
#[derive(Debug)]
pub struct AcapReconstruction {
    rest: Vec<Vec3>,
    edges: Vec<[usize; 2]>,
    weights: Vec<f64>,
    system: PinnedSystem,
}

impl AcapReconstruction {
    /// Factorises the system for reference positions `rest` (N), undirected `edges` (i ≠ j,
    /// indices < N, each once) and their weights (`weights.len() == edges.len()`, all finite and
    /// > 0).
    pub fn new(rest: &[Vec3], edges: &[[usize; 2]], weights: &[f64]) -> Result<Self> {
        let n = rest.len();
        if weights.len() != edges.len() {
            return Err(Error::Invalid(format!("reconstruction: {} weights for {} edges", weights.len(), edges.len())));
        }
        for (e, (&[i, j], &c)) in edges.iter().zip(weights).enumerate() {
            if i >= n || j >= n || i == j {
                return Err(Error::Invalid(format!("reconstruction: bad edge {e} = [{i}, {j}] for {n} vertices")));
            }
            if !(c.is_finite() && c > 0.0) {
                return Err(Error::Invalid(format!("reconstruction: weight of edge [{i}, {j}] is {c}, must be > 0")));
            }
        }
        let entries =
            edges.iter().zip(weights).flat_map(|(&[i, j], &c)| [(i, i, c), (j, j, c), (i, j, -c), (j, i, -c)]);
        let system = PinnedSystem::new(rest, edges, entries, "edge reconstruction")?;
        Ok(AcapReconstruction { rest: rest.to_vec(), edges: edges.to_vec(), weights: weights.to_vec(), system })
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.rest.len()
    }

    /// Positions (N) from per-vertex deformation gradients `transforms` (N, row-major 3×3,
    /// applied to reference edge vectors), each component centred on its reference centroid.
    pub fn solve(&self, transforms: &[Mat3]) -> Result<Vec<Vec3>> {
        self.system.solve_from(|rhs| self.rhs(transforms, rhs))
    }

    /// The linear part of [`Self::solve`] for several sets of transforms at once (one solve with
    /// 3 right-hand sides per set), each up to a translation per component (see
    /// [`PinnedSystem::solve_linear_many`]).
    pub fn solve_linear_many(&self, sets: &[Vec<Mat3>]) -> Result<Vec<Vec<Vec3>>> {
        self.system.solve_linear_sets(sets, |t, rhs| self.rhs(t, rhs))
    }

    /// The right-hand side (3 × reduced rows, column-major, added to `rhs`) of `transforms`.
    fn rhs(&self, transforms: &[Mat3], rhs: &mut [f64]) -> Result<()> {
        let n = self.rest.len();
        if transforms.len() != n {
            return Err(Error::Invalid(format!("reconstruction: {} transforms for {n} vertices", transforms.len())));
        }
        let m = self.system.n_reduced();
        for (&[i, j], &c) in self.edges.iter().zip(&self.weights) {
            let (ti, tj) = (&transforms[i], &transforms[j]);
            let e = [
                self.rest[i][0] - self.rest[j][0],
                self.rest[i][1] - self.rest[j][1],
                self.rest[i][2] - self.rest[j][2],
            ];
            let (ri, rj) = (self.system.row(i), self.system.row(j));
            for k in 0..3 {
                let d = 0.5
                    * c
                    * ((ti[k][0] + tj[k][0]) * e[0] + (ti[k][1] + tj[k][1]) * e[1] + (ti[k][2] + tj[k][2]) * e[2]);
                if ri != usize::MAX {
                    rhs[k * m + ri] += d;
                }
                if rj != usize::MAX {
                    rhs[k * m + rj] -= d;
                }
            }
        }
        Ok(())
    }
}

impl AcapReconstruction {
    /// Adjoint of [`AcapReconstruction::solve`] (the map from transforms to positions is affine):
    /// for a gradient `grad` (N × 3) with respect to the positions, the gradient with respect to
    /// every transform (N, row-major 3×3).
    pub fn solve_adjoint(&self, grad: &[Vec3]) -> Result<Vec<Mat3>> {
        let n = self.rest.len();
        if grad.len() != n {
            return Err(Error::Invalid(format!("reconstruction adjoint: {} gradients for {n} vertices", grad.len())));
        }
        let lam = self.system.solve_adjoint(grad)?;
        let mut out = vec![[[0.0; 3]; 3]; n];
        edge_term_adjoint(&self.rest, &self.edges, &self.weights, &self.system, &lam, &mut out);
        Ok(out)
    }
}

/// Adds the adjoint of the edge right-hand side Σ c_ij ½(T_i + T_j)(q_i − q_j) (scattered to
/// rows i, −j) for the right-hand-side gradient `lam` (3 × reduced rows, column-major) to `out`.
pub(crate) fn edge_term_adjoint(
    rest: &[Vec3],
    edges: &[[usize; 2]],
    weights: &[f64],
    system: &PinnedSystem,
    lam: &[f64],
    out: &mut [Mat3],
) {
    let m = system.n_reduced();
    for (&[i, j], &c) in edges.iter().zip(weights) {
        let e = sub(rest[i], rest[j]);
        let (ri, rj) = (system.row(i), system.row(j));
        for k in 0..3 {
            let li = if ri != usize::MAX { lam[k * m + ri] } else { 0.0 };
            let lj = if rj != usize::MAX { lam[k * m + rj] } else { 0.0 };
            let d = 0.5 * c * (li - lj);
            for q in 0..3 {
                out[i][k][q] += d * e[q];
                out[j][k][q] += d * e[q];
            }
        }
    }
}

/// One-shot helper: factorise and solve once (see [`AcapReconstruction`]).
pub fn reconstruct(rest: &[Vec3], edges: &[[usize; 2]], weights: &[f64], transforms: &[Mat3]) -> Result<Vec<Vec3>> {
    AcapReconstruction::new(rest, edges, weights)?.solve(transforms)
}

/// Solves the factorised system for `cols` right-hand sides stored column-major in `rhs`
/// (`cols × m`, overwritten with the solution).
fn solve_columns(symbolic: &SymbolicCholesky<usize>, values: &[f64], rhs: &mut [f64], m: usize, cols: usize) {
    let llt = LltRef::new(symbolic, values);
    let mut mem = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(cols, Par::Seq));
    llt.solve_in_place_with_conj(
        Conj::No,
        MatMut::from_column_major_slice_mut(rhs, m, cols),
        Par::Seq,
        MemStack::new(&mut mem),
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::mat3::{IDENTITY, exp_so3};

    fn tetra() -> (Vec<Vec3>, Vec<[usize; 2]>) {
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let e = vec![[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];
        (p, e)
    }

    #[test]
    fn identity_returns_reference_and_rigid_motion_is_exact() {
        let (p, e) = tetra();
        let w = vec![1.0, 2.0, 0.5, 1.0, 1.0, 3.0];
        let rec = AcapReconstruction::new(&p, &e, &w).unwrap();
        let q = rec.solve(&vec![IDENTITY; 4]).unwrap();
        for (a, b) in p.iter().zip(&q) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-14);
            }
        }
        // A global rotation + scale: the exact result is R·s·(q − c) + c.
        let r = exp_so3([0.3, -1.1, 0.4]);
        let t: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| 1.5 * r[i][j]));
        let q = rec.solve(&vec![t; 4]).unwrap();
        let c = [0.25, 0.25, 0.25];
        for (a, b) in p.iter().zip(&q) {
            for i in 0..3 {
                let want = c[i] + (0..3).map(|j| t[i][j] * (a[j] - c[j])).sum::<f64>();
                assert!((b[i] - want).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn components_are_centred_separately_and_bad_input_rejected() {
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [5.0, 0.0, 0.0], [5.0, 2.0, 0.0], [9.0, 9.0, 9.0]];
        let e = vec![[0, 1], [2, 3]];
        let rec = AcapReconstruction::new(&p, &e, &[1.0, 1.0]).unwrap();
        let q = rec.solve(&vec![IDENTITY; 5]).unwrap();
        assert_eq!(q[4], [9.0, 9.0, 9.0]);
        for (a, b) in p.iter().zip(&q) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-14);
            }
        }
        assert!(AcapReconstruction::new(&p, &e, &[1.0, 0.0]).is_err());
        assert!(AcapReconstruction::new(&p, &[[0, 7]], &[1.0]).is_err());
        assert!(rec.solve(&[IDENTITY; 2]).is_err());
    }
}
