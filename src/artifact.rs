//! The artefact directory every method writes, and the versioned model file format.
//!
//! ```text
//! <out>/config.toml      the resolved config (every default written out)
//! <out>/model.json       model header: format version, method, representation, rest mesh,
//!                        scalings, hyperparameters, and the table of arrays in model.bin
//! <out>/model.bin        little-endian f64 arrays, concatenated, as listed in model.json
//! <out>/weights.csv      frame × component weights of the training frames
//! <out>/metrics.json     method, representation, components, train_erms, test_erms, …
//! <out>/manifest.json    length and CRC-32 of every other top-level file, written last
//! <out>/components/      with `[output] views = true`: heat maps and ±1 shapes per component
//! ```
//!
//! Writing: a run locks the directory ([`DirLock`], one writer), writes everything into a
//! staging directory beside it and commits it at the end ([`Staging`]): one sync for the whole
//! directory, the staging directory renamed to a commit directory in one step, the manifest
//! replaced last, and a commit that a killed run left half done finished by the next open — the
//! directory is always the old model or the new one. Single files outside a staging directory
//! are written atomically ([`write_atomic_with`]: a temporary file unique to the process in the
//! same directory, sync, rename). Non-finite or implausibly large numbers are refused. Reading:
//! [`open_for_reading`] checks every listed file against the manifest (which must list every
//! file the loaders read; `config.toml` is not checked) and says when a training is writing the
//! directory; [`load_model`] checks the array table against `model.bin` and every value.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Version of the model file format written by this build.
pub const FORMAT_VERSION: u32 = 1;

/// Largest magnitude of a number a model stores (`model.bin`'s arrays, `model.json`'s numbers,
/// the autoencoder's parameters): far beyond any mesh's coordinates or a trained model's values,
/// far below what overflows a decoded shape (or its single-precision glTF copy). A larger value
/// is refused when saving and when loading: it is damage, not a model.
pub const MAX_MODEL_VALUE: f64 = 1e15;

/// Shape and location of one array inside `model.bin`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArrayEntry {
    /// Dimensions, outermost first (row-major).
    pub shape: Vec<usize>,
    /// Offset in f64 elements from the start of `model.bin`.
    pub offset: usize,
}

/// Named f64 arrays stored alongside a model header.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ArrayStore {
    arrays: BTreeMap<String, (Vec<usize>, Vec<f64>)>,
}

impl ArrayStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }
    /// Adds (or replaces) an array; `data.len()` must equal the product of `shape`.
    pub fn insert(&mut self, name: &str, shape: Vec<usize>, data: Vec<f64>) -> Result<()> {
        let n: usize = shape.iter().product();
        if n != data.len() {
            return Err(Error::Invalid(format!(
                "array `{name}`: shape {shape:?} needs {n} numbers, got {}",
                data.len()
            )));
        }
        if let Some(i) = data.iter().position(|x| !x.is_finite()) {
            return Err(Error::Numerical(format!(
                "array `{name}` has a non-finite value at element {i}; refusing to save it"
            )));
        }
        if let Some(i) = data.iter().position(|x| x.abs() > MAX_MODEL_VALUE) {
            return Err(Error::Numerical(format!(
                "array `{name}` has the value {:e} at element {i}, beyond the ±{MAX_MODEL_VALUE:e} a model stores",
                data[i]
            )));
        }
        self.arrays.insert(name.to_string(), (shape, data));
        Ok(())
    }
    /// The array `name` with its shape.
    pub fn get(&self, name: &str) -> Result<(&[usize], &[f64])> {
        self.arrays
            .get(name)
            .map(|(s, d)| (s.as_slice(), d.as_slice()))
            .ok_or_else(|| Error::Invalid(format!("model has no array `{name}`")))
    }
    /// The array `name`, checking its shape.
    pub fn get_shaped(&self, name: &str, shape: &[usize]) -> Result<&[f64]> {
        let (s, d) = self.get(name)?;
        if s != shape {
            return Err(Error::Invalid(format!("model array `{name}` has shape {s:?}, expected {shape:?}")));
        }
        Ok(d)
    }
    /// Names of the stored arrays.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.arrays.keys().map(String::as_str)
    }
}

/// The on-disk header: free-form method header plus the array table.
#[derive(Debug, Serialize, Deserialize)]
struct HeaderFile<H> {
    format_version: u32,
    #[serde(flatten)]
    header: H,
    arrays: BTreeMap<String, ArrayEntry>,
}

/// Writes `path` atomically, streaming the content: `body` writes into a temporary file in the
/// same directory ([`temp_path`]: unique to this process and call, so two writers of one file
/// never share it), which is then flushed, synced to disk and renamed over `path`, so a reader
/// never sees a half-written file (two writers: the last rename wins, each file whole). On any
/// failure, including an error returned by `body`, the temporary file is removed and `path` is
/// left as it was; the error is [`Error::Io`] naming `path`. The parent directory must exist
/// ([`write_atomic`] creates it).
///
/// This is the one atomic writer of the crate; every file meshdeco writes goes through it.
/// Inside [`deferred_sync`] (the write phase of a [`Staging`] directory) the per-file sync is
/// skipped: the directory is synced once when it is committed.
pub fn write_atomic_with(path: &Path, body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> Result<()> {
    let tmp = temp_path(path);
    let result = crate::timing::timed("write", || -> std::io::Result<()> {
        let file = std::fs::OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        let mut w = BufWriter::new(file);
        body(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        if !DEFER_SYNC.with(|d| d.get()) {
            file.sync_all()?;
        }
        std::fs::rename(&tmp, path)
    });
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
}

/// [`write_atomic_with`] for a body that fails with the crate's errors (a value it refuses, not
/// only a write): on any error nothing is left at `path` and the body's own error is returned.
/// The body maps its write errors itself (`Error::io(path, e)`).
pub fn write_atomic_checked(path: &Path, body: impl FnOnce(&mut BufWriter<File>) -> Result<()>) -> Result<()> {
    let mut failure: Option<Error> = None;
    let written = write_atomic_with(path, |w| {
        body(w).map_err(|e| {
            let message = e.to_string();
            failure = Some(e);
            std::io::Error::other(message)
        })
    });
    match failure {
        Some(e) => Err(e),
        None => written,
    }
}

/// Longest file name (bytes) of the common file systems (ext4, XFS, Btrfs, APFS, NTFS).
pub const MAX_FILE_NAME: usize = 255;

/// The temporary file [`write_atomic_with`] writes before renaming it to `path`:
/// `.<name>.<pid>.<n>.tmp` beside it (hidden; `n` counts the calls of this process), with
/// `<name>` shortened (at a character boundary) so that the whole name fits in
/// [`MAX_FILE_NAME`] bytes when `path`'s own name does.
pub fn temp_path(path: &Path) -> PathBuf {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let suffix = format!(".{}.{n}.tmp", std::process::id());
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let room = MAX_FILE_NAME - 1 - suffix.len();
    let mut end = name.len().min(room);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    path.with_file_name(format!(".{}{suffix}", &name[..end]))
}

/// Writes `bytes` to `path` atomically (see [`write_atomic_with`]), creating the parent
/// directory first if needed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Writes a serialisable value as pretty JSON, atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
    write_atomic(path, text.as_bytes())
}

/// Reads a JSON file.
pub fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| Error::parse(path, Some(e.line()), e.to_string()))
}

/// Saves a model: `<dir>/model.json` (header + array table) and `<dir>/model.bin`.
/// The binary file is written first, so a reader never sees a header without its data.
pub fn save_model<H: Serialize>(dir: &Path, header: &H, arrays: &ArrayStore) -> Result<()> {
    let mut table = BTreeMap::new();
    let mut bytes = Vec::new();
    let mut offset = 0;
    for (name, (shape, data)) in &arrays.arrays {
        table.insert(name.clone(), ArrayEntry { shape: shape.clone(), offset });
        for x in data {
            bytes.extend_from_slice(&x.to_le_bytes());
        }
        offset += data.len();
    }
    write_atomic(&dir.join("model.bin"), &bytes)?;
    write_json(&dir.join("model.json"), &HeaderFile { format_version: FORMAT_VERSION, header, arrays: table })
}

/// Loads a model saved by [`save_model`]. `dir` may also be the path of `model.json` itself.
pub fn load_model<H: for<'de> Deserialize<'de>>(dir: &Path) -> Result<(H, ArrayStore)> {
    let dir = model_dir(dir);
    let json = dir.join("model.json");
    let text = std::fs::read_to_string(&json).map_err(|e| Error::io(&json, e))?;
    let probe: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::parse(&json, Some(e.line()), e.to_string()))?;
    let version = probe.get("format_version").and_then(|v| v.as_u64()).unwrap_or(0);
    if version != FORMAT_VERSION as u64 {
        return Err(Error::parse(
            &json,
            None,
            format!("model format version {version} is not supported by this build (expects {FORMAT_VERSION})"),
        ));
    }
    check_plausible_json(&json, &probe)?;
    let file: HeaderFile<H> =
        serde_json::from_str(&text).map_err(|e| Error::parse(&json, Some(e.line()), e.to_string()))?;
    let bin = dir.join("model.bin");
    let meta = std::fs::metadata(&bin).map_err(|e| Error::io(&bin, e))?;
    // The table must tile model.bin exactly (as `save_model` writes it): every array where the
    // previous one ends, the last one ending at the end of the file. Checked before reading, with
    // checked arithmetic, so absurd shapes neither allocate nor wrap.
    let mut spans: Vec<(&String, usize, usize)> = Vec::with_capacity(file.arrays.len());
    for (name, entry) in &file.arrays {
        let n = entry.shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).ok_or_else(|| {
            Error::parse(&json, None, format!("array `{name}`: shape {:?} is too large", entry.shape))
        })?;
        spans.push((name, entry.offset, n));
    }
    spans.sort_by_key(|&(_, offset, _)| offset);
    let (mut end, mut before) = (0usize, None);
    for &(name, offset, n) in &spans {
        if offset != end {
            let prev = before.map_or("the start of the file".to_string(), |p| format!("array `{p}`"));
            return Err(Error::parse(
                &json,
                None,
                format!(
                    "array `{name}` starts at number {offset} of model.bin, but {prev} ends at {end}: the table does not describe model.bin"
                ),
            ));
        }
        before = Some(name);
        end = offset.checked_add(n).filter(|&e| e <= usize::MAX / 8).ok_or_else(|| {
            Error::parse(&json, None, format!("array `{name}` ({n} numbers at {offset}) is too large"))
        })?;
    }
    if meta.len() != 8 * end as u64 {
        return Err(Error::parse(
            &bin,
            None,
            format!(
                "{} bytes, but the array table of model.json describes {} numbers ({} bytes): the file does not belong to this model.json",
                meta.len(),
                end,
                8 * end as u64
            ),
        ));
    }
    let bytes = std::fs::read(&bin).map_err(|e| Error::io(&bin, e))?;
    if bytes.len() as u64 != meta.len() {
        return Err(Error::parse(&bin, None, "changed while it was read".to_string()));
    }
    let mut store = ArrayStore::new();
    for (name, entry) in file.arrays {
        let n: usize = entry.shape.iter().product();
        let data: Vec<f64> = bytes[8 * entry.offset..8 * (entry.offset + n)]
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        store.insert(&name, entry.shape, data).map_err(|e| Error::parse(&bin, None, e.to_string()))?;
    }
    Ok((file.header, store))
}

/// Refuses a number of a model header beyond ±[`MAX_MODEL_VALUE`], naming its key.
fn check_plausible_json(path: &Path, v: &serde_json::Value) -> Result<()> {
    fn walk(v: &serde_json::Value, key: &mut String, path: &Path) -> Result<()> {
        match v {
            serde_json::Value::Number(n) => {
                let x = n.as_f64().unwrap_or(f64::INFINITY);
                if !x.is_finite() || x.abs() > MAX_MODEL_VALUE {
                    return Err(Error::parse(
                        path,
                        None,
                        format!("`{key}` is {n}, beyond the ±{MAX_MODEL_VALUE:e} a model stores"),
                    ));
                }
            }
            serde_json::Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    let len = key.len();
                    key.push_str(&format!("[{i}]"));
                    walk(x, key, path)?;
                    key.truncate(len);
                }
            }
            serde_json::Value::Object(o) => {
                for (k, x) in o {
                    let len = key.len();
                    if !key.is_empty() {
                        key.push('.');
                    }
                    key.push_str(k);
                    walk(x, key, path)?;
                    key.truncate(len);
                }
            }
            _ => {}
        }
        Ok(())
    }
    walk(v, &mut String::new(), path)
}

/// The model directory for a path that is either the directory or its `model.json`.
pub fn model_dir(path: &Path) -> PathBuf {
    if path.file_name().is_some_and(|n| n == "model.json") {
        path.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."))
    } else {
        path.to_path_buf()
    }
}

/// Writes a frame × component weight table as CSV (header `frame,c0,c1,…`).
pub fn write_weights_csv(path: &Path, frame_names: &[String], weights: &[f64], k: usize) -> Result<()> {
    let mut s = String::from("frame");
    for c in 0..k {
        s.push_str(&format!(",c{c}"));
    }
    s.push('\n');
    for (f, name) in frame_names.iter().enumerate() {
        s.push_str(name);
        for c in 0..k {
            let w = weights[f * k + c];
            if !w.is_finite() {
                return Err(Error::Numerical(format!(
                    "weight of frame {name}, component {c} is {w}; refusing to write {}",
                    path.display()
                )));
            }
            s.push_str(&format!(",{w}"));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}

/// A weight table read back from a `weights.csv` that [`write_weights_csv`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct WeightsTable {
    /// Frame names, in file order.
    pub frames: Vec<String>,
    /// One row of K weights per frame (frame-major, as written).
    pub weights: Vec<Vec<f64>>,
}

/// Reads a weight table (header `frame,c0,c1,…`, then one row per frame: its name and K finite
/// numbers), verified: the header names the columns in order, every row has K + 1 fields, every
/// weight is a finite number. Errors name the file and the 1-based line.
pub fn read_weights_csv(path: &Path) -> Result<WeightsTable> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let bad = |line: usize, m: String| Error::parse(path, Some(line), m);
    let mut lines = text.lines();
    let header = lines.next().ok_or_else(|| Error::parse(path, None, "empty: no header `frame,c0,…`"))?;
    let columns: Vec<&str> = header.split(',').collect();
    if columns[0] != "frame" || columns.len() < 2 {
        return Err(bad(1, format!("header `{header}` is not `frame,c0,c1,…`")));
    }
    let k = columns.len() - 1;
    if let Some((c, name)) = columns[1..].iter().enumerate().find(|(c, name)| **name != format!("c{c}")) {
        return Err(bad(1, format!("column {} is named `{name}`, expected `c{c}`", c + 2)));
    }
    let (mut frames, mut weights) = (Vec::new(), Vec::new());
    for (i, row) in lines.enumerate() {
        let line = i + 2;
        let fields: Vec<&str> = row.split(',').collect();
        if fields.len() != k + 1 {
            return Err(bad(line, format!("{} fields, the header names {}", fields.len(), k + 1)));
        }
        let mut w = Vec::with_capacity(k);
        for (c, x) in fields[1..].iter().enumerate() {
            match x.trim().parse::<f64>() {
                Ok(v) if v.is_finite() => w.push(v),
                _ => return Err(bad(line, format!("weight c{c} `{x}` is not a finite number"))),
            }
        }
        frames.push(fields[0].to_string());
        weights.push(w);
    }
    Ok(WeightsTable { frames, weights })
}

/// Reads exactly `buf.len()` bytes of `file` at `offset`, without moving a shared cursor on
/// Unix (so several threads may read one file: the feature cache, a `.npy` read a frame at a
/// time).
#[cfg(unix)]
pub fn read_exact_at(file: &std::fs::File, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

/// Reads exactly `buf.len()` bytes of `file` at `offset` (seek, then read).
#[cfg(not(unix))]
pub fn read_exact_at(file: &std::fs::File, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = file.try_clone()?;
    f.seek(SeekFrom::Start(offset))?;
    f.read_exact(buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Serialize, Deserialize, PartialEq)]
    struct H {
        method: String,
        k: usize,
    }

    fn tmpdir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("meshdeco-artifact-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// A header number exactly at the bound is kept; one beyond it is refused, naming the file
    /// and the number's key path.
    #[test]
    fn header_numbers_up_to_the_bound_are_plausible() {
        let p = Path::new("model.json");
        let ok = serde_json::json!({ "a": [1.0, -MAX_MODEL_VALUE], "b": { "c": MAX_MODEL_VALUE } });
        assert!(check_plausible_json(p, &ok).is_ok());
        let bad = serde_json::json!({ "a": [1.0], "b": { "c": 1.5 * MAX_MODEL_VALUE } });
        let e = check_plausible_json(p, &bad).unwrap_err().to_string();
        assert!(e.contains("model.json") && e.contains("`b.c`"), "{e}");
    }

    /// A fresh folder `tag` holding `w.csv`: three frames f0–f2 of two weights each,
    /// 0.5, 1 / 2, 3 / −4, 5.25.
    fn three_frame_weights(tag: &str) -> (PathBuf, Vec<String>, PathBuf) {
        let d = tmpdir(tag);
        std::fs::create_dir_all(&d).unwrap();
        let names = vec!["f0".to_string(), "f1".to_string(), "f2".to_string()];
        let p = d.join("w.csv");
        write_weights_csv(&p, &names, &[0.5, 1.0, 2.0, 3.0, -4.0, 5.25], 2).unwrap();
        (d, names, p)
    }

    /// The weight table: a header, one row per frame in frame-major order (weight `f·k + c`),
    /// and nothing written when a weight is not finite.
    #[test]
    fn weights_csv_is_frame_major_and_refuses_non_finite() {
        let (d, names, p) = three_frame_weights("weights-csv");
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "frame,c0,c1\nf0,0.5,1\nf1,2,3\nf2,-4,5.25\n");
        let q = d.join("nan.csv");
        let e = write_weights_csv(&q, &names, &[0.5, 1.0, 2.0, f64::NAN, 0.0, 0.0], 2).unwrap_err().to_string();
        assert!(e.contains("frame f1, component 1") && e.contains("nan.csv"), "{e}");
        assert!(!q.exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// The weight table reads back as written, and a damaged one is refused naming the file
    /// and the line.
    #[test]
    fn weights_csv_reads_back_verified() {
        let (d, names, p) = three_frame_weights("weights-csv-read");
        let back = read_weights_csv(&p).unwrap();
        assert_eq!(back.frames, names);
        assert_eq!(back.weights, vec![vec![0.5, 1.0], vec![2.0, 3.0], vec![-4.0, 5.25]]);
        // Read back verified: each damage is refused naming the file and its line.
        for (text, want) in [
            ("frame,c0,c1\nf0,0.5,1\nf1,2\n", ":3: 2 fields, the header names 3"),
            ("frame,c0,c1\nf0,0.5,inf\n", ":2: weight c1 `inf` is not a finite number"),
            ("frame,c0,c1\nf0,NaN,1\n", ":2: weight c0 `NaN`"),
            ("frame,c0,c1\nf0,0.5,x\n", ":2: weight c1 `x`"),
            ("frame,c1,c0\nf0,0.5,1\n", ":1: column 2 is named `c1`, expected `c0`"),
            ("name,c0\nf0,1\n", ":1: header `name,c0`"),
            ("", "empty"),
        ] {
            let r = d.join("bad.csv");
            std::fs::write(&r, text).unwrap();
            let e = read_weights_csv(&r).unwrap_err().to_string();
            assert!(e.contains("bad.csv") && e.contains(want), "{text:?}: {e}");
        }
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn model_round_trip() {
        let d = tmpdir("rt");
        let mut a = ArrayStore::new();
        a.insert("components", vec![2, 3], vec![1.0, -2.0, 3.5, 1e-300, 0.0, 7.0]).unwrap();
        a.insert("mean", vec![3], vec![0.1, 0.2, 0.3]).unwrap();
        let h = H { method: "pca".into(), k: 2 };
        save_model(&d, &h, &a).unwrap();
        let (h2, a2): (H, ArrayStore) = load_model(&d.join("model.json")).unwrap();
        assert_eq!(h, h2);
        assert_eq!(a, a2);
        assert!(a2.get_shaped("mean", &[4]).is_err());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn refuses_nan_and_wrong_shapes() {
        let mut a = ArrayStore::new();
        assert!(a.insert("x", vec![2], vec![1.0, f64::NAN]).unwrap_err().to_string().contains("non-finite"));
        assert!(a.insert("x", vec![3], vec![1.0]).is_err());
    }

    /// `names` lists every stored array once, in name order (region PCA asks it whether a model
    /// has `train_weights`; issue 33: an empty or constant list went unnoticed).
    #[test]
    fn names_lists_the_stored_arrays() {
        let mut a = ArrayStore::new();
        assert_eq!(a.names().count(), 0);
        a.insert("mean", vec![1], vec![0.0]).unwrap();
        a.insert("components", vec![2], vec![1.0, 2.0]).unwrap();
        a.insert("mean", vec![1], vec![3.0]).unwrap();
        assert_eq!(a.names().collect::<Vec<_>>(), ["components", "mean"]);
    }

    /// The bound ±MAX_MODEL_VALUE itself is stored, the next number beyond it is refused naming
    /// the array and element (issue 33: mutation testing found `>` → `>=` unnoticed).
    #[test]
    fn stores_values_up_to_the_bound_and_refuses_beyond() {
        let mut a = ArrayStore::new();
        a.insert("edge", vec![2], vec![MAX_MODEL_VALUE, -MAX_MODEL_VALUE]).unwrap();
        assert_eq!(a.get("edge").unwrap().1, &[MAX_MODEL_VALUE, -MAX_MODEL_VALUE]);
        let beyond = MAX_MODEL_VALUE.next_up();
        let e = a.insert("far", vec![2], vec![0.0, -beyond]).unwrap_err().to_string();
        assert!(e.contains("array `far`") && e.contains("element 1"), "{e}");
    }

    /// A 255-byte name of two-byte characters is cut back to a character boundary, keeping as
    /// much as fits (issue 33: mutation testing found `end -= 1` → `+= 1` unnoticed, a 256-byte
    /// temporary name, because one name's parity may or may not put the cut inside a character;
    /// the two names here have their boundaries at even and at odd bytes, so one of them is cut
    /// inside a character whatever the suffix's length).
    #[test]
    fn temporary_names_of_multibyte_names_fit_and_cut_at_a_character() {
        let dir = Path::new("out");
        for name in ["é".repeat(127) + "x", "x".to_string() + &"é".repeat(127)] {
            assert_eq!(name.len(), 255);
            let tmp = temp_path(&dir.join(&name));
            assert_eq!(tmp.parent(), Some(dir));
            let file = tmp.file_name().unwrap().to_str().unwrap().to_string();
            let suffix = format!(".{}.", std::process::id());
            let kept = &file[1..file.rfind(&suffix).unwrap()];
            assert!(file.starts_with('.') && file.ends_with(".tmp"), "{file}");
            assert!(name.starts_with(kept), "{kept} is not a prefix of the name");
            assert!(file.len() <= MAX_FILE_NAME && file.len() >= MAX_FILE_NAME - 1, "{} bytes: {file}", file.len());
        }
        let short = temp_path(Path::new("a.obj"));
        let file = short.file_name().unwrap().to_str().unwrap();
        assert!(file.starts_with(".a.obj.") && file.ends_with(".tmp"), "{file}");
    }

    #[test]
    fn truncated_bin_is_a_clear_error() {
        let d = tmpdir("trunc");
        let mut a = ArrayStore::new();
        a.insert("x", vec![4], vec![1.0, 2.0, 3.0, 4.0]).unwrap();
        save_model(&d, &H { method: "m".into(), k: 1 }, &a).unwrap();
        let bin = d.join("model.bin");
        let bytes = std::fs::read(&bin).unwrap();
        std::fs::write(&bin, &bytes[..16]).unwrap();
        let e = load_model::<H>(&d).unwrap_err().to_string();
        assert!(e.contains("model.bin") && e.contains("describes 4 numbers"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A resumed training takes the interrupted run's checkpoint (in the staging directory)
    /// before the finished run's (in the directory itself), and none when neither is a file.
    #[test]
    fn resumable_checkpoint_prefers_the_interrupted_run() {
        let d = tmpdir("resume");
        let out = d.join("run");
        std::fs::create_dir_all(out.join(CHECKPOINT_FILE)).unwrap();
        assert_eq!(resumable_checkpoint(&out), None, "a directory is not a checkpoint");
        std::fs::remove_dir(out.join(CHECKPOINT_FILE)).unwrap();
        assert_eq!(resumable_checkpoint(&out), None);
        std::fs::write(out.join(CHECKPOINT_FILE), b"finished").unwrap();
        assert_eq!(resumable_checkpoint(&out), Some(out.join(CHECKPOINT_FILE)));
        let staged = staging_path(&out).unwrap();
        std::fs::create_dir_all(&staged).unwrap();
        std::fs::write(staged.join(CHECKPOINT_FILE), b"interrupted").unwrap();
        assert_eq!(resumable_checkpoint(&out), Some(staged.join(CHECKPOINT_FILE)));
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A commit directory whose plan is gone (removed last, just before the directory) is
    /// simply removed; a plan that cannot be read for another reason is an error naming it.
    #[test]
    fn a_commit_without_its_plan_is_cleaned_up_and_an_unreadable_plan_is_an_error() {
        let d = tmpdir("finish");
        let out = d.join("run");
        let dir = commit_path(&out).unwrap();
        std::fs::create_dir_all(dir.join("components")).unwrap();
        finish_commit(&out).unwrap();
        assert!(!dir.exists(), "the plan-less commit directory was left");
        std::fs::create_dir_all(dir.join(PLAN_FILE)).unwrap();
        let e = finish_commit(&out).unwrap_err().to_string();
        assert!(e.contains(PLAN_FILE), "{e}");
        assert!(dir.join(PLAN_FILE).is_dir(), "an unreadable plan's commit was removed");
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// An uncommitted run that has a checkpoint keeps its staging directory; resuming it keeps
    /// the work files (checkpoint, log) and drops everything else it left. A commit into a
    /// directory that holds no artefact (no manifest, no resolved config) leaves the user's
    /// entries alone, even ones named like artefact files; one with a resolved config does not.
    #[test]
    fn staging_keeps_work_files_for_resume_and_a_users_directory_alone() {
        let d = tmpdir("staging");
        let out = d.join("run");
        let s = Staging::begin(&out, false).unwrap();
        let staged = s.dir().to_path_buf();
        for name in [CHECKPOINT_FILE, LOG_FILE, "model.json"] {
            std::fs::write(staged.join(name), name).unwrap();
        }
        drop(s);
        assert!(staged.join(CHECKPOINT_FILE).is_file(), "an interrupted run's checkpoint was removed");
        let s = Staging::begin(&out, true).unwrap();
        assert_eq!(s.resume_from(), Some(staged.join(CHECKPOINT_FILE).as_path()));
        assert!(staged.join(CHECKPOINT_FILE).is_file() && staged.join(LOG_FILE).is_file());
        assert!(!staged.join("model.json").exists(), "a stray file of the interrupted run was kept");
        drop(s);
        let mine = d.join("mine");
        std::fs::create_dir_all(&mine).unwrap();
        std::fs::write(mine.join("metrics.json"), "my own").unwrap();
        let s = Staging::begin(&mine, false).unwrap();
        std::fs::write(s.dir().join("model.json"), "{}").unwrap();
        s.commit().unwrap();
        assert_eq!(std::fs::read_to_string(mine.join("metrics.json")).unwrap(), "my own");
        assert!(mine.join("model.json").is_file() && mine.join(MANIFEST_FILE).is_file());
        // A config resolved by meshdeco marks an earlier run even without a manifest: the
        // entries that run wrote and this one did not are removed.
        let earlier = d.join("earlier");
        std::fs::create_dir_all(&earlier).unwrap();
        std::fs::write(earlier.join("config.toml"), "# Resolved by meshdeco 0.1\n").unwrap();
        std::fs::write(earlier.join("metrics.json"), "stale").unwrap();
        let s = Staging::begin(&earlier, false).unwrap();
        std::fs::write(s.dir().join("model.json"), "{}").unwrap();
        s.commit().unwrap();
        assert!(!earlier.join("metrics.json").exists(), "the earlier run's metrics were kept");
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// The skipped per-file sync is scoped to the call: on when inside (nested too), off again
    /// after it returns or panics, so later writes on the thread are synced.
    #[test]
    fn deferred_sync_is_scoped_to_the_call_even_when_it_panics() {
        let deferred = || DEFER_SYNC.with(|d| d.get());
        assert!(!deferred());
        deferred_sync(|| {
            assert!(deferred());
            deferred_sync(|| assert!(deferred()));
            assert!(deferred(), "the inner call ended the outer one's deferral");
        });
        assert!(!deferred(), "still deferred after the call");
        assert!(std::panic::catch_unwind(|| deferred_sync(|| panic!("inside"))).is_err());
        assert!(!deferred(), "still deferred after a panic");
    }
}

thread_local! {
    static DEFER_SYNC: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` with the per-file sync of [`write_atomic_with`] skipped on this thread: for files
/// written into a [`Staging`] directory, which [`Staging::commit`] syncs once as a whole.
pub fn deferred_sync<R>(f: impl FnOnce() -> R) -> R {
    struct Restore(bool);
    impl Drop for Restore {
        fn drop(&mut self) {
            DEFER_SYNC.with(|d| d.set(self.0));
        }
    }
    let _restore = Restore(DEFER_SYNC.with(|d| d.replace(true)));
    f()
}

// ---------------------------------------------------------------------------------------------
// Manifest: length and CRC-32 of every file of an artefact, verified on load.

/// File name of an artefact directory's manifest, written last by [`Staging::commit`]: an
/// artefact directory without it is incomplete and is not loaded.
pub const MANIFEST_FILE: &str = "manifest.json";

/// Work files of a training (the autoencoder's checkpoint and log): kept in the directory, not
/// part of the manifest (the checkpoint carries its own checksum).
pub const WORK_FILES: &[&str] = &[CHECKPOINT_FILE, LOG_FILE];

/// The autoencoder's last training checkpoint, which `--resume` continues from.
pub const CHECKPOINT_FILE: &str = "checkpoint.bin";
/// The autoencoder's per-iteration training log.
pub const LOG_FILE: &str = "training.jsonl";

/// Names a training writes into an artefact directory (files and the `components/` folder): a
/// committed run removes those of an earlier run that it did not write itself, and leaves every
/// other entry (a user's own files) alone.
pub const ARTEFACT_NAMES: &[&str] = &[
    "config.toml",
    "model.json",
    "model.bin",
    "autoencoder.json",
    "autoencoder.bpk",
    "weights.csv",
    "metrics.json",
    "segmentation.ply",
    "components",
    CHECKPOINT_FILE,
    LOG_FILE,
];

/// Length and checksum of one file of an artefact.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestEntry {
    /// Length in bytes.
    pub bytes: u64,
    /// CRC-32 (IEEE) of the content, 8 lowercase hex digits.
    pub crc32: String,
}

/// `manifest.json`: every top-level file of an artefact directory (not the work files, not the
/// `components/` views) with its length and checksum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Version of the manifest format.
    pub manifest_version: u32,
    /// meshdeco version that wrote the artefact.
    pub written_by: String,
    /// File name → entry.
    pub files: BTreeMap<String, ManifestEntry>,
}

impl Manifest {
    /// Errors unless every file of `names` is listed: a loader reads only files the manifest
    /// vouches for (a manifest listing no files, or one without `model.bin`, is refused).
    pub fn require(&self, dir: &Path, names: &[&str]) -> Result<()> {
        if let Some(missing) = names.iter().find(|n| !self.files.contains_key(**n)) {
            return Err(Error::Invalid(format!(
                "{}: does not list `{missing}`, which the model's loader reads ({} files listed): the manifest does not vouch for this artefact; train it again",
                dir.join(MANIFEST_FILE).display(),
                self.files.len()
            )));
        }
        Ok(())
    }
}

/// CRC-32 of `bytes` as 8 lowercase hex digits.
pub fn crc32_hex(bytes: &[u8]) -> String {
    format!("{:08x}", crc32fast::hash(bytes))
}

/// Files of an artefact that the manifest does not check, because no loader reads them:
/// `config.toml`, the resolved config, is for people (and for training again) — editing it,
/// even adding a comment, leaves the model loadable.
pub const UNCHECKED_FILES: &[&str] = &["config.toml"];

/// Files every model's loader reads ([`load_model`]): a manifest must list them.
pub const MODEL_FILES: &[&str] = &["model.json", "model.bin"];

fn manifest_listed(name: &str) -> bool {
    name != MANIFEST_FILE
        && !WORK_FILES.contains(&name)
        && !UNCHECKED_FILES.contains(&name)
        && !name.ends_with(".tmp")
        && !name.starts_with('.')
}

/// Computes the manifest of the top-level files of `dir` (see [`Manifest`]).
pub fn compute_manifest(dir: &Path) -> Result<Manifest> {
    let mut files = BTreeMap::new();
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let ty = entry.file_type().map_err(|e| Error::io(entry.path(), e))?;
        if !ty.is_file() || !manifest_listed(&name) {
            continue;
        }
        let path = entry.path();
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        files.insert(name, ManifestEntry { bytes: bytes.len() as u64, crc32: crc32_hex(&bytes) });
    }
    Ok(Manifest { manifest_version: 1, written_by: env!("CARGO_PKG_VERSION").to_string(), files })
}

/// Checks every file listed in `dir`'s manifest: present, a regular file, of the recorded
/// length and checksum. Errors name the file and what differs; a directory without a manifest
/// is an incomplete (or pre-manifest) artefact.
pub fn verify_manifest(dir: &Path) -> Result<Manifest> {
    let path = dir.join(MANIFEST_FILE);
    if !path.exists() {
        if !dir.is_dir() {
            return Err(Error::Invalid(format!("{}: no such artefact directory", dir.display())));
        }
        return Err(Error::Invalid(format!(
            "{}: no {MANIFEST_FILE}: not a complete meshdeco artefact (a run that did not finish, or one written before meshdeco recorded checksums); train it again",
            dir.display()
        )));
    }
    let manifest: Manifest = read_json(&path)?;
    manifest.require(dir, MODEL_FILES)?;
    for (name, entry) in &manifest.files {
        if UNCHECKED_FILES.contains(&name.as_str()) {
            continue;
        }
        let file = dir.join(name);
        if name.is_empty() || name.contains(['/', '\\']) || name.starts_with('.') {
            return Err(Error::parse(&path, None, format!("lists `{name}`, which is not a file of the artefact")));
        }
        let meta = std::fs::metadata(&file).map_err(|e| Error::io(&file, e))?;
        if !meta.is_file() {
            return Err(Error::Invalid(format!("{}: not a regular file", file.display())));
        }
        if meta.len() != entry.bytes {
            return Err(Error::Invalid(format!(
                "{}: {} bytes, but {} records {} bytes: the file was changed or damaged after training",
                file.display(),
                meta.len(),
                MANIFEST_FILE,
                entry.bytes
            )));
        }
        let bytes = std::fs::read(&file).map_err(|e| Error::io(&file, e))?;
        let crc = crc32_hex(&bytes);
        if crc != entry.crc32 {
            return Err(Error::Invalid(format!(
                "{}: checksum {crc} differs from {} ({}): the file was changed or damaged after training",
                file.display(),
                MANIFEST_FILE,
                entry.crc32
            )));
        }
    }
    Ok(manifest)
}

// ---------------------------------------------------------------------------------------------
// Locks and staging: one writer per artefact directory, all-or-nothing artefacts.

/// Suffix of the lock file beside an artefact directory `<parent>/.<name>` + this.
pub const LOCK_SUFFIX: &str = ".meshdeco-lock";
/// Suffix of the staging directory beside an artefact directory `<parent>/.<name>` + this.
pub const STAGING_SUFFIX: &str = ".meshdeco-partial";

fn sibling(out: &Path, suffix: &str) -> Result<PathBuf> {
    let named = if out.file_name().is_some() {
        out.to_path_buf()
    } else {
        std::fs::canonicalize(out).map_err(|e| Error::io(out, e))?
    };
    let name = named.file_name().ok_or_else(|| {
        Error::Invalid(format!("output directory `{}` needs a name (e.g. checkpoints/run)", out.display()))
    })?;
    let parent = named.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut file = std::ffi::OsString::from(".");
    file.push(name);
    file.push(suffix);
    Ok(parent.join(file))
}

/// The lock file of artefact directory `out` (beside it, hidden).
pub fn lock_path(out: &Path) -> Result<PathBuf> {
    sibling(out, LOCK_SUFFIX)
}

/// The staging directory of artefact directory `out` (beside it, hidden).
pub fn staging_path(out: &Path) -> Result<PathBuf> {
    sibling(out, STAGING_SUFFIX)
}

/// Suffix of the directory beside an artefact directory `<parent>/.<name>` + this into which a
/// complete staging directory is renamed when its commit starts ([`Staging::commit`]): while it
/// exists, a commit is under way or was interrupted, and the next open finishes it.
pub const COMMIT_SUFFIX: &str = ".meshdeco-commit";

/// The directory of artefact directory `out` holding a commit under way (beside it, hidden).
pub fn commit_path(out: &Path) -> Result<PathBuf> {
    sibling(out, COMMIT_SUFFIX)
}

/// Where a resumed training of `out` finds its checkpoint: an interrupted run's (in the staging
/// directory) before a finished run's (in `out`).
pub fn resumable_checkpoint(out: &Path) -> Option<PathBuf> {
    let staged = staging_path(out).ok().map(|s| s.join(CHECKPOINT_FILE));
    staged.into_iter().chain([out.join(CHECKPOINT_FILE)]).find(|p| p.is_file())
}

/// An exclusive lock on an artefact directory: one writer at a time. The lock file (holding the
/// writer's process id) lies beside the directory ([`lock_path`]) and is removed when dropped.
#[derive(Debug)]
pub struct DirLock {
    path: PathBuf,
    _file: File,
}

impl DirLock {
    /// Locks artefact directory `out`, or errors at once — naming the directory and the process
    /// holding it — when another process writes there.
    pub fn acquire(out: &Path) -> Result<Self> {
        let path = lock_path(out)?;
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .read(true)
            .write(true)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let holder = std::fs::read_to_string(&path).unwrap_or_default();
                return Err(Error::Invalid(format!(
                    "{} is being written by another meshdeco process (pid {}); wait for it to finish or choose another output directory",
                    out.display(),
                    holder.trim()
                )));
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(Error::io(&path, e)),
        }
        file.set_len(0).map_err(|e| Error::io(&path, e))?;
        file.write_all(std::process::id().to_string().as_bytes()).map_err(|e| Error::io(&path, e))?;
        Ok(DirLock { path, _file: file })
    }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// The process id of the meshdeco process writing artefact directory `out` right now (holding
/// its [`DirLock`]), if any. Only looks: creates nothing, takes nothing.
pub fn writer_of(out: &Path) -> Option<String> {
    let path = lock_path(out).ok()?;
    let file = File::open(&path).ok()?;
    match file.try_lock_shared() {
        Ok(()) => None,
        Err(std::fs::TryLockError::WouldBlock) => {
            Some(std::fs::read_to_string(&path).unwrap_or_default().trim().to_string())
        }
        Err(std::fs::TryLockError::Error(_)) => None,
    }
}

/// Opens artefact directory `dir` for reading: finishes a commit that an interrupted run left
/// half done (so the directory is the new model, [`Staging::commit`]), then verifies it
/// ([`verify_manifest`]). While another process writes `dir` (it holds the lock), a commit under
/// way or a failed check is reported as that: "being written".
pub fn open_for_reading(dir: &Path) -> Result<Manifest> {
    let under_way = commit_path(dir).is_ok_and(|c| c.is_dir());
    if under_way {
        match DirLock::acquire(dir) {
            Ok(_lock) => finish_commit(dir)?,
            Err(e) => {
                return Err(match writer_of(dir) {
                    Some(pid) => being_written_message(dir, &pid, "its new model is being moved in", None),
                    None => e,
                });
            }
        }
    }
    verify_manifest(dir).map_err(|e| being_written(dir, e))
}

/// `e`, or — when another meshdeco process holds `dir`'s lock — an error saying that `dir` is
/// being written (with `e` after it): what a reader is told when it meets a directory that a
/// training is writing. An error that already says so is returned as it is.
pub fn being_written(dir: &Path, e: Error) -> Error {
    if matches!(&e, Error::Invalid(m) if m.contains(BEING_WRITTEN)) {
        return e;
    }
    match writer_of(dir) {
        Some(pid) => being_written_message(dir, &pid, "a training is writing or replacing the model", Some(&e)),
        None => e,
    }
}

/// The words of [`being_written`]'s message that name the writer.
const BEING_WRITTEN: &str = " is being written by meshdeco process ";

/// "`dir` is being written by meshdeco process `pid` (`what`) …", with what reading it gave.
fn being_written_message(dir: &Path, pid: &str, what: &str, gave: Option<&Error>) -> Error {
    let gave = gave.map(|e| format!(" (reading it gave: {e})")).unwrap_or_default();
    Error::Invalid(format!(
        "{}{BEING_WRITTEN}{pid} ({what}), so it cannot be read now; try again when that run has finished{gave}",
        dir.display()
    ))
}

/// What a reader of artefact directory `dir` compares before and after reading it, to know
/// whether a commit changed the directory meanwhile: the content of its manifest (replaced
/// last by every commit) and whether a commit is under way.
pub fn read_state(dir: &Path) -> (Option<Vec<u8>>, bool) {
    (std::fs::read(dir.join(MANIFEST_FILE)).ok(), commit_path(dir).is_ok_and(|c| c.is_dir()))
}

/// File in a commit's directory: what the commit moves into the artefact directory.
const PLAN_FILE: &str = ".meshdeco-plan.json";

/// What a commit does, written into its directory before it starts: the entries it moves into
/// the artefact directory, and whether entries of an earlier run that it did not write are
/// removed. Finishing a commit twice does what finishing it once does.
#[derive(Debug, Serialize, Deserialize)]
struct CommitPlan {
    earlier: bool,
    names: Vec<String>,
}

/// Environment variable of the crash tests: `<step>` or `<step>#<n>` kills this process (SIGKILL,
/// nothing cleaned up) the n-th time (default 1st) a commit reaches `<step>`: `staged` (before
/// the staging directory becomes the commit's), `renamed` (after), `remove` (before removing an
/// earlier run's entry), `move` (before moving an entry in), `manifest` (before the new manifest
/// replaces the old), `cleanup` (before the commit's directory goes). Unset in normal use.
pub const KILL_AT_ENV: &str = "MESHDECO_TEST_KILL_AT";

fn kill_point(step: &str) {
    static COUNTS: std::sync::Mutex<BTreeMap<String, usize>> = std::sync::Mutex::new(BTreeMap::new());
    let Ok(spec) = std::env::var(KILL_AT_ENV) else { return };
    let (name, nth) = match spec.split_once('#') {
        Some((n, k)) => (n.to_string(), k.parse().unwrap_or(1)),
        None => (spec, 1usize),
    };
    if name != step {
        return;
    }
    let mut counts = COUNTS.lock().unwrap_or_else(|e| e.into_inner());
    let c = counts.entry(name).or_insert(0);
    *c += 1;
    if *c == nth {
        #[cfg(unix)]
        // SAFETY: sends a signal to this very process; no memory is touched.
        unsafe {
            libc::kill(libc::getpid(), libc::SIGKILL);
        }
        std::process::abort();
    }
}

/// Finishes the commit of artefact directory `out` that its commit directory ([`commit_path`])
/// describes, if there is one; the caller holds `out`'s lock. Every step can be repeated: a run
/// killed at any point of a commit leaves `out` as the old model (commit not started) or as a
/// commit that this finishes into the new one.
fn finish_commit(out: &Path) -> Result<()> {
    let dir = commit_path(out)?;
    if !dir.is_dir() {
        return Ok(());
    }
    let plan_path = dir.join(PLAN_FILE);
    let plan: CommitPlan = match std::fs::read(&plan_path) {
        Ok(bytes) => serde_json::from_slice(&bytes).map_err(|e| Error::parse(&plan_path, None, e.to_string()))?,
        // The plan is the last thing removed: without it, nothing is left to do.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e));
        }
        Err(e) => return Err(Error::io(&plan_path, e)),
    };
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    if plan.earlier {
        for name in ARTEFACT_NAMES {
            let target = out.join(name);
            if !plan.names.iter().any(|w| w == name) && std::fs::symlink_metadata(&target).is_ok() {
                kill_point("remove");
                remove_entry(&target)?;
            }
        }
    }
    // The manifest last: until it is replaced, the old one stays (the directory is the old
    // model or a commit under way, never a directory without a manifest).
    let mut names: Vec<&String> = plan.names.iter().filter(|n| *n != MANIFEST_FILE).collect();
    names.extend(plan.names.iter().filter(|n| *n == MANIFEST_FILE));
    for name in names {
        let (from, to) = (dir.join(name), out.join(name));
        if std::fs::symlink_metadata(&from).is_err() {
            continue; // moved before an interruption
        }
        kill_point(if name == MANIFEST_FILE { "manifest" } else { "move" });
        if std::fs::symlink_metadata(&to).is_ok_and(|m| m.is_dir()) {
            std::fs::remove_dir_all(&to).map_err(|e| Error::io(&to, e))?;
        }
        std::fs::rename(&from, &to).map_err(|e| Error::io(&to, e))?;
    }
    File::open(out).and_then(|d| d.sync_all()).map_err(|e| Error::io(out, e))?;
    kill_point("cleanup");
    std::fs::remove_file(&plan_path).map_err(|e| Error::io(&plan_path, e))?;
    std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    sync_parent(out);
    Ok(())
}

/// Syncs the directory holding `path` (so a rename of `path` is durable); best effort.
fn sync_parent(path: &Path) {
    if let Some(parent) = path.parent() {
        let parent = if parent.as_os_str().is_empty() { Path::new(".") } else { parent };
        let _ = File::open(parent).and_then(|d| d.sync_all());
    }
}

/// An artefact directory being written: every file goes into a hidden staging directory beside
/// `out` ([`staging_path`]); [`Self::commit`] writes the manifest, syncs the staging directory
/// once, and moves its entries into `out` (manifest last, crash-safe). A run that fails or is
/// dropped before committing leaves `out` as it was and removes the staging directory — unless
/// it holds an autoencoder checkpoint that this run wrote, which a `--resume` continues from.
#[derive(Debug)]
pub struct Staging {
    out: PathBuf,
    dir: PathBuf,
    resume_from: Option<PathBuf>,
    committed: bool,
    _lock: DirLock,
}

impl Staging {
    /// Locks `out` (finishing a commit an interrupted run left half done) and prepares its
    /// staging directory. With `resume`, the run continues from the checkpoint of an
    /// interrupted run (in the staging directory) or else of the finished run in `out`
    /// ([`Self::resume_from`]; it is read where it is, never copied into hiding); it is an error
    /// when there is none.
    pub fn begin(out: &Path, resume: bool) -> Result<Self> {
        if out.exists() && !out.is_dir() {
            return Err(Error::Invalid(format!("output directory {}: exists and is not a directory", out.display())));
        }
        let lock = DirLock::acquire(out)?;
        finish_commit(out)?;
        let dir = staging_path(out)?;
        let staged_checkpoint = dir.join(CHECKPOINT_FILE);
        let mut resume_from = None;
        if resume && staged_checkpoint.is_file() {
            // An interrupted run: keep its work files, drop anything else it left.
            for entry in std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))? {
                let entry = entry.map_err(|e| Error::io(&dir, e))?;
                if !WORK_FILES.contains(&entry.file_name().to_string_lossy().as_ref()) {
                    remove_entry(&entry.path())?;
                }
            }
            resume_from = Some(staged_checkpoint);
        } else {
            if dir.exists() {
                std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
            }
            std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
            if resume {
                let finished = out.join(CHECKPOINT_FILE);
                if !finished.is_file() {
                    let _ = std::fs::remove_dir(&dir);
                    return Err(Error::Invalid(format!(
                        "--resume: no checkpoint at {} (nor an interrupted run's at {})",
                        finished.display(),
                        dir.join(CHECKPOINT_FILE).display()
                    )));
                }
                // The log goes on where the run writes; the checkpoint is read in place, so a
                // refused one is not left behind in the staging directory.
                let log = out.join(LOG_FILE);
                if log.is_file() {
                    std::fs::copy(&log, dir.join(LOG_FILE)).map_err(|e| Error::io(&log, e))?;
                }
                resume_from = Some(finished);
            }
        }
        Ok(Staging { out: out.to_path_buf(), dir, resume_from, committed: false, _lock: lock })
    }

    /// The staging directory: write every file of the artefact here.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The artefact directory this run commits into.
    pub fn out(&self) -> &Path {
        &self.out
    }

    /// With `--resume`: the checkpoint the run continues from (the interrupted run's in the
    /// staging directory, or the finished run's in `out`).
    pub fn resume_from(&self) -> Option<&Path> {
        self.resume_from.as_deref()
    }

    /// Writes the manifest, syncs the staging directory once, and moves its entries into `out`,
    /// crash-safe: the staging directory, complete and with a plan of what moves, is renamed to
    /// the commit directory ([`commit_path`]) in one step; then entries of an earlier run that
    /// this one did not write go, the new entries move in and the new manifest replaces the old
    /// one last. A process killed at any point leaves the old model (before the rename) or a
    /// commit that the next open of `out` finishes ([`open_for_reading`], [`Self::begin`]).
    pub fn commit(mut self) -> Result<()> {
        let manifest = compute_manifest(&self.dir)?;
        write_json(&self.dir.join(MANIFEST_FILE), &manifest)?;
        let mut names = Vec::new();
        for entry in std::fs::read_dir(&self.dir).map_err(|e| Error::io(&self.dir, e))? {
            let entry = entry.map_err(|e| Error::io(&self.dir, e))?;
            names.push(entry.file_name().to_string_lossy().into_owned());
        }
        names.sort();
        std::fs::create_dir_all(&self.out).map_err(|e| Error::io(&self.out, e))?;
        let plan = CommitPlan { earlier: holds_artefact(&self.out), names };
        write_json(&self.dir.join(PLAN_FILE), &plan)?;
        sync_tree(&self.dir)?;
        kill_point("staged");
        let commit = commit_path(&self.out)?;
        std::fs::rename(&self.dir, &commit).map_err(|e| Error::io(&commit, e))?;
        sync_parent(&commit);
        self.committed = true;
        kill_point("renamed");
        finish_commit(&self.out)
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        // A checkpoint in the staging directory is this run's or an interrupted one's (never a
        // copy of the finished run's): `--resume` continues from it.
        if !self.committed && !self.dir.join(CHECKPOINT_FILE).is_file() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Whether `dir` holds an artefact of an earlier run (its manifest, or a config resolved by
/// meshdeco): only then are that run's entries which this run did not write removed.
fn holds_artefact(dir: &Path) -> bool {
    dir.join(MANIFEST_FILE).is_file()
        || std::fs::read_to_string(dir.join("config.toml")).is_ok_and(|t| t.starts_with("# Resolved by meshdeco"))
}

fn remove_entry(path: &Path) -> Result<()> {
    let meta = std::fs::symlink_metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_dir() { std::fs::remove_dir_all(path) } else { std::fs::remove_file(path) }
        .map_err(|e| Error::io(path, e))
}

/// Makes everything written under `dir` durable: one `syncfs` on Linux (the file system of
/// `dir`), a sync of each file elsewhere.
fn sync_tree(dir: &Path) -> Result<()> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let d = File::open(dir).map_err(|e| Error::io(dir, e))?;
        // SAFETY: `syncfs` only reads the descriptor, which `d` keeps open for the call.
        if unsafe { libc::syncfs(d.as_raw_fd()) } != 0 {
            return Err(Error::io(dir, std::io::Error::last_os_error()));
        }
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    {
        fn walk(p: &Path) -> Result<()> {
            for entry in std::fs::read_dir(p).map_err(|e| Error::io(p, e))? {
                let path = entry.map_err(|e| Error::io(p, e))?.path();
                if path.is_dir() {
                    walk(&path)?;
                } else {
                    File::open(&path).and_then(|f| f.sync_all()).map_err(|e| Error::io(&path, e))?;
                }
            }
            Ok(())
        }
        walk(dir)
    }
}
