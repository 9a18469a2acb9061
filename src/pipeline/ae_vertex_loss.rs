//! The autoencoder's vertex term (`lambda_vertex`): the error of a decoded shape measured where
//! the user measures it, on the reconstructed vertices, rather than on the ACAP features.
//!
//! For each shape of a training batch (lane j), with x the input's scaled features and x̂ the
//! decoder's output,
//!
//! ```text
//! ℓ_j = Σ_i ‖p_i(x̂) − p_i(x)‖² / d²,    p = ACAP-decode(T(unscale(·)))
//! ```
//!
//! where d is the rest mesh's bounding-box diagonal (so ℓ is dimensionless) and T_i =
//! exp(logR_i)·S_i. Both reconstructions have the reference's centroid, so ℓ_j·d²/N is the
//! centroid-aligned mean squared vertex error of the network on that shape (the quantity Erms
//! measures), where the feature error weighs a rotation error at a joint the same as one at a
//! fingertip although the first moves a whole limb.
//!
//! **Gradient.** The decoding is affine in the T_i ([`Acap::decode_transforms`]): with
//! ΔT_i = T_i(x̂) − T_i(x), p(x̂) − p(x) = A₀ΔT (one solve), and ∂ℓ/∂T = A₀ᵀ(2(p(x̂) − p(x))/d²)
//! (one adjoint solve, [`Acap::decode_transforms_adjoint`]); then per vertex through T_i(f_i)
//! ([`crate::representation::acap::feature_transform_vjp`], closed form) and the scaling's
//! inverse. Two solves with the decoder's factor per shape and step; the lanes run in parallel.
//! T(x) of an input seen before (the training shapes of a full batch, every step) comes from a
//! cache.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::math::mat3::Mat3;
use crate::mesh::{Vec3, bounding_box};
use crate::nn::OutputLoss;
use crate::representation::acap::{
    Acap, FeatureMap, feature_rotation, feature_transform_vjp_with, feature_transform_with,
};
use crate::representation::scaling::FeatureScaling;

/// The vertex term of one ACAP decoder and feature scaling (see the module docs).
pub struct AcapVertexLoss<'a> {
    acap: &'a Acap,
    /// Per feature dimension: (∂f/∂x̂, centre) of the scaling's inverse.
    unscale: [(f64, f64); 9],
    /// The decoding of T = 0 (the affine map's constant part).
    offset: Vec<Vec3>,
    /// 1/d².
    inv_d2: f64,
    /// T(x) of inputs seen before, by a hash of the lane's bits (the bits are kept and compared).
    cache: Mutex<HashMap<u64, CachedInput>>,
    /// Most inputs cached (about 64 MB).
    cache_entries: usize,
}

/// A cached input: its bits and its transforms.
type CachedInput = (Vec<u32>, Arc<Vec<Mat3>>);

impl<'a> AcapVertexLoss<'a> {
    /// The term for features scaled by `scaling` (width 9) and decoded by `acap`, whose rest
    /// mesh sets the unit d (its bounding-box diagonal; must be positive).
    pub fn new(acap: &'a Acap, scaling: &FeatureScaling) -> Result<Self> {
        let unscale = scaling.inverse_affine_array::<9>()?;
        let (lo, hi) = bounding_box(acap.reference());
        let d2: f64 = (0..3).map(|c| (hi[c] - lo[c]) * (hi[c] - lo[c])).sum();
        if !(d2.is_finite() && d2 > 0.0) {
            return Err(Error::Invalid("vertex term: the rest mesh has no extent".into()));
        }
        let offset = acap.decode_transforms(&vec![[[0.0; 3]; 3]; acap.n_vertices()])?;
        let entry_bytes = acap.n_vertices() * (9 * 4 + 9 * 8);
        Ok(AcapVertexLoss {
            acap,
            unscale,
            offset,
            inv_d2: 1.0 / d2,
            cache: Mutex::new(HashMap::new()),
            cache_entries: (64 << 20) / entry_bytes.max(1),
        })
    }

    /// T(x) of one lane's input (N transforms), from the cache when this exact input was seen
    /// before (the training shapes of a full batch come back every step).
    fn input_transforms(&self, x: &[f32], bp: usize, j: usize) -> Arc<Vec<Mat3>> {
        let n = self.acap.n_vertices();
        let column: Vec<u32> = (0..9 * n).map(|r| x[r * bp + j].to_bits()).collect();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for &v in &column {
            h = (h ^ v as u64).wrapping_mul(0x0100_0000_01b3);
        }
        if let Ok(cache) = self.cache.lock()
            && let Some((col, t)) = cache.get(&h)
            && *col == column
        {
            return t.clone();
        }
        let u = &self.unscale;
        let t: Arc<Vec<Mat3>> = Arc::new(
            column
                .chunks_exact(9)
                .map(|v| {
                    let f: [f64; 9] = std::array::from_fn(|q| f32::from_bits(v[q]) as f64 * u[q].0 + u[q].1);
                    self.acap.map().transform(&f)
                })
                .collect(),
        );
        if let Ok(mut cache) = self.cache.lock()
            && cache.len() < self.cache_entries
        {
            cache.insert(h, (column, t.clone()));
        }
        t
    }

    /// ℓ of one lane and ∂ℓ/∂x̂ (9N, vertex-major).
    fn lane(&self, x: &[f32], xhat: &[f32], bp: usize, j: usize) -> Result<(f64, Vec<f32>)> {
        let n = self.acap.n_vertices();
        let u = &self.unscale;
        let tx = self.input_transforms(x, bp, j);
        let fh: Vec<[f64; 9]> =
            (0..n).map(|i| std::array::from_fn(|q| xhat[(i * 9 + q) * bp + j] as f64 * u[q].0 + u[q].1)).collect();
        // ACAP's rotations once per lane, for T and its vector–Jacobian product alike.
        let rh: Vec<Mat3> = match self.acap.map() {
            FeatureMap::RotationStretch => fh.iter().map(|f| feature_rotation(f)).collect(),
            FeatureMap::Gradient => Vec::new(),
        };
        let transform = |i: usize| match self.acap.map() {
            FeatureMap::RotationStretch => feature_transform_with(&fh[i], &rh[i]),
            map => map.transform(&fh[i]),
        };
        let dt: Vec<Mat3> = (0..n)
            .zip(tx.iter())
            .map(|(i, tt)| {
                let ta = transform(i);
                std::array::from_fn(|a| std::array::from_fn(|c| ta[a][c] - tt[a][c]))
            })
            .collect();
        let p = self.acap.decode_transforms(&dt)?;
        let mut loss = 0.0;
        let g: Vec<Vec3> = p
            .iter()
            .zip(&self.offset)
            .map(|(p, o)| {
                let d: Vec3 = std::array::from_fn(|c| p[c] - o[c]);
                loss += d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                std::array::from_fn(|c| 2.0 * self.inv_d2 * d[c])
            })
            .collect();
        let adj = self.acap.decode_transforms_adjoint(&g)?;
        let mut out = vec![0.0f32; 9 * n];
        for (i, (f, a)) in fh.iter().zip(&adj).enumerate() {
            let v = match self.acap.map() {
                FeatureMap::RotationStretch => feature_transform_vjp_with(f, &rh[i], a),
                map => map.transform_vjp(f, a),
            };
            for q in 0..9 {
                out[i * 9 + q] = (v[q] * u[q].0) as f32;
            }
        }
        Ok((loss * self.inv_d2, out))
    }
}

impl OutputLoss for AcapVertexLoss<'_> {
    fn add_loss_and_grad(
        &self,
        x: &[f32],
        xhat: &[f32],
        bp: usize,
        lanes: &[usize],
        scale: f32,
        grad: &mut [f32],
    ) -> f64 {
        let done: Vec<Result<(f64, Vec<f32>)>> = lanes.par_iter().map(|&j| self.lane(x, xhat, bp, j)).collect();
        let mut total = 0.0;
        for (&j, lane) in lanes.iter().zip(done) {
            let Ok((l, g)) = lane else { return f64::NAN };
            total += l;
            for (row, v) in g.iter().enumerate() {
                grad[row * bp + j] += scale * v;
            }
        }
        total
    }
}
