//! Writes a mesh sequence (a directory, glob or `synthetic:<name>`) as a NumPy array
//! (F × N × 3, float64) plus its first frame as the template mesh, e.g. to check that a `.npy`
//! data set trains like the mesh files:
//!
//! ```sh
//! cargo run --release --example to_npy -- ../shared/data/scape /tmp/scape.npy /tmp/scape-template.obj
//! cargo run --release --example to_npy -- ../shared/data/scape /tmp/scape.npz /tmp/scape-template.obj verts
//! ```

fn main() -> meshdeco::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        eprintln!("usage: to_npy <frames> <out.npy|out.npz> <template.obj> [array name for .npz]");
        std::process::exit(2);
    }
    let seq = meshdeco::preprocess::load_frames(&args[1])?;
    let out = std::path::Path::new(&args[2]);
    if args[2].ends_with(".npz") {
        let name = args.get(4).map(String::as_str).unwrap_or("verts");
        meshdeco::mesh::npy::write_npz(out, &[(name, &seq.frames)])?;
    } else {
        meshdeco::mesh::npy::write_npy(out, &seq.frames)?;
    }
    meshdeco::mesh::write_obj(std::path::Path::new(&args[3]), &seq.mesh(0))?;
    println!("wrote {} ({} frames × {} vertices) and {}", args[2], seq.n_frames(), seq.n_vertices(), args[3]);
    Ok(())
}
