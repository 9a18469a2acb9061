//! Rotation consistency of ACAP: choosing, per vertex, one of the infinitely many axis–angle
//! vectors of its rotation so that neighbouring vertices get similar vectors.
//!
//! A rotation R ≠ I with axis–angle (a, θ), θ ∈ (0, π), has the logarithms
//! ω = (θ + 2πk)·a for every integer k (the "flipped" ones (−a, 2π − θ + 2πk) are among them:
//! (2π − θ)(−a) = (θ − 2π)a). The identity has ω = 2πk·u for any unit u.
//!
//! * [`bfs_consistency`] is the reference implementation's option 0 (docs/design.md § acap step 6):
//!   a breadth-first walk from vertex 0 in which every child aligns its axis with its parent's
//!   (flipping to (−a, 2π − θ)) and tracks a cycle count k from the jump of the stored angle.
//! * [`global_consistency`] replaces the reference's option 1 (two integer programs solved by a
//!   commercial MIQP solver) by a local search on one energy, started from the BFS result:
//!
//!   ```text
//!   E(ω) = Σ_{undirected edges (i,j)} ‖ω_i − ω_j‖²
//!   ```
//!
//!   the squared difference of neighbouring rotation vectors, which is what both of the
//!   reference's integer programs approximate (its first minimises sign disagreements of
//!   neighbouring axes, its second Σ (φ_i − φ_j)² over the cycle counts of the angles φ = θ + 2πk).
//!   Each vertex's variable is the integer m_i in ω_i = (φ_i + 2πm_i)·a_i (a_i, φ_i from BFS),
//!   which covers every logarithm of R_i, flips included; vertices whose rotation is the identity
//!   (θ ≤ 1e-6, as in the reference) may also change their axis. Moves, each accepted only when
//!   it lowers E: (1) single-vertex moves to the best m_i given the neighbours (iterated
//!   conditional modes, exact closed form because E is quadratic in φ_i); (2) cluster moves on a
//!   whole connected region of mutually consistent vertices (neighbour differences below π):
//!   with every angle stored non-negative (axis along ω), all members' angles change by +2π or
//!   −2π (ω → (‖ω‖ ± 2π)·ω/‖ω‖), which repairs seams where two BFS branches met with different
//!   cycle counts or axis signs (for instance the reference's own BFS output on its fixture).
//!   The search stops when no move improves E; hence E(global) ≤ E(BFS) always.

#![allow(clippy::needless_range_loop)] // index loops over 3-vectors read like the formulas
use crate::math::vec3::{Vec3, dist2, dot};
use std::f64::consts::PI;

/// Angles at or below this are treated as the identity rotation (the reference's 1e-6).
pub const IDENTITY_ANGLE: f64 = 1e-6;

const TWO_PI: f64 = 2.0 * PI;

/// A per-vertex rotation-vector field ω_i = `angle[i]`·`axis[i]` (angle in radians, any real
/// value; axis unit, or zero for a vertex with no rotation information).
#[derive(Debug, Clone, PartialEq)]
pub struct RotationField {
    pub axis: Vec<Vec3>,
    pub angle: Vec<f64>,
}

impl RotationField {
    /// ω_i.
    #[inline]
    pub fn vector(&self, i: usize) -> Vec3 {
        let (a, t) = (self.axis[i], self.angle[i]);
        [a[0] * t, a[1] * t, a[2] * t]
    }
}

/// Breadth-first spanning forest of the 1-ring graph: vertices in visiting order with their
/// parents. Roots (vertex 0, then the smallest unvisited vertex of every further component) have
/// parent `usize::MAX`. Neighbours are visited in the order the rings are given.
#[derive(Debug, Clone)]
pub struct BfsTree {
    /// Vertices in BFS order.
    pub order: Vec<usize>,
    /// Parent of each vertex (`usize::MAX` for roots).
    pub parent: Vec<usize>,
}

impl BfsTree {
    /// Builds the forest from rings in CSR form (`ring[offsets[v]..offsets[v+1]]`).
    pub fn new(offsets: &[usize], ring: &[usize]) -> Self {
        let n = offsets.len().saturating_sub(1);
        let mut parent = vec![usize::MAX; n];
        let mut visited = vec![false; n];
        let mut order = Vec::with_capacity(n);
        for root in 0..n {
            if visited[root] {
                continue;
            }
            visited[root] = true;
            let mut head = order.len();
            order.push(root);
            while head < order.len() {
                let v = order[head];
                head += 1;
                for &u in &ring[offsets[v]..offsets[v + 1]] {
                    if !visited[u] {
                        visited[u] = true;
                        parent[u] = v;
                        order.push(u);
                    }
                }
            }
        }
        BfsTree { order, parent }
    }
}

/// BFS consistency (the reference's option 0). Input: per-vertex axis–angle with θ ∈ [0, π]
/// (axis unit, zero allowed for θ = 0). The root keeps its axis–angle (axis zero when
/// θ ≤ [`IDENTITY_ANGLE`]) and cycle count 0. A child j of parent i:
/// * θ_j ≤ 1e-6: takes the parent's axis and cycle count, stored angle 0;
/// * otherwise: if a_j·a_i < 0, a_j ← −a_j and θ_j ← 2π − θ_j (the stored angle lies in
///   [0, 2π)). Near θ = π the axis comes from [`crate::math::mat3::axis_angle`], which is
///   accurate there; the reference instead copies the parent's axis within 1e-6 of π, which
///   misrepresents the rotation unless both axes agree, so that branch is not reproduced;
/// * the child inherits the parent's cycle count k; if |θ_j − θ_i| > π (stored angles),
///   k ← k − 1 when θ_i < π, else k ← k + 1.
///
/// The result has angle θ_j + 2πk_j on the (possibly flipped) axis.
pub fn bfs_consistency(tree: &BfsTree, axis: &[Vec3], theta: &[f64]) -> RotationField {
    let n = axis.len();
    let mut out_axis = vec![[0.0; 3]; n];
    let mut stored = vec![0.0; n];
    let mut cycles = vec![0i64; n];
    for &j in &tree.order {
        let p = tree.parent[j];
        if p == usize::MAX {
            if theta[j] <= IDENTITY_ANGLE {
                out_axis[j] = [0.0; 3];
                stored[j] = 0.0;
            } else {
                out_axis[j] = axis[j];
                stored[j] = theta[j];
            }
            cycles[j] = 0;
            continue;
        }
        let (pa, pt, pk) = (out_axis[p], stored[p], cycles[p]);
        let (a, t) = if theta[j] <= IDENTITY_ANGLE {
            (pa, 0.0)
        } else {
            let a = axis[j];
            if dot(a, pa) < 0.0 { ([-a[0], -a[1], -a[2]], TWO_PI - theta[j]) } else { (a, theta[j]) }
        };
        let mut k = pk;
        if (t - pt).abs() > PI {
            if pt < PI {
                k -= 1;
            } else {
                k += 1;
            }
        }
        out_axis[j] = a;
        stored[j] = t;
        cycles[j] = k;
    }
    let angle = (0..n).map(|i| stored[i] + TWO_PI * cycles[i] as f64).collect();
    RotationField { axis: out_axis, angle }
}

/// E(ω) = Σ over undirected edges of ‖ω_i − ω_j‖² (see the module docs).
pub fn neighbour_energy(field: &RotationField, edges: &[[usize; 2]]) -> f64 {
    let w: Vec<Vec3> = (0..field.axis.len()).map(|i| field.vector(i)).collect();
    edges.iter().map(|&[i, j]| dist2(w[i], w[j])).sum()
}

/// Rewrites vertex i as (−a, −φ) when φ < 0 (the same vector ω).
#[inline]
fn make_angle_non_negative(field: &mut RotationField, i: usize) {
    if field.angle[i] < 0.0 {
        field.angle[i] = -field.angle[i];
        let a = field.axis[i];
        field.axis[i] = [-a[0], -a[1], -a[2]];
    }
}

/// Minimum energy decrease for a move to be accepted (guards against cycling on rounding).
const MIN_GAIN: f64 = 1e-9;

/// Neighbour differences below these count as consistent when clusters are formed (several
/// thresholds find different seams; π alone misses some on horse-gallop).
const CLUSTER_JUMPS: [f64; 3] = [PI, 2.0, 1.0];

/// Buffers of [`best_cluster_move`]: cluster label per vertex, members of all clusters
/// concatenated, and the start of each cluster in `members` (plus the end).
struct ClusterScratch {
    label: Vec<usize>,
    stack: Vec<usize>,
    members: Vec<usize>,
    starts: Vec<usize>,
}

/// Splits the vertices into components of edges with ‖ω_i − ω_j‖ < `jump` and returns the
/// most improving move `(ΔE, cluster, sign)` that changes every angle of one cluster by 2π·sign
/// (angles stored non-negative, so each ω moves along its own direction), if any lowers E by
/// more than [`MIN_GAIN`]. Clusters are left in `scratch`.
fn best_cluster_move(
    field: &RotationField,
    w: &[Vec3],
    offsets: &[usize],
    ring: &[usize],
    jump: f64,
    scratch: &mut ClusterScratch,
) -> Option<(f64, usize, f64)> {
    let n = w.len();
    let ClusterScratch { label, stack, members, starts } = scratch;
    label.iter_mut().for_each(|l| *l = usize::MAX);
    members.clear();
    starts.clear();
    for s0 in 0..n {
        if label[s0] != usize::MAX {
            continue;
        }
        let c = starts.len();
        starts.push(members.len());
        label[s0] = c;
        stack.push(s0);
        while let Some(v) = stack.pop() {
            members.push(v);
            for &u in &ring[offsets[v]..offsets[v + 1]] {
                if label[u] == usize::MAX && dist2(w[v], w[u]) < jump * jump {
                    label[u] = c;
                    stack.push(u);
                }
            }
        }
    }
    starts.push(members.len());
    let n_clusters = starts.len() - 1;
    if n_clusters < 2 {
        return None;
    }
    let mut best = (-MIN_GAIN, usize::MAX, 0.0);
    for c in 0..n_clusters {
        for sign in [1.0, -1.0] {
            let shift = TWO_PI * sign;
            let mut delta = 0.0;
            for &i in &members[starts[c]..starts[c + 1]] {
                let a = field.axis[i];
                let wi_new = [w[i][0] + shift * a[0], w[i][1] + shift * a[1], w[i][2] + shift * a[2]];
                for &j in &ring[offsets[i]..offsets[i + 1]] {
                    if label[j] == c {
                        if j < i {
                            continue; // each internal edge once
                        }
                        let b = field.axis[j];
                        let wj_new = [w[j][0] + shift * b[0], w[j][1] + shift * b[1], w[j][2] + shift * b[2]];
                        delta += dist2(wi_new, wj_new) - dist2(w[i], w[j]);
                    } else {
                        delta += dist2(wi_new, w[j]) - dist2(w[i], w[j]);
                    }
                }
            }
            if delta < best.0 {
                best = (delta, c, sign);
            }
        }
    }
    (best.1 != usize::MAX).then_some(best)
}

/// Global consistency by local search on E (module docs), started from `field` (normally the
/// BFS result) and modifying it in place. `identity[i]` marks vertices whose rotation is the
/// identity (their axis is free). Rings in CSR form, `edges` the undirected edges. Returns the
/// final energy, which never exceeds the initial one.
pub fn global_consistency(
    field: &mut RotationField,
    identity: &[bool],
    offsets: &[usize],
    ring: &[usize],
    edges: &[[usize; 2]],
) -> f64 {
    let n = field.axis.len();
    // Store every vertex with a non-negative angle (axis along ω): the cluster shift below moves
    // each ω by 2π along its own direction, which is consistent across a cluster only if the
    // axes agree with the vectors.
    for i in 0..n {
        make_angle_non_negative(field, i);
    }
    let mut w: Vec<Vec3> = (0..n).map(|i| field.vector(i)).collect();
    let mut scratch =
        ClusterScratch { label: vec![usize::MAX; n], stack: Vec::new(), members: Vec::new(), starts: Vec::new() };
    for _round in 0..10_000 {
        let mut improved = false;
        // (1) Iterated conditional modes.
        for _sweep in 0..1000 {
            let mut changed = false;
            for i in 0..n {
                let nb = &ring[offsets[i]..offsets[i + 1]];
                if nb.is_empty() {
                    continue;
                }
                let deg = nb.len() as f64;
                let mut s = [0.0; 3];
                for &j in nb {
                    for k in 0..3 {
                        s[k] += w[j][k];
                    }
                }
                // Local energy of candidate ω: deg‖ω‖² − 2 ω·s (+ const).
                let local = |x: Vec3| deg * dot(x, x) - 2.0 * dot(x, s);
                let cur = local(w[i]);
                if identity[i] {
                    // ω = 2πm·u: best u = s/‖s‖, best m ≥ 0 nearest to ‖s‖/(2π deg).
                    let sn = dot(s, s).sqrt();
                    if sn > 0.0 {
                        let m = (sn / deg / TWO_PI).round();
                        let u = [s[0] / sn, s[1] / sn, s[2] / sn];
                        let phi = TWO_PI * m;
                        let cand = [u[0] * phi, u[1] * phi, u[2] * phi];
                        if local(cand) < cur - MIN_GAIN {
                            field.axis[i] = u;
                            field.angle[i] = phi;
                            w[i] = cand;
                            changed = true;
                        }
                    }
                } else {
                    let a = field.axis[i];
                    let best_phi = dot(a, s) / deg;
                    let m = ((best_phi - field.angle[i]) / TWO_PI).round();
                    if m != 0.0 {
                        let phi = field.angle[i] + TWO_PI * m;
                        let cand = [a[0] * phi, a[1] * phi, a[2] * phi];
                        if local(cand) < cur - MIN_GAIN {
                            field.angle[i] = phi;
                            make_angle_non_negative(field, i);
                            w[i] = cand;
                            changed = true;
                        }
                    }
                }
            }
            if !changed {
                break;
            }
            improved = true;
        }
        // (2) Cluster moves: components of the graph of consistent edges, for several
        // thresholds; the best move over all clusters and thresholds is applied (greedy
        // best-first: applying the first improving one could commit to a worse branch, e.g.
        // unwrapping the near-identity half of a bar instead of the half beyond π).
        let mut best: Option<(f64, Vec<usize>, f64)> = None;
        for &jump in &CLUSTER_JUMPS {
            if let Some((delta, c, sign)) = best_cluster_move(field, &w, offsets, ring, jump, &mut scratch)
                && best.as_ref().is_none_or(|b| delta < b.0)
            {
                let members = scratch.members[scratch.starts[c]..scratch.starts[c + 1]].to_vec();
                best = Some((delta, members, sign));
            }
        }
        if let Some((_, members, sign)) = best {
            let shift = TWO_PI * sign;
            for &i in &members {
                field.angle[i] += shift;
                make_angle_non_negative(field, i);
                w[i] = field.vector(i);
            }
            improved = true;
        }
        if !improved {
            break;
        }
    }
    edges.iter().map(|&[i, j]| dist2(w[i], w[j])).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A path graph 0 - 1 - ... - (n-1) in CSR form, plus its edges.
    fn path(n: usize) -> (Vec<usize>, Vec<usize>, Vec<[usize; 2]>) {
        let mut offsets = vec![0];
        let mut ring = Vec::new();
        for v in 0..n {
            if v > 0 {
                ring.push(v - 1);
            }
            if v + 1 < n {
                ring.push(v + 1);
            }
            offsets.push(ring.len());
        }
        let edges = (0..n - 1).map(|v| [v, v + 1]).collect();
        (offsets, ring, edges)
    }

    /// Canonical axis–angle (θ ∈ [0, π]) of a rotation by `psi` about +z.
    fn canonical(psi: f64) -> (Vec3, f64) {
        let t = psi.rem_euclid(TWO_PI);
        if t <= PI { ([0.0, 0.0, 1.0], t) } else { ([0.0, 0.0, -1.0], TWO_PI - t) }
    }

    #[test]
    fn bfs_unwraps_a_monotone_twist_past_two_pi() {
        let n = 60;
        let (offsets, ring, edges) = path(n);
        let psi: Vec<f64> = (0..n).map(|v| 0.12 * v as f64).collect(); // up to 7.08 rad
        let (axis, theta): (Vec<Vec3>, Vec<f64>) = psi.iter().map(|&p| canonical(p)).unzip();
        let tree = BfsTree::new(&offsets, &ring);
        let f = bfs_consistency(&tree, &axis, &theta);
        for v in 1..n {
            let wz = f.vector(v)[2];
            assert!((wz - psi[v]).abs() < 1e-9, "vertex {v}: {wz} vs {}", psi[v]);
        }
        assert!(neighbour_energy(&f, &edges) < n as f64 * 0.0145);
    }

    #[test]
    fn global_repairs_a_seam_and_never_increases_energy() {
        // A path whose second half was given the wrong cycle (a seam as produced by two BFS
        // branches): global consistency must remove the 2π jump.
        let n = 40;
        let (offsets, ring, edges) = path(n);
        let mut f = RotationField {
            axis: vec![[0.0, 0.0, 1.0]; n],
            angle: (0..n).map(|v| 0.1 * v as f64 + if v >= 20 { -TWO_PI } else { 0.0 }).collect(),
        };
        let e0 = neighbour_energy(&f, &edges);
        let identity = vec![false; n];
        let e1 = global_consistency(&mut f, &identity, &offsets, &ring, &edges);
        assert!(e1 <= e0);
        assert!((e1 - 0.01 * (n - 1) as f64).abs() < 1e-9, "energy {e1}");
        for v in 1..n {
            let (a, b) = (f.vector(v - 1)[2], f.vector(v)[2]);
            assert!((b - a - 0.1).abs() < 1e-9 || (a - b - 0.1).abs() < 1e-9, "{a} {b}");
        }
        assert!((e1 - neighbour_energy(&f, &edges)).abs() < 1e-9);
    }

    #[test]
    fn identity_vertex_takes_neighbour_axis() {
        // A path with ω = (2π − 0.2, 2π − 0.1, identity, 2π + 0.1, 2π + 0.2)·z: the identity vertex
        // in the middle must become 2π·z (one full turn, like its neighbours).
        let (offsets, ring, edges) = path(5);
        let z = [0.0, 0.0, 1.0];
        let mut f = RotationField {
            axis: vec![z, z, [0.0; 3], z, z],
            angle: vec![TWO_PI - 0.2, TWO_PI - 0.1, 0.0, TWO_PI + 0.1, TWO_PI + 0.2],
        };
        let e = global_consistency(&mut f, &[false, false, true, false, false], &offsets, &ring, &edges);
        assert!((e - 0.04).abs() < 1e-12, "energy {e}");
        assert!((f.vector(2)[2] - TWO_PI).abs() < 1e-12);
    }
}
