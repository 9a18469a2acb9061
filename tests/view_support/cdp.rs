//! A minimal Chrome DevTools Protocol client on `std::net` (a WebSocket client of ~100 lines),
//! enough to drive headless Chromium with real input events: navigate, evaluate, dispatch mouse
//! events, capture screenshots. No Node, no npm package: it runs wherever Chromium is installed.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

/// The Chromium binary: `$MESHDECO_CHROMIUM`, else the first of chromium-headless-shell,
/// chromium, google-chrome on the PATH.
pub fn find_chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("MESHDECO_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    for name in ["chromium-headless-shell", "chromium", "google-chrome", "chrome"] {
        for dir in std::env::split_paths(&path) {
            let p = dir.join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    None
}

/// A headless Chromium with one page, killed when dropped — with every process it started: it
/// runs in its own process group, because the `chromium-headless-shell` on the PATH of Debian is
/// a shell script that starts the browser as its child (killing the script alone leaves the
/// browser running).
pub struct Browser {
    child: Child,
    ws: TcpStream,
    next: u64,
    _profile: PathBuf,
    /// Every event received while waiting for a command's result (`{"method", "params"}`), in
    /// order: e.g. `Network.requestWillBeSent` after `Network.enable`.
    pub events: Vec<Value>,
}

impl Drop for Browser {
    fn drop(&mut self) {
        kill_group(&mut self.child);
        let _ = std::fs::remove_dir_all(&self._profile);
    }
}

/// Processes whose command line mentions `needle` (from /proc; empty where there is none).
pub fn processes_mentioning(needle: &str) -> Vec<u32> {
    let Ok(dir) = std::fs::read_dir("/proc") else { return Vec::new() };
    dir.filter_map(|e| {
        let e = e.ok()?;
        let pid: u32 = e.file_name().to_str()?.parse().ok()?;
        let cmd = std::fs::read(e.path().join("cmdline")).ok()?;
        String::from_utf8_lossy(&cmd).contains(needle).then_some(pid)
    })
    .collect()
}

impl Browser {
    /// The browser's profile directory (unique to it; its processes name it).
    pub fn profile(&self) -> &Path {
        &self._profile
    }
}

/// Kills the process group led by `child` (see [`Browser`]) and reaps the child.
fn kill_group(child: &mut Child) {
    if let Ok(pgid) = i32::try_from(child.id()) {
        // SAFETY: kill(2) with a negative pid signals that process group; no memory is touched.
        unsafe {
            libc::kill(-pgid, libc::SIGKILL);
        }
    }
    let _ = child.kill();
    let _ = child.wait();
}

fn ws_connect(url: &str) -> TcpStream {
    let rest = url.strip_prefix("ws://").expect("ws:// URL");
    let (host, path) = rest.split_at(rest.find('/').unwrap());
    let mut s = TcpStream::connect(host).expect("connect to DevTools");
    s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    s.set_nodelay(true).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: bWVzaGRlY28tdmlldy10ZXN0\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    .unwrap();
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        s.read_exact(&mut b).unwrap();
        head.push(b[0]);
    }
    let head = String::from_utf8_lossy(&head);
    assert!(head.starts_with("HTTP/1.1 101"), "WebSocket handshake refused: {head}");
    s
}

fn ws_send(s: &mut TcpStream, text: &str) {
    let p = text.as_bytes();
    let mut f = vec![0x81u8];
    match p.len() {
        n if n < 126 => f.push(0x80 | n as u8),
        n if n < 65536 => {
            f.push(0x80 | 126);
            f.extend((n as u16).to_be_bytes());
        }
        n => {
            f.push(0x80 | 127);
            f.extend((n as u64).to_be_bytes());
        }
    }
    let mask = [0x12u8, 0x34, 0x56, 0x78];
    f.extend(mask);
    f.extend(p.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
    s.write_all(&f).unwrap();
}

fn ws_recv(s: &mut TcpStream) -> String {
    let mut msg = Vec::new();
    loop {
        let mut h = [0u8; 2];
        s.read_exact(&mut h).expect("DevTools connection closed");
        let (fin, op) = (h[0] & 0x80 != 0, h[0] & 0x0f);
        let mut len = (h[1] & 0x7f) as u64;
        if len == 126 {
            let mut e = [0u8; 2];
            s.read_exact(&mut e).unwrap();
            len = u16::from_be_bytes(e) as u64;
        } else if len == 127 {
            let mut e = [0u8; 8];
            s.read_exact(&mut e).unwrap();
            len = u64::from_be_bytes(e);
        }
        let mask = if h[1] & 0x80 != 0 {
            let mut m = [0u8; 4];
            s.read_exact(&mut m).unwrap();
            Some(m)
        } else {
            None
        };
        let mut p = vec![0u8; len as usize];
        s.read_exact(&mut p).unwrap();
        if let Some(m) = mask {
            for (i, b) in p.iter_mut().enumerate() {
                *b ^= m[i % 4];
            }
        }
        match op {
            0x8 => panic!("DevTools closed the connection"),
            0x9 | 0xA => continue, // ping / pong
            _ => msg.extend(p),
        }
        if fin {
            return String::from_utf8(msg).unwrap();
        }
    }
}

impl Browser {
    /// Starts headless Chromium (WebGL2 through SwiftShader, no GPU) with a `w`×`h` viewport.
    pub fn launch(chromium: &Path, w: u32, h: u32) -> Browser {
        let profile = std::env::temp_dir().join(format!("meshdeco-chromium-{}-{}", std::process::id(), w * 7 + h));
        let _ = std::fs::remove_dir_all(&profile);
        let mut child = Command::new(chromium);
        std::os::unix::process::CommandExt::process_group(&mut child, 0);
        let mut child = child
            .args([
                "--headless",
                "--no-sandbox",
                "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader",
                "--disable-gpu-vsync",
                "--no-first-run",
                "--hide-scrollbars",
                "--remote-debugging-port=0",
                &format!("--window-size={w},{h}"),
                &format!("--user-data-dir={}", profile.display()),
                "about:blank",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("start {}: {e}", chromium.display()));
        let mut err = BufReader::new(child.stderr.take().unwrap());
        let browser_ws = loop {
            let mut line = String::new();
            if err.read_line(&mut line).unwrap() == 0 {
                kill_group(&mut child);
                panic!("{} exited before DevTools listened", chromium.display());
            }
            if let Some(u) = line.split("DevTools listening on ").nth(1) {
                break u.trim().to_string();
            }
        };
        std::thread::spawn(move || {
            let mut sink = String::new();
            let _ = err.read_to_string(&mut sink);
        });
        let host = browser_ws.strip_prefix("ws://").unwrap().split('/').next().unwrap().to_string();
        // The page target of about:blank.
        let t0 = Instant::now();
        let page_ws = loop {
            let (_, _, body) = super::http(&host, "GET", "/json/list", b"");
            let list: Value = serde_json::from_slice(&body).unwrap_or(Value::Null);
            if let Some(p) = list.as_array().and_then(|a| a.iter().find(|t| t["type"] == "page")) {
                break p["webSocketDebuggerUrl"].as_str().unwrap().to_string();
            }
            assert!(t0.elapsed().as_secs() < 30, "no page target in DevTools");
            std::thread::sleep(Duration::from_millis(100));
        };
        let ws = ws_connect(&page_ws);
        let mut b = Browser { child, ws, next: 0, _profile: profile, events: Vec::new() };
        b.call(
            "Emulation.setDeviceMetricsOverride",
            json!({ "width": w, "height": h, "deviceScaleFactor": 1, "mobile": false }),
        );
        b
    }

    /// Sends a command and waits for its result (events in between are kept in `events`).
    pub fn call(&mut self, method: &str, params: Value) -> Value {
        self.next += 1;
        let id = self.next;
        ws_send(&mut self.ws, &json!({ "id": id, "method": method, "params": params }).to_string());
        loop {
            let m: Value = serde_json::from_str(&ws_recv(&mut self.ws)).unwrap();
            if m["id"] == id {
                if let Some(e) = m.get("error") {
                    panic!("{method}: {e}");
                }
                return m["result"].clone();
            }
            if m.get("method").is_some() {
                self.events.push(m);
            }
        }
    }

    pub fn navigate(&mut self, url: &str) {
        self.call("Page.navigate", json!({ "url": url }));
    }

    /// Evaluates `expr` (awaiting a promise) and returns its JSON value; panics on an exception.
    pub fn eval(&mut self, expr: &str) -> Value {
        let r =
            self.call("Runtime.evaluate", json!({ "expression": expr, "returnByValue": true, "awaitPromise": true }));
        if let Some(e) = r.get("exceptionDetails") {
            panic!("page exception in `{expr}`: {e}");
        }
        r["result"]["value"].clone()
    }

    /// Waits until `expr` is true (at most `secs`).
    pub fn wait_for(&mut self, expr: &str, secs: u64) {
        let t0 = Instant::now();
        while self.eval(expr) != Value::Bool(true) {
            assert!(t0.elapsed().as_secs() < secs, "timed out waiting for `{expr}`");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// A real mouse event (`mousePressed`, `mouseMoved`, `mouseReleased`) at CSS pixel (x, y)
    /// with the left button (`pressed`: held during a move).
    pub fn mouse(&mut self, kind: &str, x: f64, y: f64, pressed: bool) {
        let button = if kind == "mouseMoved" && !pressed { "none" } else { "left" };
        self.call(
            "Input.dispatchMouseEvent",
            json!({ "type": kind, "x": x, "y": y, "button": button, "buttons": if pressed || kind == "mousePressed" { 1 } else { 0 }, "clickCount": 1 }),
        );
    }

    /// A left-button drag from `a` to `b` in `steps` moves.
    pub fn drag(&mut self, a: (f64, f64), b: (f64, f64), steps: usize) {
        self.mouse("mouseMoved", a.0, a.1, false);
        self.mouse("mousePressed", a.0, a.1, true);
        for i in 1..=steps {
            let t = i as f64 / steps as f64;
            self.mouse("mouseMoved", a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t, true);
        }
        self.mouse("mouseReleased", b.0, b.1, false);
    }

    /// A left click.
    pub fn click(&mut self, x: f64, y: f64) {
        self.mouse("mouseMoved", x, y, false);
        self.mouse("mousePressed", x, y, true);
        self.mouse("mouseReleased", x, y, false);
    }

    /// The centre of the first element matching `selector` (CSS pixels).
    pub fn centre(&mut self, selector: &str) -> (f64, f64) {
        let r = self.eval(&format!(
            "(() => {{ const r = document.querySelector({}).getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; }})()",
            Value::String(selector.into())
        ));
        (r[0].as_f64().unwrap(), r[1].as_f64().unwrap())
    }

    /// A screenshot of the viewport as an RGB image.
    pub fn screenshot(&mut self) -> image::RgbImage {
        let r = self.call("Page.captureScreenshot", json!({ "format": "png" }));
        let png = base64(r["data"].as_str().unwrap());
        image::load_from_memory(&png).unwrap().to_rgb8()
    }
}

/// Standard base64 decoding (padding and whitespace ignored).
pub fn base64(s: &str) -> Vec<u8> {
    let val = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for c in s.bytes().filter_map(val) {
        acc = (acc << 6) | c;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    out
}
