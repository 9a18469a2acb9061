//! `meshdeco._native`: the PyO3 binding of the meshdeco library (NumPy arrays in and out).
//!
//! The public Python API is `python/meshdeco/__init__.py`, which checks and converts arguments
//! (dtypes, shapes, memory order) and calls the functions here; they call the library directly
//! (no subprocess). Conventions:
//!
//! - positions are `float64` in the data's own units, `F × N × 3` (frames) or `N × 3` (one
//!   mesh); triangles are `int64`, `T × 3`, 0-based; weights are `float64`, `F × K`;
//! - library errors become `meshdeco.Error` subclasses carrying the library's message
//!   (`FileNotFoundError` / `OSError` for files, `ValueError` for bad input, config and parse
//!   errors, `ArithmeticError` for numerical failures);
//! - every library call runs with the GIL released and inside `catch_unwind`, so a panic is a
//!   `meshdeco.Error`, never a crash; training runs on a worker thread while the calling thread
//!   forwards progress to Python and checks for signals (Ctrl-C stops training).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use meshdeco::config::Config;
use meshdeco::mesh::{self, MeshSequence, Vec3};
use meshdeco::model::{Constraints, Model, PosePrior};
use meshdeco::pipeline::{self, Progress, TrainOptions};
use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

// ---------------------------------------------------------------------------------------------
// Errors

/// The Python exception for a library error: a class of `meshdeco._errors` chosen by the
/// variant, carrying the library's message.
fn lib_err(e: meshdeco::Error) -> PyErr {
    let class = match &e {
        meshdeco::Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => "FileNotFound",
        meshdeco::Error::Io { .. } => "FileError",
        meshdeco::Error::Parse { .. } | meshdeco::Error::Mismatch { .. } => "ParseError",
        meshdeco::Error::Config { .. } => "ConfigError",
        meshdeco::Error::Invalid(_) => "InvalidInput",
        meshdeco::Error::Numerical(_) => "NumericalError",
    };
    py_error(class, e.to_string())
}

/// An exception of class `class` of `meshdeco._errors` with `message`.
fn py_error(class: &str, message: String) -> PyErr {
    Python::attach(|py| {
        let made = py.import("meshdeco._errors").and_then(|m| m.getattr(class)).and_then(|c| c.call1((&message,)));
        match made {
            Ok(obj) => PyErr::from_value(obj),
            Err(e) => e,
        }
    })
}

/// A `meshdeco.ArgumentError` (a `ValueError`) whose message starts with the argument's name.
fn arg_err(arg: &str, message: impl std::fmt::Display) -> PyErr {
    py_error("ArgumentError", format!("{arg}: {message}"))
}

/// Runs a library call with the GIL released; a panic becomes a `meshdeco.Error`.
fn run<T: Send>(py: Python<'_>, f: impl FnOnce() -> meshdeco::Result<T> + Send) -> PyResult<T> {
    py.detach(|| caught(f)).map_err(|e| match e {
        Failure::Lib(e) => lib_err(e),
        Failure::Panic(m) => py_error("Error", format!("internal error (a bug in meshdeco, please report it): {m}")),
    })
}

enum Failure {
    Lib(meshdeco::Error),
    Panic(String),
}

fn caught<T>(f: impl FnOnce() -> meshdeco::Result<T>) -> Result<T, Failure> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(Failure::Lib),
        Err(p) => Err(Failure::Panic(panic_message(p.as_ref()))),
    }
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".to_string())
}

// ---------------------------------------------------------------------------------------------
// Arrays

/// Positions `N × 3` (`float64`).
type Points<'py> = Bound<'py, PyArray2<f64>>;
/// Triangles `T × 3` (`int64`).
type Faces<'py> = Bound<'py, PyArray2<i64>>;
/// Frames `F × N × 3` (`float64`).
type Frames<'py> = Bound<'py, PyArray3<f64>>;

/// A C-contiguous view's slice, or a copy in C order of any other layout.
fn c_order<'a, D: numpy::ndarray::Dimension>(
    a: &'a numpy::ndarray::ArrayView<'_, f64, D>,
) -> std::borrow::Cow<'a, [f64]> {
    match a.as_slice() {
        Some(s) => std::borrow::Cow::Borrowed(s),
        None => std::borrow::Cow::Owned(a.iter().copied().collect()),
    }
}

fn c_order_i64<D: numpy::ndarray::Dimension>(a: &numpy::ndarray::ArrayView<'_, i64, D>) -> Vec<i64> {
    match a.as_slice() {
        Some(s) => s.to_vec(),
        None => a.iter().copied().collect(),
    }
}

/// Positions `N × 3` of one mesh as an `N × 3` array.
fn points_to_py<'py>(py: Python<'py>, p: &[Vec3]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = p.iter().flatten().copied().collect();
    let a = Array2::from_shape_vec((p.len(), 3), flat).expect("N × 3");
    PyArray2::from_owned_array(py, a)
}

fn faces_to_py<'py>(py: Python<'py>, f: &[[usize; 3]]) -> Bound<'py, PyArray2<i64>> {
    let flat: Vec<i64> = f.iter().flatten().map(|&v| v as i64).collect();
    PyArray2::from_owned_array(py, Array2::from_shape_vec((f.len(), 3), flat).expect("T × 3"))
}

fn frames_to_py<'py>(py: Python<'py>, frames: Vec<f64>, f: usize, n: usize) -> Bound<'py, PyArray3<f64>> {
    PyArray3::from_owned_array(py, Array3::from_shape_vec((f, n, 3), frames).expect("F × N × 3"))
}

fn flatten_frames(frames: &[Vec<Vec3>]) -> Vec<f64> {
    let n: usize = frames.iter().map(Vec::len).sum();
    let mut out = Vec::with_capacity(3 * n);
    for f in frames {
        out.extend(f.iter().flatten());
    }
    out
}

/// Frames `F × N × 3` from an array, checked (finite) by the library; `what` names the argument.
fn frames_arg(what: &str, a: &PyReadonlyArray3<'_, f64>, faces: Vec<[usize; 3]>) -> PyResult<MeshSequence> {
    let view = a.as_array();
    let (f, n, c) = view.dim();
    if c != 3 || f == 0 || n == 0 {
        return Err(arg_err(what, format!("shape ({f}, {n}, {c}); expected (F, N, 3) with F, N ≥ 1")));
    }
    let flat = c_order(&view);
    let seq = mesh::arrays::sequence_from_arrays((what, "faces"), &flat, f, &[0, 0, 0], None).map_err(lib_err)?;
    Ok(MeshSequence { faces, ..seq })
}

/// Weights `F × K` as one vector per frame, each checked finite.
fn weights_arg(what: &str, a: &PyReadonlyArray2<'_, f64>, k: usize) -> PyResult<Vec<Vec<f64>>> {
    let view = a.as_array();
    let (f, kk) = view.dim();
    if kk != k {
        return Err(arg_err(what, format!("shape ({f}, {kk}); the model has {k} components: expected (F, {k})")));
    }
    if let Some(((i, j), x)) = view.indexed_iter().find(|(_, x)| !x.is_finite()) {
        return Err(arg_err(what, format!("row {i}, column {j} is {x} (must be finite)")));
    }
    Ok(view.outer_iter().map(|r| r.to_vec()).collect())
}

// ---------------------------------------------------------------------------------------------
// The model

/// A trained model behind a mutex. Every concrete model type is `Send` (checked below), so the
/// box may move between threads; the mutex makes shared use from Python threads safe whatever
/// the model's interior caches do.
struct SendModel(Box<dyn Model>);

// SAFETY: `pipeline::load_model` and `pipeline::fit` only ever box the three types asserted
// `Send` here; the trait object just does not carry the bound.
unsafe impl Send for SendModel {}
const _: () = {
    const fn send<T: Send>() {}
    send::<meshdeco::pipeline::linear::LinearArtifact>();
    send::<meshdeco::pipeline::region::RegionArtifact>();
    send::<meshdeco::pipeline::autoencoder::AeArtifact>();
};

/// A trained meshdeco model (see `meshdeco.Model` for the documented wrapper).
#[pyclass(module = "meshdeco._native", name = "NativeModel", frozen)]
struct NativeModel {
    model: Mutex<SendModel>,
    /// `metrics.json` of the training (JSON text), when known.
    metrics: Option<String>,
    /// Where the artefact directory is, when there is one.
    directory: Option<PathBuf>,
    n_vertices: usize,
    n_components: usize,
}

impl NativeModel {
    fn new(model: Box<dyn Model>, metrics: Option<String>, directory: Option<PathBuf>) -> Self {
        let n_vertices = model.rest().n_vertices();
        let n_components = model.n_components();
        NativeModel { model: Mutex::new(SendModel(model)), metrics, directory, n_vertices, n_components }
    }
    /// The name a page shows: the artefact directory's, else `model`.
    fn page_name(&self) -> String {
        self.directory
            .as_ref()
            .and_then(|d| d.file_name())
            .map(|f| f.to_string_lossy().to_string())
            .unwrap_or_else(|| "model".into())
    }
    /// Runs `f` on the model with the GIL released (panics caught).
    fn with<T: Send>(&self, py: Python<'_>, f: impl FnOnce(&dyn Model) -> meshdeco::Result<T> + Send) -> PyResult<T> {
        run(py, || {
            let guard = self.model.lock().unwrap_or_else(|p| p.into_inner());
            f(guard.0.as_ref())
        })
    }
}

#[pymethods]
impl NativeModel {
    #[getter]
    fn kind(&self, py: Python<'_>) -> PyResult<String> {
        self.with(py, |m| Ok(m.kind().name().to_string()))
    }
    #[getter]
    fn representation(&self, py: Python<'_>) -> PyResult<String> {
        self.with(py, |m| Ok(m.representation().name().to_string()))
    }
    #[getter]
    fn n_components(&self) -> usize {
        self.n_components
    }
    #[getter]
    fn n_vertices(&self) -> usize {
        self.n_vertices
    }
    #[getter]
    fn rest<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let r = self.with(py, |m| Ok(m.rest()))?;
        Ok(points_to_py(py, &r.positions))
    }
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<i64>>> {
        let r = self.with(py, |m| Ok(m.rest()))?;
        Ok(faces_to_py(py, &r.faces))
    }
    #[getter]
    fn train_frames(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        self.with(py, |m| Ok(m.train_frames().to_vec()))
    }
    #[getter]
    fn train_weights<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        let w = self.with(py, |m| Ok(m.train_weights()))?;
        let k = self.n_components;
        Ok(w.map(|w| {
            let flat: Vec<f64> = w.iter().flatten().copied().collect();
            PyArray2::from_owned_array(py, Array2::from_shape_vec((w.len(), k), flat).expect("F × K"))
        }))
    }
    #[getter]
    fn metrics_json(&self) -> Option<String> {
        self.metrics.clone()
    }
    #[getter]
    fn directory(&self) -> Option<String> {
        self.directory.as_ref().map(|p| p.display().to_string())
    }

    /// List of (index, rank, name, centre, magnitude array).
    fn components<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let comps = self.with(py, |m| m.components())?;
        comps
            .into_iter()
            .map(|c| {
                let d = PyDict::new(py);
                d.set_item("index", c.index)?;
                d.set_item("rank", c.rank)?;
                d.set_item("name", c.name)?;
                d.set_item("centre", c.center)?;
                d.set_item("magnitude", PyArray1::from_vec(py, c.magnitudes))?;
                Ok(d)
            })
            .collect()
    }

    fn encode<'py>(&self, py: Python<'py>, frames: PyReadonlyArray3<'py, f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let (_, n, _) = frames.as_array().dim();
        if n != self.n_vertices {
            return Err(arg_err("frames", format!("{n} vertices per frame; the model has {}", self.n_vertices)));
        }
        let seq = frames_arg("frames", &frames, Vec::new())?;
        let k = self.n_components;
        let flat = self.with(py, move |m| {
            let seq = MeshSequence { faces: m.rest().faces, ..seq };
            Ok(m.encode(&seq)?.into_iter().flatten().collect::<Vec<f64>>())
        })?;
        let f = flat.len() / k.max(1);
        Ok(PyArray2::from_owned_array(py, Array2::from_shape_vec((f, k), flat).expect("F × K")))
    }

    /// Decodes `F × K` weights to `F × N × 3` positions, `chunk` frames per library call.
    fn decode<'py>(&self, py: Python<'py>, weights: PyReadonlyArray2<'py, f64>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let w = weights_arg("weights", &weights, self.n_components)?;
        let n = self.n_vertices;
        let f = w.len();
        let flat = self.with(py, move |m| {
            let mut out = Vec::with_capacity(f * n * 3);
            for chunk in w.chunks(64) {
                let frames = m.decode(chunk)?;
                for fr in &frames {
                    out.extend(fr.iter().flatten());
                }
            }
            Ok(out)
        })?;
        Ok(frames_to_py(py, flat, f, n))
    }

    fn synthesize<'py>(
        &self,
        py: Python<'py>,
        dials: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let d = dials.as_array().to_vec();
        if d.len() != self.n_components {
            return Err(arg_err(
                "dials",
                format!("{} numbers; the model has {} components", d.len(), self.n_components),
            ));
        }
        if let Some((i, x)) = d.iter().enumerate().find(|(_, x)| !x.is_finite()) {
            return Err(arg_err("dials", format!("entry {i} is {x} (must be finite)")));
        }
        let p = self.with(py, move |m| meshdeco::model::synthesize(m, &d))?;
        Ok(points_to_py(py, &p))
    }

    /// Poses: `targets_json` is `{"vertex": [x, y, z], …}` (data units); `start` an `N × 3`
    /// shape whose encoding is the start, or the model's default; `spread` the landing
    /// correction's radius (fraction of the bounding-box diagonal, 0: the model's shape only).
    #[pyo3(signature = (targets_json, start=None, gamma=None, beta=None, max_iterations=None, prior=None, spread=None))]
    #[allow(clippy::too_many_arguments)]
    fn pose<'py>(
        &self,
        py: Python<'py>,
        targets_json: &str,
        start: Option<PyReadonlyArray2<'py, f64>>,
        gamma: Option<f64>,
        beta: Option<f64>,
        max_iterations: Option<usize>,
        prior: Option<&str>,
        spread: Option<f64>,
    ) -> PyResult<(Points<'py>, Bound<'py, PyArray1<f64>>, Points<'py>)> {
        let value: serde_json::Value =
            serde_json::from_str(targets_json).map_err(|e| arg_err("targets", format!("not JSON: {e}")))?;
        let constraints = Constraints::from_json("targets", &value, self.n_vertices).map_err(lib_err)?;
        let start = match start {
            None => None,
            Some(s) => {
                let v = s.as_array();
                if v.dim() != (self.n_vertices, 3) {
                    return Err(arg_err(
                        "start",
                        format!("shape {:?}; expected ({}, 3), one position per vertex", v.dim(), self.n_vertices),
                    ));
                }
                let flat = c_order(&v);
                Some(mesh::arrays::mesh_from_arrays(("start", "faces"), &flat, &[0, 0, 0]).map_err(lib_err)?.positions)
            }
        };
        // The model kind's defaults (`meshdeco pose`'s and the viewer's).
        let mut options = self.with(py, |m| Ok(m.pose_defaults()))?;
        if let Some(g) = gamma {
            options.gamma = g;
        }
        if let Some(b) = beta {
            options.beta = b;
        }
        if let Some(i) = max_iterations {
            options.max_iterations = i;
        }
        if let Some(p) = prior {
            options.prior = PosePrior::parse(p)
                .ok_or_else(|| arg_err("prior", format!("`{p}`: expected \"shape\", \"weights\" or \"data\"")))?;
        }
        if let Some(s) = spread {
            options.spread = s;
        }
        options.validate().map_err(lib_err)?;
        let r = self.with(py, move |m| {
            let w0 = m.start_weights(start.as_deref())?;
            let spreader = meshdeco::model::spreader(m);
            meshdeco::model::landed_pose(m, &spreader, &constraints.vertices, &constraints.targets, &w0, &options)
        })?;
        Ok((points_to_py(py, &r.positions), PyArray1::from_vec(py, r.weights), points_to_py(py, &r.start)))
    }

    /// Which pose options this model reads.
    fn pose_parameters(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        self.with(py, |m| Ok(m.pose_parameters().iter().map(|s| s.to_string()).collect()))
    }

    /// The standalone viewer page (one self-contained HTML document; `meshdeco export --out
    /// view.html`), titled `name` (default: the artefact directory's name, else the method).
    #[pyo3(signature = (name=None))]
    fn html(&self, py: Python<'_>, name: Option<String>) -> PyResult<String> {
        let name = name.unwrap_or_else(|| self.page_name());
        self.with(py, move |m| {
            meshdeco::view::standalone::page(m, &name, &meshdeco::export::gltf::ExportOptions::default())
                .map(|(h, _)| h)
        })
    }

    /// Writes `.glb` (glTF 2.0 morph targets), `.usda` (USD blend shapes), `.html` (the
    /// standalone page) or `.h5` (the SPLOCS reference's layout); returns the report.
    #[pyo3(signature = (path, animation=false, fps=30.0, colors=false, up="auto", bake=false))]
    #[allow(clippy::too_many_arguments)]
    fn export<'py>(
        &self,
        py: Python<'py>,
        path: PathBuf,
        animation: bool,
        fps: f64,
        colors: bool,
        up: &str,
        bake: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        use meshdeco::export::gltf::{ExportOptions, UpAxis, fps_error};
        if let Some(e) = fps_error(fps) {
            return Err(arg_err("fps", e.trim_start_matches("--fps ")));
        }
        let up_axis =
            UpAxis::parse(up).ok_or_else(|| arg_err("up", format!("`{up}`: expected auto, x, y, z, +x, -y, …")))?;
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        if !["glb", "usda", "html", "h5"].contains(&ext.as_str()) {
            return Err(arg_err(
                "path",
                format!("`{}`: the file name must end in .glb, .usda, .html or .h5", path.display()),
            ));
        }
        if ext == "html" || ext == "h5" {
            if animation || colors || bake || up != "auto" {
                return Err(arg_err(
                    "path",
                    format!("`{}`: animation, colors, up and bake apply to .glb and .usda only", path.display()),
                ));
            }
            let name = self.page_name();
            let d = PyDict::new(py);
            if ext == "html" {
                let r = self.with(py, move |m| {
                    meshdeco::view::standalone::export_html(m, &name, &path, &ExportOptions::default())
                })?;
                d.set_item("targets", r.targets)?;
                d.set_item("targets_kind", r.targets_kind)?;
                d.set_item("additivity_erms", r.additivity_erms)?;
                d.set_item("storage", r.storage.name())?;
                d.set_item("frames", r.frames)?;
                d.set_item("bytes", r.bytes)?;
            } else {
                let r = self.with(py, move |m| meshdeco::export::hdf5::export_splocs_h5(m, &path))?;
                d.set_item("components", r.components)?;
                d.set_item("frames", r.frames)?;
                d.set_item("blend_error", r.blend_error)?;
                d.set_item("bytes", r.bytes)?;
            }
            return Ok(d);
        }
        let options = ExportOptions { animation, fps, colors, up: up_axis, bake, ..ExportOptions::default() };
        let report = self.with(py, move |m| {
            if ext == "glb" {
                meshdeco::export::gltf::export_glb(m, &path, &options)
            } else {
                meshdeco::export::usd::export_usda(m, &path, &options)
            }
        })?;
        let d = PyDict::new(py);
        d.set_item("targets", report.targets)?;
        d.set_item("names", report.names)?;
        d.set_item("additivity_erms", report.additivity_erms)?;
        d.set_item("additivity_extreme_erms", report.additivity_extreme_erms)?;
        d.set_item("targets_fitted", report.targets_fitted)?;
        d.set_item("up_axis", report.up_axis)?;
        d.set_item("animation_frames", report.animation_frames)?;
        d.set_item("bytes", report.bytes)?;
        Ok(d)
    }
}

// ---------------------------------------------------------------------------------------------
// Meshes

/// `(vertices N × 3, faces T × 3)` of one mesh file (OBJ, PLY, OFF).
#[pyfunction]
fn load_mesh<'py>(py: Python<'py>, path: PathBuf) -> PyResult<(Points<'py>, Faces<'py>)> {
    let m = run(py, || mesh::load_mesh(&path))?;
    Ok((points_to_py(py, &m.positions), faces_to_py(py, &m.faces)))
}

/// `(frames F × N × 3, faces T × 3, names)` of a directory, glob or `synthetic:<name>`.
#[pyfunction]
fn load_sequence<'py>(py: Python<'py>, path: &str) -> PyResult<(Frames<'py>, Faces<'py>, Vec<String>)> {
    let spec = path.to_string();
    let (seq, flat) = run(py, move || {
        let seq = meshdeco::preprocess::load_frames(&spec)?;
        let flat = flatten_frames(&seq.frames);
        Ok((seq, flat))
    })?;
    let (f, n) = (seq.n_frames(), seq.n_vertices());
    Ok((frames_to_py(py, flat, f, n), faces_to_py(py, &seq.faces), seq.names))
}

/// Writes one mesh; the format follows the extension (`.obj`, `.ply`, `.off`).
#[pyfunction]
fn save_mesh(
    py: Python<'_>,
    path: PathBuf,
    vertices: PyReadonlyArray2<'_, f64>,
    faces: PyReadonlyArray2<'_, i64>,
) -> PyResult<()> {
    let v = vertices.as_array();
    if v.ncols() != 3 || v.nrows() == 0 {
        return Err(arg_err("vertices", format!("shape {:?}; expected (N, 3) with N ≥ 1", v.dim())));
    }
    let fv = faces.as_array();
    if fv.ncols() != 3 {
        return Err(arg_err("faces", format!("shape {:?}; expected (T, 3)", fv.dim())));
    }
    let m = mesh::arrays::mesh_from_arrays(("vertices", "faces"), &c_order(&v), &c_order_i64(&fv)).map_err(lib_err)?;
    run(py, move || mesh::write_mesh(&path, &m))
}

// ---------------------------------------------------------------------------------------------
// Training

/// A Python value of a config dict as TOML; `key` names it in errors.
fn toml_value(key: &str, v: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    let bad = |what: String| arg_err("config", format!("key `{key}`: {what}"));
    if v.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(v.extract()?));
    }
    if v.is_instance_of::<PyInt>() {
        return v.extract::<i64>().map(toml::Value::Integer).map_err(|_| bad(format!("{v} does not fit in 64 bits")));
    }
    if v.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(v.extract()?));
    }
    if v.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(v.extract()?));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        return Ok(toml::Value::Table(toml_table(key, d)?));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let items = v.try_iter()?.enumerate().map(|(i, x)| toml_value(&format!("{key}[{i}]"), &x?));
        return items.collect::<PyResult<Vec<_>>>().map(toml::Value::Array);
    }
    // numpy scalars and path-likes: their Python value.
    let py = v.py();
    if let Ok(path) = py.import("os").and_then(|os| os.call_method1("fspath", (v,))) {
        return Ok(toml::Value::String(path.extract()?));
    }
    if let Ok(item) = v.call_method0("item")
        && !item.is(v)
    {
        return toml_value(key, &item);
    }
    Err(bad(format!("{} is not a TOML value (bool, int, float, str, list, dict)", v.get_type().name()?)))
}

fn toml_table(prefix: &str, d: &Bound<'_, PyDict>) -> PyResult<toml::Table> {
    let mut t = toml::Table::new();
    for (k, v) in d.iter() {
        let k: String = k.extract().map_err(|_| arg_err("config", format!("key {k} of `{prefix}` is not a string")))?;
        let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
        if v.is_none() {
            continue; // None: the key's default
        }
        t.insert(k, toml_value(&key, &v)?);
    }
    Ok(t)
}

/// Progress events sent from the training thread to the calling thread.
enum Event {
    Stage(String, u64),
    Step(u64, String),
}

struct ChannelProgress(mpsc::Sender<Event>);

impl Progress for ChannelProgress {
    fn stage(&mut self, name: &str, total: u64) {
        let _ = self.0.send(Event::Stage(name.to_string(), total));
    }
    fn step(&mut self, i: u64, message: &str) {
        let _ = self.0.send(Event::Step(i, message.to_string()));
    }
    /// The command line's notes (the training's time estimate) are not printed from Python: the
    /// callback's steps carry the progress, and `progress=False` stays quiet.
    fn note(&mut self, _: &str) {}
}

/// What a training thread returns.
struct Trained {
    model: SendModel,
    metrics: String,
}

static TEMP_COUNTER: AtomicUsize = AtomicUsize::new(0);

/// Trains a model: `config` is a dict (the TOML's structure) or a path; `frames`/`faces` replace
/// the data of `[data] path`; `out` (or a temporary directory, removed after) receives the
/// artefact directory. `progress(stage, step, total, message)` is called on this thread.
#[pyfunction]
#[pyo3(signature = (config, frames=None, faces=None, out=None, progress=None, frame_names=None))]
fn train(
    py: Python<'_>,
    config: &Bound<'_, PyAny>,
    frames: Option<PyReadonlyArray3<'_, f64>>,
    faces: Option<PyReadonlyArray2<'_, i64>>,
    out: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
    frame_names: Option<Vec<String>>,
) -> PyResult<NativeModel> {
    if frames.is_some() != faces.is_some() {
        let (arg, other) = if frames.is_some() { ("faces", "frames") } else { ("frames", "faces") };
        return Err(arg_err(arg, format!("is required with `{other}` (the data come from both arrays)")));
    }
    let cfg = if let Ok(d) = config.cast::<PyDict>() {
        let mut table = toml_table("", d)?;
        if frames.is_some() {
            let data = table.entry("data").or_insert_with(|| toml::Value::Table(toml::Table::new()));
            if let toml::Value::Table(t) = data {
                t.entry("path").or_insert_with(|| "<arrays>".into());
            }
        }
        let text = toml::to_string(&table).map_err(|e| arg_err("config", e))?;
        Config::from_toml(&text).map_err(lib_err)?
    } else {
        let path: PathBuf = config.extract().map_err(|_| {
            arg_err(
                "config",
                format!(
                    "a dict or a path, not {}",
                    config.get_type().name().map(|n| n.to_string()).unwrap_or_default()
                ),
            )
        })?;
        run(py, || Config::from_file(&path))?
    };
    let seq = match (&frames, &faces) {
        (Some(fr), Some(fa)) => {
            let view = fr.as_array();
            let (f, n, c) = view.dim();
            if c != 3 || f == 0 || n == 0 {
                return Err(arg_err("frames", format!("shape ({f}, {n}, {c}); expected (F, N, 3) with F, N ≥ 1")));
            }
            let fv = fa.as_array();
            if fv.ncols() != 3 {
                return Err(arg_err("faces", format!("shape {:?}; expected (T, 3)", fv.dim())));
            }
            let flat = c_order(&view);
            Some(
                mesh::arrays::sequence_from_arrays(("frames", "faces"), &flat, f, &c_order_i64(&fv), frame_names)
                    .map_err(lib_err)?,
            )
        }
        _ => None,
    };
    let (dir, temporary) = match out {
        Some(o) => (o, false),
        None => {
            let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
            (std::env::temp_dir().join(format!("meshdeco-py-{}-{n}", std::process::id())).join(&cfg.name), true)
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    let options = TrainOptions { resume: false, stop: Some(stop.clone()) };
    let (tx, rx) = mpsc::channel::<Event>();
    let mut rx = Some(rx);
    let mut interrupted: Option<PyErr> = None;
    let result = std::thread::scope(|s| {
        let worker = s.spawn(|| {
            let tx = tx;
            caught(|| {
                let mut progress = ChannelProgress(tx);
                let outcome = match seq {
                    Some(seq) => {
                        let prep = meshdeco::preprocess::prepare_sequence(seq, &cfg.data)?;
                        pipeline::train_prepared(&cfg, &prep, &dir, &options, &mut progress)?
                    }
                    None => pipeline::train(&cfg, &dir, &options, &mut progress)?,
                };
                let metrics = serde_json::to_string(&outcome.metrics)
                    .map_err(|e| meshdeco::Error::Invalid(format!("metrics: {e}")))?;
                Ok(Trained { model: SendModel(outcome.model), metrics })
            })
        });
        loop {
            let r = rx.take().expect("receiver");
            let (r, got) = py.detach(move || {
                let got = r.recv_timeout(Duration::from_millis(100));
                (r, got)
            });
            rx = Some(r);
            match got {
                Ok(ev) => {
                    if let Some(cb) = &progress
                        && interrupted.is_none()
                    {
                        let call = match ev {
                            Event::Stage(name, total) => cb.call1(py, (name, 0u64, total, "")),
                            Event::Step(i, msg) => cb.call1(py, ("", i, 0u64, msg)),
                        };
                        if let Err(e) = call {
                            stop.store(true, Ordering::Relaxed);
                            interrupted = Some(e);
                        }
                    }
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            }
            if interrupted.is_none()
                && let Err(e) = py.check_signals()
            {
                stop.store(true, Ordering::Relaxed);
                interrupted = Some(e);
            }
        }
        py.detach(|| worker.join())
    });
    let cleanup = || {
        if temporary && let Some(parent) = dir.parent() {
            let _ = std::fs::remove_dir_all(parent);
        }
    };
    let result = match result {
        Ok(r) => r,
        Err(p) => Err(Failure::Panic(panic_message(p.as_ref()))),
    };
    if let Some(e) = interrupted {
        cleanup();
        if e.is_instance_of::<PyKeyboardInterrupt>(py) {
            return Err(PyKeyboardInterrupt::new_err("training stopped (Ctrl-C)"));
        }
        return Err(e);
    }
    cleanup();
    let trained = result.map_err(|e| match e {
        Failure::Lib(e) => lib_err(e),
        Failure::Panic(m) => py_error("Error", format!("internal error (a bug in meshdeco, please report it): {m}")),
    })?;
    let directory = (!temporary).then(|| dir.clone());
    Ok(NativeModel::new(trained.model.0, Some(trained.metrics), directory))
}

/// Loads a trained model's artefact directory (`checkpoints/<name>`).
#[pyfunction]
fn load_model(py: Python<'_>, directory: PathBuf) -> PyResult<NativeModel> {
    let dir = directory.clone();
    let model = run(py, move || pipeline::load_model(&dir).map(SendModel)).map_err(|e| {
        // A directory that is not there is a FileNotFoundError (the library's message kept).
        if directory.exists() { e } else { py_error("FileNotFound", e.value(py).to_string()) }
    })?;
    let metrics = std::fs::read_to_string(directory.join("metrics.json")).ok();
    Ok(NativeModel::new(model.0, metrics, Some(directory)))
}

/// The native module; `meshdeco/__init__.py` is the documented API.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<NativeModel>()?;
    m.add_function(wrap_pyfunction!(load_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(load_sequence, m)?)?;
    m.add_function(wrap_pyfunction!(save_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(train, m)?)?;
    m.add_function(wrap_pyfunction!(load_model, m)?)?;
    Ok(())
}
