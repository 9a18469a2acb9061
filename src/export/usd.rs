//! USD text (`.usda`) export of a trained model: the neutral mesh, one UsdSkel `BlendShape` per
//! morph target (the same targets, names, orientation and fitting as the glTF export,
//! [`super::gltf::Blendshapes`]), and, with `animation` or `bake`, the training frames' weights
//! as a `SkelAnimation`'s `blendShapeWeights` time samples (one per frame, time code = frame
//! index, `timeCodesPerSecond` = fps).
//!
//! Layer metadata: `upAxis = "Y"` (the shape is rotated as the glTF export rotates it),
//! `metersPerUnit = 1` (meshdeco keeps the data's units and does not know them: one data unit is
//! written as one metre), `defaultPrim`, and the time range. Structure:
//!
//! ```text
//! /Model (SkelRoot, SkelBindingAPI: skel:skeleton = </Model/Skel>)
//!   /Model/Skel (Skeleton, no joints, skel:animationSource = </Model/Skel/Anim>)
//!     /Model/Skel/Anim (SkelAnimation: blendShapes, blendShapeWeights.timeSamples)
//!   /Model/Mesh (Mesh, SkelBindingAPI: skel:blendShapes, skel:blendShapeTargets)
//!     /Model/Mesh/<target> (BlendShape: offsets, normalOffsets)
//! ```
//!
//! Numbers are written with Rust's shortest round-trip form of the `f32` values (USD's `point3f`,
//! `vector3f`, `float`), so a reader gets back exactly the values glTF would hold.

use std::fmt::Write as _;
use std::path::Path;

use super::gltf::{ExportOptions, ExportReport, prepare};
use crate::error::Result;
use crate::mesh::Vec3;
use crate::model::Model;

/// A USD identifier from a target name (`r0 k3 v12` → `r0_k3_v12`; a leading digit gets `_`).
fn identifier(name: &str, used: &mut std::collections::BTreeSet<String>) -> String {
    let mut id: String = name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    if id.is_empty() || id.starts_with(|c: char| c.is_ascii_digit()) {
        id.insert(0, '_');
    }
    let base = id.clone();
    let mut n = 1;
    while !used.insert(id.clone()) {
        n += 1;
        id = format!("{base}_{n}");
    }
    id
}

fn vec3_list(out: &mut String, points: &[Vec3]) {
    out.push('[');
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        let _ = write!(out, "({:?}, {:?}, {:?})", p[0] as f32, p[1] as f32, p[2] as f32);
    }
    out.push(']');
}

fn float_list(out: &mut String, values: &[f64]) {
    out.push('[');
    for (i, v) in values.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        let _ = write!(out, "{:?}", *v as f32);
    }
    out.push(']');
}

/// Writes `model` as a `.usda` at `path`, atomically (see the module docs).
pub fn export_usda(model: &dyn Model, path: &Path, options: &ExportOptions) -> Result<ExportReport> {
    let p = prepare(model, options)?;
    let rest = model.rest();
    let n_targets = p.shapes.deltas.len();
    let mut used = std::collections::BTreeSet::new();
    let ids: Vec<String> = p.shapes.names.iter().map(|n| identifier(n, &mut used)).collect();
    let keys = p.keyed_weights(options)?;
    let fps = options.fps;
    let mut s = String::new();
    s.push_str("#usda 1.0\n(\n    defaultPrim = \"Model\"\n    metersPerUnit = 1\n    upAxis = \"Y\"\n");
    if !keys.is_empty() {
        let _ = writeln!(s, "    startTimeCode = 0\n    endTimeCode = {}", keys.len() - 1);
        let _ = writeln!(s, "    timeCodesPerSecond = {fps:?}\n    framesPerSecond = {fps:?}");
    }
    let _ = writeln!(
        s,
        "    doc = \"meshdeco {} export: {} model, {} representation; data axis {} is +Y; {} blend shapes ({}); additivity Erms {}\"\n)\n",
        env!("CARGO_PKG_VERSION"),
        model.kind().name(),
        model.representation().name(),
        p.up_axis,
        n_targets,
        p.targets_kind(options),
        p.additivity.map_or("not measured".to_string(), |e| format!("{e:.6}"))
    );
    s.push_str("def SkelRoot \"Model\" (\n    prepend apiSchemas = [\"SkelBindingAPI\"]\n)\n{\n");
    s.push_str("    rel skel:skeleton = </Model/Skel>\n\n");
    s.push_str("    def Skeleton \"Skel\" (\n        prepend apiSchemas = [\"SkelBindingAPI\"]\n    )\n    {\n");
    s.push_str("        uniform token[] joints = []\n        uniform matrix4d[] bindTransforms = []\n        uniform matrix4d[] restTransforms = []\n");
    if !keys.is_empty() {
        s.push_str("        rel skel:animationSource = </Model/Skel/Anim>\n\n");
        s.push_str("        def SkelAnimation \"Anim\"\n        {\n            uniform token[] blendShapes = [");
        s.push_str(&ids.iter().map(|i| format!("\"{i}\"")).collect::<Vec<_>>().join(", "));
        s.push_str("]\n            float[] blendShapeWeights.timeSamples = {\n");
        for (t, w) in keys.iter().enumerate() {
            let _ = write!(s, "                {t}: ");
            float_list(&mut s, w);
            s.push_str(",\n");
        }
        s.push_str("            }\n        }\n");
    }
    s.push_str("    }\n\n");
    s.push_str("    def Mesh \"Mesh\" (\n        prepend apiSchemas = [\"SkelBindingAPI\"]\n    )\n    {\n");
    let _ = writeln!(s, "        int[] faceVertexCounts = [{}]", vec!["3"; rest.n_faces()].join(", "));
    s.push_str("        int[] faceVertexIndices = [");
    s.push_str(&rest.faces.iter().flatten().map(|i| i.to_string()).collect::<Vec<_>>().join(", "));
    s.push_str("]\n        point3f[] points = ");
    vec3_list(&mut s, &p.shapes.base);
    s.push_str("\n        normal3f[] normals = ");
    vec3_list(&mut s, &p.base_normals);
    s.push_str(" (\n            interpolation = \"vertex\"\n        )\n");
    s.push_str(
        "        uniform token orientation = \"rightHanded\"\n        uniform token subdivisionScheme = \"none\"\n",
    );
    let _ = writeln!(s, "        uniform bool doubleSided = {}", p.open);
    s.push_str("        uniform token[] skel:blendShapes = [");
    s.push_str(&ids.iter().map(|i| format!("\"{i}\"")).collect::<Vec<_>>().join(", "));
    s.push_str("]\n        rel skel:blendShapeTargets = [");
    s.push_str(&ids.iter().map(|i| format!("</Model/Mesh/{i}>")).collect::<Vec<_>>().join(", "));
    s.push_str("]\n        rel skel:skeleton = </Model/Skel>\n");
    for (t, id) in ids.iter().enumerate() {
        let _ = write!(s, "\n        def BlendShape \"{id}\"\n        {{\n            uniform vector3f[] offsets = ");
        vec3_list(&mut s, &p.shapes.deltas[t]);
        s.push_str("\n            uniform vector3f[] normalOffsets = ");
        vec3_list(&mut s, &p.target_normals[t]);
        s.push_str("\n        }\n");
    }
    s.push_str("    }\n}\n");
    crate::artifact::write_atomic(path, s.as_bytes())?;
    Ok(p.report(s.len(), keys.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Identifiers keep ASCII letters and digits, turn everything else into `_`, never start
    /// with a digit or come out empty, and are made unique with `_2`, `_3`, … in order.
    #[test]
    fn identifiers_are_valid_and_unique() {
        let mut used = std::collections::BTreeSet::new();
        let ids: Vec<String> =
            ["r0 k3 v12", "3 arms", "", "a-b", "a_b", "a-b", "é"].iter().map(|n| identifier(n, &mut used)).collect();
        assert_eq!(ids, ["r0_k3_v12", "_3_arms", "_", "a_b", "a_b_2", "a_b_3", "__2"]);
    }

    /// Lists are bracketed, comma-separated and hold the shortest round-trip form of each
    /// value's `f32`.
    #[test]
    fn lists_hold_the_single_precision_values() {
        let mut s = String::new();
        vec3_list(&mut s, &[[1.0, -2.5, 0.1], [0.0, 1e-3, 3.0]]);
        assert_eq!(s, "[(1.0, -2.5, 0.1), (0.0, 0.001, 3.0)]");
        s.clear();
        vec3_list(&mut s, &[]);
        assert_eq!(s, "[]");
        s.clear();
        float_list(&mut s, &[0.5, 1.0 / 3.0, -7.0]);
        assert_eq!(s, "[0.5, 0.33333334, -7.0]");
        s.clear();
        float_list(&mut s, &[2.0]);
        assert_eq!(s, "[2.0]");
    }
}
