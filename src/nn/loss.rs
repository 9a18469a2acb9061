//! The training loss: reconstruction + λ1·(geodesic-weighted ℓ2,1 of C) + λ2·(hinge on Z).
//!
//! ```text
//! L = (1/B) Σ_b ‖X̂_b − X_b‖²                                   (reconstruction)
//!   + λ1 · (1/K) Σ_k Σ_i Λ_ik ‖C_k,i‖₂                          (sparsity, C_k,i ∈ R⁹)
//!   + λ2 · (1/K) Σ_k max(max_m |Z_km| − θ, 0)                   (hinge, m over the batch)
//! ```
//! `Λ_ik` ramps from 0 (normalised geodesic distance to the centre `c_k` below `d_min`) to 1
//! (above `d_max`), with `c_k = argmax_i ‖C_k,i‖` recomputed every step and treated as a
//! constant (no gradient through it). The norm is ε-guarded: `‖v‖_ε = sqrt(max(‖v‖², ε²))`, with
//! sub-gradient 0 where `‖v‖ ≤ ε`.

use std::collections::HashMap;
use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::config::AutoencoderConfig;
use super::kernels;
use super::model::{AutoencoderModule, NeighborTensors};
use super::neighbors::NeighborIndex;
use crate::error::{Error, Result};

/// ε of the guarded norm `sqrt(max(‖v‖², ε²))`.
pub const NORM_EPS: f32 = 1e-8;
/// Lower bound of `‖C_k‖²` in the decorrelation term's denominators.
pub const ORTHO_EPS: f32 = 1e-12;

/// Distances on the rest mesh from one centre vertex, normalised by the largest pairwise
/// geodesic distance (so that the ramp `[d_min, d_max]` is scale-free).
///
/// Implementations may cache; the trainer asks only for centres whose rows it does not hold
/// (several at a time, in parallel, hence `Sync`).
pub trait CenterDistances: Sync {
    /// Normalised distance of every vertex to `center` (N values, `0` at the centre). Non-finite
    /// values (unreachable vertices) are treated as "far" (Λ = 1).
    fn distances(&self, center: usize) -> Vec<f64>;
}

/// Hop distances on the neighbour graph (BFS), divided by the graph's diameter estimated with a
/// double sweep (farthest vertex from the farthest vertex of vertex 0). For tests and synthetic
/// data; the command line uses heat-method geodesics.
#[derive(Debug, Clone)]
pub struct HopDistances {
    rings: Vec<Vec<usize>>,
    scale: f64,
}

impl HopDistances {
    /// Builds the BFS helper from the neighbour index.
    pub fn new(nb: &NeighborIndex) -> Self {
        let rings: Vec<Vec<usize>> =
            (0..nb.n_vertices()).map(|i| nb.neighbors(i).iter().map(|&j| j as usize).collect()).collect();
        let mut h = HopDistances { rings, scale: 1.0 };
        let d0 = h.hops(0);
        let far = argmax_finite(&d0);
        let d1 = h.hops(far);
        let diam = d1.iter().copied().filter(|d| d.is_finite()).fold(0.0, f64::max);
        h.scale = if diam > 0.0 { diam } else { 1.0 };
        h
    }

    fn hops(&self, s: usize) -> Vec<f64> {
        let mut d = vec![f64::INFINITY; self.rings.len()];
        let mut q = std::collections::VecDeque::new();
        d[s] = 0.0;
        q.push_back(s);
        while let Some(u) = q.pop_front() {
            for &v in &self.rings[u] {
                if d[v].is_infinite() {
                    d[v] = d[u] + 1.0;
                    q.push_back(v);
                }
            }
        }
        d
    }
}

impl CenterDistances for HopDistances {
    fn distances(&self, center: usize) -> Vec<f64> {
        self.hops(center).into_iter().map(|d| d / self.scale).collect()
    }
}

/// Euclidean distances between rest positions, divided by the largest pairwise distance
/// (exact, O(N²) once). For tests and small synthetic meshes.
#[derive(Debug, Clone)]
pub struct EuclideanDistances {
    positions: Vec<[f64; 3]>,
    scale: f64,
}

impl EuclideanDistances {
    /// From rest positions.
    pub fn new(positions: &[[f64; 3]]) -> Self {
        let mut m: f64 = 0.0;
        for (i, a) in positions.iter().enumerate() {
            for b in &positions[i + 1..] {
                m = m.max(crate::mesh::dist(*a, *b));
            }
        }
        EuclideanDistances { positions: positions.to_vec(), scale: if m > 0.0 { m } else { 1.0 } }
    }
}

impl CenterDistances for EuclideanDistances {
    fn distances(&self, center: usize) -> Vec<f64> {
        let c = self.positions[center];
        self.positions.iter().map(|&p| crate::mesh::dist(p, c) / self.scale).collect()
    }
}

fn argmax_finite(v: &[f64]) -> usize {
    let mut best = 0;
    for (i, &x) in v.iter().enumerate() {
        if x.is_finite() && (!v[best].is_finite() || x > v[best]) {
            best = i;
        }
    }
    best
}

/// The loss terms of one step (unweighted terms and the weighted total).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LossTerms {
    /// `L = reconstruction + λ1·sparsity + λ2·hinge`.
    pub total: f64,
    /// `(1/B) Σ_b ‖X̂_b − X_b‖²`.
    pub reconstruction: f64,
    /// `(1/K) Σ_k Σ_i Λ_ik ‖C_k,i‖`.
    pub sparsity: f64,
    /// `(1/K) Σ_k max(max_m |Z_km| − θ, 0)`.
    pub hinge: f64,
    /// `(1/K) Σ_{k≠l} (C_k·C_l)² / (‖C_k‖² ‖C_l‖²)` (computed only when `lambda_orthogonal > 0`).
    #[serde(default)]
    pub orthogonality: f64,
    /// `(1/B) Σ_b Σ_i ‖p_i(X̂_b) − p_i(X_b)‖² / d²`: the decoded and the input features'
    /// reconstructed vertices p, d the rest bounding-box diagonal (computed only when
    /// `lambda_vertex > 0`).
    #[serde(default)]
    pub vertex: f64,
    /// `(1/B) Σ_b Σ_k |z_bk − z_rest,k|` over the lanes but the rest shape's (computed only when
    /// `lambda_code > 0`).
    #[serde(default)]
    pub code: f64,
}

impl LossTerms {
    /// Whether every term is finite.
    pub fn is_finite(&self) -> bool {
        self.total.is_finite()
            && self.reconstruction.is_finite()
            && self.sparsity.is_finite()
            && self.hinge.is_finite()
            && self.orthogonality.is_finite()
            && self.vertex.is_finite()
            && self.code.is_finite()
    }
}

/// The centres of a support-map update and the distance rows it needs (see
/// [`SupportMaps::plan_update`]).
#[derive(Debug, Clone)]
pub struct CentreUpdate {
    centers: Vec<usize>,
    missing: Vec<usize>,
}

impl CentreUpdate {
    /// Centres whose rows must be queried.
    pub fn missing(&self) -> &[usize] {
        &self.missing
    }
}

/// Per-component centres and support weights Λ (`K × N`), refreshed from the current `C`.
///
/// Λ rows are kept per centre vertex: components with the same centre share one row, and the rows
/// of recent centres stay cached (at most [`Self::cache_rows`] rows), so a centre that comes back
/// costs no distance query.
#[derive(Debug, Clone)]
pub struct SupportMaps {
    k: usize,
    n: usize,
    centers: Vec<usize>,
    weights: Vec<Arc<[f32]>>,
    valid: Vec<bool>,
    /// `‖C_k,i‖²` of the `C` of the last update, `[K, N]`.
    sq_norms: Vec<f32>,
    /// Λ rows by centre vertex, with the update count at which each was last used.
    cache: HashMap<usize, (Arc<[f32]>, u64)>,
    updates: u64,
    queries: u64,
}

impl SupportMaps {
    /// Empty maps for `k` components on `n` vertices.
    pub fn new(k: usize, n: usize) -> Self {
        SupportMaps {
            k,
            n,
            centers: vec![0; k],
            weights: vec![Arc::from(Vec::new()); k],
            valid: vec![false; k],
            sq_norms: vec![0.0; k * n],
            cache: HashMap::new(),
            updates: 0,
            queries: 0,
        }
    }

    /// Most Λ rows kept (those of the current centres and of recent ones): `2K`.
    pub fn cache_rows(&self) -> usize {
        2 * self.k
    }

    /// Distance rows asked of the [`CenterDistances`] so far.
    pub fn distance_queries(&self) -> u64 {
        self.queries
    }

    /// Current centres `c_k` (valid after [`Self::update`]).
    pub fn centers(&self) -> &[usize] {
        &self.centers
    }

    /// Λ row of component `k` (N values).
    pub fn weights(&self, k: usize) -> &[f32] {
        &self.weights[k]
    }

    /// `‖C_k,i‖²` of the last update, `[K, N]` (see [`Self::update_from_norms`]).
    pub fn sq_norms(&self) -> &[f32] {
        &self.sq_norms
    }

    /// The squared vertex norms (mutable) and the Λ rows, for an update of `C` that writes the
    /// norms of the new `C` while it reads Λ.
    pub fn norms_and_weights(&mut self) -> (&mut [f32], Vec<&[f32]>) {
        (&mut self.sq_norms, self.weights.iter().map(|w| &w[..]).collect())
    }

    /// The squared vertex norms to fill before [`Self::update_from_norms`] (`[K, N]`).
    pub fn sq_norms_mut(&mut self) -> &mut [f32] {
        &mut self.sq_norms
    }

    /// Recomputes the centres from `c` (`[K, 9N]`, vertex-major) and asks `dist` for the rows of
    /// the centres that changed.
    pub fn update(&mut self, c: &[f32], cfg: &AutoencoderConfig, dist: &dyn CenterDistances) -> Result<()> {
        self.set_norms_from(c);
        self.update_from_norms(cfg, dist)
    }

    /// Like [`Self::update`], with the squared vertex norms of the current `C` already in
    /// [`Self::sq_norms_mut`] (the trainer's fused update writes them).
    pub fn update_from_norms(&mut self, cfg: &AutoencoderConfig, dist: &dyn CenterDistances) -> Result<()> {
        let plan = self.plan_update();
        let rows = Self::query_rows(&plan, self.n, cfg, dist);
        self.apply_update(plan, rows)
    }

    /// First part of [`Self::update_from_norms`]: the centres of the current norms and the
    /// distance rows to ask for (neither held nor cached).
    pub fn plan_update(&self) -> CentreUpdate {
        let n = self.n;
        let centers: Vec<usize> = self
            .sq_norms
            .par_chunks(n.max(1))
            .map(|sq| {
                let mut best = (0usize, -1.0f32);
                for (i, &s) in sq.iter().enumerate() {
                    if s > best.1 {
                        best = (i, s);
                    }
                }
                best.0
            })
            .collect();
        let mut missing: Vec<usize> = centers
            .iter()
            .enumerate()
            .filter(|&(k, &c)| !((self.valid[k] && self.centers[k] == c) || self.cache.contains_key(&c)))
            .map(|(_, &c)| c)
            .collect();
        missing.sort_unstable();
        missing.dedup();
        CentreUpdate { centers, missing }
    }

    /// Second part of [`Self::update_from_norms`]: the Λ rows of `plan`'s missing centres, from
    /// distance queries in parallel (`n` vertices). Touches no map, so it may run beside other
    /// work.
    pub fn query_rows(
        plan: &CentreUpdate,
        n: usize,
        cfg: &AutoencoderConfig,
        dist: &dyn CenterDistances,
    ) -> Vec<Result<Arc<[f32]>>> {
        plan.missing
            .par_iter()
            .map(|&center| {
                let d = dist.distances(center);
                if d.len() != n {
                    return Err(Error::Invalid(format!(
                        "centre distances: expected {n} values for centre {center}, got {}",
                        d.len()
                    )));
                }
                Ok(d.iter().map(|&d| cfg.support_weight(d) as f32).collect::<Vec<f32>>().into())
            })
            .collect()
    }

    /// Last part of [`Self::update_from_norms`]: installs the rows of [`Self::query_rows`] and
    /// the new centres.
    pub fn apply_update(&mut self, plan: CentreUpdate, rows: Vec<Result<Arc<[f32]>>>) -> Result<()> {
        self.updates += 1;
        self.queries += plan.missing.len() as u64;
        for (&center, row) in plan.missing.iter().zip(rows) {
            self.cache.insert(center, (row?, self.updates));
        }
        for (k, &center) in plan.centers.iter().enumerate() {
            let entry = self.cache.entry(center).or_insert_with(|| (self.weights[k].clone(), 0));
            entry.1 = self.updates;
            if !(self.valid[k] && self.centers[k] == center) {
                self.weights[k] = entry.0.clone();
                self.centers[k] = center;
                self.valid[k] = true;
            }
        }
        // Forget the least recently used rows beyond the cache size.
        let cap = self.cache_rows();
        if self.cache.len() > cap {
            let mut old: Vec<(u64, usize)> =
                self.cache.iter().filter(|(_, e)| e.1 < self.updates).map(|(&c, e)| (e.1, c)).collect();
            old.sort_unstable();
            let excess = self.cache.len() - cap;
            for (_, c) in old.into_iter().take(excess) {
                self.cache.remove(&c);
            }
        }
        Ok(())
    }

    /// Vertices N.
    pub fn n_vertices(&self) -> usize {
        self.n
    }

    /// Computes the squared vertex norms of `c` (`[K, 9N]`) into the maps, for
    /// [`Self::plan_update`].
    pub fn set_norms_from(&mut self, c: &[f32]) {
        let n = self.n;
        c.par_chunks(9 * n.max(1))
            .zip(self.sq_norms.par_chunks_mut(n.max(1)))
            .for_each(|(row, sq)| kernels::vertex_sq_norms(row, sq));
    }

    /// Λ as a `[K, N]` tensor (for the Burn reference loss).
    pub fn to_tensor(&self, device: &Device) -> Tensor<2> {
        let flat: Vec<f32> = self.weights.iter().flat_map(|w| w.iter().copied()).collect();
        Tensor::from_data(TensorData::new(flat, [self.k, self.n]), device)
    }
}

/// Sparsity term `(1/K) Σ_k Σ_i Λ_ik ‖C_k,i‖_ε` and its gradient: adds `scale·Λ_ik·C_k,i/‖C_k,i‖`
/// to `grad` (zero where `‖C_k,i‖ ≤ ε`). Returns the unweighted term. `maps` must have been
/// updated with this same `c` (its squared norms are reused).
///
/// # Shapes
/// `c`, `grad`: `[K, 9N]` row-major, vertex-major columns.
pub fn sparsity_with_grad(c: &[f32], maps: &SupportMaps, scale: f32, grad: &mut [f32]) -> f64 {
    let n = maps.n;
    let k = maps.k;
    let sums: Vec<f64> = grad
        .par_chunks_mut(9 * n)
        .zip(c.par_chunks(9 * n))
        .zip(maps.sq_norms.par_chunks(n))
        .enumerate()
        .map(|(kk, ((g, row), sq))| kernels::group_sparsity(row, sq, &maps.weights[kk], NORM_EPS * NORM_EPS, scale, g))
        .collect();
    sums.iter().sum::<f64>() / k as f64
}

/// [`sparsity_with_grad`], and whether every entry of the updated `grad` is finite (checked in
/// the same pass).
pub fn sparsity_with_grad_checked(c: &[f32], maps: &SupportMaps, scale: f32, grad: &mut [f32]) -> (f64, bool) {
    let n = maps.n;
    let k = maps.k;
    let parts: Vec<(f64, u32)> = grad
        .par_chunks_mut(9 * n)
        .zip(c.par_chunks(9 * n))
        .zip(maps.sq_norms.par_chunks(n))
        .enumerate()
        .map(|(kk, ((g, row), sq))| {
            kernels::group_sparsity_checked(row, sq, &maps.weights[kk], NORM_EPS * NORM_EPS, scale, g)
        })
        .collect();
    let sum = parts.iter().map(|p| p.0).sum::<f64>() / k as f64;
    (sum, parts.iter().all(|p| p.1 != kernels::NON_FINITE_EXPONENT))
}

/// The same loss as a Burn graph (reference for the gradient check; small problems only).
/// Λ comes from `maps` (already updated for the module's current `C`).
///
/// `vertex_w` weights each vertex's feature error (`feature_weights`; none: every vertex 1).
///
/// # Shapes
/// - `x`: `[B, N, 9]`
/// - `vertex_w`: `[N]`
/// - output: (`L` `[1]`, the terms as numbers)
pub fn reference_loss(
    module: &AutoencoderModule,
    x: Tensor<3>,
    nb: &NeighborTensors,
    maps: &SupportMaps,
    cfg: &AutoencoderConfig,
    vertex_w: Option<&[f32]>,
) -> (Tensor<1>, LossTerms) {
    let device = x.device();
    let [b, n, _] = x.dims();
    let (xh, z) = module.forward(x.clone(), nb);
    let sq = (xh - x).square();
    let sq = match vertex_w {
        Some(w) => sq * Tensor::<1>::from_data(TensorData::new(w.to_vec(), [n]), &device).reshape([1, n, 1]),
        None => sq,
    };
    let recon = sq.sum().div_scalar(b as f32);
    let [k, _] = module.components_shape();
    let c = module.components_tensor().reshape([k, n, 9]);
    let norms = c.square().sum_dim(2).reshape([k, n]).clamp_min(NORM_EPS * NORM_EPS).sqrt();
    let sparsity = (norms * maps.to_tensor(&device)).sum().div_scalar(k as f32);
    let hinge = z.clone().abs().max_dim(0).sub_scalar(cfg.theta as f32).clamp_min(0.0).sum().div_scalar(k as f32);
    let mut total =
        recon.clone() + sparsity.clone().mul_scalar(cfg.lambda1 as f32) + hinge.clone().mul_scalar(cfg.lambda2 as f32);
    // The code term: the last lane is the rest shape ([`AutoencoderConfig::lambda_code`]).
    let mut code = None;
    if cfg.lambda_code > 0.0 && b > 1 {
        let others = z.clone().slice([0..b - 1, 0..k]);
        let rest = z.slice([b - 1..b, 0..k]);
        let c = (others - rest).abs().sum().div_scalar((b - 1) as f32);
        total = total + c.clone().mul_scalar(cfg.lambda_code as f32);
        code = Some(c);
    }
    let mut orthogonality = None;
    if cfg.lambda_orthogonal > 0.0 {
        let c2 = module.components_tensor();
        let g = c2.clone().matmul(c2.transpose());
        let off_mask: Vec<f32> = (0..k * k).map(|i| if i / k == i % k { 0.0 } else { 1.0 }).collect();
        let off_mask = Tensor::<2>::from_data(TensorData::new(off_mask, [k, k]), &device);
        let eye_mask = off_mask.clone().neg().add_scalar(1.0);
        let d = (g.clone() * eye_mask).sum_dim(1).clamp_min(ORTHO_EPS); // [K, 1]
        let dd = d.clone().matmul(d.transpose()); // [K, K]: G_kk G_ll
        let o = (g.square() / dd * off_mask).sum().div_scalar(k as f32);
        total = total + o.clone().mul_scalar(cfg.lambda_orthogonal as f32);
        orthogonality = Some(o);
    }
    let scalar =
        |t: Tensor<1>| -> f64 { t.into_data().try_into_vec_as::<f32>().map(|v| v[0] as f64).unwrap_or(f64::NAN) };
    let terms = LossTerms {
        total: scalar(total.clone().detach()),
        reconstruction: scalar(recon.detach()),
        sparsity: scalar(sparsity.detach()),
        hinge: scalar(hinge.detach()),
        orthogonality: orthogonality.map(|o| scalar(o.detach())).unwrap_or(0.0),
        vertex: 0.0,
        code: code.map(|c| scalar(c.detach())).unwrap_or(0.0),
    };
    (total, terms)
}
