//! Built-in synthetic datasets with known, planted local deformations, so that the README's
//! first command and the test suite run without any external data.
//!
//! Select one with `data.path = "synthetic:<name>"` in a config (or the same string wherever a
//! mesh path is accepted). Every dataset is deterministic: the same name always gives the same
//! frames.
//!
//! | name | mesh | frames | planted deformations |
//! |---|---|---|---|
//! | `tube` | closed capped tube, length 1 along +z, radius 0.1, 24 × 61 rings + 2 caps (1 466 vertices) | 60 | bend at joint A (z = 0.3, about x), bend at joint B (z = 0.7, about y), bulge around z = 0.5 on the +x side |
//! | `bumps` | closed capped tube as above | 40 | three localized radial bumps (z = 0.2, 0.5, 0.8, on different sides) with independent amplitudes |
//! | `pieces` | two separate tubes (2 932 vertices) | 40 | the first bends at joint A; the second carries the three bumps and slides along x by up to ±0.1 |
//! | `pieces:N` (1 ≤ N ≤ 200) | the tube plus N separate small closed parts (elongated octahedra, 0.08 long, 6 vertices each): 1 466 + 6N vertices, N + 1 pieces | 60 | the tube bends at joints A and B and bulges; even-numbered parts sit on the tube and follow its bends rigidly while each also swivels about its own axis (up to ±60°); odd-numbered parts float beside it, each swivelling and drifting (up to ±0.2) on its own; the whole scene turns a quarter turn about z and walks 2 units along +x (frame 1 is the rest) |
//!
//! Units: the tube is 1 unit long. Amplitudes: bends up to ±50°, bulge and bumps up to 0.06
//! units radial push (60 % of the radius) at their centres, falling smoothly to zero at 0.12
//! units geodesic-ish distance (measured along the surface in z and around the circumference).

use crate::error::{Error, Result};
use crate::mesh::{MeshSequence, TriMesh, Vec3};
use crate::rng::Rng;

/// Prefix that selects a synthetic dataset in a data path.
pub const PREFIX: &str = "synthetic:";

/// Names of the built-in datasets (`pieces:N` takes a count of small parts, see the module docs).
pub const NAMES: &[&str] = &["tube", "bumps", "pieces", "pieces:N"];

/// Largest part count of `pieces:N`.
pub const MAX_PARTS: usize = 200;

/// Offset along x of the second tube of the `pieces` dataset.
const PIECES_OFFSET: f64 = 0.5;

const RINGS: usize = 61;
const AROUND: usize = 24;
const RADIUS: f64 = 0.1;
const LENGTH: f64 = 1.0;

/// A planted deformation: its name and the vertices inside its support (every vertex it moves,
/// for bumps; the bending zone, for joints).
#[derive(Debug, Clone)]
pub struct PlantedRegion {
    pub name: String,
    pub vertices: Vec<usize>,
}

/// True if `path` names a synthetic dataset (`synthetic:<name>`).
pub fn is_synthetic(path: &str) -> bool {
    path.starts_with(PREFIX)
}

/// The datasets a name selects (checked by [`check_name`]).
enum Dataset {
    Tube,
    Bumps,
    Pieces,
    ManyPieces(usize),
}

/// Parses a dataset name (without the `synthetic:` prefix); the error says what is accepted.
fn parse_name(name: &str) -> std::result::Result<Dataset, String> {
    match name {
        "tube" => Ok(Dataset::Tube),
        "bumps" => Ok(Dataset::Bumps),
        "pieces" => Ok(Dataset::Pieces),
        _ => {
            let available = || NAMES.iter().map(|n| format!("synthetic:{n}")).collect::<Vec<_>>().join(", ");
            let Some(count) = name.strip_prefix("pieces:") else {
                return Err(format!("unknown synthetic dataset `{name}`; available: {}", available()));
            };
            match count.parse::<usize>() {
                Ok(n) if (1..=MAX_PARTS).contains(&n) => Ok(Dataset::ManyPieces(n)),
                _ => Err(format!(
                    "`{name}`: the part count of synthetic:pieces:N must be a whole number from 1 to {MAX_PARTS}, got `{count}`"
                )),
            }
        }
    }
}

/// Checks a dataset name (without the `synthetic:` prefix) without generating it.
pub fn check_name(name: &str) -> std::result::Result<(), String> {
    parse_name(name).map(|_| ())
}

/// Generates the dataset named by `path` (`synthetic:<name>`, or just `<name>`).
pub fn load(path: &str) -> Result<MeshSequence> {
    let name = path.strip_prefix(PREFIX).unwrap_or(path);
    match parse_name(name).map_err(|e| Error::Invalid(format!("{e} (in `{path}`)")))? {
        Dataset::Tube => Ok(tube_sequence()),
        Dataset::Bumps => Ok(bumps_sequence()),
        Dataset::Pieces => Ok(pieces_sequence()),
        Dataset::ManyPieces(n) => Ok(many_pieces_sequence(n)),
    }
}

/// The planted regions of a dataset (for tests and reports).
pub fn planted_regions(path: &str) -> Result<Vec<PlantedRegion>> {
    let name = path.strip_prefix(PREFIX).unwrap_or(path);
    let rest = tube_mesh();
    let region = |name: &str, f: &dyn Fn(f64, f64) -> f64| PlantedRegion {
        name: name.to_string(),
        vertices: rest
            .positions
            .iter()
            .enumerate()
            .filter(|(_, p)| f(p[2], p[1].atan2(p[0])) > 0.0)
            .map(|(i, _)| i)
            .collect(),
    };
    if let Ok(Dataset::ManyPieces(parts)) = parse_name(name) {
        // The tube, then each part.
        let n = rest.n_vertices();
        let mut regions = vec![PlantedRegion { name: "tube".into(), vertices: (0..n).collect() }];
        regions.extend((0..parts).map(|i| PlantedRegion {
            name: format!("part-{i}"),
            vertices: (n + PART_VERTICES * i..n + PART_VERTICES * (i + 1)).collect(),
        }));
        return Ok(regions);
    }
    if name == "pieces" {
        // The two pieces: the bending tube and the sliding, bumped one.
        let n = rest.n_vertices();
        return Ok(vec![
            PlantedRegion { name: "piece-0".into(), vertices: (0..n).collect() },
            PlantedRegion { name: "piece-1".into(), vertices: (n..2 * n).collect() },
        ]);
    }
    match name {
        "tube" => Ok(vec![
            region("joint-a", &|z, _| joint_zone(z, JOINT_A)),
            region("joint-b", &|z, _| joint_zone(z, JOINT_B)),
            region("bulge", &|z, phi| bump_profile(z, phi, 0.5, 0.0)),
        ]),
        "bumps" => Ok(BUMPS
            .iter()
            .enumerate()
            .map(|(k, b)| region(&format!("bump-{k}"), &|z, phi| bump_profile(z, phi, b.0, b.1)))
            .collect()),
        _ => load(path).map(|_| Vec::new()),
    }
}

/// The rest mesh shared by the tube datasets: rings of `AROUND` vertices from z = 0 to z = 1,
/// plus a centre vertex on each cap. Faces are counter-clockwise seen from outside.
pub fn tube_mesh() -> TriMesh {
    let mut positions = Vec::with_capacity(RINGS * AROUND + 2);
    for r in 0..RINGS {
        let z = LENGTH * r as f64 / (RINGS - 1) as f64;
        for a in 0..AROUND {
            let phi = 2.0 * std::f64::consts::PI * a as f64 / AROUND as f64;
            positions.push([RADIUS * phi.cos(), RADIUS * phi.sin(), z]);
        }
    }
    let bottom = positions.len();
    positions.push([0.0, 0.0, 0.0]);
    let top = positions.len();
    positions.push([0.0, 0.0, LENGTH]);
    let idx = |r: usize, a: usize| r * AROUND + (a % AROUND);
    let mut faces = Vec::with_capacity(2 * (RINGS - 1) * AROUND + 2 * AROUND);
    for r in 0..RINGS - 1 {
        for a in 0..AROUND {
            faces.push([idx(r, a), idx(r, a + 1), idx(r + 1, a + 1)]);
            faces.push([idx(r, a), idx(r + 1, a + 1), idx(r + 1, a)]);
        }
    }
    for a in 0..AROUND {
        faces.push([bottom, idx(0, a + 1), idx(0, a)]);
        faces.push([top, idx(RINGS - 1, a), idx(RINGS - 1, a + 1)]);
    }
    TriMesh::new(positions, faces)
}

const JOINT_A: f64 = 0.3;
const JOINT_B: f64 = 0.7;
const JOINT_HALF_WIDTH: f64 = 0.06;
/// (z, angle around the axis) of the `bumps` dataset's bumps.
const BUMPS: [(f64, f64); 3] = [(0.2, 0.0), (0.5, 2.0), (0.8, -2.0)];

fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Blend weight of a joint's rotation at height z: 0 below the zone, 1 above it.
fn joint_blend(z: f64, joint: f64) -> f64 {
    smoothstep((z - (joint - JOINT_HALF_WIDTH)) / (2.0 * JOINT_HALF_WIDTH))
}

/// Indicator-like weight of the joint's bending zone (where the blend is strictly between 0 and 1).
fn joint_zone(z: f64, joint: f64) -> f64 {
    let b = joint_blend(z, joint);
    4.0 * b * (1.0 - b)
}

/// Radial bump profile centred at (z0, phi0): 1 at the centre, 0 beyond 0.12 units.
fn bump_profile(z: f64, phi: f64, z0: f64, phi0: f64) -> f64 {
    let mut dphi = (phi - phi0).rem_euclid(2.0 * std::f64::consts::PI);
    if dphi > std::f64::consts::PI {
        dphi -= 2.0 * std::f64::consts::PI;
    }
    let d = ((z - z0).powi(2) + (RADIUS * dphi).powi(2)).sqrt();
    let t = (d / 0.12).min(1.0);
    let s = 1.0 - t * t;
    s * s
}

/// Uniform in [−1, 1] from the crate's deterministic generator.
fn symmetric(rng: &mut Rng) -> f64 {
    2.0 * rng.uniform() - 1.0
}

/// Rotation of `p` about the axis through `(0, 0, pivot_z)` along unit `axis` by `angle`.
fn rotate_about(p: Vec3, pivot_z: f64, axis: Vec3, angle: f64) -> Vec3 {
    let v = [p[0], p[1], p[2] - pivot_z];
    let (s, c) = angle.sin_cos();
    let d = axis[0] * v[0] + axis[1] * v[1] + axis[2] * v[2];
    let x = [axis[1] * v[2] - axis[2] * v[1], axis[2] * v[0] - axis[0] * v[2], axis[0] * v[1] - axis[1] * v[0]];
    let r = [0, 1, 2].map(|k| v[k] * c + x[k] * s + axis[k] * d * (1.0 - c));
    [r[0], r[1], r[2] + pivot_z]
}

/// Deforms the rest tube: bulge/bumps (radial, in rest coordinates) then the two joint bends
/// (distal joint B first, so joint A carries everything above it).
fn deform(rest: &TriMesh, bends: (f64, f64), bumps: &[(f64, f64, f64)]) -> Vec<Vec3> {
    rest.positions
        .iter()
        .map(|&p| {
            let (z, phi) = (p[2], p[1].atan2(p[0]));
            let radial = [p[0], p[1]];
            let rlen = (radial[0] * radial[0] + radial[1] * radial[1]).sqrt();
            let mut q = p;
            if rlen > 1e-12 {
                let push: f64 = bumps.iter().map(|&(z0, phi0, amp)| amp * bump_profile(z, phi, z0, phi0)).sum();
                q[0] += radial[0] / rlen * push;
                q[1] += radial[1] / rlen * push;
            }
            q = rotate_about(q, JOINT_B, [0.0, 1.0, 0.0], bends.1 * joint_blend(z, JOINT_B));
            rotate_about(q, JOINT_A, [1.0, 0.0, 0.0], bends.0 * joint_blend(z, JOINT_A))
        })
        .collect()
}

fn tube_sequence() -> MeshSequence {
    let rest = tube_mesh();
    let mut rng = Rng { state: 0x7475_6265 };
    let max_bend = 50f64.to_radians();
    let mut frames = vec![rest.positions.clone()];
    for _ in 1..60 {
        let a = max_bend * symmetric(&mut rng);
        let b = max_bend * symmetric(&mut rng);
        let bulge = 0.06 * rng.uniform();
        frames.push(deform(&rest, (a, b), &[(0.5, 0.0, bulge)]));
    }
    named("tube", rest.faces, frames)
}

fn bumps_sequence() -> MeshSequence {
    let rest = tube_mesh();
    let mut rng = Rng { state: 0x6275_6d70 };
    let mut frames = vec![rest.positions.clone()];
    for _ in 1..40 {
        let amps: Vec<(f64, f64, f64)> = BUMPS.iter().map(|&(z, phi)| (z, phi, 0.06 * rng.uniform())).collect();
        frames.push(deform(&rest, (0.0, 0.0), &amps));
    }
    named("bumps", rest.faces, frames)
}

/// Two separate tubes (two connected pieces, 2932 vertices): the first bends at its joint A, the
/// second, beside it at x = 0.5, carries the three bumps and slides along x by up to ±0.1 — a
/// motion of one piece relative to the other that only a per-piece position can express.
fn pieces_sequence() -> MeshSequence {
    let rest = tube_mesh();
    let n = rest.n_vertices();
    let mut faces = rest.faces.clone();
    faces.extend(rest.faces.iter().map(|f| f.map(|v| v + n)));
    let second = |p: &[Vec3], dx: f64| p.iter().map(|q| [q[0] + PIECES_OFFSET + dx, q[1], q[2]]).collect::<Vec<_>>();
    let mut rng = Rng { state: 0x7069_6563 };
    let max_bend = 50f64.to_radians();
    let mut frames = Vec::with_capacity(40);
    for i in 0..40 {
        let (a, amps, dx) = if i == 0 {
            (0.0, Vec::new(), 0.0)
        } else {
            let a = max_bend * symmetric(&mut rng);
            let amps: Vec<(f64, f64, f64)> = BUMPS.iter().map(|&(z, phi)| (z, phi, 0.06 * rng.uniform())).collect();
            (a, amps, 0.1 * symmetric(&mut rng))
        };
        let (first, bumped) = if i == 0 {
            (rest.positions.clone(), rest.positions.clone())
        } else {
            (deform(&rest, (a, 0.0), &[]), deform(&rest, (0.0, 0.0), &amps))
        };
        let mut frame = first;
        frame.extend(second(&bumped, dx));
        frames.push(frame);
    }
    named("pieces", faces, frames)
}

/// Vertices of one small part of `pieces:N`.
const PART_VERTICES: usize = 6;

/// One small part of `pieces:N`: an elongated octahedron (half-lengths 0.04 along its own axis,
/// 0.015 across) centred at the origin, axis along x. Faces counter-clockwise seen from outside.
fn part_mesh() -> (Vec<Vec3>, Vec<[usize; 3]>) {
    let positions = vec![
        [0.04, 0.0, 0.0],
        [-0.04, 0.0, 0.0],
        [0.0, 0.015, 0.0],
        [0.0, -0.015, 0.0],
        [0.0, 0.0, 0.015],
        [0.0, 0.0, -0.015],
    ];
    let faces = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    (positions, faces)
}

/// A random unit vector.
fn unit_vector(rng: &mut Rng) -> Vec3 {
    loop {
        let v = [symmetric(rng), symmetric(rng), symmetric(rng)];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if n > 0.1 && n <= 1.0 {
            return v.map(|x| x / n);
        }
    }
}

/// Rotation of `p` about the axis through `centre` along unit `axis` by `angle`.
fn rotate_about_point(p: Vec3, centre: Vec3, axis: Vec3, angle: f64) -> Vec3 {
    let shifted = [p[0] - centre[0], p[1] - centre[1], p[2]];
    let r = rotate_about(shifted, centre[2], axis, angle);
    [r[0] + centre[0], r[1] + centre[1], r[2]]
}

/// The tube plus `parts` small parts (module docs): every part is rigid in every frame; the
/// attached ones (even index) ride the tube's bends as rigid bodies (the bend of the tube at the
/// part's centre height), the free ones (odd index) drift on their own; everything turns and walks.
fn many_pieces_sequence(parts: usize) -> MeshSequence {
    const FRAMES: usize = 60;
    let rest = tube_mesh();
    let (part, part_faces) = part_mesh();
    let mut rng = Rng { state: 0x6d61_6e79 ^ parts as u64 };
    struct Part {
        centre: Vec3,
        orient_axis: Vec3,
        orient_angle: f64,
        swivel_axis: Vec3,
        swivel: (f64, f64, f64),
        drift: Vec3,
        attached: bool,
    }
    let parts: Vec<Part> = (0..parts)
        .map(|i| {
            let attached = i % 2 == 0;
            let z = 0.05 + 0.9 * rng.uniform();
            let phi = 2.0 * std::f64::consts::PI * rng.uniform();
            let r = if attached { RADIUS + 0.02 } else { RADIUS + 0.12 + 0.1 * rng.uniform() };
            Part {
                centre: [r * phi.cos(), r * phi.sin(), z],
                orient_axis: unit_vector(&mut rng),
                orient_angle: std::f64::consts::PI * rng.uniform(),
                swivel_axis: unit_vector(&mut rng),
                // amplitude (rad), angular rate per frame, phase
                swivel: (
                    60f64.to_radians() * (0.3 + 0.7 * rng.uniform()),
                    0.1 + 0.4 * rng.uniform(),
                    6.3 * rng.uniform(),
                ),
                drift: if attached {
                    [0.0; 3]
                } else {
                    [0.1 * symmetric(&mut rng), 0.1 * symmetric(&mut rng), 0.1 * symmetric(&mut rng)]
                },
                attached,
            }
        })
        .collect();
    let n_tube = rest.n_vertices();
    let mut faces = rest.faces.clone();
    for i in 0..parts.len() {
        faces.extend(part_faces.iter().map(|f| f.map(|v| v + n_tube + PART_VERTICES * i)));
    }
    // Rest placement of each part's vertices.
    let rest_parts: Vec<Vec<Vec3>> = parts
        .iter()
        .map(|p| {
            part.iter()
                .map(|&q| {
                    let o = rotate_about(q, 0.0, p.orient_axis, p.orient_angle);
                    [o[0] + p.centre[0], o[1] + p.centre[1], o[2] + p.centre[2]]
                })
                .collect()
        })
        .collect();
    let max_bend = 50f64.to_radians();
    let mut frames = Vec::with_capacity(FRAMES);
    for f in 0..FRAMES {
        let (bends, bulge) = if f == 0 {
            ((0.0, 0.0), 0.0)
        } else {
            ((max_bend * symmetric(&mut rng), max_bend * symmetric(&mut rng)), 0.06 * rng.uniform())
        };
        let mut frame = if f == 0 { rest.positions.clone() } else { deform(&rest, bends, &[(0.5, 0.0, bulge)]) };
        for (p, rest_part) in parts.iter().zip(&rest_parts) {
            let (amp, rate, phase) = p.swivel;
            // Both zero at frame 1 (the rest).
            let wobble = (rate * f as f64 + phase).sin() - phase.sin();
            let angle = amp * wobble;
            for &q in rest_part {
                let mut x = rotate_about_point(q, p.centre, p.swivel_axis, angle);
                if p.attached {
                    // Rigidly with the tube: the bends at the part's centre height.
                    x = rotate_about(x, JOINT_B, [0.0, 1.0, 0.0], bends.1 * joint_blend(p.centre[2], JOINT_B));
                    x = rotate_about(x, JOINT_A, [1.0, 0.0, 0.0], bends.0 * joint_blend(p.centre[2], JOINT_A));
                } else {
                    x = [0, 1, 2].map(|k| x[k] + p.drift[k] * wobble);
                }
                frame.push(x);
            }
        }
        // The walk across the scene: a quarter turn about the tube's axis (z) and 2 units along x.
        let s = f as f64 / (FRAMES - 1) as f64;
        let heading = std::f64::consts::FRAC_PI_2 * s;
        for x in &mut frame {
            *x = rotate_about(*x, 0.0, [0.0, 0.0, 1.0], heading);
            x[0] += 2.0 * s;
            x[1] += 0.05 * (4.0 * std::f64::consts::PI * s).sin();
        }
        frames.push(frame);
    }
    named("pieces", faces, frames)
}

/// Many frames made from a few (issue 28's large-data benchmarks): frame `f` blends three
/// source frames with random convex weights and adds a smooth random displacement (three plane
/// waves, amplitude up to 1 % of the source's bounding-box diagonal, wavelengths 0.5–2 × the
/// diagonal). Frame `f` depends only on `(seed, f)`, so frames can be made in any order and in
/// parallel, and the same arguments always give the same frames. Units: the source's.
#[derive(Debug, Clone)]
pub struct Blend {
    frames: Vec<Vec<Vec3>>,
    diagonal: f64,
    seed: u64,
}

impl Blend {
    /// Share of the bounding-box diagonal the perturbation reaches at most.
    pub const PERTURBATION: f64 = 0.01;

    /// A generator over `source`'s frames (at least one, all of one vertex count).
    pub fn new(source: &MeshSequence, seed: u64) -> Result<Self> {
        let n = source.n_vertices();
        if source.n_frames() == 0 || n == 0 {
            return Err(Error::Invalid("blend: the source has no frames".into()));
        }
        let (lo, hi) = crate::mesh::bounding_box(&source.frames[0]);
        let diagonal = crate::mesh::dist(lo, hi);
        if !(diagonal.is_finite() && diagonal > 0.0) {
            return Err(Error::Invalid(format!(
                "blend: the source's first frame has bounding-box diagonal {diagonal}"
            )));
        }
        Ok(Blend { frames: source.frames.clone(), diagonal, seed })
    }

    /// Vertex count N of every frame.
    pub fn n_vertices(&self) -> usize {
        self.frames[0].len()
    }

    /// Frame `f` (N positions).
    pub fn frame(&self, f: usize) -> Vec<Vec3> {
        let mut rng =
            Rng::new(self.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (f as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93));
        let picks: Vec<usize> = (0..3).map(|_| rng.below(self.frames.len())).collect();
        let raw: Vec<f64> = (0..3).map(|_| -(1.0 - rng.uniform()).ln()).collect(); // Dirichlet(1,1,1)
        let total: f64 = raw.iter().sum();
        let waves: Vec<(Vec3, Vec3, f64)> = (0..3)
            .map(|_| {
                let dir = unit_vector(&mut rng);
                let push = unit_vector(&mut rng);
                let wavelength = self.diagonal * (0.5 + 1.5 * rng.uniform());
                let k = dir.map(|d| d * std::f64::consts::TAU / wavelength);
                let amp = Self::PERTURBATION * self.diagonal * rng.uniform() / 3.0;
                (k, push.map(|p| p * amp), rng.uniform() * std::f64::consts::TAU)
            })
            .collect();
        (0..self.n_vertices())
            .map(|i| {
                let mut p = [0.0; 3];
                for (j, &src) in picks.iter().enumerate() {
                    let q = self.frames[src][i];
                    for c in 0..3 {
                        p[c] += raw[j] / total * q[c];
                    }
                }
                let base = self.frames[0][i];
                for (k, push, phase) in &waves {
                    let s = (k[0] * base[0] + k[1] * base[1] + k[2] * base[2] + phase).sin();
                    for c in 0..3 {
                        p[c] += s * push[c];
                    }
                }
                p
            })
            .collect()
    }
}

/// Largest frame count [`write_blend_npy`] writes.
pub const MAX_BLEND_FRAMES: usize = 10_000_000;

/// Writes `n_frames` frames of [`Blend`] over `source` to `out` as an F × N × 3 float32 `.npy`,
/// made in parallel 256 frames at a time (memory: one such chunk), atomically.
/// `on_progress(frames_done)` is called after each chunk.
pub fn write_blend_npy(
    source: &MeshSequence,
    n_frames: usize,
    seed: u64,
    out: &std::path::Path,
    on_progress: &mut dyn FnMut(usize),
) -> Result<()> {
    use rayon::prelude::*;
    if !(1..=MAX_BLEND_FRAMES).contains(&n_frames) {
        return Err(Error::Invalid(format!("--frames {n_frames}: must be in 1 ..= {MAX_BLEND_FRAMES}")));
    }
    let blend = Blend::new(source, seed)?;
    crate::mesh::npy::write_npy_f32_chunked(out, n_frames, blend.n_vertices(), 256, |start, len| {
        let frames: Vec<Vec<Vec3>> = (start..start + len).into_par_iter().map(|f| blend.frame(f)).collect();
        on_progress(start + len);
        Ok(frames)
    })
}

fn named(prefix: &str, faces: Vec<[usize; 3]>, frames: Vec<Vec<Vec3>>) -> MeshSequence {
    let names = (0..frames.len()).map(|i| format!("{prefix}{:03}", i + 1)).collect();
    MeshSequence { faces, frames, names }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Topology;

    #[test]
    fn tube_is_closed_single_component() {
        let m = tube_mesh();
        assert_eq!(m.n_vertices(), RINGS * AROUND + 2);
        let t = Topology::new(m.n_vertices(), &m.faces);
        assert_eq!(t.n_boundary_edges(), 0);
        assert!(t.non_manifold_edges().is_empty());
        assert_eq!(t.components().1, 1);
        // Outward orientation: signed volume positive.
        let vol: f64 = m
            .faces
            .iter()
            .map(|f| {
                let (a, b, c) = (m.positions[f[0]], m.positions[f[1]], m.positions[f[2]]);
                (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0]))
                    / 6.0
            })
            .sum();
        assert!(vol > 0.0, "signed volume {vol} should be positive");
    }

    #[test]
    fn datasets_are_deterministic_and_finite() {
        for name in NAMES.iter().map(|n| n.replace(":N", ":40")) {
            let name = name.as_str();
            let a = load(&format!("synthetic:{name}")).unwrap();
            let b = load(name).unwrap();
            assert_eq!(a, b);
            assert!(a.frames.iter().flatten().flatten().all(|x| x.is_finite()));
            let rest = tube_mesh().positions;
            assert_eq!(a.frames[0][..rest.len()], rest[..], "frame 1 starts with the rest tube");
        }
        assert!(load("synthetic:nope").unwrap_err().to_string().contains("synthetic:tube"));
        for bad in ["pieces:0", "pieces:201", "pieces:x", "pieces:"] {
            let e = load(&format!("synthetic:{bad}")).unwrap_err().to_string();
            assert!(e.contains("from 1 to 200") && e.contains(bad), "{e}");
        }
    }

    /// `pieces:N` has N + 1 pieces, every part keeps its shape (rigid) in every frame while it
    /// turns, the tube bends, and the whole scene walks 2 units along x.
    #[test]
    fn many_pieces_are_rigid_parts_beside_a_bending_tube() {
        let seq = load("synthetic:pieces:40").unwrap();
        let n_tube = tube_mesh().n_vertices();
        assert_eq!(seq.n_vertices(), n_tube + 40 * PART_VERTICES);
        let t = Topology::new(seq.n_vertices(), &seq.faces);
        assert_eq!(t.components().1, 41);
        assert_eq!(t.n_boundary_edges(), 0);
        assert_eq!(planted_regions("synthetic:pieces:40").unwrap().len(), 41);
        let first = &seq.frames[0];
        let mut max_turn: f64 = 0.0;
        for f in &seq.frames {
            for i in 0..40 {
                let v0 = n_tube + PART_VERTICES * i;
                for a in v0..v0 + PART_VERTICES {
                    for b in a + 1..v0 + PART_VERTICES {
                        let (l0, l1) = (crate::mesh::dist(first[a], first[b]), crate::mesh::dist(f[a], f[b]));
                        assert!((l0 - l1).abs() < 1e-12, "part {i} is not rigid");
                    }
                }
                // How far the part's axis turned from its rest direction.
                let d0 = [0, 1, 2].map(|k| first[v0][k] - first[v0 + 1][k]);
                let d1 = [0, 1, 2].map(|k| f[v0][k] - f[v0 + 1][k]);
                let cos = (0..3).map(|k| d0[k] * d1[k]).sum::<f64>() / 0.08 / 0.08;
                max_turn = max_turn.max(cos.clamp(-1.0, 1.0).acos());
            }
        }
        assert!(max_turn > 0.5, "parts turn (largest {max_turn} rad)");
        // The walk: the centroid moves about 2 units along x (the quarter turn and the bends move
        // it a little more).
        let cx = |x: &[Vec3]| x.iter().map(|p| p[0]).sum::<f64>() / x.len() as f64;
        let walked = cx(seq.frames.last().unwrap()) - cx(first);
        assert!((walked - 2.0).abs() < 0.25, "walked {walked}");
    }

    #[test]
    fn bumps_move_only_their_planted_regions() {
        let seq = load("synthetic:bumps").unwrap();
        let regions = planted_regions("synthetic:bumps").unwrap();
        assert_eq!(regions.len(), 3);
        let inside: std::collections::HashSet<usize> =
            regions.iter().flat_map(|r| r.vertices.iter().copied()).collect();
        for f in &seq.frames {
            for (v, (p, q)) in f.iter().zip(&seq.frames[0]).enumerate() {
                if !inside.contains(&v) {
                    assert!(crate::mesh::dist(*p, *q) < 1e-12, "vertex {v} outside every region moved");
                }
            }
        }
        // Each region is small relative to the mesh but not empty.
        for r in &regions {
            assert!(
                !r.vertices.is_empty() && r.vertices.len() < seq.n_vertices() / 5,
                "{}: {}",
                r.name,
                r.vertices.len()
            );
        }
    }

    #[test]
    fn tube_bends_preserve_edge_lengths_outside_joint_zones() {
        let seq = load("synthetic:tube").unwrap();
        let rest = tube_mesh();
        let t = Topology::new(rest.n_vertices(), &rest.faces);
        let regions = planted_regions("synthetic:tube").unwrap();
        let touched: std::collections::HashSet<usize> =
            regions.iter().flat_map(|r| r.vertices.iter().copied()).collect();
        for f in &seq.frames {
            for e in &t.edges {
                if touched.contains(&e[0]) || touched.contains(&e[1]) {
                    continue;
                }
                let l0 = crate::mesh::dist(rest.positions[e[0]], rest.positions[e[1]]);
                let l1 = crate::mesh::dist(f[e[0]], f[e[1]]);
                assert!((l0 - l1).abs() < 1e-9 * l0.max(1.0), "rigid parts must stay rigid");
            }
        }
    }
    #[test]
    fn blend_is_deterministic_convex_and_near_the_source() {
        let src = load("synthetic:tube").unwrap();
        let b = Blend::new(&src, 7).unwrap();
        let a = b.frame(123);
        assert_eq!(a, Blend::new(&src, 7).unwrap().frame(123), "same (seed, frame), same frame");
        assert_ne!(a, b.frame(124));
        assert_ne!(a, Blend::new(&src, 8).unwrap().frame(123));
        // Within the source's per-vertex hull, widened by the perturbation's bound.
        let (lo, hi) = crate::mesh::bounding_box(&src.frames[0]);
        let bound = Blend::PERTURBATION * crate::mesh::dist(lo, hi) + 1e-12;
        for (i, p) in a.iter().enumerate() {
            for c in 0..3 {
                let min = src.frames.iter().map(|f| f[i][c]).fold(f64::INFINITY, f64::min);
                let max = src.frames.iter().map(|f| f[i][c]).fold(f64::NEG_INFINITY, f64::max);
                assert!(
                    p[c] >= min - bound && p[c] <= max + bound,
                    "vertex {i} axis {c}: {} not in [{min}, {max}]",
                    p[c]
                );
            }
        }
        let empty = MeshSequence { faces: vec![], frames: vec![], names: vec![] };
        assert!(Blend::new(&empty, 0).is_err());
    }
}
