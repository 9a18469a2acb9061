//! A minimal HTTP/1.1 server on `std::net`: one thread per connection, keep-alive, bounded
//! request heads and bodies, `Content-Length` bodies only (no chunked uploads). Enough for a
//! local viewer and for scripts; nothing here touches the file system.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::time::Duration;

/// Longest request head (request line and headers) accepted.
pub const MAX_HEAD: usize = 16 * 1024;
/// Largest request body accepted (a pose request with thousands of pins is far below this).
pub const MAX_BODY: usize = 4 * 1024 * 1024;
/// An idle keep-alive connection is closed after this long.
pub const IDLE: Duration = Duration::from_secs(120);

/// One parsed request.
#[derive(Debug, Clone)]
pub struct Request {
    pub method: String,
    /// Path without the query string.
    pub path: String,
    /// The query string (after `?`), empty when none.
    pub query: String,
    pub body: Vec<u8>,
}

/// One response.
#[derive(Debug, Clone)]
pub struct Response {
    pub status: u16,
    pub content_type: &'static str,
    pub body: Vec<u8>,
    /// Extra headers (name, value).
    pub headers: Vec<(&'static str, String)>,
}

impl Response {
    pub fn new(status: u16, content_type: &'static str, body: Vec<u8>) -> Response {
        Response { status, content_type, body, headers: Vec::new() }
    }
    /// A JSON body.
    pub fn json(status: u16, value: &serde_json::Value) -> Response {
        Response::new(status, "application/json", value.to_string().into_bytes())
    }
    /// An error: `{"error": message}` with `status`.
    pub fn error(status: u16, message: impl Into<String>) -> Response {
        Response::json(status, &serde_json::json!({ "error": message.into() }))
    }
    /// Binary little-endian arrays.
    pub fn binary(body: Vec<u8>) -> Response {
        Response::new(200, "application/octet-stream", body)
    }
    pub fn with_header(mut self, name: &'static str, value: String) -> Response {
        self.headers.push((name, value));
        self
    }
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        411 => "Length Required",
        413 => "Payload Too Large",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        _ => "Status",
    }
}

/// Why a request could not be read: an error response to send (then close), or a closed /
/// timed-out connection (nothing to send).
enum ReadError {
    Respond(Response),
    Closed,
}

fn read_request(r: &mut BufReader<TcpStream>) -> Result<(Request, bool), ReadError> {
    let mut head = Vec::new();
    loop {
        let before = head.len();
        let n = r.by_ref().take((MAX_HEAD + 1 - head.len()) as u64).read_until(b'\n', &mut head);
        match n {
            Ok(0) => return Err(ReadError::Closed),
            Ok(_) => {}
            Err(_) => return Err(ReadError::Closed),
        }
        if head.len() > MAX_HEAD {
            return Err(ReadError::Respond(Response::error(431, format!("request head longer than {MAX_HEAD} bytes"))));
        }
        let line = &head[before..];
        if line == b"\r\n" || line == b"\n" {
            if before == 0 {
                // Stray blank line between requests: skip it.
                head.clear();
                continue;
            }
            break;
        }
    }
    let text = String::from_utf8_lossy(&head);
    let mut lines = text.lines();
    let first = lines.next().unwrap_or_default();
    let mut parts = first.split_whitespace();
    let (Some(method), Some(target), Some(version)) = (parts.next(), parts.next(), parts.next()) else {
        return Err(ReadError::Respond(Response::error(400, format!("malformed request line `{first}`"))));
    };
    let mut length: Option<usize> = None;
    let mut keep_alive = version == "HTTP/1.1";
    let mut expect_continue = false;
    for l in lines {
        let Some((name, value)) = l.split_once(':') else { continue };
        let value = value.trim();
        match name.trim().to_ascii_lowercase().as_str() {
            "content-length" => match value.parse::<usize>() {
                Ok(n) => length = Some(n),
                Err(_) => {
                    return Err(ReadError::Respond(Response::error(
                        400,
                        format!("Content-Length `{value}` is not a number"),
                    )));
                }
            },
            "transfer-encoding" => {
                return Err(ReadError::Respond(Response::error(
                    411,
                    "chunked request bodies are not accepted: send Content-Length",
                )));
            }
            "expect" => expect_continue = value.eq_ignore_ascii_case("100-continue"),
            "connection" => {
                let v = value.to_ascii_lowercase();
                if v.contains("close") {
                    keep_alive = false;
                } else if v.contains("keep-alive") {
                    keep_alive = true;
                }
            }
            _ => {}
        }
    }
    let length = length.unwrap_or(0);
    if length > MAX_BODY {
        return Err(ReadError::Respond(Response::error(
            413,
            format!("request body of {length} bytes is larger than the limit of {MAX_BODY}"),
        )));
    }
    if expect_continue && length > 0 {
        // curl asks before sending larger bodies; answer at once instead of letting it wait.
        let _ = r.get_mut().write_all(b"HTTP/1.1 100 Continue\r\n\r\n");
    }
    let mut body = vec![0u8; length];
    if r.read_exact(&mut body).is_err() {
        return Err(ReadError::Closed);
    }
    let (path, query) = match target.split_once('?') {
        Some((p, q)) => (p.to_string(), q.to_string()),
        None => (target.to_string(), String::new()),
    };
    Ok((Request { method: method.to_string(), path, query, body }, keep_alive))
}

fn write_response(w: &mut TcpStream, resp: &Response, keep_alive: bool) -> std::io::Result<()> {
    let mut head = format!(
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: {}\r\n",
        resp.status,
        reason(resp.status),
        resp.content_type,
        resp.body.len(),
        if keep_alive { "keep-alive" } else { "close" }
    );
    for (k, v) in &resp.headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    w.write_all(head.as_bytes())?;
    w.write_all(&resp.body)?;
    w.flush()
}

/// Serves one connection until it closes: reads requests, answers each with `handle`.
pub fn serve_connection(stream: TcpStream, handle: &dyn Fn(&Request) -> Response) {
    let _ = stream.set_read_timeout(Some(IDLE));
    let _ = stream.set_nodelay(true);
    let Ok(mut writer) = stream.try_clone() else { return };
    let mut reader = BufReader::new(stream);
    loop {
        match read_request(&mut reader) {
            Ok((req, keep_alive)) => {
                let resp = handle(&req);
                if write_response(&mut writer, &resp, keep_alive).is_err() || !keep_alive {
                    return;
                }
            }
            Err(ReadError::Respond(resp)) => {
                let _ = write_response(&mut writer, &resp, false);
                return;
            }
            Err(ReadError::Closed) => return,
        }
    }
}
