//! Criterion benchmarks of the representations on real data (`../shared/data`; each benchmark
//! prints a reason and is skipped when its folder is absent):
//! * `triangle_gradient/encode_scape_71`: triangle-gradient features of all 71 SCAPE shapes
//!   (rest = 1.obj), `Representation::encode` (frames in parallel);
//! * `triangle_gradient/decode_horse_frame`: decoding one horse-gallop frame (8431 vertices)
//!   after factorisation (Eq. (6) right-hand side + 3 Cholesky solves);
//! * `triangle_gradient/factorise_horse`: building the representation (rest frames, assembly,
//!   symbolic + numeric Cholesky) of the horse.
//!
//! Run: `cargo bench --bench representations`.

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use meshdeco::mesh::{MeshSequence, TriMesh, load_mesh};
use meshdeco::representation::{Representation, RepresentationKind, RepresentationOptions};

/// The OBJ files `names` of data folder `folder`, or `None` (with a message) when absent.
fn load(folder: &str, names: &[String]) -> Option<MeshSequence> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(folder);
    if !dir.is_dir() {
        eprintln!("skipping {folder} benchmarks: {} is absent", dir.display());
        return None;
    }
    let meshes: Vec<TriMesh> = names
        .iter()
        .map(|n| dir.join(n))
        .map(|p| load_mesh(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .collect();
    Some(MeshSequence {
        faces: meshes[0].faces.clone(),
        frames: meshes.into_iter().map(|m| m.positions).collect(),
        names: names.to_vec(),
    })
}

fn benches(c: &mut Criterion) {
    let scape_names: Vec<String> = (1..=71).map(|i| format!("{i}.obj")).collect();
    if let Some(scape) = load("scape", &scape_names) {
        let rep =
            Representation::new(RepresentationKind::TriangleGradient, &scape.mesh(0), RepresentationOptions::default())
                .expect("SCAPE triangle-gradient representation");
        c.bench_function("triangle_gradient/encode_scape_71", |b| b.iter(|| black_box(rep.encode(&scape).unwrap())));
    }
    let horse_names: Vec<String> = vec!["0001.obj".into(), "0010.obj".into()];
    if let Some(horse) = load("horse-gallop", &horse_names) {
        let rest = horse.mesh(0);
        let rep = Representation::new(RepresentationKind::TriangleGradient, &rest, RepresentationOptions::default())
            .expect("horse triangle-gradient representation");
        let features = rep.encode_frame(&horse.frames[1]).unwrap();
        c.bench_function("triangle_gradient/decode_horse_frame", |b| {
            b.iter(|| black_box(rep.decode_frame(black_box(&features)).unwrap()))
        });
        let mut group = c.benchmark_group("triangle_gradient");
        group.sample_size(10);
        group.bench_function("factorise_horse", |b| {
            b.iter(|| {
                black_box(
                    Representation::new(RepresentationKind::TriangleGradient, &rest, RepresentationOptions::default())
                        .unwrap(),
                )
            })
        });
        group.finish();
    }
}

criterion_group!(representations, benches);
criterion_main!(representations);
