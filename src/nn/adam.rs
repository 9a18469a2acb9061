//! Adam for the latent map `C`, in place on the trainer's own buffers.
//!
//! `C` is by far the largest parameter (`K × 9N`: 13 M numbers on a 29 k-vertex mesh), so its
//! update is one fused pass ([`kernels::adam_step`]) over the parameters, the gradient and the two
//! moments, which also writes the squared vertex norms of the new `C` (for the next step's support
//! maps) and checks it for non-finite values. The arithmetic is Burn's Adam
//! ([`burn::optim::AdamConfig`], as configured by the trainer) operation for operation, so the
//! result is bit-identical to running Burn's optimizer on the same gradient. The small layer
//! parameters keep Burn's optimizer.

use super::config::AutoencoderConfig;
use super::kernels::{self, AdamScalars};

/// Adam's state for `C`: the step count and the two moments (empty before the first step).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ComponentAdam {
    /// Steps taken (Burn's `time`).
    pub time: usize,
    /// First moment, `[K, 9N]` (empty while `time == 0`).
    pub moment_1: Vec<f32>,
    /// Second moment, `[K, 9N]` (empty while `time == 0`).
    pub moment_2: Vec<f32>,
}

impl ComponentAdam {
    /// Starts a step on `len` parameters: allocates the moments at the first step, advances the
    /// step count and returns the step's scalars.
    pub fn begin_step(&mut self, cfg: &AutoencoderConfig, lr: f64, len: usize) -> AdamScalars {
        if self.time == 0 || self.moment_1.len() != len {
            // Written before being read on the first step (zero pages until then).
            self.moment_1 = vec![0.0; len];
            self.moment_2 = vec![0.0; len];
            self.time = 0;
        }
        self.time += 1;
        AdamScalars::new(cfg.beta1 as f32, cfg.beta2 as f32, cfg.epsilon as f32, lr, self.time)
    }

    /// One step with step size `lr` on `c` (`[K, 9N]`) from `grad`; writes `‖C_k,i‖²` of the
    /// updated `c` into `sq_norms` (`[K, N]`). Returns whether every updated entry is finite.
    pub fn step(
        &mut self,
        cfg: &AutoencoderConfig,
        lr: f64,
        c: &mut [f32],
        grad: &[f32],
        sq_norms: &mut [f32],
    ) -> bool {
        let a = self.begin_step(cfg, lr, c.len());
        kernels::adam_step(c, grad, &mut self.moment_1, &mut self.moment_2, &a, sq_norms)
    }
}

#[cfg(test)]
mod tests {
    use burn::optim::{AdamConfig, GradientsParams};
    use burn::tensor::{Tensor, TensorData};

    use super::*;
    use crate::nn::engine::tensor_to_vec;
    use crate::nn::model::AutoencoderModule;
    use crate::nn::rng::Rng;
    use crate::nn::training::default_device;

    /// The fused kernel reproduces Burn's Adam bit for bit over several steps (including the
    /// first, which Burn treats apart), with a step size that changes.
    #[test]
    fn component_adam_is_burns_adam_bit_for_bit() {
        let cfg = AutoencoderConfig { beta2: 0.99, epsilon: 1e-8, ..Default::default() };
        let (k, n) = (3, 40);
        let len = k * 9 * n;
        let mut rng = Rng::new(7);
        let init = rng.normal_vec(len, 0.3);
        let device = default_device();
        let mut module = AutoencoderModule {
            layers: Vec::new(),
            components: AutoencoderModule::component_blocks(&init, n, &device),
        };
        let mut burn = AdamConfig::new()
            .with_beta_1(cfg.beta1 as f32)
            .with_beta_2(cfg.beta2 as f32)
            .with_epsilon(cfg.epsilon as f32)
            .init();
        let mut mine = ComponentAdam::default();
        let mut c = init.clone();
        let mut sq = vec![0.0f32; k * n];
        for step in 0..5 {
            let mut g = rng.normal_vec(len, 1.0);
            g[3] = 0.0;
            g[4] = -0.0;
            let lr = 1e-2 / (1.0 + step as f64);
            let mut gp = GradientsParams::new();
            let id = module.components[0].id;
            gp.register(id, Tensor::<2>::from_data(TensorData::new(g.clone(), [k, 9 * n]), &device.clone().inner()));
            module = burn.step(lr, module, gp);
            assert!(mine.step(&cfg, lr, &mut c, &g, &mut sq));
            let want = tensor_to_vec(module.components[0].val());
            assert!(
                want.iter().zip(&c).all(|(a, b)| a.to_bits() == b.to_bits()),
                "step {step}: differs from Burn's Adam"
            );
            for (i, s) in sq.iter().enumerate() {
                let v = &c[9 * i..9 * i + 9];
                let plain: f32 = v.iter().map(|x| x * x).sum();
                assert!((s - plain).abs() <= 1e-5 * plain.max(1e-30), "squared norm {i}");
            }
        }
    }
}
