//! Linear feature scaling to [−0.95, 0.95] for the network (Tan et al. 2018), fitted on the
//! training set and stored with the model.
//!
//! Dimension `k` of the width-W feature vectors (shared by all elements and frames) maps
//! `x ↦ y = (x − c_k)·a_k` with `c_k = (min_k + max_k)/2`, `a_k = 2·0.95/(max_k − min_k)`, so the
//! training minimum goes to −0.95 and the maximum to +0.95; [`FeatureScaling::invert`] is
//! `x = y/a_k + c_k`. The minima and maxima are taken
//! * [`ScalingMode::PerDimension`] (default, the paper): per dimension, over all frames and
//!   elements;
//! * [`ScalingMode::Grouped`] (the reference code): one shared min/max over all dimensions of a
//!   group; [`ScalingMode::reference_grouped`] gives the reference's groups `{0,1,2}` (rotation)
//!   and `{3..8}` (stretch) of a 9-wide feature. Dimensions in no group form their own group.
//!
//! **Fenced quantile ranges** ([`FeatureScaling::fit_quantile`], the autoencoder's
//! `scaling_quantile` and `scaling_fence` keys): with q > 0 the range of a group is the q and
//! 1 − q quantiles [a, b] of its training values (read off a histogram of [`HISTOGRAM_BINS`] bins
//! over the full range, rounded outwards to bin edges) widened by fence × (b − a) on each side,
//! and never beyond the training minimum and maximum. Where it ends inside them, values beyond
//! that end are outliers: [`FeatureScaling::apply_in_place`] clamps them to it before scaling
//! ([`FeatureScaling::clamped`]); where it does not, nothing changes. A few extreme features
//! (slivers of a 29 299-vertex face stretch 70×) otherwise set the range alone and squeeze every
//! other feature into a sliver of [−0.95, 0.95]; clamped, they are the only ones the decoder
//! (tanh outputs) cannot reproduce. [`FeatureScaling::invert_in_place`] never clamps.
//!
//! **Constant dimensions.** When `max_k − min_k ≤ CONSTANT_TOL·(1 + max(|min_k|, |max_k|))` there
//! is nothing to stretch: the map is the shift `y = x − min_k` (`a_k = 1`, `c_k = min_k`), which
//! sends the training value to 0, never divides by zero and stays exactly invertible.

#![warn(missing_docs)]

use serde::{Deserialize, Serialize};

use super::Features;
use crate::error::{Error, Result};

/// Training minimum/maximum map to ∓`TARGET`.
pub const TARGET: f64 = 0.95;

/// Relative range under which a dimension counts as constant (see the module docs).
pub const CONSTANT_TOL: f64 = 1e-12;

/// Bins of the histogram a quantile range is read from (module docs): the range's ends are
/// exact to 1/65 536 of a group's full range.
pub const HISTOGRAM_BINS: usize = 1 << 16;

/// Largest quantile [`FeatureScaling::fit_quantile`] takes (a range of at least the middle 90 %).
pub const MAX_QUANTILE: f64 = 0.05;

/// Which dimensions share a min/max.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ScalingMode {
    /// Every dimension has its own min/max (the paper; default).
    #[default]
    PerDimension,
    /// Each group of dimension indices (0-based, `< width`, each index at most once) shares one
    /// min/max; unlisted dimensions are their own group.
    Grouped {
        /// Groups of 0-based dimension indices.
        groups: Vec<Vec<usize>>,
    },
}

impl ScalingMode {
    /// The reference implementation's grouping of a 9-wide feature: rotation dims 0..3 and
    /// stretch dims 3..9.
    pub fn reference_grouped() -> Self {
        ScalingMode::Grouped { groups: vec![vec![0, 1, 2], vec![3, 4, 5, 6, 7, 8]] }
    }

    /// Group label per dimension (`width` entries), validating the groups.
    fn labels(&self, width: usize) -> Result<Vec<usize>> {
        let mut label: Vec<usize> = vec![usize::MAX; width];
        if let ScalingMode::Grouped { groups } = self {
            for (g, dims) in groups.iter().enumerate() {
                if dims.is_empty() {
                    return Err(Error::Invalid(format!("scaling group {g} is empty")));
                }
                for &k in dims {
                    if k >= width {
                        return Err(Error::Invalid(format!(
                            "scaling group {g} names dimension {k}, but the features are {width} wide"
                        )));
                    }
                    if label[k] != usize::MAX {
                        return Err(Error::Invalid(format!("scaling dimension {k} is in groups {} and {g}", label[k])));
                    }
                    label[k] = g;
                }
            }
        }
        let mut next = match self {
            ScalingMode::Grouped { groups } => groups.len(),
            ScalingMode::PerDimension => 0,
        };
        for l in &mut label {
            if *l == usize::MAX {
                *l = next;
                next += 1;
            }
        }
        Ok(label)
    }
}

/// A fitted scaling: the training min/max per dimension (equal within a group).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeatureScaling {
    /// How min/max were shared.
    pub mode: ScalingMode,
    /// Feature width W.
    pub width: usize,
    /// Training minimum per dimension (W).
    pub min: Vec<f64>,
    /// Training maximum per dimension (W).
    pub max: Vec<f64>,
    /// Per dimension, whether its range was narrowed below the training minimum / maximum (a
    /// fenced quantile range, module docs): [`FeatureScaling::apply_in_place`] clamps that end.
    /// Empty: no end is (files written before the field).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clamped: Vec<[bool; 2]>,
}

/// Histogram of each group's training values over its full range, from which
/// [`FeatureScaling::fit_quantile`] reads quantile ranges; fed one block of width-W vectors at a
/// time, so streamed training sets need one pass over their frames, not a copy.
#[derive(Debug, Clone)]
pub struct RangeHistogram {
    full: FeatureScaling,
    label: Vec<usize>,
    /// Per group: [lo, hi] of the full range, and [`HISTOGRAM_BINS`] counts.
    groups: Vec<(f64, f64, Vec<u64>)>,
}

impl RangeHistogram {
    /// An empty histogram over the full ranges of `full` (a min/max scaling of the same data).
    pub fn new(full: &FeatureScaling) -> Result<Self> {
        full.validate()?;
        let label = full.mode.labels(full.width)?;
        let n_groups = label.iter().max().map_or(0, |m| m + 1);
        let mut groups = vec![(0.0, 0.0, Vec::new()); n_groups];
        for (k, &g) in label.iter().enumerate() {
            groups[g] = (full.min[k], full.max[k], vec![0; HISTOGRAM_BINS]);
        }
        Ok(RangeHistogram { full: full.clone(), label, groups })
    }

    /// Counts a flat block of width-W vectors (values outside the full range count at its ends).
    pub fn add(&mut self, data: &[f64]) -> Result<()> {
        self.full.check_len(data.len())?;
        for v in data.chunks_exact(self.full.width) {
            for (&x, &g) in v.iter().zip(&self.label) {
                let (lo, hi, counts) = &mut self.groups[g];
                let t = if *hi > *lo { (x - *lo) / (*hi - *lo) } else { 0.0 };
                let b = (t * HISTOGRAM_BINS as f64).floor().clamp(0.0, (HISTOGRAM_BINS - 1) as f64) as usize;
                counts[b] += 1;
            }
        }
        Ok(())
    }

    /// The scaling whose group ranges are the `q` and 1 − `q` quantiles [a, b] of the counted
    /// values widened by `fence` × (b − a) on each side, within the full range (`q` in
    /// [0, [`MAX_QUANTILE`]], `fence` ≥ 0; `q` = 0: the full ranges, as [`FeatureScaling::fit`]).
    /// An end that the fence brings inside the full range is clamped by
    /// [`FeatureScaling::apply_in_place`].
    pub fn scaling(&self, q: f64, fence: f64) -> Result<FeatureScaling> {
        if !(0.0..=MAX_QUANTILE).contains(&q) {
            return Err(Error::Invalid(format!("scaling quantile {q} must be in [0, {MAX_QUANTILE}]")));
        }
        if !(fence >= 0.0 && fence.is_finite()) {
            return Err(Error::Invalid(format!("scaling fence {fence} must be a finite number ≥ 0")));
        }
        if q == 0.0 {
            return Ok(self.full.clone());
        }
        let ranges: Vec<(f64, f64)> = self
            .groups
            .iter()
            .map(|(lo, hi, counts)| {
                let total: u64 = counts.iter().sum();
                if total == 0 || hi <= lo {
                    return (*lo, *hi);
                }
                let width = (hi - lo) / HISTOGRAM_BINS as f64;
                // The bin holding the value of rank r (0-based) from below, and from above.
                let r = (q * total as f64).floor() as u64;
                let mut seen = 0;
                let low = counts.iter().position(|&c| {
                    seen += c;
                    seen > r
                });
                seen = 0;
                let high = counts.iter().rposition(|&c| {
                    seen += c;
                    seen > r
                });
                let a = low.map_or(*lo, |b| lo + b as f64 * width).max(*lo);
                let b = high.map_or(*hi, |b| (lo + (b + 1) as f64 * width).min(*hi)).max(a);
                let w = b - a;
                ((a - fence * w).max(*lo), (b + fence * w).min(*hi))
            })
            .collect();
        let min: Vec<f64> = self.label.iter().map(|&g| ranges[g].0).collect();
        let max: Vec<f64> = self.label.iter().map(|&g| ranges[g].1).collect();
        let clamped: Vec<[bool; 2]> =
            (0..self.full.width).map(|k| [min[k] > self.full.min[k], max[k] < self.full.max[k]]).collect();
        let clamped = if clamped.iter().flatten().any(|&c| c) { clamped } else { Vec::new() };
        let s = FeatureScaling { mode: self.full.mode.clone(), width: self.full.width, min, max, clamped };
        s.validate()?;
        Ok(s)
    }
}

impl FeatureScaling {
    /// Fits on training features (all frames and elements). Errors on empty or non-finite data
    /// or invalid groups.
    pub fn fit(features: &Features, mode: ScalingMode) -> Result<Self> {
        if features.data.len() != features.n_frames * features.n_elements * features.width {
            return Err(Error::Invalid(format!(
                "features hold {} numbers, expected {} × {} × {}",
                features.data.len(),
                features.n_frames,
                features.n_elements,
                features.width
            )));
        }
        Self::fit_slice(&features.data, features.width, mode)
    }

    /// Fits on a flat array of width-`width` vectors (see [`FeatureScaling::fit`]).
    pub fn fit_slice(data: &[f64], width: usize, mode: ScalingMode) -> Result<Self> {
        if width == 0 || data.is_empty() || !data.len().is_multiple_of(width) {
            return Err(Error::Invalid(format!("cannot fit a scaling on {} numbers of width {width}", data.len())));
        }
        if let Some(i) = data.iter().position(|x| !x.is_finite()) {
            return Err(Error::Invalid(format!(
                "feature {i} (vector {}, dimension {}) is not finite: {}",
                i / width,
                i % width,
                data[i]
            )));
        }
        let mut lo = vec![f64::INFINITY; width];
        let mut hi = vec![f64::NEG_INFINITY; width];
        for v in data.chunks_exact(width) {
            for (k, &x) in v.iter().enumerate() {
                lo[k] = lo[k].min(x);
                hi[k] = hi[k].max(x);
            }
        }
        Self::fit_column_ranges(&lo, &hi, mode)
    }

    /// [`FeatureScaling::fit_slice`] with each group's range at the `q` and 1 − `q` quantiles of
    /// its values, widened by `fence` times its width ([`RangeHistogram::scaling`], module docs;
    /// `q` = 0 is `fit_slice` exactly).
    pub fn fit_quantile(data: &[f64], width: usize, mode: ScalingMode, q: f64, fence: f64) -> Result<Self> {
        let full = Self::fit_slice(data, width, mode)?;
        if q == 0.0 {
            return Ok(full);
        }
        let mut h = RangeHistogram::new(&full)?;
        h.add(data)?;
        h.scaling(q, fence)
    }

    /// Fits from each dimension's training minimum and maximum (W each; what a feature cache
    /// records): groups share the smallest minimum and largest maximum of their dimensions, as
    /// [`FeatureScaling::fit`] on the features themselves.
    pub fn fit_column_ranges(min: &[f64], max: &[f64], mode: ScalingMode) -> Result<Self> {
        let width = min.len();
        if width == 0 || max.len() != width {
            return Err(Error::Invalid(format!("{} minima and {} maxima: cannot fit a scaling", min.len(), max.len())));
        }
        if let Some(k) = (0..width).find(|&k| !(min[k].is_finite() && max[k].is_finite() && min[k] <= max[k])) {
            return Err(Error::Invalid(format!(
                "dimension {k}: range [{}, {}] is not a finite interval",
                min[k], max[k]
            )));
        }
        let label = mode.labels(width)?;
        let n_groups = label.iter().max().map_or(0, |m| m + 1);
        let mut glo = vec![f64::INFINITY; n_groups];
        let mut ghi = vec![f64::NEG_INFINITY; n_groups];
        for k in 0..width {
            let g = label[k];
            glo[g] = glo[g].min(min[k]);
            ghi[g] = ghi[g].max(max[k]);
        }
        Ok(FeatureScaling {
            min: label.iter().map(|&g| glo[g]).collect(),
            max: label.iter().map(|&g| ghi[g]).collect(),
            mode,
            width,
            clamped: Vec::new(),
        })
    }

    /// Checks a (deserialised) scaling: lengths, finiteness, min ≤ max, groups.
    pub fn validate(&self) -> Result<()> {
        if self.min.len() != self.width || self.max.len() != self.width {
            return Err(Error::Invalid(format!(
                "scaling of width {} has {} minima and {} maxima",
                self.width,
                self.min.len(),
                self.max.len()
            )));
        }
        self.mode.labels(self.width)?;
        if !self.clamped.is_empty() && self.clamped.len() != self.width {
            return Err(Error::Invalid(format!(
                "scaling of width {} has {} clamp flags",
                self.width,
                self.clamped.len()
            )));
        }
        for k in 0..self.width {
            let (lo, hi) = (self.min[k], self.max[k]);
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(Error::Invalid(format!(
                    "scaling dimension {k}: min ({lo}) must be finite and ≤ max ({hi})"
                )));
            }
        }
        Ok(())
    }

    /// `true` when dimension `k` is treated as constant (module docs).
    pub fn is_constant(&self, k: usize) -> bool {
        let (lo, hi) = (self.min[k], self.max[k]);
        hi - lo <= CONSTANT_TOL * (1.0 + lo.abs().max(hi.abs()))
    }

    /// Per dimension `k`: `(1/a_k, c_k)` of the inverse `x = y/a + c`, i.e. `∂x/∂y` and the
    /// centre (what a chain rule through [`FeatureScaling::invert_in_place`] needs).
    pub fn inverse_affine(&self) -> Vec<(f64, f64)> {
        (0..self.width)
            .map(|k| {
                let (c, a) = self.affine(k);
                (1.0 / a, c)
            })
            .collect()
    }

    /// [`Self::inverse_affine`] as an array of the expected width `W` (an error naming both
    /// widths otherwise).
    pub fn inverse_affine_array<const W: usize>(&self) -> Result<[(f64, f64); W]> {
        let v = self.inverse_affine();
        <[(f64, f64); W]>::try_from(v.as_slice())
            .map_err(|_| Error::Invalid(format!("the feature scaling has width {}, not {W}", v.len())))
    }

    /// `(c_k, a_k)` of dimension `k`: `y = (x − c)·a`.
    fn affine(&self, k: usize) -> (f64, f64) {
        if self.is_constant(k) {
            (self.min[k], 1.0)
        } else {
            (0.5 * (self.min[k] + self.max[k]), 2.0 * TARGET / (self.max[k] - self.min[k]))
        }
    }

    fn check_len(&self, len: usize) -> Result<()> {
        if self.width == 0
            || !len.is_multiple_of(self.width)
            || self.min.len() != self.width
            || self.max.len() != self.width
        {
            return Err(Error::Invalid(format!("{len} numbers do not split into vectors of width {}", self.width)));
        }
        Ok(())
    }

    /// Scales a flat array of width-W vectors in place (the ends of a fenced quantile range that
    /// lie inside the training range clamp first: module docs).
    pub fn apply_in_place(&self, data: &mut [f64]) -> Result<()> {
        self.check_len(data.len())?;
        let ab: Vec<(f64, f64)> = (0..self.width).map(|k| self.affine(k)).collect();
        if !self.clamped.is_empty() {
            let lo: Vec<f64> =
                (0..self.width).map(|k| if self.clamped[k][0] { self.min[k] } else { f64::NEG_INFINITY }).collect();
            let hi: Vec<f64> =
                (0..self.width).map(|k| if self.clamped[k][1] { self.max[k] } else { f64::INFINITY }).collect();
            for v in data.chunks_exact_mut(self.width) {
                for (k, (x, &(c, a))) in v.iter_mut().zip(&ab).enumerate() {
                    *x = (x.max(lo[k]).min(hi[k]) - c) * a;
                }
            }
        } else {
            for v in data.chunks_exact_mut(self.width) {
                for (x, &(c, a)) in v.iter_mut().zip(&ab) {
                    *x = (*x - c) * a;
                }
            }
        }
        Ok(())
    }

    /// Inverse of [`FeatureScaling::apply_in_place`].
    pub fn invert_in_place(&self, data: &mut [f64]) -> Result<()> {
        self.check_len(data.len())?;
        let ab: Vec<(f64, f64)> = (0..self.width).map(|k| self.affine(k)).collect();
        for v in data.chunks_exact_mut(self.width) {
            for (y, &(c, a)) in v.iter_mut().zip(&ab) {
                *y = *y / a + c;
            }
        }
        Ok(())
    }

    /// Scaled copy of `features` (width must match).
    pub fn apply(&self, features: &Features) -> Result<Features> {
        self.check_width(features)?;
        let mut out = features.clone();
        self.apply_in_place(&mut out.data)?;
        Ok(out)
    }

    /// Unscaled copy of `features` (inverse of [`FeatureScaling::apply`]).
    pub fn invert(&self, features: &Features) -> Result<Features> {
        self.check_width(features)?;
        let mut out = features.clone();
        self.invert_in_place(&mut out.data)?;
        Ok(out)
    }

    fn check_width(&self, features: &Features) -> Result<()> {
        if features.width != self.width {
            return Err(Error::Invalid(format!(
                "features are {} wide, the scaling was fitted on width {}",
                features.width, self.width
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 1 000 vectors of width 2: dim 0 is k/999 (0..1) but one value of 100, dim 1 is 1 − dim 0.
    fn with_outlier() -> Vec<f64> {
        let mut d: Vec<f64> = (0..1000).flat_map(|k| [k as f64 / 999.0, 1.0 - k as f64 / 999.0]).collect();
        d[2 * 500] = 100.0;
        d
    }

    #[test]
    fn a_quantile_range_clamps_the_outlier_and_a_fence_keeps_the_rest() {
        let d = with_outlier();
        let s = FeatureScaling::fit_quantile(&d, 2, ScalingMode::PerDimension, 0.002, 0.0).unwrap();
        // Dim 0: two values below the 0.2 % rank 2 are 0 and 1/999; the range starts at the bin
        // of 2/999 and ends at the bin of the third largest value (the outlier and 1 above it).
        let bin0 = 100.0 / HISTOGRAM_BINS as f64;
        assert!(s.min[0] <= 2.0 / 999.0 && s.min[0] > 2.0 / 999.0 - bin0, "min {}", s.min[0]);
        assert!(s.max[0] >= 998.0 / 999.0 - 1e-12 && s.max[0] < 998.0 / 999.0 + bin0, "max {}", s.max[0]);
        // Dim 1 has no outlier: its range is the same middle, to its finer bins.
        assert!((s.min[1] - 2.0 / 999.0).abs() < 1.0 / HISTOGRAM_BINS as f64, "{}", s.min[1]);
        assert!((s.max[1] - 997.0 / 999.0).abs() < 1.0 / HISTOGRAM_BINS as f64, "{}", s.max[1]);
        assert_eq!(s.clamped, vec![[true, true], [true, true]]);
        let mut y = d.clone();
        s.apply_in_place(&mut y).unwrap();
        // The outlier is clamped to the top of the range; nothing leaves [−0.95, 0.95].
        assert!((y[1000] - TARGET).abs() < 1e-12, "{}", y[1000]);
        assert!(y.iter().all(|v| v.abs() <= TARGET + 1e-12));
        // Inverting never clamps: −2 scaled units map back beyond the range's low end.
        let mut z = vec![-2.0, 0.0];
        s.invert_in_place(&mut z).unwrap();
        assert!(z[0] < s.min[0] - 0.5, "{}", z[0]);
        // A fence of 1 widens [a, b] by its width each side: dim 1 and the low end of dim 0 reach
        // the training extremes and clamp nothing; the outlier (100 ≫ 1 + 1) is still clamped.
        let f = FeatureScaling::fit_quantile(&d, 2, ScalingMode::PerDimension, 0.002, 1.0).unwrap();
        assert_eq!(f.clamped, vec![[false, true], [false, false]]);
        assert_eq!((f.min[0], f.min[1], f.max[1]), (0.0, 0.0, 1.0));
        assert!((f.max[0] - (2.0 * s.max[0] - s.min[0])).abs() < 1e-12, "{}", f.max[0]);
        let mut y = vec![-5.0, 7.0, 100.0, -3.0];
        f.apply_in_place(&mut y).unwrap();
        assert!(y[0] < -TARGET - 1.0 && y[1] > TARGET + 1.0, "unclamped ends pass: {y:?}");
        assert!((y[2] - TARGET).abs() < 1e-12 && y[3] < -TARGET - 1.0, "{y:?}");
        // q = 0 is the minimum and maximum, whatever the fence.
        let full = FeatureScaling::fit_quantile(&d, 2, ScalingMode::PerDimension, 0.0, 1.0).unwrap();
        assert_eq!(full, FeatureScaling::fit_slice(&d, 2, ScalingMode::PerDimension).unwrap());
        assert_eq!((full.max[0], full.clamped.len()), (100.0, 0));
    }

    #[test]
    fn a_histogram_fed_in_blocks_equals_one_pass_and_groups_share_a_range() {
        let d = with_outlier();
        let mode = ScalingMode::Grouped { groups: vec![vec![0, 1]] };
        let one = FeatureScaling::fit_quantile(&d, 2, mode.clone(), 0.01, 0.5).unwrap();
        let mut h = RangeHistogram::new(&FeatureScaling::fit_slice(&d, 2, mode).unwrap()).unwrap();
        for block in d.chunks(2 * 37) {
            h.add(block).unwrap();
        }
        assert_eq!(h.scaling(0.01, 0.5).unwrap(), one);
        assert_eq!((one.min[0], one.max[0]), (one.min[1], one.max[1]));
        assert!(one.max[0] < 1.6 && one.min[0] == 0.0, "{:?}", (one.min[0], one.max[0]));
        // Out of range q or fence; a file written before the field (no `clamped`) clamps nothing.
        assert!(h.scaling(0.2, 1.0).unwrap_err().to_string().contains("0.2"));
        assert!(h.scaling(0.01, -1.0).unwrap_err().to_string().contains("-1"));
        let mut v = serde_json::to_value(&one).unwrap();
        assert_eq!(v["clamped"], serde_json::json!([[false, true], [false, true]]));
        v.as_object_mut().unwrap().remove("clamped");
        let old: FeatureScaling = serde_json::from_value(v).unwrap();
        assert!(old.clamped.is_empty());
        let mut y = vec![100.0, 0.0];
        old.apply_in_place(&mut y).unwrap();
        assert!(y[0] > 1.0, "without clamp flags nothing is clamped: {}", y[0]);
        let bad = FeatureScaling { clamped: vec![[true, false]], ..one };
        assert!(bad.validate().unwrap_err().to_string().contains("clamp flags"));
    }

    fn sample() -> Features {
        // 2 frames × 3 elements × 4 dims; dim 3 constant.
        let data = vec![
            0.0, -1.0, 5.0, 2.0, //
            1.0, 3.0, 6.0, 2.0, //
            0.5, 1.0, 7.0, 2.0, //
            -1.0, 0.0, 5.5, 2.0, //
            2.0, 2.0, 6.5, 2.0, //
            0.0, -0.5, 5.0, 2.0,
        ];
        Features { n_frames: 2, n_elements: 3, width: 4, data }
    }

    #[test]
    fn per_dimension_hits_the_bounds_and_inverts() {
        let f = sample();
        let s = FeatureScaling::fit(&f, ScalingMode::PerDimension).unwrap();
        assert_eq!(s.min, vec![-1.0, -1.0, 5.0, 2.0]);
        assert_eq!(s.max, vec![2.0, 3.0, 7.0, 2.0]);
        let y = s.apply(&f).unwrap();
        for k in 0..3 {
            let col: Vec<f64> = y.data.iter().skip(k).step_by(4).copied().collect();
            let lo = col.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = col.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            assert!((lo + TARGET).abs() < 1e-15 && (hi - TARGET).abs() < 1e-15, "dim {k}: {lo} {hi}");
        }
        // Constant dimension: shifted to 0, no division by zero.
        assert!(s.is_constant(3));
        assert!(y.data.iter().skip(3).step_by(4).all(|&v| v == 0.0));
        let back = s.invert(&y).unwrap();
        for (a, b) in back.data.iter().zip(&f.data) {
            assert!((a - b).abs() < 1e-14);
        }
        // Also exact inverses away from the training data (including the constant dim).
        let mut z = vec![10.0, -7.0, 0.3, 2.5];
        let z0 = z.clone();
        s.invert_in_place(&mut z).unwrap();
        s.apply_in_place(&mut z).unwrap();
        for (a, b) in z.iter().zip(&z0) {
            assert!((a - b).abs() < 1e-13);
        }
    }

    #[test]
    fn grouped_shares_min_max_and_unlisted_dims_stand_alone() {
        let f = sample();
        let s = FeatureScaling::fit(&f, ScalingMode::Grouped { groups: vec![vec![0, 1]] }).unwrap();
        assert_eq!(s.min, vec![-1.0, -1.0, 5.0, 2.0]);
        assert_eq!(s.max, vec![3.0, 3.0, 7.0, 2.0]);
        let y = s.apply(&f).unwrap();
        // Dim 0 reaches −0.95 (its min equals the group min) but not +0.95.
        let d0: Vec<f64> = y.data.iter().step_by(4).copied().collect();
        assert!((d0.iter().copied().fold(f64::INFINITY, f64::min) + TARGET).abs() < 1e-15);
        assert!(d0.iter().copied().fold(f64::NEG_INFINITY, f64::max) < TARGET - 0.1);
        let back = s.invert(&y).unwrap();
        for (a, b) in back.data.iter().zip(&f.data) {
            assert!((a - b).abs() < 1e-14);
        }
        let r = ScalingMode::reference_grouped();
        assert_eq!(r.labels(9).unwrap(), vec![0, 0, 0, 1, 1, 1, 1, 1, 1]);
    }

    #[test]
    fn invalid_inputs_are_errors_with_values() {
        let f = sample();
        let e = FeatureScaling::fit(&f, ScalingMode::Grouped { groups: vec![vec![0, 4]] }).unwrap_err();
        assert!(e.to_string().contains("dimension 4"), "{e}");
        let e = FeatureScaling::fit(&f, ScalingMode::Grouped { groups: vec![vec![0, 1], vec![1]] }).unwrap_err();
        assert!(e.to_string().contains("dimension 1"), "{e}");
        let mut g = f.clone();
        g.data[5] = f64::NAN;
        assert!(FeatureScaling::fit(&g, ScalingMode::PerDimension).is_err());
        let s = FeatureScaling::fit(&f, ScalingMode::PerDimension).unwrap();
        let wrong = Features::zeros(1, 2, 3);
        assert!(s.apply(&wrong).is_err());
        let mut bad = s.clone();
        bad.min[1] = 9.0;
        assert!(bad.validate().is_err());
        assert!(s.validate().is_ok());
    }

    #[test]
    fn serde_round_trip() {
        let s = FeatureScaling::fit(&sample(), ScalingMode::Grouped { groups: vec![vec![0, 2], vec![1]] }).unwrap();
        let text = serde_json::to_string(&s).unwrap();
        let back: FeatureScaling = serde_json::from_str(&text).unwrap();
        assert_eq!(back, s);
        back.validate().unwrap();
    }
}
