//! Direct-manipulation posing ("click and drag") of linear models: given target values for a
//! few constrained vertices, find model weights that meet them while staying near the current
//! weights (Lewis & Anjyo 2010; Tena et al. 2011, Eq. 8–10).
//!
//! Targets are in the model's data units and space: for a model of vertex displacements (W = 3)
//! the target of vertex v is `target position − rest position`. Only W = 3 (per-vertex) models
//! can be posed here; a triangle-gradient model's vertices come out of a Poisson solve and need
//! a different (non-local) formulation.
//!
//! **γ is dimensionless, and the pull's strength does not depend on the pins.** The paper's γ
//! (0.025) multiplies ‖c − c0‖² in mm² units with orthonormal PCA bases. To make one γ work for
//! any units and any component normalisation (SPLOCS components are not unit vectors), every
//! pull of posing is measured in the whole shape's mean squared vertex motion ([`Pull`]):
//! `γ·(w − w0)ᵀ M (w − w0)` with M the shape metric `G = BᵀB / N` (B the model's linear map from
//! weights to the N×3 vertex positions), `m·I` (m = trace(G)/K, the weights prior) or the data
//! metric ([`data_metric`]), so a drag costs the same wherever its pin is. (The papers' scaling
//! by the components' mean squared response *at the pins*, [`Pull::AtPins`], made the pull 10×
//! and more weaker at a pin the components barely move: one drag of non-negative SCAPE SPLOCS at
//! the back swung an arm 5.8× the drag.) The pull is a prior of fixed strength: more pins ask
//! more of the model. β (boundary consistency, region PCA) is used as given: both the data and
//! the boundary term are squared vertex differences in the same units.
//!
//! **What the pull measures (`PosePrior`).** The paper's pull is on the weights, ‖w − w0‖². It
//! lets the solver buy a pin's motion with whichever weights are cheapest *at the pin*: a
//! component small at the pin and large elsewhere gets a large weight. [`PosePrior::Shape`]
//! measures the change of the whole shape instead (the mean squared motion of a vertex), so the
//! solver moves the pins with the least motion of everything else. [`PosePrior::Data`] (PCA
//! and SPLOCS's default) measures the weights by the training weights' spread: a Gaussian prior
//! whose cheap directions are those the training poses take together, so that a few pins pose
//! the whole shape as the training poses do (the drag benchmark's gain over the correction
//! alone: docs/posing-drag-bench.md).
//!
//! Factor once / solve many: a poser is built once per model and constraint-vertex set
//! (assembling and factorising a P × P system) and then [`LinearPoser::solve`] /
//! [`RegionPoser::solve`] run per drag event (one back-substitution, plus an active-set loop for
//! non-negative weights).

use faer::Mat;
use faer::linalg::solvers::Solve;
use serde::{Deserialize, Serialize};

use super::linear_model::nnls_gram;
use super::region_pca::{RegionPcaModel, SharedPair, boundary_rhs, factor_spd};
use super::{LinearModel, WeightConstraint};
use crate::mesh::Vec3;
use crate::{Error, Result};

/// Posing hyperparameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseConfig {
    /// γ ≥ 0 (dimensionless, see the module docs): pull towards the previous weights. Default
    /// 0.025 (the paper's value).
    pub gamma: f64,
    /// β ≥ 0: boundary consistency between regions (region PCA only). Default 1.
    pub beta: f64,
}

impl Default for PoseConfig {
    fn default() -> Self {
        PoseConfig { gamma: 0.025, beta: 1.0 }
    }
}

/// What the pull towards the start measures (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PosePrior {
    /// The change of the whole shape: mean squared vertex motion (meshdeco's default).
    #[default]
    Shape,
    /// The change of the weights, ‖w − w0‖² (paper 002 Eq. 8/10).
    Weights,
    /// The change of the weights measured by the training weights' spread (a Gaussian prior:
    /// [`data_metric`]); models that keep their training weights (PCA, SPLOCS).
    Data,
}

impl PosePrior {
    /// Parses `shape` | `weights` | `data`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "shape" => Some(PosePrior::Shape),
            "weights" => Some(PosePrior::Weights),
            "data" => Some(PosePrior::Data),
            _ => None,
        }
    }
    /// Name as written in flags and requests.
    pub fn name(self) -> &'static str {
        match self {
            PosePrior::Shape => "shape",
            PosePrior::Weights => "weights",
            PosePrior::Data => "data",
        }
    }
}

/// The shape metric `G = BᵀB / N` (K × K) of a model whose shape is `offset + B·w`, from the
/// K columns of B (each N×3 values, e.g. a component's vertex displacements).
pub fn shape_metric(columns: &[Vec<f64>]) -> Mat<f64> {
    let k = columns.len();
    let n = columns.first().map_or(1, |c| (c.len() / 3).max(1));
    let mut g = Mat::<f64>::zeros(k, k);
    for i in 0..k {
        for j in i..k {
            let d: f64 = columns[i].iter().zip(&columns[j]).map(|(a, b)| a * b).sum::<f64>() / n as f64;
            g[(i, j)] = d;
            g[(j, i)] = d;
        }
    }
    g
}

/// What the pull towards the start measures and how strong it is (module docs). K weights, G
/// the shape metric ([`shape_metric`]), m = trace(G)/K the mean squared motion of a vertex per
/// unit of one weight over the whole shape.
#[derive(Debug, Clone, Copy)]
pub enum Pull<'m> {
    /// `γ·(w − w0)ᵀM(w − w0)` for a metric M in the shape's units: the shape metric G (the whole
    /// shape's mean squared motion) or the data metric ([`data_metric`]). Its strength does not
    /// depend on where the pins are.
    Shape(&'m Mat<f64>),
    /// `γ·m·‖w − w0‖²`: the papers' pull on the weights, as strong as the shape metric's on
    /// average and likewise independent of where the pins are.
    Weights,
    /// `γ·s·‖w − w0‖²` with s the mean squared response of one weight *at the pins*: the papers'
    /// pull scaled by what the components do at the constrained vertices, so that its strength
    /// follows the pins (10× and more from vertex to vertex on a localized model). Kept for the
    /// control-point fit of `meshdeco eval`, whose control points cover the shape.
    AtPins,
}

/// The pull matrix (K × K) of `pull` for the data term `data` (its Hessian at the constrained
/// vertices; read by [`Pull::AtPins`] only), `mean_response` m (used by [`Pull::Weights`] and,
/// for a component the metric has no hold on, by [`Pull::Shape`]). The system adds it to its
/// Hessian ([`add_into`]) and its right-hand side takes `pull·w0`.
pub fn pull_matrix(data: &Mat<f64>, gamma: f64, pull: Pull<'_>, mean_response: f64) -> Result<Mat<f64>> {
    let k = data.nrows();
    let diagonal = |x: f64| Mat::<f64>::from_fn(k, k, |i, j| if i == j { x } else { 0.0 });
    let strength = gamma;
    Ok(match pull {
        Pull::AtPins => diagonal(gamma * (0..k).map(|i| data[(i, i)]).sum::<f64>() / k.max(1) as f64),
        Pull::Weights => diagonal(strength * mean_response),
        Pull::Shape(g) => {
            if g.nrows() != k || g.ncols() != k {
                return Err(Error::Invalid(format!(
                    "posing: a {}×{} shape metric for {k} weights",
                    g.nrows(),
                    g.ncols()
                )));
            }
            // A component that moves nothing keeps the weights pull (the metric has no hold on it).
            let floor = 1e-9 * mean_response;
            Mat::<f64>::from_fn(k, k, |i, j| {
                let x = strength * g[(i, j)];
                if i == j && g[(i, i)] <= floor { x + strength * mean_response } else { x }
            })
        }
    })
}

/// The data metric of [`PosePrior::Data`] (K × K, used as [`Pull::Shape`]): `m · (tr Σ / K) · (Σ + η (tr Σ / K) I)⁻¹`
/// with Σ the covariance of the training weights (`weights`: F × K, row-major), m the mean
/// response ([`linear_mean_response`]) and η = [`DATA_PRIOR_RIDGE`]. A weight change along a
/// direction the training poses vary in is cheap, one they never take is dear: the Gaussian
/// prior of the training weights (PCA posing's own), scaled so that for Σ ∝ I it is
/// [`Pull::Weights`] (up to 1/(1 + η)). Errors when there are no training weights.
pub fn data_metric(weights: &[f64], k: usize, m: f64) -> Result<Mat<f64>> {
    let f = weights.len() / k.max(1);
    if k == 0 || f < 2 || weights.len() != f * k {
        return Err(Error::Invalid(format!(
            "`prior` data: the model keeps {} training weights for {k} components; the data prior needs the weights of at least two training frames",
            weights.len()
        )));
    }
    let mean: Vec<f64> = (0..k).map(|j| (0..f).map(|i| weights[i * k + j]).sum::<f64>() / f as f64).collect();
    let mut s = Mat::<f64>::from_fn(k, k, |a, b| {
        (0..f).map(|i| (weights[i * k + a] - mean[a]) * (weights[i * k + b] - mean[b])).sum::<f64>() / f as f64
    });
    let tr = (0..k).map(|i| s[(i, i)]).sum::<f64>() / k as f64;
    if !(tr.is_finite() && tr > 0.0) {
        return Err(Error::Invalid(
            "`prior` data: the training weights do not vary; use --prior shape or weights".into(),
        ));
    }
    for i in 0..k {
        s[(i, i)] += DATA_PRIOR_RIDGE * tr;
    }
    let llt = factor_spd(s, "posing (data prior)")?;
    let mut inv = Mat::<f64>::identity(k, k);
    llt.solve_in_place(inv.as_mut());
    Ok(Mat::<f64>::from_fn(k, k, |a, b| m * tr * inv[(a, b)]))
}

/// η of [`data_metric`]: the ridge added to the training weights' covariance, as a share of its
/// mean variance, so that a direction no training pose takes is dear but not forbidden. 0.1 (of
/// 0.01 / 0.1 / 1, on validation drags: docs/posing-drag-bench.md): posed ÷ null within 0.02 of
/// the best at three and ten pins on SCAPE PCA, SPLOCS signed and non-negative and the face's
/// SPLOCS.
pub const DATA_PRIOR_RIDGE: f64 = 0.1;

/// m = trace(G)/K of a shape metric.
fn metric_mean(g: &Mat<f64>) -> f64 {
    (0..g.nrows()).map(|i| g[(i, i)]).sum::<f64>() / g.nrows().max(1) as f64
}

/// `h += m` (same shape).
fn add_into(h: &mut Mat<f64>, m: &Mat<f64>) {
    for i in 0..h.nrows() {
        for j in 0..h.ncols() {
            h[(i, j)] += m[(i, j)];
        }
    }
}

/// `pull · w0`.
fn pull_times(pull: &Mat<f64>, w0: &[f64]) -> Vec<f64> {
    (0..pull.nrows()).map(|i| (0..pull.ncols()).map(|j| pull[(i, j)] * w0[j]).sum()).collect()
}

impl PoseConfig {
    /// Checks γ and β (finite, ≥ 0).
    pub fn validate(&self) -> Result<()> {
        for (k, v) in [("gamma", self.gamma), ("beta", self.beta)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::config(k, format!("{k} ({v}) must be finite and non-negative")));
            }
        }
        Ok(())
    }
}

fn check_vertices(vertices: &[usize], n: usize) -> Result<()> {
    if vertices.is_empty() {
        return Err(Error::Invalid("posing: no constrained vertex given".into()));
    }
    if let Some(&v) = vertices.iter().find(|&&v| v >= n) {
        return Err(Error::Invalid(format!("posing: constrained vertex {v} out of range ({n} vertices)")));
    }
    Ok(())
}

fn check_targets(targets: &[Vec3], n: usize) -> Result<()> {
    if targets.len() != n {
        return Err(Error::Invalid(format!("posing: {} targets for {n} constrained vertices", targets.len())));
    }
    if let Some(i) = targets.iter().position(|t| t.iter().any(|x| !x.is_finite())) {
        return Err(Error::Invalid(format!("posing: target {i} is not finite ({:?})", targets[i])));
    }
    Ok(())
}

fn check_weights(w0: &[f64], p: usize) -> Result<()> {
    if w0.len() != p {
        return Err(Error::Invalid(format!("posing: {} previous weights, the model has {p}", w0.len())));
    }
    if let Some(i) = w0.iter().position(|x| !x.is_finite()) {
        return Err(Error::Invalid(format!("posing: previous weight {i} is not finite ({})", w0[i])));
    }
    Ok(())
}

/// Lewis–Anjyo posing of a [`LinearModel`] (paper 002 Eq. 8): w minimises
/// `Σ_k ‖offset_k + Σ_j w_j C_j,k − t_k‖² + γ·s·(w − w0)ᵀP(w − w0)` subject to the model's
/// weight constraint (`Nonnegative`: w ≥ 0, exact active-set NNLS; otherwise unconstrained), P
/// the identity (the paper) or the scaled shape metric (module docs).
pub struct LinearPoser<'a> {
    model: &'a LinearModel,
    vertices: Vec<usize>,
    hessian: Mat<f64>,
    llt: faer::linalg::solvers::Llt<f64>,
    pull: Mat<f64>,
}

/// The shape metric of a per-vertex [`LinearModel`] (its components are the columns of B).
pub fn linear_shape_metric(model: &LinearModel) -> Mat<f64> {
    let cols: Vec<Vec<f64>> = (0..model.n_components).map(|j| model.component(j).to_vec()).collect();
    shape_metric(&cols)
}

/// m = trace(G)/K of a per-vertex [`LinearModel`] (without building G): the mean over its
/// components and vertices of a component's squared vertex motion.
pub fn linear_mean_response(model: &LinearModel) -> f64 {
    let k = model.n_components.max(1);
    let n = model.n_elements.max(1);
    model.components.iter().map(|x| x * x).sum::<f64>() / (n * k) as f64
}

impl<'a> LinearPoser<'a> {
    /// Assembles and factorises `C_S C_Sᵀ + γ s I` for the constrained `vertices` (the papers'
    /// weights prior scaled at the pins, [`Pull::AtPins`]: the control-point fit's).
    pub fn new(model: &'a LinearModel, vertices: &[usize], config: &PoseConfig) -> Result<Self> {
        Self::with_pull(model, vertices, config, Pull::AtPins)
    }

    /// As [`LinearPoser::new`], with the pull of posing: measured by the shape `metric` when
    /// given ([`linear_shape_metric`]; K × K; [`Pull::Shape`]), else on the weights
    /// ([`Pull::Weights`]); either as strong wherever the pins are.
    pub fn with_metric(
        model: &'a LinearModel,
        vertices: &[usize],
        config: &PoseConfig,
        metric: Option<&Mat<f64>>,
    ) -> Result<Self> {
        Self::with_pull(model, vertices, config, metric.map_or(Pull::Weights, Pull::Shape))
    }

    /// Assembles and factorises the system of `pull` for the constrained `vertices`.
    pub fn with_pull(model: &'a LinearModel, vertices: &[usize], config: &PoseConfig, pull: Pull<'_>) -> Result<Self> {
        config.validate()?;
        model.validate()?;
        if model.width != 3 {
            return Err(Error::Invalid(format!(
                "posing needs a per-vertex model (width 3), got width {}",
                model.width
            )));
        }
        check_vertices(vertices, model.n_elements)?;
        let k = model.n_components;
        let mut h = Mat::<f64>::zeros(k, k);
        for &v in vertices {
            for i in 0..k {
                let ci = &model.component(i)[3 * v..3 * v + 3];
                for j in 0..k {
                    let cj = &model.component(j)[3 * v..3 * v + 3];
                    h[(i, j)] += ci[0] * cj[0] + ci[1] * cj[1] + ci[2] * cj[2];
                }
            }
        }
        let mean = match pull {
            Pull::Shape(g) => metric_mean(g),
            Pull::Weights => linear_mean_response(model),
            Pull::AtPins => 0.0,
        };
        let pull = pull_matrix(&h, config.gamma, pull, mean)?;
        add_into(&mut h, &pull);
        let llt = factor_spd(h.clone(), "posing")?;
        Ok(LinearPoser { model, vertices: vertices.to_vec(), hessian: h, llt, pull })
    }

    /// New weights (K) for `targets` (one per constrained vertex, data units) starting from
    /// `w0` (K weights, e.g. the current pose's).
    pub fn solve(&self, targets: &[Vec3], w0: &[f64]) -> Result<Vec<f64>> {
        let m = self.model;
        let k = m.n_components;
        check_targets(targets, self.vertices.len())?;
        check_weights(w0, k)?;
        let mut b = pull_times(&self.pull, w0);
        for (&v, t) in self.vertices.iter().zip(targets) {
            for (j, bj) in b.iter_mut().enumerate() {
                let c = &m.component(j)[3 * v..3 * v + 3];
                *bj += (0..3).map(|x| c[x] * (t[x] - m.offset[3 * v + x])).sum::<f64>();
            }
        }
        if m.constraint == WeightConstraint::Nonnegative {
            let mut g = self.hessian.clone();
            let md = (0..k).map(|i| g[(i, i)]).fold(0.0f64, f64::max);
            for i in 0..k {
                g[(i, i)] += 1e-12 * md.max(f64::MIN_POSITIVE) + 1e-300;
            }
            return nnls_gram(&g, &b);
        }
        let mut rhs = Mat::<f64>::from_fn(k, 1, |i, _| b[i]);
        self.llt.solve_in_place(rhs.as_mut());
        Ok((0..k).map(|i| rhs[(i, 0)]).collect())
    }
}

/// One-shot [`LinearPoser`]: weights meeting `targets` at `vertices` from `w0`.
pub fn pose_linear(
    model: &LinearModel,
    vertices: &[usize],
    targets: &[Vec3],
    w0: &[f64],
    config: &PoseConfig,
) -> Result<Vec<f64>> {
    LinearPoser::new(model, vertices, config)?.solve(targets, w0)
}

/// Region PCA posing (paper 002 Eq. 9/10): ζ minimises the data term at the constrained
/// vertices in every region containing them, β × the boundary consistency of Eq. 6 and
/// γ·s·‖ζ − ζ0‖². Reconstruct with [`RegionPcaModel::reconstruct`] (boundary averaging).
pub struct RegionPoser<'a> {
    model: &'a RegionPcaModel,
    vertices: Vec<usize>,
    memberships: Vec<Vec<(usize, usize)>>,
    pairs: Vec<SharedPair>,
    llt: faer::linalg::solvers::Llt<f64>,
    beta: f64,
    pull: Mat<f64>,
}

/// The shape metric of a [`RegionPcaModel`]: the columns of B are the reconstructions of the
/// unit coefficient vectors minus that of zero (boundary averaging included).
pub fn region_shape_metric(model: &RegionPcaModel) -> Result<Mat<f64>> {
    let p = model.n_components();
    let base = model.reconstruct(&vec![0.0; p])?;
    let mut cols = Vec::with_capacity(p);
    let mut e = vec![0.0; p];
    for i in 0..p {
        e[i] = 1.0;
        let x = model.reconstruct(&e)?;
        e[i] = 0.0;
        cols.push(x.iter().zip(&base).map(|(a, b)| a - b).collect());
    }
    Ok(shape_metric(&cols))
}

/// m = trace(G)/P of a [`RegionPcaModel`] (without building G, [`region_shape_metric`]): a
/// coefficient moves the vertices of its region by its basis vector, each divided by the number
/// of regions sharing the vertex (the boundary averaging of [`RegionPcaModel::reconstruct`]).
pub fn region_mean_response(model: &RegionPcaModel) -> f64 {
    let shared: Vec<f64> = model.memberships().iter().map(|m| m.len().max(1) as f64).collect();
    let mut total = 0.0;
    for r in &model.regions {
        for k in 0..r.n_components {
            for (l, &v) in r.vertices.iter().enumerate() {
                total += (0..3).map(|c| r.at(k, l, c).powi(2)).sum::<f64>() / (shared[v] * shared[v]);
            }
        }
    }
    total / (model.n_vertices.max(1) * model.n_components().max(1)) as f64
}

impl<'a> RegionPoser<'a> {
    /// Assembles and factorises the Eq. 10 system for the constrained `vertices` (the papers'
    /// weights prior scaled at the pins, [`Pull::AtPins`]: the control-point fit's).
    pub fn new(model: &'a RegionPcaModel, vertices: &[usize], config: &PoseConfig) -> Result<Self> {
        Self::with_pull(model, vertices, config, Pull::AtPins)
    }

    /// As [`RegionPoser::new`], with the pull of posing: measured by the shape `metric` when
    /// given ([`region_shape_metric`]; P × P; [`Pull::Shape`]), else on the coefficients
    /// ([`Pull::Weights`]); either as strong wherever the pins are.
    pub fn with_metric(
        model: &'a RegionPcaModel,
        vertices: &[usize],
        config: &PoseConfig,
        metric: Option<&Mat<f64>>,
    ) -> Result<Self> {
        Self::with_pull(model, vertices, config, metric.map_or(Pull::Weights, Pull::Shape))
    }

    /// Assembles and factorises the Eq. 10 system of `pull` for the constrained `vertices`.
    pub fn with_pull(
        model: &'a RegionPcaModel,
        vertices: &[usize],
        config: &PoseConfig,
        pull: Pull<'_>,
    ) -> Result<Self> {
        config.validate()?;
        check_vertices(vertices, model.n_vertices)?;
        let p = model.n_components();
        let off = model.offsets();
        let all = model.memberships();
        let memberships: Vec<Vec<(usize, usize)>> = vertices.iter().map(|&v| all[v].clone()).collect();
        let mut h = Mat::<f64>::zeros(p, p);
        for mem in &memberships {
            for &(i, l) in mem {
                model.add_data_vertex(i, l, off[i], &mut h);
            }
        }
        let mean = match pull {
            Pull::Shape(g) => metric_mean(g),
            Pull::Weights => region_mean_response(model),
            Pull::AtPins => 0.0,
        };
        // The pull is scaled by the data term alone (before the boundary term).
        let pull = pull_matrix(&h, config.gamma, pull, mean)?;
        let pairs = model.shared_pairs();
        let mut dummy = vec![0.0; p];
        model.add_boundary(&pairs, config.beta, &mut h, &mut dummy);
        add_into(&mut h, &pull);
        let llt = factor_spd(h, "region posing")?;
        Ok(RegionPoser { model, vertices: vertices.to_vec(), memberships, pairs, llt, beta: config.beta, pull })
    }

    /// New coefficients ζ for `targets` (one per constrained vertex) starting from `zeta0`.
    pub fn solve(&self, targets: &[Vec3], zeta0: &[f64]) -> Result<Vec<f64>> {
        let m = self.model;
        let p = m.n_components();
        check_targets(targets, self.vertices.len())?;
        check_weights(zeta0, p)?;
        let off = m.offsets();
        let mut rhs = pull_times(&self.pull, zeta0);
        for (mem, t) in self.memberships.iter().zip(targets) {
            for &(i, l) in mem {
                let r = &m.regions[i];
                for (c, tc) in t.iter().enumerate() {
                    let d = tc - r.mean[3 * l + c];
                    for k in 0..r.n_components {
                        rhs[off[i] + k] += r.at(k, l, c) * d;
                    }
                }
            }
        }
        boundary_rhs(m, &self.pairs, self.beta, &mut rhs);
        let mut b = Mat::<f64>::from_fn(p, 1, |i, _| rhs[i]);
        self.llt.solve_in_place(b.as_mut());
        Ok((0..p).map(|i| b[(i, 0)]).collect())
    }
}

/// One-shot [`RegionPoser`].
pub fn pose_region(
    model: &RegionPcaModel,
    vertices: &[usize],
    targets: &[Vec3],
    zeta0: &[f64],
    config: &PoseConfig,
) -> Result<Vec<f64>> {
    RegionPoser::new(model, vertices, config)?.solve(targets, zeta0)
}

/// Share of the displacement energy Σ_v ‖after_v − before_v‖² (N·3 arrays) that falls on
/// `inside` vertices; 0 when nothing moved.
pub fn energy_share(before: &[f64], after: &[f64], inside: &[usize]) -> f64 {
    let e = |v: usize| (0..3).map(|c| (after[3 * v + c] - before[3 * v + c]).powi(2)).sum::<f64>();
    let total: f64 = (0..before.len() / 3).map(e).sum();
    if total <= 0.0 {
        return 0.0;
    }
    inside.iter().map(|&v| e(v)).sum::<f64>() / total
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::graph_distance::EdgeGraph;
    use crate::methods::region_pca::tests::bumps;
    use crate::methods::region_pca::{RegionPcaConfig, RegionPcaModel};
    use crate::methods::segmentation::{SegmentationConfig, segment};
    use crate::methods::{DataMatrix, Pca, PcaCentering, PcaConfig, SplocsConfig, SplocsSolver, SupportDistances};
    use crate::synthetic;

    /// A 6-vertex model with 3 components: A is 1 at vertex 0 (x) and nothing else; B is 0.5 at
    /// vertex 0 and 0.1 at vertices 1..5; C is 0.2 at vertex 0 and 2 at vertices 1..5 (small at
    /// the pin, large elsewhere: the weights prior likes it, the shape prior does not).
    fn toy(constraint: WeightConstraint) -> LinearModel {
        let n = 6;
        let mut comps = vec![0.0; 3 * 3 * n];
        comps[0] = 1.0;
        comps[3 * n] = 0.5;
        comps[2 * 3 * n] = 0.2;
        for v in 1..n {
            comps[3 * n + 3 * v] = 0.1;
            comps[2 * 3 * n + 3 * v] = 2.0;
        }
        LinearModel {
            n_elements: n,
            width: 3,
            n_components: 3,
            n_frames: 1,
            components: comps,
            weights: vec![0.0; 3],
            offset: vec![0.0; 3 * n],
            constraint,
        }
    }

    /// The objective of [`LinearPoser::with_metric`] at w (data term + γ·s·(w−w0)ᵀP(w−w0)).
    fn objective(
        m: &LinearModel,
        v: &[usize],
        t: &[Vec3],
        w0: &[f64],
        w: &[f64],
        gamma: f64,
        g: Option<&Mat<f64>>,
    ) -> f64 {
        let k = m.n_components;
        let mut h = Mat::<f64>::zeros(k, k);
        for &vv in v {
            for i in 0..k {
                for j in 0..k {
                    h[(i, j)] += (0..3).map(|c| m.component(i)[3 * vv + c] * m.component(j)[3 * vv + c]).sum::<f64>();
                }
            }
        }
        let pull = match g {
            Some(g) => pull_matrix(&h, gamma, Pull::Shape(g), metric_mean(g)).unwrap(),
            None => pull_matrix(&h, gamma, Pull::Weights, linear_mean_response(m)).unwrap(),
        };
        let mut data = 0.0;
        for (&vv, tt) in v.iter().zip(t) {
            for (c, &tc) in tt.iter().enumerate() {
                let x = m.offset[3 * vv + c] + (0..k).map(|j| w[j] * m.component(j)[3 * vv + c]).sum::<f64>();
                data += (x - tc).powi(2);
            }
        }
        let d: Vec<f64> = w.iter().zip(w0).map(|(a, b)| a - b).collect();
        data + (0..k).map(|i| (0..k).map(|j| d[i] * pull[(i, j)] * d[j]).sum::<f64>()).sum::<f64>()
    }

    #[test]
    fn shape_prior_solves_its_normal_equations_and_keeps_motion_local() {
        let m = toy(WeightConstraint::Signed);
        let g = linear_shape_metric(&m);
        let (v, t, w0) = ([0usize], [[1.0, 0.0, 0.0]], [0.1, -0.2, 0.05]);
        let cfg = PoseConfig { gamma: 0.025, beta: 0.0 };
        let w = LinearPoser::with_metric(&m, &v, &cfg, Some(&g)).unwrap().solve(&t, &w0).unwrap();
        // Stationary: every partial derivative of the objective (central differences) is ~0.
        for i in 0..3 {
            let e = 1e-6;
            let mut a = w.clone();
            let mut b = w.clone();
            a[i] += e;
            b[i] -= e;
            let d = (objective(&m, &v, &t, &w0, &a, 0.025, Some(&g)) - objective(&m, &v, &t, &w0, &b, 0.025, Some(&g)))
                / (2.0 * e);
            assert!(d.abs() < 1e-6, "∂/∂w{i} = {d} at the shape prior's solution {w:?}");
        }
        // The weights prior buys the pin with C (0.2 at the pin, 2 elsewhere) far more than the
        // shape prior does: collateral motion at vertex 1.
        let ww = LinearPoser::new(&m, &v, &cfg).unwrap().solve(&t, &[0.0; 3]).unwrap();
        let ws = LinearPoser::with_metric(&m, &v, &cfg, Some(&g)).unwrap().solve(&t, &[0.0; 3]).unwrap();
        let motion = |w: &[f64]| (0..3).map(|j| w[j] * m.component(j)[3]).sum::<f64>().abs();
        assert!(
            motion(&ws) < 0.25 * motion(&ww),
            "collateral motion: shape {} vs weights {}",
            motion(&ws),
            motion(&ww)
        );
        let landing = |w: &[f64]| ((0..3).map(|j| w[j] * m.component(j)[0]).sum::<f64>() - 1.0).abs();
        assert!(landing(&ws) < 0.05, "shape prior lands {}", landing(&ws));
    }

    #[test]
    fn isotropic_metric_is_the_weights_prior_and_bounds_hold() {
        let m = toy(WeightConstraint::Signed);
        let cfg = PoseConfig { gamma: 0.025, beta: 0.0 };
        let mean = linear_mean_response(&m);
        let iso = Mat::<f64>::from_fn(3, 3, |i, j| if i == j { mean } else { 0.0 });
        let (v, t, w0) = ([0usize, 2], [[0.8, 0.1, 0.0], [0.0, 0.3, 0.0]], [0.3, 0.0, -0.1]);
        let a = LinearPoser::with_metric(&m, &v, &cfg, None).unwrap().solve(&t, &w0).unwrap();
        let b = LinearPoser::with_metric(&m, &v, &cfg, Some(&iso)).unwrap().solve(&t, &w0).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-12, "{a:?} vs {b:?}");
        }
        // Non-negative weights stay non-negative (a target only negative weights reach) and
        // satisfy the KKT conditions: ∂f/∂w_i ≈ 0 where w_i > 0, ≥ 0 where w_i = 0.
        let m = toy(WeightConstraint::Nonnegative);
        let g = linear_shape_metric(&m);
        let t = [[-1.0, 0.0, 0.0]];
        let w = LinearPoser::with_metric(&m, &[0], &cfg, Some(&g)).unwrap().solve(&t, &[0.0; 3]).unwrap();
        assert!(w.iter().all(|&x| x >= 0.0), "{w:?}");
        for i in 0..3 {
            let e = 1e-6;
            let mut a = w.clone();
            a[i] += e;
            let d = (objective(&m, &[0], &t, &[0.0; 3], &a, 0.025, Some(&g))
                - objective(&m, &[0], &t, &[0.0; 3], &w, 0.025, Some(&g)))
                / e;
            if w[i] > 1e-9 {
                assert!(d.abs() < 1e-4, "∂/∂w{i} = {d} at an interior weight");
            } else {
                assert!(d > -1e-4, "∂/∂w{i} = {d} < 0 at a bound: moving off it would help");
            }
        }
        // A metric of the wrong size is refused.
        let bad = Mat::<f64>::zeros(2, 2);
        assert!(LinearPoser::with_metric(&m, &[0], &cfg, Some(&bad)).is_err());
    }

    struct Graph(EdgeGraph);
    impl SupportDistances for Graph {
        fn n_elements(&self) -> usize {
            self.0.n_vertices()
        }
        fn distances(&self, centers: &[usize]) -> Result<Vec<f64>> {
            Ok(self.0.distances(centers))
        }
    }

    /// Centre vertex of planted bump `b` (largest displacement over the frames).
    fn bump_centre(b: usize, d: &[f64], f: usize, n: usize) -> (usize, Vec<usize>) {
        let p = &synthetic::planted_regions("synthetic:bumps").unwrap()[b];
        let mut best = (0, -1.0);
        for &v in &p.vertices {
            let m = (0..f).map(|r| (0..3).map(|c| d[r * 3 * n + 3 * v + c].powi(2)).sum::<f64>()).fold(0.0, f64::max);
            if m > best.1 {
                best = (v, m);
            }
        }
        (best.0, p.vertices.clone())
    }

    /// Drag `v` outward by `amount` from the model's state `x0`; returns (landing error / drag
    /// distance, new state).
    fn drag_check(x0: &[f64], v: usize, dir: Vec3, amount: f64, new: &dyn Fn(&[Vec3]) -> Vec<f64>) -> (f64, Vec<f64>) {
        let t = [x0[3 * v] + amount * dir[0], x0[3 * v + 1] + amount * dir[1], x0[3 * v + 2] + amount * dir[2]];
        let x = new(&[t]);
        let err = ((0..3).map(|c| (x[3 * v + c] - t[c]).powi(2)).sum::<f64>()).sqrt();
        (err / amount, x)
    }

    fn radial(rest: &[Vec3], v: usize) -> Vec3 {
        let p = rest[v];
        let l = (p[0] * p[0] + p[1] * p[1]).sqrt();
        [p[0] / l, p[1] / l, 0.0]
    }

    #[test]
    fn region_pca_drag_lands_and_stays_local() {
        let (d, f, n, faces, rest) = bumps();
        // Automatic region count (k grown until a cluster is not compact, at most 8).
        let (nr, beta, gamma) = (None, 1.0, 0.025);
        let seg = segment(
            &rest,
            &faces,
            &d,
            f,
            &SegmentationConfig { regions: nr, max_regions: 8, restarts: 4, ..Default::default() },
        )
        .unwrap();
        let model = RegionPcaModel::fit(
            DataMatrix::new(&d, f, n, 3).unwrap(),
            &seg.regions,
            &RegionPcaConfig { components: 3 * seg.n_regions(), beta },
        )
        .unwrap();
        let zeta0 = model.encode(&d[..3 * n]).unwrap();
        let x0 = model.reconstruct(&zeta0).unwrap();
        for b in 0..3 {
            let (v, _) = bump_centre(b, &d, f, n);
            let poser = RegionPoser::new(&model, &[v], &PoseConfig { gamma, beta }).unwrap();
            let (rel, x) = drag_check(&x0, v, radial(&rest, v), 0.03, &|t| {
                model.reconstruct(&poser.solve(t, &zeta0).unwrap()).unwrap()
            });
            let region = &seg.regions[seg.labels[v]];
            let share = energy_share(&x0, &x, region);
            let (_, planted) = bump_centre(b, &d, f, n);
            eprintln!(
                "M={} region PCA bump {b}: landing error {:.2}% of drag, energy share in its region {:.3}, in the planted bump {:.3}",
                seg.n_regions(),
                100.0 * rel,
                share,
                energy_share(&x0, &x, &planted)
            );
            assert!(rel < 0.05, "bump {b}: landing error {rel}");
            assert!(share >= 0.8, "bump {b}: share {share}");
        }
    }

    #[test]
    fn splocs_and_pca_drag_land_splocs_stays_local() {
        let (d, f, n, faces, rest) = bumps();
        let x = DataMatrix::new(&d, f, n, 3).unwrap();
        let graph = Graph(EdgeGraph::new(&rest, &faces));
        let cfg = SplocsConfig { components: 3, support: [0.05, 0.3], sparsity: 2.0, ..Default::default() };
        let splocs = SplocsSolver::fit(x, &graph, &cfg, |_, _| {}).unwrap().model;
        let pca = Pca::fit(x, &PcaConfig { components: 3, centering: PcaCentering::None }).unwrap();
        for b in 0..3 {
            let (v, planted) = bump_centre(b, &d, f, n);
            for (name, model) in [("splocs", &splocs), ("pca", &pca)] {
                let w0 = vec![0.0; model.n_components];
                let x0 = model.synthesize(&w0).unwrap();
                let poser = LinearPoser::new(model, &[v], &PoseConfig::default()).unwrap();
                let (rel, xn) = drag_check(&x0, v, radial(&rest, v), 0.03, &|t| {
                    model.synthesize(&poser.solve(t, &w0).unwrap()).unwrap()
                });
                // Support of the component that dominates the vertex.
                let kmax = (0..model.n_components)
                    .max_by(|&a, &c| model.component_group_norms(a)[v].total_cmp(&model.component_group_norms(c)[v]))
                    .unwrap();
                let norms = model.component_group_norms(kmax);
                let top = norms.iter().cloned().fold(0.0, f64::max);
                let support: Vec<usize> = (0..n).filter(|&u| norms[u] > 1e-3 * top).collect();
                let share = energy_share(&x0, &xn, &support);
                eprintln!(
                    "{name} bump {b}: landing error {:.2}% of drag, energy share in the dominant component's support {:.3} ({} vertices), in the planted bump {:.3}",
                    100.0 * rel,
                    share,
                    support.len(),
                    energy_share(&x0, &xn, &planted)
                );
                assert!(rel < 0.05, "{name} bump {b}: landing error {rel}");
                if name == "splocs" {
                    assert!(share >= 0.8, "splocs bump {b}: share {share}");
                    assert!(poser.solve(&[[0.0; 3]], &w0).unwrap().iter().all(|&w| w >= 0.0));
                }
            }
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        let (d, f, n, _, _) = bumps();
        let pca = Pca::fit(
            DataMatrix::new(&d, f, n, 3).unwrap(),
            &PcaConfig { components: 3, centering: PcaCentering::Mean },
        )
        .unwrap();
        assert!(LinearPoser::new(&pca, &[n], &PoseConfig::default()).is_err());
        assert!(
            LinearPoser::new(&pca, &[0], &PoseConfig { gamma: -1.0, beta: 1.0 })
                .err()
                .unwrap()
                .to_string()
                .contains("-1")
        );
        let p = LinearPoser::new(&pca, &[0], &PoseConfig::default()).unwrap();
        assert!(p.solve(&[[f64::NAN, 0.0, 0.0]], &[0.0; 3]).is_err());
        assert!(p.solve(&[[0.0; 3]], &[0.0; 2]).is_err());
    }

    /// One component, 0.1 at vertex 0 (x), 1 at vertex 1 and 0.5 at vertices 2..5: vertex 0 is
    /// a pin where the component is weak, vertex 1 one where it is strong.
    fn weak_and_strong() -> LinearModel {
        let n = 6;
        let mut comps = vec![0.0; 3 * n];
        comps[0] = 0.1;
        comps[3] = 1.0;
        for v in 2..n {
            comps[3 * v] = 0.5;
        }
        LinearModel {
            n_elements: n,
            width: 3,
            n_components: 1,
            n_frames: 2,
            components: comps,
            weights: vec![-1.0, 1.0],
            offset: vec![0.0; 3 * n],
            constraint: WeightConstraint::Signed,
        }
    }

    /// The pull of posing is as strong wherever the pin is: its matrix is the same for a pin
    /// where the component is weak and where it is strong (the papers' pull scaled at the pins
    /// differs 100×), and the same drag at either pin moves no vertex more than 1.5 × the drag
    /// (γ 1), where the pull scaled at the pins buys the weak pin's drag with a weight ten times
    /// as large and swings the rest of the shape four and more times the drag.
    #[test]
    fn posing_pull_does_not_depend_on_the_pin() {
        let m = weak_and_strong();
        let g = linear_shape_metric(&m);
        let data = |v: usize| Mat::<f64>::from_fn(1, 1, |_, _| m.components[3 * v].powi(2));
        let mean = linear_mean_response(&m);
        for pull in [Pull::Weights, Pull::Shape(&g)] {
            let a = pull_matrix(&data(0), 0.1, pull, mean).unwrap();
            let b = pull_matrix(&data(1), 0.1, pull, mean).unwrap();
            assert!((a[(0, 0)] - b[(0, 0)]).abs() <= 1e-12 * b[(0, 0)].abs(), "{pull:?}: {a:?} vs {b:?}");
            assert!(a[(0, 0)] > 0.0);
        }
        let a = pull_matrix(&data(0), 0.1, Pull::AtPins, 0.0).unwrap();
        let b = pull_matrix(&data(1), 0.1, Pull::AtPins, 0.0).unwrap();
        assert!((b[(0, 0)] / a[(0, 0)] - 100.0).abs() < 1e-6, "{a:?} vs {b:?}");
        let cfg = PoseConfig { gamma: 1.0, beta: 0.0 };
        let drag = 0.1;
        // Largest motion of any vertex ÷ the drag, for the drag along x at pin v.
        let motion = |v: usize, pull: Pull<'_>| {
            let w = LinearPoser::with_pull(&m, &[v], &cfg, pull).unwrap().solve(&[[drag, 0.0, 0.0]], &[0.0]).unwrap();
            (0..6).map(|u| (w[0] * m.components[3 * u]).abs()).fold(0.0, f64::max) / drag
        };
        for pull in [Pull::Weights, Pull::Shape(&g)] {
            let (weak, strong) = (motion(0, pull), motion(1, pull));
            assert!(weak <= 1.5 && strong <= 1.5, "{pull:?}: weak pin {weak} × the drag, strong pin {strong} ×");
            assert!(weak > 0.0 && strong > 0.0);
        }
        let (weak, strong) = (motion(0, Pull::AtPins), motion(1, Pull::AtPins));
        assert!(weak >= 4.0 * strong && weak >= 4.0, "pull at the pins: weak pin {weak}, strong pin {strong}");
    }

    /// The data prior charges a weight change along a direction the training weights never take
    /// more than one along which they vary, and refuses a model without training weights.
    #[test]
    fn data_prior_follows_the_training_weights() {
        // Two components; the training weights vary along the first only.
        let w = [1.0, 0.0, -1.0, 0.0, 0.5, 0.0, -0.5, 0.0];
        let g = data_metric(&w, 2, 1.0).unwrap();
        assert!(g[(1, 1)] > 5.0 * g[(0, 0)], "{g:?}");
        assert!(g[(0, 1)].abs() < 1e-12);
        let err = data_metric(&[1.0, 2.0], 2, 1.0).unwrap_err().to_string();
        assert!(err.contains("`prior` data"), "{err}");
        let err = data_metric(&[0.0; 8], 2, 1.0).unwrap_err().to_string();
        assert!(err.contains("do not vary"), "{err}");
    }
}
