//! Geodesic distance providers for support maps, built on [`HeatGeodesics`].
//!
//! Two normalisations are used by the methods (docs/design.md § Normalisation of distances):
//! - SPLOCS (Neumann et al.): distances on the rest mesh scaled into the unit box (largest
//!   bounding-box side = 1) — [`GeodesicSupport::unit_box`];
//! - the autoencoder (Tan et al.): distances divided by the largest pairwise geodesic distance,
//!   estimated by a double sweep (farthest vertex from the farthest vertex of vertex 0) —
//!   [`GeodesicSupport::max_normalised`].
//!
//! Distances are computed on demand per centre set (one heat-method query each, in parallel
//! over centre sets); no N×N matrix is ever formed.
//!
//! **Meshes in several pieces.** Geodesics do not leave a connected piece, so a vertex on
//! another piece is at distance +∞ (outside every support). Pieces that *touch* — some vertex
//! within [`TOUCH_GAP_EDGES`] mean rest edge lengths of the other piece (an eye in its socket, a
//! feather on a wing; [`touching_clusters`]) — are one body for supports: from a centre to a
//! vertex on another piece of its cluster the distance is the straight line between them (rest
//! positions, same normalisation), so a component of the head may carry the eye beside it.
//! Separate objects (farther apart) stay at +∞. (Issue 32: with +∞ between every piece, SPLOCS
//! could not give a body region the parts attached to it.)

use rayon::prelude::*;

use crate::error::Result;
use crate::geometry::heat_geodesics::HeatGeodesics;
use crate::geometry::touching_pieces::touching_clusters;
use crate::mesh::{Topology, TriMesh, Vec3, dist};
use crate::methods::support_map::SupportDistances;
use crate::preprocess::UnitBox;

/// Per-vertex geodesic distances from centre sets, multiplied by a fixed normalisation factor.
pub struct GeodesicSupport {
    heat: HeatGeodesics,
    factor: f64,
    /// Rest positions and the cluster of touching pieces of every vertex, when some pieces
    /// touch (module docs); `None` for a connected mesh or pieces that all stand apart.
    bridges: Option<(Vec<Vec3>, Vec<usize>)>,
}

/// Pieces closer than this many mean rest edge lengths (vertex to vertex) touch.
pub const TOUCH_GAP_EDGES: f64 = 2.0;

/// The rest positions and touching clusters of `rest`, when it has touching pieces.
fn bridges(rest: &TriMesh) -> Option<(Vec<Vec3>, Vec<usize>)> {
    let (piece, pieces) = Topology::new(rest.n_vertices(), &rest.faces).components();
    if pieces < 2 {
        return None;
    }
    let (cluster, clusters) = touching_clusters(rest, &piece, pieces, TOUCH_GAP_EDGES * rest.mean_edge_length());
    (clusters < pieces).then(|| (rest.positions.clone(), cluster))
}

impl GeodesicSupport {
    /// SPLOCS's convention: the rest mesh scaled into the unit box, heat-method factor `m`
    /// (the reference uses 10).
    pub fn unit_box(rest: &TriMesh, m: f64) -> Result<Self> {
        let b = UnitBox::fit(&rest.positions)?;
        let heat = HeatGeodesics::new(&rest.positions, &rest.faces, m)?;
        // Geodesic distances scale linearly with the mesh, so scaling the distances is the same
        // as scaling the mesh.
        Ok(GeodesicSupport { heat, factor: b.scale, bridges: bridges(rest) })
    }

    /// The autoencoder's convention: distances divided by the (double-sweep estimate of the)
    /// largest pairwise geodesic distance, heat-method factor `m`.
    pub fn max_normalised(rest: &TriMesh, m: f64) -> Result<Self> {
        let heat = HeatGeodesics::new(&rest.positions, &rest.faces, m)?;
        let max = heat.max_distance_estimate()?;
        if !(max.is_finite() && max > 0.0) {
            return Err(crate::Error::Numerical(format!("largest geodesic distance estimate is {max}")));
        }
        Ok(GeodesicSupport { heat, factor: 1.0 / max, bridges: bridges(rest) })
    }

    /// Normalisation factor applied to raw distances (data units → normalised).
    pub fn factor(&self) -> f64 {
        self.factor
    }

    /// Number of vertices.
    pub fn n_vertices(&self) -> usize {
        self.heat.n_vertices()
    }
}

impl SupportDistances for GeodesicSupport {
    fn n_elements(&self) -> usize {
        self.heat.n_vertices()
    }

    fn distances(&self, centers: &[usize]) -> Result<Vec<f64>> {
        let mut d = self.heat.distances(centers)?;
        if let Some((positions, cluster)) = &self.bridges {
            for (v, x) in d.iter_mut().enumerate() {
                if x.is_infinite() && cluster[v] != usize::MAX {
                    *x = centers
                        .iter()
                        .filter(|&&c| cluster[c] == cluster[v])
                        .map(|&c| dist(positions[v], positions[c]))
                        .fold(f64::INFINITY, f64::min);
                }
            }
        }
        for x in d.iter_mut() {
            *x *= self.factor;
        }
        Ok(d)
    }

    fn distances_many(&self, center_sets: &[Vec<usize>]) -> Result<Vec<Vec<f64>>> {
        center_sets.par_iter().map(|c| self.distances(c)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives::icosphere;

    /// Three unit icospheres: the second a hair's breadth from the first (touching), the third
    /// far away. From a centre on the first, the second gets straight-line distances and the
    /// third stays outside every support (+∞).
    #[test]
    fn touching_pieces_share_supports_and_separate_ones_do_not() {
        let s = icosphere(2);
        let n = s.n_vertices();
        let mut positions = s.positions.clone();
        let mut faces = s.faces.clone();
        for (i, dx) in [2.01, 10.0].into_iter().enumerate() {
            positions.extend(s.positions.iter().map(|p| [p[0] + dx, p[1], p[2]]));
            faces.extend(s.faces.iter().map(|f| f.map(|v| v + (i + 1) * n)));
        }
        let mesh = TriMesh::new(positions.clone(), faces);
        let g = GeodesicSupport::unit_box(&mesh, 10.0).unwrap();
        let centre = (0..n).max_by(|&a, &b| positions[a][0].total_cmp(&positions[b][0])).unwrap();
        let d = g.distances(&[centre]).unwrap();
        assert!(d[..n].iter().all(|x| x.is_finite()));
        for v in n..2 * n {
            let straight = dist(positions[v], positions[centre]) * g.factor();
            assert!((d[v] - straight).abs() < 1e-12, "vertex {v}: {} vs straight line {straight}", d[v]);
        }
        assert!(d[2 * n..].iter().all(|x| x.is_infinite()));
    }
}
