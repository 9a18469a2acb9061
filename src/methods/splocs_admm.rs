//! Inner kernels of SPLOCS: the weight projections (Eqs. 3, 4), the block-coordinate weight
//! update in component space, and the fused group-ℓ1/ℓ2 proximal + dual update of one ADMM
//! iteration. Buffers are row-major K × (E·W) (components, dual, ...) or F × K (weights).

use super::WeightConstraint;

/// Projects one weight column onto the constraint set in place: `Nonnegative` →
/// max(0,w)/max(w) (all zero stays zero), `Signed` → w/max|w|.
pub(crate) fn project_weights(w: &mut [f64], constraint: WeightConstraint) {
    match constraint {
        WeightConstraint::Nonnegative => {
            let mut m = 0.0f64;
            for v in w.iter_mut() {
                *v = v.max(0.0);
                m = m.max(*v);
            }
            if m > 0.0 {
                for v in w.iter_mut() {
                    *v /= m;
                }
            }
        }
        WeightConstraint::Signed => {
            let m = w.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            if m > 0.0 {
                for v in w.iter_mut() {
                    *v /= m;
                }
            }
        }
        WeightConstraint::Unconstrained => {}
    }
}

/// One sweep of block-coordinate descent on the weights (F × K, row-major), each component in
/// turn, exactly the reference's sequential update but in K-space: with A = X·Cᵀ (F × K) and
/// G = C·Cᵀ (K × K), the residual product is R·C_k = A[:,k] − W·G[:,k], so
/// `opt = (A[:,k] − W·G[:,k]) / G_kk + W[:,k]`, then W[:,k] = P(opt). Components with
/// G_kk ≤ `zero_norm` get zero weights. `col` is an F-sized scratch buffer.
pub(crate) fn update_weights(
    weights: &mut [f64],
    xct: &[f64],
    cct: &[f64],
    f: usize,
    k: usize,
    constraint: WeightConstraint,
    zero_norm: f64,
    col: &mut [f64],
) {
    for c in 0..k {
        let g = cct[c * k + c];
        if g <= zero_norm {
            for r in 0..f {
                weights[r * k + c] = 0.0;
            }
            continue;
        }
        for r in 0..f {
            let wr = &weights[r * k..(r + 1) * k];
            let mut s = 0.0;
            for (j, wj) in wr.iter().enumerate() {
                s += wj * cct[j * k + c];
            }
            col[r] = (xct[r * k + c] - s) / g + wr[c];
        }
        project_weights(&mut col[..f], constraint);
        for r in 0..f {
            weights[r * k + c] = col[r];
        }
    }
}

/// Fused step after the C-update of one ADMM iteration, per group g = (k, e):
/// p = C + U; z = prox(p) = max(0, 1 − thr/‖p‖)·p with thr = Λ_k,e / ρ; U ← p − z;
/// T ← z − U (= Z − U, the right-hand side of the next C-update); C ← z.
/// Returns Σ Λ_k,e ‖z‖ (the sparsity term Ω(Z)).
pub(crate) fn prox_dual_step(c: &mut [f64], u: &mut [f64], t: &mut [f64], lambda: &[f64], rho: f64, width: usize) -> f64 {
    match width {
        3 => prox_dual_fixed::<3>(c, u, t, lambda, rho),
        9 => prox_dual_fixed::<9>(c, u, t, lambda, rho),
        _ => prox_dual_dyn(c, u, t, lambda, rho, width),
    }
}

#[inline(always)]
fn prox_group(c: &mut [f64], u: &mut [f64], t: &mut [f64], lam: f64, inv_rho: f64) -> f64 {
    let w = c.len();
    let mut n2 = 0.0;
    for q in 0..w {
        let p = c[q] + u[q];
        c[q] = p;
        n2 += p * p;
    }
    let thr = lam * inv_rho;
    if thr <= 0.0 {
        // z = p, U = 0, T = z
        for q in 0..w {
            u[q] = 0.0;
            t[q] = c[q];
        }
        return 0.0;
    }
    if n2 <= thr * thr {
        // z = 0, U = p, T = −p
        for q in 0..w {
            let p = c[q];
            u[q] = p;
            t[q] = -p;
            c[q] = 0.0;
        }
        return 0.0;
    }
    let n = n2.sqrt();
    let shrink = 1.0 - thr / n;
    for q in 0..w {
        let p = c[q];
        let z = shrink * p;
        let du = p - z;
        u[q] = du;
        t[q] = z - du;
        c[q] = z;
    }
    lam * (n - thr)
}

fn prox_dual_fixed<const W: usize>(c: &mut [f64], u: &mut [f64], t: &mut [f64], lambda: &[f64], rho: f64) -> f64 {
    let inv_rho = 1.0 / rho;
    let mut sparsity = 0.0;
    for (((cg, ug), tg), &lam) in
        c.chunks_exact_mut(W).zip(u.chunks_exact_mut(W)).zip(t.chunks_exact_mut(W)).zip(lambda)
    {
        sparsity += prox_group(cg, ug, tg, lam, inv_rho);
    }
    sparsity
}

fn prox_dual_dyn(c: &mut [f64], u: &mut [f64], t: &mut [f64], lambda: &[f64], rho: f64, w: usize) -> f64 {
    let inv_rho = 1.0 / rho;
    let mut sparsity = 0.0;
    for (((cg, ug), tg), &lam) in
        c.chunks_exact_mut(w).zip(u.chunks_exact_mut(w)).zip(t.chunks_exact_mut(w)).zip(lambda)
    {
        sparsity += prox_group(cg, ug, tg, lam, inv_rho);
    }
    sparsity
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projections() {
        let mut w = vec![-1.0, 2.0, 0.5];
        project_weights(&mut w, WeightConstraint::Nonnegative);
        assert_eq!(w, vec![0.0, 1.0, 0.25]);
        let mut w = vec![-4.0, 2.0, 0.5];
        project_weights(&mut w, WeightConstraint::Signed);
        assert_eq!(w, vec![-1.0, 0.5, 0.125]);
        let mut w = vec![-4.0, -2.0];
        project_weights(&mut w, WeightConstraint::Nonnegative);
        assert_eq!(w, vec![0.0, 0.0]);
    }

    #[test]
    fn prox_matches_closed_form() {
        // groups of width 3: one inside (Λ=0), one shrunk, one killed
        let mut c = vec![1.0, 0.0, 0.0, 3.0, 4.0, 0.0, 0.1, 0.0, 0.0];
        let mut u = vec![0.0; 9];
        let mut t = vec![0.0; 9];
        let lambda = [0.0, 10.0, 10.0];
        let s = prox_dual_step(&mut c, &mut u, &mut t, &lambda, 10.0, 3);
        // group 2: ‖p‖ = 5, thr = 1 → z = 0.8 p
        assert_eq!(&c[0..3], &[1.0, 0.0, 0.0]);
        assert!((c[3] - 2.4).abs() < 1e-15 && (c[4] - 3.2).abs() < 1e-15);
        assert_eq!(&c[6..9], &[0.0, 0.0, 0.0]);
        assert!((u[3] - 0.6).abs() < 1e-15 && (u[6] - 0.1).abs() < 1e-15);
        assert!((t[3] - (2.4 - 0.6)).abs() < 1e-15);
        assert!((s - 10.0 * 4.0).abs() < 1e-12);
        // dynamic width agrees with the fixed-width kernel
        let mut c2 = vec![1.0, 0.0, 0.0, 3.0, 4.0, 0.0, 0.1, 0.0, 0.0];
        let (mut u2, mut t2) = (vec![0.0; 9], vec![0.0; 9]);
        let s2 = prox_dual_dyn(&mut c2, &mut u2, &mut t2, &lambda, 10.0, 3);
        assert_eq!((c, u, t, s), (c2, u2, t2, s2));
    }

    #[test]
    fn weight_sweep_matches_residual_form() {
        // F=3, K=2, D=4
        let x = [1.0, 2.0, 0.0, -1.0, 0.5, 0.0, 1.0, 1.0, -2.0, 1.0, 0.0, 0.0];
        let c = [1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, -1.0];
        let (f, k, d) = (3, 2, 4);
        let mut w_res = vec![0.3, 0.2, 0.1, 0.9, 0.5, 0.5];
        let mut w_gram = w_res.clone();
        // residual form, as in the reference
        for kk in 0..k {
            let ck = &c[kk * d..(kk + 1) * d];
            let n: f64 = ck.iter().map(|v| v * v).sum();
            let mut col = vec![0.0; f];
            for r in 0..f {
                let mut rc = 0.0;
                for j in 0..d {
                    let mut res = x[r * d + j];
                    for q in 0..k {
                        if q != kk {
                            res -= w_res[r * k + q] * c[q * d + j];
                        }
                    }
                    rc += res * ck[j];
                }
                col[r] = rc / n;
            }
            project_weights(&mut col, WeightConstraint::Signed);
            for r in 0..f {
                w_res[r * k + kk] = col[r];
            }
        }
        let mut xct = vec![0.0; f * k];
        let mut cct = vec![0.0; k * k];
        for r in 0..f {
            for q in 0..k {
                xct[r * k + q] = (0..d).map(|j| x[r * d + j] * c[q * d + j]).sum();
            }
        }
        for a in 0..k {
            for b in 0..k {
                cct[a * k + b] = (0..d).map(|j| c[a * d + j] * c[b * d + j]).sum();
            }
        }
        let mut col = vec![0.0; f];
        update_weights(&mut w_gram, &xct, &cct, f, k, WeightConstraint::Signed, 1e-8, &mut col);
        for (a, b) in w_res.iter().zip(&w_gram) {
            assert!((a - b).abs() < 1e-12, "{w_res:?} vs {w_gram:?}");
        }
    }
}
