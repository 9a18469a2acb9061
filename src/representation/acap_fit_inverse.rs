//! Exact inverse of the ACAP 1-ring fit: positions whose per-vertex deformation gradients,
//! computed the way the encoder computes them, equal given ones (least squares when they are not
//! exactly realisable).
//!
//! The encoder computes, for vertex i with ring rows a_k = s_k (q_j − q_i) (s_k = sqrt(w_ij)),
//! normal row a_n and A_i = Σ a aᵀ (reference only),
//!
//! ```text
//! T_i(p) = ( Σ_k s_k (p_j − p_i) a_kᵀ + β_i(p) a_nᵀ ) A_i⁻¹,
//! ```
//!
//! with β_i(p) the deformed normal row (unit normal × 0.3 × mean 1-ring edge length of p). For a
//! fixed β this is linear in p, and each row c (x, y, z) of T_i involves only coordinate c of
//! p. So, per coordinate c,
//!
//! ```text
//! min_p  Σ_i Σ_m ( Σ_k g_k,m (p_j,c − p_i,c) − (T_i[c][m] − β_i,c h_i,m) )²,
//!        g_k = s_k A_i⁻¹ a_k,  h_i = A_i⁻¹ a_n,
//! ```
//!
//! i.e. the residual is measured in T-space. β_i is not known (it depends on the unknown
//! positions through their normals and edge lengths), but it enters vertex i's residual only
//! along h_i: minimising over β_i too amounts to projecting every residual of vertex i with
//! P_i = I − h_i h_iᵀ/‖h_i‖². The problem becomes linear in p with a matrix that depends on the
//! reference only:
//!
//! ```text
//! min_p  Σ_i Σ_c ‖ Σ_k (P_i g_k)(p_j,c − p_i,c) − P_i T_i[c] ‖²        (T_i[c] = row c of T_i)
//! ```
//!
//! The normal matrix couples 2-ring neighbours; it is factorised once, with one pinned vertex per
//! component and the reference centroid restored afterwards as in [`super::acap_reconstruct`].
//! When the T_i were computed by the encoder from positions x, x (up to translation) has zero
//! residual, so the round trip is exact to rounding. (On a flat 1-ring, h_i is the normal and
//! the removed component of the residual does not depend on p at all, so nothing is lost.)
//!
//! Optional per-vertex weights ω_i multiply vertex i's residual (all ω_i = 1 without them):
//! `min_p Σ_i ω_i Σ_c ‖…‖²`. Features that are not exactly realisable (a network's) are then
//! followed less where they are least reliable; exact features still round trip exactly (a
//! zero residual is zero under any weights).
//!
//! Some meshes leave motions the fit cannot see: symmetric 1-ring fans, e.g. the 3-colouring
//! patterns of a regular triangle grid or the antipodal pairs of an octahedron, whose fitted
//! gradients vanish. The optional edge term (weight μ, see
//! [`super::acap::AcapDecoder::FitInverse`]) keeps the system definite and resolves them.

#![allow(clippy::needless_range_loop)] // index loops over 3-vectors read like the formulas

use crate::math::mat3::{Mat3, mat_vec};
use crate::math::vec3::{dot, normalize, sub};
use crate::mesh::Vec3;
use crate::representation::acap_reconstruct::{PinnedSystem, edge_term_adjoint};
use crate::{Error, Result};

/// The encoder's 1-ring fit data (reference only): rings in CSR form (`ring[ring_offsets[i]..
/// ring_offsets[i+1]]`), per ring entry the row scale s_k = sqrt(w_ij) and reference row a_k,
/// per vertex the reference normal row a_n and A_i⁻¹.
#[derive(Debug, Clone, Copy)]
pub struct RingFit<'a> {
    pub ring_offsets: &'a [usize],
    pub ring: &'a [usize],
    pub row_scale: &'a [f64],
    pub ref_rows: &'a [Vec3],
    pub ref_normal_rows: &'a [Vec3],
    pub inv_ata: &'a [Mat3],
}

/// The optional edge least-squares term: reference positions, undirected edges and their
/// weights, already multiplied by the term's overall weight.
#[derive(Debug)]
struct EdgeTerm {
    rest: Vec<Vec3>,
    edges: Vec<[usize; 2]>,
    weights: Vec<f64>,
}

/// Factorised inverse of the 1-ring fit for one reference mesh.
#[derive(Debug)]
pub struct FitInverse {
    ring_offsets: Vec<usize>,
    ring: Vec<usize>,
    /// Per ring entry: P_i g_k, g_k = s_k A_i⁻¹ a_k.
    g: Vec<Vec3>,
    /// Per vertex: Σ_k P_i g_k (the coefficient of p_i, negated).
    g_sum: Vec<Vec3>,
    /// Per vertex: h_i/‖h_i‖ with h_i = A_i⁻¹ a_n (zero when h_i = 0).
    h: Vec<Vec3>,
    system: PinnedSystem,
    edge_term: Option<EdgeTerm>,
    /// Per vertex: √ω_i (all 1 without weights).
    root_weights: Vec<f64>,
}

impl FitInverse {
    /// Precomputes and factorises for reference positions `rest` (N), undirected `edges`
    /// (defining the components) and the encoder's fit data. `edge_term = Some((c, μ))` adds
    /// μ × the edge least squares Σ c_ij ‖(p_i − p_j) − ½(T_i + T_j)(q_i − q_j)‖² (c per edge,
    /// μ ≥ 0; μ = 0 or `None` leaves it out). `vertex_weights` (N, each finite and > 0) weights
    /// every vertex's residual (module docs; `None`: all 1).
    pub fn new(
        rest: &[Vec3],
        edges: &[[usize; 2]],
        fit: RingFit<'_>,
        edge_term: Option<(&[f64], f64)>,
        vertex_weights: Option<&[f64]>,
    ) -> Result<Self> {
        let RingFit { ring_offsets, ring, row_scale, ref_rows, ref_normal_rows, inv_ata } = fit;
        let n = rest.len();
        if ring_offsets.len() != n + 1 || ring.len() != row_scale.len() || ring.len() != ref_rows.len() {
            return Err(Error::Invalid("fit inverse: inconsistent ring arrays".into()));
        }
        let root_weights: Vec<f64> = match vertex_weights {
            None => vec![1.0; n],
            Some(w) => {
                if w.len() != n {
                    return Err(Error::Invalid(format!("fit inverse: {} vertex weights for {n} vertices", w.len())));
                }
                if let Some(i) = w.iter().position(|x| !(x.is_finite() && *x > 0.0)) {
                    return Err(Error::Invalid(format!("fit inverse: vertex {i}'s weight {} is not positive", w[i])));
                }
                w.iter().map(|x| x.sqrt()).collect()
            }
        };
        let mut g = Vec::with_capacity(ring.len());
        let mut g_sum = Vec::with_capacity(n);
        let mut h = Vec::with_capacity(n);
        for i in 0..n {
            let hi = mat_vec(&inv_ata[i], ref_normal_rows[i]);
            let u = normalize(hi);
            let mut sum = [0.0; 3];
            // √ω_i is folded into vertex i's rows here and into its targets in `rhs`.
            let wi = root_weights[i];
            for k in ring_offsets[i]..ring_offsets[i + 1] {
                let ai = mat_vec(&inv_ata[i], ref_rows[k]);
                let s = wi * row_scale[k];
                let gk = project(u, [s * ai[0], s * ai[1], s * ai[2]]);
                for m in 0..3 {
                    sum[m] += gk[m];
                }
                g.push(gk);
            }
            g_sum.push(sum);
            h.push(u);
        }
        // Normal matrix Σ_{i,m} r_{i,m} r_{i,m}ᵀ, r_{i,m} = Σ_k g_k,m (e_j − e_i).
        let entries = (0..n).flat_map(|i| {
            let (s, e) = (ring_offsets[i], ring_offsets[i + 1]);
            let (g, g_sum) = (&g, &g_sum);
            let coef = move |t: usize, m: usize| -> (usize, f64) {
                if t == 0 { (i, -g_sum[i][m]) } else { (ring[s + t - 1], g[s + t - 1][m]) }
            };
            let d = e - s + 1;
            (0..3).flat_map(move |m| {
                (0..d).flat_map(move |a| {
                    (0..d).map(move |b| {
                        let (va, ca) = coef(a, m);
                        let (vb, cb) = coef(b, m);
                        (va, vb, ca * cb)
                    })
                })
            })
        });
        let edge_term = match edge_term {
            Some((w, mu)) if mu > 0.0 => {
                if w.len() != edges.len() {
                    return Err(Error::Invalid("fit inverse: edge weights do not match edges".into()));
                }
                Some(EdgeTerm {
                    rest: rest.to_vec(),
                    edges: edges.to_vec(),
                    weights: w.iter().map(|c| c * mu).collect(),
                })
            }
            _ => None,
        };
        let laplacian = edge_term.iter().flat_map(|t| {
            t.edges.iter().zip(&t.weights).flat_map(|(&[i, j], &c)| [(i, i, c), (j, j, c), (i, j, -c), (j, i, -c)])
        });
        let system = PinnedSystem::new(rest, edges, entries.chain(laplacian), "ACAP fit inverse")?;
        Ok(FitInverse {
            ring_offsets: ring_offsets.to_vec(),
            ring: ring.to_vec(),
            g,
            g_sum,
            h,
            system,
            edge_term,
            root_weights,
        })
    }

    /// Positions (N) whose encoder gradients best match `transforms` (N), centred on the
    /// reference centroid.
    pub fn solve(&self, transforms: &[Mat3]) -> Result<Vec<Vec3>> {
        self.system.solve_from(|rhs| self.rhs(transforms, rhs))
    }

    /// The linear part of [`Self::solve`] for several sets of transforms at once (one solve with
    /// 3 right-hand sides per set), each up to a translation per component.
    pub fn solve_linear_many(&self, sets: &[Vec<Mat3>]) -> Result<Vec<Vec<Vec3>>> {
        self.system.solve_linear_sets(sets, |t, rhs| self.rhs(t, rhs))
    }

    /// The right-hand side (3 × reduced rows, column-major, added to `rhs`) of `transforms`.
    fn rhs(&self, transforms: &[Mat3], rhs: &mut [f64]) -> Result<()> {
        let n = self.g_sum.len();
        if transforms.len() != n {
            return Err(Error::Invalid(format!("fit inverse: {} transforms for {n} vertices", transforms.len())));
        }
        let mrows = self.system.n_reduced();
        for i in 0..n {
            let (s, e) = (self.ring_offsets[i], self.ring_offsets[i + 1]);
            if s == e {
                continue;
            }
            let wi = self.root_weights[i];
            for c in 0..3 {
                // y = √ω_i P_i T_i[c]
                let t = transforms[i][c];
                let y = project(self.h[i], [wi * t[0], wi * t[1], wi * t[2]]);
                let col = &mut rhs[c * mrows..(c + 1) * mrows];
                let ri = self.system.row(i);
                if ri != usize::MAX {
                    col[ri] -= dot(self.g_sum[i], y);
                }
                for k in s..e {
                    let rj = self.system.row(self.ring[k]);
                    if rj != usize::MAX {
                        let gk = self.g[k];
                        col[rj] += dot(gk, y);
                    }
                }
            }
        }
        if let Some(EdgeTerm { rest, edges, weights }) = &self.edge_term {
            for (&[i, j], &c) in edges.iter().zip(weights) {
                let (ti, tj) = (&transforms[i], &transforms[j]);
                let e = sub(rest[i], rest[j]);
                let (ri, rj) = (self.system.row(i), self.system.row(j));
                for k in 0..3 {
                    let d = 0.5
                        * c
                        * ((ti[k][0] + tj[k][0]) * e[0] + (ti[k][1] + tj[k][1]) * e[1] + (ti[k][2] + tj[k][2]) * e[2]);
                    if ri != usize::MAX {
                        rhs[k * mrows + ri] += d;
                    }
                    if rj != usize::MAX {
                        rhs[k * mrows + rj] -= d;
                    }
                }
            }
        }
        Ok(())
    }
}

impl FitInverse {
    /// Adjoint of [`FitInverse::solve`] (affine in the transforms): for a gradient `grad`
    /// (N × 3) with respect to the positions, the gradient with respect to every transform
    /// (N, row-major 3×3). One solve with the same factor.
    pub fn solve_adjoint(&self, grad: &[Vec3]) -> Result<Vec<Mat3>> {
        let n = self.g_sum.len();
        if grad.len() != n {
            return Err(Error::Invalid(format!("fit inverse adjoint: {} gradients for {n} vertices", grad.len())));
        }
        let lam = self.system.solve_adjoint(grad)?;
        let mrows = self.system.n_reduced();
        let at = |c: usize, v: usize| {
            let r = self.system.row(v);
            if r == usize::MAX { 0.0 } else { lam[c * mrows + r] }
        };
        let mut out = vec![[[0.0; 3]; 3]; n];
        for i in 0..n {
            let (s, e) = (self.ring_offsets[i], self.ring_offsets[i + 1]);
            if s == e {
                continue;
            }
            let wi = self.root_weights[i];
            for c in 0..3 {
                let li = at(c, i);
                let mut y = [-self.g_sum[i][0] * li, -self.g_sum[i][1] * li, -self.g_sum[i][2] * li];
                for k in s..e {
                    let lj = at(c, self.ring[k]);
                    for m in 0..3 {
                        y[m] += self.g[k][m] * lj;
                    }
                }
                out[i][c] = project(self.h[i], [wi * y[0], wi * y[1], wi * y[2]]);
            }
        }
        if let Some(EdgeTerm { rest, edges, weights }) = &self.edge_term {
            edge_term_adjoint(rest, edges, weights, &self.system, &lam, &mut out);
        }
        Ok(out)
    }
}

/// (I − u uᵀ) v for a unit (or zero) u.
#[inline]
fn project(u: Vec3, v: Vec3) -> Vec3 {
    let d = dot(u, v);
    [v[0] - d * u[0], v[1] - d * u[1], v[2] - d * u[2]]
}
