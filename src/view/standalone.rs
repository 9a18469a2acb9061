//! The standalone page: `meshdeco export <model> --out view.html` and Python's `Model.show()`.
//! One self-contained HTML file — the live viewer's page (`web/index.html`, `web/app.js`) with
//! the model's blendshapes embedded and `web/embedded.js` answering the page's API routes inside
//! the page — that opens from disk with no server and makes no network request.
//!
//! - **What is embedded.** The blendshapes the glTF export writes ([`crate::export::gltf::prepare`]:
//!   the neutral shape and one target per component; for models whose decoding is not linear in
//!   the dials, the least-squares targets fitted to the model's own decoding of its training
//!   frames, with the additivity error shown on the page), in the data's own axes and units; the
//!   rest mesh; each component's heat map (`u16` relative to its peak); the segmentation; the
//!   training frames' dials to step through. The page blends `base + Σ_k dial_k·target_k`.
//! - **Targets' precision.** The error of `int16` targets (each with its own scale: its largest
//!   coordinate magnitude / 32767) is measured on the training frames: Erms of the quantised
//!   blend against the unquantised one. The targets are stored quantised only when that error is
//!   below the additivity error (a model whose blend only approximates it: the autoencoder,
//!   gradient SPLOCS), so quantising never shows more error than blending already does; a
//!   displacement model blends exactly (additivity error 0) and keeps `f32` targets. Both errors
//!   are reported and shown on the page.
//! - **Size.** The binary block is gzip'd (the targets of localized components are mostly zero)
//!   and base64'd into the page; the browser unpacks it with `DecompressionStream`.

use std::io::Write;
use std::path::Path;

use serde_json::{Value, json};

use crate::error::{Error, Result};
use crate::export::gltf::{ExportOptions, prepare};
use crate::math::mat3::{mat_vec, transpose};
use crate::mesh::Vec3;
use crate::model::Model;

/// How the targets are stored in the page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TargetStorage {
    Int16,
    Float32,
}

impl TargetStorage {
    pub fn name(self) -> &'static str {
        match self {
            TargetStorage::Int16 => "int16",
            TargetStorage::Float32 => "float32",
        }
    }
}

/// What [`page`] made.
#[derive(Debug, Clone, PartialEq)]
pub struct PageReport {
    /// Size of the page, bytes.
    pub bytes: usize,
    /// Blend targets (components).
    pub targets: usize,
    /// `fitted` (least squares over the training frames) or `extreme` (dial-1 shapes).
    pub targets_kind: &'static str,
    /// The blended targets' Erms against the model's own decoding of its training frames (the
    /// unit of train Erms), when the model stores their weights.
    pub additivity_erms: Option<f64>,
    pub storage: TargetStorage,
    /// Erms of the `int16` targets' blend against the unquantised blend over the training frames
    /// (whether or not they were chosen), when the model stores training weights.
    pub quantisation_erms: Option<f64>,
    /// Largest vertex distance between the `int16` and the unquantised blend over the training
    /// frames (without training weights: at dial 1 of each component), data units.
    pub quantisation_max: f64,
    /// The rest mesh's bounding-box diagonal, data units.
    pub diagonal: f64,
    /// Training frames whose dials the page steps through.
    pub frames: usize,
}

/// The standalone page of `model`, named `name` on the page; `options.targets` and
/// `options.fit_regularisation` choose the targets as for the glTF export (its other fields do
/// not apply).
pub fn page(model: &dyn Model, name: &str, options: &ExportOptions) -> Result<(String, PageReport)> {
    let opts = ExportOptions { animation: false, bake: false, colors: false, ..*options };
    let p = prepare(model, &opts)?;
    let rest = model.rest();
    let n = rest.n_vertices();
    let k = model.n_components();
    if p.shapes.index.len() != k {
        return Err(Error::Invalid(format!("{} blend targets for {k} components", p.shapes.index.len())));
    }
    // Back to the data's axes (the rotation is a signed permutation: exact).
    let back = transpose(&p.rotation);
    let unrotate = |v: &[Vec3]| -> Vec<Vec3> { v.iter().map(|&x| mat_vec(&back, x)).collect() };
    let base = unrotate(&p.shapes.base);
    let mut deltas = vec![Vec::new(); k];
    let mut heat = vec![Vec::new(); k];
    for (t, &i) in p.shapes.index.iter().enumerate() {
        deltas[i] = unrotate(&p.shapes.deltas[t]);
        heat[i] = p.shapes.magnitudes[t].clone();
    }
    let (lo, hi) = rest.bounding_box();
    let diagonal = crate::mesh::dist(lo, hi);
    let scales: Vec<f64> =
        deltas.iter().map(|d| d.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs())) / 32767.0).collect();
    let quantised: Vec<Vec<[i16; 3]>> = deltas
        .iter()
        .zip(&scales)
        .map(|(d, &s)| {
            d.iter()
                .map(|v| v.map(|x| if s > 0.0 { (x / s).round().clamp(-32767.0, 32767.0) as i16 } else { 0 }))
                .collect()
        })
        .collect();
    let dequantised: Vec<Vec<Vec3>> =
        quantised.iter().zip(&scales).map(|(q, &s)| q.iter().map(|v| v.map(|x| x as f64 * s)).collect()).collect();
    let training = p.training.as_ref();
    let frame_dials: Vec<Vec<f64>> = training.map(|t| t.dials.clone()).unwrap_or_default();
    let (quantisation_erms, quantisation_max) = if frame_dials.is_empty() {
        let max = deltas
            .iter()
            .zip(&dequantised)
            .flat_map(|(d, q)| d.iter().zip(q).map(|(a, b)| crate::mesh::dist(*a, *b)))
            .fold(0.0, f64::max);
        (None, max)
    } else {
        let exact: Vec<Vec<Vec3>> = frame_dials.iter().map(|d| crate::export::gltf::blend(&base, &deltas, d)).collect();
        let quant: Vec<Vec<Vec3>> =
            frame_dials.iter().map(|d| crate::export::gltf::blend(&base, &dequantised, d)).collect();
        let max = exact
            .iter()
            .zip(&quant)
            .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| crate::mesh::dist(*x, *y)))
            .fold(0.0, f64::max);
        let e = crate::metrics::erms::erms(&exact, &quant, crate::metrics::erms::Alignment::None)?;
        (Some(e), max)
    };
    let storage = match (quantisation_erms, p.additivity) {
        (Some(q), Some(a)) if q < a => TargetStorage::Int16,
        _ => TargetStorage::Float32,
    };
    let targets_kind = if p.fitted { "fitted" } else { "extreme" };

    // The binary block.
    let mut block = Block::default();
    block.put("faces", rest.faces.len() * 3, rest.faces.iter().flatten().flat_map(|&i| (i as u32).to_le_bytes()));
    block.put("rest", 3 * n, rest.positions.iter().flatten().flat_map(|&x| (x as f32).to_le_bytes()));
    block.put("base", 3 * n, base.iter().flatten().flat_map(|&x| (x as f32).to_le_bytes()));
    let description = super::describe_model(
        model,
        name,
        (!frame_dials.is_empty()).then_some(("training frames (their stored weights)", model.train_frames())),
    )?;
    block.put("segmentation", n, description.labels.iter().flat_map(|l| l.to_le_bytes()));
    match storage {
        TargetStorage::Int16 => {
            block.put("targets", 3 * n * k, quantised.iter().flatten().flatten().flat_map(|x| x.to_le_bytes()))
        }
        TargetStorage::Float32 => {
            block.put("targets", 3 * n * k, deltas.iter().flatten().flatten().flat_map(|&x| (x as f32).to_le_bytes()))
        }
    }
    let heat_q = heat.iter().flat_map(|h| {
        let peak = h.iter().cloned().fold(0.0f64, f64::max);
        h.iter().map(move |&m| if peak > 0.0 { (m / peak * 65535.0).round().clamp(0.0, 65535.0) as u16 } else { 0 })
    });
    block.put("heat", n * k, heat_q.flat_map(|x| x.to_le_bytes()));
    block.put("frame_dials", frame_dials.len() * k, frame_dials.iter().flatten().flat_map(|x| x.to_le_bytes()));
    let packed = gzip(&block.bytes)?;

    let additivity_text = match p.additivity {
        Some(a) if p.fitted => format!(
            "least-squares targets fitted to the model's own decoding of its {} training frames: additivity error Erms {a:.4} (blend against the model; the unit of train Erms)",
            frame_dials.len()
        ),
        Some(a) => {
            format!("the model's own shapes (additivity error Erms {a:.2e}: a displacement model blends exactly)")
        }
        None => "dial-1 targets (the model stores no training weights: additivity not measured)".to_string(),
    };
    let note = format!(
        "Standalone page (meshdeco export): {k} blend targets, {additivity_text}; targets stored as {}{}. Posing and the frames' own shapes need the live viewer: meshdeco view MODEL.",
        storage.name(),
        match quantisation_erms {
            Some(q) => format!(
                " (int16 targets would err by Erms {q:.2e} on the training frames, at most {:.1e} of the diagonal: quantised only below the additivity error)",
                quantisation_max / diagonal.max(f64::MIN_POSITIVE)
            ),
            None => String::new(),
        }
    );
    let mut desc = description.json;
    let start_dials = desc["start"]["dials"].clone();
    desc["start"]["weights"] = start_dials;
    desc["pose_parameters"] = json!([]);
    desc["standalone"] = json!({
        "note": note,
        "targets": targets_kind,
        "storage": storage.name(),
        "additivity_erms": p.additivity,
        "quantisation_erms": quantisation_erms,
        "quantisation_max": quantisation_max,
        "diagonal": diagonal,
    });
    let embedded = json!({
        "desc": desc,
        "layout": block.layout,
        "targets": storage.name(),
        "scales": if storage == TargetStorage::Int16 { json!(scales) } else { Value::Null },
        "blob": base64(&packed),
    });
    let html = assemble(&embedded)?;
    let report = PageReport {
        bytes: html.len(),
        targets: k,
        targets_kind,
        additivity_erms: p.additivity,
        storage,
        quantisation_erms,
        quantisation_max,
        diagonal,
        frames: frame_dials.len(),
    };
    Ok((html, report))
}

/// The name a page shows for the model at `model_path` (a directory, or its `model.json`).
pub fn page_name(model_path: &Path) -> String {
    super::model_name(&crate::artifact::model_dir(model_path))
}

/// Writes [`page`] of `model`, titled `name`, to `path`, atomically.
pub fn export_html(model: &dyn Model, name: &str, path: &Path, options: &ExportOptions) -> Result<PageReport> {
    let (html, report) = page(model, name, options)?;
    crate::artifact::write_atomic(path, html.as_bytes())?;
    Ok(report)
}

/// The page: the live viewer's `index.html` with the data and both scripts inline.
fn assemble(embedded: &Value) -> Result<String> {
    const SCRIPT_TAG: &str = r#"<script type="module" src="/app.js"></script>"#;
    if !super::INDEX_HTML.contains(SCRIPT_TAG) {
        return Err(Error::Invalid("the viewer page has no app.js script tag to inline".into()));
    }
    for (what, js) in [("app.js", super::APP_JS), ("embedded.js", super::EMBEDDED_JS)] {
        if js.contains("</script") || js.contains("<!--") {
            return Err(Error::Invalid(format!("{what} cannot be inlined: it contains `</script` or `<!--`")));
        }
    }
    // JSON inside a script element: `<` escaped, so no name can close the element.
    let data = embedded.to_string().replace('<', "\\u003c");
    let scripts = format!(
        "<script type=\"application/json\" id=\"meshdeco-embedded\">{data}</script>\n<script>\n{}</script>\n<script type=\"module\">\n{}</script>",
        super::EMBEDDED_JS,
        super::APP_JS
    );
    Ok(super::INDEX_HTML.replacen(SCRIPT_TAG, &scripts, 1))
}

/// Arrays appended 8-byte aligned, with their (byte offset, element count).
#[derive(Default)]
struct Block {
    bytes: Vec<u8>,
    layout: serde_json::Map<String, Value>,
}

impl Block {
    fn put(&mut self, name: &str, count: usize, bytes: impl IntoIterator<Item = u8>) {
        while !self.bytes.len().is_multiple_of(8) {
            self.bytes.push(0);
        }
        self.layout.insert(name.into(), json!([self.bytes.len(), count]));
        self.bytes.extend(bytes);
    }
}

fn gzip(bytes: &[u8]) -> Result<Vec<u8>> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    e.write_all(bytes).and_then(|_| e.finish()).map_err(|e| Error::Invalid(format!("compressing the page's data: {e}")))
}

/// Standard base64 with padding.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let v = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for j in 0..4 {
            if j <= c.len() {
                out.push(A[(v >> (18 - 6 * j) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_the_standard_alphabet_and_padding() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
        assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
    }

    #[test]
    fn a_name_cannot_close_the_data_element() {
        let html = assemble(&json!({ "desc": { "model": "</script><script>alert(1)</script>" } })).unwrap();
        let data = html.split("id=\"meshdeco-embedded\">").nth(1).unwrap().split("</script>").next().unwrap();
        assert!(data.contains("\\u003c/script>"), "{data}");
        assert_eq!(html.matches("<script").count(), 3, "only the page's three script elements");
    }
}
