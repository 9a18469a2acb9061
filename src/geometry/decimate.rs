//! Mesh simplification by quadric-error edge collapse (Garland & Heckbert 1997): a coarser
//! triangle mesh of about a target vertex count that keeps the surface's shape, its boundary
//! loops and its topology (genus, pieces, manifoldness).
//!
//! Each vertex carries the quadric Q (a symmetric 4×4 matrix) of the planes of its incident
//! triangles, weighted by their areas, plus, on a boundary edge, the plane through the edge
//! perpendicular to its triangle, weighted [`BOUNDARY_WEIGHT`]× the edge's squared length, so
//! the outline stays put. The edge of least cost vᵀ(Q_a + Q_b)v is collapsed first, into the
//! point v that minimises it (or, when that 3×3 system is singular, the best of the two ends
//! and the midpoint).
//!
//! A collapse is refused when it would change the topology — the two ends share a neighbour
//! that is not opposite the edge (the link condition), an interior edge joins two boundary
//! vertices, or a vertex opposite the edge would be left with fewer than 4 neighbours — or
//! when it would fold the surface: a surviving triangle whose normal turns by more than
//! about 78° (cosine below [`MIN_NORMAL_COSINE`]), a worst shape quality 4√3·area / Σ edge²
//! around the edge below [`MIN_QUALITY`] (and below the worst before), or an edge longer than
//! [`MAX_EDGE_FACTOR`] × the target resolution's edge length. Refused
//! edges are tried again after a neighbour changes.
//!
//! Units: positions in the caller's units; costs in units². Orientation: the output triangles
//! keep the input's winding. Cost: O(F log F).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::error::{Error, Result};
use crate::math::vec3::{Vec3, add, cross, dist, dot, norm, norm2, scale, sub};

/// Weight of a boundary edge's perpendicular plane, relative to its squared length.
pub const BOUNDARY_WEIGHT: f64 = 1.0;
/// Smallest cosine between a surviving triangle's normal before and after a collapse.
pub const MIN_NORMAL_COSINE: f64 = 0.2;
/// Smallest shape quality 4√3·area / Σ edge² (1: equilateral) a collapse may create, unless
/// the triangles around the edge are already worse.
pub const MIN_QUALITY: f64 = 0.2;
/// Longest edge a collapse may create, in units of the edge length of equilateral triangles
/// covering the surface at the target vertex count (≈ 2 triangles per vertex). Without it, a
/// straight stretch of boundary (a mouth's slit) collapses, at no position error, into one edge
/// with fans of slivers on it.
pub const MAX_EDGE_FACTOR: f64 = 3.0;

/// Largest angle between two triangles' normals for their shared edge to be flipped.
pub const FLIP_MAX_DIHEDRAL_DEG: f64 = 15.0;

/// A decimated mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Decimated {
    /// Vertex positions (input units).
    pub positions: Vec<Vec3>,
    /// Triangles (indices into `positions`), the input's winding.
    pub faces: Vec<[usize; 3]>,
    /// For each output vertex, the input vertex it descends from (the survivor of its
    /// collapses).
    pub source: Vec<usize>,
}

/// Symmetric 4×4 quadric, upper triangle row by row: a², ab, ac, ad, b², bc, bd, c², cd, d².
#[derive(Debug, Clone, Copy, Default)]
struct Quadric([f64; 10]);

impl Quadric {
    /// w·(plane n·x + d = 0)², n of unit length.
    fn plane(n: Vec3, d: f64, w: f64) -> Self {
        let [a, b, c] = n;
        Quadric([a * a, a * b, a * c, a * d, b * b, b * c, b * d, c * c, c * d, d * d].map(|x| x * w))
    }

    fn add(&mut self, o: &Quadric) {
        for (x, y) in self.0.iter_mut().zip(o.0) {
            *x += y;
        }
    }

    fn sum(a: &Quadric, b: &Quadric) -> Quadric {
        let mut q = *a;
        q.add(b);
        q
    }

    /// vᵀQv for v = (p, 1).
    fn error(&self, p: Vec3) -> f64 {
        let q = &self.0;
        let [x, y, z] = p;
        q[0] * x * x
            + 2.0 * q[1] * x * y
            + 2.0 * q[2] * x * z
            + 2.0 * q[3] * x
            + q[4] * y * y
            + 2.0 * q[5] * y * z
            + 2.0 * q[6] * y
            + q[7] * z * z
            + 2.0 * q[8] * z
            + q[9]
    }

    /// The minimiser of the error, when its 3×3 system is well conditioned.
    fn optimum(&self) -> Option<Vec3> {
        let q = &self.0;
        let m = [[q[0], q[1], q[2]], [q[1], q[4], q[5]], [q[2], q[5], q[7]]];
        let rhs = [-q[3], -q[6], -q[8]];
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        let scale = (q[0] + q[4] + q[7]).max(1e-300);
        if det.abs() <= 1e-9 * scale * scale * scale {
            return None;
        }
        let solve = |col: usize| {
            let mut a = m;
            for r in 0..3 {
                a[r][col] = rhs[r];
            }
            (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
                + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
                / det
        };
        let p = [solve(0), solve(1), solve(2)];
        p.iter().all(|x| x.is_finite()).then_some(p)
    }
}

/// A candidate collapse in the queue (least cost first; stale entries skipped by stamps).
#[derive(Debug, Clone, Copy)]
struct Candidate {
    cost: f64,
    a: usize,
    b: usize,
    stamp_a: u32,
    stamp_b: u32,
}

impl PartialEq for Candidate {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Candidate {
    /// Reversed (BinaryHeap is a max-heap), ties by vertex pair: deterministic.
    fn cmp(&self, o: &Self) -> Ordering {
        o.cost.total_cmp(&self.cost).then_with(|| (o.a, o.b).cmp(&(self.a, self.b)))
    }
}

/// Area-weighted normal (twice the area in length) of a triangle.
fn area_normal(p: &[Vec3], f: [usize; 3]) -> Vec3 {
    cross(sub(p[f[1]], p[f[0]]), sub(p[f[2]], p[f[0]]))
}

/// Shape quality 4√3·area / Σ edge² (1: equilateral, 0: degenerate).
fn quality(a: Vec3, b: Vec3, c: Vec3) -> f64 {
    let n = cross(sub(b, a), sub(c, a));
    let s = norm2(sub(b, a)) + norm2(sub(c, b)) + norm2(sub(a, c));
    if s <= 0.0 { 0.0 } else { 2.0 * 3f64.sqrt() * norm(n) / s }
}

/// The working state of a decimation.
struct Work {
    pos: Vec<Vec3>,
    faces: Vec<[usize; 3]>,
    face_alive: Vec<bool>,
    vertex_faces: Vec<Vec<usize>>,
    alive: Vec<bool>,
    stamp: Vec<u32>,
    quadric: Vec<Quadric>,
    /// Longest edge a collapse may create (see [`MAX_EDGE_FACTOR`]).
    max_edge: f64,
}

impl Work {
    /// Neighbours of `v` (sorted, unique) through its live faces.
    fn neighbors(&self, v: usize) -> Vec<usize> {
        let mut out: Vec<usize> =
            self.vertex_faces[v].iter().flat_map(|&f| self.faces[f]).filter(|&w| w != v).collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Live faces containing both `a` and `b`.
    fn shared_faces(&self, a: usize, b: usize) -> Vec<usize> {
        self.vertex_faces[a].iter().copied().filter(|&f| self.faces[f].contains(&b)).collect()
    }

    /// Whether `v` lies on a boundary edge (an edge of exactly one live face).
    fn on_boundary(&self, v: usize) -> bool {
        self.neighbors(v).into_iter().any(|w| self.shared_faces(v, w).len() == 1)
    }

    /// The collapse point and cost of edge (a, b).
    fn plan(&self, a: usize, b: usize) -> (Vec3, f64) {
        let q = Quadric::sum(&self.quadric[a], &self.quadric[b]);
        let mid = scale(add(self.pos[a], self.pos[b]), 0.5);
        let mut best = (mid, q.error(mid));
        for p in [self.pos[a], self.pos[b]].into_iter().chain(q.optimum()) {
            let e = q.error(p);
            if e < best.1 {
                best = (p, e);
            }
        }
        (best.0, best.1.max(0.0))
    }

    fn push(&self, heap: &mut BinaryHeap<Candidate>, a: usize, b: usize) {
        let (a, b) = (a.min(b), a.max(b));
        let (_, cost) = self.plan(a, b);
        heap.push(Candidate { cost, a, b, stamp_a: self.stamp[a], stamp_b: self.stamp[b] });
    }

    /// Whether collapsing (a, b) into `p` keeps the topology and does not fold the surface.
    fn allowed(&self, a: usize, b: usize, p: Vec3) -> bool {
        let shared = self.shared_faces(a, b);
        if shared.is_empty() || shared.len() > 2 {
            return false;
        }
        let opposite: Vec<usize> =
            shared.iter().map(|&f| *self.faces[f].iter().find(|&&w| w != a && w != b).expect("a triangle")).collect();
        let (na, nb) = (self.neighbors(a), self.neighbors(b));
        let common: Vec<usize> = na.iter().copied().filter(|w| nb.binary_search(w).is_ok()).collect();
        let mut want = opposite.clone();
        want.sort_unstable();
        if common != want {
            return false;
        }
        if shared.len() == 2 && self.on_boundary(a) && self.on_boundary(b) {
            return false;
        }
        if opposite.iter().any(|&o| self.neighbors(o).len() <= 3) {
            return false;
        }
        // A closed piece must not shrink below a tetrahedron.
        if shared.len() == 2 && na.len() + nb.len() <= 6 {
            return false;
        }
        // The worst shape around the edge now, and after the collapse.
        let mut q_before = f64::INFINITY;
        let mut q_after = f64::INFINITY;
        for &v in &[a, b] {
            for &f in &self.vertex_faces[v] {
                let tri = self.faces[f];
                q_before = q_before.min(quality(self.pos[tri[0]], self.pos[tri[1]], self.pos[tri[2]]));
                if shared.contains(&f) {
                    continue;
                }
                let before = area_normal(&self.pos, tri);
                let moved: Vec<Vec3> = tri.iter().map(|&w| if w == a || w == b { p } else { self.pos[w] }).collect();
                let after = cross(sub(moved[1], moved[0]), sub(moved[2], moved[0]));
                let (lb, la) = (norm(before), norm(after));
                if la <= 0.0 || dot(before, after) < MIN_NORMAL_COSINE * lb * la {
                    return false;
                }
                q_after = q_after.min(quality(moved[0], moved[1], moved[2]));
                if moved.iter().any(|&m| m != p && dist(m, p) > self.max_edge) {
                    return false;
                }
            }
        }
        q_after >= MIN_QUALITY.min(q_before)
    }

    /// Collapses b into a at `p`.
    fn collapse(&mut self, a: usize, b: usize, p: Vec3) {
        for f in self.shared_faces(a, b) {
            self.face_alive[f] = false;
            for w in self.faces[f] {
                self.vertex_faces[w].retain(|&g| g != f);
            }
        }
        let moved = std::mem::take(&mut self.vertex_faces[b]);
        for &f in &moved {
            for w in self.faces[f].iter_mut() {
                if *w == b {
                    *w = a;
                }
            }
        }
        self.vertex_faces[a].extend(moved);
        self.pos[a] = p;
        let qb = self.quadric[b];
        self.quadric[a].add(&qb);
        self.alive[b] = false;
        self.stamp[a] = self.stamp[a].wrapping_add(1);
        self.stamp[b] = self.stamp[b].wrapping_add(1);
    }
}

/// Decimates a triangle mesh (positions, faces) to at most `target` vertices, or as close as
/// the topology allows (see the module docs). Vertices referenced by no face are dropped.
/// Errors on an index out of range, a non-finite position, or `target` below 4.
pub fn decimate(positions: &[Vec3], faces: &[[usize; 3]], target: usize) -> Result<Decimated> {
    let n = positions.len();
    if target < 4 {
        return Err(Error::Invalid(format!("decimation target {target}: at least 4 vertices")));
    }
    if let Some(f) = faces.iter().find(|f| f.iter().any(|&v| v >= n) || f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) {
        return Err(Error::Invalid(format!("decimation: face {f:?} is degenerate or out of range ({n} vertices)")));
    }
    if let Some(v) = positions.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(Error::Invalid(format!("decimation: vertex {v} has a non-finite position")));
    }
    let mut vertex_faces = vec![Vec::new(); n];
    for (i, f) in faces.iter().enumerate() {
        for &v in f {
            vertex_faces[v].push(i);
        }
    }
    let mut w = Work {
        pos: positions.to_vec(),
        faces: faces.to_vec(),
        face_alive: vec![true; faces.len()],
        alive: vertex_faces.iter().map(|f| !f.is_empty()).collect(),
        vertex_faces,
        stamp: vec![0; n],
        quadric: vec![Quadric::default(); n],
        max_edge: {
            let area: f64 = faces.iter().map(|f| 0.5 * norm(area_normal(positions, *f))).sum();
            MAX_EDGE_FACTOR * (4.0 * area / (3f64.sqrt() * 2.0 * target as f64)).sqrt()
        },
    };
    // Plane quadrics of the triangles (area-weighted) and of the boundary edges.
    for f in faces {
        let an = area_normal(positions, *f);
        let len = norm(an);
        if len <= 0.0 {
            continue;
        }
        let unit = scale(an, 1.0 / len);
        let q = Quadric::plane(unit, -dot(unit, positions[f[0]]), 0.5 * len);
        for &v in f {
            w.quadric[v].add(&q);
        }
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if w.shared_faces(a, b).len() == 1 {
                let e = sub(positions[b], positions[a]);
                let m = cross(e, unit);
                let ml = norm(m);
                if ml > 0.0 {
                    let m = scale(m, 1.0 / ml);
                    let q = Quadric::plane(m, -dot(m, positions[a]), BOUNDARY_WEIGHT * norm2(e));
                    w.quadric[a].add(&q);
                    w.quadric[b].add(&q);
                }
            }
        }
    }
    let mut heap = BinaryHeap::new();
    for f in faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if a < b || w.shared_faces(a, b).len() == 1 {
                w.push(&mut heap, a, b);
            }
        }
    }
    let mut count = w.alive.iter().filter(|&&x| x).count();
    while count > target {
        let Some(c) = heap.pop() else { break };
        if !w.alive[c.a] || !w.alive[c.b] || w.stamp[c.a] != c.stamp_a || w.stamp[c.b] != c.stamp_b {
            continue;
        }
        let (p, _) = w.plan(c.a, c.b);
        if !w.allowed(c.a, c.b, p) {
            continue;
        }
        w.collapse(c.a, c.b, p);
        count -= 1;
        // New candidates around the survivor; its neighbours' other edges kept their stamps.
        for v in w.neighbors(c.a) {
            w.push(&mut heap, c.a, v);
            // A neighbour's refused edges may be allowed now: re-queue them.
            w.stamp[v] = w.stamp[v].wrapping_add(1);
            for u in w.neighbors(v) {
                w.push(&mut heap, v, u);
            }
        }
    }
    // Compact.
    let mut index = vec![usize::MAX; n];
    let mut out = Decimated { positions: Vec::with_capacity(count), faces: Vec::new(), source: Vec::new() };
    for (v, slot) in index.iter_mut().enumerate() {
        if w.alive[v] && !w.vertex_faces[v].is_empty() {
            *slot = out.positions.len();
            out.positions.push(w.pos[v]);
            out.source.push(v);
        }
    }
    for (f, tri) in w.faces.iter().enumerate() {
        if w.face_alive[f] {
            out.faces.push(tri.map(|v| index[v]));
        }
    }
    improve_by_flips(&out.positions, &mut out.faces);
    Ok(out)
}

/// Angle at `a` of the triangle (a, b, c), radians.
fn angle_at(a: Vec3, b: Vec3, c: Vec3) -> f64 {
    let (u, v) = (sub(b, a), sub(c, a));
    norm(cross(u, v)).atan2(dot(u, v))
}

/// Flips interior edges between nearly coplanar triangles (normals within
/// [`FLIP_MAX_DIHEDRAL_DEG`]) whose opposite angles sum to more than π, when the flip raises the
/// pair's worse shape quality and the new edge does not exist yet; passes until none flips (at
/// most 20). Positions are unchanged; triangles keep their winding. Returns the flips made.
pub fn improve_by_flips(p: &[Vec3], faces: &mut [[usize; 3]]) -> usize {
    use std::collections::HashMap;
    let cos_max = FLIP_MAX_DIHEDRAL_DEG.to_radians().cos();
    let key = |a: usize, b: usize| (a.min(b), a.max(b));
    let mut total = 0;
    for _ in 0..20 {
        let mut edges: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
        for (i, f) in faces.iter().enumerate() {
            for k in 0..3 {
                edges.entry(key(f[k], f[(k + 1) % 3])).or_default().push(i);
            }
        }
        let mut touched = vec![false; faces.len()];
        let mut flips = 0;
        let mut list: Vec<((usize, usize), Vec<usize>)> = edges.iter().map(|(k, v)| (*k, v.clone())).collect();
        list.sort_unstable_by_key(|(k, _)| *k);
        for ((x, y), fs) in list {
            if fs.len() != 2 || touched[fs[0]] || touched[fs[1]] {
                continue;
            }
            let (f1, f2) = (fs[0], fs[1]);
            // Orient: f1 holds the directed edge a → b, f2 the edge b → a.
            let t1 = faces[f1];
            let k = (0..3).find(|&k| key(t1[k], t1[(k + 1) % 3]) == (x, y)).expect("edge of f1");
            let (a, b, c) = (t1[k], t1[(k + 1) % 3], t1[(k + 2) % 3]);
            let t2 = faces[f2];
            let Some(d) = t2.iter().copied().find(|&v| v != a && v != b) else { continue };
            if c == d || edges.contains_key(&key(c, d)) {
                continue;
            }
            let (n1, n2) = (area_normal(p, [a, b, c]), area_normal(p, [b, a, d]));
            let (l1, l2) = (norm(n1), norm(n2));
            if l1 <= 0.0 || l2 <= 0.0 || dot(n1, n2) < cos_max * l1 * l2 {
                continue;
            }
            if angle_at(p[c], p[a], p[b]) + angle_at(p[d], p[b], p[a]) <= std::f64::consts::PI + 1e-9 {
                continue;
            }
            let (g1, g2) = ([a, d, c], [d, b, c]);
            let (m1, m2) = (area_normal(p, g1), area_normal(p, g2));
            // The new pair must face the same way as the old one (no fold).
            if dot(m1, n1) <= 0.0 || dot(m2, n1) <= 0.0 {
                continue;
            }
            let q_old = quality(p[a], p[b], p[c]).min(quality(p[b], p[a], p[d]));
            let q_new = quality(p[a], p[d], p[c]).min(quality(p[d], p[b], p[c]));
            if q_new <= q_old {
                continue;
            }
            faces[f1] = g1;
            faces[f2] = g2;
            touched[f1] = true;
            touched[f2] = true;
            flips += 1;
        }
        total += flips;
        if flips == 0 {
            break;
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Topology;
    use crate::mesh::primitives::{grid, icosphere};

    fn euler(n: usize, faces: &[[usize; 3]]) -> i64 {
        let t = Topology::new(n, faces);
        n as i64 - t.edges.len() as i64 + faces.len() as i64
    }

    fn manifold(n: usize, faces: &[[usize; 3]]) -> bool {
        let t = Topology::new(n, faces);
        t.non_manifold_edges().is_empty() && t.edge_faces.iter().all(|e| e.len() <= 2)
    }

    #[test]
    fn a_sphere_keeps_its_topology_and_shape() {
        let m = icosphere(4); // 2562 vertices on the unit sphere
        let d = decimate(&m.positions, &m.faces, 300).unwrap();
        assert!(d.positions.len() <= 300 && d.positions.len() >= 250, "{} vertices", d.positions.len());
        assert_eq!(euler(d.positions.len(), &d.faces), 2, "genus changed");
        assert!(manifold(d.positions.len(), &d.faces));
        assert_eq!(Topology::new(d.positions.len(), &d.faces).n_boundary_edges(), 0);
        // On the sphere: every vertex within 2 % of the radius.
        for p in &d.positions {
            assert!((norm(*p) - 1.0).abs() < 0.02, "vertex off the sphere: {}", norm(*p));
        }
        // Outward normals stay outward.
        for f in &d.faces {
            let c = scale(add(add(d.positions[f[0]], d.positions[f[1]]), d.positions[f[2]]), 1.0 / 3.0);
            assert!(dot(area_normal(&d.positions, *f), c) > 0.0, "a flipped triangle");
        }
        // Sources are distinct input vertices.
        let mut s = d.source.clone();
        s.sort_unstable();
        s.dedup();
        assert_eq!(s.len(), d.positions.len());
    }

    #[test]
    fn a_sheet_keeps_its_outline_and_stays_flat() {
        let m = grid(30, 30, 1.0);
        let d = decimate(&m.positions, &m.faces, 200).unwrap();
        assert!(d.positions.len() <= 200);
        let t = Topology::new(d.positions.len(), &d.faces);
        assert_eq!(t.boundary_loops(&d.faces).len(), 1);
        assert_eq!(euler(d.positions.len(), &d.faces), 1);
        let z0 = m.positions[0][2];
        assert!(d.positions.iter().all(|p| (p[2] - z0).abs() < 1e-9), "left the plane");
        // The four corners survive, and the area is the same.
        let (lo, hi) = crate::mesh::bounding_box(&m.positions);
        for corner in [[lo[0], lo[1]], [hi[0], lo[1]], [lo[0], hi[1]], [hi[0], hi[1]]] {
            assert!(
                d.positions.iter().any(|p| (p[0] - corner[0]).abs() < 1e-9 && (p[1] - corner[1]).abs() < 1e-9),
                "corner {corner:?} lost"
            );
        }
        let area = |p: &[Vec3], f: &[[usize; 3]]| f.iter().map(|t| 0.5 * norm(area_normal(p, *t))).sum::<f64>();
        assert!((area(&d.positions, &d.faces) - area(&m.positions, &m.faces)).abs() < 1e-9);
    }

    #[test]
    fn a_target_above_the_vertex_count_changes_nothing_and_bad_input_is_refused() {
        let m = icosphere(1);
        let d = decimate(&m.positions, &m.faces, 1000).unwrap();
        assert_eq!(d.positions, m.positions);
        assert_eq!(d.faces, m.faces);
        assert!(decimate(&m.positions, &m.faces, 3).is_err());
        assert!(decimate(&m.positions, &[[0, 1, 99]], 10).is_err());
        let mut bad = m.positions.clone();
        bad[2][1] = f64::NAN;
        assert!(decimate(&bad, &m.faces, 10).is_err());
    }
}
