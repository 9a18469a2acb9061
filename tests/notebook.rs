//! `model.show()` in a notebook, run headless as a user's CI would: `jupyter nbconvert --execute
//! --to html` of `examples/notebooks/scape.ipynb` (trains SCAPE from arrays, shows the model,
//! poses, exports), then the saved HTML opened from `file://` in headless Chromium: the inline
//! page (an `<iframe srcdoc>`, no server) renders the mesh, and a slider dragged with real mouse
//! events moves it.
//!
//! Needs a Python with the meshdeco wheel, nbconvert and ipykernel (`$MESHDECO_PYTHON`, else the
//! venv `.ci/run` makes: `target/tmp/py-venv`) and Chromium; without them the test is skipped with
//! a printed reason, with `CI` set it fails.

mod common;
mod view_support;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{fresh_dir, output_text};
use view_support::cdp::Browser;
use view_support::{chromium_or_skip, num as f};

fn notebook_python() -> Option<PathBuf> {
    common::python_with("MESHDECO_PYTHON", "py-venv", "meshdeco, nbconvert, ipykernel")
}

#[test]
fn model_show_in_an_executed_notebook_renders_and_a_slider_moves_the_mesh() {
    let Some(py) = notebook_python() else { return };
    let Some(chromium) = chromium_or_skip() else { return };
    let d = fresh_dir("notebook", "scape");
    let nb = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/notebooks/scape.ipynb");
    let t0 = std::time::Instant::now();
    let o = Command::new(&py)
        .args(["-m", "jupyter", "nbconvert", "--to", "html", "--execute"])
        .arg(&nb)
        .args(["--output-dir", d.to_str().unwrap(), "--output", "scape", "--ExecutePreprocessor.timeout=600"])
        .env("MESHDECO_NOTEBOOK_OUT", d.join("out"))
        .output()
        .unwrap();
    assert!(o.status.success(), "nbconvert --execute: {}", output_text(&o));
    let html = d.join("scape.html");
    let text = std::fs::read_to_string(&html).unwrap();
    eprintln!(
        "nbconvert --execute in {:.1} s: {} bytes of HTML; exports: {:?}",
        t0.elapsed().as_secs_f64(),
        text.len(),
        std::fs::read_dir(d.join("out")).unwrap().map(|e| e.unwrap().file_name()).collect::<Vec<_>>()
    );
    assert!(text.contains("<iframe srcdoc=\""), "no inline page in the notebook's output");
    assert!(!text.contains("Traceback"), "a cell raised");
    for name in ["scape.glb", "scape-view.html", "scape.h5"] {
        assert!(d.join("out").join(name).is_file(), "the notebook did not export {name}");
    }

    let mut b = Browser::launch(&chromium, 1200, 900);
    b.navigate(&format!("file://{}", html.display()));
    let frame = "document.querySelector('iframe[title=\"meshdeco standalone viewer\"]')";
    b.wait_for(
        &format!("!!({frame} && {frame}.contentWindow.meshdeco && {frame}.contentWindow.meshdeco.ready())"),
        180,
    );
    let m = format!("{frame}.contentWindow.meshdeco");
    assert_eq!(b.eval(&format!("{m}.S.lastError")), "", "page error");
    // Bring the frame into view, then find a slider in page coordinates.
    b.eval(&format!("{frame}.scrollIntoView({{block: 'start'}})"));
    std::thread::sleep(std::time::Duration::from_millis(300));
    let fr = b.eval(&format!(
        "(() => {{ const r = {frame}.getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; }})()"
    ));
    let (fx, fy) = (f(&fr[0]), f(&fr[1]));

    // Renders: pixels at projected vertices inside the frame differ from its background.
    let img = b.screenshot();
    let bg = *img.get_pixel((fx + 3.0) as u32, (fy + 3.0) as u32);
    let pts = b.eval(&format!(
        "(() => {{ const w = {m}, out = []; for (let i = 0; i < w.S.n; i += Math.max(1, Math.floor(w.S.n / 300))) out.push(w.screenOf(w.vertex(i))); return out; }})()"
    ));
    let pts = pts.as_array().unwrap();
    let inked = pts
        .iter()
        .filter(|p| {
            let (x, y) = (fx + f(&p[0]), fy + f(&p[1]));
            x >= 0.0
                && y >= 0.0
                && (x as u32) < img.width()
                && (y as u32) < img.height()
                && *img.get_pixel(x as u32, y as u32) != bg
        })
        .count();
    assert!(inked * 100 >= 80 * pts.len(), "only {inked} of {} projected vertices drawn", pts.len());

    let k = 2;
    let sel = format!(".comp input[data-index=\"{k}\"]");
    let r = b.eval(&format!(
        "(() => {{ const r = {frame}.contentDocument.querySelector('{sel}').getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; }})()",
        sel = sel.replace('"', "\\\"")
    ));
    let (x0, y, w) = (fx + f(&r[0]), fy + f(&r[1]) + f(&r[3]) / 2.0, f(&r[2]));
    let before = view_support::page_positions(&mut b, &m);
    b.drag((x0 + 0.5 * w, y), (x0 + 0.9 * w, y), 8);
    view_support::settle(&mut b, &m);
    let dial = f(&b.eval(&format!("{m}.S.dials[{k}]")));
    let moved = view_support::max_diff(&before, &view_support::page_positions(&mut b, &m));
    eprintln!("slider {k} dragged to dial {dial}: the mesh moved by up to {moved:.3e}");
    assert!(dial != 0.0, "the slider did not move its dial");
    assert!(moved > 1e-3, "the mesh did not move ({moved})");
}
