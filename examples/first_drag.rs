//! The first drag a new user makes (docs/posing-drag-bench.md, "The first drag a new user
//! makes"): one pin on a model's vertex V dragged AMOUNT data units along each of ±x, ±y, ±z from
//! the neutral shape, posed with `meshdeco pose`'s defaults (or the options given). Prints per
//! drag: landing error (% of the drag), largest motion of any vertex ÷ the drag, the share of
//! vertices moved more than half the drag; then the medians.
//! `cargo run --release --example first_drag -- MODEL [V 1467] [AMOUNT 0.2] [gamma beta spread prior]`
use meshdeco::mesh::dist;
use meshdeco::model::{PoseOptions, PosePrior, landed_pose, spreader};
use meshdeco::pipeline::load_model;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let model = load_model(std::path::Path::new(
        a.first().ok_or("usage: first_drag MODEL [V] [AMOUNT] [gamma beta spread prior]")?,
    ))?;
    let v: usize = a.get(1).map_or(Ok(1467), |s| s.parse())?;
    let amount: f64 = a.get(2).map_or(Ok(0.2), |s| s.parse())?;
    let mut o = PoseOptions::default();
    if let Some(g) = a.get(3) {
        o.gamma = g.parse()?;
    }
    if let Some(b) = a.get(4) {
        o.beta = b.parse()?;
    }
    if let Some(s) = a.get(5) {
        o.spread = s.parse()?;
    }
    if let Some(p) = a.get(6) {
        o.prior = PosePrior::parse(p).ok_or("prior: shape or weights")?;
    }
    o.validate()?;
    let w0 = model.start_weights(None)?;
    let p0 = model.decode(std::slice::from_ref(&w0))?.remove(0);
    let sp = spreader(model.as_ref());
    println!("| drag | landing % | max motion ÷ drag | moved > ½ drag |\n|---|---:|---:|---:|");
    let (mut ratios, mut shares) = (Vec::new(), Vec::new());
    for (name, axis, sign) in
        [("+x", 0, 1.0), ("−x", 0, -1.0), ("+y", 1, 1.0), ("−y", 1, -1.0), ("+z", 2, 1.0), ("−z", 2, -1.0)]
    {
        let mut t = p0[v];
        t[axis] += sign * amount;
        let r = landed_pose(model.as_ref(), &sp, &[v], &[t], &w0, &o)?;
        let motion: Vec<f64> = r.positions.iter().zip(&p0).map(|(p, q)| dist(*p, *q)).collect();
        let ratio = motion.iter().cloned().fold(0.0, f64::max) / amount;
        let share = motion.iter().filter(|&&m| m > 0.5 * amount).count() as f64 / motion.len() as f64;
        println!("| {name} | {:.3} | {ratio:.2} | {:.1} % |", 100.0 * dist(r.positions[v], t) / amount, 100.0 * share);
        ratios.push(ratio);
        shares.push(share);
    }
    let median = |x: &mut Vec<f64>| {
        x.sort_by(f64::total_cmp);
        0.5 * (x[2] + x[3])
    };
    println!("medians: max motion ÷ drag {:.2}, moved {:.1} %", median(&mut ratios), 100.0 * median(&mut shares));
    Ok(())
}
