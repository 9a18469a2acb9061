//! `meshdeco view`: serves the interactive viewer of a trained model on a local port.

use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use meshdeco::view::{ViewOptions, Viewer};

#[derive(Debug, Args)]
#[command(after_help = "The page and its script are built into the binary; nothing is fetched at run time. \
The HTTP API under /api/ is documented in the README (section `meshdeco view`). Ctrl-C stops the server.")]
pub struct ViewArgs {
    /// Model directory written by `meshdeco train` (or its model.json).
    pub model: PathBuf,
    /// Frames to step through in the Frames panel (a directory, glob, mesh file or
    /// synthetic:<name>, with the model's connectivity): each frame, its reconstruction and the
    /// per-vertex error.
    #[arg(long)]
    pub data: Option<String>,
    /// Port to listen on (0: any free port; the URL printed says which).
    #[arg(long, default_value_t = 8017)]
    pub port: u16,
    /// Address to listen on. The default serves only this machine; any other address lets
    /// other machines reach the viewer (a warning is printed).
    #[arg(long, default_value = "127.0.0.1")]
    pub host: IpAddr,
    /// Open the page in the default browser (xdg-open / open) once the server listens.
    #[arg(long)]
    pub open: bool,
}

pub fn run(a: ViewArgs) -> Result<()> {
    let viewer = Viewer::start(&ViewOptions {
        model: a.model.clone(),
        data: a.data.clone(),
        addr: SocketAddr::new(a.host, a.port),
    })
    .with_context(|| format!("starting the viewer of {}", a.model.display()))?;
    let addr = viewer.local_addr()?;
    if !a.host.is_loopback() {
        eprintln!(
            "warning: --host {}: the viewer (no authentication) is reachable from other machines on this network",
            a.host
        );
    }
    // Nothing is written while serving (downloads are response bodies), so a Ctrl-C can stop the
    // process at any instant; the handler only says so and exits with status 0.
    ctrlc::set_handler(|| {
        println!("meshdeco view: stopped");
        std::process::exit(0);
    })
    .context("installing the Ctrl-C handler")?;
    println!("{}", viewer.summary());
    let host = if addr.ip().is_unspecified() { "127.0.0.1".to_string() } else { addr.ip().to_string() };
    let url = if addr.is_ipv6() {
        format!("http://[{host}]:{}/", addr.port())
    } else {
        format!("http://{host}:{}/", addr.port())
    };
    println!("meshdeco view: serving {url} (Ctrl-C stops)");
    if a.open {
        let opener = if cfg!(target_os = "macos") { "open" } else { "xdg-open" };
        if let Err(e) = std::process::Command::new(opener).arg(&url).spawn() {
            eprintln!("--open: could not run {opener} ({e}); open {url} yourself");
        }
    }
    use std::io::Write;
    std::io::stdout().flush().ok();
    viewer.serve()?;
    Ok(())
}
