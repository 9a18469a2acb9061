//! `meshdeco generate`: a large NumPy sequence blended from a small one, for benchmarks and
//! tests of big datasets (`synthetic::Blend`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::pipeline::Progress;

use super::progress::Bars;

#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// Source frames: a mesh directory, a glob (`dir/*.obj`), or `synthetic:<name>`.
    pub from: String,
    /// Number of frames to write (1 ..= 10 000 000).
    #[arg(long)]
    pub frames: usize,
    /// Output `.npy` (F × N × 3, float32, C order).
    #[arg(long)]
    pub out: PathBuf,
    /// Template mesh (the source's first frame) written for `data.template`; default: OUT with
    /// the extension `.obj`.
    #[arg(long)]
    pub template: Option<PathBuf>,
    /// Seed of the blend weights and perturbations (frame f depends only on seed and f).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

pub fn run(a: GenerateArgs) -> Result<()> {
    if !a.out.to_string_lossy().to_ascii_lowercase().ends_with(".npy") {
        bail!("--out {}: the output is a NumPy .npy file; name it *.npy", a.out.display());
    }
    let template = a.template.clone().unwrap_or_else(|| a.out.with_extension("obj"));
    if template == a.out {
        bail!("--template {}: must differ from --out", template.display());
    }
    let source = meshdeco::preprocess::load_frames(&a.from).with_context(|| format!("reading {}", a.from))?;
    let mut bars = Bars::new();
    bars.stage("generate", a.frames as u64);
    meshdeco::synthetic::write_blend_npy(&source, a.frames, a.seed, &a.out, &mut |done| {
        bars.step(done as u64, "frames written")
    })?;
    bars.finish_stage();
    let rest = meshdeco::mesh::TriMesh::new(source.frames[0].clone(), source.faces.clone());
    meshdeco::mesh::write_obj(&template, &rest)?;
    let bytes = std::fs::metadata(&a.out).map(|m| m.len()).unwrap_or(0);
    outln!(
        "wrote {} ({} frames × {} vertices, float32, {:.1} MB) and {} (the template: data.template)",
        a.out.display(),
        a.frames,
        rest.n_vertices(),
        bytes as f64 / 1e6,
        template.display()
    );
    Ok(())
}
