//! Linear decomposition methods over a data matrix X of F rows (frames) and E·W columns
//! (E elements, W numbers per element): holistic PCA ([`pca`]) and SPLOCS ([`splocs`]), both
//! producing a [`LinearModel`] (components C: K × E·W, weights W: F × K, offset: E·W).
//!
//! Layout of a data matrix: row-major, row `f` holds frame `f`; inside a row, element `e`
//! occupies columns `e·W .. e·W + W`. This is exactly the frame-major layout of
//! [`crate::representation::Features`], so features are passed without copying through
//! [`DataMatrix::from_features`]. The W numbers of one element form one *group* (SPLOCS
//! regularises the group's Euclidean length): W = 3 for vertex displacements, W = 9 for
//! triangle deformation gradients or ACAP features.
//!
//! Spatial locality (SPLOCS) needs distances on the mesh; they come from a
//! [`SupportDistances`] provider so that the methods stay independent of how geodesics are
//! computed (heat method, Dijkstra, Euclidean, per triangle...).

pub mod linear_model;
pub mod pca;
pub mod posing;
pub mod region_pca;
pub mod segmentation;
pub mod sparse_dials;
pub mod splocs;
mod splocs_admm;
pub mod support_map;

pub use linear_model::{Encoder, LinearModel, WeightConstraint};
pub use pca::{Pca, PcaCentering, PcaConfig};
pub use splocs::{AdmmConfig, SplocsConfig, SplocsFit, SplocsSolver};
pub use support_map::{ComponentLocality, SupportDistances, TriangleSupport};

use crate::representation::Features;
use crate::{Error, Result};

/// A borrowed data matrix X: `n_rows` × (`n_elements` · `width`), row-major (see the module
/// docs). Construction checks the length and that every value is finite.
#[derive(Debug, Clone, Copy)]
pub struct DataMatrix<'a> {
    data: &'a [f64],
    n_rows: usize,
    n_elements: usize,
    width: usize,
}

impl<'a> DataMatrix<'a> {
    /// Wraps `data` (length `n_rows · n_elements · width`, row-major). Errors on a length
    /// mismatch, on an empty matrix, or on a non-finite value (reporting its row and column).
    pub fn new(data: &'a [f64], n_rows: usize, n_elements: usize, width: usize) -> Result<Self> {
        check_matrix(data, n_rows, n_elements, width)?;
        Ok(DataMatrix { data, n_rows, n_elements, width })
    }

    /// Borrows a feature array (F × E × W, frame-major) as a data matrix.
    pub fn from_features(features: &'a Features) -> Result<Self> {
        Self::new(&features.data, features.n_frames, features.n_elements, features.width)
    }

    /// All values, row-major.
    pub fn data(&self) -> &'a [f64] {
        self.data
    }
    /// Number of rows F (frames).
    pub fn n_rows(&self) -> usize {
        self.n_rows
    }
    /// Number of elements E (vertices or triangles).
    pub fn n_elements(&self) -> usize {
        self.n_elements
    }
    /// Group width W (numbers per element).
    pub fn width(&self) -> usize {
        self.width
    }
    /// Number of columns E·W.
    pub fn n_cols(&self) -> usize {
        self.n_elements * self.width
    }
    /// Row `f` (E·W numbers).
    pub fn row(&self, f: usize) -> &'a [f64] {
        let c = self.n_cols();
        &self.data[f * c..(f + 1) * c]
    }
}

/// The checks of a data matrix's construction ([`DataMatrix::new`], [`CompactMatrix::new`]):
/// non-empty, `n_rows · n_elements · width` values, every value finite (the error names its row
/// and column).
fn check_matrix<T: Copy + Into<f64> + std::fmt::Display>(
    data: &[T],
    n_rows: usize,
    n_elements: usize,
    width: usize,
) -> Result<()> {
    if n_rows == 0 || n_elements == 0 || width == 0 {
        return Err(Error::Invalid(format!(
            "data matrix must be non-empty (rows {n_rows}, elements {n_elements}, width {width})"
        )));
    }
    let expected = n_rows * n_elements * width;
    if data.len() != expected {
        return Err(Error::Invalid(format!(
            "data matrix has {} values, expected rows {n_rows} × elements {n_elements} × width {width} = {expected}",
            data.len()
        )));
    }
    let cols = n_elements * width;
    if let Some(i) = data.iter().position(|&v| !v.into().is_finite()) {
        return Err(Error::Invalid(format!(
            "data matrix value at row {}, column {} is not finite ({})",
            i / cols,
            i % cols,
            data[i]
        )));
    }
    Ok(())
}

/// A data matrix held in `f32` (row-major, the layout of [`DataMatrix`]): for data sets whose
/// `f64` matrix would not fit beside everything else (issue 28: 20 000 frames × 15 783 columns
/// is 2.5 GB in `f64`, 1.26 GB here). Values are rounded to `f32` once, when stored; every
/// product over it is computed in `f64` from blocks converted back ([`DataRef::read_rows`],
/// [`DataRef::read_cols`]). Construction checks the length and that every value is finite.
#[derive(Debug, Clone)]
pub struct CompactMatrix {
    data: Vec<f32>,
    n_rows: usize,
    n_elements: usize,
    width: usize,
}

impl CompactMatrix {
    /// Wraps `data` (row-major `n_rows` × `n_elements · width`); errors as [`DataMatrix::new`].
    pub fn new(data: Vec<f32>, n_rows: usize, n_elements: usize, width: usize) -> Result<Self> {
        check_matrix(&data, n_rows, n_elements, width)?;
        Ok(CompactMatrix { data, n_rows, n_elements, width })
    }
    /// All values, row-major.
    pub fn data(&self) -> &[f32] {
        &self.data
    }
}

/// A data matrix in either precision: what the linear methods that can work on large data
/// (PCA's randomized SVD, SPLOCS) read. Rows and column blocks come out in `f64`.
#[derive(Debug, Clone, Copy)]
pub enum DataRef<'a> {
    /// Held in `f64` (every data set that fits: the exact path).
    F64(DataMatrix<'a>),
    /// Held in `f32` ([`CompactMatrix`]).
    F32(&'a CompactMatrix),
}

impl DataRef<'_> {
    /// Number of rows F.
    pub fn n_rows(&self) -> usize {
        match self {
            DataRef::F64(x) => x.n_rows(),
            DataRef::F32(x) => x.n_rows,
        }
    }
    /// Number of elements E.
    pub fn n_elements(&self) -> usize {
        match self {
            DataRef::F64(x) => x.n_elements(),
            DataRef::F32(x) => x.n_elements,
        }
    }
    /// Group width W.
    pub fn width(&self) -> usize {
        match self {
            DataRef::F64(x) => x.width(),
            DataRef::F32(x) => x.width,
        }
    }
    /// Number of columns E·W.
    pub fn n_cols(&self) -> usize {
        self.n_elements() * self.width()
    }
    /// Rows `start .. start + count` into `out` (row-major, `count · n_cols` numbers).
    ///
    /// # Panics
    /// If the rows are out of range or `out` has the wrong length (caller bugs).
    pub fn read_rows(&self, start: usize, count: usize, out: &mut [f64]) {
        let c = self.n_cols();
        let r = start * c..(start + count) * c;
        match self {
            DataRef::F64(x) => out.copy_from_slice(&x.data()[r]),
            DataRef::F32(x) => out.iter_mut().zip(&x.data[r]).for_each(|(o, &v)| *o = f64::from(v)),
        }
    }
    /// Columns `cols` of every row into `out` (row-major F × `cols.len()`).
    ///
    /// # Panics
    /// If the columns are out of range or `out` has the wrong length (caller bugs).
    pub fn read_cols(&self, cols: std::ops::Range<usize>, out: &mut [f64]) {
        let (c, nc) = (self.n_cols(), cols.len());
        for (row, o) in out.chunks_exact_mut(nc).enumerate() {
            let r = row * c + cols.start..row * c + cols.end;
            match self {
                DataRef::F64(x) => o.copy_from_slice(&x.data()[r]),
                DataRef::F32(x) => o.iter_mut().zip(&x.data[r]).for_each(|(o, &v)| *o = f64::from(v)),
            }
        }
    }
}

impl<'a> From<DataMatrix<'a>> for DataRef<'a> {
    fn from(x: DataMatrix<'a>) -> Self {
        DataRef::F64(x)
    }
}

impl<'a> From<&'a CompactMatrix> for DataRef<'a> {
    fn from(x: &'a CompactMatrix) -> Self {
        DataRef::F32(x)
    }
}
