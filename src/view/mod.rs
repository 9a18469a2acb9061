//! `meshdeco view`: a local HTTP server with an interactive viewer page and a small API under
//! `/api/`, written once against [`crate::model::Model`] (no method-specific code here).
//!
//! - **Threads.** The model is loaded and used on one *model thread* (a trained model need not
//!   be `Send`, and solves are serialised anyway); each connection gets its own thread that
//!   parses and validates a request, hands the model work to the model thread as a closure and
//!   writes the answer ([`http`]). Everything that does not change (description, faces, rest
//!   positions, heat maps, segmentation) is computed once at start and answered without the
//!   model thread.
//! - **Binary geometry.** Shapes travel as little-endian arrays ([`shape_bytes`]): a `u32` vertex
//!   count N and weight count K, K `f64` weights (the model's own coordinates), K `f64` dials
//!   (the `meshdeco synthesize --weights` values), then N×3 `f32` positions (data units).
//! - **Safety.** Only the model directory and the `--data` frames named on the command line are
//!   read, both at start; no request names a file, and nothing is written (downloads are
//!   response bodies). Bodies are bounded ([`http::MAX_BODY`]), and so are connections, the
//!   time a request may take and the body bytes held at once ([`http::Limits`]); bad input
//!   gets a 400 with a message naming the field and value, and the server keeps serving. A
//!   panic inside a model call is caught and answered with a 500.
//! - **Assets.** The page (`web/index.html`, `web/app.js`: hand-written WebGL2, no library) is
//!   embedded with `include_str!`; nothing is fetched at run time.

pub mod http;
pub mod overview;
pub mod standalone;

use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Sender, channel};
use std::time::Instant;

use serde_json::{Value, json};

use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, TriMesh, Vec3};
use crate::metrics::erms;
use crate::model::{self, Constraints, Model, PoseOptions};
use crate::pipeline::load_model;
use http::{Request, Response};

/// The page.
pub const INDEX_HTML: &str = include_str!("web/index.html");
/// The page's script (WebGL2 viewer, panels, API client).
pub const APP_JS: &str = include_str!("web/app.js");
/// The standalone page's data source: the API's routes answered from embedded data
/// ([`standalone`]; the live page does not load it).
pub const EMBEDDED_JS: &str = include_str!("web/embedded.js");

/// Most pins one `/api/pose` request may hold.
pub const MAX_PINS: usize = 100;
/// Most solver iterations one `/api/pose` request may ask for.
pub const MAX_POSE_ITERATIONS: usize = 100;
/// Time an iterative pose (the autoencoder's) may hold the model thread; it then answers with
/// the best shape so far, so that a slider's decode waits at most about this long.
pub const POSE_TIME_LIMIT: std::time::Duration = std::time::Duration::from_millis(200);

/// What `meshdeco view` serves.
#[derive(Debug, Clone)]
pub struct ViewOptions {
    /// Model directory (or its model.json).
    pub model: PathBuf,
    /// Frames to step through (any path `meshdeco encode` accepts), optional.
    pub data: Option<String>,
    /// Address to listen on (port 0: any free port).
    pub addr: SocketAddr,
}

/// Work for the model thread.
type Job = Box<dyn FnOnce(&Session) -> Response + Send>;

/// What the model thread owns.
struct Session {
    model: Box<dyn Model>,
    /// The rest mesh's pin spreader (the landing correction of `/api/pose`).
    spreader: crate::geometry::pin_spread::PinSpread,
    frames: Option<MeshSequence>,
    data_name: String,
}

/// Everything that does not change while serving, computed at start.
struct Shared {
    description: Vec<u8>,
    rest: TriMesh,
    rest_bytes: Vec<u8>,
    faces_bytes: Vec<u8>,
    heat: Vec<Vec<u8>>,
    segmentation: Vec<u8>,
    k: usize,
    n_frames: usize,
    summary: String,
    /// Number of the newest `/api/pose` request: an older one still waiting for the model
    /// thread is answered 409 without solving (a newer drag supersedes it).
    pose_seq: Arc<AtomicU64>,
    /// The model kind's pose options ([`crate::model::Model::pose_defaults`]): what a request
    /// leaves out.
    pose_defaults: PoseOptions,
}

/// A started viewer: the model is loaded and the address bound; [`Viewer::serve`] answers.
pub struct Viewer {
    listener: TcpListener,
    shared: Arc<Shared>,
    jobs: Sender<Job>,
}

impl Viewer {
    /// Loads the model (and frames) on the model thread, computes the static answers and binds
    /// `options.addr`.
    pub fn start(options: &ViewOptions) -> Result<Viewer> {
        let (jobs, job_rx) = channel::<Job>();
        let (ready_tx, ready_rx) = channel::<Result<Shared>>();
        let opts = options.clone();
        std::thread::Builder::new()
            .name("meshdeco-model".into())
            .spawn(move || {
                let session = match open_session(&opts) {
                    Ok(s) => s,
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                let shared = describe(&session, &opts.model);
                let failed = shared.is_err();
                let _ = ready_tx.send(shared);
                if failed {
                    return;
                }
                for job in job_rx {
                    // The job's own channel carries the answer; a panic inside is turned into a 500.
                    let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| job(&session)));
                }
            })
            .map_err(|e| Error::Invalid(format!("cannot start the model thread: {e}")))?;
        let shared = ready_rx.recv().map_err(|_| Error::Invalid("the model thread stopped while loading".into()))??;
        let listener = TcpListener::bind(options.addr)
            .map_err(|e| Error::Invalid(format!("--host/--port: cannot listen on {}: {e}", options.addr)))?;
        Ok(Viewer { listener, shared: Arc::new(shared), jobs })
    }

    /// The bound address (the real port when 0 was asked for).
    pub fn local_addr(&self) -> Result<SocketAddr> {
        self.listener.local_addr().map_err(|e| Error::Invalid(format!("listening socket: {e}")))
    }

    /// One line about the model and data being served.
    pub fn summary(&self) -> &str {
        &self.shared.summary
    }

    /// Answers connections until the process ends (one thread per connection, within
    /// [`http::Limits::default`]: connections, request time, body bytes held).
    pub fn serve(self) -> Result<()> {
        let Viewer { listener, shared, jobs } = self;
        http::serve(listener, http::Limits::default(), move |req| route(req, &shared, &jobs))
            .map_err(|e| Error::Invalid(format!("serving: {e}")))
    }
}

fn open_session(opts: &ViewOptions) -> Result<Session> {
    let model = load_model(&opts.model)?;
    let (frames, data_name) = match &opts.data {
        Some(path) => {
            let seq = crate::preprocess::load_frames_for(path, &model.rest())?;
            model::check_connectivity(model.as_ref(), &seq, path)?;
            (Some(seq), path.clone())
        }
        None => (None, String::new()),
    };
    let spreader = model::spreader(model.as_ref());
    Ok(Session { model, spreader, frames, data_name })
}

fn f32_bytes(values: impl IntoIterator<Item = f64>) -> Vec<u8> {
    values.into_iter().flat_map(|v| (v as f32).to_le_bytes()).collect()
}

fn positions_bytes(p: &[Vec3]) -> Vec<u8> {
    f32_bytes(p.iter().flatten().copied())
}

/// The binary shape of the API: `u32` N, `u32` K, K `f64` weights, K `f64` dials, N×3 `f32`
/// positions (little-endian; the `f32` block starts at byte 8 + 16 K, 4-byte aligned).
pub fn shape_bytes(weights: &[f64], dials: &[f64], positions: &[Vec3]) -> Vec<u8> {
    let mut b = Vec::with_capacity(8 + 16 * weights.len() + 12 * positions.len());
    b.extend((positions.len() as u32).to_le_bytes());
    b.extend((weights.len() as u32).to_le_bytes());
    for v in weights.iter().chain(dials) {
        b.extend(v.to_le_bytes());
    }
    b.extend(positions_bytes(positions));
    b
}

/// Per component (index order) the range of its dial over the training weights (0 included,
/// padded by 10 %; [−1, 1] when the model stores none or they do not vary).
fn dial_ranges(model: &dyn Model) -> Result<(Vec<[f64; 2]>, bool)> {
    let k = model.n_components();
    let mut lo = vec![0.0f64; k];
    let mut hi = vec![0.0f64; k];
    let trained = match model.train_weights() {
        Some(ws) => {
            for w in &ws {
                let d = model.dials(w)?;
                for i in 0..k {
                    if d[i].is_finite() {
                        lo[i] = lo[i].min(d[i]);
                        hi[i] = hi[i].max(d[i]);
                    }
                }
            }
            !ws.is_empty()
        }
        None => false,
    };
    Ok((
        (0..k)
            .map(|i| {
                let span = hi[i] - lo[i];
                if span > 1e-12 { [lo[i] - 0.1 * span, hi[i] + 0.1 * span] } else { [-1.0, 1.0] }
            })
            .collect(),
        trained,
    ))
}

/// Groups components with the same support (vertices above 1e-6 of the component's peak) and
/// labels each vertex with the group of its dominant component: the region model's regions
/// (its components of one region share a support), one group per component elsewhere. Where
/// every component reaches every vertex (the autoencoder's feature changes are nowhere exactly
/// 0), each component is its own group and a vertex goes to the component largest there
/// relative to its own peak.
fn segmentation(components: &[model::Component], n: usize) -> (Vec<u32>, usize) {
    if let Some(soft) = soft_segmentation(components, n) {
        return soft;
    }
    let mut supports: Vec<Vec<bool>> = Vec::new();
    let mut group_of = Vec::with_capacity(components.len());
    for c in components {
        let peak = c.magnitudes.iter().cloned().fold(0.0, f64::max);
        let s: Vec<bool> = c.magnitudes.iter().map(|&m| m > 1e-6 * peak).collect();
        let g = supports.iter().position(|t| *t == s).unwrap_or_else(|| {
            supports.push(s);
            supports.len() - 1
        });
        group_of.push(g);
    }
    let labels = (0..n)
        .map(|v| {
            let best = components
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.magnitudes[v].total_cmp(&b.1.magnitudes[v]))
                .map(|(i, _)| group_of[i] as u32);
            best.unwrap_or(0)
        })
        .collect();
    (labels, supports.len())
}

/// [`segmentation`] of components that all reach every vertex: `None` unless that is so.
fn soft_segmentation(components: &[model::Component], n: usize) -> Option<(Vec<u32>, usize)> {
    let peaks: Vec<f64> = components.iter().map(|c| c.magnitudes.iter().cloned().fold(0.0, f64::max)).collect();
    let everywhere = components.len() > 1
        && components.iter().zip(&peaks).all(|(c, &p)| p > 0.0 && c.magnitudes.iter().all(|&m| m > 1e-6 * p));
    if !everywhere {
        return None;
    }
    let labels = (0..n)
        .map(|v| {
            (0..components.len())
                .max_by(|&a, &b| {
                    (components[a].magnitudes[v] / peaks[a]).total_cmp(&(components[b].magnitudes[v] / peaks[b]))
                })
                .unwrap_or(0) as u32
        })
        .collect();
    Some((labels, components.len()))
}

/// What the page's `/api/model` says about a model, with what it is computed from: the
/// description JSON, the components in index order and each vertex's segmentation label. Shared
/// by the live viewer and the standalone page ([`standalone`]); `frames`: the source and names
/// of the frames to step through.
pub(crate) struct Description {
    pub json: Value,
    pub components: Vec<model::Component>,
    pub labels: Vec<u32>,
}

pub(crate) fn describe_model(m: &dyn Model, name: &str, frames: Option<(&str, &[String])>) -> Result<Description> {
    let rest = m.rest();
    let n = rest.n_vertices();
    let k = m.n_components();
    let mut components = m.components()?;
    components.sort_by_key(|c| c.index);
    let (ranges, trained_ranges) = dial_ranges(m)?;
    let (labels, groups) = segmentation(&components, n);
    let w0 = m.start_weights(None)?;
    let d0 = m.dials(&w0)?;
    let (lo, hi) = rest.bounding_box();
    let (up, view, negative) = crate::mesh::render::auto_frame(&rest);
    let view_sign = if negative { -1 } else { 1 };
    let mut ranked = components.clone();
    ranked.sort_by_key(|c| c.rank);
    let comps: Vec<Value> = ranked
        .iter()
        .map(|c| {
            json!({
                "index": c.index,
                "rank": c.rank,
                "name": c.name,
                "center": c.center,
                "peak": c.magnitudes.iter().cloned().fold(0.0, f64::max),
                "range": ranges[c.index],
            })
        })
        .collect();
    let frames = frames.map(|(source, names)| json!({ "source": source, "names": names }));
    let json = json!({
        "model": name,
        "kind": m.kind().name(),
        "representation": m.representation().name(),
        "n_vertices": n,
        "n_faces": rest.n_faces(),
        "n_components": k,
        "components": comps,
        "ranges_from": if trained_ranges { "training weights" } else { "default [-1, 1]" },
        "start": { "weights": w0, "dials": d0, "description": m.start_description() },
        "bbox": { "min": lo, "max": hi },
        "up_axis": up,
        "view_axis": view,
        "view_sign": view_sign,
        "segmentation_groups": groups,
        "frames": frames,
        "pose_defaults": m.pose_defaults().to_json(),
        "pose_parameters": m.pose_parameters(),
    });
    Ok(Description { json, components, labels })
}

/// The name a page shows for the model at `model_path` (its directory's name).
pub(crate) fn model_name(model_path: &Path) -> String {
    model_path.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default()
}

fn describe(s: &Session, model_path: &Path) -> Result<Shared> {
    let m = s.model.as_ref();
    let rest = m.rest();
    let n = rest.n_vertices();
    let k = m.n_components();
    let frames = s.frames.as_ref().map(|f| (s.data_name.as_str(), f.names.as_slice()));
    let Description { json: desc, components, labels } = describe_model(m, &model_name(model_path), frames)?;
    let faces_bytes = rest.faces.iter().flatten().flat_map(|&i| (i as u32).to_le_bytes()).collect();
    let heat = components.iter().map(|c| f32_bytes(c.magnitudes.iter().copied())).collect();
    let summary = format!(
        "{} model {} ({} representation): {n} vertices, {} faces, {k} weights{}",
        m.kind().name(),
        model_path.display(),
        m.representation().name(),
        rest.n_faces(),
        s.frames.as_ref().map(|f| format!("; {} frames of {}", f.n_frames(), s.data_name)).unwrap_or_default()
    );
    Ok(Shared {
        description: desc.to_string().into_bytes(),
        rest_bytes: positions_bytes(&rest.positions),
        faces_bytes,
        heat,
        segmentation: labels.iter().flat_map(|l| l.to_le_bytes()).collect(),
        k,
        n_frames: s.frames.as_ref().map_or(0, |f| f.n_frames()),
        rest,
        summary,
        pose_seq: Arc::new(AtomicU64::new(0)),
        pose_defaults: m.pose_defaults(),
    })
}

/// Runs `job` on the model thread and waits for its answer.
fn on_model(jobs: &Sender<Job>, job: impl FnOnce(&Session) -> Response + Send + 'static) -> Response {
    let (tx, rx) = channel();
    let sent = jobs.send(Box::new(move |s: &Session| {
        let t0 = Instant::now();
        let r = job(s);
        let ms = 1e3 * t0.elapsed().as_secs_f64();
        let r = r.with_header("X-Compute-Ms", format!("{ms:.3}"));
        let _ = tx.send(r);
        Response::new(200, "text/plain", Vec::new())
    }));
    if sent.is_err() {
        return Response::error(500, "the model thread has stopped");
    }
    rx.recv().unwrap_or_else(|_| Response::error(500, "the model call failed (panicked); the server keeps serving"))
}

/// The API's error type: status and message.
type ApiResult<T> = std::result::Result<T, Response>;

fn bad(message: impl Into<String>) -> Response {
    Response::error(400, message)
}

fn parse_json(body: &[u8]) -> ApiResult<Value> {
    let v: Value = serde_json::from_slice(body)
        .map_err(|e| bad(format!("malformed JSON at line {} column {}: {e}", e.line(), e.column())))?;
    if !v.is_object() {
        return Err(bad("the request body must be a JSON object"));
    }
    Ok(v)
}

fn number(v: &Value, what: &str) -> ApiResult<f64> {
    let x = v.as_f64().ok_or_else(|| bad(format!("{what} must be a number, got {v}")))?;
    if !x.is_finite() {
        return Err(bad(format!("{what} is not finite ({x})")));
    }
    Ok(x)
}

/// A dense vector of K numbers from a JSON array of length K, or (`sparse`) from an object
/// `{"component index": value}` (unlisted: 0).
fn vector(v: &Value, what: &str, k: usize, sparse: bool) -> ApiResult<Vec<f64>> {
    match v {
        Value::Array(a) => {
            if a.len() != k {
                return Err(bad(format!("`{what}` has {} numbers, the model has {k} components", a.len())));
            }
            a.iter().enumerate().map(|(i, x)| number(x, &format!("`{what}`[{i}]"))).collect()
        }
        Value::Object(o) if sparse => {
            let mut out = vec![0.0; k];
            for (key, x) in o {
                let i: usize =
                    key.trim().parse().map_err(|_| bad(format!("`{what}`: key `{key}` is not a component index")))?;
                if i >= k {
                    return Err(bad(format!(
                        "`{what}`: unknown component {i} (the model has {k} components, 0..{})",
                        k.saturating_sub(1)
                    )));
                }
                out[i] = number(x, &format!("`{what}`[\"{key}\"]"))?;
            }
            Ok(out)
        }
        _ => Err(bad(format!(
            "`{what}` must be an array of {k} numbers{}",
            if sparse { " or an object {\"component index\": value}" } else { "" }
        ))),
    }
}

/// Dials or weights of a request body: exactly one of `dials` (as `meshdeco synthesize
/// --weights`) and `weights` (the model's own coordinates).
enum Coords {
    Dials(Vec<f64>),
    Weights(Vec<f64>),
}

fn coords(body: &Value, k: usize) -> ApiResult<Coords> {
    match (body.get("dials"), body.get("weights")) {
        (Some(d), None) => Ok(Coords::Dials(vector(d, "dials", k, true)?)),
        (None, Some(w)) => Ok(Coords::Weights(vector(w, "weights", k, false)?)),
        (Some(_), Some(_)) => Err(bad("give either `dials` or `weights`, not both")),
        (None, None) => Err(bad("missing `dials` (synthesis dials, as `meshdeco synthesize --weights`) or `weights`")),
    }
}

/// Weights, dials and positions of `c` (a 400 when decoding fails or leaves the finite range).
fn evaluate(m: &dyn Model, c: Coords) -> ApiResult<(Vec<f64>, Vec<f64>, Vec<Vec3>)> {
    let e = |e: Error| bad(e.to_string());
    let (w, d) = match c {
        Coords::Dials(d) => (m.synthesis_weights(&d).map_err(e)?, d),
        Coords::Weights(w) => {
            let d = m.dials(&w).map_err(e)?;
            (w, d)
        }
    };
    let p = m.decode(std::slice::from_ref(&w)).map_err(e)?.remove(0);
    check_drawable(&p, "these weights decode to", "pick smaller values")?;
    Ok((w, d, p))
}

/// Errors (400) when a position is not finite or beyond `f32` (the page's positions): "`what` a
/// non-finite position at vertex i; `advice`".
fn check_drawable(p: &[Vec3], what: &str, advice: &str) -> ApiResult<()> {
    match p.iter().position(|q| q.iter().any(|x| !x.is_finite() || x.abs() > f32::MAX as f64)) {
        Some(i) => Err(bad(format!("{what} a non-finite position at vertex {i}; {advice}"))),
        None => Ok(()),
    }
}

fn result(r: ApiResult<Response>) -> Response {
    r.unwrap_or_else(|e| e)
}

/// Dispatches one request.
fn route(req: &Request, shared: &Arc<Shared>, jobs: &Sender<Job>) -> Response {
    let get = req.method == "GET";
    let post = req.method == "POST";
    let path = req.path.as_str();
    let need = |ok: bool, allowed: &str| {
        if ok { None } else { Some(Response::error(405, format!("{} {path}: use {allowed}", req.method))) }
    };
    let api_get = |body: Vec<u8>, ct: &'static str| need(get, "GET").unwrap_or_else(|| Response::new(200, ct, body));
    match path {
        "/" | "/index.html" => api_get(INDEX_HTML.as_bytes().to_vec(), "text/html; charset=utf-8"),
        "/app.js" => api_get(APP_JS.as_bytes().to_vec(), "text/javascript; charset=utf-8"),
        "/api/model" => api_get(shared.description.clone(), "application/json"),
        "/api/rest" => api_get(shared.rest_bytes.clone(), "application/octet-stream"),
        "/api/faces" => api_get(shared.faces_bytes.clone(), "application/octet-stream"),
        "/api/segmentation" => api_get(shared.segmentation.clone(), "application/octet-stream"),
        "/api/decode" => need(post, "POST").unwrap_or_else(|| result(decode(req, shared, jobs))),
        "/api/pose" => need(post, "POST").unwrap_or_else(|| result(pose(req, shared, jobs))),
        "/api/export" => need(post, "POST").unwrap_or_else(|| result(export(req, shared, jobs))),
        _ => {
            if let Some(i) = path.strip_prefix("/api/heat/") {
                if let Some(r) = need(get, "GET") {
                    return r;
                }
                return match i.parse::<usize>() {
                    Ok(i) if i < shared.k => Response::binary(shared.heat[i].clone()),
                    _ => bad(format!(
                        "unknown component `{i}` (the model has {} components, 0..{})",
                        shared.k,
                        shared.k.saturating_sub(1)
                    )),
                };
            }
            if let Some(i) = path.strip_prefix("/api/frame/") {
                if let Some(r) = need(get, "GET") {
                    return r;
                }
                return result(frame(i, shared, jobs));
            }
            Response::error(404, format!("no such page or endpoint: {path}"))
        }
    }
}

fn decode(req: &Request, shared: &Shared, jobs: &Sender<Job>) -> ApiResult<Response> {
    let body = parse_json(&req.body)?;
    let c = coords(&body, shared.k)?;
    Ok(on_model(jobs, move |s| {
        result(evaluate(s.model.as_ref(), c).map(|(w, d, p)| Response::binary(shape_bytes(&w, &d, &p))))
    }))
}

/// `POST /api/pose`: `{"constraints": [{"vertex": v, "target": [x, y, z]}, …], "start": [K
/// weights] (optional), "gamma", "beta", "max_iterations", "prior", "spread", "freeze", "reach" (optional;
/// the model kind's defaults otherwise)}`: the
/// landed shape ([`model::landed_pose`]) with the model's weights and dials.
fn pose(req: &Request, shared: &Shared, jobs: &Sender<Job>) -> ApiResult<Response> {
    let body = parse_json(&req.body)?;
    let n = shared.rest.n_vertices();
    let list = body
        .get("constraints")
        .ok_or_else(|| bad("missing `constraints`: an array of {\"vertex\": index, \"target\": [x, y, z]}"))?;
    let Constraints { vertices, targets } =
        Constraints::from_json("`constraints`", list, n).map_err(|e| bad(e.to_string()))?;
    if vertices.len() > MAX_PINS {
        return Err(bad(format!(
            "`constraints`: {} pins; a pose request takes at most {MAX_PINS} (the page's pins are a person's clicks)",
            vertices.len()
        )));
    }
    crate::pipeline::pose::check_targets(&shared.rest, &vertices, &targets).map_err(|e| bad(e.to_string()))?;
    let start = match body.get("start") {
        Some(s) => Some(vector(s, "start", shared.k, false)?),
        None => None,
    };
    let d = shared.pose_defaults;
    let param = |key: &str, default: f64| -> ApiResult<f64> {
        match body.get(key) {
            None => Ok(default),
            Some(v) => number(v, &format!("`{key}`")),
        }
    };
    let iterations = param("max_iterations", d.max_iterations as f64)?;
    if !(1.0..=MAX_POSE_ITERATIONS as f64).contains(&iterations) || iterations.fract() != 0.0 {
        return Err(bad(format!(
            "`max_iterations` {iterations}: must be an integer from 1 to {MAX_POSE_ITERATIONS} (the viewer's bound per request)"
        )));
    }
    let prior = match body.get("prior") {
        None => d.prior,
        Some(v) => v
            .as_str()
            .and_then(crate::model::PosePrior::parse)
            .ok_or_else(|| bad(format!("`prior` {v}: must be \"shape\", \"weights\" or \"data\"")))?,
    };
    let freeze = match body.get("freeze") {
        None => d.freeze,
        Some(v) => v.as_bool().ok_or_else(|| bad(format!("`freeze` {v}: must be true or false")))?,
    };
    let options = PoseOptions {
        gamma: param("gamma", d.gamma)?,
        beta: param("beta", d.beta)?,
        max_iterations: iterations as usize,
        prior,
        time_limit: Some(POSE_TIME_LIMIT),
        spread: param("spread", d.spread)?,
        freeze,
        reach: param("reach", d.reach)?,
    };
    options.validate().map_err(|e| bad(e.to_string()))?;
    let seq = shared.pose_seq.clone();
    let mine = seq.fetch_add(1, Ordering::SeqCst) + 1;
    Ok(on_model(jobs, move |s| {
        if seq.load(Ordering::SeqCst) != mine {
            return Response::error(409, "superseded by a newer pose request; not solved");
        }
        let m = s.model.as_ref();
        let r = (|| -> ApiResult<Response> {
            let w0 = match start {
                Some(w) => w,
                None => m.start_weights(None).map_err(|e| bad(e.to_string()))?,
            };
            let r = model::landed_pose(m, &s.spreader, &vertices, &targets, &w0, &options)
                .map_err(|e| bad(e.to_string()))?;
            let d = m.dials(&r.weights).map_err(|e| bad(e.to_string()))?;
            check_drawable(&r.positions, "this pose gives", "drag less far")?;
            Ok(Response::binary(shape_bytes(&r.weights, &d, &r.positions)))
        })();
        result(r)
    }))
}

/// `GET /api/frame/<i>`: the frame, the model's reconstruction and the per-vertex error.
fn frame(i: &str, shared: &Shared, jobs: &Sender<Job>) -> ApiResult<Response> {
    if shared.n_frames == 0 {
        return Err(bad("no frames: start `meshdeco view` with --data PATH"));
    }
    let f: usize = i.parse().map_err(|_| bad(format!("frame `{i}` is not a frame index")))?;
    if f >= shared.n_frames {
        return Err(bad(format!("frame {f} out of range ({} frames, 0..{})", shared.n_frames, shared.n_frames - 1)));
    }
    Ok(on_model(jobs, move |s| {
        let m = s.model.as_ref();
        let frames = s.frames.as_ref().expect("frames checked");
        let one = frames.select(&[f]);
        let r = (|| -> ApiResult<Response> {
            let e = model::encode_frames(m, &one, &s.data_name, None).map_err(|e| bad(e.to_string()))?;
            let truth = &one.frames[0];
            let rec = &e.reconstructions[0];
            // The per-vertex error of the frame's Erms: after the model's alignment.
            let shift = erms::alignment_shift(truth, rec, e.alignment);
            let err: Vec<f64> =
                truth.iter().zip(rec).map(|(t, r)| erms::vertex_squared_error(*t, *r, shift).sqrt()).collect();
            let w = &e.weights[0];
            let d = m.dials(w).map_err(|e| bad(e.to_string()))?;
            let mut b = shape_bytes(w, &d, rec);
            b.extend(positions_bytes(truth));
            b.extend(f32_bytes(err));
            Ok(Response::binary(b)
                .with_header("X-Frame-Erms", format!("{}", e.total_erms))
                .with_header("X-Frame-Name", one.names.first().cloned().unwrap_or_default().replace(['\r', '\n'], " ")))
        })();
        result(r)
    }))
}

/// `POST /api/export`: `{"format": "obj" | "ply" | "json", "dials" | "weights"}` → the shape as
/// a mesh file, or `{"dials": […], "weights": […]}` that `meshdeco synthesize --weights-file`
/// reads back.
fn export(req: &Request, shared: &Shared, jobs: &Sender<Job>) -> ApiResult<Response> {
    let body = parse_json(&req.body)?;
    let format = body.get("format").and_then(Value::as_str).unwrap_or("obj").to_string();
    if !["obj", "ply", "json"].contains(&format.as_str()) {
        return Err(bad(format!("`format` `{format}`: must be obj, ply or json")));
    }
    let c = coords(&body, shared.k)?;
    let faces = shared.rest.faces.clone();
    Ok(on_model(jobs, move |s| {
        let m = s.model.as_ref();
        let r = (|| -> ApiResult<Response> {
            let (w, d, p) = evaluate(m, c)?;
            let mesh = TriMesh::new(p, faces);
            let text = |b: crate::error::Result<Vec<u8>>| -> ApiResult<Response> {
                Ok(Response::new(200, "text/plain; charset=utf-8", b.map_err(|e| bad(e.to_string()))?))
            };
            match format.as_str() {
                "json" => Ok(Response::json(200, &json!({ "kind": m.kind().name(), "dials": d, "weights": w }))),
                "ply" => text(crate::mesh::ply_bytes("shape.ply", &mesh)),
                _ => text(crate::mesh::obj_bytes("shape.obj", &mesh)),
            }
        })();
        result(r)
    }))
}
