//! Object File Format (OFF) reader, ASCII only.
//!
//! The first keyword may be `OFF` or a variant with prefixes (`COFF`, `NOFF`, `CNOFF`, `STOFF`,
//! …); the counts `n_vertices n_faces [n_edges]` follow on the same line or on the next one
//! (`n_edges` is ignored). Each vertex is one line whose first three numbers are the position
//! (colours, normals or texture coordinates after them are ignored). Each face is one line
//! `n i_1 … i_n [colour]` with 0-based indices; faces with more than 3 vertices are triangulated
//! as fans around their first vertex and reported in a warning. `#` starts a comment; blank lines
//! are skipped. Binary OFF, 4D (`4OFF`) and n-dimensional (`nOFF`) files are rejected.

use std::path::Path;

use super::TriMesh;
use super::load::{FaceCollector, LoadedMesh, finite_coordinate, numbered_lines, show, tokens};
use crate::error::{Error, Result};

/// Parses OFF content; `path` is used in messages only.
pub fn parse_off<'a>(bytes: &'a [u8], path: &Path) -> Result<LoadedMesh> {
    // Non-empty lines with comments removed, as token lists. The vertex and face lines reuse
    // one token buffer (no allocation per line).
    fn next_tokens<'a>(raw: &mut impl Iterator<Item = (usize, &'a [u8])>, tok: &mut Vec<&'a [u8]>) -> Option<usize> {
        loop {
            let (no, line) = raw.next()?;
            let line = line.split(|&b| b == b'#').next().unwrap_or(line);
            tok.clear();
            tok.extend(tokens(line));
            if !tok.is_empty() {
                return Some(no);
            }
        }
    }
    let mut raw = numbered_lines(bytes);
    let mut next_line = |tok: &mut Vec<&'a [u8]>| next_tokens(&mut raw, tok);
    let mut head = Vec::new();
    let head_no = next_line(&mut head).ok_or_else(|| Error::parse(path, None, "empty file (no 'OFF' header)"))?;
    let keyword = head[0];
    let is_off = keyword.ends_with(b"OFF")
        && keyword[..keyword.len() - 3].iter().all(|b| matches!(b, b'S' | b'T' | b'C' | b'N'));
    if !is_off {
        let msg = if keyword.ends_with(b"OFF") {
            format!("'{}' files are not supported (only 3D OFF, COFF, NOFF, STOFF)", show(keyword))
        } else {
            format!("not an OFF file (header '{}')", show(keyword))
        };
        return Err(Error::parse(path, Some(head_no), msg));
    }
    if head.get(1).is_some_and(|t| t.eq_ignore_ascii_case(b"BINARY")) {
        return Err(Error::parse(path, Some(head_no), "binary OFF is not supported"));
    }
    let (counts_no, counts) = if head.len() > 1 {
        (head_no, head[1..].to_vec())
    } else {
        let mut c = Vec::new();
        let no = next_line(&mut c)
            .ok_or_else(|| Error::parse(path, None, "unexpected end of file: no vertex/face counts"))?;
        (no, c)
    };
    let count = |i: usize, what: &str| -> Result<usize> {
        let t = counts.get(i).ok_or_else(|| Error::parse(path, Some(counts_no), format!("missing {what} count")))?;
        std::str::from_utf8(t).ok().and_then(|s| s.parse().ok()).ok_or_else(|| {
            Error::parse(path, Some(counts_no), format!("{what} count '{}' is not a non-negative integer", show(t)))
        })
    };
    let n_vertices = count(0, "vertex")?;
    let n_faces = count(1, "face")?;
    if n_vertices == 0 || n_faces == 0 {
        return Err(Error::parse(
            path,
            Some(counts_no),
            format!("the file declares {n_vertices} vertices and {n_faces} faces; a mesh needs both"),
        ));
    }

    let eof = |what: &str, i: usize, n: usize| {
        Error::parse(path, None, format!("unexpected end of file: {what} {} of {n} is missing", i + 1))
    };
    // What the header's prefixes promise after each position: ST texture (2), C colour (3 or 4),
    // N normal (3). Lines that do not match are reported once (the data is ignored either way).
    let prefix = &keyword[..keyword.len() - 3];
    let promised =
        3 + if prefix.contains(&b'N') { 3 } else { 0 } + if prefix.windows(2).any(|w| w == b"ST") { 2 } else { 0 };
    let colour = prefix.contains(&b'C');
    let mut odd_vertices: (usize, Option<usize>) = (0, None);
    let mut tok: Vec<&[u8]> = Vec::with_capacity(16);
    let mut positions = Vec::with_capacity(n_vertices.min(1 << 24));
    for i in 0..n_vertices {
        let no = next_line(&mut tok).ok_or_else(|| eof("vertex", i, n_vertices))?;
        if tok.len() < 3 {
            return Err(Error::parse(path, Some(no), format!("vertex has {} coordinates, expected 3", tok.len())));
        }
        let fits = if colour { tok.len() == promised + 3 || tok.len() == promised + 4 } else { tok.len() == promised };
        if !fits {
            odd_vertices.0 += 1;
            odd_vertices.1.get_or_insert(no);
        }
        let mut p = [0.0; 3];
        for axis in 0..3 {
            p[axis] = finite_coordinate(tok[axis], axis).map_err(|m| Error::parse(path, Some(no), m))?;
        }
        positions.push(p);
    }
    let mut faces = FaceCollector::default();
    let mut polygon = Vec::with_capacity(8);
    let mut odd_faces: (usize, Option<usize>) = (0, None);
    for i in 0..n_faces {
        let no = next_line(&mut tok).ok_or_else(|| eof("face", i, n_faces))?;
        let err = |m: String| Error::parse(path, Some(no), m);
        let n: usize = std::str::from_utf8(tok[0])
            .ok()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| err(format!("face size '{}' is not a non-negative integer", show(tok[0]))))?;
        if tok.len() < 1 + n {
            return Err(err(format!("face declares {n} vertices but lists {}", tok.len() - 1)));
        }
        // After the indices: nothing, a colour index, or an RGB(A) colour.
        let rest = &tok[1 + n..];
        if !(matches!(rest.len(), 0 | 1 | 3 | 4) && rest.iter().all(|t| super::load::parse_f64(t).is_some())) {
            odd_faces.0 += 1;
            odd_faces.1.get_or_insert(no);
        }
        polygon.clear();
        for t in &tok[1..=n] {
            let v: usize = std::str::from_utf8(t)
                .ok()
                .and_then(|s| s.parse().ok())
                .ok_or_else(|| err(format!("face vertex '{}' is not a non-negative integer index", show(t))))?;
            if v >= n_vertices {
                return Err(err(format!(
                    "vertex index {v} out of range (the file has {n_vertices} vertices, indices are 0-based)"
                )));
            }
            polygon.push(v);
        }
        faces.push(&polygon, no).map_err(err)?;
    }
    let p = path.display();
    let mut warnings: Vec<String> = faces.polygon_warning(|l| format!("{p}:{l}")).into_iter().collect();
    if let Some(no) = next_line(&mut tok) {
        warnings.push(format!("{p}:{no}: content after the last face ignored"));
    }
    if let (n, Some(first)) = odd_vertices {
        warnings.push(format!(
            "{p}:{first}: {n} vertex line(s) do not hold what the '{}' header promises ({promised} numbers{}); extra data is ignored",
            show(keyword),
            if colour { " and a colour" } else { "" }
        ));
    }
    if let (n, Some(first)) = odd_faces {
        warnings.push(format!(
            "{p}:{first}: {n} face line(s) carry data after their indices that is not a colour; it is ignored"
        ));
    }
    Ok(LoadedMesh { mesh: TriMesh::new(positions, faces.faces), warnings })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<LoadedMesh> {
        parse_off(s.as_bytes(), Path::new("t.off"))
    }

    #[test]
    fn headers_promising_more_data_and_junk_after_faces_are_reported() {
        // NOFF promises a normal after each position; this file has none.
        let m = parse("NOFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").unwrap();
        assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
        assert!(
            m.warnings[0].starts_with("t.off:3: 3 vertex line(s) do not hold what the 'NOFF' header"),
            "{:?}",
            m.warnings
        );
        // COFF without colours, and junk after a face's indices.
        let m = parse("COFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 x y\n").unwrap();
        assert_eq!(m.warnings.len(), 2, "{:?}", m.warnings);
        assert!(
            m.warnings[1].starts_with("t.off:6: 1 face line(s) carry data after their indices"),
            "{:?}",
            m.warnings
        );
        assert_eq!(m.mesh.faces, vec![[0, 1, 2]]);
    }

    #[test]
    fn reads_plain_and_coloured_variants() {
        let m = parse("OFF\n# square\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n").unwrap();
        assert_eq!(m.mesh.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(m.warnings.is_empty());
        let m = parse(
            "COFF 4 1 0\n0 0 0 255 0 0 255\n1 0 0 1 1 1 1\n1 1 0 0 0 0 0\n0 1 0 0 0 0 0\n4 0 1 2 3 0.5 0.5 0.5\n",
        )
        .unwrap();
        assert_eq!(m.mesh.positions[2], [1.0, 1.0, 0.0]);
        assert_eq!(m.mesh.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.warnings.len(), 1);
        assert!(m.warnings[0].starts_with("t.off:6: 1 polygon"), "{:?}", m.warnings);
        assert!(parse("NOFF\n3 1\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n").is_ok());
    }

    #[test]
    fn errors_name_file_and_line() {
        let e = |s: &str| parse(s).unwrap_err().to_string();
        let m = e("OFF\n3 1 0\n0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n");
        assert!(m.starts_with("t.off:4: non-finite z coordinate"), "{m}");
        let m = e("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
        assert!(m.starts_with("t.off:6: vertex index 3 out of range"), "{m}");
        let m = e("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n");
        assert!(m.starts_with("t.off:6: face declares 3 vertices but lists 2"), "{m}");
        let m = e("OFF\n3 1 0\n0 0 0\n1 0 0\n");
        assert!(m.starts_with("t.off: unexpected end of file: vertex 3 of 3"), "{m}");
        let m = e("OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n");
        assert!(m.starts_with("t.off:4: vertex has 2 coordinates"), "{m}");
        let m = e("OFF\nx 1 0\n");
        assert!(m.starts_with("t.off:2: vertex count 'x'"), "{m}");
        let m = e("PLY\n");
        assert!(m.starts_with("t.off:1: not an OFF file"), "{m}");
        let m = e("4OFF\n");
        assert!(m.contains("not supported"), "{m}");
        let m = e("OFF BINARY\n");
        assert!(m.contains("binary OFF"), "{m}");
    }

    #[test]
    fn prefixes_colours_and_counts_are_checked_exactly() {
        for text in [
            "STOFF\n3 1\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n",
            "NOFF\n3 1\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n",
            "COFF\n3 1\n0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 255\n3 0 1 2\n",
            "OFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 1 1 1 1\n",
        ] {
            let m = parse(text).unwrap();
            assert!(m.warnings.is_empty(), "{text:?}: {:?}", m.warnings);
            assert_eq!(m.mesh.faces, vec![[0, 1, 2]]);
        }
        let m = parse("OFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 x\n").unwrap();
        assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
        assert!(m.warnings[0].starts_with("t.off:6: 1 face line(s) carry data"), "{:?}", m.warnings);
        let e = parse("OFF\n3 0\n0 0 0\n1 0 0\n0 1 0\n").unwrap_err().to_string();
        assert!(e.starts_with("t.off:2: the file declares 3 vertices and 0 faces"), "{e}");
    }
}
