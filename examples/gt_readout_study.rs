//! Diagnosis of issue 53 (docs/ground-truth.md, "Span or mixing?"): for a trained model and a
//! planted set, how much of each true field the span of the component fields holds (relative
//! least-squares residual), and how the recovery scores change when each decoded component
//! field loses a global rigid motion (Kabsch on all vertices, or on the half that moves least).
//!
//! `cargo run --release --example gt_readout_study -- MODEL_DIR TRUTH_DIR [STEP]`
//! (STEP: the dial step of the readout, default 1 as `meshdeco eval` reads components).
use faer::linalg::solvers::Solve;
use meshdeco::eval::planted::Truth;
use meshdeco::geometry::rigid_align::{kabsch, kabsch_weighted};
use meshdeco::math::vec3::{norm, sub};
use meshdeco::metrics::recovery::{best_matches, summarize};
use meshdeco::pipeline::registry::load_model;
type V = [f64; 3];

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

/// Kaiser's raw varimax rotation of the columns of `y` (F × K): the orthogonal R maximising
/// Σ_k var_f((Y·R)_fk²), so that each rotated column is large in few rows (frames).
fn varimax(y: &faer::Mat<f64>) -> faer::Mat<f64> {
    let (f, k) = (y.nrows(), y.ncols());
    let mut r = faer::Mat::<f64>::identity(k, k);
    let mut last = 0.0;
    for _ in 0..500 {
        let l = y * &r;
        let mut target = faer::Mat::<f64>::zeros(f, k);
        for c in 0..k {
            let m2 = (0..f).map(|i| l[(i, c)] * l[(i, c)]).sum::<f64>() / f as f64;
            for i in 0..f {
                target[(i, c)] = l[(i, c)].powi(3) - l[(i, c)] * m2;
            }
        }
        let g = y.transpose() * &target;
        let svd = g.thin_svd().expect("SVD of a K × K matrix");
        r = svd.U() * svd.V().transpose();
        let obj: f64 = (0..k).map(|c| svd.S()[c]).sum();
        if (obj - last).abs() <= 1e-10 * obj.abs() {
            break;
        }
        last = obj;
    }
    r
}

/// Sparse non-negative dictionary of the codes: Y (F × K) ≈ W·A with W ≥ 0 (F × M), rows of A
/// (M × K) of unit norm, minimising ½‖Y − W·A‖² + λ·Σ W (alternating: projected ISTA on W,
/// least squares on A). Starts from `a0`. Returns A and W.
fn sparse_dictionary(y: &faer::Mat<f64>, a0: faer::Mat<f64>, lambda: f64) -> (faer::Mat<f64>, faer::Mat<f64>) {
    let mut a = a0;
    let mut w = (y * a.transpose()).to_owned();
    for v in w.col_iter_mut() {
        for x in v.iter_mut() {
            *x = x.max(0.0);
        }
    }
    for _ in 0..200 {
        let aat = &a * a.transpose();
        let lip = aat.norm_l2().max(1e-12) * 1.01;
        let ya = y * a.transpose();
        for _ in 0..20 {
            let grad = &w * &aat - &ya;
            for j in 0..w.ncols() {
                for i in 0..w.nrows() {
                    w[(i, j)] = (w[(i, j)] - (grad[(i, j)] + lambda) / lip).max(0.0);
                }
            }
        }
        // Least squares for A, ridge-regularised (an atom no frame uses keeps its direction).
        let mut wtw = w.transpose() * &w;
        let tr = (0..wtw.nrows()).map(|i| wtw[(i, i)]).sum::<f64>().max(1e-30);
        let eps = 1e-6 * tr / wtw.nrows() as f64;
        for i in 0..wtw.nrows() {
            wtw[(i, i)] += eps;
        }
        let wty = w.transpose() * y + &a * faer::Scale(eps);
        a = wtw.llt(faer::Side::Lower).expect("WᵀW + εI is positive definite").solve(&wty);
        for r in 0..a.nrows() {
            let n = (0..a.ncols()).map(|c| a[(r, c)] * a[(r, c)]).sum::<f64>().sqrt();
            if n > 1e-12 {
                for c in 0..a.ncols() {
                    a[(r, c)] /= n;
                }
                for i in 0..w.nrows() {
                    w[(i, r)] *= n;
                }
            }
        }
    }
    (a, w)
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
    let d0 = model.dials(&w0)?;
    let base = model.decode(std::slice::from_ref(&w0))?.remove(0);
    let k = model.n_components();
    let mut plain = vec![];
    let mut rigid = vec![];
    let mut robust = vec![];
    for i in 0..k {
        let mut d = d0.clone();
        d[i] += step;
        let mut w = w0.clone();
        w[i] = model.synthesis_weights(&d)?[i];
        let shape = model.decode(&[w])?.remove(0);
        let mut f: Vec<V> = shape.iter().zip(&base).map(|(a, b)| sub(*a, *b)).collect();
        meshdeco::metrics::recovery::remove_median_translation(&mut f);
        plain.push(f);
        let al = kabsch(&shape, &base).apply_all(&shape);
        rigid.push(al.iter().zip(&base).map(|(a, b)| sub(*a, *b)).collect::<Vec<V>>());
        let rb = robust_align(&shape, &base);
        robust.push(rb.iter().zip(&base).map(|(a, b)| sub(*a, *b)).collect::<Vec<V>>());
    }
    // Readout 4: the latent space rotated (an orthogonal Q: C ← Q·C leaves the tied network's
    // function unchanged) so that the training codes, around the rest code, are sparse
    // (varimax); each rotated axis read at its training extreme.
    let mut rotated = vec![];
    let wfile = std::path::Path::new(&a[1]).join("weights.csv");
    if let Ok(text) = std::fs::read_to_string(&wfile) {
        let codes: Vec<Vec<f64>> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').skip(1).map(|x| x.parse::<f64>()).collect::<Result<Vec<_>, _>>())
            .collect::<Result<_, _>>()?;
        let y = faer::Mat::<f64>::from_fn(codes.len(), k, |i, c| codes[i][c] - w0[c]);
        let r = varimax(&y);
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
        // Readout 5: a sparse non-negative dictionary of the codes, from the varimax axes
        // (signed so that each axis's extreme is positive).
        let ymax =
            (0..y.nrows()).flat_map(|i| (0..k).map(move |c| (i, c))).map(|(i, c)| y[(i, c)].abs()).fold(0.0, f64::max);
        for share in [0.003, 0.01, 0.03, 0.1] {
            let a0 = faer::Mat::<f64>::from_fn(k, k, |m, c| {
                let ext = (0..yr.nrows()).map(|i| yr[(i, m)]).max_by(|a, b| a.abs().total_cmp(&b.abs())).unwrap_or(1.0);
                r[(c, m)] * ext.signum()
            });
            let (dict, wts) = sparse_dictionary(&y, a0, share * ymax);
            let mut batch = vec![];
            for m in 0..k {
                let ext = (0..wts.nrows()).map(|i| wts[(i, m)]).fold(0.0, f64::max).max(1e-9);
                batch.push((0..k).map(|j| w0[j] + step * ext * dict[(m, j)]).collect::<Vec<f64>>());
            }
            let mut fields = vec![];
            for shape in model.decode(&batch)? {
                let mut f: Vec<V> = shape.iter().zip(&base).map(|(a, b)| sub(*a, *b)).collect();
                meshdeco::metrics::recovery::remove_median_translation(&mut f);
                fields.push(f);
            }
            let nz =
                (0..wts.nrows()).flat_map(|i| (0..k).map(move |c| (i, c))).filter(|&(i, c)| wts[(i, c)] > 1e-9).count();
            let resid = (&y - &wts * &dict).norm_l2() / y.norm_l2();
            let s = summarize(&best_matches(&truth.fields, &fields)?, &truth.counted());
            println!(
                "  sparse dictionary λ {share} × max: found {}/{} median|cos| {:.3} iou {:.2}; codes nonzero per frame {:.1}, code residual {:.3}",
                s.found,
                s.counted,
                s.median_abs_cos,
                s.median_iou,
                nz as f64 / wts.nrows() as f64,
                resid
            );
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
        let mut ss: Vec<f64> =
            fields.iter().map(|f| meshdeco::metrics::recovery::support_size(f) as f64 / f.len() as f64).collect();
        ss.sort_by(|a, b| a.total_cmp(b));
        println!(
            "{name:>20}: found {}/{} median|cos| {:.3} iou {:.2} support {:.1} %",
            s.found,
            s.counted,
            s.median_abs_cos,
            s.median_iou,
            100.0 * ss[ss.len() / 2]
        );
    }
    Ok(())
}
