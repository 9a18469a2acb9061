//! Farthest-point sampling of mesh vertices: the first vertex is given (e.g. drawn by a seeded
//! generator), every further one is the vertex farthest from all chosen so far, in edge-path
//! (graph) distance on the mesh ([`EdgeGraph`], Dijkstra with Euclidean edge lengths). This is
//! the "random first point, then Voronoi sampling" of Tan et al. 2018 (Fig. 6) for spreading
//! control points evenly over a surface.
//!
//! Ties are broken towards the lowest vertex index, so the result depends only on the mesh and
//! the start vertex. Vertices unreachable from the chosen set (another connected component) have
//! infinite distance and are therefore picked first, one per component.

use super::graph_distance::EdgeGraph;
use crate::error::{Error, Result};

/// Farthest-point sampler over one edge graph: one Dijkstra per chosen vertex.
pub struct FarthestPointSampler<'a> {
    graph: &'a EdgeGraph,
}

impl<'a> FarthestPointSampler<'a> {
    /// Wraps the edge graph of the mesh to sample.
    pub fn new(graph: &'a EdgeGraph) -> Self {
        FarthestPointSampler { graph }
    }

    /// `n` distinct vertices (in the order chosen, starting with `start`). Errors when `n` is 0
    /// or exceeds the vertex count, or `start` is out of range.
    pub fn sample(&self, n: usize, start: usize) -> Result<Vec<usize>> {
        let nv = self.graph.n_vertices();
        if n == 0 || n > nv {
            return Err(Error::Invalid(format!("farthest-point sampling: {n} points requested from {nv} vertices")));
        }
        if start >= nv {
            return Err(Error::Invalid(format!("farthest-point sampling: start vertex {start} out of range ({nv})")));
        }
        let mut chosen = vec![start];
        let mut min_d = self.graph.distances(&[start]);
        let mut d = vec![0.0; nv];
        while chosen.len() < n {
            // argmax of the distance to the chosen set; lowest index on ties.
            let mut best = usize::MAX;
            let mut best_d = -1.0;
            for (v, &x) in min_d.iter().enumerate() {
                if x > best_d {
                    best_d = x;
                    best = v;
                }
            }
            if best_d <= 0.0 {
                // Every remaining vertex coincides with a chosen one (zero-length edges):
                // take the lowest unchosen index.
                best = (0..nv).find(|v| !chosen.contains(v)).unwrap_or(best);
            }
            chosen.push(best);
            self.graph.distances_into(&[best], &mut d);
            for (m, &x) in min_d.iter_mut().zip(&d) {
                if x < *m {
                    *m = x;
                }
            }
            min_d[best] = 0.0;
        }
        Ok(chosen)
    }
}

/// One-shot [`FarthestPointSampler::sample`] on the edge graph of `positions`/`faces`.
pub fn farthest_point_sampling(
    positions: &[crate::mesh::Vec3],
    faces: &[[usize; 3]],
    n: usize,
    start: usize,
) -> Result<Vec<usize>> {
    let g = EdgeGraph::new(positions, faces);
    FarthestPointSampler::new(&g).sample(n, start)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives::grid;

    #[test]
    fn picks_the_farthest_vertex_each_time() {
        let g = grid(10, 10, 1.0);
        let n = g.n_vertices();
        let pts = farthest_point_sampling(&g.positions, &g.faces, 4, 0).unwrap();
        assert_eq!(pts[0], 0);
        // Second point: the corner opposite vertex 0 (largest path distance).
        let graph = EdgeGraph::new(&g.positions, &g.faces);
        let d0 = graph.distances(&[0]);
        let far = d0.iter().cloned().fold(0.0, f64::max);
        assert!((d0[pts[1]] - far).abs() < 1e-12);
        // Distinct points, and each new point is the farthest from the earlier ones.
        let mut set = pts.clone();
        set.sort_unstable();
        set.dedup();
        assert_eq!(set.len(), 4);
        for i in 1..pts.len() {
            let d = graph.distances(&pts[..i]);
            let max = d.iter().cloned().fold(0.0, f64::max);
            assert!((d[pts[i]] - max).abs() < 1e-12, "point {i}");
        }
        // Deterministic for a start, covers the whole mesh when asked for every vertex.
        assert_eq!(farthest_point_sampling(&g.positions, &g.faces, 4, 0).unwrap(), pts);
        let all = farthest_point_sampling(&g.positions, &g.faces, n, 7).unwrap();
        let mut s = all.clone();
        s.sort_unstable();
        assert_eq!(s, (0..n).collect::<Vec<_>>());
    }

    #[test]
    fn spread_beats_the_first_points_of_a_scan() {
        // The covering radius of 20 FPS points is far smaller than that of 20 consecutive indices.
        let g = grid(20, 20, 1.0);
        let graph = EdgeGraph::new(&g.positions, &g.faces);
        let fps = FarthestPointSampler::new(&graph).sample(20, 0).unwrap();
        let scan: Vec<usize> = (0..20).collect();
        let radius = |s: &[usize]| graph.distances(s).into_iter().fold(0.0, f64::max);
        assert!(radius(&fps) < 0.5 * radius(&scan), "{} vs {}", radius(&fps), radius(&scan));
    }

    #[test]
    fn rejects_bad_requests() {
        let g = grid(3, 3, 1.0);
        assert!(farthest_point_sampling(&g.positions, &g.faces, 0, 0).is_err());
        assert!(farthest_point_sampling(&g.positions, &g.faces, 1000, 0).is_err());
        assert!(farthest_point_sampling(&g.positions, &g.faces, 2, 1000).is_err());
    }
}
