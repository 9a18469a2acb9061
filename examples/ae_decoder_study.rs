//! Which ACAP decoder turns a trained autoencoder's output features into the best vertices?
//! `cargo run --release --example ae_decoder_study -- checkpoints/scape-ae ../shared/data/scape 37-71`
//! (a `.npy` sequence takes its template as a fourth argument, e.g. a planted set's
//! `frames.npy 201-300 template.obj`)
use meshdeco::pipeline::autoencoder::AeArtifact;
use meshdeco::representation::acap::AcapDecoder;
use meshdeco::representation::roundtrip::{Alignment, erms};
use meshdeco::representation::{Representation, RepresentationKind, RepresentationOptions};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let m = AeArtifact::load(std::path::Path::new(&args[1]))?;
    let seq = match args.get(4) {
        Some(t) => {
            meshdeco::mesh::npy::load_npy_sequence(std::path::Path::new(&args[2]), None, std::path::Path::new(t))?
        }
        None => meshdeco::mesh::load_sequence(&args[2])?,
    };
    let sel = meshdeco::config::FrameSelection::parse("frames", &args[3])?.resolve("frames", seq.n_frames(), None)?;
    let test = seq.select(&sel);
    let codes = m.encode_frames(&test)?;
    let xs = m.model.decode(&codes)?;
    let x = m.header.scaling.invert(&xs)?;
    for (name, dec) in [
        ("fit-inverse 1e-6", AcapDecoder::FitInverse { edge_weight: 1e-6 }),
        ("fit-inverse 1e-4", AcapDecoder::FitInverse { edge_weight: 1e-4 }),
        ("fit-inverse 1e-3", AcapDecoder::FitInverse { edge_weight: 1e-3 }),
        ("fit-inverse 1e-2", AcapDecoder::FitInverse { edge_weight: 1e-2 }),
        ("fit-inverse 3e-2", AcapDecoder::FitInverse { edge_weight: 3e-2 }),
        ("fit-inverse 0.1", AcapDecoder::FitInverse { edge_weight: 0.1 }),
        ("fit-inverse 0.3", AcapDecoder::FitInverse { edge_weight: 0.3 }),
        ("fit-inverse 1", AcapDecoder::FitInverse { edge_weight: 1.0 }),
        ("fit-inverse 3", AcapDecoder::FitInverse { edge_weight: 3.0 }),
        ("edge least squares", AcapDecoder::EdgeLeastSquares),
    ] {
        let opts = RepresentationOptions { acap_decoder: dec, ..Default::default() };
        let rep = Representation::new(RepresentationKind::Acap, &m.rest, opts)?;
        let rec = rep.decode(&x)?;
        println!("{name:>20}: Erms {:.4}", erms(&test.frames, &rec, Alignment::Centroid)?);
    }
    // Feature-space error of the network alone.
    let truth = m.representation.encode(&test)?;
    let se: f64 = truth.data.iter().zip(&x.data).map(|(a, b)| (a - b) * (a - b)).sum();
    println!("feature RMS error {:.5}", (se / truth.data.len() as f64).sqrt());
    Ok(())
}
