//! Data-driven mesh segmentation for region-based PCA (Tena et al. 2011, §4.2).
//!
//! Vertices that move together (high correlation of their training displacements) and lie close
//! on the surface are grouped by spectral clustering of the affinity
//! `A = λ·C̄ + (1−λ)·exp(−G/r)`:
//! - `C̄`: the normalised correlation of the displacement trajectories, computed per coordinate
//!   (x, y, z) over the training frames and averaged; values below `threshold` (0.7) are set to 0.
//!   A node with zero variance in a coordinate has correlation 0 with every other node there.
//! - `G`: shortest-path distances along mesh edges (Dijkstra, Euclidean edge lengths, the mesh's
//!   length units), `r` in the same units.
//! - Spectral clustering as Ng, Jordan & Weiss (2001): zero diagonal, `L = D^{-1/2} A D^{-1/2}`,
//!   the k leading eigenvectors (faer dense symmetric eigensolver), rows normalised to unit
//!   length, k-means (k-means++ seeding, `restarts` seeds, the run with the smallest
//!   within-cluster sum of squares kept).
//! - Automatic k: k = 2, 3, … until a cluster is *not compact*, keeping k − 1 (at most
//!   `max_regions`); or a fixed `regions` count. A cluster is compact when every one of its
//!   vertices belongs to a triangle whose three vertices are all in the cluster, and those
//!   triangles form one connected set (triangles sharing a vertex count as connected; on a mesh
//!   in several pieces, one set per piece the cluster touches). If already k = 2 is not compact
//!   (the paper's rule would make the whole mesh one region: holistic PCA), the search goes on
//!   up to `max_regions` and keeps the largest k whose clusters are all compact, as
//!   `keep_searching` does ([`Segmentation::searched_on`] says so); only when no k is compact
//!   is the mesh one region. Before the test, single-vertex
//!   spurs along cluster borders are handed to the neighbouring cluster (see `remove_spurs`).
//!
//! **Large meshes.** The affinity is dense (every pair may be correlated), so clustering runs on
//! at most `max_nodes` nodes: when the mesh has more vertices, `max_nodes` sites are chosen by
//! farthest-point sampling along mesh edges and every vertex joins its nearest site (a graph
//! Voronoi cell). A node's trajectory is the mean displacement of its cell; `G` between nodes is
//! the shortest path in the cell adjacency graph (edge length = through-edge distance
//! site→boundary edge→site). The paper itself clusters a 397-vertex subsample of an
//! 8 820-vertex template, so this is the same idea made automatic. The cost is O(N log N) for the
//! sampling plus O(M³) for the eigen-decomposition with M = min(N, `max_nodes`) (default 1 500).
//! The compactness test runs on the full mesh.
//!
//! **Shared boundaries.** After clustering, region m is grown by the one-ring of vertices of
//! higher-numbered regions adjacent to it: every vertex of region l that has a neighbour in
//! region m < l is shared with m. Boundary vertices are therefore one vertex layer wide, and
//! every triangle of the mesh lies entirely inside at least one grown region.

use faer::{Mat, Side};

use crate::math::DisjointSet;
use crate::mesh::{Topology, Vec3, dist};
use crate::rng::Rng;
use crate::{Error, Result};

/// Segmentation hyperparameters (validated by [`SegmentationConfig::validate`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentationConfig {
    /// λ ∈ [0, 1]: weight of the correlation term (paper: 0.7).
    pub lambda: f64,
    /// r > 0 in mesh length units: decay length of exp(−G/r). `None`: 0.1 × the bounding-box
    /// diagonal of the rest mesh (the paper's r = 10 mm on a face ≈ 150 mm across is ≈ 0.07).
    pub r: Option<f64>,
    /// Correlation threshold in [−1, 1] (paper: 0.7); C̄ values below it become 0.
    pub threshold: f64,
    /// Fixed number of regions (skips the automatic search). Must be ≥ 1.
    pub regions: Option<usize>,
    /// Largest k tried by the automatic search (≥ 2). Default 20.
    pub max_regions: usize,
    /// k-means restarts per k (≥ 1; paper: 20).
    pub restarts: usize,
    /// Maximal number of clustering nodes (≥ 2; see the module docs). Default 1 500.
    pub max_nodes: usize,
    /// Seed of the k-means initialisation (deterministic output).
    pub seed: u64,
    /// Automatic search: `false` (default, the paper) stops at the first k with a non-compact
    /// cluster and keeps k − 1; `true` tries every k up to `max_regions` and keeps the largest
    /// k whose clusters are all compact (useful when few frames make chance correlations split
    /// a cluster at some k but not at larger ones).
    pub keep_searching: bool,
    /// Fragment merging, in [0, 1): after k-means, every vertex-connected piece of a cluster
    /// other than its largest piece, smaller than `min_piece` × the cluster's size, is handed to
    /// the neighbouring cluster it shares most edges with. 0 (default, the paper) disables it.
    /// With few training frames, chance correlations scatter small islands of a cluster across
    /// the surface, which the compactness test then rejects (see `notes/posing.md`).
    pub min_piece: f64,
}

impl Default for SegmentationConfig {
    fn default() -> Self {
        SegmentationConfig {
            lambda: 0.7,
            r: None,
            threshold: 0.7,
            regions: None,
            max_regions: 20,
            restarts: 20,
            max_nodes: 1500,
            seed: 1,
            keep_searching: false,
            min_piece: 0.0,
        }
    }
}

impl SegmentationConfig {
    /// Checks every parameter, naming the bad key and value.
    pub fn validate(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.lambda) {
            return Err(Error::config("lambda", format!("lambda ({}) must lie in [0, 1]", self.lambda)));
        }
        if let Some(r) = self.r
            && !(r.is_finite() && r > 0.0)
        {
            return Err(Error::config("r", format!("r ({r}) must be positive and finite")));
        }
        if !(-1.0..=1.0).contains(&self.threshold) {
            return Err(Error::config("threshold", format!("threshold ({}) must lie in [-1, 1]", self.threshold)));
        }
        if self.regions == Some(0) {
            return Err(Error::config("regions", "regions (0) must be at least 1"));
        }
        if self.max_regions < 2 {
            return Err(Error::config("max_regions", format!("max_regions ({}) must be at least 2", self.max_regions)));
        }
        if self.restarts == 0 {
            return Err(Error::config("restarts", "restarts (0) must be at least 1"));
        }
        if !(0.0..1.0).contains(&self.min_piece) {
            return Err(Error::config("min_piece", format!("min_piece ({}) must lie in [0, 1)", self.min_piece)));
        }
        if self.max_nodes < 2 {
            return Err(Error::config("max_nodes", format!("max_nodes ({}) must be at least 2", self.max_nodes)));
        }
        Ok(())
    }
}

/// Result of [`segment`].
#[derive(Debug, Clone, PartialEq)]
pub struct Segmentation {
    /// Cluster of every vertex (N values in `0..n_regions`), before boundary sharing.
    pub labels: Vec<usize>,
    /// Grown regions: sorted vertex indices of each region, boundary vertices shared.
    pub regions: Vec<Vec<usize>>,
    /// Number of clustering nodes used (N, or `max_nodes` sites on large meshes).
    pub n_nodes: usize,
    /// The r actually used (mesh length units).
    pub r: f64,
    /// Whether the automatic search went past the paper's stopping rule because k = 2 was
    /// already not compact (see the module docs).
    pub searched_on: bool,
}

impl Segmentation {
    /// Number of regions M.
    pub fn n_regions(&self) -> usize {
        self.regions.len()
    }
}

/// Segments a mesh from training displacements.
///
/// `rest`: N positions; `faces`: triangles; `displacements`: F × N·3 row-major (frame f,
/// vertex v, coordinate c at `f·3N + 3v + c`; any per-frame vertex data works — correlations are
/// invariant to a constant offset). Errors on shape mismatches, non-finite data, or a bad config.
pub fn segment(
    rest: &[Vec3],
    faces: &[[usize; 3]],
    displacements: &[f64],
    n_frames: usize,
    config: &SegmentationConfig,
) -> Result<Segmentation> {
    config.validate()?;
    let n = rest.len();
    if n < 2 || faces.is_empty() {
        return Err(Error::Invalid(format!("segmentation: need a mesh ({n} vertices, {} faces)", faces.len())));
    }
    if let Some(f) = faces.iter().find(|f| f.iter().any(|&v| v >= n)) {
        return Err(Error::Invalid(format!("segmentation: face {f:?} indexes beyond {n} vertices")));
    }
    if n_frames == 0 || displacements.len() != n_frames * n * 3 {
        return Err(Error::Invalid(format!(
            "segmentation: {} displacement values for {n_frames} frames × {n} vertices × 3",
            displacements.len()
        )));
    }
    if let Some(i) = displacements.iter().position(|v| !v.is_finite()) {
        return Err(Error::Invalid(format!("segmentation: displacement value {i} is not finite")));
    }
    let r = match config.r {
        Some(r) => r,
        None => {
            let (lo, hi) = crate::mesh::bounding_box(rest);
            (0.1 * dist(lo, hi)).max(f64::MIN_POSITIVE)
        }
    };
    let topo = Topology::new(n, faces);

    // Clustering nodes and the cell of every vertex.
    let (owner, n_nodes) = if n <= config.max_nodes {
        ((0..n).collect::<Vec<_>>(), n)
    } else {
        voronoi_sites(rest, &topo, config.max_nodes)
    };
    let node_dist = node_distances(rest, &topo, &owner, n_nodes);

    // Node trajectories (cell means), per coordinate: F × M.
    let mut counts = vec![0usize; n_nodes];
    for &o in &owner {
        counts[o] += 1;
    }
    let mut corr = Mat::<f64>::zeros(n_nodes, n_nodes);
    for c in 0..3 {
        let mut z = Mat::<f64>::zeros(n_frames, n_nodes);
        for f in 0..n_frames {
            for v in 0..n {
                z[(f, owner[v])] += displacements[f * 3 * n + 3 * v + c];
            }
        }
        for j in 0..n_nodes {
            let mean = (0..n_frames).map(|f| z[(f, j)]).sum::<f64>() / n_frames as f64;
            let mut ss = 0.0;
            for f in 0..n_frames {
                z[(f, j)] -= mean;
                ss += z[(f, j)] * z[(f, j)];
            }
            let scale = if ss > 1e-30 * counts[j] as f64 { 1.0 / ss.sqrt() } else { 0.0 };
            for f in 0..n_frames {
                z[(f, j)] *= scale;
            }
        }
        faer::linalg::matmul::matmul(
            corr.as_mut(),
            faer::Accum::Add,
            z.transpose(),
            z.as_ref(),
            1.0 / 3.0,
            faer::Par::Seq,
        );
    }
    // Affinity with zero diagonal, normalised.
    let mut a = Mat::<f64>::zeros(n_nodes, n_nodes);
    for i in 0..n_nodes {
        for j in 0..n_nodes {
            if i != j {
                let c = if corr[(i, j)] >= config.threshold { corr[(i, j)] } else { 0.0 };
                a[(i, j)] = config.lambda * c + (1.0 - config.lambda) * (-node_dist[i * n_nodes + j] / r).exp();
            }
        }
    }
    let deg: Vec<f64> =
        (0..n_nodes).map(|i| (0..n_nodes).map(|j| a[(i, j)]).sum::<f64>().max(1e-300).sqrt().recip()).collect();
    for i in 0..n_nodes {
        for j in 0..n_nodes {
            a[(i, j)] *= deg[i] * deg[j];
        }
    }
    let k_max = match config.regions {
        Some(k) => k,
        None => config.max_regions,
    }
    .min(n_nodes);
    let eig = a.self_adjoint_eigen(Side::Lower).map_err(|e| {
        Error::Numerical(format!("segmentation: eigen-decomposition of the {n_nodes}×{n_nodes} affinity failed: {e:?}"))
    })?;
    let u = eig.U();
    // Leading eigenvectors are the last columns (ascending order).
    let leading = |k: usize| -> Vec<f64> {
        let mut y = vec![0.0; n_nodes * k];
        for i in 0..n_nodes {
            for c in 0..k {
                y[i * k + c] = u[(i, n_nodes - 1 - c)];
            }
            let len = y[i * k..(i + 1) * k].iter().map(|v| v * v).sum::<f64>().sqrt();
            if len > 0.0 {
                y[i * k..(i + 1) * k].iter_mut().for_each(|v| *v /= len);
            }
        }
        y
    };
    let cluster = |k: usize| -> Vec<usize> {
        if k == 1 {
            return vec![0; n];
        }
        let node_labels = kmeans(&leading(k), n_nodes, k, config.restarts, config.seed);
        let mut l: Vec<usize> = owner.iter().map(|&o| node_labels[o]).collect();
        remove_spurs(&mut l, faces, &topo);
        if config.min_piece > 0.0 {
            merge_fragments(&mut l, faces, &topo, config.min_piece);
            remove_spurs(&mut l, faces, &topo);
        }
        relabel(&l)
    };
    let mut searched_on = false;
    let labels = match config.regions {
        Some(_) => cluster(k_max),
        None => {
            let mut best: Option<Vec<usize>> = None;
            for k in 2..=k_max {
                let l = cluster(k);
                let m = l.iter().max().map_or(0, |&m| m + 1);
                if m == k && all_compact(&l, m, faces) {
                    best = Some(l);
                } else if !config.keep_searching && best.is_some() {
                    break;
                } else if !config.keep_searching {
                    // k = 2 is not compact: rather than one region, look further.
                    searched_on = true;
                }
            }
            best.unwrap_or_else(|| vec![0; n])
        }
    };
    let regions = share_boundaries(&labels, &topo);
    Ok(Segmentation { labels, regions, n_nodes, r, searched_on })
}

/// Reassigns *spur* vertices — vertices in no triangle whose three vertices share their label
/// — to the most frequent label among their neighbours (up to 5 passes). Such single-vertex
/// teeth appear along zig-zag cluster borders and would otherwise make every cluster count as
/// non-compact; a cluster that falls apart into separate pieces stays non-compact.
fn remove_spurs(labels: &mut [usize], faces: &[[usize; 3]], topo: &Topology) {
    for _ in 0..5 {
        let mut covered = vec![false; labels.len()];
        for f in faces {
            if labels[f[0]] == labels[f[1]] && labels[f[1]] == labels[f[2]] {
                for &v in f {
                    covered[v] = true;
                }
            }
        }
        let mut changed = false;
        for v in 0..labels.len() {
            if covered[v] || topo.neighbors(v).is_empty() {
                continue;
            }
            let mut counts: Vec<(usize, usize)> = Vec::new();
            for &u in topo.neighbors(v) {
                match counts.iter_mut().find(|c| c.0 == labels[u]) {
                    Some(c) => c.1 += 1,
                    None => counts.push((labels[u], 1)),
                }
            }
            let best = counts.iter().max_by_key(|c| (c.1, usize::MAX - c.0)).map_or(labels[v], |c| c.0);
            if best != labels[v] {
                labels[v] = best;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}

/// Hands every piece of a cluster that is not its largest piece and has fewer than
/// `min_piece` × the cluster's vertices to the neighbouring cluster sharing most edges with it
/// (up to 3 passes). Pieces are those of the compactness test: vertices joined through
/// triangles lying entirely in the cluster; a vertex in no such triangle is a piece of its own.
fn merge_fragments(labels: &mut [usize], faces: &[[usize; 3]], topo: &Topology, min_piece: f64) {
    use std::collections::HashMap;
    let n = labels.len();
    for _ in 0..3 {
        // Pieces are identified by their smallest vertex (the disjoint sets' root).
        let mut sets = DisjointSet::new(n);
        for f in faces {
            if labels[f[0]] == labels[f[1]] && labels[f[1]] == labels[f[2]] {
                sets.union(f[0], f[1]);
                sets.union(f[0], f[2]);
            }
        }
        let piece: Vec<usize> = sets.roots();
        let mut size: HashMap<usize, usize> = HashMap::new();
        let mut cluster_size: HashMap<usize, usize> = HashMap::new();
        for v in 0..n {
            *size.entry(piece[v]).or_default() += 1;
            *cluster_size.entry(labels[v]).or_default() += 1;
        }
        let mut largest: HashMap<usize, usize> = HashMap::new();
        for v in 0..n {
            let e = largest.entry(labels[v]).or_insert(piece[v]);
            if size[&piece[v]] > size[e] {
                *e = piece[v];
            }
        }
        let mut votes: HashMap<usize, Vec<(usize, usize)>> = HashMap::new();
        for v in 0..n {
            let (l, p) = (labels[v], piece[v]);
            if largest[&l] == p || size[&p] as f64 >= min_piece * cluster_size[&l] as f64 {
                continue;
            }
            let e = votes.entry(p).or_default();
            for &u in topo.neighbors(v) {
                if labels[u] != l {
                    match e.iter_mut().find(|c| c.0 == labels[u]) {
                        Some(c) => c.1 += 1,
                        None => e.push((labels[u], 1)),
                    }
                }
            }
        }
        let target: HashMap<usize, usize> = votes
            .into_iter()
            .filter_map(|(p, c)| c.into_iter().max_by_key(|c| (c.1, usize::MAX - c.0)).map(|c| (p, c.0)))
            .collect();
        if target.is_empty() {
            break;
        }
        for v in 0..n {
            if let Some(&t) = target.get(&piece[v]) {
                labels[v] = t;
            }
        }
    }
}

/// Renumbers labels 0.. in order of first appearance (drops empty clusters).
fn relabel(labels: &[usize]) -> Vec<usize> {
    let mut map = std::collections::HashMap::new();
    labels
        .iter()
        .map(|&l| {
            let next = map.len();
            *map.entry(l).or_insert(next)
        })
        .collect()
}

/// Farthest-point sampling of `m` sites along mesh edges; returns the owning site of every
/// vertex (nearest site, graph distance) and the number of sites.
fn voronoi_sites(rest: &[Vec3], topo: &Topology, m: usize) -> (Vec<usize>, usize) {
    let n = rest.len();
    let mut d = vec![f64::INFINITY; n];
    let mut owner = vec![0usize; n];
    let mut next = 0usize;
    let mut count = 0;
    let mut heap = std::collections::BinaryHeap::new();
    while count < m {
        // Incremental Dijkstra from the new site: only vertices that get closer are touched.
        d[next] = 0.0;
        owner[next] = count;
        heap.push(std::cmp::Reverse((0u64, next)));
        while let Some(std::cmp::Reverse((key, v))) = heap.pop() {
            let dv = f64::from_bits(key);
            if dv > d[v] {
                continue;
            }
            for &u in topo.neighbors(v) {
                let nd = dv + dist(rest[v], rest[u]);
                if nd < d[u] {
                    d[u] = nd;
                    owner[u] = count;
                    heap.push(std::cmp::Reverse((nd.to_bits(), u)));
                }
            }
        }
        count += 1;
        // Farthest vertex (a disconnected vertex, at +∞, is picked first).
        let (far, dmax) = d.iter().enumerate().fold((0, -1.0), |acc, (i, &x)| if x > acc.1 { (i, x) } else { acc });
        if dmax <= 0.0 {
            break;
        }
        next = far;
    }
    (owner, count)
}

/// Shortest-path distances (M × M, row-major) between clustering nodes: along mesh edges when
/// every vertex is a node; otherwise in the cell adjacency graph (see the module docs).
fn node_distances(rest: &[Vec3], topo: &Topology, owner: &[usize], m: usize) -> Vec<f64> {
    let n = rest.len();
    let mut out = vec![f64::INFINITY; m * m];
    if m == n {
        for s in 0..n {
            let d = crate::geometry::graph_distance::dijkstra(topo, rest, &[s]);
            out[s * n..(s + 1) * n].copy_from_slice(&d);
        }
        return out;
    }
    // Adjacent cells get an edge of length |site_a − a| + |a − b| + |b − site_b|, minimised over
    // the mesh edges (a, b) crossing between them.
    let mut site = vec![usize::MAX; m];
    // Site of a cell: its vertex nearest the cell centroid.
    let mut centroid = vec![[0.0; 3]; m];
    let mut cnt = vec![0.0f64; m];
    for v in 0..n {
        for c in 0..3 {
            centroid[owner[v]][c] += rest[v][c];
        }
        cnt[owner[v]] += 1.0;
    }
    for (ctr, &k) in centroid.iter_mut().zip(&cnt) {
        for x in ctr.iter_mut() {
            *x /= k.max(1.0);
        }
    }
    for v in 0..n {
        let c = owner[v];
        if site[c] == usize::MAX || dist(rest[v], centroid[c]) < dist(rest[site[c]], centroid[c]) {
            site[c] = v;
        }
    }
    let mut adj: std::collections::HashMap<(usize, usize), f64> = std::collections::HashMap::new();
    for &[a, b] in &topo.edges {
        let (ca, cb) = (owner[a], owner[b]);
        if ca != cb {
            let len = dist(rest[site[ca]], rest[a]) + dist(rest[a], rest[b]) + dist(rest[b], rest[site[cb]]);
            let key = (ca.min(cb), ca.max(cb));
            let e = adj.entry(key).or_insert(f64::INFINITY);
            *e = e.min(len);
        }
    }
    let edges: Vec<[usize; 2]> = adj.keys().map(|&(a, b)| [a, b]).collect();
    // Build a CSR graph over the sites with the computed lengths.
    let mut nbrs: Vec<Vec<(usize, f64)>> = vec![Vec::new(); m];
    for e in &edges {
        let l = adj[&(e[0], e[1])];
        nbrs[e[0]].push((e[1], l));
        nbrs[e[1]].push((e[0], l));
    }
    for s in 0..m {
        let d = &mut out[s * m..(s + 1) * m];
        let mut heap = std::collections::BinaryHeap::new();
        d[s] = 0.0;
        heap.push(std::cmp::Reverse((0u64, s)));
        while let Some(std::cmp::Reverse((key, v))) = heap.pop() {
            let dv = f64::from_bits(key);
            if dv > d[v] {
                continue;
            }
            for &(u, l) in &nbrs[v] {
                if dv + l < d[u] {
                    d[u] = dv + l;
                    heap.push(std::cmp::Reverse((d[u].to_bits(), u)));
                }
            }
        }
    }
    out
}

/// k-means of `n` points of dimension `dim` (row-major `y`), `restarts` k-means++ seedings,
/// Lloyd iterations until no label changes (≤ 300); returns the labels of the run with the
/// smallest within-cluster sum of squares.
fn kmeans(y: &[f64], n: usize, k: usize, restarts: usize, seed: u64) -> Vec<usize> {
    let dim = y.len() / n;
    let d2 = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, z)| (x - z) * (x - z)).sum::<f64>();
    let mut rng = Rng { state: seed };
    let mut best: Option<(f64, Vec<usize>)> = None;
    for _ in 0..restarts {
        // k-means++ seeding
        let mut centres: Vec<f64> = Vec::with_capacity(k * dim);
        let first = ((rng.uniform() * n as f64) as usize).min(n - 1);
        centres.extend_from_slice(&y[first * dim..(first + 1) * dim]);
        let mut dmin: Vec<f64> = (0..n).map(|i| d2(&y[i * dim..(i + 1) * dim], &centres[..dim])).collect();
        for _ in 1..k {
            let total: f64 = dmin.iter().sum();
            let mut pick = n - 1;
            if total > 0.0 {
                let mut t = rng.uniform() * total;
                for (i, &d) in dmin.iter().enumerate() {
                    t -= d;
                    if t <= 0.0 {
                        pick = i;
                        break;
                    }
                }
            } else {
                pick = ((rng.uniform() * n as f64) as usize).min(n - 1);
            }
            let c0 = centres.len();
            centres.extend_from_slice(&y[pick * dim..(pick + 1) * dim]);
            for i in 0..n {
                dmin[i] = dmin[i].min(d2(&y[i * dim..(i + 1) * dim], &centres[c0..c0 + dim]));
            }
        }
        let mut labels = vec![usize::MAX; n];
        let mut sse = 0.0;
        for _ in 0..300 {
            let mut changed = false;
            sse = 0.0;
            for i in 0..n {
                let p = &y[i * dim..(i + 1) * dim];
                let (bl, bd) = (0..k)
                    .map(|c| (c, d2(p, &centres[c * dim..(c + 1) * dim])))
                    .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
                sse += bd;
                if labels[i] != bl {
                    labels[i] = bl;
                    changed = true;
                }
            }
            if !changed {
                break;
            }
            let mut sums = vec![0.0; k * dim];
            let mut cnt = vec![0usize; k];
            for i in 0..n {
                cnt[labels[i]] += 1;
                for j in 0..dim {
                    sums[labels[i] * dim + j] += y[i * dim + j];
                }
            }
            for c in 0..k {
                if cnt[c] > 0 {
                    for j in 0..dim {
                        centres[c * dim + j] = sums[c * dim + j] / cnt[c] as f64;
                    }
                }
            }
        }
        if best.as_ref().is_none_or(|b| sse < b.0) {
            best = Some((sse, labels));
        }
    }
    best.map(|b| b.1).unwrap_or_else(|| vec![0; n])
}

/// True when every cluster `0..m` is compact (see the module docs).
pub fn all_compact(labels: &[usize], m: usize, faces: &[[usize; 3]]) -> bool {
    (0..m).all(|c| is_compact(labels, c, faces))
}

/// True when the vertices labelled `c` are all covered by triangles lying wholly inside the
/// cluster and those triangles form one vertex-connected set on each connected piece of the mesh
/// they touch. An empty cluster is not compact. (On a mesh in several pieces no surface path joins
/// two pieces, so a region may hold one patch on each: a head and the eye in it, two parts that
/// move together. With one set over the whole mesh, a mesh of 41 pieces had no compact 2-region
/// split and region PCA fell back to one region, issue 32.)
pub fn is_compact(labels: &[usize], c: usize, faces: &[[usize; 3]]) -> bool {
    let (mut inside, covered) = cluster_sets(labels, c, faces);
    let members: Vec<usize> = (0..labels.len()).filter(|&v| labels[v] == c).collect();
    if members.is_empty() || members.iter().any(|&v| !covered[v]) {
        return false;
    }
    let first = inside.find(members[0]);
    if members.iter().all(|&v| inside.find(v) == first) {
        return true;
    }
    // Several sets: each piece of the mesh may hold at most one of them.
    let mut mesh = DisjointSet::new(labels.len());
    for f in faces {
        mesh.union(f[0], f[1]);
        mesh.union(f[0], f[2]);
    }
    let mut set_of_piece = std::collections::HashMap::new();
    members.iter().all(|&v| {
        let set = inside.find(v);
        *set_of_piece.entry(mesh.find(v)).or_insert(set) == set
    })
}

/// The vertex-connected sets formed by the triangles lying wholly inside cluster `c` (a disjoint
/// set over all vertices) and which vertices such a triangle covers.
fn cluster_sets(labels: &[usize], c: usize, faces: &[[usize; 3]]) -> (DisjointSet, Vec<bool>) {
    let n = labels.len();
    let mut sets = DisjointSet::new(n);
    let mut covered = vec![false; n];
    for f in faces {
        if f.iter().all(|&v| labels[v] == c) {
            for &v in f {
                covered[v] = true;
            }
            sets.union(f[0], f[1]);
            sets.union(f[0], f[2]);
        }
    }
    (sets, covered)
}

/// The compactness test's view of cluster `c`: the vertex counts of the vertex-connected pieces
/// formed by the triangles lying wholly inside the cluster (largest first), and the number of
/// the cluster's vertices in no such triangle.
pub fn cluster_pieces(labels: &[usize], c: usize, faces: &[[usize; 3]]) -> (Vec<usize>, usize) {
    let (mut sets, covered) = cluster_sets(labels, c, faces);
    let mut sizes = std::collections::HashMap::new();
    let mut uncovered = 0;
    for v in 0..labels.len() {
        if labels[v] != c {
            continue;
        }
        if !covered[v] {
            uncovered += 1;
            continue;
        }
        *sizes.entry(sets.find(v)).or_insert(0usize) += 1;
    }
    let mut pieces: Vec<usize> = sizes.into_values().collect();
    pieces.sort_unstable_by(|a, b| b.cmp(a));
    (pieces, uncovered)
}

/// Grows every region by the adjacent vertices of higher-numbered regions (module docs).
fn share_boundaries(labels: &[usize], topo: &Topology) -> Vec<Vec<usize>> {
    let m = labels.iter().max().map_or(0, |&x| x + 1);
    let mut regions: Vec<Vec<usize>> = vec![Vec::new(); m];
    for (v, &l) in labels.iter().enumerate() {
        regions[l].push(v);
        let mut extra: Vec<usize> = topo.neighbors(v).iter().map(|&u| labels[u]).filter(|&lu| lu < l).collect();
        extra.sort_unstable();
        extra.dedup();
        for lu in extra {
            regions[lu].push(v);
        }
    }
    for r in &mut regions {
        r.sort_unstable();
        r.dedup();
    }
    regions
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic;

    fn bumps() -> (Vec<Vec3>, Vec<[usize; 3]>, Vec<f64>, usize) {
        let seq = synthetic::load("synthetic:bumps").unwrap();
        let rest = synthetic::tube_mesh();
        let n = rest.positions.len();
        let mut d = Vec::with_capacity(seq.frames.len() * n * 3);
        for fr in &seq.frames {
            for (p, q) in fr.iter().zip(&rest.positions) {
                d.extend_from_slice(&[p[0] - q[0], p[1] - q[1], p[2] - q[2]]);
            }
        }
        (rest.positions, seq.faces, d, seq.frames.len())
    }

    fn check_regions(seg: &Segmentation, faces: &[[usize; 3]], n: usize) {
        let m = seg.n_regions();
        assert!(all_compact(&seg.labels, m, faces), "clusters must be compact");
        let mut count = vec![0usize; n];
        for r in &seg.regions {
            for &v in r {
                count[v] += 1;
            }
        }
        assert!(count.iter().all(|&c| c >= 1), "every vertex covered");
        if m > 1 {
            assert!(count.iter().any(|&c| c >= 2), "regions share boundary vertices");
            // Each grown region overlaps some other region.
            for (i, r) in seg.regions.iter().enumerate() {
                let shares =
                    seg.regions.iter().enumerate().any(|(j, s)| j != i && r.iter().any(|v| s.binary_search(v).is_ok()));
                assert!(shares, "region {i} shares no vertex");
            }
        }
        // Every triangle lies inside at least one grown region.
        for f in faces {
            assert!(seg.regions.iter().any(|r| f.iter().all(|v| r.binary_search(v).is_ok())), "triangle {f:?} split");
        }
    }

    #[test]
    fn bumps_segmentation_is_compact_and_covers() {
        let (rest, faces, d, f) = bumps();
        let cfg = SegmentationConfig { max_regions: 8, restarts: 5, ..Default::default() };
        let seg = segment(&rest, &faces, &d, f, &cfg).unwrap();
        assert!(seg.n_regions() >= 2, "found {} regions", seg.n_regions());
        check_regions(&seg, &faces, rest.len());
    }

    #[test]
    fn fixed_regions_with_sampling_on_grid() {
        let g = crate::mesh::primitives::grid(20, 20, 1.0);
        let n = g.positions.len();
        // Two independent motions on the left and right halves.
        let frames = 12;
        let mut d = vec![0.0; frames * n * 3];
        for f in 0..frames {
            let (a, b) = ((f as f64 * 0.7).sin(), (f as f64 * 1.3).cos());
            for (v, p) in g.positions.iter().enumerate() {
                d[f * 3 * n + 3 * v + 2] = if p[0] < 0.5 * (g.positions[n - 1][0] + g.positions[0][0]) { a } else { b };
            }
        }
        let cfg = SegmentationConfig { regions: Some(2), max_nodes: 60, restarts: 4, ..Default::default() };
        let seg = segment(&g.positions, &g.faces, &d, frames, &cfg).unwrap();
        assert_eq!(seg.n_nodes, 60);
        assert_eq!(seg.n_regions(), 2);
        check_regions(&seg, &g.faces, n);
    }

    #[test]
    fn keep_searching_finds_at_least_as_many_compact_regions() {
        let (rest, faces, d, f) = bumps();
        let base = SegmentationConfig { max_regions: 6, restarts: 3, ..Default::default() };
        let first = segment(&rest, &faces, &d, f, &base).unwrap();
        let all = segment(&rest, &faces, &d, f, &SegmentationConfig { keep_searching: true, ..base }).unwrap();
        assert!(all.n_regions() >= first.n_regions(), "{} < {}", all.n_regions(), first.n_regions());
        check_regions(&all, &faces, rest.len());
    }

    #[test]
    fn config_errors_name_the_value() {
        let bad = SegmentationConfig { lambda: 1.5, ..Default::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("1.5"));
        let bad = SegmentationConfig { r: Some(-2.0), ..Default::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("-2"));
        let bad = SegmentationConfig { max_regions: 1, ..Default::default() };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn fragment_merging_removes_small_islands_only() {
        // 12 × 12-vertex grid: left half cluster 0, right half cluster 1, a 2 × 2-cell island of
        // cluster 0 inside the right half, and a large second piece of cluster 1 on the left.
        let g = crate::mesh::primitives::grid(11, 11, 1.0);
        let topo = Topology::new(g.n_vertices(), &g.faces);
        let at = |x: usize, y: usize| y * 12 + x;
        let mut labels: Vec<usize> = (0..144).map(|v| usize::from(v % 12 >= 6)).collect();
        for y in 4..7 {
            for x in 8..11 {
                labels[at(x, y)] = 0;
            }
        }
        assert!(!all_compact(&labels, 2, &g.faces));
        let mut merged = labels.clone();
        merge_fragments(&mut merged, &g.faces, &topo, 0.3);
        assert!(all_compact(&merged, 2, &g.faces), "island not merged");
        assert!((0..144).filter(|&v| labels[v] != merged[v]).all(|v| labels[v] == 0 && v % 12 >= 8));
        // A piece above the fraction stays (and the cluster stays non-compact).
        let mut big: Vec<usize> = (0..144).map(|v| usize::from(v % 12 >= 6)).collect();
        for y in 0..12 {
            for x in 9..12 {
                big[at(x, y)] = 0;
            }
        }
        let before = big.clone();
        merge_fragments(&mut big, &g.faces, &topo, 0.3);
        assert_eq!(big, before);
    }

    #[test]
    fn compactness_on_a_mesh_in_pieces_is_per_piece() {
        // Two separate triangles (two mesh pieces): one cluster over both is compact (one patch
        // on each piece); on a strip of two triangles sharing only vertex 2 plus a separate
        // triangle, a cluster with two patches on the strip's piece is not.
        let faces = [[0, 1, 2], [3, 4, 5]];
        assert!(is_compact(&[0; 6], 0, &faces));
        let faces = [[0, 1, 2], [2, 3, 4], [5, 6, 7], [8, 9, 10]];
        // Cluster 0: triangles 0 and 2 (on different pieces) — compact.
        let labels = [0, 0, 0, 1, 1, 0, 0, 0, 1, 1, 1];
        assert!(is_compact(&labels, 0, &faces));
        // Cluster 0: vertices 0, 1 and 3, 4 of the strip cannot be covered without vertex 2 —
        // uncovered, not compact; the separate triangle 3 does not make it compact.
        let labels = [0, 0, 1, 0, 0, 1, 1, 1, 0, 0, 0];
        assert!(!is_compact(&labels, 0, &faces));
        // Two patches on one piece: a strip of six triangles labelled 0 / 1 / 0 along it.
        let strip = [[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5], [4, 5, 6], [5, 6, 7]];
        let labels = [0, 0, 0, 1, 1, 0, 0, 0];
        assert!(!is_compact(&labels, 0, &strip));
        // The same two patches on two pieces (the middle triangles removed): compact.
        assert!(is_compact(&labels, 0, &[strip[0], strip[5]]));
    }

    #[test]
    fn compactness_detects_split_cluster() {
        // Two triangles sharing no vertex, same label: not compact.
        let faces = [[0, 1, 2], [3, 4, 5], [2, 3, 6]];
        let labels = [0, 0, 0, 0, 0, 0, 1];
        assert!(!is_compact(&labels, 0, &faces));
        let labels = [0, 0, 0, 0, 0, 0, 0];
        assert!(is_compact(&labels, 0, &faces));
    }
}
