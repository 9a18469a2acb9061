//! SPLOCS — sparse localized deformation components (Neumann et al. 2013), one engine for any
//! group width (W = 3 vertex displacements; W = 9 triangle deformation gradients as in Huang
//! et al. 2014, §3.3).
//!
//! Model: X ≈ W·C with X the F × E·W data matrix, C the K × E·W components and W the F × K
//! weights, minimising ‖X − W·C‖²_F + Ω(C), Ω(C) = Σ_k Σ_e Λ_k,e ‖C_k,e‖₂ (group ℓ1/ℓ2 over the W
//! numbers of an element), Λ_k,e = λ·ramp(d_k,e) (see [`super::support_map`]), subject to the
//! weight constraint (Eq. 3 `signed` or Eq. 4 `nonnegative`).
//!
//! Algorithm (paper §3.4 and the facts of the Python reference implementation):
//! 1. X is divided by its standard deviation s (all entries, population std around the mean of
//!    all entries, like `numpy.std`); C is multiplied by s at the end, W is unchanged.
//! 2. Deflation initialisation: for each k, the element with the largest residual norm
//!    Σ_f ‖R_f,e‖² (or the user's painted set for the first components) is the centre; the
//!    weights are the first left singular vector of the centre's residual block times its
//!    singular value, projected onto the constraint set (the sign giving the larger projected
//!    norm is kept); the component is the least-squares fit to the residual masked by
//!    1 − ramp, C_k = (1 − ramp) ⊙ (w_kᵀR)/(w_kᵀw_k); R ← R − w_k C_k.
//! 3. Each outer iteration: (a) one block-coordinate-descent sweep over the weights with
//!    projection (evaluated in component space through X·Cᵀ and C·Cᵀ, identical to the
//!    residual form); (b) centres = argmax of each component's group norm (kept when the user
//!    fixed them, kept when the component is all zero) and support maps Λ for them; (c) ADMM
//!    on C with the scaled dual U kept across outer iterations and Z initialised to C:
//!    C ← (WᵀW + ρI)⁻¹(WᵀX + ρ(Z − U)), Z ← prox_{Λ/ρ}(C + U), U ← U + C − Z, with
//!    WᵀW + ρI factorised once (Cholesky, applied as its dense K × K inverse) per outer
//!    iteration; afterwards C ← Z.
//!
//!    Like the reference, the C-step solves the normal equations without a factor 2, so the
//!    ADMM minimises ½‖X − WC‖² + Ω(C); the objective reported (as the reference prints it)
//!    is ‖X − WC‖²_F + Ω(C) in standardised units, with the Λ of the iteration.
//! 4. Convergence (paper §3.4): with E_0 the objective after initialisation and E_i after
//!    outer iteration i, stop after iteration i ≥ 5 when
//!    mean_{j=i−4..i} |E_j − E_{j−1}| ≤ `tolerance` · |E_i| (a relative threshold), or when
//!    `max_iterations` is reached. `tolerance = 0` disables the test (the reference has none).
//!
//! Cost per outer iteration: 2·(ADMM iterations + 1)·K²·E·W + 4·F·K·E·W flops of dense
//! products (faer) plus O(K·E·W) per ADMM iteration. The component update is independent
//! across columns (elements), so it runs block by block (about 240 columns, all ADMM
//! iterations of a block while it sits in cache, X·Cᵀ and C·Cᵀ accumulated on the way), the
//! blocks optionally on several threads. Support maps are computed only for centre sets not
//! seen before (a cache keyed by centre set), never as an E × E matrix.

use faer::linalg::matmul::matmul;
use faer::linalg::solvers::DenseSolveCore;
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};
use serde::{Deserialize, Serialize};

use super::splocs_admm::{AdmmAcc, AdmmShared, Blocks, admm_block, project_weights, update_weights};
use super::support_map::{ComponentLocality, SupportCache, SupportDistances, component_locality};
use super::{DataRef, LinearModel, WeightConstraint};
use crate::{Error, Result};

/// ADMM settings of the component update.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdmmConfig {
    /// Penalty ρ (> 0). Default 10 (paper and reference).
    pub rho: f64,
    /// ADMM iterations per outer iteration (≥ 1). Default 10.
    pub iterations: usize,
}

impl Default for AdmmConfig {
    fn default() -> Self {
        AdmmConfig { rho: 10.0, iterations: 10 }
    }
}

/// SPLOCS hyperparameters; defaults are the reference implementation's. Validated once by
/// [`SplocsConfig::validate`] (and against the data by [`SplocsSolver::new`]); errors name the
/// key and the bad value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SplocsConfig {
    /// Number of components K (≥ 1). Default 50.
    pub components: usize,
    /// Sparsity λ of Eq. (6) (≥ 0). Default 2.
    pub sparsity: f64,
    /// Support range [d_min, d_max] in the distance provider's units (unit-box geodesics for
    /// the reference setting), 0 ≤ d_min < d_max. Default [0.1, 0.7].
    pub support: [f64; 2],
    /// Weight constraint: `nonnegative` (Eq. 4, default) or `signed` (Eq. 3).
    pub weights: WeightConstraint,
    /// Sparse weights: each weight update soft-thresholds every component's weights by this
    /// share of their largest magnitude before the constraint's projection
    /// ([`super::splocs_admm::shrink_relative`]), so a component is active only in the frames
    /// where it carries a clear share of its peak (in [0, 1); default 0, the reference: none).
    /// Data made of a few deformations per frame then splits into those deformations rather
    /// than into mixtures of them.
    pub weight_sparsity: f64,
    /// Maximum number of outer iterations. Default 10 (the reference's fixed count).
    pub max_iterations: usize,
    /// ADMM penalty and inner iteration count.
    pub admm: AdmmConfig,
    /// Relative convergence threshold ε of the mean objective change over the last 5 outer
    /// iterations (see the module docs); 0 disables early stopping. Default 1e-6.
    pub tolerance: f64,
    /// Seed of the common method config. SPLOCS is deterministic (deflation initialisation),
    /// so the seed does not change its result; it is kept for a uniform configuration.
    pub seed: u64,
    /// User constraints (paper §3.3): painted element sets, one per component, fixing the
    /// centre set of the *first* `fixed_centers.len()` components (their support is the
    /// distance to the whole set). Elements are vertices for W = 3 data and triangles for W = 9
    /// (see [`super::support_map::vertex_set_to_triangles`]). Default none.
    pub fixed_centers: Vec<Vec<usize>>,
    /// Threads: 1 (default) runs sequentially; n > 1 runs the column blocks of the component
    /// update on a pool of n rayon threads (and the initial products with n threads); 0 uses as
    /// many threads as the machine has. With more than one thread, results agree with the
    /// sequential run up to round-off (partial sums are added in another order).
    pub threads: usize,
}

impl Default for SplocsConfig {
    fn default() -> Self {
        SplocsConfig {
            components: 50,
            sparsity: 2.0,
            support: [0.1, 0.7],
            weights: WeightConstraint::Nonnegative,
            weight_sparsity: 0.0,
            max_iterations: 10,
            admm: AdmmConfig::default(),
            tolerance: 1e-6,
            seed: 0,
            fixed_centers: Vec::new(),
            threads: 1,
        }
    }
}

impl SplocsConfig {
    /// Checks every value that does not depend on the data.
    pub fn validate(&self) -> Result<()> {
        if self.components == 0 {
            return Err(Error::config("components", "components (0) must be at least 1"));
        }
        if !(self.sparsity.is_finite() && self.sparsity >= 0.0) {
            return Err(Error::config("sparsity", format!("sparsity λ ({}) must be finite and ≥ 0", self.sparsity)));
        }
        let [d_min, d_max] = self.support;
        if !(d_min.is_finite() && d_max.is_finite()) || d_min < 0.0 {
            return Err(Error::config("support", format!("support [{d_min}, {d_max}] must be finite with d_min ≥ 0")));
        }
        if d_min >= d_max {
            return Err(Error::config("support", format!("d_min ({d_min}) must be below d_max ({d_max})")));
        }
        if !(self.weight_sparsity.is_finite() && (0.0..1.0).contains(&self.weight_sparsity)) {
            return Err(Error::config(
                "weight_sparsity",
                format!("weight_sparsity ({}) must be in [0, 1)", self.weight_sparsity),
            ));
        }
        if self.weights == WeightConstraint::Unconstrained {
            return Err(Error::config(
                "weights",
                "weights (unconstrained) must be `nonnegative` or `signed` for SPLOCS",
            ));
        }
        if !(self.admm.rho.is_finite() && self.admm.rho > 0.0) {
            return Err(Error::config("admm.rho", format!("admm.rho ({}) must be finite and > 0", self.admm.rho)));
        }
        if self.admm.iterations == 0 {
            return Err(Error::config("admm.iterations", "admm.iterations (0) must be at least 1"));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(Error::config("tolerance", format!("tolerance ({}) must be finite and ≥ 0", self.tolerance)));
        }
        if self.fixed_centers.len() > self.components {
            return Err(Error::config(
                "fixed_centers",
                format!("{} painted sets given for only {} components", self.fixed_centers.len(), self.components),
            ));
        }
        if let Some(i) = self.fixed_centers.iter().position(|s| s.is_empty()) {
            return Err(Error::config("fixed_centers", format!("painted set {i} is empty")));
        }
        Ok(())
    }

    fn par(&self) -> Par {
        if self.threads == 1 { Par::Seq } else { Par::rayon(self.threads) }
    }
}

/// Result of a SPLOCS fit.
#[derive(Debug, Clone)]
pub struct SplocsFit {
    /// Components (in the data's units) and weights; offset zero.
    pub model: LinearModel,
    /// Centre set of each component as used in the last component update.
    pub centers: Vec<Vec<usize>>,
    /// E_0 (after initialisation), E_1, …: objective ‖X − WC‖² + Ω(C) in standardised units.
    pub objective_history: Vec<f64>,
    /// Outer iterations run.
    pub iterations: usize,
    /// Whether the convergence test stopped the iterations (false: `max_iterations` reached).
    pub converged: bool,
    /// Standard deviation s of the data (standardised = data / s).
    pub data_scale: f64,
    /// Locality of each component with respect to the support map of its final centre set.
    pub locality: Vec<ComponentLocality>,
    /// Number of distance-provider queries (centre sets computed; the rest came from the cache).
    pub distance_queries: usize,
}

/// The SPLOCS optimiser as a state machine: [`SplocsSolver::new`] standardises and runs the
/// deflation initialisation, [`SplocsSolver::step`] runs one outer iteration, and
/// [`SplocsSolver::finish`] undoes the scaling. [`SplocsSolver::fit`] runs all of it.
pub struct SplocsSolver<'a, P: SupportDistances + ?Sized> {
    config: SplocsConfig,
    provider: &'a P,
    x: DataRef<'a>,
    f: usize,
    k: usize,
    d: usize,
    width: usize,
    /// 1 / std(X).
    inv_scale: f64,
    x_norm2: f64,
    /// K × D components (standardised units), blocked layout (see `Blocks`).
    c: Vec<f64>,
    /// F × K weights.
    wts: Vec<f64>,
    /// K × D scaled dual, blocked layout.
    u: Vec<f64>,
    blocks: Blocks,
    pool: Option<rayon::ThreadPool>,
    /// K × E regularisation weights Λ.
    lambda: Vec<f64>,
    centers: Vec<Vec<usize>>,
    cache: SupportCache,
    /// F × K: X·Cᵀ / s for the current C.
    xct: Vec<f64>,
    /// K × K: C·Cᵀ for the current C.
    cct: Vec<f64>,
    col: Vec<f64>,
    history: Vec<f64>,
    iterations: usize,
    converged: bool,
}

/// The deflation start's weights of one component from its centre's residual block (F × m):
/// the leading left singular vector times its singular value, projected onto the constraint set
/// with the sign that keeps the larger projected norm.
fn start_weights(block: MatRef<'_, f64>, constraint: WeightConstraint) -> Result<Vec<f64>> {
    let f = block.nrows();
    let mut wk = vec![0.0; f];
    if block.ncols() > 0 && f > 0 {
        let svd = block.thin_svd().map_err(|e| Error::Numerical(format!("SPLOCS init: SVD failed: {e:?}")))?;
        let s0 = svd.S().column_vector()[0];
        for (row, v) in wk.iter_mut().enumerate() {
            *v = s0 * svd.U()[(row, 0)];
        }
    }
    let mut p1 = wk.clone();
    project_weights(&mut p1, constraint);
    let mut p2: Vec<f64> = wk.iter().map(|v| -v).collect();
    project_weights(&mut p2, constraint);
    let n1: f64 = p1.iter().map(|v| v * v).sum();
    let n2: f64 = p2.iter().map(|v| v * v).sum();
    Ok(if n1 > n2 { p1 } else { p2 })
}

/// Rows per block when the data is in `f32` ([`DataRef::F32`]): each block is converted to
/// `f64` (256 × D numbers) before its products.
const COMPACT_ROWS: usize = 256;

/// Σ g(x) over `f32` values taken as `f64`, in blocks summed in order (in parallel).
fn compact_sum(data: &[f32], g: impl Fn(f64) -> f64 + Sync) -> f64 {
    use rayon::prelude::*;
    let parts: Vec<f64> = data.par_chunks(1 << 16).map(|c| c.iter().map(|&v| g(f64::from(v))).sum::<f64>()).collect();
    parts.iter().sum()
}

/// Target columns per block of the blocked ADMM (a few K × 240 buffers stay in L2).
const BLOCK_COLS: usize = 240;

impl<'a, P: SupportDistances + ?Sized> SplocsSolver<'a, P> {
    /// Validates the config against the data and the provider, standardises, and runs the
    /// deflation initialisation (E_0 is the first entry of the objective history).
    pub fn new(x: impl Into<DataRef<'a>>, provider: &'a P, config: &SplocsConfig) -> Result<Self> {
        let x = x.into();
        config.validate()?;
        let (f, e, width, d) = (x.n_rows(), x.n_elements(), x.width(), x.n_cols());
        let k = config.components;
        if provider.n_elements() != e {
            return Err(Error::Invalid(format!(
                "support distances cover {} elements, the data matrix has {e}",
                provider.n_elements()
            )));
        }
        for (i, set) in config.fixed_centers.iter().enumerate() {
            if let Some(&bad) = set.iter().find(|&&v| v >= e) {
                return Err(Error::config(
                    "fixed_centers",
                    format!("painted set {i} holds element {bad}, but there are only {e} elements"),
                ));
            }
        }
        // numpy-style std over all entries
        let n = (f * d) as f64;
        let (var, sq) = match x {
            DataRef::F64(m) => {
                let mean = m.data().iter().sum::<f64>() / n;
                let var = m.data().iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
                (var, m.data().iter().map(|v| v * v).sum::<f64>())
            }
            DataRef::F32(m) => {
                let mean = compact_sum(m.data(), |v| v) / n;
                let var = compact_sum(m.data(), |v| (v - mean) * (v - mean)) / n;
                (var, compact_sum(m.data(), |v| v * v))
            }
        };
        let std = var.sqrt();
        if !(std > 0.0 && std.is_finite()) {
            return Err(Error::Invalid(format!("data matrix has zero or non-finite standard deviation ({std})")));
        }
        let inv_scale = 1.0 / std;
        let x_norm2 = sq * inv_scale * inv_scale;
        let [d_min, d_max] = config.support;
        let mut s = SplocsSolver {
            config: config.clone(),
            provider,
            x,
            f,
            k,
            d,
            width,
            inv_scale,
            x_norm2,
            c: vec![0.0; k * d],
            wts: vec![0.0; f * k],
            u: vec![0.0; k * d],
            blocks: Blocks::new(e, width, k, BLOCK_COLS),
            pool: None,
            lambda: vec![0.0; k * e],
            centers: Vec::with_capacity(k),
            cache: SupportCache::new(d_min, d_max, 8 * k + 64),
            xct: vec![0.0; f * k],
            cct: vec![0.0; k * k],
            col: vec![0.0; f],
            history: Vec::new(),
            iterations: 0,
            converged: false,
        };
        if config.threads != 1 {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(config.threads)
                .build()
                .map_err(|e| Error::config("threads", format!("cannot start {} threads: {e}", config.threads)))?;
            s.pool = Some(pool);
        }
        // deflation on row-major C, then products and the blocked layout
        let mut c_rm = vec![0.0; k * d];
        let e0 = match s.x {
            DataRef::F64(_) => {
                let e0 = s.initialize(&mut c_rm)?;
                s.update_products(&c_rm, config.par());
                e0
            }
            DataRef::F32(_) => {
                let sparsity = s.initialize_implicit(&mut c_rm)?;
                s.update_products(&c_rm, config.par());
                s.residual_from_products() + sparsity
            }
        };
        s.history.push(e0);
        s.blocks.to_blocked(&c_rm, &mut s.c);
        Ok(s)
    }

    /// Runs the whole optimisation; `on_iteration(i, E_i)` is called with i = 0 after the
    /// initialisation and after every outer iteration i = 1, 2, … (objective in standardised
    /// units), e.g. to drive a progress bar of `max_iterations + 1` ticks.
    pub fn fit(
        x: impl Into<DataRef<'a>>,
        provider: &'a P,
        config: &SplocsConfig,
        mut on_iteration: impl FnMut(usize, f64),
    ) -> Result<SplocsFit> {
        let mut s = SplocsSolver::new(x, provider, config)?;
        on_iteration(0, s.history[0]);
        while !s.is_done() {
            let e = s.step()?;
            on_iteration(s.iterations, e);
        }
        s.finish()
    }

    /// True once `max_iterations` outer iterations ran or the convergence test fired.
    pub fn is_done(&self) -> bool {
        self.converged || self.iterations >= self.config.max_iterations
    }

    /// Objective history E_0, E_1, … so far.
    pub fn objective_history(&self) -> &[f64] {
        &self.history
    }

    /// Current weights (F × K, row-major).
    pub fn weights(&self) -> &[f64] {
        &self.wts
    }

    /// Current components in standardised units (K × E·W, row-major).
    pub fn components_standardised(&self) -> Vec<f64> {
        let mut out = vec![0.0; self.c.len()];
        self.blocks.to_row_major(&self.c, &mut out);
        out
    }

    /// Deflation initialisation into `c` (row-major K × D); returns E_0.
    fn initialize(&mut self, c: &mut [f64]) -> Result<f64> {
        let (f, d, w, k) = (self.f, self.d, self.width, self.k);
        let e_count = self.x.n_elements();
        let constraint = self.config.weights;
        let DataRef::F64(x) = self.x else { unreachable!("initialize runs on f64 data") };
        let mut r: Vec<f64> = x.data().iter().map(|v| v * self.inv_scale).collect();
        let mut enorm = vec![0.0; e_count];
        for row in r.chunks_exact(d) {
            for (en, g) in enorm.iter_mut().zip(row.chunks_exact(w)) {
                *en += g.iter().map(|v| v * v).sum::<f64>();
            }
        }
        let mut acc = vec![0.0; d];
        for kk in 0..k {
            let set = self.start_centre(kk, &enorm);
            // weights: leading left singular vector × singular value of the centre block
            let m = set.len() * w;
            let block = Mat::<f64>::from_fn(f, m, |row, j| r[row * d + set[j / w] * w + j % w]);
            let wk = start_weights(block.as_ref(), constraint)?;
            self.cache.ensure(self.provider, std::slice::from_ref(&set))?;
            let ramp = self.cache.ramp(&set);
            let ww: f64 = wk.iter().map(|v| v * v).sum();
            let ck = &mut c[kk * d..(kk + 1) * d];
            if ww > 0.0 {
                acc.iter_mut().for_each(|a| *a = 0.0);
                for (row, &wf) in wk.iter().enumerate() {
                    if wf != 0.0 {
                        for (a, rv) in acc.iter_mut().zip(&r[row * d..(row + 1) * d]) {
                            *a += wf * rv;
                        }
                    }
                }
                for (e, (cg, ag)) in ck.chunks_exact_mut(w).zip(acc.chunks_exact(w)).enumerate() {
                    let mask = 1.0 - ramp[e];
                    for (cv, av) in cg.iter_mut().zip(ag) {
                        *cv = mask * av / ww;
                    }
                }
                let active: Vec<usize> = (0..e_count).filter(|&e| ramp[e] < 1.0).collect();
                for (row, &wf) in wk.iter().enumerate() {
                    if wf == 0.0 {
                        continue;
                    }
                    let rr = &mut r[row * d..(row + 1) * d];
                    for &e in &active {
                        let mut delta = 0.0;
                        for q in e * w..(e + 1) * w {
                            let old = rr[q];
                            let new = old - wf * ck[q];
                            rr[q] = new;
                            delta += new * new - old * old;
                        }
                        enorm[e] = (enorm[e] + delta).max(0.0);
                    }
                }
            } else {
                ck.iter_mut().for_each(|v| *v = 0.0);
            }
            for (row, v) in wk.iter().enumerate() {
                self.wts[row * k + kk] = *v;
            }
            self.centers.push(set);
        }
        self.set_lambda()?;
        let res2: f64 = r.iter().map(|v| v * v).sum();
        Ok(res2 + self.sparsity_of(c))
    }

    /// The deflation initialisation of [`Self::initialize`] without holding the residual
    /// R = X/s − W·C (for data in `f32`, [`DataRef::F32`], where a second copy of X is what
    /// must not be held): R's centre block is X's block minus W·C there, w_kᵀR is w_kᵀX/s −
    /// (w_kᵀW)·C (one pass over X per component), and the residual norms of the elements move
    /// by Σ_q (c_q²·w_kᵀw_k − 2·c_q·(w_kᵀR)_q) over each element's numbers q — the same
    /// quantities, summed in another order. Returns Ω(C); the data term comes from the Gram
    /// products ([`Self::residual_from_products`]).
    fn initialize_implicit(&mut self, c: &mut [f64]) -> Result<f64> {
        use rayon::prelude::*;
        let (f, d, w, k) = (self.f, self.d, self.width, self.k);
        let e_count = self.x.n_elements();
        let constraint = self.config.weights;
        let (xr, inv_scale) = (self.x, self.inv_scale);
        let n_blocks = f.div_ceil(COMPACT_ROWS);
        // Σ_f ‖X_f,e / s‖² per element
        let mut enorm = (0..n_blocks)
            .into_par_iter()
            .fold(
                || vec![0.0; e_count],
                |mut en, b| {
                    let rows = COMPACT_ROWS.min(f - b * COMPACT_ROWS);
                    let mut buf = vec![0.0; rows * d];
                    xr.read_rows(b * COMPACT_ROWS, rows, &mut buf);
                    for row in buf.chunks_exact(d) {
                        for (e, g) in en.iter_mut().zip(row.chunks_exact(w)) {
                            *e += g.iter().map(|v| (v * inv_scale) * (v * inv_scale)).sum::<f64>();
                        }
                    }
                    en
                },
            )
            .reduce(|| vec![0.0; e_count], |a, b| a.iter().zip(&b).map(|(p, q)| p + q).collect());
        for kk in 0..k {
            let set = self.start_centre(kk, &enorm);
            // the centre block of R = X/s − W·C (components ≥ kk are still zero)
            let m = set.len() * w;
            let mut col = vec![0.0; f * w];
            let mut block = Mat::<f64>::zeros(f, m);
            for (j, &el) in set.iter().enumerate() {
                xr.read_cols(el * w..(el + 1) * w, &mut col);
                for row in 0..f {
                    for q in 0..w {
                        let cq = el * w + q;
                        let wc: f64 = (0..kk).map(|j2| self.wts[row * k + j2] * c[j2 * d + cq]).sum();
                        block[(row, j * w + q)] = col[row * w + q] * inv_scale - wc;
                    }
                }
            }
            let wk = start_weights(block.as_ref(), constraint)?;
            self.cache.ensure(self.provider, std::slice::from_ref(&set))?;
            let ramp = self.cache.ramp(&set).to_vec();
            let ww: f64 = wk.iter().map(|v| v * v).sum();
            if ww > 0.0 {
                // w_kᵀR = w_kᵀX/s − (w_kᵀW)·C
                let wkr = &wk;
                let mut acc = (0..n_blocks)
                    .into_par_iter()
                    .fold(
                        || vec![0.0; d],
                        |mut a, b| {
                            let first = b * COMPACT_ROWS;
                            let rows = COMPACT_ROWS.min(f - first);
                            if wkr[first..first + rows].iter().all(|&v| v == 0.0) {
                                return a;
                            }
                            let mut buf = vec![0.0; rows * d];
                            xr.read_rows(first, rows, &mut buf);
                            for (row, xrow) in buf.chunks_exact(d).enumerate() {
                                let wf = wkr[first + row];
                                if wf != 0.0 {
                                    a.iter_mut().zip(xrow).for_each(|(av, xv)| *av += wf * (xv * inv_scale));
                                }
                            }
                            a
                        },
                    )
                    .reduce(|| vec![0.0; d], |a, b| a.iter().zip(&b).map(|(p, q)| p + q).collect());
                for j2 in 0..kk {
                    let wtw: f64 = (0..f).map(|row| wk[row] * self.wts[row * k + j2]).sum();
                    if wtw != 0.0 {
                        acc.iter_mut().zip(&c[j2 * d..(j2 + 1) * d]).for_each(|(a, cv)| *a -= wtw * cv);
                    }
                }
                let ck = &mut c[kk * d..(kk + 1) * d];
                for (e, (cg, ag)) in ck.chunks_exact_mut(w).zip(acc.chunks_exact(w)).enumerate() {
                    let mask = 1.0 - ramp[e];
                    for (cv, av) in cg.iter_mut().zip(ag) {
                        *cv = mask * av / ww;
                    }
                }
                for e in (0..e_count).filter(|&e| ramp[e] < 1.0) {
                    let delta: f64 = (e * w..(e + 1) * w).map(|q| ck[q] * ck[q] * ww - 2.0 * ck[q] * acc[q]).sum();
                    enorm[e] = (enorm[e] + delta).max(0.0);
                }
            } else {
                c[kk * d..(kk + 1) * d].iter_mut().for_each(|v| *v = 0.0);
            }
            for (row, v) in wk.iter().enumerate() {
                self.wts[row * k + kk] = *v;
            }
            self.centers.push(set);
        }
        self.set_lambda()?;
        Ok(self.sparsity_of(c))
    }

    /// ‖X/s − W·C‖² from the products X·Cᵀ/s and C·Cᵀ of the current C and W (as the outer
    /// iterations measure it).
    fn residual_from_products(&self) -> f64 {
        let (f, k) = (self.f, self.k);
        let wm = MatRef::from_row_major_slice(&self.wts, f, k);
        let mut wtw = Mat::<f64>::zeros(k, k);
        matmul(wtw.as_mut(), Accum::Replace, wm.transpose(), wm, 1.0, Par::Seq);
        let cross: f64 = self.wts.iter().zip(&self.xct).map(|(a, b)| a * b).sum();
        let mut quad = 0.0;
        for a in 0..k {
            for b in 0..k {
                quad += wtw[(a, b)] * self.cct[a * k + b];
            }
        }
        (self.x_norm2 - 2.0 * cross + quad).max(0.0)
    }

    /// The centre set of component `kk` in the deflation start: the user's painted set (sorted,
    /// without repeats), else the element of largest residual norm `enorm` (the first maximum,
    /// like numpy.argmax).
    fn start_centre(&self, kk: usize, enorm: &[f64]) -> Vec<usize> {
        if kk < self.config.fixed_centers.len() {
            let mut s = self.config.fixed_centers[kk].clone();
            s.sort_unstable();
            s.dedup();
            return s;
        }
        let mut best = 0;
        for (i, &v) in enorm.iter().enumerate() {
            if v > enorm[best] {
                best = i;
            }
        }
        vec![best]
    }

    /// Ω(C) = Σ_k Σ_e Λ_k,e ‖C_k,e‖ of a row-major C with the current Λ.
    fn sparsity_of(&self, c: &[f64]) -> f64 {
        let (d, w, e_count) = (self.d, self.width, self.x.n_elements());
        let mut sparsity = 0.0;
        for kk in 0..self.k {
            for e in 0..e_count {
                let lam = self.lambda[kk * e_count + e];
                if lam > 0.0 {
                    let g = &c[kk * d + e * w..kk * d + (e + 1) * w];
                    sparsity += lam * g.iter().map(|v| v * v).sum::<f64>().sqrt();
                }
            }
        }
        sparsity
    }

    /// Λ from the current centre sets (ensuring their support maps are cached).
    fn set_lambda(&mut self) -> Result<()> {
        self.cache.ensure(self.provider, &self.centers)?;
        let e = self.x.n_elements();
        let lam = self.config.sparsity;
        for (kk, set) in self.centers.iter().enumerate() {
            let ramp = self.cache.ramp(set);
            for (l, r) in self.lambda[kk * e..(kk + 1) * e].iter_mut().zip(ramp) {
                *l = lam * r;
            }
        }
        Ok(())
    }

    /// X·Cᵀ/s and C·Cᵀ for a row-major C.
    fn update_products(&mut self, c: &[f64], par: Par) {
        let (f, k, d) = (self.f, self.k, self.d);
        let c = MatRef::from_row_major_slice(c, k, d);
        match self.x {
            DataRef::F64(x) => {
                let x = MatRef::from_row_major_slice(x.data(), f, d);
                matmul(
                    MatMut::from_row_major_slice_mut(&mut self.xct, f, k),
                    Accum::Replace,
                    x,
                    c.transpose(),
                    self.inv_scale,
                    par,
                );
            }
            DataRef::F32(_) => {
                use rayon::prelude::*;
                let (xr, inv_scale) = (self.x, self.inv_scale);
                self.xct.par_chunks_mut(COMPACT_ROWS * k).enumerate().for_each(|(b, out)| {
                    let rows = out.len() / k;
                    let mut buf = vec![0.0; rows * d];
                    xr.read_rows(b * COMPACT_ROWS, rows, &mut buf);
                    matmul(
                        MatMut::from_row_major_slice_mut(out, rows, k),
                        Accum::Replace,
                        MatRef::from_row_major_slice(&buf, rows, d),
                        c.transpose(),
                        inv_scale,
                        Par::Seq,
                    );
                });
            }
        }
        matmul(MatMut::from_row_major_slice_mut(&mut self.cct, k, k), Accum::Replace, c, c.transpose(), 1.0, par);
    }

    /// One outer iteration (weights, centres and support maps, ADMM on the components);
    /// returns the new objective E_i.
    pub fn step(&mut self) -> Result<f64> {
        let (f, k, d, w) = (self.f, self.k, self.d, self.width);
        let e_count = self.x.n_elements();
        // (a) weights
        update_weights(
            &mut self.wts,
            &self.xct,
            &self.cct,
            f,
            k,
            self.config.weights,
            1e-8,
            &mut self.col,
            self.config.weight_sparsity,
        );
        // (b) centres and Λ
        let n_fixed = self.config.fixed_centers.len();
        for (kk, (best, n2)) in self.blocks.argmax_groups(&self.c).into_iter().enumerate().skip(n_fixed) {
            if n2 > 0.0 {
                self.centers[kk] = vec![best];
            }
        }
        self.set_lambda()?;
        // (c) ADMM, one factorisation of WᵀW + ρI, blocks of columns in parallel
        let rho = self.config.admm.rho;
        let wm = MatRef::from_row_major_slice(&self.wts, f, k);
        let mut wtw = Mat::<f64>::zeros(k, k);
        matmul(wtw.as_mut(), Accum::Replace, wm.transpose(), wm, 1.0, Par::Seq);
        let mut g = wtw.clone();
        for i in 0..k {
            g[(i, i)] += rho;
        }
        let llt =
            g.llt(Side::Lower).map_err(|e| Error::Numerical(format!("SPLOCS: Cholesky of WᵀW + ρI failed: {e:?}")))?;
        let minv = llt.inverse();
        let shared = AdmmShared {
            x: self.x,
            inv_scale: self.inv_scale,
            weights: &self.wts,
            minv: minv.as_ref(),
            lambda: &self.lambda,
            rho,
            iterations: self.config.admm.iterations,
            f,
            d,
            e: e_count,
            k,
            width: w,
        };
        let blocks = &self.blocks;
        let compact = matches!(self.x, DataRef::F32(_));
        let max_cols = (0..blocks.len()).map(|b| blocks.cols(b).len()).max().unwrap_or(0);
        let items: Vec<(usize, &mut [f64], &mut [f64])> = blocks
            .split_mut(&mut self.c)
            .into_iter()
            .zip(blocks.split_mut(&mut self.u))
            .enumerate()
            .map(|(b, (c, u))| (b, c, u))
            .collect();
        let acc = match (&self.pool, self.config.threads) {
            (None, 1) => {
                let mut acc = AdmmAcc::new(f, k, max_cols, compact);
                for (b, c, u) in items {
                    admm_block(&shared, blocks, b, c, u, &mut acc);
                }
                acc
            }
            (pool, _) => {
                use rayon::prelude::*;
                let run = || {
                    items
                        .into_par_iter()
                        .fold(
                            || AdmmAcc::new(f, k, max_cols, compact),
                            |mut acc, (b, c, u)| {
                                admm_block(&shared, blocks, b, c, u, &mut acc);
                                acc
                            },
                        )
                        .reduce_with(AdmmAcc::merge)
                        .unwrap_or_else(|| AdmmAcc::new(f, k, 0, false))
                };
                match pool {
                    Some(p) => p.install(run),
                    None => run(),
                }
            }
        };
        self.xct = acc.xct;
        self.cct = acc.cct;
        // objective ‖X − WC‖² + Ω(C) from the Gram products
        let mut cross = 0.0;
        for (wv, xv) in self.wts.iter().zip(&self.xct) {
            cross += wv * xv;
        }
        let mut quad = 0.0;
        for a in 0..k {
            for bb in 0..k {
                quad += wtw[(a, bb)] * self.cct[a * k + bb];
            }
        }
        let res2 = (self.x_norm2 - 2.0 * cross + quad).max(0.0);
        let obj = res2 + acc.sparsity;
        if !obj.is_finite() {
            return Err(Error::Numerical(format!(
                "SPLOCS: objective became {obj} at iteration {}",
                self.iterations + 1
            )));
        }
        self.history.push(obj);
        self.iterations += 1;
        self.converged = self.convergence_test();
        Ok(obj)
    }

    fn convergence_test(&self) -> bool {
        let h = &self.history;
        let i = h.len() - 1;
        if self.config.tolerance <= 0.0 || i < 5 {
            return false;
        }
        let mean_change = (i - 4..=i).map(|j| (h[j] - h[j - 1]).abs()).sum::<f64>() / 5.0;
        mean_change <= self.config.tolerance * h[i].abs()
    }

    /// Undoes the standardisation and packages the model, centres, history and locality.
    pub fn finish(self) -> Result<SplocsFit> {
        let scale = 1.0 / self.inv_scale;
        let e = self.x.n_elements();
        let mut components = vec![0.0; self.c.len()];
        self.blocks.to_row_major(&self.c, &mut components);
        components.iter_mut().for_each(|v| *v *= scale);
        let model = LinearModel {
            n_elements: e,
            width: self.width,
            n_components: self.k,
            n_frames: self.f,
            components,
            weights: self.wts,
            offset: vec![0.0; self.d],
            constraint: self.config.weights,
        };
        model.validate()?;
        let locality = (0..self.k)
            .map(|kk| {
                let norms = model.component_group_norms(kk);
                let ramp = self.cache.ramp(&self.centers[kk]);
                component_locality(self.centers[kk][0], &norms, ramp)
            })
            .collect();
        Ok(SplocsFit {
            model,
            centers: self.centers,
            objective_history: self.history,
            iterations: self.iterations,
            converged: self.converged,
            data_scale: scale,
            locality,
            distance_queries: self.cache.n_queries,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::methods::{CompactMatrix, DataMatrix};

    /// Distances along a line of `n` elements spaced `h`.
    struct Line {
        n: usize,
        h: f64,
    }
    impl SupportDistances for Line {
        fn n_elements(&self) -> usize {
            self.n
        }
        fn distances(&self, centers: &[usize]) -> Result<Vec<f64>> {
            Ok((0..self.n)
                .map(|i| centers.iter().map(|&c| (i as f64 - c as f64).abs() * self.h).fold(f64::INFINITY, f64::min))
                .collect())
        }
    }

    /// Two bumps on a line of 40 elements (width 2), moving independently over 30 frames.
    fn two_bumps() -> (Vec<f64>, usize, usize, usize) {
        let (f, e, w) = (30, 40, 2);
        let mut x = vec![0.0; f * e * w];
        let mut s = 7u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for fr in 0..f {
            let (a, b) = (rnd(), rnd());
            for el in 0..e {
                let g1 = (-((el as f64 - 8.0) / 2.5f64).powi(2)).exp();
                let g2 = (-((el as f64 - 30.0) / 2.5f64).powi(2)).exp();
                x[(fr * e + el) * w] = a * g1;
                x[(fr * e + el) * w + 1] = b * g2;
            }
        }
        (x, f, e, w)
    }

    /// The same data held in `f32` (values exactly representable, so both precisions see the
    /// same numbers): the implicit-residual initialisation and the converted blocks give the
    /// exact path's fit up to summation order, for both constraints and fixed centres. Catches
    /// a wrong sign or term in the implicit residual (w_kᵀR, the norms' update), a block
    /// conversion reading the wrong rows or columns, and a wrong data term of E_0.
    #[test]
    fn f32_data_fits_like_f64_data() {
        let (x, f, e, w) = two_bumps();
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let x64: Vec<f64> = x32.iter().map(|&v| f64::from(v)).collect();
        let compact = CompactMatrix::new(x32, f, e, w).unwrap();
        let p = Line { n: e, h: 0.025 };
        for (constraint, fixed) in
            [(WeightConstraint::Nonnegative, vec![]), (WeightConstraint::Signed, vec![vec![30usize, 31]])]
        {
            let cfg = SplocsConfig {
                components: 3,
                weights: constraint,
                fixed_centers: fixed,
                max_iterations: 15,
                ..Default::default()
            };
            let exact = SplocsSolver::fit(DataMatrix::new(&x64, f, e, w).unwrap(), &p, &cfg, |_, _| {}).unwrap();
            let small = SplocsSolver::fit(&compact, &p, &cfg, |_, _| {}).unwrap();
            assert_eq!(exact.centers, small.centers);
            assert_eq!(exact.objective_history.len(), small.objective_history.len());
            for (a, b) in exact.objective_history.iter().zip(&small.objective_history) {
                assert!((a - b).abs() <= 1e-9 * a.abs(), "objective {a} vs {b}");
            }
            let scale = exact.model.components.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (a, b) in exact.model.components.iter().zip(&small.model.components) {
                assert!((a - b).abs() <= 1e-8 * scale, "component {a} vs {b}");
            }
        }
    }

    /// One outer iteration's ADMM, by hand (dense, row-major) from the state the previous one
    /// left (`Z` = C and the scaled dual `U`) and the weights and Λ this one chose: `iterations`
    /// times `C = (WᵀW + ρI)⁻¹(WᵀX/s + ρ(Z − U))`, `Z = prox(C + U)` (each element's group shrunk
    /// by Λ/ρ, or zero), `U += C − Z`; the objective returned is `‖X/s − W·Z‖² + Σ Λ·‖Z_g‖`.
    /// Λ itself is `sparsity · ramp(distance to the centre)`. Catches ρ, the inner iteration
    /// count or λ not reaching the solver, and a wrong threshold, dual update or objective.
    #[test]
    fn an_outer_iteration_runs_the_configured_admm() {
        use crate::methods::support_map::support_ramp;
        let (x, f, e, w) = two_bumps();
        let p = Line { n: e, h: 0.025 };
        for (rho, iterations, sparsity) in [(10.0, 1, 2.0), (3.0, 4, 0.5), (25.0, 2, 6.0)] {
            let cfg = SplocsConfig {
                components: 3,
                sparsity,
                support: [0.1, 0.3],
                admm: AdmmConfig { rho, iterations },
                ..Default::default()
            };
            let mut s = SplocsSolver::new(DataMatrix::new(&x, f, e, w).unwrap(), &p, &cfg).unwrap();
            s.step().unwrap();
            let (k, d) = (s.k, s.d);
            let row = |s: &SplocsSolver<'_, Line>, b: &[f64]| {
                let mut r = vec![0.0; k * d];
                s.blocks.to_row_major(b, &mut r);
                r
            };
            let (mut z, mut u) = (row(&s, &s.c), row(&s, &s.u));
            let objective = s.step().unwrap();
            let wts = &s.wts;
            for kk in 0..k {
                let dist = p.distances(&s.centers[kk]).unwrap();
                for (el, &dv) in dist.iter().enumerate() {
                    let want = sparsity * support_ramp(dv, 0.1, 0.3);
                    assert!((s.lambda[kk * e + el] - want).abs() <= 1e-12 * sparsity, "Λ[{kk}, {el}]");
                }
            }
            // (WᵀW + ρI)⁻¹ (K = 3: the adjugate of `math::mat3`), and WᵀX/s.
            let mut gram = [[0.0; 3]; 3];
            for (i, gi) in gram.iter_mut().enumerate() {
                for (j, gij) in gi.iter_mut().enumerate() {
                    *gij =
                        (0..f).map(|r| wts[r * k + i] * wts[r * k + j]).sum::<f64>() + if i == j { rho } else { 0.0 };
                }
            }
            let minv = crate::math::mat3::inverse(&gram).expect("WᵀW + ρI is positive definite");
            let wx: Vec<f64> = (0..k * d)
                .map(|i| (0..f).map(|r| wts[r * k + i / d] * x[r * d + i % d]).sum::<f64>() * s.inv_scale)
                .collect();
            for _ in 0..iterations {
                let sv: Vec<f64> = (0..k * d).map(|i| wx[i] + rho * (z[i] - u[i])).collect();
                let c: Vec<f64> =
                    (0..k * d).map(|i| (0..k).map(|q| minv[i / d][q] * sv[q * d + i % d]).sum()).collect();
                for g in 0..k * e {
                    let r = g * w..(g + 1) * w;
                    let norm = r.clone().map(|i| (c[i] + u[i]).powi(2)).sum::<f64>().sqrt();
                    let thr = s.lambda[g] / rho;
                    for i in r {
                        let zi = if norm > thr { (1.0 - thr / norm) * (c[i] + u[i]) } else { 0.0 };
                        u[i] += c[i] - zi;
                        z[i] = zi;
                    }
                }
            }
            let scale = z.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let (got_z, got_u) = (row(&s, &s.c), row(&s, &s.u));
            for i in 0..k * d {
                assert!(
                    (got_z[i] - z[i]).abs() <= 1e-9 * scale,
                    "ρ {rho}, {iterations} iterations: Z[{i}] {} vs {}",
                    got_z[i],
                    z[i]
                );
                assert!(
                    (got_u[i] - u[i]).abs() <= 1e-9 * scale,
                    "ρ {rho}, {iterations} iterations: U[{i}] {} vs {}",
                    got_u[i],
                    u[i]
                );
            }
            assert!(z.contains(&0.0) && z.iter().any(|&v| v != 0.0), "the prox must cut some groups, not all");
            let mut want = 0.0;
            for r in 0..f {
                for j in 0..d {
                    let fit: f64 = (0..k).map(|q| wts[r * k + q] * z[q * d + j]).sum();
                    want += (x[r * d + j] * s.inv_scale - fit).powi(2);
                }
            }
            for g in 0..k * e {
                want += s.lambda[g] * (g * w..(g + 1) * w).map(|i| z[i] * z[i]).sum::<f64>().sqrt();
            }
            assert!((objective - want).abs() <= 1e-9 * want, "objective {objective} vs {want}");
        }
    }

    #[test]
    fn config_errors_name_the_value() {
        let bad = SplocsConfig { support: [0.8, 0.7], ..Default::default() };
        let msg = bad.validate().unwrap_err().to_string();
        assert!(msg.contains("d_min (0.8) must be below d_max (0.7)"), "{msg}");
        let msg = SplocsConfig { sparsity: -1.0, ..Default::default() }.validate().unwrap_err().to_string();
        assert!(msg.contains("sparsity") && msg.contains("-1"), "{msg}");
        let msg = SplocsConfig { admm: AdmmConfig { rho: 0.0, iterations: 10 }, ..Default::default() }
            .validate()
            .unwrap_err()
            .to_string();
        assert!(msg.contains("admm.rho (0)"), "{msg}");
        let msg = SplocsConfig { components: 0, ..Default::default() }.validate().unwrap_err().to_string();
        assert!(msg.contains("components (0)"), "{msg}");
        let msg = SplocsConfig { weights: WeightConstraint::Unconstrained, ..Default::default() }
            .validate()
            .unwrap_err()
            .to_string();
        assert!(msg.contains("unconstrained"), "{msg}");
        let (x, f, e, w) = two_bumps();
        let p = Line { n: e, h: 0.025 };
        let cfg = SplocsConfig { components: 2, fixed_centers: vec![vec![3, 99]], ..Default::default() };
        let msg = SplocsSolver::new(DataMatrix::new(&x, f, e, w).unwrap(), &p, &cfg).err().unwrap().to_string();
        assert!(msg.contains("99"), "{msg}");
        let p_bad = Line { n: e + 1, h: 0.025 };
        let msg = SplocsSolver::new(DataMatrix::new(&x, f, e, w).unwrap(), &p_bad, &SplocsConfig::default())
            .err()
            .unwrap()
            .to_string();
        assert!(msg.contains("41") && msg.contains("40"), "{msg}");
        // TOML round trip with the config's key names
        let t: SplocsConfig =
            toml::from_str("components = 3\nsupport = [0.2, 0.5]\nweights = \"signed\"\n[admm]\nrho = 5.0\n").unwrap();
        assert_eq!(
            (t.components, t.support, t.weights, t.admm.rho, t.admm.iterations),
            (3, [0.2, 0.5], WeightConstraint::Signed, 5.0, 10)
        );
    }

    #[test]
    fn two_bumps_are_separated_and_weights_constrained() {
        let (x, f, e, w) = two_bumps();
        let p = Line { n: e, h: 0.025 };
        for constraint in [WeightConstraint::Nonnegative, WeightConstraint::Signed] {
            let cfg = SplocsConfig { components: 2, weights: constraint, support: [0.1, 0.3], ..Default::default() };
            let mut calls = Vec::new();
            let fit =
                SplocsSolver::fit(DataMatrix::new(&x, f, e, w).unwrap(), &p, &cfg, |i, o| calls.push((i, o))).unwrap();
            assert_eq!(calls.len(), fit.objective_history.len());
            let mut centres: Vec<usize> = fit.centers.iter().map(|s| s[0]).collect();
            centres.sort();
            assert!((6..=10).contains(&centres[0]) && (28..=32).contains(&centres[1]), "{centres:?}");
            for kk in 0..2 {
                let col: Vec<f64> = (0..f).map(|r| fit.model.weights[r * 2 + kk]).collect();
                let mx = col.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
                let mx_abs = col.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
                match constraint {
                    WeightConstraint::Nonnegative => {
                        assert!(col.iter().all(|&v| v >= 0.0) && (mx - 1.0).abs() < 1e-12)
                    }
                    _ => assert!((mx_abs - 1.0).abs() < 1e-12),
                }
            }
            // reconstruction explains most of the data
            let rec = fit.model.reconstruct().unwrap();
            let num: f64 = rec.iter().zip(&x).map(|(a, b)| (a - b) * (a - b)).sum();
            let den: f64 = x.iter().map(|v| v * v).sum();
            assert!(num / den < 0.05, "{constraint:?}: relative error {}", num / den);
        }
    }

    #[test]
    fn fixed_centres_are_kept() {
        let (x, f, e, w) = two_bumps();
        let p = Line { n: e, h: 0.025 };
        let cfg = SplocsConfig {
            components: 2,
            support: [0.1, 0.3],
            fixed_centers: vec![vec![29, 30, 31]],
            ..Default::default()
        };
        let fit = SplocsSolver::fit(DataMatrix::new(&x, f, e, w).unwrap(), &p, &cfg, |_, _| {}).unwrap();
        assert_eq!(fit.centers[0], vec![29, 30, 31]);
        // the first component lives around the painted set
        let norms = fit.model.component_group_norms(0);
        let inside: f64 = norms[20..40].iter().map(|v| v * v).sum();
        let total: f64 = norms.iter().map(|v| v * v).sum();
        assert!(inside / total > 0.95, "{}", inside / total);
    }
}
