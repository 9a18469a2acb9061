//! Training data of the autoencoder: per-shape feature matrices `N × 9` (scaled ACAP features)
//! validated once, and their batching into the kernels' VCB layout or Burn tensors.
//!
//! The shapes live either in memory (`f32`, shape-major) or in a feature cache file
//! ([`crate::representation::feature_cache::FeatureFile`]), read a shape at a time when a batch
//! needs it (each frame checked against its checksum) and scaled on the way in — the same
//! arithmetic as scaling in memory, so both give the same numbers; with the file, memory is a
//! batch's, not the data's.

use std::borrow::Cow;
use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};

use super::kernels::padded_width;
use crate::error::{Error, Result};
use crate::representation::Features;
use crate::representation::feature_cache::FeatureFile;
use crate::representation::scaling::FeatureScaling;

/// Feature width of the autoencoder (ACAP: 9 numbers per vertex).
pub const WIDTH: usize = 9;

/// Where the shapes are.
#[derive(Debug, Clone)]
enum Storage {
    /// Shape-major `[S, N, 9]`.
    Memory(Vec<f32>),
    /// Unscaled features in a cache file: shape `s` is the file's frame `frames[s]`, scaled.
    File { file: Arc<FeatureFile>, scaling: FeatureScaling, frames: Vec<usize> },
}

/// The shapes the autoencoder is trained on: `n_shapes` matrices `N × 9` (row-major, `f32`).
#[derive(Debug, Clone)]
pub struct TrainingData {
    n_shapes: usize,
    n_vertices: usize,
    storage: Storage,
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
            storage: Storage::Memory(f.data.iter().map(|&v| v as f32).collect()),
        })
    }

    /// The frames of a feature cache file (unscaled ACAP features, width 9), scaled by `scaling`
    /// as they are read. The file's values were checked finite when it was written, and each
    /// frame is checked against its checksum when read.
    pub fn from_feature_file(file: Arc<FeatureFile>, scaling: FeatureScaling) -> Result<Self> {
        let h = file.header();
        if h.width != WIDTH || scaling.width != WIDTH {
            return Err(Error::Invalid(format!(
                "the autoencoder needs {WIDTH} numbers per vertex (ACAP features), the cache {} holds width {} (scaling width {})",
                file.path().display(),
                h.width,
                scaling.width
            )));
        }
        if h.n_frames == 0 || h.n_elements == 0 {
            return Err(Error::Invalid(format!(
                "no training data ({} frames × {} vertices)",
                h.n_frames, h.n_elements
            )));
        }
        scaling.validate()?;
        let (n_shapes, n_vertices) = (h.n_frames, h.n_elements);
        Ok(TrainingData {
            n_shapes,
            n_vertices,
            storage: Storage::File { file, scaling, frames: (0..n_shapes).collect() },
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

    /// True when the shapes are read from a file as they are needed.
    pub fn is_streamed(&self) -> bool {
        matches!(self.storage, Storage::File { .. })
    }

    /// Features of shape `s`, `N × 9` row-major (borrowed from memory, or read from the file).
    pub fn shape(&self, s: usize) -> Result<Cow<'_, [f32]>> {
        let sz = self.n_vertices * WIDTH;
        if s >= self.n_shapes {
            return Err(Error::Invalid(format!("shape {s} of {}", self.n_shapes)));
        }
        match &self.storage {
            Storage::Memory(data) => Ok(Cow::Borrowed(&data[s * sz..(s + 1) * sz])),
            Storage::File { .. } => Ok(Cow::Owned(self.scaled_frame(s)?.into_iter().map(|v| v as f32).collect())),
        }
    }

    /// Shape `s` of streamed data, read from the file and scaled in `f64` (an error for shapes
    /// held in memory).
    fn scaled_frame(&self, s: usize) -> Result<Vec<f64>> {
        let Storage::File { file, scaling, frames } = &self.storage else {
            return Err(Error::Invalid("the shapes are held in memory, not in a feature file".into()));
        };
        let mut x = file.frame(frames[s])?;
        scaling.apply_in_place(&mut x)?;
        Ok(x)
    }

    /// Scaled `f64` features of the shapes `range` (what [`TrainingData::shape`] gives, before
    /// the cast to `f32`): for encoding the training shapes a run at a time. Only for streamed
    /// data; in memory the caller holds the `f64` features itself.
    pub fn scaled_features(&self, range: std::ops::Range<usize>) -> Result<Features> {
        if !self.is_streamed() {
            return Err(Error::Invalid("scaled_features: the shapes are held in memory".into()));
        }
        if range.end > self.n_shapes || range.start > range.end {
            return Err(Error::Invalid(format!("shapes {range:?} of {}", self.n_shapes)));
        }
        let mut out = Features::zeros(0, self.n_vertices, WIDTH);
        out.n_frames = range.len();
        out.data.reserve(range.len() * self.n_vertices * WIDTH);
        for s in range {
            out.data.extend_from_slice(&self.scaled_frame(s)?);
        }
        Ok(out)
    }

    /// The shapes `indices` in VCB layout (see [`super::kernels`]) with the batch width padded to
    /// `padded_width(indices.len())`; padding lanes are zero.
    ///
    /// # Shapes
    /// output: `N × 9 × bp`
    pub fn batch_vcb(&self, indices: &[usize]) -> Result<Vec<f32>> {
        self.batch_vcb_width(indices, padded_width(indices.len()))
    }

    /// The shapes `indices` in VCB layout of batch width `bp` (≥ `indices.len()`, a multiple of
    /// [`super::kernels::LANES`]); the other lanes are zero.
    pub fn batch_vcb_width(&self, indices: &[usize], bp: usize) -> Result<Vec<f32>> {
        assert!(bp >= indices.len() && bp.is_multiple_of(super::kernels::LANES));
        let mut out = vec![0.0f32; self.n_vertices * WIDTH * bp];
        for (j, &s) in indices.iter().enumerate() {
            for (row, v) in self.shape(s)?.iter().enumerate() {
                out[row * bp + j] = *v;
            }
        }
        Ok(out)
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
        let sub = |idx: &[usize]| -> TrainingData {
            let storage = match &self.storage {
                Storage::Memory(data) => {
                    let sz = self.n_vertices * WIDTH;
                    Storage::Memory(idx.iter().flat_map(|&i| data[i * sz..(i + 1) * sz].iter().copied()).collect())
                }
                Storage::File { file, scaling, frames } => Storage::File {
                    file: file.clone(),
                    scaling: scaling.clone(),
                    frames: idx.iter().map(|&i| frames[i]).collect(),
                },
            };
            TrainingData { n_shapes: idx.len(), n_vertices: self.n_vertices, storage }
        };
        Ok((sub(&keep), sub(&held), held))
    }

    /// The shapes `indices` as a Burn tensor.
    ///
    /// # Shapes
    /// output: `[B, N, 9]`
    pub fn batch_tensor(&self, indices: &[usize], device: &Device) -> Result<Tensor<3>> {
        let mut v = Vec::with_capacity(indices.len() * self.n_vertices * WIDTH);
        for &s in indices {
            v.extend_from_slice(&self.shape(s)?);
        }
        Ok(Tensor::from_data(TensorData::new(v, [indices.len(), self.n_vertices, WIDTH]), device))
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
