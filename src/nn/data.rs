//! Training data of the autoencoder: per-shape feature matrices `N × 9` (scaled ACAP features)
//! validated once, and their batching into the kernels' VCB layout or Burn tensors.

use burn::tensor::{Device, Tensor, TensorData};

use super::kernels::padded_width;
use crate::error::{Error, Result};
use crate::representation::Features;

/// Feature width of the autoencoder (ACAP: 9 numbers per vertex).
pub const WIDTH: usize = 9;

/// The shapes the autoencoder is trained on: `n_shapes` matrices `N × 9` (row-major, `f32`).
#[derive(Debug, Clone)]
pub struct TrainingData {
    n_shapes: usize,
    n_vertices: usize,
    /// Shape-major `[S, N, 9]`.
    data: Vec<f32>,
}

impl TrainingData {
    /// From a feature array (`width` must be 9). Errors name the first non-finite value by frame,
    /// vertex and channel.
    pub fn from_features(f: &Features) -> Result<Self> {
        if f.width != WIDTH {
            return Err(Error::Invalid(format!(
                "the autoencoder needs {WIDTH} numbers per vertex (ACAP features), got width {}",
                f.width
            )));
        }
        if f.n_frames == 0 || f.n_elements == 0 {
            return Err(Error::Invalid(format!(
                "no training data ({} frames × {} vertices)",
                f.n_frames, f.n_elements
            )));
        }
        if f.data.len() != f.n_frames * f.n_elements * f.width {
            return Err(Error::Invalid(format!(
                "feature array holds {} numbers, expected {} × {} × {}",
                f.data.len(),
                f.n_frames,
                f.n_elements,
                f.width
            )));
        }
        if let Some(p) = f.data.iter().position(|v| !v.is_finite()) {
            let (fr, rest) = (p / (f.n_elements * WIDTH), p % (f.n_elements * WIDTH));
            return Err(Error::Numerical(format!(
                "training features are not finite: frame {fr}, vertex {}, channel {} is {}",
                rest / WIDTH,
                rest % WIDTH,
                f.data[p]
            )));
        }
        Ok(TrainingData {
            n_shapes: f.n_frames,
            n_vertices: f.n_elements,
            data: f.data.iter().map(|&v| v as f32).collect(),
        })
    }

    /// Number of shapes S.
    pub fn n_shapes(&self) -> usize {
        self.n_shapes
    }

    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }

    /// Features of shape `s`, `N × 9` row-major.
    pub fn shape(&self, s: usize) -> &[f32] {
        let sz = self.n_vertices * WIDTH;
        &self.data[s * sz..(s + 1) * sz]
    }

    /// The shapes `indices` in VCB layout (see [`super::kernels`]) with the batch width padded to
    /// `padded_width(indices.len())`; padding lanes are zero.
    ///
    /// # Shapes
    /// output: `N × 9 × bp`
    pub fn batch_vcb(&self, indices: &[usize]) -> Vec<f32> {
        vcb_from_shapes(indices.iter().map(|&s| self.shape(s)), indices.len(), self.n_vertices)
    }

    /// The shapes `indices` in VCB layout of batch width `bp` (≥ `indices.len()`, a multiple of
    /// [`super::kernels::LANES`]); the other lanes are zero.
    pub fn batch_vcb_width(&self, indices: &[usize], bp: usize) -> Vec<f32> {
        assert!(bp >= indices.len() && bp.is_multiple_of(super::kernels::LANES));
        let mut out = vec![0.0f32; self.n_vertices * WIDTH * bp];
        for (j, &s) in indices.iter().enumerate() {
            for (row, v) in self.shape(s).iter().enumerate() {
                out[row * bp + j] = *v;
            }
        }
        out
    }

    /// Splits off `v` shapes, evenly spaced (shape `⌊(j + ½)·S/v⌋` for j < v), as a validation
    /// set: returns (the other shapes, the held-out ones) and the held-out indices.
    pub fn split_validation(&self, v: usize) -> Result<(TrainingData, TrainingData, Vec<usize>)> {
        let s = self.n_shapes;
        if v == 0 || v >= s {
            return Err(Error::config(
                "validation",
                format!("{v} held-out shapes of {s} training shapes: must be at least 1 and leave one to train on"),
            ));
        }
        let held: Vec<usize> = (0..v).map(|j| ((2 * j + 1) * s) / (2 * v)).collect();
        let keep: Vec<usize> = (0..s).filter(|i| !held.contains(i)).collect();
        let sub = |idx: &[usize]| TrainingData {
            n_shapes: idx.len(),
            n_vertices: self.n_vertices,
            data: idx.iter().flat_map(|&i| self.shape(i).iter().copied()).collect(),
        };
        Ok((sub(&keep), sub(&held), held))
    }

    /// The shapes `indices` as a Burn tensor.
    ///
    /// # Shapes
    /// output: `[B, N, 9]`
    pub fn batch_tensor(&self, indices: &[usize], device: &Device) -> Tensor<3> {
        let mut v = Vec::with_capacity(indices.len() * self.n_vertices * WIDTH);
        for &s in indices {
            v.extend_from_slice(self.shape(s));
        }
        Tensor::from_data(TensorData::new(v, [indices.len(), self.n_vertices, WIDTH]), device)
    }
}

/// Packs `b` shape matrices (`N × 9` row-major each) into the VCB layout `N × 9 × bp`.
pub fn vcb_from_shapes<'a>(shapes: impl Iterator<Item = &'a [f32]>, b: usize, n: usize) -> Vec<f32> {
    let bp = padded_width(b);
    let mut out = vec![0.0f32; n * WIDTH * bp];
    for (j, s) in shapes.enumerate() {
        for (row, v) in s.iter().enumerate() {
            // row = i * 9 + c
            out[row * bp + j] = *v;
        }
    }
    out
}

/// Unpacks lane `j` of a VCB buffer (`N × 9 × bp`) into an `N × 9` row-major `f64` matrix.
pub fn shape_from_vcb(buf: &[f32], bp: usize, j: usize) -> Vec<f64> {
    buf.chunks_exact(bp).map(|r| r[j] as f64).collect()
}
