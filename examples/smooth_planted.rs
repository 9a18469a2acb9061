//! Probe of issue 53 (docs/ground-truth.md): does noise in the ACAP features keep the
//! ACAP-based methods from the planted deformations? Copies a planted set with each *training*
//! frame's displacement from the rest shape smoothed by `STEPS` explicit umbrella (uniform
//! Laplacian) steps of weight ½ — the test frames, fields and weights unchanged — into a new
//! planted directory that `meshdeco eval` reads like the original.
//!
//! `cargo run --release --example smooth_planted -- TRUTH_DIR OUT_DIR STEPS`
use meshdeco::eval::planted::{PlantedSet, Truth, write};
use meshdeco::mesh::npy::NpyFrames;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() != 4 {
        return Err("usage: smooth_planted TRUTH_DIR OUT_DIR STEPS".into());
    }
    let dir = std::path::Path::new(&a[1]);
    let steps: usize = a[3].parse().map_err(|_| format!("STEPS `{}` is not a count", a[3]))?;
    let truth = Truth::load(dir)?;
    let rest = meshdeco::mesh::load_mesh(&dir.join("template.obj"))?;
    let n = rest.positions.len();
    let npy = NpyFrames::open(&dir.join("frames.npy"), n)?.ok_or("frames.npy: not in C order")?;
    let mut frames = (0..npy.n_frames()).map(|f| npy.read_frame(f)).collect::<Result<Vec<_>, _>>()?;
    let weights = truth.weights()?;
    let mut nbrs = vec![Vec::new(); n];
    for f in &rest.faces {
        for k in 0..3 {
            let (i, j) = (f[k], f[(k + 1) % 3]);
            if !nbrs[i].contains(&j) {
                nbrs[i].push(j);
                nbrs[j].push(i);
            }
        }
    }
    for frame in frames.iter_mut().take(truth.file.train) {
        let mut d: Vec<[f64; 3]> =
            frame.iter().zip(&rest.positions).map(|(p, r)| [p[0] - r[0], p[1] - r[1], p[2] - r[2]]).collect();
        for _ in 0..steps {
            let prev = d.clone();
            for (i, di) in d.iter_mut().enumerate() {
                if nbrs[i].is_empty() {
                    continue;
                }
                let m = nbrs[i].len() as f64;
                for c in 0..3 {
                    let avg = nbrs[i].iter().map(|&j| prev[j][c]).sum::<f64>() / m;
                    di[c] = 0.5 * prev[i][c] + 0.5 * avg;
                }
            }
        }
        for ((p, r), di) in frame.iter_mut().zip(&rest.positions).zip(&d) {
            *p = [r[0] + di[0], r[1] + di[1], r[2] + di[2]];
        }
    }
    let set = PlantedSet { rest, truth: truth.file, fields: truth.fields, weights, frames };
    write(&set, std::path::Path::new(&a[2]))?;
    Ok(())
}
