//! `meshdeco pose`: direct-manipulation posing of a trained model from vertex constraints.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::mesh::{self, TriMesh};
use meshdeco::model::{Constraints, PoseOptions, check_connectivity};
use meshdeco::pipeline::load_model;
use meshdeco::pipeline::pose::{ball, check_targets, displacement_share};

#[derive(Debug, Args)]
#[command(after_help = "CONSTRAINTS FILE: a JSON object mapping 0-based vertex indices (as strings) to target \
positions in data units, e.g. {\"123\": [0.1, -0.02, 0.35], \"4071\": [0.0, 0.2, 0.3]}, or the \
viewer's spelling: [{\"vertex\": 123, \"target\": [0.1, -0.02, 0.35]}, ...].

START: without --from, linear models start from all weights 0 (their offset: the training mean for \
PCA, the rest shape for SPLOCS), region PCA from all coefficients 0 (the region means), the \
autoencoder from the code of its rest mesh.

MODELS: pca and splocs on displacements (Lewis-Anjyo, Tena et al. Eq. 8, honouring non-negative \
weights), region-pca (Eq. 9/10), autoencoder (Gauss-Newton on the latent code through the decoder \
and the ACAP reconstruction). Linear models on triangle gradients are refused.")]
pub struct PoseArgs {
    /// Model directory written by `meshdeco train` (or its model.json).
    pub model: PathBuf,
    /// Constraints: JSON object {"vertex index": [x, y, z], ...} (data units).
    #[arg(long, short)]
    pub constraints: PathBuf,
    /// Start pose: a mesh file (OBJ/PLY/OFF, the model's connectivity) whose encoding gives the
    /// start weights (default: see START below).
    #[arg(long)]
    pub from: Option<PathBuf>,
    /// Output mesh (.obj, .ply or .off), written atomically; a .ply is coloured by the distance
    /// each vertex moved (scalar property `displacement`).
    #[arg(long, short)]
    pub out: PathBuf,
    /// γ: pull towards the start weights, dimensionless (Eq. 8/10 regulariser, scaled by the
    /// mean squared response of one weight at the constrained vertices; also the autoencoder's).
    #[arg(long, default_value_t = PoseOptions::default().gamma)]
    pub gamma: f64,
    /// β: boundary consistency between regions (region PCA only; squared vertex differences, as
    /// given). With few training shapes β = 1 couples the regions so strongly that a drag
    /// spreads like holistic PCA; on face-poses β = 1e-6 keeps 99.7 % of the energy in the
    /// dragged vertex's region.
    #[arg(long, default_value_t = PoseOptions::default().beta)]
    pub beta: f64,
    /// Gauss-Newton iterations at most (autoencoder only).
    #[arg(long, default_value_t = PoseOptions::default().max_iterations)]
    pub max_iterations: usize,
    /// Radius (fraction of the rest mesh's bounding-box diagonal) of the ball around each
    /// constrained vertex in which the reported displacement-energy share is measured.
    #[arg(long, default_value_t = 0.2)]
    pub local_radius: f64,
}

/// Reads a constraints file (either spelling of [`Constraints::from_json`]).
pub fn read_constraints(path: &Path, n_vertices: usize) -> Result<Constraints> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(Constraints::from_json_text(&path.display().to_string(), &text, n_vertices)?)
}

/// Checks the numeric flags, naming the flag and the value.
fn check_flags(a: &PoseArgs) -> Result<()> {
    for (flag, v) in [("--gamma", a.gamma), ("--beta", a.beta)] {
        if !(v.is_finite() && v >= 0.0) {
            bail!("{flag} {v}: must be a finite number ≥ 0");
        }
    }
    if !(a.local_radius.is_finite() && a.local_radius > 0.0) {
        bail!("--local-radius {}: must be a positive fraction of the bounding-box diagonal", a.local_radius);
    }
    if !(1..=PoseOptions::MAX_ITERATIONS).contains(&a.max_iterations) {
        bail!("--max-iterations {}: must be from 1 to {}", a.max_iterations, PoseOptions::MAX_ITERATIONS);
    }
    Ok(())
}

pub fn run(a: PoseArgs) -> Result<()> {
    check_flags(&a)?;
    let model = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    let rest = model.rest();
    let n = rest.n_vertices();
    let cons = read_constraints(&a.constraints, n)?;
    let from = match &a.from {
        Some(p) => {
            let m = mesh::load_mesh(p)?;
            let seq = meshdeco::mesh::MeshSequence {
                faces: m.faces.clone(),
                frames: vec![m.positions.clone()],
                names: vec![p.display().to_string()],
            };
            check_connectivity(model.as_ref(), &seq, &p.display().to_string())?;
            println!("start: encoding of {}", p.display());
            Some(m.positions)
        }
        None => {
            println!("start: {}", model.start_description());
            None
        }
    };
    let opts = PoseOptions { gamma: a.gamma, beta: a.beta, max_iterations: a.max_iterations };
    opts.validate()?;
    let w0 = model.start_weights(from.as_deref())?;
    let Constraints { vertices, targets } = cons;
    check_targets(&rest, &vertices, &targets).with_context(|| format!("{}", a.constraints.display()))?;
    let t0 = Instant::now();
    let res = model.pose(&vertices, &targets, &w0, &opts)?;
    let secs = t0.elapsed().as_secs_f64();
    if res.positions.iter().flatten().any(|x| !x.is_finite()) {
        bail!("posing {} produced non-finite coordinates; nothing written", a.model.display());
    }
    println!("{} model, {} constraint(s), solved in {:.1} ms", model.kind().name(), vertices.len(), 1e3 * secs);
    let (lo, hi) = rest.bounding_box();
    let diag = mesh::dist(lo, hi);
    for (&v, t) in vertices.iter().zip(&targets) {
        let drag = mesh::dist(res.start[v], *t);
        let err = mesh::dist(res.positions[v], *t);
        let rel =
            if drag > 0.0 { format!(" ({:.2}% of the drag {drag:.4})", 100.0 * err / drag) } else { String::new() };
        let ball_set = ball(&rest.positions, v, a.local_radius * diag);
        let mut line = format!(
            "vertex {v}: distance to target {err:.6}{rel}; displacement energy within {:.0}% of the diagonal: {:.3}",
            100.0 * a.local_radius,
            displacement_share(&res.start, &res.positions, &ball_set)
        );
        if let Some((name, set)) = model.locality_set(v) {
            line += &format!(", in {name}: {:.3}", displacement_share(&res.start, &res.positions, &set));
        }
        println!("{line}");
    }
    let is_ply = a.out.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if is_ply {
        // Coloured by the distance each vertex moved (scalar `displacement`, data units).
        let moved: Vec<f64> = res.start.iter().zip(&res.positions).map(|(p, q)| mesh::dist(*p, *q)).collect();
        let colors = mesh::colormap(&moved);
        mesh::write_ply(
            &a.out,
            &TriMesh::new(res.positions, rest.faces.clone()),
            Some(&colors),
            Some(("displacement", &moved)),
        )?;
    } else {
        mesh::write_mesh(&a.out, &TriMesh::new(res.positions, rest.faces.clone()))?;
    }
    println!("wrote {}", a.out.display());
    Ok(())
}
