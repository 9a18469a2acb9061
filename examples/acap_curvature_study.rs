//! Study of issue 53 (docs/ground-truth.md § "Weighting the decoder by the features'
//! reliability"): how far from linear are a planted set's deformations in the ACAP features,
//! and where does that come from?
//!
//! A planted set is linear in the vertices (frame = rest + Σ w_d field_d + noise). For every
//! true deformation d the example encodes the rest shape moved by ½ and by 1 × field_d, takes
//! the features' linear extrapolation from ½ to 1 (2 F(½) − F(0)), decodes it and prints its
//! Erms against the shape at 1 (as a share of the deformation's own Erms from the rest shape):
//! how curved the deformation's path is in feature space. Then the same with the vertices whose
//! features moved most off the line (the worst 1 %) given their exact features, with their
//! noise weight (`feature_weights = "noise"`) and rotation angle; and decoded by the
//! noise-weighted decoder (`decoder_noise_power`, `decoder_edge_weight`). Last, the best linear
//! models of the training frames' features (PCA on them, unweighted and noise-weighted, K
//! components) on the test frames, decoded: the floor of a model linear in the features. And the
//! true deformations as such a model, each test frame from its true weights (`weights.csv`):
//! linear in the features (r + Σ w_d (F_d(1) − r)), each deformation along its own exact path
//! summed (r + Σ (F_d(w_d) − r), what is left is their interaction in the features), and the
//! linear one with every weight fitted to the frame's vertices (Gauss–Newton from the true
//! weights, as the autoencoder's encoder steps fit its code): the floor of a model additive in
//! the ACAP features with K = the number of deformations.
//!
//! `cargo run --release --example acap_curvature_study -- TRUTH_DIR [POWER EDGE_WEIGHT]`
//! (defaults: the autoencoder's defaults; 2–3 min on a 4 000-vertex face, 2 cores).
use meshdeco::config::{AE_DECODER_EDGE_WEIGHT, AE_DECODER_NOISE_POWER};
use meshdeco::eval::planted::Truth;
use meshdeco::math::vec3::Vec3;
use meshdeco::mesh::MeshSequence;
use meshdeco::mesh::npy::NpyFrames;
use meshdeco::metrics::erms::erms_from_squared_error;
use meshdeco::representation::acap::{AcapDecoder, Consistency};
use meshdeco::representation::noise_sensitivity::{NOISE_DRAWS, NOISE_LEVEL, feature_noise_variance, noise_weights};
use meshdeco::representation::roundtrip::{Alignment, erms};
use meshdeco::representation::{Features, Representation, RepresentationKind, RepresentationOptions};
use nalgebra::{DMatrix, DVector};

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 2 {
        return Err("usage: acap_curvature_study TRUTH_DIR [POWER EDGE_WEIGHT]".into());
    }
    let dir = std::path::Path::new(&a[1]);
    let power: f64 = a.get(2).map_or(Ok(AE_DECODER_NOISE_POWER), |s| s.parse())?;
    let mu: f64 = a.get(3).map_or(Ok(AE_DECODER_EDGE_WEIGHT), |s| s.parse())?;
    let truth = Truth::load(dir)?;
    let rest = meshdeco::mesh::load_mesh(&dir.join("template.obj"))?;
    let n = rest.positions.len();
    let npy = NpyFrames::open(&dir.join("frames.npy"), n)?.ok_or("frames.npy: not in C order")?;
    let rep_at = |mu: f64| {
        let decoder = AcapDecoder::FitInverse { edge_weight: mu };
        let opts = RepresentationOptions {
            acap_consistency: Consistency::Global,
            acap_decoder: decoder,
            ..Default::default()
        };
        Representation::new(RepresentationKind::Acap, &rest, opts)
    };
    let rep = rep_at(mu)?;
    let w = noise_weights(&feature_noise_variance(&rep, NOISE_LEVEL, NOISE_DRAWS, 0, &|x: Features| Ok(x))?);
    let fit_w: Vec<f64> = w.iter().map(|x| x.powf(power).max(f64::MIN_POSITIVE)).collect();
    let weighted = rep_at(mu)?.with_acap_fit_weights(&fit_w)?;
    let seq = |frames: Vec<Vec<Vec3>>| {
        let names = (0..frames.len()).map(|i| format!("f{i}")).collect();
        MeshSequence { faces: rest.faces.clone(), frames, names }
    };
    let rest_f = rep.encode_frame(&rest.positions)?;
    let per = 9 * n;
    println!(
        "{}: {n} vertices, {} deformations; decoder μ {mu}, noise power {power}",
        dir.display(),
        truth.fields.len()
    );
    println!(
        "deformation | Erms of the shape at 1 | linear extrapolation ½ → 1 (share) | worst 1 % exact | weighted decoder"
    );
    let (mut shares, mut shares_w) = (vec![], vec![]);
    for (d, field) in truth.fields.iter().enumerate() {
        let at = |s: f64| -> Vec<Vec3> {
            rest.positions.iter().zip(field).map(|(p, q)| [p[0] + s * q[0], p[1] + s * q[1], p[2] + s * q[2]]).collect()
        };
        let one = at(1.0);
        let f = rep.encode(&seq(vec![at(0.5), one.clone()]))?;
        let mut line = Features::zeros(1, n, 9);
        for ((l, x), r) in line.data.iter_mut().zip(&f.data[..per]).zip(&rest_f) {
            *l = 2.0 * x - r;
        }
        let e0 = erms(std::slice::from_ref(&one), std::slice::from_ref(&rest.positions), Alignment::Centroid)?;
        let e = erms(std::slice::from_ref(&one), &rep.decode(&line)?, Alignment::Centroid)?;
        let mut off: Vec<(f64, usize)> = (0..n)
            .map(|i| ((0..9).map(|c| (f.data[per + 9 * i + c] - line.data[9 * i + c]).powi(2)).sum::<f64>(), i))
            .collect();
        off.sort_by(|x, y| y.0.total_cmp(&x.0));
        let mut fixed = line.clone();
        for &(_, i) in &off[..n.div_ceil(100)] {
            fixed.data[9 * i..9 * i + 9].copy_from_slice(&f.data[per + 9 * i..per + 9 * i + 9]);
        }
        let ef = erms(std::slice::from_ref(&one), &rep.decode(&fixed)?, Alignment::Centroid)?;
        let ew = erms(std::slice::from_ref(&one), &weighted.decode(&line)?, Alignment::Centroid)?;
        let v = off[0].1;
        let angle = (0..3).map(|c| f.data[per + 9 * v + c].powi(2)).sum::<f64>().sqrt();
        println!(
            "{:>12} | {e0:7.3} | {e:7.3} ({:5.1} %) | {ef:7.3} ({:4.1} %) | {ew:7.3} ({:5.1} %)   most off: vertex {v}, noise weight {:.1e}, |log R| {angle:.2} at 1",
            truth.file.deformations[d].name,
            100.0 * e / e0,
            100.0 * ef / e0,
            100.0 * ew / e0,
            w[v]
        );
        shares.push(e / e0);
        shares_w.push(ew / e0);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "median share: {:.1} % (unweighted decoder), {:.1} % (weighted); above 50 %: {} and {}",
        100.0 * median(&mut shares.clone()),
        100.0 * median(&mut shares_w.clone()),
        shares.iter().filter(|s| **s > 0.5).count(),
        shares_w.iter().filter(|s| **s > 0.5).count()
    );
    // The best linear models of the features.
    let ntr = truth.file.train;
    let read = |r: std::ops::Range<usize>| -> Res<MeshSequence> {
        Ok(seq(r.map(|f| npy.read_frame(f)).collect::<Result<_, _>>()?))
    };
    let (train, test) = (read(0..ntr)?, read(ntr..npy.n_frames())?);
    let (ftr, fte) = (rep.encode(&train)?, rep.encode(&test)?);
    println!("round trip of the test frames: Erms {:.4}", erms(&test.frames, &rep.decode(&fte)?, Alignment::Centroid)?);
    let mean: Vec<f64> = (0..per).map(|i| (0..ntr).map(|f| ftr.data[f * per + i]).sum::<f64>() / ntr as f64).collect();
    for (label, noise_weighted) in [("unweighted", false), ("noise-weighted", true)] {
        let sw: Vec<f64> = (0..per).map(|i| if noise_weighted { w[i / 9].sqrt() } else { 1.0 }).collect();
        let m = DMatrix::from_fn(per, ntr, |i, f| (ftr.data[f * per + i] - mean[i]) * sw[i]);
        let u = m.svd(true, false).u.ok_or("svd")?;
        let mut row = format!("PCA on the features, {label}:");
        for k in [20usize, 41, 100, ntr - 1] {
            let uk = u.columns(0, k.min(u.ncols())).into_owned();
            let mut out = fte.clone();
            for f in 0..fte.n_frames {
                let x = DVector::from_fn(per, |i, _| (fte.data[f * per + i] - mean[i]) * sw[i]);
                let p = &uk * (uk.transpose() * &x);
                for i in 0..per {
                    out.data[f * per + i] = p[i] / sw[i] + mean[i];
                }
            }
            let e = erms(&test.frames, &rep.decode(&out)?, Alignment::Centroid)?;
            let ew = erms(&test.frames, &weighted.decode(&out)?, Alignment::Centroid)?;
            row += &format!(" K {k}: {e:.3} ({ew:.3} weighted decoder);");
        }
        println!("{row}");
    }
    // The true components as a model of the features, with the true weights of each test frame:
    // linear in the features (r + Σ w_d (F_d(1) − r)), and each deformation along its own exact
    // path, summed (r + Σ (F_d(w_d) − r)): what is left in the second is the deformations'
    // interaction in the features.
    let csv = std::fs::read_to_string(dir.join("weights.csv"))?;
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(1).map(|x| x.parse::<f64>()).collect::<Result<Vec<_>, _>>())
        .collect::<Result<_, _>>()?;
    if rows.len() != npy.n_frames() || rows.iter().any(|r| r.len() != truth.fields.len()) {
        return Err(format!(
            "{}: expected {} rows of {} weights (frames.npy, the deformations)",
            dir.join("weights.csv").display(),
            npy.n_frames(),
            truth.fields.len()
        )
        .into());
    }
    // F_d(1) − r per deformation.
    let deltas: Vec<Vec<f64>> = truth
        .fields
        .iter()
        .map(|field| -> Res<Vec<f64>> {
            let one: Vec<Vec3> =
                rest.positions.iter().zip(field).map(|(p, q)| [p[0] + q[0], p[1] + q[1], p[2] + q[2]]).collect();
            Ok(rep.encode_frame(&one)?.iter().zip(&rest_f).map(|(a, r)| a - r).collect())
        })
        .collect::<Res<_>>()?;
    let (mut lin, mut path) = (fte.clone(), fte.clone());
    for f in 0..fte.n_frames {
        let wt = &rows[ntr + f];
        let (l, p) = (&mut lin.data[f * per..(f + 1) * per], &mut path.data[f * per..(f + 1) * per]);
        l.copy_from_slice(&rest_f);
        p.copy_from_slice(&rest_f);
        for (d, &wd) in wt.iter().enumerate().filter(|(_, x)| **x != 0.0) {
            let at: Vec<Vec3> = rest
                .positions
                .iter()
                .zip(&truth.fields[d])
                .map(|(p, q)| [p[0] + wd * q[0], p[1] + wd * q[1], p[2] + wd * q[2]])
                .collect();
            let fd = rep.encode_frame(&at)?;
            for i in 0..per {
                l[i] += wd * deltas[d][i];
                p[i] += fd[i] - rest_f[i];
            }
        }
    }
    for (label, feats) in [("linear in the features", &lin), ("each on its own path, summed", &path)] {
        let e = erms(&test.frames, &rep.decode(feats)?, Alignment::Centroid)?;
        let ew = erms(&test.frames, &weighted.decode(feats)?, Alignment::Centroid)?;
        println!("true components and weights, {label}: test Erms {e:.3} ({ew:.3} weighted decoder)");
    }
    // The same linear model with each test frame's weights fitted in vertex space (Gauss–Newton
    // from the true weights, every component free): the floor of a model linear in the features
    // with the true components, as the autoencoder's encoder steps would meet it.
    let dn = truth.fields.len();
    let centred = |x: &[Vec3]| -> Vec<f64> {
        let mut c = [0.0; 3];
        for p in x {
            for k in 0..3 {
                c[k] += p[k] / x.len() as f64;
            }
        }
        x.iter().flat_map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]]).collect()
    };
    let decode_w = |w: &[f64]| -> Res<Vec<f64>> {
        let mut f = Features::zeros(1, n, 9);
        f.data.copy_from_slice(&rest_f);
        for (delta, &wd) in deltas.iter().zip(w) {
            for (x, dx) in f.data.iter_mut().zip(delta) {
                *x += wd * dx;
            }
        }
        Ok(centred(&weighted.decode(&f)?[0]))
    };
    let mut total = 0.0;
    for f in 0..test.frames.len() {
        let t = centred(&test.frames[f]);
        let mut wt = rows[ntr + f].clone();
        let res = |x: &[f64]| -> Vec<f64> { x.iter().zip(&t).map(|(a, b)| a - b).collect() };
        let mut r = res(&decode_w(&wt)?);
        let mut e = r.iter().map(|x| x * x).sum::<f64>();
        for _ in 0..12 {
            let h = 1e-4;
            let mut j = DMatrix::zeros(3 * n, dn);
            for d in 0..dn {
                let mut wp = wt.clone();
                wp[d] += h;
                let rp = res(&decode_w(&wp)?);
                for i in 0..3 * n {
                    j[(i, d)] = (rp[i] - r[i]) / h;
                }
            }
            let rv = DVector::from_column_slice(&r);
            let mut a = j.transpose() * &j;
            let lam = 1e-6 * a.trace() / dn as f64;
            for d in 0..dn {
                a[(d, d)] += lam;
            }
            let step = a.cholesky().ok_or("cholesky")?.solve(&(-(j.transpose() * rv)));
            let wn: Vec<f64> = wt.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            let rn = res(&decode_w(&wn)?);
            let en = rn.iter().map(|x| x * x).sum::<f64>();
            if en >= e {
                break;
            }
            (wt, r, e) = (wn, rn, en);
        }
        total += e;
    }
    println!(
        "true components, linear in the features, weights fitted in vertex space: test Erms {:.3} (weighted decoder)",
        erms_from_squared_error(total, 3 * n * test.frames.len())
    );
    Ok(())
}
