//! Geodesic distances by the heat method (Crane, Weischedel & Wardetzky 2013), factor once /
//! query many.
//!
//! # Algorithm
//! With `L` the positive semi-definite cotangent Laplacian (`L_ii = Σ w_ij`, `L_ij = −w_ij`, as
//! in [`super::cotan_laplacian`]), `M` the barycentric lumped mass, both built on the intrinsic
//! Delaunay triangulation of the mesh (see below), `h` the mean edge length of the input mesh and
//! `t = m·h²`:
//!
//! 1. heat flow: solve `(M + t·L) u = δ_S` (one backward-Euler step from the indicator of the
//!    source set S; with the PSD sign this is Crane's `(A − tL_c) u = δ`);
//! 2. per face: `X = −∇u / |∇u|` (faces where `∇u` is exactly zero or not finite get `X = 0`);
//! 3. integrated divergence and Poisson solve: `L φ = Gᵀ M_F X`, i.e. the least-squares fit of
//!    `∇φ` to `X` (`G` the per-face gradient, `M_F` the face areas). Per vertex the right-hand side
//!    is `Σ_f area_f ∇φ_i|_f · X_f`, the same as Crane's
//!    `½ Σ cot θ₁ (e₁·X) + cot θ₂ (e₂·X)` with the opposite sign convention of `L`;
//! 4. shift so that the smallest distance in each connected component that holds a source is 0.
//!
//! Both systems are factored once in [`HeatGeodesics::new`] (sparse Cholesky, one shared
//! symbolic analysis); a query costs two or three sparse triangular solve pairs plus two passes
//! over the faces, and never forms an N×N dense matrix. Gradients and divergences are computed
//! per triangle in the triangle's own plane (from its side lengths), so everything is intrinsic.
//!
//! # Intrinsic Delaunay triangulation (default)
//! Crane et al. suggest it for meshes of poor quality, and real meshes need it: on the horse
//! gallop (many obtuse triangles, 4552 negative cotangent weights) the heat method on the mesh's
//! own triangles returns 0.35 for a vertex whose edge-path distance is 1.87 (≈ 60 h too short),
//! because with negative weights the heat solution oscillates and cancels far from the source.
//! The operators are therefore built on the intrinsic Delaunay triangulation
//! ([`super::intrinsic_delaunay`]: same vertices and surface, edges flipped until every interior
//! weight is ≥ 0). The weights still negative there (boundary edges, which cannot be flipped, and
//! rare skipped flips) are set to 0 in the heat system only, so `M + tL` is an M-matrix: the heat
//! solution is positive and its triangular solves have no cancellation. The horse's distances
//! then agree with the edge-path distances (see the tests). On meshes that are already Delaunay
//! (the test primitives) nothing changes. `HeatOptions::intrinsic_delaunay = false` uses the
//! mesh's own triangles and weights.
//!
//! # Clamping to rigorous bounds ([`DistanceBounds`])
//! Every geodesic distance on the surface lies between the straight-line distance to the
//! nearest source and the edge-path (Dijkstra) distance. By default each result is raised to at
//! least the straight-line distance (cheap); [`DistanceBounds::StraightLineAndEdgePath`] also
//! caps it by the edge-path distance (one Dijkstra search per query). Since the exact value lies
//! in the interval, clamping can only reduce the error. It matters on meshes the heat method
//! cannot resolve: frame 1 of `face-poses` has a band of sliver triangles 1.4 long (80×
//! the mean edge) where the heat method returns distances far below the straight-line
//! distance (by up to 50 h at m = 1, with or without the intrinsic Delaunay triangulation); on
//! good meshes it changes values by at most about an edge length.
//!
//! # Making the Poisson system definite (pinning)
//! `L` is singular: its kernel is the constants on every connected component (components are
//! formed by the non-degenerate faces). In each component one vertex (its smallest index) is
//! pinned: its row and column are replaced by the identity row/column and its right-hand side
//! set to 0, which makes the system SPD without changing the solution beyond a constant per
//! component (the pinned equation is implied by the others because `Gᵀ` maps into the
//! complement of the constants). The constant is then removed by step 4.
//! Vertices on no non-degenerate face (isolated, or only on degenerate faces) get an identity row
//! in both systems; their distance is 0 if they are a source, otherwise their edge-path distance
//! with [`DistanceBounds::StraightLineAndEdgePath`] and `+∞` otherwise. Vertices in a component
//! without any source get `+∞` (callers that save distances must handle it).
//!
//! # Boundary conditions
//! [`BoundaryCondition::Averaged`] (the default, the recommendation of Crane et al.) averages
//! the heat of the Neumann solution (the natural condition of the system above) and of the Dirichlet
//! solution (`u = 0` on boundary vertices: their rows/columns replaced by the identity, a second
//! factorisation). A source on the boundary is exempt from the Dirichlet condition (`u = 0` on
//! the rest of the boundary only): the factored Dirichlet system is reused with a Schur
//! complement on the k boundary sources (k + 1 right-hand sides and a dense k×k solve). With more
//! than [`MAX_FREE_BOUNDARY_SOURCES`] boundary sources a query uses the Neumann solution alone.
//! On a closed mesh both options are identical. [`BoundaryCondition::Neumann`] uses the Neumann
//! solution only (one factorisation and one heat solve per query less).
//!
//! # Units
//! Distances are in the units of the positions; scaling the mesh by `s` scales every distance by
//! `s` (h scales by `s`, t by `s²`, `L` is scale-invariant).
//!
//! # Accuracy (measured by the unit tests, without the clamping)
//! m = 1 on a unit icosphere with 2562 vertices (4 subdivisions): largest error against the
//! great-circle distance 1.0% of π (mean 0.4%); on a flat 40×40 grid: largest error 0.4–0.55 h
//! for interior and edge sources, 0.96 h for a corner source (`h` the mean edge length; Neumann
//! alone: up to 1.5 h). Multi-source queries overestimate by up to ≈ 1.2 h along the lines
//! equidistant from two sources (the kink of the minimum is smoothed). Open cylinder (64×40):
//! 0.9–1.0 h against the unrolled distance. Sheared planar strip (157 h long, non-Delaunay
//! diagonals): 0.72 h (2.26 h without the intrinsic Delaunay triangulation). Horse gallop frame 1:
//! within [graph/1.2 − 0.75 h, graph + 0.52 h] of the edge-path distances. Larger m smooths
//! more (SPLOCS uses m = 10): distances become smoother and less exact.

use faer::sparse::SparseColMat;

use crate::geometry::cotan_laplacian::{EdgeIncidence, SymmetricPattern};
use crate::geometry::graph_distance::EdgeGraph;
use crate::geometry::intrinsic_delaunay::{IntrinsicTriangulation, area_from_lengths};
use crate::geometry::sparse_cholesky::{FactorLayout, SparseCholesky};
use crate::math::DisjointSet;
use crate::mesh::Vec3;
use crate::{Error, Result};

/// Boundary condition of the heat flow step. See the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BoundaryCondition {
    /// Zero normal derivative (the natural condition of the FEM system).
    Neumann,
    /// Mean of the Neumann and the Dirichlet (`u = 0` on the boundary) solutions; Neumann alone
    /// for a query with a source on the boundary.
    #[default]
    Averaged,
}

/// Hyperparameters of the heat method.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeatOptions {
    /// Time step factor: `t = m·h²` with `h` the mean edge length. Must be finite and > 0.
    /// Crane et al. suggest 1; the SPLOCS reference uses 10.
    pub m: f64,
    /// Boundary condition of the heat step.
    pub boundary: BoundaryCondition,
    /// Build the operators on the intrinsic Delaunay triangulation of the mesh (default `true`,
    /// see the module docs); `false` uses the mesh's own triangles.
    pub intrinsic_delaunay: bool,
    /// Rigorous bounds every distance is clamped into (see the module docs).
    pub bounds: DistanceBounds,
}

/// Rigorous bounds of the geodesic distance that results are clamped into. Every geodesic
/// distance on the surface is at least the straight-line distance to the nearest source and at
/// most the edge-path (Dijkstra) distance; clamping into an interval that holds the exact value
/// can only reduce the error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DistanceBounds {
    /// The heat method's values as they are.
    None,
    /// At least the straight-line distance to the nearest source (O(N·|S|) per query, about
    /// 0.03 ms on the horse). The default: it removes the heat method's dangerous failure mode,
    /// distances far too small where it cannot resolve the mesh.
    #[default]
    StraightLine,
    /// Also at most the edge-path distance (one Dijkstra search per query, about as long as the
    /// heat method's own solves). Trims the overestimates near the sources (≤ 2 h at m = 1, up to
    /// 6 h at m = 10 on the test meshes).
    StraightLineAndEdgePath,
}

impl Default for HeatOptions {
    /// `m = 1`, averaged boundary conditions, intrinsic Delaunay triangulation, straight-line
    /// lower bound.
    fn default() -> Self {
        HeatOptions {
            m: 1.0,
            boundary: BoundaryCondition::Averaged,
            intrinsic_delaunay: true,
            bounds: DistanceBounds::StraightLine,
        }
    }
}

impl HeatOptions {
    /// Options with time factor `m` and the default boundary condition.
    pub fn with_m(m: f64) -> Self {
        HeatOptions { m, ..Default::default() }
    }

    /// Checks `m` (finite, > 0).
    pub fn validate(&self) -> Result<()> {
        if !(self.m.is_finite() && self.m > 0.0) {
            return Err(Error::Invalid(format!("heat method time factor m ({}) must be finite and positive", self.m)));
        }
        Ok(())
    }
}

const NONE: usize = usize::MAX;

/// With [`BoundaryCondition::Averaged`], a query with more sources on the boundary than this
/// skips the Dirichlet half (see the module docs).
pub const MAX_FREE_BOUNDARY_SOURCES: usize = 64;

/// Heat-method geodesic distance solver for one mesh (positions fixed at construction).
///
/// Build once with [`HeatGeodesics::new`], then call [`HeatGeodesics::distances`] for any
/// number of source sets. Thread-safe (`&self` queries).
#[derive(Debug, Clone)]
pub struct HeatGeodesics {
    n: usize,
    options: HeatOptions,
    mean_edge_length: f64,
    t: f64,
    /// Non-degenerate faces only.
    faces: Vec<[usize; 3]>,
    /// Per kept face: gradients of the three hat functions (constant on the face) in the face's
    /// own 2D layout, 1/length.
    grad_basis: Vec<[[f64; 2]; 3]>,
    /// Per kept face: area.
    area: Vec<f64>,
    /// Heat matrix M + tL (Neumann), kept for the boundary-source Schur complement.
    heat_matrix: SparseColMat<usize, f64>,
    heat_neumann: SparseCholesky,
    heat_dirichlet: Option<SparseCholesky>,
    poisson: SparseCholesky,
    is_boundary: Vec<bool>,
    /// Component label per vertex (`NONE` for vertices on no kept face).
    label: Vec<usize>,
    n_components: usize,
    /// Positions for the straight-line bound (kept unless the bounds are `None`).
    positions: Vec<Vec3>,
    /// Edge graph for the edge-path bound.
    graph: Option<EdgeGraph>,
}

impl HeatGeodesics {
    /// Prepares the solver for the mesh (`positions`: N points, `faces`: triangles) with time
    /// factor `m` and [`BoundaryCondition::Averaged`]. See [`HeatGeodesics::with_options`].
    pub fn new(positions: &[Vec3], faces: &[[usize; 3]], m: f64) -> Result<Self> {
        Self::with_options(positions, faces, HeatOptions::with_m(m))
    }

    /// Prepares the solver: validates the input, assembles and factors the heat system(s) and the
    /// pinned Poisson system, precomputes per-face gradient bases and areas.
    ///
    /// Errors ([`Error::Invalid`]) on: invalid `options`, no vertex, no face, a face index ≥ N,
    /// a non-finite coordinate, or no non-degenerate face; [`Error::Numerical`] if a
    /// factorisation fails.
    pub fn with_options(positions: &[Vec3], faces: &[[usize; 3]], options: HeatOptions) -> Result<Self> {
        options.validate()?;
        let n = positions.len();
        if n == 0 || faces.is_empty() {
            return Err(Error::Invalid(format!(
                "heat geodesics need a mesh with faces (got {n} vertices, {} faces)",
                faces.len()
            )));
        }
        if let Some((fi, f)) = faces.iter().enumerate().find(|(_, f)| f.iter().any(|&v| v >= n)) {
            return Err(Error::Invalid(format!("face {fi} {f:?} refers to a vertex ≥ {n} (number of vertices)")));
        }
        if let Some((vi, p)) = positions.iter().enumerate().find(|(_, p)| p.iter().any(|c| !c.is_finite())) {
            return Err(Error::Invalid(format!("vertex {vi} has a non-finite coordinate {p:?}")));
        }
        let mut edge_sum = 0.0;
        for f in faces {
            for k in 0..3 {
                edge_sum += crate::mesh::dist(positions[f[k]], positions[f[(k + 1) % 3]]);
            }
        }
        let mean_edge_length = edge_sum / (3 * faces.len()) as f64;
        let tri = if options.intrinsic_delaunay {
            IntrinsicTriangulation::delaunay(positions, faces)
        } else {
            IntrinsicTriangulation::new(positions, faces)
        };
        if (0..faces.len()).all(|f| tri.is_degenerate(f)) || mean_edge_length.is_nan() || mean_edge_length <= 0.0 {
            return Err(Error::Invalid(format!(
                "heat geodesics: all {} faces are degenerate (zero area)",
                faces.len()
            )));
        }
        let t = options.m * mean_edge_length * mean_edge_length;

        // Kept (non-degenerate) triangles of the (intrinsic) triangulation, each laid out in its
        // own plane: per-face gradient basis (2D) and area.
        let mut kept = Vec::with_capacity(faces.len());
        let mut grad_basis = Vec::with_capacity(faces.len());
        let mut area = Vec::with_capacity(faces.len());
        for (fi, f) in tri.faces().iter().enumerate() {
            if tri.is_degenerate(fi) {
                continue;
            }
            let l = tri.side_lengths()[fi];
            let a = area_from_lengths(l);
            // Corner 0 at the origin, corner 1 on the x axis, corner 2 above (counter-clockwise).
            let x2 = (l[0] * l[0] + l[2] * l[2] - l[1] * l[1]) / (2.0 * l[0]);
            let p = [[0.0, 0.0], [l[0], 0.0], [x2, 2.0 * a / l[0]]];
            let mut g = [[0.0; 2]; 3];
            for (c, gc) in g.iter_mut().enumerate() {
                // Side opposite corner c, counter-clockwise, turned by +90°: points towards c,
                // length |e| / 2A = 1 / height.
                let e = [p[(c + 2) % 3][0] - p[(c + 1) % 3][0], p[(c + 2) % 3][1] - p[(c + 1) % 3][1]];
                *gc = [-e[1] / (2.0 * a), e[0] / (2.0 * a)];
            }
            kept.push(*f);
            grad_basis.push(g);
            area.push(a);
        }

        // Components over the kept faces (union–find); pin = smallest vertex of each.
        let mut sets = DisjointSet::new(n);
        let mut on_face = vec![false; n];
        for f in &kept {
            for &v in f {
                on_face[v] = true;
            }
            sets.union(f[0], f[1]);
            sets.union(f[0], f[2]);
        }
        let mut label = vec![NONE; n];
        let mut root_label = vec![NONE; n];
        let mut pinned = vec![false; n];
        let mut n_components = 0;
        for v in 0..n {
            if !on_face[v] {
                continue;
            }
            let r = sets.find(v);
            if root_label[r] == NONE {
                root_label[r] = n_components;
                n_components += 1;
                pinned[v] = true; // first (smallest) vertex of its component
            }
            label[v] = root_label[r];
        }

        let (pairs, weights) = tri.edge_weights();
        let mass = tri.lumped_mass();
        let pattern = SymmetricPattern::from_edges(n, &pairs);
        let mut lap_diag = vec![0.0; n];
        for (e, &w) in pairs.iter().zip(&weights) {
            lap_diag[e[0]] += w;
            lap_diag[e[1]] += w;
        }

        // Heat system (Neumann): M + tL; identity rows for vertices on no kept face. On the
        // intrinsic Delaunay triangulation the weights left negative (boundary edges, skipped
        // flips) are clamped to 0 in this system only, which makes it an M-matrix.
        let heat_weights: Vec<f64> =
            if options.intrinsic_delaunay { weights.iter().map(|w| w.max(0.0)).collect() } else { weights.clone() };
        let mut heat_lap_diag = vec![0.0; n];
        for (e, &w) in pairs.iter().zip(&heat_weights) {
            heat_lap_diag[e[0]] += w;
            heat_lap_diag[e[1]] += w;
        }
        let heat_diag: Vec<f64> =
            (0..n).map(|i| if label[i] == NONE { 1.0 } else { mass[i] + t * heat_lap_diag[i] }).collect();
        let heat_off: Vec<f64> = heat_weights.iter().map(|w| -t * w).collect();
        let heat_matrix = pattern.assemble(&heat_diag, &heat_off);
        let symbolic = SparseCholesky::analyze_with(heat_matrix.as_ref(), FactorLayout::PreferSimplicial)?;
        let heat_neumann =
            SparseCholesky::factor_with_symbolic(symbolic.clone(), heat_matrix.as_ref(), "heat system M + tL")?;

        let is_boundary = EdgeIncidence::new(faces).boundary_vertices(n);
        let has_boundary = is_boundary.iter().any(|&b| b);
        let heat_dirichlet = if options.boundary == BoundaryCondition::Averaged && has_boundary {
            let off = masked_off(&pairs, &heat_off, &is_boundary);
            let diag: Vec<f64> = (0..n).map(|i| if is_boundary[i] { 1.0 } else { heat_diag[i] }).collect();
            let m = pattern.assemble(&diag, &off);
            Some(SparseCholesky::factor_with_symbolic(symbolic.clone(), m.as_ref(), "Dirichlet heat system M + tL")?)
        } else {
            None
        };

        // Pinned Poisson system.
        let fixed: Vec<bool> = (0..n).map(|i| pinned[i] || label[i] == NONE).collect();
        let lap_off: Vec<f64> = weights.iter().map(|w| -w).collect();
        let off = masked_off(&pairs, &lap_off, &fixed);
        let diag: Vec<f64> = (0..n).map(|i| if fixed[i] { 1.0 } else { lap_diag[i] }).collect();
        let poisson_matrix = pattern.assemble(&diag, &off);
        let poisson =
            SparseCholesky::factor_with_symbolic(symbolic, poisson_matrix.as_ref(), "pinned Poisson system L")?;

        Ok(HeatGeodesics {
            n,
            options,
            mean_edge_length,
            t,
            faces: kept,
            grad_basis,
            area,
            heat_matrix,
            heat_neumann,
            heat_dirichlet,
            poisson,
            is_boundary,
            label,
            n_components,
            positions: if options.bounds == DistanceBounds::None { Vec::new() } else { positions.to_vec() },
            graph: (options.bounds == DistanceBounds::StraightLineAndEdgePath)
                .then(|| EdgeGraph::new(positions, faces)),
        })
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.n
    }

    /// The options the solver was built with.
    pub fn options(&self) -> HeatOptions {
        self.options
    }

    /// Mean edge length h over the faces' edges (an interior edge counted once per face, as in
    /// [`crate::mesh::TriMesh::mean_edge_length`]), in length units.
    pub fn mean_edge_length(&self) -> f64 {
        self.mean_edge_length
    }

    /// Time step t = m·h² (length²).
    pub fn time_step(&self) -> f64 {
        self.t
    }

    /// Number of connected components (over non-degenerate faces).
    pub fn n_components(&self) -> usize {
        self.n_components
    }

    /// Geodesic distance from the nearest vertex of `sources` to every vertex, in length units:
    /// N values, ≥ 0, the minimum 0 in each component that holds a source (with the default
    /// bounds every source is exactly 0), `+∞` for vertices not connected to any source.
    /// Duplicate sources are allowed. Cost: two or three sparse solve pairs, two passes over the
    /// faces, the bounds (N·|S| distances; one Dijkstra search for the edge-path bound).
    ///
    /// Errors ([`Error::Invalid`]) on an empty source list or a source index ≥ N.
    pub fn distances(&self, sources: &[usize]) -> Result<Vec<f64>> {
        let mut out = vec![0.0; self.n];
        self.distances_into(sources, &mut out)?;
        Ok(out)
    }

    /// Like [`HeatGeodesics::distances`] but writes into `out` (N values).
    pub fn distances_into(&self, sources: &[usize], out: &mut [f64]) -> Result<()> {
        if sources.is_empty() {
            return Err(Error::Invalid("geodesic distances: no source vertex given".into()));
        }
        if let Some(&s) = sources.iter().find(|&&s| s >= self.n) {
            return Err(Error::Invalid(format!(
                "geodesic source vertex {s} out of range (the mesh has {} vertices)",
                self.n
            )));
        }
        if out.len() != self.n {
            return Err(Error::Invalid(format!(
                "output buffer holds {} values, the mesh has {} vertices",
                out.len(),
                self.n
            )));
        }
        let n = self.n;

        // 1. Heat flow.
        let mut u = vec![0.0; n];
        for &s in sources {
            u[s] = 1.0;
        }
        let ud = self.heat_dirichlet.as_ref().and_then(|fact| self.dirichlet_heat(fact, sources));
        self.heat_neumann.solve_in_place(&mut u);
        if let Some(ud) = ud {
            for (a, b) in u.iter_mut().zip(&ud) {
                *a = 0.5 * (*a + b);
            }
        }

        // 2–3. Normalised negative gradient per face and its integrated divergence (into `out`).
        let rhs = out;
        rhs.fill(0.0);
        for ((f, g), &a) in self.faces.iter().zip(&self.grad_basis).zip(&self.area) {
            let (u0, u1, u2) = (u[f[0]], u[f[1]], u[f[2]]);
            let gu = [g[0][0] * u0 + g[1][0] * u1 + g[2][0] * u2, g[0][1] * u0 + g[1][1] * u1 + g[2][1] * u2];
            let len = (gu[0] * gu[0] + gu[1] * gu[1]).sqrt();
            if !(len > 0.0 && len.is_finite()) {
                continue;
            }
            let s = -a / len; // area × (−1/|∇u|)
            for c in 0..3 {
                rhs[f[c]] += s * (g[c][0] * gu[0] + g[c][1] * gu[1]);
            }
        }
        // Pinned vertices (first of each component) and vertices on no face: right-hand side 0.
        let mut seen = vec![false; self.n_components];
        for (r, &l) in rhs.iter_mut().zip(&self.label) {
            if l == NONE {
                *r = 0.0;
            } else if !seen[l] {
                seen[l] = true;
                *r = 0.0;
            }
        }
        self.poisson.solve_in_place(rhs);
        let phi = rhs;

        // 4. Shift per component so the minimum is 0; +∞ where no source is connected.
        let mut has_source = vec![false; self.n_components];
        let mut isolated_source = Vec::new();
        for &s in sources {
            match self.label[s] {
                NONE => isolated_source.push(s),
                l => has_source[l] = true,
            }
        }
        let mut min = vec![f64::INFINITY; self.n_components];
        for (&p, &l) in phi.iter().zip(&self.label) {
            if l != NONE && p < min[l] {
                min[l] = p;
            }
        }
        for (p, &l) in phi.iter_mut().zip(&self.label) {
            *p = if l != NONE && has_source[l] { *p - min[l] } else { f64::INFINITY };
        }
        for s in isolated_source {
            phi[s] = 0.0;
        }

        // 5. Rigorous bounds: straight line ≤ geodesic ≤ edge path.
        if self.options.bounds != DistanceBounds::None {
            let pos = &self.positions;
            for (v, p) in phi.iter_mut().enumerate() {
                if p.is_finite() {
                    let lo = sources.iter().map(|&s| crate::mesh::dist(pos[v], pos[s])).fold(f64::INFINITY, f64::min);
                    *p = p.max(lo);
                }
            }
        }
        if let Some(graph) = &self.graph {
            let upper = graph.distances(sources);
            for (p, up) in phi.iter_mut().zip(upper) {
                *p = if p.is_finite() { p.min(up) } else { up };
            }
        }
        if let Some(bad) = phi.iter().position(|x| x.is_nan()) {
            return Err(Error::Numerical(format!("heat geodesics produced NaN at vertex {bad}")));
        }
        Ok(())
    }

    /// Dirichlet heat solution (`u = 0` on boundary vertices that are not sources), or `None`
    /// when more than [`MAX_FREE_BOUNDARY_SOURCES`] sources lie on the boundary.
    ///
    /// With I the constrained-free vertices of the factored Dirichlet system (interior), B the
    /// boundary sources and A the heat matrix:
    /// `[A_II A_IB; A_BI A_BB] [u_I; u_B] = [δ_I; 1]`, solved as
    /// `Y = A_II⁻¹ [δ_I, −A_IB]`, `(A_BB + A_BI Y_B) u_B = 1 − A_BI Y_0`, `u_I = Y_0 + Y_B u_B`.
    fn dirichlet_heat(&self, fact: &SparseCholesky, sources: &[usize]) -> Option<Vec<f64>> {
        let n = self.n;
        let mut free: Vec<usize> = sources.iter().copied().filter(|&s| self.is_boundary[s]).collect();
        free.sort_unstable();
        free.dedup();
        let k = free.len();
        if k > MAX_FREE_BOUNDARY_SOURCES {
            return None;
        }
        let mut y = vec![0.0; n * (k + 1)];
        for &s in sources {
            if !self.is_boundary[s] {
                y[s] = 1.0;
            }
        }
        if k == 0 {
            fact.solve_in_place(&mut y);
            return Some(y);
        }
        let a = self.heat_matrix.as_ref();
        for (j, &b) in free.iter().enumerate() {
            let col = &mut y[(j + 1) * n..(j + 2) * n];
            for (&row, &val) in a.row_idx_of_col_raw(b).iter().zip(a.val_of_col(b)) {
                if !self.is_boundary[row] {
                    col[row] = -val;
                }
            }
        }
        fact.solve_columns_in_place(&mut y, k + 1);
        // Dense Schur complement system on the boundary sources.
        let mut s = vec![0.0; k * k];
        let mut r = vec![1.0; k];
        for (p, &bp) in free.iter().enumerate() {
            for (&row, &val) in a.row_idx_of_col_raw(bp).iter().zip(a.val_of_col(bp)) {
                if self.is_boundary[row] {
                    if let Ok(q) = free.binary_search(&row) {
                        s[p * k + q] += val;
                    }
                } else {
                    r[p] -= val * y[row];
                    for q in 0..k {
                        s[p * k + q] += val * y[(q + 1) * n + row];
                    }
                }
            }
        }
        let ub = solve_dense(&mut s, &mut r, k)?;
        let (y0, yb) = y.split_at_mut(n);
        for (q, &bq) in free.iter().enumerate() {
            let col = &yb[q * n..(q + 1) * n];
            for i in 0..n {
                y0[i] += col[i] * ub[q];
            }
            y0[bq] = ub[q];
        }
        y.truncate(n);
        Some(y)
    }

    /// Double sweep: the farthest vertex `a` from a start vertex (vertex 0, or the first vertex on
    /// a non-degenerate face if vertex 0 is on none), then the farthest vertex `b` from `a`.
    /// Returns `(a, b, d(a, b))`. Only the start vertex's component is explored.
    pub fn double_sweep(&self) -> Result<(usize, usize, f64)> {
        let start = (0..self.n).find(|&v| self.label[v] != NONE).unwrap_or(0);
        let d0 = self.distances(&[start])?;
        let a = argmax_finite(&d0).unwrap_or(start);
        let da = self.distances(&[a])?;
        let b = argmax_finite(&da).unwrap_or(a);
        Ok((a, b, da[b]))
    }

    /// Estimate of the largest pairwise geodesic distance (the geodesic diameter) by the double
    /// sweep of [`HeatGeodesics::double_sweep`], in length units. It is the eccentricity of one
    /// vertex, so (up to the heat method's error) it lies between half the true diameter and the
    /// diameter, and in practice is very close to the diameter on shapes like bodies or faces.
    /// Used to normalise distances (the autoencoder of Tan et al. divides by the diameter).
    pub fn max_distance_estimate(&self) -> Result<f64> {
        Ok(self.double_sweep()?.2)
    }
}

/// One-shot helper: builds a [`HeatGeodesics`] with time factor `m` (averaged boundary
/// conditions) and returns the distances from `sources`. Prefer the struct for several queries.
pub fn geodesic_distances(positions: &[Vec3], faces: &[[usize; 3]], sources: &[usize], m: f64) -> Result<Vec<f64>> {
    HeatGeodesics::new(positions, faces, m)?.distances(sources)
}

/// Solves the dense k×k system `s·x = r` (row-major `s`) by Gaussian elimination with partial
/// pivoting; `None` if singular or not finite. Overwrites `s` and `r`.
fn solve_dense(s: &mut [f64], r: &mut [f64], k: usize) -> Option<Vec<f64>> {
    for c in 0..k {
        let p = (c..k).max_by(|&a, &b| s[a * k + c].abs().total_cmp(&s[b * k + c].abs()))?;
        let pivot = s[p * k + c];
        if pivot == 0.0 || !pivot.is_finite() {
            return None;
        }
        if p != c {
            for j in 0..k {
                s.swap(p * k + j, c * k + j);
            }
            r.swap(p, c);
        }
        for i in c + 1..k {
            let f = s[i * k + c] / s[c * k + c];
            for j in c..k {
                s[i * k + j] -= f * s[c * k + j];
            }
            r[i] -= f * r[c];
        }
    }
    let mut x = vec![0.0; k];
    for c in (0..k).rev() {
        let mut v = r[c];
        for j in c + 1..k {
            v -= s[c * k + j] * x[j];
        }
        x[c] = v / s[c * k + c];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Off-diagonal values with every entry of an edge touching a `fixed` vertex set to 0.
fn masked_off(pairs: &[[usize; 2]], off: &[f64], fixed: &[bool]) -> Vec<f64> {
    pairs.iter().zip(off).map(|(e, &v)| if fixed[e[0]] || fixed[e[1]] { 0.0 } else { v }).collect()
}

fn argmax_finite(d: &[f64]) -> Option<usize> {
    let mut best: Option<usize> = None;
    for (i, &x) in d.iter().enumerate() {
        if x.is_finite() && best.is_none_or(|b| x > d[b]) {
            best = Some(i);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::intrinsic_delaunay::IntrinsicTriangulation;
    use crate::math::vec3::{dot, scale};
    use crate::mesh::primitives::{cylinder, grid, icosphere};

    /// The heat method's own values (m = 1, no clamping to the bounds), for accuracy tests:
    /// clamping can only reduce the error, so these bound the default's error too.
    fn raw(p: &[Vec3], f: &[[usize; 3]]) -> HeatGeodesics {
        HeatGeodesics::with_options(p, f, HeatOptions { bounds: DistanceBounds::None, ..Default::default() }).unwrap()
    }

    /// The sheared strip of `intrinsic_delaunay_fixes_a_sheared_strip`.
    fn sheared_strip() -> crate::mesh::TriMesh {
        let (nx, ny) = (200usize, 10usize);
        let mut g = grid(nx, ny, 1.0);
        for p in g.positions.iter_mut() {
            let row = (p[1] * ny as f64).round();
            *p = [10.0 * p[0] + 0.04 * row, 0.5 * p[1], 0.0];
        }
        g
    }

    fn great_circle(a: Vec3, b: Vec3) -> f64 {
        dot(a, b).clamp(-1.0, 1.0).acos()
    }

    #[test]
    fn sphere_distances_match_great_circle_within_2_percent_of_pi() {
        let s = icosphere(4); // 2562 vertices
        let solver = raw(&s.positions, &s.faces);
        for src in [0usize, 100, 2000] {
            let d = solver.distances(&[src]).unwrap();
            assert_eq!(d[src], 0.0, "the source holds the minimum");
            let mut max_err = 0.0f64;
            let mut sum_err = 0.0;
            for (v, &dv) in d.iter().enumerate() {
                let truth = great_circle(s.positions[src], s.positions[v]);
                max_err = max_err.max((dv - truth).abs());
                sum_err += (dv - truth).abs();
            }
            let pi = std::f64::consts::PI;
            eprintln!(
                "icosphere(4), source {src}: max |d − d_gc| = {:.4} ({:.2}% of π), mean {:.2}% of π",
                max_err,
                100.0 * max_err / pi,
                100.0 * sum_err / d.len() as f64 / pi
            );
            assert!(max_err < 0.02 * pi, "max error {max_err}");
            assert!(d.iter().all(|x| x.is_finite() && *x >= 0.0));
            let min = d.iter().cloned().fold(f64::INFINITY, f64::min);
            assert_eq!(min, 0.0);
        }
    }

    #[test]
    fn flat_grid_distances_within_one_edge_length() {
        let g = grid(40, 40, 1.0);
        // Neumann alone is less accurate near the boundary (up to 1.5 h here): only Averaged is held
        // to the one-edge bound.
        for boundary in [BoundaryCondition::Averaged, BoundaryCondition::Neumann] {
            let solver = HeatGeodesics::with_options(
                &g.positions,
                &g.faces,
                HeatOptions { boundary, bounds: DistanceBounds::None, ..Default::default() },
            )
            .unwrap();
            let h = solver.mean_edge_length();
            // Interior sources (centre, near a corner) and boundary sources (edge middle, corner).
            for src in [20 * 41 + 20, 5 * 41 + 3, 20, 0] {
                let d = solver.distances(&[src]).unwrap();
                let max_err = d
                    .iter()
                    .zip(&g.positions)
                    .map(|(dv, p)| (dv - crate::mesh::dist(*p, g.positions[src])).abs())
                    .fold(0.0, f64::max);
                eprintln!("grid 40×40 {boundary:?}, source {src}: max error {:.4} = {:.2} h", max_err, max_err / h);
                if boundary == BoundaryCondition::Averaged {
                    assert!(max_err < h, "{boundary:?} source {src}: max error {max_err} ≥ h = {h}");
                } else {
                    assert!(max_err < 2.0 * h, "{boundary:?} source {src}: max error {max_err} ≥ 2h = {}", 2.0 * h);
                }
            }
        }
    }

    #[test]
    fn open_cylinder_matches_the_unrolled_distance() {
        // Developable surface with two boundary loops: the exact geodesic distance is the
        // Euclidean distance in the unrolled plane (shorter way around).
        let (r, height) = (0.5, 2.0);
        let c = cylinder(64, 40, r, height);
        let solver = raw(&c.positions, &c.faces);
        let h = solver.mean_edge_length();
        let exact = |a: Vec3, b: Vec3| {
            let mut dt = (a[1].atan2(a[0]) - b[1].atan2(b[0])).abs();
            dt = dt.min(2.0 * std::f64::consts::PI - dt);
            ((r * dt).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        };
        // A source in the middle band and one on a boundary loop.
        for src in [20 * 64 + 5, 3] {
            let d = solver.distances(&[src]).unwrap();
            let max_err =
                d.iter().zip(&c.positions).map(|(dv, p)| (dv - exact(*p, c.positions[src])).abs()).fold(0.0, f64::max);
            eprintln!("cylinder, source {src}: max error {max_err:.4} = {:.2} h", max_err / h);
            assert!(max_err < h, "source {src}: max error {max_err} (h = {h})");
        }
        // Double sweep on the grid finds the diagonal.
        let g = grid(30, 30, 1.0);
        let est = HeatGeodesics::new(&g.positions, &g.faces, 1.0).unwrap().max_distance_estimate().unwrap();
        assert!((est - 2f64.sqrt()).abs() < g.mean_edge_length(), "grid diameter estimate {est}");
    }

    #[test]
    fn intrinsic_delaunay_fixes_a_sheared_strip() {
        // A long planar strip (157 h) of sheared cells, half of whose diagonals are non-Delaunay
        // (negative cotangent weights). Exact distances are Euclidean.
        let (nx, ny) = (200usize, 10usize);
        let g = sheared_strip();
        let tri = IntrinsicTriangulation::delaunay(&g.positions, &g.faces);
        assert!(tri.n_flips() > 0);
        let mut errors = Vec::new();
        for intrinsic_delaunay in [true, false] {
            let s = HeatGeodesics::with_options(
                &g.positions,
                &g.faces,
                HeatOptions { intrinsic_delaunay, bounds: DistanceBounds::None, ..Default::default() },
            )
            .unwrap();
            let h = s.mean_edge_length();
            let src = (ny / 2) * (nx + 1) + 3;
            let d = s.distances(&[src]).unwrap();
            let e = d
                .iter()
                .zip(&g.positions)
                .map(|(dv, p)| (dv - crate::mesh::dist(*p, g.positions[src])).abs())
                .fold(0.0, f64::max);
            eprintln!("sheared strip, intrinsic Delaunay {intrinsic_delaunay}: max error {:.2} h", e / h);
            errors.push(e / h);
        }
        assert!(errors[0] < 1.0, "intrinsic Delaunay: {} h", errors[0]);
        assert!(errors[1] > errors[0]);
    }

    #[test]
    fn clamping_projects_onto_the_bounds_and_never_increases_the_error() {
        // On the plane the lower bound (straight line) is the exact distance.
        let g = sheared_strip();
        let topo = crate::mesh::Topology::new(g.n_vertices(), &g.faces);
        for intrinsic_delaunay in [false, true] {
            let opts = HeatOptions { intrinsic_delaunay, bounds: DistanceBounds::None, ..Default::default() };
            let raw = HeatGeodesics::with_options(&g.positions, &g.faces, opts).unwrap();
            let sources = [5usize, 1500];
            let r = raw.distances(&sources).unwrap();
            let up = crate::geometry::graph_distance::dijkstra(&topo, &g.positions, &sources);
            for bounds in [DistanceBounds::StraightLine, DistanceBounds::StraightLineAndEdgePath] {
                let clamped =
                    HeatGeodesics::with_options(&g.positions, &g.faces, HeatOptions { bounds, ..opts }).unwrap();
                let c = clamped.distances(&sources).unwrap();
                let mut changed = 0;
                for v in 0..r.len() {
                    let lo = sources
                        .iter()
                        .map(|&s| crate::mesh::dist(g.positions[v], g.positions[s]))
                        .fold(f64::INFINITY, f64::min);
                    let hi = if bounds == DistanceBounds::StraightLine { f64::INFINITY } else { up[v] };
                    assert_eq!(c[v], r[v].max(lo).min(hi));
                    assert!((c[v] - lo).abs() <= (r[v] - lo).abs());
                    changed += usize::from(c[v] != r[v]);
                }
                eprintln!(
                    "intrinsic Delaunay {intrinsic_delaunay}, {bounds:?}: clamping changed {changed} of {} values",
                    r.len()
                );
            }
        }
    }

    #[test]
    fn horse_heat_distances_agree_with_graph_distances() {
        // Real data: frame 1 of the horse gallop (8431 vertices, a boundary slit). Skipped when
        // the shared data are absent; the synthetic counterparts are the tests above.
        let path = std::path::Path::new("../shared/data/horse-gallop/0001.obj");
        if !path.exists() {
            eprintln!("skipping: {} not found (shared data absent)", path.display());
            return;
        }
        let mesh = crate::mesh::load_mesh(path).unwrap();
        let (p, f): (Vec<Vec3>, Vec<[usize; 3]>) = (mesh.positions, mesh.faces);
        assert_eq!(p.len(), 8431);
        let solver = raw(&p, &f);
        let topo = crate::mesh::Topology::new(p.len(), &f);
        let h = solver.mean_edge_length();
        for src in [0usize, 4000] {
            let d = solver.distances(&[src]).unwrap();
            let g = crate::geometry::graph_distance::dijkstra(&topo, &p, &[src]);
            // Edge paths are never shorter than geodesics and at most ~15–20% longer (plus a
            // zig-zag near the source); the heat method is accurate to about an edge length. On
            // the mesh's own (non-Delaunay) triangles the heat method fails far from the source
            // (heat 0.35 where the graph distance is 1.87, −60 h): this is the check for it.
            let mut above = 0.0f64;
            let mut below = 0.0f64;
            for (dv, gv) in d.iter().zip(&g) {
                above = above.max(dv - gv);
                below = below.max(gv / 1.2 - dv);
            }
            eprintln!(
                "horse source {src}: max(heat − graph) = {:.2} h, max(graph/1.2 − heat) = {:.2} h",
                above / h,
                below / h
            );
            assert!(above < 2.0 * h && below < h, "source {src}");
        }
    }

    #[test]
    fn multi_source_is_min_of_single_sources() {
        let s = icosphere(4);
        let solver = raw(&s.positions, &s.faces);
        let srcs = [3usize, 200, 555];
        let multi = solver.distances(&srcs).unwrap();
        let singles: Vec<Vec<f64>> = srcs.iter().map(|&v| solver.distances(&[v]).unwrap()).collect();
        let h = solver.mean_edge_length();
        let (mut max_diff, mut max_err) = (0.0f64, 0.0f64);
        for v in 0..s.n_vertices() {
            let m = singles.iter().map(|d| d[v]).fold(f64::INFINITY, f64::min);
            max_diff = max_diff.max((multi[v] - m).abs());
            let truth =
                srcs.iter().map(|&q| great_circle(s.positions[q], s.positions[v])).fold(f64::INFINITY, f64::min);
            max_err = max_err.max((multi[v] - truth).abs());
        }
        eprintln!(
            "multi-source: max |d − min singles| = {max_diff:.4} = {:.2} h; max |d − min d_gc| = {max_err:.4} = {:.2} h",
            max_diff / h,
            max_err / h
        );
        // The heat method smooths the kink of the min along the equidistant lines between sources
        // (an overestimate there of about one edge length, shrinking with h).
        assert!(max_diff < 1.5 * h, "max diff {max_diff}");
        assert!(max_err < 1.5 * h, "max error {max_err}");
        // One source holds the minimum 0; the others are near 0 (the shift is global).
        assert!(srcs.iter().any(|&v| multi[v] == 0.0));
        for &v in &srcs {
            assert!(multi[v] < 0.5 * h, "source {v}: {}", multi[v]);
        }
    }

    #[test]
    fn boundary_source_dirichlet_matches_a_direct_solve() {
        // Dirichlet heat with the boundary sources exempt, via the Schur complement, against a
        // dense solve of the same system assembled directly.
        let g = grid(6, 5, 1.0);
        let solver = HeatGeodesics::new(&g.positions, &g.faces, 1.0).unwrap();
        let n = g.n_vertices();
        let fact = solver.heat_dirichlet.as_ref().unwrap();
        for sources in [vec![0usize], vec![3, 20], vec![2, 9, 15, 41], vec![16]] {
            let got = solver.dirichlet_heat(fact, &sources).unwrap();
            let clamped = |i: usize| solver.is_boundary[i] && !sources.contains(&i);
            let mut a = vec![0.0; n * n];
            let mut b = vec![0.0; n];
            for t in solver.heat_matrix.triplet_iter() {
                if !clamped(t.row) && !clamped(t.col) {
                    a[t.row * n + t.col] = *t.val;
                }
            }
            for i in 0..n {
                if clamped(i) {
                    a[i * n + i] = 1.0;
                }
            }
            for &s in &sources {
                b[s] = 1.0;
            }
            let want = solve_dense(&mut a, &mut b, n).unwrap();
            for i in 0..n {
                assert!(
                    (got[i] - want[i]).abs() < 1e-12 * (1.0 + want[i].abs()),
                    "{sources:?} vertex {i}: {} vs {}",
                    got[i],
                    want[i]
                );
                if clamped(i) {
                    assert_eq!(got[i], 0.0);
                }
            }
        }
    }

    #[test]
    fn distances_scale_with_the_mesh() {
        let c = cylinder(24, 10, 0.5, 2.0);
        let base = HeatGeodesics::new(&c.positions, &c.faces, 1.0).unwrap().distances(&[7]).unwrap();
        for s in [1e-6, 1e6] {
            let p: Vec<Vec3> = c.positions.iter().map(|p| scale(*p, s)).collect();
            let d = HeatGeodesics::new(&p, &c.faces, 1.0).unwrap().distances(&[7]).unwrap();
            for (a, b) in base.iter().zip(&d) {
                assert!((b / s - a).abs() <= 1e-8 * (1.0 + a), "scale {s}: {a} vs {}", b / s);
            }
        }
    }

    #[test]
    fn double_sweep_on_sphere_finds_antipodes() {
        let s = icosphere(3);
        let solver = HeatGeodesics::new(&s.positions, &s.faces, 1.0).unwrap();
        let (a, b, d) = solver.double_sweep().unwrap();
        let truth = great_circle(s.positions[a], s.positions[b]);
        assert!(truth > 0.97 * std::f64::consts::PI, "sweep ends {a}, {b} are {truth} apart");
        assert!((d - std::f64::consts::PI).abs() < 0.03 * std::f64::consts::PI, "estimate {d}");
        assert_eq!(solver.max_distance_estimate().unwrap(), d);
    }

    #[test]
    fn solver_can_be_shared_between_threads() {
        fn assert_send_sync<T: Send + Sync>() {}
        assert_send_sync::<HeatGeodesics>();
        let s = icosphere(2);
        let solver = HeatGeodesics::new(&s.positions, &s.faces, 1.0).unwrap();
        let serial: Vec<Vec<f64>> = (0..4).map(|v| solver.distances(&[v]).unwrap()).collect();
        let parallel: Vec<Vec<f64>> = std::thread::scope(|sc| {
            let solver = &solver;
            let hs: Vec<_> = (0..4).map(|v| sc.spawn(move || solver.distances(&[v]).unwrap())).collect();
            hs.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert_eq!(serial, parallel);
    }

    #[test]
    fn bad_input_is_rejected_and_components_are_separated() {
        let g = grid(3, 3, 1.0);
        assert!(matches!(HeatGeodesics::new(&g.positions, &g.faces, 0.0), Err(Error::Invalid(_))));
        assert!(matches!(HeatGeodesics::new(&g.positions, &g.faces, f64::NAN), Err(Error::Invalid(_))));
        assert!(matches!(HeatGeodesics::new(&g.positions, &[[0, 1, 99]], 1.0), Err(Error::Invalid(_))));
        let mut p = g.positions.clone();
        p[2][1] = f64::INFINITY;
        assert!(matches!(HeatGeodesics::new(&p, &g.faces, 1.0), Err(Error::Invalid(_))));
        let solver = HeatGeodesics::new(&g.positions, &g.faces, 1.0).unwrap();
        assert!(matches!(solver.distances(&[]), Err(Error::Invalid(_))));
        assert!(matches!(solver.distances(&[16]), Err(Error::Invalid(_))));

        // Two disjoint grids plus an isolated vertex: distances are +∞ off the source's part.
        let a = grid(4, 4, 1.0);
        let mut pos = a.positions.clone();
        let mut faces = a.faces.clone();
        let off = pos.len();
        pos.extend(a.positions.iter().map(|p| [p[0] + 5.0, p[1], p[2]]));
        faces.extend(a.faces.iter().map(|f| [f[0] + off, f[1] + off, f[2] + off]));
        pos.push([9.0, 9.0, 9.0]);
        let solver = HeatGeodesics::new(&pos, &faces, 1.0).unwrap();
        assert_eq!(solver.n_components(), 2);
        let d = solver.distances(&[off + 3]).unwrap();
        assert!(d[..off].iter().all(|x| x.is_infinite()));
        assert!(d[off..2 * off].iter().all(|x| x.is_finite()));
        assert!(d[2 * off].is_infinite());
        let d = solver.distances(&[2 * off, 0]).unwrap();
        assert_eq!(d[2 * off], 0.0);
        assert!(d[off..2 * off].iter().all(|x| x.is_infinite()));
        // One-shot helper agrees with the solver.
        let one = geodesic_distances(&pos, &faces, &[2 * off, 0], 1.0).unwrap();
        assert_eq!(one, d);
    }
}
