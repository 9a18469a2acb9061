//! `meshdeco export <model> --out F.glb|F.usda|F.html|F.h5`: glTF 2.0 with one morph target per
//! component, USD blend shapes, the standalone viewer page, or the SPLOCS reference's HDF5 layout.

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
    /// Output file, written atomically: .glb (binary glTF 2.0: morph targets, animation),
    /// .usda (USD text: UsdSkel blend shapes, the animation as a SkelAnimation; Y-up,
    /// metersPerUnit 1 = one data unit), .html (one self-contained viewer page: sliders, heat
    /// maps, the training frames; opens from disk, no server) or .h5 (a linear model in the
    /// SPLOCS reference's HDF5 layout: default, tris, comp000…, weights, verts).
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
    let ext = if ext == "hdf5" || ext == "htm" { &ext[..ext.len() - 1] } else { ext.as_str() };
    if !["glb", "usda", "html", "h5", "hdf"].contains(&ext) {
        bail!(
            "--out {}: name the file .glb (binary glTF 2.0), .usda (USD text), .html (standalone viewer page) or .h5 (SPLOCS's HDF5 layout)",
            a.out.display()
        );
    }
    if let Some(e) = meshdeco::export::gltf::fps_error(a.fps) {
        bail!(e);
    }
    if ext == "html" || ext == "h5" || ext == "hdf" {
        return page_or_hdf5(&a, ext == "html");
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

/// `--out view.html` (the standalone page) or `--out m.h5` (the SPLOCS layout). The glTF-only
/// flags are refused by name.
fn page_or_hdf5(a: &ExportArgs, html: bool) -> Result<()> {
    let gltf_only = [
        ("--animation", a.animation),
        ("--colors", a.colors),
        ("--bake", a.bake),
        ("--up", a.up != UpAxis::Auto),
        ("--fps", a.fps != 30.0),
    ];
    let mut refused: Vec<&str> = gltf_only.iter().filter(|(_, given)| *given).map(|(f, _)| *f).collect();
    if !html {
        let defaults = a.targets == "fitted" && a.fit_regularisation == meshdeco::export::gltf::FIT_REGULARISATION;
        if !defaults {
            refused.push("--targets/--fit-regularisation");
        }
    }
    if !refused.is_empty() {
        bail!(
            "{} {} to .glb and .usda exports, not to --out {}",
            refused.join(", "),
            if refused.len() == 1 { "applies" } else { "apply" },
            a.out.display()
        );
    }
    let model = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    if !html {
        let r = meshdeco::export::hdf5::export_splocs_h5(model.as_ref(), &a.out)?;
        outln!(
            "wrote {} ({} bytes): the SPLOCS reference's layout, default + tris + comp000…comp{:03} + weights ({} × {}) + verts ({} frames)",
            a.out.display(),
            r.bytes,
            r.components.saturating_sub(1),
            r.frames,
            r.components,
            r.frames
        );
        outln!(
            "default + weights × (comp − default) equals the model's decoding to {:.1e} of the diagonal",
            r.blend_error
        );
        return Ok(());
    }
    let opts = ExportOptions {
        targets: if a.targets == "extreme" { TargetFit::Extreme } else { TargetFit::Fitted },
        fit_regularisation: a.fit_regularisation,
        ..ExportOptions::default()
    };
    let r = meshdeco::view::standalone::export_html(
        model.as_ref(),
        &meshdeco::view::standalone::page_name(&a.model),
        &a.out,
        &opts,
    )?;
    outln!(
        "wrote {} ({} bytes): a standalone viewer page, {} blend targets ({}), {} training frames; open it in a browser (no server)",
        a.out.display(),
        r.bytes,
        r.targets,
        r.targets_kind,
        r.frames
    );
    let rel = r.quantisation_max / r.diagonal.max(f64::MIN_POSITIVE);
    outln!(
        "targets stored as {}: int16 error on the training frames{} largest {rel:.1e} of the diagonal",
        r.storage.name(),
        r.quantisation_erms.map(|q| format!(" Erms {q:.2e},")).unwrap_or_default()
    );
    match r.additivity_erms {
        Some(e) => outln!(
            "additivity error: Erms {e:.4} of the blended targets against the model's own decoding of its training frames (shown on the page)"
        ),
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
