//! The neighbour index of the mesh convolution: the rest mesh's 1-rings, in CSR form for the
//! hand-written kernels and as a padded index tensor for the Burn graph.

use crate::error::{Error, Result};
use crate::mesh::topology::Topology;

/// 1-ring neighbour lists of the N vertices with the weights of the neighbour mean
/// `mean_{j∈N(i)} x_j = (1/|N(i)|) Σ_j x_j`, plus the transposed lists (for back-propagation).
///
/// A vertex without neighbours has a neighbour mean of zero. Lists may be asymmetric; duplicates
/// count as often as they appear.
#[derive(Debug, Clone, PartialEq)]
pub struct NeighborIndex {
    n: usize,
    offsets: Vec<usize>,
    indices: Vec<u32>,
    inv_degree: Vec<f32>,
    t_offsets: Vec<usize>,
    t_indices: Vec<u32>,
    t_weights: Vec<f32>,
}

impl NeighborIndex {
    /// From one neighbour list per vertex (`rings.len()` = N).
    ///
    /// Errors when an index is ≥ N.
    pub fn new(rings: &[Vec<usize>]) -> Result<Self> {
        let mut offsets = Vec::with_capacity(rings.len() + 1);
        offsets.push(0);
        let mut indices = Vec::new();
        for r in rings {
            indices.extend_from_slice(r);
            offsets.push(indices.len());
        }
        Self::from_csr(&offsets, &indices)
    }

    /// From CSR lists: the neighbours of vertex `i` are `indices[offsets[i]..offsets[i+1]]`
    /// (`offsets.len()` = N + 1).
    pub fn from_csr(offsets: &[usize], indices: &[usize]) -> Result<Self> {
        if offsets.is_empty() || offsets[0] != 0 || *offsets.last().unwrap() != indices.len() {
            return Err(Error::Invalid(format!(
                "neighbour CSR: offsets must start at 0 and end at {} (got {:?}..{:?})",
                indices.len(),
                offsets.first(),
                offsets.last()
            )));
        }
        let n = offsets.len() - 1;
        if n == 0 {
            return Err(Error::Invalid("neighbour index: the mesh has no vertices".into()));
        }
        if n > u32::MAX as usize {
            return Err(Error::Invalid(format!("neighbour index: {n} vertices is too many")));
        }
        let mut inv_degree = Vec::with_capacity(n);
        for i in 0..n {
            if offsets[i + 1] < offsets[i] {
                return Err(Error::Invalid(format!("neighbour CSR: offsets decrease at vertex {i}")));
            }
            let d = offsets[i + 1] - offsets[i];
            inv_degree.push(if d == 0 { 0.0 } else { 1.0 / d as f32 });
            for &j in &indices[offsets[i]..offsets[i + 1]] {
                if j >= n {
                    return Err(Error::Invalid(format!(
                        "neighbour index: vertex {i} lists neighbour {j}, but there are only {n} vertices"
                    )));
                }
            }
        }
        // Transposed lists: for each j, the (i, 1/|N(i)|) with j ∈ N(i), i ascending.
        let mut count = vec![0usize; n + 1];
        for &j in indices {
            count[j + 1] += 1;
        }
        for j in 0..n {
            count[j + 1] += count[j];
        }
        let t_offsets = count.clone();
        let mut fill = count;
        let mut t_indices = vec![0u32; indices.len()];
        let mut t_weights = vec![0f32; indices.len()];
        for i in 0..n {
            for &j in &indices[offsets[i]..offsets[i + 1]] {
                t_indices[fill[j]] = i as u32;
                t_weights[fill[j]] = inv_degree[i];
                fill[j] += 1;
            }
        }
        Ok(NeighborIndex {
            n,
            offsets: offsets.to_vec(),
            indices: indices.iter().map(|&j| j as u32).collect(),
            inv_degree,
            t_offsets,
            t_indices,
            t_weights,
        })
    }

    /// From a triangle mesh's faces: the 1-rings of [`Topology`].
    pub fn from_faces(n_vertices: usize, faces: &[[usize; 3]]) -> Result<Self> {
        if let Some((f, bad)) = faces.iter().enumerate().find(|(_, f)| f.iter().any(|&v| v >= n_vertices)) {
            return Err(Error::Invalid(format!("face {f} {bad:?} references a vertex ≥ {n_vertices}")));
        }
        let topo = Topology::new(n_vertices, faces);
        let indices: Vec<usize> = topo.ring.clone();
        Self::from_csr(&topo.ring_offsets, &indices)
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.n
    }

    /// Neighbours of vertex `i`.
    #[inline]
    pub fn neighbors(&self, i: usize) -> &[u32] {
        &self.indices[self.offsets[i]..self.offsets[i + 1]]
    }

    /// `1/|N(i)|`, or 0 for a vertex without neighbours.
    #[inline]
    pub fn inv_degree(&self, i: usize) -> f32 {
        self.inv_degree[i]
    }

    /// The vertices `i` with `j ∈ N(i)` and their weights `1/|N(i)|`.
    #[inline]
    pub fn transposed(&self, j: usize) -> (&[u32], &[f32]) {
        let r = self.t_offsets[j]..self.t_offsets[j + 1];
        (&self.t_indices[r.clone()], &self.t_weights[r])
    }

    /// Largest neighbour count.
    pub fn max_degree(&self) -> usize {
        (0..self.n).map(|i| self.offsets[i + 1] - self.offsets[i]).max().unwrap_or(0)
    }

    /// Padded index `N × D` (D = max degree, at least 1), row-major; missing entries point at the
    /// extra row N (a zero row appended by the caller). With [`Self::inv_degree`] this gives the
    /// neighbour mean as gather + sum + scale.
    pub fn padded(&self) -> (Vec<i64>, usize) {
        let d = self.max_degree().max(1);
        let mut out = vec![self.n as i64; self.n * d];
        for i in 0..self.n {
            for (k, &j) in self.neighbors(i).iter().enumerate() {
                out[i * d + k] = j as i64;
            }
        }
        (out, d)
    }

    /// A 64-bit fingerprint (FNV-1a) of the lists, stored with a model so that loading it
    /// against a different mesh is detected.
    pub fn fingerprint(&self) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |v: u64| {
            for b in v.to_le_bytes() {
                h ^= b as u64;
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        eat(self.n as u64);
        for &o in &self.offsets {
            eat(o as u64);
        }
        for &j in &self.indices {
            eat(j as u64);
        }
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transposed_lists_match_and_bad_index_is_rejected() {
        let rings = vec![vec![1, 2], vec![0], vec![0, 1, 1], vec![]];
        let nb = NeighborIndex::new(&rings).unwrap();
        assert_eq!(nb.n_vertices(), 4);
        assert_eq!(nb.inv_degree(3), 0.0);
        // j = 1 appears in N(0) once and N(2) twice.
        let (idx, w) = nb.transposed(1);
        assert_eq!(idx, &[0, 2, 2]);
        assert_eq!(w, &[0.5, 1.0 / 3.0, 1.0 / 3.0]);
        let (p, d) = nb.padded();
        assert_eq!(d, 3);
        assert_eq!(&p[9..12], &[4, 4, 4]);
        let err = NeighborIndex::new(&[vec![5]]).unwrap_err().to_string();
        assert!(err.contains("neighbour 5"), "{err}");
        assert_ne!(
            nb.fingerprint(),
            NeighborIndex::new(&[vec![1, 2], vec![0], vec![0, 1], vec![]]).unwrap().fingerprint()
        );
    }
}
