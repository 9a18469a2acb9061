//! Reconstruction of unseen shapes from sparse control points (Neumann et al. 2013 §4.1, Fig. 5;
//! Tan et al. 2018, Fig. 6).
//!
//! Control points: n vertices chosen by farthest-point sampling in edge-path distance on the
//! rest mesh ([`crate::geometry::farthest_point_sampling`]) from a random start vertex (seeded).
//! The sampling is nested — the first n of a run of m > n points are the n-point set — so one
//! sampling per trial serves every n.
//!
//! Fit: for a linear model of vertex displacements (PCA, SPLOCS on displacements; region PCA),
//! the weights w minimise `Σ_{v ∈ S} ‖x_v(w) − t_v‖² + γ·s·‖w‖²` over the control set S, with
//! `t_v` the test shape's position of v, `x_v(w)` the model's, honouring the model's weight
//! constraint (SPLOCS Eq. 4: w ≥ 0), via [`crate::methods::posing`] with w0 = 0 (PCA: the mean
//! shape; SPLOCS: the rest shape). The Tikhonov term keeps the system well-posed when 3n < K;
//! γ is dimensionless (s = the mean diagonal of the data-term Hessian; default 1e-3, i.e. 0.1 %
//! of a typical weight's data response), so with enough points the fit is within round-off of
//! plain least squares. The full shape is then the model's reconstruction from w, measured
//! against the test shape with Erms (no alignment: displacement models keep translation).
//!
//! Autoencoder: the latent code is optimised to meet the points
//! ([`crate::pipeline::ae_fit::AeFitEncoder`], Levenberg–Marquardt, the same γ, start code = the
//! training reference shape's code, [`crate::pipeline::ae_fit::POINT_FIT_ITERATIONS`] iterations at most). Its ACAP decoding
//! fixes the centroid, so the best global translation (control points' mean residual) is
//! applied in closed form, and the result is the decoded shape moved by it — measured, like the
//! linear models, without further alignment.
//!
//! SPLOCS on triangle gradients (nonlinear Poisson decoding of rotations) is not fitted here.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::farthest_point_sampling::FarthestPointSampler;
use crate::geometry::graph_distance::EdgeGraph;
use crate::mesh::Vec3;
use crate::metrics::erms::{Alignment, erms};
use crate::model::Model;
use crate::rng::Rng;

/// Mean, minimum and maximum Erms over trials for one number of control points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControlPointErms {
    /// Number of control points n.
    pub n: usize,
    /// Mean over trials of the Erms over all test shapes.
    pub erms_mean: f64,
    pub erms_min: f64,
    pub erms_max: f64,
    /// Number of trials (random start vertices).
    pub trials: usize,
}

/// Random start vertices of the trials (seeded).
pub fn start_vertices(n_vertices: usize, trials: usize, seed: u64) -> Vec<usize> {
    let mut rng = Rng::new(seed);
    (0..trials).map(|_| rng.below(n_vertices.max(1))).collect()
}

/// Erms versus n: for each trial, farthest-point sampling from a random start on the rest mesh,
/// then for every n in `counts` the fit of every `test` shape (data units) from its first n
/// points. Counts above the vertex count are skipped.
pub fn erms_curve(
    model: &dyn Model,
    test: &[Vec<Vec3>],
    counts: &[usize],
    trials: usize,
    gamma: f64,
    seed: u64,
) -> Result<Vec<ControlPointErms>> {
    let rest = model.rest();
    let nv = rest.n_vertices();
    if let Some(s) = test.iter().find(|s| s.len() != nv) {
        return Err(Error::Invalid(format!("shape has {} vertices, the model {nv}", s.len())));
    }
    let counts: Vec<usize> = counts.iter().copied().filter(|&n| n <= nv).collect();
    let Some(&max_n) = counts.iter().max() else { return Ok(Vec::new()) };
    // Distances are edge-path lengths on the rest mesh in the model's own space (unit box or
    // data units): the same sampling either way, as the unit box is a uniform scaling.
    let graph = EdgeGraph::new(&rest.positions, &rest.faces);
    let sampler = FarthestPointSampler::new(&graph);
    let mut per_n: Vec<Vec<f64>> = vec![Vec::new(); counts.len()];
    for start in start_vertices(nv, trials, seed) {
        let points = sampler.sample(max_n, start)?;
        for (i, &n) in counts.iter().enumerate() {
            let fit = model.point_fit(&points[..n], gamma)?.ok_or_else(|| {
                Error::Invalid(format!(
                    "control points: a `{}` model on `{}` cannot be fitted to points",
                    model.kind().name(),
                    model.representation().name()
                ))
            })?;
            let rec = test.iter().map(|s| fit.reconstruct(s)).collect::<Result<Vec<_>>>()?;
            per_n[i].push(erms(test, &rec, Alignment::None)?);
        }
    }
    Ok(counts
        .iter()
        .zip(per_n)
        .map(|(&n, e)| ControlPointErms {
            n,
            erms_mean: e.iter().sum::<f64>() / e.len() as f64,
            erms_min: e.iter().cloned().fold(f64::INFINITY, f64::min),
            erms_max: e.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
            trials: e.len(),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use crate::mesh::primitives::icosphere;
    use crate::methods::{LinearModel, WeightConstraint};
    use crate::pipeline::linear::{LinearArtifact, LinearHeader};
    use crate::preprocess::UnitBox;
    use crate::representation::{Representation, RepresentationKind, RepresentationOptions};

    /// A 3-component displacement model on an icosphere: smooth global fields.
    fn model(constraint: WeightConstraint, unit_box: UnitBox) -> LinearArtifact {
        let rest = icosphere(2);
        let n = rest.n_vertices();
        let k = 3;
        let mut components = Vec::new();
        for c in 0..k {
            for p in &rest.positions {
                let f = [p[0] * p[1], (p[2] + c as f64).sin(), p[0] + 0.3 * c as f64 * p[2]];
                components.extend_from_slice(&[f[c % 3], f[(c + 1) % 3] * 0.5, f[(c + 2) % 3] * 0.25]);
            }
        }
        let lm = LinearModel {
            n_elements: n,
            width: 3,
            n_components: k,
            n_frames: 1,
            components,
            weights: vec![0.0; k],
            offset: (0..3 * n).map(|i| 0.01 * (i % 7) as f64).collect(),
            constraint,
        };
        let representation =
            Representation::new(RepresentationKind::Displacement, &rest, RepresentationOptions::default()).unwrap();
        LinearArtifact {
            header: LinearHeader {
                method: "pca".into(),
                representation: "displacement".into(),
                consistency: None,
                unit_box,
                components: k,
                constraint,
                train_frames: vec!["a".into()],
            },
            rest: TriMesh::new(rest.positions.clone(), rest.faces.clone()),
            model: lm,
            representation,
            shape_metric: Default::default(),
            data_metric: Default::default(),
        }
    }

    #[test]
    fn recovers_a_shape_in_the_span_exactly() {
        let ub = UnitBox { offset: [0.5, -1.0, 2.0], scale: 0.25 };
        for constraint in [WeightConstraint::Unconstrained, WeightConstraint::Nonnegative] {
            let a = model(constraint, ub);
            let w = [0.7, 0.2, 1.3];
            let truth = a.synthesize(&w).unwrap();
            let rest = a.rest.positions.clone();
            let pts = farthest_point_sampling_on(&rest, &a.rest.faces, 6);
            // γ = 0: plain (constrained) least squares on 18 equations for 3 unknowns.
            let fit = a.point_fit(&pts, 0.0).unwrap().unwrap();
            let rec = fit.reconstruct(&truth).unwrap();
            let e = erms(std::slice::from_ref(&truth), &[rec], Alignment::None).unwrap();
            assert!(e < 1e-6, "{constraint:?}: Erms {e}");
            // A small regulariser moves the answer only slightly.
            let fit = a.point_fit(&pts, 1e-3).unwrap().unwrap();
            let e = erms(std::slice::from_ref(&truth), &[fit.reconstruct(&truth).unwrap()], Alignment::None).unwrap();
            assert!(e > 0.0 && e < 5.0, "{constraint:?}: regularised Erms {e}");
        }
    }

    #[test]
    fn nonnegative_models_keep_nonnegative_weights() {
        let a = model(WeightConstraint::Nonnegative, UnitBox::identity());
        // A shape needing a negative first weight cannot be met exactly by w ≥ 0.
        let truth = a.synthesize(&[-0.8, 0.5, 0.5]).unwrap();
        let pts = farthest_point_sampling_on(&a.rest.positions, &a.rest.faces, 10);
        let rec = a.point_fit(&pts, 0.0).unwrap().unwrap().reconstruct(&truth).unwrap();
        let e = erms(std::slice::from_ref(&truth), &[rec], Alignment::None).unwrap();
        assert!(e > 1.0, "Erms {e}");
        let b = model(WeightConstraint::Unconstrained, UnitBox::identity());
        let rec = b.point_fit(&pts, 0.0).unwrap().unwrap().reconstruct(&truth).unwrap();
        assert!(erms(&[truth], &[rec], Alignment::None).unwrap() < 1e-6);
    }

    #[test]
    fn curve_is_seeded_and_exact_in_the_span() {
        let a = model(WeightConstraint::Unconstrained, UnitBox::identity());
        let test: Vec<Vec<Vec3>> =
            [[0.1, 0.2, 0.3], [1.0, -1.0, 0.5]].iter().map(|w| a.synthesize(w).unwrap()).collect();
        let c1 = erms_curve(&a, &test, &[2, 5, 10_000], 3, 0.0, 4).unwrap();
        assert_eq!(c1.iter().map(|c| c.n).collect::<Vec<_>>(), vec![2, 5]);
        assert!(c1.iter().all(|c| c.erms_max < 1e-6 && c.trials == 3));
        assert_eq!(c1, erms_curve(&a, &test, &[2, 5], 3, 0.0, 4).unwrap());
        assert!(a.point_fit(&[], 0.0).is_err());
    }

    fn farthest_point_sampling_on(p: &[Vec3], f: &[[usize; 3]], n: usize) -> Vec<usize> {
        crate::geometry::farthest_point_sampling::farthest_point_sampling(p, f, n, 0).unwrap()
    }
}
