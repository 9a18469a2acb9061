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
//! **Cost.** Φ is zero between pins farther apart than their radii, so it is block diagonal
//! over the groups of pins whose bumps overlap (directly or through other pins): each group is
//! solved on its own, a dense LU of its size s (8·s² bytes, ~s³ operations). The groups are
//! found first, with one Dijkstra bounded by ρ_b per pin (work proportional to the vertices in
//! reach); a group of more than [`MAX_GROUP`] pins is refused with an error before anything of
//! its size is allocated, and the dense blocks are allocated fallibly (an allocation that fails
//! is an error, not an abort). Each pin's reach (vertex, weight) lists are kept from that first
//! search for the solve and the field while they fit 128 MiB; past that nothing of size pins ×
//! vertices is held: each pin's reach is searched again when its column is filled and when its
//! bump is added, a few hundred pins at a time. On the 29 299-vertex face with spread 0.2, 1 000
//! random pins take about a second and 10 000 (one group) under a minute and 0.9 GB; 20 000 are
//! refused within seconds.
//!
//! Factor once ([`PinSpread::new`]: the edge graph), spread many ([`PinSpread::field`]; a few
//! milliseconds for a few pins on 30 000 vertices).

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::graph_distance::EdgeGraph;
use crate::math::disjoint_set::DisjointSet;
use crate::math::vec3::norm;
use crate::mesh::{Vec3, bounding_box, dist};

/// A pin's radius is at least this many times its residual's length (module docs).
pub const FOLD_FREE: f64 = 3.0;

/// Most pins whose bumps overlap (one group of the module docs) that [`PinSpread::field`]
/// solves together: a dense system of this size takes 800 MB and tens of seconds.
pub const MAX_GROUP: usize = 10_000;

/// Pins searched at a time while their reach is used (bounds the memory of the reach lists).
const RUN: usize = 256;

/// Most (vertex, weight) entries of the pins' reach kept from the first search for the solve
/// and the field (128 MiB); past this each pin's reach is searched again when needed.
const KEPT_ENTRIES: usize = 8 << 20;

/// Added to Φ's diagonal (module docs).
const RIDGE: f64 = 1e-9;

/// Each pin's reach: (vertex, weight) lists, one per pin.
type Reaches = Vec<Vec<(usize, f64)>>;

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

/// No pin at this vertex (in [`PinSpread::field`]'s vertex → pin map).
const NO_PIN: usize = usize::MAX;

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
    /// surface from every pin a. Pins must be distinct and < N; more than [`MAX_GROUP`] pins
    /// whose bumps overlap are refused (module docs).
    pub fn field(&self, pins: &[usize], residuals: &[Vec3], radius: f64) -> Result<Vec<Vec3>> {
        self.field_within(pins, residuals, radius, Bounds { max_group: MAX_GROUP, kept_entries: KEPT_ENTRIES })
    }

    /// [`Self::field`] within `bounds`.
    fn field_within(&self, pins: &[usize], residuals: &[Vec3], radius: f64, bounds: Bounds) -> Result<Vec<Vec3>> {
        let n = self.n_vertices();
        if pins.len() != residuals.len() {
            return Err(Error::Invalid(format!("{} pins and {} residuals", pins.len(), residuals.len())));
        }
        if !(radius.is_finite() && radius > 0.0) {
            return Err(Error::Invalid(format!("spread radius {radius}: must be a finite number > 0")));
        }
        let mut slot = vec![NO_PIN; n];
        for (a, &p) in pins.iter().enumerate() {
            if p >= n {
                return Err(Error::Invalid(format!("pin {p} out of range ({n} vertices)")));
            }
            if slot[p] != NO_PIN {
                return Err(Error::Invalid(format!("vertex {p} is pinned twice")));
            }
            slot[p] = a;
        }
        let radii: Vec<f64> = residuals.iter().map(|&r| radius.max(FOLD_FREE * norm(r))).collect();
        if radii.iter().any(|r| !r.is_finite()) {
            return Err(Error::Invalid("a pin's residual is not finite".into()));
        }
        let sys = System { pins, radii: &radii, slot: &slot };
        let (groups, kept) = crate::timing::timed("pin spread: groups", || self.groups(&sys, radius, bounds))?;
        let reach = Reach { spread: self, sys, kept };
        let mut coefficients = vec![[0.0; 3]; pins.len()];
        // Each pin's place in its group (a pin is in one group only).
        let mut local = vec![0usize; pins.len()];
        crate::timing::timed("pin spread: solve", || {
            for group in &groups {
                for (j, &a) in group.iter().enumerate() {
                    local[a] = j;
                }
                solve_group(group, &reach, &local, residuals, &mut coefficients)?;
            }
            Ok::<(), Error>(())
        })?;
        if coefficients.iter().flatten().any(|c| !c.is_finite()) {
            return Err(Error::Numerical("spreading the pins' residuals: the pin system is singular".into()));
        }
        // d(v) = Σ_b φ(g(v, p_b)/ρ_b) c_b, summed in pin order (the same numbers every run).
        let mut d = vec![[0.0; 3]; n];
        reach.each_in_order(|b, list| {
            for &(v, w) in list {
                for k in 0..3 {
                    d[v][k] += w * coefficients[b][k];
                }
            }
        });
        Ok(d)
    }

    /// (vertex, φ(g(v, p_b)/ρ_b)) for every vertex v in reach of each pin b of `run`, nearest
    /// first (searched in parallel).
    fn search(&self, run: &[usize], sys: &System<'_>) -> Vec<Vec<(usize, f64)>> {
        run.par_iter()
            .map_init(
                || self.graph.scratch(),
                |scratch, &b| {
                    let rho = sys.radii[b];
                    let mut list = Vec::new();
                    self.graph.for_each_within(sys.pins[b], rho, scratch, |v, g| list.push((v, wendland(g / rho))));
                    list
                },
            )
            .collect()
    }

    /// The groups of pins (indices into `pins`, ascending; groups ordered by their first pin)
    /// whose bumps overlap: b and a are in one group when p_a lies within ρ_b of p_b; and every
    /// pin's reach when all of them fit `bounds.kept_entries`. Errors as soon as a group passes
    /// `bounds.max_group` pins.
    fn groups(&self, sys: &System<'_>, radius: f64, bounds: Bounds) -> Result<(Vec<Vec<usize>>, Option<Reaches>)> {
        let Bounds { max_group, kept_entries } = bounds;
        let m = sys.pins.len();
        let mut sets = DisjointSet::new(m);
        let mut size = vec![1usize; m];
        let mut kept = Some(Vec::new());
        let mut entries = 0usize;
        let order: Vec<usize> = (0..m).collect();
        for run in order.chunks(RUN) {
            let lists = self.search(run, sys);
            for (&b, list) in run.iter().zip(&lists) {
                for &(v, _) in list {
                    let a = sys.slot[v];
                    if a == NO_PIN {
                        continue;
                    }
                    let (ra, rb) = (sets.find(a), sets.find(b));
                    if ra != rb {
                        sets.union(ra, rb);
                        let (root, other) = (ra.min(rb), ra.max(rb));
                        size[root] += size[other];
                        if size[root] > max_group {
                            return Err(Error::Invalid(format!(
                                "the landing correction of {m} pins: more than {max_group} of them lie within each other's \
                                 reach ({radius} data units along the surface, or 3 × a pin's residual), and the \
                                 correction solves at most {max_group} together; use fewer pins, a smaller spread, or \
                                 spread 0 (the model's shape only)"
                            )));
                        }
                    }
                }
            }
            entries += lists.iter().map(Vec::len).sum::<usize>();
            kept = kept.filter(|_| entries <= kept_entries).map(|mut k| {
                k.extend(lists);
                k
            });
        }
        let mut groups: Vec<Vec<usize>> = Vec::new();
        let mut index = vec![usize::MAX; m];
        for a in 0..m {
            let root = sets.find(a);
            if index[root] == usize::MAX {
                index[root] = groups.len();
                groups.push(Vec::new());
            }
            groups[index[root]].push(a);
        }
        Ok((groups, kept))
    }
}

/// What [`PinSpread::field`] allows: the most pins of one group, the most reach entries kept.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    max_group: usize,
    kept_entries: usize,
}

/// The pins of one [`PinSpread::field`] call: their vertices and radii, and the pin at each
/// vertex (`slot`, [`NO_PIN`] where none).
#[derive(Clone, Copy)]
struct System<'a> {
    pins: &'a [usize],
    radii: &'a [f64],
    slot: &'a [usize],
}

/// Each pin's reach, (vertex, φ) nearest first: the lists of the first search when they were
/// kept, else searched again [`RUN`] pins at a time.
struct Reach<'a> {
    spread: &'a PinSpread,
    sys: System<'a>,
    kept: Option<Vec<Vec<(usize, f64)>>>,
}

impl Reach<'_> {
    /// `f(b, reach of b)` for the pins b of `pins` (indices into the system's pins), in order.
    fn each(&self, pins: &[usize], mut f: impl FnMut(usize, &[(usize, f64)])) {
        match &self.kept {
            Some(kept) => pins.iter().for_each(|&b| f(b, &kept[b])),
            None => {
                for run in pins.chunks(RUN) {
                    for (&b, list) in run.iter().zip(self.spread.search(run, &self.sys)) {
                        f(b, &list);
                    }
                }
            }
        }
    }

    /// `f(b, reach of b)` for every pin, in order.
    fn each_in_order(&self, f: impl FnMut(usize, &[(usize, f64)])) {
        let all: Vec<usize> = (0..self.sys.pins.len()).collect();
        self.each(&all, f);
    }
}

/// Solves Φ c = r on one group (module docs) into `coefficients`: a dense LU with partial
/// pivoting of its s × s matrix, allocated fallibly; `local[a]`: pin a's place in its group.
fn solve_group(
    group: &[usize],
    reach: &Reach<'_>,
    local: &[usize],
    residuals: &[Vec3],
    coefficients: &mut [Vec3],
) -> Result<()> {
    use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
    use faer::linalg::lu::partial_pivoting::{factor, solve};
    let s = group.len();
    if s == 1 {
        let a = group[0];
        coefficients[a] = residuals[a].map(|r| r / (1.0 + RIDGE));
        return Ok(());
    }
    let too_large = |what: &str| {
        Error::Invalid(format!(
            "the landing correction of {s} pins whose bumps overlap: could not allocate {what} ({} MB)",
            8 * s * s / 1_000_000
        ))
    };
    // Φ of the group, column-major: column j holds φ(g(p_a, p_b)/ρ_b) for b = group[j].
    let mut phi: Vec<f64> = Vec::new();
    phi.try_reserve_exact(s * s).map_err(|_| too_large("the pins' system"))?;
    phi.resize(s * s, 0.0);
    let slot = reach.sys.slot;
    reach.each(group, |b, list| {
        let column = &mut phi[local[b] * s..(local[b] + 1) * s];
        for &(v, w) in list {
            if slot[v] != NO_PIN {
                column[local[slot[v]]] = w;
            }
        }
    });
    for j in 0..s {
        phi[j * s + j] += RIDGE;
    }
    let par = faer::get_global_parallelism();
    let scratch = StackReq::any_of(&[
        factor::lu_in_place_scratch::<usize, f64>(s, s, par, Default::default()),
        solve::solve_in_place_scratch::<usize, f64>(s, 3, par),
    ]);
    let mut buffer = MemBuffer::try_new(scratch).map_err(|_| too_large("the factorisation's work space"))?;
    let stack = MemStack::new(&mut buffer);
    let (mut forward, mut inverse) = (vec![0usize; s], vec![0usize; s]);
    let mut lu = faer::MatMut::from_column_major_slice_mut(&mut phi, s, s);
    let (_, perm) = factor::lu_in_place(lu.as_mut(), &mut forward, &mut inverse, par, stack, Default::default());
    let mut rhs = faer::Mat::<f64>::from_fn(s, 3, |j, k| residuals[group[j]][k]);
    // L (unit lower, below the diagonal) and U (upper) share the factored matrix.
    solve::solve_in_place(lu.as_ref(), lu.as_ref(), perm, rhs.as_mut(), par, stack);
    for (j, &a) in group.iter().enumerate() {
        coefficients[a] = [rhs[(j, 0)], rhs[(j, 1)], rhs[(j, 2)]];
    }
    Ok(())
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
        let e = s.field(&[7, 3, 7], &[[0.0; 3]; 3], 0.1).unwrap_err().to_string();
        assert!(e.contains("vertex 7 is pinned twice"), "{e}");
    }

    /// The field as one dense solve over every pin (the definition in the module docs).
    fn dense_field(s: &PinSpread, pins: &[usize], r: &[Vec3], radius: f64) -> Vec<Vec3> {
        use faer::linalg::solvers::Solve;
        let m = pins.len();
        let radii: Vec<f64> = r.iter().map(|&x| radius.max(FOLD_FREE * norm(x))).collect();
        let reach: Vec<_> = pins.iter().zip(&radii).map(|(&p, &rho)| s.graph.distances_within(p, rho)).collect();
        let phi = faer::Mat::<f64>::from_fn(m, m, |a, b| {
            let g = reach[b].iter().find(|e| e.0 == pins[a]).map_or(f64::INFINITY, |e| e.1);
            wendland(g / radii[b]) + if a == b { RIDGE } else { 0.0 }
        });
        let mut c = faer::Mat::<f64>::from_fn(m, 3, |a, k| r[a][k]);
        phi.partial_piv_lu().solve_in_place(c.as_mut());
        let mut d = vec![[0.0; 3]; s.n_vertices()];
        for (b, list) in reach.iter().enumerate() {
            for &(v, g) in list {
                for k in 0..3 {
                    d[v][k] += wendland(g / radii[b]) * c[(b, k)];
                }
            }
        }
        d
    }

    #[test]
    fn groups_solved_apart_give_the_one_dense_solve() {
        // Three groups on the 21 × 21 grid (pins 0.05 apart; radius 0.12): a row of four pins
        // near one corner, a pair near the middle with one long drag (radius 0.3 for it: it
        // reaches two more pins, which join its group), and two pins alone.
        let (p, f) = grid();
        let s = PinSpread::new(&p, &f);
        let at = |i: usize, j: usize| 21 * j + i;
        let pins = [
            at(1, 1),
            at(2, 1),
            at(3, 1),
            at(4, 1),
            at(10, 10),
            at(11, 10),
            at(14, 10),
            at(15, 12),
            at(19, 19),
            at(1, 19),
        ];
        let r: Vec<Vec3> = (0..pins.len())
            .map(|a| {
                let t = a as f64;
                [0.01 * (t + 1.0), -0.004 * t, if a == 4 { 0.1 } else { 0.003 * (t - 4.0) }]
            })
            .collect();
        let radius = 0.12;
        let want = dense_field(&s, &pins, &r, radius);
        for kept_entries in [0, 1000, usize::MAX] {
            let d = s.field_within(&pins, &r, radius, Bounds { max_group: MAX_GROUP, kept_entries }).unwrap();
            for (v, (x, y)) in d.iter().zip(&want).enumerate() {
                for k in 0..3 {
                    assert!(
                        (x[k] - y[k]).abs() <= 1e-12 * (1.0 + y[k].abs()),
                        "kept {kept_entries}, vertex {v}: {x:?} vs {y:?}"
                    );
                }
            }
            for (a, &v) in pins.iter().enumerate() {
                for k in 0..3 {
                    assert!((d[v][k] - r[a][k]).abs() < 1e-8, "pin {v} does not land");
                }
            }
        }
        // The groups themselves: the row, the drag with the two pins it reaches, and the ones alone.
        let radii: Vec<f64> = r.iter().map(|&x| radius.max(FOLD_FREE * norm(x))).collect();
        let mut slot = vec![NO_PIN; s.n_vertices()];
        for (a, &v) in pins.iter().enumerate() {
            slot[v] = a;
        }
        let sys = System { pins: &pins, radii: &radii, slot: &slot };
        let bounds = Bounds { max_group: MAX_GROUP, kept_entries: usize::MAX };
        let (groups, kept) = s.groups(&sys, radius, bounds).unwrap();
        assert_eq!(groups, vec![vec![0, 1, 2, 3], vec![4, 5, 6, 7], vec![8], vec![9]]);
        assert_eq!(kept.unwrap().len(), pins.len());
        // Reach lists kept while they fit, dropped past the bound.
        let total: usize = pins.iter().zip(&radii).map(|(&q, &rho)| s.graph.distances_within(q, rho).len()).sum();
        let (_, kept) = s.groups(&sys, radius, Bounds { kept_entries: total, ..bounds }).unwrap();
        assert!(kept.is_some());
        let (_, kept) = s.groups(&sys, radius, Bounds { kept_entries: total - 1, ..bounds }).unwrap();
        assert!(kept.is_none());
        // A group of exactly the bound is solved; one more pin in it is refused, naming the bound.
        let (groups, _) = s.groups(&sys, radius, Bounds { max_group: 4, ..bounds }).unwrap();
        assert_eq!(groups.len(), 4);
        let e = s.field_within(&pins, &r, radius, Bounds { max_group: 3, ..bounds }).unwrap_err().to_string();
        assert!(e.contains("more than 3 of them") && e.contains("spread 0"), "{e}");
    }

    #[test]
    fn many_pins_far_apart_are_each_their_own_group() {
        // Every vertex of a 101 × 101 grid pinned with a radius below the edge length: 10 201
        // groups of one (a dense system would take 830 MB); each pin moves by r / (1 + 1e-9)
        // and nothing else moves.
        let m = primitives::grid(100, 100, 1.0);
        let s = PinSpread::new(&m.positions, &m.faces);
        let pins: Vec<usize> = (0..m.n_vertices()).collect();
        let r: Vec<Vec3> = pins.iter().map(|&v| [1e-4 * (v % 7) as f64, 0.0, -1e-4]).collect();
        let d = s.field(&pins, &r, 0.005).unwrap();
        for (v, x) in d.iter().enumerate() {
            assert_eq!(*x, r[v].map(|c| c / (1.0 + RIDGE)), "vertex {v}");
        }
        // More overlapping pins than a group may hold: refused before a dense system is built.
        let e = s.field(&pins, &r, 0.5).unwrap_err().to_string();
        assert!(e.contains(&format!("more than {MAX_GROUP}")), "{e}");
    }
}
