//! `meshdeco features` and `meshdeco roundtrip`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use meshdeco::mesh::TriMesh;
use meshdeco::representation::acap::{Acap, Consistency};
use meshdeco::representation::acap_text::write_acap_text;
use meshdeco::representation::roundtrip::roundtrip;
use meshdeco::representation::{Representation, RepresentationKind, RepresentationOptions};

#[derive(Debug, Args)]
pub struct FeaturesArgs {
    /// Frames: directory, glob, or synthetic:<name>. The first frame (natural order) is the
    /// reference shape, as in the reference implementation.
    pub path: String,
    /// Representation: acap | triangle-gradient | displacement.
    #[arg(long, short, default_value = "acap")]
    pub representation: String,
    /// ACAP: run the global rotation-consistency step after BFS (never a higher energy).
    #[arg(long)]
    pub global: bool,
    /// Output directory. acap: LOGRNEW.txt and S.txt in the reference's layout (one row per
    /// shape, full 3×3 matrices per vertex, row-major); others: features.txt (one row per
    /// shape, the per-element numbers in order).
    #[arg(long, short)]
    pub out: PathBuf,
}

#[derive(Debug, Args)]
pub struct RoundtripArgs {
    /// Frames: directory, glob, or synthetic:<name>; the first frame is the rest shape.
    pub path: String,
    /// Representation: acap | triangle-gradient | displacement.
    #[arg(long, short, default_value = "acap")]
    pub representation: String,
    /// ACAP: global rotation consistency instead of BFS.
    #[arg(long)]
    pub global: bool,
}

fn kind(s: &str) -> Result<RepresentationKind> {
    RepresentationKind::parse(s)
        .with_context(|| format!("--representation `{s}`: expected acap, triangle-gradient or displacement"))
}

pub fn features(a: FeaturesArgs) -> Result<()> {
    let k = kind(&a.representation)?;
    let seq = meshdeco::preprocess::load_frames(&a.path)?;
    let rest = seq.mesh(0);
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    if k == RepresentationKind::Acap {
        let acap = Acap::new(&rest)?;
        let consistency = if a.global { Consistency::Global } else { Consistency::Bfs };
        let frames = acap.encode_sequence(&seq.frames, consistency)?;
        write_acap_text(&a.out, &frames)?;
        for (f, name) in frames.iter().zip(&seq.names) {
            outln!("{name}: consistency energy BFS {:.6}, final {:.6}", f.energy_bfs, f.energy);
        }
        outln!(
            "wrote {} and {} ({} shapes × {} vertices)",
            a.out.join("LOGRNEW.txt").display(),
            a.out.join("S.txt").display(),
            seq.n_frames(),
            seq.n_vertices()
        );
        return Ok(());
    }
    if a.global {
        bail!("--global applies to --representation acap only");
    }
    let rep = Representation::new(k, &rest, RepresentationOptions::default())?;
    let x = rep.encode(&seq)?;
    let mut text = String::new();
    for f in 0..x.n_frames {
        let row: Vec<String> = x.frame(f).iter().map(|v| v.to_string()).collect();
        text.push_str(&row.join(" "));
        text.push('\n');
    }
    let path = a.out.join("features.txt");
    meshdeco::artifact::write_atomic(&path, text.as_bytes())?;
    outln!("wrote {} ({} shapes × {} elements × {})", path.display(), x.n_frames, x.n_elements, x.width);
    Ok(())
}

pub fn roundtrip_cmd(a: RoundtripArgs) -> Result<()> {
    let k = kind(&a.representation)?;
    let seq = meshdeco::preprocess::load_frames(&a.path)?;
    let rest: TriMesh = seq.mesh(0);
    let options = RepresentationOptions {
        acap_consistency: if a.global { Consistency::Global } else { Consistency::Bfs },
        ..Default::default()
    };
    let rep = Representation::new(k, &rest, options)?;
    let report = roundtrip(&rep, &seq)?;
    out!("{report}");
    Ok(())
}
