//! Triangle deformation gradients (Huang et al. 2014, "Sparse localized decomposition of
//! deformation gradients"): 9 numbers per triangle, a log-rotation (3) and a stretch (6), and
//! the least-squares reconstruction of vertex positions from a gradient field (the paper's
//! Eq. (6)), factorised once per rest mesh.
//!
//! # Encoding (per triangle, rest `v0 v1 v2`, deformed `v0' v1' v2'`)
//! * `V = [v1 − v0, v2 − v0]` (3×2), thin QR `V = Q2·R` by Gram–Schmidt (so `R` has a positive
//!   diagonal and the rest normal is `n = q1 × q2`, the unit normal of the face's own winding).
//! * The minimum-norm deformation gradient `J = V'·R⁻¹·Q2ᵀ` (Eq. (5)); it maps the rest edges
//!   onto the deformed edges and the rest normal onto zero.
//! * Polar decomposition `J = U·P`. `J` has rank 2, so the rotation is only fixed by asking
//!   `U ∈ SO(3)`: `U` maps the rest frame `(q1, q2, n)` to `(a1', a2', n')` where `n'` is the
//!   deformed unit normal and `a1', a2'` the in-plane polar rotation of the 2×2 map `R'·R⁻¹`
//!   (closed form, no SVD). Because `U` carries `n` to `n'` by construction, **no reflection can
//!   occur**: `det U = +1` for every non-degenerate deformed triangle. A degenerate (zero-area)
//!   deformed triangle has no normal; it falls back to an SVD of `J` with the reflection fixed by
//!   flipping the singular vector of the smallest singular value (which is 0, so `J` is kept).
//! * The stretch `P` depends on the [`NormalConvention`]:
//!   - [`NormalConvention::UnitNormal`] (default): `P = Uᵀ·J + n·nᵀ`, i.e. the gradient of the
//!     map that also sends the rest unit normal to the deformed unit normal. The rest shape then
//!     has exactly zero features and a rigid motion has `p = 0`.
//!   - [`NormalConvention::MinNorm`]: `P = Uᵀ·J` literally (Eq. (5)); `P` has the eigenvalue 0 along
//!     `n`, so even the rest shape has `p = −g(n·nᵀ) ≠ 0`.
//!
//!   The two differ by the constant `g(n·nᵀ)` per triangle, and decoding ignores the normal
//!   column of `J` (see below), so both decode identically.
//! * Feature `q = [u, p]`:
//!   - `u = θ·axis` ∈ ℝ³, the axis-angle vector of `log U` with θ ∈ [0, π] (right-hand rule,
//!     `log U = [u]×`). The paper writes `log U = u1·e1 + u2·e2 + u3·e3` with its own basis; its
//!     vector is `(−u_z, u_y, −u_x)` in ours: same norm, a fixed signed permutation.
//!   - `p = [a−1, b−1, c−1, d, e, f]` from `P = [[a, d, e], [d, b, f], [e, f, c]]` (Eq. (13)):
//!     diagonal minus one, then the off-diagonal entries (0,1), (0,2), (1,2).
//!
//! # Decoding
//! `U = exp([u]×)` (Rodrigues), `P = I + g⁻¹(p)`, `J = U·P`, then vertex positions minimising
//! the paper's Eq. (6), `E(x) = Σ_t ‖V'_t(x)·R_t⁻¹·Q2,tᵀ − J_t‖²_F` (unweighted, as in the
//! paper). Each coordinate separates; with `D_t = R_t⁻¹·Q2,tᵀ` (2×3), `M_t = D_t·D_tᵀ =
//! (V_tᵀV_t)⁻¹` and `G` the 2×3 edge operator of a triangle, the normal equations are
//! `(Σ_t G_tᵀ·M_t·G_t) x_c = Σ_t G_tᵀ·D_t·(row c of J_t)ᵀ` — a cotangent-Laplacian-like SPD
//! matrix (on each connected component, after pinning one vertex) that depends on the rest mesh
//! only, factorised once ([`GradientReconstruction`]). Only `J·Q2` enters the right-hand side,
//! so the normal column of `J` is irrelevant.
//!
//! **Translation.** Gradients carry no translation: one vertex per connected component is pinned
//! to remove the null space, then every component is translated so that its vertex centroid
//! (unweighted mean) equals the rest mesh's centroid of that component. Vertices referenced by no
//! face are returned at their rest positions. Compare decoded shapes after centroid alignment.

#![warn(missing_docs)]

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par, Side};

use crate::error::{Error, Result};
pub use crate::math::mat3::Mat3;
use crate::math::mat3::{ReflectionFix, add_outer, exp_so3, log_so3, mat_mul, polar_svd};
use crate::math::vec3::{cross, dot, norm, scale, sub};
use crate::mesh::{Topology, TriMesh, Vec3};

/// Numbers per triangle in the feature vector.
pub const WIDTH: usize = 9;

/// Relative size below which a (rest or deformed) triangle counts as degenerate: the height
/// `r22` of the triangle over its first edge is at most `DEGENERATE_TOL` × the longest edge.
pub const DEGENERATE_TOL: f64 = 1e-12;

/// How the normal direction of the rank-2 minimum-norm gradient enters the stretch `P` (see the
/// module docs). Decoding is identical for both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NormalConvention {
    /// `P = Uᵀ·J + n·nᵀ`: the rest shape encodes to zero features (default).
    #[default]
    UnitNormal,
    /// `P = Uᵀ·J` with `J` of Eq. (5) literally; the rest shape has `p = −g(n·nᵀ)`.
    MinNorm,
}

/// Precomputed rest-triangle quantities: Gram–Schmidt frame and `D = R⁻¹·Q2ᵀ`.
#[derive(Debug, Clone, Copy)]
struct RestTriangle {
    q1: Vec3,
    q2: Vec3,
    n: Vec3,
    /// `R = [[r11, r12], [0, r22]]`.
    r11: f64,
    r12: f64,
    r22: f64,
    /// `D = R⁻¹·Q2ᵀ`, rows `d[0]`, `d[1]` (2×3).
    d: [Vec3; 2],
}

/// Thin QR of `[e1, e2]` by Gram–Schmidt: `(q1, q2, r11, r12, r22)`, or `None` when the
/// triangle is degenerate (see [`DEGENERATE_TOL`]) or not finite.
fn gram_schmidt(e1: Vec3, e2: Vec3) -> Option<(Vec3, Vec3, f64, f64, f64)> {
    let r11 = norm(e1);
    let longest = r11.max(norm(e2));
    if r11 == 0.0 || !r11.is_finite() || !longest.is_finite() {
        return None;
    }
    let q1 = scale(e1, 1.0 / r11);
    let r12 = dot(q1, e2);
    let w = sub(e2, scale(q1, r12));
    let r22 = norm(w);
    if r22.is_nan() || r22 <= DEGENERATE_TOL * longest {
        return None;
    }
    Some((q1, scale(w, 1.0 / r22), r11, r12, r22))
}

impl RestTriangle {
    fn new(p0: Vec3, p1: Vec3, p2: Vec3) -> Option<Self> {
        let (q1, q2, r11, r12, r22) = gram_schmidt(sub(p1, p0), sub(p2, p0))?;
        // R⁻¹ = [[1/r11, −r12/(r11 r22)], [0, 1/r22]].
        let a = 1.0 / r11;
        let b = -r12 / (r11 * r22);
        let c = 1.0 / r22;
        let d0 = [a * q1[0] + b * q2[0], a * q1[1] + b * q2[1], a * q1[2] + b * q2[2]];
        let d1 = scale(q2, c);
        Some(RestTriangle { q1, q2, n: cross(q1, q2), r11, r12, r22, d: [d0, d1] })
    }

    /// `M = D·Dᵀ = (VᵀV)⁻¹` as `(m00, m01, m11)`.
    fn metric(&self) -> (f64, f64, f64) {
        (dot(self.d[0], self.d[0]), dot(self.d[0], self.d[1]), dot(self.d[1], self.d[1]))
    }
}

/// `p = g(P − I) = [a−1, b−1, c−1, d, e, f]` of a symmetric `P` (Eq. (13); the lower triangle is
/// averaged with the upper one).
pub fn stretch_to_vec(p: &Mat3) -> [f64; 6] {
    [
        p[0][0] - 1.0,
        p[1][1] - 1.0,
        p[2][2] - 1.0,
        0.5 * (p[0][1] + p[1][0]),
        0.5 * (p[0][2] + p[2][0]),
        0.5 * (p[1][2] + p[2][1]),
    ]
}

/// Inverse of [`stretch_to_vec`]: `P = I + g⁻¹(p)`.
pub fn vec_to_stretch(p: &[f64]) -> Mat3 {
    [[1.0 + p[0], p[3], p[4]], [p[3], 1.0 + p[1], p[5]], [p[4], p[5], 1.0 + p[2]]]
}

/// Rotation `U` and stretch `P` (in the given convention) of one triangle, rest frame `rt`,
/// deformed edges `e1' = v1' − v0'`, `e2' = v2' − v0'`.
fn rotation_stretch(rt: &RestTriangle, e1: Vec3, e2: Vec3, convention: NormalConvention) -> (Mat3, Mat3) {
    let (u, mut p) = match gram_schmidt(e1, e2) {
        Some((q1d, q2d, s11, s12, s22)) => {
            // M = R'·R⁻¹ (2×2 upper triangular) in the frames (q1, q2) → (q1', q2').
            let m00 = s11 / rt.r11;
            let m01 = (s12 - s11 * rt.r12 / rt.r11) / rt.r22;
            let m11 = s22 / rt.r22;
            // 2×2 polar M = O·S with O the rotation by φ (m10 = 0).
            let phi = (-m01).atan2(m00 + m11);
            let (s, c) = phi.sin_cos();
            // S = Oᵀ·M, symmetric positive definite.
            let s00 = c * m00;
            let s01 = 0.5 * ((c * m01 + s * m11) + (-s * m00));
            let s11v = -s * m01 + c * m11;
            let a1 = [c * q1d[0] + s * q2d[0], c * q1d[1] + s * q2d[1], c * q1d[2] + s * q2d[2]];
            let a2 = [-s * q1d[0] + c * q2d[0], -s * q1d[1] + c * q2d[1], -s * q1d[2] + c * q2d[2]];
            let nd = cross(q1d, q2d);
            let mut u = [[0.0; 3]; 3];
            add_outer(&mut u, a1, rt.q1, 1.0);
            add_outer(&mut u, a2, rt.q2, 1.0);
            add_outer(&mut u, nd, rt.n, 1.0);
            let mut p = [[0.0; 3]; 3];
            add_outer(&mut p, rt.q1, rt.q1, s00);
            add_outer(&mut p, rt.q1, rt.q2, s01);
            add_outer(&mut p, rt.q2, rt.q1, s01);
            add_outer(&mut p, rt.q2, rt.q2, s11v);
            (u, p)
        }
        None => {
            // Degenerate deformed triangle: J = V'·D, polar by SVD.
            let mut j = [[0.0; 3]; 3];
            add_outer(&mut j, e1, rt.d[0], 1.0);
            add_outer(&mut j, e2, rt.d[1], 1.0);
            polar_svd(&j, ReflectionFix::Last)
        }
    };
    if convention == NormalConvention::UnitNormal {
        add_outer(&mut p, rt.n, rt.n, 1.0);
    }
    // Exact symmetry.
    for (i, k) in [(0, 1), (0, 2), (1, 2)] {
        let m = 0.5 * (p[i][k] + p[k][i]);
        p[i][k] = m;
        p[k][i] = m;
    }
    (u, p)
}

/// The minimum-norm deformation gradient `J = V'·R⁻¹·Q2ᵀ` (Eq. (5)) of one triangle.
/// Errors when the rest triangle is degenerate.
pub fn deformation_gradient(rest: [Vec3; 3], deformed: [Vec3; 3]) -> Result<Mat3> {
    let rt = RestTriangle::new(rest[0], rest[1], rest[2])
        .ok_or_else(|| Error::Invalid(format!("degenerate rest triangle {rest:?}")))?;
    let mut j = [[0.0; 3]; 3];
    add_outer(&mut j, sub(deformed[1], deformed[0]), rt.d[0], 1.0);
    add_outer(&mut j, sub(deformed[2], deformed[0]), rt.d[1], 1.0);
    Ok(j)
}

/// The triangle-gradient representation of one rest mesh: encoder and (factorised) decoder.
#[derive(Debug)]
pub struct TriangleGradient {
    faces: Vec<[usize; 3]>,
    n_vertices: usize,
    convention: NormalConvention,
    rest: Vec<RestTriangle>,
    solver: GradientReconstruction,
}

impl TriangleGradient {
    /// Precomputes the rest frames and factorises the reconstruction system. Errors on bad face
    /// indices, non-finite positions or a degenerate rest triangle (index and area in the message).
    pub fn new(rest: &TriMesh, convention: NormalConvention) -> Result<Self> {
        let rest_tris = rest_triangles(rest)?;
        let solver = GradientReconstruction::from_rest(rest, &rest_tris)?;
        Ok(TriangleGradient {
            faces: rest.faces.clone(),
            n_vertices: rest.n_vertices(),
            convention,
            rest: rest_tris,
            solver,
        })
    }

    /// Number of triangles T (elements).
    pub fn n_triangles(&self) -> usize {
        self.faces.len()
    }

    /// The normal convention of the stretch part.
    pub fn convention(&self) -> NormalConvention {
        self.convention
    }

    /// Features of one frame: T × 9 numbers `[u (3), p (6)]` per triangle (module docs).
    /// Errors when the vertex count differs or a position is not finite.
    pub fn encode_frame(&self, positions: &[Vec3]) -> Result<Vec<f64>> {
        check_positions(positions, self.n_vertices)?;
        let mut out = vec![0.0; self.faces.len() * WIDTH];
        for ((f, rt), q) in self.faces.iter().zip(&self.rest).zip(out.chunks_exact_mut(WIDTH)) {
            let p0 = positions[f[0]];
            let (u, p) = rotation_stretch(rt, sub(positions[f[1]], p0), sub(positions[f[2]], p0), self.convention);
            q[..3].copy_from_slice(&log_so3(&u));
            q[3..].copy_from_slice(&stretch_to_vec(&p));
        }
        Ok(out)
    }

    /// Deformation gradients `J_t = exp([u_t]×)·(I + g⁻¹(p_t))` of a T × 9 feature vector.
    pub fn gradients(&self, features: &[f64]) -> Result<Vec<Mat3>> {
        check_features(features, self.faces.len())?;
        Ok(features.chunks_exact(WIDTH).map(gradient_of).collect())
    }

    /// Vertex positions from a T × 9 feature vector (Eq. (6) least squares, translation as in
    /// the module docs).
    pub fn decode_frame(&self, features: &[f64]) -> Result<Vec<Vec3>> {
        check_features(features, self.faces.len())?;
        self.solver.solve_with(|t| gradient_of(&features[t * WIDTH..(t + 1) * WIDTH]))
    }

    /// The factorised Eq. (6) solver of this rest mesh.
    pub fn reconstruction(&self) -> &GradientReconstruction {
        &self.solver
    }
}

/// `J = exp([u]×)·(I + g⁻¹(p))` for one 9-vector.
fn gradient_of(q: &[f64]) -> Mat3 {
    mat_mul(&exp_so3([q[0], q[1], q[2]]), &vec_to_stretch(&q[3..9]))
}

fn check_positions(positions: &[Vec3], n: usize) -> Result<()> {
    if positions.len() != n {
        return Err(Error::Invalid(format!("frame has {} vertices, the rest mesh has {n}", positions.len())));
    }
    if let Some(i) = positions.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        return Err(Error::Invalid(format!("vertex {i} has a non-finite position {:?}", positions[i])));
    }
    Ok(())
}

fn check_features(features: &[f64], n_triangles: usize) -> Result<()> {
    if features.len() != n_triangles * WIDTH {
        return Err(Error::Invalid(format!(
            "triangle-gradient features have {} numbers, expected {n_triangles} triangles × {WIDTH}",
            features.len()
        )));
    }
    if let Some(i) = features.iter().position(|x| !x.is_finite()) {
        return Err(Error::Invalid(format!("feature {i} (triangle {}) is not finite: {}", i / WIDTH, features[i])));
    }
    Ok(())
}

fn rest_triangles(rest: &TriMesh) -> Result<Vec<RestTriangle>> {
    if let Some((fi, f)) = rest.first_bad_index() {
        return Err(Error::Invalid(format!("face {fi} {f:?} refers to a vertex ≥ {}", rest.n_vertices())));
    }
    check_positions(&rest.positions, rest.n_vertices())?;
    rest.faces
        .iter()
        .enumerate()
        .map(|(fi, f)| {
            let [a, b, c] = f.map(|v| rest.positions[v]);
            RestTriangle::new(a, b, c).ok_or_else(|| {
                let area = 0.5 * norm(cross(sub(b, a), sub(c, a)));
                Error::Invalid(format!("rest triangle {fi} {f:?} is degenerate (area {area:e})"))
            })
        })
        .collect()
}

/// The factorised least-squares reconstruction of the paper's Eq. (6): vertex positions from one
/// deformation gradient per triangle, on a fixed rest mesh (see the module docs for the system
/// and the translation convention). Factor once with [`GradientReconstruction::new`], then call
/// [`GradientReconstruction::solve`] per frame (three sparse triangular solve pairs).
#[derive(Debug)]
pub struct GradientReconstruction {
    faces: Vec<[usize; 3]>,
    /// `D_t = R_t⁻¹·Q2,tᵀ` per triangle.
    d: Vec<[Vec3; 2]>,
    /// Reduced (unknown) index per vertex; `usize::MAX` for pinned or isolated vertices.
    reduced: Vec<usize>,
    n_reduced: usize,
    /// Component label per vertex (`usize::MAX` for isolated vertices).
    component: Vec<usize>,
    /// Rest centroid and vertex count per component.
    rest_centroids: Vec<(Vec3, usize)>,
    /// Rest positions (used for isolated vertices).
    rest_positions: Vec<Vec3>,
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
}

impl GradientReconstruction {
    /// Assembles and factorises the Eq. (6) system of `rest` (sparse Cholesky, AMD ordering,
    /// sequential). Errors on bad indices, non-finite positions, degenerate rest triangles, or a
    /// failed factorisation.
    pub fn new(rest: &TriMesh) -> Result<Self> {
        let tris = rest_triangles(rest)?;
        Self::from_rest(rest, &tris)
    }

    fn from_rest(rest: &TriMesh, tris: &[RestTriangle]) -> Result<Self> {
        let n = rest.n_vertices();
        let topo = Topology::new(n, &rest.faces);
        let (component, n_comp) = topo.components();
        // Pin the first vertex of each component.
        let mut pinned = vec![false; n_comp];
        let mut reduced = vec![usize::MAX; n];
        let mut n_reduced = 0;
        let mut rest_centroids = vec![([0.0; 3], 0usize); n_comp];
        for v in 0..n {
            let c = component[v];
            if c == usize::MAX {
                continue;
            }
            let acc = &mut rest_centroids[c];
            for k in 0..3 {
                acc.0[k] += rest.positions[v][k];
            }
            acc.1 += 1;
            if !pinned[c] {
                pinned[c] = true;
            } else {
                reduced[v] = n_reduced;
                n_reduced += 1;
            }
        }
        for (c, cnt) in rest_centroids.iter_mut() {
            *c = scale(*c, 1.0 / *cnt as f64);
        }
        // K = Σ_t Gᵀ M G: local [[a+2b+c, −a−b, −b−c], [·, a, b], [·, ·, c]].
        let mut trip = Vec::with_capacity(tris.len() * 9);
        for (f, rt) in rest.faces.iter().zip(tris) {
            let (a, b, c) = rt.metric();
            let k = [[a + 2.0 * b + c, -a - b, -b - c], [-a - b, a, b], [-b - c, b, c]];
            for i in 0..3 {
                let ri = reduced[f[i]];
                if ri == usize::MAX {
                    continue;
                }
                for j in 0..3 {
                    let rj = reduced[f[j]];
                    if rj != usize::MAX && rj <= ri {
                        trip.push(Triplet::new(ri, rj, k[i][j]));
                    }
                }
            }
        }
        let mat = SparseColMat::<usize, f64>::try_new_from_triplets(n_reduced, n_reduced, &trip)
            .map_err(|e| Error::Numerical(format!("assembling the gradient reconstruction matrix: {e:?}")))?;
        let symbolic = factorize_symbolic_cholesky(mat.symbolic(), Side::Lower, Default::default(), Default::default())
            .map_err(|e| Error::Numerical(format!("symbolic Cholesky of the gradient reconstruction matrix: {e:?}")))?;
        let mut l_values = vec![0.0; symbolic.len_val()];
        {
            let mut mem =
                MemBuffer::try_new(symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()))
                    .map_err(|e| Error::Numerical(format!("Cholesky workspace: {e:?}")))?;
            symbolic
                .factorize_numeric_llt(
                    &mut l_values,
                    mat.as_ref(),
                    Side::Lower,
                    Default::default(),
                    Par::Seq,
                    MemStack::new(&mut mem),
                    Default::default(),
                )
                .map_err(|e| {
                    Error::Numerical(format!(
                        "Cholesky of the gradient reconstruction matrix ({n_reduced} unknowns): {e:?}"
                    ))
                })?;
        }
        Ok(GradientReconstruction {
            faces: rest.faces.clone(),
            d: tris.iter().map(|t| t.d).collect(),
            reduced,
            n_reduced,
            component,
            rest_centroids,
            rest_positions: rest.positions.clone(),
            symbolic,
            l_values,
        })
    }

    /// Vertex positions (N) from one gradient per triangle (T, each mapping rest vectors to
    /// deformed ones); translation per the module docs. Errors when the count differs or a
    /// gradient is not finite.
    pub fn solve(&self, gradients: &[Mat3]) -> Result<Vec<Vec3>> {
        if gradients.len() != self.faces.len() {
            return Err(Error::Invalid(format!("{} gradients for {} triangles", gradients.len(), self.faces.len())));
        }
        if let Some(t) = gradients.iter().position(|j| !j.iter().flatten().all(|x| x.is_finite())) {
            return Err(Error::Invalid(format!("gradient of triangle {t} is not finite: {:?}", gradients[t])));
        }
        self.solve_with(|t| gradients[t])
    }

    fn solve_with(&self, gradient: impl Fn(usize) -> Mat3) -> Result<Vec<Vec3>> {
        let n = self.reduced.len();
        let mut rhs = Mat::<f64>::zeros(self.n_reduced, 3);
        for (t, (f, d)) in self.faces.iter().zip(&self.d).enumerate() {
            let j = gradient(t);
            let [r0, r1, r2] = f.map(|v| self.reduced[v]);
            for (c, jc) in j.iter().enumerate() {
                // h = D · (row c of J)ᵀ; rhs += Gᵀ h.
                let h0 = dot(d[0], *jc);
                let h1 = dot(d[1], *jc);
                if r0 != usize::MAX {
                    rhs[(r0, c)] -= h0 + h1;
                }
                if r1 != usize::MAX {
                    rhs[(r1, c)] += h0;
                }
                if r2 != usize::MAX {
                    rhs[(r2, c)] += h1;
                }
            }
        }
        if self.n_reduced > 0 {
            let mut mem = MemBuffer::try_new(self.symbolic.solve_in_place_scratch::<f64>(3, Par::Seq))
                .map_err(|e| Error::Numerical(format!("solve workspace: {e:?}")))?;
            LltRef::new(&self.symbolic, &self.l_values).solve_in_place_with_conj(
                Conj::No,
                rhs.as_mut(),
                Par::Seq,
                MemStack::new(&mut mem),
            );
        }
        // Pinned vertices sit at 0; shift each component onto its rest centroid.
        let mut out = vec![[0.0; 3]; n];
        let mut sums = vec![[0.0; 3]; self.rest_centroids.len()];
        for (v, o) in out.iter_mut().enumerate() {
            let c = self.component[v];
            if c == usize::MAX {
                *o = self.rest_positions[v];
                continue;
            }
            let r = self.reduced[v];
            if r != usize::MAX {
                *o = [rhs[(r, 0)], rhs[(r, 1)], rhs[(r, 2)]];
            }
            for k in 0..3 {
                sums[c][k] += o[k];
            }
        }
        let shift: Vec<Vec3> = sums
            .iter()
            .zip(&self.rest_centroids)
            .map(|(s, (rc, cnt))| std::array::from_fn(|k| rc[k] - s[k] / *cnt as f64))
            .collect();
        for (o, &c) in out.iter_mut().zip(&self.component) {
            if c != usize::MAX {
                for k in 0..3 {
                    o[k] += shift[c][k];
                }
            }
        }
        if let Some(i) = out.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(Error::Numerical(format!("gradient reconstruction produced a non-finite vertex {i}")));
        }
        Ok(out)
    }
}

/// One-shot Eq. (6) reconstruction: factorises the system of `rest` and solves for one gradient
/// field. Use [`GradientReconstruction`] to solve many frames.
pub fn reconstruct_from_gradients(rest: &TriMesh, gradients: &[Mat3]) -> Result<Vec<Vec3>> {
    GradientReconstruction::new(rest)?.solve(gradients)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A (nx+1)×(ny+1) vertex grid in the xy-plane, two triangles per cell, CCW from +z.
    fn grid(nx: usize, ny: usize) -> TriMesh {
        let mut p = Vec::new();
        for j in 0..=ny {
            for i in 0..=nx {
                p.push([i as f64 / nx as f64, j as f64 / ny as f64 * 0.8, 0.0]);
            }
        }
        let mut f = Vec::new();
        let id = |i: usize, j: usize| j * (nx + 1) + i;
        for j in 0..ny {
            for i in 0..nx {
                f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        TriMesh::new(p, f)
    }

    /// An octahedron refined by `levels` midpoint subdivisions, projected to the unit sphere.
    fn sphere(levels: usize) -> TriMesh {
        let mut p: Vec<Vec3> =
            vec![[1., 0., 0.], [-1., 0., 0.], [0., 1., 0.], [0., -1., 0.], [0., 0., 1.], [0., 0., -1.]];
        let mut f: Vec<[usize; 3]> =
            vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
        for _ in 0..levels {
            let mut mid = std::collections::HashMap::new();
            let mut nf = Vec::new();
            for t in &f {
                let mut m = [0; 3];
                for k in 0..3 {
                    let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                    m[k] = *mid.entry((a, b)).or_insert_with(|| {
                        let q = std::array::from_fn(|c| 0.5 * (p[a][c] + p[b][c]));
                        p.push(q);
                        p.len() - 1
                    });
                }
                nf.push([t[0], m[0], m[2]]);
                nf.push([m[0], t[1], m[1]]);
                nf.push([m[2], m[1], t[2]]);
                nf.push([m[0], m[1], m[2]]);
            }
            f = nf;
        }
        for q in &mut p {
            let l = norm(*q);
            *q = scale(*q, 1.0 / l);
        }
        TriMesh::new(p, f)
    }

    fn rot(axis: Vec3, angle: f64) -> Mat3 {
        let a = scale(axis, angle / norm(axis));
        exp_so3(a)
    }

    fn apply(m: &Mat3, p: Vec3) -> Vec3 {
        std::array::from_fn(|i| dot(m[i], p))
    }

    fn max_dev_centroid_aligned(a: &[Vec3], b: &[Vec3]) -> f64 {
        let ca: Vec3 = std::array::from_fn(|k| a.iter().map(|p| p[k]).sum::<f64>() / a.len() as f64);
        let cb: Vec3 = std::array::from_fn(|k| b.iter().map(|p| p[k]).sum::<f64>() / b.len() as f64);
        a.iter().zip(b).map(|(p, q)| norm(sub(sub(*p, ca), sub(*q, cb)))).fold(0.0, f64::max)
    }

    #[test]
    fn identity_gives_zero_features_in_unit_normal_convention() {
        let m = sphere(2);
        let tg = TriangleGradient::new(&m, NormalConvention::UnitNormal).unwrap();
        let q = tg.encode_frame(&m.positions).unwrap();
        assert!(q.iter().all(|x| x.abs() < 1e-12), "max {}", q.iter().fold(0.0f64, |a, x| a.max(x.abs())));
    }

    #[test]
    fn identity_in_min_norm_convention_is_minus_normal_projector() {
        // J = Q2·Q2ᵀ = I − n·nᵀ, so U = I and P − I = −n·nᵀ.
        let m = sphere(1);
        let tg = TriangleGradient::new(&m, NormalConvention::MinNorm).unwrap();
        let q = tg.encode_frame(&m.positions).unwrap();
        for (f, qt) in m.faces.iter().zip(q.chunks_exact(9)) {
            let [a, b, c] = f.map(|v| m.positions[v]);
            let n = crate::math::vec3::normalize(cross(sub(b, a), sub(c, a)));
            let expect = [-n[0] * n[0], -n[1] * n[1], -n[2] * n[2], -n[0] * n[1], -n[0] * n[2], -n[1] * n[2]];
            assert!(norm([qt[0], qt[1], qt[2]]) < 1e-12);
            for k in 0..6 {
                assert!((qt[3 + k] - expect[k]).abs() < 1e-12, "{qt:?} vs {expect:?}");
            }
        }
    }

    #[test]
    fn rigid_rotation_gives_constant_axis_angle_and_zero_stretch() {
        let m = sphere(2);
        let u_true = scale([0.2, -0.5, 0.8], 2.2 / norm([0.2, -0.5, 0.8]));
        let r = exp_so3(u_true);
        let moved: Vec<Vec3> = m
            .positions
            .iter()
            .map(|p| {
                let q = apply(&r, *p);
                [q[0] + 3.0, q[1] - 1.0, q[2] + 0.5]
            })
            .collect();
        for conv in [NormalConvention::UnitNormal, NormalConvention::MinNorm] {
            let tg = TriangleGradient::new(&m, conv).unwrap();
            let q = tg.encode_frame(&moved).unwrap();
            let q0 = tg.encode_frame(&m.positions).unwrap();
            for (qt, q0t) in q.chunks_exact(9).zip(q0.chunks_exact(9)) {
                assert!(norm(sub([qt[0], qt[1], qt[2]], u_true)) < 1e-10, "{qt:?}");
                // Stretch equals the rest shape's stretch (zero for UnitNormal).
                for k in 3..9 {
                    assert!((qt[k] - q0t[k]).abs() < 1e-10);
                }
            }
        }
    }

    #[test]
    fn uniform_scaling_stretches_in_plane_only() {
        // Min-norm J of a scaled triangle is s·(I − n·nᵀ): U = I, and the normal direction is
        // never stretched. Grid in the xy-plane (n = +z): UnitNormal p = (s−1, s−1, 0, 0, 0, 0),
        // MinNorm p = (s−1, s−1, −1, 0, 0, 0). On a sphere (varying n) UnitNormal gives
        // P − I = (s−1)(I − n·nᵀ).
        let s = 1.7;
        let g = grid(4, 3);
        let scaled: Vec<Vec3> = g.positions.iter().map(|p| scale(*p, s)).collect();
        for (conv, expect) in [
            (NormalConvention::UnitNormal, [s - 1.0, s - 1.0, 0.0]),
            (NormalConvention::MinNorm, [s - 1.0, s - 1.0, -1.0]),
        ] {
            let tg = TriangleGradient::new(&g, conv).unwrap();
            for qt in tg.encode_frame(&scaled).unwrap().chunks_exact(9) {
                let want = [0.0, 0.0, 0.0, expect[0], expect[1], expect[2], 0.0, 0.0, 0.0];
                for k in 0..9 {
                    assert!((qt[k] - want[k]).abs() < 1e-12, "{conv:?}: {qt:?}");
                }
            }
        }
        let m = sphere(1);
        let tg = TriangleGradient::new(&m, NormalConvention::UnitNormal).unwrap();
        let scaled: Vec<Vec3> = m.positions.iter().map(|p| scale(*p, s)).collect();
        for (f, qt) in m.faces.iter().zip(tg.encode_frame(&scaled).unwrap().chunks_exact(9)) {
            let [a, b, c] = f.map(|v| m.positions[v]);
            let n = crate::math::vec3::normalize(cross(sub(b, a), sub(c, a)));
            let k = s - 1.0;
            let want = [
                k * (1.0 - n[0] * n[0]),
                k * (1.0 - n[1] * n[1]),
                k * (1.0 - n[2] * n[2]),
                -k * n[0] * n[1],
                -k * n[0] * n[2],
                -k * n[1] * n[2],
            ];
            assert!(norm([qt[0], qt[1], qt[2]]) < 1e-12);
            for i in 0..6 {
                assert!((qt[3 + i] - want[i]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn gradient_reproduces_edges_and_polar_factors_are_valid() {
        let m = sphere(1);
        let def: Vec<Vec3> = m
            .positions
            .iter()
            .map(|p| [p[0] * 1.3 + 0.2 * p[1], p[1] - 0.4 * p[2] * p[2], p[2] * 0.7 + p[0] * p[1]])
            .collect();
        let tg = TriangleGradient::new(&m, NormalConvention::UnitNormal).unwrap();
        let q = tg.encode_frame(&def).unwrap();
        let js = tg.gradients(&q).unwrap();
        for ((f, j), qt) in m.faces.iter().zip(&js).zip(q.chunks_exact(9)) {
            let rest = f.map(|v| m.positions[v]);
            let dfm = f.map(|v| def[v]);
            // J from features maps rest edges exactly onto deformed edges.
            for k in 1..3 {
                let e = apply(j, sub(rest[k], rest[0]));
                assert!(norm(sub(e, sub(dfm[k], dfm[0]))) < 1e-12);
            }
            // Same in-plane action as Eq. (5).
            let jmin = deformation_gradient(rest, dfm).unwrap();
            let e1 = sub(rest[1], rest[0]);
            assert!(norm(sub(apply(&jmin, e1), apply(j, e1))) < 1e-12);
            // P is positive definite (the stretch of a non-degenerate triangle).
            let p = vec_to_stretch(&qt[3..]);
            let pm = nalgebra::Matrix3::from_fn(|r, c| p[r][c]);
            assert!(pm.symmetric_eigenvalues().min() > 0.0);
            assert!(norm([qt[0], qt[1], qt[2]]) <= std::f64::consts::PI + 1e-12);
        }
    }

    #[test]
    fn degenerate_deformed_triangle_uses_proper_rotation() {
        let rest = TriMesh::new(vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]], vec![[0, 1, 2]]);
        let tg = TriangleGradient::new(&rest, NormalConvention::MinNorm).unwrap();
        // Collapse onto a line (zero area), mirrored in x.
        let q = tg.encode_frame(&[[0., 0., 0.], [-2., 0., 0.], [-1., 0., 0.]]).unwrap();
        let u = exp_so3([q[0], q[1], q[2]]);
        let det = nalgebra::Matrix3::from_fn(|r, c| u[r][c]).determinant();
        assert!((det - 1.0).abs() < 1e-12);
        let j = gradient_of(&q);
        let jmin = deformation_gradient(
            rest.faces[0].map(|v| rest.positions[v]),
            [[0., 0., 0.], [-2., 0., 0.], [-1., 0., 0.]],
        )
        .unwrap();
        for r in 0..3 {
            for c in 0..3 {
                assert!((j[r][c] - jmin[r][c]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn decode_encode_round_trip_on_deformed_sphere_and_grid() {
        for m in [sphere(3), grid(12, 9)] {
            // A non-rigid deformation with large rotations: twist about z plus bending.
            let def: Vec<Vec3> = m
                .positions
                .iter()
                .map(|p| {
                    let a = 2.5 * p[1] + 0.5 * p[0];
                    let (s, c) = a.sin_cos();
                    [c * p[0] - s * p[2] + 0.1, 1.2 * p[1] + 0.3 * p[0] * p[0], s * p[0] + c * p[2] - 2.0]
                })
                .collect();
            for conv in [NormalConvention::UnitNormal, NormalConvention::MinNorm] {
                let tg = TriangleGradient::new(&m, conv).unwrap();
                let q = tg.encode_frame(&def).unwrap();
                let back = tg.decode_frame(&q).unwrap();
                let dev = max_dev_centroid_aligned(&def, &back);
                assert!(dev < 1e-9, "{conv:?}: max deviation {dev}");
                // Decoded centroid is the rest centroid.
                let c_back: Vec3 = std::array::from_fn(|k| back.iter().map(|p| p[k]).sum::<f64>() / back.len() as f64);
                let c_rest: Vec3 =
                    std::array::from_fn(|k| m.positions.iter().map(|p| p[k]).sum::<f64>() / m.positions.len() as f64);
                assert!(norm(sub(c_back, c_rest)) < 1e-12);
            }
        }
    }

    #[test]
    fn two_components_are_each_centred_on_their_rest_centroid() {
        let a = sphere(1);
        let mut p = a.positions.clone();
        let n = p.len();
        p.extend(a.positions.iter().map(|q| [q[0] + 5.0, q[1], q[2]]));
        let mut f = a.faces.clone();
        f.extend(a.faces.iter().map(|t| t.map(|v| v + n)));
        let m = TriMesh::new(p, f);
        let tg = TriangleGradient::new(&m, NormalConvention::UnitNormal).unwrap();
        let r = rot([0.0, 1.0, 0.0], 0.9);
        let def: Vec<Vec3> = m.positions.iter().map(|q| apply(&r, *q)).collect();
        let back = tg.decode_frame(&tg.encode_frame(&def).unwrap()).unwrap();
        for (half, rest_half) in [(&back[..n], &m.positions[..n]), (&back[n..], &m.positions[n..])] {
            let c: Vec3 = std::array::from_fn(|k| half.iter().map(|q| q[k]).sum::<f64>() / n as f64);
            let cr: Vec3 = std::array::from_fn(|k| rest_half.iter().map(|q| q[k]).sum::<f64>() / n as f64);
            assert!(norm(sub(c, cr)) < 1e-12);
        }
        let def_half: Vec<Vec3> = def[n..].to_vec();
        assert!(max_dev_centroid_aligned(&def_half, &back[n..]) < 1e-10);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let degenerate = TriMesh::new(vec![[0., 0., 0.], [1., 0., 0.], [2., 0., 0.]], vec![[0, 1, 2]]);
        assert!(TriangleGradient::new(&degenerate, NormalConvention::UnitNormal).is_err());
        let m = grid(2, 2);
        let tg = TriangleGradient::new(&m, NormalConvention::UnitNormal).unwrap();
        assert!(tg.encode_frame(&m.positions[1..]).is_err());
        let mut bad = m.positions.clone();
        bad[3][1] = f64::NAN;
        assert!(tg.encode_frame(&bad).is_err());
        let mut q = tg.encode_frame(&m.positions).unwrap();
        assert!(tg.decode_frame(&q[1..]).is_err());
        q[5] = f64::INFINITY;
        assert!(tg.decode_frame(&q).is_err());
    }
}
