//! The artefact directory every method writes, and the versioned model file format.
//!
//! ```text
//! <out>/config.toml      the resolved config (every default written out)
//! <out>/model.json       model header: format version, method, representation, rest mesh,
//!                        scalings, hyperparameters, and the table of arrays in model.bin
//! <out>/model.bin        little-endian f64 arrays, concatenated, as listed in model.json
//! <out>/weights.csv      frame × component weights of the training frames
//! <out>/metrics.json     method, representation, components, train_erms, test_erms, …
//! <out>/components/      per component: heat-map PLY on the rest mesh and ±1 shapes (OBJ)
//! ```
//!
//! Every file is written atomically ([`write_atomic_with`]: temporary file in the same directory,
//! then rename), so
//! an interrupted run never leaves a half-written model; non-finite numbers are refused.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Version of the model file format written by this build.
pub const FORMAT_VERSION: u32 = 1;

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

/// Writes `path` atomically, streaming the content: `body` writes into the temporary file
/// `<path>.tmp` in the same directory (buffered), which is then flushed, synced to disk and renamed
/// over `path`, so a reader never sees a half-written file. On any failure, including an error
/// returned by `body`, the temporary file is removed and `path` is left as it was; the error is
/// [`Error::Io`] naming `path`. The parent directory must exist ([`write_atomic`] creates it).
///
/// This is the one atomic writer of the crate; every file meshdeco writes goes through it.
pub fn write_atomic_with(path: &Path, body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let result = (|| {
        let file = File::create(&tmp)?;
        let mut w = BufWriter::new(file);
        body(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
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
    let file: HeaderFile<H> =
        serde_json::from_str(&text).map_err(|e| Error::parse(&json, Some(e.line()), e.to_string()))?;
    let bin = dir.join("model.bin");
    let bytes = std::fs::read(&bin).map_err(|e| Error::io(&bin, e))?;
    if bytes.len() % 8 != 0 {
        return Err(Error::parse(&bin, None, format!("size {} is not a multiple of 8 bytes", bytes.len())));
    }
    let all: Vec<f64> = bytes.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
    let mut store = ArrayStore::new();
    for (name, entry) in file.arrays {
        let n: usize = entry.shape.iter().product();
        let data = all.get(entry.offset..entry.offset + n).ok_or_else(|| {
            Error::parse(
                &bin,
                None,
                format!(
                    "array `{name}` ({n} numbers at {}) lies past the end of the file ({} numbers)",
                    entry.offset,
                    all.len()
                ),
            )
        })?;
        store.insert(&name, entry.shape, data.to_vec()).map_err(|e| Error::parse(&bin, None, e.to_string()))?;
    }
    Ok((file.header, store))
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
        assert!(e.contains("model.bin") && e.contains("past the end"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}

/// File name of the lock of an artefact directory being written.
pub const LOCK_FILE: &str = ".meshdeco.lock";

/// An exclusive lock on an artefact directory: one writer at a time. Held until dropped; the
/// lock file (holding the writer's process id) is removed then.
#[derive(Debug)]
pub struct DirLock {
    path: PathBuf,
    _file: File,
}

impl DirLock {
    /// Locks `dir` (created if missing), or errors at once — naming the directory and the
    /// process holding it — when another process writes there.
    pub fn acquire(dir: &Path) -> Result<Self> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let path = dir.join(LOCK_FILE);
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
                    dir.display(),
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
