//! `meshdeco render`: a PNG picture of a mesh (software rasterizer, vertex colours of a PLY).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::mesh::{self, render};

#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Mesh file (.obj, .ply, .off); an ASCII PLY's red/green/blue vertex colours are used.
    pub mesh: PathBuf,
    /// Output PNG, written atomically.
    #[arg(long, short)]
    pub out: PathBuf,
    /// View direction: auto (the up axis is the bounding box's longest, the camera looks along
    /// its shortest, so a body lying along z stands up and a face looks at you), front (from
    /// +z, y up), side (from +x, y up), top (from +y).
    #[arg(long, default_value = "auto")]
    pub view: String,
    /// Image size WxH in pixels.
    #[arg(long, default_value = "800x800")]
    pub size: String,
}

pub fn run(a: RenderArgs) -> Result<()> {
    let m = mesh::load_mesh(&a.mesh)?;
    let view = match a.view.as_str() {
        "auto" => render::View::auto(&m),
        v => render::View::parse(v).with_context(|| format!("--view: `{v}` is not one of auto, front, side, top"))?,
    };
    let (w, h) = a
        .size
        .split_once(['x', 'X'])
        .and_then(|(w, h)| Some((w.trim().parse::<usize>().ok()?, h.trim().parse::<usize>().ok()?)))
        .with_context(|| format!("--size: `{}` is not WxH (e.g. 800x600)", a.size))?;
    let is_ply = a.mesh.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    let colors = if is_ply { render::vertex_colors_from_ply(&a.mesh)? } else { None };
    let opts = render::RenderOptions { width: w, height: h, view, ..Default::default() };
    let rgb = render::render(&m, colors.as_deref(), &opts)?;
    let img = image::RgbImage::from_raw(w as u32, h as u32, rgb).context("image buffer size")?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageOutputFormat::Png)
        .with_context(|| format!("encoding {}", a.out.display()))?;
    if !a.out.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
        bail!("{}: output must be a .png file", a.out.display());
    }
    meshdeco::artifact::write_atomic(&a.out, &png)?;
    outln!(
        "wrote {} ({w}×{h}, {} view, {})",
        a.out.display(),
        a.view,
        if colors.is_some() { "vertex colours" } else { "grey" }
    );
    Ok(())
}
