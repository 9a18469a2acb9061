//! A small software rasterizer for pictures of meshes: orthographic view along a coordinate
//! axis, z-buffer, Lambert shading (two-sided, smooth vertex normals) times per-vertex colours.
//!
//! Output is an RGB8 image, row-major from the top-left pixel. [`vertex_colors_from_ply`] reads
//! the `red green blue` vertex properties of an ASCII PLY (e.g. `segmentation.ply`), which the
//! mesh loader skips.

use std::path::Path;

use super::normals::{NormalWeighting, vertex_normals};
use super::{TriMesh, Vec3};
use crate::math::vec3::{dot, norm};
use crate::{Error, Result};

/// Viewing direction (orthographic; +y is up except for `Top`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// Camera on +z looking towards −z; screen right = +x, up = +y.
    Front,
    /// Camera on +x looking towards −x; screen right = −z, up = +y.
    Side,
    /// Camera on +y looking down; screen right = +x, up = −z.
    Top,
    /// Camera on the + side of axis `view` (the − side when `negative`), the + side of axis `up`
    /// pointing up, screen right = e_up × (camera direction) ([`View::auto`] chooses the axes
    /// from the shape, see [`auto_axes`] and [`front_is_negative`]).
    Axes { up: usize, view: usize, negative: bool },
}

impl View {
    /// Parses `front`, `side` or `top`.
    pub fn parse(s: &str) -> Option<View> {
        match s {
            "front" => Some(View::Front),
            "side" => Some(View::Side),
            "top" => Some(View::Top),
            _ => None,
        }
    }

    /// The automatic view of a shape: axes by [`auto_axes`], the camera on the side of the view
    /// axis that sees the front ([`front_is_negative`]).
    pub fn auto(mesh: &TriMesh) -> View {
        let (up, view, negative) = auto_frame(mesh);
        View::Axes { up, view, negative }
    }

    /// (screen x, screen y, depth towards the camera) of a point.
    fn project(self, p: Vec3) -> Vec3 {
        match self {
            View::Front => [p[0], p[1], p[2]],
            View::Side => [-p[2], p[1], p[0]],
            View::Top => [p[0], -p[2], p[1]],
            View::Axes { up, view, negative } => {
                let (u, v) = (up.min(2), view.min(2));
                // right = e_up × e_view: the remaining axis with the sign of the permutation.
                let r = 3 - u - v;
                let sign = if (u + 1) % 3 == v { 1.0 } else { -1.0 };
                // e_u × e_v = +e_r when (u, v, r) is cyclic, i.e. v = u + 1 (mod 3). From the −
                // side, right and depth both flip (a half turn about the up axis).
                let f = if negative { -1.0 } else { 1.0 };
                [f * sign * p[r], p[u], f * p[v]]
            }
        }
    }
}

/// The automatic framing of a shape: its up axis is the axis of largest bounding-box extent
/// (a standing body, a face, a tube lying along z), the camera looks along the axis of smallest
/// extent (a face's depth, a body's front-to-back). Ties prefer y, z, x for up and z, x, y for
/// the view, so a shape already given y-up and z-facing keeps that framing.
/// Returns `(up axis, view axis)` (0 = x, 1 = y, 2 = z); the camera sits on the + side of the
/// view axis, the + side of the up axis points up.
pub fn auto_axes(positions: &[Vec3]) -> (usize, usize) {
    let (lo, hi) = super::bounding_box(positions);
    let e: Vec<f64> = (0..3).map(|k| if positions.is_empty() { 0.0 } else { hi[k] - lo[k] }).collect();
    let tol = 1e-6 * e.iter().cloned().fold(0.0, f64::max);
    let mut up = 1;
    for k in [2, 0] {
        if e[k] > e[up] + tol {
            up = k;
        }
    }
    let mut view = usize::MAX;
    for k in [2, 0, 1] {
        if k != up && (view == usize::MAX || e[k] < e[view] - tol) {
            view = k;
        }
    }
    (up, view)
}

/// The automatic framing of [`View::auto`] as numbers: `(up axis, view axis, camera on the −
/// side)` ([`auto_axes`], [`front_is_negative`]); the viewer's page frames its camera with them.
pub fn auto_frame(mesh: &TriMesh) -> (usize, usize, bool) {
    let (up, view) = auto_axes(&mesh.positions);
    (up, view, front_is_negative(&mesh.positions, &mesh.faces, view))
}

/// Which side of the view axis `view` (0 = x, 1 = y, 2 = z) shows a shape's front: the side
/// most vertex normals face. `true` when more vertices face the − side (ties: the + side).
///
/// For an open shape (a face mask) nearly every normal faces the front. For a closed one the
/// area-weighted normals cancel exactly, but the vertex count does not: detail (a face, hands,
/// toes) is finer on the front. SCAPE's frame 1: 10 % more vertices face −y than +y, so it is
/// seen from −y (from +y it showed its back).
pub fn front_is_negative(positions: &[Vec3], faces: &[[usize; 3]], view: usize) -> bool {
    let v = view.min(2);
    let mut balance = 0i64;
    for n in vertex_normals(positions, faces, NormalWeighting::Area) {
        if n[v] > 1e-9 {
            balance += 1;
        } else if n[v] < -1e-9 {
            balance -= 1;
        }
    }
    balance < 0
}

/// Picture settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Image width in pixels (≥ 8).
    pub width: usize,
    /// Image height in pixels (≥ 8).
    pub height: usize,
    pub view: View,
    /// Background colour.
    pub background: [u8; 3],
    /// Colour of vertices when none are given.
    pub base_color: [u8; 3],
    /// The box (min, max corner, data units) fitted into the image; `None`: the mesh's own
    /// bounding box. Pictures of several shapes share one framing by passing the same box.
    pub bounds: Option<(Vec3, Vec3)>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 800,
            height: 800,
            view: View::Front,
            background: [255; 3],
            base_color: [200; 3],
            bounds: None,
        }
    }
}

/// Renders `mesh` with optional per-vertex `colors` (N). Returns `width × height × 3` bytes.
/// Errors on bad sizes, bad face indices or non-finite positions.
pub fn render(mesh: &TriMesh, colors: Option<&[[u8; 3]]>, opts: &RenderOptions) -> Result<Vec<u8>> {
    let (w, h) = (opts.width, opts.height);
    if !(8..=16384).contains(&w) || !(8..=16384).contains(&h) {
        return Err(Error::Invalid(format!("render: image size {w}×{h} must be between 8 and 16384 per side")));
    }
    let n = mesh.n_vertices();
    if let Some((f, face)) = mesh.first_bad_index() {
        return Err(Error::Invalid(format!("render: face {f} {face:?} refers past {n} vertices")));
    }
    if let Some(i) = mesh.positions.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(Error::Invalid(format!("render: vertex {i} is not finite")));
    }
    if let Some(c) = colors
        && c.len() != n
    {
        return Err(Error::Invalid(format!("render: {} colours for {n} vertices", c.len())));
    }
    let mut img: Vec<u8> = (0..w * h).flat_map(|_| opts.background).collect();
    if n == 0 || mesh.faces.is_empty() {
        return Ok(img);
    }
    let q: Vec<Vec3> = mesh.positions.iter().map(|&p| opts.view.project(p)).collect();
    let normals: Vec<Vec3> = vertex_normals(&mesh.positions, &mesh.faces, NormalWeighting::Area)
        .into_iter()
        .map(|nv| opts.view.project(nv))
        .collect();
    // Fit the projected bounding box into the image with a 5 % margin, square pixels.
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let corners: Vec<Vec3> = match opts.bounds {
        Some((a, b)) => (0..8)
            .map(|i| {
                opts.view.project([
                    if i & 1 == 0 { a[0] } else { b[0] },
                    if i & 2 == 0 { a[1] } else { b[1] },
                    if i & 4 == 0 { a[2] } else { b[2] },
                ])
            })
            .collect(),
        None => Vec::new(),
    };
    for p in if corners.is_empty() { &q } else { &corners } {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let span = [(hi[0] - lo[0]).max(1e-300), (hi[1] - lo[1]).max(1e-300)];
    let s = (0.9 * w as f64 / span[0]).min(0.9 * h as f64 / span[1]);
    let (cx, cy) = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]));
    let px: Vec<[f64; 3]> =
        q.iter().map(|p| [0.5 * w as f64 + s * (p[0] - cx), 0.5 * h as f64 - s * (p[1] - cy), p[2]]).collect();
    // Light from the camera, a little up and to the left.
    let light = crate::math::vec3::normalize([-0.3, 0.4, 1.0]);
    let mut depth = vec![f64::NEG_INFINITY; w * h];
    let col = |v: usize| colors.map_or(opts.base_color, |c| c[v]);
    for f in &mesh.faces {
        let [a, b, c] = [px[f[0]], px[f[1]], px[f[2]]];
        let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0) as usize;
        let x1 = (a[0].max(b[0]).max(c[0]).ceil() as usize).min(w - 1);
        let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0) as usize;
        let y1 = (a[1].max(b[1]).max(c[1]).ceil() as usize).min(h - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (sx, sy) = (x as f64 + 0.5, y as f64 + 0.5);
                let l1 = ((b[0] - sx) * (c[1] - sy) - (b[1] - sy) * (c[0] - sx)) / area;
                let l2 = ((c[0] - sx) * (a[1] - sy) - (c[1] - sy) * (a[0] - sx)) / area;
                let l3 = 1.0 - l1 - l2;
                if l1 < 0.0 || l2 < 0.0 || l3 < 0.0 {
                    continue;
                }
                let z = l1 * a[2] + l2 * b[2] + l3 * c[2];
                let i = y * w + x;
                if z <= depth[i] {
                    continue;
                }
                depth[i] = z;
                let mut nrm = [0.0; 3];
                for k in 0..3 {
                    nrm[k] = l1 * normals[f[0]][k] + l2 * normals[f[1]][k] + l3 * normals[f[2]][k];
                }
                let len = norm(nrm).max(1e-300);
                let lambert = (dot(nrm, light) / len).abs();
                let shade = 0.2 + 0.8 * lambert;
                let (ca, cb, cc) = (col(f[0]), col(f[1]), col(f[2]));
                for k in 0..3 {
                    let v = l1 * ca[k] as f64 + l2 * cb[k] as f64 + l3 * cc[k] as f64;
                    img[3 * i + k] = (v * shade).round().clamp(0.0, 255.0) as u8;
                }
            }
        }
    }
    Ok(img)
}

/// The `red green blue` vertex properties of an ASCII PLY file (`None` when the file is binary
/// or has no colour properties).
pub fn vertex_colors_from_ply(path: &Path) -> Result<Option<Vec<[u8; 3]>>> {
    let text = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let text = String::from_utf8_lossy(&text);
    let mut lines = text.lines().enumerate();
    let mut ascii = false;
    let mut n = 0usize;
    let mut in_vertex = false;
    let mut props: Vec<String> = Vec::new();
    for (no, line) in lines.by_ref() {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.as_slice() {
            ["format", f, ..] => ascii = *f == "ascii",
            ["element", "vertex", c] => {
                n = c.parse().map_err(|_| Error::parse(path, Some(no + 1), format!("bad vertex count `{c}`")))?;
                in_vertex = true;
            }
            ["element", ..] => in_vertex = false,
            ["property", "list", ..] => {}
            ["property", _, name] if in_vertex => props.push(name.to_string()),
            ["end_header"] => break,
            _ => {}
        }
    }
    let idx = |name: &str| props.iter().position(|p| p == name);
    let (Some(r), Some(g), Some(b)) = (idx("red"), idx("green"), idx("blue")) else { return Ok(None) };
    if !ascii {
        return Ok(None);
    }
    let mut out = Vec::with_capacity(n);
    for (no, line) in lines.take(n) {
        let t: Vec<&str> = line.split_whitespace().collect();
        let get = |k: usize| -> Result<u8> {
            t.get(k)
                .and_then(|s| s.parse::<u8>().ok())
                .ok_or_else(|| Error::parse(path, Some(no + 1), format!("bad colour value in `{line}`")))
        };
        out.push([get(r)?, get(g)?, get(b)?]);
    }
    if out.len() != n {
        return Err(Error::Invalid(format!("{}: {} vertex lines, header says {n}", path.display(), out.len())));
    }
    Ok(Some(out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives::icosphere;

    #[test]
    fn sphere_covers_the_centre_and_leaves_corners_background() {
        let m = icosphere(2);
        let opts = RenderOptions { width: 64, height: 48, ..Default::default() };
        let img = render(&m, None, &opts).unwrap();
        assert_eq!(img.len(), 64 * 48 * 3);
        let px = |x: usize, y: usize| &img[3 * (y * 64 + x)..3 * (y * 64 + x) + 3];
        assert_eq!(px(0, 0), &[255, 255, 255]);
        assert_ne!(px(32, 24), &[255, 255, 255]);
        // Facing the light: the centre is brighter than the rim.
        assert!(px(30, 22)[0] > px(32 + 20, 24)[0]);
        assert!(render(&m, Some(&[[0; 3]; 3]), &opts).is_err());
        assert!(render(&m, None, &RenderOptions { width: 2, ..opts }).is_err());
    }

    #[test]
    fn axes_views_match_the_named_ones_and_auto_stands_a_long_shape_up() {
        let axes = |up, view, negative| View::Axes { up, view, negative };
        assert_eq!(axes(1, 2, false).project([1.0, 2.0, 3.0]), View::Front.project([1.0, 2.0, 3.0]));
        assert_eq!(axes(1, 0, false).project([1.0, 2.0, 3.0]), View::Side.project([1.0, 2.0, 3.0]));
        // From the − side: a half turn about the up axis (right and depth flip, up stays).
        assert_eq!(axes(1, 2, true).project([1.0, 2.0, 3.0]), [-1.0, 2.0, -3.0]);
        // A shape lying along z (the synthetic tube: long in z, round in x and y) stands up, seen
        // from +x; a flat shape facing z (a face) keeps y up and z towards the camera.
        let tube = crate::synthetic::tube_mesh();
        assert_eq!(auto_axes(&tube.positions), (2, 0));
        let face: Vec<Vec3> = vec![[0.0, 0.0, 0.0], [0.8, 1.0, 0.1], [-0.8, -1.0, 0.3]];
        assert_eq!(auto_axes(&face), (1, 2));
        // Rendered automatically, the tube's picture is taller than wide.
        let opts = RenderOptions { width: 100, height: 100, view: View::auto(&tube), ..Default::default() };
        let img = render(&tube, None, &opts).unwrap();
        let (mut xs, mut ys) = (Vec::new(), Vec::new());
        for y in 0..100 {
            for x in 0..100 {
                if img[3 * (y * 100 + x)..3 * (y * 100 + x) + 3] != [255, 255, 255] {
                    xs.push(x);
                    ys.push(y);
                }
            }
        }
        let w = xs.iter().max().unwrap() - xs.iter().min().unwrap();
        let h = ys.iter().max().unwrap() - ys.iter().min().unwrap();
        assert!(h > 3 * w, "auto view of the tube: {w}×{h} pixels of ink");
    }

    #[test]
    fn the_camera_sees_the_side_most_normals_face() {
        // A cap (open, a face mask): facing +z it is seen from +z; turned over, from −z.
        let mut cap = crate::mesh::primitives::grid(8, 8, 1.0);
        for p in &mut cap.positions {
            p[2] = -((p[0] - 0.5).powi(2) + (p[1] - 0.5).powi(2));
        }
        let faces_up =
            vertex_normals(&cap.positions, &cap.faces, NormalWeighting::Area).iter().filter(|n| n[2] > 0.0).count();
        assert!(faces_up > cap.positions.len() / 2, "the test cap faces +z");
        assert!(!front_is_negative(&cap.positions, &cap.faces, 2));
        let flipped: Vec<[usize; 3]> = cap.faces.iter().map(|f| [f[0], f[2], f[1]]).collect();
        assert!(front_is_negative(&cap.positions, &flipped, 2));
        assert_eq!(
            View::auto(&TriMesh { positions: cap.positions.clone(), faces: flipped }),
            View::Axes { up: 1, view: 2, negative: true }
        );
        // A vote by vertex count: a fine grid (81 vertices) facing one way outvotes a coarse
        // one (9) facing the other, whichever way each faces; equal counts: the + side.
        let two = |fine_up: bool, coarse: usize| {
            let (fine, rough) =
                (crate::mesh::primitives::grid(8, 8, 1.0), crate::mesh::primitives::grid(coarse, coarse, 1.0));
            let flip = |f: &[usize; 3], up: bool| if up { *f } else { [f[0], f[2], f[1]] };
            let n = fine.positions.len();
            let positions: Vec<Vec3> = fine.positions.iter().chain(&rough.positions).copied().collect();
            let faces: Vec<[usize; 3]> = fine
                .faces
                .iter()
                .map(|f| flip(f, fine_up))
                .chain(rough.faces.iter().map(|f| flip(&[f[0] + n, f[1] + n, f[2] + n], !fine_up)))
                .collect();
            front_is_negative(&positions, &faces, 2)
        };
        assert!(!two(true, 2), "81 vertices face +z, 9 face −z");
        assert!(two(false, 2), "81 vertices face −z, 9 face +z");
        assert!(!two(false, 8), "as many face each way");
        // Vertices whose normal has no component along the view (here: on no face) do not vote.
        let mut lone = crate::mesh::primitives::grid(2, 2, 1.0);
        lone.positions.extend((0..20).map(|i| [i as f64, 5.0, 0.0]));
        assert!(!front_is_negative(&lone.positions, &lone.faces, 2), "9 face +z, 20 have no normal");
    }

    /// Pixels of a `w`-wide picture that are not the white background.
    fn inked(img: &[u8], w: usize) -> Vec<(usize, usize)> {
        (0..img.len() / 3).filter(|i| img[3 * i..3 * i + 3] != [255, 255, 255]).map(|i| (i % w, i / w)).collect()
    }

    /// The colour of pixel (`x`, `y`) of a `w`-wide picture.
    fn pixel(img: &[u8], w: usize, x: usize, y: usize) -> [u8; 3] {
        let i = 3 * (y * w + x);
        [img[i], img[i + 1], img[i + 2]]
    }

    /// The Lambert factor of a surface facing the camera (normal +z, light ∝ (−0.3, 0.4, 1)):
    /// 0.2 + 0.8 n·l.
    fn facing_shade() -> f64 {
        0.2 + 0.8 / 1.25f64.sqrt()
    }

    /// The right triangle (0,0,0), (1,0,0), (0,1,0), facing +z.
    fn corner_triangle() -> TriMesh {
        TriMesh { positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], faces: vec![[0, 1, 2]] }
    }

    /// Seen from the front in 100 × 100 pixels, the unit triangle is fitted with a 5 % margin:
    /// pixel x = 5 + 90 X, y = 95 − 90 Y, so it covers (5, 95), (95, 95), (5, 5). A pixel is
    /// drawn exactly when its centre is inside or on an edge (the hypotenuse's pixels too), all
    /// in one Lambert shade of the base colour: 0.2 + 0.8 |n·l|, light ∝ (−0.3, 0.4, 1).
    #[test]
    fn a_flat_triangle_fills_the_pixels_inside_it_in_one_shade() {
        let opts = RenderOptions { width: 100, height: 100, base_color: [200, 100, 50], ..Default::default() };
        let img = render(&corner_triangle(), None, &opts).unwrap();
        let want = [200.0, 100.0, 50.0].map(|c: f64| (c * facing_shade()).round() as u8);
        for y in 0..100 {
            for x in 0..100 {
                let inside = x >= 5 && y <= 94 && x <= y;
                assert_eq!(pixel(&img, 100, x, y), if inside { want } else { [255; 3] }, "pixel ({x}, {y})");
            }
        }
        // Two-sided: the same triangle wound the other way (facing −z) looks the same.
        let mut back = corner_triangle();
        back.faces = vec![[0, 2, 1]];
        assert_eq!(render(&back, None, &opts).unwrap(), img);
    }

    /// Vertex colours are blended by the pixel centre's barycentric weights, then shaded.
    #[test]
    fn vertex_colours_blend_by_barycentric_weight() {
        let opts = RenderOptions { width: 100, height: 100, ..Default::default() };
        let colors = [[255, 0, 0], [0, 255, 0], [0, 0, 255]];
        let img = render(&corner_triangle(), Some(&colors), &opts).unwrap();
        for (x, y) in [(34usize, 64usize), (6, 93), (90, 93), (6, 10), (50, 80)] {
            // Weights of the corners at the pixel centre (x + ½, y + ½): b = (1,0,0) grows with
            // x, c = (0,1,0) grows upwards, a takes the rest.
            let wb = (x as f64 + 0.5 - 5.0) / 90.0;
            let wc = (95.0 - (y as f64 + 0.5)) / 90.0;
            let wa = 1.0 - wb - wc;
            let want = [wa, wb, wc].map(|w| (255.0 * w * facing_shade()).round() as i32);
            let got = pixel(&img, 100, x, y);
            for k in 0..3 {
                assert!((got[k] as i32 - want[k]).abs() <= 1, "pixel ({x}, {y}): {got:?}, expected {want:?}");
            }
        }
    }

    /// The nearer surface hides the farther one whatever the face order; from the other side
    /// the other surface is nearer.
    #[test]
    fn the_nearer_face_wins_in_either_order() {
        // Two squares overlapping in x ∈ [1, 2]: red at z = 0 (x ∈ [0, 2]), blue at z = 0.5
        // (x ∈ [1, 3]); both y ∈ [0, 1].
        let mut positions = Vec::new();
        for (x0, z) in [(0.0, 0.0), (1.0, 0.5)] {
            positions.extend([[x0, 0.0, z], [x0 + 2.0, 0.0, z], [x0 + 2.0, 1.0, z], [x0, 1.0, z]]);
        }
        let red_blue = [[[255, 0, 0]; 4], [[0, 0, 255]; 4]].concat();
        let squares = |order: [usize; 2]| TriMesh {
            positions: positions.clone(),
            faces: order.iter().flat_map(|&q| [[4 * q, 4 * q + 1, 4 * q + 2], [4 * q, 4 * q + 2, 4 * q + 3]]).collect(),
        };
        // 3 × 1 units fitted into 120 × 40: 36 pixels per unit, x = 6 + 36 X, the middle row y = 20.
        let middle = |img: &[u8], x_units: f64| pixel(img, 120, (6.0 + 36.0 * x_units) as usize, 20);
        for (view, overlap) in [(View::Front, "blue"), (View::Axes { up: 1, view: 2, negative: true }, "red")] {
            let opts = RenderOptions { width: 120, height: 40, view, ..Default::default() };
            let a = render(&squares([0, 1]), Some(&red_blue), &opts).unwrap();
            let b = render(&squares([1, 0]), Some(&red_blue), &opts).unwrap();
            assert_eq!(a, b, "{view:?}: the face order changed the picture");
            // From −z the picture is mirrored: red's own part is on the right.
            let (red_x, blue_x) = if overlap == "blue" { (0.5, 2.5) } else { (2.5, 0.5) };
            let m = middle(&a, 1.5);
            assert!(
                if overlap == "blue" { m[2] > 150 && m[0] == 0 } else { m[0] > 150 && m[2] == 0 },
                "{view:?}: overlap {m:?}"
            );
            assert!(middle(&a, red_x)[0] > 150 && middle(&a, red_x)[2] == 0, "{view:?}");
            assert!(middle(&a, blue_x)[2] > 150 && middle(&a, blue_x)[0] == 0, "{view:?}");
        }
    }

    /// Ties in extent prefer y, z, x for up: exactly (a point, no extent at all) and within the
    /// tolerance of 10⁻⁶ × the largest extent, which scales with the shape (here 1000 units).
    #[test]
    fn auto_axes_ties_prefer_y_up_at_any_scale() {
        assert_eq!(auto_axes(&[[3.0, 4.0, 5.0]]), (1, 2));
        assert_eq!(auto_axes(&[]), (1, 2));
        // x and y 1000 units, x longer by 10⁻⁴ (within 10⁻³): still y up; z shortest: view z.
        let near_tie = [[0.0, 0.0, 0.0], [1000.0 + 1e-4, 1000.0, 10.0]];
        assert_eq!(auto_axes(&near_tie), (1, 2));
        // Longer by 10⁻² (beyond the tolerance): x up.
        let longer = [[0.0, 0.0, 0.0], [1000.01, 1000.0, 10.0]];
        assert_eq!(auto_axes(&longer), (0, 2));
        // The view axis is the shortest other than up, even when it comes later in z, x, y.
        assert_eq!(auto_axes(&[[0.0, 0.0, 0.0], [1.0, 5.0, 3.0]]), (1, 0));
        assert_eq!(auto_axes(&[[0.0, 0.0, 0.0], [5.0, 1.0, 3.0]]), (0, 1));
    }

    /// Side and top views put the screen axes where their docs say: side: right = −z, up = +y;
    /// top: right = +x, up = −z. The right angle of a corner triangle lands in a known corner.
    #[test]
    fn side_and_top_views_orient_the_picture() {
        let tri = |q: Vec3, r: Vec3| TriMesh { positions: vec![[0.0; 3], q, r], faces: vec![[0, 1, 2]] };
        // The drawn pixel nearest each corner of the 100 × 100 image's fitted square (5..95).
        let corners = |img: &[u8]| {
            let at = |x: usize, y: usize| pixel(img, 100, x, y) != [255; 3];
            [at(6, 6), at(93, 6), at(6, 93), at(93, 93)] // top-left, top-right, bottom-left, bottom-right
        };
        let opts = |view| RenderOptions { width: 100, height: 100, view, ..Default::default() };
        // Side: the triangle in the y-z plane with its right angle at the origin, legs +z and +y:
        // +z is screen left, so the right angle is bottom-right.
        let side = render(&tri([0.0, 0.0, 1.0], [0.0, 1.0, 0.0]), None, &opts(View::Side)).unwrap();
        assert_eq!(corners(&side), [false, true, true, true]);
        // Top: legs +x and +z: +z is screen down, so the right angle is top-left.
        let top = render(&tri([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]), None, &opts(View::Top)).unwrap();
        assert_eq!(corners(&top), [true, true, true, false]);
        // Front: legs +x and +y: the right angle is bottom-left.
        let front = render(&corner_triangle(), None, &opts(View::Front)).unwrap();
        assert_eq!(corners(&front), [true, false, true, true]);
        assert_eq!(View::parse("side"), Some(View::Side));
        assert_eq!(View::parse("top"), Some(View::Top));
        assert_eq!(View::parse("front"), Some(View::Front));
        assert_eq!(View::parse("back"), None);
    }

    /// A given box frames the picture instead of the mesh's own: a larger box draws the shape
    /// smaller; a smaller one crops it at the image border (no panic, nothing wrapped).
    #[test]
    fn a_given_box_frames_the_picture() {
        let opts = |bounds| RenderOptions { width: 100, height: 100, bounds, ..Default::default() };
        let tri = corner_triangle();
        // Box (−1, −1, −1)–(2, 2, 2): 30 pixels per unit about the centre (0.5, 0.5):
        // the triangle spans (35, 65), (65, 65), (35, 35).
        let small = render(&tri, None, &opts(Some(([-1.0; 3], [2.0; 3])))).unwrap();
        let want: Vec<(usize, usize)> = (0..100)
            .flat_map(|y| (0..100).map(move |x| (x, y)))
            .filter(|&(x, y)| x >= 35 && y <= 64 && x <= y)
            .collect();
        assert_eq!(inked(&small, 100), want);
        // Box (0, 0, 0)–(0.5, 0.5, 0): 180 pixels per unit about (0.25, 0.25): the triangle
        // spans (5, 95), (185, 95), (5, −85), cut by the image border.
        let big = render(&tri, None, &opts(Some(([0.0; 3], [0.5, 0.5, 0.0])))).unwrap();
        let want: Vec<(usize, usize)> = (0..100)
            .flat_map(|y| (0..100).map(move |x| (x, y)))
            .filter(|&(x, y)| x >= 5 && y <= 94 && x <= y + 90)
            .collect();
        assert_eq!(inked(&big, 100), want);
    }

    /// The framing does not depend on where the shape sits, and the side that limits the scale
    /// fills 90 % of its image side: a 2 × 1 triangle spans x 5..95 and y 27.5..72.5 of a
    /// 100 × 100 picture, a 1 × 2 one the transpose. A given box's extent along the view's
    /// screen axes frames it (here z, seen from the side).
    #[test]
    fn framing_ignores_position_and_fills_the_limiting_side() {
        let opts = RenderOptions { width: 100, height: 100, ..Default::default() };
        let scaled = |sx: f64, sy: f64, at: Vec3| TriMesh {
            positions: corner_triangle()
                .positions
                .iter()
                .map(|p| [at[0] + sx * p[0], at[1] + sy * p[1], at[2] + p[2]])
                .collect(),
            faces: vec![[0, 1, 2]],
        };
        let extent = |img: &[u8]| {
            let ink = inked(img, 100);
            let xs = ink.iter().map(|p| p.0);
            let ys = ink.iter().map(|p| p.1);
            (xs.clone().min().unwrap(), xs.max().unwrap(), ys.clone().min().unwrap(), ys.max().unwrap())
        };
        for (sx, sy, want) in [(2.0, 1.0, (5, 94, 28, 72)), (1.0, 2.0, (27, 71, 5, 94))] {
            let here = render(&scaled(sx, sy, [0.0; 3]), None, &opts).unwrap();
            assert_eq!(extent(&here), want, "{sx} × {sy}");
            let there = render(&scaled(sx, sy, [10.0, 20.0, 30.0]), None, &opts).unwrap();
            assert_eq!(there, here, "{sx} × {sy} moved by (10, 20, 30)");
        }
        // Seen from the side (screen x = −z), a triangle in the y-z plane inside a box 3 deep in z:
        let side = RenderOptions { view: View::Side, bounds: Some(([0.0, 0.0, -1.0], [1.0, 1.0, 2.0])), ..opts };
        let tri_yz = TriMesh { positions: vec![[0.0; 3], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]], faces: vec![[0, 1, 2]] };
        // 3 units of z across: 30 pixels a unit about z = 0.5 (screen x = −z): z = 0 at x = 65,
        // z = 1 at x = 35; y = 0 at 65, y = 1 at 35.
        let ink = inked(&render(&tri_yz, None, &side).unwrap(), 100);
        let xs: Vec<usize> = ink.iter().map(|p| p.0).collect();
        assert_eq!((*xs.iter().min().unwrap(), *xs.iter().max().unwrap()), (35, 64), "side view framed by the box's z");
    }

    /// A face of (near) zero area draws nothing — its barycentric weights would be 0/0 — and
    /// the sizes 8 and 16384 are the bounds; an empty mesh is the background.
    #[test]
    fn degenerate_faces_draw_nothing_and_sizes_are_bounded() {
        let opts = RenderOptions { width: 100, height: 100, ..Default::default() };
        let mut m = corner_triangle();
        // Three points on the line y = 1 − x: a face of zero area across the picture.
        m.positions.extend([[0.0, 1.0, 0.0], [0.5, 0.5, 0.0], [1.0, 0.0, 0.0]]);
        m.faces.push([3, 4, 5]);
        assert_eq!(render(&m, None, &opts).unwrap(), render(&corner_triangle(), None, &opts).unwrap());
        let tri = corner_triangle();
        for (w, h, ok) in
            [(8, 8, true), (7, 8, false), (8, 7, false), (16384, 8, true), (16385, 8, false), (8, 16385, false)]
        {
            assert_eq!(render(&tri, None, &RenderOptions { width: w, height: h, ..opts }).is_ok(), ok, "{w}×{h}");
        }
        let empty = TriMesh { positions: vec![], faces: vec![] };
        let bg = RenderOptions { background: [1, 2, 3], ..opts };
        assert!(render(&empty, None, &bg).unwrap().chunks(3).all(|c| c == [1, 2, 3]));
        let mut bad = corner_triangle();
        bad.faces = vec![[0, 1, 3]];
        assert!(render(&bad, None, &opts).unwrap_err().to_string().contains("face 0"));
        let mut nan = corner_triangle();
        nan.positions[2][1] = f64::NAN;
        assert!(render(&nan, None, &opts).unwrap_err().to_string().contains("vertex 2"));
        nan.positions[2][1] = f64::INFINITY;
        assert!(render(&nan, None, &opts).is_err());
    }

    /// Colours from an ASCII PLY's `red green blue` vertex properties, wherever they sit among
    /// the others; `None` for a binary PLY or one without colours; errors name the file and line.
    #[test]
    fn ply_vertex_colours_are_read_by_property_name() {
        let dir = crate::mesh::load::test_dir("ply-colours");
        let read = |name: &str, text: &str| {
            let path = dir.join(name);
            std::fs::write(&path, text).unwrap();
            vertex_colors_from_ply(&path).map_err(|e| e.to_string())
        };
        let head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty uchar blue\n\
                    property float y\nproperty uchar red\nproperty float z\nproperty uchar green\n\
                    element face 1\nproperty list uchar int vertex_indices\nproperty uchar red\nend_header\n";
        let ok = format!("{head}0 1 0 2 0 3\n1 4 1 5 1 6\n3 0 1 1 9\n");
        assert_eq!(read("ok.ply", &ok).unwrap(), Some(vec![[2, 3, 1], [5, 6, 4]]));
        let binary = ok.replace("format ascii 1.0", "format binary_little_endian 1.0");
        assert_eq!(read("binary.ply", &binary).unwrap(), None);
        let plain = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                     property float z\nend_header\n0 0 0\n";
        assert_eq!(read("plain.ply", plain).unwrap(), None);
        // Colours given only on faces are not vertex colours.
        let face_only = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nelement face 0\n\
                         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0\n";
        assert_eq!(read("face.ply", face_only).unwrap(), None);
        let e = read("big.ply", &format!("{head}0 1 0 2 0 3\n1 4 1 256 1 6\n")).unwrap_err();
        assert!(e.contains("big.ply:15") && e.contains("256"), "{e}");
        let e = read("short.ply", &format!("{head}0 1 0 2 0 3\n")).unwrap_err();
        assert!(e.contains("short.ply") && e.contains("1 vertex lines, header says 2"), "{e}");
        let e = read("count.ply", &head.replace("element vertex 2", "element vertex two")).unwrap_err();
        assert!(e.contains("count.ply:3") && e.contains("`two`"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A box cropping the shape at the bottom draws down to the last row and no further: box
    /// (0, 0.5, 0)–(0.5, 1, 0), 180 pixels per unit about (0.25, 0.75): the triangle spans
    /// (5, 185), (185, 185), (5, 5), cut by the bottom and right borders.
    #[test]
    fn a_box_cropping_the_bottom_stops_at_the_last_row() {
        let bounds = Some(([0.0, 0.5, 0.0], [0.5, 1.0, 0.0]));
        let opts = RenderOptions { width: 100, height: 100, bounds, ..Default::default() };
        let img = render(&corner_triangle(), None, &opts).unwrap();
        let want: Vec<(usize, usize)> =
            (0..100).flat_map(|y| (0..100).map(move |x| (x, y))).filter(|&(x, y)| x >= 5 && x <= y).collect();
        assert_eq!(inked(&img, 100), want);
    }

    /// Smooth shading: a roof of two steep faces (normals ∝ (∓4, 0, 1)) meeting at a ridge along
    /// y (vertex normals +z there). Each pixel is shaded by the normal interpolated with its
    /// barycentric weights, renormalised, lit from (−0.3, 0.4, 1).
    #[test]
    fn shading_interpolates_vertex_normals_across_a_face() {
        let h = 4.0;
        let roof = TriMesh {
            positions: vec![[-1.0, 0.0, 0.0], [0.0, 0.0, h], [0.0, 1.0, h], [1.0, 0.0, 0.0]],
            faces: vec![[0, 1, 2], [1, 3, 2]],
        };
        let img = render(&roof, None, &RenderOptions { width: 100, height: 100, ..Default::default() }).unwrap();
        let light = crate::math::vec3::normalize([-0.3, 0.4, 1.0]);
        let r = (h * h + 1.0f64).sqrt();
        // 2 × 1 units in 100 × 100: 45 pixels a unit about (0, 0.5): x = 50 + 45 X, y = 72.5 − 45 Y.
        for (x, y) in [(31usize, 58usize), (68, 58), (14, 70), (86, 70), (49, 40), (40, 66), (60, 66)] {
            let cx = (x as f64 + 0.5 - 50.0) / 45.0;
            // The eave vertex (±1, 0, 0) weighs |X|; the two ridge vertices (normal +z) the rest.
            let t = cx.abs();
            let n = [t * cx.signum() * h / r, 0.0, t / r + (1.0 - t)];
            let want = (200.0 * (0.2 + 0.8 * dot(n, light).abs() / norm(n))).round() as i32;
            let got = pixel(&img, 100, x, y);
            assert!(got.iter().all(|&g| (g as i32 - want).abs() <= 1), "pixel ({x}, {y}): {got:?}, expected {want}");
        }
    }

    /// Depth is interpolated across a face: a square tilted in depth (z = X, 0..2) crosses a flat
    /// one at z = 1. From the front the flat red one shows for X < 1, the tilted blue one for X > 1.
    #[test]
    fn depth_is_interpolated_across_a_tilted_face() {
        let positions = vec![
            [0.0, 0.0, 1.0],
            [2.0, 0.0, 1.0],
            [2.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 2.0],
            [2.0, 1.0, 2.0],
            [0.0, 1.0, 0.0],
        ];
        let mesh = TriMesh { positions, faces: vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]] };
        let colors = [[[255, 0, 0]; 4], [[0, 0, 255]; 4]].concat();
        let opts = RenderOptions { width: 100, height: 50, ..Default::default() };
        let img = render(&mesh, Some(&colors), &opts).unwrap();
        // 2 × 1 units in 100 × 50: 45 pixels a unit, x = 5 + 45 X, y = 47.5 − 45 Y.
        for y in 3..47 {
            for x in 6..94 {
                let cx = (x as f64 + 0.5 - 5.0) / 45.0;
                if (cx - 1.0).abs() < 0.05 {
                    continue;
                }
                let p = pixel(&img, 100, x, y);
                if cx < 1.0 {
                    assert!(p[0] > 0 && p[2] == 0, "pixel ({x}, {y}): {p:?}, expected red");
                } else {
                    assert!(p[2] > 0 && p[0] == 0, "pixel ({x}, {y}): {p:?}, expected blue");
                }
            }
        }
    }

    /// A `property list` line in the vertex element is never a colour, even one cut to three words.
    #[test]
    fn a_list_property_is_never_a_colour() {
        let dir = crate::mesh::load::test_dir("ply-list-colour");
        let path = dir.join("list.ply");
        let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty uchar red\nproperty uchar blue\n\
                    property list green\nend_header\n1 2 3\n";
        std::fs::write(&path, text).unwrap();
        assert_eq!(vertex_colors_from_ply(&path).unwrap(), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The zero-area cut-off is strict: a sliver whose doubled pixel area is exactly 10⁻¹² is
    /// still drawn. Box (−36, −36)–(36, 36) in 80 × 80: 0.9 · 80 / 72 = 1 pixel a unit about the
    /// origin, so pixel x = 40 + X, y = 40 − Y exactly. The sliver has a base of M = 10⁻¹² · 2⁴⁷
    /// pixels along the row of centres y = 39.5 and a height of 2⁻⁴⁷ (all exact in binary), so
    /// its area term is exactly −10⁻¹²; the centres on its base lie on an edge and are drawn.
    #[test]
    fn a_sliver_at_the_area_cut_off_is_still_drawn() {
        let two47 = 140_737_488_355_328.0; // 2^47
        let m = 1e-12 * two47;
        let eps = 1.0 / two47;
        let sliver = TriMesh {
            positions: vec![[-29.5, 0.5, 0.0], [m - 29.5, 0.5, 0.0], [-29.5, 0.5 + eps, 0.0]],
            faces: vec![[0, 1, 2]],
        };
        let opts = RenderOptions {
            width: 80,
            height: 80,
            bounds: Some(([-36.0, -36.0, -1.0], [36.0, 36.0, 1.0])),
            ..Default::default()
        };
        let ink = inked(&render(&sliver, None, &opts).unwrap(), 80);
        assert!(!ink.is_empty(), "the sliver of area exactly 1e-12 was skipped");
        assert!(ink.iter().all(|&(_, y)| y == 39), "{ink:?}");
    }
}
