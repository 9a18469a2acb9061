//! How well does a linear model in each representation generalise? For a train/test split, each
//! test shape's features are projected (least squares) onto the affine span of the training
//! shapes' features, decoded, and compared with the test shape (centroid-aligned Erms). This is
//! the best any linear model with up to (train − 1) components can do on the test set.
//! `cargo run --release --example acap_linear_study -- ../shared/data/scape 1-36 37-71`
use meshdeco::config::FrameSelection;
use meshdeco::representation::acap::Consistency;
use meshdeco::representation::roundtrip::{Alignment, erms};
use meshdeco::representation::scaling::{FeatureScaling, ScalingMode};
use meshdeco::representation::{Features, Representation, RepresentationKind, RepresentationOptions};
use nalgebra::{DMatrix, DVector};

fn project(train: &Features, test: &Features) -> Features {
    let per = train.n_elements * train.width;
    let nt = train.n_frames;
    let mean: Vec<f64> = (0..per).map(|i| (0..nt).map(|f| train.data[f * per + i]).sum::<f64>() / nt as f64).collect();
    let a = DMatrix::from_fn(per, nt, |i, f| train.data[f * per + i] - mean[i]);
    let svd = a.svd(true, false);
    let u = svd.u.unwrap();
    let rank = svd.singular_values.iter().filter(|s| **s > 1e-9 * svd.singular_values[0]).count();
    let u = u.columns(0, rank).into_owned();
    let mut out = test.clone();
    for f in 0..test.n_frames {
        let x = DVector::from_fn(per, |i, _| test.data[f * per + i] - mean[i]);
        let c = u.transpose() * &x;
        let p = &u * c;
        for i in 0..per {
            out.data[f * per + i] = p[i] + mean[i];
        }
    }
    out
}

/// Rewrites every vertex's logR as the equivalent a·(θ + 2πk) nearest to the mean over `template`
/// frames (iterated on the template itself first).
fn canonicalise(train: &mut Features, test: &mut Features) {
    use nalgebra::Vector3;
    let get = |f: &Features, fr: usize, v: usize| {
        let e = f.element(fr, v);
        Vector3::new(-e[2], e[1], -e[0])
    };
    let set = |f: &mut Features, fr: usize, v: usize, w: Vector3<f64>| {
        let base = (fr * f.n_elements + v) * f.width;
        f.data[base] = -w.z;
        f.data[base + 1] = w.y;
        f.data[base + 2] = -w.x;
    };
    let near = |w: Vector3<f64>, mu: Vector3<f64>| {
        let th = w.norm();
        if th < 1e-9 {
            return w;
        }
        let a = w / th;
        let mut best = w;
        for k in -2..=2 {
            let c = a * (th + 2.0 * std::f64::consts::PI * k as f64);
            if (c - mu).norm() < (best - mu).norm() {
                best = c;
            }
        }
        best
    };
    let nv = train.n_elements;
    for _ in 0..5 {
        for v in 0..nv {
            let mu = (0..train.n_frames).map(|f| get(train, f, v)).sum::<Vector3<f64>>() / train.n_frames as f64;
            for f in 0..train.n_frames {
                let w = near(get(train, f, v), mu);
                set(train, f, v, w);
            }
        }
    }
    for v in 0..nv {
        let mu = (0..train.n_frames).map(|f| get(train, f, v)).sum::<Vector3<f64>>() / train.n_frames as f64;
        for f in 0..test.n_frames {
            let w = near(get(test, f, v), mu);
            set(test, f, v, w);
        }
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let seq = meshdeco::mesh::load_sequence(&args[1])?;
    let n = seq.n_frames();
    let tr = FrameSelection::parse("train", &args[2])?.resolve("train", n, None)?;
    let te = FrameSelection::parse("test", &args[3])?.resolve("test", n, None)?;
    let rest = seq.mesh(0);
    let (train, test) = (seq.select(&tr), seq.select(&te));
    use meshdeco::representation::acap::AcapDecoder as D;
    for (kind, cons, dec) in [
        (RepresentationKind::Displacement, Consistency::Bfs, D::EdgeLeastSquares),
        (RepresentationKind::Acap, Consistency::Bfs, D::FitInverse { edge_weight: 1e-6 }),
        (RepresentationKind::Acap, Consistency::Global, D::FitInverse { edge_weight: 1e-6 }),
        (RepresentationKind::Acap, Consistency::Global, D::FitInverse { edge_weight: 0.1 }),
        (RepresentationKind::Acap, Consistency::Global, D::EdgeLeastSquares),
    ] {
        let opts = RepresentationOptions { acap_consistency: cons, acap_decoder: dec, ..Default::default() };
        let r = Representation::new(kind, &rest, opts)?;
        let ftr = r.encode(&train)?;
        let fte = r.encode(&test)?;
        let rt = r.decode(&fte)?;
        let p = project(&ftr, &fte);
        let rec = r.decode(&p)?;
        let e = erms(&test.frames, &rec, Alignment::Centroid)?;
        let sc = FeatureScaling::fit(&ftr, ScalingMode::PerDimension)?;
        let ps = sc.invert(&project(&sc.apply(&ftr)?, &sc.apply(&fte)?))?;
        let es = erms(&test.frames, &r.decode(&ps)?, Alignment::Centroid)?;
        if kind == RepresentationKind::Acap {
            let (mut a, mut b) = (ftr.clone(), fte.clone());
            canonicalise(&mut a, &mut b);
            let e = erms(&test.frames, &r.decode(&project(&a, &b))?, Alignment::Centroid)?;
            let sc = FeatureScaling::fit(&a, ScalingMode::PerDimension)?;
            let ps = sc.invert(&project(&sc.apply(&a)?, &sc.apply(&b)?))?;
            let es = erms(&test.frames, &r.decode(&ps)?, Alignment::Centroid)?;
            let rt = erms(&test.frames, &r.decode(&b)?, Alignment::Centroid)?;
            println!(
                "    canonicalised to the training mean: round trip {rt:.4}, projection {e:.3} (raw) {es:.3} (scaled)"
            );
        }
        if kind == RepresentationKind::Acap && dec == (D::FitInverse { edge_weight: 1e-6 }) {
            // Cross-shape consistency: logR distance much larger than the rotation distance.
            let om = |f: &Features, fr: usize, v: usize| {
                let e = f.element(fr, v);
                nalgebra::Vector3::new(-e[2], e[1], -e[0])
            };
            let (mut bad, mut tot, mut at_vertex) = (0usize, 0usize, vec![false; ftr.n_elements]);
            for a in 0..ftr.n_frames {
                for b in 0..fte.n_frames {
                    for (v, flag) in at_vertex.iter_mut().enumerate() {
                        let (wa, wb) = (om(&ftr, a, v), om(&fte, b, v));
                        let ra = nalgebra::Rotation3::new(wa);
                        let rb = nalgebra::Rotation3::new(wb);
                        let drot = ra.angle_to(&rb);
                        let dlog = (wa - wb).norm();
                        tot += 1;
                        if dlog > drot + 1.0 {
                            bad += 1;
                            *flag = true;
                        }
                    }
                }
            }
            let nv = at_vertex.iter().filter(|c| **c).count();
            let maxw = (0..ftr.n_frames)
                .flat_map(|f| (0..ftr.n_elements).map(move |v| (f, v)))
                .map(|(f, v)| om(&ftr, f, v).norm())
                .fold(0.0, f64::max);
            println!(
                "    inconsistent (|dlog| > drot + 1 rad): {bad} of {tot} pairs, at {nv} vertices; max |omega| train {maxw:.3}"
            );
        }
        if kind == RepresentationKind::Acap {
            // Project one half only, keeping the test shape's own other half.
            for (name, dims) in [("rotation only", 0..3), ("stretch only", 3..9)] {
                let mut q = fte.clone();
                for (i, v) in q.data.iter_mut().enumerate() {
                    if dims.contains(&(i % 9)) {
                        *v = p.data[i];
                    }
                }
                println!("    projecting {name}: {:.3}", erms(&test.frames, &r.decode(&q)?, Alignment::Centroid)?);
            }
        }
        println!(
            "{:>13} {:?} {:?}: round trip {:.4}, affine-span projection {:.3} (raw) {:.3} (scaled)",
            kind.name(),
            cons,
            dec,
            erms(&test.frames, &rt, Alignment::Centroid)?,
            e,
            es
        );
    }
    Ok(())
}
