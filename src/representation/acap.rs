//! PLACEHOLDER for the ACAP representation (Gao et al.), owned by helper `acap`; this file only
//! declares the agreed interface so that [`super::Representation`] compiles. Every constructor
//! returns an error. The lead replaces this file with acap's real one on merge.

use crate::error::{Error, Result};
use crate::mesh::{TriMesh, Vec3};

/// Rotation-consistency strategy (agreed interface).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Consistency {
    /// Breadth-first propagation (the reference's option 0).
    Bfs,
    /// Global minimisation of the neighbour-difference energy (option 1).
    Global,
}

/// ACAP features of one frame (agreed interface).
#[derive(Debug, Clone)]
pub struct AcapFrame {
    /// Consistent log-rotation per vertex.
    pub log_r: Vec<[[f64; 3]; 3]>,
    /// Symmetric stretch per vertex.
    pub s: Vec<[[f64; 3]; 3]>,
    /// Neighbour-difference energy after BFS consistency.
    pub energy_bfs: f64,
    /// Energy of the returned rotations.
    pub energy: f64,
}

impl AcapFrame {
    /// N × 9 feature layout (placeholder: empty).
    pub fn features(&self) -> Vec<f64> {
        Vec::new()
    }
}

/// The ACAP encoder/decoder of one reference mesh (placeholder: cannot be built).
#[derive(Debug)]
pub struct Acap {
    _private: (),
}

impl Acap {
    /// Always an error in this placeholder.
    pub fn new(_reference: &TriMesh) -> Result<Acap> {
        Err(Error::Invalid("acap not yet merged".into()))
    }
    /// Always an error in this placeholder.
    pub fn encode_frame(&self, _positions: &[Vec3], _consistency: Consistency) -> Result<AcapFrame> {
        Err(Error::Invalid("acap not yet merged".into()))
    }
    /// Always an error in this placeholder.
    pub fn decode_frame(&self, _features: &[f64]) -> Result<Vec<Vec3>> {
        Err(Error::Invalid("acap not yet merged".into()))
    }
}
