//! `meshdeco eval --config F [--out DIR] [--replot]`.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use indicatif::MultiProgress;
use meshdeco::eval::{EvalConfig, EvalOptions};

use super::progress::Bars;

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Evaluation config (TOML: [[dataset]], [[method]], [sweep], [control_points]).
    #[arg(long, short)]
    pub config: PathBuf,
    /// Output directory (default: checkpoints/eval-<name>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Only re-read finished cells and redraw the tables and plots (fails if a cell is missing).
    #[arg(long)]
    pub replot: bool,
}

pub fn run(a: EvalArgs) -> Result<()> {
    let t0 = Instant::now();
    let cfg =
        EvalConfig::from_file(&a.config).with_context(|| format!("reading eval config {}", a.config.display()))?;
    let out = a.out.clone().unwrap_or_else(|| PathBuf::from("checkpoints").join(format!("eval-{}", cfg.name)));
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    // Ctrl-C: stop after the current cell (the autoencoder after its current step, keeping a
    // checkpoint); a second Ctrl-C quits at once. Unfinished cells have no cell.json.
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("\ninterrupt: stopping after the current cell (Ctrl-C again to quit at once)");
    })
    .context("installing the Ctrl-C handler")?;
    let multi = MultiProgress::new();
    let mut sweep = Bars::in_multi(&multi);
    let mut inner = Bars::in_multi(&multi);
    let opts = EvalOptions { replot: a.replot, stop: Some(stop) };
    let o = meshdeco::eval::run(&cfg, &out, &opts, &mut sweep, &mut inner)
        .with_context(|| format!("evaluating {} into {}", a.config.display(), out.display()))?;
    outln!(
        "{} cells: {} trained, {} reused, {} measured again (only inference keys changed); {} control-point rows; {:.1} s",
        o.results.len(),
        o.trained,
        o.reused,
        o.remeasured,
        o.control_points.len(),
        t0.elapsed().as_secs_f64()
    );
    for r in &o.results {
        outln!(
            "{:>10} {:>16} {:>18} K={:<3} test Erms {:>9.4} ({}) STED {:.4}{}",
            r.dataset,
            r.method,
            r.representation,
            r.k,
            r.test_erms,
            r.alignment,
            r.sted_spatial,
            r.sted_temporal.map(|t| format!(" / {t:.4}")).unwrap_or_default()
        );
    }
    for f in &o.files {
        outln!("wrote {}", f.display());
    }
    for f in &o.failed {
        eprintln!("failed: {}/{}/K{}: {}", f.dataset, f.method, f.k, f.error);
    }
    if !o.failed.is_empty() {
        anyhow::bail!(
            "{} of {} cells failed (listed above, in the report and in failed_cells.csv); the others are done and a rerun retries only the failed ones",
            o.failed.len(),
            o.failed.len() + o.results.len()
        );
    }
    Ok(())
}
