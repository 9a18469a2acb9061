//! Support maps of SPLOCS (Neumann et al. 2013, Eq. 6) and the distance providers they need.
//!
//! For component k with centre set J_k, d_k,e is the distance of element e to J_k on the rest
//! mesh; the *support ramp* is `clamp((d − d_min) / (d_max − d_min), 0, 1)`: 0 inside d_min,
//! a linear ramp, 1 beyond d_max. The regularisation weight is Λ_k,e = λ · ramp(d_k,e) and the
//! deflation initialisation masks with 1 − ramp. The *support region* of a component is
//! {e : d_k,e < d_max} (Λ below λ).

use serde::{Deserialize, Serialize};
use std::collections::HashMap;

use crate::{Error, Result};

/// Distances on the rest mesh from a set of centre elements, in the units the support range
/// [d_min, d_max] is expressed in.
///
/// For SPLOCS as in the paper and its reference implementation: geodesic distances (heat
/// method, m = 10) on the rest mesh scaled into the unit box (largest bounding-box side 1),
/// *not* further normalised. Elements are vertices for width-3 displacement data and triangles
/// for width-9 triangle-gradient data (see [`TriangleSupport`] for turning a vertex provider
/// into a triangle provider).
pub trait SupportDistances {
    /// Number of elements E the provider returns distances for.
    fn n_elements(&self) -> usize;

    /// Distance of every element (E values, ≥ 0, 0 on the centres) to the nearest element of
    /// `centers` (non-empty, indices < E).
    fn distances(&self, centers: &[usize]) -> Result<Vec<f64>>;

    /// Distances for several centre sets (one `Vec` of E values per set). The default calls
    /// [`SupportDistances::distances`] for each; override it to batch the solves (e.g. one
    /// multi-right-hand-side solve of the heat method) or to run them in parallel.
    fn distances_many(&self, center_sets: &[Vec<usize>]) -> Result<Vec<Vec<f64>>> {
        center_sets.iter().map(|c| self.distances(c)).collect()
    }
}

impl<T: SupportDistances + ?Sized> SupportDistances for &T {
    fn n_elements(&self) -> usize {
        (**self).n_elements()
    }
    fn distances(&self, centers: &[usize]) -> Result<Vec<f64>> {
        (**self).distances(centers)
    }
    fn distances_many(&self, center_sets: &[Vec<usize>]) -> Result<Vec<Vec<f64>>> {
        (**self).distances_many(center_sets)
    }
}

/// Per-triangle distances from a per-vertex provider: the centre triangles' corners are the
/// source vertices, and a triangle's distance is the **mean of its three corner distances**
/// (so a centre triangle has distance 0). Huang et al. 2014 use centroid-to-centroid geodesics
/// on the 1-to-3 subdivided mesh; the corner mean is a cheaper stand-in that differs from it
/// by at most about one edge length.
pub struct TriangleSupport<'a, P: SupportDistances + ?Sized> {
    vertex_distances: &'a P,
    faces: &'a [[usize; 3]],
}

impl<'a, P: SupportDistances + ?Sized> TriangleSupport<'a, P> {
    /// Wraps a vertex provider; errors when a face refers to a vertex the provider lacks.
    pub fn new(vertex_distances: &'a P, faces: &'a [[usize; 3]]) -> Result<Self> {
        let n = vertex_distances.n_elements();
        if let Some((t, f)) = faces.iter().enumerate().find(|(_, f)| f.iter().any(|&v| v >= n)) {
            return Err(Error::Invalid(format!(
                "triangle {t} {f:?} refers to a vertex ≥ {n} (vertex count of the provider)"
            )));
        }
        Ok(TriangleSupport { vertex_distances, faces })
    }

    fn sources(&self, centers: &[usize]) -> Result<Vec<usize>> {
        let mut src = Vec::with_capacity(3 * centers.len());
        for &t in centers {
            let f = self.faces.get(t).ok_or_else(|| {
                Error::Invalid(format!("centre triangle {t} out of range ({} triangles)", self.faces.len()))
            })?;
            src.extend_from_slice(f);
        }
        src.sort_unstable();
        src.dedup();
        Ok(src)
    }

    fn to_triangles(&self, dv: &[f64]) -> Vec<f64> {
        self.faces.iter().map(|f| (dv[f[0]] + dv[f[1]] + dv[f[2]]) / 3.0).collect()
    }
}

impl<P: SupportDistances + ?Sized> SupportDistances for TriangleSupport<'_, P> {
    fn n_elements(&self) -> usize {
        self.faces.len()
    }
    fn distances(&self, centers: &[usize]) -> Result<Vec<f64>> {
        let dv = self.vertex_distances.distances(&self.sources(centers)?)?;
        Ok(self.to_triangles(&dv))
    }
    fn distances_many(&self, center_sets: &[Vec<usize>]) -> Result<Vec<Vec<f64>>> {
        let sets = center_sets.iter().map(|c| self.sources(c)).collect::<Result<Vec<_>>>()?;
        let dvs = self.vertex_distances.distances_many(&sets)?;
        Ok(dvs.iter().map(|dv| self.to_triangles(dv)).collect())
    }
}

/// Triangles having at least one corner in a (painted) vertex set, for turning a user's
/// painted vertex mask into triangle centres for triangle-gradient SPLOCS.
pub fn vertex_set_to_triangles(faces: &[[usize; 3]], vertices: &[usize]) -> Vec<usize> {
    let set: std::collections::HashSet<usize> = vertices.iter().copied().collect();
    faces.iter().enumerate().filter(|(_, f)| f.iter().any(|v| set.contains(v))).map(|(t, _)| t).collect()
}

/// Support ramp of Eq. (6) without λ: 0 for d ≤ d_min, 1 for d ≥ d_max, linear in between.
#[inline]
pub fn support_ramp(d: f64, d_min: f64, d_max: f64) -> f64 {
    ((d.clamp(d_min, d_max) - d_min) / (d_max - d_min)).clamp(0.0, 1.0)
}

/// Locality statistics of one component (measured, so that "localized" is not only claimed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComponentLocality {
    /// Centre element (argmax of the group norm, or the first element of a user set).
    pub center: usize,
    /// Number of elements with a non-zero group norm (> 1e-12 × the component's largest).
    pub support_size: usize,
    /// Number of elements of the support region, d < d_max.
    pub region_size: usize,
    /// Share of the component's energy Σ‖C_k,e‖² inside the support region (1 for an
    /// all-zero component).
    pub energy_share: f64,
    /// Energy Σ_e ‖C_k,e‖² of the component (in the model's units squared).
    pub energy: f64,
}

/// Locality of one component given its group norms and its support ramp (d < d_max ⇔
/// ramp < 1).
pub fn component_locality(center: usize, group_norms: &[f64], ramp: &[f64]) -> ComponentLocality {
    let max = group_norms.iter().fold(0.0f64, |a, &b| a.max(b));
    let mut energy = 0.0;
    let mut inside = 0.0;
    let mut support_size = 0;
    let mut region_size = 0;
    for (&n, &r) in group_norms.iter().zip(ramp) {
        energy += n * n;
        if r < 1.0 {
            inside += n * n;
            region_size += 1;
        }
        if n > 1e-12 * max && n > 0.0 {
            support_size += 1;
        }
    }
    ComponentLocality {
        center,
        support_size,
        region_size,
        energy_share: if energy > 0.0 { inside / energy } else { 1.0 },
        energy,
    }
}

/// Cache of support ramps keyed by centre set, so that distances are computed only for
/// centres not seen before (centres rarely move between outer iterations). Holds at most
/// `capacity` maps (cleared when full); never an E × E matrix.
pub(crate) struct SupportCache {
    maps: HashMap<Vec<usize>, Vec<f64>>,
    capacity: usize,
    d_min: f64,
    d_max: f64,
    pub(crate) n_queries: usize,
}

impl SupportCache {
    pub(crate) fn new(d_min: f64, d_max: f64, capacity: usize) -> Self {
        SupportCache { maps: HashMap::new(), capacity: capacity.max(1), d_min, d_max, n_queries: 0 }
    }

    /// Makes sure the ramps of all `sets` are cached (one batched provider call for the
    /// missing ones) and checks the provider's output.
    pub(crate) fn ensure<P: SupportDistances + ?Sized>(&mut self, provider: &P, sets: &[Vec<usize>]) -> Result<()> {
        let mut missing: Vec<Vec<usize>> = Vec::new();
        for s in sets {
            if !self.maps.contains_key(s) && !missing.contains(s) {
                missing.push(s.clone());
            }
        }
        if missing.is_empty() {
            return Ok(());
        }
        if self.maps.len() + missing.len() > self.capacity {
            self.maps.retain(|k, _| sets.contains(k));
        }
        let e = provider.n_elements();
        let dists = provider.distances_many(&missing)?;
        if dists.len() != missing.len() {
            return Err(Error::Invalid(format!(
                "support distances: provider returned {} maps for {} centre sets",
                dists.len(),
                missing.len()
            )));
        }
        self.n_queries += missing.len();
        for (set, d) in missing.into_iter().zip(dists) {
            if d.len() != e {
                return Err(Error::Invalid(format!(
                    "support distances for centres {set:?}: {} values, expected {e}",
                    d.len()
                )));
            }
            // +∞ is the distance to another connected piece of the mesh: outside every support
            // (ramp 1). NaN and negative values are errors.
            if let Some(i) = d.iter().position(|v| v.is_nan() || *v < 0.0) {
                return Err(Error::Numerical(format!(
                    "support distances for centres {set:?}: element {i} has distance {}",
                    d[i]
                )));
            }
            let ramp = d.iter().map(|&v| support_ramp(v, self.d_min, self.d_max)).collect();
            self.maps.insert(set, ramp);
        }
        Ok(())
    }

    /// The cached ramp of `set` (call [`SupportCache::ensure`] first).
    pub(crate) fn ramp(&self, set: &[usize]) -> &[f64] {
        &self.maps[set]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Line(usize);
    impl SupportDistances for Line {
        fn n_elements(&self) -> usize {
            self.0
        }
        fn distances(&self, centers: &[usize]) -> Result<Vec<f64>> {
            Ok((0..self.0)
                .map(|i| centers.iter().map(|&c| (i as f64 - c as f64).abs()).fold(f64::INFINITY, f64::min))
                .collect())
        }
    }

    #[test]
    fn ramp_shape() {
        assert_eq!(support_ramp(0.05, 0.1, 0.7), 0.0);
        assert_eq!(support_ramp(0.1, 0.1, 0.7), 0.0);
        assert!((support_ramp(0.4, 0.1, 0.7) - 0.5).abs() < 1e-15);
        assert_eq!(support_ramp(0.7, 0.1, 0.7), 1.0);
        assert_eq!(support_ramp(3.0, 0.1, 0.7), 1.0);
    }

    #[test]
    fn triangle_support_is_corner_mean() {
        // strip of vertices 0..5 on a line, triangles (0,1,2), (1,2,3), (2,3,4)
        let faces = [[0, 1, 2], [1, 2, 3], [2, 3, 4]];
        let p = Line(5);
        let t = TriangleSupport::new(&p, &faces).unwrap();
        let d = t.distances(&[0]).unwrap();
        assert_eq!(d, vec![0.0, 1.0 / 3.0, 1.0]);
        assert_eq!(t.distances_many(&[vec![2]]).unwrap()[0], vec![1.0, 1.0 / 3.0, 0.0]);
        assert!(t.distances(&[7]).is_err());
        assert!(TriangleSupport::new(&p, &[[0, 1, 9]]).err().unwrap().to_string().contains("9"));
        assert_eq!(vertex_set_to_triangles(&faces, &[4]), vec![2]);
    }

    #[test]
    fn cache_queries_only_new_centres() {
        let p = Line(10);
        let mut c = SupportCache::new(1.0, 3.0, 100);
        c.ensure(&p, &[vec![0], vec![5], vec![0]]).unwrap();
        assert_eq!(c.n_queries, 2);
        c.ensure(&p, &[vec![5], vec![9]]).unwrap();
        assert_eq!(c.n_queries, 3);
        assert_eq!(c.ramp(&[5])[5], 0.0);
        assert_eq!(c.ramp(&[5])[7], 0.5);
        assert_eq!(c.ramp(&[5])[9], 1.0);
    }

    #[test]
    fn locality_counts() {
        let l = component_locality(0, &[2.0, 1.0, 0.0, 1.0], &[0.0, 0.5, 1.0, 1.0]);
        assert_eq!(l.support_size, 3);
        assert_eq!(l.region_size, 2);
        assert!((l.energy_share - 5.0 / 6.0).abs() < 1e-15);
    }
}
