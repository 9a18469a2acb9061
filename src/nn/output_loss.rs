//! A loss on the decoded features beyond the paper's feature error, supplied by the caller.
//!
//! The network sees only scaled features; what the features mean (ACAP rotations and stretches
//! whose reconstruction gives vertices) lives outside it. [`OutputLoss`] lets the pipeline add
//! a term measured there — the vertex term of `lambda_vertex`
//! ([`crate::pipeline::ae_vertex_loss`]) — while the network code stays free of geometry.

/// A per-shape loss on the decoder's output, with its gradient.
pub trait OutputLoss: Sync {
    /// Adds `scale · ∂ℓ_j/∂X̂_j` into `grad` for every lane j in `lanes` and returns `Σ_j ℓ_j`
    /// (unscaled), where `ℓ_j` compares lane j of the decoded batch with lane j of the input.
    /// A non-finite return value stops training with an error.
    ///
    /// # Shapes
    /// - `x`, `xhat`, `grad`: `[9N, bp]` (VCB: row `i·9 + c`, lane j at `row·bp + j`), the input
    ///   batch, the decoded batch and `∂L/∂X̂`; lanes not listed stay untouched.
    /// - `lanes`: distinct lane indices below `bp`.
    fn add_loss_and_grad(
        &self,
        x: &[f32],
        xhat: &[f32],
        bp: usize,
        lanes: &[usize],
        scale: f32,
        grad: &mut [f32],
    ) -> f64;
}

/// An [`OutputLoss`], the lanes of the batch it sees this step (the vertex term's
/// `vertex_batch` shapes) and its weight this step ([`crate::nn::AutoencoderConfig::lambda_vertex_at`]).
pub type OutputTerm<'a> = (&'a dyn OutputLoss, &'a [usize], f64);
