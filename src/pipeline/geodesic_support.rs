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

use rayon::prelude::*;

use crate::error::Result;
use crate::geometry::heat_geodesics::HeatGeodesics;
use crate::mesh::TriMesh;
use crate::methods::support_map::SupportDistances;
use crate::preprocess::UnitBox;

/// Per-vertex geodesic distances from centre sets, multiplied by a fixed normalisation factor.
pub struct GeodesicSupport {
    heat: HeatGeodesics,
    factor: f64,
}

impl GeodesicSupport {
    /// SPLOCS's convention: the rest mesh scaled into the unit box, heat-method factor `m`
    /// (the reference uses 10).
    pub fn unit_box(rest: &TriMesh, m: f64) -> Result<Self> {
        let b = UnitBox::fit(&rest.positions)?;
        let heat = HeatGeodesics::new(&rest.positions, &rest.faces, m)?;
        // Geodesic distances scale linearly with the mesh, so scaling the distances is the same
        // as scaling the mesh.
        Ok(GeodesicSupport { heat, factor: b.scale })
    }

    /// The autoencoder's convention: distances divided by the (double-sweep estimate of the)
    /// largest pairwise geodesic distance, heat-method factor `m`.
    pub fn max_normalised(rest: &TriMesh, m: f64) -> Result<Self> {
        let heat = HeatGeodesics::new(&rest.positions, &rest.faces, m)?;
        let max = heat.max_distance_estimate()?;
        if !(max.is_finite() && max > 0.0) {
            return Err(crate::Error::Numerical(format!("largest geodesic distance estimate is {max}")));
        }
        Ok(GeodesicSupport { heat, factor: 1.0 / max })
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
        for x in d.iter_mut() {
            *x *= self.factor;
        }
        Ok(d)
    }

    fn distances_many(&self, center_sets: &[Vec<usize>]) -> Result<Vec<Vec<f64>>> {
        center_sets.par_iter().map(|c| self.distances(c)).collect()
    }
}
