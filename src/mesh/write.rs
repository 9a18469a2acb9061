//! Mesh writers (OBJ, ASCII PLY with per-vertex colours and a scalar, OFF) and a colour map for
//! heat maps.
//!
//! Every writer is atomic ([`crate::artifact::write_atomic_with`]): it writes a temporary file
//! unique to the process ([`crate::artifact::temp_path`]) in the same directory, flushes it to
//! disk and renames it over `path`, so a reader never sees a half-written file. Nothing
//! non-finite is written: a non-finite coordinate or scalar, a face index out of range or a
//! colour/scalar array of the wrong length is an error and leaves `path` untouched. Coordinates
//! are written in Rust's shortest round-trip form, so reading a written file gives back the exact
//! `f64` values.

use std::io::Write;
use std::path::Path;

use super::TriMesh;
use crate::artifact::write_atomic_with;
use crate::error::{Error, Result};

/// Writes `mesh` as Wavefront OBJ (`v x y z` lines, then `f a b c` with 1-based indices).
pub fn write_obj(path: &Path, mesh: &TriMesh) -> Result<()> {
    check_mesh(path, mesh)?;
    write_atomic_with(path, |w| emit_obj(w, mesh))
}

/// The OBJ text [`write_obj`] writes, in memory (e.g. a download); `what` names it in errors.
pub fn obj_bytes(what: &str, mesh: &TriMesh) -> Result<Vec<u8>> {
    check_mesh(Path::new(what), mesh)?;
    let mut out = Vec::new();
    emit_obj(&mut out, mesh).map_err(|e| Error::Invalid(format!("{what}: {e}")))?;
    Ok(out)
}

fn emit_obj(w: &mut impl Write, mesh: &TriMesh) -> std::io::Result<()> {
    writeln!(w, "# meshdeco: {} vertices, {} faces", mesh.n_vertices(), mesh.n_faces())?;
    for p in &mesh.positions {
        writeln!(w, "v {:?} {:?} {:?}", p[0], p[1], p[2])?;
    }
    for f in &mesh.faces {
        writeln!(w, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
    }
    Ok(())
}

/// Writes `mesh` as ASCII OFF (0-based indices).
pub fn write_off(path: &Path, mesh: &TriMesh) -> Result<()> {
    check_mesh(path, mesh)?;
    write_atomic_with(path, |w| {
        writeln!(w, "OFF\n{} {} 0", mesh.n_vertices(), mesh.n_faces())?;
        for p in &mesh.positions {
            writeln!(w, "{:?} {:?} {:?}", p[0], p[1], p[2])?;
        }
        for f in &mesh.faces {
            writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
        }
        Ok(())
    })
}

/// Writes `mesh` as ASCII PLY.
///
/// Vertex properties: `double x, y, z` (exact round trip), then, when `colors` is given,
/// `uchar red, green, blue` (one colour per vertex, e.g. from [`colormap`]), then, when `scalars`
/// is given as `(name, values)`, one `float <name>` property (one value per vertex; `name` must be
/// a non-empty identifier of ASCII letters, digits and `_`, and not a name already used). Faces
/// are `list uchar int vertex_indices` with 0-based indices.
pub fn write_ply(
    path: &Path,
    mesh: &TriMesh,
    colors: Option<&[[u8; 3]]>,
    scalars: Option<(&str, &[f64])>,
) -> Result<()> {
    check_mesh(path, mesh)?;
    let n = mesh.n_vertices();
    let target = path.display();
    if let Some(c) = colors
        && c.len() != n
    {
        return Err(Error::Invalid(format!("{target}: {} colours given for {n} vertices", c.len())));
    }
    if let Some((name, values)) = scalars {
        let valid_name = !name.is_empty()
            && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
            && !["x", "y", "z", "red", "green", "blue"].contains(&name);
        if !valid_name {
            return Err(Error::Invalid(format!(
                "{target}: scalar property name '{name}' must be a new identifier of ASCII letters, digits and '_'"
            )));
        }
        if values.len() != n {
            return Err(Error::Invalid(format!("{target}: {} '{name}' values given for {n} vertices", values.len())));
        }
        if let Some(i) = values.iter().position(|v| !(v.is_finite() && v.abs() <= f32::MAX as f64)) {
            return Err(Error::Invalid(format!(
                "{target}: '{name}' value {} at vertex {i} is not a finite single-precision number; nothing written",
                values[i]
            )));
        }
    }
    write_atomic_with(path, |w| emit_ply(w, mesh, colors, scalars))
}

/// The PLY text [`write_ply`] writes (no colours, no scalar), in memory; `what` names it in errors.
pub fn ply_bytes(what: &str, mesh: &TriMesh) -> Result<Vec<u8>> {
    check_mesh(Path::new(what), mesh)?;
    let mut out = Vec::new();
    emit_ply(&mut out, mesh, None, None).map_err(|e| Error::Invalid(format!("{what}: {e}")))?;
    Ok(out)
}

fn emit_ply(
    w: &mut impl Write,
    mesh: &TriMesh,
    colors: Option<&[[u8; 3]]>,
    scalars: Option<(&str, &[f64])>,
) -> std::io::Result<()> {
    let n = mesh.n_vertices();
    writeln!(w, "ply\nformat ascii 1.0\ncomment written by meshdeco")?;
    writeln!(w, "element vertex {n}\nproperty double x\nproperty double y\nproperty double z")?;
    if colors.is_some() {
        writeln!(w, "property uchar red\nproperty uchar green\nproperty uchar blue")?;
    }
    if let Some((name, _)) = scalars {
        writeln!(w, "property float {name}")?;
    }
    writeln!(w, "element face {}\nproperty list uchar int vertex_indices\nend_header", mesh.n_faces())?;
    for (i, p) in mesh.positions.iter().enumerate() {
        write!(w, "{:?} {:?} {:?}", p[0], p[1], p[2])?;
        if let Some(c) = colors {
            write!(w, " {} {} {}", c[i][0], c[i][1], c[i][2])?;
        }
        if let Some((_, s)) = scalars {
            write!(w, " {:?}", s[i] as f32)?;
        }
        writeln!(w)?;
    }
    for f in &mesh.faces {
        writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
    }
    Ok(())
}

/// Maps values linearly onto a perceptually uniform blue → green → yellow colour ramp (a
/// viridis-like map: dark blue-violet at the minimum, yellow at the maximum) over the values'
/// own finite `min..max`. See [`colormap_range`] for a fixed range (e.g. one scale across frames).
pub fn colormap(values: &[f64]) -> Vec<[u8; 3]> {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    colormap_range(values, lo, hi)
}

/// Like [`colormap`] over the fixed range `lo..hi`: values are clamped to it; when the range is
/// empty (`hi <= lo`, all values equal) every finite value gets the minimum colour. Non-finite
/// values are drawn mid grey `[128, 128, 128]`, so missing data stays visible.
pub fn colormap_range(values: &[f64], lo: f64, hi: f64) -> Vec<[u8; 3]> {
    // Anchor colours of the ramp at t = 0, 1/8, …, 1 (sRGB), interpolated linearly.
    const RAMP: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 122.0],
        [59.0, 81.0, 139.0],
        [44.0, 113.0, 142.0],
        [33.0, 144.0, 141.0],
        [39.0, 173.0, 129.0],
        [92.0, 200.0, 99.0],
        [170.0, 220.0, 50.0],
        [253.0, 231.0, 37.0],
    ];
    let span = hi - lo;
    values
        .iter()
        .map(|&v| {
            if !v.is_finite() {
                return [128, 128, 128];
            }
            let t = if span > 0.0 && span.is_finite() { ((v - lo) / span).clamp(0.0, 1.0) } else { 0.0 };
            let x = t * (RAMP.len() - 1) as f64;
            let k = (x.floor() as usize).min(RAMP.len() - 2);
            let a = x - k as f64;
            let mix = |c: usize| (RAMP[k][c] * (1.0 - a) + RAMP[k + 1][c] * a).round() as u8;
            [mix(0), mix(1), mix(2)]
        })
        .collect()
}

/// Checks what every writer needs: finite coordinates and face indices in range.
fn check_mesh(path: &Path, mesh: &TriMesh) -> Result<()> {
    if let Some((i, p)) = mesh.positions.iter().enumerate().find(|(_, p)| p.iter().any(|c| !c.is_finite())) {
        return Err(Error::Invalid(format!(
            "{}: vertex {i} has a non-finite coordinate {p:?}; nothing written",
            path.display()
        )));
    }
    if let Some((i, f)) = mesh.first_bad_index() {
        return Err(Error::Invalid(format!(
            "{}: face {i} {f:?} refers to a vertex ≥ {} (the mesh's vertex count); nothing written",
            path.display(),
            mesh.n_vertices()
        )));
    }
    Ok(())
}

/// Writes `mesh` in the format its extension names: `.obj`, `.ply` (no colours) or `.off`
/// (case-insensitive); any other extension is an error naming the path.
pub fn write_mesh(path: &Path, mesh: &TriMesh) -> Result<()> {
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("ply") => write_ply(path, mesh, None, None),
        Some("off") => write_off(path, mesh),
        Some("obj") => write_obj(path, mesh),
        _ => Err(Error::Invalid(format!("{}: unknown output format (use .obj, .ply or .off)", path.display()))),
    }
}

#[cfg(test)]
mod tests {
    use super::super::load::read_mesh;
    use super::*;
    use crate::mesh::load::test_dir;

    /// A tetrahedron with awkward coordinates (no short decimal form, tiny and huge magnitudes).
    fn tetra() -> TriMesh {
        TriMesh::new(
            vec![[0.1, 1.0 / 3.0, -2e-9], [std::f64::consts::PI, -0.0, 7.25e12], [1.0, 2.0, 3.0], [-5e-300, 0.5, 1e-7]],
            vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        )
    }

    #[test]
    fn round_trips_are_exact() {
        let d = test_dir("write-rt");
        let m = tetra();
        for name in ["a.obj", "a.ply", "a.off"] {
            let p = d.join(name);
            match name {
                "a.obj" => write_obj(&p, &m).unwrap(),
                "a.ply" => write_ply(&p, &m, None, None).unwrap(),
                _ => write_off(&p, &m).unwrap(),
            }
            let back = read_mesh(&p).unwrap();
            assert_eq!(back.mesh, m, "{name}");
            assert!(back.warnings.is_empty(), "{name}: {:?}", back.warnings);
            assert!(!d.join(format!("{name}.tmp")).exists());
        }
        // PLY with colours and a scalar still reads back the same geometry, and the header
        // declares the extra properties.
        let p = d.join("heat.ply");
        let values = [0.0, 1.0, 2.0, 3.5];
        let colors = colormap(&values);
        write_ply(&p, &m, Some(&colors), Some(("dist", &values))).unwrap();
        assert_eq!(read_mesh(&p).unwrap().mesh, m);
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.contains("property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float dist\n"));
        let last_vertex = text.lines().nth(17).unwrap();
        assert!(
            last_vertex.ends_with(&format!(" {} {} {} 3.5", colors[3][0], colors[3][1], colors[3][2])),
            "{last_vertex}"
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn refuses_bad_input_and_leaves_target_untouched() {
        let d = test_dir("write-bad");
        let p = d.join("m.obj");
        std::fs::write(&p, "old").unwrap();
        let mut m = tetra();
        m.positions[2][1] = f64::NAN;
        let e = write_obj(&p, &m).unwrap_err().to_string();
        assert!(e.contains("m.obj") && e.contains("vertex 2") && e.contains("non-finite"), "{e}");
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old");
        let mut m = tetra();
        m.faces[1][2] = 4;
        assert!(write_off(&d.join("m.off"), &m).unwrap_err().to_string().contains("face 1"));
        let m = tetra();
        let q = d.join("m.ply");
        assert!(write_ply(&q, &m, Some(&[[0, 0, 0]; 3]), None).is_err());
        assert!(write_ply(&q, &m, None, Some(("d", &[0.0; 3]))).is_err());
        assert!(write_ply(&q, &m, None, Some(("bad name", &[0.0; 4]))).is_err());
        assert!(write_ply(&q, &m, None, Some(("x", &[0.0; 4]))).is_err());
        let e = write_ply(&q, &m, None, Some(("d", &[0.0, f64::INFINITY, 0.0, 0.0]))).unwrap_err().to_string();
        assert!(e.contains("vertex 1"), "{e}");
        assert!(!q.exists());
        // A missing directory is an I/O error naming the target; no temp file remains.
        let e = write_obj(&d.join("nodir/m.obj"), &m).unwrap_err().to_string();
        assert!(e.contains("nodir/m.obj"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn colormap_spans_the_ramp_monotonically() {
        let values: Vec<f64> = (0..=100).map(|i| 5.0 + i as f64 * 0.1).collect();
        let c = colormap(&values);
        assert_eq!(c[0], [68, 1, 84]);
        assert_eq!(c[100], [253, 231, 37]);
        // Lightness proxy (sum of channels weighted like luma) increases along the ramp.
        let luma = |c: [u8; 3]| 0.299 * c[0] as f64 + 0.587 * c[1] as f64 + 0.114 * c[2] as f64;
        for k in 1..c.len() {
            assert!(luma(c[k]) >= luma(c[k - 1]) - 1.0, "luma drops at {k}: {:?} -> {:?}", c[k - 1], c[k]);
        }
        assert_eq!(colormap(&[2.0, 2.0]), vec![[68, 1, 84]; 2]);
        assert_eq!(colormap(&[f64::NAN, 0.0, 1.0])[0], [128, 128, 128]);
        assert_eq!(colormap_range(&[-1.0, 0.5, 9.0], 0.0, 1.0)[2], [253, 231, 37]);
        assert_eq!(colormap_range(&[-1.0], 0.0, 1.0)[0], [68, 1, 84]);
    }

    #[test]
    fn bytes_match_files_and_write_mesh_picks_the_format() {
        let d = test_dir("write-bytes");
        let m = tetra();
        write_obj(&d.join("a.obj"), &m).unwrap();
        write_ply(&d.join("a.ply"), &m, None, None).unwrap();
        assert_eq!(obj_bytes("a.obj", &m).unwrap(), std::fs::read(d.join("a.obj")).unwrap());
        assert_eq!(ply_bytes("a.ply", &m).unwrap(), std::fs::read(d.join("a.ply")).unwrap());
        for name in ["b.PLY", "b.off", "b.obj"] {
            let p = d.join(name);
            write_mesh(&p, &m).unwrap();
            assert_eq!(read_mesh(&p).unwrap().mesh, m, "{name}");
        }
        assert!(write_mesh(&d.join("b.stl"), &m).is_err());
        // Finite but too large for f32: refused.
        let e = write_ply(&d.join("big.ply"), &m, None, Some(("d", &[0.0, 1e39, 0.0, 0.0]))).unwrap_err().to_string();
        assert!(e.contains("vertex 1"), "{e}");
        // A range other than 0..1 is scaled: t = 0.25 and 0.5 hit ramp anchors 2 and 4.
        assert_eq!(colormap_range(&[0.5, 1.0], 0.0, 2.0), vec![[59, 81, 139], [33, 144, 141]]);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
