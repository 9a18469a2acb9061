//! Augmentation in (scaled) ACAP feature space: synthetic training shapes drawn afresh every
//! step from the training shapes, so that the encoder sees more than the few shapes it is given.
//!
//! Two kinds of synthetic shape, both made of two training shapes `a` and `b` (distinct, drawn
//! uniformly):
//! - **local** ([`AugmentMix::Local`]): `x = x_a + m ⊙ (x_b − x_a)` with a per-vertex mask `m`
//!   that is 1 within a random geodesic radius `r` of a random centre and falls to 0 over a
//!   band of width `r/2` beyond it (smoothstep). Shape `b`'s part around the centre is
//!   transplanted into shape `a`: a new combination of the parts' poses, the kind of shape a
//!   collection of poses holds and a few training shapes miss. ACAP features are per-vertex
//!   (rotation logarithm and stretch), so a per-vertex blend of two shapes' features is again a
//!   valid feature field (no cycle or sign ambiguity is created by the consistency).
//! - **blend** ([`AugmentMix::Blend`]): `x = x_a + α (x_b − x_a)`, α uniform in [0, 1] (a
//!   convex blend of two shapes).
//! - **mixed** ([`AugmentMix::Mixed`]): each draw is local or blend, with probability ½.
//!
//! Blends of features inside [−0.95, 0.95] stay inside it (convexity), so the scaled data's
//! range is kept. Centres come from a pool of [`POOL`] vertices (farthest-point-like spread by
//! a seeded random draw) whose normalised geodesic distance rows are computed once.

use serde::{Deserialize, Serialize};

use super::loss::CenterDistances;
use super::rng::Rng;
use crate::error::{Error, Result};

/// Number of precomputed centres of the local masks.
pub const POOL: usize = 64;

/// How synthetic shapes are made (`augment_mix` key).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AugmentMix {
    /// A region of one shape transplanted into another (smooth geodesic mask).
    #[default]
    Local,
    /// A convex blend of two whole shapes.
    Blend,
    /// Each draw is [`AugmentMix::Local`] or [`AugmentMix::Blend`] with probability ½.
    Mixed,
}

impl AugmentMix {
    /// Parses `local` | `blend`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "local" => Some(AugmentMix::Local),
            "blend" => Some(AugmentMix::Blend),
            "mixed" => Some(AugmentMix::Mixed),
            _ => None,
        }
    }
}

/// Draws synthetic shapes from a set of training shapes.
#[derive(Debug, Clone)]
pub struct Augmenter {
    mix: AugmentMix,
    radius: [f64; 2],
    n: usize,
    /// Normalised geodesic distance rows of the pool's centres (`f32`, N each).
    pool: Vec<Vec<f32>>,
}

/// Smoothstep mask: 1 for `d ≤ r`, 0 for `d ≥ r + w`, C¹ between.
#[inline]
pub fn mask(d: f32, r: f32, w: f32) -> f32 {
    if d <= r {
        1.0
    } else if d >= r + w || !d.is_finite() {
        0.0
    } else {
        let t = 1.0 - (d - r) / w;
        t * t * (3.0 - 2.0 * t)
    }
}

impl Augmenter {
    /// An augmenter on `n` vertices. With [`AugmentMix::Local`], the pool centres are drawn
    /// from `seed` (so a resumed run rebuilds the same pool) and their distance rows are asked
    /// of `distances` once. `radius` = [r_min, r_max] of the local region (normalised geodesic
    /// distance).
    pub fn new(
        mix: AugmentMix,
        radius: [f64; 2],
        n: usize,
        distances: &dyn CenterDistances,
        seed: u64,
    ) -> Result<Self> {
        let mut pool = Vec::new();
        if mix != AugmentMix::Blend {
            let mut rng = Rng::new(seed ^ 0xA06_0E47_0000_0001);
            let centers = rng.sample_distinct(n, POOL.min(n));
            for c in centers {
                let d = distances.distances(c);
                if d.len() != n {
                    return Err(Error::Invalid(format!(
                        "augmentation: expected {n} distances for centre {c}, got {}",
                        d.len()
                    )));
                }
                pool.push(d.iter().map(|&x| if x.is_finite() { x as f32 } else { f32::INFINITY }).collect());
            }
        }
        Ok(Augmenter { mix, radius, n, pool })
    }

    /// How synthetic shapes are made.
    pub fn mix(&self) -> AugmentMix {
        self.mix
    }

    /// Number of vertices N of the shapes it draws.
    pub fn n_vertices(&self) -> usize {
        self.n
    }

    /// Draws one synthetic shape from `shapes` (each `N × 9` row-major) and writes it through
    /// `put(row, value)` for every row `i * 9 + c` (so the caller can write straight into a
    /// batch layout). Needs at least one shape; with one shape the shape itself is returned.
    ///
    /// `shapes(s)` gives shape `s` (borrowed, or read from a file); its error ends the draw.
    pub fn draw<'s>(
        &self,
        shapes: &dyn Fn(usize) -> Result<std::borrow::Cow<'s, [f32]>>,
        n_shapes: usize,
        rng: &mut Rng,
        mut put: impl FnMut(usize, f32),
    ) -> Result<()> {
        let a = rng.below(n_shapes);
        let b = if n_shapes > 1 { (a + 1 + rng.below(n_shapes - 1)) % n_shapes } else { a };
        let (xa, xb) = (shapes(a)?, shapes(b)?);
        let (xa, xb): (&[f32], &[f32]) = (&xa, &xb);
        debug_assert!(xa.len() == 9 * self.n && xb.len() == 9 * self.n);
        let local = match self.mix {
            AugmentMix::Local => true,
            AugmentMix::Blend => false,
            AugmentMix::Mixed => rng.uniform() < 0.5,
        };
        if !local {
            let t = rng.uniform() as f32;
            for (row, (&u, &v)) in xa.iter().zip(xb).enumerate() {
                put(row, u + t * (v - u));
            }
            return Ok(());
        }
        let d = &self.pool[rng.below(self.pool.len())];
        let r = (self.radius[0] + rng.uniform() * (self.radius[1] - self.radius[0])) as f32;
        let w = 0.5 * r;
        for (i, &di) in d.iter().enumerate() {
            let m = mask(di, r, w);
            for c in 0..9 {
                let row = i * 9 + c;
                let (u, v) = (xa[row], xb[row]);
                put(row, u + m * (v - u));
            }
        }
        Ok(())
    }
}
