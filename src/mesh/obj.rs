//! Wavefront OBJ reader (geometry only).
//!
//! meshdeco parses OBJ itself instead of going through `tobj`: `tobj` reports errors without
//! file or line and silently skips lines it cannot parse, which would let a corrupt file through.
//! Only what a deformation dataset needs is read:
//! - `v x y z [...]`: the first three numbers are the position (a `w` or vertex colours after
//!   them are ignored); fewer than three numbers, a non-number or a non-finite value is an error.
//! - `f a b c ...`: vertex references `i`, `i/t`, `i//n` or `i/t/n`; only `i` is used. Indices are
//!   1-based; negative indices count back from the last vertex defined so far. Zero, an index that
//!   resolves outside the vertex list, or a non-integer is an error. Faces may refer to vertices
//!   defined later in the file. Polygons with more than 3 vertices are **triangulated as fans**
//!   around their first vertex and reported in a warning.
//! - `vt`, `vn`, `vp`, `g`, `o`, `s`, `usemtl`, `mtllib` and comments are ignored without a
//!   warning (they do not change the geometry); `l`, `p` and free-form geometry statements
//!   (`curv`, `surf`, …) are skipped with a warning; any other statement is skipped with a warning
//!   naming its first line.
//!
//! `#` starts a comment anywhere on a line. Line continuations (`\` at the end of a line) are
//! rejected with a clear error.

use std::path::Path;

use super::TriMesh;
use super::load::{
    FaceCollector, LoadedMesh, fast_decimal, finite_coordinate, numbered_lines, parse_f64, show, tokens,
};
use crate::error::{Error, Result};

/// Statements that do not affect positions or triangles and are skipped without a warning.
const SILENT: [&[u8]; 12] =
    [b"vt", b"vn", b"vp", b"g", b"o", b"s", b"usemtl", b"mtllib", b"lod", b"maplib", b"usemap", b"shadow_obj"];

/// Parses OBJ content; `path` is used in messages only. See the module docs for what is read.
pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<LoadedMesh> {
    let mut positions: Vec<[f64; 3]> = Vec::new();
    let mut faces = FaceCollector::default();
    let mut polygon: Vec<usize> = Vec::with_capacity(8);
    // (count, first line, statement) of skipped statements, for the warnings.
    let mut skipped: Vec<(usize, usize, String)> = Vec::new();
    // (count, first line) of `v` lines with unexpected data after the position.
    let mut trailing: (usize, Option<usize>) = (0, None);

    for (line_no, line) in numbered_lines(bytes) {
        // The lines almost every file is made of take one pass; anything else (comments, extra
        // data, other number forms, errors) goes the general way below.
        if let Some(p) = plain_vertex(line) {
            positions.push(p);
            continue;
        }
        if plain_face(line, &mut polygon) {
            faces.push(&polygon, line_no).map_err(|m| Error::parse(path, Some(line_no), m))?;
            continue;
        }
        let line = line.split(|&b| b == b'#').next().unwrap_or(line);
        let mut tok = tokens(line);
        let Some(keyword) = tok.next() else { continue };
        if line.trim_ascii_end().ends_with(b"\\") {
            return Err(Error::parse(
                path,
                Some(line_no),
                "line continuations ('\\' at the end of a line) are not supported",
            ));
        }
        match keyword {
            b"v" => {
                let mut p = [0.0; 3];
                for (axis, slot) in p.iter_mut().enumerate() {
                    let t = tok.next().ok_or_else(|| {
                        Error::parse(path, Some(line_no), format!("vertex has {axis} coordinates, expected 3"))
                    })?;
                    *slot = finite_coordinate(t, axis).map_err(|m| Error::parse(path, Some(line_no), m))?;
                }
                // After x y z, OBJ allows a weight w or a colour r g b (numbers); anything else
                // is reported (and ignored).
                let (mut extra, mut numeric) = (0, true);
                for t in tok {
                    extra += 1;
                    numeric &= parse_f64(t).is_some_and(f64::is_finite);
                }
                if !(numeric && matches!(extra, 0 | 1 | 3)) {
                    trailing.0 += 1;
                    trailing.1.get_or_insert(line_no);
                }
                positions.push(p);
            }
            b"f" => {
                polygon.clear();
                for t in tok {
                    let idx = resolve_index(t, positions.len()).map_err(|m| Error::parse(path, Some(line_no), m))?;
                    polygon.push(idx);
                }
                faces.push(&polygon, line_no).map_err(|m| Error::parse(path, Some(line_no), m))?;
            }
            k if SILENT.contains(&k) => {}
            k => {
                let name = show(k);
                match skipped.iter_mut().find(|s| s.2 == name) {
                    Some(s) => s.0 += 1,
                    None => skipped.push((1, line_no, name)),
                }
            }
        }
    }

    if positions.is_empty() {
        return Err(Error::parse(path, None, "no vertices ('v' lines) found"));
    }
    if faces.faces.is_empty() {
        return Err(Error::parse(path, None, "no faces ('f' lines) found: a point cloud is not a mesh"));
    }
    if let Some((line, v)) = faces.first_out_of_range(positions.len()) {
        return Err(Error::parse(
            path,
            Some(line),
            format!("vertex index {} out of range (the file has {} vertices)", v + 1, positions.len()),
        ));
    }
    let p = path.display();
    let mut warnings: Vec<String> = faces.polygon_warning(|l| format!("{p}:{l}")).into_iter().collect();
    if let (n, Some(first)) = trailing {
        warnings.push(format!(
            "{p}:{first}: {n} 'v' line(s) carry data after x y z that is neither a weight w nor a colour r g b; it is ignored"
        ));
    }
    for (count, line, name) in skipped {
        let what = match name.as_str() {
            "l" => "line elements ('l')".to_string(),
            "p" => "point elements ('p')".to_string(),
            other => format!("'{other}' statements"),
        };
        warnings.push(format!("{p}:{line}: {count} {what} ignored (only 'v' and 'f' are read)"));
    }
    Ok(LoadedMesh { mesh: TriMesh::new(positions, faces.faces), warnings })
}

/// Spaces and tabs from `i`: the index after them.
#[inline]
fn skip_blank(line: &[u8], mut i: usize) -> usize {
    while i < line.len() && (line[i] == b' ' || line[i] == b'\t') {
        i += 1;
    }
    i
}

/// `v x y z` with three plain decimals (Clinger's fast path: the same bits as the general
/// parser) and nothing after them but blanks; `None` sends the line the general way.
#[inline]
fn plain_vertex(line: &[u8]) -> Option<[f64; 3]> {
    if line.len() < 2 || line[0] != b'v' || (line[1] != b' ' && line[1] != b'\t') {
        return None;
    }
    let mut i = 1;
    let mut p = [0.0; 3];
    for slot in &mut p {
        let start = skip_blank(line, i);
        if start == i {
            return None;
        }
        i = start;
        while i < line.len() && !line[i].is_ascii_whitespace() {
            i += 1;
        }
        *slot = fast_decimal(&line[start..i])?;
    }
    (skip_blank(line, i) == line.len()).then_some(p)
}

/// `f a b c …` with positive indices, each optionally followed by `/t/n` parts made of digits
/// and slashes, nothing else but blanks, at least 3 of them: fills `polygon` (0-based) and
/// returns `true`; `false` sends the line the general way.
#[inline]
fn plain_face(line: &[u8], polygon: &mut Vec<usize>) -> bool {
    if line.len() < 2 || line[0] != b'f' || (line[1] != b' ' && line[1] != b'\t') {
        return false;
    }
    polygon.clear();
    let mut i = 1;
    loop {
        let start = skip_blank(line, i);
        if start == line.len() {
            break;
        }
        if start == i {
            return false;
        }
        i = start;
        let mut v: usize = 0;
        while i < line.len() && line[i].is_ascii_digit() {
            if i - start >= 18 {
                return false;
            }
            v = v * 10 + usize::from(line[i] - b'0');
            i += 1;
        }
        if i == start || v == 0 {
            return false;
        }
        while i < line.len() && (line[i] == b'/' || line[i].is_ascii_digit()) {
            i += 1;
        }
        if i < line.len() && line[i] != b' ' && line[i] != b'\t' {
            return false;
        }
        polygon.push(v - 1);
    }
    polygon.len() >= 3
}

/// `[-]digits` with at most 18 digits (no overflow), else `None` (the general parser decides).
fn digits_i64(t: &[u8]) -> Option<i64> {
    let (neg, d) = match t.first()? {
        b'-' => (true, &t[1..]),
        _ => (false, t),
    };
    if d.is_empty() || d.len() > 18 || !d.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let v = d.iter().fold(0i64, |v, &b| v * 10 + i64::from(b - b'0'));
    Some(if neg { -v } else { v })
}

/// Resolves one face vertex reference (`i`, `i/t`, `i//n`, `i/t/n`) to a 0-based index.
/// `defined` is the number of vertices defined before this line (for negative indices). The
/// upper bound of positive indices is checked after the whole file is read.
fn resolve_index(token: &[u8], defined: usize) -> std::result::Result<usize, String> {
    let head = token.split(|&b| b == b'/').next().unwrap_or(token);
    let value: i64 = digits_i64(head)
        .or_else(|| std::str::from_utf8(head).ok().and_then(|s| s.parse().ok()))
        .ok_or_else(|| format!("face vertex '{}' is not an integer index", show(token)))?;
    match value {
        0 => Err("face vertex index 0 (OBJ indices start at 1)".to_string()),
        v if v > 0 => Ok(v as usize - 1),
        v => {
            let back = v.unsigned_abs() as usize;
            if back > defined {
                Err(format!(
                    "relative face vertex index {v} reaches before the first vertex ({defined} defined so far)"
                ))
            } else {
                Ok(defined - back)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<LoadedMesh> {
        parse_obj(s.as_bytes(), Path::new("t.obj"))
    }

    #[test]
    fn reads_vertices_and_face_reference_forms() {
        let m = parse(
            "# comment\nv 0 0 0\nv 1 0 0 1.0\nv 0 1 0 0.5 0.5 0.5\r\nv 1 1 0\nvt 0 0\nvn 0 0 1\n\
             g grp\ns off\nf 1 2 3 # trailing comment\nf 2/1/1 4//1 -2/1\n",
        )
        .unwrap();
        assert!(m.warnings.is_empty(), "{:?}", m.warnings);
        assert_eq!(m.mesh.positions[1], [1.0, 0.0, 0.0]);
        assert_eq!(m.mesh.positions[2], [0.0, 1.0, 0.0]);
        // -2 after four vertices is the third vertex (index 2).
        assert_eq!(m.mesh.faces, vec![[0, 1, 2], [1, 3, 2]]);
    }

    #[test]
    fn quads_are_fanned_with_a_warning() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
        assert_eq!(m.mesh.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.warnings.len(), 1);
        assert!(m.warnings[0].starts_with("t.obj:5: 1 polygon"), "{}", m.warnings[0]);
    }

    #[test]
    fn plain_lines_take_the_fast_path_with_the_general_paths_results() {
        assert_eq!(plain_vertex(b"v 0.0176488 -0.0854527 0.270707"), Some([0.0176488, -0.0854527, 0.270707]));
        assert_eq!(plain_vertex(b"v\t1e-3 2.5E+2 -0 "), Some([1e-3, 2.5e2, -0.0]));
        for general in
            [&b"v 1 2"[..], b"v 1 2 3 4", b"v 1 2 3 # c", b" v 1 2 3", b"v 1 2 nan", b"v 1 2 3\\", b"vn 1 2 3"]
        {
            assert_eq!(plain_vertex(general), None, "{}", String::from_utf8_lossy(general));
        }
        let mut p = Vec::new();
        assert!(plain_face(b"f 1141// 1085// 1165//", &mut p) && p == [1140, 1084, 1164]);
        assert!(plain_face(b"f 1/2/3 4/5/6 7/8/9 10 ", &mut p) && p == [0, 3, 6, 9]);
        for general in [&b"f 1 2"[..], b"f 1 -2 3", b"f 0 1 2", b"f 1 2 3 # c", b"f 1 2 x", b"f 1/-1 2 3", b"fo 1 2 3"]
        {
            assert!(!plain_face(general, &mut p), "{}", String::from_utf8_lossy(general));
        }
        // Same mesh either way: the fast path on, and every line forced the general way by a
        // trailing comment.
        let text = "v 0.5 -1.25e-2 3\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1// 3// 4//\nf 2/1/1 3/2/2 4/3/3\n";
        let slow: String = text.lines().map(|l| format!("{l} #\n")).collect();
        let (a, b) = (parse(text).unwrap().mesh, parse(&slow).unwrap().mesh);
        assert_eq!((a.positions, a.faces), (b.positions, b.faces));
    }

    #[test]
    fn forward_references_are_allowed() {
        let m = parse("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
        assert_eq!(m.mesh.faces, vec![[0, 1, 2]]);
    }

    #[test]
    fn unknown_statements_are_reported() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nl 1 2\nbogus 1\nbogus 2\n").unwrap();
        assert_eq!(m.warnings.len(), 2);
        assert!(m.warnings[0].contains("t.obj:5: 1 line elements"), "{:?}", m.warnings);
        assert!(m.warnings[1].contains("t.obj:6: 2 'bogus' statements"), "{:?}", m.warnings);
    }

    #[test]
    fn trailing_data_on_vertex_lines_is_reported_unless_a_weight_or_colour() {
        let ok = parse("v 0 0 0 1\nv 1 0 0 0.5 0.5 0.5\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert!(ok.warnings.is_empty(), "{:?}", ok.warnings);
        let m = parse("v 0 0 0 junk\nv 1 0 0 1 2\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(m.mesh.positions[1], [1.0, 0.0, 0.0]);
        assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
        assert!(m.warnings[0].starts_with("t.obj:1: 2 'v' line(s) carry data after x y z"), "{:?}", m.warnings);
    }

    fn err(s: &str) -> String {
        parse(s).unwrap_err().to_string()
    }

    #[test]
    fn malformed_lines_name_file_and_line() {
        let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        let e = err(&format!("{tri}v 1 2\nf 1 2 3\n"));
        assert!(e.starts_with("t.obj:4: vertex has 2 coordinates"), "{e}");
        let e = err(&format!("{tri}v 1 x 2\n"));
        assert!(e.starts_with("t.obj:4: y coordinate 'x' is not a number"), "{e}");
        let e = err(&format!("{tri}v 1 2 NaN\nf 1 2 3\n"));
        assert!(e.starts_with("t.obj:4: non-finite z coordinate 'NaN'"), "{e}");
        let e = err(&format!("{tri}f 1 2 4\n"));
        assert!(e.starts_with("t.obj:4: vertex index 4 out of range (the file has 3 vertices)"), "{e}");
        let e = err(&format!("{tri}f 0 1 2\n"));
        assert!(e.starts_with("t.obj:4: face vertex index 0"), "{e}");
        let e = err(&format!("{tri}f 1 2 -4\n"));
        assert!(e.starts_with("t.obj:4: relative face vertex index -4"), "{e}");
        let e = err(&format!("{tri}f 1 2\n"));
        assert!(e.starts_with("t.obj:4: face with 2 vertices"), "{e}");
        let e = err(&format!("{tri}f 1 2 a\n"));
        assert!(e.starts_with("t.obj:4: face vertex 'a' is not an integer"), "{e}");
        let e = err(&format!("{tri}f 1 2 \\\n 3\n"));
        assert!(e.starts_with("t.obj:4: line continuations"), "{e}");
        let e = err(tri);
        assert!(e.starts_with("t.obj: no faces"), "{e}");
        let e = err("# empty\n");
        assert!(e.starts_with("t.obj: no vertices"), "{e}");
    }

    /// General-path indices (multi-digit, negative back to the first vertex, a lone '-', more
    /// digits than an i64), digits_i64's own answers, and tabs in fast-path faces.
    #[test]
    fn general_path_indices_and_fast_path_edges() {
        let mut text: String = (0..12).map(|i| format!("v {i} 0 0\n")).collect();
        text.push_str("f 10 11 12 #\nf -12 -11 -10\nf -3 -2 -1\n");
        let m = parse(&text).unwrap();
        assert_eq!(m.mesh.faces, vec![[9, 10, 11], [0, 1, 2], [9, 10, 11]]);
        let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        for bad in ["-", "99999999999999999999"] {
            let e = err(&format!("{tri}f 1 2 {bad}\n"));
            assert!(e.starts_with(&format!("t.obj:4: face vertex '{bad}' is not an integer index")), "{e}");
        }
        assert_eq!(digits_i64(b"-12"), Some(-12));
        assert_eq!(digits_i64(b"123456789012345678"), Some(123_456_789_012_345_678));
        let mut p = Vec::new();
        assert!(plain_face(b"f\t1 2 3", &mut p) && p == [0, 1, 2]);
        assert!(plain_face(b"f 1\t2\t3", &mut p) && p == [0, 1, 2]);
    }

    /// Only `f` lines are faces: a polyline or a point element of three indices (`l 1 2 3`,
    /// `p 1 2 3`) is counted and reported, never read as a triangle by the fast path.
    #[test]
    fn line_and_point_elements_of_three_indices_are_not_faces() {
        let mut p = Vec::new();
        for other in [&b"l 1 2 3"[..], b"p 1 2 3", b"s 1 2 3", b"g\t1 2 3"] {
            assert!(!plain_face(other, &mut p), "{}", String::from_utf8_lossy(other));
        }
        let m = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nl 1 2 3\nl 2 3 4\np 1 2 4\nf 1 2 3\n").unwrap();
        assert_eq!(m.mesh.faces, vec![[0, 1, 2]]);
        assert_eq!(m.warnings.len(), 2, "{:?}", m.warnings);
        assert!(m.warnings[0].starts_with("t.obj:5: 2 line elements ('l') ignored"), "{}", m.warnings[0]);
        assert!(m.warnings[1].starts_with("t.obj:7: 1 point elements ('p') ignored"), "{}", m.warnings[1]);
    }
}
