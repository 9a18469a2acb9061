//! Command-line definitions (clap) and dispatch. Each command lives in its own file and turns
//! its arguments into library calls.

use anyhow::Result;
use clap::{Parser, Subcommand};

#[macro_use]
pub mod out;

mod apply;
mod eval;
mod export;
mod features;
mod generate;
mod geodesic;
mod inspect;
mod plant;
mod pose;
mod progress;
mod render;
mod train;
mod view;

/// Sparse, localized deformation components from meshes that share one connectivity.
#[derive(Debug, Parser)]
#[command(name = "meshdeco", version, about, long_about = None)]
pub struct Cli {
    /// Print where the time went at the end (phases: load, features, fit, measure, write, …).
    #[arg(long, short, global = true)]
    pub verbose: bool,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Export each component's shapes and heat map, ranked, with components.csv (any model).
    Components(apply::ComponentsArgs),
    /// Interpolation between two shapes in a model's weights (the autoencoder: latent codes).
    Interpolate(apply::InterpolateArgs),
    /// Fit a trained model's weights to new meshes; writes reconstructions, weights and Erms.
    Encode(apply::EncodeArgs),
    /// Build a shape from component weights ("index:weight,…").
    Synthesize(apply::SynthesizeArgs),
    /// Export a model as glTF 2.0 (.glb): its neutral mesh with one morph target per component.
    Export(export::ExportArgs),
    /// Compute a representation's features (ACAP in the reference's LOGRNEW.txt / S.txt layout).
    Features(features::FeaturesArgs),
    /// Encode → decode every frame and print per-frame and total Erms against the input.
    Roundtrip(features::RoundtripArgs),
    /// Heat-method geodesic distances from source vertices, written as a coloured PLY.
    Geodesic(geodesic::GeodesicArgs),
    /// Write a large NumPy sequence (float32 .npy) blended and perturbed from a small one.
    Generate(generate::GenerateArgs),
    /// Summarise a mesh sequence: frames, vertices, faces, boundary loops, components, bounding
    /// box, warnings.
    Inspect(inspect::InspectArgs),
    /// Train a model from a TOML experiment config (see README for the keys).
    Train(train::TrainArgs),
    /// Train and evaluate every (dataset, method, K) cell of an eval config; tables and plots.
    Eval(eval::EvalArgs),
    /// Pose a trained model by dragging vertices: constraints JSON {"vertex": [x, y, z]} → mesh.
    Pose(pose::PoseArgs),
    /// Plant known localized deformations on a mesh and mix them into frames (ground truth for
    /// `eval`'s recovery scores).
    Plant(plant::PlantArgs),
    /// Drag benchmark: pins moved to their places in test frames; landing, collateral motion, Erms.
    DragBench(pose::DragBenchArgs),
    /// Picture of a mesh as PNG (z-buffer, Lambert shading × vertex colours of a PLY).
    Render(render::RenderArgs),
    /// Interactive viewer in the browser: component sliders, drag posing, heat maps, frames.
    View(view::ViewArgs),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    let t = std::time::Instant::now();
    let verbose = cli.verbose;
    let result = dispatch(cli.command);
    if verbose {
        print_timings(t.elapsed().as_secs_f64());
    }
    result
}

/// The phase timings recorded by the library, and the rest of the wall time.
fn print_timings(total: f64) {
    let phases = meshdeco::timing::phases();
    let known: f64 = phases.iter().map(|(_, s)| s).sum();
    eprintln!("time: {total:.3} s in all");
    for (name, s) in &phases {
        eprintln!("  {name:<14} {s:>9.3} s  {:>5.1} %", 100.0 * s / total.max(1e-12));
    }
    let other = (total - known).max(0.0);
    eprintln!("  {:<14} {other:>9.3} s  {:>5.1} %", "other", 100.0 * other / total.max(1e-12));
    for (name, n) in meshdeco::timing::counts() {
        eprintln!("  {name}: {n}");
    }
    // Reading speed of the mesh files (they are read and parsed in parallel).
    let bytes = meshdeco::timing::counts().into_iter().find(|(n, _)| n == "mesh bytes read").map(|(_, b)| b);
    let load = phases.iter().find(|(n, _)| n == "load meshes" || n == "load").map(|(_, s)| *s);
    if let (Some(b), Some(s)) = (bytes, load) {
        eprintln!("  mesh loading: {:.1} MB/s ({} bytes in {s:.3} s)", b as f64 / 1e6 / s.max(1e-9), b);
    }
}

fn dispatch(command: Command) -> Result<()> {
    match command {
        Command::Components(a) => apply::components(a),
        Command::Interpolate(a) => apply::interpolate(a),
        Command::Encode(a) => apply::encode(a),
        Command::DragBench(a) => pose::drag_bench(a),
        Command::Synthesize(a) => apply::synthesize(a),
        Command::Export(a) => export::run(a),
        Command::Features(a) => features::features(a),
        Command::Roundtrip(a) => features::roundtrip_cmd(a),
        Command::Geodesic(a) => geodesic::run(a),
        Command::Generate(a) => generate::run(a),
        Command::Inspect(a) => inspect::run(a),
        Command::Train(a) => train::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Plant(a) => plant::run(a),
        Command::Pose(a) => pose::run(a),
        Command::Render(a) => render::run(a),
        Command::View(a) => view::run(a),
    }
}
