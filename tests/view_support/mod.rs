//! Helpers of the `meshdeco view` tests (tests/view_api.rs, tests/view_browser.rs,
//! tests/view_standalone.rs, tests/notebook.rs): train a small model, start the viewer binary on a
//! free port, speak HTTP to it, parse its binary shapes; find Chromium and read the page's state.
#![allow(dead_code)]

pub mod cdp;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use meshdeco::config::Config;
use meshdeco::pipeline::Silent;

/// The Chromium to drive ([`cdp::find_chromium`]), or `None` with the skip printed and recorded
/// (`crate::common::record_skip`); with `CI` set a missing Chromium fails the test.
pub fn chromium_or_skip() -> Option<PathBuf> {
    if let Some(p) = cdp::find_chromium() {
        return Some(p);
    }
    let test = std::thread::current().name().unwrap_or("?").to_string();
    if std::env::var_os("CI").is_some() {
        panic!("CI is set but no Chromium is installed (chromium-headless-shell or chromium; needed by {test})");
    }
    eprintln!("SKIPPED {test}: no chromium-headless-shell / chromium on the PATH (set MESHDECO_CHROMIUM to a binary)");
    crate::common::record_skip("chromium (not installed)");
    None
}

/// A JSON number of the page.
pub fn num(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The positions the page `meshdeco` object (in `window`, or `w` given as a JS expression) shows.
pub fn page_positions(b: &mut cdp::Browser, w: &str) -> Vec<[f64; 3]> {
    let p = b.eval(&format!("Array.from({w}.S.pos)"));
    p.as_array().unwrap().chunks(3).map(|c| [num(&c[0]), num(&c[1]), num(&c[2])]).collect()
}

/// Waits until the page (`w`: its `meshdeco` object as a JS expression) has no request in flight
/// or waiting.
pub fn settle(b: &mut cdp::Browser, w: &str) {
    std::thread::sleep(Duration::from_millis(50));
    b.wait_for(&format!("{w}.idle()"), 120);
}

/// Trains `method` (TOML lines of `[method]`) on `data` (e.g. `synthetic:tube`) into `dir/name`.
pub fn train(dir: &Path, name: &str, data: &str, method: &str) -> PathBuf {
    let cfg = Config::from_toml(&format!(
        "name = \"{name}\"\n[data]\npath = \"{data}\"\ntrain = \"every:2\"\ntest = \"rest\"\n[method]\n{method}\n"
    ))
    .unwrap();
    let out = dir.join(name);
    meshdeco::pipeline::train(&cfg, &out, &meshdeco::pipeline::TrainOptions::default(), &mut Silent).unwrap();
    out
}

/// A running `meshdeco view`, killed when dropped.
pub struct Viewer {
    pub child: Child,
    /// `127.0.0.1:<port>`.
    pub addr: String,
    /// What it printed before serving.
    pub banner: String,
}

impl Viewer {
    /// Starts `meshdeco view <args> --port 0` and waits for its `serving http://…` line.
    // The child is waited for by `Drop` once it is a `Viewer`, and before the panic otherwise.
    #[allow(clippy::zombie_processes)]
    pub fn start(args: &[&str]) -> Viewer {
        let mut child = Command::new(env!("CARGO_BIN_EXE_meshdeco"))
            .arg("view")
            .args(args)
            .args(["--port", "0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start meshdeco view");
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let mut banner = String::new();
        loop {
            let mut line = String::new();
            if out.read_line(&mut line).unwrap() == 0 {
                let mut err = String::new();
                child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
                let _ = child.wait();
                panic!("meshdeco view exited before serving:\n{banner}{err}");
            }
            banner.push_str(&line);
            if let Some(rest) = line.split("serving http://").nth(1) {
                let addr = rest.split('/').next().unwrap().to_string();
                // Keep draining stdout so the child never blocks on a full pipe.
                std::thread::spawn(move || {
                    let mut sink = String::new();
                    let _ = out.read_to_string(&mut sink);
                });
                return Viewer { child, addr, banner };
            }
        }
    }

    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// One request (`Connection: close`): (status, headers lower-cased, body).
    pub fn request(&self, method: &str, path: &str, body: &[u8]) -> (u16, Vec<(String, String)>, Vec<u8>) {
        http(&self.addr, method, path, body)
    }

    /// POST a JSON body.
    pub fn post(&self, path: &str, json: &serde_json::Value) -> (u16, Vec<(String, String)>, Vec<u8>) {
        self.request("POST", path, json.to_string().as_bytes())
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A raw HTTP/1.1 exchange over TCP.
pub fn http(addr: &str, method: &str, path: &str, body: &[u8]) -> (u16, Vec<(String, String)>, Vec<u8>) {
    let mut s = TcpStream::connect(addr).expect("connect to the viewer");
    s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let head = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    s.write_all(head.as_bytes()).unwrap();
    s.write_all(body).unwrap();
    // Read the head, then Content-Length bytes (some servers keep the connection open).
    let mut raw = Vec::new();
    let mut buf = [0u8; 65536];
    loop {
        let n = s.read(&mut buf).unwrap();
        raw.extend_from_slice(&buf[..n]);
        if let Some(split) = raw.windows(4).position(|w| w == b"\r\n\r\n") {
            let (_, headers, _) = parse_response(&raw);
            if let Some(len) = header(&headers, "content-length").and_then(|l| l.parse::<usize>().ok()) {
                while raw.len() < split + 4 + len {
                    let n = s.read(&mut buf).unwrap();
                    assert!(n > 0, "connection closed before the body's end");
                    raw.extend_from_slice(&buf[..n]);
                }
                break;
            }
        }
        if n == 0 {
            break;
        }
    }
    parse_response(&raw)
}

/// The reason phrase of each status meshdeco's server sends (RFC 7231 §6.1; 431: RFC 6585 §5).
fn reason_phrase(status: u16) -> &'static str {
    match status {
        100 => "Continue",
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        409 => "Conflict",
        411 => "Length Required",
        413 => "Payload Too Large",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        other => panic!("status {other} is not one the server is meant to send"),
    }
}

/// A response's status, headers (names in lower case) and body; its status line must be
/// `HTTP/1.1 <status> <reason phrase>`.
pub fn parse_response(raw: &[u8]) -> (u16, Vec<(String, String)>, Vec<u8>) {
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n").expect("response head");
    let head = String::from_utf8_lossy(&raw[..split]);
    let mut lines = head.lines();
    let status_line = lines.next().unwrap();
    let status: u16 = status_line.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert_eq!(status_line, format!("HTTP/1.1 {status} {}", reason_phrase(status)), "the status line");
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    (status, headers, raw[split + 4..].to_vec())
}

pub fn header<'a>(headers: &'a [(String, String)], name: &str) -> Option<&'a str> {
    headers.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
}

/// A decoded binary shape of the API: weights, dials, positions.
#[derive(Debug, Clone)]
pub struct Shape {
    pub weights: Vec<f64>,
    pub dials: Vec<f64>,
    pub positions: Vec<[f64; 3]>,
    /// Bytes after the positions (frames: truth positions, per-vertex error).
    pub rest: Vec<u8>,
}

pub fn parse_shape(b: &[u8]) -> Shape {
    let u = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap()) as usize;
    let (n, k) = (u(0), u(4));
    let f64s = |o: usize, c: usize| -> Vec<f64> {
        (0..c).map(|i| f64::from_le_bytes(b[o + 8 * i..o + 8 * i + 8].try_into().unwrap())).collect()
    };
    let weights = f64s(8, k);
    let dials = f64s(8 + 8 * k, k);
    let off = 8 + 16 * k;
    assert!(b.len() >= off + 12 * n, "shape of {} bytes too short for {n} vertices and {k} weights", b.len());
    let positions = f32s(&b[off..off + 12 * n]).chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    Shape { weights, dials, positions, rest: b[off + 12 * n..].to_vec() }
}

/// Little-endian `f32`s as `f64`.
pub fn f32s(b: &[u8]) -> Vec<f64> {
    b.chunks(4).map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64).collect()
}

/// Largest coordinate difference between two position lists.
pub fn max_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs())).fold(0.0, f64::max)
}

pub fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}
