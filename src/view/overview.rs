//! The components overview picture (`meshdeco components` writes it as `overview.png`): per
//! ranked component, the rest shape, the component's extreme shape and its heat map on the rest
//! shape, side by side, rendered by the software rasterizer ([`crate::mesh::render`]) with the
//! automatic up axis and one framing for every picture — the figure every paper shows.
//!
//! The extreme of a component is its dial (the `meshdeco synthesize --weights` value, other
//! dials 0) of largest magnitude over the training weights (the autoencoder: up to its extreme
//! code z_h at dial 1); ±1 when the model stores no training weights.

use std::path::Path;

use crate::error::{Error, Result};
use crate::mesh::TriMesh;
use crate::mesh::render::{RenderOptions, View, render};
use crate::model::{Model, ranked, synthesize};

/// Layout of the overview.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OverviewOptions {
    /// Side of one picture in pixels.
    pub cell: usize,
    /// Components per row.
    pub per_row: usize,
}

impl Default for OverviewOptions {
    fn default() -> Self {
        OverviewOptions { cell: 150, per_row: 4 }
    }
}

const LABEL: usize = 20;
const GAP: usize = 12;

/// Per component (index order) the training dial of largest magnitude (`None` without
/// training weights).
pub fn extreme_dials(model: &dyn Model) -> Result<Vec<Option<f64>>> {
    let k = model.n_components();
    let mut best: Vec<Option<f64>> = vec![None; k];
    if let Some(ws) = model.train_weights() {
        for w in &ws {
            let d = model.dials(w)?;
            for i in 0..k {
                if d[i].is_finite() && best[i].is_none_or(|b| d[i].abs() > b.abs()) {
                    best[i] = Some(d[i]);
                }
            }
        }
    }
    Ok(best)
}

/// The overview as an RGB image (width, height, bytes) and the components' names in rank order.
pub fn overview(model: &dyn Model, opts: &OverviewOptions) -> Result<(usize, usize, Vec<u8>, Vec<String>)> {
    if !(32..=2048).contains(&opts.cell) || opts.per_row == 0 {
        return Err(Error::Invalid(format!(
            "overview: cell {} px (32..=2048), {} per row (≥ 1)",
            opts.cell, opts.per_row
        )));
    }
    let rest = model.rest();
    let k = model.n_components();
    let comps = ranked(model)?;
    let extremes = extreme_dials(model)?;
    // Shapes first, so that one box frames them all.
    let mut shapes = Vec::with_capacity(comps.len());
    for c in &comps {
        let mut d = vec![0.0; k];
        d[c.index] = match extremes[c.index] {
            Some(x) if x != 0.0 => x,
            _ => 1.0,
        };
        let p = synthesize(model, &d)?;
        if p.iter().flatten().any(|x| !x.is_finite()) {
            return Err(Error::Numerical(format!("component {} decodes to non-finite positions", c.name)));
        }
        shapes.push((d[c.index], p));
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in std::iter::once(&rest.positions).chain(shapes.iter().map(|s| &s.1)) {
        let (a, b) = crate::mesh::bounding_box(p);
        for j in 0..3 {
            lo[j] = lo[j].min(a[j]);
            hi[j] = hi[j].max(b[j]);
        }
    }
    let view = View::auto(&rest);
    let cell = opts.cell;
    let ropts = RenderOptions { width: cell, height: cell, view, bounds: Some((lo, hi)), ..Default::default() };
    let block_w = 3 * cell + GAP;
    let block_h = cell + LABEL + GAP / 2;
    let cols = opts.per_row.min(comps.len().max(1));
    let rows = comps.len().div_ceil(cols).max(1);
    let (w, h) = (cols * block_w + GAP, rows * block_h + GAP);
    let mut img = vec![255u8; w * h * 3];
    let rest_pic = render(&rest, None, &ropts)?;
    let mut names = Vec::with_capacity(comps.len());
    for (i, (c, (dial, shape))) in comps.iter().zip(&shapes).enumerate() {
        let (bx, by) = (GAP + (i % cols) * block_w, GAP / 2 + (i / cols) * block_h + LABEL);
        let extreme = render(&TriMesh::new(shape.clone(), rest.faces.clone()), None, &ropts)?;
        let colours = crate::mesh::colormap(&c.magnitudes);
        let heat = render(&rest, Some(&colours), &ropts)?;
        for (j, pic) in [&rest_pic, &extreme, &heat].into_iter().enumerate() {
            blit(&mut img, w, pic, cell, bx + j * cell, by);
        }
        names.push(format!("#{} {} (dial {dial:.3})", c.rank, c.name));
    }
    label(&mut img, w, h, &names, cols, block_w, block_h);
    Ok((w, h, img, names))
}

fn blit(img: &mut [u8], w: usize, pic: &[u8], cell: usize, x0: usize, y0: usize) {
    for y in 0..cell {
        let src = &pic[3 * y * cell..3 * (y + 1) * cell];
        let o = 3 * ((y0 + y) * w + x0);
        img[o..o + 3 * cell].copy_from_slice(src);
    }
}

/// Draws each block's name above it (skipped, with no error, when no font is found).
fn label(img: &mut [u8], w: usize, h: usize, names: &[String], cols: usize, block_w: usize, block_h: usize) {
    use plotters::prelude::*;
    static FONT: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ready = *FONT.get_or_init(|| {
        crate::eval::plots::font_path()
            .and_then(|p| std::fs::read(p).ok())
            .map(|bytes| {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                plotters::style::register_font("meshdeco-overview", FontStyle::Normal, bytes).is_ok()
            })
            .unwrap_or(false)
    });
    if !ready {
        return;
    }
    let root = BitMapBackend::with_buffer(img, (w as u32, h as u32)).into_drawing_area();
    let style = ("meshdeco-overview", 14).into_font().color(&BLACK);
    for (i, n) in names.iter().enumerate() {
        let (x, y) = (GAP + (i % cols) * block_w, GAP / 2 + (i / cols) * block_h + 2);
        let _ = root.draw(&Text::new(n.clone(), (x as i32, y as i32), style.clone()));
    }
    let _ = root.present();
}

/// Writes the overview as a PNG (atomically).
pub fn write_overview(model: &dyn Model, path: &Path, opts: &OverviewOptions) -> Result<()> {
    let (w, h, rgb, _) = overview(model, opts)?;
    let img = image::RgbImage::from_raw(w as u32, h as u32, rgb)
        .ok_or_else(|| Error::Invalid("overview: image buffer size".into()))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageOutputFormat::Png)
        .map_err(|e| Error::Invalid(format!("encoding {}: {e}", path.display())))?;
    crate::artifact::write_atomic(path, &png)
}
