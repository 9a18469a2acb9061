//! `meshdeco plant`: a data set with known answers — localized deformations planted on a mesh
//! and mixed sparsely into frames, their true fields written beside them
//! (`meshdeco::eval::planted`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::eval::planted::{MirrorChoice, PlantConfig, plant, write};

#[derive(Debug, Args)]
pub struct PlantArgs {
    /// The mesh to plant the deformations on (.obj, .ply, .off): its shape is the rest shape.
    pub mesh: PathBuf,
    /// Output directory (written all at once): frames.npy, template.obj, fields.npy,
    /// weights.csv, truth.json, eval.toml, overview.png.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Number of planted deformations D (1 ..= 500).
    #[arg(long, default_value_t = 40)]
    pub deformations: usize,
    /// Training frames (frames 1 ..= T of frames.npy).
    #[arg(long, default_value_t = 200)]
    pub train: usize,
    /// Test frames (after the training frames).
    #[arg(long, default_value_t = 100)]
    pub test: usize,
    /// Gaussian noise per coordinate, as a fraction of the bounding-box diagonal (0 ..= 0.1).
    #[arg(long, default_value_t = 1e-4)]
    pub noise: f64,
    /// Most deformations active in one frame (each frame has 1 ..= this many).
    #[arg(long, default_value_t = 4)]
    pub max_active: usize,
    /// MIN,MAX radius of a deformation's disc, as fractions of the bounding-box diagonal.
    #[arg(long, default_value = "0.08,0.3")]
    pub radius: String,
    /// Decimate the mesh to at most this many vertices first (quadric edge collapse).
    #[arg(long)]
    pub vertices: Option<usize>,
    /// Mirror plane of left/right pairs: auto (found when the mesh is symmetric), none, x, y, z.
    #[arg(long, default_value = "auto")]
    pub mirror: String,
    /// Seed of the centres, kinds, sizes, weights and noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

pub fn run(a: PlantArgs) -> Result<()> {
    let radius = a
        .radius
        .split_once(',')
        .and_then(|(l, h)| Some([l.trim().parse::<f64>().ok()?, h.trim().parse::<f64>().ok()?]))
        .with_context(|| format!("--radius: `{}` is not MIN,MAX (e.g. 0.08,0.3)", a.radius))?;
    let mirror = match a.mirror.as_str() {
        "auto" => MirrorChoice::Auto,
        "none" => MirrorChoice::None,
        "x" => MirrorChoice::Axis(0),
        "y" => MirrorChoice::Axis(1),
        "z" => MirrorChoice::Axis(2),
        m => bail!("--mirror: `{m}` is not one of auto, none, x, y, z"),
    };
    let cfg = PlantConfig {
        deformations: a.deformations,
        train: a.train,
        test: a.test,
        noise: a.noise,
        max_active: a.max_active,
        radius,
        vertices: a.vertices,
        mirror,
        seed: a.seed,
    };
    cfg.validate()?;
    let mesh = meshdeco::mesh::load_mesh(&a.mesh)?;
    let source = a.mesh.display().to_string();
    let set = plant(&mesh, &source, &cfg)?;
    write(&set, &a.out)?;
    let t = &set.truth;
    let by_kind = |k: &str| t.deformations.iter().filter(|d| format!("{:?}", d.kind).to_lowercase() == k).count();
    outln!(
        "wrote {} : {} frames ({} train, {} test) of {} vertices ({} before decimation), {} deformations ({} pulls, {} hinges, {} stretches; {} in mirrored pairs), {} identifiable",
        a.out.display(),
        t.train + t.test,
        t.train,
        t.test,
        t.n_vertices,
        t.source_vertices,
        t.deformations.len(),
        by_kind("pull"),
        by_kind("hinge"),
        by_kind("stretch"),
        t.deformations.iter().filter(|d| d.partner.is_some()).count(),
        t.identifiable
    );
    outln!(
        "noise σ {:.3e} ({} of the diagonal {:.4}); test Erms of the rest shape {:.3}, of the least-squares oracle on the true fields {:.3}",
        t.noise_sigma,
        t.noise,
        t.diagonal,
        t.rest_test_erms,
        t.oracle_test_erms
    );
    outln!("evaluate every method on it: meshdeco eval --config {}", a.out.join("eval.toml").display());
    Ok(())
}
