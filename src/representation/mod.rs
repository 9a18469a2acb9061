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

use serde::{Deserialize, Serialize};

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

pub mod acap;
pub mod acap_consistency;
pub mod acap_fit_inverse;
pub mod acap_reconstruct;
pub mod acap_rotation;
pub mod acap_text;
