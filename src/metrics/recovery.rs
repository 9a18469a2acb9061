//! Recovery of known deformations: how well a model's components match ground-truth
//! displacement fields (planted deformations, `meshdeco plant`).
//!
//! A **field** is one displacement per vertex (N × 3, data units). Each true field t is scored
//! by the learned component field c that matches it best:
//!
//! - **|cos|** = |⟨t, c⟩| / (‖t‖·‖c‖), the inner product over all 3N numbers (1: the same
//!   direction field up to scale and sign; 0: orthogonal). The **signed cosine** of that same
//!   component says whether its positive dial moves the way the true deformation does (a
//!   method with signed weights may find it with the opposite sign);
//! - **support IoU**: the vertices moving more than [`SUPPORT_FRACTION`] (5 %) of the field's
//!   peak displacement, for t and for c, intersected over their union (1: the same region).
//!
//! The best component is chosen for each true field independently (one component may be the
//! best match of two true fields). A true field counts as **found** when its best |cos| is at
//! least [`FOUND_COSINE`] (0.9). The summary also reports the median best |cos| and IoU.
//!
//! **Vertex-space support** ([`support_size`]): the number of vertices a field moves by more than
//! 5 % of its peak — the locality of a component as a person sees it (the feature-space
//! locality of `metrics.json`'s `locality` can hide a small change of rotation that moves a
//! whole limb).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::math::vec3::{Vec3, dot, norm};

/// Vertices moving more than this fraction of a field's peak are its support.
pub const SUPPORT_FRACTION: f64 = 0.05;
/// A true field is found when a component's |cos| with it is at least this.
pub const FOUND_COSINE: f64 = 0.9;

/// ⟨a, b⟩ / (‖a‖·‖b‖) over all 3N numbers; 0 when either field is zero. Errors when the
/// lengths differ or a value is not finite.
pub fn cosine(a: &[Vec3], b: &[Vec3]) -> Result<f64> {
    check_pair(a, b)?;
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += dot(*x, *y);
        aa += dot(*x, *x);
        bb += dot(*y, *y);
    }
    Ok(if aa > 0.0 && bb > 0.0 { ab / (aa.sqrt() * bb.sqrt()) } else { 0.0 })
}

fn check_pair(a: &[Vec3], b: &[Vec3]) -> Result<()> {
    if a.len() != b.len() {
        return Err(Error::Invalid(format!("recovery: fields of {} and {} vertices", a.len(), b.len())));
    }
    if a.iter().chain(b).flatten().any(|x| !x.is_finite()) {
        return Err(Error::Numerical("recovery: a field has a non-finite value".into()));
    }
    Ok(())
}

/// The vertices moving more than `fraction` of the field's peak displacement (none for a zero
/// field).
pub fn support(field: &[Vec3], fraction: f64) -> Vec<bool> {
    let lengths: Vec<f64> = field.iter().map(|d| norm(*d)).collect();
    let peak = lengths.iter().copied().fold(0.0, f64::max);
    lengths.iter().map(|&l| peak > 0.0 && l > fraction * peak).collect()
}

/// Number of vertices moving more than [`SUPPORT_FRACTION`] of the field's peak.
pub fn support_size(field: &[Vec3]) -> usize {
    support(field, SUPPORT_FRACTION).into_iter().filter(|&b| b).count()
}

/// Share of the field's squared displacement (Σ_v |f_v|²) that its [`CONCENTRATION_SHARE`] of
/// vertices moving most carry (at least one vertex): 1 for a field on a tenth of the vertices or
/// fewer, 0.1 for a uniform one; 0 for a zero field. A locality score that needs no threshold
/// on the peak (a field with a long low tail scores by where its mass is).
pub fn energy_concentration(field: &[Vec3]) -> f64 {
    let mut sq: Vec<f64> = field.iter().map(|d| d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).collect();
    let total: f64 = sq.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return 0.0;
    }
    let top = ((sq.len() as f64 * CONCENTRATION_SHARE).ceil() as usize).clamp(1, sq.len());
    sq.select_nth_unstable_by(top - 1, |a, b| b.total_cmp(a));
    sq[..top].iter().sum::<f64>() / total
}

/// The share of vertices [`energy_concentration`] looks at: a tenth.
pub const CONCENTRATION_SHARE: f64 = 0.1;

/// |A ∩ B| / |A ∪ B| of two vertex sets (0 when both are empty).
pub fn iou(a: &[bool], b: &[bool]) -> f64 {
    let inter = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let union = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    if union == 0 { 0.0 } else { inter as f64 / union as f64 }
}

/// The best-matching component of one true field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Match {
    /// Index of the component (into the component fields given).
    pub component: usize,
    /// Its |cos| with the true field.
    pub abs_cos: f64,
    /// Its signed cosine (positive: its dial moves the way the true deformation does).
    pub cos: f64,
    /// Support IoU of the true field and that component.
    pub iou: f64,
}

/// For every true field, the component of largest |cos| (ties: the lower index). Errors when
/// there are no components, or on fields of different lengths or non-finite values.
pub fn best_matches(truth: &[Vec<Vec3>], components: &[Vec<Vec3>]) -> Result<Vec<Match>> {
    if components.is_empty() {
        return Err(Error::Invalid("recovery: the model has no components".into()));
    }
    let comp_support: Vec<Vec<bool>> = components.iter().map(|c| support(c, SUPPORT_FRACTION)).collect();
    truth
        .iter()
        .map(|t| {
            let mut best: Option<(usize, f64)> = None;
            for (k, c) in components.iter().enumerate() {
                let cos = cosine(t, c)?;
                if best.is_none_or(|(_, b)| cos.abs() > b.abs()) {
                    best = Some((k, cos));
                }
            }
            let (component, cos) = best.expect("at least one component");
            let iou = iou(&support(t, SUPPORT_FRACTION), &comp_support[component]);
            Ok(Match { component, abs_cos: cos.abs(), cos, iou })
        })
        .collect()
}

/// Summary of the matches of the true fields (those flagged `counted`: the identifiable ones).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecoverySummary {
    /// True fields counted.
    pub counted: usize,
    /// Of those, found (best |cos| ≥ [`FOUND_COSINE`]).
    pub found: usize,
    /// Median best |cos| over the counted fields.
    pub median_abs_cos: f64,
    /// Median support IoU of the best matches over the counted fields.
    pub median_iou: f64,
    /// Distinct components that are the best match of a counted field.
    pub components_used: usize,
}

/// Summarises `matches` over the fields with `counted[i]` (all when `counted` is empty).
pub fn summarize(matches: &[Match], counted: &[bool]) -> RecoverySummary {
    let keep: Vec<&Match> =
        matches.iter().enumerate().filter(|(i, _)| counted.is_empty() || counted[*i]).map(|(_, m)| m).collect();
    let med = |mut v: Vec<f64>| -> f64 {
        if v.is_empty() {
            return 0.0;
        }
        v.sort_by(|a, b| a.total_cmp(b));
        let n = v.len();
        if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
    };
    let mut used: Vec<usize> = keep.iter().map(|m| m.component).collect();
    used.sort_unstable();
    used.dedup();
    RecoverySummary {
        counted: keep.len(),
        found: keep.iter().filter(|m| m.abs_cos >= FOUND_COSINE).count(),
        median_abs_cos: med(keep.iter().map(|m| m.abs_cos).collect()),
        median_iou: med(keep.iter().map(|m| m.iou).collect()),
        components_used: used.len(),
    }
}

/// Removes a field's translation robustly: subtracts the per-coordinate median displacement,
/// which is zero for a field that leaves at least half the vertices in place (a localized
/// deformation decoded by a representation that does not fix translation).
pub fn remove_median_translation(field: &mut [Vec3]) {
    if field.is_empty() {
        return;
    }
    for c in 0..3 {
        let mut v: Vec<f64> = field.iter().map(|d| d[c]).collect();
        let mid = v.len() / 2;
        let (_, m, _) = v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        let m = *m;
        for d in field.iter_mut() {
            d[c] -= m;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bump(n: usize, at: usize, width: usize, dir: Vec3) -> Vec<Vec3> {
        (0..n)
            .map(|i| {
                let d = (i as f64 - at as f64).abs() / width as f64;
                let s = if d < 1.0 { (1.0 - d * d).powi(3) } else { 0.0 };
                [dir[0] * s, dir[1] * s, dir[2] * s]
            })
            .collect()
    }

    #[test]
    fn energy_concentration_reads_where_the_mass_is() {
        // Uniform: a tenth of the vertices carry a tenth; 10 of 100 moving: all of it.
        assert!((energy_concentration(&[[0.0, 2.0, 0.0]; 100]) - 0.1).abs() < 1e-12);
        let mut f = vec![[0.0; 3]; 100];
        for (i, d) in f.iter_mut().enumerate().skip(40).take(10) {
            *d = [i as f64, 0.0, 1.0];
        }
        assert!((energy_concentration(&f) - 1.0).abs() < 1e-12);
        // One vertex of 1 and 99 of 0.1: (1 + 9 · 0.01) / (1 + 99 · 0.01), independent of the
        // order and of a common scale; a narrow bump beats a wide one.
        let mut g = vec![[0.1, 0.0, 0.0]; 100];
        g[73] = [-1.0, 0.0, 0.0];
        let want = 1.09 / 1.99;
        assert!((energy_concentration(&g) - want).abs() < 1e-12);
        g.reverse();
        let scaled: Vec<Vec3> = g.iter().map(|d| [7.0 * d[0], 0.0, 0.0]).collect();
        assert!((energy_concentration(&scaled) - want).abs() < 1e-12);
        assert!(
            energy_concentration(&bump(100, 50, 5, [1.0, 0.0, 0.0]))
                > energy_concentration(&bump(100, 50, 30, [1.0, 0.0, 0.0]))
        );
        // A zero field and no vertices: 0; three vertices: the top one (ceil of 0.3).
        assert_eq!(energy_concentration(&[[0.0; 3]; 5]), 0.0);
        assert_eq!(energy_concentration(&[]), 0.0);
        assert!((energy_concentration(&[[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0; 3]]) - 0.8).abs() < 1e-12);
    }

    #[test]
    fn the_matching_component_is_found_with_its_sign_and_support() {
        let a = bump(100, 20, 10, [0.0, 0.0, 1.0]);
        let b = bump(100, 70, 10, [1.0, 0.0, 0.0]);
        // Components: b negated and scaled, a half-shifted copy of a, and a global field.
        let comps = vec![
            b.iter().map(|d| [-3.0 * d[0], 0.0, 0.0]).collect::<Vec<_>>(),
            bump(100, 25, 10, [0.0, 0.0, 1.0]),
            vec![[0.0, 1.0, 0.0]; 100],
        ];
        let m = best_matches(&[a.clone(), b.clone()], &comps).unwrap();
        assert_eq!(m[1].component, 0);
        assert!((m[1].abs_cos - 1.0).abs() < 1e-12 && (m[1].cos + 1.0).abs() < 1e-12);
        assert!((m[1].iou - 1.0).abs() < 1e-12);
        assert_eq!(m[0].component, 1);
        assert!(m[0].abs_cos > 0.5 && m[0].abs_cos < 0.95, "{}", m[0].abs_cos);
        // Supports (above 5 % of the peak) are 15 vertices each, 10 shared: 10 / 20.
        assert!((m[0].iou - 0.5).abs() < 1e-12, "{}", m[0].iou);
        let s = summarize(&m, &[]);
        assert_eq!((s.counted, s.found, s.components_used), (2, 1, 2));
        let only_b = summarize(&m, &[false, true]);
        assert_eq!((only_b.counted, only_b.found), (1, 1));
        assert!((only_b.median_abs_cos - 1.0).abs() < 1e-12);
    }

    #[test]
    fn support_counts_vertices_above_five_percent_of_the_peak() {
        let f: Vec<Vec3> = [1.0, 0.06, 0.05, 0.0, -0.5].iter().map(|&x| [x, 0.0, 0.0]).collect();
        assert_eq!(support(&f, SUPPORT_FRACTION), vec![true, true, false, false, true]);
        assert_eq!(support_size(&f), 3);
        assert_eq!(support_size(&[[0.0; 3]; 4]), 0);
        assert_eq!(iou(&[true, true, false], &[false, true, true]), 1.0 / 3.0);
        assert_eq!(iou(&[false], &[false]), 0.0);
    }

    #[test]
    fn the_median_translation_of_a_local_field_is_removed() {
        let mut f = bump(101, 10, 5, [0.0, 2.0, 0.0]);
        let shift = [0.3, -0.2, 0.1];
        for d in f.iter_mut() {
            for c in 0..3 {
                d[c] += shift[c];
            }
        }
        remove_median_translation(&mut f);
        let clean = bump(101, 10, 5, [0.0, 2.0, 0.0]);
        for (a, b) in f.iter().zip(&clean) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn mismatched_or_non_finite_fields_are_refused() {
        assert!(cosine(&[[1.0, 0.0, 0.0]], &[]).is_err());
        assert!(cosine(&[[f64::NAN, 0.0, 0.0]], &[[1.0, 0.0, 0.0]]).is_err());
        assert_eq!(cosine(&[[0.0; 3]], &[[1.0, 0.0, 0.0]]).unwrap(), 0.0);
        assert!(best_matches(&[vec![[1.0, 0.0, 0.0]]], &[]).is_err());
    }
}
