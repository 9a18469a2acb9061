use std::time::Instant;
fn main() {
    let mut v: Vec<f32> = (0..1_000_000).map(|i| ((i % 2000) as f32 - 1000.0) * 0.003).collect();
    for _ in 0..5 {
        let t0 = Instant::now();
        meshdeco::nn::kernels::tanh_slice(&mut v);
        println!("tanh_slice 1M: {:.3} ms ({})", t0.elapsed().as_secs_f64() * 1e3, v[12345]);
    }
    let mut w: Vec<f32> = (0..1_000_000).map(|i| ((i % 2000) as f32 - 1000.0) * 0.003).collect();
    let t0 = Instant::now();
    for x in w.iter_mut() { *x = x.tanh(); }
    println!("std tanh 1M: {:.3} ms", t0.elapsed().as_secs_f64() * 1e3);
}
