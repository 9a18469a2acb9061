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
//! Coordinates are stored as `f32` (glTF's only float type), so a round trip is exact to about
//! 1e-7 relative.

use std::collections::BTreeMap;
use std::path::Path;

use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;
use serde_json::value::RawValue;

use crate::error::{Error, Result};
use crate::mesh::normals::{NormalWeighting, vertex_normals};
use crate::mesh::{MeshSequence, Vec3};
use crate::metrics::erms::erms;
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
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions { animation: false, fps: 30.0, colors: false }
    }
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
            deltas.push(shape.iter().zip(&base).map(|(s, b)| [s[0] - b[0], s[1] - b[1], s[2] - b[2]]).collect());
            names.push(format!("r{} k{} v{}", c.rank, c.index, c.center));
            index.push(c.index);
            magnitudes.push(c.magnitudes);
        }
        Ok(Blendshapes { base, index, names, deltas, magnitudes })
    }

    /// base + Σ_t dials[index_t]·delta_t.
    pub fn blend(&self, dials: &[f64]) -> Vec<Vec3> {
        let w: Vec<f64> = self.index.iter().map(|&k| dials[k]).collect();
        blend(&self.base, &self.deltas, &w)
    }
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

/// Additivity error of `shapes` against the model over its training frames (see the module
/// docs); `None` when the model stores no training weights.
pub fn additivity_error(model: &dyn Model, shapes: &Blendshapes) -> Result<Option<f64>> {
    let Some(weights) = model.train_weights() else { return Ok(None) };
    let truth = model.decode(&weights)?;
    let blends = weights.iter().map(|w| Ok(shapes.blend(&model.dials(w)?))).collect::<Result<Vec<_>>>()?;
    Ok(Some(erms(&truth, &blends, model.alignment())?))
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

/// Writes `model` as a `.glb` at `path`, atomically (see the module docs).
pub fn export_glb(model: &dyn Model, path: &Path, options: &ExportOptions) -> Result<ExportReport> {
    if options.animation && !(options.fps.is_finite() && options.fps > 0.0) {
        return Err(Error::Invalid(format!("--fps ({}) must be a positive number", options.fps)));
    }
    let rest = model.rest();
    let shapes = Blendshapes::of(model)?;
    let additivity = additivity_error(model, &shapes)?;
    let train = if options.animation {
        let w = model.train_weights().ok_or_else(|| {
            Error::Invalid("--animation: the model stores no training weights to animate".to_string())
        })?;
        Some(w)
    } else {
        None
    };

    let mut b = Builder::new();
    use json::accessor::Type;
    use json::buffer::Target;
    let positions = b.floats(&flat(&shapes.base), Type::Vec3, Some(Target::ArrayBuffer), true, "positions");
    let normals: Vec<Vec3> = vertex_normals(&shapes.base, &rest.faces, NormalWeighting::Area)
        .into_iter()
        .map(|n| if n == [0.0; 3] { [0.0, 0.0, 1.0] } else { n })
        .collect();
    let normals = b.floats(&flat(&normals), Type::Vec3, Some(Target::ArrayBuffer), false, "normals");
    let indices = b.indices(&rest.faces)?;
    let mut attributes = BTreeMap::new();
    attributes.insert(Valid(json::mesh::Semantic::Positions), positions);
    attributes.insert(Valid(json::mesh::Semantic::Normals), normals);
    if options.colors {
        let c = support_colors(&shapes.magnitudes, rest.n_vertices());
        let colors = b.floats(&c, Type::Vec3, Some(Target::ArrayBuffer), false, "support colours");
        attributes.insert(Valid(json::mesh::Semantic::Colors(0)), colors);
    }
    let targets: Vec<json::mesh::MorphTarget> = shapes
        .deltas
        .iter()
        .zip(&shapes.names)
        .map(|(d, name)| json::mesh::MorphTarget {
            positions: Some(b.floats(&flat(d), Type::Vec3, Some(Target::ArrayBuffer), true, name)),
            normals: None,
            tangents: None,
        })
        .collect();
    let n_targets = targets.len();
    let primitive = json::mesh::Primitive {
        attributes,
        extensions: None,
        extras: None,
        indices: Some(indices),
        material: None,
        mode: Valid(json::mesh::Mode::Triangles),
        targets: (n_targets > 0).then_some(targets),
    };
    let mesh = b.root.push(json::Mesh {
        extensions: None,
        extras: Some(raw(serde_json::json!({ "targetNames": shapes.names }))?),
        name: Some(format!("meshdeco {}", model.kind().name())),
        primitives: vec![primitive],
        weights: (n_targets > 0).then(|| vec![0.0; n_targets]),
    });
    let node = b.root.push(json::Node { mesh: Some(mesh), name: Some("model".into()), ..Default::default() });
    let scene = b.root.push(json::Scene { extensions: None, extras: None, name: None, nodes: vec![node] });
    b.root.scene = Some(scene);

    let mut animation_frames = 0;
    if let Some(weights) = &train
        && n_targets > 0
    {
        let times: Vec<f32> = (0..weights.len()).map(|i| (i as f64 / options.fps) as f32).collect();
        let mut values = Vec::with_capacity(weights.len() * n_targets);
        for w in weights {
            let dials = model.dials(w)?;
            values.extend(shapes.index.iter().map(|&k| dials[k] as f32));
        }
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
        animation_frames = weights.len();
    }
    b.root.asset = json::Asset {
        copyright: None,
        extensions: None,
        extras: Some(raw(serde_json::json!({
            "method": model.kind().name(),
            "representation": model.representation().name(),
            "components": n_targets,
            "additivity_erms": additivity,
            "additivity_note": "Erms (1000 × RMS, data units) between the model's decoding of its training frames and the base mesh plus the weighted morph targets",
            "train_frames": model.train_frames(),
        }))?),
        generator: Some(format!("meshdeco {}", env!("CARGO_PKG_VERSION"))),
        min_version: None,
        version: "2.0".into(),
    };
    let bytes = b.finish()?;
    crate::artifact::write_atomic(path, &bytes)?;
    Ok(ExportReport {
        targets: n_targets,
        names: shapes.names,
        additivity_erms: additivity,
        animation_frames,
        bytes: bytes.len(),
    })
}

/// The parts of a `.glb` written by [`export_glb`] that a reader needs to replay it: base
/// positions, morph-target deltas (file order), target names and the animation's keyed weights
/// (one row per key). Checks the container and the accessors it reads.
#[derive(Debug, Clone, PartialEq)]
pub struct GlbMorphs {
    pub base: Vec<Vec3>,
    pub faces: Vec<[usize; 3]>,
    pub targets: Vec<Vec<Vec3>>,
    pub names: Vec<String>,
    pub animation: Vec<Vec<f64>>,
}

impl GlbMorphs {
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
    for t in prim.targets.iter().flatten() {
        targets.push(vec3s(t.positions.ok_or_else(|| bad("morph target without POSITION"))?)?);
    }
    let names: Vec<String> = mesh
        .extras
        .as_ref()
        .and_then(|e| serde_json::from_str::<serde_json::Value>(e.get()).ok())
        .and_then(|v| v.get("targetNames").cloned())
        .and_then(|v| serde_json::from_value(v).ok())
        .unwrap_or_default();
    let mut animation = Vec::new();
    if let Some(anim) = root.animations.first()
        && let Some(s) = anim.samplers.first()
    {
        let values = floats(s.output)?;
        animation = values.chunks_exact(targets.len().max(1)).map(<[f64]>::to_vec).collect();
    }
    Ok(GlbMorphs { base, faces, targets, names, animation })
}
