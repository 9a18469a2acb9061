//! Intrinsic Delaunay triangulation by edge flips (Fisher, Springborn, Bobenko & Schröder 2007;
//! Bobenko & Springborn 2007) and the operators built on it.
//!
//! A triangle mesh is described intrinsically by its connectivity and its edge lengths. An
//! interior edge is *Delaunay* when the two angles opposite it sum to at most π, i.e. when its
//! cotangent weight `½(cot α + cot β)` is ≥ 0. Flipping every non-Delaunay edge (the new edge's
//! length is measured in the unfolded pair of triangles, so the surface's metric is unchanged)
//! terminates in the intrinsic Delaunay triangulation, whose cotangent Laplacian has only
//! non-negative edge weights: it is an M-matrix and satisfies a maximum principle. The vertices
//! and the surface are the same as the input's; only the triangulation on top of it changes.
//!
//! Why it matters here: with negative weights (obtuse triangles, common in scanned and animated
//! meshes such as the horse gallop) the heat method's solution oscillates and is drowned in
//! cancellation far from the source, so distances there are wrong by many edge lengths; on the
//! intrinsic Delaunay triangulation the heat solution is positive and its triangular solves have
//! no cancellation. See [`super::heat_geodesics`].
//!
//! # Conventions
//! * `faces` are the current intrinsic triangles (vertex indices of the input; after flips two
//!   corners may even be the same vertex in unusual meshes); `side_lengths[f][k]` is the length
//!   of side k, from corner k to corner k+1 (length units).
//! * Only edges with exactly two incident, consistently oriented, non-degenerate faces are
//!   flipped; boundary edges, non-manifold edges and edges of degenerate faces stay as they are.
//!   A flip is also skipped when its two triangles share a second edge (an edge at a vertex of
//!   degree 2, where the flip would create an edge from a vertex to itself), so such rare edges
//!   may stay non-Delaunay: on frame 1 of `face-poses` (29k vertices, 19 320 flips) 3 interior
//!   edges remain; on the horse gallop (6016 flips) and SCAPE (1124 flips) none.
//! * Degenerate faces (twice the area ≤ 1e-12 × longest side², from the side lengths) are skipped
//!   by the operators, like in [`super::cotan_laplacian`].
//! * The Laplacian uses the positive semi-definite sign convention of [`super::cotan_laplacian`];
//!   its pattern has one entry per distinct vertex pair joined by an intrinsic edge (edges joining
//!   the same pair are merged, an edge from a vertex to itself contributes nothing).

use faer::sparse::SparseColMat;

use crate::geometry::cotan_laplacian::{DEGENERATE_RELATIVE_AREA, SymmetricPattern};
use crate::mesh::Vec3;

const NONE: usize = usize::MAX;

/// An edge is flipped when its cotangent weight sum `cot α + cot β` is below `−DELAUNAY_TOLERANCE`
/// (so co-circular configurations such as the diagonals of a square grid are left alone).
pub const DELAUNAY_TOLERANCE: f64 = 1e-9;

/// An intrinsic triangulation (connectivity + edge lengths) of a triangle mesh.
#[derive(Debug, Clone)]
pub struct IntrinsicTriangulation {
    n_vertices: usize,
    faces: Vec<[usize; 3]>,
    side_lengths: Vec<[f64; 3]>,
    /// Per half-edge `3f + k` (side k of face f): the opposite half-edge, or `NONE` when the edge
    /// may not be flipped.
    twin: Vec<usize>,
    degenerate: Vec<bool>,
    flips: usize,
}

impl IntrinsicTriangulation {
    /// The triangulation of the input mesh (edge lengths from `positions`, no flips yet).
    ///
    /// # Panics
    /// If a face index is ≥ `positions.len()` (validate first).
    pub fn new(positions: &[Vec3], faces: &[[usize; 3]]) -> Self {
        let side_lengths: Vec<[f64; 3]> = faces
            .iter()
            .map(|f| {
                let d = |a: usize, b: usize| crate::mesh::dist(positions[a], positions[b]);
                [d(f[0], f[1]), d(f[1], f[2]), d(f[2], f[0])]
            })
            .collect();
        let degenerate: Vec<bool> = side_lengths.iter().map(|l| is_degenerate_lengths(*l)).collect();
        // Twins by sorting the half-edges on their unordered vertex pair.
        let mut keys: Vec<(usize, usize, usize)> = Vec::with_capacity(faces.len() * 3);
        for (fi, f) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                keys.push((a.min(b), a.max(b), 3 * fi + k));
            }
        }
        keys.sort_unstable();
        let mut twin = vec![NONE; faces.len() * 3];
        let mut s = 0;
        while s < keys.len() {
            let mut e = s + 1;
            while e < keys.len() && (keys[e].0, keys[e].1) == (keys[s].0, keys[s].1) {
                e += 1;
            }
            if e - s == 2 {
                let (h1, h2) = (keys[s].2, keys[s + 1].2);
                let (f1, f2) = (h1 / 3, h2 / 3);
                let from = |h: usize| faces[h / 3][h % 3];
                let opposite_orientation = from(h1) != from(h2);
                if f1 != f2 && opposite_orientation && keys[s].0 != keys[s].1 && !degenerate[f1] && !degenerate[f2] {
                    twin[h1] = h2;
                    twin[h2] = h1;
                }
            }
            s = e;
        }
        IntrinsicTriangulation {
            n_vertices: positions.len(),
            faces: faces.to_vec(),
            side_lengths,
            twin,
            degenerate,
            flips: 0,
        }
    }

    /// The intrinsic Delaunay triangulation of the mesh: [`IntrinsicTriangulation::new`] followed by
    /// [`IntrinsicTriangulation::flip_to_delaunay`].
    pub fn delaunay(positions: &[Vec3], faces: &[[usize; 3]]) -> Self {
        let mut t = Self::new(positions, faces);
        t.flip_to_delaunay();
        t
    }

    /// Flips non-Delaunay edges until none is left (or a safety cap of 50 flips per half-edge is
    /// reached, which does not happen in exact arithmetic: the flip algorithm terminates).
    /// Returns the number of flips done by this call.
    pub fn flip_to_delaunay(&mut self) -> usize {
        let cap = 50 * self.twin.len() + 100;
        let mut done = 0;
        let mut stack: Vec<usize> =
            (0..self.twin.len()).filter(|&h| self.twin[h] != NONE && h < self.twin[h]).collect();
        while let Some(h) = stack.pop() {
            if done >= cap {
                break;
            }
            if self.twin[h] == NONE || self.edge_cot_sum(h) >= -DELAUNAY_TOLERANCE {
                continue;
            }
            if let Some(outer) = self.flip(h) {
                done += 1;
                stack.extend_from_slice(&outer);
            }
        }
        self.flips += done;
        done
    }

    /// `true` when every flippable edge satisfies the Delaunay condition (within the tolerance);
    /// can be `false` after [`IntrinsicTriangulation::flip_to_delaunay`] only because of skipped
    /// flips (see the module docs).
    pub fn is_delaunay(&self) -> bool {
        (0..self.twin.len()).all(|h| self.twin[h] == NONE || self.edge_cot_sum(h) >= -DELAUNAY_TOLERANCE)
    }

    /// Total number of flips done so far.
    pub fn n_flips(&self) -> usize {
        self.flips
    }

    /// Number of vertices N (unchanged by flips).
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }

    /// Current intrinsic triangles (same count as the input's).
    pub fn faces(&self) -> &[[usize; 3]] {
        &self.faces
    }

    /// Side lengths per face: side k goes from corner k to corner k+1.
    pub fn side_lengths(&self) -> &[[f64; 3]] {
        &self.side_lengths
    }

    /// `true` when face `f` is degenerate (skipped by the operators).
    pub fn is_degenerate(&self, f: usize) -> bool {
        self.degenerate[f]
    }

    /// Area of face `f` from its side lengths (Heron's formula in its stable form).
    pub fn face_area(&self, f: usize) -> f64 {
        area_from_lengths(self.side_lengths[f])
    }

    /// Cotangents of the three corner angles of face `f` (corner c is opposite side c+1).
    /// Meaningless for a degenerate face.
    pub fn corner_cotangents(&self, f: usize) -> [f64; 3] {
        let l = self.side_lengths[f];
        let a4 = 4.0 * area_from_lengths(l);
        let sq = [l[0] * l[0], l[1] * l[1], l[2] * l[2]];
        // Corner c lies between sides c (to c+1) and c+2 (from c+2); the opposite side is c+1.
        [(sq[0] + sq[2] - sq[1]) / a4, (sq[1] + sq[0] - sq[2]) / a4, (sq[2] + sq[1] - sq[0]) / a4]
    }

    /// Cotangent weights merged per vertex pair: `(pairs, weights)` with `pairs` sorted, unique,
    /// `[i, j]`, `i < j`, and `weights[e] = ½ Σ cot(angle opposite an intrinsic edge joining the
    /// pair)`. Degenerate faces and self-edges are skipped.
    pub fn edge_weights(&self) -> (Vec<[usize; 2]>, Vec<f64>) {
        let mut entries: Vec<(usize, usize, f64)> = Vec::with_capacity(self.faces.len() * 3);
        for (fi, f) in self.faces.iter().enumerate() {
            let cot = if self.degenerate[fi] { [0.0; 3] } else { self.corner_cotangents(fi) };
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                if a != b {
                    entries.push((a.min(b), a.max(b), 0.5 * cot[(k + 2) % 3]));
                }
            }
        }
        entries.sort_unstable_by_key(|e| (e.0, e.1));
        let mut pairs: Vec<[usize; 2]> = Vec::with_capacity(entries.len() / 2 + 1);
        let mut weights: Vec<f64> = Vec::with_capacity(entries.len() / 2 + 1);
        for (a, b, w) in entries {
            if pairs.last() == Some(&[a, b]) {
                *weights.last_mut().unwrap() += w;
            } else {
                pairs.push([a, b]);
                weights.push(w);
            }
        }
        (pairs, weights)
    }

    /// N×N cotangent Laplacian of the current triangulation (PSD convention: `L_ij = −w_ij`,
    /// `L_ii = Σ w_ij`). After [`IntrinsicTriangulation::flip_to_delaunay`] every off-diagonal
    /// entry is ≤ 0 (up to the tolerance) on edges away from degenerate faces.
    pub fn cotan_laplacian(&self) -> SparseColMat<usize, f64> {
        let (pairs, weights) = self.edge_weights();
        let mut diag = vec![0.0; self.n_vertices];
        for (e, &w) in pairs.iter().zip(&weights) {
            diag[e[0]] += w;
            diag[e[1]] += w;
        }
        let off: Vec<f64> = weights.iter().map(|w| -w).collect();
        SymmetricPattern::from_edges(self.n_vertices, &pairs).assemble(&diag, &off)
    }

    /// Barycentric lumped mass of the current triangulation (a third of each intrinsic face's
    /// area per corner, length²). The total equals the input's surface area.
    pub fn lumped_mass(&self) -> Vec<f64> {
        let mut m = vec![0.0; self.n_vertices];
        for (fi, f) in self.faces.iter().enumerate() {
            let a = self.face_area(fi) / 3.0;
            for &v in f {
                m[v] += a;
            }
        }
        m
    }

    /// `cot α + cot β` of the edge of half-edge `h` (which must have a twin).
    fn edge_cot_sum(&self, h: usize) -> f64 {
        let t = self.twin[h];
        let ca = self.corner_cotangents(h / 3)[(h % 3 + 2) % 3];
        let cb = self.corner_cotangents(t / 3)[(t % 3 + 2) % 3];
        ca + cb
    }

    /// Flips the edge of half-edge `h`; returns the four outer half-edges to re-check, or `None`
    /// when the configuration cannot be flipped (an outer edge glued back onto the pair).
    fn flip(&mut self, h: usize) -> Option<[usize; 4]> {
        let t = self.twin[h];
        let (fa, a) = (h / 3, h % 3);
        let (fb, b) = (t / 3, t % 3);
        let (i, j, k) = (self.faces[fa][a], self.faces[fa][(a + 1) % 3], self.faces[fa][(a + 2) % 3]);
        let l = self.faces[fb][(b + 2) % 3];
        let la = self.side_lengths[fa];
        let lb = self.side_lengths[fb];
        let (l_ij, l_jk, l_ki) = (la[a], la[(a + 1) % 3], la[(a + 2) % 3]);
        let (l_il, l_lj) = (lb[(b + 1) % 3], lb[(b + 2) % 3]);
        let t_jk = self.twin[3 * fa + (a + 1) % 3];
        let t_ki = self.twin[3 * fa + (a + 2) % 3];
        let t_il = self.twin[3 * fb + (b + 1) % 3];
        let t_lj = self.twin[3 * fb + (b + 2) % 3];
        let inside = |x: usize| x != NONE && (x / 3 == fa || x / 3 == fb);
        if inside(t_jk) || inside(t_ki) || inside(t_il) || inside(t_lj) {
            return None;
        }
        // Unfold: i = (0, 0), j = (l_ij, 0), k above, l below.
        let area_a = area_from_lengths(la);
        let area_b = area_from_lengths(lb);
        let xk = (l_ij * l_ij + l_ki * l_ki - l_jk * l_jk) / (2.0 * l_ij);
        let yk = 2.0 * area_a / l_ij;
        let xl = (l_ij * l_ij + l_il * l_il - l_lj * l_lj) / (2.0 * l_ij);
        let yl = -2.0 * area_b / l_ij;
        let l_kl = ((xk - xl).powi(2) + (yk - yl).powi(2)).sqrt();
        if !(l_kl > 0.0 && l_kl.is_finite()) {
            return None;
        }
        // New faces: A = (k, i, l), B = (l, j, k); the new edge is side 2 of both.
        self.faces[fa] = [k, i, l];
        self.side_lengths[fa] = [l_ki, l_il, l_kl];
        self.faces[fb] = [l, j, k];
        self.side_lengths[fb] = [l_lj, l_jk, l_kl];
        let links = [(3 * fa, t_ki), (3 * fa + 1, t_il), (3 * fb, t_lj), (3 * fb + 1, t_jk)];
        for (he, tw) in links {
            self.twin[he] = tw;
            if tw != NONE {
                self.twin[tw] = he;
            }
        }
        self.twin[3 * fa + 2] = 3 * fb + 2;
        self.twin[3 * fb + 2] = 3 * fa + 2;
        Some([3 * fa, 3 * fa + 1, 3 * fb, 3 * fb + 1])
    }
}

/// Area of a triangle with side lengths `l` (stable Heron formula; 0 when the lengths violate the
/// triangle inequality by round-off).
pub fn area_from_lengths(l: [f64; 3]) -> f64 {
    let mut s = l;
    s.sort_unstable_by(|x, y| y.total_cmp(x)); // a ≥ b ≥ c
    let (a, b, c) = (s[0], s[1], s[2]);
    let p = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c));
    if p > 0.0 { 0.25 * p.sqrt() } else { 0.0 }
}

/// Degeneracy test from side lengths: twice the area ≤ [`DEGENERATE_RELATIVE_AREA`] × longest
/// side², or a length that is not finite.
pub fn is_degenerate_lengths(l: [f64; 3]) -> bool {
    let lmax = l[0].max(l[1]).max(l[2]);
    !(l.iter().all(|x| x.is_finite())) || 2.0 * area_from_lengths(l) <= DEGENERATE_RELATIVE_AREA * lmax * lmax
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::cotan_laplacian::cotan_laplacian;
    use crate::mesh::primitives::{grid, icosphere};

    /// An ellipsoid (icosphere stretched 4× along x): closed, with many obtuse triangles.
    fn ellipsoid() -> (Vec<Vec3>, Vec<[usize; 3]>) {
        let m = icosphere(3);
        (m.positions.iter().map(|p| [4.0 * p[0], p[1], p[2]]).collect(), m.faces)
    }

    /// A planar grid squashed and sheared so that one diagonal of each cell is non-Delaunay.
    fn sheared_grid() -> (Vec<Vec3>, Vec<[usize; 3]>) {
        let m = grid(10, 10, 1.0);
        (m.positions.iter().map(|p| [p[0] + 1.5 * p[1], 0.3 * p[1], 0.0]).collect(), m.faces)
    }

    #[test]
    fn delaunay_meshes_are_unchanged() {
        for m in [icosphere(3), grid(8, 8, 1.0)] {
            let t = IntrinsicTriangulation::delaunay(&m.positions, &m.faces);
            assert_eq!(t.n_flips(), 0);
            assert_eq!(t.faces(), &m.faces[..]);
            let a = t.cotan_laplacian();
            let b = cotan_laplacian(&m.positions, &m.faces);
            assert_eq!(a.symbolic().row_idx(), b.symbolic().row_idx());
            for (x, y) in a.val().iter().zip(b.val()) {
                assert!((x - y).abs() < 1e-12 * (1.0 + y.abs()));
            }
        }
    }

    #[test]
    fn flipping_removes_negative_weights_and_keeps_area() {
        let (p, f) = ellipsoid();
        let before = cotan_laplacian(&p, &f);
        let positive_off =
            |l: &SparseColMat<usize, f64>| l.triplet_iter().filter(|t| t.row != t.col && *t.val > 1e-9).count();
        assert!(positive_off(&before) > 0, "the test mesh must have negative weights");
        let t = IntrinsicTriangulation::delaunay(&p, &f);
        assert!(t.n_flips() > 0);
        assert!(t.is_delaunay());
        assert_eq!(t.faces().len(), f.len());
        let l = t.cotan_laplacian();
        assert_eq!(positive_off(&l), 0);
        let n = p.len();
        let mut row_sum = vec![0.0; n];
        let mut diag = vec![0.0; n];
        for e in l.triplet_iter() {
            row_sum[e.row] += *e.val;
            if e.row == e.col {
                diag[e.row] = *e.val;
            }
        }
        for i in 0..n {
            assert!(diag[i] > 0.0 && row_sum[i].abs() <= 1e-12 * diag[i]);
        }
        let area = |m: &[f64]| m.iter().sum::<f64>();
        let a0 = area(&crate::geometry::mass_matrix::lumped_mass(&p, &f));
        assert!((area(&t.lumped_mass()) - a0).abs() < 1e-12 * a0);
    }

    #[test]
    fn flipping_a_planar_mesh_keeps_the_energy_of_linear_functions() {
        // On any triangulation of a planar region the cotangent Laplacian is exact for linear
        // functions: their Dirichlet energy is |∇x|² × area, before and after flipping.
        let (p, f) = sheared_grid();
        let before = cotan_laplacian(&p, &f);
        let t = IntrinsicTriangulation::delaunay(&p, &f);
        assert!(t.n_flips() > 0, "the sheared grid has non-Delaunay diagonals");
        let l = t.cotan_laplacian();
        let x: Vec<f64> = p.iter().map(|q| 2.0 * q[0] - q[1]).collect();
        let energy =
            |l: &SparseColMat<usize, f64>| -> f64 { l.triplet_iter().map(|e| x[e.row] * e.val * x[e.col]).sum() };
        let exact = 5.0 * 0.3; // |∇x|² = 4 + 1, area = 0.3
        assert!((energy(&before) - exact).abs() < 1e-9);
        assert!((energy(&l) - exact).abs() < 1e-9, "{} vs {exact}", energy(&l));
    }
}
