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
    super::sequence::require_regular(path, &meta)?;
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

/// Lines of a text buffer with their 1-based numbers; a trailing `\r` is removed. (The same
/// lines as splitting at every `\n`, found eight bytes at a time.)
pub(crate) fn numbered_lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    let mut rest = Some(bytes);
    std::iter::from_fn(move || {
        let r = rest?;
        let line = match find_newline(r) {
            Some(i) => {
                rest = Some(&r[i + 1..]);
                &r[..i]
            }
            None => {
                rest = None;
                r
            }
        };
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    })
    .enumerate()
    .map(|(i, l)| (i + 1, l))
}

/// Index of the first `\n` in `s`: eight bytes per step (a word has a zero byte after XOR with
/// `\n` repeated exactly when `(w − 0x01…) & !w & 0x80…` is non-zero), then byte by byte.
#[inline]
fn find_newline(s: &[u8]) -> Option<usize> {
    const ONES: u64 = 0x0101_0101_0101_0101;
    const HIGHS: u64 = 0x8080_8080_8080_8080;
    let mut i = 0;
    while i + 8 <= s.len() {
        let w = u64::from_le_bytes(s[i..i + 8].try_into().unwrap_or([0; 8])) ^ (ONES * u64::from(b'\n'));
        let z = w.wrapping_sub(ONES) & !w & HIGHS;
        if z != 0 {
            return Some(i + (z.trailing_zeros() / 8) as usize);
        }
        i += 8;
    }
    s[i..].iter().position(|&b| b == b'\n').map(|k| i + k)
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
    fast_decimal(token).or_else(|| std::str::from_utf8(token).ok()?.parse::<f64>().ok())
}

/// Exact powers of ten representable in an f64 (10^0 … 10^22).
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20,
    1e21, 1e22,
];

/// Clinger's fast path for the numbers mesh files are made of: `[+-]digits[.digits][e[+-]digits]`
/// with at most 15 significant digits and a decimal exponent within ±22. The mantissa is then
/// exact in an f64 and so is the power of ten, and one correctly rounded multiplication or
/// division gives the correctly rounded result — the same bits as `str::parse`. Anything else
/// (more digits, large exponents, `nan`, `inf`, junk) returns `None` and takes the general path.
pub(crate) fn fast_decimal(t: &[u8]) -> Option<f64> {
    let (neg, mut i) = match t.first()? {
        b'-' => (true, 1),
        b'+' => (false, 1),
        _ => (false, 0),
    };
    let (mut mant, mut digits, mut exp, mut any) = (0u64, 0u32, 0i32, false);
    let mut take = |i: &mut usize, after_point: bool| {
        while let Some(&b) = t.get(*i) {
            if !b.is_ascii_digit() {
                break;
            }
            any = true;
            if mant != 0 || b != b'0' {
                digits += 1;
            }
            mant = mant.wrapping_mul(10) + u64::from(b - b'0');
            if after_point {
                exp -= 1;
            }
            *i += 1;
        }
    };
    take(&mut i, false);
    if t.get(i) == Some(&b'.') {
        i += 1;
        take(&mut i, true);
    }
    if !any || digits > 15 {
        return None;
    }
    if let Some(&b) = t.get(i)
        && (b | 0x20) == b'e'
    {
        i += 1;
        let eneg = match t.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let start = i;
        let mut e: i32 = 0;
        while let Some(&b) = t.get(i) {
            if !b.is_ascii_digit() || e > 1000 {
                break;
            }
            e = e * 10 + i32::from(b - b'0');
            i += 1;
        }
        if i == start || e > 1000 {
            return None;
        }
        exp += if eneg { -e } else { e };
    }
    if i != t.len() {
        return None;
    }
    let v = if mant == 0 {
        0.0
    } else if (0..=22).contains(&exp) {
        mant as f64 * POW10[exp as usize]
    } else if (-22..0).contains(&exp) {
        mant as f64 / POW10[(-exp) as usize]
    } else {
        return None;
    };
    Some(if neg { -v } else { v })
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

#[cfg(test)]
mod line_tests {
    #[test]
    fn lines_are_those_of_a_plain_split() {
        let mut text = Vec::new();
        for i in 0..200usize {
            text.extend(std::iter::repeat_n(b'a' + (i % 26) as u8, i % 19));
            text.extend_from_slice(if i % 7 == 0 { b"\r\n" } else { b"\n" });
            if i % 11 == 0 {
                text.push(b'\n');
            }
        }
        for cut in [0, 1, 7, 8, 9, text.len() - 1, text.len()] {
            let t = &text[..cut];
            let want: Vec<(usize, &[u8])> = t
                .split(|&b| b == b'\n')
                .enumerate()
                .map(|(i, l)| (i + 1, l.strip_suffix(b"\r").unwrap_or(l)))
                .collect();
            assert_eq!(super::numbered_lines(t).collect::<Vec<_>>(), want, "cut {cut}");
        }
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
    fn fast_decimal_gives_the_bits_of_str_parse() {
        // Deterministic mix of the forms mesh files hold (and some that take the slow path).
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut fast = 0;
        for _ in 0..200_000 {
            let r = next();
            let int = r % 10u64.pow((r >> 8) as u32 % 8);
            let frac_digits = (r >> 16) as usize % 12;
            let frac = next() % 10u64.pow(frac_digits as u32);
            let sign = ["", "-", "+"][(r >> 24) as usize % 3];
            let exp = match (r >> 28) % 4 {
                0 => String::new(),
                1 => format!("e{}", (r >> 32) % 30),
                2 => format!("E-{}", (r >> 32) % 30),
                _ => format!("e+{}", (r >> 32) % 5),
            };
            let text = if frac_digits == 0 {
                format!("{sign}{int}{exp}")
            } else {
                format!("{sign}{int}.{frac:0frac_digits$}{exp}")
            };
            let want: f64 = text.parse().unwrap();
            let got = parse_f64(text.as_bytes()).unwrap();
            assert_eq!(got.to_bits(), want.to_bits(), "{text}");
            fast += usize::from(fast_decimal(text.as_bytes()).is_some());
        }
        assert!(fast > 100_000, "the fast path took only {fast} of 200000");
        for junk in ["", "-", ".", "1.2.3", "1e", "1e+", "e5", "1x", "nan", "inf", "0x10", "--1"] {
            assert_eq!(
                parse_f64(junk.as_bytes()).map(f64::to_bits),
                junk.parse::<f64>().ok().map(f64::to_bits),
                "{junk}"
            );
            if junk != "nan" && junk != "inf" {
                assert!(fast_decimal(junk.as_bytes()).is_none(), "{junk}");
            }
        }
        assert_eq!(parse_f64(b"-0.0").unwrap().to_bits(), (-0.0f64).to_bits());
        assert_eq!(parse_f64(b"12345678901234567890").unwrap(), 12345678901234567890.0);
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

    /// The fast path's own contract at its bounds (the random test above checks only that its
    /// results equal `str::parse`'s and that it is taken often): 15 significant digits (leading
    /// zeros not counted) and not 16, both exponent letters and signs, decimal exponents ±22 and
    /// not ±23, junk after the exponent, and exponents too long for an `i32`.
    #[test]
    fn fast_decimal_takes_its_numbers_and_no_others() {
        let fast = |t: &str| fast_decimal(t.as_bytes()).map(f64::to_bits);
        let parsed = |t: &str| Some(t.parse::<f64>().unwrap().to_bits());
        for t in [
            "123456789012345",
            "-1234567.89012345",
            "0.000000000000000012",
            "0.0000000000000000000012",
            "1e5",
            "1E5",
            "2.5e-5",
            "2.5E+5",
            "7e22",
            "7e-22",
            "+3",
        ] {
            assert_eq!(fast(t), parsed(t), "{t} takes the fast path");
        }
        for t in ["1234567890123456", "1000000000000000", "7e23", "7e-23", "1e5x", "1e-5-", "1e+"] {
            assert_eq!(fast(t), None, "{t} is not for the fast path");
        }
        // Exponents that would overflow an i32 when accumulated: the general path's answers.
        for t in ["1e4294967296", "1e-4294967296", "1e99999999999", "5e1000"] {
            assert_eq!(fast(t), None, "{t}");
            assert_eq!(parse_f64(t.as_bytes()).map(f64::to_bits), parsed(t), "{t}");
        }
        assert_eq!(parse_f64(b"1e5x"), None);
    }

    #[test]
    fn shown_tokens_are_cut_after_40_characters() {
        let forty = "é".repeat(40);
        assert_eq!(show(forty.as_bytes()), forty);
        let forty_one = format!("{forty}z");
        assert_eq!(show(forty_one.as_bytes()), format!("{forty}…"));
        assert_eq!(show(&[b'a', 0xff]), "a\u{fffd}");
    }
}
