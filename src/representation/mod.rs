//! Deformation representations shared by every method: per-element feature vectors computed
//! against a rest (reference) mesh, and their inverse back to vertex positions.
//!
//! | kind | element | width | features |
//! |---|---|---|---|
//! | `displacement` | vertex | 3 | x_f − x_rest |
//! | `triangle-gradient` | triangle | 9 | Huang et al.: log-rotation axis-angle (3) + stretch − I (6) |
//! | `acap` | vertex | 9 | Gao et al.: consistent logR (0,1),(0,2),(1,2) + S (0,0),(0,1),(0,2),(1,1),(1,2),(2,2) |
//!
//! Layout of [`Features::data`]: frame-major, then element, then the `width` numbers of the
//! element: index `(f * n_elements + e) * width + k`.
//!
//! [`Representation`] is the one entry point every method uses: built once per rest mesh (it
//! precomputes and factorises what decoding needs), it encodes a [`MeshSequence`] into
//! [`Features`] and decodes features back to vertex positions. `triangle-gradient` and `acap`
//! lose translation ([`Representation::translation_free`]): their decoders place the result's
//! centroid on the rest centroid, and errors must be measured after centroid alignment
//! ([`roundtrip`]).
//!
//! **Meshes in several pieces.** When the rest mesh has P ≥ 2 connected pieces, the
//! translation-free kinds carry where each piece sits ([`piece_placement`]): every element gets
//! three more numbers after its own W, the translation `t_p` of the piece it belongs to
//! (dimensionless, in units of the rest bounding-box diagonal), so the width is 12 instead of 9
//! ([`Representation::width`]). Decoding averages those numbers over each piece's elements and
//! moves the piece there; the round trip of a multi-piece sequence is as exact as a connected
//! one's.

pub mod acap;
pub mod acap_consistency;
pub mod acap_fit_inverse;
pub mod acap_reconstruct;
pub mod acap_text;
pub mod displacement;
pub mod feature_cache;
pub mod noise_sensitivity;
pub mod piece_placement;
pub mod roundtrip;
pub mod scaling;
pub mod triangle_gradient;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::mesh::{FrameSource, MeshSequence, Topology, TriMesh, Vec3};
use acap::{Acap, Consistency};
use displacement::Displacement;
use piece_placement::PiecePlacement;
use triangle_gradient::{NormalConvention, TriangleGradient};

/// Which mesh element carries a feature vector (and on which graph support maps live).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Element {
    /// One feature vector per vertex; neighbourhoods from the mesh's edges.
    Vertex,
    /// One feature vector per triangle; neighbourhoods from triangles sharing an edge.
    Triangle,
}

/// The representations meshdeco knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RepresentationKind {
    Displacement,
    TriangleGradient,
    Acap,
}

impl RepresentationKind {
    /// Numbers per element.
    pub fn width(self) -> usize {
        match self {
            RepresentationKind::Displacement => 3,
            RepresentationKind::TriangleGradient | RepresentationKind::Acap => 9,
        }
    }
    /// Element type.
    pub fn element(self) -> Element {
        match self {
            RepresentationKind::TriangleGradient => Element::Triangle,
            _ => Element::Vertex,
        }
    }
    /// Name as used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            RepresentationKind::Displacement => "displacement",
            RepresentationKind::TriangleGradient => "triangle-gradient",
            RepresentationKind::Acap => "acap",
        }
    }
    /// Parses a config / command-line name.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "displacement" => Some(RepresentationKind::Displacement),
            "triangle-gradient" => Some(RepresentationKind::TriangleGradient),
            "acap" => Some(RepresentationKind::Acap),
            _ => None,
        }
    }
}

/// Feature array F × E × W (see the module docs for the layout).
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    pub n_frames: usize,
    pub n_elements: usize,
    pub width: usize,
    pub data: Vec<f64>,
}

impl Features {
    /// All-zero features.
    pub fn zeros(n_frames: usize, n_elements: usize, width: usize) -> Self {
        Features { n_frames, n_elements, width, data: vec![0.0; n_frames * n_elements * width] }
    }
    /// The E·W numbers of frame `f`.
    pub fn frame(&self, f: usize) -> &[f64] {
        let s = self.n_elements * self.width;
        &self.data[f * s..(f + 1) * s]
    }
    /// Mutable E·W numbers of frame `f`.
    pub fn frame_mut(&mut self, f: usize) -> &mut [f64] {
        let s = self.n_elements * self.width;
        &mut self.data[f * s..(f + 1) * s]
    }
    /// The W numbers of element `e` in frame `f`.
    pub fn element(&self, f: usize, e: usize) -> &[f64] {
        let i = (f * self.n_elements + e) * self.width;
        &self.data[i..i + self.width]
    }
}

/// Options of [`Representation::new`] (the parts that are not implied by the kind).
#[derive(Debug, Clone, Copy)]
pub struct RepresentationOptions {
    /// ACAP rotation consistency: BFS (default, the reference's option 0) or global.
    pub acap_consistency: Consistency,
    /// Triangle-gradient stretch convention for the normal direction (default
    /// [`NormalConvention::UnitNormal`]: the rest shape encodes to zero).
    pub gradient_normal: NormalConvention,
    /// ACAP decoder (features → vertices); see [`acap::AcapDecoder`].
    pub acap_decoder: acap::AcapDecoder,
    /// What the acap kind's 9 numbers per vertex are (default logR and S); see
    /// [`acap::FeatureMap`].
    pub acap_map: acap::FeatureMap,
}

impl Default for RepresentationOptions {
    fn default() -> Self {
        RepresentationOptions {
            acap_consistency: Consistency::Bfs,
            gradient_normal: NormalConvention::UnitNormal,
            acap_decoder: acap::AcapOptions::default().decoder,
            acap_map: acap::FeatureMap::default(),
        }
    }
}

impl RepresentationOptions {
    /// The options as the text of content keys (the feature cache's): their `Debug` text without
    /// the ACAP feature map at its default, a field added later, so that keys made before it
    /// stay valid.
    pub fn key_text(&self) -> String {
        let text = format!("{self:?}");
        if self.acap_map == acap::FeatureMap::default() {
            text.replacen(", acap_map: RotationStretch", "", 1)
        } else {
            text
        }
    }
}

/// Per-kind encoder/decoder state.
enum Codec {
    Displacement(Displacement),
    TriangleGradient(Box<TriangleGradient>),
    Acap(Box<Acap>),
}

/// A representation bound to a rest mesh: encoder, decoder (factorised once) and the element
/// graph on which support maps live.
pub struct Representation {
    kind: RepresentationKind,
    options: RepresentationOptions,
    rest: TriMesh,
    codec: Codec,
    adjacency: Vec<Vec<usize>>,
    /// Translation-free kinds on a mesh with several pieces: where each piece sits, and the
    /// piece of every element (`usize::MAX`: a vertex referenced by no face).
    pieces: Option<(PiecePlacement, Vec<usize>)>,
}

impl std::fmt::Debug for Representation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Representation")
            .field("kind", &self.kind)
            .field("options", &self.options)
            .field("n_vertices", &self.rest.n_vertices())
            .field("n_faces", &self.rest.n_faces())
            .finish()
    }
}

impl Representation {
    /// Builds the representation of `kind` against `rest` (the mesh whose features are zero
    /// displacement / identity gradients). Validates the rest mesh (face indices, finite
    /// positions; for triangle-gradient no degenerate triangle) and factorises the decoder.
    pub fn new(kind: RepresentationKind, rest: &TriMesh, options: RepresentationOptions) -> Result<Self> {
        if let Some((fi, f)) = rest.first_bad_index() {
            return Err(Error::Invalid(format!(
                "rest mesh face {fi} {f:?} refers to a vertex ≥ {}",
                rest.n_vertices()
            )));
        }
        let codec = match kind {
            RepresentationKind::Displacement => Codec::Displacement(Displacement::new(&rest.positions)?),
            RepresentationKind::TriangleGradient => {
                Codec::TriangleGradient(Box::new(TriangleGradient::new(rest, options.gradient_normal)?))
            }
            RepresentationKind::Acap => Codec::Acap(Box::new(Acap::with_options(
                rest,
                acap::AcapOptions { decoder: options.acap_decoder, map: options.acap_map },
            )?)),
        };
        let topo = Topology::new(rest.n_vertices(), &rest.faces);
        let adjacency = match kind.element() {
            Element::Vertex => (0..rest.n_vertices()).map(|v| topo.neighbors(v).to_vec()).collect(),
            Element::Triangle => triangle_adjacency(&topo, rest.n_faces()),
        };
        let pieces = match kind {
            RepresentationKind::Displacement => None,
            _ => PiecePlacement::new(rest, &topo).map(|p| {
                let of_vertex = p.piece_of_vertex();
                let element_piece = match kind.element() {
                    Element::Vertex => of_vertex.to_vec(),
                    Element::Triangle => rest.faces.iter().map(|f| of_vertex[f[0]]).collect(),
                };
                (p, element_piece)
            }),
        };
        Ok(Representation { kind, options, rest: rest.clone(), codec, adjacency, pieces })
    }

    /// The kind.
    pub fn kind(&self) -> RepresentationKind {
        self.kind
    }

    /// The options it was built with.
    pub fn options(&self) -> RepresentationOptions {
        self.options
    }

    /// Element carrying the feature vectors.
    pub fn element(&self) -> Element {
        self.kind.element()
    }

    /// Numbers per element W: the kind's own ([`RepresentationKind::width`]), plus 3 (the
    /// piece's translation) for a translation-free kind on a mesh with several pieces.
    pub fn width(&self) -> usize {
        self.kind.width() + if self.pieces.is_some() { 3 } else { 0 }
    }

    /// Where each piece sits, for a translation-free kind on a mesh with several connected
    /// pieces (`None` otherwise): the placement and the piece of every element.
    pub fn pieces(&self) -> Option<(&PiecePlacement, &[usize])> {
        self.pieces.as_ref().map(|(p, e)| (p, e.as_slice()))
    }

    /// Number of elements E (vertices N or triangles T of the rest mesh).
    pub fn n_elements(&self) -> usize {
        match self.element() {
            Element::Vertex => self.rest.n_vertices(),
            Element::Triangle => self.rest.n_faces(),
        }
    }

    /// The rest mesh.
    pub fn rest(&self) -> &TriMesh {
        &self.rest
    }

    /// `true` when decoding loses translation (triangle-gradient, acap): decoded shapes have
    /// the rest centroid (each piece placed by its carried translation on a multi-piece mesh)
    /// and must be compared after centroid alignment. `false` for displacement (absolute positions).
    pub fn translation_free(&self) -> bool {
        !matches!(self.kind, RepresentationKind::Displacement)
    }

    /// Neighbourhood graph of the elements (E lists): for vertices the mesh's 1-ring (in the
    /// topology's counter-clockwise order), for triangles the triangles sharing an edge
    /// (ascending; more than 3 only at non-manifold edges).
    pub fn element_adjacency(&self) -> &[Vec<usize>] {
        &self.adjacency
    }

    /// One position per element of `mesh` (same connectivity as the rest mesh): vertex positions
    /// or triangle centroids. Errors on a vertex or face count mismatch.
    pub fn element_positions(&self, mesh: &TriMesh) -> Result<Vec<Vec3>> {
        if mesh.n_vertices() != self.rest.n_vertices() || mesh.faces != self.rest.faces {
            return Err(Error::Invalid(format!(
                "mesh ({} vertices, {} faces) does not share the rest mesh's connectivity ({} vertices, {} faces)",
                mesh.n_vertices(),
                mesh.n_faces(),
                self.rest.n_vertices(),
                self.rest.n_faces()
            )));
        }
        Ok(match self.element() {
            Element::Vertex => mesh.positions.clone(),
            Element::Triangle => mesh
                .faces
                .iter()
                .map(|f| {
                    std::array::from_fn(|k| {
                        (mesh.positions[f[0]][k] + mesh.positions[f[1]][k] + mesh.positions[f[2]][k]) / 3.0
                    })
                })
                .collect(),
        })
    }

    /// The same representation with its ACAP decoder's fit residual weighted per vertex by
    /// `weights` (N, each finite and > 0; [`acap::Acap::with_fit_weights`]). Errors for another
    /// kind or another ACAP decoder than `FitInverse`.
    pub fn with_acap_fit_weights(mut self, weights: &[f64]) -> Result<Self> {
        if self.kind != RepresentationKind::Acap
            || !matches!(self.options.acap_decoder, acap::AcapDecoder::FitInverse { .. })
        {
            return Err(Error::Invalid(format!(
                "fit weights need the acap representation with its fit-inverse decoder, not {} ({:?})",
                self.kind.name(),
                self.options.acap_decoder
            )));
        }
        let options = acap::AcapOptions { decoder: self.options.acap_decoder, map: self.options.acap_map };
        self.codec = Codec::Acap(Box::new(Acap::with_fit_weights(&self.rest, options, Some(weights))?));
        Ok(self)
    }

    /// The ACAP codec, when the kind is acap (energies, neighbourhoods, raw matrices).
    pub fn acap(&self) -> Option<&Acap> {
        match &self.codec {
            Codec::Acap(a) => Some(a.as_ref()),
            _ => None,
        }
    }

    /// The triangle-gradient codec, when the kind is triangle-gradient.
    pub fn triangle_gradient(&self) -> Option<&TriangleGradient> {
        match &self.codec {
            Codec::TriangleGradient(t) => Some(t.as_ref()),
            _ => None,
        }
    }

    /// E·W features of one frame (N vertex positions of the rest connectivity).
    pub fn encode_frame(&self, positions: &[Vec3]) -> Result<Vec<f64>> {
        if positions.len() != self.rest.n_vertices() {
            return Err(Error::Invalid(format!(
                "frame has {} vertices, the rest mesh has {}",
                positions.len(),
                self.rest.n_vertices()
            )));
        }
        let own = match &self.codec {
            Codec::Displacement(d) => d.encode_frame(positions),
            Codec::TriangleGradient(t) => t.encode_frame(positions),
            Codec::Acap(a) => a.encode_values(positions, self.options.acap_consistency),
        }?;
        let Some((placement, element_piece)) = &self.pieces else {
            return Ok(own);
        };
        let t = placement.translations(positions);
        let w0 = self.kind.width();
        let mut out = Vec::with_capacity(element_piece.len() * (w0 + 3));
        for (e, &p) in element_piece.iter().enumerate() {
            out.extend_from_slice(&own[e * w0..(e + 1) * w0]);
            out.extend_from_slice(&if p == usize::MAX { [0.0; 3] } else { t[p] });
        }
        Ok(out)
    }

    /// N vertex positions from the E·W features of one frame.
    pub fn decode_frame(&self, features: &[f64]) -> Result<Vec<Vec3>> {
        let expect = self.n_elements() * self.width();
        if features.len() != expect {
            return Err(Error::Invalid(format!(
                "{} features have {} numbers, expected {} elements × {}",
                self.kind.name(),
                features.len(),
                self.n_elements(),
                self.width()
            )));
        }
        let own_decode = |own: &[f64]| match &self.codec {
            Codec::Displacement(d) => d.decode_frame(own),
            Codec::TriangleGradient(tg) => tg.decode_frame(own),
            Codec::Acap(a) => a.decode_frame(own),
        };
        let Some((placement, _)) = &self.pieces else {
            return own_decode(features);
        };
        let mut own = Vec::with_capacity(self.n_elements() * self.kind.width());
        let t = self.split_frame(features, &mut own);
        if let Some((p, _)) = t.iter().enumerate().find(|(_, tp)| tp.iter().any(|v| !v.is_finite())) {
            return Err(Error::Invalid(format!("{} decode: non-finite translation of piece {p}", self.kind.name())));
        }
        let mut positions = own_decode(&own)?;
        placement.place(&mut positions, &t);
        Ok(positions)
    }

    /// Features F × E × W of every frame of `seq` (frames in parallel). Errors when the
    /// sequence's connectivity differs from the rest mesh's; the message names the frame.
    pub fn encode(&self, seq: &MeshSequence) -> Result<Features> {
        let all: Vec<usize> = (0..seq.n_frames()).collect();
        self.encode_selected(seq, &all)
    }

    /// Features of the frames `frames` of `seq` (0-based, in that order), written in place into
    /// one array (frames in parallel; no copy of the sequence, no second array). Errors as
    /// [`Representation::encode`]; an index out of range is an error naming it.
    pub fn encode_selected(&self, seq: &dyn FrameSource, frames: &[usize]) -> Result<Features> {
        if seq.faces() != self.rest.faces.as_slice() {
            return Err(Error::Invalid(format!(
                "sequence faces ({}) differ from the rest mesh's faces ({})",
                seq.faces().len(),
                self.rest.n_faces()
            )));
        }
        if let Some(&f) = frames.iter().find(|&&f| f >= seq.n_frames()) {
            return Err(Error::Invalid(format!("frame index {f} is out of range ({} frames)", seq.n_frames())));
        }
        let size = self.n_elements() * self.width();
        let mut out = Features::zeros(frames.len(), self.n_elements(), self.width());
        if size > 0 {
            out.data.par_chunks_mut(size).zip(frames.par_iter()).try_for_each(|(dst, &f)| -> Result<()> {
                let v = self
                    .encode_frame(&seq.frame(f)?)
                    .map_err(|e| Error::Invalid(format!("frame {f} ({}): {e}", seq.name(f))))?;
                if v.len() != size {
                    return Err(Error::Invalid(format!("frame {f}: {} features, expected {size}", v.len())));
                }
                dst.copy_from_slice(&v);
                Ok(())
            })?;
        }
        Ok(out)
    }

    /// One frame of a multi-piece representation's features (E × (W + 3) numbers): appends the
    /// kind's own E × W to `own` and returns the P piece translations, each the mean of its
    /// elements' three extra numbers. Only called when there are pieces.
    fn split_frame(&self, frame: &[f64], own: &mut Vec<f64>) -> Vec<Vec3> {
        let Some((placement, element_piece)) = &self.pieces else { return Vec::new() };
        let (w0, w) = (self.kind.width(), self.width());
        let mut t = vec![[0.0; 3]; placement.n_pieces()];
        let mut count = vec![0usize; placement.n_pieces()];
        for (e, &p) in element_piece.iter().enumerate() {
            let x = &frame[e * w..(e + 1) * w];
            own.extend_from_slice(&x[..w0]);
            if p != usize::MAX {
                count[p] += 1;
                for k in 0..3 {
                    t[p][k] += x[w0 + k];
                }
            }
        }
        t.iter().zip(&count).map(|(tp, &n)| tp.map(|v| v / n.max(1) as f64)).collect()
    }

    /// Splits features of this representation (width W + 3 on a multi-piece mesh) into the
    /// kind's own features (width W) and, per frame, the P translations `t_p` (the mean of each
    /// piece's elements' three extra numbers). Without pieces: the features and no translations.
    pub fn split_pieces(&self, features: Features) -> Result<(Features, Vec<Vec<Vec3>>)> {
        let Some((_, element_piece)) = &self.pieces else {
            return Ok((features, Vec::new()));
        };
        let (w0, w) = (self.kind.width(), self.width());
        if features.width != w
            || features.n_elements != element_piece.len()
            || features.data.len() != features.n_frames * features.n_elements * w
        {
            return Err(Error::Invalid(format!(
                "features are {} elements × {} ({} numbers for {} frames), the {} representation of this mesh has {} × {}",
                features.n_elements,
                features.width,
                features.data.len(),
                features.n_frames,
                self.kind.name(),
                element_piece.len(),
                w
            )));
        }
        let mut own = Features::zeros(0, features.n_elements, w0);
        own.n_frames = features.n_frames;
        own.data.reserve(features.n_frames * features.n_elements * w0);
        let translations = (0..features.n_frames).map(|f| self.split_frame(features.frame(f), &mut own.data)).collect();
        Ok((own, translations))
    }

    /// The inverse of [`Representation::split_pieces`]: the kind's own features (width W) and
    /// per frame the P piece translations, joined into this representation's features (every
    /// element carries its piece's translation). Without pieces `translations` must be empty.
    pub fn join_pieces(&self, own: &Features, translations: &[Vec<Vec3>]) -> Result<Features> {
        let Some((placement, element_piece)) = &self.pieces else {
            if !translations.is_empty() {
                return Err(Error::Invalid("piece translations given for a mesh in one piece".into()));
            }
            return Ok(own.clone());
        };
        let (w0, w) = (self.kind.width(), self.width());
        if own.width != w0 || own.n_elements != element_piece.len() || translations.len() != own.n_frames {
            return Err(Error::Invalid(format!(
                "joining {} frames of {} elements × {} with {} frames of piece translations; expected {} elements × {}",
                own.n_frames,
                own.n_elements,
                own.width,
                translations.len(),
                element_piece.len(),
                w0
            )));
        }
        let mut out = Features::zeros(own.n_frames, own.n_elements, w);
        for (f, t) in translations.iter().enumerate() {
            if t.len() != placement.n_pieces() {
                return Err(Error::Invalid(format!(
                    "frame {f}: {} piece translations for {} pieces",
                    t.len(),
                    placement.n_pieces()
                )));
            }
            let dst = out.frame_mut(f);
            for (e, &p) in element_piece.iter().enumerate() {
                dst[e * w..e * w + w0].copy_from_slice(own.element(f, e));
                if p != usize::MAX {
                    dst[e * w + w0..(e + 1) * w].copy_from_slice(&t[p]);
                }
            }
        }
        Ok(out)
    }

    /// Vertex positions (F × N) of every frame of `features` (frames in parallel).
    pub fn decode(&self, features: &Features) -> Result<Vec<Vec<Vec3>>> {
        if features.n_elements != self.n_elements() || features.width != self.width() {
            return Err(Error::Invalid(format!(
                "features are {} elements × {}, the {} representation has {} × {}",
                features.n_elements,
                features.width,
                self.kind.name(),
                self.n_elements(),
                self.width()
            )));
        }
        if features.data.len() != features.n_frames * features.n_elements * features.width {
            return Err(Error::Invalid(format!(
                "features hold {} numbers, expected {} frames × {} × {}",
                features.data.len(),
                features.n_frames,
                features.n_elements,
                features.width
            )));
        }
        (0..features.n_frames)
            .into_par_iter()
            .map(|f| self.decode_frame(features.frame(f)).map_err(|e| Error::Invalid(format!("frame {f}: {e}"))))
            .collect()
    }
}

/// Edge-sharing triangle neighbours, ascending per triangle.
fn triangle_adjacency(topo: &Topology, n_faces: usize) -> Vec<Vec<usize>> {
    let mut adj = vec![Vec::new(); n_faces];
    for inc in &topo.edge_faces {
        for (a, &(fa, _)) in inc.iter().enumerate() {
            for &(fb, _) in &inc[a + 1..] {
                if fa != fb {
                    adj[fa].push(fb);
                    adj[fb].push(fa);
                }
            }
        }
    }
    for l in &mut adj {
        l.sort_unstable();
        l.dedup();
    }
    adj
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> TriMesh {
        TriMesh::new(
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        )
    }

    #[test]
    fn describes_itself_and_graphs() {
        let m = tetra();
        let d = Representation::new(RepresentationKind::Displacement, &m, Default::default()).unwrap();
        assert_eq!((d.element(), d.width(), d.n_elements(), d.translation_free()), (Element::Vertex, 3, 4, false));
        for (v, nb) in d.element_adjacency().iter().enumerate() {
            let mut s = nb.clone();
            s.sort_unstable();
            let want: Vec<usize> = (0..4).filter(|&u| u != v).collect();
            assert_eq!(s, want);
        }
        let t = Representation::new(RepresentationKind::TriangleGradient, &m, Default::default()).unwrap();
        assert_eq!((t.element(), t.width(), t.n_elements(), t.translation_free()), (Element::Triangle, 9, 4, true));
        for (f, nb) in t.element_adjacency().iter().enumerate() {
            let want: Vec<usize> = (0..4).filter(|&u| u != f).collect();
            assert_eq!(nb, &want);
        }
        let c = t.element_positions(&m).unwrap();
        assert!((c[2][0] - 1.0 / 3.0).abs() < 1e-15 && (c[2][2] - 1.0 / 3.0).abs() < 1e-15);
        assert_eq!(d.element_positions(&m).unwrap(), m.positions);
    }

    #[test]
    fn sequence_encode_decode_and_mismatches() {
        let m = tetra();
        let frames: Vec<Vec<Vec3>> = (0..3)
            .map(|f| {
                m.positions
                    .iter()
                    .map(|p| [p[0] * (1.0 + 0.1 * f as f64), p[1] + 0.2 * p[2] * f as f64, p[2] + 1.0])
                    .collect()
            })
            .collect();
        let seq = MeshSequence {
            faces: m.faces.clone(),
            frames: frames.clone(),
            names: vec!["a".into(), "b".into(), "c".into()],
        };
        for kind in [RepresentationKind::Displacement, RepresentationKind::TriangleGradient] {
            let r = Representation::new(kind, &m, Default::default()).unwrap();
            let feats = r.encode(&seq).unwrap();
            assert_eq!((feats.n_frames, feats.n_elements, feats.width), (3, 4, r.width()));
            assert_eq!(feats.frame(1), &r.encode_frame(&frames[1]).unwrap()[..]);
            let back = r.decode(&feats).unwrap();
            for (b, x) in back.iter().zip(&frames) {
                let off: Vec3 = if r.translation_free() {
                    std::array::from_fn(|k| {
                        (x.iter().map(|p| p[k]).sum::<f64>() - b.iter().map(|p| p[k]).sum::<f64>()) / 4.0
                    })
                } else {
                    [0.0; 3]
                };
                for (p, q) in b.iter().zip(x) {
                    for k in 0..3 {
                        assert!((p[k] + off[k] - q[k]).abs() < 1e-12);
                    }
                }
            }
            let mut bad = seq.clone();
            bad.faces.swap(0, 1);
            assert!(r.encode(&bad).is_err());
            let mut short = feats.clone();
            short.width = 2;
            assert!(r.decode(&short).is_err());
        }
    }
    #[test]
    fn pieces_carry_their_translation() {
        // Two tetrahedra; in every frame the second one slides and turns against the first, which
        // turns the other way (rigid pieces: ACAP's decoder is exact for them on a tetrahedron,
        // whose 1-rings are too small for an exact stretch).
        let t = tetra();
        let mut positions = t.positions.clone();
        positions.extend(t.positions.iter().map(|p| [p[0] + 2.0, p[1], p[2]]));
        let mut faces = t.faces.clone();
        faces.extend(t.faces.iter().map(|f| f.map(|v| v + 4)));
        let rest = TriMesh::new(positions, faces.clone());
        let frames: Vec<Vec<Vec3>> = (0..3)
            .map(|f| {
                let (s, c) = (0.3 * f as f64).sin_cos();
                rest.positions
                    .iter()
                    .enumerate()
                    .map(|(i, p)| {
                        if i < 4 {
                            [c * p[0] + s * p[2], p[1], -s * p[0] + c * p[2] + 1.0]
                        } else {
                            [c * p[0] - s * p[1] + 0.4 * f as f64, s * p[0] + c * p[1] - 0.2 * f as f64, p[2] + 1.0]
                        }
                    })
                    .collect()
            })
            .collect();
        let seq = MeshSequence { faces, frames: frames.clone(), names: vec!["a".into(), "b".into(), "c".into()] };
        for kind in [RepresentationKind::TriangleGradient, RepresentationKind::Acap] {
            let r = Representation::new(kind, &rest, Default::default()).unwrap();
            assert_eq!(r.width(), 12);
            let (placement, element_piece) = r.pieces().unwrap();
            assert_eq!((placement.n_pieces(), element_piece.len()), (2, r.n_elements()));
            // The rest shape has zero translations.
            let rest_seq =
                MeshSequence { faces: rest.faces.clone(), frames: vec![rest.positions.clone()], names: vec![] };
            let z = r.encode(&rest_seq).unwrap();
            assert!((0..r.n_elements()).all(|e| z.element(0, e)[9..].iter().all(|v| v.abs() < 1e-15)));
            let feats = r.encode(&seq).unwrap();
            let (own, t) = r.split_pieces(feats.clone()).unwrap();
            assert_eq!((own.width, t.len(), t[0].len()), (9, 3, 2));
            assert_eq!(r.join_pieces(&own, &t).unwrap(), feats);
            assert!(t.iter().all(|tf| tf[placement.anchor()] == [0.0; 3]));
            let back = r.decode(&feats).unwrap();
            for (b, x) in back.iter().zip(&frames) {
                let off: Vec3 = std::array::from_fn(|k| {
                    (x.iter().map(|p| p[k]).sum::<f64>() - b.iter().map(|p| p[k]).sum::<f64>()) / 8.0
                });
                for (p, q) in b.iter().zip(x) {
                    assert!((0..3).all(|k| (p[k] + off[k] - q[k]).abs() < 1e-9), "{kind:?}: {p:?} vs {q:?}");
                }
            }
        }
        // A frame with two coincident vertices (a zero-length edge) still encodes and decodes to
        // finite positions.
        let mut collapsed = frames[1].clone();
        collapsed[5] = collapsed[4];
        for kind in [RepresentationKind::TriangleGradient, RepresentationKind::Acap] {
            let r = Representation::new(kind, &rest, Default::default()).unwrap();
            let back = r.decode_frame(&r.encode_frame(&collapsed).unwrap()).unwrap();
            assert!(back.iter().flatten().all(|v| v.is_finite()), "{kind:?}");
        }
        // Displacement is absolute: no pieces to carry.
        let d = Representation::new(RepresentationKind::Displacement, &rest, Default::default()).unwrap();
        assert!(d.pieces().is_none() && d.width() == 3);
    }
}
