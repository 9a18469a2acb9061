//! Preprocessing of a loaded sequence before any representation is computed: train/test split,
//! rest shape (first frame, mean, or a mesh file), rigid alignment of every frame to the rest
//! shape, and optional scaling into the unit box.
//!
//! The unit-box transform is x' = (x − offset)·scale, with `offset` the minimum corner of the
//! bounding box of the rest shape and `scale` = 1 / (largest side). Everything a method
//! computes in the scaled space is mapped back with [`UnitBox::invert`] before it is written
//! or measured, so outputs and metrics are in the data's own units.

use std::borrow::Cow;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::config::{Align, DataConfig, RestShape};
use crate::error::{Error, Result};
use crate::geometry::rigid_align::{RigidTransform, kabsch};
use crate::mesh::{self, FrameSource, MeshSequence, TriMesh, Vec3};
use crate::representation::feature_cache::CachePolicy;

/// An affine scaling into the unit box: x' = (x − offset)·scale.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UnitBox {
    pub offset: Vec3,
    pub scale: f64,
}

impl UnitBox {
    /// Checks a stored transform (read from a model header): finite offset, positive finite
    /// scale; the message names the bad value.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let max = crate::artifact::MAX_MODEL_VALUE;
        if !(self.scale.is_finite() && (1.0 / max..=max).contains(&self.scale)) {
            return Err(format!("scale {} must be a number in [{:e}, {max:e}]", self.scale, 1.0 / max));
        }
        if let Some(x) = self.offset.iter().find(|x| !x.is_finite()) {
            return Err(format!("offset {x} must be finite"));
        }
        Ok(())
    }

    /// The identity transform.
    pub fn identity() -> Self {
        UnitBox { offset: [0.0; 3], scale: 1.0 }
    }
    /// The transform that maps the bounding box of `points` into [0, 1]³ (largest side → 1).
    pub fn fit(points: &[Vec3]) -> Result<Self> {
        let (lo, hi) = mesh::bounding_box(points);
        let side = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        if !(side.is_finite() && side > 0.0) {
            return Err(Error::Invalid(format!("cannot scale into the unit box: bounding box side is {side}")));
        }
        Ok(UnitBox { offset: lo, scale: 1.0 / side })
    }
    /// Maps a point into the unit box.
    pub fn apply(&self, p: Vec3) -> Vec3 {
        [0, 1, 2].map(|k| (p[k] - self.offset[k]) * self.scale)
    }
    /// Maps a point back to data units.
    pub fn invert(&self, p: Vec3) -> Vec3 {
        [0, 1, 2].map(|k| p[k] / self.scale + self.offset[k])
    }
    /// A mesh in model space mapped back to data units (same faces).
    pub fn invert_mesh(&self, m: &TriMesh) -> TriMesh {
        TriMesh::new(m.positions.iter().map(|p| self.invert(*p)).collect(), m.faces.clone())
    }
}

/// Data ready for a method: all frames preprocessed, the rest mesh, the split and the scaling.
#[derive(Debug)]
pub struct Prepared {
    /// All frames after alignment and scaling (natural order, as loaded): in memory, or read on
    /// demand from a large `.npy` ([`PreparedFrames`]).
    pub sequence: PreparedFrames,
    /// The rest (reference) mesh in the same space.
    pub rest: TriMesh,
    /// 0-based indices of the training frames.
    pub train: Vec<usize>,
    /// 0-based indices of the test frames (empty without a test split).
    pub test: Vec<usize>,
    /// 0-based indices of the validation frames (`data.validation`; empty without one): held
    /// out of `train`, which no longer holds them.
    pub validation: Vec<usize>,
    /// Scaling applied (identity unless `unit_box = true`).
    pub unit_box: UnitBox,
    /// Where the methods cache the training frames' features (`data.cache`).
    pub cache: CachePolicy,
    /// When frames are read on demand and features held in `f32`.
    pub limits: MemoryLimits,
}

/// Sizes above which data is not held whole in `f64` (bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryLimits {
    /// A C-order `.npy`, or a folder (pattern) of mesh files, whose frames take more than this in
    /// `f64` (F · N · 24 bytes) is read a frame at a time when used ([`PreparedFrames::Streamed`]). Default 256 MiB (~2 200 frames
    /// of 5 000 vertices: 5 000 frames of the cactus' 5 261 held whole took the autoencoder's run
    /// to 1.44 GB, streamed 0.84 GB; docs/training-budget.md); `MESHDECO_STREAM_BYTES`.
    pub stream_bytes: u64,
    /// PCA and SPLOCS hold their training features in `f32` when the `f64` matrix would take
    /// more than this (F · E·W · 8 bytes), and PCA then uses a randomized SVD. Default 1 GiB;
    /// `MESHDECO_COMPACT_BYTES`.
    pub compact_bytes: u64,
}

impl Default for MemoryLimits {
    fn default() -> Self {
        MemoryLimits { stream_bytes: 256 << 20, compact_bytes: 1 << 30 }
    }
}

impl MemoryLimits {
    /// The defaults, overridden by `MESHDECO_STREAM_BYTES` / `MESHDECO_COMPACT_BYTES` (a whole
    /// number of bytes); a value that is not one is an error naming the variable.
    pub fn from_env() -> Result<Self> {
        let mut m = MemoryLimits::default();
        for (name, slot) in
            [("MESHDECO_STREAM_BYTES", &mut m.stream_bytes), ("MESHDECO_COMPACT_BYTES", &mut m.compact_bytes)]
        {
            if let Ok(v) = std::env::var(name) {
                *slot = v.trim().parse().map_err(|_| {
                    Error::Invalid(format!("environment variable {name} is `{v}`, not a whole number of bytes"))
                })?;
            }
        }
        Ok(m)
    }
}

impl Prepared {
    /// Training frames as their own sequence.
    pub fn train_sequence(&self) -> Result<MeshSequence> {
        self.sequence.select_frames(&self.train)
    }
    /// Names of the training frames (without copying their positions).
    pub fn train_names(&self) -> Vec<String> {
        self.train.iter().map(|&f| self.sequence.name(f).to_string()).collect()
    }
    /// Test frames as their own sequence.
    pub fn test_sequence(&self) -> Result<MeshSequence> {
        self.sequence.select_frames(&self.test)
    }
}

/// The prepared frames: held in memory, or — for a C-order `.npy` or a folder of mesh files
/// whose frames would take more than [`MemoryLimits::stream_bytes`] in `f64` — read from the
/// file whenever a frame is used, aligned and
/// scaled on the way with the same arithmetic as in memory (the same numbers, bit for bit).
#[derive(Debug)]
pub enum PreparedFrames {
    /// Every frame in memory.
    Memory(MeshSequence),
    /// Frames read on demand.
    Streamed(StreamedFrames),
}

/// Frames of a `.npy` or of mesh files read on demand, with each frame's rigid alignment (if any) and the unit
/// box (if any) applied when read.
#[derive(Debug)]
pub struct StreamedFrames {
    file: FrameFiles,
    faces: Vec<[usize; 3]>,
    names: Vec<String>,
    /// Per frame: the rigid motion onto the rest shape (`align = "rigid"`).
    alignment: Option<Vec<RigidTransform>>,
    /// The unit box (`unit_box = true`).
    unit_box: Option<UnitBox>,
}

/// Where streamed frames come from: a C-order `.npy`, or a folder (or pattern) of mesh files.
#[derive(Debug)]
enum FrameFiles {
    Npy(mesh::npy::NpyFrames),
    Meshes(mesh::sequence::MeshFiles),
}

impl FrameFiles {
    fn n_frames(&self) -> usize {
        match self {
            FrameFiles::Npy(n) => n.n_frames(),
            FrameFiles::Meshes(m) => m.n_frames(),
        }
    }
    fn n_vertices(&self) -> usize {
        match self {
            FrameFiles::Npy(n) => n.n_vertices(),
            FrameFiles::Meshes(m) => m.n_vertices(),
        }
    }
    fn names(&self) -> Vec<String> {
        match self {
            FrameFiles::Npy(n) => n.names(),
            FrameFiles::Meshes(m) => m.names(),
        }
    }
    /// Frame `f` as stored, with the mesh reader's warnings (none for a `.npy`).
    fn read_frame(&self, f: usize) -> Result<(Vec<Vec3>, Vec<String>)> {
        match self {
            FrameFiles::Npy(n) => Ok((n.read_frame(f)?, Vec::new())),
            FrameFiles::Meshes(m) => m.read_frame(f),
        }
    }
}

/// Frames as stored, aligned and scaled when read.
impl FrameSource for StreamedFrames {
    fn faces(&self) -> &[[usize; 3]] {
        &self.faces
    }
    fn n_frames(&self) -> usize {
        self.file.n_frames()
    }
    fn n_vertices(&self) -> usize {
        self.file.n_vertices()
    }
    fn name(&self, f: usize) -> &str {
        self.names.get(f).map_or("?", String::as_str)
    }
    fn frame(&self, f: usize) -> Result<Cow<'_, [Vec3]>> {
        let (mut frame, _) = self.file.read_frame(f)?;
        if let Some(t) = &self.alignment {
            frame.iter_mut().for_each(|p| *p = t[f].apply(*p));
        }
        if let Some(u) = &self.unit_box {
            frame.iter_mut().for_each(|p| *p = u.apply(*p));
        }
        Ok(Cow::Owned(frame))
    }
}

impl PreparedFrames {
    fn source(&self) -> &dyn FrameSource {
        match self {
            PreparedFrames::Memory(s) => s,
            PreparedFrames::Streamed(s) => s,
        }
    }
}

impl FrameSource for PreparedFrames {
    fn faces(&self) -> &[[usize; 3]] {
        self.source().faces()
    }
    fn n_frames(&self) -> usize {
        self.source().n_frames()
    }
    fn n_vertices(&self) -> usize {
        self.source().n_vertices()
    }
    fn name(&self, f: usize) -> &str {
        self.source().name(f)
    }
    fn frame(&self, f: usize) -> Result<Cow<'_, [Vec3]>> {
        self.source().frame(f)
    }
}

/// Loads the frames a data config names: `synthetic:<name>` or a directory/glob of mesh files.
pub fn load_frames(path: &str) -> Result<MeshSequence> {
    if crate::synthetic::is_synthetic(path) { crate::synthetic::load(path) } else { mesh::load_sequence(path) }
}

/// Loads frames to use with a trained model whose rest mesh is `rest`: anything
/// [`load_frames`] reads, or a NumPy `.npy` (F × N × 3) — or `.npz` written `file.npz:array` —
/// whose connectivity is the model's (the template it was trained with).
pub fn load_frames_for(path: &str, rest: &crate::mesh::TriMesh) -> Result<MeshSequence> {
    // HDF5 (`x.h5`, `x.h5:dataset`): the file's `tris`, else the model's faces.
    if let Some((file, dataset)) = mesh::hdf5::split_spec(path) {
        return mesh::hdf5::load_hdf5_sequence(
            Path::new(file),
            dataset.unwrap_or(mesh::hdf5::DEFAULT_DATASET),
            mesh::hdf5::Faces::FileOr(&rest.faces),
        );
    }
    let (file, array) = match path.rsplit_once(':') {
        Some((f, a)) if f.to_ascii_lowercase().ends_with(".npz") => (f, Some(a)),
        _ => (path, None),
    };
    if mesh::npy::is_numpy_path(file) {
        if file.to_ascii_lowercase().ends_with(".npz") && array.is_none() {
            return Err(Error::Invalid(format!("{path}: name the array of the .npz to read, as `{path}:<array>`")));
        }
        return mesh::npy::load_npy_with_faces(Path::new(file), array, rest.n_vertices(), rest.faces.clone());
    }
    load_frames(path)
}

/// Loads the frames of a `[data]` section: a NumPy `.npy`/`.npz` array with its template mesh
/// (`data.template`, `data.array`), or anything [`load_frames`] reads.
pub fn load_data(cfg: &DataConfig) -> Result<MeshSequence> {
    let template = cfg.numpy_template()?;
    if let Some(seq) = load_hdf5(cfg)? {
        return Ok(seq);
    }
    match template {
        Some(template) => mesh::npy::load_npy_sequence(Path::new(&cfg.path), cfg.array.as_deref(), template),
        None => load_frames(&cfg.path),
    }
}

/// The frames of an HDF5 `data.path` (`data.dataset`, faces from `data.template` or the file's
/// `tris`), read into memory; `None` for other paths.
fn load_hdf5(cfg: &DataConfig) -> Result<Option<MeshSequence>> {
    let Some((file, dataset, template)) = cfg.hdf5_source() else { return Ok(None) };
    let faces = match template {
        Some(t) => mesh::hdf5::Faces::Template(t),
        None => mesh::hdf5::Faces::FromFile,
    };
    mesh::hdf5::load_hdf5_sequence(file, dataset, faces).map(Some)
}

/// Loads and preprocesses the data of a config.
pub fn prepare(cfg: &DataConfig) -> Result<Prepared> {
    prepare_with(cfg, MemoryLimits::from_env()?)
}

/// [`prepare`] with the given [`MemoryLimits`] (tests pass 0 to stream small sets): a C-order
/// `.npy` or a folder of mesh files past `stream_bytes` is read on demand.
pub fn prepare_with(cfg: &DataConfig, limits: MemoryLimits) -> Result<Prepared> {
    let template = cfg.numpy_template()?;
    if let Some(seq) = load_hdf5(cfg)? {
        return prepare_sequence_with(seq, cfg, limits);
    }
    let seq = match template {
        Some(template) => {
            let path = Path::new(&cfg.path);
            let tmpl = mesh::load_mesh(template)?;
            let npz = path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("npz"));
            if !npz
                && cfg.array.is_none()
                && let Some(file) = mesh::npy::NpyFrames::open(path, tmpl.n_vertices())?
                && (file.n_frames() * file.n_vertices()) as u64 * 24 > limits.stream_bytes
            {
                return prepare_streamed(FrameFiles::Npy(file), tmpl.faces, cfg, limits);
            }
            // what `load_data` reads, with the template already loaded
            mesh::npy::load_npy_with_faces(path, cfg.array.as_deref(), tmpl.n_vertices(), tmpl.faces)?
        }
        None if !crate::synthetic::is_synthetic(&cfg.path) => {
            let files = mesh::sequence::MeshFiles::open(&cfg.path)?;
            let bytes = (files.n_frames() * files.n_vertices()) as u64 * 24;
            if bytes > limits.stream_bytes && files.n_frames() > 1 {
                let faces = files.faces().to_vec();
                return prepare_streamed(FrameFiles::Meshes(files), faces, cfg, limits);
            }
            load_frames(&cfg.path)?
        }
        None => load_frames(&cfg.path)?,
    };
    prepare_sequence_with(seq, cfg, limits)
}

/// The train/test split of `f` frames (a warning when they overlap).
/// (training frames to fit, test frames, validation frames), 0-based.
fn split(cfg: &DataConfig, f: usize) -> Result<(Vec<usize>, Vec<usize>, Vec<usize>)> {
    let train = cfg.train.resolve("data.train", f, None)?;
    let test = match &cfg.test {
        Some(t) => t.resolve("data.test", f, Some(&train))?,
        None => Vec::new(),
    };
    let overlap: Vec<usize> = test.iter().filter(|t| train.contains(t)).map(|&t| t + 1).collect();
    if !overlap.is_empty() {
        eprintln!(
            "warning: data.test shares {} frame(s) with data.train (1-based: {}{}): test Erms on them is not a held-out error",
            overlap.len(),
            overlap.iter().take(10).map(|v| v.to_string()).collect::<Vec<_>>().join(", "),
            if overlap.len() > 10 { ", …" } else { "" }
        );
    }
    let (validation, train) = match &cfg.validation {
        Some(v) => v.resolve(f, &train)?,
        None => (Vec::new(), train),
    };
    Ok((train, test, validation))
}

/// [`prepare_sequence`] for frames read on demand: one pass reads (and so checks) every frame
/// and computes its alignment; only the rest shape and one rigid motion per frame are kept.
fn prepare_streamed(
    file: FrameFiles,
    faces: Vec<[usize; 3]>,
    cfg: &DataConfig,
    limits: MemoryLimits,
) -> Result<Prepared> {
    let names = file.names();
    // Not yet aligned or scaled: the rest shape is taken from the frames as stored.
    let mut raw = StreamedFrames { file, faces, names, alignment: None, unit_box: None };
    let (train, test, validation) = split(cfg, raw.file.n_frames())?;
    let rest_positions = rest_shape(&raw, &cfg.rest, &train)?;
    // Every frame is read once here: a bad value fails now, not half way through training.
    let rigid = cfg.align == Align::Rigid;
    let mut alignment = Vec::with_capacity(if rigid { raw.file.n_frames() } else { 0 });
    let mut warnings = Vec::new();
    let mut first = Vec::new();
    for f in 0..raw.file.n_frames() {
        let (frame, w) = raw.file.read_frame(f)?;
        if rigid {
            alignment.push(kabsch(&frame, &rest_positions));
        }
        warnings.push(w);
        if f == 0 {
            first = frame;
        }
    }
    // The mesh readers' warnings, as loading a sequence prints them, and the first frame's
    // connectivity problems.
    if let FrameFiles::Meshes(m) = &raw.file {
        for w in m.merge_warnings(&warnings) {
            eprintln!("warning: {w}");
        }
        let first = MeshSequence { faces: raw.faces.clone(), frames: vec![first], names: Vec::new() };
        let topology = mesh::Topology::new(first.n_vertices(), &first.faces);
        for w in mesh::inspect::problem_warnings(&first, &topology) {
            eprintln!("warning: {}: {w}", cfg.path);
        }
    }
    let mut rest = TriMesh::new(rest_positions, raw.faces.clone());
    let unit_box = if cfg.unit_box { UnitBox::fit(&rest.positions)? } else { UnitBox::identity() };
    if cfg.unit_box {
        for p in rest.positions.iter_mut() {
            *p = unit_box.apply(*p);
        }
        raw.unit_box = Some(unit_box);
    }
    if rigid {
        raw.alignment = Some(alignment);
    }
    Ok(Prepared {
        sequence: PreparedFrames::Streamed(raw),
        rest,
        train,
        test,
        validation,
        unit_box,
        cache: cfg.cache.clone(),
        limits,
    })
}

/// Preprocesses an already loaded sequence according to `cfg`.
pub fn prepare_sequence(seq: MeshSequence, cfg: &DataConfig) -> Result<Prepared> {
    prepare_sequence_with(seq, cfg, MemoryLimits::from_env()?)
}

/// [`prepare_sequence`] with the given [`MemoryLimits`] (what the linear fits read).
fn prepare_sequence_with(mut seq: MeshSequence, cfg: &DataConfig, limits: MemoryLimits) -> Result<Prepared> {
    let (train, test, validation) = split(cfg, seq.n_frames())?;
    let rest_positions = rest_shape(&seq, &cfg.rest, &train)?;
    if cfg.align == Align::Rigid {
        align_rigid(&mut seq, &rest_positions);
    }
    let mut rest = TriMesh::new(rest_positions, seq.faces.clone());
    let unit_box = if cfg.unit_box { UnitBox::fit(&rest.positions)? } else { UnitBox::identity() };
    if cfg.unit_box {
        for p in seq.frames.iter_mut().flatten() {
            *p = unit_box.apply(*p);
        }
        for p in rest.positions.iter_mut() {
            *p = unit_box.apply(*p);
        }
    }
    Ok(Prepared {
        sequence: PreparedFrames::Memory(seq),
        rest,
        train,
        test,
        validation,
        unit_box,
        cache: cfg.cache.clone(),
        limits,
    })
}

/// The rest shape's positions: the first training frame, the mean of the training frames, or a
/// mesh file with the sequence's vertex count and faces.
pub fn rest_shape(seq: &dyn FrameSource, rest: &RestShape, train: &[usize]) -> Result<Vec<Vec3>> {
    match rest {
        RestShape::First => Ok(seq.frame(train[0])?.into_owned()),
        RestShape::Mean => {
            let n = seq.n_vertices();
            let mut mean = vec![[0.0; 3]; n];
            for &f in train {
                for (m, p) in mean.iter_mut().zip(seq.frame(f)?.iter()) {
                    for k in 0..3 {
                        m[k] += p[k];
                    }
                }
            }
            let s = 1.0 / train.len() as f64;
            Ok(mean.into_iter().map(|m| m.map(|x| x * s)).collect())
        }
        RestShape::File(path) => {
            let m = mesh::load_mesh(path)?;
            if m.n_vertices() != seq.n_vertices() {
                return Err(Error::Mismatch {
                    path: path.clone(),
                    message: format!(
                        "rest mesh has {} vertices, the sequence has {}",
                        m.n_vertices(),
                        seq.n_vertices()
                    ),
                });
            }
            if m.faces != seq.faces() {
                return Err(Error::Mismatch {
                    path: path.clone(),
                    message: "rest mesh faces differ from the sequence's faces".into(),
                });
            }
            Ok(m.positions)
        }
    }
}

/// Rigidly aligns every frame to `rest` (Kabsch, proper rotations only).
pub fn align_rigid(seq: &mut MeshSequence, rest: &[Vec3]) {
    for frame in seq.frames.iter_mut() {
        let t = kabsch(frame, rest);
        for p in frame.iter_mut() {
            *p = t.apply(*p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::FrameSelection;

    fn cfg(path: &str) -> DataConfig {
        DataConfig {
            path: path.into(),
            train: FrameSelection::All,
            test: None,
            validation: None,
            rest: RestShape::First,
            align: Align::None,
            unit_box: false,
            array: None,
            template: None,
            dataset: None,
            cache: CachePolicy::Off,
        }
    }

    #[test]
    fn unit_box_round_trip() {
        let pts = vec![[1.0, 2.0, 3.0], [3.0, 2.5, 3.5], [2.0, 6.0, 3.0]];
        let b = UnitBox::fit(&pts).unwrap();
        for p in &pts {
            let q = b.apply(*p);
            assert!(q.iter().all(|&x| (-1e-12..=1.0 + 1e-12).contains(&x)));
            let r = b.invert(q);
            for k in 0..3 {
                assert!((r[k] - p[k]).abs() < 1e-12);
            }
        }
        assert!(UnitBox::fit(&[[1.0; 3], [1.0; 3]]).is_err());
    }

    #[test]
    fn rigid_alignment_undoes_a_rigid_motion() {
        let seq0 = crate::synthetic::load("synthetic:tube").unwrap();
        let mut seq = seq0.clone();
        let (s, c) = 0.7f64.sin_cos();
        for p in seq.frames[3].iter_mut() {
            *p = [c * p[0] - s * p[1] + 0.5, s * p[0] + c * p[1] - 2.0, p[2] + 1.0];
        }
        let mut c = cfg("synthetic:tube");
        c.align = Align::Rigid;
        let prep = prepare_sequence(seq, &c).unwrap();
        // Frame 4 was moved rigidly; after alignment it matches the alignment of the original.
        let mut reference = seq0.clone();
        align_rigid(&mut reference, &seq0.frames[0]);
        for (a, b) in prep.sequence.frame(3).unwrap().iter().zip(&reference.frames[3]) {
            assert!(mesh::dist(*a, *b) < 1e-9);
        }
    }

    #[test]
    fn mean_rest_and_unit_box() {
        let mut c = cfg("synthetic:bumps");
        c.rest = RestShape::Mean;
        c.unit_box = true;
        c.train = FrameSelection::Ranges(vec![(1, 10)]);
        c.test = Some(FrameSelection::Rest);
        let p = prepare(&c).unwrap();
        assert_eq!(p.train.len(), 10);
        assert_eq!(p.test.len(), 30);
        let (lo, hi) = mesh::bounding_box(&p.rest.positions);
        let side = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        assert!((side - 1.0).abs() < 1e-12);
    }
}
