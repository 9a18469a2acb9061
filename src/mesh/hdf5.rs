//! Mesh sequences stored in HDF5 files, as the field's reference tools write them: the SPLOCS
//! reference implementation's `verts` (F × N × 3) with its triangles in `tris` (T × 3), and
//! DFAUST's registrations (one dataset per `<subject>_<sequence>`, N × 3 × F, faces elsewhere:
//! a template mesh). Read with the HDF Group's C library (the `hdf5-metno` crate), which handles
//! every storage layout and filter h5py writes (contiguous, chunked, gzip, shuffle).
//!
//! Everything is checked before anything large is allocated, and errors name the file and the
//! dataset: a missing dataset (listing those present), a non-float type, a rank other than 3 or
//! a shape with no axis of 3, data the file cannot hold (a header declaring more frames than the
//! file stores: contiguous data past the end of the file, chunks never written, more values than
//! gzip could inflate the file to), non-finite values (naming frame, vertex and coordinate), and
//! triangles out of range. Frames are named `<dataset>_<i>` (1-based, zero-padded).

use std::path::Path;

use super::{MeshSequence, Vec3};
use crate::error::{Error, Result};

/// The dataset read when a path names none: the SPLOCS reference's.
pub const DEFAULT_DATASET: &str = "verts";
/// The triangles' dataset of the SPLOCS reference's files.
pub const TRIS: &str = "tris";
/// Largest ratio of decoded bytes to file bytes accepted: deflate cannot inflate data by more
/// than 1032 : 1, so a header declaring more values than that is not data the file holds.
const MAX_INFLATION: u64 = 1100;

/// Whether `path` names an HDF5 file (`.h5`, `.hdf5` or `.hdf`, case-insensitive), with or
/// without a `:dataset` suffix.
pub fn is_hdf5_path(path: &str) -> bool {
    split_spec(path).is_some()
}

/// `file.h5` → (`file.h5`, `None`); `file.h5:dataset` → (`file.h5`, `Some("dataset")`); `None`
/// for a path that is not an HDF5 file's.
pub fn split_spec(spec: &str) -> Option<(&str, Option<&str>)> {
    let ext = |p: &str| {
        let l = p.to_ascii_lowercase();
        l.ends_with(".h5") || l.ends_with(".hdf5") || l.ends_with(".hdf")
    };
    if ext(spec) {
        return Some((spec, None));
    }
    match spec.rsplit_once(':') {
        Some((f, d)) if ext(f) && !d.is_empty() => Some((f, Some(d))),
        _ => None,
    }
}

/// Where the triangles of an HDF5 sequence come from.
#[derive(Debug, Clone)]
pub enum Faces<'a> {
    /// The file's `tris` dataset (an error naming `data.template` when it has none).
    FromFile,
    /// The faces of this template mesh file.
    Template(&'a Path),
    /// The file's `tris` when it has one, else these (a trained model's connectivity).
    FileOr(&'a [[usize; 3]]),
}

/// Reads the sequence `dataset` of the HDF5 file `path` (layout F × N × 3 or N × 3 × F, float32
/// or float64) with the faces from `faces`.
pub fn load_hdf5_sequence(path: &Path, dataset: &str, faces: Faces<'_>) -> Result<MeshSequence> {
    crate::timing::timed("load hdf5", || {
        let file = open(path).map_err(|e| match e {
            Error::Invalid(m) => Error::Invalid(format!("{m} (reading dataset `{dataset}`)")),
            other => other,
        })?;
        let frames = read_frames(&file, path, dataset)?;
        let n = frames.first().map_or(0, |f| f.len());
        let faces = match faces {
            Faces::Template(t) => {
                let tmpl = super::load_mesh(t)?;
                if tmpl.n_vertices() != n {
                    return Err(Error::config(
                        "data.template",
                        format!(
                            "{} has {} vertices, dataset `{dataset}` of {} has {n}",
                            t.display(),
                            tmpl.n_vertices(),
                            path.display()
                        ),
                    ));
                }
                tmpl.faces
            }
            Faces::FromFile => {
                if !has_dataset(&file, TRIS) {
                    return Err(Error::config(
                        "data.template",
                        format!(
                            "{} has no `{TRIS}` dataset (the SPLOCS layout's triangles): give the faces as data.template = \"t.obj\"",
                            path.display()
                        ),
                    ));
                }
                read_tris(&file, path, n)?
            }
            Faces::FileOr(given) => {
                if has_dataset(&file, TRIS) {
                    read_tris(&file, path, n)?
                } else {
                    given.to_vec()
                }
            }
        };
        let width = frames.len().to_string().len();
        let stem = dataset.rsplit('/').next().unwrap_or(dataset);
        let names = (1..=frames.len()).map(|i| format!("{stem}_{i:0width$}")).collect();
        Ok(MeshSequence { faces, frames, names })
    })
}

/// Reads `spec` (`file.h5` or `file.h5:dataset`, default [`DEFAULT_DATASET`]) with the faces of
/// its `tris` dataset.
pub fn load_spec(spec: &str) -> Result<MeshSequence> {
    let (file, dataset) = split_spec(spec)
        .ok_or_else(|| Error::Invalid(format!("{spec}: not an HDF5 path (.h5, .hdf5 or .hdf, optionally :dataset)")))?;
    load_hdf5_sequence(Path::new(file), dataset.unwrap_or(DEFAULT_DATASET), Faces::FromFile)
}

/// Opens `path` read-only after checking that it is a regular file (a FIFO would block).
pub fn open(path: &Path) -> Result<::hdf5::File> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    super::sequence::require_regular(path, &meta)?;
    ::hdf5::File::open(path).map_err(|e| {
        Error::Invalid(format!("{}: not a readable HDF5 file (truncated or damaged?): {}", path.display(), clean(&e)))
    })
}

/// The HDF5 library's message without its stack noise.
fn clean(e: &::hdf5::Error) -> String {
    e.to_string().trim().to_string()
}

fn has_dataset(file: &::hdf5::File, name: &str) -> bool {
    file.link_exists(name) && file.dataset(name).is_ok()
}

/// The datasets at the root of `file` (for an error message).
fn root_datasets(file: &::hdf5::File) -> String {
    let names: Vec<String> =
        file.member_names().unwrap_or_default().into_iter().filter(|n| file.dataset(n).is_ok()).collect();
    if names.is_empty() { "none".into() } else { names.join(", ") }
}

/// Opens dataset `name`, naming the file and the datasets present when it is missing.
pub fn dataset(file: &::hdf5::File, path: &Path, name: &str) -> Result<::hdf5::Dataset> {
    if !file.link_exists(name) {
        return Err(Error::config(
            "data.dataset",
            format!("{} has no dataset `{name}` (datasets: {})", path.display(), root_datasets(file)),
        ));
    }
    file.dataset(name)
        .map_err(|e| Error::Invalid(format!("{}: `{name}` is not a readable dataset: {}", path.display(), clean(&e))))
}

/// Checks that every value the shape of `ds` declares is stored in the file (`elements` values):
/// contiguous data within the file, every chunk written and within the file, and no more values
/// than deflate could make of the file's bytes.
fn check_stored(ds: &::hdf5::Dataset, path: &Path, name: &str, elements: u64) -> Result<()> {
    let file_len = std::fs::metadata(path).map_err(|e| Error::io(path, e))?.len();
    let what = || format!("dataset `{name}` of {} (shape {:?})", path.display(), ds.shape());
    let type_size = ds.dtype().map(|t| t.size() as u64).unwrap_or(8);
    let declared = elements.checked_mul(type_size);
    if declared.is_none_or(|b| b > MAX_INFLATION.saturating_mul(file_len).saturating_add(1 << 20)) {
        return Err(Error::Invalid(format!(
            "{}: declares {elements} values, more than the file's {file_len} bytes can hold: a damaged or truncated file",
            what()
        )));
    }
    if ds.is_chunked() {
        let chunk = ds.chunk().unwrap_or_default();
        let needed: u64 = ds.shape().iter().zip(&chunk).map(|(&d, &c)| (d as u64).div_ceil(c.max(1) as u64)).product();
        let stored = ds.num_chunks().unwrap_or(0) as u64;
        if stored < needed {
            return Err(Error::Invalid(format!(
                "{}: stores {stored} of the {needed} chunks its shape needs: truncated or never fully written",
                what()
            )));
        }
        for i in 0..stored as usize {
            if let Some(c) = ds.chunk_info(i)
                && c.addr.saturating_add(c.size) > file_len
            {
                return Err(Error::Invalid(format!(
                    "{}: chunk {i} lies past the end of the file ({file_len} bytes): truncated",
                    what()
                )));
            }
        }
    } else if let Some(offset) = ds.offset() {
        let end = declared.and_then(|b| b.checked_add(offset));
        if end.is_none_or(|e| e > file_len) {
            return Err(Error::Invalid(format!(
                "{}: its {elements} values need bytes up to {}, the file has {file_len}: truncated",
                what(),
                end.map_or("beyond 2^64".to_string(), |e| e.to_string())
            )));
        }
    } else if ds.storage_size() < declared.unwrap_or(u64::MAX)
        && elements > 0
        && ds.layout() != ::hdf5::dataset::Layout::Compact
    {
        return Err(Error::Invalid(format!("{}: holds no data (never written)", what())));
    }
    Ok(())
}

/// The frames of dataset `name`: F × N × 3 (SPLOCS) or N × 3 × F (DFAUST), read as `f64`.
fn read_frames(file: &::hdf5::File, path: &Path, name: &str) -> Result<Vec<Vec<Vec3>>> {
    let ds = dataset(file, path, name)?;
    let what = || format!("dataset `{name}` of {}", path.display());
    let dtype = ds.dtype().map_err(|e| Error::Invalid(format!("{}: unreadable type: {}", what(), clean(&e))))?;
    if !(dtype.is::<f32>() || dtype.is::<f64>()) {
        let d = dtype.to_descriptor().map(|d| d.to_string()).unwrap_or_else(|_| "unknown".into());
        return Err(Error::Invalid(format!("{}: type {d}, expected float32 or float64 coordinates", what())));
    }
    let shape = ds.shape();
    if shape.len() != 3 {
        return Err(Error::Invalid(format!(
            "{}: rank {} (shape {shape:?}); expected 3: frames × vertices × 3 (SPLOCS) or vertices × 3 × frames (DFAUST)",
            what(),
            shape.len()
        )));
    }
    // F × N × 3 unless only the middle axis is 3.
    let frames_first = shape[2] == 3;
    if !frames_first && shape[1] != 3 {
        return Err(Error::Invalid(format!(
            "{}: shape {shape:?} has no axis of 3 coordinates where expected: frames × vertices × 3 or vertices × 3 × frames",
            what()
        )));
    }
    let (f, n) = if frames_first { (shape[0], shape[1]) } else { (shape[2], shape[0]) };
    if f == 0 || n == 0 {
        return Err(Error::Invalid(format!("{}: shape {shape:?} holds no frame or no vertex", what())));
    }
    let elements = (f as u64).checked_mul(n as u64).and_then(|x| x.checked_mul(3)).unwrap_or(u64::MAX);
    check_stored(&ds, path, name, elements)?;
    let raw: Vec<f64> =
        ds.read_raw().map_err(|e| Error::Invalid(format!("{}: reading its values failed: {}", what(), clean(&e))))?;
    if raw.len() as u64 != elements {
        return Err(Error::Invalid(format!("{}: read {} values, its shape declares {elements}", what(), raw.len())));
    }
    let at = |fi: usize, v: usize, c: usize| if frames_first { (fi * n + v) * 3 + c } else { (v * 3 + c) * f + fi };
    let mut frames = Vec::with_capacity(f);
    for fi in 0..f {
        let mut frame = Vec::with_capacity(n);
        for v in 0..n {
            let p = [raw[at(fi, v, 0)], raw[at(fi, v, 1)], raw[at(fi, v, 2)]];
            if let Some(c) = p.iter().position(|x| !x.is_finite()) {
                return Err(Error::Invalid(format!(
                    "{}: frame {} (0-based {fi}), vertex {v}, coordinate {c} is not finite ({})",
                    what(),
                    fi + 1,
                    p[c]
                )));
            }
            frame.push(p);
        }
        frames.push(frame);
    }
    Ok(frames)
}

/// The `tris` dataset: T × 3 integer vertex indices below `n`.
fn read_tris(file: &::hdf5::File, path: &Path, n: usize) -> Result<Vec<[usize; 3]>> {
    let ds = dataset(file, path, TRIS)?;
    let what = || format!("dataset `{TRIS}` of {}", path.display());
    let dtype = ds.dtype().map_err(|e| Error::Invalid(format!("{}: unreadable type: {}", what(), clean(&e))))?;
    let integer = matches!(
        dtype.to_descriptor(),
        Ok(::hdf5::types::TypeDescriptor::Integer(_)) | Ok(::hdf5::types::TypeDescriptor::Unsigned(_))
    );
    if !integer {
        return Err(Error::Invalid(format!("{}: expected integer vertex indices", what())));
    }
    let shape = ds.shape();
    if shape.len() != 2 || shape[1] != 3 || shape[0] == 0 {
        return Err(Error::Invalid(format!("{}: shape {shape:?}, expected (triangles, 3)", what())));
    }
    check_stored(&ds, path, TRIS, shape[0] as u64 * 3)?;
    let raw: Vec<i64> =
        ds.read_raw().map_err(|e| Error::Invalid(format!("{}: reading its values failed: {}", what(), clean(&e))))?;
    raw.chunks_exact(3)
        .enumerate()
        .map(|(t, c)| {
            let mut tri = [0usize; 3];
            for (j, &i) in c.iter().enumerate() {
                if i < 0 || i as u64 >= n as u64 {
                    return Err(Error::Invalid(format!(
                        "{}: triangle {t} has vertex index {i}, out of range for {n} vertices",
                        what()
                    )));
                }
                tri[j] = i as usize;
            }
            Ok(tri)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hdf5_paths_and_dataset_suffixes() {
        assert_eq!(split_spec("a/b.h5"), Some(("a/b.h5", None)));
        assert_eq!(split_spec("b.HDF5:50002_jumping_jacks"), Some(("b.HDF5", Some("50002_jumping_jacks"))));
        assert_eq!(split_spec("b.hdf:verts"), Some(("b.hdf", Some("verts"))));
        assert_eq!(split_spec("b.h5:"), None);
        assert_eq!(split_spec("b.npz:verts"), None);
        assert_eq!(split_spec("dir/frames"), None);
        assert!(!is_hdf5_path("x.obj"));
    }
}
