//! Criterion benchmark of one SPLOCS outer iteration (weight sweep, centres, 10 ADMM
//! iterations, objective) on SCAPE (71 × 2161) and the horse gallop (48 × 8431), K = 50, with
//! the reference's settings. Support distances: Euclidean distance on the unit-box rest mesh
//! (cheap stand-in; after the first iteration the support maps come from the cache anyway).
//! Skipped (with a message) when `../shared/data` is absent.

use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use meshdeco::Result;
use meshdeco::methods::support_map::SupportDistances;
use meshdeco::methods::{DataMatrix, SplocsConfig, SplocsSolver};

struct Euclidean(Vec<[f64; 3]>);

impl SupportDistances for Euclidean {
    fn n_elements(&self) -> usize {
        self.0.len()
    }
    fn distances(&self, centers: &[usize]) -> Result<Vec<f64>> {
        Ok(self
            .0
            .iter()
            .map(|p| {
                centers
                    .iter()
                    .map(|&c| {
                        let q = self.0[c];
                        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect())
    }
}

/// (displacements F × N × 3, unit-box rest positions)
fn load(dir: &Path) -> Option<(Vec<f64>, usize, Vec<[f64; 3]>)> {
    if !dir.is_dir() {
        return None;
    }
    let frames = meshdeco::mesh::load_sequence(&format!("{}/*.obj", dir.display())).ok()?.frames;
    let rest = frames[0].clone();
    let mut x = Vec::new();
    for fr in &frames {
        for (p, r) in fr.iter().zip(&rest) {
            x.extend_from_slice(&[p[0] - r[0], p[1] - r[1], p[2] - r[2]]);
        }
    }
    let (lo, hi) = meshdeco::mesh::bounding_box(&rest);
    let ext = (0..3).map(|q| hi[q] - lo[q]).fold(0.0f64, f64::max);
    let scaled = rest.iter().map(|p| [p[0] / ext, p[1] / ext, p[2] / ext]).collect();
    Some((x, frames.len(), scaled))
}

fn bench(c: &mut Criterion) {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    let mut group = c.benchmark_group("splocs_outer_iteration");
    group.sample_size(10);
    for (name, folder) in [("scape", "scape"), ("horse", "horse-gallop")] {
        let Some((x, f, rest)) = load(&data.join(folder)) else {
            eprintln!("splocs bench: {} absent, skipping {name}", data.join(folder).display());
            continue;
        };
        let provider = Euclidean(rest);
        let n = provider.0.len();
        for threads in [1usize, 2] {
            let cfg = SplocsConfig { threads, ..Default::default() };
            let mut solver = SplocsSolver::new(DataMatrix::new(&x, f, n, 3).unwrap(), &provider, &cfg).unwrap();
            solver.step().unwrap();
            group.bench_function(format!("{name}_threads{threads}"), |b| b.iter(|| solver.step().unwrap()));
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
