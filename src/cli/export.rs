//! `meshdeco export <model> --out F.glb`: glTF 2.0 with one morph target per component.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::export::{ExportOptions, TargetFit, UpAxis, export_glb};
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
    /// Output file, written atomically: .glb (binary glTF 2.0: morph targets, animation) or
    /// .usda (USD text: UsdSkel blend shapes, the animation as a SkelAnimation; Y-up,
    /// metersPerUnit 1 = one data unit).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Add the training frames' weights as a glTF animation of the morph weights (one key per
    /// frame), so the training sequence replays in any glTF viewer.
    #[arg(long)]
    pub animation: bool,
    /// Frames per second of --animation (0.01 to 1000).
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Add vertex colours (COLOR_0): each vertex in the colour of the component that dominates
    /// it, darkened by that component's relative magnitude.
    #[arg(long)]
    pub colors: bool,
    /// The data axis that points up in the file (glTF is Y-up): auto (the longest bounding-box
    /// axis, as `meshdeco render --view auto`), x, y, z, -x, -y or -z. The shape is rotated.
    #[arg(long, default_value = "auto", value_parser = parse_up, allow_hyphen_values = true)]
    pub up: UpAxis,
    /// Morph targets of models whose decoding is not linear in the dials (the autoencoder, SPLOCS
    /// on triangle gradients or ACAP): `fitted` (least squares over the training frames,
    /// regularised towards the dial-1 shapes) or `extreme` (the dial-1 shapes).
    #[arg(long, default_value = "fitted", value_parser = ["fitted", "extreme"])]
    pub targets: String,
    /// Regularisation of the fitted targets towards the dial-1 shapes, relative to the mean
    /// squared training dial (> 0; larger: closer to the dial-1 shapes).
    #[arg(long, default_value_t = meshdeco::export::gltf::FIT_REGULARISATION)]
    pub fit_regularisation: f64,
    /// One morph target per training frame (its decoding) keyed in turn at weight 1: exact
    /// playback of the training frames instead of dials (implies --animation).
    #[arg(long)]
    pub bake: bool,
}

fn parse_up(s: &str) -> std::result::Result<UpAxis, String> {
    UpAxis::parse(s).ok_or_else(|| format!("`{s}`: expected auto, x, y, z, -x, -y or -z"))
}

pub fn run(a: ExportArgs) -> Result<()> {
    let ext = a.out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    if ext != "glb" && ext != "usda" {
        bail!("--out {}: name the file .glb (binary glTF 2.0) or .usda (USD text)", a.out.display());
    }
    if let Some(e) = meshdeco::export::gltf::fps_error(a.fps) {
        bail!(e);
    }
    let model = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    let opts = ExportOptions {
        animation: a.animation,
        fps: a.fps,
        colors: a.colors,
        up: a.up,
        targets: if a.targets == "extreme" { TargetFit::Extreme } else { TargetFit::Fitted },
        fit_regularisation: a.fit_regularisation,
        bake: a.bake,
    };
    let r = if ext == "usda" {
        meshdeco::export::export_usda(model.as_ref(), &a.out, &opts)?
    } else {
        export_glb(model.as_ref(), &a.out, &opts)?
    };
    outln!(
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
    outln!("up axis: data {} is the file's +Y", r.up_axis);
    let train_erms = train_erms(&a.model);
    match r.additivity_erms {
        Some(e) => {
            let how = if a.bake {
                "baked frames".to_string()
            } else if r.targets_fitted {
                format!(
                    "targets fitted to the training frames; the dial-1 shapes' would be {:.4}",
                    r.additivity_extreme_erms.unwrap_or(f64::NAN)
                )
            } else {
                "dial-1 targets".to_string()
            };
            outln!(
                "additivity error: Erms {e:.4} (the unit of train/test Erms) of the blended targets against the model's own decoding of its {} training frames ({how})",
                model.train_frames().len()
            );
            if let Some(t) = train_erms
                && e > t
            {
                eprintln!(
                    "warning: the blendshapes miss the model's own shapes by Erms {e:.4}, more than the model's train Erms {t:.4}: \
                     dialled or animated in another tool they will not look like the model; --bake keys the training frames exactly"
                );
            }
        }
        None => outln!("additivity error: not measured (the model stores no training weights)"),
    }
    Ok(())
}

/// The model's train Erms from its `metrics.json` (verified with the artefact on load), if any.
fn train_erms(model: &std::path::Path) -> Option<f64> {
    let dir = meshdeco::artifact::model_dir(model);
    let v: serde_json::Value = meshdeco::artifact::read_json(&dir.join("metrics.json")).ok()?;
    v.get("train_erms")?.as_f64().filter(|x| x.is_finite())
}
