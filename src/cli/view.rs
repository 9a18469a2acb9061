//! `meshdeco view`: serves the interactive viewer of a trained model on a local port.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, ToSocketAddrs};
use std::path::PathBuf;

use anyhow::{Context, Result, anyhow};
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
    /// Address to listen on: an IPv4 or IPv6 address (`::`, `[::1]`) or a host name
    /// (`localhost`). The default serves only this machine; any other address lets other
    /// machines reach the viewer (a warning is printed).
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// Open the page in the default browser (xdg-open / open) once the server listens.
    #[arg(long)]
    pub open: bool,
}

/// The address `--host` names: an IP address (IPv6 with or without brackets), `localhost`
/// (127.0.0.1), or a host name the system resolves (its first IPv4 address, else its first).
fn listen_ip(host: &str) -> Result<IpAddr> {
    let bare = host.strip_prefix('[').and_then(|h| h.strip_suffix(']')).unwrap_or(host);
    if let Ok(ip) = bare.parse::<IpAddr>() {
        return Ok(ip);
    }
    if bare.eq_ignore_ascii_case("localhost") {
        return Ok(IpAddr::V4(Ipv4Addr::LOCALHOST));
    }
    let not_found = |why: String| anyhow!("--host `{host}`: not an IP address or a host name of this machine ({why})");
    if bare.is_empty() || bare.contains(|c: char| c.is_whitespace() || c == '/' || c == ':') {
        return Err(not_found("expected e.g. 127.0.0.1, ::1, 0.0.0.0 or localhost".into()));
    }
    let addrs: Vec<SocketAddr> = (bare, 0u16).to_socket_addrs().map_err(|e| not_found(e.to_string()))?.collect();
    addrs
        .iter()
        .find(|a| a.is_ipv4())
        .or(addrs.first())
        .map(SocketAddr::ip)
        .ok_or_else(|| not_found("it resolves to no address".into()))
}

/// The URL to open for a server bound to `addr`: an unspecified address (`0.0.0.0`, `::`) is
/// reached through this machine's loopback (127.0.0.1, [::1]); IPv6 hosts are bracketed.
fn url_of(addr: SocketAddr) -> String {
    match addr.ip() {
        IpAddr::V4(ip) => {
            let ip = if ip.is_unspecified() { Ipv4Addr::LOCALHOST } else { ip };
            format!("http://{ip}:{}/", addr.port())
        }
        IpAddr::V6(ip) => {
            let ip = if ip.is_unspecified() { Ipv6Addr::LOCALHOST } else { ip };
            format!("http://[{ip}]:{}/", addr.port())
        }
    }
}

pub fn run(a: ViewArgs) -> Result<()> {
    let host = listen_ip(&a.host)?;
    let viewer = Viewer::start(&ViewOptions {
        model: a.model.clone(),
        data: a.data.clone(),
        addr: SocketAddr::new(host, a.port),
    })
    .with_context(|| format!("starting the viewer of {}", a.model.display()))?;
    let addr = viewer.local_addr()?;
    if !host.is_loopback() {
        eprintln!(
            "warning: --host {}: the viewer (no authentication) is reachable from other machines on this network",
            a.host
        );
    }
    // Nothing is written while serving (downloads are response bodies), so a Ctrl-C can stop the
    // process at any instant; the handler only says so and exits with status 0.
    ctrlc::set_handler(|| {
        outln!("meshdeco view: stopped");
        std::process::exit(0);
    })
    .context("installing the Ctrl-C handler")?;
    outln!("{}", viewer.summary());
    let url = url_of(addr);
    if addr.ip().is_unspecified() {
        outln!("meshdeco view: serving {url} (listening on every address, {addr}; Ctrl-C stops)");
    } else {
        outln!("meshdeco view: serving {url} (Ctrl-C stops)");
    }
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
