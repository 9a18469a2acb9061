//! Is the autoencoder's test error the encoder's or the decoder's? For frames of a data set:
//! scaled features outside [−1, 1] (unreachable by tanh), Erms with the encoder's codes, and
//! Erms with codes fitted to the features by Gauss–Newton through the decoder.
//! `cargo run --release --example ae_capacity_study -- OUT_DIR ../shared/data/scape 37-71`
use meshdeco::pipeline::autoencoder::AeArtifact;
use meshdeco::representation::roundtrip::{Alignment, erms};
use nalgebra::{DMatrix, DVector};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let m = AeArtifact::load(std::path::Path::new(&args[1]))?;
    let seq = meshdeco::mesh::load_sequence(&args[2])?;
    let sel = meshdeco::config::FrameSelection::parse("frames", &args[3])?.resolve("frames", seq.n_frames(), None)?;
    let test = seq.select(&sel);
    let x = m.representation.encode(&test)?;
    let xs = m.header.scaling.apply(&x)?;
    let out1 = xs.data.iter().filter(|v| v.abs() > 1.0).count();
    let out95 = xs.data.iter().filter(|v| v.abs() > 0.95).count();
    let maxabs = xs.data.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    println!("scaled features: {} of {} beyond ±0.95, {} beyond ±1, max |x| {maxabs:.3}", out95, xs.data.len(), out1);
    let mut codes = m.encode_frames(&test)?;
    let rec = m.decode_codes(&codes)?;
    println!("encoder codes: Erms {:.4}", erms(&test.frames, &rec, Alignment::Centroid)?);
    let zmax = codes.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    println!("max |z| {zmax:.3}");
    let k = codes[0].len();
    let per = xs.n_elements * xs.width;
    let resid = |c: &[Vec<f64>]| -> anyhow::Result<Vec<f64>> {
        let d = m.model.decode(c)?;
        Ok(d.data.iter().zip(&xs.data).map(|(a, b)| a - b).collect())
    };
    for it in 0..8 {
        let r0 = resid(&codes)?;
        let h = 1e-3;
        let mut jac: Vec<Vec<f64>> = Vec::new();
        for kk in 0..k {
            let mut c = codes.clone();
            for z in c.iter_mut() {
                z[kk] += h;
            }
            let r = resid(&c)?;
            jac.push(r.iter().zip(&r0).map(|(a, b)| (a - b) / h).collect());
        }
        let mut sse = 0.0;
        for (f, z) in codes.iter_mut().enumerate() {
            let rf = &r0[f * per..(f + 1) * per];
            sse += rf.iter().map(|v| v * v).sum::<f64>();
            let j = DMatrix::from_fn(per, k, |i, kk| jac[kk][f * per + i]);
            let jt = j.transpose();
            let mut a = &jt * &j;
            for d in 0..k {
                a[(d, d)] += 1e-6;
            }
            let g = &jt * DVector::from_column_slice(rf);
            let delta = a.lu().solve(&g).unwrap();
            for d in 0..k {
                z[d] -= delta[d];
            }
        }
        println!("GN {it}: feature SSE per frame {:.4}", sse / codes.len() as f64);
    }
    let rec = m.decode_codes(&codes)?;
    println!("fitted codes: Erms {:.4}", erms(&test.frames, &rec, Alignment::Centroid)?);
    Ok(())
}
