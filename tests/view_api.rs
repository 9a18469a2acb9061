//! `meshdeco view`'s HTTP API without a browser, as a script meets it: the binary started on a
//! free port with models trained here on the synthetic tube. Decoding equals `meshdeco
//! synthesize`; a pose lands the dragged vertex; heat maps equal the model's components; frames
//! come with their reconstruction and Erms; every kind of bad request gets a 400 (or 404 / 405 /
//! 413) with a message naming the problem and the next good request succeeds; Ctrl-C stops the
//! server with status 0.

mod common;
mod view_support;

use common::{fresh_dir, meshdeco, output_text};
use meshdeco::pipeline::load_model;
use serde_json::{Value, json};
use view_support::{Viewer, dist, f32s, header, max_diff, parse_shape, train};

fn obj_positions(path: &std::path::Path) -> Vec<[f64; 3]> {
    common::obj_vertices(path)
}

#[test]
fn view_api_serves_decode_pose_heat_frames_and_export() {
    let d = fresh_dir("view-api", "pca");
    let model = train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 8");
    let m = load_model(&model).unwrap();
    let k = m.n_components();
    let v = Viewer::start(&[model.to_str().unwrap(), "--data", "synthetic:tube"]);
    assert!(v.banner.contains("pca model"), "{}", v.banner);

    // The page and its script are served from the binary.
    let (s, h, body) = v.request("GET", "/", b"");
    assert_eq!(s, 200);
    assert!(header(&h, "content-type").unwrap().starts_with("text/html"));
    assert!(String::from_utf8_lossy(&body).contains("/app.js"));
    let (s, _, js) = v.request("GET", "/app.js", b"");
    assert_eq!(s, 200);
    assert!(String::from_utf8_lossy(&js).contains("webgl2"));

    // Description: components in rank order, ranges containing 0, frames of --data.
    let (s, _, body) = v.request("GET", "/api/model", b"");
    assert_eq!(s, 200);
    let desc: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(desc["n_vertices"], 1466);
    assert_eq!(desc["n_components"], k);
    assert_eq!(desc["up_axis"], 2, "the tube lies along z");
    let comps = desc["components"].as_array().unwrap();
    assert_eq!(comps.len(), k);
    for (r, c) in comps.iter().enumerate() {
        assert_eq!(c["rank"], r);
        let range = c["range"].as_array().unwrap();
        let (lo, hi) = (range[0].as_f64().unwrap(), range[1].as_f64().unwrap());
        assert!(lo < 0.0 && hi > 0.0 && lo.is_finite() && hi.is_finite(), "range {range:?}");
    }
    assert_eq!(desc["ranges_from"], "training weights");
    assert_eq!(desc["frames"]["names"].as_array().unwrap().len(), 60);

    // Faces and rest positions: binary, the model's.
    let rest = m.rest();
    let (_, _, faces) = v.request("GET", "/api/faces", b"");
    assert_eq!(faces.len(), 12 * rest.n_faces());
    assert_eq!(u32::from_le_bytes(faces[12..16].try_into().unwrap()) as usize, rest.faces[1][0]);
    let (_, _, rp) = v.request("GET", "/api/rest", b"");
    let rp: Vec<[f64; 3]> = f32s(&rp).chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    assert!(max_diff(&rp, &rest.positions) < 1e-6);

    // Decode = `meshdeco synthesize --weights`.
    let (s, h, body) = v.post("/api/decode", &json!({ "dials": { "1": 0.7, "3": -0.4 } }));
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&body));
    assert!(header(&h, "x-compute-ms").unwrap().parse::<f64>().unwrap() >= 0.0);
    let shape = parse_shape(&body);
    assert_eq!(shape.dials[1], 0.7);
    let o = meshdeco(&["synthesize", model.to_str().unwrap(), "--weights", "1:0.7,3:-0.4", "--out", "synth.obj"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let synth = obj_positions(&d.join("synth.obj"));
    let diff = max_diff(&shape.positions, &synth);
    assert!(diff < 1e-5, "decode differs from synthesize by {diff}");
    // The dense form, and weights in the model's coordinates, give the same shape.
    let mut dense = vec![0.0; k];
    dense[1] = 0.7;
    dense[3] = -0.4;
    let (_, _, b2) = v.post("/api/decode", &json!({ "dials": dense }));
    assert!(max_diff(&parse_shape(&b2).positions, &synth) < 1e-5);
    let (_, _, b3) = v.post("/api/decode", &json!({ "weights": shape.weights }));
    assert!(max_diff(&parse_shape(&b3).positions, &synth) < 1e-5);

    // Export: the weights JSON goes back through `synthesize --weights-file`; OBJ text equals it.
    let (s, _, wjson) = v.post("/api/export", &json!({ "format": "json", "dials": { "1": 0.7, "3": -0.4 } }));
    assert_eq!(s, 200);
    std::fs::write(d.join("weights.json"), &wjson).unwrap();
    let o =
        meshdeco(&["synthesize", model.to_str().unwrap(), "--weights-file", "weights.json", "--out", "back.obj"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    assert!(max_diff(&obj_positions(&d.join("back.obj")), &synth) < 1e-12);
    let (s, _, obj) = v.post("/api/export", &json!({ "format": "obj", "dials": { "1": 0.7, "3": -0.4 } }));
    assert_eq!(s, 200);
    std::fs::write(d.join("export.obj"), &obj).unwrap();
    assert!(max_diff(&obj_positions(&d.join("export.obj")), &synth) < 1e-12);
    let (s, _, ply) = v.post("/api/export", &json!({ "format": "ply", "weights": shape.weights }));
    assert_eq!(s, 200);
    std::fs::write(d.join("export.ply"), &ply).unwrap();
    assert!(max_diff(&meshdeco::mesh::load_mesh(&d.join("export.ply")).unwrap().positions, &synth) < 1e-12);

    // Pose: the tip of the tube dragged sideways lands (the landing correction, on by default).
    let tip = (0..rest.n_vertices()).max_by(|&a, &b| rest.positions[a][2].total_cmp(&rest.positions[b][2])).unwrap();
    let start = m.decode(&[m.start_weights(None).unwrap()]).unwrap().remove(0);
    let target = [start[tip][0], start[tip][1] + 0.1, start[tip][2]];
    let pose = |spread: Option<f64>| {
        let mut req =
            json!({ "constraints": [{ "vertex": tip, "target": target }], "start": m.start_weights(None).unwrap() });
        if let Some(s) = spread {
            req["spread"] = json!(s);
        }
        let (s, h, body) = v.post("/api/pose", &req);
        assert_eq!(s, 200, "{}", String::from_utf8_lossy(&body));
        assert!(header(&h, "x-compute-ms").is_some());
        parse_shape(&body)
    };
    let posed = pose(None);
    let drag = dist(start[tip], target);
    let miss = dist(posed.positions[tip], target);
    assert!(miss <= 1e-4 * drag, "posed tip misses the target by {miss} (drag {drag})");
    // Without the correction the shape is the model's own: its weights decode to its positions,
    // and its dials are the synthesis dials of the weights; the correction leaves the weights.
    let own = pose(Some(0.0));
    assert_eq!(own.weights, posed.weights);
    let (_, _, b4) = v.post("/api/decode", &json!({ "dials": own.dials }));
    assert!(max_diff(&parse_shape(&b4).positions, &own.positions) < 1e-5);
    let (s, _, body) =
        v.post("/api/pose", &json!({ "constraints": [{ "vertex": tip, "target": target }], "spread": 1.5 }));
    assert_eq!(s, 400);
    assert!(String::from_utf8_lossy(&body).contains("`spread` 1.5"), "{}", String::from_utf8_lossy(&body));

    // Heat maps equal the model's per-vertex magnitudes, and (measured independently of the
    // function that computes them) how far each vertex moves when that dial goes from 0 to 1 —
    // through the served decode (issue 33: the heat map was only compared with itself).
    let (_, _, zero) = v.post("/api/decode", &json!({ "dials": {} }));
    let zero = parse_shape(&zero).positions;
    for c in m.components().unwrap() {
        let (s, _, heat) = v.request("GET", &format!("/api/heat/{}", c.index), b"");
        assert_eq!(s, 200);
        let heat = f32s(&heat);
        assert_eq!(heat.len(), rest.n_vertices());
        let worst = heat.iter().zip(&c.magnitudes).map(|(a, b)| (a - b).abs() / b.abs().max(1e-3)).fold(0.0, f64::max);
        assert!(worst < 1e-5, "heat map of component {} differs by {worst}", c.index);
        let (_, _, one) = v.post("/api/decode", &json!({ "dials": { c.index.to_string(): 1.0 } }));
        let one = parse_shape(&one).positions;
        let peak = heat.iter().cloned().fold(0.0, f64::max);
        let worst =
            heat.iter().zip(one.iter().zip(&zero)).map(|(h, (a, b))| (h - dist(*a, *b)).abs()).fold(0.0, f64::max);
        assert!(
            worst <= 1e-5 * peak.max(1e-9),
            "component {}: heat map vs motion at dial 1 differ by {worst} (peak {peak})",
            c.index
        );
    }
    let (s, _, seg) = v.request("GET", "/api/segmentation", b"");
    assert_eq!(s, 200);
    assert_eq!(seg.len(), 4 * rest.n_vertices());

    // Frames: reconstruction, truth and per-vertex error; the Erms is the encode command's.
    let (s, h, body) = v.request("GET", "/api/frame/5", b"");
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&body));
    let erms: f64 = header(&h, "x-frame-erms").unwrap().parse().unwrap();
    assert!(erms.is_finite() && erms >= 0.0);
    let f = parse_shape(&body);
    let n = rest.n_vertices();
    assert_eq!(f.rest.len(), 16 * n);
    let truth: Vec<[f64; 3]> = f32s(&f.rest[..12 * n]).chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    let err = f32s(&f.rest[12 * n..]);
    let seq = meshdeco::synthetic::load("synthetic:tube").unwrap();
    assert!(max_diff(&truth, &seq.frames[5]) < 1e-6);
    for i in 0..n {
        assert!((err[i] - dist(truth[i], f.positions[i])).abs() < 1e-5);
    }
    // The header's Erms from its definition, on the served frame and reconstruction (a PCA on
    // displacements: no alignment): 1000 · sqrt(mean squared coordinate error).
    let by_hand = 1000.0
        * (truth.iter().zip(&f.positions).map(|(a, b)| dist(*a, *b).powi(2)).sum::<f64>() / (3 * n) as f64).sqrt();
    assert!((by_hand - erms).abs() <= 1e-5 * erms.max(1e-9), "Erms {erms} vs {by_hand} from its definition");
    let own = meshdeco::model::encode_frames(m.as_ref(), &seq.select(&[5]), "t", None).unwrap();
    assert!((own.total_erms - erms).abs() <= 1e-9 * erms.max(1.0), "Erms {erms} vs encode's {}", own.total_erms);
    // The frame index's bounds: the last of the 60 frames is served, one past it is a 400.
    let (s, _, body) = v.request("GET", "/api/frame/59", b"");
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&body));
    let last = parse_shape(&body);
    let truth: Vec<[f64; 3]> = f32s(&last.rest[..12 * n]).chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    assert!(max_diff(&truth, &seq.frames[59]) < 1e-6, "frame 59 is the data's last frame");
    let (s, _, body) = v.request("GET", "/api/frame/60", b"");
    assert_eq!(s, 400, "{}", String::from_utf8_lossy(&body));
}

#[test]
fn view_api_refuses_bad_requests_and_keeps_serving() {
    let d = fresh_dir("view-api", "bad");
    let model = train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 4");
    let v = Viewer::start(&[model.to_str().unwrap()]);
    let good = || {
        let (s, _, b) = v.post("/api/decode", &json!({ "dials": { "0": 0.5 } }));
        assert_eq!(s, 200, "a good request after a bad one: {}", String::from_utf8_lossy(&b));
        assert_eq!(parse_shape(&b).positions.len(), 1466);
    };
    // Work per pose request is bounded: pins, iterations (a clear 400 before any solving).
    let many_pins: Vec<Value> = (0..101).map(|v| json!({ "vertex": v, "target": [0, 0, 0] })).collect();
    let most_pins = serde_json::to_vec(&json!({ "constraints": many_pins[..100] })).unwrap();
    let many_pins = serde_json::to_vec(&json!({ "constraints": many_pins })).unwrap();
    let one_pin =
        |extra: &str| format!(r#"{{"constraints": [{{"vertex": 3, "target": [0, 0, 0]}}]{extra}}}"#).into_bytes();
    let cases: Vec<(&str, &str, Vec<u8>, u16, &str)> = vec![
        ("POST", "/api/pose", many_pins, 400, "101 pins; a pose request takes at most 100"),
        ("POST", "/api/pose", most_pins, 200, ""),
        ("POST", "/api/pose", one_pin(r#", "max_iterations": 1000"#), 400, "`max_iterations` 1000"),
        ("POST", "/api/pose", one_pin(r#", "max_iterations": 100"#), 200, ""),
        ("POST", "/api/pose", one_pin(r#", "max_iterations": 101"#), 400, "`max_iterations` 101"),
        ("POST", "/api/pose", one_pin(r#", "max_iterations": 0"#), 400, "`max_iterations` 0"),
        ("POST", "/api/pose", one_pin(r#", "prior": "maximal""#), 400, "`prior`"),
        ("POST", "/api/pose", one_pin(r#", "prior": "weights""#), 200, ""),
        ("POST", "/api/decode", b"{\"dials\": [1, 2".to_vec(), 400, "malformed JSON"),
        ("POST", "/api/decode", b"[1, 2]".to_vec(), 400, "JSON object"),
        ("POST", "/api/decode", br#"{"dials": {"9": 1}}"#.to_vec(), 400, "unknown component 9"),
        ("POST", "/api/decode", br#"{"dials": [1, 2]}"#.to_vec(), 400, "2 numbers"),
        ("POST", "/api/decode", br#"{"dials": {"0": "NaN"}}"#.to_vec(), 400, "must be a number"),
        ("POST", "/api/decode", br#"{"dials": {"0": 1e999}}"#.to_vec(), 400, "malformed JSON"),
        ("POST", "/api/decode", br#"{"dials": {"0": 1e300}}"#.to_vec(), 400, "non-finite"),
        ("POST", "/api/decode", br#"{}"#.to_vec(), 400, "missing `dials`"),
        ("POST", "/api/decode", br#"{"weights": {"0": 1}}"#.to_vec(), 400, "`weights` must be an array of 4 numbers"),
        ("GET", "/api/heat/4", vec![], 400, "unknown component `4`"),
        ("GET", "/api/heat/x", vec![], 400, "unknown component `x`"),
        (
            "POST",
            "/api/pose",
            br#"{"constraints": [{"vertex": 1466, "target": [0, 0, 0]}]}"#.to_vec(),
            400,
            "vertex 1466 out of range",
        ),
        (
            "POST",
            "/api/pose",
            br#"{"constraints": [{"vertex": 3, "target": [0, "inf", 0]}]}"#.to_vec(),
            400,
            "target[1] must be a number",
        ),
        (
            "POST",
            "/api/pose",
            br#"{"constraints": [{"vertex": 3, "target": [0, 1e300, 0]}]}"#.to_vec(),
            400,
            "vertex 3",
        ),
        ("POST", "/api/pose", br#"{"constraints": [{"vertex": 3, "target": [0, 0]}]}"#.to_vec(), 400, "[x, y, z]"),
        ("POST", "/api/pose", br#"{"constraints": []}"#.to_vec(), 400, "empty"),
        (
            "POST",
            "/api/pose",
            br#"{"constraints": [{"vertex": 3, "target": [0, 0, 0]}, {"vertex": 3, "target": [0, 0, 0]}]}"#.to_vec(),
            400,
            "twice",
        ),
        (
            "POST",
            "/api/pose",
            br#"{"constraints": [{"vertex": 3, "target": [0, 0, 0]}], "gamma": -1}"#.to_vec(),
            400,
            "`gamma`",
        ),
        (
            "POST",
            "/api/pose",
            br#"{"constraints": [{"vertex": 3, "target": [0, 0, 0]}], "start": [0]}"#.to_vec(),
            400,
            "`start` has 1",
        ),
        ("GET", "/api/frame/0", vec![], 400, "--data"),
        ("POST", "/api/export", br#"{"format": "stl", "dials": {}}"#.to_vec(), 400, "stl"),
        ("GET", "/api/decode", vec![], 405, "POST"),
        ("POST", "/api/model", vec![], 405, "GET"),
        ("GET", "/../Cargo.toml", vec![], 404, "no such"),
        ("GET", "/api/../../etc/passwd", vec![], 404, "no such"),
    ];
    for (method, path, body, status, needle) in cases {
        let (s, h, b) = v.request(method, path, &body);
        let text = String::from_utf8_lossy(&b).to_string();
        assert_eq!(s, status, "{method} {path} {}: {text}", String::from_utf8_lossy(&body));
        if status == 200 {
            continue;
        }
        assert_eq!(header(&h, "content-type"), Some("application/json"));
        let msg: Value = serde_json::from_str(&text).unwrap();
        assert!(msg["error"].as_str().unwrap().contains(needle), "{method} {path}: `{text}` lacks `{needle}`");
        good();
    }
    // A body over the limit is refused before it is read.
    let huge = format!("POST /api/decode HTTP/1.1\r\nContent-Length: {}\r\n\r\n", meshdeco::view::http::MAX_BODY + 1);
    let mut s = std::net::TcpStream::connect(&v.addr).unwrap();
    use std::io::{Read, Write};
    s.write_all(huge.as_bytes()).unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    assert_eq!(view_support::parse_response(&raw).0, 413);
    good();
    // Keep-alive: two requests on one connection.
    let mut s = std::net::TcpStream::connect(&v.addr).unwrap();
    s.write_all(b"GET /api/model HTTP/1.1\r\n\r\nGET /api/model HTTP/1.1\r\nConnection: close\r\n\r\n").unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    assert_eq!(String::from_utf8_lossy(&raw).matches("HTTP/1.1 200 OK").count(), 2);
    // `Expect: 100-continue` (curl, larger bodies) is answered before the body is sent.
    let body = br#"{"dials": {"0": 0.25}}"#;
    let mut s = std::net::TcpStream::connect(&v.addr).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(30))).unwrap();
    write!(
        s,
        "POST /api/decode HTTP/1.1\r\nContent-Length: {}\r\nExpect: 100-continue\r\nConnection: close\r\n\r\n",
        body.len()
    )
    .unwrap();
    let mut first = [0u8; 25];
    s.read_exact(&mut first).unwrap();
    assert_eq!(&first, b"HTTP/1.1 100 Continue\r\n\r\n");
    s.write_all(body).unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    assert_eq!(view_support::parse_response(&raw).0, 200);
}

#[test]
fn view_command_flags_errors_and_ctrl_c() {
    let d = fresh_dir("view-api", "cli");
    // A missing model directory: non-zero exit naming it, nothing served.
    let o = meshdeco(&["view", "no-such-model", "--port", "0"], &d);
    assert!(!o.status.success());
    assert!(output_text(&o).contains("no-such-model"), "{}", output_text(&o));
    let model = train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 3");
    // --data with another connectivity is refused, naming it.
    let o = meshdeco(&["view", model.to_str().unwrap(), "--data", "synthetic:nope", "--port", "0"], &d);
    assert!(!o.status.success());
    assert!(output_text(&o).contains("synthetic:nope"), "{}", output_text(&o));
    // A port in use: named.
    let v = Viewer::start(&[model.to_str().unwrap()]);
    let port = v.addr.rsplit(':').next().unwrap().to_string();
    let o = meshdeco(&["view", model.to_str().unwrap(), "--port", &port], &d);
    assert!(!o.status.success());
    assert!(output_text(&o).contains(&port), "{}", output_text(&o));
    // --host other than loopback warns.
    let mut w = std::process::Command::new(env!("CARGO_BIN_EXE_meshdeco"))
        .args(["view", model.to_str().unwrap(), "--port", "0", "--host", "0.0.0.0"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let _ = w.kill();
    let o = w.wait_with_output().unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("warning: --host 0.0.0.0"), "{}", output_text(&o));
    // Ctrl-C (SIGINT): a clean stop with status 0.
    let mut v = v;
    let pid = v.child.id().to_string();
    let k = std::process::Command::new("kill").args(["-INT", &pid]).status().unwrap();
    assert!(k.success());
    let t0 = std::time::Instant::now();
    let status = loop {
        if let Some(s) = v.child.try_wait().unwrap() {
            break s;
        }
        assert!(t0.elapsed().as_secs() < 10, "meshdeco view did not stop on SIGINT");
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    assert!(status.success(), "exit status after Ctrl-C: {status}");
}

#[test]
fn view_api_decodes_an_autoencoder_like_synthesize() {
    let d = fresh_dir("view-api", "ae");
    let model = train(
        &d,
        "ae",
        "synthetic:tube",
        "kind = \"autoencoder\"\ncomponents = 4\niterations = 60\ncheckpoint_every = 60\nseed = 1",
    );
    let v = Viewer::start(&[model.to_str().unwrap(), "--data", "synthetic:tube"]);
    let (s, _, body) = v.post("/api/decode", &json!({ "dials": { "2": 0.8 } }));
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&body));
    let o = meshdeco(&["synthesize", model.to_str().unwrap(), "--weights", "2:0.8", "--out", "s.obj"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let diff = max_diff(&parse_shape(&body).positions, &obj_positions(&d.join("s.obj")));
    assert!(diff < 1e-5, "autoencoder decode differs from synthesize by {diff}");
    let (s, _, body) = v.request("GET", "/api/model", b"");
    assert_eq!(s, 200);
    let desc: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(desc["kind"], "autoencoder");
    // The page shows the pose options the model reads, with the one set of defaults.
    assert_eq!(desc["pose_parameters"], json!(["gamma", "max_iterations"]));
    // Its segmentation overlay is one group per component, not a single colour: every component
    // reaches every vertex, and a vertex goes to the component largest there relative to its
    // own peak.
    assert_eq!(desc["segmentation_groups"], json!(4));
    let (s, _, seg) = v.request("GET", "/api/segmentation", b"");
    assert_eq!(s, 200);
    let labels: Vec<u32> = seg.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    let m = load_model(&model).unwrap();
    let comps = m.components().unwrap();
    for c in &comps {
        let peak = c.magnitudes.iter().cloned().fold(0.0, f64::max);
        assert!(c.magnitudes.iter().all(|&x| x > 1e-6 * peak), "component {} is not everywhere", c.index);
    }
    let peaks: Vec<f64> = comps.iter().map(|c| c.magnitudes.iter().cloned().fold(0.0, f64::max)).collect();
    assert!(
        peaks.iter().any(|&p| (p - peaks[0]).abs() > 1e-3 * peaks[0]),
        "the peaks {peaks:?} are equal: relative and absolute magnitudes would give the same labels"
    );
    assert_eq!((labels.clone(), 4), segmentation_by_definition(&comps, m.rest().n_vertices()));
    let used: std::collections::BTreeSet<u32> = labels.iter().copied().collect();
    assert!(used.len() >= 2, "the autoencoder's segmentation has {} label(s)", used.len());
    // The compute time the page shows is the model call's: within the request's round trip.
    let t0 = std::time::Instant::now();
    let (s, h, _) = v.post("/api/decode", &json!({ "dials": { "1": 0.5 } }));
    let round_trip_ms = 1e3 * t0.elapsed().as_secs_f64();
    assert_eq!(s, 200);
    let compute_ms: f64 = header(&h, "x-compute-ms").unwrap().parse().unwrap();
    assert!((0.0..=round_trip_ms).contains(&compute_ms), "X-Compute-Ms {compute_ms} for a {round_trip_ms} ms request");
    // A frame's per-vertex error is measured as its Erms is, after the centroid alignment
    // (the autoencoder's features do not hold a translation): the reconstruction is shifted by
    // the mean of truth − reconstruction.
    let (s, _, body) = v.request("GET", "/api/frame/5", b"");
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&body));
    let f = parse_shape(&body);
    let n = f.positions.len();
    let truth: Vec<[f64; 3]> = f32s(&f.rest[..12 * n]).chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    let err = f32s(&f.rest[12 * n..]);
    let shift: [f64; 3] =
        std::array::from_fn(|k| truth.iter().zip(&f.positions).map(|(t, r)| t[k] - r[k]).sum::<f64>() / n as f64);
    let size = dist(m.rest().bounding_box().0, m.rest().bounding_box().1);
    assert!(dist(shift, [0.0; 3]) > 1e-3 * size, "the shift {shift:?} is too small to tell");
    for (i, ((t, r), e)) in truth.iter().zip(&f.positions).zip(&err).enumerate() {
        let want = dist(*t, [r[0] + shift[0], r[1] + shift[1], r[2] + shift[2]]);
        assert!((e - want).abs() <= 1e-5 * size, "vertex {i}: error {e} against {want}");
    }
    // The model kind's pose defaults (`Model::pose_defaults`), not one set for every kind.
    let d = m.pose_defaults();
    assert_eq!(desc["pose_defaults"]["gamma"], json!(d.gamma));
    assert_eq!(desc["pose_defaults"]["prior"], json!(d.prior.name()));
    assert_eq!(desc["pose_defaults"]["reach"], json!(d.reach));
}

/// `meshdeco components` writes overview.png: one block (rest, extreme, heat map) per ranked
/// component, the tube standing up (automatic up axis), heat maps in colour.
#[test]
fn components_overview_png_shows_every_component() {
    let d = fresh_dir("view-api", "overview");
    let model = train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 5");
    let o = meshdeco(&["components", model.to_str().unwrap(), "--out", "comps", "--cell", "100", "--per-row", "3"], &d);
    assert!(o.status.success(), "{}", output_text(&o));
    let png = d.join("comps/overview.png");
    let (w, h, ink, colours) = common::png_ink(&png);
    // 3 blocks per row of 3 × 100 px + 12 px gaps; 2 rows of 100 + 20 (label) + 6 px.
    assert_eq!((w, h), (3 * 312 + 12, 2 * 126 + 12));
    assert!(ink > 0.05, "overview is {:.1} % ink", 100.0 * ink);
    assert!(colours > 50, "overview has {colours} colours: no heat map");
    // Each picture: the tube stands up (taller than wide) and the extreme differs from the rest.
    let img = image::open(&png).unwrap().to_rgb8();
    let cell = |bx: u32, by: u32, j: u32| -> Vec<[u8; 3]> {
        let (x0, y0) = (12 + bx * 312 + j * 100, 6 + by * 126 + 20);
        (0..100).flat_map(|y| (0..100).map(move |x| (x, y))).map(|(x, y)| img.get_pixel(x0 + x, y0 + y).0).collect()
    };
    let extent = |c: &[[u8; 3]]| {
        let on: Vec<(usize, usize)> =
            (0..10000).filter(|&i| c[i] != [255, 255, 255]).map(|i| (i % 100, i / 100)).collect();
        let w = on.iter().map(|p| p.0).max().unwrap() - on.iter().map(|p| p.0).min().unwrap();
        let h = on.iter().map(|p| p.1).max().unwrap() - on.iter().map(|p| p.1).min().unwrap();
        (w, h)
    };
    for (bx, by) in [(0, 0), (1, 0), (2, 0), (0, 1), (1, 1)] {
        let rest = cell(bx, by, 0);
        let (w, h) = extent(&rest);
        assert!(h > 2 * w, "block ({bx}, {by}): rest picture {w}×{h}, not standing up");
        assert_ne!(rest, cell(bx, by, 1), "block ({bx}, {by}): the extreme equals the rest");
        let heat = cell(bx, by, 2);
        assert!(heat.iter().any(|p| p[0] != p[1] || p[1] != p[2]), "block ({bx}, {by}): heat map without colour");
    }
    // The sixth slot of the grid stays empty.
    assert!(cell(2, 1, 0).iter().all(|p| *p == [255, 255, 255]));
}

/// The overview's picture, pixel by pixel, from the library: block r (rank order, `per_row` to a
/// row) holds the rest shape, the component at its extreme training dial and the heat map, each
/// rendered with the same view and the one box that frames the rest and every extreme; the name
/// (rank, name, dial) sits in the 20 px strip above its block (and the 6 px gap above that) and
/// every other pixel is white.
/// Bad layouts are refused with the value in the message.
#[test]
fn overview_places_each_picture_and_label_of_each_component() {
    use meshdeco::mesh::render::{RenderOptions, View, render};
    use meshdeco::view::overview::{OverviewOptions, extreme_dials, overview};
    let d = fresh_dir("view-api", "overview-lib");
    let model = train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 5");
    let m = load_model(&model).unwrap();
    let k = m.n_components();

    // The extreme dial of each component: the training weight of largest magnitude, sign kept.
    let ws = m.train_weights().expect("a PCA model keeps its training weights");
    let train_dials: Vec<Vec<f64>> = ws.iter().map(|w| m.dials(w).unwrap()).collect();
    let ext = extreme_dials(&*m).unwrap();
    assert_eq!(ext.len(), k);
    for (i, e) in ext.iter().enumerate() {
        let e = e.expect("every component has training dials");
        let all: Vec<f64> = train_dials.iter().map(|d| d[i]).collect();
        assert!(all.iter().all(|x| x.abs() <= e.abs()), "component {i}: {e} is not the largest of {all:?}");
        assert!(all.contains(&e), "component {i}: {e} is not one of the training dials");
        assert!((e.abs() - 1.0).abs() > 1e-3, "component {i}: the test needs an extreme other than ±1");
    }

    for (cell, per_row) in [(31, 2), (2049, 2), (100, 0)] {
        let e = overview(&*m, &OverviewOptions { cell, per_row }).expect_err("a bad layout").to_string();
        assert!(e.contains(&format!("cell {cell} px")) && e.contains(&format!("{per_row} per row")), "{e}");
    }

    let (cell, per_row) = (100usize, 2usize);
    let (w, h, img, names) = overview(&*m, &OverviewOptions { cell, per_row }).unwrap();
    let (block_w, block_h) = (3 * cell + 12, cell + 20 + 6);
    assert_eq!((w, h), (2 * block_w + 12, 3 * block_h + 12), "5 blocks, 2 to a row");
    assert_eq!(img.len(), 3 * w * h);

    // The expected pictures, from the renderer with the overview's view and framing.
    let rest = m.rest();
    let comps = meshdeco::model::ranked(&*m).unwrap();
    let mut shapes = Vec::new();
    for c in &comps {
        let mut dials = vec![0.0; k];
        dials[c.index] = ext[c.index].unwrap();
        shapes.push(meshdeco::model::synthesize(&*m, &dials).unwrap());
    }
    let (rest_lo, rest_hi) = rest.bounding_box();
    let (mut lo, mut hi) = (rest_lo, rest_hi);
    for s in &shapes {
        let (a, b) = meshdeco::mesh::bounding_box(s);
        for j in 0..3 {
            lo[j] = lo[j].min(a[j]);
            hi[j] = hi[j].max(b[j]);
        }
    }
    assert!((0..3).any(|j| lo[j] < rest_lo[j] - 1e-9 || hi[j] > rest_hi[j] + 1e-9), "no extreme leaves the rest's box");
    let ropts = RenderOptions {
        width: cell,
        height: cell,
        view: View::auto(&rest),
        bounds: Some((lo, hi)),
        ..Default::default()
    };
    let rest_pic = render(&rest, None, &ropts).unwrap();
    let font = meshdeco::eval::plots::font_path().is_some();
    let mut class = vec![0u8; w * h]; // 0: must be white, 1: a picture, 2: a label strip
    for (r, c) in comps.iter().enumerate() {
        let dial = ext[c.index].unwrap();
        assert_eq!(names[r], format!("#{} {} (dial {dial:.3})", c.rank, c.name));
        let (bx, top) = (12 + (r % per_row) * block_w, 6 + (r / per_row) * block_h);
        let mesh = meshdeco::mesh::TriMesh::new(shapes[r].clone(), rest.faces.clone());
        let heat = meshdeco::mesh::colormap(&c.magnitudes);
        let extreme = render(&mesh, None, &ropts).unwrap();
        let heat_pic = render(&rest, Some(&heat), &ropts).unwrap();
        for (j, pic) in [&rest_pic, &extreme, &heat_pic].into_iter().enumerate() {
            let (x0, y0) = (bx + j * cell, top + 20);
            for y in 0..cell {
                for x in 0..cell {
                    let (o, p) = (3 * ((y0 + y) * w + x0 + x), 3 * (y * cell + x));
                    assert_eq!(img[o..o + 3], pic[p..p + 3], "rank {r}, picture {j}, pixel ({x}, {y})");
                    class[(y0 + y) * w + x0 + x] = 1;
                }
            }
        }
        let mut ink_x = Vec::new();
        // The label's glyphs may reach a few pixels above its strip, into the gap above.
        for y in top - 6..top + 20 {
            for x in bx..(bx + block_w).min(w) {
                class[y * w + x] = 2;
                if img[3 * (y * w + x)..3 * (y * w + x) + 3] != [255, 255, 255] {
                    ink_x.push(x);
                }
            }
        }
        if font {
            let first = *ink_x.iter().min().unwrap_or_else(|| panic!("rank {r}: no label above its block"));
            assert!((bx..bx + 6).contains(&first), "rank {r}: label starts at x = {first}, block at {bx}");
        }
    }
    for (i, c) in class.iter().enumerate() {
        if *c == 0 {
            assert_eq!(img[3 * i..3 * i + 3], [255, 255, 255], "pixel ({}, {}) is outside every block", i % w, i / w);
        }
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// The segmentation overlay's rule, written from its documentation: where every component
/// reaches every vertex (above 10⁻⁶ of its peak), a vertex goes to the component largest there
/// relative to its peak; otherwise components with the same support form a group (in order of
/// first appearance) and a vertex goes to the group of its largest component. Ties go to the
/// later component. Returns the labels and the number of groups.
fn segmentation_by_definition(comps: &[meshdeco::model::Component], n: usize) -> (Vec<u32>, usize) {
    let peaks: Vec<f64> = comps.iter().map(|c| c.magnitudes.iter().cloned().fold(0.0, f64::max)).collect();
    let everywhere = comps.len() > 1
        && comps.iter().zip(&peaks).all(|(c, &p)| p > 0.0 && c.magnitudes.iter().all(|&m| m > 1e-6 * p));
    let argmax = |score: &dyn Fn(usize) -> f64| {
        let mut best = 0;
        for a in 1..comps.len() {
            if score(a) >= score(best) {
                best = a;
            }
        }
        best
    };
    if everywhere {
        let labels = (0..n).map(|v| argmax(&|a| comps[a].magnitudes[v] / peaks[a]) as u32).collect();
        return (labels, comps.len());
    }
    let mut supports: Vec<Vec<bool>> = Vec::new();
    let mut group = Vec::new();
    for (c, &p) in comps.iter().zip(&peaks) {
        let s: Vec<bool> = c.magnitudes.iter().map(|&m| m > 1e-6 * p).collect();
        group.push(supports.iter().position(|t| *t == s).unwrap_or_else(|| {
            supports.push(s);
            supports.len() - 1
        }) as u32);
    }
    let labels = (0..n).map(|v| group[argmax(&|a| comps[a].magnitudes[v])]).collect();
    (labels, supports.len())
}

/// `/api/model`'s dial ranges and peaks and `/api/segmentation` against their definitions: a
/// range spans 0 and every training dial, padded by 10 % of its span on each side; labels for a
/// PCA's global components (one support) and a region PCA's regions (supports shared within one).
#[test]
fn description_ranges_and_segmentation_follow_their_definitions() {
    let d = fresh_dir("view-api", "ranges");
    let cases = [
        ("pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 5"),
        ("region", "synthetic:bumps", "kind = \"region-pca\"\ncomponents = 8\nmax_regions = 4"),
    ];
    for (name, data, method) in cases {
        let model = train(&d, name, data, method);
        let m = load_model(&model).unwrap();
        let k = m.n_components();
        let n = m.rest().n_vertices();
        let v = Viewer::start(&[model.to_str().unwrap()]);
        let (s, _, body) = v.request("GET", "/api/model", b"");
        assert_eq!(s, 200);
        let desc: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(desc["ranges_from"], "training weights");
        let comps = m.components().unwrap();
        let train_dials: Vec<Vec<f64>> = m.train_weights().unwrap().iter().map(|w| m.dials(w).unwrap()).collect();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + b.abs());
        let mut padded = 0;
        for c in desc["components"].as_array().unwrap() {
            let i = c["index"].as_u64().unwrap() as usize;
            let dials: Vec<f64> = train_dials.iter().map(|d| d[i]).collect();
            let lo = dials.iter().cloned().fold(0.0, f64::min);
            let hi = dials.iter().cloned().fold(0.0, f64::max);
            let span = hi - lo;
            // Dials that do not vary (a region's unused component) get the default [−1, 1].
            let want = if span > 1e-12 { [lo - 0.1 * span, hi + 0.1 * span] } else { [-1.0, 1.0] };
            let got = [c["range"][0].as_f64().unwrap(), c["range"][1].as_f64().unwrap()];
            assert!(
                close(got[0], want[0]) && close(got[1], want[1]),
                "{name} component {i}: range {got:?}, dials from {lo} to {hi}"
            );
            padded += usize::from(span > 1e-12);
            let peak = comps[i].magnitudes.iter().cloned().fold(0.0, f64::max);
            assert!(close(c["peak"].as_f64().unwrap(), peak), "{name} component {i}: peak");
        }
        assert!(padded >= 3, "{name}: only {padded} components with varying dials");
        let (want, groups) = segmentation_by_definition(&comps, n);
        assert_eq!(desc["segmentation_groups"], json!(groups), "{name}");
        let (s, _, seg) = v.request("GET", "/api/segmentation", b"");
        assert_eq!(s, 200);
        let labels: Vec<u32> = seg.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        assert_eq!(labels, want, "{name}: segmentation labels");
        if name == "region" {
            let used: std::collections::BTreeSet<u32> = labels.iter().copied().collect();
            assert!(used.len() >= 2, "region PCA: one label everywhere");
            assert!(
                groups < k,
                "region PCA: {groups} groups for {k} components (a region's components share a support)"
            );
        }
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// `/api/model`'s camera framing (`up_axis`, `view_axis`, `view_sign`) is the renderer's
/// automatic framing of the rest shape: the page's camera looks at the side most vertex normals
/// face. A bumpy sheet whose faces wind toward +z and the same sheet wound toward −z are seen
/// from opposite sides.
#[test]
fn description_frames_the_camera_like_the_renderer() {
    use meshdeco::mesh::render::auto_frame;
    let d = fresh_dir("view-api", "frame");
    // A 9 × 9 grid in the unit square, its faces wound toward +z.
    let (grid, faces) = common::unit_grid(9, 9);
    let mut signs = Vec::new();
    for (name, flip) in [("up", false), ("down", true)] {
        let dir = d.join(name);
        std::fs::create_dir_all(&dir).unwrap();
        for f in 0..10 {
            let (a, b) = ((f as f64 * 0.7).sin(), (f as f64 * 1.3).cos());
            let positions = grid
                .iter()
                .map(|&[x, y, _]| {
                    let bump = |cx: f64, cy: f64| (-20.0 * ((x - cx).powi(2) + (y - cy).powi(2))).exp();
                    let z = 0.1 * (a * bump(0.3, 0.3) + b * bump(0.7, 0.6));
                    [x, y, z]
                })
                .collect();
            let faces = faces.iter().map(|t| if flip { [t[0], t[2], t[1]] } else { *t }).collect();
            let mesh = meshdeco::mesh::TriMesh { positions, faces };
            meshdeco::mesh::write_obj(&dir.join(format!("f{f:02}.obj")), &mesh).unwrap();
        }
        let model = train(&d, &format!("{name}-model"), dir.to_str().unwrap(), "kind = \"pca\"\ncomponents = 2");
        let (up, view, negative) = auto_frame(&load_model(&model).unwrap().rest());
        assert_eq!(view, 2, "{name}: the sheet is seen along z");
        let sign = if negative { -1 } else { 1 };
        let v = Viewer::start(&[model.to_str().unwrap()]);
        let (s, _, body) = v.request("GET", "/api/model", b"");
        assert_eq!(s, 200);
        let desc: Value = serde_json::from_slice(&body).unwrap();
        let got = [&desc["up_axis"], &desc["view_axis"], &desc["view_sign"]];
        assert_eq!(got, [&json!(up), &json!(view), &json!(sign)], "{name}");
        signs.push(sign);
    }
    assert_eq!(signs, [1, -1], "the sheet wound toward +z, then toward −z");
    std::fs::remove_dir_all(&d).unwrap();
}

/// Pose requests queued behind a busy model thread are superseded by newer ones (README's API
/// table): they are answered 409 Conflict without solving, and the newest is solved. Two dozen
/// requests of 100 pins each are sent at once, so that several wait while one is solved.
#[test]
fn queued_pose_requests_are_superseded_by_newer_ones() {
    let d = fresh_dir("view-api", "supersede");
    let model = train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 4");
    let v = Viewer::start(&[model.to_str().unwrap()]);
    let pins: Vec<Value> = (0..100).map(|i| json!({ "vertex": 7 * i, "target": [0, 0, 0] })).collect();
    let body = serde_json::to_vec(&json!({ "constraints": pins, "max_iterations": 100 })).unwrap();
    let answers: Vec<(u16, Vec<u8>)> = std::thread::scope(|s| {
        let sent: Vec<_> = (0..24)
            .map(|_| {
                s.spawn(|| {
                    let (status, _, b) = v.request("POST", "/api/pose", &body);
                    (status, b)
                })
            })
            .collect();
        sent.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let statuses: Vec<u16> = answers.iter().map(|a| a.0).collect();
    let superseded = statuses.iter().filter(|&&s| s == 409).count();
    let solved = statuses.iter().filter(|&&s| s == 200).count();
    assert_eq!(superseded + solved, 24, "{statuses:?}");
    assert!(superseded >= 1 && solved >= 1, "{superseded} superseded and {solved} solved of 24 at once");
    for (s, b) in &answers {
        if *s == 409 {
            let text = String::from_utf8_lossy(b);
            assert!(text.contains("superseded by a newer pose request; not solved"), "{text}");
        } else {
            assert_eq!(parse_shape(b).positions.len(), 1466);
        }
    }
    eprintln!("pose requests at once: {solved} solved, {superseded} superseded");
    std::fs::remove_dir_all(&d).unwrap();
}

/// The segmentation's "everywhere" threshold is 10⁻⁶ of each component's peak, also where the
/// peak is below 1 (a unit-norm PCA component spread over the 15 vertices that move has peak
/// 0.26): two PCA components on a 4 × 4 sheet that move every vertex, one along x and one along
/// y, each with one vertex that moves only 3·10⁻⁶ as far as the others. Each component is its
/// own group; a threshold of 10⁻⁶ / peak would call neither everywhere and give one group.
#[test]
fn segmentation_counts_a_component_everywhere_relative_to_its_peak() {
    let d = fresh_dir("view-api", "relative-peak");
    let data = d.join("frames");
    std::fs::create_dir_all(&data).unwrap();
    let (rest, faces) = common::unit_grid(4, 4);
    let (n, frames) = (rest.len(), 8);
    let faint = 3e-6;
    for t in 0..frames {
        let phase = std::f64::consts::TAU * t as f64 / frames as f64;
        let (a, b) = (0.02 * phase.cos(), 0.01 * phase.sin());
        let mut text = String::new();
        for (i, p) in rest.iter().enumerate() {
            let fx = if i == 0 { faint } else { 1.0 };
            let fy = if i == n - 1 { faint } else { 1.0 };
            text.push_str(&format!("v {:e} {:e} {:e}\n", p[0] + a * fx, p[1] + b * fy, p[2]));
        }
        for f in &faces {
            text.push_str(&format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1));
        }
        std::fs::write(data.join(format!("{t}.obj")), text).unwrap();
    }
    let model = train(&d, "pca", data.to_str().unwrap(), "kind = \"pca\"\ncomponents = 2");
    let m = load_model(&model).unwrap();
    let comps = m.components().unwrap();
    assert_eq!(comps.len(), 2);
    // The case this test is for: every component is everywhere by the documented rule, and its
    // smallest magnitude lies below 10⁻⁶ / peak (the peaks are below 1).
    for c in &comps {
        let peak = c.magnitudes.iter().cloned().fold(0.0, f64::max);
        let least = c.magnitudes.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(least > 1e-6 * peak && least < 1e-6 / peak, "component {}: peak {peak}, least {least}", c.index);
        eprintln!("component {}: peak {peak:.3e}, least {least:.3e}", c.index);
    }
    let v = Viewer::start(&[model.to_str().unwrap()]);
    let (s, _, body) = v.request("GET", "/api/model", b"");
    assert_eq!(s, 200);
    let desc: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(desc["segmentation_groups"], json!(2));
    let (s, _, seg) = v.request("GET", "/api/segmentation", b"");
    assert_eq!(s, 200);
    let labels: Vec<u32> = seg.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    assert_eq!((labels.clone(), 2), segmentation_by_definition(&comps, n));
    let used: std::collections::BTreeSet<u32> = labels.iter().copied().collect();
    assert_eq!(used.len(), 2, "labels {labels:?}");
    std::fs::remove_dir_all(&d).unwrap();
}
