//! `meshdeco inspect <path>`.

use anyhow::Result;
use clap::Args;
use meshdeco::mesh;

#[derive(Debug, Args)]
pub struct InspectArgs {
    /// A mesh directory, a glob (`dir/*.obj`), a single mesh file, or `synthetic:<name>`.
    pub path: String,
    /// Print the report as JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: InspectArgs) -> Result<()> {
    let report = if meshdeco::synthetic::is_synthetic(&a.path) {
        let mut r = mesh::inspect(&meshdeco::synthetic::load(&a.path)?);
        r.source = Some(a.path.clone());
        r
    } else {
        mesh::inspect_path(&a.path)?
    };
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        out!("{report}");
    }
    Ok(())
}
