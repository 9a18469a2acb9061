//! `meshdeco export <model> --out F.glb`: glTF 2.0 with one morph target per component.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::export::{ExportOptions, export_glb};
use meshdeco::pipeline::load_model;

#[derive(Debug, Args)]
#[command(after_help = "The base mesh is the model's neutral shape (all weights 0: the rest shape for SPLOCS, the \
training mean for PCA, the region means for region PCA, the reference shape for the autoencoder). Target k is the \
shape at weight 1 of component k (the autoencoder: its extreme) minus the base, ranked as `meshdeco components` \
ranks them, named \"r<rank> k<index> v<centre vertex>\" in mesh.extras.targetNames. For models whose decoding is \
not linear in the weights (SPLOCS on triangle gradients or ACAP, the autoencoder) the additivity error is printed \
and stored in asset.extras: Erms between the model's decoding of its training frames and the blended targets.")]
pub struct ExportArgs {
    /// Model directory written by `meshdeco train` (or its model.json).
    pub model: PathBuf,
    /// Output file (.glb, binary glTF 2.0), written atomically.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Add the training frames' weights as a glTF animation of the morph weights (one key per
    /// frame), so the training sequence replays in any glTF viewer.
    #[arg(long)]
    pub animation: bool,
    /// Frames per second of --animation (> 0).
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Add vertex colours (COLOR_0): each vertex in the colour of the component that dominates
    /// it, darkened by that component's relative magnitude.
    #[arg(long)]
    pub colors: bool,
}

pub fn run(a: ExportArgs) -> Result<()> {
    if !a.out.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("glb")) {
        bail!("--out {}: the export writes binary glTF; name the file .glb", a.out.display());
    }
    if !(a.fps.is_finite() && a.fps > 0.0) {
        bail!("--fps {}: must be a positive number", a.fps);
    }
    let model = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    let opts = ExportOptions { animation: a.animation, fps: a.fps, colors: a.colors };
    let r = export_glb(model.as_ref(), &a.out, &opts)?;
    println!(
        "wrote {} ({} bytes): {} morph targets{}",
        a.out.display(),
        r.bytes,
        r.targets,
        if r.animation_frames > 0 {
            format!(", an animation of {} frames at {} fps", r.animation_frames, a.fps)
        } else {
            String::new()
        }
    );
    match r.additivity_erms {
        Some(e) => println!(
            "additivity error (Erms of blended targets vs the model's own decoding of the {} training frames): {e:.4}",
            model.train_frames().len()
        ),
        None => println!("additivity error: not measured (the model stores no training weights)"),
    }
    Ok(())
}
