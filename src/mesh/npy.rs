//! Mesh sequences stored as NumPy arrays: a `.npy` file, or one array of a `.npz` archive, of
//! shape F × N × 3 (frames × vertices × xyz; `float32` or `float64`, either byte order, C or
//! Fortran order), with the faces taken from a template mesh of N vertices (the DFAUST- and
//! COMA-style layout). Frames are named `<stem>_<i>` (1-based, zero-padded).
//!
//! Everything read is checked before anything large is allocated: the array's shape against the
//! bytes actually present, the vertex count against the template, every value finite. Errors name
//! the file, the array and the expected shape.

use std::io::{Cursor, Read};
use std::path::Path;

use super::{MeshSequence, Vec3};
use crate::error::{Error, Result};

/// Whether `path` names a NumPy file (`.npy` or `.npz`, case-insensitive).
pub fn is_numpy_path(path: &str) -> bool {
    let l = path.to_ascii_lowercase();
    l.ends_with(".npy") || l.ends_with(".npz")
}

/// Reads the F × N × 3 array of `path` (`array`: the name inside a `.npz`; must be `None` for a
/// `.npy`) as a sequence with the faces of the mesh file `template`.
pub fn load_npy_sequence(path: &Path, array: Option<&str>, template: &Path) -> Result<MeshSequence> {
    let tmpl = super::load_mesh(template)?;
    load_npy_with_faces(path, array, tmpl.n_vertices(), tmpl.faces)
}

/// Reads the F × N × 3 array of `path` as a sequence with the given connectivity (`n_vertices`
/// vertices, `faces`: e.g. a trained model's rest mesh, which is the template it was trained
/// with).
pub fn load_npy_with_faces(
    path: &Path,
    array: Option<&str>,
    n_vertices: usize,
    faces: Vec<[usize; 3]>,
) -> Result<MeshSequence> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let is_npz = path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    let (npy, what) = if is_npz {
        let name = array.ok_or_else(|| {
            Error::config("data.array", format!("{}: name the array of the .npz to read", path.display()))
        })?;
        (npz_entry(path, &bytes, name)?, format!("{} (array `{name}`)", path.display()))
    } else {
        if let Some(a) = array {
            return Err(Error::config(
                "data.array",
                format!("`{a}` is given, but {} is a .npy with a single array", path.display()),
            ));
        }
        (bytes, path.display().to_string())
    };
    let frames = parse_frames(&npy, &what, n_vertices)?;
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("frame").to_string();
    let width = frames.len().to_string().len();
    let names = (1..=frames.len()).map(|i| format!("{stem}_{i:0width$}")).collect();
    Ok(MeshSequence { faces, frames, names })
}

/// The bytes of `<name>.npy` inside the `.npz` archive `bytes`.
fn npz_entry(path: &Path, bytes: &[u8], name: &str) -> Result<Vec<u8>> {
    let bad = |m: String| Error::parse(path, None, m);
    let mut zip =
        zip::ZipArchive::new(Cursor::new(bytes)).map_err(|e| bad(format!("not a .npz (zip) archive: {e}")))?;
    let names: Vec<String> = zip.file_names().filter_map(|f| f.strip_suffix(".npy")).map(str::to_string).collect();
    let mut entry = zip.by_name(&format!("{name}.npy")).map_err(|_| {
        Error::config("data.array", format!("{}: no array `{name}` (it holds: {})", path.display(), names.join(", ")))
    })?;
    // The declared size must fit the archive before anything is allocated for it.
    if entry.size() > 64 * (bytes.len() as u64).max(1 << 20) {
        return Err(bad(format!("array `{name}` claims {} bytes, implausible for this archive", entry.size())));
    }
    let mut out = Vec::with_capacity(entry.size() as usize);
    entry.read_to_end(&mut out).map_err(|e| bad(format!("array `{name}`: {e}")))?;
    Ok(out)
}

/// Parses an F × N × 3 `.npy` image into frames, checking the shape against `n_vertices`.
fn parse_frames(bytes: &[u8], what: &str, n_vertices: usize) -> Result<Vec<Vec<Vec3>>> {
    let bad = |m: String| Error::Invalid(format!("{what}: {m}"));
    let npy = npyz::NpyFile::new(bytes).map_err(|e| bad(format!("not a NumPy .npy array: {e}")))?;
    let shape: Vec<u64> = npy.shape().to_vec();
    if shape.len() != 3 || shape[2] != 3 {
        return Err(bad(format!("shape {shape:?}, expected (frames, {n_vertices}, 3)")));
    }
    let (f, n) = (shape[0] as usize, shape[1] as usize);
    if n != n_vertices {
        return Err(bad(format!(
            "shape {shape:?}: {n} vertices per frame, the template mesh has {n_vertices} (expected ({f}, {n_vertices}, 3))"
        )));
    }
    if f == 0 {
        return Err(bad("the array holds no frame".into()));
    }
    let item = match npy.dtype().num_bytes() {
        Some(b @ (4 | 8)) => b as u64,
        _ => return Err(bad(format!("dtype {} is not float32 or float64", npy.dtype().descr()))),
    };
    let needed = shape.iter().product::<u64>().saturating_mul(item);
    if needed > bytes.len() as u64 {
        return Err(bad(format!("shape {shape:?} needs {needed} bytes of data, the file has {} in all", bytes.len())));
    }
    let fortran = npy.order() == npyz::Order::Fortran;
    let values: Vec<f64> = match npy.try_data::<f64>() {
        Ok(r) => r.collect::<std::io::Result<Vec<f64>>>().map_err(|e| bad(format!("reading the values: {e}")))?,
        Err(npy) => match npy.try_data::<f32>() {
            Ok(r) => r
                .collect::<std::io::Result<Vec<f32>>>()
                .map_err(|e| bad(format!("reading the values: {e}")))?
                .into_iter()
                .map(f64::from)
                .collect(),
            Err(npy) => return Err(bad(format!("dtype {} is not float32 or float64", npy.dtype().descr()))),
        },
    };
    if values.len() != f * n * 3 {
        return Err(bad(format!("{} values read, shape {shape:?} needs {}", values.len(), f * n * 3)));
    }
    let at = |fi: usize, v: usize, c: usize| {
        if fortran { values[fi + f * (v + n * c)] } else { values[(fi * n + v) * 3 + c] }
    };
    let mut frames = Vec::with_capacity(f);
    for fi in 0..f {
        let mut frame = Vec::with_capacity(n);
        for v in 0..n {
            let p = [at(fi, v, 0), at(fi, v, 1), at(fi, v, 2)];
            if p.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!("frame {} (0-based {fi}), vertex {v} is not finite: {p:?}", fi + 1)));
            }
            frame.push(p);
        }
        frames.push(frame);
    }
    Ok(frames)
}

/// The header of a `.npy` (format 1.0) of `descr` (e.g. `<f8`), order and shape, padded so the
/// data starts at a multiple of 64 bytes.
fn npy_header(descr: &str, fortran: bool, shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let mut header = format!(
        "{{'descr': '{descr}', 'fortran_order': {}, 'shape': ({},), }}",
        if fortran { "True" } else { "False" },
        dims.join(", ")
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out
}

/// The `.npy` image (little-endian float64, C order) of frames, shape F × N × 3.
pub fn npy_image(frames: &[Vec<Vec3>]) -> Vec<u8> {
    let n = frames.first().map_or(0, Vec::len);
    let mut out = npy_header("<f8", false, &[frames.len(), n, 3]);
    for p in frames.iter().flatten() {
        for x in p {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    out
}

/// Writes frames (all of one vertex count) as a `.npy` (F × N × 3, float64), atomically.
pub fn write_npy(path: &Path, frames: &[Vec<Vec3>]) -> Result<()> {
    crate::artifact::write_atomic(path, &npy_image(frames))
}

/// Writes named frame arrays as an uncompressed `.npz` (what `numpy.savez` writes), atomically.
pub fn write_npz(path: &Path, arrays: &[(&str, &[Vec<Vec3>])]) -> Result<()> {
    let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let opts = zip::write::FileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, frames) in arrays {
        let io = |e: std::io::Error| Error::io(path, e);
        zip.start_file(format!("{name}.npy"), opts).map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
        std::io::Write::write_all(&mut zip, &npy_image(frames)).map_err(io)?;
    }
    let bytes = zip.finish().map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?.into_inner();
    crate::artifact::write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy_bytes(descr: &str, fortran: bool, shape: &[usize], data: &[u8]) -> Vec<u8> {
        let mut out = npy_header(descr, fortran, shape);
        out.extend_from_slice(data);
        out
    }

    #[test]
    fn reads_f32_f64_and_fortran_order() {
        // 2 frames × 2 vertices × 3: value = 100 f + 10 v + c.
        let val = |f: usize, v: usize, c: usize| (100 * f + 10 * v + c) as f64;
        let mut c64 = Vec::new();
        let mut c32 = Vec::new();
        let mut fo = Vec::new();
        for f in 0..2 {
            for v in 0..2 {
                for c in 0..3 {
                    c64.extend_from_slice(&val(f, v, c).to_le_bytes());
                    c32.extend_from_slice(&(val(f, v, c) as f32).to_le_bytes());
                }
            }
        }
        for c in 0..3 {
            for v in 0..2 {
                for f in 0..2 {
                    fo.extend_from_slice(&val(f, v, c).to_le_bytes());
                }
            }
        }
        for (descr, fortran, data) in [("<f8", false, c64), ("<f4", false, c32), ("<f8", true, fo)] {
            let frames = parse_frames(&npy_bytes(descr, fortran, &[2, 2, 3], &data), "t.npy", 2).unwrap();
            assert_eq!(frames[1][1], [110.0, 111.0, 112.0], "{descr} fortran {fortran}");
            assert_eq!(frames[0][1], [10.0, 11.0, 12.0]);
        }
    }

    #[test]
    fn bad_shapes_and_sizes_are_errors_naming_the_file() {
        let data = vec![0u8; 8 * 6];
        let e = parse_frames(&npy_bytes("<f8", false, &[1, 2, 3], &data), "t.npy", 5).unwrap_err().to_string();
        assert!(e.contains("t.npy") && e.contains("template mesh has 5") && e.contains("(1, 5, 3)"), "{e}");
        let e = parse_frames(&npy_bytes("<f8", false, &[2, 3], &data), "t.npy", 2).unwrap_err().to_string();
        assert!(e.contains("expected (frames, 2, 3)"), "{e}");
        // A header claiming 10^12 frames is refused before any allocation.
        let e = parse_frames(&npy_bytes("<f8", false, &[1_000_000_000_000, 2, 3], &data), "t.npy", 2)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bytes of data"), "{e}");
        let e = parse_frames(&npy_bytes("<i4", false, &[1, 2, 3], &data), "t.npy", 2).unwrap_err().to_string();
        assert!(e.contains("not float32 or float64"), "{e}");
        let mut nan = data.clone();
        nan[8..16].copy_from_slice(&f64::NAN.to_le_bytes());
        let e = parse_frames(&npy_bytes("<f8", false, &[1, 2, 3], &nan), "t.npy", 2).unwrap_err().to_string();
        assert!(e.contains("not finite"), "{e}");
        assert!(parse_frames(b"not numpy", "t.npy", 2).unwrap_err().to_string().contains("t.npy"));
    }
}
