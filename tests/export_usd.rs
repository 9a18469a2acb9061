//! `meshdeco export --out F.usda` as a user meets it: Pixar's usd-core opens the file and every
//! validator of its `pxr.UsdValidation` registry reports no error; the blend shapes are the
//! model's K components (a baked export: one per training frame), the animation holds one time
//! sample per training frame, the stage is Y-up with metres per unit stated, and the rest mesh
//! stands along Y.
//!
//! The validator runs in the Python named by `MESHDECO_USD_PYTHON` or in the virtual environment
//! `.ci/run` makes (`$CARGO_TARGET_DIR/tmp/usd-venv`, `pip install usd-core`). In CI (`CI` set)
//! its absence is a failure; locally the test says it skipped and why.

use std::path::PathBuf;
use std::process::Command;

mod common;
use common::{json_lines, meshdeco, output_text, train_cli};
use meshdeco::export::read_glb;

fn usd_python() -> Option<PathBuf> {
    common::python_with("MESHDECO_USD_PYTHON", "usd-venv", "pxr.UsdValidation")
}

/// Every list of 3-vectors that follows `key` on a line of a `.usda` text, in order.
fn usda_vec3s(text: &str, key: &str) -> Vec<Vec<[f64; 3]>> {
    text.lines()
        .filter_map(|l| l.split_once(key).map(|(_, v)| v))
        .map(|v| {
            let v = &v[..=v.rfind(']').unwrap_or_else(|| panic!("{key}{v}"))];
            let inner = v.strip_prefix("[(").and_then(|v| v.strip_suffix(")]")).unwrap_or_else(|| panic!("{key}{v}"));
            inner
                .split("), (")
                .map(|p| {
                    let c: Vec<f64> = p.split(", ").map(|x| x.parse::<f32>().unwrap() as f64).collect();
                    [c[0], c[1], c[2]]
                })
                .collect()
        })
        .collect()
}

const BUMPS: &str = "path = \"synthetic:bumps\"\ntrain = \"1-30\"\ntest = \"rest\"";

#[test]
fn usd_exports_pass_every_pxr_validator() {
    let d = common::fresh_dir("export-usd", "validate");
    let models = [
        ("splocs", "kind = \"splocs\"\ncomponents = 3", 3),
        ("ae", "kind = \"autoencoder\"\ncomponents = 3\niterations = 100\ncheckpoint_every = 100\nfit_test = false", 3),
    ];
    let mut files = Vec::new();
    for (name, method, k) in models {
        let dir = train_cli(&d, name, BUMPS, method);
        for (tag, extra) in [("anim", "--animation"), ("bake", "--bake")] {
            let f = d.join(format!("{name}-{tag}.usda"));
            let o = meshdeco(&["export", dir.to_str().unwrap(), "--out", f.to_str().unwrap(), extra], &d);
            assert!(o.status.success(), "{name} {tag}: {}", output_text(&o));
            let text = std::fs::read_to_string(&f).unwrap();
            assert!(
                text.starts_with("#usda 1.0") && text.contains("upAxis = \"Y\"") && text.contains("metersPerUnit = 1")
            );
            let shapes = if tag == "bake" { 30 } else { k };
            // The same numbers as the glTF export of the same model with the same options.
            let g = d.join(format!("{name}-{tag}.glb"));
            let o = meshdeco(&["export", dir.to_str().unwrap(), "--out", g.to_str().unwrap(), extra], &d);
            assert!(o.status.success(), "{name} {tag}: {}", output_text(&o));
            let g = read_glb(&g).unwrap();
            assert_eq!(usda_vec3s(&text, "point3f[] points = "), vec![g.base.clone()], "{name} {tag}: points");
            assert_eq!(usda_vec3s(&text, "uniform vector3f[] offsets = "), g.targets, "{name} {tag}: offsets");
            assert_eq!(usda_vec3s(&text, "uniform vector3f[] normalOffsets = "), g.target_normals, "{name} {tag}");
            assert_eq!(g.targets.len(), shapes);
            assert!(text.contains("startTimeCode = 0\n    endTimeCode = 29\n"), "{name} {tag}");
            assert!(text.contains("timeCodesPerSecond = 30.0\n    framesPerSecond = 30.0\n"), "{name} {tag}");
            let samples: Vec<Vec<f64>> = text
                .lines()
                .filter_map(|l| l.trim().split_once(": [").filter(|(t, _)| t.parse::<usize>().is_ok()))
                .map(|(_, v)| v.trim_end_matches("],").split(", ").map(|x| x.parse::<f32>().unwrap() as f64).collect())
                .collect();
            assert_eq!(samples, g.animation, "{name} {tag}: blendShapeWeights time samples");
            files.push((f, shapes));
        }
        // Without an animation: no time range, no SkelAnimation.
        let f = d.join(format!("{name}-still.usda"));
        let o = meshdeco(&["export", dir.to_str().unwrap(), "--out", f.to_str().unwrap()], &d);
        assert!(o.status.success(), "{name} still: {}", output_text(&o));
        let text = std::fs::read_to_string(&f).unwrap();
        assert!(!text.contains("TimeCode") && !text.contains("SkelAnimation") && !text.contains("animationSource"));
        // The bumps are closed: single-sided (`export_gltf.rs::open_meshes_export_double_sided`).
        assert!(text.contains("uniform bool doubleSided = false\n"), "{name} still");
        assert_eq!(usda_vec3s(&text, "uniform vector3f[] offsets = ").len(), k, "{name} still");
    }
    // A bad output name is refused and nothing is written.
    let o = meshdeco(&["export", d.join("splocs").to_str().unwrap(), "--out", "x.usdz"], &d);
    assert!(!o.status.success() && output_text(&o).contains(".usda"), "{}", output_text(&o));
    assert!(!d.join("x.usdz").exists());
    if let Some(py) = usd_python() {
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/validate_usd.py");
        let mut cmd = Command::new(py);
        cmd.arg(script).args(files.iter().map(|f| f.0.clone()));
        let o = cmd.output().unwrap();
        assert!(o.status.success(), "validate_usd.py: {}", output_text(&o));
        let lines = json_lines(&o);
        assert_eq!(lines.len(), files.len());
        for (r, (_, shapes)) in lines.iter().zip(&files) {
            println!("usd: {r}");
            assert!(r["validators"].as_u64().unwrap() > 10, "{r}");
            assert_eq!(r["errors"], serde_json::json!([]), "{r}");
            assert_eq!(r["blend_shapes"].as_u64(), Some(*shapes as u64), "{r}");
            assert_eq!(r["blend_shape_targets"].as_u64(), Some(*shapes as u64), "{r}");
            assert_eq!(r["time_samples"].as_u64(), Some(30), "{r}");
            assert_eq!((r["up_axis"].as_str(), r["tallest_axis"].as_str()), (Some("Y"), Some("Y")), "{r}");
            assert_eq!(r["meters_per_unit"].as_f64(), Some(1.0), "{r}");
        }
    }
    std::fs::remove_dir_all(&d).unwrap();
}
