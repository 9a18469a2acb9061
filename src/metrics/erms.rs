//! Erms (Neumann et al. 2013, docs/design.md § Metrics and protocol): the root-mean-square vertex coordinate
//! error, `Erms = 1000·sqrt(Σ_f Σ_v ‖v − v'‖² / (3·F·N))`, reported in the data's own units
//! × 1000.
//!
//! Methods whose representation drops translation are compared after moving each result
//! frame's vertex centroid (unweighted mean) onto the ground truth frame's
//! ([`Alignment::Centroid`]); [`Erms`] keeps the alignment with the number so that a report
//! always says which one it used.

use std::fmt;

use crate::error::{Error, Result};
use crate::mesh::Vec3;

/// How a result is aligned to the ground truth before measuring.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Alignment {
    /// Absolute positions.
    None,
    /// Each result frame translated so that its vertex centroid equals the ground truth's.
    Centroid,
}

impl fmt::Display for Alignment {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Alignment::None => "none",
            Alignment::Centroid => "centroid",
        })
    }
}

/// The translation added to every result vertex before measuring under `alignment` (data
/// units): zero for [`Alignment::None`] or no vertices, else the mean of `truth_v − result_v`
/// (so the shifted result's centroid is the truth's). Assumes equal lengths (pairs beyond the
/// shorter slice are ignored, the mean divides by `truth.len()`).
pub fn alignment_shift(truth: &[Vec3], result: &[Vec3], alignment: Alignment) -> Vec3 {
    match alignment {
        Alignment::None => [0.0; 3],
        Alignment::Centroid if truth.is_empty() => [0.0; 3],
        Alignment::Centroid => {
            let n = truth.len() as f64;
            std::array::from_fn(|k| truth.iter().zip(result).map(|(t, r)| t[k] - r[k]).sum::<f64>() / n)
        }
    }
}

/// `‖truth_v − (result_v + shift)‖²` of one vertex (data units²).
#[inline]
pub fn vertex_squared_error(truth: Vec3, result: Vec3, shift: Vec3) -> f64 {
    (0..3).map(|k| (truth[k] - result[k] - shift[k]).powi(2)).sum::<f64>()
}

/// Sum over vertices of `‖truth_v − result_v‖²` for one frame (data units²), after
/// `alignment`. Errors when the vertex counts differ.
pub fn frame_squared_error(truth: &[Vec3], result: &[Vec3], alignment: Alignment) -> Result<f64> {
    if truth.len() != result.len() {
        return Err(Error::Invalid(format!("frame has {} vertices, the result {}", truth.len(), result.len())));
    }
    let shift = alignment_shift(truth, result, alignment);
    Ok(truth.iter().zip(result).map(|(t, r)| vertex_squared_error(*t, *r, shift)).sum())
}

/// Erms from a sum of squared vertex distances and the number of coordinates it covers
/// (3 × vertices × frames): `1000·sqrt(sum / n_coords)`, data units × 1000; 0 when
/// `n_coords` is 0.
#[inline]
pub fn erms_from_squared_error(sum: f64, n_coords: usize) -> f64 {
    if n_coords == 0 { 0.0 } else { 1000.0 * (sum / n_coords as f64).sqrt() }
}

/// Erms of F result frames against F ground-truth frames of N vertices each (module docs), as
/// a bare number. Errors on a frame or vertex count mismatch; 0 for no vertices.
pub fn erms(truth: &[Vec<Vec3>], result: &[Vec<Vec3>], alignment: Alignment) -> Result<f64> {
    if truth.len() != result.len() {
        return Err(Error::Invalid(format!("{} ground-truth frames, {} result frames", truth.len(), result.len())));
    }
    let mut sum = 0.0;
    let mut count = 0usize;
    for (t, r) in truth.iter().zip(result) {
        sum += frame_squared_error(t, r, alignment)?;
        count += 3 * t.len();
    }
    Ok(erms_from_squared_error(sum, count))
}

/// An Erms value together with the alignment it was measured under.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Erms {
    /// `1000·sqrt(mean squared coordinate error)`, data units × 1000.
    pub value: f64,
    /// Alignment applied before measuring.
    pub alignment: Alignment,
}

impl Erms {
    /// Measures Erms under `alignment` (see [`erms`]).
    pub fn measure(truth: &[Vec<Vec3>], result: &[Vec<Vec3>], alignment: Alignment) -> Result<Erms> {
        Ok(Erms { value: erms(truth, result, alignment)?, alignment })
    }

    /// Raw (`Alignment::None`) and centroid-aligned Erms, in that order.
    pub fn raw_and_aligned(truth: &[Vec<Vec3>], result: &[Vec<Vec3>]) -> Result<[Erms; 2]> {
        Ok([Self::measure(truth, result, Alignment::None)?, Self::measure(truth, result, Alignment::Centroid)?])
    }
}

impl fmt::Display for Erms {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.6} (alignment {})", self.value, self.alignment)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erms_definition_and_centroid_alignment() {
        let t = vec![vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]];
        // Result shifted by (0.3, 0, 0) and one vertex off by 0.002 in y.
        let r = vec![vec![[0.3, 0.0, 0.0], [1.3, 0.002, 0.0]]];
        let none = erms(&t, &r, Alignment::None).unwrap();
        let want_none = 1000.0 * ((0.09 + 0.09 + 0.002f64 * 0.002) / 6.0).sqrt();
        assert!((none - want_none).abs() < 1e-12);
        // After centroid alignment only the y error remains: residuals ±0.001 in y.
        let cent = erms(&t, &r, Alignment::Centroid).unwrap();
        let want = 1000.0 * ((2.0 * 0.001f64 * 0.001) / 6.0).sqrt();
        assert!((cent - want).abs() < 1e-12, "{cent} vs {want}");
        assert!(erms(&t, &[], Alignment::None).is_err());
        assert!(frame_squared_error(&t[0], &r[0][..1], Alignment::None).is_err());

        let [raw, aligned] = Erms::raw_and_aligned(&t, &r).unwrap();
        assert_eq!((raw.value, raw.alignment), (none, Alignment::None));
        assert_eq!((aligned.value, aligned.alignment), (cent, Alignment::Centroid));
        assert!(aligned.to_string().contains("centroid"));
    }

    #[test]
    fn erms_averages_over_frames_and_coordinates() {
        // Two frames of one vertex: errors (3,4,0) (squared norm 25) and 0 → 1000·sqrt(25/6).
        let t = vec![vec![[0.0; 3]], vec![[1.0, 1.0, 1.0]]];
        let r = vec![vec![[3.0, 4.0, 0.0]], vec![[1.0, 1.0, 1.0]]];
        let e = erms(&t, &r, Alignment::None).unwrap();
        assert!((e - 1000.0 * (25.0f64 / 6.0).sqrt()).abs() < 1e-9);
        // A one-vertex frame is always matched exactly by centroid alignment.
        assert_eq!(erms(&t, &r, Alignment::Centroid).unwrap(), 0.0);
    }
}
