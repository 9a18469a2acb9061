//! How strongly each element's features answer position noise, and the feature-error weights
//! that follow from it (issue 53, `feature_weights = "noise"`).
//!
//! A representation built on 1-ring fits (ACAP) turns a small, even position noise into very
//! uneven feature noise: a vertex whose ring is nearly degenerate for the fit (a sliver, a
//! very flat or very unevenly spaced ring) carries feature noise thousands of times that of a
//! typical vertex. On the decimated planted face (`checkpoints/ground-truth/faceval-1e-4`) the
//! 1 % noisiest vertices carry 91 % of the training features' noise energy, and the noise's
//! energy is 1.9× the planted signal's (`examples/feature_noise_study.rs`); an unweighted feature loss spends the network on them.
//!
//! [`feature_noise_variance`] measures the sensitivity without any data but the rest mesh:
//! per element, the mean over `draws` noisy copies of the rest mesh (independent Gaussian noise
//! of standard deviation `level` × the bounding-box diagonal on every coordinate) of the squared
//! Euclidean distance between the copy's features and the rest's, both mapped by the caller's
//! `map` first (the network's feature scaling, so that the variance is in the units the loss
//! sees). At small `level` the features are linear in the noise, so the variances of two
//! elements stand in a ratio that does not depend on `level`, and their logarithms correlate
//! 0.97 with the measured noise of the face's training frames (0.95 on the body).
//!
//! [`noise_weights`] turns them into weights of the feature error: `w_e = min(1, m / v_e)` with
//! `m` the median variance — every element at most as noise-sensitive as the median keeps
//! weight 1, a noisier one is weighted down in proportion (the inverse-variance weight, capped
//! at the typical element's).

use crate::error::{Error, Result};
use crate::mesh::MeshSequence;
use crate::rng::Rng;

use super::{Features, Representation};

/// Noisy copies [`feature_noise_variance`] draws by default.
pub const NOISE_DRAWS: usize = 8;
/// Default noise level of the copies, as a fraction of the rest mesh's bounding-box diagonal
/// (the planted sets' 1e-4: small enough for the features to answer linearly).
pub const NOISE_LEVEL: f64 = 1e-4;

/// Per element of `rep` (`rep.n_elements()`): the mean squared distance between `map` of the
/// features of a noisy copy of the rest mesh and `map` of the rest's own, over `draws` copies
/// drawn with `seed` (module docs). Units: those of `map`'s output, squared.
///
/// `map` receives one frame's features (`Features` of 1 frame, `rep.width()` wide) and returns
/// features of 1 frame with `rep.n_elements()` elements (any width).
///
/// Errors when `draws` is 0, `level` is not positive and finite, `map` fails or changes the
/// element count, or a copy cannot be encoded.
pub fn feature_noise_variance(
    rep: &Representation,
    level: f64,
    draws: usize,
    seed: u64,
    map: &dyn Fn(Features) -> Result<Features>,
) -> Result<Vec<f64>> {
    if draws == 0 {
        return Err(Error::Invalid("feature noise variance: needs at least one noisy copy".into()));
    }
    if !(level.is_finite() && level > 0.0) {
        return Err(Error::Invalid(format!("feature noise variance: noise level {level} is not positive")));
    }
    let rest = rep.rest();
    let n_el = rep.n_elements();
    let (lo, hi) = rest.bounding_box();
    let diagonal = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    let sigma = level * diagonal;
    let mut rng = Rng::new(seed);
    let mut frames = Vec::with_capacity(draws + 1);
    frames.push(rest.positions.clone());
    for _ in 0..draws {
        frames.push(
            rest.positions
                .iter()
                .map(|p| [p[0] + sigma * rng.normal(), p[1] + sigma * rng.normal(), p[2] + sigma * rng.normal()])
                .collect(),
        );
    }
    let names = (0..=draws).map(|d| format!("noise{d}")).collect();
    let seq = MeshSequence { faces: rest.faces.clone(), frames, names };
    let all = rep.encode(&seq)?;
    let one = |f: usize| -> Result<Vec<f64>> {
        let x = Features { n_frames: 1, n_elements: all.n_elements, width: all.width, data: all.frame(f).to_vec() };
        let y = map(x)?;
        if y.n_frames != 1 || y.n_elements != n_el {
            return Err(Error::Invalid(format!(
                "feature noise variance: the map returned {} frames of {} elements for 1 of {n_el}",
                y.n_frames, y.n_elements
            )));
        }
        Ok(y.data)
    };
    let base = one(0)?;
    let width = base.len() / n_el.max(1);
    let mut var = vec![0.0f64; n_el];
    for d in 1..=draws {
        let x = one(d)?;
        for (e, v) in var.iter_mut().enumerate() {
            let s = e * width;
            *v += x[s..s + width].iter().zip(&base[s..s + width]).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
        }
    }
    for v in &mut var {
        *v /= draws as f64;
    }
    Ok(var)
}

/// Weights of the feature error from per-element noise variances: `min(1, m / v_e)` with `m`
/// the median of `variance` (the upper middle for an even count); 1 where `v_e` is 0 or not
/// finite, and all 1 when the median is 0 (module docs). Same length as `variance`, each in
/// (0, 1].
pub fn noise_weights(variance: &[f64]) -> Vec<f64> {
    let mut sorted: Vec<f64> = variance.iter().copied().filter(|v| v.is_finite()).collect();
    if sorted.is_empty() {
        return vec![1.0; variance.len()];
    }
    sorted.sort_by(f64::total_cmp);
    let m = sorted[sorted.len() / 2];
    variance.iter().map(|&v| if m > 0.0 && v.is_finite() && v > m { m / v } else { 1.0 }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use crate::representation::{RepresentationKind, RepresentationOptions};

    /// A bumpy grid (so that no ring is flat; the library's 8 × 7 criss-cross grid, spacing
    /// `scale`) with vertex 41 (a ring of 4) pushed almost onto its neighbour 40 (a ring of 8):
    /// the sliver's ring is the noisiest (20× the median variance).
    fn grid_with_sliver(scale: f64) -> (TriMesh, usize) {
        let mut mesh = crate::mesh::primitives::grid(8, 7, 8.0 * scale);
        for p in &mut mesh.positions {
            let (x, y) = (p[0] / scale, p[1] / scale);
            p[2] = 0.3 * scale * ((0.9 * x).sin() + (0.7 * y).cos());
        }
        let (v, u) = (41, 40);
        let (pu, pv) = (mesh.positions[u], mesh.positions[v]);
        mesh.positions[v] = [0, 1, 2].map(|c| pu[c] + 0.03 * (pv[c] - pu[c]));
        (mesh, v)
    }

    fn acap(mesh: &TriMesh) -> Representation {
        Representation::new(RepresentationKind::Acap, mesh, RepresentationOptions::default()).unwrap()
    }

    /// The sliver's vertex is the most noise-sensitive and weighted down; the median element
    /// keeps weight 1; the variances are those of the identity map squared-distance, the
    /// weights do not depend on the mesh's size (the noise is relative to its diagonal) and
    /// barely on the level (the linear regime), and the same seed gives the same numbers.
    #[test]
    fn a_sliver_is_noisier_and_weighted_down() {
        let (mesh, sliver) = grid_with_sliver(1.0);
        let rep = acap(&mesh);
        let id = |x: Features| Ok(x);
        let var = feature_noise_variance(&rep, NOISE_LEVEL, NOISE_DRAWS, 7, &id).unwrap();
        assert_eq!(var.len(), mesh.positions.len());
        let most = (0..var.len()).max_by(|&a, &b| var[a].total_cmp(&var[b])).unwrap();
        let mut sorted = var.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        assert!(
            var[sliver] > 10.0 * median,
            "the sliver's variance {} against the median {median} (noisiest: vertex {most}, {})",
            var[sliver],
            var[most]
        );
        let w = noise_weights(&var);
        assert!(w[sliver] < 0.1, "the sliver keeps weight {}", w[sliver]);
        assert!(w.iter().all(|&x| x > 0.0 && x <= 1.0));
        let at_one = w.iter().filter(|&&x| x == 1.0).count();
        assert!(at_one > var.len() / 2, "{at_one} of {} at weight 1", var.len());
        // Reproducible, and independent of the mesh's size.
        assert_eq!(var, feature_noise_variance(&rep, NOISE_LEVEL, NOISE_DRAWS, 7, &id).unwrap());
        let (big, _) = grid_with_sliver(40.0);
        let wb = noise_weights(&feature_noise_variance(&acap(&big), NOISE_LEVEL, NOISE_DRAWS, 7, &id).unwrap());
        for (a, b) in w.iter().zip(&wb) {
            assert!((a - b).abs() < 0.02 * a.max(*b), "weights {a} and {b} for the mesh 40× larger");
        }
        // A tenfold smaller level: the features answer linearly, the weights stay.
        let ws = noise_weights(&feature_noise_variance(&rep, NOISE_LEVEL / 10.0, NOISE_DRAWS, 7, &id).unwrap());
        for (a, b) in w.iter().zip(&ws) {
            assert!((a - b).abs() < 0.05 * a.max(*b), "weights {a} and {b} at a tenth of the level");
        }
        // A map that doubles the features quadruples the variances.
        let double = |mut x: Features| {
            x.data.iter_mut().for_each(|v| *v *= 2.0);
            Ok(x)
        };
        let v2 = feature_noise_variance(&rep, NOISE_LEVEL, NOISE_DRAWS, 7, &double).unwrap();
        for (a, b) in var.iter().zip(&v2) {
            assert!((4.0 * a - b).abs() <= 1e-9 * b.abs().max(1e-300), "{a} ×4 vs {b}");
        }
    }

    #[test]
    fn weights_of_edge_cases() {
        assert_eq!(noise_weights(&[]), Vec::<f64>::new());
        assert_eq!(noise_weights(&[0.0, 0.0, 0.0]), vec![1.0; 3]);
        assert_eq!(noise_weights(&[1.0, 2.0, 4.0, 8.0]), vec![1.0, 1.0, 1.0, 0.5]);
        assert_eq!(noise_weights(&[f64::NAN, 1.0, 3.0]), vec![1.0, 1.0, 1.0]);
        let (mesh, _) = grid_with_sliver(1.0);
        let rep = acap(&mesh);
        let id = |x: Features| Ok(x);
        assert!(feature_noise_variance(&rep, NOISE_LEVEL, 0, 1, &id).is_err());
        assert!(feature_noise_variance(&rep, 0.0, 1, 1, &id).is_err());
        assert!(feature_noise_variance(&rep, f64::NAN, 1, 1, &id).is_err());
        let drop =
            |x: Features| Ok(Features { n_frames: 1, n_elements: 1, width: x.width, data: x.data[..x.width].to_vec() });
        let e = feature_noise_variance(&rep, NOISE_LEVEL, 1, 1, &drop).unwrap_err().to_string();
        assert!(e.contains("elements"), "{e}");
    }
}
