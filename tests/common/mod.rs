//! Helpers shared by the integration tests (`mod common;` in each test file).
//!
//! `shared_or_skip` is the one way a test reaches the external references in `../shared`
//! (real datasets, the ACAP reference fixtures). In CI (`CI` set in the environment) a missing
//! path is a failure: `../shared` is always beside the clone there. Locally a missing path skips
//! the test with a reason on stderr and a line in [`skip_log`], which `.ci/run` and
//! `scripts/skipped` count at the end of a run (`cargo test` hides a passing test's output).
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};

/// `../shared` beside the repository.
/// `[method]` lines that give an autoencoder the paper's training settings where meshdeco's
/// default differs (issues 31 and 53): for tests whose numbers were measured with them. A block that
/// also sets `learning_rate` must set `learning_rate_final` to it (constant rate) itself. With
/// them, the min/max scaling and the earlier default encoder (one vertex step).
#[allow(dead_code)]
pub const PAPER_AE_KEYS: &str = "scaling = \"per-dimension\"\nscaling_quantile = 0.0\nlearning_rate_norm = 0.0\n\
     beta2 = 0.999\nlambda1 = 0.5\naugment = 0\nlambda_orthogonal = 0.0\nencoder_passes = 0\nencoder_steps = 1\nstall_restarts = 0\n\
     init_bias = \"zero\"\nfeature_weights = \"uniform\"\nsupport = [0.2, 0.4]\ndecoder_edge_weight = 1e-6\ndecoder_noise_power = 0\n";

pub fn shared_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared")
}

/// The file that records skipped tests, one line per skip: `<test>\t<missing path>`.
/// `$CARGO_TARGET_DIR/tmp/meshdeco-skipped-tests.txt` (Cargo's scratch folder for integration
/// tests); `.ci/run` and `scripts/skipped` read it.
pub fn skip_log() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("meshdeco-skipped-tests.txt")
}

/// `../shared/<rel>` when it exists. Otherwise: panics when `CI` is set (naming the path), else
/// prints the reason, records the skip and returns `None`.
pub fn shared_or_skip(rel: &str) -> Option<PathBuf> {
    let p = shared_root().join(rel);
    if p.exists() {
        return Some(p);
    }
    let test = std::thread::current().name().unwrap_or("?").to_string();
    if std::env::var_os("CI").is_some() {
        panic!("CI is set but the external reference {} is missing (needed by {test})", p.display());
    }
    eprintln!("SKIPPED {test}: {} is absent", p.display());
    record_skip(&p.display().to_string());
    None
}

/// Records a local skip of the running test in [`skip_log`] (`missing`: what was absent — a
/// path, a program), so that `.ci/run` and `scripts/skipped` count it. Callers fail instead when
/// `CI` is set.
pub fn record_skip(missing: &str) {
    let test = std::thread::current().name().unwrap_or("?").to_string();
    let log = skip_log();
    if let Some(dir) = log.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    if let Ok(mut f) = std::fs::OpenOptions::new().create(true).append(true).open(&log) {
        let _ = writeln!(f, "{}\t{test}\t{missing}", env!("CARGO_CRATE_NAME"));
    }
}

/// Erms (data units × 1000, `metrics::erms`) of one constant shape standing in for every frame:
/// the baseline a model that learns nothing reaches (the rest shape: all weights zero; the
/// mean shape: PCA with no component).
pub fn constant_shape_erms(
    frames: &[Vec<meshdeco::mesh::Vec3>],
    shape: &[meshdeco::mesh::Vec3],
    alignment: meshdeco::metrics::erms::Alignment,
) -> f64 {
    let result: Vec<Vec<meshdeco::mesh::Vec3>> = frames.iter().map(|_| shape.to_vec()).collect();
    meshdeco::metrics::erms::erms(frames, &result, alignment).unwrap()
}

/// The per-vertex mean of `frames`.
pub fn mean_shape(frames: &[Vec<meshdeco::mesh::Vec3>]) -> Vec<meshdeco::mesh::Vec3> {
    let n = frames.len() as f64;
    (0..frames[0].len()).map(|v| std::array::from_fn(|c| frames.iter().map(|f| f[v][c]).sum::<f64>() / n)).collect()
}

/// The vertex positions of an OBJ file, in file order (meshdeco's reader).
pub fn obj_vertices(path: &Path) -> Vec<meshdeco::mesh::Vec3> {
    meshdeco::mesh::load_mesh(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).positions
}

/// One named vertex property of an ASCII PLY, in vertex order.
pub fn ply_vertex_property(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (header, body) = text.split_once("end_header\n").expect("PLY header");
    let mut n = 0;
    let mut props = Vec::new();
    let mut in_vertex = false;
    for l in header.lines() {
        let f: Vec<&str> = l.split_whitespace().collect();
        match f.as_slice() {
            ["element", "vertex", c] => {
                n = c.parse().unwrap();
                in_vertex = true;
            }
            ["element", ..] => in_vertex = false,
            ["property", _, p] if in_vertex => props.push(p.to_string()),
            _ => {}
        }
    }
    let col =
        props.iter().position(|p| p == name).unwrap_or_else(|| panic!("{}: no vertex property {name}", path.display()));
    body.lines().take(n).map(|l| l.split_whitespace().nth(col).unwrap().parse().unwrap()).collect()
}

/// Runs the `meshdeco` binary in `cwd`.
pub fn meshdeco(args: &[&str], cwd: &Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_meshdeco"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run meshdeco")
}

/// (width, height, share of pixels that differ from the top-left (background) pixel, number of
/// distinct colours) of a PNG: a plot or picture that drew nothing has share 0 and one colour.
pub fn png_ink(path: &Path) -> (u32, u32, f64, usize) {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgb8();
    let bg = *img.get_pixel(0, 0);
    let ink = img.pixels().filter(|p| **p != bg).count();
    let colours: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    (img.width(), img.height(), ink as f64 / (img.width() * img.height()) as f64, colours.len())
}

/// A fresh, empty directory `<temp>/meshdeco-<prefix>-<tag>-<pid>` (removed first if present).
pub fn fresh_dir(prefix: &str, tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("meshdeco-{prefix}-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A command's stdout followed by its stderr, as text.
pub fn output_text(o: &std::process::Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// A regular grid of `nx × ny` vertices in the unit square (positions, triangles), two triangles
/// per cell split along the same diagonal — the small mesh of the autoencoder tests.
pub fn unit_grid(nx: usize, ny: usize) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let mut p = Vec::new();
    for y in 0..ny {
        for x in 0..nx {
            p.push([x as f64 / (nx - 1) as f64, y as f64 / (ny - 1) as f64, 0.0]);
        }
    }
    let mut f = Vec::new();
    for y in 0..ny - 1 {
        for x in 0..nx - 1 {
            let v = y * nx + x;
            f.push([v, v + 1, v + nx + 1]);
            f.push([v, v + nx + 1, v + nx]);
        }
    }
    (p, f)
}

/// Rest positions, faces, ACAP-like features (F × N × 9) and the two planted centres.
pub type PlantedBumps = (Vec<[f64; 3]>, Vec<[usize; 3]>, meshdeco::representation::Features, [usize; 2]);

/// `frames` shapes on the [`unit_grid`] `nx × ny`: two localized bumps (around vertices `c1`,
/// `c2`, Gaussian of width 0.12, each with its own 9-number pattern) whose amplitudes, drawn
/// from the generator seeded with `seed`, vary independently across the shapes; every feature
/// clamped to [−0.95, 0.95].
pub fn planted_bumps(nx: usize, ny: usize, frames: usize, seed: u64) -> PlantedBumps {
    let (p, f) = unit_grid(nx, ny);
    let n = p.len();
    let c1 = (ny / 4) * nx + nx / 4;
    let c2 = (3 * ny / 4) * nx + 3 * nx / 4;
    let mut rng = meshdeco::nn::rng::Rng::new(seed);
    let mut feat = meshdeco::representation::Features::zeros(frames, n, 9);
    for s in 0..frames {
        let a1 = rng.uniform() * 1.6 - 0.8;
        let a2 = rng.uniform() * 1.6 - 0.8;
        for i in 0..n {
            let d1 = meshdeco::mesh::dist(p[i], p[c1]);
            let d2 = meshdeco::mesh::dist(p[i], p[c2]);
            let b1 = (-(d1 * d1) / (2.0 * 0.12f64.powi(2))).exp();
            let b2 = (-(d2 * d2) / (2.0 * 0.12f64.powi(2))).exp();
            for c in 0..9 {
                let pat1 = [0.9, -0.5, 0.3, 0.7, -0.2, 0.1, 0.4, -0.6, 0.2][c];
                let pat2 = [-0.3, 0.8, 0.5, -0.1, 0.6, -0.7, 0.2, 0.3, -0.4][c];
                feat.data[(s * n + i) * 9 + c] = (a1 * b1 * pat1 + a2 * b2 * pat2).clamp(-0.95, 0.95);
            }
        }
    }
    (p, f, feat, [c1, c2])
}

/// The three.js release the export checks load (`npm install three@…`).
pub const THREE_SPEC: &str = "three@0.170.0";

/// `<target tmp>/<dir>/node_modules/<package>` of the npm package `spec`, installed on first use;
/// `None` (with the reason printed) where Node or npm is absent or the install fails. In CI (`CI`
/// set) either is an error, since `.ci/run` installs Node.
pub fn npm_package(dir: &str, package: &str, spec: &str) -> Option<PathBuf> {
    let node = std::process::Command::new("node").arg("--version").output();
    if node.as_ref().map_or(true, |o| !o.status.success()) {
        assert!(std::env::var_os("CI").is_none(), "CI: node is missing (.ci/run installs nodejs)");
        eprintln!("SKIP {package}: `node` not found");
        record_skip("node (Node.js)");
        return None;
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(dir);
    let installed = dir.join("node_modules").join(package);
    if !installed.join("package.json").is_file() {
        std::fs::create_dir_all(&dir).unwrap();
        let o = std::process::Command::new("npm")
            .args(["install", "--no-audit", "--no-fund", "--silent", spec])
            .current_dir(&dir)
            .output();
        match o {
            Ok(o) if o.status.success() => {}
            other => {
                assert!(std::env::var_os("CI").is_none(), "CI: npm install {spec} failed: {other:?}");
                eprintln!("SKIP {package}: npm install failed: {other:?}");
                record_skip(&format!("npm package {spec}"));
                return None;
            }
        }
    }
    Some(installed)
}

/// [`train_cli`] on the synthetic tube, every second frame: a model in about a second.
pub fn train_tube(d: &Path, name: &str, method: &str) -> PathBuf {
    train_cli(d, name, "path = \"synthetic:tube\"\ntrain = \"every:2\"", method)
}

/// A Python that can `import <imports>` (comma-separated): `$<env>`, else the venv
/// `<target tmp>/<venv>` that `.ci/run` makes; `None` (with the reason printed and the skip
/// recorded) when neither can. With `CI` set a missing one fails the test.
pub fn python_with(env: &str, venv: &str, imports: &str) -> Option<PathBuf> {
    let candidates = [
        std::env::var_os(env).map(PathBuf::from),
        Some(PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(venv).join("bin/python")),
    ];
    for p in candidates.into_iter().flatten() {
        let ok = std::process::Command::new(&p)
            .args(["-c", &format!("import {imports}")])
            .output()
            .is_ok_and(|o| o.status.success());
        if ok {
            return Some(p);
        }
    }
    let missing =
        format!("python with {imports} (${env} or {}/{venv}; .ci/run installs it)", env!("CARGO_TARGET_TMPDIR"));
    assert!(std::env::var_os("CI").is_none(), "CI: no {missing}");
    eprintln!("SKIPPED: no {missing}");
    record_skip(&format!("python with {imports}"));
    None
}

/// The rows of a model's `weights.csv` (header skipped, the frame name dropped).
pub fn weights_csv(model: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(model.join("weights.csv")).unwrap();
    text.lines().skip(1).map(|l| l.split(',').skip(1).map(|x| x.trim().parse().unwrap()).collect()).collect()
}

/// Trains `method` on `data` (the lines of a `[data]` table) with `meshdeco train`, as a user
/// runs it, into `d/<name>` (config `d/<name>.toml`); panics with the command's output on failure.
pub fn train_cli(d: &Path, name: &str, data: &str, method: &str) -> PathBuf {
    let cfg = d.join(format!("{name}.toml"));
    std::fs::write(&cfg, format!("name = \"{name}\"\n[data]\n{data}\n[method]\n{method}\n")).unwrap();
    let out = d.join(name);
    let o = meshdeco(&["train", "--config", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()], d);
    assert!(o.status.success(), "{name}: {}", output_text(&o));
    out
}

/// A checking script's stdout, one JSON value per line (the scripts under `tests/js`,
/// `tests/python`); panics on a line that is not JSON.
pub fn json_lines(o: &std::process::Output) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect()
}
