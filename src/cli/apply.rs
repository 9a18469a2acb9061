//! `meshdeco encode` and `meshdeco synthesize`: apply a trained model to new data.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::artifact;
use meshdeco::mesh::{self, TriMesh};
use meshdeco::pipeline::linear::LinearArtifact;
use meshdeco::representation::roundtrip::frame_squared_error;

#[derive(Debug, Args)]
pub struct EncodeArgs {
    /// Model directory written by `meshdeco train` (or its model.json).
    pub model: PathBuf,
    /// Frames to encode: directory, glob, mesh file, or synthetic:<name>.
    pub path: String,
    /// Output directory for the reconstructions (OBJ per frame) and weights.csv.
    #[arg(long, short, default_value = "encoded")]
    pub out: PathBuf,
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
    v.get("method").and_then(|m| m.as_str()).map(str::to_string).with_context(|| format!("{}: no `method` field", json.display()))
}

/// Parses "i:w,j:v" into a dense weight vector of length k.
pub fn parse_weights(s: &str, k: usize) -> Result<Vec<f64>> {
    let mut w = vec![0.0; k];
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (i, v) = part.split_once(':').with_context(|| format!("--weights: `{part}` is not index:weight"))?;
        let i: usize = i.trim().parse().with_context(|| format!("--weights: `{i}` in `{part}` is not a component index"))?;
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
    let seq = meshdeco::preprocess::load_frames(&a.path)?;
    match method.as_str() {
        "pca" | "splocs" => {
            let m = LinearArtifact::load(&a.model)?;
            if seq.n_vertices() != m.rest.n_vertices() || seq.faces != m.rest.faces {
                bail!("{}: connectivity differs from the model's rest mesh ({} vertices, {} faces vs {} and {})", a.path, seq.n_vertices(), seq.n_faces(), m.rest.n_vertices(), m.rest.n_faces());
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
            println!("total Erms {erms:.4} over {} frames [alignment: {alignment}]; reconstructions and weights.csv in {}", seq.n_frames(), a.out.display());
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
        other => bail!("synthesize: models of method `{other}` are not supported by this build"),
    }
}
