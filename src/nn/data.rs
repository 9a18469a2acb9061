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

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use super::*;
    use crate::nn::kernels::LANES;
    use crate::representation::feature_cache::Header;
    use crate::representation::scaling::ScalingMode;

    /// Feature `c` of vertex `v` in frame `f`: distinct, exact in `f32`.
    fn value(f: usize, v: usize, c: usize) -> f64 {
        (100 * f + 10 * v + c) as f64 + 0.25
    }

    /// `n_frames` frames of `n_elements` vertices, width `width`, holding [`value`].
    fn features(n_frames: usize, n_elements: usize, width: usize) -> Features {
        let mut data = Vec::with_capacity(n_frames * n_elements * width);
        for f in 0..n_frames {
            for v in 0..n_elements {
                for c in 0..width {
                    data.push(value(f, v, c));
                }
            }
        }
        Features { n_frames, n_elements, width, data }
    }

    /// The numbers of frame `f` of `x` as `f32`.
    fn frame_f32(x: &Features, f: usize) -> Vec<f32> {
        x.frame(f).iter().map(|&v| v as f32).collect()
    }

    /// A fresh scratch folder for one test.
    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("meshdeco-nn-data-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Writes `x` as a feature cache file (the format of [`crate::representation::feature_cache`]:
    /// magic line, the `f64` data, the JSON header, the header's offset) and opens it.
    fn cache_file(path: &Path, x: &Features) -> FeatureFile {
        let mut bytes = b"MESHDECO-FEATURES 3\n".to_vec();
        let size = x.n_elements * x.width;
        let mut frame_crc32 = Vec::new();
        for f in 0..x.n_frames {
            let b: Vec<u8> = x.data[f * size..(f + 1) * size].iter().flat_map(|v| v.to_le_bytes()).collect();
            frame_crc32.push(crc32fast::hash(&b));
            bytes.extend(b);
        }
        let (mut lo, mut hi) = (vec![0.0f64; x.width], vec![0.0f64; x.width]);
        if !x.data.is_empty() {
            for k in 0..x.width {
                let col = x.data.iter().skip(k).step_by(x.width).copied();
                lo[k] = col.clone().fold(f64::INFINITY, f64::min);
                hi[k] = col.fold(f64::NEG_INFINITY, f64::max);
            }
        }
        let mut h = Header {
            key: "test".into(),
            n_frames: x.n_frames,
            n_elements: x.n_elements,
            width: x.width,
            frame_crc32,
            min_bits: lo.iter().map(|v| v.to_bits()).collect(),
            max_bits: hi.iter().map(|v| v.to_bits()).collect(),
            header_crc32: 0,
        };
        h.header_crc32 = h.checksum();
        let at = bytes.len() as u64;
        bytes.extend(serde_json::to_vec(&h).unwrap());
        bytes.extend(at.to_le_bytes());
        std::fs::write(path, bytes).unwrap();
        FeatureFile::open(path, "test", (x.n_frames, x.n_elements, x.width)).unwrap()
    }

    /// A scaling of width `width` that moves and stretches every dimension.
    fn scaling(width: usize) -> FeatureScaling {
        let min: Vec<f64> = (0..width).map(|k| k as f64 - 3.0).collect();
        let max: Vec<f64> = (0..width).map(|k| 400.0 + 2.0 * k as f64).collect();
        FeatureScaling::fit_column_ranges(&min, &max, ScalingMode::PerDimension).unwrap()
    }

    #[test]
    fn shapes_in_memory_are_the_frames_as_f32() {
        let x = features(3, 2, WIDTH);
        let d = TrainingData::from_features(&x).unwrap();
        assert_eq!((d.n_shapes(), d.n_vertices(), d.is_streamed()), (3, 2, false));
        for s in 0..3 {
            let shape = d.shape(s).unwrap();
            assert!(matches!(shape, Cow::Borrowed(_)), "in memory, shape {s} is borrowed");
            assert_eq!(shape.as_ref(), frame_f32(&x, s).as_slice(), "shape {s}");
        }
        // Vertex 1, channel 4 of shape 2, by hand.
        assert_eq!(d.shape(2).unwrap()[9 + 4], 214.25);
        assert!(d.shape(3).is_err() && d.shape(usize::MAX).is_err());
        // In memory the caller holds the f64 features: none from here, not even an empty run.
        assert!(d.scaled_features(0..1).is_err() && d.scaled_features(0..0).is_err());
        // One shape of one vertex.
        let one = TrainingData::from_features(&features(1, 1, WIDTH)).unwrap();
        assert_eq!((one.n_shapes(), one.n_vertices()), (1, 1));
        assert_eq!(one.shape(0).unwrap().as_ref(), frame_f32(&features(1, 1, WIDTH), 0).as_slice());
    }

    #[test]
    fn from_features_refuses_other_widths_empty_sets_and_wrong_lengths() {
        let invalid = |x: &Features| matches!(TrainingData::from_features(x), Err(Error::Invalid(_)));
        assert!(invalid(&features(3, 2, 3)), "width 3");
        assert!(invalid(&features(2, 2, 10)), "width 10");
        assert!(invalid(&Features { n_frames: 0, n_elements: 2, width: WIDTH, data: Vec::new() }), "no frames");
        assert!(invalid(&Features { n_frames: 2, n_elements: 0, width: WIDTH, data: Vec::new() }), "no vertices");
        assert!(invalid(&Features { n_frames: 0, n_elements: 0, width: WIDTH, data: Vec::new() }), "nothing");
        let mut short = features(3, 2, WIDTH);
        short.data.pop();
        assert!(invalid(&short), "53 numbers for 3 × 2 × 9");
        let mut long = features(3, 2, WIDTH);
        long.data.push(1.0);
        assert!(invalid(&long), "55 numbers for 3 × 2 × 9");
        let mut other = features(3, 2, WIDTH);
        other.n_frames = 2;
        assert!(invalid(&other), "54 numbers for 2 × 2 × 9");
    }

    #[test]
    fn a_non_finite_feature_is_named_by_frame_vertex_and_channel() {
        let mut x = features(3, 2, WIDTH);
        // Frame 2, vertex 1, channel 4 (number 2·18 + 9 + 4 = 49), and a later one.
        x.data[49] = f64::NAN;
        x.data[53] = f64::INFINITY;
        match TrainingData::from_features(&x) {
            Err(Error::Numerical(m)) => assert!(m.contains("frame 2, vertex 1, channel 4 is NaN"), "{m}"),
            other => panic!("expected a numerical error, got {other:?}"),
        }
        let mut x = features(3, 2, WIDTH);
        x.data[25] = f64::NEG_INFINITY; // frame 1, vertex 0, channel 7
        match TrainingData::from_features(&x) {
            Err(Error::Numerical(m)) => assert!(m.contains("frame 1, vertex 0, channel 7 is -inf"), "{m}"),
            other => panic!("expected a numerical error, got {other:?}"),
        }
    }

    #[test]
    fn streamed_shapes_are_the_file_frames_scaled() {
        let dir = scratch("streamed");
        let x = features(3, 2, WIDTH);
        let sc = scaling(WIDTH);
        let file = Arc::new(cache_file(&dir.join("a.features"), &x));
        let d = TrainingData::from_feature_file(file, sc.clone()).unwrap();
        assert_eq!((d.n_shapes(), d.n_vertices(), d.is_streamed()), (3, 2, true));
        // The same numbers as the scaled features held in memory.
        let scaled = sc.apply(&x).unwrap();
        let mem = TrainingData::from_features(&scaled).unwrap();
        for s in 0..3 {
            let shape = d.shape(s).unwrap();
            assert!(matches!(shape, Cow::Owned(_)));
            assert_eq!(shape.as_ref(), frame_f32(&scaled, s).as_slice(), "shape {s}");
            assert_eq!(shape.as_ref(), mem.shape(s).unwrap().as_ref(), "shape {s}");
        }
        // Dimension 0 maps [-3, 400] to [-0.95, 0.95]: value(1, 1, 0) = 110.25.
        let want = (110.25 - 198.5) * (1.9 / 403.0);
        assert!((d.shape(1).unwrap()[9] as f64 - want).abs() < 1e-6);
        assert!(d.shape(3).is_err());
        // scaled_features: the f64 numbers of a run of shapes.
        let all = d.scaled_features(0..3).unwrap();
        assert_eq!(all, scaled);
        let first = d.scaled_features(0..1).unwrap();
        assert_eq!((first.n_frames, first.n_elements, first.width), (1, 2, WIDTH));
        assert_eq!(first.data, scaled.frame(0));
        let last = d.scaled_features(2..3).unwrap();
        assert_eq!((last.n_frames, last.data.as_slice()), (1, scaled.frame(2)));
        let tail = d.scaled_features(1..3).unwrap();
        assert_eq!((tail.n_frames, tail.data.as_slice()), (2, &scaled.data[18..]));
        for r in [0..0, 1..1, 3..3] {
            let empty = d.scaled_features(r.clone()).unwrap();
            assert_eq!((empty.n_frames, empty.n_elements, empty.width, empty.data.len()), (0, 2, WIDTH, 0), "{r:?}");
        }
        #[allow(clippy::reversed_empty_ranges)]
        let backwards = [2..1, 3..0];
        for r in backwards {
            assert!(d.scaled_features(r.clone()).is_err(), "{r:?}");
        }
        for r in [0..4, 3..4, 2..7] {
            assert!(d.scaled_features(r.clone()).is_err(), "{r:?}");
        }
        // Held out from streamed data: shape ⌊1.5⌋ = 1, still read from the file.
        let (fit, val, held) = d.split_validation(1).unwrap();
        assert_eq!(held, [1]);
        assert!(fit.is_streamed() && val.is_streamed());
        assert_eq!((fit.n_shapes(), val.n_shapes(), fit.n_vertices()), (2, 1, 2));
        assert_eq!(val.shape(0).unwrap().as_ref(), frame_f32(&scaled, 1).as_slice());
        assert_eq!(fit.shape(1).unwrap().as_ref(), frame_f32(&scaled, 2).as_slice());
        assert_eq!(fit.scaled_features(0..2).unwrap().data, [scaled.frame(0), scaled.frame(2)].concat());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn from_feature_file_refuses_other_widths_and_empty_files() {
        let dir = scratch("refused");
        let nine = Arc::new(cache_file(&dir.join("nine.features"), &features(2, 2, WIDTH)));
        let three = Arc::new(cache_file(&dir.join("three.features"), &features(2, 2, 3)));
        let invalid = |r: Result<TrainingData>| matches!(r, Err(Error::Invalid(_)));
        assert!(TrainingData::from_feature_file(nine.clone(), scaling(WIDTH)).is_ok());
        assert!(invalid(TrainingData::from_feature_file(nine.clone(), scaling(3))), "scaling of width 3");
        assert!(invalid(TrainingData::from_feature_file(three.clone(), scaling(WIDTH))), "file of width 3");
        assert!(invalid(TrainingData::from_feature_file(three, scaling(3))), "both of width 3");
        let no_frames = Features { n_frames: 0, n_elements: 2, width: WIDTH, data: Vec::new() };
        let no_vertices = Features { n_frames: 2, n_elements: 0, width: WIDTH, data: Vec::new() };
        for (name, x) in [("no-frames", no_frames), ("no-vertices", no_vertices)] {
            let f = Arc::new(cache_file(&dir.join(format!("{name}.features")), &x));
            assert!(invalid(TrainingData::from_feature_file(f, scaling(WIDTH))), "{name}");
        }
        // An invalid scaling (min > max) is refused too.
        let mut bad = scaling(WIDTH);
        bad.min[3] = 1e9;
        assert!(TrainingData::from_feature_file(nine, bad).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn split_validation_holds_out_evenly_spaced_shapes() {
        let x = features(10, 2, WIDTH);
        let d = TrainingData::from_features(&x).unwrap();
        // ⌊(j + ½)·10/3⌋ for j = 0, 1, 2: 1, 5, 8.
        let (fit, val, held) = d.split_validation(3).unwrap();
        assert_eq!(held, [1, 5, 8]);
        let keep = [0usize, 2, 3, 4, 6, 7, 9];
        assert_eq!((fit.n_shapes(), val.n_shapes()), (7, 3));
        assert_eq!((fit.n_vertices(), val.n_vertices(), fit.is_streamed(), val.is_streamed()), (2, 2, false, false));
        for (i, &s) in keep.iter().enumerate() {
            assert_eq!(fit.shape(i).unwrap().as_ref(), frame_f32(&x, s).as_slice(), "fitted shape {i}");
        }
        for (i, &s) in held.iter().enumerate() {
            assert_eq!(val.shape(i).unwrap().as_ref(), frame_f32(&x, s).as_slice(), "held-out shape {i}");
        }
        assert!(fit.shape(7).is_err() && val.shape(3).is_err());
        // One held out: the middle shape ⌊½·10⌋ = 5; nine: ⌊(j + ½)·10/9⌋ skips 4, the one kept.
        assert_eq!(d.split_validation(1).unwrap().2, [5]);
        let (fit, val, held) = d.split_validation(9).unwrap();
        assert_eq!(held, [0, 1, 2, 3, 5, 6, 7, 8, 9]);
        assert_eq!((fit.n_shapes(), val.n_shapes()), (1, 9));
        assert_eq!(fit.shape(0).unwrap().as_ref(), frame_f32(&x, 4).as_slice());
        assert_eq!(val.shape(8).unwrap().as_ref(), frame_f32(&x, 9).as_slice());
        // ⌊(j + ½)·10/4⌋: 1, 3, 6, 8.
        assert_eq!(d.split_validation(4).unwrap().2, [1, 3, 6, 8]);
        // Two shapes, one held out: shape 1.
        let two = TrainingData::from_features(&features(2, 1, WIDTH)).unwrap();
        let (fit, val, held) = two.split_validation(1).unwrap();
        assert_eq!(held, [1]);
        assert_eq!(fit.shape(0).unwrap().as_ref(), frame_f32(&features(2, 1, WIDTH), 0).as_slice());
        assert_eq!(val.shape(0).unwrap().as_ref(), frame_f32(&features(2, 1, WIDTH), 1).as_slice());
        // None held out, or none left to train on: refused.
        for v in [0, 10, 11] {
            assert!(matches!(d.split_validation(v), Err(Error::Config { .. })), "{v} of 10");
        }
        assert!(two.split_validation(2).is_err());
    }

    #[test]
    fn a_vcb_batch_puts_shape_indices_j_in_lane_j() {
        let x = features(3, 2, WIDTH);
        let d = TrainingData::from_features(&x).unwrap();
        let n9 = 2 * WIDTH;
        let lane = |buf: &[f32], bp: usize, j: usize| -> Vec<f32> { (0..n9).map(|r| buf[r * bp + j]).collect() };
        // Two shapes: one block of LANES lanes.
        let buf = d.batch_vcb(&[2, 0]).unwrap();
        assert_eq!(buf.len(), n9 * LANES);
        assert_eq!(lane(&buf, LANES, 0), frame_f32(&x, 2));
        assert_eq!(lane(&buf, LANES, 1), frame_f32(&x, 0));
        assert!((2..LANES).all(|j| lane(&buf, LANES, j).iter().all(|&v| v == 0.0)), "padding lanes");
        // Vertex 1, channel 3 of lane 1 (shape 0) sits at row 1·9 + 3: value 13.25.
        assert_eq!(buf[12 * LANES + 1], 13.25);
        // LANES + 1 shapes (repeats allowed): two blocks.
        let idx: Vec<usize> = (0..=LANES).map(|j| (j * 2 + 1) % 3).collect();
        let buf = d.batch_vcb(&idx).unwrap();
        assert_eq!(buf.len(), n9 * 2 * LANES);
        for (j, &s) in idx.iter().enumerate() {
            assert_eq!(lane(&buf, 2 * LANES, j), frame_f32(&x, s), "lane {j}");
        }
        assert!((idx.len()..2 * LANES).all(|j| lane(&buf, 2 * LANES, j).iter().all(|&v| v == 0.0)));
        // A chosen width.
        let bp = 3 * LANES;
        let buf = d.batch_vcb_width(&[1, 2, 0], bp).unwrap();
        assert_eq!(buf.len(), n9 * bp);
        for (j, s) in [1, 2, 0].into_iter().enumerate() {
            assert_eq!(lane(&buf, bp, j), frame_f32(&x, s), "lane {j}");
        }
        assert!((3..bp).all(|j| lane(&buf, bp, j).iter().all(|&v| v == 0.0)));
        // No shapes: one block of zeros; a shape that is not there: an error.
        assert_eq!(d.batch_vcb(&[]).unwrap(), vec![0.0; n9 * LANES]);
        assert!(d.batch_vcb(&[0, 3]).is_err() && d.batch_vcb_width(&[5], LANES).is_err());
        // Packed by vcb_from_shapes, the same buffer; lanes read back by shape_from_vcb.
        let shapes: Vec<Vec<f32>> = [2, 0].iter().map(|&s| frame_f32(&x, s)).collect();
        let packed = vcb_from_shapes(shapes.iter().map(|s| s.as_slice()), 2, 2);
        assert_eq!(packed, d.batch_vcb(&[2, 0]).unwrap());
        for (j, &s) in [2usize, 0].iter().enumerate() {
            assert_eq!(
                shape_from_vcb(&packed, LANES, j),
                x.frame(s).iter().map(|&v| v as f32 as f64).collect::<Vec<_>>()
            );
        }
        assert_eq!(shape_from_vcb(&packed, LANES, 5), vec![0.0; n9]);
    }

    #[test]
    fn vcb_from_shapes_layout_by_hand() {
        // Three shapes of one vertex: shape j holds 10·j + c in channel c.
        let shapes: Vec<Vec<f32>> = (0..3).map(|j| (0..WIDTH).map(|c| (10 * j + c) as f32).collect()).collect();
        let buf = vcb_from_shapes(shapes.iter().map(|s| s.as_slice()), 3, 1);
        assert_eq!(buf.len(), WIDTH * LANES);
        for c in 0..WIDTH {
            let mut row = vec![0.0f32; LANES];
            row[..3].copy_from_slice(&[c as f32, (10 + c) as f32, (20 + c) as f32]);
            assert_eq!(&buf[c * LANES..(c + 1) * LANES], row.as_slice(), "channel {c}");
        }
        assert_eq!(shape_from_vcb(&buf, LANES, 1), (0..WIDTH).map(|c| (10 + c) as f64).collect::<Vec<_>>());
        assert_eq!(shape_from_vcb(&buf, LANES, 2), (0..WIDTH).map(|c| (20 + c) as f64).collect::<Vec<_>>());
        // LANES + 2 shapes of two vertices: two blocks.
        let b = LANES + 2;
        let shapes: Vec<Vec<f32>> = (0..b).map(|j| (0..2 * WIDTH).map(|r| (100 * j + r) as f32).collect()).collect();
        let buf = vcb_from_shapes(shapes.iter().map(|s| s.as_slice()), b, 2);
        let bp = 2 * LANES;
        assert_eq!(buf.len(), 2 * WIDTH * bp);
        for (j, s) in shapes.iter().enumerate() {
            assert_eq!(shape_from_vcb(&buf, bp, j), s.iter().map(|&v| v as f64).collect::<Vec<_>>(), "lane {j}");
        }
        assert_eq!(buf[17 * bp + 9], 917.0, "vertex 1, channel 8 of shape 9");
    }

    #[test]
    fn a_tensor_batch_is_b_by_n_by_9() {
        let x = features(3, 2, WIDTH);
        let d = TrainingData::from_features(&x).unwrap();
        let t = d.batch_tensor(&[2, 0], &crate::nn::training::default_device()).unwrap();
        assert_eq!(t.dims(), [2, 2, WIDTH]);
        let v = t.into_data().try_into_vec_as::<f32>().unwrap();
        assert_eq!(v, [frame_f32(&x, 2), frame_f32(&x, 0)].concat());
        assert!(d.batch_tensor(&[3], &crate::nn::training::default_device()).is_err());
    }
}
