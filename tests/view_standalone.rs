//! The standalone viewer page (`meshdeco export <model> --out view.html`) opened from `file://`
//! in headless Chromium (WebGL2 through SwiftShader), driven with real mouse events, as a person
//! who received the file meets it: the mesh is drawn; a slider dragged with the mouse moves the
//! mesh, and the page's shape equals `meshdeco synthesize` with the same dial to ≤ 1e-4 of the
//! bounding-box diagonal (displacement models); the frames panel steps through the training
//! frames (dials equal to `weights.csv`); a component's heat map colours the mesh; and the page
//! makes no network request (the DevTools Network domain sees only the page's own file).
//!
//! On SCAPE SPLOCS K 50 (`configs/scape-splocs.toml`) and the 29k-vertex face region PCA
//! (`configs/face-poses-region.toml`) from ../shared, and on the synthetic tube (always). Without
//! Chromium the tests are skipped with a printed reason; with `CI` set they must run.

mod common;
mod view_support;

use std::path::Path;

use common::{fresh_dir, meshdeco, output_text, weights_csv};
use serde_json::json;
use view_support::cdp::Browser;
use view_support::{chromium_or_skip, num as f};

fn positions(b: &mut Browser) -> Vec<[f64; 3]> {
    view_support::page_positions(b, "meshdeco")
}

fn settle(b: &mut Browser) {
    view_support::settle(b, "meshdeco");
}

/// What the page check measured.
struct Checked {
    bytes: u64,
    slider_error: f64,
    diagonal: f64,
}

/// Exports `model` as a page, opens it from `file://` and checks it (module docs). `k`: the
/// component whose slider is dragged.
fn check_page(chromium: &Path, d: &Path, model: &Path, k: usize) -> Checked {
    let page = d.join("view.html");
    let o = meshdeco(&["export", model.to_str().unwrap(), "--out", page.to_str().unwrap()], d);
    assert!(o.status.success(), "{}", output_text(&o));
    let said = output_text(&o);
    assert!(said.contains("a standalone viewer page"), "{said}");
    let bytes = std::fs::metadata(&page).unwrap().len();

    let mut b = Browser::launch(chromium, 1200, 800);
    b.call("Network.enable", json!({}));
    let url = format!("file://{}", page.display());
    b.navigate(&url);
    b.wait_for("!!(window.meshdeco && (meshdeco.ready() || meshdeco.S.lastError))", 120);
    assert_eq!(b.eval("meshdeco.S.lastError"), "", "page error at start");
    assert!(b.eval("meshdeco.S.standalone !== null").as_bool().unwrap(), "the page knows it is standalone");
    let note = b.eval("document.getElementById('standalone').textContent");
    assert!(note.as_str().unwrap().contains("blend targets"), "{note}");
    assert_eq!(b.eval("getComputedStyle(document.getElementById('pose-box')).display"), "none", "no posing");

    // 1. Drawn: pixels at the projected centroids of sizeable triangles differ from the
    // background.
    let img = b.screenshot();
    let bg = *img.get_pixel(3, 3);
    let pts = b.eval(
        "(() => { const S = meshdeco.S, F = S.faces, out = [], step = Math.max(1, Math.floor(F.length / 3 / 4000)); \
         for (let t = 0; t < F.length / 3 && out.length < 200; t += step) { \
           const p = [0, 1, 2].map(j => meshdeco.screenOf(meshdeco.vertex(F[3 * t + j]))); \
           const area = Math.abs((p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0])) / 2; \
           if (area >= 4) out.push([(p[0][0] + p[1][0] + p[2][0]) / 3, (p[0][1] + p[1][1] + p[2][1]) / 3]); } \
         return out; })()",
    );
    let pts = pts.as_array().unwrap();
    assert!(pts.len() >= 20, "only {} sizeable triangles on screen", pts.len());
    let inked = pts.iter().filter(|p| *img.get_pixel(f(&p[0]) as u32, f(&p[1]) as u32) != bg).count();
    assert!(inked * 100 >= 95 * pts.len(), "only {inked} of {} triangle centroids drawn", pts.len());

    // 2. Slider k dragged with the mouse: the mesh moves, and equals `synthesize --weights k:w`.
    let before = positions(&mut b);
    let sel = format!(".comp input[data-index=\"{k}\"]");
    let r = b.eval(&format!(
        "(() => {{ const e = document.querySelector('{sel}'); e.scrollIntoView({{block: 'center'}}); const r = e.getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; }})()",
        sel = sel.replace('\'', "\\'")
    ));
    let (x0, y, w) = (f(&r[0]), f(&r[1]) + f(&r[3]) / 2.0, f(&r[2]));
    b.drag((x0 + 0.5 * w, y), (x0 + 0.9 * w, y), 10);
    settle(&mut b);
    let value = b.eval(&format!("document.querySelector('{}').value", sel.replace('\'', "\\'")));
    let value = value.as_str().unwrap().to_string();
    let dial: f64 = value.parse().unwrap();
    assert_eq!(f(&b.eval(&format!("meshdeco.S.dials[{k}]"))), dial, "the slider sets its dial");
    let page_shape = positions(&mut b);
    let moved = view_support::max_diff(&before, &page_shape);
    let o = meshdeco(
        &["synthesize", model.to_str().unwrap(), "--weights", &format!("{k}:{value}"), "--out", "slider.obj"],
        d,
    );
    assert!(o.status.success(), "{}", output_text(&o));
    let synth = common::obj_vertices(&d.join("slider.obj"));
    let slider_error = view_support::max_diff(&page_shape, &synth);
    let bbox = b.eval("meshdeco.S.desc.bbox");
    let (lo, hi) = (&bbox["min"], &bbox["max"]);
    let diagonal = (0..3).map(|c| (f(&hi[c]) - f(&lo[c])).powi(2)).sum::<f64>().sqrt();
    eprintln!(
        "{}: page {bytes} bytes; slider {k} at {value} moved the mesh by up to {moved:.3e}; |page − synthesize| {slider_error:.2e} = {:.2e} of the diagonal {diagonal:.4}",
        model.display(),
        slider_error / diagonal
    );
    assert!(moved > 1e-3 * diagonal, "slider {k} at {value} moved the mesh by only {moved}");
    assert!(slider_error <= 1e-4 * diagonal, "page differs from synthesize by {slider_error} (diagonal {diagonal})");

    // 3. A component's heat map: clicking its name colours the mesh.
    let name = b.centre(&format!(".comp[data-index=\"{k}\"] .name"));
    b.click(name.0, name.1);
    b.wait_for(&format!("meshdeco.S.heat.has({k}) && meshdeco.S.overlay === 'heat'"), 30);
    let heat_max = f(&b.eval(&format!("Math.max(...meshdeco.S.heat.get({k}))")));
    assert!(heat_max > 0.0, "heat map of {k} is empty");

    // 4. The frames panel: ▶ steps to the next training frame; its dials are its weights.csv row.
    let csv = weights_csv(model);
    let next = b.centre("#next");
    b.click(next.0, next.1);
    settle(&mut b);
    let shown = f(&b.eval("+document.getElementById('frame-i').value")) as usize;
    assert_eq!(shown, 2, "▶ from frame 1 shows frame 2");
    let dials: Vec<f64> = b.eval("Array.from(meshdeco.S.dials)").as_array().unwrap().iter().map(f).collect();
    for (i, (a, e)) in dials.iter().zip(&csv[1]).enumerate() {
        assert!((a - e).abs() <= 1e-12 * e.abs().max(1.0), "frame 2 dial {i}: page {a}, weights.csv {e}");
    }
    let info = b.eval("document.getElementById('frame-info').textContent");
    assert!(info.as_str().unwrap().contains("training weights"), "{info}");

    // 5. No network: the only request is the page's own file.
    b.eval("1");
    let requests: Vec<String> = b
        .events
        .iter()
        .filter(|e| e["method"] == "Network.requestWillBeSent")
        .map(|e| e["params"]["request"]["url"].as_str().unwrap_or("").to_string())
        .collect();
    assert_eq!(requests, vec![url.clone()], "requests other than the page itself");
    Checked { bytes, slider_error, diagonal }
}

#[test]
fn standalone_page_of_the_tube_draws_dials_steps_frames_offline() {
    let Some(chromium) = chromium_or_skip() else { return };
    let d = fresh_dir("standalone", "tube");
    let model = common::train_tube(&d, "tube-splocs", "kind = \"splocs\"\ncomponents = 6\nmax_iterations = 3");
    let c = check_page(&chromium, &d, &model, 1);
    assert!(c.slider_error <= 1e-4 * c.diagonal);
}

/// Trains the shipped `config` (its data in ../shared/`data`) and checks its page (dragging
/// slider `k`), which must stay under `max_bytes`.
fn shipped_config_page(config: &str, data: &str, k: usize, max_bytes: u64) {
    let Some(chromium) = chromium_or_skip() else { return };
    if common::shared_or_skip(data).is_none() {
        return;
    }
    let name = Path::new(config).file_stem().unwrap().to_str().unwrap();
    let d = fresh_dir("standalone", name);
    let model = d.join(name);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let o = meshdeco(&["train", "--config", config, "--out", model.to_str().unwrap()], root);
    assert!(o.status.success(), "{}", output_text(&o));
    let c = check_page(&chromium, &d, &model, k);
    eprintln!("{config}: view.html {} bytes", c.bytes);
    assert!(c.bytes < max_bytes, "{config}: the page is {} bytes", c.bytes);
}

#[test]
fn standalone_page_of_scape_splocs_k50() {
    shipped_config_page("configs/scape-splocs.toml", "data/scape", 3, 4_000_000);
}

#[test]
fn standalone_page_of_the_face_region_pca() {
    shipped_config_page("configs/face-poses-region.toml", "data/face-poses", 5, 12_000_000);
}

#[test]
fn standalone_page_refuses_gltf_flags_and_writes_nothing() {
    let d = fresh_dir("standalone", "flags");
    let model = common::train_tube(&d, "tube-pca", "kind = \"pca\"\ncomponents = 4");
    for (flag, out) in [("--animation", "v.html"), ("--bake", "v.html"), ("--colors", "m.h5")] {
        let o = meshdeco(&["export", model.to_str().unwrap(), "--out", out, flag], &d);
        assert_eq!(o.status.code(), Some(1), "{}", output_text(&o));
        let text = output_text(&o);
        assert!(text.contains(flag) && text.contains(out), "{text}");
        assert!(!d.join(out).exists(), "{out} written after a refused flag");
    }
}
