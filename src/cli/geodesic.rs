//! `meshdeco geodesic <mesh> --source V --out dist.ply`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::geometry::heat_geodesics::{BoundaryCondition, HeatGeodesics, HeatOptions};
use meshdeco::mesh::{self, TriMesh};

#[derive(Debug, Args)]
pub struct GeodesicArgs {
    /// A mesh file (OBJ/PLY/OFF), or a sequence (directory, glob, synthetic:<name>) whose first
    /// frame is used.
    pub mesh: String,
    /// Source vertex (0-based); repeat or separate by commas for several sources.
    #[arg(long, short, required = true, value_delimiter = ',')]
    pub source: Vec<usize>,
    /// Output PLY: distances as vertex colours (viridis-like, 0 = dark) and as a `distance` column.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Heat-method time factor m (t = m·h², h = mean edge length). Crane et al. suggest 1;
    /// the SPLOCS reference uses 10.
    #[arg(long, default_value_t = 1.0)]
    pub m: f64,
    /// Use Neumann boundary conditions only (default: average of Neumann and Dirichlet).
    #[arg(long)]
    pub neumann: bool,
}

pub fn run(a: GeodesicArgs) -> Result<()> {
    let m = load_first_frame(&a.mesh)?;
    let n = m.n_vertices();
    if let Some(&bad) = a.source.iter().find(|&&s| s >= n) {
        bail!(
            "--source {bad} is out of range: {} has {n} vertices (0-based indices 0..{})",
            a.mesh,
            n.saturating_sub(1)
        );
    }
    let options = HeatOptions {
        m: a.m,
        boundary: if a.neumann { BoundaryCondition::Neumann } else { BoundaryCondition::Averaged },
        ..Default::default()
    };
    let solver = HeatGeodesics::with_options(&m.positions, &m.faces, options).context("setting up the heat method")?;
    let d = solver.distances(&a.source)?;
    let colors = mesh::colormap(&d);
    mesh::write_ply(&a.out, &m, Some(&colors), Some(("distance", &d)))?;
    let max = d.iter().cloned().fold(0.0, f64::max);
    outln!(
        "{}: {n} vertices, sources {:?}, max distance {max:.6} (data units), wrote {}",
        a.mesh,
        a.source,
        a.out.display()
    );
    Ok(())
}

/// A single mesh file, or the first frame of a sequence.
pub fn load_first_frame(spec: &str) -> Result<TriMesh> {
    let p = std::path::Path::new(spec);
    if p.is_file() {
        return Ok(mesh::load_mesh(p)?);
    }
    let seq = meshdeco::preprocess::load_frames(spec)?;
    Ok(seq.mesh(0))
}
