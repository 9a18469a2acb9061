//! Deterministic test meshes: an icosphere (closed, unit radius), a flat grid (open boundary)
//! and an open cylinder (two boundary loops).
//!
//! All faces are counter-clockwise seen from outside (sphere, cylinder) or from +z (grid), so
//! face normals point outwards / up. The same arguments always give the same mesh, vertex for
//! vertex (no hashing order, no randomness).

use std::collections::HashMap;

use super::{TriMesh, Vec3};

/// Unit icosphere: a regular icosahedron whose triangles are split `subdivisions` times into
/// four (edge midpoints), every vertex projected onto the unit sphere centred at the origin.
///
/// Sizes: N = 10·4ˢ + 2 vertices, T = 20·4ˢ faces, E = 30·4ˢ edges (s = `subdivisions`).
/// Mean edge length ≈ 1.1 / 2ˢ (1.05 for s = 0, 0.069 for s = 4). Vertex 0 is `(−a, b, 0)/r`
/// of the standard icosahedron; vertices of coarser levels keep their indices.
pub fn icosphere(subdivisions: usize) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    for p in &mut positions {
        *p = unit(*p);
    }
    let mut faces: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        // Midpoint indices are created in face order, so the result is deterministic; the map
        // is only looked up, never iterated.
        let mut midpoint: HashMap<(usize, usize), usize> = HashMap::with_capacity(faces.len() * 3 / 2);
        let mut mid = |a: usize, b: usize, positions: &mut Vec<Vec3>| -> usize {
            let key = (a.min(b), a.max(b));
            *midpoint.entry(key).or_insert_with(|| {
                let (p, q) = (positions[a], positions[b]);
                positions.push(unit([p[0] + q[0], p[1] + q[1], p[2] + q[2]]));
                positions.len() - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for &[a, b, c] in &faces {
            let ab = mid(a, b, &mut positions);
            let bc = mid(b, c, &mut positions);
            let ca = mid(c, a, &mut positions);
            next.push([a, ab, ca]);
            next.push([b, bc, ab]);
            next.push([c, ca, bc]);
            next.push([ab, bc, ca]);
        }
        faces = next;
    }
    TriMesh::new(positions, faces)
}

/// Flat grid in the plane z = 0 covering `[0, size] × [0, size]` with `nx × ny` cells (so
/// `(nx+1)·(ny+1)` vertices and `2·nx·ny` triangles); cells are `size/nx` by `size/ny`.
///
/// Vertex `(i, j)` (0 ≤ i ≤ nx along x, 0 ≤ j ≤ ny along y) has index `j·(nx+1) + i` and
/// position `(i·size/nx, j·size/ny, 0)`. Each cell is split along a diagonal that alternates
/// with the parity of `i + j` (a "criss-cross" pattern, so the triangulation has no preferred
/// diagonal direction). Faces are counter-clockwise seen from +z. The boundary is one open loop.
/// `nx` or `ny` equal to 0 gives a mesh without faces.
pub fn grid(nx: usize, ny: usize, size: f64) -> TriMesh {
    let mut positions = Vec::with_capacity((nx + 1) * (ny + 1));
    for j in 0..=ny {
        for i in 0..=nx {
            let x = if nx == 0 { 0.0 } else { i as f64 * size / nx as f64 };
            let y = if ny == 0 { 0.0 } else { j as f64 * size / ny as f64 };
            positions.push([x, y, 0.0]);
        }
    }
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    let mut faces = Vec::with_capacity(2 * nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                // Diagonal a–c.
                faces.push([a, b, c]);
                faces.push([a, c, d]);
            } else {
                // Diagonal b–d.
                faces.push([a, b, d]);
                faces.push([b, c, d]);
            }
        }
    }
    TriMesh::new(positions, faces)
}

/// Open cylinder (a tube without caps) of the given `radius` around the z axis, from z = 0 to
/// z = `height`: `n_around` vertices per ring (≥ 3 for a valid tube) and `n_along + 1` rings
/// (`n_along` ≥ 1 bands of quads, each split into two triangles).
///
/// Vertex `(k, r)` (k-th around, r-th ring) has index `r·n_around + k` and position
/// `(radius·cos 2πk/n, radius·sin 2πk/n, r·height/n_along)`. Faces point outwards. The mesh has
/// two boundary loops (the rings r = 0 and r = n_along). Degenerate arguments (n_around < 3 or
/// n_along = 0) give a mesh without faces.
pub fn cylinder(n_around: usize, n_along: usize, radius: f64, height: f64) -> TriMesh {
    let mut positions = Vec::with_capacity(n_around * (n_along + 1));
    for r in 0..=n_along {
        let z = if n_along == 0 { 0.0 } else { r as f64 * height / n_along as f64 };
        for k in 0..n_around {
            let a = 2.0 * std::f64::consts::PI * k as f64 / n_around as f64;
            positions.push([radius * a.cos(), radius * a.sin(), z]);
        }
    }
    let mut faces = Vec::new();
    if n_around >= 3 {
        for r in 0..n_along {
            for k in 0..n_around {
                let k1 = (k + 1) % n_around;
                let (a, b) = (r * n_around + k, r * n_around + k1);
                let (c, d) = ((r + 1) * n_around + k1, (r + 1) * n_around + k);
                faces.push([a, b, c]);
                faces.push([a, c, d]);
            }
        }
    }
    TriMesh::new(positions, faces)
}

fn unit(p: Vec3) -> Vec3 {
    crate::math::vec3::normalize(p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::vec3::{cross, dot, sub};
    use crate::mesh::Topology;
    use crate::mesh::normals::face_normals_raw;

    #[test]
    fn icosphere_counts_closed_outward_and_on_sphere() {
        for s in 0..4 {
            let m = icosphere(s);
            let p4 = 4usize.pow(s as u32);
            assert_eq!(m.n_vertices(), 10 * p4 + 2);
            assert_eq!(m.n_faces(), 20 * p4);
            let t = Topology::new(m.n_vertices(), &m.faces);
            assert_eq!(t.edges.len(), 30 * p4);
            assert_eq!(t.n_boundary_edges(), 0);
            assert!(t.non_manifold_edges().is_empty());
            for p in &m.positions {
                assert!((dot(*p, *p) - 1.0).abs() < 1e-12);
            }
            // Outward: each face normal points away from the origin.
            for (f, n) in m.faces.iter().zip(face_normals_raw(&m.positions, &m.faces)) {
                assert!(dot(n, m.positions[f[0]]) > 0.0);
            }
        }
        assert_eq!(icosphere(3), icosphere(3));
    }

    #[test]
    fn grid_counts_boundary_and_orientation() {
        let m = grid(4, 3, 2.0);
        assert_eq!(m.n_vertices(), 20);
        assert_eq!(m.n_faces(), 24);
        let t = Topology::new(m.n_vertices(), &m.faces);
        // E = V + F − 1 for a disc.
        assert_eq!(t.edges.len(), 20 + 24 - 1);
        assert_eq!(t.n_boundary_edges(), 2 * (4 + 3));
        assert_eq!(t.boundary_loops(&m.faces).len(), 1);
        for n in face_normals_raw(&m.positions, &m.faces) {
            assert!(n[2] > 0.0);
        }
        let total: f64 = face_normals_raw(&m.positions, &m.faces).iter().map(|n| n[2] / 2.0).sum();
        assert!((total - 4.0).abs() < 1e-12);
        assert_eq!(m.positions[4 + 5 * 3], [2.0, 2.0, 0.0]);
    }

    #[test]
    fn cylinder_is_a_tube_with_two_loops_pointing_out() {
        let m = cylinder(12, 5, 0.5, 2.0);
        let t = Topology::new(m.n_vertices(), &m.faces);
        assert_eq!(t.boundary_loops(&m.faces).len(), 2);
        assert!(t.non_manifold_edges().is_empty());
        for f in &m.faces {
            let (a, b, c) = (m.positions[f[0]], m.positions[f[1]], m.positions[f[2]]);
            let n = cross(sub(b, a), sub(c, a));
            let centre = [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0, 0.0];
            assert!(dot(n, centre) > 0.0);
        }
    }

    #[test]
    fn base_icosahedron_is_regular_and_cylinder_vertices_sit_where_documented() {
        let m = icosphere(0);
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let r = (1.0 + t * t).sqrt();
        assert!((m.positions[0][0] + 1.0 / r).abs() < 1e-12 && (m.positions[0][1] - t / r).abs() < 1e-12);
        for f in &m.faces {
            for k in 0..3 {
                let l = crate::math::vec3::dist(m.positions[f[k]], m.positions[f[(k + 1) % 3]]);
                assert!((l - 2.0 / r).abs() < 1e-12, "{f:?}: {l}");
            }
        }
        let c = cylinder(12, 5, 0.5, 2.0);
        for (i, p) in c.positions.iter().enumerate() {
            let (k, ring) = (i % 12, i / 12);
            assert!((p[2] - 0.4 * ring as f64).abs() < 1e-12, "vertex {i}: {p:?}");
            let a = 2.0 * std::f64::consts::PI * k as f64 / 12.0;
            assert!((p[0] - 0.5 * a.cos()).abs() < 1e-12 && (p[1] - 0.5 * a.sin()).abs() < 1e-12, "vertex {i}: {p:?}");
        }
    }
}
