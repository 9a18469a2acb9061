//! The evaluation config (TOML) of `meshdeco eval`, parsed strictly and validated in full before
//! any training starts. Errors name the key (`dataset.<name>.<key>`, `method.<label>.<key>`,
//! `sweep.<key>`, `control_points.<key>`) and the bad value.
//!
//! ```toml
//! name = "scape"                       # report title
//! [[dataset]]                          # one or more; every key of train's [data] section, plus:
//! name = "scape"                       #   file-name-safe, unique (cells/<dataset>/…)
//!                                      #   (align defaults to "rigid" here, as the papers align)
//! ordered = false                      #   true: frames are a time sequence (temporal STED)
//! path = "../shared/data/scape"
//! train = "1-36"
//! test = "37-71"                       #   a test split is required
//! [[method]]                           # one or more; every key of train's [method] section, plus:
//! label = "pca"                        #   file-name-safe, unique (the method's name in tables)
//! kind = "pca"
//! components = [50]                    #   optional: this method's own K list instead of the sweep
//! [sweep]
//! components = [5, 10, 20, 30, 50]     # K of every method without its own list
//! select = "validation"                # optional: per dataset, mark the cell of lowest
//!                                      #   validation Erms (every dataset needs `validation`)
//! [control_points]                     # optional: reconstruction from sparse control points
//! counts = [5, 10, 20, 50, 100, 200]   #   numbers n of control points
//! trials = 5                           #   random start vertices per n (default 5)
//! autoencoder_trials = 1               #   the same for the autoencoder (default 1: its fit is
//!                                      #   an iterative optimisation, about 1 s per shape)
//! gamma = 0.001                        #   Tikhonov weight (default 1e-3, see control_points)
//! methods = ["pca", "splocs"]          #   method labels to include (default: every supported)
//! seed = 0                             #   seed of the start vertices (default 0)
//! ```

use std::path::Path;

use crate::config::{Config, DataConfig, MethodConfig, MethodKind};
use crate::error::{Error, Result};

/// One dataset of the evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalDataset {
    /// Name (directory name under `cells/`, row label of the tables).
    pub name: String,
    /// Whether the frames are a time sequence (temporal STED is measured on the test frames).
    pub ordered: bool,
    /// The validated `[data]` section.
    pub data: DataConfig,
    /// The data table as written (without `name`, `ordered` and `truth`), for the cells'
    /// configs.
    pub table: toml::Table,
    /// `truth = "DIR"`: a planted set (`meshdeco plant`) whose true deformations the cells'
    /// components are scored against (`path`, `template`, `rest`, `train`, `test` and `align`
    /// default to the set's).
    pub truth: Option<std::path::PathBuf>,
}

/// One method of the evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalMethod {
    /// Label (directory name under `cells/<dataset>/`, method column of the tables).
    pub label: String,
    /// Method kind.
    pub kind: MethodKind,
    /// The method's typed config (with the first K of its list, or 1).
    pub method: MethodConfig,
    /// Own K list (opt-out of the sweep), if given.
    pub components: Option<Vec<usize>>,
    /// The datasets it runs on (`datasets = ["scape", …]`); `None`: every dataset.
    pub datasets: Option<Vec<String>>,
    /// The method table as written (without `label`, `components` and `datasets`).
    pub table: toml::Table,
}

/// Sparse control-point reconstruction settings (`[control_points]`).
#[derive(Debug, Clone, PartialEq)]
pub struct ControlPointsConfig {
    /// Numbers of control points n (each ≥ 1, ascending after validation).
    pub counts: Vec<usize>,
    /// Random start vertices per n (≥ 1).
    pub trials: usize,
    /// Random start vertices per n for the autoencoder (≥ 1; its fit is iterative and slow).
    pub autoencoder_trials: usize,
    /// Dimensionless Tikhonov weight γ (≥ 0) of the weight fit.
    pub gamma: f64,
    /// Seed of the start vertices.
    pub seed: u64,
    /// Method labels to include (`None`: every method that supports control points).
    pub methods: Option<Vec<String>>,
}

/// A validated evaluation config.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalConfig {
    /// Report title.
    pub name: String,
    pub datasets: Vec<EvalDataset>,
    pub methods: Vec<EvalMethod>,
    /// The sweep's K list (may be empty when every method has its own).
    pub sweep: Vec<usize>,
    /// `sweep.select = "validation"`: the report marks, per dataset, the cell of lowest
    /// validation Erms (chosen without the test numbers).
    pub select_on_validation: bool,
    pub control_points: Option<ControlPointsConfig>,
}

/// One (dataset, method, K) cell: its resolved `meshdeco train` config.
#[derive(Debug, Clone)]
pub struct Cell {
    /// Index into [`EvalConfig::datasets`].
    pub dataset: usize,
    /// Index into [`EvalConfig::methods`].
    pub method: usize,
    /// Number of components K.
    pub k: usize,
    /// The train config text of the cell (its cache key).
    pub config_text: String,
    /// The validated train config.
    pub config: Config,
}

fn safe_name(key: &str, s: &str) -> Result<()> {
    if s.is_empty() || !s.chars().all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c)) || s.starts_with('.') {
        return Err(Error::config(key, format!("`{s}` must be a non-empty name of letters, digits, '-', '_', '.'")));
    }
    Ok(())
}

fn as_table(key: &str, v: toml::Value) -> Result<toml::Table> {
    match v {
        toml::Value::Table(t) => Ok(t),
        other => Err(Error::config(key, format!("expected a table, got `{other}`"))),
    }
}

fn take_string(t: &mut toml::Table, key: &str, full: &str) -> Result<Option<String>> {
    match t.remove(key) {
        None => Ok(None),
        Some(toml::Value::String(s)) => Ok(Some(s)),
        Some(other) => Err(Error::config(full, format!("`{other}` must be a string"))),
    }
}

fn usize_list(key: &str, v: toml::Value) -> Result<Vec<usize>> {
    let items = match v {
        toml::Value::Integer(i) => vec![toml::Value::Integer(i)],
        toml::Value::Array(a) => a,
        other => return Err(Error::config(key, format!("`{other}` must be a list of positive integers"))),
    };
    let mut out = Vec::new();
    for x in items {
        match x {
            toml::Value::Integer(i) if i >= 1 => out.push(i as usize),
            other => return Err(Error::config(key, format!("`{other}` must be a positive integer"))),
        }
    }
    if out.is_empty() {
        return Err(Error::config(key, "must not be empty"));
    }
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

/// Renames the key of a train-config error into the eval config's namespace.
fn rekey(e: Error, section: &str, prefix: &str) -> Error {
    match e {
        Error::Config { key, message } => {
            let rest = key.strip_prefix(section).unwrap_or(&key).trim_start_matches('.');
            Error::config(format!("{prefix}.{rest}"), message)
        }
        Error::Parse { message, .. } => Error::config(prefix.to_string(), message),
        other => other,
    }
}

/// Fills a planted set's data keys that the dataset table leaves out: its frames, template (also
/// the rest shape), training and test ranges, and no alignment (the frames do not move as a
/// whole, and aligning them would change the true fields).
fn planted_defaults(t: &mut toml::Table, dir: &Path) -> Result<()> {
    let file: crate::eval::planted::TruthFile =
        crate::artifact::read_json(&dir.join(crate::eval::planted::TRUTH_FILE))?;
    let s = |p: &str| dir.join(p).display().to_string();
    t.entry("path").or_insert_with(|| s("frames.npy").into());
    t.entry("template").or_insert_with(|| s("template.obj").into());
    t.entry("rest").or_insert_with(|| s("template.obj").into());
    t.entry("train").or_insert_with(|| format!("1-{}", file.train).into());
    if file.test > 0 {
        t.entry("test").or_insert_with(|| format!("{}-{}", file.train + 1, file.train + file.test).into());
    }
    t.entry("align").or_insert_with(|| "none".into());
    Ok(())
}

/// Builds the `meshdeco train` config text of a dataset table and a method table.
pub fn train_config_text(name: &str, data: &toml::Table, method: &toml::Table) -> String {
    let mut root = toml::Table::new();
    root.insert("name".into(), name.into());
    root.insert("data".into(), toml::Value::Table(data.clone()));
    root.insert("method".into(), toml::Value::Table(method.clone()));
    toml::to_string(&root).unwrap_or_default()
}

impl EvalConfig {
    /// Reads and validates an eval config file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::from_toml(&text).map_err(|e| match e {
            Error::Config { key, message } => Error::config(key, format!("{message} (in {})", path.display())),
            Error::Parse { line, message, .. } => Error::parse(path, line, message),
            other => other,
        })
    }

    /// Parses and validates TOML text.
    pub fn from_toml(text: &str) -> Result<Self> {
        let mut root: toml::Table = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
            Error::parse("<eval config>", line, e.message().to_string())
        })?;
        let name = take_string(&mut root, "name", "name")?.unwrap_or_else(|| "evaluation".into());
        safe_name("name", &name)?;

        let mut datasets = Vec::new();
        match root.remove("dataset") {
            Some(toml::Value::Array(a)) => {
                for (i, v) in a.into_iter().enumerate() {
                    let mut t = as_table(&format!("dataset[{i}]"), v)?;
                    let dname = take_string(&mut t, "name", &format!("dataset[{i}].name"))?
                        .ok_or_else(|| Error::config(format!("dataset[{i}].name"), "is required"))?;
                    let prefix = format!("dataset.{dname}");
                    safe_name(&format!("{prefix}.name"), &dname)?;
                    if datasets.iter().any(|d: &EvalDataset| d.name == dname) {
                        return Err(Error::config(format!("{prefix}.name"), format!("`{dname}` is given twice")));
                    }
                    let ordered = match t.remove("ordered") {
                        None => false,
                        Some(toml::Value::Boolean(b)) => b,
                        Some(other) => {
                            return Err(Error::config(
                                format!("{prefix}.ordered"),
                                format!("`{other}` must be true or false"),
                            ));
                        }
                    };
                    let truth = take_string(&mut t, "truth", &format!("{prefix}.truth"))?.map(std::path::PathBuf::from);
                    if let Some(dir) = &truth {
                        planted_defaults(&mut t, dir)
                            .map_err(|e| Error::config(format!("{prefix}.truth"), e.to_string()))?;
                    }
                    // The papers align frames rigidly before decomposing them (SPLOCS, paper 000
                    // § 3: "rigid alignment through global translation and rotation is performed
                    // before assembling the animation matrix"): an evaluation does so unless the
                    // dataset says `align = "none"` (issue 32).
                    t.entry("align").or_insert_with(|| "rigid".into());
                    let mut probe = toml::Table::new();
                    probe.insert("kind".into(), MethodKind::Pca.name().into());
                    let c = Config::from_toml(&train_config_text("probe", &t, &probe))
                        .map_err(|e| rekey(e, "data", &prefix))?;
                    if c.data.test.is_none() {
                        return Err(Error::config(
                            format!("{prefix}.test"),
                            "is required: the evaluation measures on the test split",
                        ));
                    }
                    datasets.push(EvalDataset { name: dname, ordered, data: c.data, table: t, truth });
                }
            }
            Some(_) => return Err(Error::config("dataset", "must be an array of tables ([[dataset]])")),
            None => return Err(Error::config("dataset", "at least one [[dataset]] is required")),
        }

        let mut methods = Vec::new();
        match root.remove("method") {
            Some(toml::Value::Array(a)) => {
                for (i, v) in a.into_iter().enumerate() {
                    let mut t = as_table(&format!("method[{i}]"), v)?;
                    let label = take_string(&mut t, "label", &format!("method[{i}].label"))?
                        .ok_or_else(|| Error::config(format!("method[{i}].label"), "is required"))?;
                    let prefix = format!("method.{label}");
                    safe_name(&format!("{prefix}.label"), &label)?;
                    if methods.iter().any(|m: &EvalMethod| m.label == label) {
                        return Err(Error::config(format!("{prefix}.label"), format!("`{label}` is given twice")));
                    }
                    let components =
                        t.remove("components").map(|v| usize_list(&format!("{prefix}.components"), v)).transpose()?;
                    let only = match t.remove("datasets") {
                        None => None,
                        Some(toml::Value::Array(a)) if !a.is_empty() => {
                            let mut names = Vec::new();
                            for v in a {
                                match v {
                                    toml::Value::String(n) if datasets.iter().any(|d| d.name == n) => names.push(n),
                                    other => {
                                        return Err(Error::config(
                                            format!("{prefix}.datasets"),
                                            format!("{other} is not the name of a [[dataset]]"),
                                        ));
                                    }
                                }
                            }
                            Some(names)
                        }
                        Some(other) => {
                            return Err(Error::config(
                                format!("{prefix}.datasets"),
                                format!("`{other}` must be a non-empty list of dataset names"),
                            ));
                        }
                    };
                    let mut probe = t.clone();
                    probe.insert("components".into(), (components.as_ref().map_or(1, |c| c[0]) as i64).into());
                    let data = &datasets[0].table;
                    let c = Config::from_toml(&train_config_text("probe", data, &probe))
                        .map_err(|e| rekey(e, "method", &prefix))?;
                    methods.push(EvalMethod {
                        label,
                        kind: c.kind(),
                        method: c.method,
                        components,
                        datasets: only,
                        table: t,
                    });
                }
            }
            Some(_) => return Err(Error::config("method", "must be an array of tables ([[method]])")),
            None => return Err(Error::config("method", "at least one [[method]] is required")),
        }

        let (sweep, select_on_validation) = match root.remove("sweep") {
            None => (Vec::new(), false),
            Some(v) => {
                let mut t = as_table("sweep", v)?;
                let k = t.remove("components").map(|v| usize_list("sweep.components", v)).transpose()?;
                let select = match t.remove("select") {
                    None => false,
                    Some(toml::Value::String(s)) if s == "validation" => true,
                    Some(v) => {
                        return Err(Error::config(
                            "sweep.select",
                            format!("{v} is not \"validation\" (the only choice)"),
                        ));
                    }
                };
                if let Some(key) = t.keys().next() {
                    return Err(Error::config(format!("sweep.{key}"), "unknown key (allowed: components, select)"));
                }
                (k.unwrap_or_default(), select)
            }
        };
        if select_on_validation && let Some(d) = datasets.iter().find(|d| d.data.validation.is_none()) {
            return Err(Error::config(
                format!("dataset.{}.validation", d.name),
                "is required by sweep.select = \"validation\" (frames held out of train to choose on)",
            ));
        }
        if sweep.is_empty()
            && let Some(m) = methods.iter().find(|m| m.components.is_none())
        {
            return Err(Error::config(
                "sweep.components",
                format!("is required: method `{}` has no components list of its own", m.label),
            ));
        }

        let control_points = match root.remove("control_points") {
            None => None,
            Some(v) => {
                let mut t = as_table("control_points", v)?;
                let counts = usize_list(
                    "control_points.counts",
                    t.remove("counts").ok_or_else(|| Error::config("control_points.counts", "is required"))?,
                )?;
                let trials = match t.remove("trials") {
                    None => 5,
                    Some(toml::Value::Integer(i)) if i >= 1 => i as usize,
                    Some(other) => {
                        return Err(Error::config("control_points.trials", format!("`{other}` must be at least 1")));
                    }
                };
                let autoencoder_trials = match t.remove("autoencoder_trials") {
                    None => 1,
                    Some(toml::Value::Integer(i)) if i >= 1 => i as usize,
                    Some(other) => {
                        return Err(Error::config(
                            "control_points.autoencoder_trials",
                            format!("`{other}` must be at least 1"),
                        ));
                    }
                };
                let gamma = match t.remove("gamma") {
                    None => 1e-3,
                    Some(toml::Value::Float(x)) if x.is_finite() && x >= 0.0 => x,
                    Some(toml::Value::Integer(i)) if i >= 0 => i as f64,
                    Some(other) => {
                        return Err(Error::config(
                            "control_points.gamma",
                            format!("`{other}` must be a finite non-negative number"),
                        ));
                    }
                };
                let seed = match t.remove("seed") {
                    None => 0,
                    Some(toml::Value::Integer(i)) if i >= 0 => i as u64,
                    Some(other) => {
                        return Err(Error::config(
                            "control_points.seed",
                            format!("`{other}` must be a non-negative integer"),
                        ));
                    }
                };
                let methods_list = match t.remove("methods") {
                    None => None,
                    Some(toml::Value::Array(a)) => {
                        let mut v = Vec::new();
                        for x in a {
                            match x {
                                toml::Value::String(l) if methods.iter().any(|m: &EvalMethod| m.label == l) => {
                                    v.push(l)
                                }
                                other => {
                                    return Err(Error::config(
                                        "control_points.methods",
                                        format!("`{other}` is not the label of a [[method]]"),
                                    ));
                                }
                            }
                        }
                        Some(v)
                    }
                    Some(other) => {
                        return Err(Error::config(
                            "control_points.methods",
                            format!("`{other}` must be a list of labels"),
                        ));
                    }
                };
                if let Some(key) = t.keys().next() {
                    return Err(Error::config(
                        format!("control_points.{key}"),
                        "unknown key (allowed: counts, trials, autoencoder_trials, gamma, seed, methods)",
                    ));
                }
                Some(ControlPointsConfig { counts, trials, autoencoder_trials, gamma, seed, methods: methods_list })
            }
        };
        if let Some(key) = root.keys().next() {
            return Err(Error::config(
                key.clone(),
                "unknown key (allowed: name, [[dataset]], [[method]], [sweep], [control_points])",
            ));
        }
        Ok(EvalConfig { name, datasets, methods, sweep, select_on_validation, control_points })
    }

    /// K values of a method: its own list or the sweep.
    pub fn ks(&self, method: usize) -> &[usize] {
        self.methods[method].components.as_deref().unwrap_or(&self.sweep)
    }

    /// Every (dataset, method, K) cell in dataset, method, K order, with its validated train
    /// config. Errors (naming the method) when a cell's config does not validate.
    pub fn cells(&self) -> Result<Vec<Cell>> {
        let mut out = Vec::new();
        for (di, d) in self.datasets.iter().enumerate() {
            for (mi, m) in self.methods.iter().enumerate() {
                if m.datasets.as_ref().is_some_and(|only| !only.contains(&d.name)) {
                    continue;
                }
                for &k in self.ks(mi) {
                    let mut t = m.table.clone();
                    t.insert("components".into(), (k as i64).into());
                    let name = format!("{}-{}-K{k}", d.name, m.label);
                    let text = train_config_text(&name, &d.table, &t);
                    let config =
                        Config::from_toml(&text).map_err(|e| rekey(e, "method", &format!("method.{}", m.label)))?;
                    out.push(Cell { dataset: di, method: mi, k, config_text: text, config });
                }
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
name = "t"
[[dataset]]
name = "tube"
path = "synthetic:tube"
train = "every:2"
test = "rest"
ordered = true
[[method]]
label = "pca"
kind = "pca"
[[method]]
label = "ae"
kind = "autoencoder"
components = [4]
iterations = 10
[sweep]
components = [6, 2, 4]
[control_points]
counts = [10, 5]
"#;

    #[test]
    fn parses_cells_and_defaults() {
        let c = EvalConfig::from_toml(GOOD).unwrap();
        assert_eq!(c.sweep, vec![2, 4, 6]);
        assert!(c.datasets[0].ordered);
        let cells = c.cells().unwrap();
        let ks: Vec<(usize, usize)> = cells.iter().map(|c| (c.method, c.k)).collect();
        assert_eq!(ks, vec![(0, 2), (0, 4), (0, 6), (1, 4)]);
        // Frames are aligned rigidly unless the dataset says otherwise (as the papers align).
        assert_eq!(c.datasets[0].data.align, crate::config::Align::Rigid);
        assert!(cells.iter().all(|cell| cell.config.data.align == crate::config::Align::Rigid));
        let own = EvalConfig::from_toml(&GOOD.replace("ordered = true", "ordered = true\nalign = \"none\"")).unwrap();
        assert_eq!(own.datasets[0].data.align, crate::config::Align::None);
        assert!(own.cells().unwrap().iter().all(|cell| cell.config.data.align == crate::config::Align::None));
        assert_eq!(cells[3].config.kind(), MethodKind::Autoencoder);
        let MethodConfig::Autoencoder(m) = &cells[3].config.method else { panic!("kind") };
        assert_eq!(m.iterations, 10);
        let cp = c.control_points.clone().unwrap();
        assert_eq!((cp.counts, cp.trials, cp.gamma, cp.seed), (vec![5, 10], 5, 1e-3, 0));
        // The cell text is deterministic and differs between cells.
        assert_eq!(c.cells().unwrap()[0].config_text, cells[0].config_text);
        assert_ne!(cells[0].config_text, cells[1].config_text);
    }

    /// `datasets = [...]` runs a method on the named datasets only (e.g. PCA at each one's
    /// largest K).
    #[test]
    fn a_method_runs_on_its_datasets_only() {
        let two = GOOD.replace(
            "[[method]]\nlabel = \"pca\"",
            "[[dataset]]\nname = \"pieces\"\npath = \"synthetic:pieces\"\ntrain = \"every:2\"\ntest = \"rest\"\n\n[[method]]\nlabel = \"pca\"\ndatasets = [\"pieces\"]",
        );
        let c = EvalConfig::from_toml(&two).unwrap();
        assert_eq!(c.methods[0].datasets, Some(vec!["pieces".to_string()]));
        let cells: Vec<(usize, usize, usize)> = c.cells().unwrap().iter().map(|c| (c.dataset, c.method, c.k)).collect();
        // tube: the autoencoder only; pieces: PCA at every K, then the autoencoder.
        assert_eq!(cells, vec![(0, 1, 4), (1, 0, 2), (1, 0, 4), (1, 0, 6), (1, 1, 4)]);
        // The key does not reach the method's own config.
        assert!(!c.methods[0].table.contains_key("datasets"));
    }

    #[test]
    fn errors_name_the_key() {
        let cases = [
            (GOOD.replace("train = \"every:2\"", "trian = \"every:2\""), "trian"),
            (GOOD.replace("iterations = 10", "iteratons = 10"), "iteratons"),
            (GOOD.replace("iterations = 10", "sparsity = 1.0"), "method.ae.sparsity"),
            (GOOD.replace("[sweep]", "[sweep]\nsteps = 3"), "sweep.steps"),
            (GOOD.replace("counts = [10, 5]", "counts = [10, 0]"), "control_points.counts"),
            (GOOD.replace("counts = [10, 5]", "counts = [10]\ntrails = 3"), "control_points.trails"),
            (GOOD.replace("test = \"rest\"", ""), "dataset.tube.test"),
            (GOOD.replace("counts = [10, 5]", "counts = [10]\nmethods = [\"ica\"]"), "control_points.methods"),
            (GOOD.replace("name = \"t\"", "name = \"t\"\nsweeep = 1"), "sweeep"),
            (GOOD.replace("label = \"ae\"", "label = \"pca\""), "method.pca.label"),
            (GOOD.replace("train = \"every:2\"", "train = \"9-3\""), "dataset.tube.train"),
            (GOOD.replace("kind = \"pca\"", "kind = \"pca\"\nlayers = 2"), "method.pca.layers"),
            (GOOD.replace("name = \"t\"", "name = \"t\"\nmethods = 1"), "methods"),
            (GOOD.replace("label = \"ae\"", "label = \"ae\"\ndatasets = [\"tbue\"]"), "method.ae.datasets"),
            (GOOD.replace("label = \"ae\"", "label = \"ae\"\ndatasets = []"), "method.ae.datasets"),
        ];
        for (text, needle) in cases {
            let e = EvalConfig::from_toml(&text).unwrap_err().to_string();
            assert!(e.contains(needle), "`{needle}` not in `{e}`");
        }
    }
}
