//! Cotangent Laplacian (the FEM stiffness matrix of piecewise-linear functions).
//!
//! # Sign convention
//! `L` is **symmetric positive semi-definite**:
//!
//! * `L_ij = −w_ij` for every mesh edge `{i, j}`,
//! * `L_ii = Σ_j w_ij` (so every row sums to zero),
//! * `w_ij = ½ (cot α_ij + cot β_ij)`, α and β the angles opposite edge `ij` in its two
//!   triangles; a boundary edge has one triangle and gets the one term `½ cot α_ij`; an edge of
//!   more than two triangles (non-manifold) sums one term per triangle.
//!
//! With this sign, `xᵀ L x = Σ_edges w_ij (x_i − x_j)² = ∫ |∇x|²` (the Dirichlet energy of the
//! piecewise-linear interpolant) and `L = −(the integrated Laplace–Beltrami operator)`.
//! The smooth Laplacian at vertex i is approximately `−(L x)_i / m_i` with `m` the lumped mass of
//! [`super::mass_matrix::lumped_mass`].
//! Weights are dimensionless (ratios of lengths), so `L` does not change when the mesh is scaled.
//! Weights can be negative (obtuse triangles) or exactly zero (e.g. an edge opposite two right
//! angles).
//!
//! # Degenerate triangles
//! A triangle counts as degenerate when twice its area is at most `1e-12 ×` (its longest edge)²,
//! i.e. when it is numerically a line or a point (see [`is_degenerate`]). A degenerate triangle
//! contributes **nothing** to any weight (it is skipped), so no NaN or infinity can appear. Its
//! edges still belong to the sparsity pattern (possibly with weight 0).
//!
//! # Sparsity pattern
//! The matrix has exactly one stored entry per vertex (the diagonal, also for vertices on no face)
//! and two per edge of [`Topology::edges`]: `nnz = N + 2E`, explicit zeros included. Row indices
//! are sorted within each column. [`SymmetricPattern`] reuses this pattern for any matrix of the
//! form "diagonal + one symmetric value per edge" (heat and Poisson systems).

use faer::sparse::{SparseColMat, SymbolicSparseColMat};

use crate::math::vec3::{cross, dot, norm, sub};
use crate::mesh::{Topology, Vec3};

/// Relative threshold of [`is_degenerate`]: `|(b − a) × (c − a)| ≤ DEGENERATE_RELATIVE_AREA · ℓ_max²`.
pub const DEGENERATE_RELATIVE_AREA: f64 = 1e-12;

/// `true` when triangle (a, b, c) is numerically degenerate: twice its area is at most
/// [`DEGENERATE_RELATIVE_AREA`] times its longest edge squared (scale invariant), or any
/// coordinate is not finite. Such triangles are skipped by the cotangent weights.
pub fn is_degenerate(a: Vec3, b: Vec3, c: Vec3) -> bool {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let bc = sub(c, b);
    let l2 = dot(ab, ab).max(dot(ac, ac)).max(dot(bc, bc));
    let twice_area = norm(cross(ab, ac));
    !(twice_area.is_finite() && l2.is_finite()) || twice_area <= DEGENERATE_RELATIVE_AREA * l2
}

/// Cotangent of the angle at `apex` of the triangle (apex, p, q): `(p−apex)·(q−apex) / |(p−apex)×(q−apex)|`.
/// Only meaningful for a non-degenerate triangle (see [`is_degenerate`]); dimensionless.
pub fn cotangent(apex: Vec3, p: Vec3, q: Vec3) -> f64 {
    let u = sub(p, apex);
    let v = sub(q, apex);
    dot(u, v) / norm(cross(u, v))
}

/// Per-face degeneracy flags ([`is_degenerate`]) for `faces`.
pub fn degenerate_faces(positions: &[Vec3], faces: &[[usize; 3]]) -> Vec<bool> {
    faces.iter().map(|f| is_degenerate(positions[f[0]], positions[f[1]], positions[f[2]])).collect()
}

/// Cotangent weight `w_ij = ½ Σ cot(angle opposite ij)` of every edge, in the order of
/// `topology.edges` (one entry per edge, dimensionless). Degenerate triangles contribute 0.
///
/// `topology` must be `Topology::new(positions.len(), faces)`; face indices must be valid.
pub fn cotan_weights(positions: &[Vec3], faces: &[[usize; 3]], topology: &Topology) -> Vec<f64> {
    let degenerate = degenerate_faces(positions, faces);
    topology
        .edges
        .iter()
        .zip(&topology.edge_faces)
        .map(|(e, inc)| edge_weight(positions, &degenerate, *e, inc))
        .collect()
}

fn edge_weight(positions: &[Vec3], degenerate: &[bool], e: [usize; 2], incident: &[(usize, usize)]) -> f64 {
    incident
        .iter()
        .filter(|(f, _)| !degenerate[*f])
        .map(|&(_, opp)| 0.5 * cotangent(positions[opp], positions[e[0]], positions[e[1]]))
        .sum()
}

/// The N×N cotangent Laplacian (positive semi-definite convention, see the module docs):
/// `L_ij = −w_ij`, `L_ii = Σ_j w_ij`, `nnz = N + 2E`. N = `positions.len()`.
///
/// Face indices must be `< N` (validate first). Builds its edge list by sorting (it does not
/// need the 1-rings of a full [`Topology`]); the edges and weights are those of
/// [`Topology::edges`] and [`cotan_weights`].
pub fn cotan_laplacian(positions: &[Vec3], faces: &[[usize; 3]]) -> SparseColMat<usize, f64> {
    let inc = EdgeIncidence::new(faces);
    let weights = inc.cotan_weights(positions, &degenerate_faces(positions, faces));
    let mut diag = vec![0.0; positions.len()];
    for (e, &w) in inc.edges.iter().zip(&weights) {
        diag[e[0]] += w;
        diag[e[1]] += w;
    }
    let off: Vec<f64> = weights.iter().map(|w| -w).collect();
    SymmetricPattern::from_edges(positions.len(), &inc.edges).assemble(&diag, &off)
}

/// Unique undirected edges of a face list with their incident (face, opposite vertex) pairs,
/// built by sorting (no hashing). Same edges, order and incidence as [`Topology`].
#[derive(Debug, Clone)]
pub struct EdgeIncidence {
    /// Unique edges `[i, j]`, `i < j`, sorted lexicographically.
    pub edges: Vec<[usize; 2]>,
    /// CSR offsets: the incident faces of edge e are `incident[offsets[e]..offsets[e + 1]]`.
    pub offsets: Vec<usize>,
    /// `(face, opposite vertex)` pairs, grouped per edge, faces ascending.
    pub incident: Vec<(usize, usize)>,
}

impl EdgeIncidence {
    /// Edges of `faces`; a face side whose two ends are equal is ignored (as in [`Topology`]).
    pub fn new(faces: &[[usize; 3]]) -> Self {
        let mut sides: Vec<(usize, usize, usize, usize)> = Vec::with_capacity(faces.len() * 3);
        for (fi, f) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b, c) = (f[k], f[(k + 1) % 3], f[(k + 2) % 3]);
                if a != b {
                    sides.push((a.min(b), a.max(b), fi, c));
                }
            }
        }
        sides.sort_unstable();
        let mut edges = Vec::with_capacity(sides.len() / 2 + 1);
        let mut offsets = Vec::with_capacity(sides.len() / 2 + 2);
        let mut incident = Vec::with_capacity(sides.len());
        for (k, &(i, j, f, c)) in sides.iter().enumerate() {
            if k == 0 || (sides[k - 1].0, sides[k - 1].1) != (i, j) {
                edges.push([i, j]);
                offsets.push(incident.len());
            }
            incident.push((f, c));
        }
        offsets.push(incident.len());
        EdgeIncidence { edges, offsets, incident }
    }

    /// Incident `(face, opposite vertex)` pairs of edge `e`.
    pub fn faces_of(&self, e: usize) -> &[(usize, usize)] {
        &self.incident[self.offsets[e]..self.offsets[e + 1]]
    }

    /// `true` for every vertex (of `n`) on an edge with exactly one incident face.
    pub fn boundary_vertices(&self, n: usize) -> Vec<bool> {
        let mut b = vec![false; n];
        for (e, edge) in self.edges.iter().enumerate() {
            if self.offsets[e + 1] - self.offsets[e] == 1 {
                b[edge[0]] = true;
                b[edge[1]] = true;
            }
        }
        b
    }

    /// Cotangent weight of every edge (as [`cotan_weights`]), skipping faces flagged in
    /// `degenerate` (one flag per face).
    pub fn cotan_weights(&self, positions: &[Vec3], degenerate: &[bool]) -> Vec<f64> {
        (0..self.edges.len()).map(|e| edge_weight(positions, degenerate, self.edges[e], self.faces_of(e))).collect()
    }
}

/// Assembles `L_ij = −w_ij`, `L_ii = Σ_j w_ij` for arbitrary symmetric edge weights `weights`
/// (one per edge of `topology.edges`), with the pattern of [`SymmetricPattern`].
///
/// # Panics
/// If `weights.len() != topology.edges.len()`.
pub fn laplacian_from_weights(topology: &Topology, weights: &[f64]) -> SparseColMat<usize, f64> {
    assert_eq!(weights.len(), topology.edges.len(), "one weight per edge");
    let mut diag = vec![0.0; topology.n_vertices];
    for (e, &w) in topology.edges.iter().zip(weights) {
        diag[e[0]] += w;
        diag[e[1]] += w;
    }
    let off: Vec<f64> = weights.iter().map(|w| -w).collect();
    SymmetricPattern::from_edges(topology.n_vertices, &topology.edges).assemble(&diag, &off)
}

/// Sparsity pattern "diagonal + both entries of every edge" of an N×N symmetric matrix in
/// compressed-column form (sorted row indices), with the value slot of each diagonal entry and
/// of both entries of each edge, so that several matrices with this pattern (Laplacian, heat
/// system, pinned Poisson system) can be filled without re-sorting.
#[derive(Debug, Clone)]
pub struct SymmetricPattern {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Slot of entry (i, i).
    diag_slot: Vec<usize>,
    /// Slots of entries (i, j) and (j, i) for edge `[i, j]`.
    edge_slots: Vec<[usize; 2]>,
}

impl SymmetricPattern {
    /// Pattern of `topology` (N = `topology.n_vertices`, E = `topology.edges.len()`).
    pub fn new(topology: &Topology) -> Self {
        Self::from_edges(topology.n_vertices, &topology.edges)
    }

    /// Pattern of N vertices and the given edges, which must be unique, `[i, j]` with
    /// `i < j < n`, sorted lexicographically (as [`Topology::edges`] and [`EdgeIncidence::edges`]).
    ///
    /// # Panics
    /// If an edge is out of range or the edges are not strictly increasing.
    pub fn from_edges(n: usize, edges: &[[usize; 2]]) -> Self {
        assert!(edges.windows(2).all(|w| w[0] < w[1]), "edges must be unique and sorted");
        assert!(edges.iter().all(|e| e[0] < e[1] && e[1] < n), "edges must be [i, j] with i < j < n");
        let mut count = vec![1usize; n]; // the diagonal
        for e in edges {
            count[e[0]] += 1;
            count[e[1]] += 1;
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        col_ptr.push(0);
        for c in &count {
            col_ptr.push(col_ptr.last().unwrap() + c);
        }
        let nnz = col_ptr[n];
        // Column c holds, in this order: rows i < c of edges [i, c] (ascending, since the edges
        // are sorted by i first), the diagonal, rows j > c of edges [c, j] (ascending). So the
        // three passes below leave every column sorted.
        let mut row_idx = vec![0usize; nnz];
        let mut cursor: Vec<usize> = col_ptr[..n].to_vec();
        let mut edge_slots = vec![[0usize; 2]; edges.len()];
        for (k, e) in edges.iter().enumerate() {
            let s = cursor[e[1]];
            row_idx[s] = e[0];
            edge_slots[k][0] = s; // entry (i, j): row i, column j
            cursor[e[1]] += 1;
        }
        let mut diag_slot = vec![0usize; n];
        for (c, d) in diag_slot.iter_mut().enumerate() {
            row_idx[cursor[c]] = c;
            *d = cursor[c];
            cursor[c] += 1;
        }
        for (k, e) in edges.iter().enumerate() {
            let s = cursor[e[0]];
            row_idx[s] = e[1];
            edge_slots[k][1] = s; // entry (j, i): row j, column i
            cursor[e[0]] += 1;
        }
        SymmetricPattern { n, col_ptr, row_idx, diag_slot, edge_slots }
    }

    /// Number of rows (and columns) N.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of stored entries, N + 2E.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// The matrix with `diag[i]` at (i, i) and `off[e]` at both (i, j) and (j, i) of edge e.
    ///
    /// # Panics
    /// If `diag.len() != N` or `off.len() != E`.
    pub fn assemble(&self, diag: &[f64], off: &[f64]) -> SparseColMat<usize, f64> {
        assert_eq!(diag.len(), self.n);
        assert_eq!(off.len(), self.edge_slots.len());
        let mut values = vec![0.0; self.row_idx.len()];
        for (i, &d) in diag.iter().enumerate() {
            values[self.diag_slot[i]] = d;
        }
        for (s, &v) in self.edge_slots.iter().zip(off) {
            values[s[0]] = v;
            values[s[1]] = v;
        }
        let symbolic =
            SymbolicSparseColMat::new_checked(self.n, self.n, self.col_ptr.clone(), None, self.row_idx.clone());
        SparseColMat::new(symbolic, values)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use crate::mesh::primitives::{cylinder, grid, icosphere};

    /// A grid with every interior vertex jittered in-plane and lifted (deterministic), so the
    /// triangles are irregular and some are obtuse.
    pub(crate) fn perturbed_grid(n: usize) -> TriMesh {
        let mut m = grid(n, n, 1.0);
        let h = 1.0 / n as f64;
        let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut rnd = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        for p in &mut m.positions {
            let interior = p[0] > 1e-9 && p[0] < 1.0 - 1e-9 && p[1] > 1e-9 && p[1] < 1.0 - 1e-9;
            let (dx, dy, dz) = (rnd(), rnd(), rnd());
            if interior {
                p[0] += 0.6 * h * dx;
                p[1] += 0.6 * h * dy;
            }
            p[2] += 0.5 * h * dz;
        }
        m
    }

    fn meshes() -> Vec<(&'static str, TriMesh)> {
        vec![
            ("icosphere(3)", icosphere(3)),
            ("grid(9,7)", grid(9, 7, 2.0)),
            ("perturbed grid", perturbed_grid(12)),
            ("cylinder", cylinder(16, 6, 0.3, 1.0)),
        ]
    }

    fn dense(l: &SparseColMat<usize, f64>) -> Vec<Vec<f64>> {
        let n = l.nrows();
        let mut d = vec![vec![0.0; n]; n];
        for t in l.triplet_iter() {
            d[t.row][t.col] += *t.val;
        }
        d
    }

    #[test]
    fn invariants_symmetric_zero_rows_nnz_psd() {
        for (name, m) in meshes() {
            let n = m.n_vertices();
            let topo = Topology::new(n, &m.faces);
            let l = cotan_laplacian(&m.positions, &m.faces);
            assert_eq!(l.compute_nnz(), n + 2 * topo.edges.len(), "{name}: nnz");
            let d = dense(&l);
            for (i, row) in d.iter().enumerate() {
                let scale = row[i].abs().max(1e-300);
                assert!(row[i] > 0.0, "{name}: diagonal {i} = {}", row[i]);
                let sum: f64 = row.iter().sum();
                assert!(sum.abs() <= 1e-12 * scale, "{name}: row {i} sums to {sum}");
                for (j, x) in row.iter().enumerate() {
                    assert!(x.is_finite());
                    assert!((x - d[j][i]).abs() <= 1e-15 * scale, "{name}: asymmetric at ({i},{j})");
                }
            }
            // Dirichlet energy of a linear function = its gradient² × area (flat grid only),
            // and xᵀLx ≥ 0 for a non-constant vector everywhere.
            let x: Vec<f64> = m.positions.iter().map(|p| p[0] + 0.3 * p[1]).collect();
            let energy: f64 = (0..n).map(|i| x[i] * (0..n).map(|j| d[i][j] * x[j]).sum::<f64>()).sum();
            assert!(energy > 0.0, "{name}: energy {energy}");
            if name.starts_with("grid") {
                // Area 2×2 = 4, |∇x|² = 1 + 0.09.
                assert!((energy - 4.0 * 1.09).abs() < 1e-10, "{name}: energy {energy}");
            }
        }
    }

    #[test]
    fn edge_incidence_and_laplacian_agree_with_topology() {
        for (name, m) in meshes() {
            let topo = Topology::new(m.n_vertices(), &m.faces);
            let inc = EdgeIncidence::new(&m.faces);
            assert_eq!(inc.edges, topo.edges, "{name}");
            for e in 0..inc.edges.len() {
                let mut a = inc.faces_of(e).to_vec();
                let mut b = topo.edge_faces[e].clone();
                a.sort_unstable();
                b.sort_unstable();
                assert_eq!(a, b, "{name}: edge {e}");
            }
            assert_eq!(inc.boundary_vertices(m.n_vertices()), topo.is_boundary_vertex, "{name}");
            let w = cotan_weights(&m.positions, &m.faces, &topo);
            let a = laplacian_from_weights(&topo, &w);
            let b = cotan_laplacian(&m.positions, &m.faces);
            assert_eq!(a.symbolic().col_ptr(), b.symbolic().col_ptr());
            assert_eq!(a.symbolic().row_idx(), b.symbolic().row_idx());
            assert_eq!(a.val(), b.val(), "{name}");
            // Every column's rows are strictly increasing (faer's sorted-CSC invariant).
            let (cp, ri) = (b.symbolic().col_ptr(), b.symbolic().row_idx());
            for c in 0..m.n_vertices() {
                assert!(ri[cp[c]..cp[c + 1]].windows(2).all(|w| w[0] < w[1]));
            }
        }
    }

    #[test]
    fn laplacian_is_scale_invariant() {
        for (name, m) in meshes() {
            let l = cotan_laplacian(&m.positions, &m.faces);
            for s in [1e-6, 1e6] {
                let p: Vec<Vec3> = m.positions.iter().map(|p| [p[0] * s, p[1] * s, p[2] * s]).collect();
                let ls = cotan_laplacian(&p, &m.faces);
                assert_eq!(ls.symbolic().row_idx(), l.symbolic().row_idx());
                for (a, b) in l.val().iter().zip(ls.val()) {
                    assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{name} scaled by {s}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn weights_match_known_values() {
        // Right isosceles triangle pair (unit square split along 0–2): the diagonal is opposite
        // two right angles (weight 0), the legs are opposite 45° (weight ½ each, one triangle).
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let f = vec![[0, 1, 2], [0, 2, 3]];
        let t = Topology::new(4, &f);
        let w = cotan_weights(&p, &f, &t);
        for (e, w) in t.edges.iter().zip(&w) {
            let expect = if *e == [0, 2] { 0.0 } else { 0.5 };
            assert!((w - expect).abs() < 1e-15, "edge {e:?}: {w}");
        }
        // Equilateral triangle: cot 60° / 2 on each edge.
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 3f64.sqrt() / 2.0, 0.0]];
        let f = vec![[0, 1, 2]];
        let w = cotan_weights(&p, &f, &Topology::new(3, &f));
        for w in w {
            assert!((w - 0.5 / 3f64.sqrt()).abs() < 1e-15);
        }
    }

    #[test]
    fn degenerate_triangles_are_skipped_without_nan() {
        // A square with a zero-area sliver glued on (vertex 4 on the edge 1–2) and a collapsed
        // face (two equal positions).
        let p =
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.5, 0.0], [0.0, 1.0, 0.0]];
        let f = vec![[0, 1, 2], [0, 2, 3], [1, 4, 2], [2, 5, 3]];
        let deg = degenerate_faces(&p, &f);
        assert_eq!(deg, vec![false, false, true, true]);
        let l = cotan_laplacian(&p, &f);
        assert!(l.val().iter().all(|v| v.is_finite()));
        let t = Topology::new(6, &f);
        assert_eq!(l.compute_nnz(), 6 + 2 * t.edges.len());
        // Vertex 4 only touches the sliver: its row is all zeros.
        let d = dense(&l);
        assert!(d[4].iter().all(|&v| v == 0.0));
    }
}
