//! The hand engine's training step against its arithmetic limit, per shape-vertex, on meshes of
//! three sizes (issue 57, item 3).
//!
//! 1. The machine: its `f32` multiply-add rate with the kernels' own pattern (blocks of 8 lanes,
//!    `mul_add` compiled for AVX2+FMA, as `kernels::axpy`; twelve independent chains, so the rate
//!    is the FMA pipes' and not a latency), single-threaded and on every rayon thread; faer's
//!    GEMM at the shapes of the step's latent products (`K × 9·512` tiles of `C` against a batch
//!    of `B` shapes, in cache); and the memory bandwidth of a triad `a = b + s·c` over 64 MiB
//!    arrays (for the memory side of the limit).
//! 2. The step: `Trainer::step` at `AutoencoderConfig::default()` (K = 50, L = 1, no augment, the
//!    fused update of `C`) with `batch_size` 32 on 32 shapes of random features in [−0.95, 0.95]
//!    (the step costs the same for any values), hop-count distances (as benches/autoencoder.rs),
//!    on `../shared/data/scape/1.obj` (2 161 vertices), `../shared/data/cactus/cactus0.ply`
//!    (5 261) and `../shared/data/face-poses/1.obj` (29 299); an icosphere of similar size
//!    stands in for an absent file. Three warm-up steps, then the median of 20 steps (10 on the
//!    face).
//!
//! ```text
//! cargo run --release --example step_limit [-- --steps 20]
//! ```
//!
//! Prints the flop count of one step per shape-vertex (the formula of [`step_flops`], for
//! K = 50 and 41), the machine's rates, and one table row per mesh: vertices N, mean degree d,
//! shapes per step (batch + augment), median (and fastest) step seconds, µs per shape-vertex,
//! flops per shape-vertex, the achieved GFLOP/s and its ratio to the measured all-core FMA rate
//! (and to faer's all-core GEMM rate), the arithmetic limit in µs per shape-vertex (flops ÷ the
//! all-core FMA rate), the memory limit (the estimated bytes of [`step_bytes`] ÷ the all-core
//! triad bandwidth), and the step's phases (forward/backward, update of `C`).

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use meshdeco::mesh::primitives::icosphere;
use meshdeco::nn::rng::Rng;
use meshdeco::nn::{AutoencoderConfig, HopDistances, NeighborIndex, Trainer, TrainingData};
use meshdeco::representation::Features;
use rayon::prelude::*;

/// Arithmetic operations of one `kernels::tanh_f32` (branch-free: both branches are computed):
/// x², the x⁹ Taylor polynomial (9), 2|x| (1), the range reduction (7), the degree-7 polynomial
/// of e^r (14), the scaling (1) and 1 − 2/(e + 1) (3); the divide counts as one.
const TANH_FLOPS: f64 = 36.0;

/// Flops of one training step of the hand engine (fused path: linear encoder,
/// `lambda_orthogonal = 0`), `K` components, `L` layers, mean vertex degree `d`.
#[derive(Debug, Clone, Copy)]
struct StepFlops {
    /// Per shape-vertex: the six products with `C` (encode `C·F`, decode `Cᵀ·Z`, `dZ = C·dF̂`,
    /// `dF = Cᵀ·dZ`, and `∂L/∂C = Z·dF̂ᵀ + dZ·Fᵀ`), each `K·9` multiply-adds: `108·K`.
    latent: f64,
    /// Per shape-vertex: convolutions, neighbour means, tanh, loss and their backward passes.
    layers: f64,
    /// Per vertex (independent of the batch): the fused sparsity gradient + Adam + squared norms
    /// of `C` (156 per vertex and component) and the sparsity term's value (3): `159·K`.
    per_vertex: f64,
}

impl StepFlops {
    /// Total per shape-vertex with `b` shapes per step.
    fn per_shape_vertex(&self, b: usize) -> f64 {
        self.latent + self.layers + self.per_vertex / b as f64
    }
}

/// The count (see the report of issue 57 item 3 for its derivation, kernel by kernel).
fn step_flops(k: usize, d: f64, l: usize) -> StepFlops {
    let (k, lf) = (k as f64, l as f64);
    // Encoder layers with tanh: all of them for L = 1, all but the last otherwise.
    let te = if l == 1 { 1.0 } else { lf - 1.0 };
    let mean = 9.0 * (d + 1.0); // mean_rows: d adds + one scale per channel
    let conv = 324.0; // conv_rows: 9 × 9 × 2 multiply-adds
    let wgrad = 333.0; // weight_grad_rows: two 9 × 9 outer products + 9 bias sums
    let igrad = 324.0; // input_grad_rows: two 9 × 9 transposed products
    let mean_t = 18.0 * d; // mean_rows_transpose_add: d multiply-adds per channel
    let tanh_bw = 27.0; // tanh_backward: 1 − y², times dy
    let loss = 45.0; // squared_error: difference, mask, square-add, scale
    let forward = 2.0 * lf * (mean + conv) + 9.0 * TANH_FLOPS * (lf + te) + loss;
    let backward = lf * (tanh_bw + wgrad + igrad + mean_t) // decoder
        + te * tanh_bw + lf * wgrad + (lf - 1.0) * (igrad + mean_t); // encoder
    StepFlops { latent: 108.0 * k, layers: forward + backward, per_vertex: 159.0 * k }
}

/// Estimated memory traffic of one step per shape-vertex, bytes: every pass over a batch buffer
/// (9 `f32` per shape-vertex) that the kernels make, counted once (38 for L = 1, 34 more per
/// layer), plus ten passes over `C`-sized arrays per vertex (four products read `C`; the fused
/// update reads and writes `C` and both Adam moments), shared by the `b` shapes.
fn step_bytes(k: usize, l: usize, b: usize) -> f64 {
    let act_passes = 38.0 + 34.0 * (l as f64 - 1.0);
    36.0 * act_passes + 10.0 * 36.0 * k as f64 / b as f64
}

// ---------------------------------------------------------------------------------------------
// The machine
// ---------------------------------------------------------------------------------------------

/// Independent chains of 8-lane multiply-adds (as `kernels::axpy` on `[f32; 8]` blocks).
const CHAINS: usize = 12;

#[inline(always)]
fn fma_chains_body(w: f32, x: &[f32; 8], iters: usize, fused: bool) -> f32 {
    let mut acc = [[0.0f32; 8]; CHAINS];
    for (i, a) in acc.iter_mut().enumerate() {
        a[0] = i as f32;
    }
    for _ in 0..iters {
        for a in acc.iter_mut() {
            for l in 0..8 {
                a[l] = if fused { w.mul_add(x[l], a[l]) } else { w * x[l] + a[l] };
            }
        }
    }
    acc.iter().flatten().sum()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn fma_chains_avx2(w: f32, x: &[f32; 8], iters: usize) -> f32 {
    fma_chains_body(w, x, iters, true)
}

/// `iters` rounds of [`CHAINS`] × 8 multiply-adds (2 flops each); returns a checksum.
fn fma_chains(w: f32, x: &[f32; 8], iters: usize) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has the features the function was compiled for.
        return unsafe { fma_chains_avx2(w, x, iters) };
    }
    fma_chains_body(w, x, iters, false)
}

/// Best of `reps` of `run` (which returns the flops or bytes it did), per second.
fn best_rate(reps: usize, mut run: impl FnMut() -> f64) -> f64 {
    let mut best = 0.0f64;
    for _ in 0..reps {
        let t = Instant::now();
        let work = run();
        best = best.max(work / t.elapsed().as_secs_f64());
    }
    best
}

/// FMA rate, flop/s: one thread, or every rayon thread at once.
fn fma_rate(all: bool) -> f64 {
    let iters = 4_000_000; // 0.77 Gflop per thread
    let x = [1.0f32, 0.5, 0.25, 0.125, 1.5, 0.75, 0.375, 0.1875];
    let w = 0.999_999f32;
    let flops = (iters * CHAINS * 8 * 2) as f64;
    best_rate(5, || {
        if all {
            let sums = rayon::broadcast(|_| fma_chains(black_box(w), black_box(&x), iters));
            black_box(sums);
            flops * rayon::current_num_threads() as f64
        } else {
            black_box(fma_chains(black_box(w), black_box(&x), iters));
            flops
        }
    })
}

/// faer's GEMM at the step's latent shapes, in cache (one `K × 9·512` tile of `C`, the tile of
/// the fused update, against `b` shapes): `Zᵀ = C·Fᵀ`, `F̂ᵀ = Cᵀ·Zᵀ` and `∂C = Zᵀ·dF̂`, flop/s of
/// the three together; one thread, or every rayon thread on its own tile at once.
fn gemm_rate(k: usize, b: usize, all: bool) -> f64 {
    let cols = 9 * 512;
    let run = || {
        let mut rng = Rng::new(3);
        let mut v = |len: usize| -> Vec<f32> { (0..len).map(|_| rng.uniform() as f32 - 0.5).collect() };
        let (c, f, z0) = (v(k * cols), v(cols * b), v(k * b));
        let (mut z, mut fh, mut dc) = (vec![0.0f32; k * b], vec![0.0f32; cols * b], vec![0.0f32; k * cols]);
        let reps = 30;
        for _ in 0..reps {
            let cm = MatRef::from_row_major_slice(&c, k, cols);
            let fm = MatRef::from_row_major_slice(&f, cols, b);
            let zm = MatRef::from_row_major_slice(&z0, k, b);
            matmul(MatMut::from_row_major_slice_mut(&mut z, k, b), Accum::Replace, cm, fm, 1.0f32, Par::Seq);
            matmul(
                MatMut::from_row_major_slice_mut(&mut fh, cols, b),
                Accum::Replace,
                cm.transpose(),
                zm,
                1.0f32,
                Par::Seq,
            );
            matmul(
                MatMut::from_row_major_slice_mut(&mut dc, k, cols),
                Accum::Add,
                zm,
                fm.transpose(),
                1.0f32,
                Par::Seq,
            );
        }
        black_box((&z, &fh, &dc));
        (reps * 3 * 2 * k * cols * b) as f64
    };
    best_rate(3, || if all { rayon::broadcast(|_| run()).iter().sum() } else { run() })
}

/// Triad bandwidth `a = b + s·c` over three arrays of 64 MiB, bytes/s (12 per element, the
/// write-allocate read not counted); one thread, or split over the rayon threads.
fn triad_rate(all: bool) -> f64 {
    let n = 16 << 20;
    let mut a = vec![0.0f32; n];
    let b: Vec<f32> = (0..n).map(|i| (i % 97) as f32).collect();
    let c: Vec<f32> = (0..n).map(|i| (i % 89) as f32).collect();
    let s = black_box(0.5f32);
    let bytes = 12.0 * n as f64;
    best_rate(5, || {
        let ch = 1 << 16;
        if all {
            a.par_chunks_mut(ch).zip(b.par_chunks(ch)).zip(c.par_chunks(ch)).for_each(|((a, b), c)| {
                for ((a, &b), &c) in a.iter_mut().zip(b).zip(c) {
                    *a = b + s * c;
                }
            });
        } else {
            for ((a, &b), &c) in a.iter_mut().zip(&b).zip(&c) {
                *a = b + s * c;
            }
        }
        black_box(&a);
        bytes
    })
}

// ---------------------------------------------------------------------------------------------
// The step
// ---------------------------------------------------------------------------------------------

/// Vertex count, triangles and a description of a mesh file, or of an icosphere when it is absent.
fn mesh(rel: &str, fallback_subdivisions: usize) -> (usize, Vec<[usize; 3]>, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    match meshdeco::mesh::load_mesh(&path) {
        Ok(m) => (m.n_vertices(), m.faces, rel.to_string()),
        Err(_) => {
            let s = icosphere(fallback_subdivisions);
            (s.n_vertices(), s.faces, format!("icosphere({fallback_subdivisions}) ({rel} absent)"))
        }
    }
}

struct Rates {
    fma: f64,
    gemm: f64,
    triad: f64,
}

fn time_case(rel: &str, fallback: usize, shapes: usize, steps: usize, rates: &Rates) -> meshdeco::Result<()> {
    let (n, faces, what) = mesh(rel, fallback);
    let nb = NeighborIndex::from_faces(n, &faces)?;
    let d = (0..n).map(|i| nb.neighbors(i).len()).sum::<usize>() as f64 / n as f64;
    let mut rng = Rng::new(1);
    let mut feats = Features::zeros(shapes, n, 9);
    for v in feats.data.iter_mut() {
        *v = rng.uniform() * 1.9 - 0.95;
    }
    let data = TrainingData::from_features(&feats)?;
    let dist = HopDistances::new(&nb);
    let cfg = AutoencoderConfig { batch_size: Some(shapes), ..AutoencoderConfig::default() };
    let (k, l) = (cfg.components, cfg.layers);
    let per_step = shapes.min(data.n_shapes()) + cfg.augment;
    let mut trainer = Trainer::new(cfg, &data, &nb, &dist)?;
    for _ in 0..3 {
        trainer.step()?;
    }
    let (mut total, mut fb, mut upd) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..steps {
        let t = Instant::now();
        trainer.step()?;
        total.push(t.elapsed().as_secs_f64());
        let p = trainer.last_step_timings();
        fb.push(p.forward_backward);
        upd.push(p.optimizer);
    }
    let fastest = total.iter().copied().fold(f64::INFINITY, f64::min);
    // The library's median (mean of the two middle values for even lengths); steps ≥ 1.
    let median = |v: &[f64]| meshdeco::pipeline::metrics_file::median(v).expect("at least one timed step");
    let (t, fb, upd) = (median(&total), median(&fb), median(&upd));
    let sv = (n * per_step) as f64;
    let flops = step_flops(k, d, l).per_shape_vertex(per_step);
    let achieved = flops * sv / t;
    let limit_us = flops / rates.fma * 1e6;
    let mem_us = step_bytes(k, l, per_step) / rates.triad * 1e6;
    println!(
        "| {what} | {n} | {d:.2} | {per_step} | {t:.4} ({fastest:.4}) | {:.3} | {flops:.0} | {:.2} | {:.3} ({:.3}) | {limit_us:.4} | {mem_us:.4} | {:.1} / {:.1} |",
        t / sv * 1e6,
        achieved / 1e9,
        achieved / rates.fma,
        achieved / rates.gemm,
        fb * 1e3,
        upd * 1e3,
    );
    Ok(())
}

fn main() -> meshdeco::Result<()> {
    let mut args = std::env::args().skip(1);
    let mut steps = 20usize;
    while let Some(a) = args.next() {
        if a == "--steps" {
            steps = args.next().and_then(|s| s.parse().ok()).unwrap_or(steps);
        }
    }
    let shapes = 32;
    let cfg = AutoencoderConfig::default();
    println!(
        "flops of one step (default config: L = {}, augment {}, tanh = {TANH_FLOPS} flops):",
        cfg.layers, cfg.augment
    );
    for k in [50, 41] {
        let f = step_flops(k, 6.0, cfg.layers);
        println!(
            "  K = {k}, d = 6: {:.0} (latent 108K) + {:.0} (layers) per shape-vertex + {:.0} (159K) per vertex \
             = {:.0} per shape-vertex at B = {shapes}; est. {:.0} bytes per shape-vertex",
            f.latent,
            f.layers,
            f.per_vertex,
            f.per_shape_vertex(shapes),
            step_bytes(k, cfg.layers, shapes),
        );
    }
    let threads = rayon::current_num_threads();
    let (fma1, fma_all) = (fma_rate(false), fma_rate(true));
    let (gemm1, gemm_all) = (gemm_rate(cfg.components, shapes, false), gemm_rate(cfg.components, shapes, true));
    let (triad1, triad_all) = (triad_rate(false), triad_rate(true));
    println!("machine ({threads} rayon threads), best of repeated runs:");
    println!("  FMA, 8-lane AVX2 chains:   {:.1} GFLOP/s on 1 thread, {:.1} on all", fma1 / 1e9, fma_all / 1e9);
    println!(
        "  faer GEMM, K {} × 9·512 × B {shapes}: {:.1} GFLOP/s on 1 thread, {:.1} on all",
        cfg.components,
        gemm1 / 1e9,
        gemm_all / 1e9
    );
    println!("  triad a = b + s·c, 64 MiB:  {:.1} GB/s on 1 thread, {:.1} on all", triad1 / 1e9, triad_all / 1e9);
    let rates = Rates { fma: fma_all, gemm: gemm_all, triad: triad_all };
    println!();
    println!(
        "| mesh | N | d | shapes/step | step s, median (fastest) | µs / shape-vertex | flops / shape-vertex | GFLOP/s | ÷ FMA peak (÷ GEMM) | limit µs/sv (FMA) | limit µs/sv (memory) | fwd+bwd / update ms |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    time_case("scape/1.obj", 4, shapes, steps, &rates)?;
    time_case("cactus/cactus0.ply", 5, shapes, steps, &rates)?;
    time_case("face-poses/1.obj", 6, shapes, (steps / 2).max(3), &rates)?;
    Ok(())
}
