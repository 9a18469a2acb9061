//! Every hyperparameter of a method's solver is a `[method]` key: each field of
//! `nn::AutoencoderConfig` and of `SplocsConfig` is set from TOML to a value other than its
//! default, and the config the method hands its solver carries that value. A field added to the
//! solver's struct without a key fails here (and does not compile in `config/method.rs`).

use std::collections::BTreeSet;

use meshdeco::config::{AutoencoderMethod, MethodConfig, SplocsMethod};
use meshdeco::methods::splocs::SplocsConfig;
use meshdeco::nn::config::AutoencoderConfig;
use serde_json::Value;

/// Field names of a struct, from its JSON serialisation.
fn fields(v: &Value) -> BTreeSet<String> {
    v.as_object().expect("a struct").keys().cloned().collect()
}

/// For each `(field, toml line)`: the line parsed as the method's table (plus `kind`) gives a
/// solver config whose `field` differs from the default's and equals `expect`.
fn check_keys<F: Fn(&str) -> Value>(solver_default: &Value, cases: &[(&str, &str, Value)], solver_of: F) {
    let covered: BTreeSet<String> = cases.iter().map(|c| c.0.to_string()).collect();
    assert_eq!(
        covered,
        fields(solver_default),
        "the cases must name every field of the solver's config (a new field needs a TOML key and a case here)"
    );
    for (field, line, expect) in cases {
        let got = solver_of(line);
        assert_ne!(got[field], solver_default[field], "`{line}` does not change `{field}`");
        assert_eq!(&got[field], expect, "`{line}` sets `{field}` to {}", got[field]);
    }
}

#[test]
fn every_autoencoder_network_field_is_a_method_key() {
    use serde_json::json;
    let cases: Vec<(&str, &str, Value)> = vec![
        ("components", "components = 7", json!(7)),
        ("layers", "layers = 2", json!(2)),
        ("init_std", "init_std = 0.05", json!(0.05)),
        ("init_bias", "init_bias = \"mean\"", json!("mean")),
        ("learning_rate", "learning_rate = 0.01", json!(0.01)),
        ("learning_rate_final", "learning_rate_final = 0.0001", json!(0.0001)),
        ("learning_rate_norm", "learning_rate_norm = 40.0", json!(40.0)),
        ("stall_restarts", "stall_restarts = 5", json!(5)),
        ("beta1", "beta1 = 0.8", json!(0.8)),
        ("beta2", "beta2 = 0.99", json!(0.99)),
        ("epsilon", "epsilon = 1e-6", json!(1e-6)),
        ("iterations", "iterations = 11", json!(11)),
        ("batch_size", "batch_size = 4", json!(4)),
        ("lambda1", "lambda1 = 2.0", json!(2.0)),
        ("lambda2", "lambda2 = 0.25", json!(0.25)),
        ("theta", "theta = 3.0", json!(3.0)),
        ("d_min", "support = [0.1, 0.4]", json!(0.1)),
        ("d_max", "support = [0.2, 0.6]", json!(0.6)),
        ("checkpoint_every", "checkpoint_every = 9", json!(9)),
        ("seed", "seed = 5", json!(5)),
        ("engine", "engine = \"graph\"", json!("graph")),
        ("device", "device = \"wgpu\"", json!("wgpu")),
        ("augment", "augment = 3", json!(3)),
        ("augment_mix", "augment_mix = \"blend\"", json!("blend")),
        ("augment_radius", "augment_radius = [0.2, 0.4]", json!([0.2, 0.4])),
        ("input_noise", "input_noise = 0.05", json!(0.05)),
        ("validation", "validation = 2", json!(2)),
        ("validate_every", "validate_every = 10", json!(10)),
        ("encoder", "encoder = \"least-squares\"", json!("least-squares")),
        ("lambda_orthogonal", "lambda_orthogonal = 10.0", json!(10.0)),
        ("lambda_vertex", "lambda_vertex = 3.0", json!(3.0)),
        ("lambda_code", "lambda_code = 0.5", json!(0.5)),
        ("vertex_batch", "vertex_batch = 4", json!(4)),
        ("vertex_warmup", "vertex_warmup = 0.5", json!(0.5)),
        ("vertex_clip", "vertex_clip = 2.0", json!(2.0)),
        ("encoder_passes", "encoder_passes = 2", json!(2)),
        ("encoder_steps", "encoder_steps = 3", json!(3)),
    ];
    let default = serde_json::to_value(AutoencoderConfig::default()).unwrap();
    check_keys(&default, &cases, |line| {
        // Parsed without the value checks (e.g. `device = "wgpu"` needs a wgpu build): this test
        // is about reaching the field; `MethodConfig::from_table` validates.
        let m: AutoencoderMethod = toml::from_str(line).unwrap_or_else(|e| panic!("`{line}`: {e}"));
        serde_json::to_value(m.network_config()).unwrap()
    });
    // And through the validated path, the keys a default build accepts.
    let t: toml::Table = toml::from_str(
        "kind = \"autoencoder\"\ninit_std = 0.05\nepsilon = 1e-6\naugment_mix = \"mixed\"\ninit_bias = \"mean\"",
    )
    .unwrap();
    let MethodConfig::Autoencoder(m) = MethodConfig::from_table(&t).unwrap() else { panic!("kind") };
    let n = m.network_config();
    assert_eq!((n.init_std, n.epsilon, n.init_bias), (0.05, 1e-6, meshdeco::nn::config::InitBias::Mean));
    // A value that is neither names the key and the choices.
    let bad: toml::Table = toml::from_str("kind = \"autoencoder\"\ninit_bias = \"median\"").unwrap();
    let e = MethodConfig::from_table(&bad).unwrap_err().to_string();
    assert!(e.contains("init_bias") && e.contains("zero") && e.contains("mean"), "{e}");
    // The resolved table (an artefact's config.toml) parses back to the same config.
    let back = MethodConfig::from_table(&MethodConfig::Autoencoder(m.clone()).to_table().unwrap()).unwrap();
    assert_eq!(back, MethodConfig::Autoencoder(m));
}

/// `feature_weights` (a key of the method, not of the network): both values parse and round-trip
/// through an artefact's `config.toml`; another names the key and the choices.
#[test]
fn feature_weights_is_a_method_key() {
    use meshdeco::config::FeatureWeights;
    for (line, want) in [
        ("", AutoencoderMethod::default().feature_weights),
        ("feature_weights = \"noise\"", FeatureWeights::Noise),
        ("feature_weights = \"uniform\"", FeatureWeights::Uniform),
    ] {
        let t: toml::Table = toml::from_str(&format!("kind = \"autoencoder\"\n{line}")).unwrap();
        let MethodConfig::Autoencoder(m) = MethodConfig::from_table(&t).unwrap() else { panic!("kind") };
        assert_eq!(m.feature_weights, want, "`{line}`");
        let back = MethodConfig::from_table(&MethodConfig::Autoencoder(m.clone()).to_table().unwrap()).unwrap();
        assert_eq!(back, MethodConfig::Autoencoder(m));
    }
    let bad: toml::Table = toml::from_str("kind = \"autoencoder\"\nfeature_weights = \"area\"").unwrap();
    let e = MethodConfig::from_table(&bad).unwrap_err().to_string();
    assert!(e.contains("feature_weights") && e.contains("uniform") && e.contains("noise"), "{e}");
}

/// The experiment's `name` becomes the artefact folder's name: empty, a path separator of
/// either kind, `.` and `..` are each refused naming the key; a plain name is accepted (issue
/// 58's mutants of the check's `||`s).
#[test]
fn an_experiment_name_is_one_file_name() {
    let cfg = |name: &str| {
        meshdeco::config::Config::from_toml(&format!(
            "name = {name:?}\n[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"pca\"\ncomponents = 3\n"
        ))
    };
    for bad in ["", "a/b", "a\\b", ".", ".."] {
        let e = cfg(bad).err().unwrap_or_else(|| panic!("name {bad:?} accepted")).to_string();
        assert!(e.contains("`name`") && e.contains("without path separators"), "{bad:?}: {e}");
    }
    assert_eq!(cfg("scape-pca.2").unwrap().name, "scape-pca.2");
}

/// The data keys that belong to one kind of `data.path` (issue 58's mutants): `template` to a
/// NumPy or HDF5 path, `array` to a NumPy path, `dataset` to an HDF5 path — each elsewhere is
/// refused naming the key; and the HDF5 source a path names (the file, the dataset from the key,
/// the path's suffix or `verts`, the template).
#[test]
fn data_keys_belong_to_their_kind_of_path() {
    use std::path::Path;
    let cfg = |data: &str| {
        meshdeco::config::Config::from_toml(&format!(
            "name = \"k\"\n[data]\n{data}\n[method]\nkind = \"pca\"\ncomponents = 3\n"
        ))
    };
    for (data, key) in [
        ("path = \"shapes\"\ntemplate = \"t.obj\"", "data.template"),
        ("path = \"shapes\"\narray = \"verts\"", "data.array"),
        ("path = \"x.h5\"\narray = \"verts\"", "data.array"),
        ("path = \"shapes\"\ndataset = \"verts\"", "data.dataset"),
        ("path = \"x.npy\"\ntemplate = \"t.obj\"\ndataset = \"verts\"", "data.dataset"),
    ] {
        let e = cfg(data).err().unwrap_or_else(|| panic!("accepted: {data}")).to_string();
        assert!(e.contains(key) && e.contains("only"), "{data}: {e}");
    }
    let c = cfg("path = \"x.h5:jump\"\ntemplate = \"t.obj\"").unwrap();
    assert_eq!(c.data.hdf5_source(), Some((Path::new("x.h5"), "jump", Some(Path::new("t.obj")))));
    let c = cfg("path = \"x.h5\"\ndataset = \"run\"").unwrap();
    assert_eq!(c.data.hdf5_source(), Some((Path::new("x.h5"), "run", None)));
    let c = cfg("path = \"x.hdf5\"").unwrap();
    assert_eq!(c.data.hdf5_source(), Some((Path::new("x.hdf5"), "verts", None)));
    let c = cfg("path = \"x.npy\"\ntemplate = \"t.obj\"").unwrap();
    assert_eq!((c.data.hdf5_source(), c.data.numpy_template().unwrap()), (None, Some(Path::new("t.obj"))));
    assert_eq!(cfg("path = \"shapes\"").unwrap().data.hdf5_source(), None);
}

#[test]
fn every_splocs_solver_field_is_a_method_key() {
    use serde_json::json;
    let cases: Vec<(&str, &str, Value)> = vec![
        ("components", "components = 7", json!(7)),
        ("sparsity", "sparsity = 1.5", json!(1.5)),
        ("support", "support = [0.2, 0.5]", json!([0.2, 0.5])),
        ("weights", "weights = \"signed\"", json!("signed")),
        ("max_iterations", "max_iterations = 4", json!(4)),
        ("admm", "admm = { rho = 5.0, iterations = 3 }", json!({ "rho": 5.0, "iterations": 3 })),
        ("tolerance", "tolerance = 0.001", json!(0.001)),
        ("seed", "seed = 3", json!(3)),
        ("fixed_centers", "fixed_centers = [[1, 2]]", json!([[1, 2]])),
        ("threads", "threads = 2", json!(2)),
        ("weight_sparsity", "weight_sparsity = 0.1", json!(0.1)),
    ];
    // The method's defaults: every core (threads = 0) where the solver's own default is 1.
    let method_default = serde_json::to_value(SplocsMethod::default().solver_config().unwrap()).unwrap();
    assert_eq!(method_default["threads"], json!(0));
    let solver_default = serde_json::to_value(SplocsConfig::default()).unwrap();
    assert_eq!(fields(&method_default), fields(&solver_default));
    check_keys(&method_default, &cases, |line| {
        let t: toml::Table = toml::from_str(&format!("kind = \"splocs\"\n{line}")).unwrap();
        let MethodConfig::Splocs(m) = MethodConfig::from_table(&t).unwrap_or_else(|e| panic!("`{line}`: {e}")) else {
            panic!("kind")
        };
        serde_json::to_value(m.solver_config().unwrap()).unwrap()
    });
}
