//! Touching pieces: which connected pieces of a mesh lie against each other (an eye in its
//! socket, a feather on a wing, a button on a coat), so that distance-based supports may pass
//! between them while separate objects (two props side by side) stay apart.
//!
//! Two pieces *touch* when some vertex of one lies within `gap` (data units, straight line) of
//! some vertex of the other; touching is closed transitively into *clusters*. The search hashes
//! vertices into a grid of cells of side `gap` and compares only neighbouring cells: O(N) for
//! meshes whose vertices are spread over many cells.

use std::collections::HashMap;

use crate::math::disjoint_set::DisjointSet;
#[cfg(doc)]
use crate::mesh::Topology;
use crate::mesh::{TriMesh, dist};

/// The cluster of touching pieces of every vertex: `(cluster per vertex, number of clusters)`;
/// `usize::MAX` for vertices referenced by no face. `piece` and `n_pieces` are the mesh's
/// connected components as [`Topology::components`] gives them (a piece per vertex, `usize::MAX`
/// for none); `gap` ≥ 0 in data units.
pub fn touching_clusters(mesh: &TriMesh, piece: &[usize], n_pieces: usize, gap: f64) -> (Vec<usize>, usize) {
    let mut sets = DisjointSet::new(n_pieces);
    if n_pieces > 1 && gap.is_finite() && gap > 0.0 {
        let cell = |p: [f64; 3]| p.map(|x| (x / gap).floor() as i64);
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (v, p) in mesh.positions.iter().enumerate() {
            if piece[v] != usize::MAX && p.iter().all(|x| x.is_finite()) {
                grid.entry(cell(*p)).or_default().push(v);
            }
        }
        for (c, vs) in &grid {
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(ws) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else { continue };
                        for &v in vs {
                            for &w in ws {
                                if piece[v] != piece[w]
                                    && !sets.same(piece[v], piece[w])
                                    && dist(mesh.positions[v], mesh.positions[w]) <= gap
                                {
                                    sets.union(piece[v], piece[w]);
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    let mut id = vec![usize::MAX; n_pieces];
    let mut count = 0;
    let cluster = piece
        .iter()
        .map(|&p| {
            if p == usize::MAX {
                return usize::MAX;
            }
            let r = sets.find(p);
            if id[r] == usize::MAX {
                id[r] = count;
                count += 1;
            }
            id[r]
        })
        .collect();
    (cluster, count)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Topology;

    /// Three unit-spaced tetrahedra: the first two 0.05 apart, the third 2 units away.
    fn three() -> TriMesh {
        let tet = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mut positions = Vec::new();
        for dx in [0.0, 1.05, 4.0] {
            positions.extend(tet.iter().map(|p| [p[0] + dx, p[1], p[2]]));
        }
        let f = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        let faces = (0..3).flat_map(|i| f.iter().map(move |t| t.map(|v| v + 4 * i))).collect();
        TriMesh::new(positions, faces)
    }

    #[test]
    fn pieces_within_the_gap_form_one_cluster() {
        let m = three();
        let (piece, pieces) = Topology::new(m.n_vertices(), &m.faces).components();
        let clusters = |gap| touching_clusters(&m, &piece, pieces, gap);
        let (c, n) = clusters(0.1);
        assert_eq!(n, 2);
        assert!(c[..8].iter().all(|&x| x == c[0]) && c[8..].iter().all(|&x| x == c[8]) && c[0] != c[8]);
        // A smaller gap separates all three; a gap of 0 never joins.
        assert_eq!(clusters(0.04).1, 3);
        assert_eq!(clusters(0.0).1, 3);
        // Transitive: with gap 3 the far one touches the middle one (1.95 apart), so all join.
        assert_eq!(clusters(3.0).1, 1);
    }
}
