//! Diagnosis of issue 53 (docs/ground-truth.md, "Span or mixing?"): for a trained model and a
//! planted set, how much of each true field the span of the component fields holds (relative
//! least-squares residual), and how the recovery scores change when each decoded component
//! field loses a global rigid motion (Kabsch on all vertices, or on the half that moves least).
//!
//! Also: the varimax rotation of the latent space (read from the cell's training codes,
//! `weights.csv`). The dial bases `dial_sparsity = "auto"` tries, and its score, are read by
//! `examples/dial_rule_study.rs` (until issue 53's rule, this example refitted them itself).
//!
//! `cargo run --release --example gt_readout_study -- MODEL_DIR TRUTH_DIR [STEP]`
//! (STEP: the dial step of the readout, default 1 as `meshdeco eval` reads components).
use meshdeco::eval::planted::Truth;
use meshdeco::geometry::rigid_align::{kabsch, kabsch_weighted};
use meshdeco::math::vec3::{norm, sub};
use meshdeco::methods::sparse_dials::varimax;
use meshdeco::metrics::recovery::{best_matches, summarize};
use meshdeco::pipeline::registry::load_model;
type V = [f64; 3];

/// Median over the fields of the share of vertices a field moves by more than 5 % of its peak.
fn median_support(fields: &[Vec<V>]) -> f64 {
    let mut ss: Vec<f64> =
        fields.iter().map(|f| meshdeco::metrics::recovery::support_size(f) as f64 / f.len() as f64).collect();
    ss.sort_by(|a, b| a.total_cmp(b));
    ss[ss.len() / 2]
}

fn robust_align(shape: &[V], base: &[V]) -> Vec<V> {
    // Rigid motion fitted on the vertices that move least (the field's complement), iterated.
    let mut cur = kabsch(shape, base).apply_all(shape);
    for _ in 0..5 {
        let mut d: Vec<f64> = cur.iter().zip(base).map(|(a, b)| norm(sub(*a, *b))).collect();
        let mut s = d.clone();
        s.sort_by(|a, b| a.total_cmp(b));
        let q = s[s.len() / 2];
        for x in d.iter_mut() {
            *x = if *x <= q { 1.0 } else { 0.0 };
        }
        cur = kabsch_weighted(shape, base, &d).expect("weights are 0 or 1").apply_all(shape);
    }
    cur
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        return Err("usage: gt_readout_study MODEL_DIR TRUTH_DIR [STEP]".into());
    }
    let model = load_model(std::path::Path::new(&a[1]))?;
    let truth = Truth::load(std::path::Path::new(&a[2]))?;
    let step: f64 = match a.get(3) {
        Some(s) => s.parse().map_err(|_| format!("STEP `{s}` is not a number"))?,
        None => 1.0,
    };
    let rest = model.rest();
    let w0 = model.start_weights(Some(&rest.positions))?;
    let base = model.decode(std::slice::from_ref(&w0))?.remove(0);
    let k = model.n_components();
    let mut plain = vec![];
    let mut rigid = vec![];
    let mut robust = vec![];
    for w in meshdeco::model::component_weights(model.as_ref(), &w0, step)? {
        let shape = model.decode(&[w])?.remove(0);
        let mut f: Vec<V> = shape.iter().zip(&base).map(|(a, b)| sub(*a, *b)).collect();
        meshdeco::metrics::recovery::remove_median_translation(&mut f);
        plain.push(f);
        let al = kabsch(&shape, &base).apply_all(&shape);
        rigid.push(al.iter().zip(&base).map(|(a, b)| sub(*a, *b)).collect::<Vec<V>>());
        let rb = robust_align(&shape, &base);
        robust.push(rb.iter().zip(&base).map(|(a, b)| sub(*a, *b)).collect::<Vec<V>>());
    }
    // Readout 4: the latent space rotated by varimax (an orthogonal Q: C ← Q·C leaves the tied
    // network's function unchanged), each rotated axis read at its training extreme.
    let mut rotated = vec![];
    let wfile = std::path::Path::new(&a[1]).join("weights.csv");
    if wfile.is_file() {
        let codes = meshdeco::artifact::read_weights_csv(&wfile)?.weights;
        if codes.first().is_some_and(|c| c.len() < k) {
            return Err(format!("{}: fewer than {k} codes per frame", wfile.display()).into());
        }
        let y = faer::Mat::<f64>::from_fn(codes.len(), k, |i, c| codes[i][c] - w0[c]);
        let r = varimax(&y)?;
        let yr = &y * &r;
        let mut batch = vec![];
        for c in 0..k {
            let ext = (0..yr.nrows()).map(|i| yr[(i, c)]).max_by(|a, b| a.abs().total_cmp(&b.abs())).unwrap_or(1.0);
            batch.push((0..k).map(|j| w0[j] + step * ext * r[(j, c)]).collect::<Vec<f64>>());
        }
        for shape in model.decode(&batch)? {
            let mut f: Vec<V> = shape.iter().zip(&base).map(|(a, b)| sub(*a, *b)).collect();
            meshdeco::metrics::recovery::remove_median_translation(&mut f);
            rotated.push(f);
        }
    }
    let counted = truth.counted();
    // How much of each true field the span of the component fields holds (least squares).
    let n3 = plain[0].len() * 3;
    let a = faer::Mat::<f64>::from_fn(n3, k, |r, c| plain[c][r / 3][r % 3]);
    let qr = a.qr();
    let q = qr.compute_thin_Q();
    let mut res: Vec<f64> = truth
        .fields
        .iter()
        .map(|t| {
            let b = faer::Mat::<f64>::from_fn(n3, 1, |r, _| t[r / 3][r % 3]);
            let proj = &q * (q.transpose() * &b);
            let r = &b - &proj;
            r.norm_l2() / b.norm_l2()
        })
        .collect();
    res.sort_by(|a, b| a.total_cmp(b));
    println!(
        "span residual of true fields: median {:.3}, max {:.3}, min {:.3}",
        res[res.len() / 2],
        res[res.len() - 1],
        res[0]
    );
    for (name, fields) in
        [("median translation", &plain), ("kabsch", &rigid), ("robust kabsch", &robust), ("varimax codes", &rotated)]
    {
        if fields.is_empty() {
            continue;
        }
        let m = best_matches(&truth.fields, fields)?;
        let s = summarize(&m, &counted);
        println!(
            "{name:>20}: found {}/{} median|cos| {:.3} iou {:.2} support {:.1} %",
            s.found,
            s.counted,
            s.median_abs_cos,
            s.median_iou,
            100.0 * median_support(fields)
        );
    }
    Ok(())
}
