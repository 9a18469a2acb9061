//! ACAP ("as-consistent-as-possible") deformation features of Gao et al., as used by Tan et al.,
//! matching the reference implementation (docs/design.md § Representations → acap).
//!
//! Per vertex i of a frame, against the reference mesh (positions q):
//! 1. Weights from the reference only: w_ij = sqrt(sexp(½(cot α_ij + cot β_ij))), α, β the
//!    angles opposite edge ij, sexp(x) = eˣ (x ≤ 0) or 1 + x (x > 0); NaN or > 1e5 becomes 1. A
//!    boundary edge has one opposite angle (the reference wraps its ring cyclically instead).
//! 2. Rows a_k = sqrt(w_ij)(q_j − q_i) and b_k = sqrt(w_ij)(p_j − p_i), plus a normal row:
//!    the unit vertex normal (sum of unit face normals, as OpenMesh computes it) times 0.3 × the
//!    mean 1-ring edge length, each mesh its own.
//! 3. T_i = (Σ b aᵀ)(Σ a aᵀ)⁻¹ (3×3, maps reference edge vectors to deformed ones).
//! 4. T_i = R_i S_i by [`polar_decomposition`] (reflection fix of the reference).
//! 5. Axis–angle of R_i, made consistent over the mesh by [`Consistency::Bfs`] or
//!    [`Consistency::Global`] (see [`super::acap_consistency`]).
//! 6. logR_i = φ_i \[a_i\]× with φ_i the consistent angle (radians, any real value).
//!
//! Feature vector per vertex (width 9): logR (0,1), (0,2), (1,2), then S (0,0), (0,1), (0,2),
//! (1,1), (1,2), (2,2). The reference itself gives logR = 0, S = I. With
//! [`FeatureMap::Gradient`] (the autoencoder's `features = "gradient"`) the 9 numbers are T_i − I
//! row-major instead (steps 4–6 skipped; the reference gives 0); decoding is the same from T_i on.
//!
//! Decoding (features → positions): T_i = exp(logR_i)·S_i (Rodrigues), then, by default, the
//! exact inverse of step 3 ([`FitInverse`]: positions whose 1-ring fits give these T_i; encode →
//! decode is exact to rounding), optionally regularised by the edge least squares; or docs/design.md's
//! edge least squares alone ([`AcapReconstruction`], min Σ c_ij ‖(p_i − p_j) − ½(T_i + T_j)(q_i −
//! q_j)‖² with c_ij = w_ij, the ACAP weights above: positive, bounded, the ones that weight the
//! 1-ring fits). See [`AcapDecoder`]. Both matrices depend on the reference only and are
//! factorised once in [`Acap::new`]; the result's centroid is the reference's.
//!
//! Matching the reference: on its fixtures (`../shared/fixtures/acap`) S and logR equal the
//! with-opt output files within 6.2e-5 (printing precision); the BFS output files were produced
//! from other inputs (their S, which no consistency option changes, differs from the with-opt
//! S by 5.4e-3) and carry a 2π seam that no BFS from vertex 0 over that mesh produces. Rings
//! come from [`Topology`] (counter-clockwise); the reference circulates OpenMesh's clockwise
//! order. Only the BFS tree depends on it, and on the fixtures both orders give identical
//! results.

pub use crate::math::mat3::Mat3;
use crate::math::mat3::{
    IDENTITY, add_outer, axis_angle, exp_so3, inverse, mat_mul, polar_decomposition, skew, transpose, unskew,
};
use crate::math::vec3::{cross, dist, dot, norm, scale, sub};
use crate::mesh::normals::{NormalWeighting, vertex_normals};
use crate::mesh::{Topology, TriMesh, Vec3};
use crate::representation::Features;
pub use crate::representation::acap_consistency::{BfsTree, RotationField};
use crate::representation::acap_consistency::{IDENTITY_ANGLE, bfs_consistency, global_consistency, neighbour_energy};
pub use crate::representation::acap_fit_inverse::{FitInverse, RingFit};
pub use crate::representation::acap_reconstruct::AcapReconstruction;
use crate::{Error, Result};
use rayon::prelude::*;

/// Scale of the normal row relative to the mean 1-ring edge length (the reference's 0.3).
pub const NORMAL_SCALE: f64 = 0.3;

/// Numbers per vertex in the feature vector.
pub const WIDTH: usize = 9;

/// Which rotation-consistency step to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Consistency {
    /// Breadth-first propagation from vertex 0 (the reference's option 0).
    #[default]
    Bfs,
    /// BFS followed by the local search on the neighbour-difference energy (replaces the
    /// reference's MIQP, option 1); never ends above the BFS energy.
    Global,
}

/// ACAP features of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct AcapFrame {
    /// Per vertex (N): the consistent rotation logarithm φ\[a\]× (skew-symmetric, radians).
    pub log_r: Vec<Mat3>,
    /// Per vertex (N): the symmetric stretch S (identity for no deformation).
    pub s: Vec<Mat3>,
    /// Neighbour-difference energy Σ_edges ‖ω_i − ω_j‖² (rad²) of the BFS result.
    pub energy_bfs: f64,
    /// The same energy of `log_r` (equals `energy_bfs` for [`Consistency::Bfs`]; NaN when the
    /// frame was built by [`AcapFrame::from_features`], which has no edges to measure it on).
    pub energy: f64,
}

impl AcapFrame {
    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.log_r.len()
    }

    /// N×9 feature vector (layout in the module docs).
    pub fn features(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.log_r.len() * WIDTH);
        for (l, s) in self.log_r.iter().zip(&self.s) {
            out.extend_from_slice(&[l[0][1], l[0][2], l[1][2], s[0][0], s[0][1], s[0][2], s[1][1], s[1][2], s[2][2]]);
        }
        out
    }

    /// Inverse of [`AcapFrame::features`]: logR skew-symmetric, S symmetric. Energies are NaN
    /// (unknown). Errors when the length is not a multiple of 9.
    pub fn from_features(features: &[f64]) -> Result<Self> {
        if !features.len().is_multiple_of(WIDTH) {
            return Err(Error::Invalid(format!(
                "ACAP features: length {} is not a multiple of {WIDTH}",
                features.len()
            )));
        }
        let (log_r, s) = features
            .chunks_exact(WIDTH)
            .map(|f| {
                let l = [[0.0, f[0], f[1]], [-f[0], 0.0, f[2]], [-f[1], -f[2], 0.0]];
                let s = [[f[3], f[4], f[5]], [f[4], f[6], f[7]], [f[5], f[7], f[8]]];
                (l, s)
            })
            .unzip();
        Ok(AcapFrame { log_r, s, energy_bfs: f64::NAN, energy: f64::NAN })
    }

    /// Stacks frames' features into an F × N × 9 array (all frames must have the same N).
    pub fn stack(frames: &[AcapFrame]) -> Result<Features> {
        let n = frames.first().map_or(0, |f| f.n_vertices());
        let mut out = Features::zeros(frames.len(), n, WIDTH);
        for (f, fr) in frames.iter().enumerate() {
            if fr.n_vertices() != n {
                return Err(Error::Invalid(format!(
                    "ACAP frame {f} has {} vertices, frame 0 has {n}",
                    fr.n_vertices()
                )));
            }
            out.frame_mut(f).copy_from_slice(&fr.features());
        }
        Ok(out)
    }
}

/// ACAP encoder/decoder for one reference mesh: weights, 1-ring fits and the reconstruction
/// factorisation are computed once in [`Acap::new`].
#[derive(Debug)]
pub struct Acap {
    faces: Vec<[usize; 3]>,
    reference: Vec<Vec3>,
    /// 1-rings in CSR form (the order used by BFS).
    ring_offsets: Vec<usize>,
    ring: Vec<usize>,
    neighbors: Vec<Vec<usize>>,
    /// Undirected edges (i < j), sorted.
    edges: Vec<[usize; 2]>,
    /// Per ring entry: sqrt(w_ij), the row scale.
    row_scale: Vec<f64>,
    /// Per ring entry: the reference row a = sqrt(w_ij)(q_j − q_i).
    ref_rows: Vec<Vec3>,
    /// Per vertex: the reference normal row.
    ref_normal_rows: Vec<Vec3>,
    /// Per vertex: (Σ a aᵀ)⁻¹ (identity for isolated vertices).
    inv_ata: Vec<Mat3>,
    tree: BfsTree,
    decoder: Decoder,
    options: AcapOptions,
}

/// How [`Acap::decode_frame`] turns per-vertex gradients T_i = exp(logR_i)·S_i into positions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AcapDecoder {
    /// The exact inverse of the encoder's 1-ring fit ([`FitInverse`]): encode → decode returns
    /// the input up to rounding (and translation). `edge_weight` ≥ 0 adds that multiple of the
    /// edge least squares of [`AcapDecoder::EdgeLeastSquares`], divided by h̄² (h̄ the mean
    /// reference edge length, making the weight scale-free). A small weight (default 1e-6) keeps
    /// the system well-posed on meshes where the fit alone leaves some motion undetermined
    /// (symmetric 1-ring fans, e.g. the 3-colouring patterns of a regular triangular grid, which
    /// the edge term then resolves) and biases exact round trips by about 10·weight in Erms
    /// units; a larger one regularises features that are not exactly realisable (network
    /// outputs). Measured round trips (Erms, 1000 × data units, centroid-aligned): all 71 SCAPE
    /// shapes without noise, weight 0 / 1e-9 / 1e-6 / 0.01 / 0.1 give 3e-11 / 8e-9 / 8e-6 /
    /// 0.05 / 0.24 (edge least squares alone: 0.93); the first 10 SCAPE shapes with uniform noise
    /// of ±0.05 added to every feature, weight 0 / 0.01 / 0.1 give 2.25 / 1.84 / 1.50 (edge least
    /// squares alone: 1.74).
    FitInverse { edge_weight: f64 },
    /// docs/design.md's edge least squares alone ([`AcapReconstruction`], weights c_ij = w_ij).
    EdgeLeastSquares,
}

/// Default `edge_weight` of [`AcapDecoder::FitInverse`].
pub const DEFAULT_EDGE_WEIGHT: f64 = 1e-6;

/// What the 9 numbers per vertex are: how a vertex's features make its deformation gradient
/// T_i (step 3 of the module docs), which both maps decode alike.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FeatureMap {
    /// logR and S of T = exp(logR)·S (the layout of the module docs; the paper's ACAP
    /// features): a rotation of any size is one feature value, and rotations add along their
    /// consistent angle.
    #[default]
    RotationStretch,
    /// T − I, row-major (T₀₀ − 1, T₀₁, T₀₂, T₁₀, …, T₂₂ − 1): the 1-ring fit itself, linear in
    /// the frame's vertices except for its normal row (step 2), so deformations that add in
    /// positions add here too; a sum of rotations is no rotation (large rotations shrink).
    Gradient,
}

impl FeatureMap {
    /// The config name: `acap` | `gradient`.
    pub fn name(self) -> &'static str {
        match self {
            FeatureMap::RotationStretch => "acap",
            FeatureMap::Gradient => "gradient",
        }
    }

    /// Inverse of [`FeatureMap::name`].
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "acap" => Some(FeatureMap::RotationStretch),
            "gradient" => Some(FeatureMap::Gradient),
            _ => None,
        }
    }

    /// T of one vertex from its 9 unscaled features ([`feature_transform`] for ACAP).
    pub fn transform(self, f: &[f64]) -> Mat3 {
        match self {
            FeatureMap::RotationStretch => feature_transform(f),
            FeatureMap::Gradient => [[1.0 + f[0], f[1], f[2]], [f[3], 1.0 + f[4], f[5]], [f[6], f[7], 1.0 + f[8]]],
        }
    }

    /// ∂T/∂f_q for q = 0..9 ([`feature_transform_jacobian`] for ACAP; the unit matrices E_q
    /// for the gradient map).
    pub fn transform_jacobian(self, f: &[f64]) -> [Mat3; 9] {
        match self {
            FeatureMap::RotationStretch => feature_transform_jacobian(f),
            FeatureMap::Gradient => std::array::from_fn(|q| {
                let mut e = [[0.0; 3]; 3];
                e[q / 3][q % 3] = 1.0;
                e
            }),
        }
    }

    /// The vector–Jacobian product ⟨A, ∂T/∂f_q⟩ for q = 0..9 ([`feature_transform_vjp`] for
    /// ACAP; A's entries row-major for the gradient map).
    pub fn transform_vjp(self, f: &[f64], a: &Mat3) -> [f64; 9] {
        match self {
            FeatureMap::RotationStretch => feature_transform_vjp(f, a),
            FeatureMap::Gradient => std::array::from_fn(|q| a[q / 3][q % 3]),
        }
    }

    /// The 9 features of a deformation gradient T (the inverse of [`FeatureMap::transform`]
    /// for the gradient map; ACAP's need the frame's rotation consistency:
    /// [`Acap::encode_values`]).
    fn gradient_values(t: &Mat3) -> [f64; 9] {
        std::array::from_fn(|q| t[q / 3][q % 3] - if q / 3 == q % 3 { 1.0 } else { 0.0 })
    }
}

/// Hyperparameters of the ACAP encoder/decoder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AcapOptions {
    /// The decoder (default: fit inverse with edge weight [`DEFAULT_EDGE_WEIGHT`]).
    pub decoder: AcapDecoder,
    /// What the features are (default: ACAP's logR and S).
    pub map: FeatureMap,
}

impl Default for AcapOptions {
    fn default() -> Self {
        AcapOptions {
            decoder: AcapDecoder::FitInverse { edge_weight: DEFAULT_EDGE_WEIGHT },
            map: FeatureMap::default(),
        }
    }
}

impl AcapOptions {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<()> {
        if let AcapDecoder::FitInverse { edge_weight } = self.decoder
            && !(edge_weight.is_finite() && edge_weight >= 0.0)
        {
            return Err(Error::config("edge_weight", format!("edge_weight ({edge_weight}) must be finite and ≥ 0")));
        }
        Ok(())
    }
}

/// The factorised decoder.
#[derive(Debug)]
enum Decoder {
    FitInverse(FitInverse),
    Edge(AcapReconstruction),
}

/// sexp(x) = eˣ for x ≤ 0, 1 + x otherwise.
fn sexp(x: f64) -> f64 {
    if x <= 0.0 { x.exp() } else { 1.0 + x }
}

/// Cotangent of the angle at `o` between `a − o` and `b − o`, as the reference computes it
/// (0 for a degenerate side, 1 when the cosine is exactly 1).
fn cot_at(o: Vec3, a: Vec3, b: Vec3) -> f64 {
    let u = sub(a, o);
    let v = sub(b, o);
    let nu = norm(u);
    let nv = norm(v);
    if nu < 1e-12 || nv < 1e-12 {
        return 0.0;
    }
    let c = dot(u, v) / (nu * nv);
    if c == 1.0 {
        return 1.0;
    }
    c / (1.0 - c * c).sqrt()
}

/// The ACAP edge weight w_ij from the cotangents of the opposite angles.
fn acap_weight(cot_sum: f64) -> f64 {
    let w = sexp(0.5 * cot_sum).sqrt();
    if w.is_nan() || w > 1e5 { 1.0 } else { w }
}

impl Acap {
    /// [`Acap::with_options`] with the default options.
    pub fn new(reference: &TriMesh) -> Result<Acap> {
        Acap::with_options(reference, AcapOptions::default())
    }

    /// Precomputes everything that depends on the reference mesh only. Errors on bad options,
    /// bad face indices, non-finite positions, a singular 1-ring fit (a degenerate
    /// neighbourhood), or a failed factorisation.
    pub fn with_options(reference: &TriMesh, options: AcapOptions) -> Result<Acap> {
        Acap::with_fit_weights(reference, options, None)
    }

    /// [`Acap::with_options`] whose [`AcapDecoder::FitInverse`] weights vertex i's fit residual
    /// by `fit_weights[i]` (N, each finite and > 0; [`FitInverse`]); `None`, or another decoder:
    /// unweighted. Encoding is unchanged.
    pub fn with_fit_weights(reference: &TriMesh, options: AcapOptions, fit_weights: Option<&[f64]>) -> Result<Acap> {
        options.validate()?;
        let n = reference.n_vertices();
        if let Some((f, face)) = reference.first_bad_index() {
            return Err(Error::Invalid(format!("ACAP reference: face {f} {face:?} refers past {n} vertices")));
        }
        check_finite(&reference.positions, "ACAP reference")?;
        let q = &reference.positions;
        let topo = Topology::new(n, &reference.faces);
        let ring_offsets = topo.ring_offsets.clone();
        let ring = topo.ring.clone();
        let neighbors: Vec<Vec<usize>> = (0..n).map(|v| ring[ring_offsets[v]..ring_offsets[v + 1]].to_vec()).collect();

        // Edge weights from the opposite angles of the reference.
        let edge_weight: Vec<f64> = topo
            .edges
            .iter()
            .zip(&topo.edge_faces)
            .map(|(&[i, j], inc)| {
                let cot: f64 = inc.iter().map(|&(_, o)| cot_at(q[o], q[i], q[j])).sum();
                acap_weight(cot)
            })
            .collect();

        let normals = vertex_normals(q, &reference.faces, NormalWeighting::Uniform);
        let mut row_scale = Vec::with_capacity(ring.len());
        let mut ref_rows = Vec::with_capacity(ring.len());
        let mut ref_normal_rows = Vec::with_capacity(n);
        let mut inv_ata = Vec::with_capacity(n);
        for i in 0..n {
            let nb = &ring[ring_offsets[i]..ring_offsets[i + 1]];
            let mut ata = [[0.0; 3]; 3];
            let mut len_sum = 0.0;
            for &j in nb {
                let e = sub(q[j], q[i]);
                len_sum += norm(e);
                let id = topo.edge_id(i, j).ok_or_else(|| {
                    Error::Invalid(format!("ACAP reference: ring neighbours {i} and {j} share no edge"))
                })?;
                let sw = edge_weight[id].sqrt();
                let a = [sw * e[0], sw * e[1], sw * e[2]];
                add_outer(&mut ata, a, a, 1.0);
                row_scale.push(sw);
                ref_rows.push(a);
            }
            if nb.is_empty() {
                ref_normal_rows.push([0.0; 3]);
                inv_ata.push(IDENTITY);
                continue;
            }
            let h = NORMAL_SCALE * len_sum / nb.len() as f64;
            let a = [normals[i][0] * h, normals[i][1] * h, normals[i][2] * h];
            add_outer(&mut ata, a, a, 1.0);
            ref_normal_rows.push(a);
            inv_ata.push(inverse(&ata).ok_or_else(|| {
                Error::Numerical(format!(
                    "ACAP reference: the 1-ring of vertex {i} ({} neighbours) is degenerate (singular fit)",
                    nb.len()
                ))
            })?);
        }
        let tree = BfsTree::new(&ring_offsets, &ring);
        let decoder = match options.decoder {
            AcapDecoder::EdgeLeastSquares => Decoder::Edge(AcapReconstruction::new(q, &topo.edges, &edge_weight)?),
            AcapDecoder::FitInverse { edge_weight: mu } => {
                let h = reference.mean_edge_length();
                let scale = if h > 0.0 { mu / (h * h) } else { 0.0 };
                let fit = RingFit {
                    ring_offsets: &ring_offsets,
                    ring: &ring,
                    row_scale: &row_scale,
                    ref_rows: &ref_rows,
                    ref_normal_rows: &ref_normal_rows,
                    inv_ata: &inv_ata,
                };
                Decoder::FitInverse(FitInverse::new(q, &topo.edges, fit, Some((&edge_weight, scale)), fit_weights)?)
            }
        };
        Ok(Acap {
            faces: reference.faces.clone(),
            reference: q.clone(),
            ring_offsets,
            ring,
            neighbors,
            edges: topo.edges,
            row_scale,
            ref_rows,
            ref_normal_rows,
            inv_ata,
            tree,
            decoder,
            options,
        })
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.reference.len()
    }

    /// The 1-rings used (for each vertex its neighbours, in the order the BFS visits them).
    pub fn neighbors(&self) -> &[Vec<usize>] {
        &self.neighbors
    }

    /// Undirected edges (i < j) on which the consistency energy is measured.
    pub fn edges(&self) -> &[[usize; 2]] {
        &self.edges
    }

    /// Reference positions.
    pub fn reference(&self) -> &[Vec3] {
        &self.reference
    }

    /// The options in use.
    pub fn options(&self) -> AcapOptions {
        self.options
    }

    /// Deformed normal rows β_i = n_i × 0.3 × mean 1-ring edge length of `positions` (zero for
    /// isolated vertices).
    fn normal_rows(&self, positions: &[Vec3]) -> Vec<Vec3> {
        let normals = vertex_normals(positions, &self.faces, NormalWeighting::Uniform);
        (0..positions.len())
            .map(|i| {
                let (s, e) = (self.ring_offsets[i], self.ring_offsets[i + 1]);
                if s == e {
                    return [0.0; 3];
                }
                let p = positions[i];
                let len_sum: f64 = self.ring[s..e].iter().map(|&j| dist(positions[j], p)).sum();
                let h = NORMAL_SCALE * len_sum / (e - s) as f64;
                [normals[i][0] * h, normals[i][1] * h, normals[i][2] * h]
            })
            .collect()
    }

    /// Per-vertex deformation gradients T_i of a frame (step 3 of the module docs).
    pub fn deformation_gradients(&self, positions: &[Vec3]) -> Result<Vec<Mat3>> {
        let n = self.n_vertices();
        if positions.len() != n {
            return Err(Error::Invalid(format!("ACAP: frame has {} vertices, reference has {n}", positions.len())));
        }
        check_finite(positions, "ACAP frame")?;
        let beta = self.normal_rows(positions);
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let (s, e) = (self.ring_offsets[i], self.ring_offsets[i + 1]);
            if s == e {
                out.push(IDENTITY);
                continue;
            }
            let p = positions[i];
            let mut m = [[0.0; 3]; 3];
            for k in s..e {
                let j = self.ring[k];
                let sw = self.row_scale[k];
                let d = scale(sub(positions[j], p), sw);
                add_outer(&mut m, d, self.ref_rows[k], 1.0);
            }
            add_outer(&mut m, beta[i], self.ref_normal_rows[i], 1.0);
            out.push(mat_mul(&m, &self.inv_ata[i]));
        }
        Ok(out)
    }

    /// ACAP features of one frame (N positions).
    pub fn encode_frame(&self, positions: &[Vec3], consistency: Consistency) -> Result<AcapFrame> {
        let t = self.deformation_gradients(positions)?;
        let n = t.len();
        let mut s = Vec::with_capacity(n);
        let mut axis = Vec::with_capacity(n);
        let mut theta = Vec::with_capacity(n);
        for ti in &t {
            let (r, si) = polar_decomposition(ti);
            let (a, th) = axis_angle(&r);
            s.push(si);
            axis.push(a);
            theta.push(th);
        }
        let mut field = bfs_consistency(&self.tree, &axis, &theta);
        let energy_bfs = neighbour_energy(&field, &self.edges);
        let energy = match consistency {
            Consistency::Bfs => energy_bfs,
            Consistency::Global => {
                let identity: Vec<bool> = theta.iter().map(|&t| t <= IDENTITY_ANGLE).collect();
                global_consistency(&mut field, &identity, &self.ring_offsets, &self.ring, &self.edges)
            }
        };
        let log_r = (0..n).map(|i| skew(field.vector(i))).collect();
        Ok(AcapFrame { log_r, s, energy_bfs, energy })
    }

    /// The N×9 feature vector of one frame in this codec's [`FeatureMap`]: ACAP's
    /// ([`Acap::encode_frame`] with `consistency`) or T − I (the consistency unused).
    pub fn encode_values(&self, positions: &[Vec3], consistency: Consistency) -> Result<Vec<f64>> {
        match self.options.map {
            FeatureMap::RotationStretch => Ok(self.encode_frame(positions, consistency)?.features()),
            FeatureMap::Gradient => {
                Ok(self.deformation_gradients(positions)?.iter().flat_map(FeatureMap::gradient_values).collect())
            }
        }
    }

    /// What the features are.
    pub fn map(&self) -> FeatureMap {
        self.options.map
    }

    /// Positions (N) from an N×9 feature vector of this codec's [`FeatureMap`]; the centroid
    /// is the reference's.
    pub fn decode_frame(&self, features: &[f64]) -> Result<Vec<Vec3>> {
        let n = self.n_vertices();
        if features.len() != n * WIDTH {
            return Err(Error::Invalid(format!(
                "ACAP decode: {} feature values, expected {n} × {WIDTH}",
                features.len()
            )));
        }
        if let Some(k) = features.iter().position(|x| !x.is_finite()) {
            return Err(Error::Invalid(format!(
                "ACAP decode: non-finite feature {} at vertex {} component {}",
                features[k],
                k / WIDTH,
                k % WIDTH
            )));
        }
        let map = self.options.map;
        let t: Vec<Mat3> = features.chunks_exact(WIDTH).map(|f| map.transform(f)).collect();
        self.decode_transforms(&t)
    }

    /// Positions (N) from per-vertex deformation gradients T_i (N) with the configured
    /// decoder; the centroid is the reference's.
    pub fn decode_transforms(&self, transforms: &[Mat3]) -> Result<Vec<Vec3>> {
        match &self.decoder {
            Decoder::FitInverse(f) => f.solve(transforms),
            Decoder::Edge(r) => r.solve(transforms),
        }
    }

    /// The linear part of [`Acap::decode_transforms`] (an affine map) for several sets of
    /// transforms (N each) in one solve with the decoder's factor: per set the positions
    /// p(T) − p(0) up to one translation per connected piece (centre them to compare).
    pub fn decode_transforms_linear_many(&self, sets: &[Vec<Mat3>]) -> Result<Vec<Vec<Vec3>>> {
        match &self.decoder {
            Decoder::FitInverse(f) => f.solve_linear_many(sets),
            Decoder::Edge(r) => r.solve_linear_many(sets),
        }
    }

    /// [`Acap::encode_frame`] for many frames, in parallel (rayon).
    pub fn encode_sequence(&self, frames: &[Vec<Vec3>], consistency: Consistency) -> Result<Vec<AcapFrame>> {
        frames.par_iter().map(|f| self.encode_frame(f, consistency)).collect()
    }

    /// Features F × N × 9 of many frames (parallel).
    pub fn encode_features(&self, frames: &[Vec<Vec3>], consistency: Consistency) -> Result<Features> {
        AcapFrame::stack(&self.encode_sequence(frames, consistency)?)
    }

    /// Adjoint of [`Acap::decode_transforms`] (an affine map): for a gradient `grad` (N × 3)
    /// with respect to the decoded positions, the gradient with respect to every T_i (N,
    /// row-major 3×3). Costs one solve with the decoder's factor. Both decoders treat the three
    /// coordinates alike, so the gradient of coordinate c of one vertex touches only row c of
    /// every T_i, with the same coefficients for every c.
    pub fn decode_transforms_adjoint(&self, grad: &[Vec3]) -> Result<Vec<Mat3>> {
        match &self.decoder {
            Decoder::FitInverse(f) => f.solve_adjoint(grad),
            Decoder::Edge(r) => r.solve_adjoint(grad),
        }
    }

    /// [`Acap::decode_frame`] for every frame of an F × N × 9 array, in parallel (rayon).
    pub fn decode_sequence(&self, features: &Features) -> Result<Vec<Vec<Vec3>>> {
        if features.n_elements != self.n_vertices() || features.width != WIDTH {
            return Err(Error::Invalid(format!(
                "ACAP decode: features are {} × {}, expected {} × {WIDTH}",
                features.n_elements,
                features.width,
                self.n_vertices()
            )));
        }
        (0..features.n_frames).into_par_iter().map(|f| self.decode_frame(features.frame(f))).collect()
    }
}

/// R = exp(logR) of one vertex from its 9 unscaled ACAP features (layout in the module docs).
pub fn feature_rotation(f: &[f64]) -> Mat3 {
    exp_so3(unskew(&[[0.0, f[0], f[1]], [-f[0], 0.0, f[2]], [-f[1], -f[2], 0.0]]))
}

/// T = exp(logR)·S of one vertex from its 9 unscaled ACAP features (layout in the module docs).
pub fn feature_transform(f: &[f64]) -> Mat3 {
    feature_transform_with(f, &feature_rotation(f))
}

/// [`feature_transform`] with the rotation `r` = [`feature_rotation`]`(f)` already known.
pub fn feature_transform_with(f: &[f64], r: &Mat3) -> Mat3 {
    let s = [[f[3], f[4], f[5]], [f[4], f[6], f[7]], [f[5], f[7], f[8]]];
    mat_mul(r, &s)
}

/// ∂T/∂f_q of [`feature_transform`] for q = 0..9 (rotation part by central differences of
/// Rodrigues' formula, step 1e-6; S part exact).
pub fn feature_transform_jacobian(f: &[f64]) -> [Mat3; 9] {
    const H: f64 = 1e-6;
    let mut out = [[[0.0; 3]; 3]; 9];
    let mut fp = [0.0; 9];
    fp.copy_from_slice(&f[..9]);
    for (q, o) in out.iter_mut().enumerate().take(3) {
        let mut a = fp;
        let mut b = fp;
        a[q] += H;
        b[q] -= H;
        let (ta, tb) = (feature_transform(&a), feature_transform(&b));
        for i in 0..3 {
            for j in 0..3 {
                o[i][j] = (ta[i][j] - tb[i][j]) / (2.0 * H);
            }
        }
    }
    let r = exp_so3(unskew(&[[0.0, f[0], f[1]], [-f[0], 0.0, f[2]], [-f[1], -f[2], 0.0]]));
    // S entries: (q, [(row, col)]) of the symmetric matrix.
    let pos: [&[(usize, usize)]; 6] =
        [&[(0, 0)], &[(0, 1), (1, 0)], &[(0, 2), (2, 0)], &[(1, 1)], &[(1, 2), (2, 1)], &[(2, 2)]];
    for (q, cells) in pos.iter().enumerate() {
        let mut ds = [[0.0; 3]; 3];
        for &(i, j) in cells.iter() {
            ds[i][j] = 1.0;
        }
        out[q + 3] = mat_mul(&r, &ds);
    }
    out
}

/// The vector–Jacobian product of [`feature_transform`]: `⟨A, ∂T/∂f_q⟩` (Frobenius) for
/// q = 0..9, i.e. the gradient with respect to the 9 unscaled features of a loss whose gradient
/// with respect to T is A. Closed form (Gallego & Yezzi 2015 for the rotation:
/// `∂R/∂ω_i = [u_i]×R`, `u_i = (ω_i ω + ω × (I − R)e_i)/‖ω‖²`); below a rotation angle of 1e-4
/// it contracts [`feature_transform_jacobian`] instead.
pub fn feature_transform_vjp(f: &[f64], a: &Mat3) -> [f64; 9] {
    feature_transform_vjp_with(f, &feature_rotation(f), a)
}

/// [`feature_transform_vjp`] with the rotation `r` = [`feature_rotation`]`(f)` already known
/// (the same numbers, one exponential less).
pub fn feature_transform_vjp_with(f: &[f64], r: &Mat3, a: &Mat3) -> [f64; 9] {
    let w = unskew(&[[0.0, f[0], f[1]], [-f[0], 0.0, f[2]], [-f[1], -f[2], 0.0]]);
    let t2 = dot(w, w);
    let mut out = [0.0; 9];
    if t2 < 1e-8 {
        let jac = feature_transform_jacobian(f);
        for (o, jq) in out.iter_mut().zip(&jac) {
            *o = (0..3).map(|r| (0..3).map(|c| a[r][c] * jq[r][c]).sum::<f64>()).sum();
        }
        return out;
    }
    let s = [[f[3], f[4], f[5]], [f[4], f[6], f[7]], [f[5], f[7], f[8]]];
    let rt = transpose(r);
    // Stretch: ⟨A, R·∂S⟩ = ⟨RᵀA, ∂S⟩.
    let b = mat_mul(&rt, a);
    out[3] = b[0][0];
    out[4] = b[0][1] + b[1][0];
    out[5] = b[0][2] + b[2][0];
    out[6] = b[1][1];
    out[7] = b[1][2] + b[2][1];
    out[8] = b[2][2];
    // Rotation: ⟨A, [u]×R·S⟩ = ⟨A·S·Rᵀ, [u]×⟩ = u · vee(W − Wᵀ).
    let wm = mat_mul(&mat_mul(a, &s), &rt);
    let axial = [wm[2][1] - wm[1][2], wm[0][2] - wm[2][0], wm[1][0] - wm[0][1]];
    let mut dw = [0.0; 3];
    for (i, d) in dw.iter_mut().enumerate() {
        let col = [IDENTITY[0][i] - r[0][i], IDENTITY[1][i] - r[1][i], IDENTITY[2][i] - r[2][i]];
        let x = cross(w, col);
        let u: Vec3 = std::array::from_fn(|c| (w[i] * w[c] + x[c]) / t2);
        *d = dot(u, axial);
    }
    // f = (−ω2, ω1, −ω0) (the layout of the module docs).
    out[0] = -dw[2];
    out[1] = dw[1];
    out[2] = -dw[0];
    out
}

fn check_finite(p: &[Vec3], what: &str) -> Result<()> {
    if let Some(v) = p.iter().position(|x| !x.iter().all(|c| c.is_finite())) {
        return Err(Error::Invalid(format!("{what}: vertex {v} has a non-finite position {:?}", p[v])));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed-form vector–Jacobian product agrees with the contracted finite-difference
    /// Jacobian, for rotation angles from 1e-5 (the series fallback) to near π.
    #[test]
    fn feature_transform_vjp_matches_the_jacobian() {
        let mut rng = crate::rng::Rng::new(11);
        for (trial, angle) in [1e-5, 1e-3, 0.3, 1.5, 3.0].into_iter().enumerate() {
            let dir: Vec<f64> = (0..3).map(|_| rng.normal_vec(1, 1.0)[0] as f64).collect();
            let len = dir.iter().map(|d| d * d).sum::<f64>().sqrt();
            let mut f: Vec<f64> = rng.normal_vec(9, 0.2).iter().map(|&v| v as f64).collect();
            for q in 0..3 {
                f[q] = dir[q] / len * angle;
            }
            f[3] += 1.0;
            f[6] += 1.0;
            f[8] += 1.0;
            let a: Mat3 = std::array::from_fn(|_| std::array::from_fn(|_| rng.normal_vec(1, 1.0)[0] as f64));
            let got = feature_transform_vjp(&f, &a);
            let jac = feature_transform_jacobian(&f);
            for q in 0..9 {
                let want: f64 = (0..3).map(|r| (0..3).map(|c| a[r][c] * jac[q][r][c]).sum::<f64>()).sum();
                assert!(
                    (got[q] - want).abs() < 1e-6 * (1.0 + want.abs()),
                    "trial {trial}, q {q}: {} vs {want}",
                    got[q]
                );
            }
        }
    }

    /// A closed octahedron.
    fn octahedron() -> TriMesh {
        let p = vec![
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ];
        let f = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
        TriMesh::new(p, f)
    }

    #[test]
    fn identity_frame_gives_zero_rotation_and_identity_stretch() {
        let m = octahedron();
        let acap = Acap::new(&m).unwrap();
        let f = acap.encode_frame(&m.positions, Consistency::Global).unwrap();
        let feat = f.features();
        for v in feat.chunks_exact(9) {
            let want = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0];
            for k in 0..9 {
                assert!((v[k] - want[k]).abs() < 1e-12, "{v:?}");
            }
        }
        assert_eq!(f.energy, 0.0);
        let back = AcapFrame::from_features(&feat).unwrap();
        assert_eq!(back.features(), feat);
    }

    #[test]
    fn rigid_motion_is_one_rotation_and_round_trips() {
        let m = octahedron();
        let acap = Acap::new(&m).unwrap();
        let r = exp_so3([0.4, 0.2, -0.9]);
        let moved: Vec<Vec3> = m
            .positions
            .iter()
            .map(|p| {
                let q = crate::math::mat3::mat_vec(&r, *p);
                [q[0] + 3.0, q[1] - 1.0, q[2] + 0.5]
            })
            .collect();
        let f = acap.encode_frame(&moved, Consistency::Bfs).unwrap();
        for (l, s) in f.log_r.iter().zip(&f.s) {
            let w = unskew(l);
            for k in 0..3 {
                assert!((w[k] - [0.4, 0.2, -0.9][k]).abs() < 1e-12);
                for c in 0..3 {
                    assert!((s[k][c] - IDENTITY[k][c]).abs() < 1e-12);
                }
            }
        }
        for decoder in [
            AcapDecoder::FitInverse { edge_weight: 1e-6 },
            AcapDecoder::FitInverse { edge_weight: 0.5 },
            AcapDecoder::EdgeLeastSquares,
        ] {
            let acap = Acap::with_options(&m, AcapOptions { decoder, ..Default::default() }).unwrap();
            let back = acap.decode_frame(&f.features()).unwrap();
            // The decoder keeps the reference centroid (origin here).
            for (b, p) in back.iter().zip(&m.positions) {
                let want = crate::math::mat3::mat_vec(&r, *p);
                for k in 0..3 {
                    assert!((b[k] - want[k]).abs() < 1e-9, "{decoder:?}");
                }
            }
        }
    }

    #[test]
    fn fit_weights_keep_exact_round_trips_and_discount_their_vertex() {
        let m = octahedron();
        let moved: Vec<Vec3> =
            m.positions.iter().map(|p| [1.2 * p[0] + 0.1 * p[1], p[1], 0.9 * p[2] - 0.2 * p[0]]).collect();
        let options = AcapOptions { decoder: AcapDecoder::FitInverse { edge_weight: 1e-6 }, ..Default::default() };
        let plain = Acap::with_options(&m, options).unwrap();
        let f = plain.encode_frame(&moved, Consistency::Bfs).unwrap().features();
        let weights = [1e-4, 1.0, 0.3, 1.0, 0.05, 1.0];
        let weighted = Acap::with_fit_weights(&m, options, Some(&weights)).unwrap();
        let centroid = |p: &[Vec3]| -> Vec3 {
            let mut c = [0.0; 3];
            for q in p {
                for k in 0..3 {
                    c[k] += q[k] / p.len() as f64;
                }
            }
            c
        };
        let (cm, cw) = (centroid(&moved), centroid(&m.positions));
        // Exact features decode exactly under any weights (up to the translation).
        for acap in [&plain, &weighted] {
            let back = acap.decode_frame(&f).unwrap();
            for (b, p) in back.iter().zip(&moved) {
                for k in 0..3 {
                    assert!((b[k] - cw[k] - (p[k] - cm[k])).abs() < 1e-6, "{b:?} vs {p:?}");
                }
            }
        }
        // A wrong rotation at one vertex moves the decoding far less where that vertex weighs
        // 1e-4 (on a bumpy, jittered grid: the octahedron's antipodal fans leave motions the fit
        // alone cannot see).
        let mut grid = crate::mesh::primitives::grid(5, 5, 5.0);
        let n = grid.positions.len();
        for (v, p) in grid.positions.iter_mut().enumerate() {
            let j = ((v * 7919) % 13) as f64 / 13.0 - 0.5;
            *p = [p[0] + 0.2 * j, p[1] - 0.15 * j, 0.3 * (0.9 * p[0]).sin() * (0.7 * p[1]).cos() + 0.1 * j];
        }
        let options = AcapOptions { decoder: AcapDecoder::FitInverse { edge_weight: 1e-4 }, ..Default::default() };
        let plain = Acap::with_options(&grid, options).unwrap();
        let centre = 2 * 6 + 2; // vertex (2, 2) of the 6 × 6
        let mut weights = vec![1.0; n];
        weights[centre] = 1e-4;
        let weighted = Acap::with_fit_weights(&grid, options, Some(&weights)).unwrap();
        let f = plain.encode_frame(&grid.positions, Consistency::Bfs).unwrap().features();
        let mut bad = f.clone();
        bad[9 * centre] += 0.8;
        let shift = |acap: &Acap| -> f64 {
            let (a, b) = (acap.decode_frame(&f).unwrap(), acap.decode_frame(&bad).unwrap());
            a.iter().zip(&b).map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).powi(2)).sum::<f64>()).sum::<f64>().sqrt()
        };
        let (sp, sw) = (shift(&plain), shift(&weighted));
        assert!(sp > 1e-2 && sw < 0.1 * sp, "unweighted {sp}, weighted {sw}");
        // Weights are checked.
        for w in [vec![1.0; 5], vec![0.0, 1.0, 1.0, 1.0, 1.0, 1.0], vec![f64::NAN; 6]] {
            assert!(Acap::with_fit_weights(&m, options, Some(&w)).is_err(), "{w:?}");
        }
    }

    /// The gradient map: the rest shape encodes to zero, a frame's features are its 1-ring fits
    /// T − I and decode back to it (up to the translation), and T, its Jacobian (against central
    /// differences) and its vector–Jacobian product agree; the names read back.
    #[test]
    fn the_gradient_map_is_t_minus_i_and_round_trips() {
        let m = octahedron();
        let options = AcapOptions { map: FeatureMap::Gradient, ..Default::default() };
        let acap = Acap::with_options(&m, options).unwrap();
        assert_eq!(acap.map(), FeatureMap::Gradient);
        assert!(acap.encode_values(&m.positions, Consistency::Bfs).unwrap().iter().all(|v| v.abs() < 1e-12));
        let moved: Vec<Vec3> =
            m.positions.iter().map(|p| [1.2 * p[0] + 0.1 * p[1], p[1] - 0.3 * p[2], 0.9 * p[2] - 0.2 * p[0]]).collect();
        let f = acap.encode_values(&moved, Consistency::Bfs).unwrap();
        let t = acap.deformation_gradients(&moved).unwrap();
        for (v, ti) in f.chunks_exact(9).zip(&t) {
            let back = FeatureMap::Gradient.transform(v);
            assert!((0..9).all(|q| (back[q / 3][q % 3] - ti[q / 3][q % 3]).abs() < 1e-12), "{back:?} vs {ti:?}");
        }
        // The same frame's ACAP features are another vector that decodes to the same shape.
        let acap_features = Acap::new(&m).unwrap().encode_values(&moved, Consistency::Bfs).unwrap();
        assert!(acap_features.iter().zip(&f).any(|(a, b)| (a - b).abs() > 0.05));
        let back = acap.decode_frame(&f).unwrap();
        let mean = |p: &[Vec3], k: usize| p.iter().map(|q| q[k]).sum::<f64>() / p.len() as f64;
        for (b, p) in back.iter().zip(&moved) {
            for k in 0..3 {
                let (db, dp) = (b[k] - mean(&back, k), p[k] - mean(&moved, k));
                assert!((db - dp).abs() < 1e-5, "{b:?} vs {p:?}");
            }
        }
        let mut rng = crate::rng::Rng::new(5);
        let v: Vec<f64> = rng.normal_vec(9, 0.3).iter().map(|&x| x as f64).collect();
        let a: Mat3 = std::array::from_fn(|_| std::array::from_fn(|_| rng.normal_vec(1, 1.0)[0] as f64));
        let map = FeatureMap::Gradient;
        let (jac, vjp) = (map.transform_jacobian(&v), map.transform_vjp(&v, &a));
        for q in 0..9 {
            let (mut hi, mut lo) = (v.clone(), v.clone());
            hi[q] += 1e-4;
            lo[q] -= 1e-4;
            let (th, tl) = (map.transform(&hi), map.transform(&lo));
            let mut contracted = 0.0;
            for r in 0..3 {
                for c in 0..3 {
                    assert!(((th[r][c] - tl[r][c]) / 2e-4 - jac[q][r][c]).abs() < 1e-9, "∂T/∂f_{q}");
                    contracted += a[r][c] * jac[q][r][c];
                }
            }
            assert!((vjp[q] - contracted).abs() < 1e-12, "vjp {q}");
        }
        for map in [FeatureMap::RotationStretch, FeatureMap::Gradient] {
            assert_eq!(FeatureMap::parse(map.name()), Some(map));
        }
        assert_eq!(FeatureMap::parse("logr"), None);
    }

    #[test]
    fn decoder_options_are_validated() {
        let m = octahedron();
        let bad = AcapOptions { decoder: AcapDecoder::FitInverse { edge_weight: -1.0 }, ..Default::default() };
        assert!(Acap::with_options(&m, bad).is_err());
        let bad = AcapOptions { decoder: AcapDecoder::FitInverse { edge_weight: f64::NAN }, ..Default::default() };
        assert!(Acap::with_options(&m, bad).is_err());
    }

    #[test]
    fn bad_input_is_an_error() {
        let m = octahedron();
        let acap = Acap::new(&m).unwrap();
        assert!(acap.encode_frame(&m.positions[..5], Consistency::Bfs).is_err());
        let mut p = m.positions.clone();
        p[2][1] = f64::NAN;
        assert!(acap.encode_frame(&p, Consistency::Bfs).is_err());
        assert!(acap.decode_frame(&[0.0; 10]).is_err());
        assert!(AcapFrame::from_features(&[0.0; 10]).is_err());
        let mut bad = m.clone();
        bad.faces.push([0, 1, 9]);
        assert!(Acap::new(&bad).is_err());
    }
}
