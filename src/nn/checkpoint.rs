//! Training checkpoints: one file holding everything a resumed run needs (hyperparameters,
//! iteration, RNG state, the module's parameters and Adam's state), written atomically.
//!
//! File layout (little-endian):
//! ```text
//! b"MDAECKPT"  u32 format version
//! u64 n, n bytes   JSON header (CheckpointHeader)
//! u64 n, n bytes   module record (burnpack, Burn's ModuleRecord)
//! u64 m            number of optimizer records
//! m × (u64 n, n bytes)  optimizer records (burnpack, Burn's ModuleOptimizer): the layers' Adam,
//!                  then one per row block of C
//! u32              CRC-32 of every byte before it (format version 2)
//! ```
//!
//! The checksum is verified before anything else is read: a damaged checkpoint is named, never
//! resumed from.

use std::io::Write;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::config::AutoencoderConfig;
use super::loss::LossTerms;
use crate::artifact::write_atomic_with;
use crate::error::{Error, Result};

const MAGIC: &[u8; 8] = b"MDAECKPT";
const VERSION: u32 = 2;

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
}

/// A checkpoint in memory.
#[derive(Debug, Clone)]
pub struct Checkpoint {
    /// Metadata.
    pub header: CheckpointHeader,
    /// Burnpack bytes of the module record.
    pub module: Vec<u8>,
    /// Burnpack bytes of the optimizer records (layers, then each block of `C`).
    pub optimizers: Vec<Vec<u8>>,
}

impl Checkpoint {
    /// Serialises and writes the checkpoint atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let header = serde_json::to_vec(&self.header).map_err(|e| Error::Invalid(format!("checkpoint header: {e}")))?;
        let total: usize = self.optimizers.iter().map(|o| o.len() + 8).sum();
        let mut out = Vec::with_capacity(40 + header.len() + self.module.len() + total);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        for part in [&header[..], &self.module[..]] {
            out.extend_from_slice(&(part.len() as u64).to_le_bytes());
            out.extend_from_slice(part);
        }
        out.extend_from_slice(&(self.optimizers.len() as u64).to_le_bytes());
        for part in &self.optimizers {
            out.extend_from_slice(&(part.len() as u64).to_le_bytes());
            out.extend_from_slice(part);
        }
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        write_atomic_with(path, |w| w.write_all(&out))
    }

    /// Reads a checkpoint written by [`Self::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let corrupt = |m: &str| Error::parse(path, None, format!("not a meshdeco autoencoder checkpoint: {m}"));
        if bytes.len() < 12 || &bytes[..8] != MAGIC {
            return Err(corrupt("bad magic"));
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().unwrap());
        if version != VERSION {
            return Err(corrupt(&format!("format version {version}, this build reads {VERSION}")));
        }
        if bytes.len() < 16 {
            return Err(corrupt("truncated"));
        }
        let (body, trailer) = bytes.split_at(bytes.len() - 4);
        let stored = u32::from_le_bytes(trailer.try_into().unwrap());
        let actual = crc32fast::hash(body);
        if stored != actual {
            return Err(corrupt(&format!(
                "checksum {actual:08x} differs from the recorded {stored:08x} (damaged or truncated)"
            )));
        }
        let bytes = body;
        let mut pos = 12;
        let mut take = |len_only: bool| -> Result<Vec<u8>> {
            if bytes.len() < pos + 8 {
                return Err(corrupt("truncated"));
            }
            let n = u64::from_le_bytes(bytes[pos..pos + 8].try_into().unwrap()) as usize;
            pos += 8;
            if len_only {
                return Ok(n.to_le_bytes().to_vec());
            }
            if pos.checked_add(n).is_none_or(|end| end > bytes.len()) {
                return Err(corrupt("truncated"));
            }
            let v = bytes[pos..pos + n].to_vec();
            pos += n;
            Ok(v)
        };
        let header = take(false)?;
        let module = take(false)?;
        let count = usize::from_le_bytes(take(true)?.try_into().unwrap());
        if count > 1 << 20 {
            return Err(corrupt("implausible number of optimizer records"));
        }
        let optimizers = (0..count).map(|_| take(false)).collect::<Result<Vec<_>>>()?;
        if pos != bytes.len() {
            return Err(corrupt("trailing bytes"));
        }
        let header: CheckpointHeader = serde_json::from_slice(&header).map_err(|e| corrupt(&format!("header: {e}")))?;
        Ok(Checkpoint { header, module, optimizers })
    }
}
