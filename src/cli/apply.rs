//! `meshdeco encode`, `synthesize`, `components` and `interpolate`: apply a trained model of
//! any method (through [`meshdeco::model::Model`]) to new data.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use meshdeco::artifact;
use meshdeco::mesh::{self, TriMesh};
use meshdeco::model::{self, RefineOptions};
use meshdeco::pipeline::load_model;

#[derive(Debug, Args)]
pub struct EncodeArgs {
    /// Model directory written by `meshdeco train` (or its model.json).
    pub model: PathBuf,
    /// Frames to encode: directory, glob, mesh file, or synthetic:<name>.
    pub path: String,
    /// Output directory for the reconstructions (OBJ per frame) and weights.csv.
    #[arg(long, short, default_value = "encoded")]
    pub out: PathBuf,
    /// Only these frames of `path` (1-based, natural order, the config syntax: "37-71",
    /// "every:10", "1-3,7").
    #[arg(long)]
    pub frames: Option<String>,
    /// Refine each code by fitting the decoded shape to this many vertices (farthest-point
    /// spread; a number ≥ the vertex count uses every vertex), where the model has a refinement
    /// (the autoencoder: Levenberg–Marquardt through the decoder, plus a global translation;
    /// about 0.25 s per SCAPE shape on 2 cores whatever the count; much closer on unseen
    /// shapes). Linear models already encode by least squares: the flag changes nothing there.
    #[arg(long, value_name = "POINTS")]
    pub fit: Option<usize>,
    /// With --fit: dimensionless pull towards the encoder's code.
    #[arg(long, default_value_t = meshdeco::pipeline::ae_fit::DEFAULT_FIT_GAMMA)]
    pub fit_gamma: f64,
}

#[derive(Debug, Args)]
pub struct SynthesizeArgs {
    /// Model directory written by `meshdeco train` (or its model.json).
    pub model: PathBuf,
    /// Component weights as `index:weight` pairs, e.g. "3:0.8,7:-1.2" (0-based component
    /// indices; unlisted components get weight 0). Autoencoder: z_i = Z_r,i + (Z_h,i − Z_r,i)·w_i.
    #[arg(long, short, allow_hyphen_values = true, required_unless_present = "weights_file")]
    pub weights: Option<String>,
    /// The same weights from a JSON file: `{"dials": [w0, w1, …]}` (all K) or `{"dials":
    /// {"3": 0.8}}` (unlisted: 0), as saved by `meshdeco view` ("weights .json").
    #[arg(long, value_name = "FILE", conflicts_with = "weights")]
    pub weights_file: Option<PathBuf>,
    /// Output mesh (.obj, .ply or .off).
    #[arg(long, short)]
    pub out: PathBuf,
}

#[derive(Debug, Args)]
pub struct ComponentsArgs {
    /// Model directory written by `meshdeco train`.
    pub model: PathBuf,
    /// Output directory: per component its shapes and heat map, and `components.csv` (ranked).
    /// Autoencoder: `<rank>_<dim>.obj` extreme shapes and `<rank>_<dim>_change.ply` heat maps of
    /// per-vertex feature change; linear and region models: `<name>_minus.obj`,
    /// `<name>_plus.obj` (weight −1 and +1) and `<name>_magnitude.ply`. Every model:
    /// `overview.png`, per ranked component its rest shape, extreme shape and heat map.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Side in pixels of one picture of overview.png.
    #[arg(long, default_value_t = 150)]
    pub cell: usize,
    /// Components per row of overview.png.
    #[arg(long, default_value_t = 4)]
    pub per_row: usize,
}

#[derive(Debug, Args)]
pub struct InterpolateArgs {
    /// Model directory written by `meshdeco train`.
    pub model: PathBuf,
    /// First shape (a mesh file with the model's connectivity).
    #[arg(long)]
    pub from: PathBuf,
    /// Second shape.
    #[arg(long)]
    pub to: PathBuf,
    /// Number of meshes written, including both ends (≥ 2).
    #[arg(long, default_value_t = 10)]
    pub steps: usize,
    /// Output directory (`interp_000.obj`, …).
    #[arg(long, short)]
    pub out: PathBuf,
}

/// The frames of `path` for `model` (a `.npy` takes the model's connectivity), only those of
/// `--frames` when given.
pub fn load_frames_for_model(
    model: &dyn meshdeco::model::Model,
    path: &str,
    frames: Option<&str>,
) -> Result<meshdeco::mesh::MeshSequence> {
    let mut seq = meshdeco::preprocess::load_frames_for(path, &model.rest())?;
    if let Some(spec) = frames {
        let sel =
            meshdeco::config::FrameSelection::parse("--frames", spec)?.resolve("--frames", seq.n_frames(), None)?;
        seq = seq.select(&sel);
    }
    Ok(seq)
}

pub fn encode(a: EncodeArgs) -> Result<()> {
    let m = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    let seq = load_frames_for_model(m.as_ref(), &a.path, a.frames.as_deref())?;
    if a.fit == Some(0) {
        anyhow::bail!("--fit 0: the number of vertices to fit must be at least 1");
    }
    if !(a.fit_gamma.is_finite() && a.fit_gamma >= 0.0) {
        anyhow::bail!("--fit-gamma {}: must be a finite number ≥ 0", a.fit_gamma);
    }
    let refine = a.fit.map(|points| RefineOptions { points, gamma: a.fit_gamma });
    if let Some(o) = &refine {
        outln!("fitting codes to min({}, {}) vertices per frame", o.points, seq.n_vertices());
    }
    let t = std::time::Instant::now();
    let e = model::encode_frames(m.as_ref(), &seq, &a.path, refine.as_ref())?;
    outln!(
        "encoded {} frames in {:.1} ms ({})",
        seq.n_frames(),
        t.elapsed().as_secs_f64() * 1e3,
        m.encoder_description()
    );
    if refine.is_some() && !e.refined {
        outln!("a {} model has no refined encoding: least-squares weights", m.kind().name());
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    for ((name, erms), rec) in seq.names.iter().zip(&e.frame_erms).zip(&e.reconstructions) {
        outln!("{name}: Erms {erms:.4}");
        mesh::write_obj(&a.out.join(format!("{name}.obj")), &TriMesh::new(rec.clone(), seq.faces.clone()))?;
    }
    let flat: Vec<f64> = e.weights.iter().flatten().copied().collect();
    artifact::write_weights_csv(&a.out.join("weights.csv"), &seq.names, &flat, m.n_components())?;
    outln!(
        "total Erms {:.4} over {} frames [alignment: {}]; reconstructions and weights.csv in {}",
        e.total_erms,
        seq.n_frames(),
        e.alignment,
        a.out.display()
    );
    Ok(())
}

pub fn synthesize(a: SynthesizeArgs) -> Result<()> {
    let m = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    let dials = match (&a.weights, &a.weights_file) {
        (Some(w), _) => model::parse_dials("--weights", w, m.n_components())?,
        (None, Some(f)) => {
            let text =
                std::fs::read_to_string(f).with_context(|| format!("--weights-file: reading {}", f.display()))?;
            model::parse_dials_json(&f.display().to_string(), &text, m.n_components())?
        }
        (None, None) => anyhow::bail!("give --weights or --weights-file"),
    };
    let p = model::synthesize(m.as_ref(), &dials)?;
    mesh::write_mesh(&a.out, &TriMesh::new(p, m.rest().faces))?;
    outln!("wrote {}", a.out.display());
    Ok(())
}

pub fn components(a: ComponentsArgs) -> Result<()> {
    let m = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    m.write_components(&a.out)?;
    let overview = a.out.join("overview.png");
    meshdeco::view::overview::write_overview(
        m.as_ref(),
        &overview,
        &meshdeco::view::overview::OverviewOptions { cell: a.cell, per_row: a.per_row },
    )
    .with_context(|| format!("--cell {} --per-row {}", a.cell, a.per_row))?;
    outln!("wrote {} components (ranked, components.csv, overview.png) to {}", m.n_components(), a.out.display());
    Ok(())
}

pub fn interpolate(a: InterpolateArgs) -> Result<()> {
    let m = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    let rest = m.rest();
    let mut ends = Vec::new();
    for p in [&a.from, &a.to] {
        let mesh = mesh::load_mesh(p)?;
        if mesh.faces != rest.faces {
            anyhow::bail!("{}: connectivity differs from the model's rest mesh", p.display());
        }
        ends.push(mesh.positions);
    }
    let meshes = model::interpolate(m.as_ref(), &ends[0], &ends[1], a.steps)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    for (i, p) in meshes.into_iter().enumerate() {
        mesh::write_obj(&a.out.join(format!("interp_{i:03}.obj")), &TriMesh::new(p, rest.faces.clone()))?;
    }
    outln!("wrote {} meshes to {}", a.steps, a.out.display());
    Ok(())
}
