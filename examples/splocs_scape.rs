//! SPLOCS (K 50, λ 2, support [0.1, 0.7], 10 iterations, nonnegative weights) on SCAPE and the
//! horse gallop from `../shared/data`, with the reference's preprocessing choices: rest shape =
//! first frame, data = vertex displacements in the data's own units, support distances on the
//! rest mesh scaled into the unit box (largest bounding-box side 1).
//!
//! Prints the SPLOCS wall time (excluding loading), the train Erms in the data's units,
//! holistic PCA's Erms for comparison, and per-component locality (share of energy inside the
//! support region d < d_max, support size).
//!
//! Distances: a stand-in for heat geodesics — Dijkstra along mesh edges (graph distance, an
//! over-estimate of the geodesic distance of a few percent) — until `geometry::heat_geodesics`
//! is merged.
//!
//! ```text
//! cargo run --release --example splocs_scape -- [scape|horse|all] [--align] [--threads N]
//!     [--iterations N] [--signed] [--per-component]
//! ```
//! `--align` rigidly aligns every frame to the first (Kabsch) before decomposing; Erms is then
//! measured against the aligned frames.

use std::cell::Cell;
use std::path::Path;
use std::time::{Duration, Instant};

use meshdeco::Result;
use meshdeco::geometry::graph_distance::EdgeGraph;
use meshdeco::geometry::rigid_align::kabsch;
use meshdeco::methods::support_map::SupportDistances;
use meshdeco::methods::{DataMatrix, Pca, PcaConfig, SplocsConfig, SplocsSolver, WeightConstraint};

type V3 = [f64; 3];

/// Faces and per-frame positions of every OBJ in `dir`, in natural order.
fn load_folder(dir: &Path) -> (Vec<[usize; 3]>, Vec<Vec<V3>>) {
    let spec = format!("{}/*.obj", dir.display());
    let seq = meshdeco::mesh::load_sequence(&spec).unwrap_or_else(|e| panic!("{spec}: {e}"));
    (seq.faces, seq.frames)
}

/// Dijkstra along mesh edges (the library's [`EdgeGraph`]); counts the time spent.
struct GraphDistances {
    graph: EdgeGraph,
    time: Cell<Duration>,
}

impl GraphDistances {
    fn new(pos: Vec<V3>, faces: &[[usize; 3]]) -> Self {
        GraphDistances { graph: EdgeGraph::new(&pos, faces), time: Cell::new(Duration::ZERO) }
    }
}

impl SupportDistances for GraphDistances {
    fn n_elements(&self) -> usize {
        self.graph.n_vertices()
    }
    fn distances(&self, centers: &[usize]) -> Result<Vec<f64>> {
        let t0 = Instant::now();
        let mut d = self.graph.distances(centers);
        // unreachable vertices (other connected components) are "far"
        for v in &mut d {
            if !v.is_finite() {
                *v = 1e9;
            }
        }
        self.time.set(self.time.get() + t0.elapsed());
        Ok(d)
    }
}

/// Process CPU time (user + system, all threads) in seconds from /proc (Linux; NaN elsewhere).
/// Reported beside the wall time because the machine is shared: under load the wall time
/// includes waiting for a core.
fn cpu_seconds() -> f64 {
    let Ok(s) = std::fs::read_to_string("/proc/self/stat") else { return f64::NAN };
    let fields: Vec<&str> = s.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let tick = |i: usize| fields.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(f64::NAN);
    (tick(11) + tick(12)) / 100.0
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().next().unwrap_or("?").to_string())
        .unwrap_or_default()
}

fn erms(a: &[f64], b: &[f64]) -> f64 {
    let s: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    1000.0 * (s / a.len() as f64).sqrt()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    if v.is_empty() { f64::NAN } else { v[v.len() / 2] }
}

struct Opts {
    align: bool,
    threads: usize,
    iterations: usize,
    signed: bool,
    per_component: bool,
}

fn run(name: &str, dir: &Path, target_s: f64, target_erms: f64, o: &Opts) {
    if !dir.is_dir() {
        println!("{name}: {} absent, skipped", dir.display());
        return;
    }
    let (faces, mut frames) = load_folder(dir);
    if o.align {
        let rest = frames[0].clone();
        for f in frames.iter_mut().skip(1) {
            *f = kabsch(f, &rest).apply_all(f);
        }
    }
    let (nf, nv) = (frames.len(), frames[0].len());
    let rest = frames[0].clone();
    // displacements in the data's units
    let mut x = Vec::with_capacity(nf * nv * 3);
    for f in &frames {
        for (p, r) in f.iter().zip(&rest) {
            x.extend_from_slice(&[p[0] - r[0], p[1] - r[1], p[2] - r[2]]);
        }
    }
    // support distances on the rest mesh scaled into the unit box
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in &rest {
        for q in 0..3 {
            lo[q] = lo[q].min(p[q]);
            hi[q] = hi[q].max(p[q]);
        }
    }
    let extent = (0..3).map(|q| hi[q] - lo[q]).fold(0.0, f64::max);
    let scaled: Vec<V3> = rest.iter().map(|p| [p[0] / extent, p[1] / extent, p[2] / extent]).collect();
    let provider = GraphDistances::new(scaled, &faces);
    let cfg = SplocsConfig {
        max_iterations: o.iterations,
        threads: o.threads,
        weights: if o.signed { WeightConstraint::Signed } else { WeightConstraint::Nonnegative },
        ..Default::default()
    };
    println!(
        "{name}: {nf} frames × {nv} vertices, {} faces, rest = first, unit-box extent {extent:.4}, align {}, \
         distances: Dijkstra graph distance (stand-in for heat geodesics), threads {}",
        faces.len(),
        o.align,
        o.threads
    );
    let dm = DataMatrix::new(&x, nf, nv, 3).unwrap();
    let (t0, c0) = (Instant::now(), cpu_seconds());
    let fit = SplocsSolver::fit(dm, &provider, &cfg, |i, e| println!("  iteration {i:03}, E={e:.6}")).unwrap();
    let secs = t0.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - c0;
    let rec = fit.model.reconstruct().unwrap();
    let e_splocs = erms(&rec, &x);
    println!(
        "  SPLOCS: {secs:.3} s wall (target ≤ {target_s} s; process CPU {cpu:.2} s, load average {}; of which distances \
         {:.3} s for {} centre sets), {} iterations, train Erms {e_splocs:.3} (target ≤ {target_erms})",
        load_average(),
        provider.time.get().as_secs_f64(),
        fit.distance_queries,
        fit.iterations
    );
    let t1 = Instant::now();
    let kp = 50.min(nf);
    let pca = Pca::fit(dm, &PcaConfig { components: kp, ..Default::default() }).unwrap();
    println!(
        "  PCA (K {kp}, mean-centred): train Erms {:.3} ({:.3} s)",
        erms(&pca.reconstruct().unwrap(), &x),
        t1.elapsed().as_secs_f64()
    );
    let shares: Vec<f64> = fit.locality.iter().map(|l| l.energy_share).collect();
    let sizes: Vec<f64> = fit.locality.iter().map(|l| l.support_size as f64).collect();
    let regions: Vec<f64> = fit.locality.iter().map(|l| l.region_size as f64).collect();
    let zero = fit.locality.iter().filter(|l| l.energy == 0.0).count();
    println!(
        "  locality: median energy share inside d < d_max {:.4} (min {:.4}, target median ≥ 0.95), \
         median support size {} of {nv} vertices (min {}, max {}), median region size {}, zero components {zero}",
        median(shares.clone()),
        shares.iter().fold(1.0f64, |a, &b| a.min(b)),
        median(sizes.clone()),
        sizes.iter().fold(f64::INFINITY, |a, &b| a.min(b)),
        sizes.iter().fold(0.0f64, |a, &b| a.max(b)),
        median(regions),
    );
    if o.per_component {
        for (k, l) in fit.locality.iter().enumerate() {
            println!(
                "    component {k:2}: centre {:5}, support {:5}, region {:5}, energy share {:.4}",
                l.center, l.support_size, l.region_size, l.energy_share
            );
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut which = "all".to_string();
    let mut o = Opts { align: false, threads: 1, iterations: 10, signed: false, per_component: false };
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--align" => o.align = true,
            "--signed" => o.signed = true,
            "--per-component" => o.per_component = true,
            "--threads" => {
                i += 1;
                o.threads = args[i].parse().expect("--threads N");
            }
            "--iterations" => {
                i += 1;
                o.iterations = args[i].parse().expect("--iterations N");
            }
            s => which = s.to_string(),
        }
        i += 1;
    }
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    if !data.is_dir() {
        println!("{} absent: nothing to do", data.display());
        return;
    }
    if which == "scape" || which == "all" {
        run("scape", &data.join("scape"), 0.4, 14.18, &o);
    }
    if which == "horse" || which == "all" {
        run("horse-gallop", &data.join("horse-gallop"), 1.2, 5.75, &o);
    }
}
