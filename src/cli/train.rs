//! `meshdeco train --config F`.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result};
use clap::Args;
use meshdeco::config::Config;
use meshdeco::pipeline::metrics_file::Metrics;
use meshdeco::pipeline::{TrainOptions, train};

use super::progress::Bars;

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Experiment config (TOML); see the README for every key.
    #[arg(long, short)]
    pub config: PathBuf,
    /// Artefact directory (default: checkpoints/<name>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Continue from the last checkpoint in the artefact directory (autoencoder).
    #[arg(long)]
    pub resume: bool,
}

pub fn run(a: TrainArgs) -> Result<()> {
    let cfg = Config::from_file(&a.config).with_context(|| format!("reading config {}", a.config.display()))?;
    let out = cfg.output_dir(a.out.as_deref());
    let mut options = TrainOptions { resume: a.resume, stop: None };
    if cfg.method.can_resume() {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        // Ctrl-C: finish the current step, write a checkpoint, exit non-zero with a hint.
        ctrlc::set_handler(move || {
            if flag.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\ninterrupt: stopping after this step and writing a checkpoint (Ctrl-C again to quit at once)");
        })
        .context("installing the Ctrl-C handler")?;
        options.stop = Some(stop);
    }
    let mut bars = Bars::new();
    let o = train(&cfg, &out, &options, &mut bars)
        .with_context(|| format!("training {} ({})", cfg.name, a.config.display()))?;
    print_summary(&cfg.name, &o.metrics);
    outln!("artefacts in {}", o.out_dir.display());
    Ok(())
}

fn print_summary(name: &str, m: &Metrics) {
    outln!(
        "{} ({}, {}, K = {}): train Erms {:.4}{} [alignment: {}], fit {:.3} s, representation {:.3} s, {} iterations{}",
        name,
        m.method,
        m.representation,
        m.components,
        m.train_erms,
        m.validation_erms
            .map(|v| format!(", validation Erms {v:.4} ({} frames held out)", m.validation_frames))
            .unwrap_or_default()
            + &m.test_erms.map(|t| format!(", test Erms {t:.4}")).unwrap_or_default()
            + &m.test_erms_network.map(|t| format!(" (network only: {t:.4})")).unwrap_or_default()
            + &m.test_erms_one_pass.map(|t| format!(" (one encoder pass: {t:.4})")).unwrap_or_default()
            + &m.test_erms_fitted.map(|t| format!(" (codes fitted to the shapes: {t:.4})")).unwrap_or_default(),
        m.erms_alignment,
        m.train_seconds,
        m.representation_seconds,
        m.iterations,
        m.median_energy_share.map(|s| format!(", median in-support energy {s:.3}")).unwrap_or_default(),
    );
}
