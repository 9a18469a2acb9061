//! Single-point guards of numerical details (issue 33): cases built so that one plausible bug
//! changes the answer. The PCA mean, on data whose mean is *not* in the span of the variation
//! (so a wrong or missing mean cannot be absorbed by the components), and STED's temporal δ² on a
//! hand case with δ ≠ 1 (so δ and δ² differ).

use meshdeco::methods::{DataMatrix, Pca, PcaConfig};
use meshdeco::metrics::{FrameOrder, StedParams, sted};

#[test]
fn pca_offset_is_the_data_mean_and_one_component_reproduces_rank_one_data() {
    // 4 elements × 3 numbers; frames = m + a_f·u with m ⟂ u and a mean of a_f that is not 0,
    // so the data mean m + ā·u is neither 0 nor m.
    let m: Vec<f64> = (0..12).map(|i| 5.0 + (i % 3) as f64 - 0.5 * (i / 3) as f64).collect();
    let mut u: Vec<f64> = (0..12).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
    // Make u ⟂ m (Gram–Schmidt), so the mean is outside the component's span.
    let mu: f64 = m.iter().zip(&u).map(|(a, b)| a * b).sum::<f64>() / m.iter().map(|a| a * a).sum::<f64>();
    for (x, a) in u.iter_mut().zip(&m) {
        *x -= mu * a;
    }
    let a = [0.3, 1.7, 2.2, -0.4, 1.1];
    let x: Vec<f64> = a.iter().flat_map(|&af| m.iter().zip(&u).map(move |(mi, ui)| mi + af * ui)).collect();
    let model =
        Pca::fit(DataMatrix::new(&x, a.len(), 4, 3).unwrap(), &PcaConfig { components: 1, ..Default::default() })
            .unwrap();
    let abar = a.iter().sum::<f64>() / a.len() as f64;
    for i in 0..12 {
        let mean = m[i] + abar * u[i];
        assert!((model.offset[i] - mean).abs() < 1e-12, "offset[{i}] = {} vs the data mean {mean}", model.offset[i]);
    }
    // offset + w_f·c reproduces every frame (rank 1 after centring).
    let c = model.component(0);
    for (f, row) in x.chunks_exact(12).enumerate() {
        let w = model.weights[f];
        for i in 0..12 {
            let rec = model.offset[i] + w * c[i];
            assert!((rec - row[i]).abs() < 1e-10, "frame {f}, number {i}: {rec} vs {}", row[i]);
        }
    }
}

#[test]
fn sted_temporal_uses_delta_squared_with_delta_the_mean_first_frame_edge() {
    // One equilateral triangle of side 2: the mean edge length, hence δ (temporal scale 1), is 2.
    let h = 3f64.sqrt();
    let frame0 = vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, h, 0.0]];
    let mut truth1 = frame0.clone();
    truth1[2][2] += 3.0; // vertex 2 moves 3 (the triangle deforms)
    let mut result1 = frame0.clone();
    result1[2][2] += 4.0; // the result moves it 4
    let faces = [[0, 1, 2]];
    let params = StedParams { rings: 1, temporal_scale: 1.0, c: 0.5 };
    let r = sted(&faces, &[frame0.clone(), truth1], &[frame0, result1], params, FrameOrder::Sequence).unwrap();
    // Vertex 2: t = sqrt(3² + 2²), t' = sqrt(4² + 2²); the other vertices do not move (no error).
    let (t, tr) = ((9.0f64 + 4.0).sqrt(), (16.0f64 + 4.0).sqrt());
    let want = ((tr - t).abs() / t) / 3.0;
    let got = r.temporal.unwrap();
    assert!((got - want).abs() < 1e-12, "temporal STED {got}, expected {want} (δ = 2, δ² = 4)");
}
