//! Inspection of a mesh sequence: counts, boundary, components, extent, and warnings about
//! everything that is legal but may surprise a method (never fixed silently).
//!
//! Warnings (see [`WarningKind`]): faces that repeat a vertex index, faces of (numerically) zero
//! area in any frame, non-manifold edges, edges whose two faces disagree in orientation,
//! non-manifold vertices (several fans of faces meeting at one vertex), boundary loops, several connected components, vertices referenced by no face, and whatever the file
//! readers reported. `meshdeco inspect <path>` prints [`InspectReport`]'s `Display`.

use std::fmt;

use serde::Serialize;

use super::sequence::read_sequence;
use super::{MeshSequence, Topology, Vec3, bounding_box, dist};
use crate::error::Result;
use crate::math::DisjointSet;
use crate::math::vec3::{cross, dist2, dot, sub};

/// What a [`Warning`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum WarningKind {
    /// Reported by a file reader (polygons triangulated, statements ignored).
    Reader,
    /// Faces with a repeated vertex index.
    RepeatedIndex,
    /// Faces whose area is zero up to rounding in some frame.
    ZeroArea,
    /// Edges shared by more than two faces.
    NonManifoldEdge,
    /// Interior edges whose two faces traverse them in the same direction.
    InconsistentOrientation,
    /// Vertices where separate fans of faces meet (e.g. two cones touching at their tips); their
    /// 1-ring has no single cyclic order.
    NonManifoldVertex,
    /// The surface is open (informational for data like faces; not a problem by itself).
    BoundaryLoops,
    /// More than one connected component.
    Components,
    /// Vertices referenced by no face.
    UnreferencedVertices,
}

/// One warning: its kind and a readable one-line message.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Warning {
    /// What it is about.
    pub kind: WarningKind,
    /// The message (vertex and face indices in it are 0-based).
    pub message: String,
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// Summary of a sequence, printed by `meshdeco inspect`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InspectReport {
    /// The directory, pattern or file it was loaded from (`None` for an in-memory sequence).
    pub source: Option<String>,
    /// Number of frames F.
    pub frames: usize,
    /// Names of the first and last frame.
    pub first_name: String,
    /// Name of the last frame.
    pub last_name: String,
    /// Number of vertices N.
    pub vertices: usize,
    /// Number of triangles T.
    pub faces: usize,
    /// Number of unique undirected edges E.
    pub edges: usize,
    /// Number of boundary edges (edges of exactly one face).
    pub boundary_edges: usize,
    /// Number of vertices of each boundary loop (0 loops for a closed surface).
    pub boundary_loops: Vec<usize>,
    /// Number of connected components (over vertices used by faces).
    pub components: usize,
    /// Euler characteristic V − E + F (vertices used by faces only).
    pub euler_characteristic: i64,
    /// Axis-aligned bounding box `(min, max)` of the first frame, in the data's units.
    pub bbox_first: (Vec3, Vec3),
    /// Axis-aligned bounding box `(min, max)` over all frames.
    pub bbox_all: (Vec3, Vec3),
    /// Mean length of the unique edges in the first frame, in the data's units.
    pub mean_edge_length: f64,
    /// Reader warnings first, then the connectivity/geometry warnings.
    pub warnings: Vec<Warning>,
}

/// Inspects an in-memory sequence (its faces must index valid vertices, as after loading).
pub fn inspect(seq: &MeshSequence) -> InspectReport {
    let n = seq.n_vertices();
    let topology = Topology::new(n, &seq.faces);
    let boundary_loops: Vec<usize> = topology.boundary_loops(&seq.faces).iter().map(|l| l.len()).collect();
    let (_, components) = topology.components();
    let used = n - topology.isolated_vertices().len();
    let first = seq.frames.first().map(Vec::as_slice).unwrap_or(&[]);
    let mean_edge_length = if topology.edges.is_empty() || first.is_empty() {
        0.0
    } else {
        topology.edges.iter().map(|e| dist(first[e[0]], first[e[1]])).sum::<f64>() / topology.edges.len() as f64
    };
    let mut bbox_all = bounding_box(first);
    for frame in seq.frames.iter().skip(1) {
        let (lo, hi) = bounding_box(frame);
        for k in 0..3 {
            bbox_all.0[k] = bbox_all.0[k].min(lo[k]);
            bbox_all.1[k] = bbox_all.1[k].max(hi[k]);
        }
    }
    InspectReport {
        source: None,
        frames: seq.n_frames(),
        first_name: seq.names.first().cloned().unwrap_or_default(),
        last_name: seq.names.last().cloned().unwrap_or_default(),
        vertices: n,
        faces: seq.n_faces(),
        edges: topology.edges.len(),
        boundary_edges: topology.n_boundary_edges(),
        boundary_loops,
        components,
        euler_characteristic: used as i64 - topology.edges.len() as i64 + seq.n_faces() as i64,
        bbox_first: bounding_box(first),
        bbox_all,
        mean_edge_length,
        warnings: mesh_warnings(seq, &topology),
    }
}

/// Loads a sequence (see [`super::sequence`] for `spec`) and inspects it; the readers' warnings
/// come first in the report's list.
pub fn inspect_path(spec: &str) -> Result<InspectReport> {
    let loaded = read_sequence(spec)?;
    let mut report = inspect(&loaded.sequence);
    report.source = Some(spec.to_string());
    let mut warnings: Vec<Warning> =
        loaded.warnings.into_iter().map(|message| Warning { kind: WarningKind::Reader, message }).collect();
    warnings.append(&mut report.warnings);
    report.warnings = warnings;
    Ok(report)
}

/// The connectivity and geometry warnings that point at a problem, i.e. all of
/// [`mesh_warnings`] except boundary loops (an open surface is normal for many datasets).
pub fn problem_warnings(seq: &MeshSequence, topology: &Topology) -> Vec<Warning> {
    mesh_warnings(seq, topology).into_iter().filter(|w| w.kind != WarningKind::BoundaryLoops).collect()
}

/// Faces count as zero-area when `|(b − a) × (c − a)| ≤ ZERO_AREA_REL · (longest edge)²`, i.e.
/// when their smallest angle's sine is at rounding level.
const ZERO_AREA_REL: f64 = 1e-12;

/// All connectivity and geometry warnings of a sequence (`topology` built from its faces).
pub fn mesh_warnings(seq: &MeshSequence, topology: &Topology) -> Vec<Warning> {
    let mut out = Vec::new();
    let mut warn = |kind, message: String| out.push(Warning { kind, message });
    let faces = &seq.faces;
    let s = |k: usize| if k == 1 { "" } else { "s" };

    let repeated: Vec<usize> = (0..faces.len())
        .filter(|&i| faces[i][0] == faces[i][1] || faces[i][1] == faces[i][2] || faces[i][0] == faces[i][2])
        .collect();
    if let Some(&i) = repeated.first() {
        warn(
            WarningKind::RepeatedIndex,
            format!(
                "{} degenerate face{} repeat a vertex index (first: face {i} = {:?})",
                repeated.len(),
                s(repeated.len()),
                faces[i]
            ),
        );
    }

    // Zero-area faces per frame (faces with repeated indices are already reported).
    let zero_area = |frame: &[Vec3]| -> Vec<usize> {
        (0..faces.len())
            .filter(|&i| {
                // Squared on both sides (no square roots): |n|² ≤ (rel · longest²)².
                let [a, b, c] = faces[i].map(|v| frame[v]);
                let longest2 = dist2(a, b).max(dist2(b, c)).max(dist2(c, a));
                let n = cross(sub(b, a), sub(c, a));
                dot(n, n) <= (ZERO_AREA_REL * longest2).powi(2)
            })
            .filter(|i| repeated.binary_search(i).is_err())
            .collect()
    };
    let mut first_other: Option<(usize, usize, usize)> = None; // (frame, count, first face)
    let mut other_frames = 0;
    for (f, frame) in seq.frames.iter().enumerate() {
        let z = zero_area(frame);
        if z.is_empty() {
            continue;
        }
        if f == 0 {
            warn(
                WarningKind::ZeroArea,
                format!(
                    "{} face{} of zero area in the first frame '{}' (first: face {} = {:?})",
                    z.len(),
                    s(z.len()),
                    seq.names.first().map_or("", |n| n.as_str()),
                    z[0],
                    faces[z[0]]
                ),
            );
        } else {
            other_frames += 1;
            first_other.get_or_insert((f, z.len(), z[0]));
        }
    }
    if let Some((f, count, i)) = first_other {
        warn(
            WarningKind::ZeroArea,
            format!(
                "faces of zero area in {other_frames} frame{} after the first (first: frame '{}', {count} face{}, face {i})",
                s(other_frames),
                seq.names.get(f).map_or("", |n| n.as_str()),
                s(count)
            ),
        );
    }

    // Edge checks count only incidences of faces without a repeated index (those are reported
    // above and would otherwise show up again as spurious non-manifold or flipped edges).
    let is_repeated = |face: usize| repeated.binary_search(&face).is_ok();
    let mut non_manifold: Vec<[usize; 2]> = Vec::new();
    let mut flipped: Vec<[usize; 2]> = Vec::new();
    let forward = |face: usize, a: usize, b: usize| {
        let f = faces[face];
        (0..3).any(|k| f[k] == a && f[(k + 1) % 3] == b)
    };
    for (e, inc) in topology.edges.iter().zip(&topology.edge_faces) {
        let mut proper = inc.iter().map(|&(face, _)| face).filter(|&face| !is_repeated(face));
        match (proper.next(), proper.next(), proper.next()) {
            (Some(_), Some(_), Some(_)) => non_manifold.push(*e),
            (Some(f1), Some(f2), None) if forward(f1, e[0], e[1]) == forward(f2, e[0], e[1]) => flipped.push(*e),
            _ => {}
        }
    }
    if let Some(e) = non_manifold.first() {
        warn(
            WarningKind::NonManifoldEdge,
            format!(
                "{} non-manifold edge{} shared by more than two faces (first: vertices {}–{})",
                non_manifold.len(),
                s(non_manifold.len()),
                e[0],
                e[1]
            ),
        );
    }
    if let Some(e) = flipped.first() {
        warn(
            WarningKind::InconsistentOrientation,
            format!(
                "{} edge{} whose two faces have opposite orientations (first: vertices {}–{}); normals and \
                 1-ring orders are unreliable there",
                flipped.len(),
                s(flipped.len()),
                e[0],
                e[1]
            ),
        );
    }

    let pinched = non_manifold_vertices(faces, topology, &is_repeated);
    if let Some(&v) = pinched.first() {
        let k = pinched.len();
        warn(
            WarningKind::NonManifoldVertex,
            format!(
                "{k} non-manifold vert{} where separate fans of faces meet (first: vertex {v}); their 1-rings \
                 have no single cyclic order",
                if k == 1 { "ex" } else { "ices" }
            ),
        );
    }

    let loops = topology.boundary_loops(faces);
    if !loops.is_empty() {
        let lengths: Vec<String> = loops.iter().map(|l| l.len().to_string()).collect();
        warn(
            WarningKind::BoundaryLoops,
            format!(
                "open surface: {} boundary loop{} ({} boundary edges; loop lengths {})",
                loops.len(),
                s(loops.len()),
                topology.n_boundary_edges(),
                abbreviate(&lengths)
            ),
        );
    }

    let (labels, n_components) = topology.components();
    if n_components > 1 {
        let mut sizes = vec![0usize; n_components];
        for &l in labels.iter().filter(|&&l| l != usize::MAX) {
            sizes[l] += 1;
        }
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        let sizes: Vec<String> = sizes.iter().map(|x| x.to_string()).collect();
        warn(
            WarningKind::Components,
            format!("{n_components} connected components (vertex counts {})", abbreviate(&sizes)),
        );
    }

    let mut referenced = vec![false; seq.n_vertices()];
    for f in faces {
        for &v in f {
            referenced[v] = true;
        }
    }
    let unreferenced: Vec<usize> = (0..referenced.len()).filter(|&v| !referenced[v]).collect();
    if let Some(&v) = unreferenced.first() {
        let k = unreferenced.len();
        warn(
            WarningKind::UnreferencedVertices,
            format!("{k} vert{} referenced by no face (first: vertex {v})", if k == 1 { "ex" } else { "ices" }),
        );
    }
    out
}

/// Vertices whose incident faces form more than one fan, i.e. whose face corners fall into
/// several groups when corners of the same vertex are joined across shared edges with exactly two
/// (non-degenerate) faces. Faces with a repeated index are left out.
fn non_manifold_vertices(
    faces: &[[usize; 3]],
    topology: &Topology,
    is_repeated: &impl Fn(usize) -> bool,
) -> Vec<usize> {
    // Union–find over corners `3 · face + k`.
    let mut corners = DisjointSet::new(3 * faces.len());
    let corner = |face: usize, v: usize| 3 * face + faces[face].iter().position(|&u| u == v).expect("vertex of face");
    for (e, inc) in topology.edges.iter().zip(&topology.edge_faces) {
        let proper: Vec<usize> = inc.iter().map(|&(f, _)| f).filter(|&f| !is_repeated(f)).collect();
        if let [f1, f2] = proper[..] {
            for &v in e {
                corners.union(corner(f1, v), corner(f2, v));
            }
        }
    }
    let mut fans: Vec<(usize, usize)> = Vec::with_capacity(3 * faces.len());
    for (fi, f) in faces.iter().enumerate() {
        if !is_repeated(fi) {
            for (k, &v) in f.iter().enumerate() {
                fans.push((v, corners.find(3 * fi + k)));
            }
        }
    }
    fans.sort_unstable();
    fans.dedup();
    let mut out: Vec<usize> = fans.windows(2).filter(|w| w[0].0 == w[1].0).map(|w| w[0].0).collect();
    out.dedup();
    out
}

/// Joins at most 8 items with ", ", then "… (k more)".
fn abbreviate(items: &[String]) -> String {
    let mut s = items.iter().take(8).cloned().collect::<Vec<_>>().join(", ");
    if items.len() > 8 {
        s += &format!(", … ({} more)", items.len() - 8);
    }
    s
}

/// A number with 6 significant digits, trailing zeros removed; scientific notation outside
/// 1e-4 ≤ |x| < 1e7.
fn num(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let mag = x.abs().log10().floor();
    if !(-4.0..7.0).contains(&mag) {
        return format!("{x:.5e}");
    }
    let s = format!("{x:.prec$}", prec = (5.0 - mag).max(0.0) as usize);
    if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s }
}

fn point(p: Vec3) -> String {
    format!("({}, {}, {})", num(p[0]), num(p[1]), num(p[2]))
}

impl fmt::Display for InspectReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let row = |f: &mut fmt::Formatter<'_>, key: &str, value: String| writeln!(f, "{key:<18}{value}");
        if let Some(src) = &self.source {
            row(f, "source", src.clone())?;
        }
        let names = match self.frames {
            0 => String::new(),
            1 => format!(" ({})", self.first_name),
            _ => format!(" ({} … {})", self.first_name, self.last_name),
        };
        row(f, "frames", format!("{}{names}", self.frames))?;
        row(f, "vertices", self.vertices.to_string())?;
        row(f, "faces", format!("{} triangles", self.faces))?;
        row(f, "edges", self.edges.to_string())?;
        let boundary = match self.boundary_loops.len() {
            0 => "0 loops (closed surface)".to_string(),
            k => {
                let lengths: Vec<String> = self.boundary_loops.iter().map(|l| l.to_string()).collect();
                format!(
                    "{k} loop{} ({} boundary edges; loop lengths {})",
                    if k == 1 { "" } else { "s" },
                    self.boundary_edges,
                    abbreviate(&lengths)
                )
            }
        };
        row(f, "boundary", boundary)?;
        row(f, "components", self.components.to_string())?;
        row(f, "euler char.", format!("{} (V − E + F)", self.euler_characteristic))?;
        let (lo, hi) = self.bbox_first;
        let size = sub(hi, lo);
        row(f, "bounding box", format!("first frame  min {}  max {}  size {}", point(lo), point(hi), point(size)))?;
        let (lo, hi) = self.bbox_all;
        let size = sub(hi, lo);
        row(f, "", format!("all frames   min {}  max {}  size {}", point(lo), point(hi), point(size)))?;
        row(f, "mean edge length", format!("{} (first frame)", num(self.mean_edge_length)))?;
        if self.warnings.is_empty() {
            row(f, "warnings", "none".to_string())?;
        } else {
            writeln!(f, "warnings ({}, vertex and face indices 0-based):", self.warnings.len())?;
            for w in &self.warnings {
                writeln!(f, "  - {w}")?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seq(frames: Vec<Vec<Vec3>>, faces: Vec<[usize; 3]>) -> MeshSequence {
        let names = (0..frames.len()).map(|i| format!("f{i}")).collect();
        MeshSequence { faces, frames, names }
    }

    /// Octahedron (closed, 6 vertices, 8 faces, 12 edges), scaled by `s`.
    fn octahedron(s: f64) -> (Vec<Vec3>, Vec<[usize; 3]>) {
        let p = vec![[s, 0.0, 0.0], [-s, 0.0, 0.0], [0.0, s, 0.0], [0.0, -s, 0.0], [0.0, 0.0, s], [0.0, 0.0, -s]];
        let f = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
        (p, f)
    }

    #[test]
    fn closed_surface_has_no_warnings() {
        let (p, f) = octahedron(1.0);
        let (q, _) = octahedron(2.0);
        let r = inspect(&seq(vec![p, q], f));
        assert_eq!((r.frames, r.vertices, r.faces, r.edges), (2, 6, 8, 12));
        assert!(r.boundary_loops.is_empty());
        assert_eq!(r.components, 1);
        assert_eq!(r.euler_characteristic, 2);
        assert_eq!(r.bbox_first, ([-1.0; 3], [1.0; 3]));
        assert_eq!(r.bbox_all, ([-2.0; 3], [2.0; 3]));
        assert!((r.mean_edge_length - 2f64.sqrt()).abs() < 1e-12);
        assert!(r.warnings.is_empty(), "{:?}", r.warnings);
        let text = r.to_string();
        assert!(text.contains("frames            2 (f0 … f1)\n"), "{text}");
        assert!(text.contains("boundary          0 loops (closed surface)\n"), "{text}");
        assert!(text.contains("warnings          none\n"), "{text}");
    }

    #[test]
    fn every_warning_kind_is_found() {
        // Octahedron with one face removed (a 3-loop) and one face flipped, plus a second
        // component that is a zero-area triangle, a face repeating an index, and an unreferenced
        // vertex.
        let (mut p, mut f) = octahedron(1.0);
        f.remove(7);
        f[0] = [0, 4, 2]; // flipped relative to its neighbours
        p.extend([[5.0, 0.0, 0.0], [6.0, 0.0, 0.0], [7.0, 0.0, 0.0], [9.0, 9.0, 9.0], [3.0; 3], [4.0; 3]]);
        f.push([6, 7, 8]); // collinear: zero area
        f.push([10, 11, 10]); // repeated index
        let r = inspect(&seq(vec![p], f));
        let kinds: Vec<WarningKind> = r.warnings.iter().map(|w| w.kind).collect();
        assert_eq!(
            kinds,
            vec![
                WarningKind::RepeatedIndex,
                WarningKind::ZeroArea,
                WarningKind::InconsistentOrientation,
                WarningKind::BoundaryLoops,
                WarningKind::Components,
                WarningKind::UnreferencedVertices,
            ],
            "{:#?}",
            r.warnings
        );
        assert!(r.warnings[0].message.contains("face 8 = [10, 11, 10]"), "{}", r.warnings[0]);
        assert!(r.warnings[1].message.starts_with("1 face of zero area") && r.warnings[1].message.contains("face 7"));
        assert!(r.warnings[2].message.starts_with("3 edges whose two faces"), "{}", r.warnings[2]);
        assert!(
            r.warnings[3].message.contains("2 boundary loops (6 boundary edges; loop lengths 3, 3)"),
            "{}",
            r.warnings[3]
        );
        assert!(r.warnings[4].message.contains("2 connected components (vertex counts 6, 3)"), "{}", r.warnings[4]);
        assert!(
            r.warnings[5].message.starts_with("1 vertex referenced by no face (first: vertex 9)"),
            "{}",
            r.warnings[5]
        );
        assert_eq!(r.components, 2);
    }

    #[test]
    fn bow_tie_vertex_is_non_manifold() {
        // Two triangles touching only at vertex 0, and a closed octahedron (no such vertex).
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];
        let r = inspect(&seq(vec![p], vec![[0, 1, 2], [0, 3, 4]]));
        let w = r.warnings.iter().find(|w| w.kind == WarningKind::NonManifoldVertex).expect("bow tie");
        assert!(w.message.starts_with("1 non-manifold vertex where") && w.message.contains("vertex 0)"), "{w}");
        assert_eq!(r.components, 1);
        let (_, f) = octahedron(1.0);
        let t = Topology::new(6, &f);
        assert!(non_manifold_vertices(&f, &t, &|_| false).is_empty());
        // An open fan (octahedron minus the faces around vertex 5 but one) is still one fan.
        let open: Vec<[usize; 3]> = f.iter().copied().filter(|f| !f.contains(&5)).chain([[2, 0, 5]]).collect();
        let t = Topology::new(6, &open);
        assert!(non_manifold_vertices(&open, &t, &|_| false).is_empty());
    }

    #[test]
    fn an_open_surface_alone_is_not_a_problem() {
        let (p, mut f) = octahedron(1.0);
        f.pop();
        let s = seq(vec![p], f);
        let t = Topology::new(6, &s.faces);
        assert_eq!(mesh_warnings(&s, &t).len(), 1);
        assert!(problem_warnings(&s, &t).is_empty());
    }

    #[test]
    fn non_manifold_and_later_zero_area_frames() {
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]];
        let f = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        let mut q = p.clone();
        q[4] = [0.5, 0.0, 0.0]; // face 2 collapses onto the edge 0–1 in the second frame
        let r = inspect(&seq(vec![p, q], f));
        let nm = r.warnings.iter().find(|w| w.kind == WarningKind::NonManifoldEdge).unwrap();
        assert!(nm.message.starts_with("1 non-manifold edge shared") && nm.message.contains("vertices 0–1"), "{nm}");
        let za = r.warnings.iter().find(|w| w.kind == WarningKind::ZeroArea).unwrap();
        assert!(za.message.contains("in 1 frame after the first (first: frame 'f1', 1 face, face 2)"), "{za}");
    }

    #[test]
    fn numbers_print_with_six_significant_digits() {
        assert_eq!(num(1222.30081), "1222.3");
        assert_eq!(num(0.0176488), "0.0176488");
        assert_eq!(num(-2.0), "-2");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(1.5e-7), "1.50000e-7");
        assert_eq!(num(123456789.0), "1.23457e8");
    }

    /// Counts and plurals of the messages, each repeated-index position, faces that are not
    /// there, and the bounds of the abbreviated lists and of the frame line.
    #[test]
    fn counts_plurals_and_bounds_of_the_report() {
        // A repeated index at each pair of positions: three degenerate faces.
        let p =
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [1.0, 0.0, 1.0]];
        let r = inspect(&seq(vec![p], vec![[0, 0, 1], [2, 3, 3], [4, 5, 4]]));
        assert_eq!(r.warnings[0].kind, WarningKind::RepeatedIndex);
        assert!(
            r.warnings[0].message.starts_with("3 degenerate faces repeat a vertex index (first: face 0 = [0, 0, 1])")
        );

        // No faces: no edges (mean edge length 0, not 0/0), every vertex unreferenced.
        let r = inspect(&seq(vec![vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]], vec![]));
        assert_eq!((r.edges, r.mean_edge_length, r.euler_characteristic), (0, 0.0, 0));
        let w = r.warnings.last().unwrap();
        assert_eq!(w.kind, WarningKind::UnreferencedVertices);
        assert!(w.message.starts_with("3 vertices referenced by no face (first: vertex 0)"), "{w}");

        // An unreferenced vertex does not count in V − E + F; one frame prints its name alone.
        let (mut p, f) = octahedron(1.0);
        p.push([5.0; 3]);
        let r = inspect(&seq(vec![p], f.clone()));
        assert_eq!((r.vertices, r.euler_characteristic, r.components), (7, 2, 1));
        assert!(r.to_string().contains("frames            1 (f0)\n"), "{r}");
        let empty = inspect(&seq(vec![], vec![]));
        assert!(empty.to_string().contains("frames            0\n"), "{empty}");

        // Problems are every warning but the boundary loops.
        let (p, mut f) = octahedron(1.0);
        f.pop();
        f.push([0, 0, 1]);
        let s = seq(vec![p], f);
        let t = Topology::new(6, &s.faces);
        let kinds = |w: Vec<Warning>| w.iter().map(|w| w.kind).collect::<Vec<_>>();
        assert_eq!(kinds(mesh_warnings(&s, &t)), [WarningKind::RepeatedIndex, WarningKind::BoundaryLoops]);
        assert_eq!(kinds(problem_warnings(&s, &t)), [WarningKind::RepeatedIndex]);

        // One boundary loop, in the report's text and in its warning.
        let (p, mut f) = octahedron(1.0);
        f.pop();
        let r = inspect(&seq(vec![p], f));
        assert!(r.to_string().contains("boundary          1 loop (3 boundary edges; loop lengths 3)\n"), "{r}");
        assert!(
            r.warnings[0].message.contains("1 boundary loop (3 boundary edges; loop lengths 3)"),
            "{}",
            r.warnings[0]
        );
        assert_eq!(r.warnings[0].to_string(), r.warnings[0].message);
        assert!(
            r.to_string().contains("warnings (1, vertex and face indices 0-based):\n  - open surface: 1 boundary loop"),
            "{r}"
        );

        // Zero area: two faces in the first frame, one face in each of two later frames.
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]];
        let f = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        let (mut flat, mut later) = (p.clone(), p.clone());
        flat[2] = [0.25, 0.0, 0.0];
        flat[4] = [0.5, 0.0, 0.0];
        later[4] = [0.5, 0.0, 0.0];
        let r = inspect(&seq(vec![flat, later.clone(), later], f));
        let za: Vec<&Warning> = r.warnings.iter().filter(|w| w.kind == WarningKind::ZeroArea).collect();
        assert_eq!(za.len(), 2, "{za:?}");
        assert!(za[0].message.starts_with("2 faces of zero area in the first frame 'f0' (first: face 0 = [0, 1, 2])"));
        assert!(za[1].message.contains("in 2 frames after the first (first: frame 'f1', 1 face, face 2)"), "{}", za[1]);

        // Lists of up to 8 items are written whole.
        let items = |n: usize| (1..=n).map(|i| i.to_string()).collect::<Vec<_>>();
        assert_eq!(abbreviate(&items(8)), "1, 2, 3, 4, 5, 6, 7, 8");
        assert_eq!(abbreviate(&items(9)), "1, 2, 3, 4, 5, 6, 7, 8, … (1 more)");
        assert_eq!(abbreviate(&items(11)), "1, 2, 3, 4, 5, 6, 7, 8, … (3 more)");
    }

    /// The report's bounding-box rows: each corner and the size as points of `num`s, for the
    /// first frame and over all frames.
    #[test]
    fn report_rows_show_both_boxes_as_points() {
        let (p, f) = octahedron(1.0);
        let (mut q, _) = octahedron(2.5);
        q[3] = [0.0, -0.125, 0.0];
        let text = inspect(&seq(vec![p, q], f)).to_string();
        let rows: Vec<&str> = text.lines().filter(|l| l.contains(" min (")).collect();
        assert_eq!(
            rows,
            [
                "bounding box      first frame  min (-1, -1, -1)  max (1, 1, 1)  size (2, 2, 2)",
                "                  all frames   min (-2.5, -1, -2.5)  max (2.5, 2.5, 2.5)  size (5, 3.5, 5)",
            ],
            "{text}"
        );
        assert!(text.contains("\nmean edge length  1.41421 (first frame)\n"), "{text}");
    }
}
