//! A minimal HTTP/1.1 server on `std::net`: one thread per connection, keep-alive, bounded
//! request heads and bodies, `Content-Length` bodies only (no chunked uploads). Enough for a
//! local viewer and for scripts; nothing here touches the file system.
//!
//! Every resource a client can hold is bounded ([`Limits`]): the number of connections, the time
//! a request may take to arrive whole from its first byte and a response to be written (not only
//! the time between two reads, so a client sending one byte every few seconds is cut off: 408),
//! the time a new connection has for its first request, the idle time of a keep-alive
//! connection, and the bytes of request bodies held at once over all connections (each body's
//! `Content-Length` is reserved before it is read; a request that does not fit is answered 503).
//!
//! Only a connection whose request is being answered holds its slot for sure: when every slot
//! is taken, a new connection closes the one that has waited longest without sending a whole
//! request (first those that never sent one, then idle keep-alive ones), so connections that
//! send nothing cannot lock the page out; only when every connection is being answered is a new
//! one answered 503.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Longest request head (request line and headers) accepted.
pub const MAX_HEAD: usize = 16 * 1024;
/// Largest request body accepted (a pose request with thousands of pins is far below this).
pub const MAX_BODY: usize = 4 * 1024 * 1024;
/// An idle keep-alive connection is closed after this long.
pub const IDLE: Duration = Duration::from_secs(120);
/// A new connection is closed when its first request has not arrived whole within this long.
pub const FIRST_REQUEST: Duration = Duration::from_secs(10);
/// Time one request may take to arrive whole, from its first byte (and one response to be
/// written).
pub const REQUEST_TIME: Duration = Duration::from_secs(30);
/// Most connections served at once.
pub const MAX_CONNECTIONS: usize = 64;
/// Most bytes of request bodies held at once, over all connections.
pub const MAX_BODY_BYTES_IN_FLIGHT: usize = 4 * MAX_BODY;

/// The bounds of a server ([`serve`]); [`Limits::default`] is what `meshdeco view` uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// How long a keep-alive connection may wait for the first byte of its next request.
    pub idle: Duration,
    /// How long a new connection may take to send its first request whole (from the moment
    /// it is accepted).
    pub first_request: Duration,
    /// How long a request may take to arrive whole (head and body) from its first byte, and a
    /// response to be written.
    pub request: Duration,
    /// Most connections served at once; one more closes the connection that has waited
    /// longest without a whole request, or is answered 503 when all are being answered.
    pub max_connections: usize,
    /// Most bytes of request bodies reserved at once over all connections; a request whose
    /// `Content-Length` does not fit is answered 503.
    pub max_body_bytes_in_flight: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            idle: IDLE,
            first_request: FIRST_REQUEST,
            request: REQUEST_TIME,
            max_connections: MAX_CONNECTIONS,
            max_body_bytes_in_flight: MAX_BODY_BYTES_IN_FLIGHT,
        }
    }
}

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
        408 => "Request Timeout",
        409 => "Conflict",
        411 => "Length Required",
        413 => "Payload Too Large",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "Status",
    }
}

/// Why a request could not be read: an error response to send (then close), or a closed /
/// timed-out connection (nothing to send).
enum ReadError {
    Respond(Response),
    Closed,
}

/// The connection's stream for reading, with a deadline for all reads together (each read
/// waits at most until then).
struct DeadlineReader {
    stream: TcpStream,
    deadline: Instant,
}

impl Read for DeadlineReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let left = self.deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(std::io::Error::new(std::io::ErrorKind::TimedOut, "deadline passed"));
        }
        self.stream.set_read_timeout(Some(left))?;
        self.stream.read(buf)
    }
}

/// Whether a read error is the deadline (or a read timeout) rather than a closed connection.
fn timed_out(e: &std::io::Error) -> bool {
    matches!(e.kind(), std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock)
}

/// The server's shared state: its connections, body bytes reserved.
#[derive(Debug, Default)]
struct Load {
    slots: Mutex<Slots>,
    body_bytes: AtomicUsize,
}

/// The connections holding a slot.
#[derive(Debug, Default)]
struct Slots {
    /// Identity of the next connection.
    next: u64,
    open: Vec<Slot>,
}

/// One connection's slot: a handle to close it with, whether it has sent a whole request yet,
/// whether one is being answered, and since when it has been waiting.
#[derive(Debug)]
struct Slot {
    id: u64,
    stream: TcpStream,
    served: bool,
    answering: bool,
    since: Instant,
}

impl Slots {
    /// The slot to close for a new connection: of those not being answered, the one waiting
    /// longest among those that never sent a whole request, else the one idle longest.
    fn to_close(&self) -> Option<usize> {
        (0..self.open.len())
            .filter(|&i| !self.open[i].answering)
            .min_by_key(|&i| (self.open[i].served, self.open[i].since))
    }
}

impl Load {
    fn slots(&self) -> std::sync::MutexGuard<'_, Slots> {
        self.slots.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Marks connection `id`'s request as being answered (`true`) or answered (`false`);
    /// `false` when the connection was closed for another one meanwhile (its request is not
    /// answered then).
    fn answering(&self, id: u64, answering: bool) -> bool {
        let mut slots = self.slots();
        match slots.open.iter_mut().find(|s| s.id == id) {
            Some(s) => {
                s.answering = answering;
                s.served = true;
                s.since = Instant::now();
                true
            }
            None => false,
        }
    }
}

/// Body bytes reserved in [`Load::body_bytes`], given back when dropped (after the request was
/// answered).
struct BodyReservation {
    load: Arc<Load>,
    bytes: usize,
}

impl BodyReservation {
    /// Reserves `bytes`, or `None` when that would pass `limit`.
    fn take(load: &Arc<Load>, bytes: usize, limit: usize) -> Option<BodyReservation> {
        load.body_bytes
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |held| held.checked_add(bytes).filter(|&t| t <= limit))
            .ok()
            .map(|_| BodyReservation { load: Arc::clone(load), bytes })
    }
}

impl Drop for BodyReservation {
    fn drop(&mut self) {
        self.load.body_bytes.fetch_sub(self.bytes, Ordering::SeqCst);
    }
}

/// Connection `.1`'s slot in [`Load::slots`], given back when dropped (if it was not taken
/// for another connection before).
struct ConnectionSlot(Arc<Load>, u64);

impl Drop for ConnectionSlot {
    fn drop(&mut self) {
        self.0.slots().open.retain(|s| s.id != self.1);
    }
}

/// Reads one request within `limits`; `late` is the 408 message for one that does not arrive
/// in time.
fn read_request(
    r: &mut BufReader<DeadlineReader>,
    limits: &Limits,
    load: &Arc<Load>,
    late: &str,
) -> Result<(Request, bool, Option<BodyReservation>), ReadError> {
    let late = || ReadError::Respond(Response::error(408, late));
    let mut head = Vec::new();
    loop {
        let before = head.len();
        let n = r.by_ref().take((MAX_HEAD + 1 - head.len()) as u64).read_until(b'\n', &mut head);
        match n {
            Ok(0) => return Err(ReadError::Closed),
            Ok(_) => {}
            Err(e) if timed_out(&e) => return Err(late()),
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
            "content-length" => {
                if length.is_some() {
                    return Err(ReadError::Respond(Response::error(
                        400,
                        "duplicate Content-Length header: send exactly one",
                    )));
                }
                // Digits only (`+5`, `5 5` and `0x5` are refused, as RFC 9110 says).
                match value.parse::<usize>() {
                    Ok(n) if !value.is_empty() && value.bytes().all(|b| b.is_ascii_digit()) => length = Some(n),
                    _ => {
                        return Err(ReadError::Respond(Response::error(
                            400,
                            format!("Content-Length `{value}` is not a number"),
                        )));
                    }
                }
            }
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
    let reservation = if length > 0 {
        let Some(r) = BodyReservation::take(load, length, limits.max_body_bytes_in_flight) else {
            return Err(ReadError::Respond(
                Response::error(
                    503,
                    format!(
                        "busy: other request bodies are being received (at most {} bytes at once); try again",
                        limits.max_body_bytes_in_flight
                    ),
                )
                .with_header("Retry-After", "1".into()),
            ));
        };
        Some(r)
    } else {
        None
    };
    if expect_continue && length > 0 {
        // curl asks before sending larger bodies; answer at once instead of letting it wait.
        let conn = r.get_mut();
        let _ = write_all_by(&mut conn.stream, b"HTTP/1.1 100 Continue\r\n\r\n", conn.deadline);
    }
    // Read as the bytes come (the reservation bounds the total held over all connections).
    let mut body = Vec::with_capacity(length);
    match r.by_ref().take(length as u64).read_to_end(&mut body) {
        Ok(n) if n == length => {}
        Ok(_) => return Err(ReadError::Closed),
        Err(e) if timed_out(&e) => return Err(late()),
        Err(_) => return Err(ReadError::Closed),
    }
    let (path, query) = match target.split_once('?') {
        Some((p, q)) => (p.to_string(), q.to_string()),
        None => (target.to_string(), String::new()),
    };
    Ok((Request { method: method.to_string(), path, query, body }, keep_alive, reservation))
}

/// Writes all of `bytes` before `deadline` (each write waits at most until then).
fn write_all_by(w: &mut TcpStream, mut bytes: &[u8], deadline: Instant) -> std::io::Result<()> {
    while !bytes.is_empty() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(std::io::Error::new(std::io::ErrorKind::TimedOut, "response not taken in time"));
        }
        w.set_write_timeout(Some(left))?;
        match w.write(&bytes[..bytes.len().min(64 * 1024)]) {
            Ok(0) => return Err(std::io::ErrorKind::WriteZero.into()),
            Ok(n) => bytes = &bytes[n..],
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

fn write_response(w: &mut TcpStream, resp: &Response, keep_alive: bool, deadline: Instant) -> std::io::Result<()> {
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
    write_all_by(w, head.as_bytes(), deadline)?;
    write_all_by(w, &resp.body, deadline)
}

/// Serves connection `id` (accepted at `accepted`) within `limits` (`load`: the server's
/// shared state).
fn serve_limited(
    stream: TcpStream,
    handle: &dyn Fn(&Request) -> Response,
    limits: &Limits,
    load: &Arc<Load>,
    (id, accepted): (u64, Instant),
) {
    let _ = stream.set_nodelay(true);
    let Ok(mut writer) = stream.try_clone() else { return };
    let mut reader = BufReader::new(DeadlineReader { stream, deadline: Instant::now() });
    // The first request must arrive whole within `limits.first_request` of the connection.
    let mut first = Some(accepted + limits.first_request);
    loop {
        // Idle: wait for the first byte of the next request (nothing to answer if none comes).
        let idle = Instant::now() + limits.idle;
        reader.get_mut().deadline = first.map_or(idle, |f| f.min(idle));
        match reader.fill_buf() {
            Ok([]) | Err(_) => return,
            Ok(_) => {}
        }
        // From its first byte the request has `limits.request` to arrive whole.
        let whole = Instant::now() + limits.request;
        let (deadline, late) = match first {
            Some(f) if f < whole => (
                f,
                format!(
                    "the request did not arrive whole within {} s of connecting",
                    limits.first_request.as_secs_f64()
                ),
            ),
            _ => (whole, format!("the request did not arrive whole within {} s", limits.request.as_secs_f64())),
        };
        reader.get_mut().deadline = deadline;
        match read_request(&mut reader, limits, load, &late) {
            Ok((req, keep_alive, reservation)) => {
                first = None;
                if !load.answering(id, true) {
                    return; // closed for another connection meanwhile
                }
                let resp = handle(&req);
                drop(req);
                drop(reservation);
                let deadline = Instant::now() + limits.request;
                if write_response(&mut writer, &resp, keep_alive, deadline).is_err() || !keep_alive {
                    return;
                }
                if !load.answering(id, false) {
                    return;
                }
            }
            Err(ReadError::Respond(resp)) => {
                let _ = write_response(&mut writer, &resp, false, Instant::now() + limits.request);
                return;
            }
            Err(ReadError::Closed) => return,
        }
    }
}

/// Accepts connections on `listener` until the process ends, each served on its own thread
/// within `limits` and answered with `handle`. A connection beyond `limits.max_connections`
/// closes the one that has waited longest without sending a whole request (module docs), or,
/// when every connection's request is being answered, is answered 503 and closed at once (no
/// thread is started for it).
pub fn serve<H>(listener: TcpListener, limits: Limits, handle: H) -> std::io::Result<()>
where
    H: Fn(&Request) -> Response + Send + Sync + 'static,
{
    let handle = Arc::new(handle);
    let load = Arc::new(Load::default());
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else { continue };
        let accepted = Instant::now();
        let Ok(closer) = stream.try_clone() else { continue };
        let id = {
            let mut slots = load.slots();
            if slots.open.len() >= limits.max_connections {
                match slots.to_close() {
                    Some(i) => {
                        let _ = slots.open.swap_remove(i).stream.shutdown(std::net::Shutdown::Both);
                    }
                    None => {
                        let open = slots.open.len();
                        drop(slots);
                        let resp = Response::error(
                            503,
                            format!("busy: {open} connections are being answered, the most this server serves at once; try again"),
                        )
                        .with_header("Retry-After", "1".into());
                        let _ = write_response(&mut stream, &resp, false, Instant::now() + Duration::from_millis(200));
                        let _ = stream.shutdown(std::net::Shutdown::Write);
                        continue;
                    }
                }
            }
            let id = slots.next;
            slots.next += 1;
            slots.open.push(Slot { id, stream: closer, served: false, answering: false, since: accepted });
            id
        };
        let slot = ConnectionSlot(Arc::clone(&load), id);
        let handle = Arc::clone(&handle);
        let load = Arc::clone(&load);
        let _ = std::thread::Builder::new().name("meshdeco-http".into()).spawn(move || {
            let _slot = slot;
            serve_limited(stream, &*handle, &limits, &load, (id, accepted));
        });
    }
    Ok(())
}
