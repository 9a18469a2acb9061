//! Ground truth for the components: known localized deformations planted on a real mesh and
//! mixed sparsely into frames (`meshdeco plant`), so that a method's components can be scored
//! against the deformations that made the data ([`crate::metrics::recovery`], `meshdeco eval`
//! with `truth = "DIR"`).
//!
//! **Deformations.** D deformations, each confined to a geodesic disc of radius r around a
//! centre vertex c, with the smooth falloff s(g) = (1 − (g/r)²)³ (1 at c, 0 with zero slope at
//! g = r; g the heat-method geodesic distance on the rest mesh). Three kinds, by weight w:
//!
//! - **pull**: every vertex moves by w·A·s·u, u the unit normal at c tilted towards a random
//!   tangent (a bulge, a raised brow); A ∈ [0.12, 0.22]·r;
//! - **hinge**: a local rotation of the disc about a hinge line, as a jaw, an eyelid or a limb
//!   turns: the vertex p turns by the angle w·θ·s about the axis a through the pivot h, where
//!   h = c + 0.6·r·t lies towards the rest of the mesh (t the tangent direction at c towards
//!   the mesh's centroid) and a = n × t; |θ| ∈ [12°, 24°]. Not linear in w: a linear method
//!   needs a second component for the arc;
//! - **stretch**: the disc stretches (or squashes) along a tangent direction t:
//!   w·α·s·((p − c)·t)·t, |α| ∈ [0.4, 0.7].
//!
//! The three kinds' peak displacements at weight 1 are alike (about 0.1–0.25 r).
//!
//! Left/right pairs: when the rest mesh is mirror-symmetric (a plane through the centroid
//! perpendicular to a coordinate or principal axis maps it onto itself within 2 % of the
//! diagonal), D/4 pairs of deformations are planted, the second at the mirror image
//! of the first's centre with mirrored directions (`_l` / `_r`). Centres are spread by farthest
//! points; every fifth single deformation shares the centre of an earlier one with another kind
//! (overlapping supports).
//!
//! **Frames.** Training frames first, then test frames. Each frame has 1 to `max_active`
//! deformations active (uniformly many, uniformly chosen) with weights uniform in [0.1, 1];
//! the frame is the rest mesh plus the sum of their displacements, plus Gaussian noise of
//! `noise` × the bounding-box diagonal per coordinate (drawn from a stream of its own: the same
//! seed gives the same deformations and weights at every noise level).
//!
//! **True fields.** Each deformation's displacement at weight 1 (N × 3, data units).
//!
//! **Identifiable.** A deformation counts in the recovery score when it is active in at least
//! [`MIN_ACTIVE_FRAMES`] training frames and its field is not (nearly) a combination of the
//! others: the relative residual of its least-squares projection onto the other fields is at
//! least [`MIN_INDEPENDENCE`].
//!
//! **Directory** (written all at once, like a model: `artifact::Staging`; every file listed with
//! its CRC-32 in `manifest.json` and verified when read): `frames.npy` (F × N × 3 float64),
//! `template.obj` (the rest mesh), `fields.npy` (D × N × 3 float64), `weights.csv` (F × D true
//! weights), `truth.json` ([`TruthFile`]), and `eval.toml` (an evaluation of the five methods on
//! the set).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::artifact;
use crate::error::{Error, Result};
use crate::geometry::decimate::decimate;
use crate::geometry::heat_geodesics::HeatGeodesics;
use crate::math::mat3::{exp_so3, mat_vec};
use crate::math::vec3::{Vec3, add, cross, dist, dot, norm, normalize, scale, sub};
use crate::mesh::normals::{NormalWeighting, vertex_normals};
use crate::mesh::{TriMesh, bounding_box};
use crate::rng::Rng;

/// Version of the planted directory's layout.
pub const TRUTH_FORMAT: u32 = 1;
/// Training frames a deformation must be active in to count as identifiable.
pub const MIN_ACTIVE_FRAMES: usize = 3;
/// Smallest relative residual of a field's projection onto the others for it to count.
pub const MIN_INDEPENDENCE: f64 = 0.1;
/// The truth file's name.
pub const TRUTH_FILE: &str = "truth.json";
/// The true fields' file name.
pub const FIELDS_FILE: &str = "fields.npy";
/// The true weights (frame × deformation, `frame,c0,c1,…`), beside the frames.
pub const WEIGHTS_FILE: &str = "weights.csv";

/// Which mirror plane pairs deformations (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MirrorChoice {
    /// The best plane through the centroid perpendicular to a coordinate or principal axis,
    /// when it maps the mesh onto itself within 2 % of the diagonal.
    #[default]
    Auto,
    /// No pairs.
    None,
    /// The plane perpendicular to this coordinate axis (0 = x) through the centroid.
    Axis(usize),
}

/// Settings of a planted set.
#[derive(Debug, Clone, PartialEq)]
pub struct PlantConfig {
    /// Number of deformations D (1 ..= 500).
    pub deformations: usize,
    /// Training and test frames.
    pub train: usize,
    pub test: usize,
    /// Noise standard deviation per coordinate, as a fraction of the bounding-box diagonal.
    pub noise: f64,
    /// Most deformations active in one frame (1 ..= D).
    pub max_active: usize,
    /// [min, max] radius of a deformation's disc, as fractions of the bounding-box diagonal.
    pub radius: [f64; 2],
    /// Decimate the mesh to at most this many vertices first.
    pub vertices: Option<usize>,
    pub mirror: MirrorChoice,
    pub seed: u64,
}

impl Default for PlantConfig {
    fn default() -> Self {
        PlantConfig {
            deformations: 40,
            train: 200,
            test: 100,
            noise: 1e-4,
            max_active: 4,
            radius: [0.08, 0.3],
            vertices: None,
            mirror: MirrorChoice::Auto,
            seed: 0,
        }
    }
}

impl PlantConfig {
    /// Checks every setting; errors name the flag.
    pub fn validate(&self) -> Result<()> {
        let bad = |flag: &str, m: String| Err(Error::Invalid(format!("{flag}: {m}")));
        if !(1..=500).contains(&self.deformations) {
            return bad("--deformations", format!("{} is outside 1 ..= 500", self.deformations));
        }
        if self.train == 0 || self.train + self.test > 1_000_000 {
            return bad(
                "--train",
                format!("{} training and {} test frames: 1 ..= 1 000 000 in all", self.train, self.test),
            );
        }
        if !(self.noise.is_finite() && (0.0..=0.1).contains(&self.noise)) {
            return bad("--noise", format!("{} is outside [0, 0.1] (a fraction of the diagonal)", self.noise));
        }
        if self.max_active == 0 || self.max_active > self.deformations {
            return bad(
                "--max-active",
                format!("{} is outside 1 ..= {} (the deformations)", self.max_active, self.deformations),
            );
        }
        let [lo, hi] = self.radius;
        if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo <= hi && hi <= 1.0) {
            return bad("--radius", format!("[{lo}, {hi}] must satisfy 0 < min ≤ max ≤ 1 (fractions of the diagonal)"));
        }
        if let Some(v) = self.vertices
            && v < 100
        {
            return bad("--vertices", format!("{v}: at least 100"));
        }
        if let MirrorChoice::Axis(a) = self.mirror
            && a > 2
        {
            return bad("--mirror", format!("axis {a}"));
        }
        Ok(())
    }
}

/// Kind of a planted deformation (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PlantKind {
    Pull,
    Hinge,
    Stretch,
}

impl PlantKind {
    fn name(self) -> &'static str {
        match self {
            PlantKind::Pull => "pull",
            PlantKind::Hinge => "hinge",
            PlantKind::Stretch => "stretch",
        }
    }
}

/// One planted deformation, as recorded in `truth.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlantedDeformation {
    /// `<kind><index>` with `_l` / `_r` for a mirrored pair.
    pub name: String,
    pub kind: PlantKind,
    /// Centre vertex (0-based).
    pub center: usize,
    /// Radius of the disc (geodesic, data units).
    pub radius: f64,
    /// Index of the mirrored partner, if any.
    pub partner: Option<usize>,
    /// Pull: displacement at the centre (data units); hinge: angle θ (radians); stretch: α.
    pub amplitude: f64,
    /// Pull: direction u; hinge: axis a; stretch: direction t (unit vectors).
    pub direction: Vec3,
    /// Hinge only: the pivot h (data units).
    pub pivot: Option<Vec3>,
    /// Vertices moving more than 5 % of the peak at weight 1.
    pub support: usize,
    /// Largest vertex displacement at weight 1 (data units).
    pub peak: f64,
    /// Training frames it is active in.
    pub train_active: usize,
    /// Relative residual of its field's least-squares projection onto the other fields.
    pub independence: f64,
    /// Whether it counts in the recovery score (see the module docs).
    pub identifiable: bool,
}

/// `truth.json`: what the planted directory holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthFile {
    pub format: u32,
    /// The mesh the deformations were planted on, as given.
    pub source: String,
    /// Vertices and faces of the rest mesh (after decimation).
    pub n_vertices: usize,
    pub n_faces: usize,
    /// Vertices of the source mesh before decimation.
    pub source_vertices: usize,
    /// Bounding-box diagonal of the rest mesh (data units).
    pub diagonal: f64,
    pub seed: u64,
    /// Noise as a fraction of the diagonal, and its standard deviation in data units.
    pub noise: f64,
    pub noise_sigma: f64,
    pub max_active: usize,
    pub radius: [f64; 2],
    /// Mirror plane (unit normal, offset: n·x = offset) that paired deformations, if any, and
    /// its symmetry error (median distance of a reflected vertex to the mesh, ÷ diagonal).
    pub mirror: Option<(Vec3, f64, f64)>,
    /// Training frames are 1 ..= train, test frames train + 1 ..= train + test (1-based, as
    /// `data.train` / `data.test` select them).
    pub train: usize,
    pub test: usize,
    /// Erms (1000 · RMS, data units) of the frames' least-squares projection onto the true
    /// fields (around the rest mesh): what a perfect linear model of the deformations reaches.
    pub oracle_train_erms: f64,
    pub oracle_test_erms: f64,
    /// Erms of the rest mesh itself (every weight zero).
    pub rest_test_erms: f64,
    /// Number of identifiable deformations.
    pub identifiable: usize,
    pub deformations: Vec<PlantedDeformation>,
}

/// A planted set in memory.
#[derive(Debug, Clone)]
pub struct PlantedSet {
    pub rest: TriMesh,
    pub truth: TruthFile,
    /// D true fields (N × 3 each, data units).
    pub fields: Vec<Vec<Vec3>>,
    /// F × D true weights.
    pub weights: Vec<Vec<f64>>,
    /// F frames (N × 3 each).
    pub frames: Vec<Vec<Vec3>>,
}

/// Falloff s(g) = (1 − (g/r)²)³ inside the disc, 0 outside.
fn falloff(g: f64, r: f64) -> f64 {
    if g >= r {
        0.0
    } else {
        let t = g / r;
        (1.0 - t * t).powi(3)
    }
}

/// The mirror plane (unit normal n, offset d with n·x = d) and its error, per `choice`.
fn mirror_plane(p: &[Vec3], diagonal: f64, choice: MirrorChoice) -> Option<(Vec3, f64, f64)> {
    let n = p.len() as f64;
    let c = scale(p.iter().fold([0.0; 3], |a, q| add(a, *q)), 1.0 / n);
    let mut candidates: Vec<Vec3> = Vec::new();
    match choice {
        MirrorChoice::None => return None,
        MirrorChoice::Axis(a) => {
            let mut e = [0.0; 3];
            e[a] = 1.0;
            candidates.push(e);
        }
        MirrorChoice::Auto => {
            candidates.extend([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
            // Principal axes by power iteration on the covariance.
            let mut cov = [[0.0; 3]; 3];
            for q in p {
                let d = sub(*q, c);
                for i in 0..3 {
                    for j in 0..3 {
                        cov[i][j] += d[i] * d[j] / n;
                    }
                }
            }
            let mut found: Vec<Vec3> = Vec::new();
            for start in [[1.0, 0.3, 0.1], [0.2, 1.0, 0.4], [0.3, 0.1, 1.0]] {
                let mut v = normalize(start);
                for _ in 0..200 {
                    let mut w = mat_vec(&cov, v);
                    for f in &found {
                        w = sub(w, scale(*f, dot(w, *f)));
                    }
                    if norm(w) == 0.0 {
                        break;
                    }
                    v = normalize(w);
                }
                found.push(v);
            }
            candidates.extend(found);
        }
    }
    // Symmetry error: median distance of reflected sample vertices to the nearest vertex.
    let step = (p.len() / 400).max(1);
    let mut best: Option<(Vec3, f64, f64)> = None;
    for nrm in candidates {
        let d = dot(nrm, c);
        let mut errs: Vec<f64> = p
            .iter()
            .step_by(step)
            .map(|q| {
                let r = sub(*q, scale(nrm, 2.0 * (dot(nrm, *q) - d)));
                p.iter().map(|x| dist(*x, r)).fold(f64::INFINITY, f64::min)
            })
            .collect();
        errs.sort_by(|a, b| a.total_cmp(b));
        let e = errs[errs.len() / 2] / diagonal;
        if best.is_none_or(|b| e < b.2) {
            best = Some((nrm, d, e));
        }
    }
    let limit = if choice == MirrorChoice::Auto { 0.02 } else { f64::INFINITY };
    best.filter(|b| b.2 <= limit)
}

fn reflect_point(q: Vec3, (n, d): (Vec3, f64)) -> Vec3 {
    sub(q, scale(n, 2.0 * (dot(n, q) - d)))
}

fn reflect_dir(v: Vec3, n: Vec3) -> Vec3 {
    sub(v, scale(n, 2.0 * dot(n, v)))
}

fn nearest(p: &[Vec3], q: Vec3) -> usize {
    (0..p.len()).min_by(|&a, &b| dist(p[a], q).total_cmp(&dist(p[b], q))).unwrap_or(0)
}

/// A unit vector perpendicular to `n` (random direction in the tangent plane).
fn random_tangent(n: Vec3, rng: &mut Rng) -> Vec3 {
    loop {
        let v = [rng.normal(), rng.normal(), rng.normal()];
        let t = sub(v, scale(n, dot(v, n)));
        if norm(t) > 1e-6 {
            return normalize(t);
        }
    }
}

/// Farthest-point spreading of centres (Euclidean).
struct Spread {
    /// Distance of every vertex to the nearest centre chosen so far.
    far: Vec<f64>,
    any: bool,
}

impl Spread {
    /// The allowed vertex farthest from the centres so far (the first: a random allowed one).
    fn pick(&mut self, p: &[Vec3], allowed: &dyn Fn(usize) -> bool, rng: &mut Rng) -> usize {
        let ok: Vec<usize> = (0..p.len()).filter(|&v| allowed(v)).collect();
        let v = if ok.is_empty() {
            rng.below(p.len())
        } else if !self.any {
            ok[rng.below(ok.len())]
        } else {
            ok.iter().copied().max_by(|&a, &b| self.far[a].total_cmp(&self.far[b])).expect("not empty")
        };
        self.add(p, v);
        v
    }

    fn add(&mut self, p: &[Vec3], v: usize) {
        self.any = true;
        for (u, f) in self.far.iter_mut().enumerate() {
            *f = f.min(dist(p[u], p[v]));
        }
    }
}

/// A deformation's parameters before its field is computed.
#[derive(Debug, Clone)]
struct Plan {
    kind: PlantKind,
    center: usize,
    radius: f64,
    amplitude: f64,
    direction: Vec3,
    pivot: Option<Vec3>,
    partner: Option<usize>,
    name: String,
}

/// Displacement of the rest positions by plan `d` at weight `w`, given its geodesic distances.
fn displacement(p: &[Vec3], d: &Plan, g: &[f64], w: f64) -> Vec<Vec3> {
    let c = p[d.center];
    p.iter()
        .zip(g)
        .map(|(q, &gi)| {
            let s = falloff(gi, d.radius);
            if s == 0.0 || w == 0.0 {
                return [0.0; 3];
            }
            match d.kind {
                PlantKind::Pull => scale(d.direction, w * d.amplitude * s),
                PlantKind::Stretch => scale(d.direction, w * d.amplitude * s * dot(sub(*q, c), d.direction)),
                PlantKind::Hinge => {
                    let h = d.pivot.expect("a hinge has a pivot");
                    let r = exp_so3(scale(d.direction, w * d.amplitude * s));
                    sub(add(mat_vec(&r, sub(*q, h)), h), *q)
                }
            }
        })
        .collect()
}

/// Plants deformations on `mesh` and mixes them into frames (see the module docs). `source`
/// names the mesh in `truth.json`. Deterministic in the config.
pub fn plant(mesh: &TriMesh, source: &str, cfg: &PlantConfig) -> Result<PlantedSet> {
    cfg.validate()?;
    let source_vertices = mesh.n_vertices();
    let rest = match cfg.vertices {
        Some(v) if v < mesh.n_vertices() => {
            let d = decimate(&mesh.positions, &mesh.faces, v)?;
            TriMesh::new(d.positions, d.faces)
        }
        _ => mesh.clone(),
    };
    let p = &rest.positions;
    let n = p.len();
    let (lo, hi) = bounding_box(p);
    let diagonal = dist(lo, hi);
    if diagonal.is_nan() || diagonal <= 0.0 {
        return Err(Error::Invalid(format!("{source}: the mesh has no extent")));
    }
    let normals = vertex_normals(p, &rest.faces, NormalWeighting::Area);
    let centroid = scale(p.iter().fold([0.0; 3], |a, q| add(a, *q)), 1.0 / n as f64);
    let heat = HeatGeodesics::new(p, &rest.faces, 1.0)?;
    let mirror = mirror_plane(p, diagonal, cfg.mirror);
    let mut rng = Rng::new(cfg.seed);

    // Centres: pairs on the positive side of the mirror, then singles, spread by farthest points.
    let n_pairs = if mirror.is_some() { cfg.deformations / 4 } else { 0 };
    let n_single = cfg.deformations - 2 * n_pairs;
    let side_ok: Vec<bool> = match mirror {
        Some((m, d, _)) => p.iter().map(|q| dot(m, *q) - d > 0.05 * diagonal).collect(),
        None => vec![true; n],
    };
    let mut spread = Spread { far: vec![f64::INFINITY; n], any: false };
    let kinds = [PlantKind::Pull, PlantKind::Hinge, PlantKind::Stretch];
    let mut plans: Vec<Plan> = Vec::new();
    let make = |kind: PlantKind, center: usize, rng: &mut Rng, index: usize| -> Plan {
        let radius = diagonal * (cfg.radius[0] + (cfg.radius[1] - cfg.radius[0]) * rng.uniform());
        let nc = normalize(normals[center]);
        let name = format!("{}{index:02}", kind.name());
        match kind {
            PlantKind::Pull => {
                let t = random_tangent(nc, rng);
                let u = normalize(add(nc, scale(t, rng.uniform() - 0.5)));
                let a = radius * (0.12 + 0.1 * rng.uniform());
                Plan { kind, center, radius, amplitude: a, direction: u, pivot: None, partner: None, name }
            }
            PlantKind::Hinge => {
                let to_mid = sub(centroid, p[center]);
                let tangential = sub(to_mid, scale(nc, dot(to_mid, nc)));
                let t =
                    if norm(tangential) > 1e-9 * diagonal { normalize(tangential) } else { random_tangent(nc, rng) };
                let pivot = add(p[center], scale(t, 0.6 * radius));
                let axis = normalize(cross(nc, t));
                let deg = 12.0 + 12.0 * rng.uniform();
                let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
                Plan {
                    kind,
                    center,
                    radius,
                    amplitude: sign * deg.to_radians(),
                    direction: axis,
                    pivot: Some(pivot),
                    partner: None,
                    name,
                }
            }
            PlantKind::Stretch => {
                let t = random_tangent(nc, rng);
                let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
                let a = sign * (0.4 + 0.3 * rng.uniform());
                Plan { kind, center, radius, amplitude: a, direction: t, pivot: None, partner: None, name }
            }
        }
    };
    for i in 0..n_pairs {
        let (m, d, _) = mirror.expect("pairs only with a mirror");
        let c = spread.pick(p, &|v| side_ok[v], &mut rng);
        let kind = kinds[rng.below(3)];
        let mut left = make(kind, c, &mut rng, i);
        let c2 = nearest(p, reflect_point(p[c], (m, d)));
        spread.add(p, c2);
        let mut right = left.clone();
        right.center = c2;
        match kind {
            PlantKind::Pull | PlantKind::Stretch => right.direction = reflect_dir(left.direction, m),
            PlantKind::Hinge => {
                right.direction = scale(reflect_dir(left.direction, m), -1.0);
                right.pivot = left.pivot.map(|h| reflect_point(h, (m, d)));
            }
        }
        let at = plans.len();
        left.partner = Some(at + 1);
        right.partner = Some(at);
        left.name.push_str("_l");
        right.name.push_str("_r");
        plans.push(left);
        plans.push(right);
    }
    for i in 0..n_single {
        let index = n_pairs + i;
        let (center, kind) = if i % 5 == 4 && !plans.is_empty() {
            // Overlapping supports: an earlier centre, another kind.
            let other = &plans[rng.below(plans.len())];
            let k = kinds.iter().copied().filter(|k| *k != other.kind).collect::<Vec<_>>();
            (other.center, k[rng.below(k.len())])
        } else {
            (spread.pick(p, &|_| true, &mut rng), kinds[rng.below(3)])
        };
        plans.push(make(kind, center, &mut rng, index));
    }

    // Fields at weight 1.
    let dists: Vec<Vec<f64>> = plans.iter().map(|d| heat.distances(&[d.center])).collect::<Result<Vec<_>>>()?;
    let fields: Vec<Vec<Vec3>> = plans.iter().zip(&dists).map(|(d, g)| displacement(p, d, g, 1.0)).collect();

    // Weights and frames.
    let dn = plans.len();
    let frames_n = cfg.train + cfg.test;
    let sigma = cfg.noise * diagonal;
    let mut weights = Vec::with_capacity(frames_n);
    let mut frames = Vec::with_capacity(frames_n);
    // Noise from its own stream: the same seed gives the same deformations and weights at every
    // noise level.
    let mut noise_rng = Rng::new(cfg.seed ^ 0x6E6F_6973_6521);
    for _ in 0..frames_n {
        let k = 1 + rng.below(cfg.max_active);
        let mut w = vec![0.0; dn];
        for d in rng.sample_distinct(dn, k) {
            w[d] = 0.1 + 0.9 * rng.uniform();
        }
        let mut f = p.clone();
        for (d, &wd) in w.iter().enumerate() {
            if wd != 0.0 {
                let disp = if plans[d].kind == PlantKind::Hinge {
                    displacement(p, &plans[d], &dists[d], wd)
                } else {
                    fields[d].iter().map(|x| scale(*x, wd)).collect()
                };
                for (q, x) in f.iter_mut().zip(disp) {
                    *q = add(*q, x);
                }
            }
        }
        if sigma > 0.0 {
            for q in f.iter_mut() {
                for c in q.iter_mut() {
                    *c += sigma * noise_rng.normal();
                }
            }
        }
        weights.push(w);
        frames.push(f);
    }

    // The oracle: least-squares projection of every frame's displacement onto the fields.
    let projector = Projector::new(&fields)?;
    let oracle = |range: std::ops::Range<usize>| -> Result<f64> {
        let (mut sq, mut cnt) = (0.0, 0usize);
        for f in &frames[range] {
            let disp: Vec<Vec3> = f.iter().zip(p.iter()).map(|(a, b)| sub(*a, *b)).collect();
            let fit = projector.project(&disp)?;
            for (a, b) in disp.iter().zip(&fit) {
                sq += crate::math::vec3::dist2(*a, *b);
            }
            cnt += 3 * n;
        }
        Ok(1000.0 * (sq / cnt.max(1) as f64).sqrt())
    };
    let oracle_train_erms = oracle(0..cfg.train)?;
    let oracle_test_erms = oracle(cfg.train..frames_n)?;
    let rest_test_erms = {
        let (mut sq, mut cnt) = (0.0, 0usize);
        for f in &frames[cfg.train..] {
            sq += f.iter().zip(p.iter()).map(|(a, b)| crate::math::vec3::dist2(*a, *b)).sum::<f64>();
            cnt += 3 * n;
        }
        1000.0 * (sq / cnt.max(1) as f64).sqrt()
    };

    let independence = projector.independence()?;
    let deformations: Vec<PlantedDeformation> = plans
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let train_active = weights[..cfg.train].iter().filter(|w| w[i] != 0.0).count();
            let peak = fields[i].iter().map(|x| norm(*x)).fold(0.0, f64::max);
            let identifiable = train_active >= MIN_ACTIVE_FRAMES && independence[i] >= MIN_INDEPENDENCE;
            PlantedDeformation {
                name: d.name.clone(),
                kind: d.kind,
                center: d.center,
                radius: d.radius,
                partner: d.partner,
                amplitude: d.amplitude,
                direction: d.direction,
                pivot: d.pivot,
                support: crate::metrics::recovery::support_size(&fields[i]),
                peak,
                train_active,
                independence: independence[i],
                identifiable,
            }
        })
        .collect();
    let truth = TruthFile {
        format: TRUTH_FORMAT,
        source: source.to_string(),
        n_vertices: n,
        n_faces: rest.n_faces(),
        source_vertices,
        diagonal,
        seed: cfg.seed,
        noise: cfg.noise,
        noise_sigma: sigma,
        max_active: cfg.max_active,
        radius: cfg.radius,
        mirror,
        train: cfg.train,
        test: cfg.test,
        oracle_train_erms,
        oracle_test_erms,
        rest_test_erms,
        identifiable: deformations.iter().filter(|d| d.identifiable).count(),
        deformations,
    };
    Ok(PlantedSet { rest, truth, fields, weights, frames })
}

/// Least-squares projection onto the span of D fields (factor the Gram matrix once).
struct Projector<'a> {
    fields: &'a [Vec<Vec3>],
    gram: faer::Mat<f64>,
}

impl<'a> Projector<'a> {
    fn new(fields: &'a [Vec<Vec3>]) -> Result<Self> {
        let d = fields.len();
        let gram = faer::Mat::<f64>::from_fn(d, d, |i, j| {
            fields[i].iter().zip(&fields[j]).map(|(a, b)| dot(*a, *b)).sum::<f64>()
        });
        Ok(Projector { fields, gram })
    }

    /// Solves (G + εI) x = b for a symmetric positive semi-definite G restricted to `keep`.
    fn solve(&self, keep: &[usize], b: &[f64]) -> Result<Vec<f64>> {
        use faer::linalg::solvers::Solve;
        let m = keep.len();
        let mut g = faer::Mat::<f64>::from_fn(m, m, |i, j| self.gram[(keep[i], keep[j])]);
        let md = (0..m).map(|i| g[(i, i)]).fold(0.0f64, f64::max);
        for i in 0..m {
            g[(i, i)] += 1e-12 * md + 1e-300;
        }
        let mut rhs = faer::Mat::<f64>::from_fn(m, 1, |i, _| b[i]);
        let llt = g.llt(faer::Side::Lower).map_err(|e| Error::Numerical(format!("planted fields: {e:?}")))?;
        llt.solve_in_place(rhs.as_mut());
        Ok((0..m).map(|i| rhs[(i, 0)]).collect())
    }

    /// The least-squares fit of `disp` by the fields.
    fn project(&self, disp: &[Vec3]) -> Result<Vec<Vec3>> {
        let all: Vec<usize> = (0..self.fields.len()).collect();
        let b: Vec<f64> = self.fields.iter().map(|f| f.iter().zip(disp).map(|(a, x)| dot(*a, *x)).sum()).collect();
        let x = self.solve(&all, &b)?;
        let mut out = vec![[0.0; 3]; disp.len()];
        for (f, &c) in self.fields.iter().zip(&x) {
            for (o, v) in out.iter_mut().zip(f) {
                *o = add(*o, scale(*v, c));
            }
        }
        Ok(out)
    }

    /// Per field, the relative residual ‖f − P_others f‖ / ‖f‖ of its projection onto the
    /// others (1: orthogonal to them all).
    fn independence(&self) -> Result<Vec<f64>> {
        let d = self.fields.len();
        (0..d)
            .map(|i| {
                let ff = self.gram[(i, i)];
                if ff <= 0.0 {
                    return Ok(0.0);
                }
                if d == 1 {
                    return Ok(1.0);
                }
                let others: Vec<usize> = (0..d).filter(|&j| j != i).collect();
                let b: Vec<f64> = others.iter().map(|&j| self.gram[(j, i)]).collect();
                let x = self.solve(&others, &b)?;
                let explained: f64 = x.iter().zip(&b).map(|(a, c)| a * c).sum();
                Ok(((ff - explained).max(0.0) / ff).sqrt())
            })
            .collect()
    }
}

/// The evaluation config written beside a planted set: PCA, SPLOCS (non-negative and signed),
/// region PCA, SPLOCS on ACAP features and the autoencoder, at K = D + 1.
pub fn eval_config_text(dir: &Path, truth: &TruthFile) -> String {
    let name = dir.file_name().and_then(|s| s.to_str()).unwrap_or("planted");
    let safe: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_".contains(c) { c } else { '_' }).collect();
    let k = truth.deformations.len() + 1;
    format!(
        "# Written by `meshdeco plant`: every method on the planted set at K = D + 1 = {k}, scored against\n\
         # the true deformations (recovery columns of report.md). Run: meshdeco eval --config {cfg}\n\
         name = \"planted-{safe}\"\n\n\
         [[dataset]]\n\
         name = \"{safe}\"\n\
         truth = \"{dir}\"\n\n\
         [[method]]\nlabel = \"pca\"\nkind = \"pca\"\n\n\
         [[method]]\nlabel = \"splocs\"\nkind = \"splocs\"\n\n\
         [[method]]\nlabel = \"splocs-signed\"\nkind = \"splocs\"\nweights = \"signed\"\n\n\
         [[method]]\nlabel = \"region-pca\"\nkind = \"region-pca\"\n\n\
         [[method]]\nlabel = \"splocs-acap\"\nkind = \"splocs\"\nrepresentation = \"acap\"\n\n\
         [[method]]\nlabel = \"autoencoder\"\nkind = \"autoencoder\"\n\n\
         [sweep]\ncomponents = [{k}]\n",
        cfg = dir.join("eval.toml").display(),
        dir = dir.display().to_string().replace('\\', "/").replace('"', "\\\""),
    )
}

/// Writes a planted set into the directory `out`, all at once (see the module docs).
pub fn write(set: &PlantedSet, out: &Path) -> Result<()> {
    let staging = artifact::Staging::begin(out, false)?;
    let dir = staging.dir();
    artifact::deferred_sync(|| -> Result<()> {
        crate::mesh::npy::write_npy(&dir.join("frames.npy"), &set.frames)?;
        crate::mesh::npy::write_npy(&dir.join(FIELDS_FILE), &set.fields)?;
        crate::mesh::write_obj(&dir.join("template.obj"), &set.rest)?;
        let names: Vec<String> = (1..=set.frames.len()).map(|i| format!("frames_{i}")).collect();
        let flat: Vec<f64> = set.weights.iter().flatten().copied().collect();
        artifact::write_weights_csv(&dir.join(WEIGHTS_FILE), &names, &flat, set.fields.len())?;
        artifact::write_json(&dir.join(TRUTH_FILE), &set.truth)?;
        artifact::write_atomic(&dir.join("eval.toml"), eval_config_text(out, &set.truth).as_bytes())?;
        Ok(())
    })?;
    staging.commit()
}

/// Checks that the planted directory's manifest (read once) lists each of `names` with the
/// file's present length and checksum.
fn check_listed(dir: &Path, names: &[&str]) -> Result<()> {
    let manifest_path = dir.join(artifact::MANIFEST_FILE);
    let manifest: artifact::Manifest = artifact::read_json(&manifest_path)?;
    for name in names {
        let entry = manifest
            .files
            .get(*name)
            .ok_or_else(|| Error::Invalid(format!("{}: does not list `{name}`", manifest_path.display())))?;
        let path = dir.join(name);
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        if bytes.len() as u64 != entry.bytes || artifact::crc32_hex(&bytes) != entry.crc32 {
            return Err(Error::Invalid(format!(
                "{}: length or checksum differs from {}: the planted set was changed or damaged; plant it again",
                path.display(),
                manifest_path.display()
            )));
        }
    }
    Ok(())
}

/// The ground truth of a planted directory, read back and verified: every file the manifest
/// lists has its recorded length and checksum, the truth file's counts agree with the fields.
#[derive(Debug, Clone)]
pub struct Truth {
    pub dir: PathBuf,
    pub file: TruthFile,
    /// D true fields (N × 3 each).
    pub fields: Vec<Vec<Vec3>>,
}

impl Truth {
    /// Reads `dir` (a directory written by [`write`]). Errors name the file and what is wrong.
    pub fn load(dir: &Path) -> Result<Self> {
        if !dir.join(TRUTH_FILE).is_file() {
            return Err(Error::Invalid(format!(
                "{}: no {TRUTH_FILE}: not a directory written by `meshdeco plant`",
                dir.display()
            )));
        }
        check_listed(dir, &[TRUTH_FILE, FIELDS_FILE, "frames.npy", "template.obj"])?;
        let file: TruthFile = artifact::read_json(&dir.join(TRUTH_FILE))?;
        let bad = |m: String| Error::parse(dir.join(TRUTH_FILE), None, m);
        if file.format != TRUTH_FORMAT {
            return Err(bad(format!("format {} (this meshdeco reads {TRUTH_FORMAT})", file.format)));
        }
        let path = dir.join(FIELDS_FILE);
        let frames = crate::mesh::npy::NpyFrames::open(&path, file.n_vertices)?
            .ok_or_else(|| Error::Invalid(format!("{}: not in C order", path.display())))?;
        if frames.n_frames() != file.deformations.len() {
            return Err(bad(format!(
                "lists {} deformations, {} holds {} fields",
                file.deformations.len(),
                path.display(),
                frames.n_frames()
            )));
        }
        let fields = (0..frames.n_frames()).map(|f| frames.read_frame(f)).collect::<Result<Vec<_>>>()?;
        if let Some(d) = file.deformations.iter().find(|d| d.center >= file.n_vertices) {
            return Err(bad(format!("deformation {}: centre {} is not a vertex", d.name, d.center)));
        }
        Ok(Truth { dir: dir.to_path_buf(), file, fields })
    }

    /// The true weights of every frame (training frames, then test frames; one weight per
    /// deformation), read from `weights.csv` and verified: the manifest's length and checksum,
    /// one row per frame the truth file counts, one column per deformation.
    pub fn weights(&self) -> Result<Vec<Vec<f64>>> {
        check_listed(&self.dir, &[WEIGHTS_FILE])?;
        let path = self.dir.join(WEIGHTS_FILE);
        let table = artifact::read_weights_csv(&path)?;
        let (frames, d) = (self.file.train + self.file.test, self.file.deformations.len());
        if table.weights.len() != frames || table.weights.first().is_some_and(|w| w.len() != d) {
            return Err(Error::parse(
                &path,
                None,
                format!(
                    "{} frames of {} weights; {} lists {frames} frames of {d} deformations",
                    table.weights.len(),
                    table.weights.first().map_or(0, Vec::len),
                    TRUTH_FILE
                ),
            ));
        }
        Ok(table.weights)
    }

    /// Which deformations count in the score.
    pub fn counted(&self) -> Vec<bool> {
        self.file.deformations.iter().map(|d| d.identifiable).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives::cylinder;

    fn small() -> (TriMesh, PlantConfig) {
        let m = cylinder(24, 30, 0.3, 2.0);
        let cfg = PlantConfig { deformations: 8, train: 40, test: 10, noise: 0.0, ..Default::default() };
        (m, cfg)
    }

    #[test]
    fn frames_are_the_rest_plus_the_weighted_fields_and_fields_are_local() {
        let (m, cfg) = small();
        let set = plant(&m, "cylinder", &cfg).unwrap();
        assert_eq!(set.fields.len(), 8);
        assert_eq!(set.frames.len(), 50);
        for (f, w) in set.frames.iter().zip(&set.weights) {
            let active = w.iter().filter(|&&x| x != 0.0).count();
            assert!((1..=4).contains(&active));
            assert!(w.iter().all(|&x| x == 0.0 || (0.1..=1.0).contains(&x)));
            // Pulls and stretches are linear in w; a frame with only those is rest + Σ w·field.
            if w.iter().enumerate().all(|(d, &x)| x == 0.0 || set.truth.deformations[d].kind != PlantKind::Hinge) {
                for (v, q) in f.iter().enumerate() {
                    let mut e = set.rest.positions[v];
                    for (d, &x) in w.iter().enumerate() {
                        e = add(e, scale(set.fields[d][v], x));
                    }
                    assert!(dist(e, *q) < 1e-12);
                }
            }
        }
        for (d, f) in set.truth.deformations.iter().zip(&set.fields) {
            assert!(d.peak > 0.0);
            assert!(d.support > 0 && d.support < m.n_vertices() / 2, "{} moves {} vertices", d.name, d.support);
            // Nothing moves outside the disc (geodesic ≥ radius ⇒ Euclidean ≥ … not needed:
            // check the far end of the cylinder from the centre stays).
            let c = m.positions[d.center];
            for (v, x) in f.iter().enumerate() {
                if dist(m.positions[v], c) > d.radius * 1.05 {
                    assert_eq!(norm(*x), 0.0, "{} moves vertex {v} outside its disc", d.name);
                }
            }
        }
        // Without noise the oracle reconstructs pulls and stretches exactly; hinges are arcs.
        assert!(set.truth.oracle_test_erms < set.truth.rest_test_erms);
    }

    #[test]
    fn a_symmetric_mesh_gets_mirrored_pairs() {
        let (m, cfg) = small();
        let set = plant(&m, "cylinder", &cfg).unwrap();
        let (n, d, e) = set.truth.mirror.expect("a cylinder is symmetric");
        assert!(e < 0.02);
        let pairs: Vec<&PlantedDeformation> = set.truth.deformations.iter().filter(|x| x.partner.is_some()).collect();
        assert_eq!(pairs.len(), 4);
        for a in pairs {
            let b = &set.truth.deformations[a.partner.unwrap()];
            assert_eq!(b.partner.map(|i| &set.truth.deformations[i].name), Some(&a.name));
            let mirrored = reflect_point(m.positions[a.center], (n, d));
            assert!(dist(mirrored, m.positions[b.center]) < 0.1, "partner centre not mirrored");
            assert_eq!(a.kind, b.kind);
            assert!((a.peak - b.peak).abs() < 0.2 * a.peak, "{} {} vs {}", a.name, a.peak, b.peak);
        }
    }

    #[test]
    fn same_config_same_set_and_noise_has_its_size() {
        let (m, cfg) = small();
        let a = plant(&m, "c", &cfg).unwrap();
        let b = plant(&m, "c", &cfg).unwrap();
        assert_eq!(a.frames, b.frames);
        let noisy = plant(&m, "c", &PlantConfig { noise: 1e-3, ..cfg.clone() }).unwrap();
        assert_eq!(noisy.weights, a.weights, "the noise changed the weights");
        let sigma = 1e-3 * noisy.truth.diagonal;
        assert!((noisy.truth.noise_sigma - sigma).abs() < 1e-15);
        let diff: Vec<f64> = noisy
            .frames
            .iter()
            .zip(&a.frames)
            .flat_map(|(x, y)| x.iter().zip(y).flat_map(|(p, q)| (0..3).map(move |c| p[c] - q[c])))
            .collect();
        let rms = (diff.iter().map(|x| x * x).sum::<f64>() / diff.len() as f64).sqrt();
        assert!((rms / sigma - 1.0).abs() < 0.05, "noise rms {rms} vs σ {sigma}");
        assert!(plant(&m, "c", &PlantConfig { max_active: 9, ..cfg.clone() }).is_err());
        assert!(plant(&m, "c", &PlantConfig { noise: f64::NAN, ..cfg }).is_err());
    }

    #[test]
    fn a_written_set_reads_back_verified() {
        let (m, cfg) = small();
        let set = plant(&m, "c", &cfg).unwrap();
        let tmp = std::env::temp_dir().join(format!("meshdeco-planted-{}", std::process::id()));
        let out = tmp.join("set");
        write(&set, &out).unwrap();
        let t = Truth::load(&out).unwrap();
        assert_eq!(t.fields, set.fields);
        assert_eq!(t.file, set.truth);
        // The true weights read back exactly (the CSV writes each f64 in its shortest exact form).
        assert_eq!(t.weights().unwrap(), set.weights);
        // A changed weight is refused, naming the file.
        let w = out.join(WEIGHTS_FILE);
        let text = std::fs::read_to_string(&w).unwrap();
        std::fs::write(&w, text.replacen(",0,", ",0.5,", 1)).unwrap();
        let e = t.weights().unwrap_err().to_string();
        assert!(e.contains(WEIGHTS_FILE) && e.contains("changed or damaged"), "{e}");
        std::fs::write(&w, text).unwrap();
        // A changed field is refused, naming the file.
        let f = out.join(FIELDS_FILE);
        let mut bytes = std::fs::read(&f).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(&f, bytes).unwrap();
        let e = Truth::load(&out).unwrap_err().to_string();
        assert!(e.contains("fields.npy") && e.contains("changed or damaged"), "{e}");
        let _ = std::fs::remove_dir_all(&tmp);
    }
}
