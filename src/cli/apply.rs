//! `meshdeco encode` and `meshdeco synthesize`: apply a trained model to new data.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::artifact;
use meshdeco::mesh::{self, TriMesh};
use meshdeco::pipeline::autoencoder::AeArtifact;
use meshdeco::pipeline::linear::LinearArtifact;
use meshdeco::representation::roundtrip::{Alignment, frame_squared_error};

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
    /// Autoencoder only: refine each encoder code by fitting the decoded shape to this many
    /// vertices (farthest-point spread; a number ≥ the vertex count uses every vertex) with
    /// Levenberg–Marquardt through the decoder, plus a global translation. About 0.25 s per
    /// SCAPE shape on 2 cores whatever the count; much closer on unseen shapes.
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
    /// indices; unlisted components get weight 0).
    #[arg(long, short, allow_hyphen_values = true)]
    pub weights: String,
    /// Output mesh (.obj, .ply or .off).
    #[arg(long, short)]
    pub out: PathBuf,
}

/// The `method` field of a model header.
pub fn model_method(model: &Path) -> Result<String> {
    let json = artifact::model_dir(model).join("model.json");
    let v: serde_json::Value = artifact::read_json(&json)?;
    v.get("method")
        .and_then(|m| m.as_str())
        .map(str::to_string)
        .with_context(|| format!("{}: no `method` field", json.display()))
}

/// Parses "i:w,j:v" into a dense weight vector of length k.
pub fn parse_weights(s: &str, k: usize) -> Result<Vec<f64>> {
    let mut w = vec![0.0; k];
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (i, v) = part.split_once(':').with_context(|| format!("--weights: `{part}` is not index:weight"))?;
        let i: usize =
            i.trim().parse().with_context(|| format!("--weights: `{i}` in `{part}` is not a component index"))?;
        let v: f64 = v.trim().parse().with_context(|| format!("--weights: `{v}` in `{part}` is not a number"))?;
        if i >= k {
            bail!("--weights: component {i} does not exist (the model has {k} components, 0..{})", k - 1);
        }
        if !v.is_finite() {
            bail!("--weights: weight of component {i} is {v}");
        }
        w[i] = v;
    }
    Ok(w)
}

pub fn write_mesh(path: &Path, m: &TriMesh) -> Result<()> {
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("ply") => mesh::write_ply(path, m, None, None)?,
        Some("off") => mesh::write_off(path, m)?,
        Some("obj") => mesh::write_obj(path, m)?,
        _ => bail!("{}: unknown output format (use .obj, .ply or .off)", path.display()),
    }
    Ok(())
}

pub fn encode(a: EncodeArgs) -> Result<()> {
    let method = model_method(&a.model)?;
    let mut seq = meshdeco::preprocess::load_frames(&a.path)?;
    if let Some(spec) = &a.frames {
        let sel =
            meshdeco::config::FrameSelection::parse("--frames", spec)?.resolve("--frames", seq.n_frames(), None)?;
        seq = seq.select(&sel);
    }
    match method.as_str() {
        "pca" | "splocs" => {
            let m = LinearArtifact::load(&a.model)?;
            if seq.n_vertices() != m.rest.n_vertices() || seq.faces != m.rest.faces {
                bail!(
                    "{}: connectivity differs from the model's rest mesh ({} vertices, {} faces vs {} and {})",
                    a.path,
                    seq.n_vertices(),
                    seq.n_faces(),
                    m.rest.n_vertices(),
                    m.rest.n_faces()
                );
            }
            let w = m.encode_frames(&seq)?;
            let k = m.model.n_components;
            std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
            let mut total = 0.0;
            let alignment = m.alignment();
            for (f, name) in seq.names.iter().enumerate() {
                let rec = m.synthesize(&w[f * k..(f + 1) * k])?;
                let se = frame_squared_error(&seq.frames[f], &rec, alignment)?;
                total += se;
                let erms = 1000.0 * (se / (3.0 * seq.n_vertices() as f64)).sqrt();
                println!("{name}: Erms {erms:.4}");
                mesh::write_obj(&a.out.join(format!("{name}.obj")), &TriMesh::new(rec, seq.faces.clone()))?;
            }
            artifact::write_weights_csv(&a.out.join("weights.csv"), &seq.names, &w, k)?;
            let erms = 1000.0 * (total / (3.0 * (seq.n_frames() * seq.n_vertices()) as f64)).sqrt();
            println!(
                "total Erms {erms:.4} over {} frames [alignment: {alignment}]; reconstructions and weights.csv in {}",
                seq.n_frames(),
                a.out.display()
            );
            Ok(())
        }
        "autoencoder" => {
            let m = AeArtifact::load(&a.model)?;
            if seq.n_vertices() != m.rest.n_vertices() || seq.faces != m.rest.faces {
                bail!("{}: connectivity differs from the model's rest mesh", a.path);
            }
            let (codes, rec, alignment) = match a.fit {
                None => {
                    let codes = m.encode_frames(&seq)?;
                    let rec = m.decode_codes(&codes)?;
                    (codes, rec, Alignment::Centroid)
                }
                Some(points) => {
                    let fitter = meshdeco::pipeline::ae_fit::AeFitEncoder::new(&m, points, a.fit_gamma)?;
                    println!("fitting codes to {} vertices per frame", fitter.vertices().len());
                    let (codes, rec) = fitter.fit_frames(&seq)?;
                    let raw = meshdeco::metrics::erms::erms(&seq.frames, &rec, Alignment::None)?;
                    println!("fitted reconstructions: Erms {raw:.4} without alignment (translation fitted too)");
                    (codes, rec, Alignment::Centroid)
                }
            };
            std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
            let per: Vec<f64> = seq
                .frames
                .iter()
                .zip(&rec)
                .map(|(t, r)| Ok(1000.0 * (frame_squared_error(t, r, alignment)? / (3.0 * t.len() as f64)).sqrt()))
                .collect::<meshdeco::Result<_>>()?;
            for ((name, e), r) in seq.names.iter().zip(&per).zip(&rec) {
                println!("{name}: Erms {e:.4}");
                mesh::write_obj(&a.out.join(format!("{name}.obj")), &TriMesh::new(r.clone(), seq.faces.clone()))?;
            }
            let k = m.header.components;
            let flat: Vec<f64> = codes.iter().flatten().copied().collect();
            artifact::write_weights_csv(&a.out.join("weights.csv"), &seq.names, &flat, k)?;
            let total = (per.iter().map(|e| e * e).sum::<f64>() / per.len().max(1) as f64).sqrt();
            println!(
                "total Erms {total:.4} over {} frames [alignment: {alignment}]; reconstructions and latent codes (weights.csv) in {}",
                seq.n_frames(),
                a.out.display()
            );
            Ok(())
        }
        other => bail!("encode: models of method `{other}` are not supported by this build"),
    }
}

pub fn synthesize(a: SynthesizeArgs) -> Result<()> {
    let method = model_method(&a.model)?;
    match method.as_str() {
        "pca" | "splocs" => {
            let m = LinearArtifact::load(&a.model)?;
            let w = parse_weights(&a.weights, m.model.n_components)?;
            let p = m.synthesize(&w)?;
            write_mesh(&a.out, &TriMesh::new(p, m.rest.faces.clone()))?;
            println!("wrote {}", a.out.display());
            Ok(())
        }
        "autoencoder" => {
            let m = AeArtifact::load(&a.model)?;
            let dense = parse_weights(&a.weights, m.header.components)?;
            let pairs: Vec<(usize, f64)> =
                dense.iter().enumerate().filter(|(_, w)| **w != 0.0).map(|(i, w)| (i, *w)).collect();
            let z = m.synthesis_code(&pairs)?;
            let p = m.decode_codes(&[z])?.remove(0);
            write_mesh(&a.out, &TriMesh::new(p, m.rest.faces.clone()))?;
            println!("wrote {} (z_i = Z_r,i + (Z_h,i − Z_r,i)·w_i)", a.out.display());
            Ok(())
        }
        other => bail!("synthesize: models of method `{other}` are not supported by this build"),
    }
}

#[derive(Debug, Args)]
pub struct ComponentsArgs {
    /// Autoencoder model directory written by `meshdeco train`.
    pub model: PathBuf,
    /// Output directory: `<rank>_<dim>.obj` extreme shapes, `<rank>_<dim>_change.ply` heat maps
    /// of per-vertex feature change, and `components.csv`.
    #[arg(long, short)]
    pub out: PathBuf,
}

#[derive(Debug, Args)]
pub struct InterpolateArgs {
    /// Autoencoder model directory written by `meshdeco train`.
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

pub fn components(a: ComponentsArgs) -> Result<()> {
    let method = model_method(&a.model)?;
    match method.as_str() {
        "autoencoder" => {
            let m = AeArtifact::load(&a.model)?;
            m.write_components(&a.out)?;
            println!(
                "wrote {} components (ranked by distance of the extreme shape) to {}",
                m.header.components,
                a.out.display()
            );
            Ok(())
        }
        "pca" | "splocs" => {
            let m = LinearArtifact::load(&a.model)?;
            meshdeco::pipeline::linear::write_components(&m, &a.out)?;
            println!("wrote {} components to {}", m.model.n_components, a.out.display());
            Ok(())
        }
        other => bail!("components: models of method `{other}` are not supported by this build"),
    }
}

pub fn interpolate(a: InterpolateArgs) -> Result<()> {
    if a.steps < 2 {
        bail!("--steps ({}) must be at least 2", a.steps);
    }
    let method = model_method(&a.model)?;
    if method != "autoencoder" {
        bail!("interpolate needs an autoencoder model; {} is `{method}`", a.model.display());
    }
    let m = AeArtifact::load(&a.model)?;
    let mut frames = Vec::new();
    for p in [&a.from, &a.to] {
        let mesh = mesh::load_mesh(p)?;
        if mesh.faces != m.rest.faces {
            bail!("{}: connectivity differs from the model's rest mesh", p.display());
        }
        frames.push(mesh.positions);
    }
    let seq =
        meshdeco::mesh::MeshSequence { faces: m.rest.faces.clone(), frames, names: vec!["from".into(), "to".into()] };
    let codes = m.encode_frames(&seq)?;
    let codes: Vec<Vec<f64>> = (0..a.steps)
        .map(|s| {
            let t = s as f64 / (a.steps - 1) as f64;
            codes[0].iter().zip(&codes[1]).map(|(x, y)| x + (y - x) * t).collect()
        })
        .collect();
    let meshes = m.decode_codes(&codes)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    for (i, p) in meshes.into_iter().enumerate() {
        mesh::write_obj(&a.out.join(format!("interp_{i:03}.obj")), &TriMesh::new(p, m.rest.faces.clone()))?;
    }
    println!("wrote {} meshes to {}", a.steps, a.out.display());
    Ok(())
}
