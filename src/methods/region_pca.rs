//! Region-based PCA (Tena et al. 2011, §3.1): an independent PCA per mesh region, regions sharing
//! boundary vertices (see [`super::segmentation`]), coupled by the paper's Eq. 6/7.
//!
//! Data: rows of N·3 numbers (vertex v, coordinate c at `3v + c`; vertex displacements or
//! positions, any length units). Region i models the sub-vector of its N_i vertices as
//! `μ_i + B_iᵀ c_i` with mean μ_i (3N_i) and orthonormal basis B_i (P_i × 3N_i, row-major rows =
//! components). Components per region: the **total budget** K is split evenly, P_i = ⌊K/M⌋ plus
//! one for the first K mod M regions, each capped at min(F, 3N_i); what the caps leave over goes
//! to the regions with room left, so the total is exactly K. A K above Σ_i min(F, 3N_i) is
//! refused (naming that capacity).
//!
//! Encoding (Eq. 6/7, including the means the paper's notation folds away): ζ = [c_1; …; c_M]
//! minimises `Σ_i ‖x_i − μ_i − B_iᵀc_i‖² + β Σ_{i<j} Σ_{v shared by i, j} ‖(μ_i + B_iᵀc_i)_v −
//! (μ_j + B_jᵀc_j)_v‖²`, a symmetric positive definite P × P system (P = Σ P_i) factorised once.
//! Reconstruction averages every shared vertex over the regions containing it.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use serde::{Deserialize, Serialize};

use super::{DataMatrix, Pca, PcaCentering, PcaConfig};
use crate::{Error, Result};

/// Region PCA hyperparameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionPcaConfig {
    /// Total component budget K over all regions (≥ number of regions).
    pub components: usize,
    /// β ≥ 0: weight of boundary consistency in encoding (Eq. 6). Default 1.
    pub beta: f64,
}

impl Default for RegionPcaConfig {
    fn default() -> Self {
        RegionPcaConfig { components: 50, beta: 1.0 }
    }
}

impl RegionPcaConfig {
    /// Checks K ≥ 1 and β finite, ≥ 0.
    pub fn validate(&self) -> Result<()> {
        if self.components == 0 {
            return Err(Error::config("components", "components (0) must be at least 1"));
        }
        if !(self.beta.is_finite() && self.beta >= 0.0) {
            return Err(Error::config("beta", format!("beta ({}) must be finite and non-negative", self.beta)));
        }
        Ok(())
    }
}

/// One region's sub-model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionBasis {
    /// Sorted global vertex indices (N_i).
    pub vertices: Vec<usize>,
    /// Mean, 3N_i numbers.
    pub mean: Vec<f64>,
    /// P_i × 3N_i orthonormal components, row-major.
    pub basis: Vec<f64>,
    /// P_i.
    pub n_components: usize,
}

impl RegionBasis {
    /// Entry of component p at local vertex l, coordinate c.
    #[inline]
    pub fn at(&self, p: usize, l: usize, c: usize) -> f64 {
        self.basis[p * 3 * self.vertices.len() + 3 * l + c]
    }
}

/// A fitted region PCA model (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionPcaModel {
    /// Number of mesh vertices N.
    pub n_vertices: usize,
    /// Sub-models, one per region.
    pub regions: Vec<RegionBasis>,
    /// β used for encoding.
    pub beta: f64,
}

/// A vertex shared by regions i and j: (i, local index in i, j, local index in j), i < j.
pub(crate) type SharedPair = (usize, usize, usize, usize);

impl RegionPcaModel {
    /// Fits one PCA per region of `regions` (vertex lists covering every vertex, e.g.
    /// [`super::segmentation::Segmentation::regions`]) to `x` (F × N·3, width 3).
    pub fn fit(x: DataMatrix<'_>, regions: &[Vec<usize>], config: &RegionPcaConfig) -> Result<Self> {
        config.validate()?;
        if x.width() != 3 {
            return Err(Error::Invalid(format!("region PCA needs 3 numbers per vertex, got width {}", x.width())));
        }
        let n = x.n_elements();
        let m = regions.len();
        if m == 0 || config.components < m {
            return Err(Error::config(
                "components",
                format!("components ({}) must be at least the number of regions ({m})", config.components),
            ));
        }
        let mut covered = vec![false; n];
        for r in regions {
            for &v in r {
                if v >= n {
                    return Err(Error::Invalid(format!("region vertex {v} out of range ({n} vertices)")));
                }
                covered[v] = true;
            }
        }
        if let Some(v) = covered.iter().position(|c| !c) {
            return Err(Error::Invalid(format!("vertex {v} belongs to no region")));
        }
        let f = x.n_rows();
        // Each region can give at most min(F, 3·N_r) components: refuse a budget beyond that
        // rather than train fewer components than the config says.
        let caps: Vec<usize> = regions
            .iter()
            .map(|r| {
                let mut v = r.clone();
                v.sort_unstable();
                v.dedup();
                f.min(3 * v.len()).max(1)
            })
            .collect();
        let capacity: usize = caps.iter().sum();
        if config.components > capacity {
            return Err(Error::config(
                "components",
                format!(
                    "components ({}) exceeds what region PCA can give on these data: {m} regions with at most min(training frames {f}, 3 × region size) components each, {capacity} in all; lower it to ≤ {capacity}",
                    config.components
                ),
            ));
        }
        // K split evenly (the first K mod M regions one more), each capped at its capacity; what
        // the caps leave over goes, one at a time, to the regions with room left.
        let mut counts: Vec<usize> =
            (0..m).map(|i| (config.components / m + usize::from(i < config.components % m)).min(caps[i])).collect();
        let mut left = config.components - counts.iter().sum::<usize>();
        while left > 0 {
            for i in 0..m {
                if left > 0 && counts[i] < caps[i] {
                    counts[i] += 1;
                    left -= 1;
                }
            }
        }
        let mut out = Vec::with_capacity(m);
        for (i, r) in regions.iter().enumerate() {
            let mut verts = r.clone();
            verts.sort_unstable();
            verts.dedup();
            let ni = verts.len();
            let mut sub = Vec::with_capacity(f * 3 * ni);
            for row in 0..f {
                let xr = x.row(row);
                for &v in &verts {
                    sub.extend_from_slice(&xr[3 * v..3 * v + 3]);
                }
            }
            let p = counts[i];
            debug_assert!(p <= f.min(3 * ni).max(1));
            let lm = Pca::fit(
                DataMatrix::new(&sub, f, ni, 3)?,
                &PcaConfig { components: p, centering: PcaCentering::Mean },
            )?;
            out.push(RegionBasis { vertices: verts, mean: lm.offset, basis: lm.components, n_components: p });
        }
        Ok(RegionPcaModel { n_vertices: n, regions: out, beta: config.beta })
    }

    /// Total number of coefficients P = Σ P_i.
    pub fn n_components(&self) -> usize {
        self.regions.iter().map(|r| r.n_components).sum()
    }

    /// Offset of region i's coefficients inside ζ.
    pub fn offsets(&self) -> Vec<usize> {
        let mut o = Vec::with_capacity(self.regions.len() + 1);
        o.push(0);
        for r in &self.regions {
            o.push(o.last().copied().unwrap_or(0) + r.n_components);
        }
        o
    }

    /// Every (region, local index) pair of each vertex.
    pub fn memberships(&self) -> Vec<Vec<(usize, usize)>> {
        let mut mem = vec![Vec::new(); self.n_vertices];
        for (i, r) in self.regions.iter().enumerate() {
            for (l, &v) in r.vertices.iter().enumerate() {
                mem[v].push((i, l));
            }
        }
        mem
    }

    /// Shared vertices as (i, li, j, lj) with i < j (every pair of regions sharing the vertex).
    pub(crate) fn shared_pairs(&self) -> Vec<SharedPair> {
        let mut out = Vec::new();
        for mem in self.memberships() {
            for a in 0..mem.len() {
                for b in a + 1..mem.len() {
                    out.push((mem[a].0, mem[a].1, mem[b].0, mem[b].1));
                }
            }
        }
        out
    }

    /// Adds β·(boundary term) of Eq. 6/9 to the system `h` (P × P) and `rhs` (P).
    pub(crate) fn add_boundary(&self, pairs: &[SharedPair], beta: f64, h: &mut Mat<f64>, rhs: &mut [f64]) {
        if beta == 0.0 {
            return;
        }
        let off = self.offsets();
        for &(i, li, j, lj) in pairs {
            let (ri, rj) = (&self.regions[i], &self.regions[j]);
            for c in 0..3 {
                let dmu = rj.mean[3 * lj + c] - ri.mean[3 * li + c];
                for p in 0..ri.n_components {
                    let a = ri.at(p, li, c);
                    rhs[off[i] + p] += beta * a * dmu;
                    for q in 0..ri.n_components {
                        h[(off[i] + p, off[i] + q)] += beta * a * ri.at(q, li, c);
                    }
                    for q in 0..rj.n_components {
                        let v = beta * a * rj.at(q, lj, c);
                        h[(off[i] + p, off[j] + q)] -= v;
                        h[(off[j] + q, off[i] + p)] -= v;
                    }
                }
                for p in 0..rj.n_components {
                    let b = rj.at(p, lj, c);
                    rhs[off[j] + p] -= beta * b * dmu;
                    for q in 0..rj.n_components {
                        h[(off[j] + p, off[j] + q)] += beta * b * rj.at(q, lj, c);
                    }
                }
            }
        }
    }

    /// Adds the data term of local vertex `l` of region `i` (weight 1) to `h`.
    pub(crate) fn add_data_vertex(&self, i: usize, l: usize, off: usize, h: &mut Mat<f64>) {
        let r = &self.regions[i];
        for c in 0..3 {
            for p in 0..r.n_components {
                let a = r.at(p, l, c);
                if a != 0.0 {
                    for q in 0..r.n_components {
                        h[(off + p, off + q)] += a * r.at(q, l, c);
                    }
                }
            }
        }
    }

    /// Per-vertex average of `μ_i + B_iᵀ c_i` over the regions containing the vertex (N·3).
    pub fn reconstruct(&self, zeta: &[f64]) -> Result<Vec<f64>> {
        let p = self.n_components();
        if zeta.len() != p {
            return Err(Error::Invalid(format!("region PCA: {} coefficients given, the model has {p}", zeta.len())));
        }
        if let Some(i) = zeta.iter().position(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!("region PCA: coefficient {i} is not finite ({})", zeta[i])));
        }
        let off = self.offsets();
        let mut out = vec![0.0; 3 * self.n_vertices];
        let mut cnt = vec![0.0f64; self.n_vertices];
        for (i, r) in self.regions.iter().enumerate() {
            let ni = r.vertices.len();
            let mut local = r.mean.clone();
            for k in 0..r.n_components {
                let w = zeta[off[i] + k];
                for (o, b) in local.iter_mut().zip(&r.basis[k * 3 * ni..(k + 1) * 3 * ni]) {
                    *o += w * b;
                }
            }
            for (l, &v) in r.vertices.iter().enumerate() {
                for c in 0..3 {
                    out[3 * v + c] += local[3 * l + c];
                }
                cnt[v] += 1.0;
            }
        }
        for (v, &c) in cnt.iter().enumerate() {
            for x in &mut out[3 * v..3 * v + 3] {
                *x /= c.max(1.0);
            }
        }
        Ok(out)
    }

    /// Builds the factorised encoder (Eq. 6/7 with the model's β).
    pub fn encoder(&self) -> Result<RegionPcaEncoder<'_>> {
        RegionPcaEncoder::new(self)
    }

    /// One-shot encode (see [`RegionPcaEncoder::encode`]).
    pub fn encode(&self, x: &[f64]) -> Result<Vec<f64>> {
        self.encoder()?.encode(x)
    }
}

/// Cholesky factor of a symmetric system with a relative ridge 1e-12·max diag (keeps
/// semi-definite systems solvable).
pub(crate) fn factor_spd(mut h: Mat<f64>, what: &str) -> Result<faer::linalg::solvers::Llt<f64>> {
    let p = h.nrows();
    let md = (0..p).map(|i| h[(i, i)]).fold(0.0f64, f64::max);
    for i in 0..p {
        h[(i, i)] += 1e-12 * md.max(f64::MIN_POSITIVE) + 1e-300;
    }
    h.llt(Side::Lower).map_err(|e| Error::Numerical(format!("{what}: Cholesky of the {p}×{p} system failed: {e:?}")))
}

/// Solves Eq. 6/7 for new rows, factorising the P × P system once.
pub struct RegionPcaEncoder<'a> {
    model: &'a RegionPcaModel,
    llt: faer::linalg::solvers::Llt<f64>,
    pairs: Vec<SharedPair>,
}

impl<'a> RegionPcaEncoder<'a> {
    /// Assembles and factorises the system.
    pub fn new(model: &'a RegionPcaModel) -> Result<Self> {
        let p = model.n_components();
        let off = model.offsets();
        let mut h = Mat::<f64>::zeros(p, p);
        for (i, r) in model.regions.iter().enumerate() {
            for l in 0..r.vertices.len() {
                model.add_data_vertex(i, l, off[i], &mut h);
            }
        }
        let pairs = model.shared_pairs();
        let mut dummy = vec![0.0; p];
        model.add_boundary(&pairs, model.beta, &mut h, &mut dummy);
        let llt = factor_spd(h, "region PCA encoder")?;
        Ok(RegionPcaEncoder { model, llt, pairs })
    }

    /// Coefficients ζ (P numbers) of one row `x` (N·3 numbers).
    pub fn encode(&self, x: &[f64]) -> Result<Vec<f64>> {
        let m = self.model;
        if x.len() != 3 * m.n_vertices {
            return Err(Error::Invalid(format!(
                "region PCA encode: {} values, expected {}",
                x.len(),
                3 * m.n_vertices
            )));
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!("region PCA encode: value {i} is not finite ({})", x[i])));
        }
        let p = m.n_components();
        let off = m.offsets();
        let mut rhs = vec![0.0; p];
        for (i, r) in m.regions.iter().enumerate() {
            for (l, &v) in r.vertices.iter().enumerate() {
                for c in 0..3 {
                    let d = x[3 * v + c] - r.mean[3 * l + c];
                    for k in 0..r.n_components {
                        rhs[off[i] + k] += r.at(k, l, c) * d;
                    }
                }
            }
        }
        // Boundary right-hand side (the matrix part was factorised in `new`).
        boundary_rhs(m, &self.pairs, m.beta, &mut rhs);
        let mut b = Mat::<f64>::from_fn(p, 1, |i, _| rhs[i]);
        self.llt.solve_in_place(b.as_mut());
        Ok((0..p).map(|i| b[(i, 0)]).collect())
    }
}

/// Right-hand side part of the boundary term only.
pub(crate) fn boundary_rhs(m: &RegionPcaModel, pairs: &[SharedPair], beta: f64, rhs: &mut [f64]) {
    if beta == 0.0 {
        return;
    }
    let off = m.offsets();
    for &(i, li, j, lj) in pairs {
        let (ri, rj) = (&m.regions[i], &m.regions[j]);
        for c in 0..3 {
            let dmu = rj.mean[3 * lj + c] - ri.mean[3 * li + c];
            for p in 0..ri.n_components {
                rhs[off[i] + p] += beta * ri.at(p, li, c) * dmu;
            }
            for p in 0..rj.n_components {
                rhs[off[j] + p] -= beta * rj.at(p, lj, c) * dmu;
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::methods::segmentation::{SegmentationConfig, segment};
    use crate::synthetic;

    /// Bumps displacements (F × N·3), faces, rest.
    pub(crate) fn bumps() -> (Vec<f64>, usize, usize, Vec<[usize; 3]>, Vec<crate::mesh::Vec3>) {
        let seq = synthetic::load("synthetic:bumps").unwrap();
        let rest = synthetic::tube_mesh();
        let n = rest.positions.len();
        let mut d = Vec::new();
        for fr in &seq.frames {
            for (p, q) in fr.iter().zip(&rest.positions) {
                d.extend_from_slice(&[p[0] - q[0], p[1] - q[1], p[2] - q[2]]);
            }
        }
        (d, seq.frames.len(), n, seq.faces, rest.positions)
    }

    pub(crate) fn bumps_model(k: usize) -> (RegionPcaModel, Vec<f64>, usize, usize) {
        let (d, f, n, faces, rest) = bumps();
        let seg =
            segment(&rest, &faces, &d, f, &SegmentationConfig { regions: Some(4), restarts: 4, ..Default::default() })
                .unwrap();
        let x = DataMatrix::new(&d, f, n, 3).unwrap();
        let model = RegionPcaModel::fit(x, &seg.regions, &RegionPcaConfig { components: k, beta: 1.0 }).unwrap();
        (model, d, f, n)
    }

    fn erms(a: &[f64], b: &[f64]) -> f64 {
        (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
    }

    #[test]
    fn full_rank_regions_reconstruct_exactly() {
        // 4 regions × 40 components ≥ rank of 40 frames per region: exact.
        let (model, d, f, n) = bumps_model(4 * 40);
        let enc = model.encoder().unwrap();
        let scale = d.iter().map(|v| v.abs()).fold(0.0, f64::max);
        for row in [0, 7, f - 1] {
            let x = &d[row * 3 * n..(row + 1) * 3 * n];
            let rec = model.reconstruct(&enc.encode(x).unwrap()).unwrap();
            assert!(erms(x, &rec) < 1e-9 * scale, "row {row}: {}", erms(x, &rec));
        }
    }

    #[test]
    fn region_pca_generalises_where_holistic_cannot() {
        // Grid with two halves sharing the middle column. Left pattern P_L and right pattern
        // P_R (both zero on the shared column) always move with the same amplitude in training
        // (rank 1), independently in the held-out frames. Same total budget K = 2: holistic PCA
        // learns only the joint mode; region PCA (1 component per half) represents any mix.
        let g = crate::mesh::primitives::grid(10, 6, 1.0);
        let n = g.positions.len();
        let pattern = |p: &crate::mesh::Vec3, left: bool| {
            let s = (std::f64::consts::PI * p[0] / 0.5).sin();
            if (p[0] < 0.5 - 1e-9) == left && (p[0] - 0.5).abs() > 1e-9 { s * s } else { 0.0 }
        };
        let frame = |a: f64, b: f64| -> Vec<f64> {
            g.positions.iter().flat_map(|p| [0.0, 0.0, a * pattern(p, true) + b * pattern(p, false)]).collect()
        };
        let train: Vec<f64> = (0..6).flat_map(|i| frame(i as f64 * 0.3, i as f64 * 0.3)).collect();
        let test: Vec<f64> = [(1.0, -0.5), (0.2, 1.3), (-0.7, 0.0)].iter().flat_map(|&(a, b)| frame(a, b)).collect();
        let left: Vec<usize> = (0..n).filter(|&v| g.positions[v][0] <= 0.5 + 1e-9).collect();
        let right: Vec<usize> = (0..n).filter(|&v| g.positions[v][0] >= 0.5 - 1e-9).collect();
        let x = DataMatrix::new(&train, 6, n, 3).unwrap();
        let model = RegionPcaModel::fit(x, &[left, right], &RegionPcaConfig { components: 2, beta: 1.0 }).unwrap();
        assert_eq!(model.n_components(), 2);
        let hol = Pca::fit(x, &PcaConfig { components: 2, centering: PcaCentering::Mean }).unwrap();
        let (enc, henc) = (model.encoder().unwrap(), hol.encoder().unwrap());
        let mut rec_r = Vec::new();
        let mut rec_h = Vec::new();
        for row in test.chunks_exact(3 * n) {
            rec_r.extend(model.reconstruct(&enc.encode(row).unwrap()).unwrap());
            rec_h.extend(hol.synthesize(&henc.encode(row).unwrap()).unwrap());
        }
        let scale = erms(&test, &vec![0.0; test.len()]);
        let (e_r, e_h) = (erms(&test, &rec_r), erms(&test, &rec_h));
        eprintln!("held-out rms error: region PCA {e_r:.3e}, holistic PCA {e_h:.3e} (data rms {scale:.3e})");
        assert!(e_r < 1e-9 * scale, "region PCA {e_r}");
        assert!(e_h > 0.1 * scale, "holistic PCA {e_h}");
    }

    #[test]
    fn budget_below_region_count_is_rejected() {
        let (d, f, n, _, _) = bumps();
        let x = DataMatrix::new(&d, f, n, 3).unwrap();
        let regions = vec![(0..n / 2 + 1).collect::<Vec<_>>(), (n / 2..n).collect()];
        let err = RegionPcaModel::fit(x, &regions, &RegionPcaConfig { components: 1, beta: 1.0 }).unwrap_err();
        assert!(err.to_string().contains("(1)"), "{err}");
    }
}
