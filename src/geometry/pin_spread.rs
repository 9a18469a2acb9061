//! Pin spreading: the smooth, local displacement field that moves each pin by a given residual
//! and leaves everything farther than a radius from every pin in place.
//!
//! With pins p_1 … p_n, residuals r_a (what a pose left between pin a and its target, data
//! units) and a radius ρ (length units of the mesh), the field is
//!
//! ```text
//!   d(v) = Σ_b φ(g(v, p_b) / ρ_b) · c_b,    φ(t) = (1 − t)⁴ (4t + 1) for t < 1, else 0,
//!   ρ_b = max(ρ, 3‖r_b‖)
//! ```
//!
//! with g the edge-path distance on the rest mesh ([`super::graph_distance`]) and the
//! coefficients c (n × 3) solving Φ c = r, Φ_ab = φ(g(p_a, p_b) / ρ_b) (φ(0) = 1 on the
//! diagonal), so that d(p_a) = r_a exactly. φ is Wendland's C² function: smooth, 1 at the pin,
//! 0 beyond ρ_b along the surface (so a drag of the lower lip does not move the upper lip, which
//! is near in space but far along the surface). A pin's radius grows with its residual
//! ([`FOLD_FREE`] × ‖r_b‖): the bump's steepest slope is 2.11·‖r_b‖/ρ_b (|φ'| peaks at t = ¼), so
//! it stays below 0.71 and one pin's correction cannot fold the surface over, however far the
//! pin is dragged. A pin whose residual is zero (a held point) keeps its place: the field is
//! zero there. Φ is not symmetric when radii differ, nor guaranteed definite with edge-path
//! distances, so it is solved by LU with partial pivoting after adding 10⁻⁹ to the diagonal
//! (pins closer than the mesh's resolution still give a finite field).
//!
//! Factor once ([`PinSpread::new`]: the edge graph), spread many ([`PinSpread::field`]: one
//! Dijkstra bounded by ρ per pin and an n × n solve; a few milliseconds on 30 000 vertices).

use faer::Mat;
use faer::linalg::solvers::Solve;

use crate::error::{Error, Result};
use crate::geometry::graph_distance::EdgeGraph;
use crate::math::vec3::norm;
use crate::mesh::{Vec3, bounding_box, dist};

/// A pin's radius is at least this many times its residual's length (module docs).
pub const FOLD_FREE: f64 = 3.0;

/// Wendland's C² function φ(t) = (1 − t)⁴ (4t + 1) on [0, 1), 0 from 1 on; t ≥ 0.
pub fn wendland(t: f64) -> f64 {
    if t >= 1.0 {
        return 0.0;
    }
    let s = 1.0 - t;
    s * s * s * s * (4.0 * t + 1.0)
}

/// The edge graph of a rest mesh, ready to spread residuals of any set of pins.
#[derive(Debug, Clone)]
pub struct PinSpread {
    graph: EdgeGraph,
    diagonal: f64,
}

impl PinSpread {
    /// The graph of `faces` over `positions` (the rest mesh, data units).
    pub fn new(positions: &[Vec3], faces: &[[usize; 3]]) -> Self {
        let (lo, hi) = bounding_box(positions);
        PinSpread { graph: EdgeGraph::new(positions, faces), diagonal: dist(lo, hi) }
    }

    /// Bounding-box diagonal of the rest mesh (data units): the unit of a relative radius.
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.graph.n_vertices()
    }

    /// The displacement field (N vectors, data units) with `d(pins[a]) = residuals[a]`, zero
    /// farther than `max(radius, FOLD_FREE·‖residuals[a]‖)` (data units; `radius` > 0) along the
    /// surface from every pin a. Pins must be distinct and < N.
    pub fn field(&self, pins: &[usize], residuals: &[Vec3], radius: f64) -> Result<Vec<Vec3>> {
        let n = self.n_vertices();
        if pins.len() != residuals.len() {
            return Err(Error::Invalid(format!("{} pins and {} residuals", pins.len(), residuals.len())));
        }
        if !(radius.is_finite() && radius > 0.0) {
            return Err(Error::Invalid(format!("spread radius {radius}: must be a finite number > 0")));
        }
        if let Some(&p) = pins.iter().find(|&&p| p >= n) {
            return Err(Error::Invalid(format!("pin {p} out of range ({n} vertices)")));
        }
        let m = pins.len();
        let radii: Vec<f64> = residuals.iter().map(|&r| radius.max(FOLD_FREE * norm(r))).collect();
        if radii.iter().any(|r| !r.is_finite()) {
            return Err(Error::Invalid("a pin's residual is not finite".into()));
        }
        let reach: Vec<Vec<(usize, f64)>> =
            pins.iter().zip(&radii).map(|(&p, &rho)| self.graph.distances_within(p, rho)).collect();
        // Φ_ab = φ(g(p_a, p_b)/ρ_b); the distance lists give column b at every vertex in reach.
        let mut slot = vec![usize::MAX; n];
        for (a, &p) in pins.iter().enumerate() {
            slot[p] = a;
        }
        let mut phi = Mat::<f64>::zeros(m, m);
        for (b, list) in reach.iter().enumerate() {
            for &(v, g) in list {
                if slot[v] != usize::MAX {
                    phi[(slot[v], b)] = wendland(g / radii[b]);
                }
            }
        }
        for a in 0..m {
            phi[(a, a)] += 1e-9;
        }
        let mut rhs = Mat::<f64>::from_fn(m, 3, |a, k| residuals[a][k]);
        phi.partial_piv_lu().solve_in_place(rhs.as_mut());
        if (0..m).any(|a| (0..3).any(|k| !rhs[(a, k)].is_finite())) {
            return Err(Error::Numerical("spreading the pins' residuals: the pin system is singular".into()));
        }
        let mut d = vec![[0.0; 3]; n];
        for (b, list) in reach.iter().enumerate() {
            for &(v, g) in list {
                let w = wendland(g / radii[b]);
                for k in 0..3 {
                    d[v][k] += w * rhs[(b, k)];
                }
            }
        }
        Ok(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives;

    fn grid() -> (Vec<Vec3>, Vec<[usize; 3]>) {
        let m = primitives::grid(20, 20, 1.0);
        (m.positions, m.faces)
    }

    #[test]
    fn wendland_is_one_at_zero_zero_at_one_and_smooth() {
        assert_eq!(wendland(0.0), 1.0);
        assert_eq!(wendland(1.0), 0.0);
        assert_eq!(wendland(2.0), 0.0);
        // φ'(t) = −20 t (1 − t)³: zero slope at both ends.
        let h = 1e-6;
        assert!(((wendland(h) - wendland(0.0)) / h).abs() < 1e-4);
        assert!(((wendland(1.0) - wendland(1.0 - h)) / h).abs() < 1e-4);
        let t: f64 = 0.3;
        let fd = (wendland(t + h) - wendland(t - h)) / (2.0 * h);
        assert!((fd + 20.0 * t * (1.0 - t).powi(3)).abs() < 1e-6, "{fd}");
    }

    #[test]
    fn pins_move_by_their_residuals_and_far_vertices_stay() {
        let (p, f) = grid();
        let s = PinSpread::new(&p, &f);
        assert!((s.diagonal() - 2f64.sqrt()).abs() < 1e-12);
        let pins = [220, 224, 100]; // (10, 10), (14, 10), (16, 4) on the 21 × 21 vertex grid
        let r = [[0.0, 0.0, 0.1], [0.02, -0.01, 0.0], [0.0, 0.0, 0.0]];
        let radius = 0.25;
        let d = s.field(&pins, &r, radius).unwrap();
        for (a, &v) in pins.iter().enumerate() {
            for k in 0..3 {
                assert!((d[v][k] - r[a][k]).abs() < 1e-8, "pin {v}: {:?} vs {:?}", d[v], r[a]);
            }
        }
        let dist = |u: usize, v: usize| ((p[u][0] - p[v][0]).powi(2) + (p[u][1] - p[v][1]).powi(2)).sqrt();
        // Each pin's radius: max(0.25, 3 × its residual's length): 0.3 for the first.
        let radii = [0.3, radius, radius];
        let mut moved = 0;
        for (v, dv) in d.iter().enumerate() {
            let far = pins.iter().zip(&radii).all(|(&q, &r)| dist(q, v) >= r + 1e-9);
            if far {
                assert_eq!(*dv, [0.0; 3], "vertex {v} beyond the radius moved");
            } else if *dv != [0.0; 3] {
                moved += 1;
            }
        }
        assert!(moved > 10, "the field should reach the pins' neighbours ({moved})");
        // The field is no larger than the largest residual by much (no overshoot spikes).
        let top = d.iter().map(|x| x.iter().map(|c| c * c).sum::<f64>().sqrt()).fold(0.0, f64::max);
        assert!(top <= 0.1 * 1.05, "{top}");
    }

    #[test]
    fn a_long_drag_widens_its_radius_and_does_not_fold() {
        // One pin dragged 0.3 in the grid's plane with a radius of 0.1: a bump of radius 0.1
        // would fold the grid over (slope 2.11 × 0.3 / 0.1 = 6.3); the widened radius (0.9)
        // keeps every triangle's orientation.
        let (p, f) = grid();
        let s = PinSpread::new(&p, &f);
        let pin = 220;
        let d = s.field(&[pin], &[[0.3, 0.0, 0.0]], 0.1).unwrap();
        assert!((d[pin][0] - 0.3).abs() < 1e-9);
        let area = |q: &[Vec3], t: &[usize; 3]| {
            let (a, b, c) = (q[t[0]], q[t[1]], q[t[2]]);
            (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        };
        let moved: Vec<Vec3> = p.iter().zip(&d).map(|(x, y)| [x[0] + y[0], x[1] + y[1], x[2] + y[2]]).collect();
        for t in &f {
            assert!(area(&moved, t) > 0.0, "triangle {t:?} folded over");
        }
        // A bump of radius 0.1 would fold: along the drag, x ↦ x + 0.3 φ(x / 0.1) decreases
        // where φ' < −1/3 (at x = 0.025, φ' = −2.11).
        let h = 1e-6;
        let map = |x: f64| x + 0.3 * wendland(x / 0.1);
        assert!(map(0.025 + h) < map(0.025), "the fixed-radius bump would not fold");
    }

    #[test]
    fn distance_is_along_the_surface() {
        // Two strips joined at one end only: a vertex across the gap is near in space, far along
        // the surface, and must not move.
        let mut p = Vec::new();
        let mut f = Vec::new();
        let cols = 20;
        for row in 0..4 {
            for c in 0..=cols {
                let y = if row < 2 { row as f64 * 0.05 } else { 0.12 + (row - 2) as f64 * 0.05 };
                p.push([c as f64 * 0.05, y, 0.0]);
            }
        }
        let w = cols + 1;
        for row in [0usize, 2] {
            for c in 0..cols {
                let a = row * w + c;
                f.push([a, a + 1, a + w + 1]);
                f.push([a, a + w + 1, a + w]);
            }
        }
        // Join the strips at the far end (c = cols - 1 .. cols).
        let (a, b) = (w + cols - 1, 2 * w + cols - 1);
        f.push([a, a + 1, b + 1]);
        f.push([a, b + 1, b]);
        let s = PinSpread::new(&p, &f);
        let pin = w; // row 1, column 0
        let across = 2 * w; // row 2, column 0: 0.07 away in space
        let d = s.field(&[pin], &[[0.0, 0.0, 0.1]], 0.3).unwrap();
        assert!(d[pin][2] > 0.099);
        assert_eq!(d[across], [0.0; 3]);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let (p, f) = grid();
        let s = PinSpread::new(&p, &f);
        assert!(s.field(&[0], &[[0.0; 3]], 0.0).is_err());
        assert!(s.field(&[0], &[[0.0; 3]], f64::NAN).is_err());
        assert!(s.field(&[1000], &[[0.0; 3]], 0.1).is_err());
        assert!(s.field(&[0, 1], &[[0.0; 3]], 0.1).is_err());
    }
}
