//! Training checkpoints: one file holding everything a resumed run needs (hyperparameters,
//! iteration, RNG state, the parameters and Adam's state), written atomically.
//!
//! File layout (little-endian):
//! ```text
//! b"MDAECKPT"  u32 format version (4; 3 is read too: it has no best step)
//! u64 n, n bytes   JSON header (CheckpointHeader)
//! u64 n, n bytes   module record of the convolution layers (burnpack, Burn's ModuleRecord of
//!                  an AutoencoderModule without component blocks)
//! u64 n, n bytes   optimizer record of the layers (burnpack, Burn's ModuleOptimizer: Adam)
//! u64 K, u64 9N, u64 t   shape of C and Adam's step count for C
//! K·9N × f32       C, row-major
//! K·9N × f32       Adam's first moment of C   (only when t > 0)
//! K·9N × f32       Adam's second moment of C  (only when t > 0)
//! u64 s            the best validation step (0: none; version 4)
//! when s > 0: u64 bits of its validation error (f64), u64 L, L × 180 f32 (each layer's
//!                  W_point and W_nb row-major, encoder and decoder bias), K·9N × f32 its C
//! u32              CRC-32 of every byte before it
//! ```
//!
//! The JSON header stores every float a second time, exactly: `float_bits` lists the bits of
//! each floating-point number of the header in the order [`visit_floats`] meets them, and a
//! reader puts those values back (a JSON reader may read a float one unit in the last place
//! off: serde_json's default parser did so for about one number in five; meshdeco now builds it
//! with `float_roundtrip`, and the bits keep the header exact whichever parser reads it), so a run resumed
//! after its last step reports its last loss to the bit. A header without `float_bits` (written
//! before it existed) is read as JSON.
//!
//! `C` and its moments are written straight from the trainer's buffers and read straight into
//! the resumed trainer's (no intermediate copies of the 13 M-number arrays of a large mesh). The
//! checksum is verified, in a first pass over the file, before anything else is read: a damaged
//! checkpoint is named, never resumed from.
//!
//! A run that holds out validation shapes (`validation > 0`) keeps the parameters of its best
//! validation step, not its last; the checkpoint holds them too, so that a resumed run keeps a
//! best step from before the interruption (version 3 did not: a run resumed from one chooses among
//! the steps after it).

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom, Write};
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::adam::ComponentAdam;
use super::config::AutoencoderConfig;
use super::engine::LayerWeights;
use super::loss::LossTerms;
use crate::artifact::write_atomic_with;
use crate::error::{Error, Result};

const MAGIC: &[u8; 8] = b"MDAECKPT";
const VERSION: u32 = 4;
/// The last version without the best validation step.
const VERSION_WITHOUT_BEST: u32 = 3;
/// f32 numbers of one layer in the best step's section (W_point, W_nb, two biases).
const LAYER_FLOATS: usize = 2 * 81 + 2 * 9;

/// The parameters of a run's best validation step (`validation > 0`).
#[derive(Debug, Clone, PartialEq)]
pub struct BestStep {
    /// The step (≥ 1).
    pub iteration: usize,
    /// Its validation error.
    pub error: f64,
    /// The encoder layers in forward order.
    pub layers: Vec<LayerWeights>,
    /// Its `C`, `[K, 9N]` row-major.
    pub components: Vec<f32>,
}

/// A best step borrowed from a trainer.
#[derive(Clone, Copy)]
pub struct BestStepParts<'a> {
    pub iteration: usize,
    pub error: f64,
    pub layers: &'a [LayerWeights],
    pub components: &'a [f32],
}

impl BestStep {
    /// Borrowed, as [`write()`] takes it.
    pub fn parts(&self) -> BestStepParts<'_> {
        BestStepParts {
            iteration: self.iteration,
            error: self.error,
            layers: &self.layers,
            components: &self.components,
        }
    }
}

impl BestStepParts<'_> {
    /// An owned copy.
    pub fn to_owned(&self) -> BestStep {
        BestStep {
            iteration: self.iteration,
            error: self.error,
            layers: self.layers.to_vec(),
            components: self.components.to_vec(),
        }
    }
}

fn layer_floats(l: &LayerWeights) -> Vec<f32> {
    let mut v = Vec::with_capacity(LAYER_FLOATS);
    v.extend(l.wp.iter().flatten());
    v.extend(l.wn.iter().flatten());
    v.extend(l.b);
    v.extend(l.bd);
    v
}

fn layer_from_floats(v: &[f32]) -> LayerWeights {
    let mat = |o: usize| std::array::from_fn(|r| std::array::from_fn(|c| v[o + 9 * r + c]));
    LayerWeights {
        wp: mat(0),
        wn: mat(81),
        b: std::array::from_fn(|i| v[162 + i]),
        bd: std::array::from_fn(|i| v[171 + i]),
    }
}

/// Metadata of a checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointHeader {
    /// Completed optimisation steps.
    pub iteration: usize,
    /// State of the mini-batch generator after `iteration` steps.
    pub rng_state: u64,
    /// Hyperparameters of the run.
    pub config: AutoencoderConfig,
    /// Number of vertices N of the mesh.
    pub n_vertices: usize,
    /// Number of training shapes.
    pub n_shapes: usize,
    /// [`super::neighbors::NeighborIndex::fingerprint`] of the mesh.
    pub neighbor_fingerprint: u64,
    /// Loss of the last completed step.
    pub last_loss: Option<LossTerms>,
    /// Shapes a step of the run ([`AutoencoderConfig::batch_for`]); absent in checkpoints
    /// written before the default batch depended on the set's size (issue 57), whose rule was
    /// `batch_size` or the full batch ([`CheckpointHeader::batch`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub batch: Option<usize>,
    /// Whether the run weighted its feature error per vertex ([`super::training::Trainer::with_feature_weights`],
    /// `feature_weights = "noise"`); absent (false) in checkpoints of unweighted runs and of
    /// runs before issue 53. A resume must weight alike.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub feature_weighted: bool,
    /// Seconds the run has trained up to this checkpoint (its steps, their validation and the
    /// checkpoints before this one), summed over the runs it was resumed through; absent (0) in
    /// checkpoints written before it was recorded.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub train_seconds: f64,
    /// The name of what the network's input features are when the caller named them
    /// ([`super::training::Trainer::with_input`]: the autoencoder's `features` key when not the
    /// default); absent for the default. A resume must read the same features.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input: Option<String>,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl CheckpointHeader {
    /// Shapes a step of the run that wrote it: the recorded batch, or the rule before issue 57
    /// (`batch_size`, else the full batch).
    pub fn batch(&self) -> usize {
        self.batch.unwrap_or_else(|| self.config.batch_size.unwrap_or(self.n_shapes).min(self.n_shapes))
    }
}

/// A checkpoint in memory.
#[derive(Debug, Clone)]
pub struct Checkpoint {
    /// Metadata.
    pub header: CheckpointHeader,
    /// Burnpack bytes of the module record of the layers (no component blocks).
    pub layers: Vec<u8>,
    /// Burnpack bytes of the layers' optimizer record.
    pub layers_optimizer: Vec<u8>,
    /// `C`, `[K, 9N]` row-major.
    pub components: Vec<f32>,
    /// Number of columns of `C` (9N).
    pub columns: usize,
    /// Adam's state for `C`.
    pub adam: ComponentAdam,
    /// The best validation step's parameters (runs with `validation > 0`, version 4).
    pub best: Option<BestStep>,
}

/// The parts of a checkpoint, borrowed from a trainer (see [`write()`]).
pub struct CheckpointParts<'a> {
    /// Metadata.
    pub header: &'a CheckpointHeader,
    /// Burnpack bytes of the module record of the layers.
    pub layers: &'a [u8],
    /// Burnpack bytes of the layers' optimizer record.
    pub layers_optimizer: &'a [u8],
    /// `C`, `[K, 9N]` row-major.
    pub components: &'a [f32],
    /// 9N.
    pub columns: usize,
    /// Adam's state for `C`.
    pub adam: &'a ComponentAdam,
    /// The best validation step so far (runs with `validation > 0`).
    pub best: Option<BestStepParts<'a>>,
}

/// Key of the header's exact floats (module docs).
const FLOAT_BITS: &str = "float_bits";

/// Calls `f` on every floating-point number in `v`, depth first, object members in the map's
/// order (the same order when the JSON text written from a value is read back).
fn visit_floats(v: &mut serde_json::Value, f: &mut dyn FnMut(&mut serde_json::Number)) {
    match v {
        serde_json::Value::Number(n) if n.is_f64() => f(n),
        serde_json::Value::Array(a) => a.iter_mut().for_each(|x| visit_floats(x, f)),
        serde_json::Value::Object(o) => o.values_mut().for_each(|x| visit_floats(x, f)),
        _ => {}
    }
}

/// The header as JSON text with its floats' bits beside them (`float_bits`, module docs).
fn header_bytes(header: &CheckpointHeader) -> Result<Vec<u8>> {
    let bad = |e: serde_json::Error| Error::Invalid(format!("checkpoint header: {e}"));
    let mut v = serde_json::to_value(header).map_err(bad)?;
    let mut bits = Vec::new();
    visit_floats(&mut v, &mut |n| bits.push(n.as_f64().unwrap_or(f64::NAN).to_bits()));
    if let serde_json::Value::Object(o) = &mut v {
        o.insert(FLOAT_BITS.into(), bits.into());
    }
    serde_json::to_vec(&v).map_err(bad)
}

/// Reads a header written by [`header_bytes`] with its floats exactly as they were written
/// (`float_bits`); each listed value must round to the number in the text, and the list must
/// have one value per float. Errors are messages for the caller to name the file.
fn parse_header(bytes: &[u8]) -> std::result::Result<CheckpointHeader, String> {
    let mut v: serde_json::Value = serde_json::from_slice(bytes).map_err(|e| e.to_string())?;
    let bits = match &mut v {
        serde_json::Value::Object(o) => o.remove(FLOAT_BITS),
        _ => None,
    };
    if let Some(bits) = bits {
        let bits: Vec<u64> = serde_json::from_value(bits).map_err(|e| format!("`{FLOAT_BITS}`: {e}"))?;
        let (mut i, mut wrong) = (0usize, None);
        visit_floats(&mut v, &mut |n| {
            let text = n.as_f64().unwrap_or(f64::NAN);
            match bits.get(i).map(|&b| f64::from_bits(b)) {
                Some(x) if (x - text).abs() <= 4.0 * f64::EPSILON * x.abs() => {
                    if let Some(exact) = serde_json::Number::from_f64(x) {
                        *n = exact;
                    }
                }
                found => {
                    if wrong.is_none() {
                        wrong = Some(format!("float {i} of the header is {text}, `{FLOAT_BITS}` says {found:?}"));
                    }
                }
            }
            i += 1;
        });
        if let Some(w) = wrong {
            return Err(w);
        }
        if i != bits.len() {
            return Err(format!("`{FLOAT_BITS}` lists {} values for the header's {i} floats", bits.len()));
        }
    }
    serde_json::from_value(v).map_err(|e| e.to_string())
}

/// A writer that keeps the CRC-32 of everything written through it.
struct Crc<W> {
    inner: W,
    hasher: crc32fast::Hasher,
}

impl<W: Write> Write for Crc<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hasher.update(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

fn write_f32s(w: &mut impl Write, v: &[f32]) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(4 * 8192);
    for chunk in v.chunks(8192) {
        buf.clear();
        for x in chunk {
            buf.extend_from_slice(&x.to_le_bytes());
        }
        w.write_all(&buf)?;
    }
    Ok(())
}

fn read_f32s(r: &mut impl Read, out: &mut [f32]) -> std::io::Result<()> {
    let mut buf = vec![0u8; 4 * 8192];
    for chunk in out.chunks_mut(8192) {
        let bytes = &mut buf[..4 * chunk.len()];
        r.read_exact(bytes)?;
        for (x, b) in chunk.iter_mut().zip(bytes.chunks_exact(4)) {
            *x = f32::from_le_bytes(b.try_into().unwrap());
        }
    }
    Ok(())
}

/// Serialises a checkpoint from borrowed parts and writes it atomically (streamed: no copy of
/// the file is built in memory).
pub fn write(path: &Path, parts: &CheckpointParts<'_>) -> Result<()> {
    let header = header_bytes(parts.header)?;
    let t = parts.adam.time;
    if parts.columns == 0
        || !parts.components.len().is_multiple_of(parts.columns)
        || (t > 0
            && (parts.adam.moment_1.len() != parts.components.len()
                || parts.adam.moment_2.len() != parts.components.len()))
    {
        return Err(Error::Invalid("checkpoint: inconsistent sizes of C and its Adam state".into()));
    }
    if let Some(b) = &parts.best
        && (b.iteration == 0 || b.components.len() != parts.components.len() || !b.error.is_finite())
    {
        return Err(Error::Invalid("checkpoint: the best step's iteration, error or C is inconsistent".into()));
    }
    write_atomic_with(path, |w| {
        let mut w = Crc { inner: w, hasher: crc32fast::Hasher::new() };
        w.write_all(MAGIC)?;
        w.write_all(&VERSION.to_le_bytes())?;
        for part in [&header[..], parts.layers, parts.layers_optimizer] {
            w.write_all(&(part.len() as u64).to_le_bytes())?;
            w.write_all(part)?;
        }
        for v in [parts.components.len() / parts.columns, parts.columns, t] {
            w.write_all(&(v as u64).to_le_bytes())?;
        }
        write_f32s(&mut w, parts.components)?;
        if t > 0 {
            write_f32s(&mut w, &parts.adam.moment_1)?;
            write_f32s(&mut w, &parts.adam.moment_2)?;
        }
        match &parts.best {
            None => w.write_all(&0u64.to_le_bytes())?,
            Some(b) => {
                w.write_all(&(b.iteration as u64).to_le_bytes())?;
                w.write_all(&b.error.to_bits().to_le_bytes())?;
                w.write_all(&(b.layers.len() as u64).to_le_bytes())?;
                for l in b.layers {
                    write_f32s(&mut w, &layer_floats(l))?;
                }
                write_f32s(&mut w, b.components)?;
            }
        }
        let crc = w.hasher.clone().finalize();
        w.inner.write_all(&crc.to_le_bytes())
    })
}

/// Whether the checkpoint at `path` is of a version that stores the best validation step (4 and
/// later; read from its first 12 bytes, nothing verified).
pub fn stores_best_step(path: &Path) -> bool {
    let mut head = [0u8; 12];
    File::open(path).and_then(|mut f| f.read_exact(&mut head)).is_ok()
        && &head[..8] == MAGIC
        && u32::from_le_bytes(head[8..12].try_into().unwrap()) >= VERSION
}

impl Checkpoint {
    /// Serialises and writes the checkpoint atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        write(
            path,
            &CheckpointParts {
                header: &self.header,
                layers: &self.layers,
                layers_optimizer: &self.layers_optimizer,
                components: &self.components,
                columns: self.columns,
                adam: &self.adam,
                best: self.best.as_ref().map(BestStep::parts),
            },
        )
    }

    /// Reads a checkpoint written by [`Self::save`] or [`write()`].
    pub fn load(path: &Path) -> Result<Self> {
        let corrupt = |m: &str| Error::parse(path, None, format!("not a meshdeco autoencoder checkpoint: {m}"));
        let io = |e: std::io::Error| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof { corrupt("truncated") } else { Error::io(path, e) }
        };
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        let mut head = [0u8; 12];
        if len < 12 || file.read_exact(&mut head).is_err() || &head[..8] != MAGIC {
            return Err(corrupt("bad magic"));
        }
        let version = u32::from_le_bytes(head[8..12].try_into().unwrap());
        if version != VERSION && version != VERSION_WITHOUT_BEST {
            return Err(corrupt(&format!(
                "format version {version}, this build reads {VERSION_WITHOUT_BEST} and {VERSION}"
            )));
        }
        if len < 16 {
            return Err(corrupt("truncated"));
        }
        // First pass: the checksum of everything before the trailer.
        let body = len - 4;
        file.seek(SeekFrom::Start(0)).map_err(|e| Error::io(path, e))?;
        let mut r = BufReader::with_capacity(1 << 20, file);
        let mut hasher = crc32fast::Hasher::new();
        let mut buf = vec![0u8; 1 << 20];
        let mut left = body;
        while left > 0 {
            let n = left.min(buf.len() as u64) as usize;
            r.read_exact(&mut buf[..n]).map_err(io)?;
            hasher.update(&buf[..n]);
            left -= n as u64;
        }
        let mut trailer = [0u8; 4];
        r.read_exact(&mut trailer).map_err(io)?;
        let stored = u32::from_le_bytes(trailer);
        let actual = hasher.finalize();
        if stored != actual {
            return Err(corrupt(&format!(
                "checksum {actual:08x} differs from the recorded {stored:08x} (damaged or truncated)"
            )));
        }
        drop(buf);
        // Second pass: the contents.
        r.seek(SeekFrom::Start(12)).map_err(|e| Error::io(path, e))?;
        let mut pos = 12u64;
        let u64_at = |r: &mut BufReader<File>, pos: &mut u64| -> Result<u64> {
            if *pos + 8 > body {
                return Err(corrupt("truncated"));
            }
            let mut b = [0u8; 8];
            r.read_exact(&mut b).map_err(io)?;
            *pos += 8;
            Ok(u64::from_le_bytes(b))
        };
        let bytes = |r: &mut BufReader<File>, pos: &mut u64| -> Result<Vec<u8>> {
            let n = u64_at(r, pos)?;
            if pos.checked_add(n).is_none_or(|end| end > body) {
                return Err(corrupt("truncated"));
            }
            let mut v = vec![0u8; n as usize];
            r.read_exact(&mut v).map_err(io)?;
            *pos += n;
            Ok(v)
        };
        let header = bytes(&mut r, &mut pos)?;
        let layers = bytes(&mut r, &mut pos)?;
        let layers_optimizer = bytes(&mut r, &mut pos)?;
        let (k, columns, time) = (u64_at(&mut r, &mut pos)?, u64_at(&mut r, &mut pos)?, u64_at(&mut r, &mut pos)?);
        let len_c = k.checked_mul(columns).filter(|&l| l <= (body - pos) / 4).ok_or_else(|| corrupt("truncated"))?;
        let arrays = if time > 0 { 3 } else { 1 };
        let end = pos + 4 * arrays * len_c;
        let fits = if version == VERSION { end + 8 <= body } else { end == body };
        if columns == 0 || !fits {
            return Err(corrupt(if end > body { "truncated" } else { "trailing bytes" }));
        }
        let read = |r: &mut BufReader<File>, n: usize| -> Result<Vec<f32>> {
            let mut v = vec![0.0f32; n];
            read_f32s(r, &mut v).map_err(io)?;
            Ok(v)
        };
        let components = read(&mut r, len_c as usize)?;
        let adam = if time > 0 {
            ComponentAdam {
                time: time as usize,
                moment_1: read(&mut r, len_c as usize)?,
                moment_2: read(&mut r, len_c as usize)?,
            }
        } else {
            ComponentAdam::default()
        };
        pos = end;
        let mut best = None;
        if version == VERSION {
            let iteration = u64_at(&mut r, &mut pos)?;
            if iteration > 0 {
                let error = f64::from_bits(u64_at(&mut r, &mut pos)?);
                let n_layers = u64_at(&mut r, &mut pos)?;
                let floats = n_layers
                    .checked_mul(LAYER_FLOATS as u64)
                    .and_then(|f| f.checked_add(len_c))
                    .filter(|&f| f <= (body - pos) / 4)
                    .ok_or_else(|| corrupt("truncated"))?;
                if pos + 4 * floats != body {
                    return Err(corrupt("trailing bytes"));
                }
                let layers = (0..n_layers)
                    .map(|_| read(&mut r, LAYER_FLOATS).map(|v| layer_from_floats(&v)))
                    .collect::<Result<Vec<_>>>()?;
                let components = read(&mut r, len_c as usize)?;
                pos += 4 * floats;
                best = Some(BestStep { iteration: iteration as usize, error, layers, components });
            } else if pos != body {
                return Err(corrupt("trailing bytes"));
            }
        }
        debug_assert_eq!(pos, body);
        let header = parse_header(&header).map_err(|e| corrupt(&format!("header: {e}")))?;
        Ok(Checkpoint { header, layers, layers_optimizer, components, columns: columns as usize, adam, best })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Numbers serde_json's default parser (without `float_roundtrip`) read one unit in the last
    /// place off (found by writing and reading random losses).
    const MISREAD: [f64; 5] =
        [1.1743710293288677e-6, 2.2088688993234186e-5, 116.48474444499239, 1.8580689537130886, 146.25613565452593];

    fn header() -> CheckpointHeader {
        let mut config = AutoencoderConfig::recommended();
        config.learning_rate = MISREAD[0];
        config.lambda1 = MISREAD[3];
        CheckpointHeader {
            iteration: 30,
            rng_state: u64::MAX - 12345,
            config,
            n_vertices: 2,
            n_shapes: 4,
            neighbor_fingerprint: 0xdead_beef_f00d,
            batch: Some(3),
            feature_weighted: true,
            train_seconds: MISREAD[2],
            input: Some("gradient".into()),
            last_loss: Some(LossTerms {
                total: MISREAD[4],
                reconstruction: MISREAD[2],
                sparsity: MISREAD[1],
                hinge: 0.0,
                orthogonality: -MISREAD[0],
                vertex: 1.0,
                code: 0.25,
            }),
        }
    }

    fn save(path: &Path, header: &CheckpointHeader) {
        let adam = ComponentAdam::default();
        let c = vec![0.5f32; 18];
        let parts = CheckpointParts {
            header,
            layers: b"L",
            layers_optimizer: b"O",
            components: &c,
            columns: 18,
            adam: &adam,
            best: None,
        };
        write(path, &parts).unwrap();
    }

    /// The best validation step reads back to the bit; a version-3 file (no best section) still
    /// reads, without one; a damaged best section is refused.
    #[test]
    fn the_best_step_reads_back_and_version_3_still_reads() {
        let dir = std::env::temp_dir().join(format!("meshdeco-ckpt-best-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("checkpoint.bin");
        let h = header();
        let adam = ComponentAdam { time: 2, moment_1: vec![0.25; 18], moment_2: vec![0.125; 18] };
        let c = vec![0.5f32; 18];
        let layer = |x: f32| LayerWeights {
            wp: std::array::from_fn(|r| std::array::from_fn(|k| x + (9 * r + k) as f32)),
            wn: std::array::from_fn(|r| std::array::from_fn(|k| -x - (9 * r + k) as f32)),
            b: std::array::from_fn(|i| x * i as f32),
            bd: std::array::from_fn(|i| 1e-3 * x * i as f32),
        };
        let layers = [layer(0.1), layer(-7.5)];
        let best_c: Vec<f32> = (0..18).map(|i| i as f32 * 0.37).collect();
        let best = BestStepParts { iteration: 20, error: MISREAD[1], layers: &layers, components: &best_c };
        let parts = CheckpointParts {
            header: &h,
            layers: b"L",
            layers_optimizer: b"O",
            components: &c,
            columns: 18,
            adam: &adam,
            best: Some(best),
        };
        write(&path, &parts).unwrap();
        let back = Checkpoint::load(&path).unwrap();
        let b = back.best.clone().expect("the best step is stored");
        assert_eq!((b.iteration, b.error.to_bits()), (20, MISREAD[1].to_bits()));
        assert_eq!(b.layers, layers.to_vec());
        assert_eq!(b.components, best_c);
        assert_eq!((back.components, back.adam.moment_2), (c.clone(), vec![0.125; 18]));
        // Written again from what was read: the same bytes.
        let again = dir.join("again.bin");
        Checkpoint::load(&path).unwrap().save(&again).unwrap();
        assert_eq!(std::fs::read(&again).unwrap(), std::fs::read(&path).unwrap());

        // Version 3: the same file without the best section's marker, the version and the CRC
        // rewritten.
        write(&path, &CheckpointParts { best: None, ..parts }).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        bytes.truncate(bytes.len() - 12);
        bytes[8..12].copy_from_slice(&3u32.to_le_bytes());
        let crc = crc32fast::hash(&bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let old = Checkpoint::load(&path).unwrap();
        assert!(old.best.is_none());
        assert!(!stores_best_step(&path) && stores_best_step(&again) && !stores_best_step(&dir.join("none")));
        assert_eq!(old.components, c);

        // A best section cut short (CRC made to match): refused, named.
        write(&path, &parts).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        bytes.truncate(bytes.len() - 4 - 8);
        let crc = crc32fast::hash(&bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let e = Checkpoint::load(&path).unwrap_err().to_string();
        assert!(e.contains("truncated") || e.contains("trailing"), "{e}");
        // A best step of another size of C: refused when written.
        let short = [0.0f32; 9];
        let bad = CheckpointParts { best: Some(BestStepParts { components: &short, ..best }), ..parts };
        assert!(write(&dir.join("bad.bin"), &bad).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_header_reads_back_every_float_exactly() {
        let dir = std::env::temp_dir().join(format!("meshdeco-ckpt-floats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("checkpoint.bin");
        let h = header();
        save(&path, &h);
        let back = Checkpoint::load(&path).unwrap();
        assert_eq!(back.header, h, "every field, floats to the bit");
        assert_eq!(back.header.last_loss.unwrap().total.to_bits(), MISREAD[4].to_bits());
        assert_eq!((back.layers.as_slice(), back.layers_optimizer.as_slice()), (&b"L"[..], &b"O"[..]));
        // The text lists every float of the header once, after the header's own fields.
        let bytes = header_bytes(&h).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        let mut floats = 0;
        let mut copy = serde_json::to_value(&h).unwrap();
        visit_floats(&mut copy, &mut |_| floats += 1);
        assert_eq!(v[FLOAT_BITS].as_array().unwrap().len(), floats);
        assert!(floats >= 10, "{floats}");
        // The bits, not the text, give the value: a reader whose text is one unit in the last
        // place off (as serde_json's default parser read these numbers) still gets each float
        // to the bit.
        let mut off = v.clone();
        let mut shifted = 0;
        visit_floats(&mut off, &mut |n| {
            let x = n.as_f64().unwrap();
            if x != 0.0 {
                *n = serde_json::Number::from_f64(f64::from_bits(x.to_bits() + 1)).unwrap();
                shifted += 1;
            }
        });
        assert!(shifted >= 5, "{shifted}");
        let read = parse_header(&serde_json::to_vec(&off).unwrap()).unwrap();
        assert_eq!(read, h, "every float from its bits");
        off.as_object_mut().unwrap().remove(FLOAT_BITS);
        assert_ne!(parse_header(&serde_json::to_vec(&off).unwrap()).unwrap(), h, "the text alone is off");
        // A header written before `float_bits` still reads (as JSON reads it).
        let old = serde_json::to_vec(&h).unwrap();
        let read = parse_header(&old).unwrap();
        assert_eq!(read.iteration, 30);
        assert!((read.last_loss.unwrap().total - MISREAD[4]).abs() < 1e-12);
        // Bits that disagree with the text, or too few or too many of them: refused.
        for (edit, says) in [
            (
                Box::new(|b: &mut Vec<serde_json::Value>| b[0] = 2.5f64.to_bits().into()) as Box<dyn Fn(&mut Vec<_>)>,
                "float 0",
            ),
            (
                Box::new(|b: &mut Vec<serde_json::Value>| {
                    b.pop();
                }),
                "float",
            ),
            (Box::new(|b: &mut Vec<serde_json::Value>| b.push(0u64.into())), "values for the header's"),
            (Box::new(|b: &mut Vec<serde_json::Value>| b[1] = "x".into()), FLOAT_BITS),
        ] {
            let mut w = v.clone();
            edit(w[FLOAT_BITS].as_array_mut().unwrap());
            let e = parse_header(&serde_json::to_vec(&w).unwrap()).unwrap_err();
            assert!(e.contains(says), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
