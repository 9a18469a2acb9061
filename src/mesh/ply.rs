//! Stanford PLY reader: ASCII, binary little endian and binary big endian.
//!
//! Read: element `vertex` with scalar properties `x`, `y`, `z` (any numeric type) and element
//! `face` with a list property `vertex_indices` or `vertex_index` (integer count and item types).
//! Every other element and property is skipped according to its declared type, so binary files
//! with normals, colours, texture coordinates or extra elements read correctly. Faces with more
//! than 3 vertices are triangulated as fans around their first vertex and reported in a warning.
//!
//! Errors name the file and the line (ASCII) or the element index (binary, 0-based): malformed
//! header, truncated body, non-numeric or non-finite coordinates, negative or out-of-range
//! indices, faces with fewer than 3 vertices, values left over on an ASCII line.

use std::path::Path;

use super::TriMesh;
use super::load::{FaceCollector, LoadedMesh, numbered_lines, parse_f64, show, tokens};
use crate::error::{Error, Result};

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &[u8]) -> Option<Scalar> {
        Some(match name {
            b"char" | b"int8" => Scalar::I8,
            b"uchar" | b"uint8" => Scalar::U8,
            b"short" | b"int16" => Scalar::I16,
            b"ushort" | b"uint16" => Scalar::U16,
            b"int" | b"int32" => Scalar::I32,
            b"uint" | b"uint32" => Scalar::U32,
            b"float" | b"float32" => Scalar::F32,
            b"double" | b"float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// Size in bytes in the binary encodings.
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PropertyType {
    Scalar(Scalar),
    /// A list: count type, item type.
    List(Scalar, Scalar),
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    ty: PropertyType,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    LittleEndian,
    BigEndian,
}

#[derive(Debug)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Byte offset of the body.
    body_offset: usize,
    /// Number of header lines (the body's first line is `header_lines + 1`).
    header_lines: usize,
}

fn parse_header(bytes: &[u8], path: &Path) -> Result<Header> {
    let err = |line: usize, msg: String| Error::parse(path, Some(line), msg);
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut offset = 0;
    let mut line_no = 0;
    while offset < bytes.len() {
        let end = bytes[offset..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |p| offset + p);
        let line = &bytes[offset..end];
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        offset = (end + 1).min(bytes.len());
        line_no += 1;
        let tok: Vec<&[u8]> = tokens(line).collect();
        if line_no == 1 {
            if tok.len() != 1 || tok[0] != b"ply".as_slice() {
                return Err(err(1, "not a PLY file (the first line is not 'ply')".into()));
            }
            continue;
        }
        match tok.first().copied() {
            None | Some(b"comment") | Some(b"obj_info") => {}
            Some(b"format") => {
                encoding = Some(match tok.get(1).copied() {
                    Some(b"ascii") => Encoding::Ascii,
                    Some(b"binary_little_endian") => Encoding::LittleEndian,
                    Some(b"binary_big_endian") => Encoding::BigEndian,
                    other => {
                        return Err(err(line_no, format!("unknown PLY format '{}'", show(other.unwrap_or(b"")))));
                    }
                });
            }
            Some(b"element") => {
                let (Some(name), Some(count), None) = (tok.get(1), tok.get(2), tok.get(3)) else {
                    return Err(err(line_no, "expected 'element <name> <count>'".into()));
                };
                let count = std::str::from_utf8(count).ok().and_then(|c| c.parse::<usize>().ok()).ok_or_else(|| {
                    err(line_no, format!("element count '{}' is not a non-negative integer", show(count)))
                })?;
                elements.push(Element { name: show(name), count, properties: Vec::new() });
            }
            Some(b"property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(err(line_no, "property declared before any element".into()));
                };
                let bad_type = |t: &[u8]| err(line_no, format!("unknown property type '{}'", show(t)));
                let (ty, name) = match tok.as_slice() {
                    [_, b"list", count, item, name] => {
                        let c = Scalar::from_name(count).ok_or_else(|| bad_type(count))?;
                        let i = Scalar::from_name(item).ok_or_else(|| bad_type(item))?;
                        if !c.is_integer() {
                            return Err(err(
                                line_no,
                                format!("list count type '{}' is not an integer type", show(count)),
                            ));
                        }
                        (PropertyType::List(c, i), name)
                    }
                    [_, ty, name] => (PropertyType::Scalar(Scalar::from_name(ty).ok_or_else(|| bad_type(ty))?), name),
                    _ => {
                        return Err(err(
                            line_no,
                            "expected 'property <type> <name>' or 'property list <count type> <item type> <name>'"
                                .into(),
                        ));
                    }
                };
                element.properties.push(Property { name: show(name), ty });
            }
            Some(b"end_header") => {
                let encoding = encoding.ok_or_else(|| err(line_no, "the header has no 'format' line".into()))?;
                return Ok(Header { encoding, elements, body_offset: offset, header_lines: line_no });
            }
            Some(other) => return Err(err(line_no, format!("unknown header line starting with '{}'", show(other)))),
        }
    }
    Err(Error::parse(path, None, "the header has no 'end_header' line (truncated or not a PLY file)"))
}

/// Where a value was read: an ASCII line or a binary element index.
#[derive(Debug, Clone, Copy)]
enum Location {
    Line(usize),
    Element(usize),
}

/// Element-by-element access to a PLY body.
trait Body {
    /// Starts instance `index` of `element`; returns its location for messages.
    fn begin(&mut self, element: &Element, index: usize) -> Result<Location>;
    /// Reads one value of type `ty`.
    fn value(&mut self, ty: Scalar) -> Result<f64>;
    /// Skips one value of type `ty`.
    fn skip(&mut self, ty: Scalar) -> Result<()>;
    /// Finishes the current instance (ASCII: no values may be left on the line).
    fn end(&mut self) -> Result<()>;
    /// A message about the content after the last element, if there is any.
    fn trailing(&mut self) -> Option<String>;
}

struct AsciiBody<'a, I: Iterator<Item = (usize, &'a [u8])>> {
    path: &'a Path,
    lines: I,
    line: usize,
    tokens: Vec<&'a [u8]>,
    next: usize,
    element: String,
}

impl<'a, I: Iterator<Item = (usize, &'a [u8])>> AsciiBody<'a, I> {
    fn token(&mut self, ty: Scalar) -> Result<&'a [u8]> {
        let t = self.tokens.get(self.next).copied().ok_or_else(|| {
            Error::parse(
                self.path,
                Some(self.line),
                format!("too few values for element '{}' (missing a {ty:?} value)", self.element),
            )
        })?;
        self.next += 1;
        Ok(t)
    }
}

impl<'a, I: Iterator<Item = (usize, &'a [u8])>> Body for AsciiBody<'a, I> {
    fn begin(&mut self, element: &Element, index: usize) -> Result<Location> {
        loop {
            let Some((no, line)) = self.lines.next() else {
                return Err(Error::parse(
                    self.path,
                    None,
                    format!(
                        "unexpected end of file: the header declares {} '{}' elements, the file ends at number {}",
                        element.count,
                        element.name,
                        index + 1
                    ),
                ));
            };
            self.tokens.clear();
            self.tokens.extend(tokens(line));
            if !self.tokens.is_empty() {
                self.line = no;
                self.next = 0;
                if self.element != element.name {
                    self.element.clone_from(&element.name);
                }
                return Ok(Location::Line(no));
            }
        }
    }

    fn value(&mut self, ty: Scalar) -> Result<f64> {
        let t = self.token(ty)?;
        let v = parse_f64(t)
            .ok_or_else(|| Error::parse(self.path, Some(self.line), format!("value '{}' is not a number", show(t))))?;
        if ty.is_integer() && (!v.is_finite() || v.fract() != 0.0) {
            return Err(Error::parse(self.path, Some(self.line), format!("value '{}' is not an integer", show(t))));
        }
        Ok(v)
    }

    fn skip(&mut self, ty: Scalar) -> Result<()> {
        self.token(ty).map(|_| ())
    }

    fn end(&mut self) -> Result<()> {
        if self.next < self.tokens.len() {
            return Err(Error::parse(
                self.path,
                Some(self.line),
                format!(
                    "{} more value(s) than the header's properties of element '{}' describe",
                    self.tokens.len() - self.next,
                    self.element
                ),
            ));
        }
        Ok(())
    }

    fn trailing(&mut self) -> Option<String> {
        self.lines
            .find(|(_, l)| tokens(l).next().is_some())
            .map(|(no, _)| format!("{}:{no}: content after the last element ignored", self.path.display()))
    }
}

struct BinaryBody<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
    element: String,
    index: usize,
    count: usize,
}

impl BinaryBody<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N]> {
        let Some(chunk) = self.bytes.get(self.pos..self.pos + N) else {
            return Err(Error::parse(
                self.path,
                None,
                format!(
                    "unexpected end of file in {} {} of {} (0-based; byte offset {})",
                    self.element, self.index, self.count, self.pos
                ),
            ));
        };
        self.pos += N;
        let mut a: [u8; N] = chunk.try_into().expect("slice of length N");
        if self.big_endian {
            a.reverse();
        }
        Ok(a)
    }
}

impl Body for BinaryBody<'_> {
    fn begin(&mut self, element: &Element, index: usize) -> Result<Location> {
        if self.element != element.name {
            self.element.clone_from(&element.name);
        }
        self.index = index;
        self.count = element.count;
        Ok(Location::Element(index))
    }

    fn value(&mut self, ty: Scalar) -> Result<f64> {
        // Bytes are brought into little-endian order by `take`.
        Ok(match ty {
            Scalar::I8 => i8::from_le_bytes(self.take::<1>()?) as f64,
            Scalar::U8 => u8::from_le_bytes(self.take::<1>()?) as f64,
            Scalar::I16 => i16::from_le_bytes(self.take::<2>()?) as f64,
            Scalar::U16 => u16::from_le_bytes(self.take::<2>()?) as f64,
            Scalar::I32 => i32::from_le_bytes(self.take::<4>()?) as f64,
            Scalar::U32 => u32::from_le_bytes(self.take::<4>()?) as f64,
            Scalar::F32 => f32::from_le_bytes(self.take::<4>()?) as f64,
            Scalar::F64 => f64::from_le_bytes(self.take::<8>()?),
        })
    }

    fn skip(&mut self, ty: Scalar) -> Result<()> {
        if self.pos + ty.size() > self.bytes.len() {
            // Produce the truncation error with its context.
            self.value(ty)?;
        }
        self.pos += ty.size();
        Ok(())
    }

    fn end(&mut self) -> Result<()> {
        Ok(())
    }

    fn trailing(&mut self) -> Option<String> {
        let rest = self.bytes.len() - self.pos;
        (rest > 0).then(|| format!("{}: {rest} bytes after the last element ignored", self.path.display()))
    }
}

/// What the reader does with an element.
enum Role {
    /// Vertex element: property indices of x, y, z.
    Vertex([usize; 3]),
    /// Face element: property index of the vertex index list.
    Face(usize),
    Skip,
}

fn role(element: &Element, path: &Path) -> Result<Role> {
    let find = |names: &[&str]| element.properties.iter().position(|p| names.contains(&p.name.as_str()));
    match element.name.as_str() {
        "vertex" => {
            let mut idx = [0; 3];
            for (axis, name) in ["x", "y", "z"].iter().enumerate() {
                let i = find(&[name])
                    .ok_or_else(|| Error::parse(path, None, format!("the vertex element has no property '{name}'")))?;
                if !matches!(element.properties[i].ty, PropertyType::Scalar(_)) {
                    return Err(Error::parse(
                        path,
                        None,
                        format!("vertex property '{name}' is a list, expected a number"),
                    ));
                }
                idx[axis] = i;
            }
            Ok(Role::Vertex(idx))
        }
        "face" => {
            let i = find(&["vertex_indices", "vertex_index"]).ok_or_else(|| {
                Error::parse(path, None, "the face element has no 'vertex_indices' or 'vertex_index' property")
            })?;
            match element.properties[i].ty {
                PropertyType::List(_, item) if item.is_integer() => Ok(Role::Face(i)),
                _ => Err(Error::parse(
                    path,
                    None,
                    format!("face property '{}' must be a list of integers", element.properties[i].name),
                )),
            }
        }
        _ => Ok(Role::Skip),
    }
}

fn read_body<B: Body>(body: &mut B, header: &Header, path: &Path) -> Result<LoadedMesh> {
    let loc_err = |loc: Location, element: &str, msg: String| match loc {
        Location::Line(l) => Error::parse(path, Some(l), msg),
        Location::Element(i) => Error::parse(path, None, format!("{element} {i} (0-based): {msg}")),
    };
    let mut positions: Option<Vec<[f64; 3]>> = None;
    let mut faces: Option<FaceCollector> = None;
    let mut polygon = Vec::with_capacity(8);
    for element in &header.elements {
        let role = role(element, path)?;
        match role {
            Role::Vertex(_) => positions = Some(Vec::with_capacity(element.count.min(1 << 24))),
            Role::Face(_) => faces = Some(FaceCollector::default()),
            Role::Skip => {}
        }
        for index in 0..element.count {
            let loc = body.begin(element, index)?;
            let mut p = [0.0f64; 3];
            polygon.clear();
            for (pi, prop) in element.properties.iter().enumerate() {
                match (&role, prop.ty) {
                    (Role::Vertex(xyz), PropertyType::Scalar(t)) if xyz.contains(&pi) => {
                        let axis = xyz.iter().position(|&q| q == pi).expect("contained");
                        p[axis] = body.value(t)?;
                    }
                    (Role::Face(fi), PropertyType::List(ct, it)) if *fi == pi => {
                        let n = body.value(ct)?;
                        if n < 0.0 {
                            return Err(loc_err(loc, &element.name, format!("negative list length {n}")));
                        }
                        for _ in 0..n as usize {
                            let v = body.value(it)?;
                            if v < 0.0 {
                                return Err(loc_err(loc, &element.name, format!("negative vertex index {v}")));
                            }
                            polygon.push(v as usize);
                        }
                    }
                    (_, PropertyType::Scalar(t)) => body.skip(t)?,
                    (_, PropertyType::List(ct, it)) => {
                        let n = body.value(ct)?;
                        if n < 0.0 {
                            return Err(loc_err(loc, &element.name, format!("negative list length {n}")));
                        }
                        for _ in 0..n as usize {
                            body.skip(it)?;
                        }
                    }
                }
            }
            body.end()?;
            match &role {
                Role::Vertex(_) => {
                    if let Some(axis) = p.iter().position(|v| !v.is_finite()) {
                        return Err(loc_err(
                            loc,
                            &element.name,
                            format!("non-finite {} coordinate {}", ["x", "y", "z"][axis], p[axis]),
                        ));
                    }
                    positions.as_mut().expect("vertex role").push(p);
                }
                Role::Face(_) => {
                    let origin = match loc {
                        Location::Line(l) | Location::Element(l) => l,
                    };
                    faces
                        .as_mut()
                        .expect("face role")
                        .push(&polygon, origin)
                        .map_err(|m| loc_err(loc, &element.name, m))?;
                }
                Role::Skip => {}
            }
        }
    }
    let positions = positions.ok_or_else(|| Error::parse(path, None, "no 'vertex' element in the header"))?;
    let faces = faces
        .ok_or_else(|| Error::parse(path, None, "no 'face' element in the header: a point cloud is not a mesh"))?;
    if positions.is_empty() {
        return Err(Error::parse(path, None, "the file has no vertices"));
    }
    if faces.faces.is_empty() {
        return Err(Error::parse(path, None, "the file has no faces"));
    }
    let ascii = header.encoding == Encoding::Ascii;
    let at = |origin: usize| if ascii { Location::Line(origin) } else { Location::Element(origin) };
    if let Some((origin, v)) = faces.first_out_of_range(positions.len()) {
        return Err(loc_err(
            at(origin),
            "face",
            format!("vertex index {v} out of range (the file has {} vertices, indices are 0-based)", positions.len()),
        ));
    }
    let p = path.display();
    let mut warnings: Vec<String> = faces
        .polygon_warning(|o| if ascii { format!("{p}:{o}") } else { format!("{p} (face {o})") })
        .into_iter()
        .collect();
    warnings.extend(body.trailing());
    Ok(LoadedMesh { mesh: TriMesh::new(positions, faces.faces), warnings })
}

/// Parses PLY content (ASCII or binary); `path` is used in messages only.
pub fn parse_ply(bytes: &[u8], path: &Path) -> Result<LoadedMesh> {
    let header = parse_header(bytes, path)?;
    let body_bytes = &bytes[header.body_offset..];
    match header.encoding {
        Encoding::Ascii => {
            let first = header.header_lines;
            let lines = numbered_lines(body_bytes).map(move |(i, l)| (i + first, l));
            let mut body = AsciiBody { path, lines, line: 0, tokens: Vec::new(), next: 0, element: String::new() };
            read_body(&mut body, &header, path)
        }
        Encoding::LittleEndian | Encoding::BigEndian => {
            let mut body = BinaryBody {
                path,
                bytes: body_bytes,
                pos: 0,
                big_endian: header.encoding == Encoding::BigEndian,
                element: String::new(),
                index: 0,
                count: 0,
            };
            read_body(&mut body, &header, path)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(bytes: &[u8]) -> Result<LoadedMesh> {
        parse_ply(bytes, Path::new("t.ply"))
    }

    const ASCII: &str = "ply\nformat ascii 1.0\ncomment hi\nelement vertex 4\nproperty float x\nproperty float y\n\
        property double z\nproperty uchar red\nelement face 2\nproperty list uchar int vertex_index\n\
        property list uchar float texcoord\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n\
        0 0 0 255\n1 0 0 0\n1 1 0.5 3\n0 1 0 7\n3 0 1 2 2 0.5 0.5\n3 0 2 3 0\n0 1\n";

    #[test]
    fn ascii_with_extra_properties_and_elements() {
        let m = parse(ASCII.as_bytes()).unwrap();
        assert!(m.warnings.is_empty(), "{:?}", m.warnings);
        assert_eq!(m.mesh.positions, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.5], [0.0, 1.0, 0.0]]);
        assert_eq!(m.mesh.faces, vec![[0, 1, 2], [0, 2, 3]]);
    }

    /// Builds a binary PLY of a unit square (one quad and one triangle), with skipped properties
    /// of several types and a skipped element, in the requested byte order.
    fn binary_square(big_endian: bool, index_name: &str, z_nan: bool) -> Vec<u8> {
        let fmt = if big_endian { "binary_big_endian" } else { "binary_little_endian" };
        let mut b = format!(
            "ply\nformat {fmt} 1.0\nelement vertex 4\nproperty double x\nproperty float y\nproperty short s\n\
             property float z\nproperty list uchar ushort extra\nelement face 2\nproperty uchar flags\n\
             property list int uint {index_name}\nelement material 1\nproperty char c\nend_header\n"
        )
        .into_bytes();
        fn put<const N: usize>(b: &mut Vec<u8>, le: [u8; N], big: bool) {
            let mut a = le;
            if big {
                a.reverse();
            }
            b.extend_from_slice(&a);
        }
        let pts: [[f64; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.25], [0.0, 1.0, -2.0]];
        for (i, p) in pts.iter().enumerate() {
            put(&mut b, p[0].to_le_bytes(), big_endian);
            put(&mut b, (p[1] as f32).to_le_bytes(), big_endian);
            put(&mut b, (-7i16).to_le_bytes(), big_endian);
            let z = if z_nan && i == 2 { f32::NAN } else { p[2] as f32 };
            put(&mut b, z.to_le_bytes(), big_endian);
            b.push(i as u8); // list length i
            for k in 0..i {
                put(&mut b, (k as u16).to_le_bytes(), big_endian);
            }
        }
        let faces: [&[u32]; 2] = [&[0, 1, 2, 3], &[3, 2, 1]];
        for f in faces {
            b.push(9);
            put(&mut b, (f.len() as i32).to_le_bytes(), big_endian);
            for &v in f {
                put(&mut b, v.to_le_bytes(), big_endian);
            }
        }
        b.push(0x7f);
        b
    }

    #[test]
    fn binary_both_endians_skip_other_properties() {
        for big in [false, true] {
            for name in ["vertex_indices", "vertex_index"] {
                let m = parse(&binary_square(big, name, false)).unwrap();
                assert_eq!(
                    m.mesh.positions,
                    vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.25], [0.0, 1.0, -2.0]],
                    "big endian: {big}"
                );
                assert_eq!(m.mesh.faces, vec![[0, 1, 2], [0, 2, 3], [3, 2, 1]]);
                assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
                assert!(m.warnings[0].starts_with("t.ply (face 0): 1 polygon"), "{:?}", m.warnings);
            }
        }
    }

    #[test]
    fn binary_errors_name_the_element() {
        let e = parse(&binary_square(false, "vertex_indices", true)).unwrap_err().to_string();
        assert!(e.starts_with("t.ply: vertex 2 (0-based): non-finite z coordinate"), "{e}");
        let full = binary_square(true, "vertex_indices", false);
        let e = parse(&full[..full.len() - 6]).unwrap_err().to_string();
        assert!(e.starts_with("t.ply: unexpected end of file in face 1 of 2"), "{e}");
        let mut extra = full.clone();
        extra.extend_from_slice(b"junk");
        let m = parse(&extra).unwrap();
        assert!(m.warnings.iter().any(|w| w == "t.ply: 4 bytes after the last element ignored"), "{:?}", m.warnings);
    }

    #[test]
    fn ascii_errors_name_the_line() {
        let e = |s: &str| parse(s.as_bytes()).unwrap_err().to_string();
        let head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 1\nproperty list uchar int vertex_indices\nend_header\n";
        assert!(parse(format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").as_bytes()).is_ok());
        let m = e(&format!("{head}0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n"));
        assert!(m.starts_with("t.ply:11: non-finite z coordinate"), "{m}");
        let m = e(&format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"));
        assert!(m.starts_with("t.ply:13: vertex index 3 out of range"), "{m}");
        let m = e(&format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n"));
        assert!(m.starts_with("t.ply:13: negative vertex index"), "{m}");
        let m = e(&format!("{head}0 0 0\n1 0 0\n0 1 0\n2 0 1\n"));
        assert!(m.starts_with("t.ply:13: face with 2 vertices"), "{m}");
        let m = e(&format!("{head}0 0 0\n1 0\n0 1 0\n3 0 1 2\n"));
        assert!(m.starts_with("t.ply:11: too few values"), "{m}");
        let m = e(&format!("{head}0 0 0\n1 0 0 5\n0 1 0\n3 0 1 2\n"));
        assert!(m.starts_with("t.ply:11: 1 more value"), "{m}");
        let m = e(&format!("{head}0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n"));
        assert!(m.starts_with("t.ply:11: value 'x' is not a number"), "{m}");
        let m = e(&format!("{head}0 0 0\n1 0 0\n"));
        assert!(m.starts_with("t.ply: unexpected end of file: the header declares 3 'vertex'"), "{m}");
        let m = e("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n");
        assert!(m.contains("no 'end_header'"), "{m}");
        let m = e("plx\n");
        assert!(m.starts_with("t.ply:1: not a PLY file"), "{m}");
        let m = e("ply\nformat ascii 1.0\nelement vertex 3\nproperty quad x\nend_header\n");
        assert!(m.starts_with("t.ply:4: unknown property type 'quad'"), "{m}");
        let m = e("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n");
        assert!(m.contains("no property 'z'"), "{m}");
        let m = e(
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n",
        );
        assert!(m.contains("point cloud"), "{m}");
    }

    #[test]
    fn ascii_values_lists_trailing_lines_and_a_cut_skip() {
        let head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 1\nproperty list uchar int vertex_indices\nend_header\n";
        let verts = "0 0 0\n1 0 0\n0 1 0\n";
        let e = |s: String| parse(s.as_bytes()).unwrap_err().to_string();
        let m = e(format!("{head}0 0 0\n1 0\n0 1 0\n3 0 1 2\n"));
        assert!(m.starts_with("t.ply:11: too few values for element 'vertex'"), "{m}");
        for (face, want) in [
            ("3 0 1.5 2", "t.ply:13: value '1.5' is not an integer"),
            ("-1 0 1 2", "t.ply:13: negative list length -1"),
            ("0", "t.ply:13: face with 0 vertices"),
        ] {
            let m = e(format!("{head}{verts}{face}\n"));
            assert!(m.starts_with(want), "{face}: {m}");
        }
        let floats = head.replace("list uchar int", "list uchar float");
        let m = e(format!("{floats}{verts}3 0 1 2\n"));
        assert!(m.contains("must be a list of integers"), "{m}");
        let ok = parse(format!("{head}{verts}3 0 1 2\n\nextra\n").as_bytes()).unwrap();
        assert_eq!(ok.warnings, vec!["t.ply:15: content after the last element ignored".to_string()]);
        // Binary: the file ends inside a skipped property (the material's char, the last byte).
        let full = binary_square(false, "vertex_indices", false);
        let m = parse(&full[..full.len() - 1]).unwrap_err().to_string();
        assert!(m.starts_with("t.ply: unexpected end of file in material 0 of 1"), "{m}");
    }
}
