//! The first drag a new user makes (docs/posing-drag-bench.md, "The first drag a new user
//! makes"): one pin on each of the model's vertices V dragged AMOUNT from the neutral shape,
//! along ±x, ±y, ±z (six drags) or along one direction DIR, posed with the model kind's
//! defaults (`meshdeco pose`'s; or the options given). AMOUNT is in data units, or a share of the
//! rest mesh's bounding-box diagonal when it ends in `%`. Prints per drag: landing error (% of the
//! drag), largest motion of any vertex ÷ the drag, the share of vertices moved more than half the
//! drag; then the medians and the largest.
//! `cargo run --release --example first_drag -- MODEL [V[,V…] 1467] [AMOUNT 0.2] [DIR x,y,z | axes] [gamma beta spread prior reach]`
//! Issue 54's example (non-negative SCAPE SPLOCS, `configs/scape-splocs.toml`):
//! `first_drag MODEL 1467,500,1800 10% 0.1083,0,0.2047`.
use meshdeco::mesh::dist;
use meshdeco::model::{PosePrior, landed_pose, spreader};
use meshdeco::pipeline::load_model;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: first_drag MODEL [V[,V…]] [AMOUNT[%]] [DIR x,y,z | axes] [gamma beta spread prior reach]";
    let model = load_model(std::path::Path::new(a.first().ok_or(usage)?))?;
    let vertices: Vec<usize> =
        a.get(1).map_or("1467", |s| s.as_str()).split(',').map(|s| s.trim().parse()).collect::<Result<_, _>>()?;
    let (lo, hi) = model.rest().bounding_box();
    let amount: f64 = match a.get(2).map_or("0.2", |s| s.as_str()) {
        s if s.ends_with('%') => s.trim_end_matches('%').parse::<f64>()? / 100.0 * dist(lo, hi),
        s => s.parse()?,
    };
    let dirs: Vec<(String, [f64; 3])> = match a.get(3).map(|s| s.as_str()) {
        None | Some("axes") => {
            [("+x", 0, 1.0), ("−x", 0, -1.0), ("+y", 1, 1.0), ("−y", 1, -1.0), ("+z", 2, 1.0), ("−z", 2, -1.0)]
                .iter()
                .map(|&(n, axis, sign)| {
                    let mut d = [0.0; 3];
                    d[axis] = sign;
                    (n.to_string(), d)
                })
                .collect()
        }
        Some(s) => {
            let c: Vec<f64> = s.split(',').map(|x| x.trim().parse()).collect::<Result<_, _>>()?;
            let l = (c.iter().map(|x| x * x).sum::<f64>()).sqrt();
            if c.len() != 3 || l.is_nan() || l <= 0.0 {
                return Err(format!("DIR `{s}`: three numbers, not all 0").into());
            }
            vec![(s.to_string(), [c[0] / l, c[1] / l, c[2] / l])]
        }
    };
    let mut o = model.pose_defaults();
    if let Some(g) = a.get(4) {
        o.gamma = g.parse()?;
    }
    if let Some(b) = a.get(5) {
        o.beta = b.parse()?;
    }
    if let Some(s) = a.get(6) {
        o.spread = s.parse()?;
    }
    if let Some(p) = a.get(7) {
        o.prior = PosePrior::parse(p).ok_or("prior: shape, weights or data")?;
    }
    if let Some(r) = a.get(8) {
        o.reach = r.parse()?;
    }
    o.validate()?;
    let w0 = model.start_weights(None)?;
    let p0 = model.decode(std::slice::from_ref(&w0))?.remove(0);
    let sp = spreader(model.as_ref());
    println!(
        "pose options: prior {} γ {} β {} spread {} reach {}; drag {amount:.4} data units",
        o.prior.name(),
        o.gamma,
        o.beta,
        o.spread,
        o.reach
    );
    println!("| vertex | drag | landing % | max motion ÷ drag | moved > ½ drag |\n|---:|---|---:|---:|---:|");
    let (mut ratios, mut shares) = (Vec::new(), Vec::new());
    for &v in &vertices {
        if v >= p0.len() {
            return Err(format!("vertex {v}: the model has {} vertices", p0.len()).into());
        }
        for (name, d) in &dirs {
            let t = [p0[v][0] + amount * d[0], p0[v][1] + amount * d[1], p0[v][2] + amount * d[2]];
            let r = landed_pose(model.as_ref(), &sp, &[v], &[t], &w0, &o)?;
            let motion: Vec<f64> = r.positions.iter().zip(&p0).map(|(p, q)| dist(*p, *q)).collect();
            let ratio = motion.iter().cloned().fold(0.0, f64::max) / amount;
            let share = motion.iter().filter(|&&m| m > 0.5 * amount).count() as f64 / motion.len() as f64;
            println!(
                "| {v} | {name} | {:.3} | {ratio:.2} | {:.1} % |",
                100.0 * dist(r.positions[v], t) / amount,
                100.0 * share
            );
            ratios.push(ratio);
            shares.push(share);
        }
    }
    let median = |x: &mut Vec<f64>| {
        x.sort_by(f64::total_cmp);
        let n = x.len();
        if n % 2 == 1 { x[n / 2] } else { 0.5 * (x[n / 2 - 1] + x[n / 2]) }
    };
    let (rmax, smax) = (ratios.iter().cloned().fold(0.0, f64::max), shares.iter().cloned().fold(0.0, f64::max));
    println!(
        "medians: max motion ÷ drag {:.2}, moved {:.1} %; largest: {rmax:.2}, {:.1} %",
        median(&mut ratios),
        100.0 * median(&mut shares),
        100.0 * smax
    );
    Ok(())
}
