//! Geometry operator benchmarks: cotangent Laplacian assembly, heat-method factorisation
//! (`HeatGeodesics::new`: intrinsic Delaunay flips, Laplacian, mass, one symbolic analysis, two
//! numeric Cholesky factorisations, three on meshes with a boundary) and one single-source
//! geodesic query (default options: averaged boundary conditions, straight-line lower bound;
//! and with the edge-path upper bound, which adds a Dijkstra search).
//!
//! Meshes: a unit icosphere with 10 242 vertices (always) and frame 1 of the horse gallop
//! (8 431 vertices, `../shared/data/horse-gallop/0001.obj`, loaded with `meshdeco::mesh::load_mesh`; skipped
//! with a message when the file is absent).
//!
//! Run: `cargo bench --bench geometry`. Target: a query on the horse ≤ 5 ms.

use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use meshdeco::geometry::cotan_laplacian::cotan_laplacian;
use meshdeco::geometry::heat_geodesics::{DistanceBounds, HeatGeodesics, HeatOptions};
use meshdeco::mesh::TriMesh;
use meshdeco::mesh::primitives::icosphere;

const HORSE: &str = "../shared/data/horse-gallop/0001.obj";

fn bench_mesh(c: &mut Criterion, name: &str, mesh: &TriMesh) {
    let mut group = c.benchmark_group(format!("geometry/{name} ({} vertices)", mesh.n_vertices()));
    group.sample_size(20).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(4));
    group.bench_function("cotan_laplacian", |b| {
        b.iter(|| cotan_laplacian(black_box(&mesh.positions), black_box(&mesh.faces)))
    });
    group.bench_function("heat_factor (m=1)", |b| {
        b.iter(|| HeatGeodesics::new(black_box(&mesh.positions), black_box(&mesh.faces), 1.0).unwrap())
    });
    let solver = HeatGeodesics::new(&mesh.positions, &mesh.faces, 1.0).unwrap();
    let source = mesh.n_vertices() / 3;
    group.bench_function("geodesic_query", |b| b.iter(|| solver.distances(black_box(&[source])).unwrap()));
    // With the edge-path (Dijkstra) upper bound as well.
    let both = HeatOptions { bounds: DistanceBounds::StraightLineAndEdgePath, ..Default::default() };
    let both = HeatGeodesics::with_options(&mesh.positions, &mesh.faces, both).unwrap();
    group.bench_function("geodesic_query (+ edge-path bound)", |b| {
        b.iter(|| both.distances(black_box(&[source])).unwrap())
    });
    group.finish();
}

fn geometry(c: &mut Criterion) {
    bench_mesh(c, "icosphere(5)", &icosphere(5));
    match meshdeco::mesh::load_mesh(Path::new(HORSE)).ok() {
        Some(horse) => bench_mesh(c, "horse-gallop/0001", &horse),
        None => eprintln!("skipping horse-gallop benchmarks: {HORSE} not found (shared data absent)"),
    }
}

criterion_group!(benches, geometry);
criterion_main!(benches);
