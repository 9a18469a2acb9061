//! Loading benchmarks on the shared datasets. A dataset that is absent is not benchmarked (a
//! line says so).

use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use meshdeco::mesh::read_sequence;

fn dataset(name: &str) -> Option<String> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(name);
    if dir.is_dir() {
        Some(dir.to_string_lossy().into_owned())
    } else {
        eprintln!("benches/io: {} is absent, not benchmarked", dir.display());
        None
    }
}

fn load(c: &mut Criterion) {
    let mut group = c.benchmark_group("io");
    group.sample_size(20);
    for (label, name) in [("load scape", "scape"), ("load horse-gallop", "horse-gallop")] {
        if let Some(spec) = dataset(name) {
            group.bench_function(label, |b| b.iter(|| read_sequence(&spec).unwrap()));
        }
    }
    group.finish();
}

criterion_group!(benches, load);
criterion_main!(benches);
