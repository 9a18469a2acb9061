//! `meshdeco export <model> --out m.h5`: a trained linear model in the HDF5 layout of the SPLOCS
//! reference implementation (`sploc.py`'s two outputs in one file), so that its users' scripts
//! and viewers read meshdeco's models:
//!
//! | dataset | shape | content (the reference's name) |
//! |---|---|---|
//! | `default` | N × 3 `f64` | the neutral shape, all weights 0 (`Xmean`: the rest shape for SPLOCS, the mean for PCA) |
//! | `tris` | T × 3 `i64` | the triangles, 0-based |
//! | `comp000` … | N × 3 `f64` each | component k at weight 1: `default` + C_k (index order: column k of `weights`) |
//! | `weights` | F × K `f64` | the training frames' weights, as `weights.csv` (the reference's `--output-anim` file) |
//! | `verts` | F × N × 3 `f64` | the model's reconstruction of each training frame, `default` + Σ_k W_fk C_k |
//!
//! Coordinates are in the data's units (the reference's files are in its unit box). Only models
//! that are linear in their weights on vertex positions fit this layout: PCA, SPLOCS and region
//! PCA on the `displacement` representation; others are refused (their `.glb` holds fitted
//! blendshapes). The file is written to a temporary file, read back and compared value for value,
//! then moved into place atomically: nothing is written on failure.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::mesh::Vec3;
use crate::model::{Model, synthesize};
use crate::representation::RepresentationKind;

/// What [`export_splocs_h5`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct H5Report {
    /// Components (`comp000` …).
    pub components: usize,
    /// Training frames (rows of `weights`, frames of `verts`).
    pub frames: usize,
    /// Largest difference between `default` + Σ W·(comp − default) and the model's own decoding
    /// of the training frames, relative to the bounding-box diagonal (rounding only).
    pub blend_error: f64,
    /// Size of the file, bytes.
    pub bytes: usize,
}

/// The arrays of the layout, row-major.
struct Layout {
    n: usize,
    default: Vec<f64>,
    tris: Vec<i64>,
    comps: Vec<Vec<f64>>,
    weights: Vec<f64>,
    frames: usize,
    verts: Vec<f64>,
}

fn flat(p: &[Vec3]) -> Vec<f64> {
    p.iter().flatten().copied().collect()
}

fn layout(model: &dyn Model) -> Result<(Layout, f64)> {
    if model.representation() != RepresentationKind::Displacement || model.kind().name() == "autoencoder" {
        return Err(Error::Invalid(format!(
            "--out *.h5 (the SPLOCS reference's layout) holds components that add to vertex positions: {} on the {} representation is not one (export .glb or .html: fitted blendshapes)",
            model.kind().name(),
            model.representation().name()
        )));
    }
    let k = model.n_components();
    let rest = model.rest();
    let n = rest.n_vertices();
    let base = synthesize(model, &vec![0.0; k])?;
    let mut comps = Vec::with_capacity(k);
    let mut deltas = Vec::with_capacity(k);
    for i in 0..k {
        let mut d = vec![0.0; k];
        d[i] = 1.0;
        let shape = synthesize(model, &d)?;
        deltas.push(shape.iter().zip(&base).map(|(s, b)| crate::math::vec3::sub(*s, *b)).collect::<Vec<Vec3>>());
        comps.push(flat(&shape));
    }
    let weights = model.train_weights().ok_or_else(|| {
        Error::Invalid("--out *.h5: the model stores no training weights (the layout's `weights` and `verts`)".into())
    })?;
    for (f, w) in weights.iter().enumerate() {
        let d = model.dials(w)?;
        if d.iter().zip(w).any(|(a, b)| (a - b).abs() > 1e-12 * b.abs().max(1.0)) {
            return Err(Error::Invalid(format!(
                "--out *.h5: training frame {f}'s weights are not its synthesis dials: the {} model is not linear in its weights",
                model.kind().name()
            )));
        }
    }
    let decoded = model.decode(&weights)?;
    let (lo, hi) = rest.bounding_box();
    let diagonal = crate::mesh::dist(lo, hi).max(f64::MIN_POSITIVE);
    let mut blend_error = 0.0f64;
    for (w, dec) in weights.iter().zip(&decoded) {
        let blended = crate::export::gltf::blend(&base, &deltas, w);
        for (a, b) in blended.iter().zip(dec) {
            blend_error = blend_error.max(crate::mesh::dist(*a, *b) / diagonal);
        }
    }
    if blend_error.is_nan() || blend_error > 1e-9 {
        return Err(Error::Invalid(format!(
            "--out *.h5: the {} model's decoding is not default + Σ weights × components (largest difference {blend_error:.2e} of the diagonal): not a linear model",
            model.kind().name()
        )));
    }
    let all = |v: &[f64]| v.iter().all(|x| x.is_finite());
    let l = Layout {
        n,
        default: flat(&base),
        tris: rest.faces.iter().flatten().map(|&i| i as i64).collect(),
        comps,
        frames: weights.len(),
        weights: weights.iter().flatten().copied().collect(),
        verts: decoded.iter().flat_map(|f| flat(f)).collect(),
    };
    if !(all(&l.default) && all(&l.weights) && all(&l.verts) && l.comps.iter().all(|c| all(c))) {
        return Err(Error::Invalid("--out *.h5: the model's shapes are not finite; nothing written".into()));
    }
    Ok((l, blend_error))
}

fn h5err(path: &Path, what: &str) -> impl Fn(::hdf5::Error) -> Error {
    let p = path.display().to_string();
    let what = what.to_string();
    move |e| Error::Invalid(format!("{p}: {what}: {}", e.to_string().trim()))
}

fn write_file(path: &Path, l: &Layout) -> Result<()> {
    let f = ::hdf5::File::create(path).map_err(h5err(path, "creating the HDF5 file"))?;
    let put = |name: &str, shape: &[usize], data: &[f64]| -> Result<()> {
        let ds = f.new_dataset::<f64>().shape(shape).create(name).map_err(h5err(path, name))?;
        ds.write_raw(data).map_err(h5err(path, name))
    };
    put("default", &[l.n, 3], &l.default)?;
    let tris = f.new_dataset::<i64>().shape([l.tris.len() / 3, 3]).create("tris").map_err(h5err(path, "tris"))?;
    tris.write_raw(&l.tris).map_err(h5err(path, "tris"))?;
    for (i, c) in l.comps.iter().enumerate() {
        put(&format!("comp{i:03}"), &[l.n, 3], c)?;
    }
    put("weights", &[l.frames, l.comps.len()], &l.weights)?;
    put("verts", &[l.frames, l.n, 3], &l.verts)?;
    f.close().map_err(h5err(path, "closing"))
}

/// Reads back what [`write_file`] wrote and compares every value.
fn verify(path: &Path, l: &Layout) -> Result<()> {
    let f = crate::mesh::hdf5::open(path)?;
    let check = |name: &str, shape: &[usize], data: &[f64]| -> Result<()> {
        let ds = crate::mesh::hdf5::dataset(&f, path, name)?;
        let got: Vec<f64> = ds.read_raw().map_err(h5err(path, name))?;
        if ds.shape() != shape || got != data {
            return Err(Error::Invalid(format!("{}: dataset `{name}` does not read back as written", path.display())));
        }
        Ok(())
    };
    check("default", &[l.n, 3], &l.default)?;
    let tris: Vec<i64> =
        crate::mesh::hdf5::dataset(&f, path, "tris")?.read_raw().map_err(h5err(path, "reading back tris"))?;
    if tris != l.tris {
        return Err(Error::Invalid(format!("{}: dataset `tris` does not read back as written", path.display())));
    }
    for (i, c) in l.comps.iter().enumerate() {
        check(&format!("comp{i:03}"), &[l.n, 3], c)?;
    }
    check("weights", &[l.frames, l.comps.len()], &l.weights)?;
    check("verts", &[l.frames, l.n, 3], &l.verts)
}

/// A temporary path beside nothing the user owns (removed when dropped).
struct TempFile(PathBuf);

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Writes `model` in the SPLOCS reference's layout (module docs) to `path`, atomically.
pub fn export_splocs_h5(model: &dyn Model, path: &Path) -> Result<H5Report> {
    let (l, blend_error) = layout(model)?;
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let tmp = TempFile(std::env::temp_dir().join(format!(
        "meshdeco-export-{}-{}.h5",
        std::process::id(),
        NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    )));
    let _ = std::fs::remove_file(&tmp.0);
    write_file(&tmp.0, &l)?;
    verify(&tmp.0, &l)?;
    let bytes = std::fs::read(&tmp.0).map_err(|e| Error::io(&tmp.0, e))?;
    crate::artifact::write_atomic(path, &bytes)?;
    Ok(H5Report { components: l.comps.len(), frames: l.frames, blend_error, bytes: bytes.len() })
}
