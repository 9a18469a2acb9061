//! `meshdeco pose`: direct-manipulation posing of a trained model from vertex constraints.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::mesh::{self, TriMesh};
use meshdeco::model::{Constraints, PoseOptions, PosePrior, check_connectivity};
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
    #[command(flatten)]
    pub pose: PoseFlags,
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

/// The pose option flags of `pose` and `drag-bench`, as given (unset: the model kind's
/// default, [`meshdeco::model::Model::pose_defaults`]).
#[derive(Debug, Args)]
pub struct PoseFlags {
    /// γ: pull towards the start, dimensionless (in the whole shape's mean squared vertex motion,
    /// measured as --prior says), as strong wherever the pins are; also the autoencoder's.
    /// Smaller asks more of the model's components; larger leaves more to the landing
    /// correction. Default: the model kind's (PCA and SPLOCS 5, region PCA 0.03, the
    /// autoencoder 1; `Model::pose_defaults`).
    #[arg(long)]
    pub gamma: Option<f64>,
    /// β: boundary consistency between regions (region PCA only; squared vertex differences, as
    /// given). With few training shapes β = 1 couples the regions so strongly that a drag
    /// spreads like holistic PCA; the default 1e-3 keeps a one-pin drag the most local (docs/posing-drag-bench.md).
    #[arg(long)]
    pub beta: Option<f64>,
    /// Gauss-Newton iterations at most (autoencoder only; default 30).
    #[arg(long)]
    pub max_iterations: Option<usize>,
    /// What the pull towards the start measures: `shape` (the whole shape's change), `weights`
    /// (the paper's ‖w − w0‖²) or `data` (the weights measured by the training weights' spread;
    /// PCA and SPLOCS). Default: the model kind's (PCA and SPLOCS data, region PCA and the
    /// autoencoder weights).
    #[arg(long, value_parser = parse_prior)]
    pub prior: Option<PosePrior>,
    /// Landing correction radius, a fraction of the rest mesh's bounding-box diagonal (0: off;
    /// default 0.2). What the model's shape leaves between a pin and its target is added as a
    /// smooth displacement that fades to zero this far along the surface from every pin, so
    /// every pin lands even where the model's components cannot reach (the written weights are
    /// the model's; the mesh is the landed shape).
    #[arg(long)]
    pub spread: Option<f64>,
    /// The most any vertex of the model's shape may move, a multiple of the largest drag (0: no
    /// bound; default 1.3): a pose that moves farther is taken back towards the start, and the
    /// landing correction lands the pins.
    #[arg(long)]
    pub reach: Option<f64>,
    /// Keep the weights at the start: the shape is the start shape plus the landing correction
    /// alone (what the drag benchmark calls the null, whose row then equals the posed one; with
    /// --spread 0 nothing moves).
    #[arg(long)]
    pub freeze: bool,
}

impl PoseFlags {
    /// The pose options of `model`'s kind with these flags; checks every value, naming the flag.
    fn options(&self, model: &dyn meshdeco::model::Model) -> Result<PoseOptions> {
        let PoseFlags { gamma, beta, max_iterations, prior, spread, reach, freeze } = *self;
        let d = model.pose_defaults();
        for (flag, v) in [("--gamma", gamma), ("--beta", beta)] {
            if let Some(v) = v
                && !(v.is_finite() && v >= 0.0)
            {
                bail!("{flag} {v}: must be a finite number ≥ 0");
            }
        }
        if let Some(n) = max_iterations
            && !(1..=PoseOptions::MAX_ITERATIONS).contains(&n)
        {
            bail!("--max-iterations {n}: must be from 1 to {}", PoseOptions::MAX_ITERATIONS);
        }
        if let Some(x) = spread
            && !(x.is_finite() && (0.0..=PoseOptions::MAX_SPREAD).contains(&x))
        {
            bail!(
                "--spread {x}: must be from 0 (off) to {} (a fraction of the bounding-box diagonal)",
                PoseOptions::MAX_SPREAD
            );
        }
        if let Some(x) = reach
            && !(x.is_finite() && (x == 0.0 || x >= 1.0))
        {
            bail!("--reach {x}: must be 0 (no bound) or a number ≥ 1 (a multiple of the largest drag)");
        }
        let options = PoseOptions {
            gamma: gamma.unwrap_or(d.gamma),
            beta: beta.unwrap_or(d.beta),
            max_iterations: max_iterations.unwrap_or(d.max_iterations),
            prior: prior.unwrap_or(d.prior),
            time_limit: None,
            spread: spread.unwrap_or(d.spread),
            freeze,
            reach: reach.unwrap_or(d.reach),
        };
        options.validate()?;
        Ok(options)
    }
}

pub fn run(a: PoseArgs) -> Result<()> {
    if !(a.local_radius.is_finite() && a.local_radius > 0.0) {
        bail!("--local-radius {}: must be a positive fraction of the bounding-box diagonal", a.local_radius);
    }
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
            outln!("start: encoding of {}", p.display());
            Some(m.positions)
        }
        None => {
            outln!("start: {}", model.start_description());
            None
        }
    };
    let opts = a.pose.options(model.as_ref())?;
    let w0 = model.start_weights(from.as_deref())?;
    let Constraints { vertices, targets } = cons;
    check_targets(&rest, &vertices, &targets).with_context(|| format!("{}", a.constraints.display()))?;
    let t0 = Instant::now();
    let spreader = meshdeco::model::spreader(model.as_ref());
    let res = meshdeco::model::landed_pose(model.as_ref(), &spreader, &vertices, &targets, &w0, &opts).with_context(
        || {
            format!(
                "posing {} with the {} pins of {} (--spread {})",
                a.model.display(),
                vertices.len(),
                a.constraints.display(),
                opts.spread
            )
        },
    )?;
    let secs = t0.elapsed().as_secs_f64();
    if res.positions.iter().flatten().any(|x| !x.is_finite()) {
        bail!("posing {} produced non-finite coordinates; nothing written", a.model.display());
    }
    outln!("{} model, {} constraint(s), solved in {:.1} ms", model.kind().name(), vertices.len(), 1e3 * secs);
    if opts.spread > 0.0 {
        // The model's own shape is the decoding of its weights.
        let own = model.decode(std::slice::from_ref(&res.weights))?.remove(0);
        let most = res.positions.iter().zip(&own).map(|(p, q)| mesh::dist(*p, *q)).fold(0.0, f64::max);
        outln!(
            "landing correction (--spread {}): largest {most:.6} data units (what the model's components could not make)",
            opts.spread
        );
    }
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
        outln!("{line}");
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
    outln!("wrote {}", a.out.display());
    Ok(())
}

#[derive(Debug, Args)]
#[command(after_help = "Each drag starts from the model's neutral shape, picks PINS random vertices and moves each \
to its position in a random test frame (centroid-aligned for models that align so), poses with the pose \
defaults (or --gamma/--beta/--max-iterations) and measures: landing error (% of the drag), largest motion \
of any vertex ÷ the largest drag, the share of vertices moved more than half the mean drag (and the same \
share for the test frame itself), and the Erms of the posed and of the neutral shape against the frame. \
Every drag is also posed by the landing correction alone (the weights frozen at the start: the null), \
giving the null's Erms and posed ÷ null (below 1: the model's components help). Rows are medians over \
the drags, with the 90th percentile and maximum of the max motion ÷ drag and the shares of drags \
that beat the null and that improve on the neutral shape, each by more than 1 %. The last line \
(`row: | …`) is the README table's row.")]
pub struct DragBenchArgs {
    /// Model directory written by `meshdeco train` (or its model.json).
    pub model: PathBuf,
    /// Test frames (any path `meshdeco encode` accepts), with the model's connectivity.
    pub data: String,
    /// Only these frames of DATA (1-based, natural order, the config syntax: "37-71").
    #[arg(long)]
    pub frames: Option<String>,
    /// Drags per pin count.
    #[arg(long, default_value_t = 50)]
    pub drags: usize,
    /// Pin counts, comma-separated.
    #[arg(long, default_value = "1,3,10")]
    pub pins: String,
    /// Seed of the draws.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub pose: PoseFlags,
    /// Name of the model in the last line (`row: | NAME | …`, the README table's row; default: MODEL).
    #[arg(long)]
    pub label: Option<String>,
    /// Also write every drag and the medians as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn drag_bench(a: DragBenchArgs) -> Result<()> {
    use meshdeco::eval::drag::{DragBenchConfig, drag_bench};
    let model = load_model(&a.model).with_context(|| format!("loading model {}", a.model.display()))?;
    let seq = super::apply::load_frames_for_model(model.as_ref(), &a.data, a.frames.as_deref())?;
    check_connectivity(model.as_ref(), &seq, &a.data)?;
    let pins = a
        .pins
        .split(',')
        .map(|t| t.trim().parse::<usize>().map_err(|_| anyhow::anyhow!("--pins `{}`: `{t}` is not a count", a.pins)))
        .collect::<Result<Vec<_>>>()?;
    let options = a.pose.options(model.as_ref())?;
    let cfg = DragBenchConfig { drags: a.drags, pins, seed: a.seed, options };
    let (rows, summary) = drag_bench(model.as_ref(), &seq, &cfg)?;
    outln!(
        "{} model {}, {} test frames of {}; pose options γ {} β {} iterations {} prior {} spread {} reach {}{}",
        model.kind().name(),
        a.model.display(),
        seq.n_frames(),
        a.data,
        options.gamma,
        options.beta,
        options.max_iterations,
        options.prior.name(),
        options.spread,
        options.reach,
        if options.freeze { " freeze" } else { "" }
    );
    outln!(
        "| pins | drags | landing % of drag | max motion ÷ drag: median / p90 / max | moved > ½ drag | test frame's own | posed Erms | null Erms | neutral Erms | posed ÷ null | beats null | improved | pose ms |"
    );
    outln!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for s in &summary {
        let m = &s.medians;
        outln!(
            "| {} | {} | {:.3} | {:.2} / {:.2} / {:.2} | {:.1} % | {:.1} % | {:.3} | {:.3} | {:.3} | {:.3} | {:.0} % | {:.0} % | {:.1} |",
            s.pins,
            s.drags,
            m.landing_percent,
            m.max_motion_ratio,
            s.max_motion_p90,
            s.max_motion_max,
            100.0 * m.moved_share,
            100.0 * m.frame_moved_share,
            m.posed_erms,
            m.null_erms,
            m.neutral_erms,
            m.null_ratio,
            100.0 * s.beats_null_share,
            100.0 * s.improved_share,
            1e3 * m.seconds
        );
    }
    // One line for the README's table (scripts/drag-bench collects them): medians over the pin
    // counts, the one-pin tail, Erms posed / null / neutral, posed ÷ null and the share beating it.
    let join = |f: &dyn Fn(&meshdeco::eval::drag::DragSummary) -> String| {
        summary.iter().map(f).collect::<Vec<_>>().join(" / ")
    };
    let first = &summary[0];
    outln!(
        "row: | {} | {} | {} | {} ({} pin: p90 {:.2}, max {:.2}) | {} | {} vs null {} vs neutral {} | {} | {} |",
        a.label.as_deref().unwrap_or(&a.model.display().to_string()),
        join(&|s| s.pins.to_string()),
        join(&|s| format!("{:.2}", s.medians.landing_percent)),
        join(&|s| format!("{:.2}", s.medians.max_motion_ratio)),
        first.pins,
        first.max_motion_p90,
        first.max_motion_max,
        join(&|s| format!("{:.0} %", 100.0 * s.medians.moved_share)),
        join(&|s| format!("{:.1}", s.medians.posed_erms)),
        join(&|s| format!("{:.1}", s.medians.null_erms)),
        join(&|s| format!("{:.1}", s.medians.neutral_erms)),
        join(&|s| format!("{:.2}", s.medians.null_ratio)),
        join(&|s| format!("{:.0} %", 100.0 * s.beats_null_share)),
    );
    if let Some(p) = &a.json {
        let v = serde_json::json!({ "summary": summary, "drags": rows });
        meshdeco::artifact::write_atomic(p, serde_json::to_string_pretty(&v)?.as_bytes())?;
        outln!("every drag in {}", p.display());
    }
    Ok(())
}

fn parse_prior(s: &str) -> std::result::Result<PosePrior, String> {
    PosePrior::parse(s).ok_or_else(|| format!("`{s}`: expected shape, weights or data"))
}
