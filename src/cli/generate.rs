//! `meshdeco generate`: a large NumPy sequence blended from a small one, for benchmarks and
//! tests of big datasets (`synthetic::Blend`).
//!
//! All or nothing, never an input: the output and its template are written beside their places
//! under temporary names and renamed into them only when both are complete (a failure leaves
//! neither, nor a temporary file); neither may be the other, a frame of the source, or a new
//! mesh file where the source would read it as a frame (paths compared with every link and
//! `..` resolved); the template is written in the format its extension names (.obj, .ply,
//! .off), any other name is refused before anything is written.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::mesh::{MeshFormat, TriMesh};
use meshdeco::pipeline::Progress;

use super::progress::Bars;

#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// Source frames: a mesh directory, a glob (`dir/*.obj`), or `synthetic:<name>`.
    pub from: String,
    /// Number of frames to write (1 ..= 10 000 000).
    #[arg(long)]
    pub frames: usize,
    /// Output `.npy` (F × N × 3, float32, C order).
    #[arg(long)]
    pub out: PathBuf,
    /// Template mesh (the source's first frame) written for `data.template`, as OBJ, PLY or OFF
    /// by its extension; default: OUT with the extension `.obj`.
    #[arg(long)]
    pub template: Option<PathBuf>,
    /// Seed of the blend weights and perturbations (frame f depends only on seed and f).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

pub fn run(a: GenerateArgs) -> Result<()> {
    if !a.out.to_string_lossy().to_ascii_lowercase().ends_with(".npy") {
        bail!("--out {}: the output is a NumPy .npy file; name it *.npy", a.out.display());
    }
    let (template, flag) = match &a.template {
        Some(t) => (t.clone(), "--template".to_string()),
        None => (a.out.with_extension("obj"), format!("--template (by default --out {} as .obj)", a.out.display())),
    };
    let Some(format) = MeshFormat::from_path(&template) else {
        bail!(
            "{flag} {}: the template is written as .obj, .ply or .off, as its extension says; name it so",
            template.display()
        );
    };
    let out = resolved(&a.out).with_context(|| format!("--out {}", a.out.display()))?;
    let tpl = resolved(&template).with_context(|| format!("{flag} {}", template.display()))?;
    if out == tpl {
        bail!("{flag} {}: the same file as --out {} ({})", template.display(), a.out.display(), out.display());
    }
    if !meshdeco::synthetic::is_synthetic(&a.from) {
        let frames = source_frames(&a.from)?;
        for (what, path, real) in [("--out".to_string(), &a.out, &out), (flag.clone(), &template, &tpl)] {
            if frames.files.contains(real) {
                bail!(
                    "{what} {}: a frame of the source {} ({}); generate never writes over its input",
                    path.display(),
                    a.from,
                    real.display()
                );
            }
        }
        if frames.would_read(&tpl) {
            bail!(
                "{flag} {}: a mesh file where the source {} would read it as one more frame; write it elsewhere",
                template.display(),
                a.from
            );
        }
    }
    let source = meshdeco::preprocess::load_frames(&a.from).with_context(|| format!("reading {}", a.from))?;
    let rest = TriMesh::new(source.frames[0].clone(), source.faces.clone());
    // Both files under temporary names beside their places (removed on any failure), the small
    // template first: a template that cannot be written costs no frames.
    let mut temps = Temporaries(Vec::new());
    let tpl_tmp = temps.add(&tpl);
    match format {
        MeshFormat::Obj => meshdeco::mesh::write_obj(&tpl_tmp, &rest),
        MeshFormat::Ply => meshdeco::mesh::write_ply(&tpl_tmp, &rest, None, None),
        MeshFormat::Off => meshdeco::mesh::write_off(&tpl_tmp, &rest),
    }
    .with_context(|| format!("writing the template {}", template.display()))?;
    let out_tmp = temps.add(&out);
    let mut bars = Bars::new();
    bars.stage("generate", a.frames as u64);
    meshdeco::synthetic::write_blend_npy(&source, a.frames, a.seed, &out_tmp, &mut |done| {
        bars.step(done as u64, "frames written")
    })
    .with_context(|| format!("writing {}", a.out.display()))?;
    bars.finish_stage();
    let bytes = std::fs::metadata(&out_tmp).map(|m| m.len()).unwrap_or(0);
    std::fs::rename(&tpl_tmp, &tpl).with_context(|| format!("{flag} {}", template.display()))?;
    std::fs::rename(&out_tmp, &out).with_context(|| format!("--out {}", a.out.display()))?;
    temps.0.clear();
    outln!(
        "wrote {} ({} frames × {} vertices, float32, {:.1} MB) and {} (the template: data.template)",
        a.out.display(),
        a.frames,
        rest.n_vertices(),
        bytes as f64 / 1e6,
        template.display()
    );
    Ok(())
}

/// `path` with every symbolic link and `..` resolved; a path that does not exist yet is its
/// folder resolved with its name appended (the folder must exist).
fn resolved(path: &Path) -> Result<PathBuf> {
    if let Ok(p) = std::fs::canonicalize(path) {
        return Ok(p);
    }
    let Some(name) = path.file_name() else { bail!("names no file") };
    let folder = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let real = std::fs::canonicalize(folder).with_context(|| format!("the folder {}", folder.display()))?;
    Ok(real.join(name))
}

/// The mesh files a source path reads (resolved), and where it looks for them: its folder and,
/// for a glob, the file-name pattern.
struct SourceFrames {
    files: Vec<PathBuf>,
    folder: Option<PathBuf>,
    pattern: Option<String>,
}

fn source_frames(spec: &str) -> Result<SourceFrames> {
    let files = meshdeco::mesh::sequence::resolve_spec(spec).with_context(|| format!("reading {spec}"))?;
    let files = files.iter().map(|f| resolved(f)).collect::<Result<Vec<_>>>()?;
    let path = Path::new(spec);
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let (folder, pattern) = if name.contains(['*', '?']) {
        (Some(resolved(&path.parent().unwrap_or(Path::new("")).join("."))?), Some(name.to_string()))
    } else if path.is_dir() {
        (Some(resolved(path)?), None)
    } else {
        (None, None)
    };
    Ok(SourceFrames { files, folder, pattern })
}

impl SourceFrames {
    /// Whether a mesh file at `file` (resolved) would be read as a frame of the source.
    fn would_read(&self, file: &Path) -> bool {
        let Some(folder) = &self.folder else { return false };
        let name = file.file_name().and_then(|n| n.to_str()).unwrap_or("");
        file.parent() == Some(folder.as_path())
            && match &self.pattern {
                Some(p) => meshdeco::mesh::sequence::glob_match(p, name),
                None => !name.starts_with('.'),
            }
    }
}

/// Temporary files removed when dropped (unless taken out of the list).
struct Temporaries(Vec<PathBuf>);

impl Temporaries {
    /// A temporary name beside `path` ([`meshdeco::artifact::temp_path`]), removed on drop.
    fn add(&mut self, path: &Path) -> PathBuf {
        let t = meshdeco::artifact::temp_path(path);
        self.0.push(t.clone());
        t
    }
}

impl Drop for Temporaries {
    fn drop(&mut self) {
        for t in &self.0 {
            let _ = std::fs::remove_file(t);
        }
    }
}
