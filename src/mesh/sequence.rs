//! Loading a mesh sequence (one mesh file per frame) from a directory, a glob pattern or a single
//! file, with natural sorting and validation that every frame shares the first frame's
//! connectivity.
//!
//! A `spec` is
//! - a directory: every regular file in it (not recursive, names starting with `.` skipped) whose
//!   extension is `.obj`, `.ply` or `.off` (case-insensitive);
//! - a pattern whose file-name part contains `*` (any run of characters, possibly empty) or `?`
//!   (exactly one character), e.g. `../shared/data/scape/*.obj` or `frames/pose_??.ply`; the
//!   directory part must be literal. Matching is case-sensitive, `*` and `?` do not match a
//!   leading `.`, and only files with a supported extension are taken;
//! - a single mesh file: a sequence of one frame.
//!
//! Files are ordered by [`natural_cmp`] on their names (`2.obj` before `10.obj`) and read in
//! parallel. Frame names are the file stems.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::load::{MESH_EXTENSIONS, MeshFormat, read_mesh};
use super::{MeshSequence, TriMesh};
use crate::error::{Error, Result};

/// A sequence together with the files it came from and the readers' warnings.
#[derive(Debug, Clone)]
pub struct LoadedSequence {
    /// The frames, sharing the first frame's faces.
    pub sequence: MeshSequence,
    /// One file per frame, in frame order.
    pub files: Vec<PathBuf>,
    /// Reader warnings (e.g. polygons triangulated). A warning that occurs identically in several
    /// frames is listed once, naming the first such file and how many other frames share it.
    pub warnings: Vec<String>,
}

/// Loads a sequence (see the module docs for `spec`) and validates it. Reader warnings and
/// connectivity problems found by [`super::inspect::problem_warnings`] (degenerate faces,
/// non-manifold edges, unreferenced vertices, several components, inconsistent orientation) are
/// printed to standard error as `warning: …` lines; use [`read_sequence`] and
/// [`super::inspect::inspect`] to receive them instead.
///
/// Errors name the file concerned: unreadable or malformed file, a frame whose vertex count or
/// face list differs from the first frame (with the first differing face), and no mesh file at all
/// (naming the directory or pattern).
pub fn load_sequence(spec: &str) -> Result<MeshSequence> {
    let loaded = read_sequence(spec)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let topology = super::Topology::new(loaded.sequence.n_vertices(), &loaded.sequence.faces);
    for w in super::inspect::problem_warnings(&loaded.sequence, &topology) {
        eprintln!("warning: {spec}: {w}");
    }
    Ok(loaded.sequence)
}

/// Loads and validates a sequence without printing anything; see [`load_sequence`].
pub fn read_sequence(spec: &str) -> Result<LoadedSequence> {
    crate::timing::timed("load meshes", || read_sequence_untimed(spec))
}

fn read_sequence_untimed(spec: &str) -> Result<LoadedSequence> {
    if let Some((file, _)) = super::hdf5::split_spec(spec) {
        let sequence = super::hdf5::load_spec(spec)?;
        let files = vec![PathBuf::from(file); sequence.n_frames()];
        return Ok(LoadedSequence { sequence, files, warnings: Vec::new() });
    }
    let files = resolve_spec(spec)?;
    let loaded: Vec<Result<super::LoadedMesh>> = files.par_iter().map(|p| read_mesh(p)).collect();
    let mut meshes = Vec::with_capacity(files.len());
    let mut per_file_warnings = Vec::with_capacity(files.len());
    for result in loaded {
        let m = result?;
        meshes.push(m.mesh);
        per_file_warnings.push(m.warnings);
    }
    let warnings = merge_warnings(&files, &per_file_warnings);
    let sequence = sequence_from_meshes(&files, meshes)?;
    Ok(LoadedSequence { sequence, files, warnings })
}

/// Builds a sequence from meshes read from `files` (one file per mesh), checking that every
/// frame has the first frame's vertex count and exactly its face list. Names are the file stems.
pub fn sequence_from_meshes(files: &[PathBuf], meshes: Vec<TriMesh>) -> Result<MeshSequence> {
    if files.len() != meshes.len() {
        return Err(Error::Invalid(format!("{} files given for {} meshes", files.len(), meshes.len())));
    }
    let Some(first) = meshes.first() else {
        return Err(Error::Invalid("a sequence needs at least one frame".into()));
    };
    let (n, faces) = (first.n_vertices(), first.faces.clone());
    for (file, m) in files.iter().zip(&meshes).skip(1) {
        same_connectivity(file, m, &files[0], n, &faces)?;
    }
    let names =
        files.iter().map(|f| f.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()).collect();
    let frames = meshes.into_iter().map(|m| m.positions).collect();
    Ok(MeshSequence { faces, frames, names })
}

/// `Ok` when `m` (read from `file`) has `n` vertices and exactly the face list `faces` of the
/// first frame `first_file`; otherwise an error naming `file` (and the first differing face).
fn same_connectivity(file: &Path, m: &TriMesh, first_file: &Path, n: usize, faces: &[[usize; 3]]) -> Result<()> {
    let first_file = first_file.display();
    if m.n_vertices() != n {
        return Err(Error::Mismatch {
            path: file.to_path_buf(),
            message: format!("{} vertices, but the first frame {first_file} has {n}", m.n_vertices()),
        });
    }
    if m.faces != faces {
        let first_diff = m.faces.iter().zip(faces).position(|(a, b)| a != b);
        let mut message = if m.faces.len() != faces.len() {
            format!("{} faces, but the first frame {first_file} has {}", m.faces.len(), faces.len())
        } else {
            let n_diff = m.faces.iter().zip(faces).filter(|(a, b)| a != b).count();
            format!("face list differs from the first frame {first_file} in {n_diff} of {} faces", faces.len())
        };
        if let Some(i) = first_diff {
            message += &format!(
                "; first difference at face {i} (0-based): {:?} here, {:?} in the first frame",
                m.faces[i], faces[i]
            );
        }
        return Err(Error::Mismatch { path: file.to_path_buf(), message });
    }
    Ok(())
}

/// The mesh files of a sequence `spec` (see the module docs) opened to read one frame at a
/// time, in any order: a folder too large to hold stays on disk. The first file is read when
/// opened (its faces are the sequence's); every frame read is checked against it like
/// [`read_sequence`] checks (vertex count, face list), and the readers' own checks apply.
#[derive(Debug)]
pub struct MeshFiles {
    files: Vec<PathBuf>,
    faces: Vec<[usize; 3]>,
    n_vertices: usize,
}

impl MeshFiles {
    /// Resolves `spec` and reads its first file. Errors as [`read_sequence`].
    pub fn open(spec: &str) -> Result<Self> {
        let files = resolve_spec(spec)?;
        let first = read_mesh(&files[0])?.mesh;
        Ok(MeshFiles { n_vertices: first.n_vertices(), faces: first.faces, files })
    }
    /// Number of frames F (files).
    pub fn n_frames(&self) -> usize {
        self.files.len()
    }
    /// Number of vertices N of every frame.
    pub fn n_vertices(&self) -> usize {
        self.n_vertices
    }
    /// The faces of the first frame (every frame's).
    pub fn faces(&self) -> &[[usize; 3]] {
        &self.faces
    }
    /// The frames' names: the file stems, as [`read_sequence`] gives them.
    pub fn names(&self) -> Vec<String> {
        self.files.iter().map(|f| f.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()).collect()
    }
    /// Frame `f` (0-based) with the reader's warnings; errors name the file.
    pub fn read_frame(&self, f: usize) -> Result<(Vec<super::Vec3>, Vec<String>)> {
        let file = self
            .files
            .get(f)
            .ok_or_else(|| Error::Invalid(format!("frame index {f} is out of range ({} frames)", self.files.len())))?;
        let m = read_mesh(file)?;
        same_connectivity(file, &m.mesh, &self.files[0], self.n_vertices, &self.faces)?;
        Ok((m.mesh.positions, m.warnings))
    }
    /// Merges per-frame reader warnings as [`read_sequence`] does (`per_file`: one list per file).
    pub fn merge_warnings(&self, per_file: &[Vec<String>]) -> Vec<String> {
        merge_warnings(&self.files, per_file)
    }
}

/// `Ok` when `meta` (of `path`) is a regular file; otherwise the readers' one error, e.g.
/// "x.npy: not a regular file (a FIFO)" (a FIFO would block, `/dev/zero` never end).
pub fn require_regular(path: &Path, meta: &std::fs::Metadata) -> Result<()> {
    if meta.is_file() {
        return Ok(());
    }
    Err(Error::Invalid(format!("{}: not a regular file ({})", path.display(), file_kind(meta))))
}

/// What a non-regular file is, in words (FIFO, device, socket, …).
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

/// The mesh files a `spec` stands for, in natural order (see the module docs). Errors: a
/// directory that cannot be listed, a path that does not exist, wildcards outside the file-name
/// part, and no matching mesh file (naming the directory or pattern).
pub fn resolve_spec(spec: &str) -> Result<Vec<PathBuf>> {
    let path = Path::new(spec);
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let is_glob = name.contains(['*', '?']);
    if !is_glob && spec.contains(['*', '?']) {
        return Err(Error::Invalid(format!("{spec}: wildcards are only supported in the file-name part of a pattern")));
    }
    let (dir, pattern) = if is_glob {
        let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if parent.to_string_lossy().contains(['*', '?']) {
            return Err(Error::Invalid(format!(
                "{spec}: wildcards are only supported in the file-name part of a pattern"
            )));
        }
        (parent.to_path_buf(), Some(name))
    } else if path.is_dir() {
        (path.to_path_buf(), None)
    } else if path.is_file() {
        return Ok(vec![path.to_path_buf()]);
    } else if let Ok(meta) = std::fs::metadata(path) {
        return Err(Error::Invalid(format!("{spec}: not a regular file or directory ({})", file_kind(&meta))));
    } else {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or directory")));
    };

    let entries = std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut found: Vec<(String, PathBuf)> = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(&dir, e))?;
        let Ok(file_name) = entry.file_name().into_string() else { continue };
        if file_name.starts_with('.') && !pattern.is_some_and(|p| p.starts_with('.')) {
            continue;
        }
        if pattern.is_some_and(|p| !glob_match(p, &file_name)) {
            continue;
        }
        let p = entry.path();
        if MeshFormat::from_path(&p).is_some() && p.is_file() {
            found.push((file_name, p));
        }
    }
    if found.is_empty() {
        let exts = MESH_EXTENSIONS.map(|e| format!(".{e}")).join(", ");
        let (where_, what) = match pattern {
            Some(_) => (PathBuf::from(spec), format!("no mesh files ({exts}) match this pattern: zero frames")),
            None => (dir, format!("no mesh files ({exts}) in this directory: zero frames")),
        };
        return Err(Error::io(where_, std::io::Error::new(std::io::ErrorKind::NotFound, what)));
    }
    found.sort_by(|a, b| natural_cmp(&a.0, &b.0));
    Ok(found.into_iter().map(|(_, p)| p).collect())
}

/// Natural order of file names: runs of ASCII digits compare by numeric value (`2` < `10`,
/// `0001` < `0002`, `cactus2` < `cactus10`), other characters compare case-insensitively; names
/// that are equal under these rules (`01` vs `1`, `A` vs `a`) fall back on byte order so that the
/// order is total.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut x, mut y) = (a.as_bytes(), b.as_bytes());
    loop {
        match (x.first(), y.first()) {
            (None, None) => return a.cmp(b),
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(c), Some(d)) if c.is_ascii_digit() && d.is_ascii_digit() => {
                let run = |s: &[u8]| s.iter().take_while(|b| b.is_ascii_digit()).count();
                let (lx, ly) = (run(x), run(y));
                let strip = |s: &[u8]| {
                    let z = s.iter().take_while(|&&b| b == b'0').count();
                    s[z..].to_vec()
                };
                let (nx, ny) = (strip(&x[..lx]), strip(&y[..ly]));
                let ord = nx.len().cmp(&ny.len()).then_with(|| nx.cmp(&ny));
                if ord != Ordering::Equal {
                    return ord;
                }
                x = &x[lx..];
                y = &y[ly..];
            }
            (Some(c), Some(d)) => {
                let ord = c.to_ascii_lowercase().cmp(&d.to_ascii_lowercase());
                if ord != Ordering::Equal {
                    return ord;
                }
                x = &x[1..];
                y = &y[1..];
            }
        }
    }
}

/// Whether `name` matches the wildcard `pattern`: `*` matches any run of characters (also
/// none), `?` exactly one character, everything else itself (case-sensitive).
pub fn glob_match(pattern: &str, name: &str) -> bool {
    let p: Vec<char> = pattern.chars().collect();
    let n: Vec<char> = name.chars().collect();
    let (mut pi, mut ni) = (0, 0);
    // Position after the last `*` seen and the name position it currently absorbs up to.
    let mut backtrack: Option<(usize, usize)> = None;
    while ni < n.len() {
        if pi < p.len() && p[pi] == '*' {
            backtrack = Some((pi + 1, ni));
            pi += 1;
        } else if pi < p.len() && (p[pi] == '?' || p[pi] == n[ni]) {
            pi += 1;
            ni += 1;
        } else if let Some((bp, bn)) = backtrack {
            // Let the last `*` absorb one more character and retry.
            pi = bp;
            ni = bn + 1;
            backtrack = Some((bp, bn + 1));
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|&c| c == '*')
}

/// Merges per-file warnings: a warning that reads the same (once its file name is removed) in
/// several frames is listed once, with the number of other frames that share it.
fn merge_warnings(files: &[PathBuf], per_file: &[Vec<String>]) -> Vec<String> {
    let mut merged: Vec<(String, String, usize)> = Vec::new(); // (key, first message, others)
    for (file, warnings) in files.iter().zip(per_file) {
        let name = file.display().to_string();
        for w in warnings {
            let key = w.replacen(&name, "", 1);
            match merged.iter_mut().find(|m| m.0 == key) {
                Some(m) => m.2 += 1,
                None => merged.push((key, w.clone(), 0)),
            }
        }
    }
    merged
        .into_iter()
        .map(|(_, w, others)| match others {
            0 => w,
            k => format!("{w} (and the same in {k} other frame{})", if k == 1 { "" } else { "s" }),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::load::test_dir;

    #[test]
    fn natural_order_examples() {
        let mut v =
            vec!["10.obj", "2.obj", "1.obj", "cactus10.ply", "cactus2.ply", "cactus0.ply", "0002.obj", "0001.obj"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            v,
            vec!["0001.obj", "1.obj", "0002.obj", "2.obj", "10.obj", "cactus0.ply", "cactus2.ply", "cactus10.ply"]
        );
        assert_eq!(natural_cmp("2.obj", "10.obj"), Ordering::Less);
        assert_eq!(natural_cmp("Smile", "neutral"), Ordering::Greater);
        assert_eq!(natural_cmp("a2b10", "a2b9"), Ordering::Greater);
        assert_eq!(natural_cmp("frame", "frame1"), Ordering::Less);
        // Ties under the rules are broken by bytes, so the order is total and antisymmetric.
        assert_eq!(natural_cmp("01", "1"), Ordering::Less);
        assert_eq!(natural_cmp("1", "01"), Ordering::Greater);
        assert_eq!(natural_cmp("x", "x"), Ordering::Equal);
        // Numbers longer than any integer type still compare.
        assert_eq!(natural_cmp("f123456789012345678901234567890", "f99"), Ordering::Greater);
    }

    #[test]
    fn glob_matching() {
        assert!(glob_match("*.obj", "10.obj"));
        assert!(glob_match("*.obj", ".obj"));
        assert!(!glob_match("*.obj", "10.ply"));
        assert!(glob_match("pose_??.ply", "pose_07.ply"));
        assert!(!glob_match("pose_??.ply", "pose_7.ply"));
        assert!(glob_match("c*s*1*", "cactus10.ply"));
        assert!(!glob_match("c*s*1*x", "cactus10.ply"));
        assert!(glob_match("*", "anything"));
        assert!(glob_match("a*b*c", "abbbbc"));
        assert!(!glob_match("a*b*c", "abbbbcd"));
        assert!(glob_match("**a", "bba"));
        assert!(glob_match("é?.obj", "éx.obj"));
        assert!(!glob_match("A.obj", "a.obj"));
        assert!(!glob_match("", "a"));
        assert!(glob_match("", ""));
    }

    const TRI: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n";
    /// One quad, split into two triangles with a warning.
    const QUAD: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";

    #[test]
    fn directory_glob_and_file_specs() {
        let d = test_dir("seq-spec");
        for name in ["10.obj", "2.OBJ", "1.obj", "notes.txt", ".hidden.obj", "3.off"] {
            let body =
                if name.ends_with(".off") { "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 1\n3 0 1 2\n3 1 3 2\n" } else { TRI };
            std::fs::write(d.join(name), body).unwrap();
        }
        std::fs::create_dir(d.join("sub.obj")).unwrap();
        let s = read_sequence(d.to_str().unwrap()).unwrap();
        assert_eq!(s.sequence.names, vec!["1", "2", "3", "10"]);
        assert_eq!(s.sequence.frames[2][3], [1.0, 1.0, 1.0]);
        assert!(s.warnings.is_empty());
        let s = read_sequence(d.join("*.obj").to_str().unwrap()).unwrap();
        assert_eq!(s.sequence.names, vec!["1", "10"]);
        let s = read_sequence(d.join("?.*").to_str().unwrap()).unwrap();
        assert_eq!(s.sequence.names, vec!["1", "2", "3"]);
        let s = read_sequence(d.join("10.obj").to_str().unwrap()).unwrap();
        assert_eq!(s.sequence.n_frames(), 1);
        let e = read_sequence(d.join("*.ply").to_str().unwrap()).unwrap_err().to_string();
        assert!(e.contains("*.ply") && e.contains("zero frames"), "{e}");
        let e = read_sequence(d.join("*/x.obj").to_str().unwrap()).unwrap_err().to_string();
        assert!(e.contains("wildcards"), "{e}");
        let e = read_sequence(d.join("missing").to_str().unwrap()).unwrap_err().to_string();
        assert!(e.contains("missing"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn mismatching_frames_are_named() {
        let d = test_dir("seq-mismatch");
        std::fs::write(d.join("1.obj"), TRI).unwrap();
        std::fs::write(d.join("2.obj"), TRI.replace("f 2 4 3", "f 2 3 4")).unwrap();
        let e = read_sequence(d.to_str().unwrap()).unwrap_err().to_string();
        assert!(e.starts_with(&format!("{}:", d.join("2.obj").display())), "{e}");
        assert!(e.contains("1 of 2 faces") && e.contains("face 1 (0-based): [1, 2, 3] here, [1, 3, 2]"), "{e}");
        std::fs::write(d.join("2.obj"), format!("{TRI}v 2 2 2\n")).unwrap();
        let e = read_sequence(d.to_str().unwrap()).unwrap_err().to_string();
        assert!(e.contains("2.obj: 5 vertices, but the first frame") && e.contains("has 4"), "{e}");
        std::fs::write(d.join("2.obj"), format!("{TRI}f 1 2 4\n")).unwrap();
        let e = read_sequence(d.to_str().unwrap()).unwrap_err().to_string();
        assert!(e.contains("2.obj: 3 faces, but the first frame") && e.contains("has 2"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn repeated_warnings_are_merged() {
        let d = test_dir("seq-warn");
        for name in ["a.obj", "b.obj", "c.obj"] {
            std::fs::write(d.join(name), QUAD).unwrap();
        }
        let s = read_sequence(d.to_str().unwrap()).unwrap();
        assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
        assert!(
            s.warnings[0].contains("a.obj:5: 1 polygon") && s.warnings[0].ends_with("(and the same in 2 other frames)")
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn mismatch_counts_only_the_differing_faces() {
        let d = test_dir("seq-ndiff");
        let three = format!("{TRI}f 1 2 4\n");
        std::fs::write(d.join("1.obj"), &three).unwrap();
        std::fs::write(d.join("2.obj"), three.replace("f 1 2 4", "f 1 4 2")).unwrap();
        let e = read_sequence(d.to_str().unwrap()).unwrap_err().to_string();
        assert!(e.contains("in 1 of 3 faces") && e.contains("face 2 (0-based): [0, 3, 1] here, [0, 1, 3]"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn mesh_files_read_one_frame_at_a_time() {
        let d = test_dir("seq-files");
        for name in ["10.obj", "2.obj", "1.obj"] {
            let body = if name == "10.obj" { QUAD.replace("v 1 1 0", "v 1 1 5") } else { QUAD.to_string() };
            std::fs::write(d.join(name), body).unwrap();
        }
        let files = MeshFiles::open(d.to_str().unwrap()).unwrap();
        assert_eq!((files.n_frames(), files.n_vertices()), (3, 4));
        assert_eq!(files.faces(), &[[0, 1, 2], [0, 2, 3]][..]);
        assert_eq!(files.names(), vec!["1", "2", "10"]);
        let (p, w) = files.read_frame(2).unwrap();
        assert_eq!(p, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 5.0], [0.0, 1.0, 0.0]]);
        assert!(w.len() == 1 && w[0].contains("10.obj:5: 1 polygon"), "{w:?}");
        let per_file: Vec<Vec<String>> = (0..3).map(|f| files.read_frame(f).unwrap().1).collect();
        let merged = files.merge_warnings(&per_file);
        assert_eq!(merged.len(), 1, "{merged:?}");
        assert!(merged[0].contains("1.obj:5: 1 polygon") && merged[0].ends_with("(and the same in 2 other frames)"));
        let e = files.read_frame(3).unwrap_err().to_string();
        assert!(e.contains("frame index 3 is out of range (3 frames)"), "{e}");
        std::fs::write(d.join("2.obj"), format!("{QUAD}v 2 2 2\n")).unwrap();
        let e = files.read_frame(1).unwrap_err().to_string();
        assert!(e.contains("2.obj: 5 vertices, but the first frame"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
