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
    let is_npz = path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    let frames = if is_npz {
        let name = array.ok_or_else(|| {
            Error::config("data.array", format!("{}: name the array of the .npz to read", path.display()))
        })?;
        let bytes = read_regular(path)?;
        npz_frames(path, &bytes, name, n_vertices)?
    } else {
        if let Some(a) = array {
            return Err(Error::config(
                "data.array",
                format!("`{a}` is given, but {} is a .npy with a single array", path.display()),
            ));
        }
        let (file, len) = open_regular(path)?;
        let what = path.display().to_string();
        read_frames(&mut std::io::BufReader::new(file), len, &what, n_vertices)?
    };
    let names = frame_names(path, frames.len());
    Ok(MeshSequence { faces, frames, names })
}

/// Opens `path` for reading if it is a regular file (after symbolic links), with its length.
/// A FIFO would block and a device (`/dev/zero`) never end: both are refused before opening,
/// with the message the mesh readers give ("not a regular file (a FIFO)").
fn open_regular(path: &Path) -> Result<(std::fs::File, u64)> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    super::sequence::require_regular(path, &meta)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    // The file opened may not be the one looked at (a rename in between): check it again.
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    super::sequence::require_regular(path, &meta)?;
    Ok((file, meta.len()))
}

/// The bytes of the regular file `path` (see [`open_regular`]), at most its length when opened.
fn read_regular(path: &Path) -> Result<Vec<u8>> {
    let (file, len) = open_regular(path)?;
    let mut bytes = Vec::new();
    file.take(len).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// The frames of the array `<name>.npy` inside the `.npz` archive `bytes` (the file `path`).
/// The member is inflated only as far as its `.npy` header implies (and never past the size the
/// archive declares for it), so an inflate bomb costs no more memory than an honest array.
fn npz_frames(path: &Path, bytes: &[u8], name: &str, n_vertices: usize) -> Result<Vec<Vec<Vec3>>> {
    let bad = |m: String| Error::parse(path, None, m);
    let mut zip =
        zip::ZipArchive::new(Cursor::new(bytes)).map_err(|e| bad(format!("not a .npz (zip) archive: {e}")))?;
    let names: Vec<String> = zip.file_names().filter_map(|f| f.strip_suffix(".npy")).map(str::to_string).collect();
    let entry = match zip.by_name(&format!("{name}.npy")) {
        Ok(entry) => entry,
        Err(zip::result::ZipError::FileNotFound) => {
            return Err(Error::config(
                "data.array",
                format!("{}: no array `{name}` (it holds: {})", path.display(), names.join(", ")),
            ));
        }
        Err(e) => return Err(bad(format!("array `{name}`: {e}"))),
    };
    let declared = entry.size();
    // The declared size must fit the archive before anything is read for it.
    if declared > 64 * (bytes.len() as u64).max(1 << 20) {
        return Err(bad(format!("array `{name}` claims {declared} bytes, implausible for this archive")));
    }
    let what = format!("{} (array `{name}`)", path.display());
    read_frames(&mut entry.take(declared), declared, &what, n_vertices)
}

/// NumPy's bound on the length of a `.npy` header (`max_header_size` of `numpy.lib.format`,
/// 10 000 bytes): a longer one is refused before anything is allocated for it.
pub const MAX_HEADER_LEN: usize = 10_000;

/// What a `.npy` header says: the element type, the order and the shape.
#[derive(Debug, Clone, PartialEq)]
struct NpyHeader {
    /// Bytes per value: 4 (`float32`) or 8 (`float64`).
    item: usize,
    /// Little-endian values.
    little: bool,
    /// Fortran (column-major) order.
    fortran: bool,
    shape: Vec<u64>,
    /// Bytes before the data: magic string, version, length field and header text.
    len: u64,
}

/// Reads the magic string, the version, the header length and the header text of a `.npy`
/// from `r`, which holds `available` bytes in all. Every length is checked against NumPy's
/// bound and against `available` before anything is allocated for it.
fn read_header(r: &mut dyn Read, available: u64) -> std::result::Result<NpyHeader, String> {
    let short = |e: std::io::Error| format!("not a NumPy .npy array (too short for its header: {e})");
    let mut pre = [0u8; 8];
    r.read_exact(&mut pre).map_err(short)?;
    if &pre[..6] != b"\x93NUMPY" {
        return Err("not a NumPy .npy array (no \\x93NUMPY magic string)".into());
    }
    let (major, minor) = (pre[6], pre[7]);
    let (header_len, pre_len) = match major {
        1 => {
            let mut b = [0u8; 2];
            r.read_exact(&mut b).map_err(short)?;
            (u64::from(u16::from_le_bytes(b)), 10u64)
        }
        2 | 3 => {
            let mut b = [0u8; 4];
            r.read_exact(&mut b).map_err(short)?;
            (u64::from(u32::from_le_bytes(b)), 12u64)
        }
        _ => return Err(format!("NumPy format version {major}.{minor} is not 1.0, 2.0 or 3.0")),
    };
    if header_len > MAX_HEADER_LEN as u64 {
        return Err(format!("header of {header_len} bytes is longer than NumPy's limit of {MAX_HEADER_LEN}"));
    }
    if pre_len + header_len > available {
        return Err(format!("header of {header_len} bytes runs past the end ({available} bytes in all)"));
    }
    let mut text = vec![0u8; header_len as usize];
    r.read_exact(&mut text).map_err(short)?;
    let text = std::str::from_utf8(&text).map_err(|_| "the header is not UTF-8 text".to_string())?;
    let mut h = parse_header_text(text.trim_end())?;
    h.len = pre_len + header_len;
    Ok(h)
}

/// Parses the header text, a Python dict literal such as
/// `{'descr': '<f8', 'fortran_order': False, 'shape': (2, 5, 3), }`: exactly these three keys,
/// a float32 or float64 `descr`, and a shape of non-negative integers.
fn parse_header_text(text: &str) -> std::result::Result<NpyHeader, String> {
    let mut p = Lit { s: text.as_bytes(), i: 0 };
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    p.expect(b'{')?;
    loop {
        p.skip_space();
        if p.eat(b'}') {
            break;
        }
        let key = p.string()?;
        p.expect(b':')?;
        p.skip_space();
        match key.as_str() {
            "descr" => descr = Some(p.descr()?),
            "fortran_order" => fortran = Some(p.boolean()?),
            "shape" => shape = Some(p.shape()?),
            other => return Err(format!("header key `{other}` is not one of descr, fortran_order, shape")),
        }
        p.skip_space();
        if !p.eat(b',') {
            p.expect(b'}')?;
            break;
        }
    }
    p.skip_space();
    if p.i != p.s.len() {
        return Err(format!("header: unexpected text after the dict at byte {}", p.i));
    }
    let ((item, little), fortran, shape) = match (descr, fortran, shape) {
        (Some(d), Some(f), Some(s)) => (d, f, s),
        _ => return Err("header: descr, fortran_order and shape are all required".into()),
    };
    Ok(NpyHeader { item, little, fortran, shape, len: 0 })
}

/// A cursor over the header text (see [`parse_header_text`]).
struct Lit<'a> {
    s: &'a [u8],
    i: usize,
}

impl Lit<'_> {
    fn skip_space(&mut self) {
        while self.i < self.s.len() && self.s[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }
    fn eat(&mut self, c: u8) -> bool {
        self.skip_space();
        let hit = self.s.get(self.i) == Some(&c);
        if hit {
            self.i += 1;
        }
        hit
    }
    fn expect(&mut self, c: u8) -> std::result::Result<(), String> {
        if self.eat(c) { Ok(()) } else { Err(format!("header: expected `{}` at byte {}", c as char, self.i)) }
    }
    /// A quoted string without escapes (`'…'` or `"…"`).
    fn string(&mut self) -> std::result::Result<String, String> {
        self.skip_space();
        let Some(&q) = self.s.get(self.i).filter(|&&q| q == b'\'' || q == b'"') else {
            return Err(format!("header: expected a quoted string at byte {}", self.i));
        };
        let start = self.i + 1;
        let Some(len) = self.s[start..].iter().position(|&c| c == q || c == b'\\') else {
            return Err(format!("header: unterminated string at byte {}", self.i));
        };
        if self.s[start + len] == b'\\' {
            return Err(format!("header: escapes in strings are not supported (byte {})", start + len));
        }
        self.i = start + len + 1;
        Ok(String::from_utf8_lossy(&self.s[start..start + len]).into_owned())
    }
    /// `'<f8'`, `'>f4'`, …: (bytes per value, little-endian).
    fn descr(&mut self) -> std::result::Result<(usize, bool), String> {
        if !matches!(self.s.get(self.i), Some(b'\'' | b'"')) {
            return Err("dtype is not float32 or float64 (a structured descr)".into());
        }
        let d = self.string()?;
        let (order, kind) = match d.as_bytes().first() {
            Some(b'<' | b'>' | b'=' | b'|') => (d.as_bytes()[0], &d[1..]),
            _ => (b'=', d.as_str()),
        };
        let item = match kind {
            "f4" => 4,
            "f8" => 8,
            _ => return Err(format!("dtype {d} is not float32 or float64")),
        };
        let little = match order {
            b'<' => true,
            b'>' => false,
            _ => cfg!(target_endian = "little"),
        };
        Ok((item, little))
    }
    fn boolean(&mut self) -> std::result::Result<bool, String> {
        for (word, value) in [(&b"True"[..], true), (&b"False"[..], false)] {
            if self.s[self.i..].starts_with(word) {
                self.i += word.len();
                return Ok(value);
            }
        }
        Err(format!("header: fortran_order is not True or False (byte {})", self.i))
    }
    /// `(a, b, c)` or `[a, b, c]` of non-negative integers (a trailing comma and Python 2's `L`
    /// suffix allowed); at most 32 dimensions, as in NumPy.
    fn shape(&mut self) -> std::result::Result<Vec<u64>, String> {
        let close = if self.eat(b'(') {
            b')'
        } else if self.eat(b'[') {
            b']'
        } else {
            return Err(format!("header: shape is not a tuple (byte {})", self.i));
        };
        let mut dims = Vec::new();
        loop {
            if self.eat(close) {
                return Ok(dims);
            }
            self.skip_space();
            let start = self.i;
            while self.i < self.s.len() && self.s[self.i].is_ascii_digit() {
                self.i += 1;
            }
            let digits = std::str::from_utf8(&self.s[start..self.i]).unwrap_or_default();
            let dim = digits
                .parse::<u64>()
                .map_err(|_| format!("header: shape entry at byte {start} is not a non-negative integer below 2^64"))?;
            if self.s.get(self.i) == Some(&b'L') {
                self.i += 1;
            }
            dims.push(dim);
            if dims.len() > 32 {
                return Err("header: shape has more than 32 dimensions".into());
            }
            if !self.eat(b',') {
                self.expect(close)?;
                return Ok(dims);
            }
        }
    }
}

/// Checks an F × N × 3 header against the bytes present (`available` in all) and the template's
/// `n_vertices`; returns (F, N, bytes of data).
fn check_shape(h: &NpyHeader, available: u64, n_vertices: usize) -> std::result::Result<(usize, usize, usize), String> {
    let shape = &h.shape;
    if shape.len() != 3 || shape[2] != 3 {
        return Err(format!("shape {shape:?}, expected (frames, {n_vertices}, 3)"));
    }
    let (f, n) = (shape[0], shape[1]);
    if n != n_vertices as u64 {
        return Err(format!(
            "shape {shape:?}: {n} vertices per frame, the template mesh has {n_vertices} (expected ({f}, {n_vertices}, 3))"
        ));
    }
    if n == 0 {
        return Err(format!("shape {shape:?}: no vertex per frame"));
    }
    if f == 0 {
        return Err("the array holds no frame".into());
    }
    let present = available - h.len;
    let needed = f.checked_mul(n).and_then(|x| x.checked_mul(3)).and_then(|x| x.checked_mul(h.item as u64));
    match needed {
        Some(b) if b <= present => Ok((f as usize, n as usize, b as usize)),
        Some(b) => Err(format!("shape {shape:?} needs {b} bytes of data, {present} follow the header")),
        None => Err(format!("shape {shape:?} needs more than 2^64 bytes of data, {present} follow the header")),
    }
}

/// One value from its `h.item` bytes.
fn decode_value(h: &NpyHeader, b: &[u8]) -> f64 {
    match (h.item, h.little) {
        (8, true) => f64::from_le_bytes(b.try_into().unwrap_or_default()),
        (8, false) => f64::from_be_bytes(b.try_into().unwrap_or_default()),
        (_, true) => f64::from(f32::from_le_bytes(b.try_into().unwrap_or_default())),
        (_, false) => f64::from(f32::from_be_bytes(b.try_into().unwrap_or_default())),
    }
}

/// One frame's `3·N·item` bytes decoded, every value checked finite (`fi`: the 0-based frame,
/// for the message).
fn decode_frame(h: &NpyHeader, buf: &[u8], fi: usize) -> std::result::Result<Vec<Vec3>, String> {
    let mut frame = Vec::with_capacity(buf.len() / (3 * h.item));
    for (v, b) in buf.chunks_exact(3 * h.item).enumerate() {
        let p =
            [decode_value(h, &b[..h.item]), decode_value(h, &b[h.item..2 * h.item]), decode_value(h, &b[2 * h.item..])];
        if p.iter().any(|x| !x.is_finite()) {
            return Err(format!("frame {} (0-based {fi}), vertex {v} is not finite: {p:?}", fi + 1));
        }
        frame.push(p);
    }
    Ok(frame)
}

/// A C-order `.npy` (F × N × 3, `float32` or `float64`) opened to read one frame at a time, in
/// any order: a data set too large to hold in memory stays on disk and each frame is read when
/// used. The header is checked when opened (shape against the template and the file's length);
/// every frame read is checked (length, finite values); errors name the file and the frame.
#[derive(Debug)]
pub struct NpyFrames {
    path: std::path::PathBuf,
    file: std::fs::File,
    header: NpyHeader,
    n_frames: usize,
    n_vertices: usize,
}

impl NpyFrames {
    /// Opens `path` (a regular file) for frames of `n_vertices` vertices; `Ok(None)` when the
    /// array is in Fortran order (a frame is then scattered over the file: read it whole).
    pub fn open(path: &Path, n_vertices: usize) -> Result<Option<Self>> {
        let (mut file, len) = open_regular(path)?;
        let bad = |m: String| Error::Invalid(format!("{}: {m}", path.display()));
        let header = read_header(&mut file, len).map_err(bad)?;
        let (n_frames, n, _) = check_shape(&header, len, n_vertices).map_err(bad)?;
        if header.fortran {
            return Ok(None);
        }
        Ok(Some(NpyFrames { path: path.to_path_buf(), file, header, n_frames, n_vertices: n }))
    }
    /// Number of frames F.
    pub fn n_frames(&self) -> usize {
        self.n_frames
    }
    /// Number of vertices N.
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }
    /// The frames' names, as [`load_npy_with_faces`] gives them (`<stem>_<i>`).
    pub fn names(&self) -> Vec<String> {
        frame_names(&self.path, self.n_frames)
    }
    /// Frame `f` (0-based), checked; errors name the file and the frame.
    pub fn read_frame(&self, f: usize) -> Result<Vec<Vec3>> {
        let what = self.path.display();
        if f >= self.n_frames {
            return Err(Error::Invalid(format!("{what}: frame index {f} is out of range ({} frames)", self.n_frames)));
        }
        let size = self.n_vertices * 3 * self.header.item;
        let mut buf = vec![0u8; size];
        crate::artifact::read_exact_at(&self.file, &mut buf, self.header.len + (f * size) as u64)
            .map_err(|e| Error::Invalid(format!("{what}: reading frame {} (0-based {f}): {e}", f + 1)))?;
        decode_frame(&self.header, &buf, f).map_err(|m| Error::Invalid(format!("{what}: {m}")))
    }
}

/// Names of `n` frames of the array file `path`: `<stem>_<i>`, 1-based, zero-padded.
fn frame_names(path: &Path, n: usize) -> Vec<String> {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("frame").to_string();
    let width = n.to_string().len();
    (1..=n).map(|i| format!("{stem}_{i:0width$}")).collect()
}

/// Reads a whole `.npy` image (header and F × N × 3 data) from `r`, which holds `available`
/// bytes, checking the shape against `n_vertices`. Exactly the bytes the header implies are read.
fn read_frames(r: &mut dyn Read, available: u64, what: &str, n_vertices: usize) -> Result<Vec<Vec<Vec3>>> {
    let bad = |m: String| Error::Invalid(format!("{what}: {m}"));
    let h = read_header(r, available).map_err(bad)?;
    let (f, n, needed) = check_shape(&h, available, n_vertices).map_err(bad)?;
    let decode = |b: &[u8]| decode_value(&h, b);
    if !h.fortran {
        // C order: one frame's bytes at a time (memory: the frames, not the file as well).
        let mut buf = vec![0u8; n * 3 * h.item];
        let mut frames = Vec::with_capacity(f);
        for fi in 0..f {
            r.read_exact(&mut buf)
                .map_err(|e| bad(format!("reading the values of frame {} (0-based {fi}): {e}", fi + 1)))?;
            let frame = decode_frame(&h, &buf, fi).map_err(bad)?;
            frames.push(frame);
        }
        return Ok(frames);
    }
    let mut data = Vec::new();
    r.take(needed as u64).read_to_end(&mut data).map_err(|e| bad(format!("reading the values: {e}")))?;
    if data.len() != needed {
        return Err(bad(format!("{} bytes of data read, shape {:?} needs {needed}", data.len(), h.shape)));
    }
    let value = |i: usize| -> f64 { decode(&data[i * h.item..(i + 1) * h.item]) };
    let at = |fi: usize, v: usize, c: usize| value(fi + f * (v + n * c));
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

/// Parses an F × N × 3 `.npy` image held in memory (see [`read_frames`]).
#[cfg(test)]
fn parse_frames(bytes: &[u8], what: &str, n_vertices: usize) -> Result<Vec<Vec<Vec3>>> {
    read_frames(&mut Cursor::new(bytes), bytes.len() as u64, what, n_vertices)
}

/// The header of a `.npy` (format 1.0) of `descr` (e.g. `<f8`), order and shape, padded so the
/// data starts at a multiple of 64 bytes (the data follows it as is).
pub fn npy_header(descr: &str, fortran: bool, shape: &[usize]) -> Vec<u8> {
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

/// Writes an F × N × 3 float32 `.npy` whose frames are made on demand, atomically, holding one
/// chunk at a time: `chunk(start, len)` returns frames `start .. start + len` (at most
/// `chunk_len` per call). A frame of another vertex count or a non-finite value ends the write
/// with an error naming the frame, and nothing is left at `path`.
pub fn write_npy_f32_chunked(
    path: &Path,
    n_frames: usize,
    n_vertices: usize,
    chunk_len: usize,
    mut chunk: impl FnMut(usize, usize) -> Result<Vec<Vec<Vec3>>>,
) -> Result<()> {
    crate::artifact::write_atomic_checked(path, |w| {
        use std::io::Write;
        let io = |e: std::io::Error| Error::io(path, e);
        w.write_all(&npy_header("<f4", false, &[n_frames, n_vertices, 3])).map_err(io)?;
        let mut start = 0;
        while start < n_frames {
            let len = chunk_len.max(1).min(n_frames - start);
            let frames = chunk(start, len)?;
            for (j, f) in frames.iter().enumerate() {
                let bad = if f.len() != n_vertices {
                    Some(format!("has {} vertices, expected {n_vertices}", f.len()))
                } else {
                    f.iter()
                        .flatten()
                        .find(|x| !x.is_finite() || x.abs() > f32::MAX as f64)
                        .map(|x| format!("holds {x}, not a finite float32"))
                };
                if let Some(why) = bad {
                    return Err(Error::Invalid(format!("{}: frame {} {why}", path.display(), start + j)));
                }
                let mut buf = Vec::with_capacity(n_vertices * 12);
                for x in f.iter().flatten() {
                    buf.extend_from_slice(&(*x as f32).to_le_bytes());
                }
                w.write_all(&buf).map_err(io)?;
            }
            if frames.len() != len {
                return Err(Error::Invalid(format!(
                    "{}: asked for {len} frames from {start}, got {}",
                    path.display(),
                    frames.len()
                )));
            }
            start += len;
        }
        Ok(())
    })
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

    #[test]
    fn npz_declared_size_bound_is_64_times_the_archive_or_1_mib() {
        use std::io::Write;
        let frames: Vec<Vec<Vec3>> = vec![vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]];
        let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
        let opts = zip::write::FileOptions::default().compression_method(zip::CompressionMethod::Stored);
        zip.start_file("a.npy", opts).unwrap();
        zip.write_all(&npy_image(&frames)).unwrap();
        let bytes = zip.finish().unwrap().into_inner();
        assert!(bytes.len() < 1 << 20);
        // The member's uncompressed size as the central directory declares it (offset 24 of the
        // `PK\x01\x02` record), rewritten: the reader goes by this size, the data stays as is.
        let claim = |size: u32| {
            let mut b = bytes.clone();
            let at = b.windows(4).position(|w| w == b"PK\x01\x02").unwrap();
            b[at + 24..at + 28].copy_from_slice(&size.to_le_bytes());
            b
        };
        let path = Path::new("t.npz");
        // A small archive may declare up to 64 × 1 MiB: exactly that is still read.
        assert_eq!(npz_frames(path, &claim(64 << 20), "a", 2).unwrap(), frames);
        // One byte more is refused before anything is inflated.
        let e = npz_frames(path, &claim((64 << 20) + 1), "a", 2).unwrap_err().to_string();
        assert!(e.contains("t.npz") && e.contains("implausible"), "{e}");
    }

    #[test]
    fn header_of_exactly_numpys_limit_is_read() {
        let mut text = "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 2, 3), }".to_string();
        while text.len() < MAX_HEADER_LEN - 1 {
            text.push(' ');
        }
        text.push('\n');
        let mut b = b"\x93NUMPY\x02\x00".to_vec();
        b.extend_from_slice(&(text.len() as u32).to_le_bytes());
        b.extend_from_slice(text.as_bytes());
        for x in 0..6 {
            b.extend_from_slice(&f64::from(x).to_le_bytes());
        }
        let frames = parse_frames(&b, "t.npy", 2).unwrap();
        assert_eq!(frames, vec![vec![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]]);
    }

    #[test]
    fn header_grammar_edges() {
        let h = |shape: &str| format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
        // Python 2's `L` suffix.
        assert_eq!(parse_header_text(&h("(2L, 5L, 3L)")).unwrap().shape, [2, 5, 3]);
        // Double-quoted strings read as single-quoted ones.
        let dq = parse_header_text("{\"descr\": \"<f4\", \"fortran_order\": True, \"shape\": (2, 5, 3)}").unwrap();
        assert_eq!((dq.item, dq.fortran, dq.shape), (4, true, vec![2, 5, 3]));
        // NumPy's limit of 32 dimensions: 32 parse (check_shape refuses them later), 33 do not.
        let dims = |k: usize| format!("({})", vec!["1"; k].join(", "));
        assert_eq!(parse_header_text(&h(&dims(32))).unwrap().shape.len(), 32);
        let e = parse_header_text(&h(&dims(33))).unwrap_err();
        assert!(e.contains("more than 32 dimensions"), "{e}");
        // A shape cut off by the end of the text, digits last: an error, not a panic.
        let e = parse_header_text("{'descr': '<f8', 'fortran_order': False, 'shape': (1, 5, 3").unwrap_err();
        assert!(e.contains("header"), "{e}");
    }

    #[test]
    fn big_endian_values_are_byte_swapped() {
        let vals = [1.5f64, -2.25, 3.0, 1024.0, 0.125, -7.0];
        let be64: Vec<u8> = vals.iter().flat_map(|x| x.to_be_bytes()).collect();
        let be32: Vec<u8> = vals.iter().flat_map(|&x| (x as f32).to_be_bytes()).collect();
        for (descr, data) in [(">f8", be64), (">f4", be32)] {
            let frames = parse_frames(&npy_bytes(descr, false, &[1, 2, 3], &data), "t.npy", 2).unwrap();
            assert_eq!(frames, vec![vec![[1.5, -2.25, 3.0], [1024.0, 0.125, -7.0]]], "{descr}");
        }
    }

    #[test]
    fn headers_are_padded_to_64_bytes() {
        let shapes: [(&str, bool, &[usize]); 4] = [
            ("<f8", false, &[1, 2, 3]),
            ("<f4", true, &[10, 5000, 3]),
            ("<f8", false, &[123_456, 78, 3]),
            ("<f8", false, &[7]),
        ];
        for (descr, fortran, shape) in shapes {
            let h = npy_header(descr, fortran, shape);
            assert_eq!(h.len() % 64, 0, "{descr} {shape:?}: {} bytes", h.len());
            assert_eq!(h.last(), Some(&b'\n'));
            assert_eq!(usize::from(u16::from_le_bytes([h[8], h[9]])), h.len() - 10);
        }
    }

    #[test]
    fn written_npy_and_npz_read_back_with_their_names() {
        let d = crate::mesh::load::test_dir("npy-roundtrip");
        let a: Vec<Vec<Vec3>> =
            (0..3).map(|f| (0..2).map(|v| [f as f64, v as f64, 0.5 * (f + v) as f64]).collect()).collect();
        let b: Vec<Vec<Vec3>> = vec![vec![[9.0, 8.0, 7.0], [6.0, 5.0, 4.0]]];
        let faces = vec![[0, 1, 1]];
        write_npy(&d.join("walk.npy"), &a).unwrap();
        let seq = load_npy_with_faces(&d.join("walk.npy"), None, 2, faces.clone()).unwrap();
        assert_eq!(seq.frames, a);
        assert_eq!(seq.names, ["walk_1", "walk_2", "walk_3"]);
        write_npz(&d.join("both.npz"), &[("a", &a[..]), ("b", &b[..])]).unwrap();
        assert_eq!(load_npy_with_faces(&d.join("both.npz"), Some("a"), 2, faces.clone()).unwrap().frames, a);
        assert_eq!(load_npy_with_faces(&d.join("both.npz"), Some("b"), 2, faces).unwrap().frames, b);
        // Zero-padded to the width of the count.
        let names = frame_names(Path::new("x/run.npy"), 12);
        assert_eq!((names.len(), names[0].as_str(), names[11].as_str()), (12, "run_01", "run_12"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn npy_frames_reads_single_frames_in_any_order() {
        let d = crate::mesh::load::test_dir("npy-frames");
        let p = d.join("walk.npy");
        let frames: Vec<Vec<Vec3>> = (0..3)
            .map(|f| (0..2).map(|v| [100.0 * f as f64 + 10.0 * v as f64, 1.0 + f as f64, 2.0 - v as f64]).collect())
            .collect();
        write_npy(&p, &frames).unwrap();
        let nf = NpyFrames::open(&p, 2).unwrap().expect("a C-order .npy is read frame by frame");
        assert_eq!((nf.n_frames(), nf.n_vertices()), (3, 2));
        assert_eq!(nf.names(), ["walk_1", "walk_2", "walk_3"]);
        for f in [2, 0, 1] {
            assert_eq!(nf.read_frame(f).unwrap(), frames[f], "frame {f}");
        }
        let e = nf.read_frame(3).unwrap_err().to_string();
        assert!(e.contains("walk.npy") && e.contains("out of range"), "{e}");
        // Fortran order: `None` (a frame is scattered over the file).
        let q = d.join("fortran.npy");
        let mut fo = npy_header("<f8", true, &[3, 2, 3]);
        for c in 0..3 {
            for v in 0..2 {
                for f in &frames {
                    fo.extend_from_slice(&f[v][c].to_le_bytes());
                }
            }
        }
        std::fs::write(&q, fo).unwrap();
        assert!(NpyFrames::open(&q, 2).unwrap().is_none());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn chunked_f32_writer_asks_for_each_frame_once_and_checks_values() {
        let d = crate::mesh::load::test_dir("npy-chunked");
        let frame = |f: usize| -> Vec<Vec3> { (0..2).map(|v| [f as f64, v as f64 + 0.5, -0.25 * f as f64]).collect() };
        let p = d.join("five.npy");
        let mut calls = Vec::new();
        write_npy_f32_chunked(&p, 5, 2, 2, |start, len| {
            calls.push((start, len));
            if calls.len() > 10 || len == 0 || start + len > 5 {
                return Err(Error::Invalid(format!("unexpected request ({start}, {len})")));
            }
            Ok((start..start + len).map(frame).collect())
        })
        .unwrap();
        assert_eq!(calls, [(0, 2), (2, 2), (4, 1)]);
        assert_eq!(std::fs::metadata(&p).unwrap().len(), npy_header("<f4", false, &[5, 2, 3]).len() as u64 + 5 * 24);
        let seq = load_npy_with_faces(&p, None, 2, vec![]).unwrap();
        assert_eq!(seq.frames, (0..5).map(frame).collect::<Vec<_>>());
        // float32's largest value is written as is.
        let m = d.join("max.npy");
        let big = f64::from(f32::MAX);
        write_npy_f32_chunked(&m, 1, 2, 4, |_, _| Ok(vec![vec![[big, -big, 0.0], [1.0; 3]]])).unwrap();
        assert_eq!(load_npy_with_faces(&m, None, 2, vec![]).unwrap().frames[0][0], [big, -big, 0.0]);
        // Past it, or not finite: the frame is named and nothing is left at the path.
        for bad in [1e300, f64::NAN, f64::INFINITY] {
            let q = d.join("bad.npy");
            let e = write_npy_f32_chunked(&q, 2, 2, 4, |s, l| {
                Ok((s..s + l).map(|f| if f == 1 { vec![[0.0, bad, 0.0], [0.0; 3]] } else { frame(f) }).collect())
            })
            .unwrap_err()
            .to_string();
            assert!(e.contains("frame 1 holds") && e.contains("not a finite float32"), "{bad}: {e}");
            assert!(!q.exists(), "{bad}: a file was left");
        }
        let e = write_npy_f32_chunked(&d.join("wide.npy"), 1, 2, 4, |_, _| Ok(vec![vec![[0.0; 3]; 3]]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("frame 0 has 3 vertices, expected 2"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
