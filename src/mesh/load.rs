//! Reading one mesh file: format dispatch by extension and the pieces every reader shares
//! (line splitting, number parsing, polygon triangulation, index validation).
//!
//! Supported formats (extension, case-insensitive): `.obj` ([`super::obj`]), `.ply` ASCII and
//! binary ([`super::ply`]), `.off` ([`super::off`]). Readers never fix a file silently: anything
//! they change (polygons triangulated as fans) or skip (statements they do not understand) is
//! returned as a warning; anything that makes the mesh unusable (bad index, non-finite
//! coordinate, truncated data) is an [`Error`] naming the file and the line (ASCII) or the
//! element index (binary).

use std::path::Path;

use super::TriMesh;
use crate::error::{Error, Result};

/// File extensions (lower case, without the dot) that [`load_mesh`] reads.
pub const MESH_EXTENSIONS: [&str; 3] = ["obj", "ply", "off"];

/// A mesh read from a file, with the warnings of the reader (each a full message that names the
/// file, e.g. `"a.obj:12: 3 polygons with more than 3 vertices were triangulated as fans"`).
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedMesh {
    /// The triangle mesh (indices validated: every face index is `< n_vertices`).
    pub mesh: TriMesh,
    /// What the reader changed or ignored; empty for a clean file.
    pub warnings: Vec<String>,
}

/// Mesh format, chosen from the file extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (`v` and `f` statements).
    Obj,
    /// Stanford PLY, ASCII or binary.
    Ply,
    /// Object File Format (OFF, COFF, NOFF, … ASCII).
    Off,
}

impl MeshFormat {
    /// The format for `path`'s extension (case-insensitive), `None` when unsupported.
    pub fn from_path(path: &Path) -> Option<MeshFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Some(MeshFormat::Obj),
            "ply" => Some(MeshFormat::Ply),
            "off" => Some(MeshFormat::Off),
            _ => None,
        }
    }
}

/// Reads a triangle mesh, choosing the reader by extension. Reader warnings are printed to
/// standard error as `warning: …` lines; use [`read_mesh`] to receive them instead.
///
/// Errors: unreadable file ([`Error::Io`]), unsupported extension or malformed content
/// ([`Error::Parse`] with the file and, for text formats, the 1-based line).
pub fn load_mesh(path: &Path) -> Result<TriMesh> {
    let loaded = read_mesh(path)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    Ok(loaded.mesh)
}

/// Reads a triangle mesh and returns it with the reader's warnings (nothing is printed).
pub fn read_mesh(path: &Path) -> Result<LoadedMesh> {
    let format = MeshFormat::from_path(path).ok_or_else(|| {
        Error::parse(
            path,
            None,
            format!(
                "unsupported mesh format (extension {:?}); supported: .obj, .ply, .off",
                path.extension().map(|e| e.to_string_lossy().into_owned()).unwrap_or_default()
            ),
        )
    })?;
    // Never open a FIFO or a device (reading /dev/zero never ends; a FIFO blocks).
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::Invalid(format!(
            "{}: not a regular file ({})",
            path.display(),
            super::sequence::file_kind(&meta)
        )));
    }
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    crate::timing::count("mesh bytes read", bytes.len() as u64);
    parse_mesh(&bytes, format, path)
}

/// Parses mesh file content already in memory; `path` is used in messages only.
pub fn parse_mesh(bytes: &[u8], format: MeshFormat, path: &Path) -> Result<LoadedMesh> {
    match format {
        MeshFormat::Obj => super::obj::parse_obj(bytes, path),
        MeshFormat::Ply => super::ply::parse_ply(bytes, path),
        MeshFormat::Off => super::off::parse_off(bytes, path),
    }
}

/// Lines of a text buffer with their 1-based numbers; a trailing `\r` is removed.
pub(crate) fn numbered_lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    bytes.split(|&b| b == b'\n').enumerate().map(|(i, l)| (i + 1, l.strip_suffix(b"\r").unwrap_or(l)))
}

/// Whitespace-separated tokens of one line.
pub(crate) fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty())
}

/// A token for messages (lossy UTF-8, shortened to 40 characters).
pub(crate) fn show(token: &[u8]) -> String {
    let s = String::from_utf8_lossy(token);
    if s.chars().count() > 40 { format!("{}…", s.chars().take(40).collect::<String>()) } else { s.into_owned() }
}

/// Parses a floating-point token (`None` when it is not a number; `nan`/`inf` parse and are
/// rejected by [`finite_coordinate`]).
pub(crate) fn parse_f64(token: &[u8]) -> Option<f64> {
    std::str::from_utf8(token).ok()?.parse::<f64>().ok()
}

/// Parses a coordinate token and rejects non-numbers and non-finite values with a message
/// (`axis` is 0, 1 or 2 for x, y, z).
pub(crate) fn finite_coordinate(token: &[u8], axis: usize) -> std::result::Result<f64, String> {
    let name = ["x", "y", "z"][axis];
    match parse_f64(token) {
        Some(v) if v.is_finite() => Ok(v),
        Some(_) => Err(format!("non-finite {name} coordinate '{}'", show(token))),
        None => Err(format!("{name} coordinate '{}' is not a number", show(token))),
    }
}

/// Collects triangles from polygons: triangles are kept, larger polygons are split into a fan
/// around their first vertex (`(v0, v1, v2), (v0, v2, v3), …`, preserving orientation) and
/// counted so that the reader can warn. Polygons with fewer than 3 vertices are an error.
#[derive(Debug, Default)]
pub(crate) struct FaceCollector {
    /// Triangles collected so far.
    pub faces: Vec<[usize; 3]>,
    /// Per triangle, where it came from (line number for text formats, face index for binary).
    pub origin: Vec<usize>,
    /// Number of polygons with more than 3 vertices.
    pub n_polygons: usize,
    /// Origin and vertex count of the first such polygon.
    pub first_polygon: Option<(usize, usize)>,
}

impl FaceCollector {
    /// Adds one polygon (already 0-based); `origin` is its line or face number.
    pub fn push(&mut self, polygon: &[usize], origin: usize) -> std::result::Result<(), String> {
        if polygon.len() < 3 {
            let n = polygon.len();
            return Err(format!("face with {n} vert{} (at least 3 needed)", if n == 1 { "ex" } else { "ices" }));
        }
        if polygon.len() > 3 {
            self.n_polygons += 1;
            self.first_polygon.get_or_insert((origin, polygon.len()));
        }
        for k in 1..polygon.len() - 1 {
            self.faces.push([polygon[0], polygon[k], polygon[k + 1]]);
            self.origin.push(origin);
        }
        Ok(())
    }

    /// The first triangle that refers to a vertex `>= n_vertices`: (origin, bad index).
    pub fn first_out_of_range(&self, n_vertices: usize) -> Option<(usize, usize)> {
        self.faces.iter().zip(&self.origin).find_map(|(f, &o)| f.iter().find(|&&v| v >= n_vertices).map(|&v| (o, v)))
    }

    /// The fan-triangulation warning, if any polygon was split. `origin_name` formats an origin
    /// (e.g. `"path:12"` or `"path (face 7)"`).
    pub fn polygon_warning(&self, origin_name: impl Fn(usize) -> String) -> Option<String> {
        let (origin, n) = self.first_polygon?;
        Some(format!(
            "{}: {} polygon{} with more than 3 vertices triangulated as fans around their first vertex \
             (first one has {n} vertices)",
            origin_name(origin),
            self.n_polygons,
            if self.n_polygons == 1 { "" } else { "s" }
        ))
    }
}

/// A fresh, empty directory under the system temp dir for one unit test (`name` keeps parallel
/// tests apart).
#[cfg(test)]
pub(crate) fn test_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_by_extension_is_case_insensitive() {
        assert_eq!(MeshFormat::from_path(Path::new("a/B.OBJ")), Some(MeshFormat::Obj));
        assert_eq!(MeshFormat::from_path(Path::new("x.Ply")), Some(MeshFormat::Ply));
        assert_eq!(MeshFormat::from_path(Path::new("x.off")), Some(MeshFormat::Off));
        assert_eq!(MeshFormat::from_path(Path::new("x.stl")), None);
        assert_eq!(MeshFormat::from_path(Path::new("obj")), None);
    }

    #[test]
    fn unsupported_extension_names_the_file() {
        let e = read_mesh(Path::new("nowhere/mesh.stl")).unwrap_err().to_string();
        assert!(e.contains("nowhere/mesh.stl") && e.contains("unsupported"), "{e}");
    }

    #[test]
    fn fan_triangulation_keeps_orientation_and_counts_polygons() {
        let mut c = FaceCollector::default();
        c.push(&[0, 1, 2], 1).unwrap();
        c.push(&[3, 4, 5, 6, 7], 2).unwrap();
        assert_eq!(c.faces, vec![[0, 1, 2], [3, 4, 5], [3, 5, 6], [3, 6, 7]]);
        assert_eq!(c.origin, vec![1, 2, 2, 2]);
        assert_eq!(c.n_polygons, 1);
        assert!(c.push(&[1, 2], 3).is_err());
        assert_eq!(c.first_out_of_range(8), None);
        assert_eq!(c.first_out_of_range(7), Some((2, 7)));
        let w = c.polygon_warning(|o| format!("f:{o}")).unwrap();
        assert!(w.starts_with("f:2: 1 polygon ") && w.contains("5 vertices"), "{w}");
    }

    #[test]
    fn coordinates_must_be_finite_numbers() {
        assert_eq!(finite_coordinate(b"1.5e2", 0), Ok(150.0));
        assert!(finite_coordinate(b"nan", 1).unwrap_err().contains("non-finite y"));
        assert!(finite_coordinate(b"-inf", 2).unwrap_err().contains("non-finite z"));
        assert!(finite_coordinate(b"abc", 0).unwrap_err().contains("not a number"));
    }
}
