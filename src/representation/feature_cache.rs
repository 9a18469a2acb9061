//! The feature cache: a representation's features of a set of frames, computed once and read
//! back by later runs (`meshdeco train` again, every `meshdeco eval` cell of one dataset).
//!
//! **Key.** A file is named by a 96-bit content hash of everything the features depend on: the
//! representation kind and options, the rest mesh (positions and faces) and the positions of
//! every selected frame, in order (after the data's preprocessing: alignment, unit box). Nothing
//! about file names or times enters it, so a changed frame, rest shape or option is a different
//! file, and two datasets with the same frames share one.
//!
//! **File** (`<key>.features` in the cache folder): a line `MESHDECO-FEATURES 3`, then the
//! F·E·W little-endian `f64` ([`Features::data`]'s layout: the exact numbers, so a run that
//! reads the cache gives the same model as one that computes), then one line of JSON
//! ([`Header`]: key, F, E, W, every frame's CRC-32, each dimension's minimum and maximum, and a
//! CRC-32 of all of these), then the header's byte offset as 8 little-endian bytes. Written
//! atomically, frames computed in parallel a run at a time (memory: one run's features).
//!
//! **Checks.** Nothing in a cache file is trusted: the header must match its own checksum, and
//! every frame is checked against its CRC-32 whenever it is read ([`FeatureFile::frame`]), so a
//! file can be opened at once and read frame by frame (a training batch at a time). The
//! recorded ranges, which scale the autoencoder's features, must be the frames' own: a file
//! reused by [`open_or_build`] is read once to check them ([`FeatureFile::verify`]), and
//! [`FeatureFile::read_all`] checks them on the way. A file whose header is unreadable, fails its
//! checksum, names another key or shape, or records ranges its frames do not have is recomputed
//! and replaced, with a note on stderr naming the file and what was wrong; a frame that fails
//! its checksum while a training streams the file is an error naming the file and frame. A
//! cache folder that cannot be written only costs the reuse: training goes on with the
//! computed features.
//!
//! **Where** ([`CachePolicy`], `data.cache`): `"auto"` (the default) uses
//! `$MESHDECO_CACHE_DIR`, else `$XDG_CACHE_HOME/meshdeco/features`, else
//! `$HOME/.cache/meshdeco/features`, for features of at least [`AUTO_MIN_BYTES`] (smaller ones
//! are computed faster than read); `"off"` never caches; any other value is a folder used for
//! every size.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{Features, Representation};
use crate::error::{Error, Result};
use crate::mesh::FrameSource;

/// First line of a cache file.
const MAGIC: &str = "MESHDECO-FEATURES 3";

/// Smallest feature array (bytes) `"auto"` caches: 64 MiB.
pub const AUTO_MIN_BYTES: usize = 64 << 20;

/// Where features are cached (`data.cache`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum CachePolicy {
    /// The user's cache folder, for large features only (see the module docs).
    #[default]
    Auto,
    /// No cache.
    Off,
    /// This folder, for features of every size.
    Dir(PathBuf),
}

impl CachePolicy {
    /// Parses `data.cache`: `auto`, `off`, or a folder.
    pub fn parse(s: &str) -> Self {
        match s {
            "auto" => CachePolicy::Auto,
            "off" => CachePolicy::Off,
            dir => CachePolicy::Dir(PathBuf::from(dir)),
        }
    }

    /// The value of `data.cache` that parses to this policy.
    pub fn to_config_string(&self) -> String {
        match self {
            CachePolicy::Auto => "auto".into(),
            CachePolicy::Off => "off".into(),
            CachePolicy::Dir(d) => d.display().to_string(),
        }
    }

    /// The folder to use for features of `bytes` bytes, if any.
    fn folder(&self, bytes: usize) -> Option<PathBuf> {
        match self {
            CachePolicy::Off => None,
            CachePolicy::Dir(d) => Some(d.clone()),
            CachePolicy::Auto if bytes < AUTO_MIN_BYTES => None,
            CachePolicy::Auto => default_folder(),
        }
    }
}

/// `$MESHDECO_CACHE_DIR`, else `$XDG_CACHE_HOME/meshdeco/features`, else
/// `$HOME/.cache/meshdeco/features` (`None` when none is set).
pub fn default_folder() -> Option<PathBuf> {
    let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    var("MESHDECO_CACHE_DIR")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("meshdeco/features")))
        .or_else(|| var("HOME").map(|d| d.join(".cache/meshdeco/features")))
}

/// What [`encode_cached`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CacheUse {
    /// Not cached (policy off, below the size of `auto`, or no folder): computed.
    Computed,
    /// Read from this file.
    Read(PathBuf),
    /// Computed and written to this file.
    Written(PathBuf),
    /// Computed; the cache could not be used (the reason).
    Unavailable(String),
}

/// Frames computed and written at a time when a cache file is built.
const BUILD_RUN: usize = 64;

/// The header of a cache file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub key: String,
    pub n_frames: usize,
    pub n_elements: usize,
    pub width: usize,
    /// CRC-32 of each frame's E·W·8 bytes.
    pub frame_crc32: Vec<u32>,
    /// Each dimension's minimum over all frames and elements (W), as the bits of the `f64`
    /// (JSON numbers would not read back exactly).
    pub min_bits: Vec<u64>,
    /// Each dimension's maximum (W), as bits.
    pub max_bits: Vec<u64>,
    /// CRC-32 of every field above ([`Header::checksum`]).
    pub header_crc32: u32,
}

impl Header {
    /// The CRC-32 of the header's fields (key, shape, frame checksums, ranges), as recorded in
    /// `header_crc32`.
    pub fn checksum(&self) -> u32 {
        let mut h = crc32fast::Hasher::new();
        h.update(&(self.key.len() as u64).to_le_bytes());
        h.update(self.key.as_bytes());
        for n in [self.n_frames, self.n_elements, self.width] {
            h.update(&(n as u64).to_le_bytes());
        }
        for c in &self.frame_crc32 {
            h.update(&c.to_le_bytes());
        }
        for (list, tag) in [(&self.min_bits, b'<'), (&self.max_bits, b'>')] {
            h.update(&[tag]);
            h.update(&(list.len() as u64).to_le_bytes());
            for b in list {
                h.update(&b.to_le_bytes());
            }
        }
        h.finalize()
    }

    /// Each dimension's minimum (W).
    pub fn min(&self) -> Vec<f64> {
        self.min_bits.iter().map(|&b| f64::from_bits(b)).collect()
    }
    /// Each dimension's maximum (W).
    pub fn max(&self) -> Vec<f64> {
        self.max_bits.iter().map(|&b| f64::from_bits(b)).collect()
    }
}

/// An open, verified cache file: frames are read on demand, each checked against its CRC-32.
#[derive(Debug)]
pub struct FeatureFile {
    path: PathBuf,
    file: File,
    data_offset: u64,
    header: Header,
}

impl FeatureFile {
    /// Opens a cache file: its magic line, header, key, shape and length must be what is
    /// expected (the frames are checked when read).
    pub fn open(path: &Path, key: &str, (n_frames, n_elements, width): (usize, usize, usize)) -> Result<Self> {
        let bad = |why: String| Error::Invalid(format!("{}: {why}", path.display()));
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        let data_offset = (MAGIC.len() + 1) as u64;
        if len < data_offset + 8 {
            return Err(bad(format!("is {len} bytes: too short for a feature cache")));
        }
        let mut magic = vec![0u8; MAGIC.len() + 1];
        file.read_exact(&mut magic).map_err(|e| Error::io(path, e))?;
        if magic != format!("{MAGIC}\n").as_bytes() {
            return Err(bad("not a meshdeco feature cache of this version".into()));
        }
        let mut tail = [0u8; 8];
        crate::artifact::read_exact_at(&file, &mut tail, len - 8).map_err(|e| Error::io(path, e))?;
        let header_at = u64::from_le_bytes(tail);
        if !(data_offset..len - 8).contains(&header_at) || len - 8 - header_at > (64 << 20) {
            return Err(bad(format!("header offset {header_at} is outside the file ({len} bytes)")));
        }
        let mut json = vec![0u8; (len - 8 - header_at) as usize];
        crate::artifact::read_exact_at(&file, &mut json, header_at).map_err(|e| Error::io(path, e))?;
        let header: Header = serde_json::from_slice(&json).map_err(|e| bad(format!("header: {e}")))?;
        if header.checksum() != header.header_crc32 {
            return Err(bad(format!(
                "header checksum {:08x} differs from the recorded {:08x} (the file changed after it was written)",
                header.checksum(),
                header.header_crc32
            )));
        }
        if header.key != key {
            return Err(bad(format!("holds key {}, expected {key}", header.key)));
        }
        if (header.n_frames, header.n_elements, header.width) != (n_frames, n_elements, width) {
            return Err(bad(format!(
                "holds {} × {} × {} features, expected {n_frames} × {n_elements} × {width}",
                header.n_frames, header.n_elements, header.width
            )));
        }
        let data_bytes = (n_frames * n_elements * width * 8) as u64;
        if header_at != data_offset + data_bytes
            || header.frame_crc32.len() != n_frames
            || header.min_bits.len() != width
            || header.max_bits.len() != width
        {
            return Err(bad(format!(
                "holds {} data bytes and {} frame checksums, expected {data_bytes} and {n_frames} (truncated or rewritten)",
                header_at.saturating_sub(data_offset),
                header.frame_crc32.len()
            )));
        }
        Ok(FeatureFile { path: path.to_path_buf(), file, data_offset, header })
    }

    /// The file's header (shape, checksums, per-dimension ranges).
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// Where the file is.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Number of frames F.
    pub fn n_frames(&self) -> usize {
        self.header.n_frames
    }

    /// Frame `f`'s E·W features into `out` (resized), checked against its CRC-32; `bytes` is a
    /// scratch buffer.
    pub fn frame_into(&self, f: usize, out: &mut Vec<f64>, bytes: &mut Vec<u8>) -> Result<()> {
        let h = &self.header;
        if f >= h.n_frames {
            return Err(Error::Invalid(format!("{}: frame {f} of {}", self.path.display(), h.n_frames)));
        }
        let size = h.n_elements * h.width * 8;
        bytes.resize(size, 0);
        crate::artifact::read_exact_at(&self.file, bytes, self.data_offset + (f * size) as u64)
            .map_err(|e| Error::io(&self.path, e))?;
        if crc32fast::hash(bytes) != h.frame_crc32[f] {
            return Err(Error::Invalid(format!(
                "{}: frame {f} fails its checksum (the cache file changed after it was written; delete it to recompute)",
                self.path.display()
            )));
        }
        out.clear();
        out.extend(bytes.chunks_exact(8).map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])));
        Ok(())
    }

    /// Frame `f`'s E·W features (see [`FeatureFile::frame_into`]).
    pub fn frame(&self, f: usize) -> Result<Vec<f64>> {
        let (mut out, mut bytes) = (Vec::new(), Vec::new());
        self.frame_into(f, &mut out, &mut bytes)?;
        Ok(out)
    }

    /// Every frame, in order, as one feature array (frames read in parallel, each verified),
    /// after checking that the recorded ranges are theirs.
    pub fn read_all(&self) -> Result<Features> {
        use rayon::prelude::*;
        let h = &self.header;
        let size = h.n_elements * h.width;
        let mut out = Features::zeros(h.n_frames, h.n_elements, h.width);
        if size > 0 {
            out.data.par_chunks_mut(size).enumerate().try_for_each_init(
                || (Vec::new(), Vec::new()),
                |(v, b), (f, dst)| -> Result<()> {
                    self.frame_into(f, v, b)?;
                    dst.copy_from_slice(v);
                    Ok(())
                },
            )?;
        }
        let mut ranges = Ranges::new(h.width);
        ranges.add(&out.data);
        self.check_ranges(&ranges)?;
        Ok(out)
    }

    /// Reads every frame (each checked against its CRC-32, in parallel) and checks that the
    /// header's ranges are the frames' own: each dimension's minimum and maximum over all frames
    /// and elements. An error names the file and the first dimension that differs.
    pub fn verify(&self) -> Result<()> {
        use rayon::prelude::*;
        let h = &self.header;
        let ranges = (0..h.n_frames)
            .into_par_iter()
            .try_fold(
                || (Ranges::new(h.width), Vec::new(), Vec::new()),
                |(mut r, mut v, mut b), f| -> Result<_> {
                    self.frame_into(f, &mut v, &mut b)?;
                    r.add(&v);
                    Ok((r, v, b))
                },
            )
            .map(|acc| acc.map(|(r, _, _)| r))
            .try_reduce(
                || Ranges::new(h.width),
                |mut a, b| {
                    a.merge(&b);
                    Ok(a)
                },
            )?;
        self.check_ranges(&ranges)
    }

    /// Errors (naming the file) unless the header's ranges equal `ranges` (values compared, so
    /// a NaN never passes).
    fn check_ranges(&self, ranges: &Ranges) -> Result<()> {
        let (min, max) = (self.header.min(), self.header.max());
        for k in 0..self.header.width {
            if min[k] != ranges.min[k] || max[k] != ranges.max[k] {
                return Err(Error::Invalid(format!(
                    "{}: the recorded range of feature dimension {k}, [{}, {}], is not its frames' [{}, {}] (the cache file changed after it was written)",
                    self.path.display(),
                    min[k],
                    max[k],
                    ranges.min[k],
                    ranges.max[k]
                )));
            }
        }
        Ok(())
    }
}

/// Each dimension's minimum and maximum over the values seen (W each; +∞ and −∞ before any).
#[derive(Debug, Clone, PartialEq)]
struct Ranges {
    min: Vec<f64>,
    max: Vec<f64>,
}

impl Ranges {
    fn new(width: usize) -> Self {
        Ranges { min: vec![f64::INFINITY; width], max: vec![f64::NEG_INFINITY; width] }
    }

    /// Takes in `values`, W numbers per element.
    fn add(&mut self, values: &[f64]) {
        let width = self.min.len();
        if width == 0 {
            return;
        }
        for v in values.chunks_exact(width) {
            for (k, &x) in v.iter().enumerate() {
                self.min[k] = self.min[k].min(x);
                self.max[k] = self.max[k].max(x);
            }
        }
    }

    /// Takes in another set's ranges.
    fn merge(&mut self, other: &Ranges) {
        for k in 0..self.min.len() {
            self.min[k] = self.min[k].min(other.min[k]);
            self.max[k] = self.max[k].max(other.max[k]);
        }
    }
}

/// What [`open_or_build`] found or made.
#[derive(Debug)]
pub enum Opened {
    /// A verified cache file; `built` when this call computed it.
    File { file: FeatureFile, built: bool },
    /// The policy caches nothing of this size.
    NotCached,
    /// The folder or the file could not be used (the reason): nothing is cached.
    Unavailable(String),
}

/// The cache file of the features of `frames` of `seq` under `policy`, built if missing or
/// unusable; a file found in the cache is verified first ([`FeatureFile::verify`]: one read of
/// its frames). `Err` only for errors of the data (a frame that cannot be encoded); a folder or
/// file that cannot be used is [`Opened::Unavailable`].
///
/// `on_frames(done)` is called after each run of frames computed for a new file.
pub fn open_or_build(
    rep: &Representation,
    seq: &dyn FrameSource,
    frames: &[usize],
    policy: &CachePolicy,
    on_frames: &mut dyn FnMut(usize),
) -> Result<Opened> {
    open_or_build_checked(rep, seq, frames, policy, on_frames, true)
}

/// Bytes of the `f64` features of `frames` frames of `elements` elements × `width` numbers: what
/// [`CachePolicy::folder`] weighs against [`AUTO_MIN_BYTES`].
fn feature_bytes(frames: usize, elements: usize, width: usize) -> usize {
    frames * elements * width * 8
}

/// [`open_or_build`]; a file found in the cache is verified only when `verify` (a caller that
/// reads it whole with [`FeatureFile::read_all`] checks it there).
fn open_or_build_checked(
    rep: &Representation,
    seq: &dyn FrameSource,
    frames: &[usize],
    policy: &CachePolicy,
    on_frames: &mut dyn FnMut(usize),
    verify: bool,
) -> Result<Opened> {
    let Some(folder) = policy.folder(feature_bytes(frames.len(), rep.n_elements(), rep.width())) else {
        return Ok(Opened::NotCached);
    };
    if let Some(&f) = frames.iter().find(|&&f| f >= seq.n_frames()) {
        return Err(Error::Invalid(format!("frame index {f} is out of range ({} frames)", seq.n_frames())));
    }
    let key = key(rep, seq, frames)?;
    let path = folder.join(format!("{key}.features"));
    let expect = (frames.len(), rep.n_elements(), rep.width());
    if path.is_file() {
        match FeatureFile::open(&path, &key, expect).and_then(|f| if verify { f.verify().map(|()| f) } else { Ok(f) }) {
            Ok(file) => return Ok(Opened::File { file, built: false }),
            Err(e) => eprintln!("note: recomputing the cached features: {e}"),
        }
    }
    if let Err(e) = std::fs::create_dir_all(&folder) {
        return Ok(Opened::Unavailable(format!("{}: {e}", folder.display())));
    }
    match build(rep, seq, frames, &path, &key, on_frames) {
        Ok(()) => {}
        Err(e @ Error::Io { .. }) => return Ok(Opened::Unavailable(e.to_string())),
        Err(e) => return Err(e),
    }
    Ok(match FeatureFile::open(&path, &key, expect) {
        Ok(file) => Opened::File { file, built: true },
        Err(e) => Opened::Unavailable(e.to_string()),
    })
}

/// The features of `frames` of `seq` ([`Representation::encode_selected`]), read from the cache
/// when a valid file exists, else computed and (when the policy caches them) written.
pub fn encode_cached(
    rep: &Representation,
    seq: &dyn FrameSource,
    frames: &[usize],
    policy: &CachePolicy,
) -> Result<(Features, CacheUse)> {
    match open_or_build_checked(rep, seq, frames, policy, &mut |_| {}, false)? {
        Opened::NotCached => Ok((rep.encode_selected(seq, frames)?, CacheUse::Computed)),
        Opened::Unavailable(why) => Ok((rep.encode_selected(seq, frames)?, CacheUse::Unavailable(why))),
        Opened::File { file, built } => {
            let path = file.path().to_path_buf();
            match file.read_all() {
                Ok(f) => Ok((f, if built { CacheUse::Written(path) } else { CacheUse::Read(path) })),
                Err(e) if !built => {
                    // A frame or a range changed on disk after the file was written: compute
                    // it again.
                    eprintln!("note: recomputing the cached features: {e}");
                    drop(file);
                    let _ = std::fs::remove_file(&path);
                    encode_cached(rep, seq, frames, policy)
                }
                Err(e) => Err(e),
            }
        }
    }
}

/// The content key of (representation, rest mesh, frames): 24 hex digits. Frames are hashed
/// in parallel, then combined in order.
pub fn key(rep: &Representation, seq: &dyn FrameSource, frames: &[usize]) -> Result<String> {
    use rayon::prelude::*;
    let mut h = Hasher::new();
    h.bytes(MAGIC.as_bytes());
    h.bytes(rep.kind().name().as_bytes());
    h.bytes(rep.options().key_text().as_bytes());
    let rest = rep.rest();
    let (rf, rc) = frame_hash(&rest.positions);
    h.word(rf);
    h.word(rc as u64);
    h.word(rest.faces.len() as u64);
    for t in &rest.faces {
        t.iter().for_each(|&i| h.word(i as u64));
    }
    h.word(frames.len() as u64);
    let hashes: Vec<(u64, u32)> =
        frames.par_iter().map(|&f| seq.frame(f).map(|p| frame_hash(&p))).collect::<Result<_>>()?;
    for (a, b) in hashes {
        h.word(a);
        h.word(b as u64);
    }
    Ok(h.finish())
}

/// (FNV-1a over the coordinates' bits, CRC-32 of their bytes) of one frame.
fn frame_hash(frame: &[crate::mesh::Vec3]) -> (u64, u32) {
    let mut fnv = 0xcbf2_9ce4_8422_2325u64 ^ frame.len() as u64;
    let mut crc = crc32fast::Hasher::new();
    let mut buf = Vec::with_capacity(frame.len().min(4096) * 24);
    for chunk in frame.chunks(4096) {
        buf.clear();
        for p in chunk {
            for x in p {
                let w = x.to_bits();
                fnv = (fnv ^ w).wrapping_mul(0x0000_0100_0000_01b3);
                buf.extend_from_slice(&w.to_le_bytes());
            }
        }
        crc.update(&buf);
    }
    (fnv ^ (fnv >> 29), crc.finalize())
}

/// FNV-1a over 64-bit words beside a CRC-32 of the same words: 96 bits.
struct Hasher {
    fnv: u64,
    crc: crc32fast::Hasher,
}

impl Hasher {
    fn new() -> Self {
        Hasher { fnv: 0xcbf2_9ce4_8422_2325, crc: crc32fast::Hasher::new() }
    }
    fn word(&mut self, w: u64) {
        self.fnv = (self.fnv ^ w).wrapping_mul(0x0000_0100_0000_01b3);
        self.fnv ^= self.fnv >> 29;
        self.crc.update(&w.to_le_bytes());
    }
    fn bytes(&mut self, b: &[u8]) {
        self.word(b.len() as u64);
        b.iter().for_each(|&x| self.word(x as u64));
    }
    fn finish(self) -> String {
        format!("{:016x}{:08x}", self.fnv, self.crc.finalize())
    }
}

/// Computes the features `BUILD_RUN` frames at a time (in parallel) and writes the cache file
/// atomically. A write that fails is an [`Error::Io`]; any other error is the data's.
fn build(
    rep: &Representation,
    seq: &dyn FrameSource,
    frames: &[usize],
    path: &Path,
    key: &str,
    on_frames: &mut dyn FnMut(usize),
) -> Result<()> {
    let width = rep.width();
    let mut header = Header {
        key: key.to_string(),
        n_frames: frames.len(),
        n_elements: rep.n_elements(),
        width,
        frame_crc32: Vec::with_capacity(frames.len()),
        min_bits: Vec::new(),
        max_bits: Vec::new(),
        header_crc32: 0,
    };
    let mut ranges = Ranges::new(width);
    crate::artifact::write_atomic_checked(path, |w| {
        use std::io::Write;
        let io = |e: std::io::Error| Error::io(path, e);
        writeln!(w, "{MAGIC}").map_err(io)?;
        let mut offset = (MAGIC.len() + 1) as u64;
        for run in frames.chunks(BUILD_RUN) {
            let f = rep.encode_selected(seq, run)?;
            if let Some(i) = f.data.iter().position(|x| !x.is_finite()) {
                return Err(Error::Numerical(format!(
                    "frame {}: feature {} is {}",
                    run[i / (f.n_elements * width).max(1)],
                    i,
                    f.data[i]
                )));
            }
            for frame in f.data.chunks_exact((f.n_elements * width).max(1)) {
                let bytes: Vec<u8> = frame.iter().flat_map(|x| x.to_le_bytes()).collect();
                header.frame_crc32.push(crc32fast::hash(&bytes));
                ranges.add(frame);
                w.write_all(&bytes).map_err(io)?;
                offset += bytes.len() as u64;
            }
            on_frames(header.frame_crc32.len());
        }
        header.min_bits = ranges.min.iter().map(|x| x.to_bits()).collect();
        header.max_bits = ranges.max.iter().map(|x| x.to_bits()).collect();
        header.header_crc32 = header.checksum();
        let json = serde_json::to_vec(&header).map_err(|e| io(std::io::Error::other(e)))?;
        w.write_all(&json).map_err(io)?;
        w.write_all(&offset.to_le_bytes()).map_err(io)?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshSequence;
    use crate::representation::{RepresentationKind, RepresentationOptions};

    fn setup() -> (Representation, MeshSequence) {
        let seq = crate::synthetic::load("synthetic:bumps").unwrap();
        let rest = crate::mesh::TriMesh::new(seq.frames[0].clone(), seq.faces.clone());
        let rep = Representation::new(RepresentationKind::Acap, &rest, RepresentationOptions::default()).unwrap();
        (rep, seq)
    }

    #[test]
    fn written_then_read_back_exactly_and_corruption_recomputed() {
        let (rep, seq) = setup();
        let dir = std::env::temp_dir().join(format!("meshdeco-cache-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let policy = CachePolicy::Dir(dir.clone());
        let frames = [3, 1, 7];
        let (a, used) = encode_cached(&rep, &seq, &frames, &policy).unwrap();
        let CacheUse::Written(path) = used else { panic!("expected a write, got {used:?}") };
        assert_eq!(a, rep.encode_selected(&seq, &frames).unwrap());
        let (b, used) = encode_cached(&rep, &seq, &frames, &policy).unwrap();
        assert_eq!(used, CacheUse::Read(path.clone()));
        assert_eq!(a, b, "read back bit for bit");
        // Other frames, other order, other options: other keys.
        assert_ne!(key(&rep, &seq, &frames).unwrap(), key(&rep, &seq, &[1, 3, 7]).unwrap());
        let opts = RepresentationOptions {
            acap_consistency: crate::representation::acap::Consistency::Global,
            ..Default::default()
        };
        let rep2 = Representation::new(RepresentationKind::Acap, rep.rest(), opts).unwrap();
        assert_ne!(key(&rep, &seq, &frames).unwrap(), key(&rep2, &seq, &frames).unwrap());
        let opts = RepresentationOptions { acap_map: crate::representation::acap::FeatureMap::Gradient, ..opts };
        let rep3 = Representation::new(RepresentationKind::Acap, rep.rest(), opts).unwrap();
        assert_ne!(key(&rep2, &seq, &frames).unwrap(), key(&rep3, &seq, &frames).unwrap(), "the feature map");
        assert!(!RepresentationOptions::default().key_text().contains("acap_map"), "the default map keeps old keys");
        assert!(opts.key_text().contains("acap_map: Gradient"));
        let mut moved = seq.clone();
        moved.frames[7][0][0] += 1e-12;
        assert_ne!(key(&rep, &seq, &frames).unwrap(), key(&rep, &moved, &frames).unwrap());
        // One flipped byte in the last frame: that frame fails its checksum when read; the
        // cache computes it again and rewrites the file.
        let k = key(&rep, &seq, &frames).unwrap();
        let expect = (3, a.n_elements, a.width);
        let clean = std::fs::read(&path).unwrap();
        let mut bytes = clean.clone();
        let data_end = (MAGIC.len() + 1) + 8 * a.data.len();
        bytes[data_end - 3] ^= 0x40;
        std::fs::write(&path, &bytes).unwrap();
        let file = FeatureFile::open(&path, &k, expect).unwrap();
        assert!(file.frame(0).is_ok());
        let e = file.frame(2).unwrap_err().to_string();
        assert!(e.contains("frame 2 fails its checksum"), "{e}");
        drop(file);
        let (c, used) = encode_cached(&rep, &seq, &frames, &policy).unwrap();
        assert_eq!((c, used), (a.clone(), CacheUse::Written(path.clone())));
        assert_eq!(std::fs::read(&path).unwrap(), clean);
        // Truncated, or another shape asked for: refused when opened.
        std::fs::write(&path, &clean[..clean.len() - 20]).unwrap();
        assert!(FeatureFile::open(&path, &k, expect).is_err());
        std::fs::write(&path, &clean).unwrap();
        let e = FeatureFile::open(&path, &k, (4, a.n_elements, a.width)).unwrap_err().to_string();
        assert!(e.contains("expected 4 ×"), "{e}");
        let e = FeatureFile::open(&path, "0123", expect).unwrap_err().to_string();
        assert!(e.contains("expected 0123"), "{e}");
        // The recorded ranges are the features' own.
        let file = FeatureFile::open(&path, &k, expect).unwrap();
        for d in 0..a.width {
            let col = a.data.iter().skip(d).step_by(a.width);
            assert_eq!(file.header().min()[d], col.clone().copied().fold(f64::INFINITY, f64::min));
            assert_eq!(file.header().max()[d], col.copied().fold(f64::NEG_INFINITY, f64::max));
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Rewrites the JSON header of the cache file at `path` with `edit`, re-recording its
    /// checksum when `rerecord` (the data and the header's offset stay).
    fn edit_header(path: &Path, rerecord: bool, edit: impl FnOnce(&mut Header)) {
        let bytes = std::fs::read(path).unwrap();
        let at = u64::from_le_bytes(bytes[bytes.len() - 8..].try_into().unwrap()) as usize;
        let mut h: Header = serde_json::from_slice(&bytes[at..bytes.len() - 8]).unwrap();
        edit(&mut h);
        if rerecord {
            h.header_crc32 = h.checksum();
        }
        let mut out = bytes[..at].to_vec();
        out.extend(serde_json::to_vec(&h).unwrap());
        out.extend((at as u64).to_le_bytes());
        std::fs::write(path, out).unwrap();
    }

    #[test]
    fn ranges_are_checksummed_and_checked_against_the_frames() {
        let (rep, seq) = setup();
        let dir = std::env::temp_dir().join(format!("meshdeco-cache-ranges-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let policy = CachePolicy::Dir(dir.clone());
        let frames = [0, 2, 4, 6];
        let (a, used) = encode_cached(&rep, &seq, &frames, &policy).unwrap();
        let CacheUse::Written(path) = used else { panic!("{used:?}") };
        let clean = std::fs::read(&path).unwrap();
        let k = key(&rep, &seq, &frames).unwrap();
        let expect = (frames.len(), a.n_elements, a.width);
        let file = FeatureFile::open(&path, &k, expect).unwrap();
        file.verify().unwrap();
        assert_eq!(file.header().checksum(), file.header().header_crc32);
        drop(file);
        let half = |b: u64| (f64::from_bits(b) / 2.0).to_bits();
        // Every field of the header is covered by its checksum.
        type Edit<'a> = Box<dyn Fn(&mut Header) + 'a>;
        let edits: Vec<(&str, Edit<'_>)> = vec![
            ("min", Box::new(|h: &mut Header| h.min_bits[0] = half(h.min_bits[0]))),
            ("max", Box::new(|h: &mut Header| h.max_bits[8] = half(h.max_bits[8]))),
            ("frame", Box::new(|h: &mut Header| h.frame_crc32[1] ^= 1)),
            ("key", Box::new(|h: &mut Header| h.key.push('0'))),
            ("frames", Box::new(|h: &mut Header| h.n_frames += 1)),
            ("elements", Box::new(|h: &mut Header| h.n_elements += 1)),
            ("width", Box::new(|h: &mut Header| h.width += 1)),
            (
                "fewer ranges",
                Box::new(|h: &mut Header| {
                    h.max_bits.pop();
                }),
            ),
        ];
        for (what, edit) in &edits {
            edit_header(&path, false, edit);
            let e = FeatureFile::open(&path, &k, expect).unwrap_err().to_string();
            assert!(e.contains("header checksum") && e.contains(&path.display().to_string()), "{what}: {e}");
            std::fs::write(&path, &clean).unwrap();
        }
        // Ranges changed behind a re-recorded checksum: the file opens, but its ranges are not
        // its frames'; open_or_build and encode_cached recompute it (the clean file again).
        let ranges: Vec<(&str, Edit<'_>)> = vec![
            ("halved minimum", Box::new(|h: &mut Header| h.min_bits[3] = half(h.min_bits[3]))),
            ("halved maximum", Box::new(|h: &mut Header| h.max_bits[0] = half(h.max_bits[0]))),
            ("huge", Box::new(|h: &mut Header| h.max_bits[5] = 1e300f64.to_bits())),
            ("minus huge", Box::new(|h: &mut Header| h.min_bits[5] = (-1e300f64).to_bits())),
            ("NaN", Box::new(|h: &mut Header| h.min_bits[1] = f64::NAN.to_bits())),
            ("NaN maximum", Box::new(|h: &mut Header| h.max_bits[1] = f64::NAN.to_bits())),
        ];
        for (what, edit) in &ranges {
            for reader in 0..2 {
                edit_header(&path, true, edit);
                let file = FeatureFile::open(&path, &k, expect).unwrap();
                let e = file.verify().unwrap_err().to_string();
                assert!(e.contains("recorded range") && e.contains(&path.display().to_string()), "{what}: {e}");
                let e = file.read_all().unwrap_err().to_string();
                assert!(e.contains("recorded range"), "{what}: {e}");
                drop(file);
                if reader == 0 {
                    let opened = open_or_build(&rep, &seq, &frames, &policy, &mut |_| {}).unwrap();
                    assert!(matches!(opened, Opened::File { built: true, .. }), "{what}: {opened:?}");
                } else {
                    let (b, used) = encode_cached(&rep, &seq, &frames, &policy).unwrap();
                    assert_eq!((b, used), (a.clone(), CacheUse::Written(path.clone())), "{what}");
                }
                assert_eq!(std::fs::read(&path).unwrap(), clean, "{what}: recomputed");
            }
        }
        // The clean file is reused as it is.
        let opened = open_or_build(&rep, &seq, &frames, &policy, &mut |_| {}).unwrap();
        assert!(matches!(opened, Opened::File { built: false, .. }), "{opened:?}");
        // A range recorded as −0 where the frames' is +0 (or the reverse) is the same range.
        let mut r = Ranges::new(2);
        r.add(&[0.0, 1.0, -0.0, 2.0]);
        let mut other = Ranges::new(2);
        other.add(&[-0.0, 2.0]);
        other.merge(&Ranges { min: vec![0.0, 1.0], max: vec![0.0, 1.0] });
        assert_eq!(r, other);
        assert_eq!((r.min.clone(), r.max.clone()), (vec![0.0, 1.0], vec![0.0, 2.0]));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn policies() {
        assert_eq!(CachePolicy::parse("auto"), CachePolicy::Auto);
        assert_eq!(CachePolicy::parse("off"), CachePolicy::Off);
        assert_eq!(CachePolicy::parse("/x/y"), CachePolicy::Dir("/x/y".into()));
        assert_eq!(CachePolicy::Auto.folder(AUTO_MIN_BYTES - 1), None);
        // From AUTO_MIN_BYTES on, the default folder (HOME is set wherever the tests run).
        let d = default_folder().expect("HOME is set");
        match std::env::var_os("MESHDECO_CACHE_DIR").filter(|v| !v.is_empty()) {
            Some(v) => assert_eq!(d, PathBuf::from(v)),
            None => assert!(d.ends_with("meshdeco/features"), "{d:?}"),
        }
        assert_eq!(CachePolicy::Auto.folder(AUTO_MIN_BYTES), Some(d));
        assert_eq!(CachePolicy::Off.folder(usize::MAX), None);
        assert_eq!(CachePolicy::Dir("d".into()).folder(0), Some(PathBuf::from("d")));
        // An unwritable folder costs only the reuse.
        let (rep, seq) = setup();
        let policy = CachePolicy::Dir("/proc/meshdeco-no-such-folder".into());
        let (f, used) = encode_cached(&rep, &seq, &[0, 1], &policy).unwrap();
        assert!(matches!(used, CacheUse::Unavailable(_)), "{used:?}");
        assert_eq!(f, rep.encode_selected(&seq, &[0, 1]).unwrap());
    }

    /// The first checks of `open`, on files made byte by byte: too short for the magic line and
    /// the header's offset (by one byte, and far), and a header offset outside the file or
    /// a header past 64 MiB — each refused by name, never read.
    #[test]
    fn short_files_and_stray_header_offsets_are_refused() {
        let dir = std::env::temp_dir().join(format!("meshdeco-cache-short-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.features");
        let open = || FeatureFile::open(&path, "k", (1, 1, 9)).map(|_| ());
        let magic = format!("{MAGIC}\n").into_bytes();
        let d = magic.len() as u64;
        let with_tail = |body_len: u64, header_at: u64| {
            let mut b = magic.clone();
            b.resize(body_len as usize, 0);
            b.extend(header_at.to_le_bytes());
            b
        };
        for bytes in [b"MES".to_vec(), magic.clone(), with_tail(d, d)[..(d + 7) as usize].to_vec()] {
            std::fs::write(&path, &bytes).unwrap();
            let e = open().unwrap_err().to_string();
            assert!(
                e.contains("too short for a feature cache") && e.contains("x.features"),
                "{} bytes: {e}",
                bytes.len()
            );
        }
        // Long enough, but the offset must point into [magic end, tail start).
        for (body, at) in [(d, d), (d + 4, d + 4), (d + 4, d - 1), (d + 4, 0), (d + 4, u64::MAX)] {
            let bytes = with_tail(body, at);
            std::fs::write(&path, &bytes).unwrap();
            let e = open().unwrap_err().to_string();
            assert!(
                e.contains(&format!("header offset {at} is outside the file")),
                "{body} + 8 bytes, offset {at}: {e}"
            );
        }
        // A header of more than 64 MiB (a sparse file: nothing is written or read).
        let sparse = |len: u64| {
            use std::io::{Seek, SeekFrom, Write};
            let mut f = std::fs::File::create(&path).unwrap();
            f.set_len(len).unwrap();
            f.write_all(&magic).unwrap();
            f.seek(SeekFrom::Start(len - 8)).unwrap();
            f.write_all(&d.to_le_bytes()).unwrap();
        };
        let len = d + (64 << 20) + 9;
        sparse(len);
        let e = open().unwrap_err().to_string();
        assert!(e.contains(&format!("header offset {d} is outside the file ({len} bytes)")), "{e}");
        // The largest header allowed is read (and then refused for what it says).
        sparse(d + (64 << 20) + 8);
        let e = open().unwrap_err().to_string();
        assert!(e.contains("header: "), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_frames_hash_is_the_files_format() {
        // The cache key holds every frame's hash: a changed hash orphans every cache file, and a
        // weaker one lets two frames share a key. Pinned values, and frames that differ in one
        // coordinate's last bit, in their length, or only by a shift of a value between
        // coordinates all hash apart.
        let frame = [[1.0, -2.5, 3.25], [0.0, 1e-300, -0.0]];
        let (fnv, crc) = frame_hash(&frame);
        assert_eq!((fnv, crc), (0x24f2_22c2_5109_7265, 0x47a4_2ef5));
        // One vertex: the length seed's low bit is one the FNV offset also has (so `^` and `|`
        // differ there).
        assert_eq!(frame_hash(&frame[..1]), (0x6ef9_971b_10eb_89cf, 0x06ad_2a93));
        let mut bit = frame;
        bit[1][1] = f64::from_bits(bit[1][1].to_bits() ^ 1);
        let mut swapped = frame;
        swapped[0].swap(0, 1);
        let hashes =
            [frame_hash(&frame), frame_hash(&bit), frame_hash(&swapped), frame_hash(&frame[..1]), frame_hash(&[])];
        for i in 0..hashes.len() {
            for j in 0..i {
                assert!(hashes[i].0 != hashes[j].0 && hashes[i].1 != hashes[j].1, "{i} and {j}: {hashes:?}");
            }
        }
        // Zero frames of different lengths: the CRC of no bytes is 0 for the empty one only; the
        // FNV part is seeded with the length.
        assert_ne!(frame_hash(&[[0.0; 3]]).0, frame_hash(&[[0.0; 3]; 2]).0);
        // The key's hasher (the key names the file): pinned, and order, value and length count.
        let key = |words: &[u64], bytes: &[u8]| {
            let mut h = Hasher::new();
            words.iter().for_each(|&w| h.word(w));
            h.bytes(bytes);
            h.finish()
        };
        let pinned = key(&[1, u64::MAX, 0x8000_0000_0000_0000], b"ab");
        assert_eq!(pinned, "fb7d783792271cbf3d959641");
        let keys = [key(&[1, 2], b""), key(&[2, 1], b""), key(&[3], b""), key(&[1, 2], b"\0"), key(&[], b"")];
        for i in 0..keys.len() {
            for j in 0..i {
                assert_ne!(keys[i][..16], keys[j][..16], "{i} and {j}: {keys:?}");
                assert_ne!(keys[i][16..], keys[j][16..], "{i} and {j}: {keys:?}");
            }
        }
    }

    #[test]
    fn auto_caches_from_64_mib_of_features() {
        // 8 bytes per number, every factor counted: 3 × 5 × 9 numbers.
        assert_eq!(feature_bytes(3, 5, 9), 1080);
        assert_eq!(feature_bytes(0, 5, 9), 0);
        // The face poses' 9-wide ACAP features of 29 299 vertices: 64 MiB at 32 frames, not 31.
        let face = |frames| feature_bytes(frames, 29_299, 9);
        assert!(face(31) < AUTO_MIN_BYTES && face(32) >= AUTO_MIN_BYTES);
        assert_eq!(CachePolicy::Auto.folder(face(31)), None);
        assert_eq!(CachePolicy::Auto.folder(face(32)), default_folder());
        assert_eq!(CachePolicy::Off.folder(face(32)), None);
        assert_eq!(CachePolicy::Dir("d".into()).folder(0), Some(PathBuf::from("d")));
    }

    /// A header whose checksum holds but whose per-frame checksums or ranges have another
    /// length than its shape says: refused when opened, each on its own.
    #[test]
    fn a_header_of_the_wrong_lengths_is_refused() {
        let (rep, seq) = setup();
        let dir = std::env::temp_dir().join(format!("meshdeco-cache-lengths-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let frames = [1, 2];
        let (a, used) = encode_cached(&rep, &seq, &frames, &CachePolicy::Dir(dir.clone())).unwrap();
        let CacheUse::Written(path) = used else { panic!("{used:?}") };
        let k = key(&rep, &seq, &frames).unwrap();
        let expect = (2, a.n_elements, a.width);
        let clean = std::fs::read(&path).unwrap();
        for which in 0..4 {
            std::fs::write(&path, &clean).unwrap();
            edit_header(&path, true, |h| match which {
                0 => {
                    h.frame_crc32.pop();
                }
                1 => h.frame_crc32.push(0),
                2 => {
                    h.min_bits.pop();
                }
                _ => h.max_bits.push(0),
            });
            let e = FeatureFile::open(&path, &k, expect).map(|_| ()).unwrap_err().to_string();
            assert!(e.contains("frame checksums, expected"), "edit {which}: {e}");
        }
        std::fs::write(&path, &clean).unwrap();
        // Intact, it opens, with the frames it holds (the histogram pass of a fenced scaling
        // reads `n_frames` of them).
        assert_eq!(FeatureFile::open(&path, &k, expect).unwrap().n_frames(), 2);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
