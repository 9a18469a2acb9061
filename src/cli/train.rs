//! `meshdeco train --config F`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::config::Config;

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Experiment config (TOML).
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
    let _out = cfg.output_dir(a.out.as_deref());
    bail!("method `{}` is not yet available in this build (config {})", cfg.kind.name(), a.config.display())
}
