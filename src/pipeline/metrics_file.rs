//! `metrics.json` of the artefact directory.

use serde::{Deserialize, Serialize};

use crate::methods::support_map::ComponentLocality;

/// Summary of a trained model's quality and cost, written as `metrics.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// `pca`, `splocs`, `region-pca` or `autoencoder`.
    pub method: String,
    /// Representation the method ran on.
    pub representation: String,
    /// Number of components K.
    pub components: usize,
    /// Erms (1000 · RMS vertex error, data units) over the training frames.
    pub train_erms: f64,
    /// Erms over the test frames (`null` without a test split). Linear models encode a test
    /// frame by least-squares weights; the autoencoder by its encoder (the network, its residual
    /// passes and its vertex steps: `encoder_passes`, `encoder_steps`).
    pub test_erms: Option<f64>,
    /// Autoencoder only: Erms over the test frames with codes fitted to every vertex
    /// ([`crate::pipeline::ae_fit::AeFitEncoder`], started from the encoder's code), the
    /// nonlinear counterpart of the linear models' least-squares weights. Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_erms_fitted: Option<f64>,
    /// Autoencoder with `encoder_passes > 0` only: Erms over the test frames with the network's
    /// plain one-pass codes (`test_erms` has the residual passes). Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_erms_one_pass: Option<f64>,
    /// Autoencoder whose encoder takes vertex steps (`encoder_steps > 0`) only: Erms over the
    /// test frames with the network's own codes (its encoder and residual passes, no steps;
    /// `test_erms` has the steps). Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_erms_network: Option<f64>,
    /// Erms over the validation frames (`data.validation`: held out of the training frames,
    /// encoded as test frames are); absent without a validation split.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validation_erms: Option<f64>,
    /// Number of validation frames (0 without a validation split).
    #[serde(default)]
    pub validation_frames: usize,
    /// How results were aligned to the ground truth before measuring: `none` or `centroid`
    /// (representations that drop translation are centroid-aligned).
    pub erms_alignment: String,
    /// Wall time of the fit (SPLOCS: including the heat-method set-up of the support maps;
    /// excluding loading, the representation, measuring and writing), seconds.
    pub train_seconds: f64,
    /// Wall time of computing the representation of the training frames, seconds.
    pub representation_seconds: f64,
    /// Iterations run.
    pub iterations: usize,
    /// Final objective (method's own units; `null` when the method has none).
    pub objective: Option<f64>,
    /// Whether a convergence test stopped the iterations.
    pub converged: Option<bool>,
    /// Number of training and test frames.
    pub train_frames: usize,
    pub test_frames: usize,
    /// Median in-support energy share of the components (`null` if not measured).
    pub median_energy_share: Option<f64>,
    /// Median support size (elements with non-zero magnitude).
    pub median_support_size: Option<f64>,
    /// Per-component locality, in component order.
    pub locality: Vec<ComponentLocality>,
    /// Vertex-space locality: per component (index order), the vertices it moves by more than
    /// 5 % of its peak, read around the rest shape ([`crate::model::component_fields`]).
    #[serde(default)]
    pub vertex_support: Vec<usize>,
    /// Median over the components of that count as a share of the vertices.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_vertex_support: Option<f64>,
    /// Autoencoder only: root-mean-square norm per training shape of the scaled training
    /// features, and the factor it put on every step size (`learning_rate_norm`; 1: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub feature_norm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learning_rate_scale: Option<f64>,
    /// A warning about the fit (the autoencoder: a run whose decoding is no better than the rest
    /// shape), also printed by `meshdeco train`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training_warning: Option<String>,
    /// Autoencoder only: the share of the best K linear components' gain over decoding every
    /// training shape as the rest shape that its own decoding makes, in feature error (SCAPE's
    /// default run 0.993, the noisy ground-truth test face 0.81; below 0.2 the run did not train).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training_gain: Option<f64>,
    /// Autoencoder with `dial_sparsity = "auto"` only: every readout of the dials it tried, the
    /// one kept marked `chosen` ([`DialReadout`]). Absent otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dial_readouts: Vec<DialReadout>,
}

/// One readout of the autoencoder's dials that `dial_sparsity = "auto"` tried.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DialReadout {
    /// The readout: 0 the latent dimensions, else the dial basis at this sparsity.
    pub dial_sparsity: f64,
    /// What the choice reads: the median over the network's K components of the share of each
    /// one's squared displacement that its tenth of vertices moving most carry, read around the
    /// rest shape ([`crate::metrics::recovery::energy_concentration`]; 0.1–1).
    pub median_concentration: f64,
    /// The median over them of the share of vertices each moves by more than 5 % of its peak
    /// (0–1; shown beside it, not chosen by).
    pub median_vertex_support: f64,
    /// The readout kept: the largest median concentration (a tie keeps the earlier).
    pub chosen: bool,
}

/// Median of a slice (mean of the two middle values for even lengths); `None` when empty.
pub fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v: Vec<f64> = values.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

#[cfg(test)]
mod tests {
    #[test]
    fn median_odd_even() {
        assert_eq!(super::median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(super::median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(super::median(&[]), None);
    }
}
