//! Combinatorial structure of a triangle mesh: unique edges, edge–face incidence, 1-rings in
//! cyclic order, boundary loops, connected components and manifoldness checks.
//!
//! Everything here depends on the faces only (no positions), so one `Topology` serves every
//! frame of a [`super::MeshSequence`].

use std::collections::HashMap;

/// Topology of a triangle mesh with `n_vertices` vertices.
#[derive(Debug, Clone)]
pub struct Topology {
    /// Number of vertices N (including vertices referenced by no face).
    pub n_vertices: usize,
    /// Unique undirected edges `[i, j]` with `i < j`, sorted lexicographically.
    pub edges: Vec<[usize; 2]>,
    /// For each edge (same order as `edges`): the incident faces as `(face index, opposite
    /// vertex)`. One entry for a boundary edge, two for an interior edge, more when non-manifold.
    pub edge_faces: Vec<Vec<(usize, usize)>>,
    /// CSR offsets into `ring`: the 1-ring of vertex `v` is `ring[ring_offsets[v]..ring_offsets[v+1]]`.
    pub ring_offsets: Vec<usize>,
    /// Concatenated 1-rings. Each ring is in counter-clockwise order around its vertex (seen from
    /// the side the faces' orientation points to). For an interior vertex the ring starts at the
    /// second vertex of the first face (in file order) incident to it; for a boundary vertex it
    /// starts at the neighbour across the boundary edge so that the open fan is walked in one pass.
    pub ring: Vec<usize>,
    /// `true` for vertices on a boundary edge.
    pub is_boundary_vertex: Vec<bool>,
}

impl Topology {
    /// Builds the topology. Face indices must be `< n_vertices` (validate before).
    pub fn new(n_vertices: usize, faces: &[[usize; 3]]) -> Self {
        // Unique edges with incident faces.
        let mut edge_index: HashMap<(usize, usize), usize> = HashMap::with_capacity(faces.len() * 3 / 2 + 8);
        let mut edges: Vec<[usize; 2]> = Vec::new();
        let mut edge_faces: Vec<Vec<(usize, usize)>> = Vec::new();
        for (fi, f) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b, c) = (f[k], f[(k + 1) % 3], f[(k + 2) % 3]);
                if a == b {
                    continue;
                }
                let key = (a.min(b), a.max(b));
                let id = *edge_index.entry(key).or_insert_with(|| {
                    edges.push([key.0, key.1]);
                    edge_faces.push(Vec::new());
                    edges.len() - 1
                });
                edge_faces[id].push((fi, c));
            }
        }
        // Sort edges lexicographically, carrying the incidence along.
        let mut order: Vec<usize> = (0..edges.len()).collect();
        order.sort_unstable_by_key(|&i| edges[i]);
        let edges: Vec<[usize; 2]> = order.iter().map(|&i| edges[i]).collect();
        let edge_faces: Vec<Vec<(usize, usize)>> = order.iter().map(|&i| std::mem::take(&mut edge_faces[i])).collect();

        let mut is_boundary_vertex = vec![false; n_vertices];
        for (e, inc) in edges.iter().zip(&edge_faces) {
            if inc.len() == 1 {
                is_boundary_vertex[e[0]] = true;
                is_boundary_vertex[e[1]] = true;
            }
        }

        // Wedges per vertex: face (v, a, b) in CCW order gives the step a -> b around v.
        let mut wedges: Vec<Vec<(usize, usize)>> = vec![Vec::new(); n_vertices];
        for f in faces {
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                continue;
            }
            for k in 0..3 {
                wedges[f[k]].push((f[(k + 1) % 3], f[(k + 2) % 3]));
            }
        }
        let mut ring_offsets = Vec::with_capacity(n_vertices + 1);
        let mut ring = Vec::with_capacity(edges.len() * 2);
        ring_offsets.push(0);
        for w in &wedges {
            order_fan(w, &mut ring);
            ring_offsets.push(ring.len());
        }
        Topology { n_vertices, edges, edge_faces, ring_offsets, ring, is_boundary_vertex }
    }

    /// The 1-ring of vertex `v` in cyclic (counter-clockwise) order.
    pub fn neighbors(&self, v: usize) -> &[usize] {
        &self.ring[self.ring_offsets[v]..self.ring_offsets[v + 1]]
    }

    /// Valence (number of distinct neighbours) of vertex `v`.
    pub fn degree(&self, v: usize) -> usize {
        self.ring_offsets[v + 1] - self.ring_offsets[v]
    }

    /// Largest valence over all vertices.
    pub fn max_degree(&self) -> usize {
        (0..self.n_vertices).map(|v| self.degree(v)).max().unwrap_or(0)
    }

    /// Index of edge `{i, j}` in [`Topology::edges`], if it exists.
    pub fn edge_id(&self, i: usize, j: usize) -> Option<usize> {
        let key = [i.min(j), i.max(j)];
        self.edges.binary_search(&key).ok()
    }

    /// Edges with more than two incident faces.
    pub fn non_manifold_edges(&self) -> Vec<[usize; 2]> {
        self.edges.iter().zip(&self.edge_faces).filter(|(_, f)| f.len() > 2).map(|(e, _)| *e).collect()
    }

    /// Number of boundary edges (edges with exactly one incident face).
    pub fn n_boundary_edges(&self) -> usize {
        self.edge_faces.iter().filter(|f| f.len() == 1).count()
    }

    /// Closed boundary loops as vertex cycles, each following the boundary edges' face
    /// orientation. Loops that cannot be closed (at non-manifold boundary vertices) are returned
    /// as the open chains walked.
    pub fn boundary_loops(&self, faces: &[[usize; 3]]) -> Vec<Vec<usize>> {
        // Directed boundary half-edges a -> b (orientation of their one face).
        let mut next: HashMap<usize, Vec<usize>> = HashMap::new();
        for (e, inc) in self.edges.iter().zip(&self.edge_faces) {
            if inc.len() != 1 {
                continue;
            }
            let f = faces[inc[0].0];
            let (a, b) = (e[0], e[1]);
            // Orientation in the face: is a -> b a face half-edge?
            let forward = (0..3).any(|k| f[k] == a && f[(k + 1) % 3] == b);
            let (s, t) = if forward { (a, b) } else { (b, a) };
            next.entry(s).or_default().push(t);
        }
        let mut starts: Vec<usize> = next.keys().copied().collect();
        starts.sort_unstable();
        let mut loops = Vec::new();
        for s in starts {
            while let Some(t) = next.get_mut(&s).and_then(|v| v.pop()) {
                let mut lp = vec![s];
                let mut cur = t;
                while cur != s {
                    lp.push(cur);
                    match next.get_mut(&cur).and_then(|v| v.pop()) {
                        Some(n) => cur = n,
                        None => break,
                    }
                }
                loops.push(lp);
            }
        }
        loops
    }

    /// Connected components of the vertices referenced by faces (vertices on no face are not
    /// counted). Returns a component label per vertex (`usize::MAX` for unreferenced vertices)
    /// and the number of components.
    pub fn components(&self) -> (Vec<usize>, usize) {
        let n = self.n_vertices;
        let mut label = vec![usize::MAX; n];
        let mut count = 0;
        let mut stack = Vec::new();
        for s in 0..n {
            if label[s] != usize::MAX || self.degree(s) == 0 {
                continue;
            }
            label[s] = count;
            stack.push(s);
            while let Some(v) = stack.pop() {
                for &u in self.neighbors(v) {
                    if label[u] == usize::MAX {
                        label[u] = count;
                        stack.push(u);
                    }
                }
            }
            count += 1;
        }
        (label, count)
    }

    /// Vertices referenced by no face.
    pub fn isolated_vertices(&self) -> Vec<usize> {
        (0..self.n_vertices).filter(|&v| self.degree(v) == 0).collect()
    }
}

/// Orders the wedges `(a, b)` of one vertex into a cyclic neighbour list appended to `out`.
/// Manifold fans come out as one CCW walk; anything else is appended in encounter order with
/// duplicates removed.
fn order_fan(wedges: &[(usize, usize)], out: &mut Vec<usize>) {
    if wedges.is_empty() {
        return;
    }
    let start_len = out.len();
    let mut succ: HashMap<usize, usize> = HashMap::with_capacity(wedges.len());
    let mut has_pred: HashMap<usize, bool> = HashMap::with_capacity(wedges.len());
    let mut manifold = true;
    for &(a, b) in wedges {
        if succ.insert(a, b).is_some() {
            manifold = false;
        }
        if has_pred.insert(b, true).is_some() {
            manifold = false;
        }
    }
    if manifold {
        // Boundary fans have exactly one start without predecessor; closed fans have none.
        let open_starts: Vec<usize> = wedges.iter().map(|w| w.0).filter(|a| !has_pred.contains_key(a)).collect();
        let start = match open_starts.len() {
            0 => wedges[0].0,
            1 => open_starts[0],
            _ => {
                manifold = false;
                wedges[0].0
            }
        };
        if manifold {
            let mut cur = start;
            loop {
                out.push(cur);
                match succ.get(&cur) {
                    Some(&n) if n != start => cur = n,
                    _ => break,
                }
                if out.len() - start_len > wedges.len() + 1 {
                    manifold = false;
                    break;
                }
            }
            if manifold && out.len() - start_len == distinct_count(wedges) {
                return;
            }
            out.truncate(start_len);
        }
    }
    for &(a, b) in wedges {
        for x in [a, b] {
            if !out[start_len..].contains(&x) {
                out.push(x);
            }
        }
    }
}

fn distinct_count(wedges: &[(usize, usize)]) -> usize {
    let mut v: Vec<usize> = wedges.iter().flat_map(|w| [w.0, w.1]).collect();
    v.sort_unstable();
    v.dedup();
    v.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles sharing edge 1–2: a square split along its diagonal.
    fn square() -> Vec<[usize; 3]> {
        vec![[0, 1, 2], [0, 2, 3]]
    }

    /// Regular octahedron faces (closed, 6 vertices, 12 edges).
    fn octahedron() -> Vec<[usize; 3]> {
        vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    }

    #[test]
    fn square_edges_boundary_and_rings() {
        let t = Topology::new(4, &square());
        assert_eq!(t.edges, vec![[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]);
        assert_eq!(t.n_boundary_edges(), 4);
        assert!(t.is_boundary_vertex.iter().all(|&b| b));
        // Vertex 0: wedges (1,2) and (2,3): open fan 1 -> 2 -> 3.
        assert_eq!(t.neighbors(0), &[1, 2, 3]);
        assert_eq!(t.neighbors(2), &[3, 0, 1]);
        let loops = t.boundary_loops(&square());
        assert_eq!(loops.len(), 1);
        assert_eq!(loops[0].len(), 4);
        let shared = t.edge_id(0, 2).unwrap();
        assert_eq!(t.edge_faces[shared].len(), 2);
    }

    #[test]
    fn octahedron_is_closed_and_rings_are_cyclic() {
        let f = octahedron();
        let t = Topology::new(6, &f);
        assert_eq!(t.edges.len(), 12);
        assert_eq!(t.n_boundary_edges(), 0);
        assert!(t.boundary_loops(&f).is_empty());
        assert_eq!(t.components().1, 1);
        for v in 0..6 {
            let r = t.neighbors(v);
            assert_eq!(r.len(), 4);
            // Consecutive ring vertices (cyclically) are adjacent.
            for k in 0..4 {
                assert!(t.edge_id(r[k], r[(k + 1) % 4]).is_some());
            }
        }
        assert!(t.non_manifold_edges().is_empty());
    }

    #[test]
    fn two_components_and_isolated_vertex() {
        let faces = vec![[0, 1, 2], [3, 4, 5]];
        let t = Topology::new(7, &faces);
        assert_eq!(t.components().1, 2);
        assert_eq!(t.isolated_vertices(), vec![6]);
        assert_eq!(t.boundary_loops(&faces).len(), 2);
    }

    #[test]
    fn non_manifold_edge_detected() {
        let faces = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        let t = Topology::new(5, &faces);
        assert_eq!(t.non_manifold_edges(), vec![[0, 1]]);
        // Rings still list every neighbour once.
        let mut r = t.neighbors(0).to_vec();
        r.sort_unstable();
        assert_eq!(r, vec![1, 2, 3, 4]);
    }

    #[test]
    fn max_degree_edge_ids_and_boundary_direction() {
        let f = square();
        let t = Topology::new(4, &f);
        assert_eq!(t.max_degree(), 3);
        assert_eq!(Topology::new(6, &octahedron()).max_degree(), 4);
        assert_eq!((t.edge_id(0, 1), t.edge_id(3, 2), t.edge_id(1, 3)), (Some(0), Some(4), None));
        // The loop follows the faces' orientation 0 → 1 → 2 → 3, not the reverse.
        assert_eq!(t.boundary_loops(&f), vec![vec![0, 1, 2, 3]]);
    }

    #[test]
    fn two_closed_fans_at_one_vertex_keep_all_neighbours() {
        // Two tetrahedra sharing only vertex 0: its wedges form two separate cycles.
        let tet = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        let faces: Vec<[usize; 3]> =
            tet.iter().copied().chain(tet.iter().map(|f| f.map(|v| if v == 0 { 0 } else { v + 3 }))).collect();
        let t = Topology::new(7, &faces);
        let mut r = t.neighbors(0).to_vec();
        r.sort_unstable();
        assert_eq!(r, vec![1, 2, 3, 4, 5, 6]);
        assert_eq!(t.components().1, 1);
    }
}
