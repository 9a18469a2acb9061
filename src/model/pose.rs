//! What a pose asks of a [`super::Model`], whatever the method: the options (one set of
//! defaults, shared by `meshdeco pose` and the viewer's `/api/pose`), the vertex constraints
//! (one type, read from either JSON spelling), and the result.

use std::collections::BTreeSet;

use serde_json::Value;

use crate::error::{Error, Result};
use crate::geometry::pin_spread::PinSpread;
use crate::math::vec3::{add, sub};
use crate::mesh::Vec3;
pub use crate::methods::posing::PosePrior;

/// Hyperparameters of one pose. Every model reads the ones it lists in
/// [`super::Model::pose_parameters`] and ignores the others.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseOptions {
    /// γ ≥ 0, dimensionless: pull towards the start (paper 002 Eq. 8/10's regulariser, in the
    /// whole shape's mean squared vertex motion and measured as [`PoseOptions::prior`] says, as
    /// strong wherever the pins are: [`crate::methods::posing::Pull`]; the autoencoder's pull
    /// towards its start code likewise).
    pub gamma: f64,
    /// β ≥ 0: boundary consistency between regions (region PCA; squared vertex differences).
    pub beta: f64,
    /// Gauss–Newton iterations at most (the autoencoder), 1 ..= [`PoseOptions::MAX_ITERATIONS`].
    pub max_iterations: usize,
    /// What the pull towards the start measures: the whole shape's change, the weights' (the
    /// paper's Eq. 8/10) or the weights' by the training weights' spread (PCA and SPLOCS); see
    /// [`crate::methods::posing`].
    pub prior: PosePrior,
    /// Wall time an iterative solver (the autoencoder's) may take before it answers with the
    /// best shape so far (`None`: no limit; the viewer sets one).
    pub time_limit: Option<std::time::Duration>,
    /// Radius of the landing correction, as a fraction of the rest mesh's bounding-box diagonal
    /// (0: off, the model's own shape). What the model's shape leaves between a pin and its
    /// target is added as a smooth displacement that is zero farther than this along the
    /// surface from every pin ([`crate::geometry::pin_spread`]), so that every pin lands; see
    /// [`landed_pose`].
    pub spread: f64,
    /// The weights stay at the start (`false` by default): the shape is the start shape plus the
    /// landing correction alone, the model's components do nothing. The drag benchmark's null
    /// (what the correction gives without the model); with `spread` 0 nothing moves.
    pub freeze: bool,
    /// The most any vertex of the model's shape may move, as a multiple of the largest drag
    /// (0: no bound): a pose that moves farther is taken back towards the start until it does
    /// not, and the landing correction lands the pins ([`landed_pose`]). A drag of a few
    /// centimetres never swings a limb a metre away, whatever the components.
    pub reach: f64,
}

impl Default for PoseOptions {
    /// The shape prior, γ = 1, β = 10⁻³, 30 iterations, no time limit, landing radius 0.2,
    /// reach 1.3; each model kind's defaults are its [`super::Model::pose_defaults`].
    fn default() -> Self {
        PoseOptions {
            gamma: 1.0,
            beta: 1e-3,
            max_iterations: 30,
            prior: PosePrior::Shape,
            time_limit: None,
            spread: 0.2,
            freeze: false,
            reach: 1.3,
        }
    }
}

impl PoseOptions {
    /// The defaults of PCA and SPLOCS ([`super::Model::pose_defaults`]; each model kind's file
    /// names its own): every pull as strong
    /// wherever the pins are, the landing correction at radius 0.2 and reach 1.3, and
    ///
    /// - PCA and SPLOCS: the data prior ([`PosePrior::Data`]), γ = 5;
    /// - region PCA: the weights prior, γ = 0.03, β = 10⁻³;
    /// - the autoencoder: the weights (code) prior, γ = 1.
    ///
    /// Chosen with `meshdeco drag-bench` on *validation* drags (`DRAG_BENCH_FRAMES=validation
    /// scripts/drag-bench`): the pose configs (and the non-negative `configs/scape-splocs.toml`)
    /// trained on part of the training frames (SCAPE 1–30, face-poses 1–5; region PCA K 60,
    /// PCA K 29), pins moved towards the held-out training frames (SCAPE 31–36, face-poses
    /// 6–7; never the test frames), 50 drags per pin count (docs/posing-drag-bench.md): per
    /// kind, the setting with the lowest posed ÷ null Erms at three and ten pins whose one-pin
    /// drags keep the 90th percentile of max motion ÷ drag within 2 (γ 0.001 … 3, shape /
    /// weights / data prior, reach off / 1 / 1.3, radius 0.05 / 0.1 / 0.2). Reach 1.3 (of 1 and
    /// 1.3) bounds the one-pin tail (without it, non-negative SPLOCS swings a limb 3.6 × its
    /// drag at γ 0.3) at the least cost in Erms.
    pub fn linear_defaults() -> PoseOptions {
        PoseOptions { prior: PosePrior::Data, gamma: 5.0, ..PoseOptions::default() }
    }

    /// Region PCA's defaults (see [`PoseOptions::linear_defaults`]): the weights prior, γ = 0.03.
    pub fn region_defaults() -> PoseOptions {
        PoseOptions { prior: PosePrior::Weights, gamma: 0.03, ..PoseOptions::default() }
    }

    /// The autoencoder's defaults (see [`PoseOptions::linear_defaults`]): the code prior, γ = 1.
    pub fn autoencoder_defaults() -> PoseOptions {
        PoseOptions { prior: PosePrior::Weights, ..PoseOptions::default() }
    }

    /// The largest `max_iterations` accepted.
    pub const MAX_ITERATIONS: usize = 1000;
    /// The largest `spread` accepted (the whole diagonal).
    pub const MAX_SPREAD: f64 = 1.0;

    /// Checks every value; the error names the option (`` `gamma` ``, `` `beta` ``,
    /// `` `max_iterations` ``) and the value.
    pub fn validate(&self) -> Result<()> {
        for (key, v) in [("gamma", self.gamma), ("beta", self.beta)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::Invalid(format!("`{key}` {v}: must be a finite number ≥ 0")));
            }
        }
        if !(self.spread.is_finite() && (0.0..=Self::MAX_SPREAD).contains(&self.spread)) {
            return Err(Error::Invalid(format!(
                "`spread` {}: must be a number from 0 (off) to {} (a fraction of the bounding-box diagonal)",
                self.spread,
                Self::MAX_SPREAD
            )));
        }
        if !(self.reach.is_finite() && (self.reach == 0.0 || self.reach >= 1.0)) {
            return Err(Error::Invalid(format!(
                "`reach` {}: must be 0 (no bound) or a number ≥ 1 (a multiple of the largest drag)",
                self.reach
            )));
        }
        if !(1..=Self::MAX_ITERATIONS).contains(&self.max_iterations) {
            return Err(Error::Invalid(format!(
                "`max_iterations` {}: must be an integer from 1 to {}",
                self.max_iterations,
                Self::MAX_ITERATIONS
            )));
        }
        Ok(())
    }

    /// The options as JSON (`{"gamma", "beta", "max_iterations", "prior", "spread", "freeze",
    /// "reach"}`), as the viewer offers them.
    pub fn to_json(&self) -> Value {
        serde_json::json!({
            "gamma": self.gamma,
            "beta": self.beta,
            "max_iterations": self.max_iterations,
            "prior": self.prior.name(),
            "spread": self.spread,
            "freeze": self.freeze,
            "reach": self.reach,
        })
    }

    /// These options with the weights frozen at the start ([`PoseOptions::freeze`]): the drag
    /// benchmark's null.
    pub fn frozen(&self) -> PoseOptions {
        PoseOptions { freeze: true, ..*self }
    }
}

/// Poses `model` ([`super::Model::pose`]) and lands the pins: with `options.spread` > 0, what
/// the model's shape leaves between each pin and its target is spread over the pin's
/// surroundings by `spreader` (built once per model from its rest mesh: [`spreader`]), zero
/// farther than `spread` × the rest's bounding-box diagonal along the surface from every pin.
/// [`PoseResult::positions`] are then the landed shape, while [`PoseResult::weights`] stay the
/// model's (their decoding is the model's own shape); with `spread` 0 both agree. With
/// `options.freeze` the model is not asked: the weights are `w0` and the model's shape is their
/// decoding (the landing correction alone moves it).
pub fn landed_pose(
    model: &dyn super::Model,
    spreader: &PinSpread,
    vertices: &[usize],
    targets: &[Vec3],
    w0: &[f64],
    options: &PoseOptions,
) -> Result<PoseResult> {
    let mut r = if options.freeze {
        let start = model.decode(&[w0.to_vec()])?.remove(0);
        PoseResult { positions: start.clone(), start, weights: w0.to_vec() }
    } else {
        model.pose(vertices, targets, w0, options)?
    };
    if options.reach > 0.0 && !options.freeze {
        reach_back(model, vertices, targets, w0, options.reach, &mut r)?;
    }
    if options.spread > 0.0 {
        if spreader.n_vertices() != r.positions.len() {
            return Err(Error::Invalid(format!(
                "the pin spreader has {} vertices, the model {}",
                spreader.n_vertices(),
                r.positions.len()
            )));
        }
        let residuals: Vec<Vec3> = vertices.iter().zip(targets).map(|(&v, &t)| sub(t, r.positions[v])).collect();
        let d = spreader.field(vertices, &residuals, options.spread * spreader.diagonal())?;
        for (p, &dv) in r.positions.iter_mut().zip(&d) {
            *p = add(*p, dv);
        }
    }
    Ok(r)
}

/// [`PoseOptions::reach`]: when the model's shape moves some vertex farther than `reach` × the
/// largest drag (‖target − start‖ over the pins), the weights are taken back along the straight
/// line to `w0` until it does not (exact for linear models; a few steps for the autoencoder,
/// whose decoding is not linear in its code).
fn reach_back(
    model: &dyn super::Model,
    vertices: &[usize],
    targets: &[Vec3],
    w0: &[f64],
    reach: f64,
    r: &mut PoseResult,
) -> Result<()> {
    let drag = vertices.iter().zip(targets).map(|(&v, t)| crate::mesh::dist(r.start[v], *t)).fold(0.0, f64::max);
    let limit = reach * drag;
    let mut scale = 1.0;
    let full = r.weights.clone();
    for _ in 0..4 {
        let most = r.positions.iter().zip(&r.start).map(|(p, q)| crate::mesh::dist(*p, *q)).fold(0.0, f64::max);
        if most <= limit * (1.0 + 1e-9) || most.is_nan() || most <= 0.0 {
            break;
        }
        scale *= limit / most;
        let w: Vec<f64> = w0.iter().zip(&full).map(|(a, b)| a + scale * (b - a)).collect();
        r.positions = model.decode(std::slice::from_ref(&w))?.remove(0);
        r.weights = w;
    }
    Ok(())
}

/// The pin spreader of `model`'s rest mesh (for [`landed_pose`]).
pub fn spreader(model: &dyn super::Model) -> PinSpread {
    let rest = model.rest();
    PinSpread::new(&rest.positions, &rest.faces)
}

/// The result of one pose.
#[derive(Debug, Clone)]
pub struct PoseResult {
    /// Start positions (N, data units).
    pub start: Vec<Vec3>,
    /// Posed positions (N, data units): the model's shape, landed by [`landed_pose`] when it spreads.
    pub positions: Vec<Vec3>,
    /// Posed weights / coefficients / latent code.
    pub weights: Vec<f64>,
}

/// Vertex constraints of a pose: distinct vertex indices (0-based, sorted) and their target
/// positions (data units, finite).
#[derive(Debug, Clone, PartialEq)]
pub struct Constraints {
    pub vertices: Vec<usize>,
    pub targets: Vec<Vec3>,
}

impl Constraints {
    /// Reads constraints from JSON text (a constraints file of `meshdeco pose`), in either
    /// spelling of [`Constraints::from_json`]. A key given twice in an object is an error (JSON
    /// readers usually keep the last silently). Errors start with `source`.
    pub fn from_json_text(source: &str, text: &str, n_vertices: usize) -> Result<Self> {
        let pairs: Spelled = serde_json::from_str(text).map_err(|e| {
            Error::Invalid(format!(
                "{source}: line {} column {}: {e} (expected {{\"vertex index\": [x, y, z], ...}} or [{{\"vertex\": index, \"target\": [x, y, z]}}, ...])",
                e.line(),
                e.column()
            ))
        })?;
        Self::from_entries(source, pairs.0, n_vertices)
    }

    /// Reads constraints from a JSON value: an object `{"vertex index": [x, y, z], …}` or an
    /// array `[{"vertex": index, "target": [x, y, z]}, …]` (the viewer's `/api/pose`). Errors
    /// start with `source` and name the entry.
    pub fn from_json(source: &str, value: &Value, n_vertices: usize) -> Result<Self> {
        let entries = match value {
            Value::Object(m) => m.iter().map(|(k, v)| Entry::Keyed(k.clone(), v.clone())).collect(),
            Value::Array(a) => a.iter().cloned().map(Entry::Listed).collect(),
            other => {
                return Err(Error::Invalid(format!(
                    "{source}: expected {{\"vertex index\": [x, y, z], ...}} or [{{\"vertex\": index, \"target\": [x, y, z]}}, ...], got {}",
                    kind_of(other)
                )));
            }
        };
        Self::from_entries(source, entries, n_vertices)
    }

    fn from_entries(source: &str, entries: Vec<Entry>, n: usize) -> Result<Self> {
        if entries.is_empty() {
            return Err(Error::Invalid(format!("{source}: no constraint given (the list is empty)")));
        }
        let bad = |m: String| Error::Invalid(format!("{source}: {m}"));
        let mut seen = BTreeSet::new();
        let mut pairs = Vec::with_capacity(entries.len());
        for (i, e) in entries.into_iter().enumerate() {
            let (what, v, t) = match e {
                Entry::Keyed(k, t) => {
                    let v = k.trim().parse::<u64>().map_err(|_| bad(format!("key `{k}` is not a vertex index")))?;
                    (format!("key `{k}`"), v, t)
                }
                Entry::Listed(c) => {
                    let v = c.get("vertex").and_then(Value::as_u64).ok_or_else(|| {
                        bad(format!("constraints[{i}]: `vertex` must be a vertex index (integer ≥ 0)"))
                    })?;
                    let t = c.get("target").cloned().unwrap_or(Value::Null);
                    (format!("constraints[{i}]"), v, t)
                }
            };
            if v >= n as u64 {
                return Err(bad(format!(
                    "{what}: vertex {v} out of range (the model has {n} vertices, 0..{})",
                    n.saturating_sub(1)
                )));
            }
            let v = v as usize;
            let Some(a) = t.as_array().filter(|a| a.len() == 3) else {
                return Err(bad(format!("{what}: target of vertex {v} must be 3 finite numbers [x, y, z], got {t}")));
            };
            let mut target = [0.0; 3];
            for (j, x) in a.iter().enumerate() {
                target[j] = x
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(format!("{what}: target[{j}] must be a number (vertex {v}), got {x}")))?;
            }
            if !seen.insert(v) {
                return Err(bad(format!("{what}: vertex {v} is constrained twice; give each vertex once")));
            }
            pairs.push((v, target));
        }
        pairs.sort_by_key(|p| p.0);
        Ok(Constraints { vertices: pairs.iter().map(|p| p.0).collect(), targets: pairs.iter().map(|p| p.1).collect() })
    }

    /// Number of constrained vertices.
    pub fn len(&self) -> usize {
        self.vertices.len()
    }

    /// Whether there is none (never, once read).
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }
}

fn kind_of(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// One constraint as written: `"v": [x, y, z]` in an object, or `{"vertex", "target"}` in an array.
enum Entry {
    Keyed(String, Value),
    Listed(Value),
}

/// The entries of a JSON object in file order with duplicates kept, or of an array.
struct Spelled(Vec<Entry>);

impl<'de> serde::Deserialize<'de> for Spelled {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Spelled;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a JSON object {\"vertex index\": [x, y, z], ...} or an array of {\"vertex\", \"target\"}")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, mut m: A) -> std::result::Result<Spelled, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = m.next_entry::<String, Value>()? {
                    out.push(Entry::Keyed(k, v));
                }
                Ok(Spelled(out))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut s: A) -> std::result::Result<Spelled, A::Error> {
                let mut out = Vec::new();
                while let Some(v) = s.next_element::<Value>()? {
                    out.push(Entry::Listed(v));
                }
                Ok(Spelled(out))
            }
        }
        d.deserialize_any(V)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_spellings_read_the_same_constraints() {
        let a = Constraints::from_json_text("c.json", r#"{"7": [1, 2, 3], "2": [0, 0, 0.5]}"#, 10).unwrap();
        let b = Constraints::from_json_text(
            "c.json",
            r#"[{"vertex": 2, "target": [0, 0, 0.5]}, {"vertex": 7, "target": [1, 2, 3]}]"#,
            10,
        )
        .unwrap();
        assert_eq!(a, b);
        assert_eq!(a.vertices, [2, 7]);
        let v: Value =
            serde_json::from_str(r#"[{"vertex": 7, "target": [1, 2, 3]}, {"vertex": 2, "target": [0, 0, 0.5]}]"#)
                .unwrap();
        assert_eq!(Constraints::from_json("body", &v, 10).unwrap(), a);
    }

    #[test]
    fn bad_constraints_name_the_entry() {
        let err = |t: &str| Constraints::from_json_text("c.json", t, 10).unwrap_err().to_string();
        assert!(err(r#"{"3": [0, 0, 0], "3": [1, 1, 1]}"#).contains("vertex 3 is constrained twice"));
        assert!(err(r#"{"x": [0, 0, 0]}"#).contains("key `x` is not a vertex index"));
        assert!(err(r#"{"10": [0, 0, 0]}"#).contains("vertex 10 out of range (the model has 10 vertices, 0..9)"));
        assert!(err(r#"[{"vertex": 1, "target": [0, 0]}]"#).contains("constraints[0]: target of vertex 1 must be"));
        assert!(err(r#"[{"vertex": -1, "target": [0, 0, 0]}]"#).contains("constraints[0]: `vertex` must be"));
        assert!(err("{}").contains("no constraint given"));
        assert!(err("[1, 2").starts_with("c.json: line 1"));
    }

    #[test]
    fn options_are_validated_by_name() {
        assert!(PoseOptions::default().validate().is_ok());
        let e = PoseOptions { gamma: -1.0, ..Default::default() }.validate().unwrap_err().to_string();
        assert!(e.contains("gamma") && e.contains("-1"), "{e}");
        let e = PoseOptions { max_iterations: 1001, ..Default::default() }.validate().unwrap_err().to_string();
        assert!(e.contains("max_iterations") && e.contains("1001"), "{e}");
    }
}
