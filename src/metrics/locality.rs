//! Support size and connected support regions of a deformation component.
//!
//! A component assigns every element e (vertex or triangle) a group norm ‖C_k,e‖ (the length of
//! its W numbers). Its **support** is the set of elements whose norm exceeds
//! `rel_threshold × max_e ‖C_k,e‖`; the **support regions** are the connected components of the
//! support in the element adjacency graph (vertices: mesh edges; triangles: shared edges). A
//! localized component (SPLOCS) has one region; a global one (PCA) has one region covering
//! almost the whole mesh; a component that moves two distant parts at once (the eyebrows of
//! Neumann et al. §4.1) has two.
//!
//! The evaluation uses [`SUPPORT_THRESHOLD`] = 1 % of the component's peak norm, so that
//! numerically tiny but non-zero values (the autoencoder's dense latent rows, PCA) do not count
//! as support; SPLOCS's exact zeros are unaffected by the choice.

use crate::error::{Error, Result};

/// Relative threshold of the evaluation's support: elements above 1 % of the peak group norm.
pub const SUPPORT_THRESHOLD: f64 = 0.01;

/// Support statistics of one component.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SupportRegions {
    /// Number of support elements.
    pub size: usize,
    /// Number of connected support regions (0 for an all-zero component).
    pub regions: usize,
}

/// Support size and number of connected support regions of a component with per-element
/// `group_norms` (E values, ≥ 0) in the graph `adjacency` (E neighbour lists, symmetric),
/// support = norms `> rel_threshold · max` (and > 0). Errors on a length mismatch, a neighbour
/// index ≥ E, a non-finite norm or a threshold outside [0, 1].
pub fn support_regions(group_norms: &[f64], adjacency: &[Vec<usize>], rel_threshold: f64) -> Result<SupportRegions> {
    let e = group_norms.len();
    if adjacency.len() != e {
        return Err(Error::Invalid(format!("support regions: {e} norms but {} adjacency lists", adjacency.len())));
    }
    if !(0.0..=1.0).contains(&rel_threshold) {
        return Err(Error::Invalid(format!("support regions: threshold {rel_threshold} must lie in [0, 1]")));
    }
    if let Some(i) = group_norms.iter().position(|x| !x.is_finite()) {
        return Err(Error::Invalid(format!("support regions: norm {i} is not finite ({})", group_norms[i])));
    }
    let max = group_norms.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    let inside: Vec<bool> = group_norms.iter().map(|&n| n.abs() > rel_threshold * max && n != 0.0).collect();
    let size = inside.iter().filter(|&&b| b).count();
    let mut seen = vec![false; e];
    let mut regions = 0;
    let mut stack = Vec::new();
    for s in 0..e {
        if !inside[s] || seen[s] {
            continue;
        }
        regions += 1;
        seen[s] = true;
        stack.push(s);
        while let Some(v) = stack.pop() {
            for &u in &adjacency[v] {
                if u >= e {
                    return Err(Error::Invalid(format!("support regions: element {v} has neighbour {u} ≥ {e}")));
                }
                if inside[u] && !seen[u] {
                    seen[u] = true;
                    stack.push(u);
                }
            }
        }
    }
    Ok(SupportRegions { size, regions })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A path graph 0 - 1 - 2 - … - (n−1).
    fn path(n: usize) -> Vec<Vec<usize>> {
        (0..n).map(|i| [i.checked_sub(1), (i + 1 < n).then_some(i + 1)].into_iter().flatten().collect()).collect()
    }

    #[test]
    fn counts_connected_regions_above_the_threshold() {
        let adj = path(8);
        // Two islands {1,2} and {5}; 0.005 at 7 is below 1 % of the peak 1.0.
        let norms = [0.0, 1.0, 0.5, 0.0, 0.0, 0.2, 0.0, 0.005];
        assert_eq!(support_regions(&norms, &adj, 0.01).unwrap(), SupportRegions { size: 3, regions: 2 });
        // With a zero threshold the tiny value is a third island.
        assert_eq!(support_regions(&norms, &adj, 0.0).unwrap(), SupportRegions { size: 4, regions: 3 });
        // Filling the gap joins the islands.
        let joined = [0.0, 1.0, 0.5, 0.3, 0.3, 0.2, 0.0, 0.0];
        assert_eq!(support_regions(&joined, &adj, 0.01).unwrap(), SupportRegions { size: 5, regions: 1 });
        assert_eq!(support_regions(&[0.0; 8], &adj, 0.01).unwrap(), SupportRegions { size: 0, regions: 0 });
    }

    #[test]
    fn counts_regions_on_a_mesh() {
        // Grid vertices: support in two opposite corners is two regions, the whole grid one.
        let g = crate::mesh::primitives::grid(6, 6, 1.0);
        let topo = crate::mesh::Topology::new(g.n_vertices(), &g.faces);
        let adj: Vec<Vec<usize>> = (0..g.n_vertices()).map(|v| topo.neighbors(v).to_vec()).collect();
        let mut norms = vec![0.0; g.n_vertices()];
        norms[0] = 1.0;
        norms[g.n_vertices() - 1] = 1.0;
        assert_eq!(support_regions(&norms, &adj, 0.01).unwrap().regions, 2);
        assert_eq!(support_regions(&vec![1.0; g.n_vertices()], &adj, 0.01).unwrap().regions, 1);
    }

    #[test]
    fn rejects_bad_input() {
        assert!(support_regions(&[1.0, 2.0], &path(3), 0.01).is_err());
        assert!(support_regions(&[1.0, f64::NAN], &path(2), 0.01).is_err());
        assert!(support_regions(&[1.0, 1.0], &[vec![1], vec![5]], 0.01).is_err());
        assert!(support_regions(&[1.0], &path(1), 1.5).is_err());
    }
}
