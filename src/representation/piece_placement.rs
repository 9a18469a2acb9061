//! Where each connected piece of a multi-piece mesh sits: the three numbers a translation-free
//! representation (triangle-gradient, acap) needs beside its per-element features so that a mesh
//! in several pieces (eyes and teeth beside a face, garments, props) decodes with every piece in
//! its place.
//!
//! Deformation gradients say how each piece is rotated and stretched, never where it is: their
//! decoders solve one Poisson system per connected piece and put every piece's vertex centroid on
//! its rest centroid. [`PiecePlacement`] records, per frame, the offset of each piece relative to
//! the whole mesh and restores it after decoding.
//!
//! # Convention
//! Pieces are placed relative to one **anchor piece** `a`, the one with the most vertices (the
//! body beside its eyes and teeth; the lowest index among equals). With `c_p(x)` the vertex
//! centroid (unweighted mean) of piece `p` in positions `x`, `q` the rest positions and `u` the
//! rest mesh's bounding-box diagonal (data units), the translation of piece `p` is the
//! dimensionless 3-vector
//!
//! ```text
//! t_p(x) = ((c_p(x) − c_a(x)) − (c_p(q) − c_a(q))) / u        (t_a = 0)
//! ```
//!
//! so the rest shape has `t = 0`, a translation of the whole mesh leaves `t` unchanged (the
//! representation stays translation-free as a whole), and moving one piece against the anchor
//! changes that piece's `t` only — a component that moves an eye stays on the eye. Decoding
//! ([`PiecePlacement::place`]) moves each piece so that `c_p − c_a = c_p(q) − c_a(q) + u·(t_p − t_a)`
//! (`t_a` as decoded, zero for exact features), then every face-referenced vertex by one vector
//! so that their centroid is the rest centroid (the centroid convention of the translation-free
//! decoders). Both maps are linear in positions and in `t`; for exact features the round trip is
//! exact up to the one global translation.
//!
//! Vertices referenced by no face belong to no piece; they are left where the decoder puts them.

use crate::mesh::{Topology, TriMesh, Vec3};

/// The pieces of a rest mesh with at least two connected pieces, and their rest offsets.
#[derive(Debug, Clone)]
pub struct PiecePlacement {
    /// Piece of each vertex (`usize::MAX` for vertices referenced by no face).
    piece_of_vertex: Vec<usize>,
    /// Vertex count per piece.
    counts: Vec<usize>,
    /// The anchor piece (most vertices).
    anchor: usize,
    /// `c_p(q) − c(q)` per piece (data units; `c` the centroid of all face-referenced vertices).
    rest_offsets: Vec<Vec3>,
    /// `c(q)`, the rest centroid of the face-referenced vertices (data units).
    rest_centroid: Vec3,
    /// Length unit `u` of the translations: the rest bounding-box diagonal (data units, > 0).
    unit: f64,
}

impl PiecePlacement {
    /// The placement of `rest`'s pieces, or `None` when the face-referenced vertices form one
    /// connected piece (nothing to carry). `topology` is `rest`'s.
    pub fn new(rest: &TriMesh, topology: &Topology) -> Option<Self> {
        let (piece_of_vertex, n_pieces) = topology.components();
        if n_pieces < 2 {
            return None;
        }
        let (lo, hi) = rest.bounding_box();
        let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let unit = if diag.is_finite() && diag > 0.0 { diag } else { 1.0 };
        let mut this = PiecePlacement {
            piece_of_vertex,
            counts: vec![0; n_pieces],
            anchor: 0,
            rest_offsets: vec![[0.0; 3]; n_pieces],
            rest_centroid: [0.0; 3],
            unit,
        };
        for &p in &this.piece_of_vertex {
            if p != usize::MAX {
                this.counts[p] += 1;
            }
        }
        // The largest piece; `max_by_key` keeps the last maximum, so scan in reverse.
        this.anchor = (0..n_pieces).rev().max_by_key(|&p| this.counts[p]).unwrap_or(0);
        let (centroids, all) = this.centroids(&rest.positions);
        this.rest_offsets = centroids.iter().map(|c| std::array::from_fn(|k| c[k] - all[k])).collect();
        this.rest_centroid = all;
        Some(this)
    }

    /// Number of pieces P (≥ 2).
    pub fn n_pieces(&self) -> usize {
        self.counts.len()
    }

    /// Piece of each vertex (`usize::MAX` for a vertex referenced by no face).
    pub fn piece_of_vertex(&self) -> &[usize] {
        &self.piece_of_vertex
    }

    /// The anchor piece (most vertices; its translation is zero by definition).
    pub fn anchor(&self) -> usize {
        self.anchor
    }

    /// Vertex count of each piece.
    pub fn counts(&self) -> &[usize] {
        &self.counts
    }

    /// The length unit `u` of the translations (rest bounding-box diagonal, data units).
    pub fn unit(&self) -> f64 {
        self.unit
    }

    /// `∂x_v/∂t_r` of [`PiecePlacement::place`] (a multiple of the 3 × 3 identity, data units)
    /// for a vertex v of piece `p` and a piece `r` other than the anchor: `u·(δ_pr − n_r / Σ n)`.
    /// (`place` is affine in `t`: the decoded shape's own piece centroids do not depend on it.)
    pub fn derivative(&self, p: usize, r: usize) -> f64 {
        let total: usize = self.counts.iter().sum();
        self.unit * ((p == r) as u8 as f64 - self.counts[r] as f64 / total as f64)
    }

    /// The RMS distance of each piece's vertices in `positions` (N, data units) from their
    /// centroid: a piece's size (P values ≥ 0).
    pub fn rms_radii(&self, positions: &[Vec3]) -> Vec<f64> {
        let (centroids, _) = self.centroids(positions);
        let mut sums = vec![0.0; self.n_pieces()];
        for (p, x) in self.piece_of_vertex.iter().zip(positions) {
            if *p != usize::MAX {
                sums[*p] += (0..3).map(|k| (x[k] - centroids[*p][k]).powi(2)).sum::<f64>();
            }
        }
        sums.iter().zip(&self.counts).map(|(s, &n)| (s / n as f64).sqrt()).collect()
    }

    /// Per-piece centroids `c_p(x)` and the centroid `c(x)` of all face-referenced vertices.
    fn centroids(&self, positions: &[Vec3]) -> (Vec<Vec3>, Vec3) {
        let mut sums = vec![[0.0; 3]; self.n_pieces()];
        for (p, x) in self.piece_of_vertex.iter().zip(positions) {
            if *p != usize::MAX {
                for k in 0..3 {
                    sums[*p][k] += x[k];
                }
            }
        }
        let total: usize = self.counts.iter().sum();
        let mut all = [0.0; 3];
        for (s, &n) in sums.iter_mut().zip(&self.counts) {
            for k in 0..3 {
                all[k] += s[k];
                s[k] /= n as f64;
            }
        }
        (sums, all.map(|a| a / total as f64))
    }

    /// The translations `t_p(x)` (P dimensionless 3-vectors, module docs) of the N positions `x`.
    pub fn translations(&self, positions: &[Vec3]) -> Vec<Vec3> {
        let (centroids, _) = self.centroids(positions);
        let (ca, ra) = (centroids[self.anchor], self.rest_offsets[self.anchor]);
        centroids
            .iter()
            .zip(&self.rest_offsets)
            .map(|(c, r)| std::array::from_fn(|k| ((c[k] - ca[k]) - (r[k] - ra[k])) / self.unit))
            .collect()
    }

    /// Moves each piece of the N decoded `positions` so that its centroid is
    /// `c_p(q) + u·(t_p − t_a)`, then every face-referenced vertex by one vector so that their
    /// centroid is `c(q)` (module docs). `t` holds P translations.
    pub fn place(&self, positions: &mut [Vec3], t: &[Vec3]) {
        debug_assert_eq!(t.len(), self.n_pieces());
        let (centroids, _) = self.centroids(positions);
        let target: Vec<Vec3> = (0..self.n_pieces())
            .map(|p| {
                std::array::from_fn(|k| {
                    self.rest_centroid[k] + self.rest_offsets[p][k] + self.unit * (t[p][k] - t[self.anchor][k])
                })
            })
            .collect();
        // Centroid of the targets, weighted by vertex counts: c(q) + u·Σ n_p (t_p − t_a) / Σ n_p.
        let total: usize = self.counts.iter().sum();
        let mean_shift: Vec3 = std::array::from_fn(|k| {
            (0..self.n_pieces()).map(|p| self.counts[p] as f64 * (target[p][k] - self.rest_centroid[k])).sum::<f64>()
                / total as f64
        });
        let shift: Vec<Vec3> = (0..self.n_pieces())
            .map(|p| std::array::from_fn(|k| target[p][k] - centroids[p][k] - mean_shift[k]))
            .collect();
        for (x, &p) in positions.iter_mut().zip(&self.piece_of_vertex) {
            if p != usize::MAX {
                for k in 0..3 {
                    x[k] += shift[p][k];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn topo(m: &TriMesh) -> Topology {
        Topology::new(m.n_vertices(), &m.faces)
    }

    fn two_tetras() -> TriMesh {
        let tet = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mut positions: Vec<Vec3> = tet.to_vec();
        positions.extend(tet.iter().map(|p| [p[0] + 3.0, p[1], p[2] - 1.0]));
        positions.push([9.0, 9.0, 9.0]); // referenced by no face
        let f = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        let mut faces: Vec<[usize; 3]> = f.to_vec();
        faces.extend(f.iter().map(|t| t.map(|v| v + 4)));
        TriMesh::new(positions, faces)
    }

    #[test]
    fn one_piece_needs_nothing_and_rest_is_zero() {
        let m = two_tetras();
        let one = TriMesh::new(m.positions[..4].to_vec(), m.faces[..4].to_vec());
        assert!(PiecePlacement::new(&one, &topo(&one)).is_none());
        let p = PiecePlacement::new(&m, &topo(&m)).unwrap();
        assert_eq!((p.n_pieces(), p.counts()), (2, &[4usize, 4][..]));
        assert_eq!(p.piece_of_vertex()[8], usize::MAX);
        for t in p.translations(&m.positions) {
            assert!(t.iter().all(|v| v.abs() < 1e-15));
        }
    }

    #[test]
    fn translations_round_trip_up_to_one_global_shift() {
        let m = two_tetras();
        let p = PiecePlacement::new(&m, &topo(&m)).unwrap();
        // Piece 1 slides by (0.5, −0.25, 2); the whole mesh also moves by (10, 20, 30).
        let mut x = m.positions.clone();
        for (i, q) in x.iter_mut().enumerate() {
            let slide = if (4..8).contains(&i) { [0.5, -0.25, 2.0] } else { [0.0; 3] };
            for k in 0..3 {
                q[k] += slide[k] + [10.0, 20.0, 30.0][k];
            }
        }
        let t = p.translations(&x);
        let moved_whole: Vec<Vec3> = x.iter().map(|q| [q[0] - 7.0, q[1] + 1.0, q[2] + 4.0]).collect();
        assert_eq!(p.translations(&moved_whole).len(), 2);
        for (a, b) in t.iter().zip(p.translations(&moved_whole)) {
            assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-12), "{a:?} {b:?}");
        }
        // The anchor (piece 0: the first of two equal pieces) has t = 0; the slid piece's t is the
        // slide in units of the diagonal.
        assert_eq!(p.anchor(), 0);
        assert!(t[0].iter().all(|v| v.abs() < 1e-15));
        assert!((0..3).all(|k| (t[1][k] * p.unit() - [0.5, -0.25, 2.0][k]).abs() < 1e-12));
        // Decoding the rest positions (what a translation-free decoder returns) with t gives x
        // up to one global translation of the face-referenced vertices.
        let mut y = m.positions.clone();
        p.place(&mut y, &t);
        let d: Vec3 = std::array::from_fn(|k| x[0][k] - y[0][k]);
        for i in 0..8 {
            assert!((0..3).all(|k| (x[i][k] - y[i][k] - d[k]).abs() < 1e-12), "vertex {i}");
        }
        assert_eq!(y[8], m.positions[8]);
        // The derivative with respect to piece 1's translation, by a finite step.
        let mut t2 = t.clone();
        t2[1][0] += 1e-3;
        let mut y2 = m.positions.clone();
        p.place(&mut y2, &t2);
        for (i, piece) in [(0, 0), (5, 1)] {
            assert!(((y2[i][0] - y[i][0]) / 1e-3 - p.derivative(piece, 1)).abs() < 1e-9);
        }
        // The face-referenced centroid is the rest one.
        let c = |v: &[Vec3], k: usize| v[..8].iter().map(|q| q[k]).sum::<f64>() / 8.0;
        assert!((0..3).all(|k| (c(&y, k) - c(&m.positions, k)).abs() < 1e-12));
    }
}
