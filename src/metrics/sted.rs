//! STED, the spatio-temporal edge difference of Váša & Skala (2011), measuring how a result
//! sequence deforms differently from a ground-truth sequence with the same connectivity.
//!
//! Definitions used here (N vertices, F frames, truth `p`, result `p'`):
//!
//! * **Relative edge change** of edge `e = (i, j)` in frame `f`:
//!   `d(e,f) = (l'(e,f) − l(e,f)) / l(e,f)` with `l = ‖p_i − p_j‖` (signed, dimensionless).
//! * **Neighbourhood** of vertex `v` with `rings = n` (≥ 1): every edge with at least one endpoint
//!   at topological distance `< n` from `v`. So `n = 1` is the edges incident to `v` (its 1-ring
//!   spokes), `n = 2` adds the rim edges of the 1-ring and the spokes of every 1-ring
//!   neighbour, and so on. Vertices with no incident edge have an empty neighbourhood and are
//!   left out of the averages.
//! * **Local deviation** `dev(v,f)`: the standard deviation of `d(e,f)` over the neighbourhood,
//!   weighted by the ground-truth lengths `l(e,f)`:
//!   `μ = Σ l d / Σ l`, `dev = sqrt(Σ l (d − μ)² / Σ l)`.
//! * **Spatial part** `STED_s`: the mean of `dev(v,f)` over all measured vertices and all F frames.
//! * **Temporal edge** of vertex `v` between frames `f` and `f+1`: length
//!   `t(v,f) = sqrt(‖p_v(f+1) − p_v(f)‖² + δ²)`, where `δ = temporal_scale · L̄` and `L̄` is the
//!   mean edge length of the ground truth's first frame (δ keeps the relative difference finite
//!   for vertices that do not move; it scales with the data, so STED is scale-free).
//! * **Temporal part** `STED_t`: the mean over all N vertices and F − 1 frame pairs of
//!   `|t'(v,f) − t(v,f)| / t(v,f)` (result temporal edges use the same δ).
//! * **STED** `= sqrt(STED_s² + c²·STED_t²)`; for unordered collections ([`FrameOrder::Unordered`],
//!   e.g. SCAPE) and single frames only the spatial part is reported and STED equals it.
//!
//! Parameters: the papers in this repository (Huang et al. 2014, Tan et al. 2018) use STED but do
//! not state its parameters, so the defaults of [`StedParams`] are our documented choices:
//! `rings = 1`, `temporal_scale = 1` (δ = one mean edge length per frame), `c = 0.5`.
//!
//! Invariances (tested in `tests/metrics_invariants.rs`): 0 for identical sequences; unchanged by
//! a rigid motion (rotation + translation) of a whole sequence, and the spatial part even by a
//! different rigid motion per frame; unchanged when both sequences are scaled by the same factor;
//! and a result that is the ground truth uniformly scaled by `s` has spatial part 0 (every
//! relative edge change equals `s − 1`, so its local deviation vanishes) but a non-zero temporal
//! part for a moving sequence.

use std::collections::VecDeque;

use crate::error::{Error, Result};
use crate::mesh::{Topology, Vec3};

/// Parameters of STED (module docs), validated by [`StedParams::validate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StedParams {
    /// Neighbourhood size n in topological rings (≥ 1); 1 = the edges incident to the vertex.
    pub rings: usize,
    /// δ of the temporal edges as a multiple of the ground truth's first-frame mean edge length
    /// (> 0, finite).
    pub temporal_scale: f64,
    /// Weight c of the temporal part in `sqrt(s² + c²·t²)` (≥ 0, finite).
    pub c: f64,
}

impl Default for StedParams {
    fn default() -> Self {
        StedParams { rings: 1, temporal_scale: 1.0, c: 0.5 }
    }
}

impl StedParams {
    /// Errors (`Error::Config` naming the key and the bad value) unless `rings ≥ 1`,
    /// `temporal_scale > 0` and `c ≥ 0`, all finite.
    pub fn validate(&self) -> Result<()> {
        if self.rings == 0 {
            return Err(Error::config("sted.rings", format!("rings ({}) must be at least 1", self.rings)));
        }
        if !(self.temporal_scale.is_finite() && self.temporal_scale > 0.0) {
            return Err(Error::config(
                "sted.temporal_scale",
                format!("temporal_scale ({}) must be positive and finite", self.temporal_scale),
            ));
        }
        if !(self.c.is_finite() && self.c >= 0.0) {
            return Err(Error::config("sted.c", format!("c ({}) must be non-negative and finite", self.c)));
        }
        Ok(())
    }
}

/// Whether the frames form a time sequence (temporal part measured) or an unordered collection
/// of shapes (spatial part only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameOrder {
    /// Frames are consecutive time steps.
    Sequence,
    /// Frames are independent shapes (e.g. SCAPE poses); no temporal part.
    Unordered,
}

/// The parts of one STED evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StedReport {
    /// Spatial part `STED_s` (dimensionless).
    pub spatial: f64,
    /// Temporal part `STED_t`; `None` for unordered collections or a single frame.
    pub temporal: Option<f64>,
    /// `sqrt(s² + c²·t²)`, or `s` when there is no temporal part.
    pub combined: f64,
    /// The parameters used.
    pub params: StedParams,
    /// (edge, frame) pairs left out of the spatial part because the ground-truth edge has length
    /// 0 there (coincident vertices): its relative change is undefined.
    pub skipped_edges: usize,
}

/// STED evaluator for one connectivity: precomputes the edges and every vertex's
/// neighbourhood once, then measures any number of sequence pairs.
#[derive(Debug, Clone)]
pub struct Sted {
    params: StedParams,
    n_vertices: usize,
    edges: Vec<[usize; 2]>,
    /// CSR offsets into `nbhd`: the neighbourhood of `v` is `nbhd[nbhd_offsets[v]..nbhd_offsets[v+1]]`.
    nbhd_offsets: Vec<usize>,
    /// Concatenated neighbourhoods (edge indices into `edges`, sorted, unique).
    nbhd: Vec<usize>,
    /// Names of the frames (file stems) for messages; positions when empty.
    frame_names: Vec<String>,
}

impl Sted {
    /// Builds the evaluator for meshes with `n_vertices` vertices and triangles `faces`.
    /// Errors on invalid parameters or a face index `≥ n_vertices`.
    pub fn new(n_vertices: usize, faces: &[[usize; 3]], params: StedParams) -> Result<Sted> {
        params.validate()?;
        if let Some((i, f)) = faces.iter().enumerate().find(|(_, f)| f.iter().any(|&v| v >= n_vertices)) {
            return Err(Error::Invalid(format!("face {i} {f:?} references a vertex ≥ {n_vertices}")));
        }
        let topology = Topology::new(n_vertices, faces);
        let edges = topology.edges;
        // Incident edges per vertex (CSR).
        let mut inc_offsets = vec![0usize; n_vertices + 1];
        for e in &edges {
            inc_offsets[e[0] + 1] += 1;
            inc_offsets[e[1] + 1] += 1;
        }
        for v in 0..n_vertices {
            inc_offsets[v + 1] += inc_offsets[v];
        }
        let mut fill = inc_offsets.clone();
        let mut incident = vec![0usize; inc_offsets[n_vertices]];
        for (id, e) in edges.iter().enumerate() {
            for &v in e {
                incident[fill[v]] = id;
                fill[v] += 1;
            }
        }
        let incident_of = |v: usize| &incident[inc_offsets[v]..inc_offsets[v + 1]];

        // Neighbourhoods: edges incident to the vertices within distance < rings (BFS).
        let mut nbhd_offsets = Vec::with_capacity(n_vertices + 1);
        let mut nbhd = Vec::new();
        nbhd_offsets.push(0);
        let mut depth = vec![usize::MAX; n_vertices];
        let mut touched = Vec::new();
        let mut queue = VecDeque::new();
        for v in 0..n_vertices {
            let start = nbhd.len();
            depth[v] = 0;
            touched.push(v);
            queue.push_back(v);
            while let Some(u) = queue.pop_front() {
                for &id in incident_of(u) {
                    nbhd.push(id);
                    let e = edges[id];
                    let w = if e[0] == u { e[1] } else { e[0] };
                    if depth[u] + 1 < params.rings && depth[w] == usize::MAX {
                        depth[w] = depth[u] + 1;
                        touched.push(w);
                        queue.push_back(w);
                    }
                }
            }
            for &u in &touched {
                depth[u] = usize::MAX;
            }
            touched.clear();
            nbhd[start..].sort_unstable();
            let mut kept = start;
            for i in start..nbhd.len() {
                if i == start || nbhd[i] != nbhd[kept - 1] {
                    nbhd[kept] = nbhd[i];
                    kept += 1;
                }
            }
            nbhd.truncate(kept);
            nbhd_offsets.push(nbhd.len());
        }
        Ok(Sted { params, n_vertices, edges, nbhd_offsets, nbhd, frame_names: Vec::new() })
    }

    /// The parameters.
    pub fn params(&self) -> &StedParams {
        &self.params
    }

    /// Unique edges `[i, j]`, `i < j` (the order of [`Topology::edges`]).
    pub fn edges(&self) -> &[[usize; 2]] {
        &self.edges
    }

    /// The neighbourhood of vertex `v`: indices into [`Sted::edges`], sorted.
    pub fn neighbourhood(&self, v: usize) -> &[usize] {
        &self.nbhd[self.nbhd_offsets[v]..self.nbhd_offsets[v + 1]]
    }

    /// Names the frames of the sequences measured next (e.g. their file stems), so that errors
    /// name `95` rather than position 84 of a test split.
    pub fn with_frame_names(mut self, names: Vec<String>) -> Self {
        self.frame_names = names;
        self
    }

    fn frame_label(&self, frame: usize) -> String {
        match self.frame_names.get(frame) {
            Some(n) => format!("`{n}` (position {frame})"),
            None => frame.to_string(),
        }
    }

    fn check_frame(&self, what: &str, frame: usize, p: &[Vec3]) -> Result<()> {
        if p.len() != self.n_vertices {
            return Err(Error::Invalid(format!(
                "{what} frame {} has {} vertices, the mesh {}",
                self.frame_label(frame),
                p.len(),
                self.n_vertices
            )));
        }
        if let Some(v) = p.iter().position(|q| q.iter().any(|x| !x.is_finite())) {
            return Err(Error::Invalid(format!(
                "{what} frame {}: vertex {v} has a non-finite coordinate {:?}",
                self.frame_label(frame),
                p[v]
            )));
        }
        Ok(())
    }

    fn check_pair(&self, truth: &[Vec<Vec3>], result: &[Vec<Vec3>]) -> Result<()> {
        if truth.len() != result.len() {
            return Err(Error::Invalid(format!("{} ground-truth frames, {} result frames", truth.len(), result.len())));
        }
        if truth.is_empty() {
            return Err(Error::Invalid("STED of an empty sequence".into()));
        }
        for (f, (t, r)) in truth.iter().zip(result).enumerate() {
            self.check_frame("ground-truth", f, t)?;
            self.check_frame("result", f, r)?;
        }
        Ok(())
    }

    /// Ground-truth edge lengths and signed relative edge changes `(l' − l)/l` of one frame
    /// pair, and how many edges were skipped: an edge of length 0 in the ground truth has an
    /// undefined relative change and gets weight 0 (length 0, change 0).
    fn edge_changes(&self, truth: &[Vec3], result: &[Vec3]) -> (Vec<f64>, Vec<f64>, usize) {
        let mut lengths = Vec::with_capacity(self.edges.len());
        let mut changes = Vec::with_capacity(self.edges.len());
        let mut skipped = 0;
        for &[i, j] in &self.edges {
            let l = crate::mesh::dist(truth[i], truth[j]);
            if l > 0.0 {
                lengths.push(l);
                changes.push((crate::mesh::dist(result[i], result[j]) - l) / l);
            } else {
                skipped += 1;
                lengths.push(0.0);
                changes.push(0.0);
            }
        }
        (lengths, changes, skipped)
    }

    /// Local deviation `dev(v)` of every vertex for one frame pair (module docs); 0 for vertices
    /// with an empty neighbourhood or only zero-length ground-truth edges. Errors on mismatched
    /// sizes or non-finite input.
    pub fn spatial_per_vertex(&self, truth: &[Vec3], result: &[Vec3]) -> Result<Vec<f64>> {
        self.check_frame("ground-truth", 0, truth)?;
        self.check_frame("result", 0, result)?;
        let (lengths, changes, _) = self.edge_changes(truth, result);
        Ok(self.local_deviations(&lengths, &changes))
    }

    fn local_deviations(&self, lengths: &[f64], changes: &[f64]) -> Vec<f64> {
        (0..self.n_vertices)
            .map(|v| {
                let nb = self.neighbourhood(v);
                if nb.is_empty() {
                    return 0.0;
                }
                let (mut sw, mut swd) = (0.0, 0.0);
                for &e in nb {
                    sw += lengths[e];
                    swd += lengths[e] * changes[e];
                }
                if sw <= 0.0 {
                    return 0.0;
                }
                let mean = swd / sw;
                let var: f64 = nb.iter().map(|&e| lengths[e] * (changes[e] - mean).powi(2)).sum::<f64>() / sw;
                var.max(0.0).sqrt()
            })
            .collect()
    }

    fn n_measured(&self) -> usize {
        (0..self.n_vertices).filter(|&v| !self.neighbourhood(v).is_empty()).count()
    }

    /// Spatial part of one frame pair: the mean of [`Sted::spatial_per_vertex`] over vertices
    /// with a non-empty neighbourhood (0 when there are none).
    pub fn spatial_frame(&self, truth: &[Vec3], result: &[Vec3]) -> Result<f64> {
        let m = self.n_measured();
        if m == 0 {
            return Ok(0.0);
        }
        Ok(self.spatial_per_vertex(truth, result)?.iter().sum::<f64>() / m as f64)
    }

    /// Spatial part `STED_s` of a sequence pair (F ≥ 1 frames, either order): the mean local
    /// deviation over all frames and measured vertices.
    pub fn spatial(&self, truth: &[Vec<Vec3>], result: &[Vec<Vec3>]) -> Result<f64> {
        Ok(self.spatial_counted(truth, result)?.0)
    }

    /// [`Sted::spatial`] and the number of (edge, frame) pairs skipped for a zero-length
    /// ground-truth edge.
    pub fn spatial_counted(&self, truth: &[Vec<Vec3>], result: &[Vec<Vec3>]) -> Result<(f64, usize)> {
        self.check_pair(truth, result)?;
        let m = self.n_measured();
        if m == 0 {
            return Ok((0.0, 0));
        }
        let (mut sum, mut skipped) = (0.0, 0);
        for (t, r) in truth.iter().zip(result) {
            let (lengths, changes, s) = self.edge_changes(t, r);
            skipped += s;
            sum += self.local_deviations(&lengths, &changes).iter().sum::<f64>();
        }
        Ok((sum / (m * truth.len()) as f64, skipped))
    }

    /// Temporal part `STED_t` of a time sequence pair (F ≥ 2 frames; module docs). Errors on
    /// fewer than two frames or a ground truth whose first frame has no edge of positive length.
    pub fn temporal(&self, truth: &[Vec<Vec3>], result: &[Vec<Vec3>]) -> Result<f64> {
        self.check_pair(truth, result)?;
        if truth.len() < 2 {
            return Err(Error::Invalid(format!("the temporal part needs at least 2 frames, got {}", truth.len())));
        }
        if self.n_vertices == 0 {
            return Ok(0.0);
        }
        let t0 = &truth[0];
        let mean_edge = if self.edges.is_empty() {
            0.0
        } else {
            self.edges.iter().map(|&[i, j]| crate::mesh::dist(t0[i], t0[j])).sum::<f64>() / self.edges.len() as f64
        };
        if mean_edge <= 0.0 {
            return Err(Error::Numerical(
                "ground-truth frame 0 has no edge of positive length; temporal scale δ undefined".into(),
            ));
        }
        let delta2 = (self.params.temporal_scale * mean_edge).powi(2);
        let mut sum = 0.0;
        for f in 0..truth.len() - 1 {
            for v in 0..self.n_vertices {
                let lt = (crate::mesh::dist(truth[f + 1][v], truth[f][v]).powi(2) + delta2).sqrt();
                let lr = (crate::mesh::dist(result[f + 1][v], result[f][v]).powi(2) + delta2).sqrt();
                sum += (lr - lt).abs() / lt;
            }
        }
        Ok(sum / (self.n_vertices * (truth.len() - 1)) as f64)
    }

    /// Spatial and (for a time sequence of ≥ 2 frames) temporal part and their combination.
    pub fn evaluate(&self, truth: &[Vec<Vec3>], result: &[Vec<Vec3>], order: FrameOrder) -> Result<StedReport> {
        let (spatial, skipped_edges) = self.spatial_counted(truth, result)?;
        let temporal = match order {
            FrameOrder::Sequence if truth.len() >= 2 => Some(self.temporal(truth, result)?),
            _ => None,
        };
        let combined = match temporal {
            Some(t) => (spatial * spatial + self.params.c * self.params.c * t * t).sqrt(),
            None => spatial,
        };
        Ok(StedReport { spatial, temporal, combined, params: self.params, skipped_edges })
    }
}

/// One-shot STED of `result` against `truth` (frames of the mesh with triangles `faces`).
pub fn sted(
    faces: &[[usize; 3]],
    truth: &[Vec<Vec3>],
    result: &[Vec<Vec3>],
    params: StedParams,
    order: FrameOrder,
) -> Result<StedReport> {
    let n = truth.first().map_or(0, |f| f.len());
    Sted::new(n, faces, params)?.evaluate(truth, result, order)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles sharing edge (0, 1): a strip 0-1-2 / 1-0-3.
    fn two_triangles() -> Vec<[usize; 3]> {
        vec![[0, 1, 2], [1, 0, 3]]
    }

    #[test]
    fn neighbourhoods_by_rings() {
        let faces = two_triangles();
        let s1 = Sted::new(4, &faces, StedParams::default()).unwrap();
        // Edges sorted: (0,1) (0,2) (0,3) (1,2) (1,3) → ids 0..5.
        assert_eq!(s1.edges(), &[[0, 1], [0, 2], [0, 3], [1, 2], [1, 3]]);
        assert_eq!(s1.neighbourhood(0), &[0, 1, 2]);
        assert_eq!(s1.neighbourhood(2), &[1, 3]);
        let s2 = Sted::new(4, &faces, StedParams { rings: 2, ..Default::default() }).unwrap();
        // Vertex 2's 1-ring is {0, 1}; their incident edges cover the whole mesh.
        assert_eq!(s2.neighbourhood(2), &[0, 1, 2, 3, 4]);
    }

    #[test]
    fn weighted_local_deviation() {
        // Vertex 2 of the strip has two edges: (0,2) length 1 and (1,2) length 3 (truth),
        // changes 0 and +1 (result lengths 1 and 6). Weighted mean = (1·0 + 3·1)/4 = 0.75,
        // variance = (1·0.75² + 3·0.25²)/4 = 0.1875, deviation = sqrt(0.1875) = 0.4330127.
        // Layout: 2 = origin, 0 = (1,0,0), 1 = (0,3,0) (→ (0,6,0) in the result); vertex 3 is
        // not in vertex 2's 1-ring neighbourhood.
        let faces = two_triangles();
        let s = Sted::new(4, &faces, StedParams::default()).unwrap();
        let truth = vec![[1.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 0.0], [1.0, 3.0, 1.0]];
        let mut result = truth.clone();
        result[1] = [0.0, 6.0, 0.0];
        let dev = s.spatial_per_vertex(&truth, &result).unwrap();
        assert!((dev[2] - 0.1875f64.sqrt()).abs() < 1e-12, "{}", dev[2]);
    }

    #[test]
    fn bad_parameters_and_inputs() {
        let faces = two_triangles();
        let e = StedParams { rings: 0, ..Default::default() }.validate().unwrap_err();
        assert!(e.to_string().contains("rings (0)"), "{e}");
        assert!(StedParams { temporal_scale: 0.0, ..Default::default() }.validate().is_err());
        assert!(StedParams { c: f64::NAN, ..Default::default() }.validate().is_err());
        assert!(Sted::new(3, &faces, StedParams::default()).is_err());
        let s = Sted::new(4, &faces, StedParams::default()).unwrap();
        let p = vec![vec![[0.0; 3]; 4]];
        // Zero-length ground-truth edges (all 5 of them) are skipped and counted, not an error.
        assert_eq!(s.spatial_counted(&p, &p).unwrap(), (0.0, 5));
        let q = vec![vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [f64::NAN, 0.0, 0.0]]];
        assert!(s.spatial(&q, &q).is_err());
        let ok = vec![vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, -1.0, 0.0]]];
        assert!(s.temporal(&ok, &ok).is_err(), "one frame has no temporal part");
        assert!(s.spatial(&ok, &[]).is_err());
        let r = s.evaluate(&ok, &ok, FrameOrder::Sequence).unwrap();
        assert_eq!((r.spatial, r.temporal, r.combined), (0.0, None, 0.0));
    }
}
