//! glTF 2.0 binary (`.glb`) export of a trained model: its neutral shape as a triangle mesh
//! (positions, smooth normals, indices) with **one morph target per component** (blendshapes),
//! ranked as `meshdeco components` ranks them, and optionally the training frames' weights as an
//! animation of the morph weights.
//!
//! - Base mesh: the model's neutral shape, all dials 0 (`meshdeco synthesize` with no weight:
//!   the rest shape for SPLOCS, the training mean for PCA, the region means for region PCA, the
//!   reference shape's decoding for the autoencoder), in data units.
//! - Target k: the shape at dial 1 of component k (the autoencoder: its extreme) minus the base.
//!   For models that are linear in their dials (displacement models) base + Σ w·target is exactly
//!   the model; for the others (SPLOCS on triangle gradients or ACAP, the autoencoder) blending is
//!   an approximation, measured as the **additivity error**: Erms between the model's own
//!   decoding of the training frames and base + Σ w·target with the same dials (aligned as the
//!   model's Erms is), written into `asset.extras` and returned.
//! - Names: `mesh.extras.targetNames` = `"r<rank> k<index> v<centre vertex>"`.
//! - `colors`: `COLOR_0` of the base mesh: every vertex in the colour of the component with the
//!   largest relative magnitude there, darkened by that magnitude (supports at a glance).
//! - `animation`: one key per training frame at t = i / fps, linear interpolation, the morph
//!   weights of frame i being the model's dials of its stored training weights.
//!
//! - `up`: glTF is Y-up and faces +Z. The shape is *rotated* (positions, normals and targets; not
//!   a node transform, which some importers drop) so that the chosen data axis points along +Y:
//!   `auto` takes `meshdeco render --view auto`'s rule (the axis of largest extent is up, the
//!   camera looks along the smallest, which becomes +Z). The rotation is stored in
//!   `asset.extras.up_axis` / `asset.extras.rotation` (rows: data → glTF).
//! - A plain material: non-metallic, rough, light grey, double-sided where the mesh has a
//!   boundary; every morph target carries its normals' change too.
//! - `targets`: for models whose decoding is not linear in the dials (the autoencoder, SPLOCS on
//!   triangle gradients or ACAP) the dial-1 shapes blend poorly. `fitted` (the default) solves
//!   for the targets T by least squares so that base + Σ_k w_fk·T_k best matches the model's own
//!   decoding of every training frame f, regularised towards the dial-1 shapes:
//!   `min Σ_f ‖base + W_f·T − D_f‖² + μ Σ_k ‖T_k − E_k‖²`, `μ = fit_regularisation ×
//!   trace(WᵀW)/K` (one K × K factorisation, 3N right-hand sides). Displacement models are
//!   linear: their fitted targets are their dial-1 shapes, and they are written as such.
//! - `bake`: one target per training frame (its decoding minus the base) and an animation that
//!   keys each in turn at weight 1: exact playback of the training frames, no dials.
//!
//! Coordinates are stored as `f32` (glTF's only float type), so a round trip is exact to about
//! 1e-7 relative.

use std::collections::BTreeMap;
use std::path::Path;

use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;
use serde_json::value::RawValue;

use crate::error::{Error, Result};
use crate::math::vec3::{add, norm, sub};
use crate::mesh::normals::{NormalWeighting, vertex_normals};
use crate::mesh::{MeshSequence, Vec3};
use crate::metrics::erms::{Alignment, erms};
use crate::model::{Model, ranked, synthesize};

/// Options of [`export_glb`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExportOptions {
    /// Add the training frames' weights as an animation.
    pub animation: bool,
    /// Frames per second of the animation (> 0).
    pub fps: f64,
    /// Add `COLOR_0` showing each component's support.
    pub colors: bool,
    /// Which data axis becomes glTF's +Y.
    pub up: UpAxis,
    /// How the targets of a nonlinear model are made.
    pub targets: TargetFit,
    /// μ of the fitted targets relative to trace(WᵀW)/K (> 0).
    pub fit_regularisation: f64,
    /// One target per training frame, keyed in turn (implies the animation).
    pub bake: bool,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            animation: false,
            fps: 30.0,
            colors: false,
            up: UpAxis::Auto,
            targets: TargetFit::Fitted,
            fit_regularisation: FIT_REGULARISATION,
            bake: false,
        }
    }
}

/// Default `fit_regularisation` (README "Export": the SCAPE autoencoder's measurements).
pub const FIT_REGULARISATION: f64 = 0.1;

/// The frame rates of an animation accepted (`--fps`), inclusive: from one frame per 100 s to
/// 1000 frames per second. Within it every key time `i / fps` is finite and, stored as `f32`,
/// strictly increasing for any realistic number of frames (glTF's validator requires both).
pub const FPS_RANGE: std::ops::RangeInclusive<f64> = 0.01..=1000.0;

/// The error for an `--fps` outside [`FPS_RANGE`] (or not a number), naming the flag and value;
/// `None` when it is in range.
pub fn fps_error(fps: f64) -> Option<String> {
    (!FPS_RANGE.contains(&fps)).then(|| {
        format!(
            "--fps {fps:?}: must be a number of frames per second from {} to {}",
            FPS_RANGE.start(),
            FPS_RANGE.end()
        )
    })
}

/// The data axis that becomes glTF's up (+Y).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpAxis {
    /// The axis of largest bounding-box extent, + side (as `meshdeco render --view auto`).
    Auto,
    /// Axis 0 = x, 1 = y, 2 = z; `true`: its − side points up.
    Axis(usize, bool),
}

impl UpAxis {
    /// Parses `auto`, `x`, `y`, `z`, `+x`, `-x`, ….
    pub fn parse(s: &str) -> Option<Self> {
        let t = s.trim().to_ascii_lowercase();
        if t == "auto" {
            return Some(UpAxis::Auto);
        }
        let (neg, name) = match t.strip_prefix('-') {
            Some(r) => (true, r),
            None => (false, t.strip_prefix('+').unwrap_or(&t)),
        };
        let axis = ["x", "y", "z"].iter().position(|a| *a == name)?;
        Some(UpAxis::Axis(axis, neg))
    }
}

/// How the morph targets of a model are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TargetFit {
    /// The shape at dial 1 of each component minus the base.
    Extreme,
    /// Least squares over the training frames, regularised towards [`TargetFit::Extreme`].
    Fitted,
}

/// The rotation (rows: data → glTF) taking the chosen up axis to +Y and the view axis (smallest
/// extent among the others) to +Z, signed so that the shape's front faces +Z (glTF's front,
/// [`crate::mesh::render::front_is_negative`]), with its description (e.g. `+x`).
pub fn orientation(positions: &[Vec3], faces: &[[usize; 3]], up: UpAxis) -> (crate::math::mat3::Mat3, String) {
    let (lo, hi) = crate::mesh::bounding_box(positions);
    let e: Vec<f64> = (0..3).map(|k| hi[k] - lo[k]).collect();
    let (axis, neg) = match up {
        UpAxis::Auto => (crate::mesh::render::auto_axes(positions).0, false),
        UpAxis::Axis(a, n) => (a, n),
    };
    let view = [2, 0, 1].into_iter().filter(|&k| k != axis).min_by(|&a, &b| e[a].total_cmp(&e[b])).unwrap_or(2);
    let unit = |k: usize, sign: f64| -> Vec3 { std::array::from_fn(|j| if j == k { sign } else { 0.0 }) };
    let y = unit(axis, if neg { -1.0 } else { 1.0 });
    let z = unit(view, if crate::mesh::render::front_is_negative(positions, faces, view) { -1.0 } else { 1.0 });
    let x = crate::math::vec3::cross(y, z);
    let name = format!("{}{}", if neg { "-" } else { "+" }, ["x", "y", "z"][axis]);
    ([x, y, z], name)
}

fn rotate(r: &crate::math::mat3::Mat3, p: &[Vec3]) -> Vec<Vec3> {
    p.iter().map(|&v| crate::math::mat3::mat_vec(r, v)).collect()
}

/// What [`export_glb`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportReport {
    /// Morph targets (components).
    pub targets: usize,
    /// Target names, in file order (rank order).
    pub names: Vec<String>,
    /// Additivity error (Erms, data units × 1000) over the training frames, when the model
    /// stores their weights.
    pub additivity_erms: Option<f64>,
    /// Additivity error of the dial-1 targets, when the written targets were fitted.
    pub additivity_extreme_erms: Option<f64>,
    /// Whether the targets were fitted to the training frames.
    pub targets_fitted: bool,
    /// The data axis written as +Y (`+x`, `-z`, …).
    pub up_axis: String,
    /// Animation keys written (0 without `animation`).
    pub animation_frames: usize,
    /// Size of the file, bytes.
    pub bytes: usize,
}

/// The blendshape form of a model: base shape and one delta per component in rank order.
pub struct Blendshapes {
    pub base: Vec<Vec3>,
    /// Component index of each target.
    pub index: Vec<usize>,
    pub names: Vec<String>,
    pub deltas: Vec<Vec<Vec3>>,
    /// Per-vertex magnitudes of each target's component (heat maps).
    pub magnitudes: Vec<Vec<f64>>,
}

impl Blendshapes {
    /// Builds the base and targets of `model` (see the module docs).
    pub fn of(model: &dyn Model) -> Result<Self> {
        let k = model.n_components();
        let base = synthesize(model, &vec![0.0; k])?;
        let (mut index, mut names, mut deltas, mut magnitudes) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for c in ranked(model)? {
            let mut dials = vec![0.0; k];
            dials[c.index] = 1.0;
            let shape = synthesize(model, &dials)?;
            deltas.push(shape.iter().zip(&base).map(|(s, b)| sub(*s, *b)).collect());
            names.push(format!("r{} k{} v{}", c.rank, c.index, c.center));
            index.push(c.index);
            magnitudes.push(c.magnitudes);
        }
        Ok(Blendshapes { base, index, names, deltas, magnitudes })
    }

    /// Replaces the targets by their least-squares fit to the model's decoding of its training
    /// frames, regularised towards the current targets with `mu_rel × trace(WᵀW)/K` (module
    /// docs). Returns `false` (nothing changed) when there is no target or no frame.
    pub fn fit_to_training(&mut self, training: &Training, mu_rel: f64) -> Result<bool> {
        let truth = &training.decoded;
        let k = self.deltas.len();
        if k == 0 || truth.is_empty() {
            return Ok(false);
        }
        // W: F × K dials in target order.
        let w: Vec<Vec<f64>> = training.dials.iter().map(|d| self.index.iter().map(|&i| d[i]).collect()).collect();
        let mut a = faer::Mat::<f64>::zeros(k, k);
        for row in &w {
            for i in 0..k {
                for j in 0..k {
                    a[(i, j)] += row[i] * row[j];
                }
            }
        }
        let tr = (0..k).map(|i| a[(i, i)]).sum::<f64>();
        let mu = mu_rel * (tr / k as f64).max(f64::MIN_POSITIVE);
        for i in 0..k {
            a[(i, i)] += mu;
        }
        let n = self.base.len();
        // Right-hand sides: Wᵀ(D_f − base) + μ·E, one column per coordinate (3N).
        let mut rhs = faer::Mat::<f64>::zeros(k, 3 * n);
        for (row, d) in w.iter().zip(truth) {
            for v in 0..n {
                for c in 0..3 {
                    let r = d[v][c] - self.base[v][c];
                    if r != 0.0 {
                        for i in 0..k {
                            rhs[(i, 3 * v + c)] += row[i] * r;
                        }
                    }
                }
            }
        }
        for (i, e) in self.deltas.iter().enumerate() {
            for v in 0..n {
                for c in 0..3 {
                    rhs[(i, 3 * v + c)] += mu * e[v][c];
                }
            }
        }
        use faer::linalg::solvers::Solve;
        let llt =
            a.llt(faer::Side::Lower).map_err(|e| Error::Numerical(format!("fitting the export's targets: {e:?}")))?;
        llt.solve_in_place(rhs.as_mut());
        for (i, e) in self.deltas.iter_mut().enumerate() {
            for v in 0..n {
                for c in 0..3 {
                    e[v][c] = rhs[(i, 3 * v + c)];
                }
            }
        }
        Ok(true)
    }

    /// One target per training frame: its decoding minus the base (`bake`). Target t is keyed
    /// by "dial" t: [`Blendshapes::blend`] of a one-hot vector is frame t.
    pub fn baked(model: &dyn Model, training: &Training) -> Result<Self> {
        let base = synthesize(model, &vec![0.0; model.n_components()])?;
        let names: Vec<String> = model.train_frames().iter().map(|f| format!("frame {f}")).collect();
        let deltas: Vec<Vec<Vec3>> =
            training.decoded.iter().map(|f| f.iter().zip(&base).map(|(s, b)| sub(*s, *b)).collect()).collect();
        let magnitudes = deltas.iter().map(|d| d.iter().map(|x| norm(*x)).collect()).collect();
        let index = (0..deltas.len()).collect();
        Ok(Blendshapes { base, index, names, deltas, magnitudes })
    }

    /// base + Σ_t dials[index_t]·delta_t.
    pub fn blend(&self, dials: &[f64]) -> Vec<Vec3> {
        let w: Vec<f64> = self.index.iter().map(|&k| dials[k]).collect();
        blend(&self.base, &self.deltas, &w)
    }
}

fn one_hot(n: usize, i: usize) -> Vec<f64> {
    (0..n).map(|j| if j == i { 1.0 } else { 0.0 }).collect()
}

/// `base + Σ_t w_t·targets_t` (w in target order).
pub fn blend(base: &[Vec3], targets: &[Vec<Vec3>], w: &[f64]) -> Vec<Vec3> {
    let mut out = base.to_vec();
    for (d, &wt) in targets.iter().zip(w) {
        if wt != 0.0 {
            for (o, x) in out.iter_mut().zip(d) {
                for c in 0..3 {
                    o[c] += wt * x[c];
                }
            }
        }
    }
    out
}

/// A model's training frames as the export uses them, decoded once: their dials (component
/// index order) and the model's own decoding of them (data units).
pub struct Training {
    pub dials: Vec<Vec<f64>>,
    pub decoded: Vec<Vec<Vec3>>,
}

impl Training {
    /// `None` when the model stores no training weights.
    pub fn of(model: &dyn Model) -> Result<Option<Self>> {
        let Some(weights) = model.train_weights() else { return Ok(None) };
        let dials = weights.iter().map(|w| model.dials(w)).collect::<Result<Vec<_>>>()?;
        let decoded = model.decode(&weights)?;
        Ok(Some(Training { dials, decoded }))
    }
}

/// Additivity error of `shapes` against the model's decoding of its training frames (see the
/// module docs): Erms with the model's `alignment`.
pub fn additivity_error(shapes: &Blendshapes, training: &Training, alignment: Alignment) -> Result<f64> {
    let blends: Vec<Vec<Vec3>> = training.dials.iter().map(|d| shapes.blend(d)).collect();
    erms(&training.decoded, &blends, alignment)
}

/// Growing binary buffer of the `.glb` with its views and accessors.
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
    buffer: json::Index<json::Buffer>,
}

fn raw(v: serde_json::Value) -> Result<Box<RawValue>> {
    RawValue::from_string(v.to_string()).map_err(|e| Error::Invalid(format!("glTF extras: {e}")))
}

impl Builder {
    fn new() -> Self {
        let mut root = json::Root::default();
        let buffer =
            root.push(json::Buffer { byte_length: USize64(0), extensions: None, extras: None, name: None, uri: None });
        Builder { root, bin: Vec::new(), buffer }
    }

    /// Appends `bytes` (4-byte aligned) as a buffer view.
    fn view(&mut self, bytes: &[u8], target: Option<json::buffer::Target>) -> json::Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: self.buffer,
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            extensions: None,
            extras: None,
            name: None,
            target: target.map(Valid),
        })
    }

    /// An accessor of `count` elements of `type_` over `values` (f32), with min/max when asked.
    fn floats(
        &mut self,
        values: &[f32],
        type_: json::accessor::Type,
        target: Option<json::buffer::Target>,
        bounds: bool,
        name: &str,
    ) -> json::Index<json::Accessor> {
        let width = type_.multiplicity();
        let count = values.len() / width;
        let (min, max) = if bounds {
            let mut lo = vec![f32::INFINITY; width];
            let mut hi = vec![f32::NEG_INFINITY; width];
            for chunk in values.chunks_exact(width) {
                for (j, &x) in chunk.iter().enumerate() {
                    lo[j] = lo[j].min(x);
                    hi[j] = hi[j].max(x);
                }
            }
            (Some(json::Value::from(lo)), Some(json::Value::from(hi)))
        } else {
            (None, None)
        };
        let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::F32)),
            extensions: None,
            extras: None,
            type_: Valid(type_),
            min,
            max,
            name: Some(name.to_string()),
            normalized: false,
            sparse: None,
        })
    }

    fn indices(&mut self, faces: &[[usize; 3]]) -> Result<json::Index<json::Accessor>> {
        let mut bytes = Vec::with_capacity(12 * faces.len());
        for &i in faces.iter().flatten() {
            let i = u32::try_from(i).map_err(|_| Error::Invalid(format!("vertex index {i} exceeds glTF's u32")))?;
            bytes.extend_from_slice(&i.to_le_bytes());
        }
        let view = self.view(&bytes, Some(json::buffer::Target::ElementArrayBuffer));
        Ok(self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(3 * faces.len()),
            component_type: Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::U32)),
            extensions: None,
            extras: None,
            type_: Valid(json::accessor::Type::Scalar),
            min: None,
            max: None,
            name: Some("indices".into()),
            normalized: false,
            sparse: None,
        }))
    }

    /// The `.glb` bytes: header, JSON chunk (space-padded), BIN chunk (zero-padded).
    fn finish(mut self) -> Result<Vec<u8>> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.root.buffers[0].byte_length = USize64::from(self.bin.len());
        let mut text = json::serialize::to_string(&self.root).map_err(|e| Error::Invalid(format!("glTF JSON: {e}")))?;
        while !text.len().is_multiple_of(4) {
            text.push(' ');
        }
        let total = 12 + 8 + text.len() + 8 + self.bin.len();
        let total32 =
            u32::try_from(total).map_err(|_| Error::Invalid(format!("{total} bytes exceed a .glb's 4 GiB")))?;
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&total32.to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(text.as_bytes());
        out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bin);
        Ok(out)
    }
}

fn flat(points: &[Vec3]) -> Vec<f32> {
    points.iter().flatten().map(|&x| x as f32).collect()
}

/// Colour of every vertex: the hue of the component with the largest relative magnitude there,
/// scaled by that magnitude (black where no component reaches).
fn support_colors(magnitudes: &[Vec<f64>], n: usize) -> Vec<f32> {
    let peaks: Vec<f64> = magnitudes.iter().map(|m| m.iter().cloned().fold(0.0, f64::max)).collect();
    let k = magnitudes.len().max(1);
    // One hue per component, spread so that neighbouring indices get distant colours.
    let hues: Vec<f64> = (0..k).map(|t| (t * 7 % k) as f64 / k as f64).collect();
    let palette = crate::mesh::colormap_range(&hues, 0.0, 1.0);
    let mut out = Vec::with_capacity(3 * n);
    for v in 0..n {
        let (best, rel) = magnitudes
            .iter()
            .zip(&peaks)
            .map(|(m, &p)| if p > 0.0 { m[v] / p } else { 0.0 })
            .enumerate()
            .fold((0, 0.0), |a, (t, r)| if r > a.1 { (t, r) } else { a });
        for x in palette[best] {
            out.push((x as f64 / 255.0 * rel.clamp(0.0, 1.0)) as f32);
        }
    }
    out
}

/// What every export format writes: the blendshapes (rotated to Y-up), their normals, the
/// additivity measures and the orientation (module docs).
pub struct Prepared {
    pub shapes: Blendshapes,
    pub base_normals: Vec<Vec3>,
    /// Each target's change of the vertex normals.
    pub target_normals: Vec<Vec<Vec3>>,
    pub additivity: Option<f64>,
    pub additivity_extreme: Option<f64>,
    pub fitted: bool,
    pub rotation: crate::math::mat3::Mat3,
    pub up_axis: String,
    /// Whether the mesh has a boundary (drawn double-sided).
    pub open: bool,
    /// The training frames (`None` when the model stores no training weights).
    pub training: Option<Training>,
}

impl Prepared {
    /// The keyed weights (target order) of the animation: one row per training frame with
    /// `animation` (the frame's dials) or `bake` (one-hot); empty otherwise.
    pub fn keyed_weights(&self, options: &ExportOptions) -> Result<Vec<Vec<f64>>> {
        if !(options.animation || options.bake) || self.shapes.deltas.is_empty() {
            return Ok(Vec::new());
        }
        let training = self.training.as_ref().ok_or_else(|| {
            Error::Invalid("--animation: the model stores no training weights to animate".to_string())
        })?;
        Ok(training.dials.iter().map(|d| self.shapes.index.iter().map(|&k| d[k]).collect()).collect())
    }

    /// `baked`, `fitted` or `extreme`.
    pub fn targets_kind(&self, options: &ExportOptions) -> &'static str {
        if options.bake {
            "baked"
        } else if self.fitted {
            "fitted"
        } else {
            "extreme"
        }
    }

    /// The report of a file of `bytes` with `frames` animation keys.
    pub fn report(self, bytes: usize, frames: usize) -> ExportReport {
        ExportReport {
            targets: self.shapes.deltas.len(),
            names: self.shapes.names,
            additivity_erms: self.additivity,
            additivity_extreme_erms: self.additivity_extreme,
            targets_fitted: self.fitted,
            up_axis: self.up_axis,
            animation_frames: frames,
            bytes,
        }
    }
}

/// Whether an additivity error `extreme` (data units) of a model whose rest mesh has the
/// bounding-box diagonal `diagonal` is more than rounding: above 10⁻⁹ of 1000 diagonals (a
/// displacement model's sum of targets is exact up to rounding, so only a nonlinear model's
/// targets are worth fitting). A zero diagonal counts as the smallest positive number.
fn beyond_rounding(extreme: f64, diagonal: f64) -> bool {
    extreme > 1e-9 * (1000.0 * diagonal).max(f64::MIN_POSITIVE)
}

/// Whether every coordinate of the base, the targets and the targets' normal changes is a
/// finite number that single precision (glTF's and USD's floats) can hold.
fn single_precision(base: &[Vec3], deltas: &[Vec<Vec3>], target_normals: &[Vec<Vec3>]) -> bool {
    let fits = |p: &[Vec3]| p.iter().flatten().all(|x| x.is_finite() && x.abs() <= f32::MAX as f64);
    fits(base) && deltas.iter().all(|d| fits(d)) && target_normals.iter().all(|d| fits(d))
}

/// Builds the blendshapes of `model` as `options` ask (fitted or baked targets, rotation to
/// Y-up, normals) and checks that everything is finite.
pub fn prepare(model: &dyn Model, options: &ExportOptions) -> Result<Prepared> {
    if (options.animation || options.bake)
        && let Some(e) = fps_error(options.fps)
    {
        return Err(Error::Invalid(e));
    }
    if !(options.fit_regularisation.is_finite() && options.fit_regularisation > 0.0) {
        return Err(Error::Invalid(format!(
            "--fit-regularisation ({}) must be a positive number",
            options.fit_regularisation
        )));
    }
    let rest = model.rest();
    let alignment = model.alignment();
    let mut training = Training::of(model)?;
    let (mut shapes, additivity, additivity_extreme, fitted) = if options.bake {
        let t = training
            .as_mut()
            .ok_or_else(|| Error::Invalid("--bake: the model stores no training weights to bake".to_string()))?;
        let s = Blendshapes::baked(model, t)?;
        // Frame i is keyed by the one-hot vector of target i.
        t.dials = (0..s.deltas.len()).map(|i| one_hot(s.deltas.len(), i)).collect();
        let e = additivity_error(&s, t, alignment)?;
        (s, Some(e), None, false)
    } else {
        let mut s = Blendshapes::of(model)?;
        let extreme = training.as_ref().map(|t| additivity_error(&s, t, alignment)).transpose()?;
        // Displacement models blend exactly (0 up to rounding): nothing to fit.
        let nonlinear = extreme.is_some_and(|e| {
            let (lo, hi) = rest.bounding_box();
            beyond_rounding(e, crate::mesh::dist(lo, hi))
        });
        match training.as_ref() {
            Some(t)
                if options.targets == TargetFit::Fitted
                    && nonlinear
                    && s.fit_to_training(t, options.fit_regularisation)? =>
            {
                let after = additivity_error(&s, t, alignment)?;
                (s, Some(after), extreme, true)
            }
            _ => (s, extreme, None, false),
        }
    };
    // Orientation: rotate the base and the targets so that the chosen axis is +Y.
    let (rotation, up_axis) = orientation(&shapes.base, &rest.faces, options.up);
    shapes.base = rotate(&rotation, &shapes.base);
    for d in &mut shapes.deltas {
        *d = rotate(&rotation, d);
    }
    let normals_of = |p: &[Vec3]| -> Vec<Vec3> {
        vertex_normals(p, &rest.faces, NormalWeighting::Area)
            .into_iter()
            .map(|n| if n == [0.0; 3] { [0.0, 1.0, 0.0] } else { n })
            .collect()
    };
    let base_normals = normals_of(&shapes.base);
    let open =
        crate::mesh::topology::Topology::new(rest.n_vertices(), &rest.faces).is_boundary_vertex.iter().any(|&b| b);

    let target_normals: Vec<Vec<Vec3>> = shapes
        .deltas
        .iter()
        .map(|d| {
            let shape: Vec<Vec3> = shapes.base.iter().zip(d).map(|(p, q)| add(*p, *q)).collect();
            normals_of(&shape).iter().zip(&base_normals).map(|(a, b)| sub(*a, *b)).collect()
        })
        .collect();
    if !single_precision(&shapes.base, &shapes.deltas, &target_normals) {
        return Err(Error::Invalid(format!(
            "the {} model's shapes are not finite single-precision numbers; nothing written",
            model.kind().name()
        )));
    }
    Ok(Prepared {
        shapes,
        base_normals,
        target_normals,
        additivity,
        additivity_extreme,
        fitted,
        rotation,
        up_axis,
        open,
        training,
    })
}

/// Writes `model` as a `.glb` at `path`, atomically (see the module docs).
pub fn export_glb(model: &dyn Model, path: &Path, options: &ExportOptions) -> Result<ExportReport> {
    let p = prepare(model, options)?;
    let rest = model.rest();
    let keys = p.keyed_weights(options)?;
    let mut b = Builder::new();
    use json::accessor::Type;
    use json::buffer::Target;
    let positions = b.floats(&flat(&p.shapes.base), Type::Vec3, Some(Target::ArrayBuffer), true, "positions");
    let normals = b.floats(&flat(&p.base_normals), Type::Vec3, Some(Target::ArrayBuffer), false, "normals");
    let indices = b.indices(&rest.faces)?;
    let mut attributes = BTreeMap::new();
    attributes.insert(Valid(json::mesh::Semantic::Positions), positions);
    attributes.insert(Valid(json::mesh::Semantic::Normals), normals);
    if options.colors {
        let c = support_colors(&p.shapes.magnitudes, rest.n_vertices());
        let colors = b.floats(&c, Type::Vec3, Some(Target::ArrayBuffer), false, "support colours");
        attributes.insert(Valid(json::mesh::Semantic::Colors(0)), colors);
    }
    let targets: Vec<json::mesh::MorphTarget> = p
        .shapes
        .deltas
        .iter()
        .zip(&p.shapes.names)
        .zip(&p.target_normals)
        .map(|((d, name), dn)| json::mesh::MorphTarget {
            positions: Some(b.floats(&flat(d), Type::Vec3, Some(Target::ArrayBuffer), true, name)),
            normals: Some(b.floats(&flat(dn), Type::Vec3, Some(Target::ArrayBuffer), false, "normal change")),
            tangents: None,
        })
        .collect();
    let material = b.root.push(json::Material {
        double_sided: p.open,
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_factor: json::material::PbrBaseColorFactor([0.8, 0.8, 0.8, 1.0]),
            metallic_factor: json::material::StrengthFactor(0.0),
            roughness_factor: json::material::StrengthFactor(0.8),
            ..Default::default()
        },
        ..Default::default()
    });
    let n_targets = targets.len();
    let primitive = json::mesh::Primitive {
        attributes,
        extensions: None,
        extras: None,
        indices: Some(indices),
        material: Some(material),
        mode: Valid(json::mesh::Mode::Triangles),
        targets: (n_targets > 0).then_some(targets),
    };
    let mesh = b.root.push(json::Mesh {
        extensions: None,
        extras: Some(raw(serde_json::json!({ "targetNames": p.shapes.names }))?),
        name: Some(format!("meshdeco {}", model.kind().name())),
        primitives: vec![primitive],
        weights: (n_targets > 0).then(|| vec![0.0; n_targets]),
    });
    let node = b.root.push(json::Node { mesh: Some(mesh), name: Some("model".into()), ..Default::default() });
    let scene = b.root.push(json::Scene { extensions: None, extras: None, name: None, nodes: vec![node] });
    b.root.scene = Some(scene);

    if !keys.is_empty() {
        let times: Vec<f32> = (0..keys.len()).map(|i| (i as f64 / options.fps) as f32).collect();
        if let Some(i) = times.windows(2).position(|w| !(w[1] > w[0] && w[1].is_finite())) {
            return Err(Error::Invalid(format!(
                "--fps {:?}: the key times of frames {i} and {} are not increasing in f32 ({} frames)",
                options.fps,
                i + 1,
                keys.len()
            )));
        }
        let values: Vec<f32> = keys.iter().flatten().map(|&x| x as f32).collect();
        let input = b.floats(&times, Type::Scalar, None, true, "frame times");
        let output = b.floats(&values, Type::Scalar, None, false, "frame weights");
        let sampler = json::animation::Sampler {
            extensions: None,
            extras: None,
            input,
            interpolation: Valid(json::animation::Interpolation::Linear),
            output,
        };
        b.root.push(json::Animation {
            extensions: None,
            extras: None,
            channels: vec![json::animation::Channel {
                sampler: json::Index::new(0),
                target: json::animation::Target {
                    extensions: None,
                    extras: None,
                    node,
                    path: Valid(json::animation::Property::MorphTargetWeights),
                },
                extensions: None,
                extras: None,
            }],
            name: Some("training frames".into()),
            samplers: vec![sampler],
        });
    }
    b.root.asset = json::Asset {
        copyright: None,
        extensions: None,
        extras: Some(raw(serde_json::json!({
            "method": model.kind().name(),
            "representation": model.representation().name(),
            "components": n_targets,
            "additivity_erms": p.additivity,
            "additivity_extreme_erms": p.additivity_extreme,
            "targets": p.targets_kind(options),
            "additivity_note": "Erms (1000 × RMS of the coordinates, data units: the unit of every Erms of meshdeco) between the model's decoding of its training frames and the base mesh plus the weighted morph targets",
            "up_axis": p.up_axis,
            "rotation": p.rotation,
            "train_frames": model.train_frames(),
        }))?),
        generator: Some(format!("meshdeco {}", env!("CARGO_PKG_VERSION"))),
        min_version: None,
        version: "2.0".into(),
    };
    let bytes = b.finish()?;
    crate::artifact::write_atomic(path, &bytes)?;
    Ok(p.report(bytes.len(), keys.len()))
}

/// The parts of a `.glb` written by [`export_glb`] that a reader needs to replay it: base
/// positions, morph-target deltas (file order), target names and the animation's keyed weights
/// (one row per key). Checks the container and the accessors it reads.
#[derive(Debug, Clone, PartialEq)]
pub struct GlbMorphs {
    pub base: Vec<Vec3>,
    pub faces: Vec<[usize; 3]>,
    pub targets: Vec<Vec<Vec3>>,
    /// Each target's normal change (empty where the file has none).
    pub target_normals: Vec<Vec<Vec3>>,
    pub names: Vec<String>,
    pub animation: Vec<Vec<f64>>,
    /// Key times of the animation, seconds.
    pub times: Vec<f64>,
    /// `asset.extras.rotation` (rows: data → file axes; identity when absent).
    pub rotation: crate::math::mat3::Mat3,
    /// `asset.extras.up_axis` (empty when absent).
    pub up_axis: String,
}

impl GlbMorphs {
    /// The same morphs rotated back into the model's data axes (Rᵀ of [`GlbMorphs::rotation`]).
    pub fn in_data_axes(mut self) -> Self {
        let rt = crate::math::mat3::transpose(&self.rotation);
        self.base = rotate(&rt, &self.base);
        for t in self.targets.iter_mut().chain(self.target_normals.iter_mut()) {
            *t = rotate(&rt, t);
        }
        self
    }

    /// base + Σ_t w_t·target_t (w in file order).
    pub fn blend(&self, w: &[f64]) -> Vec<Vec3> {
        blend(&self.base, &self.targets, w)
    }

    /// The frames as a sequence with the file's faces.
    pub fn sequence(&self, frames: Vec<Vec<Vec3>>) -> MeshSequence {
        MeshSequence { faces: self.faces.clone(), frames, names: Vec::new() }
    }
}

/// Reads a `.glb` written by [`export_glb`].
pub fn read_glb(path: &Path) -> Result<GlbMorphs> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |m: &str| Error::parse(path, None, m.to_string());
    if bytes.len() < 20 || &bytes[0..4] != b"glTF" {
        return Err(bad("not a binary glTF file"));
    }
    let u32_at = |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]) as usize;
    let json_len = u32_at(12);
    if 20 + json_len + 8 > bytes.len() || &bytes[16..20] != b"JSON" {
        return Err(bad("truncated JSON chunk"));
    }
    let root: json::Root =
        serde_json::from_slice(&bytes[20..20 + json_len]).map_err(|e| bad(&format!("glTF JSON: {e}")))?;
    let bin_at = 20 + json_len;
    let bin_len = u32_at(bin_at);
    if bin_at + 8 + bin_len > bytes.len() || &bytes[bin_at + 4..bin_at + 8] != b"BIN\0" {
        return Err(bad("truncated BIN chunk"));
    }
    let bin = &bytes[bin_at + 8..bin_at + 8 + bin_len];
    let data = |a: json::Index<json::Accessor>| -> Result<Vec<u8>> {
        let acc = root.accessors.get(a.value()).ok_or_else(|| bad("accessor out of range"))?;
        let view = root.buffer_views.get(acc.buffer_view.ok_or_else(|| bad("sparse accessor"))?.value());
        let view = view.ok_or_else(|| bad("buffer view out of range"))?;
        let start = view.byte_offset.map_or(0, |o| o.0 as usize) + acc.byte_offset.map_or(0, |o| o.0 as usize);
        let end = view.byte_offset.map_or(0, |o| o.0 as usize) + view.byte_length.0 as usize;
        bin.get(start..end).map(<[u8]>::to_vec).ok_or_else(|| bad("accessor past the buffer"))
    };
    let floats = |a| -> Result<Vec<f64>> {
        Ok(data(a)?.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64).collect())
    };
    let vec3s = |a| -> Result<Vec<Vec3>> { Ok(floats(a)?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()) };
    let mesh = root.meshes.first().ok_or_else(|| bad("no mesh"))?;
    let prim = mesh.primitives.first().ok_or_else(|| bad("no primitive"))?;
    let pos = *prim.attributes.get(&Valid(json::mesh::Semantic::Positions)).ok_or_else(|| bad("no POSITION"))?;
    let base = vec3s(pos)?;
    let idx: Vec<usize> = data(prim.indices.ok_or_else(|| bad("no indices"))?)?
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as usize)
        .collect();
    let faces = idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let mut targets = Vec::new();
    let mut target_normals = Vec::new();
    for t in prim.targets.iter().flatten() {
        targets.push(vec3s(t.positions.ok_or_else(|| bad("morph target without POSITION"))?)?);
        if let Some(n) = t.normals {
            target_normals.push(vec3s(n)?);
        }
    }
    let extras: serde_json::Value =
        root.asset.extras.as_ref().and_then(|e| serde_json::from_str(e.get()).ok()).unwrap_or(serde_json::Value::Null);
    let rotation: crate::math::mat3::Mat3 = match extras.get("rotation") {
        None => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        Some(r) => serde_json::from_value(r.clone()).map_err(|_| bad("asset.extras.rotation is not a 3×3 matrix"))?,
    };
    if (crate::math::mat3::det(&rotation) - 1.0).abs() > 1e-6 {
        return Err(bad("asset.extras.rotation is not a rotation"));
    }
    let up_axis = extras.get("up_axis").and_then(|u| u.as_str()).unwrap_or_default().to_string();
    let names: Vec<String> = mesh
        .extras
        .as_ref()
        .and_then(|e| serde_json::from_str::<serde_json::Value>(e.get()).ok())
        .and_then(|v| v.get("targetNames").cloned())
        .and_then(|v| serde_json::from_value(v).ok())
        .unwrap_or_default();
    let mut animation = Vec::new();
    let mut times = Vec::new();
    if let Some(anim) = root.animations.first()
        && let Some(s) = anim.samplers.first()
    {
        let values = floats(s.output)?;
        animation = values.chunks_exact(targets.len().max(1)).map(<[f64]>::to_vec).collect();
        times = floats(s.input)?;
        if times.len() != animation.len() {
            return Err(bad(&format!("{} key times for {} keyed weight sets", times.len(), animation.len())));
        }
    }
    Ok(GlbMorphs { base, faces, targets, target_normals, names, animation, times, rotation, up_axis })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat 4 × 2 rectangle far from the origin along z (so that a bounding box's `hi + lo`
    /// or `hi / lo` would not find z thinnest), wound so that its normals face `+z` or `−z`.
    fn plate(faces_minus_z: bool) -> (Vec<Vec3>, Vec<[usize; 3]>) {
        let p = vec![[-2.0, -1.0, 100.0], [2.0, -1.0, 100.0], [2.0, 1.0, 100.0], [-2.0, 1.0, 100.0]];
        let f = if faces_minus_z { vec![[0, 2, 1], [0, 3, 2]] } else { vec![[0, 1, 2], [0, 2, 3]] };
        (p, f)
    }

    #[test]
    fn orientation_views_along_the_thinnest_axis_from_the_front() {
        for minus in [false, true] {
            let (p, f) = plate(minus);
            let ([x, y, z], name) = orientation(&p, &f, UpAxis::Axis(1, false));
            assert_eq!(name, "+y");
            assert_eq!(y, [0.0, 1.0, 0.0]);
            // The view axis is z (extent 0), not x (extent 4), and its sign puts the front at +Z.
            let s = if minus { -1.0 } else { 1.0 };
            assert_eq!(z, [0.0, 0.0, s], "faces toward −z: {minus}");
            // A proper rotation: x = y × z.
            assert_eq!(x, [s, 0.0, 0.0]);
        }
        // Down the − side of an axis.
        let (p, f) = plate(false);
        let ([_, y, _], name) = orientation(&p, &f, UpAxis::Axis(0, true));
        assert_eq!((y, name.as_str()), ([-1.0, 0.0, 0.0], "-x"));
    }

    #[test]
    fn fitting_without_frames_or_targets_changes_nothing() {
        let target = vec![[1.0, 2.0, 3.0], [0.0, -1.0, 0.5]];
        let mut b = Blendshapes {
            base: vec![[0.0; 3]; 2],
            index: vec![0],
            names: vec!["r0 k0 v0".into()],
            deltas: vec![target.clone()],
            magnitudes: vec![vec![1.0, 1.0]],
        };
        let none = Training { dials: vec![], decoded: vec![] };
        assert!(!b.fit_to_training(&none, 0.1).unwrap(), "no frame: nothing to fit");
        assert_eq!(b.deltas, vec![target.clone()]);
        let one = Training { dials: vec![vec![0.5]], decoded: vec![vec![[2.0, 0.0, 0.0], [0.0, 0.0, 0.0]]] };
        let mut empty =
            Blendshapes { base: b.base.clone(), index: vec![], names: vec![], deltas: vec![], magnitudes: vec![] };
        assert!(!empty.fit_to_training(&one, 0.1).unwrap(), "no target: nothing to fit");
        // With both, the fit moves the target toward the frame's residual over its dial.
        assert!(b.fit_to_training(&one, 0.1).unwrap());
        assert!(b.deltas[0][0][0] > 1.0 + 1e-6, "{:?}", b.deltas[0][0]);
    }

    /// The fit solves (WᵀW + μI)·E = Wᵀ(D − base) + μ·E₀ with μ = mu_rel·trace(WᵀW)/K, checked
    /// against Cramer's rule for two targets and two frames (K = 2, so that trace/K differs
    /// from trace·K and trace mod K).
    #[test]
    fn fitted_targets_solve_the_regularised_normal_equations() {
        let base = vec![[0.5, 0.0, -1.0]];
        let e0 = [[1.0, -2.0, 0.25], [0.0, 3.0, 1.0]];
        let w = [[1.0, 0.5], [0.0, 2.0]];
        let d = [[2.0, 1.0, 0.0], [-1.0, 4.0, 2.0]];
        let mu_rel = 0.3;
        let mut b = Blendshapes {
            base: base.clone(),
            index: vec![0, 1],
            names: vec!["a".into(), "b".into()],
            deltas: vec![vec![e0[0]], vec![e0[1]]],
            magnitudes: vec![vec![1.0], vec![1.0]],
        };
        let t =
            Training { dials: w.iter().map(|r| r.to_vec()).collect(), decoded: d.iter().map(|f| vec![*f]).collect() };
        assert!(b.fit_to_training(&t, mu_rel).unwrap());
        let a = [
            [w[0][0] * w[0][0] + w[1][0] * w[1][0], w[0][0] * w[0][1] + w[1][0] * w[1][1]],
            [w[0][1] * w[0][0] + w[1][1] * w[1][0], w[0][1] * w[0][1] + w[1][1] * w[1][1]],
        ];
        let mu = mu_rel * (a[0][0] + a[1][1]) / 2.0;
        let (a00, a11) = (a[0][0] + mu, a[1][1] + mu);
        let det = a00 * a11 - a[0][1] * a[1][0];
        for c in 0..3 {
            let r: Vec<f64> =
                (0..2).map(|i| (0..2).map(|f| w[f][i] * (d[f][c] - base[0][c])).sum::<f64>() + mu * e0[i][c]).collect();
            let x0 = (r[0] * a11 - a[0][1] * r[1]) / det;
            let x1 = (a00 * r[1] - a[1][0] * r[0]) / det;
            assert!((b.deltas[0][0][c] - x0).abs() < 1e-12, "target 0, coordinate {c}: {} vs {x0}", b.deltas[0][0][c]);
            assert!((b.deltas[1][0][c] - x1).abs() < 1e-12, "target 1, coordinate {c}: {} vs {x1}", b.deltas[1][0][c]);
        }
    }

    /// Each vertex takes the colour of the component with the largest magnitude relative to that
    /// component's peak, darkened by that ratio; hues are spread as t·7 mod K over K; a vertex no
    /// component reaches is black.
    #[test]
    fn support_colours_follow_the_strongest_component() {
        let m = vec![
            vec![2.0, 1.0, 0.0, 0.0, 1.0, 1.0],
            vec![0.0, 2.0, 0.5, 0.0, 0.0, 1.0],
            vec![0.0, 0.0, 3.0, 0.0, 0.0, 0.0],
            vec![0.0; 6],
        ];
        let c = support_colors(&m, 6);
        // K = 4: hues 0, 3/4, 2/4, 1/4 for components 0..3.
        let palette = crate::mesh::colormap_range(&[0.0, 0.75, 0.5, 0.25], 0.0, 1.0);
        assert_ne!(palette[1], palette[3]);
        let expect = |t: usize, r: f64| palette[t].map(|x| (x as f64 / 255.0 * r) as f32);
        // Vertex 5: components 0 and 1 tie at half their peaks; the first wins.
        let want = [expect(0, 1.0), expect(1, 1.0), expect(2, 1.0), [0.0; 3], expect(0, 0.5), expect(0, 0.5)];
        for (v, w) in want.iter().enumerate() {
            assert_eq!(&c[3 * v..3 * v + 3], w, "vertex {v}");
        }
    }

    fn prepared(index: Vec<usize>, dials: Option<Vec<Vec<f64>>>, fitted: bool) -> Prepared {
        let k = index.len();
        Prepared {
            shapes: Blendshapes {
                base: vec![[0.0; 3]],
                index,
                names: vec![String::new(); k],
                deltas: vec![vec![[1.0, 0.0, 0.0]]; k],
                magnitudes: vec![vec![1.0]; k],
            },
            base_normals: vec![[0.0, 1.0, 0.0]],
            target_normals: vec![vec![[0.0; 3]]; k],
            additivity: None,
            additivity_extreme: None,
            fitted,
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            up_axis: "+y".into(),
            open: true,
            training: dials.map(|dials| Training { decoded: vec![vec![[0.0; 3]]; dials.len()], dials }),
        }
    }

    /// Keys are written with `animation` or `bake` (either alone), in target order, and not
    /// without a target; a model without training weights cannot be animated.
    #[test]
    fn keyed_weights_follow_the_options_in_target_order() {
        let p = prepared(vec![1, 0], Some(vec![vec![0.2, 0.7], vec![-1.0, 0.5]]), false);
        let no = ExportOptions::default();
        assert!(p.keyed_weights(&no).unwrap().is_empty());
        let want = vec![vec![0.7, 0.2], vec![0.5, -1.0]];
        assert_eq!(p.keyed_weights(&ExportOptions { animation: true, ..no }).unwrap(), want);
        assert_eq!(p.keyed_weights(&ExportOptions { bake: true, ..no }).unwrap(), want);
        let empty = prepared(vec![], Some(vec![vec![0.2, 0.7]]), false);
        assert!(empty.keyed_weights(&ExportOptions { animation: true, ..no }).unwrap().is_empty());
        let e = prepared(vec![0], None, false).keyed_weights(&ExportOptions { animation: true, ..no }).unwrap_err();
        assert!(e.to_string().contains("no training weights"), "{e}");
        // The kind of targets named in the file.
        assert_eq!(p.targets_kind(&ExportOptions { bake: true, ..no }), "baked");
        assert_eq!(prepared(vec![0], None, true).targets_kind(&no), "fitted");
        assert_eq!(p.targets_kind(&no), "extreme");
    }

    /// The reader's header checks: too short, exactly a header with an empty JSON chunk, and
    /// long enough but not glTF — each a named error, never a panic.
    #[test]
    fn read_glb_names_what_is_wrong_with_a_header() {
        let dir = crate::mesh::load::test_dir("read-glb");
        let mut header = b"glTF".to_vec();
        header.extend_from_slice(&2u32.to_le_bytes());
        header.extend_from_slice(&20u32.to_le_bytes());
        header.extend_from_slice(&0u32.to_le_bytes());
        header.extend_from_slice(b"JSON");
        for (name, bytes, want) in [
            ("short.glb", b"glTF".to_vec(), "not a binary glTF file"),
            ("header.glb", header, "truncated JSON chunk"),
            ("text.glb", vec![b'x'; 100], "not a binary glTF file"),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, &bytes).unwrap();
            let e = read_glb(&path).err().map(|e| e.to_string()).unwrap_or_default();
            assert!(e.contains(want) && e.contains(name), "{name}: {e:?}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A `.glb` from a JSON chunk and a BIN chunk (`None`: no BIN chunk), with the chunk types
    /// given (`JSON`, `BIN\0` in a valid file); the JSON is padded with spaces to 4 bytes.
    fn glb_bytes(json: &str, json_type: &[u8; 4], bin: Option<(&[u8], &[u8; 4])>) -> Vec<u8> {
        let mut j = json.as_bytes().to_vec();
        while !j.len().is_multiple_of(4) {
            j.push(b' ');
        }
        let total = 12 + 8 + j.len() + bin.map_or(0, |(b, _)| 8 + b.len());
        let mut out = b"glTF".to_vec();
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(j.len() as u32).to_le_bytes());
        out.extend_from_slice(json_type);
        out.extend_from_slice(&j);
        if let Some((b, t)) = bin {
            out.extend_from_slice(&(b.len() as u32).to_le_bytes());
            out.extend_from_slice(t);
            out.extend_from_slice(b);
        }
        out
    }

    /// A hand-made file whose accessors start inside their buffer views (view offsets 4 and 44,
    /// the positions' accessor 4 bytes into its view, the buffer's first 8 bytes a decoy 99.0),
    /// with `rotation` as the asset's rotation and an animation of `times` keys and `sets`
    /// weight sets (no morph target: one weight per set).
    fn crafted(rotation: &str, times: usize, sets: usize) -> (String, Vec<u8>) {
        let mut bin: Vec<u8> = Vec::new();
        for x in [99.0f32, 99.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0] {
            bin.extend_from_slice(&x.to_le_bytes());
        }
        for i in [0u32, 2, 1] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        let keyed = bin.len();
        for i in 0..times + sets {
            bin.extend_from_slice(&(i as f32 * 0.5).to_le_bytes());
        }
        let json = format!(
            r#"{{"asset":{{"version":"2.0","extras":{{"rotation":{rotation},"up_axis":"+z"}}}},
            "buffers":[{{"byteLength":{n}}}],
            "bufferViews":[{{"buffer":0,"byteOffset":4,"byteLength":40}},{{"buffer":0,"byteOffset":44,"byteLength":12}},
              {{"buffer":0,"byteOffset":{keyed},"byteLength":{tb}}},{{"buffer":0,"byteOffset":{wo},"byteLength":{wb}}}],
            "accessors":[{{"bufferView":0,"byteOffset":4,"componentType":5126,"count":3,"type":"VEC3"}},
              {{"bufferView":1,"componentType":5125,"count":3,"type":"SCALAR"}},
              {{"bufferView":2,"componentType":5126,"count":{times},"type":"SCALAR"}},
              {{"bufferView":3,"componentType":5126,"count":{sets},"type":"SCALAR"}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
            "nodes":[{{"mesh":0}}],
            "animations":[{{"channels":[{{"sampler":0,"target":{{"node":0,"path":"weights"}}}}],
              "samplers":[{{"input":2,"output":3}}]}}]}}"#,
            n = bin.len(),
            tb = 4 * times,
            wo = keyed + 4 * times,
            wb = 4 * sets,
        );
        (json, bin)
    }

    /// Accessors are read from their view's offset plus their own, the asset's rotation is
    /// checked, and the animation's key times must match its weight sets.
    #[test]
    fn read_glb_reads_offsets_rotation_and_keys() {
        let dir = crate::mesh::load::test_dir("read-glb-crafted");
        let path = dir.join("crafted.glb");
        let turn = "[[0.0,-1.0,0.0],[1.0,0.0,0.0],[0.0,0.0,1.0]]";
        let (json, bin) = crafted(turn, 2, 2);
        std::fs::write(&path, glb_bytes(&json, b"JSON", Some((&bin, b"BIN\0")))).unwrap();
        let g = read_glb(&path).unwrap();
        assert_eq!(g.base, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]);
        assert_eq!(g.faces, vec![[0, 2, 1]]);
        assert_eq!(g.rotation, [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        assert_eq!(g.up_axis, "+z");
        assert!(g.targets.is_empty() && g.target_normals.is_empty() && g.names.is_empty());
        assert_eq!(g.times, vec![0.0, 0.5]);
        assert_eq!(g.animation, vec![vec![1.0], vec![1.5]]);
        // Rotated back into the data axes: Rᵀ p.
        assert_eq!(g.in_data_axes().base[0], [2.0, -1.0, 3.0]);
        for (rotation, times, sets, want) in [
            ("[[2.0,0.0,0.0],[0.0,1.0,0.0],[0.0,0.0,1.0]]", 2, 2, "not a rotation"),
            ("[[1.0,0.0,0.0],[0.0,1.0,0.0],[0.0,0.0,-1.0]]", 2, 2, "not a rotation"),
            ("[[1.0,0.0],[0.0,1.0]]", 2, 2, "not a 3×3 matrix"),
            (turn, 2, 3, "2 key times for 3 keyed weight sets"),
        ] {
            let (json, bin) = crafted(rotation, times, sets);
            std::fs::write(&path, glb_bytes(&json, b"JSON", Some((&bin, b"BIN\0")))).unwrap();
            let e = read_glb(&path).err().map(|e| e.to_string()).unwrap_or_default();
            assert!(e.contains(want) && e.contains("crafted.glb"), "{rotation} {times}/{sets}: {e:?}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Chunks of the wrong type or length, a file cut anywhere, and a valid file with an empty
    /// BIN chunk: each a named error (never a panic), and the empty chunk read as such.
    #[test]
    fn read_glb_checks_every_chunk_bound() {
        let dir = crate::mesh::load::test_dir("read-glb-chunks");
        let path = dir.join("chunks.glb");
        let read = |bytes: &[u8]| -> std::result::Result<GlbMorphs, String> {
            std::fs::write(&path, bytes).unwrap();
            read_glb(&path).map_err(|e| e.to_string())
        };
        let (json, bin) = crafted("[[1.0,0.0,0.0],[0.0,1.0,0.0],[0.0,0.0,1.0]]", 2, 2);
        let good = glb_bytes(&json, b"JSON", Some((&bin, b"BIN\0")));
        assert!(read(&good).is_ok());
        for (bytes, want) in [
            (glb_bytes(&json, b"JSN\0", Some((&bin, b"BIN\0"))), "truncated JSON chunk"),
            (glb_bytes(&json, b"JSON", Some((&bin, b"BIN "))), "truncated BIN chunk"),
            (glb_bytes(&json, b"JSON", None), "truncated JSON chunk"),
            // No mesh, and a BIN chunk of 0 bytes ending the file exactly.
            (glb_bytes(r#"{"asset":{"version":"2.0"}}"#, b"JSON", Some((&[], b"BIN\0"))), "no mesh"),
            // A BIN chunk that claims one byte more than the file holds.
            (
                {
                    let mut b = good.clone();
                    let at = b.len() - bin.len() - 8;
                    b[at..at + 4].copy_from_slice(&(bin.len() as u32 + 1).to_le_bytes());
                    b
                },
                "truncated BIN chunk",
            ),
            // A JSON chunk that claims to run past the end.
            (
                {
                    let mut b = good.clone();
                    b[12..16].copy_from_slice(&(good.len() as u32).to_le_bytes());
                    b
                },
                "truncated JSON chunk",
            ),
        ] {
            let e = read(&bytes).err().unwrap_or_default();
            assert!(e.contains(want) && e.contains("chunks.glb"), "{want}: {e:?}");
        }
        for n in 0..good.len() {
            let e = read(&good[..n]).err().unwrap_or_else(|| panic!("cut at {n} read"));
            assert!(e.contains("chunks.glb"), "cut at {n}: {e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The threshold between a model that blends exactly up to rounding and one whose targets
    /// are worth fitting: 10⁻⁹ of 1000 bounding-box diagonals, a zero diagonal counting as the
    /// smallest positive number; an error at the threshold is rounding.
    #[test]
    fn rounding_threshold_scales_with_the_mesh() {
        let at = |d: f64| 1e-9 * (1000.0 * d);
        assert!(!beyond_rounding(at(1.0), 1.0));
        assert!(beyond_rounding(at(1.0) * 1.5, 1.0));
        assert!(!beyond_rounding(1e-10, 1.0));
        // A 1 mm mesh: 10⁻⁹ is beyond rounding, 10⁻¹⁰ is not.
        assert!(beyond_rounding(5e-7, 1e-3) && beyond_rounding(2e-9, 1e-3) && !beyond_rounding(1e-10, 1e-3));
        // A 10⁶ m mesh: 0.5 is rounding, 2 is not.
        assert!(!beyond_rounding(0.5, 1e6) && beyond_rounding(2.0, 1e6));
        assert!(!beyond_rounding(0.0, 0.0) && beyond_rounding(1e-300, 0.0));
    }

    /// Each of the base, the targets and the normal changes is checked, every value of it:
    /// infinite, NaN or beyond f32's range anywhere is refused.
    #[test]
    fn single_precision_checks_every_part() {
        let ok = vec![[1.0, -2.0, f32::MAX as f64]];
        let two = vec![ok.clone(), ok.clone()];
        assert!(single_precision(&ok, &two, &two));
        assert!(single_precision(&ok, &[], &[]));
        for bad in [f64::INFINITY, f64::NAN, -1e39] {
            let b = vec![[1.0, bad, 0.0]];
            let mixed = vec![ok.clone(), b.clone()];
            assert!(!single_precision(&b, &two, &two), "{bad} in the base");
            assert!(!single_precision(&ok, &mixed, &two), "{bad} in the second target");
            assert!(!single_precision(&ok, &two, &mixed), "{bad} in the second normal change");
        }
    }

    #[test]
    fn frame_rates_outside_the_range_are_named() {
        for fps in [0.01, 1.0, 24.0, 1000.0] {
            assert_eq!(fps_error(fps), None, "{fps}");
        }
        for fps in [0.0, 0.009, -24.0, 1000.5, f64::NAN, f64::INFINITY] {
            let e = fps_error(fps).unwrap_or_else(|| panic!("{fps} accepted"));
            assert!(e.starts_with("--fps ") && e.contains("from 0.01 to 1000"), "{e}");
        }
    }
}
