//! Encode → decode round trips of a sequence and their error, Erms (Neumann et al. 2013):
//! `Erms = 1000·sqrt(Σ_f Σ_v ‖v − v'‖² / (3·F·N))`, in the data's own units × 1000 (implemented
//! in [`crate::metrics::erms`], re-exported here).
//!
//! For translation-free representations ([`super::Representation::translation_free`]) every
//! decoded frame is first translated so that its vertex centroid (unweighted mean) coincides with
//! the input frame's ([`Alignment::Centroid`]); otherwise no alignment is applied. The report
//! records which one was used.

#![warn(missing_docs)]

use std::fmt;

use super::{Representation, RepresentationKind};
use crate::error::Result;
use crate::mesh::MeshSequence;

pub use crate::metrics::erms::{Alignment, erms, frame_squared_error};
use crate::metrics::erms::{alignment_shift, erms_from_squared_error, vertex_squared_error};

/// Per-frame and total error of an encode → decode round trip.
#[derive(Debug, Clone, PartialEq)]
pub struct RoundTripReport {
    /// The representation measured.
    pub kind: RepresentationKind,
    /// The alignment applied before measuring.
    pub alignment: Alignment,
    /// Vertices per frame N.
    pub n_vertices: usize,
    /// Connected pieces whose translation the representation carries (0: none carried — one
    /// piece, or an absolute representation).
    pub pieces_placed: usize,
    /// `(frame name, Erms of that frame alone)`, in input order.
    pub frames: Vec<(String, f64)>,
    /// Erms over all frames.
    pub total: f64,
    /// Largest vertex distance ‖v − v'‖ over all frames (after alignment), data units.
    pub max_distance: f64,
}

/// Encodes every frame of `seq` with `rep`, decodes it again and measures the error against the
/// input (centroid-aligned when the representation is translation-free).
pub fn roundtrip(rep: &Representation, seq: &MeshSequence) -> Result<RoundTripReport> {
    let features = rep.encode(seq)?;
    let decoded = rep.decode(&features)?;
    let alignment = if rep.translation_free() { Alignment::Centroid } else { Alignment::None };
    let n = seq.n_vertices();
    let mut frames = Vec::with_capacity(seq.n_frames());
    let mut max_distance: f64 = 0.0;
    for (f, (t, r)) in seq.frames.iter().zip(&decoded).enumerate() {
        let sq = frame_squared_error(t, r, alignment)?;
        let name = seq.names.get(f).cloned().unwrap_or_else(|| format!("{f}"));
        frames.push((name, erms_from_squared_error(sq, 3 * n)));
        let shift = alignment_shift(t, r, alignment);
        for (a, b) in t.iter().zip(r) {
            max_distance = max_distance.max(vertex_squared_error(*a, *b, shift).sqrt());
        }
    }
    let total = erms(&seq.frames, &decoded, alignment)?;
    let pieces_placed = rep.pieces().map_or(0, |(p, _)| p.n_pieces());
    Ok(RoundTripReport { kind: rep.kind(), alignment, n_vertices: n, pieces_placed, frames, total, max_distance })
}

impl fmt::Display for RoundTripReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "round trip: representation {}, {} frames × {} vertices, alignment {}{}",
            self.kind.name(),
            self.frames.len(),
            self.n_vertices,
            self.alignment,
            if self.pieces_placed > 0 { format!(", {} pieces placed", self.pieces_placed) } else { String::new() }
        )?;
        let w = self.frames.iter().map(|(n, _)| n.len()).max().unwrap_or(0).max(5);
        writeln!(f, "{:>5}  {:<w$}  {:>12}", "#", "frame", "Erms")?;
        for (i, (name, e)) in self.frames.iter().enumerate() {
            writeln!(f, "{:>5}  {:<w$}  {:>12.6e}", i, name, e)?;
        }
        writeln!(f, "{:>5}  {:<w$}  {:>12.6e}", "", "total", self.total)?;
        write!(f, "max vertex distance {:.3e} (data units)", self.max_distance)
    }
}
