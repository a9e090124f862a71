//! Partitions of rows into small clusters, for the ball search
//! ([`NnStrategy::Balls`](crate::NnStrategy::Balls)).

use faer::Par;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef};
use rayon::prelude::*;
use std::sync::Arc;

use crate::tree::split;

/// A partition of n rows into clusters of about `size` rows, to bound
/// groups of rows by balls ([`NnStrategy::Balls`](crate::NnStrategy::Balls)).
/// Computed once for a set of rows and reused for any linear image of
/// them (a functional map's `Φ_A Cᵀ` at every size of ZoomOut): the image
/// of a compact cluster stays compact, and the balls are measured again
/// in the searched rows, so any partition gives exact answers; a good
/// one prunes more.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Partition {
    labels: Vec<u32>,
}

/// Rows per block of the assignment step.
const BLOCK: usize = 256;
/// Clusters above which every Lloyd step compares each row with the
/// [`LOCAL_CANDIDATES`] clusters nearest its own instead of with all
/// (the full comparison costs n²d/size per step: minutes at 80k rows);
/// below, the first step compares with all, the later ones with
/// [`STEP_CANDIDATES`].
const LOCAL_FROM: usize = 512;
/// Clusters a row is compared with in a local Lloyd step (its own among
/// them).
const LOCAL_CANDIDATES: usize = 24;

crate::cpu::dispatched! {
    /// The first `j` minimising `c_norm[j] − 2 g[j]` (a row's squared
    /// distance to mean `j` less its own squared norm, from the dot
    /// products `g`), `None` when none is below infinity: eight running
    /// minima (lane `l` sees `j ≡ l mod 8` in order, keeping the first of
    /// equals), then the least of them, ties to the smaller index — the
    /// plain scan's answer, in SIMD lanes.
    pub(crate) fn nearest_mean(g: &[f32], c_norm: &[f64]) -> Option<u32> {
        let m = g.len().min(c_norm.len());
        let mut best = [f64::INFINITY; 8];
        let mut arg = [u32::MAX; 8];
        let (gc, cc) = (g[..m].chunks_exact(8), c_norm[..m].chunks_exact(8));
        let (gr, cr) = (gc.remainder(), cc.remainder());
        for (b, (gs, cs)) in gc.zip(cc).enumerate() {
            for l in 0..8 {
                let s = cs[l] - 2.0 * f64::from(gs[l]);
                let better = s < best[l];
                best[l] = if better { s } else { best[l] };
                arg[l] = if better { (b * 8 + l) as u32 } else { arg[l] };
            }
        }
        let base = m - gr.len();
        for (l, (&gj, &cj)) in gr.iter().zip(cr).enumerate() {
            let s = cj - 2.0 * f64::from(gj);
            if s < best[l] {
                (best[l], arg[l]) = (s, (base + l) as u32);
            }
        }
        let mut out = (f64::INFINITY, u32::MAX);
        for l in 0..8 {
            if best[l] < out.0 || (best[l] == out.0 && arg[l] < out.1) {
                out = (best[l], arg[l]);
            }
        }
        (out.1 != u32::MAX).then_some(out.1)
    }
}

/// Clusters a row is compared with in the Lloyd steps after the first
/// (with fewer than [`LOCAL_FROM`] clusters; the first compares with all):
/// those nearest its own cluster's mean after the first step, its own
/// among them. The first step moves the bisection's elongated cells the
/// most; after it a row's nearest mean is among those of its cluster's
/// neighbours (and the search is exact with any partition).
const STEP_CANDIDATES: usize = 16;

crate::cpu::dispatched! {
    /// A local Lloyd assignment: each row of `order[start..start + len]`
    /// for the `(start, len, a)` of `groups` (the rows of cluster `a`) to
    /// the nearest of the [`STEP_CANDIDATES`] clusters `near[a]` (the
    /// first minimising `c_norm[j] − 2 x·c_j`, ties to the smaller index),
    /// the products in f32 from the rows `rows32` and centres `c32` (`d`
    /// wide), the candidates' coordinates side by side in SIMD lanes.
    /// Returns the new label of each of those rows, in that order.
    fn local_assign(
        rows32: &[f32],
        c32: &[f32],
        d: usize,
        c_norm: &[f64],
        near: &[u32],
        order: &[usize],
        groups: &[(usize, usize, u32)],
    ) -> Vec<u32> {
        const L: usize = STEP_CANDIDATES;
        let mut out = Vec::new();
        // The candidates' means, transposed: coordinate i of candidate s
        // at i * L + s.
        let mut ct = vec![0.0f32; d * L];
        for &(start, len, a) in groups {
            let cands = &near[a as usize * L..(a as usize + 1) * L];
            for (s, &j) in cands.iter().enumerate() {
                for (i, &v) in c32[j as usize * d..(j as usize + 1) * d].iter().enumerate() {
                    ct[i * L + s] = v;
                }
            }
            for &r in &order[start..start + len] {
                let row = &rows32[r * d..(r + 1) * d];
                // Four sums (coordinates i mod 4), so that the adds do
                // not all wait for one another.
                let (mut a0, mut a1, mut a2, mut a3) = ([0.0f32; L], [0.0f32; L], [0.0f32; L], [0.0f32; L]);
                let (rq, cq) = (row.chunks_exact(4), ct.chunks_exact(4 * L));
                let (rr, cr) = (rq.remainder(), cq.remainder());
                for (x, c) in rq.zip(cq) {
                    let c: &[f32; 4 * L] = c.try_into().expect("4 L lanes");
                    for l in 0..L {
                        a0[l] += x[0] * c[l];
                        a1[l] += x[1] * c[L + l];
                        a2[l] += x[2] * c[2 * L + l];
                        a3[l] += x[3] * c[3 * L + l];
                    }
                }
                for (&x, c) in rr.iter().zip(cr.chunks_exact(L)) {
                    for l in 0..L {
                        a0[l] += x * c[l];
                    }
                }
                let mut best = (f64::INFINITY, a);
                for (s, &j) in cands.iter().enumerate() {
                    let dot = (a0[s] + a1[s]) + (a2[s] + a3[s]);
                    let v = c_norm[j as usize] - 2.0 * f64::from(dot);
                    if v < best.0 || (v == best.0 && j < best.1) {
                        best = (v, j);
                    }
                }
                out.push(best.1);
            }
        }
        out
    }
}

/// [`Partition::groups`] of the labels `labels`.
fn groups_of(labels: &[u32]) -> (Vec<usize>, Vec<(usize, usize)>) {
    let m = labels.iter().map(|&l| l as usize + 1).max().unwrap_or(0);
    let mut count = vec![0usize; m + 1];
    for &l in labels {
        count[l as usize + 1] += 1;
    }
    for j in 0..m {
        count[j + 1] += count[j];
    }
    let mut order = vec![0usize; labels.len()];
    let mut next = count.clone();
    for (i, &l) in labels.iter().enumerate() {
        order[next[l as usize]] = i;
        next[l as usize] += 1;
    }
    let ranges = (0..m)
        .filter(|&j| count[j + 1] > count[j])
        .map(|j| (count[j], count[j + 1] - count[j]))
        .collect();
    (order, ranges)
}

/// For each of the `m` centres (row-major, `d` wide, squared norms
/// `c_norm`), the `nb` nearest centres (itself first: distance 0), by
/// blocked GEMMs.
fn nearest_centres(centers: &[f64], c_norm: &[f64], d: usize, nb: usize) -> Vec<u32> {
    let m = c_norm.len();
    let cm = MatRef::from_row_major_slice(centers, m, d);
    let mut near = vec![0u32; m * nb];
    near.par_chunks_mut(BLOCK * nb)
        .enumerate()
        .for_each(|(b, out)| {
            let r0 = b * BLOCK;
            let rows = out.len() / nb;
            let mut g = Mat::<f64>::zeros(rows, m);
            matmul(
                g.as_mut(),
                Accum::Replace,
                cm.subrows(r0, rows),
                cm.transpose(),
                1.0,
                Par::Seq,
            );
            let mut cand: Vec<(f64, u32)> = Vec::with_capacity(m);
            for (i, o) in out.chunks_exact_mut(nb).enumerate() {
                cand.clear();
                for j in 0..m {
                    let s = if j == r0 + i {
                        f64::NEG_INFINITY
                    } else {
                        c_norm[j] - 2.0 * g[(i, j)]
                    };
                    cand.push((s, j as u32));
                }
                cand.select_nth_unstable_by(nb - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                for (o, c) in o.iter_mut().zip(&cand[..nb]) {
                    *o = c.1;
                }
            }
        });
    near
}

/// Rows per ball (about; k-means balls vary in size): the default size of
/// a [`Partition`] ([`PartitionParams::ball_size`]).
pub(crate) const BALL_SIZE: usize = 24;
/// Lloyd steps of the default [`Partition::kmeans`]
/// ([`PartitionParams::kmeans_steps`]).
pub(crate) const KMEANS_STEPS: usize = 5;

/// Rows up to which [`Partition::for_balls`] clusters (k-means with local
/// Lloyd steps above 512 clusters: ~n·24·d per step; above, the default
/// strategies).
pub(crate) const BALLS_MAX_ROWS: usize = 250_000;

/// Rows from which [`Partition::for_balls`] and its siblings cluster on
/// CPUs with matrix tiles too ([`tiles_available`](crate::tiles_available)):
/// the tiles rank every pair, so their cost grows with the square of the
/// rows, the ball search's far less. On FAUST's spectral embeddings the
/// tiles were faster at 5k rows for ZoomOut 50:150:5 and the balls from
/// 10k on (docs/tuning.md; the same maps).
pub(crate) const TILED_BALLS_FROM_ROWS: usize = 8192;

/// The ball search's clustering policy, as [`Partition::for_balls`] and
/// its siblings apply it: cluster sizes, Lloyd steps, and the row counts
/// over which clusters pay. [`Default`] is the policy they use (each value
/// measured, docs/tuning.md); [`Partition::kmeans`] takes the first two
/// explicitly.
///
/// ```
/// let p = fmaps_nearest::PartitionParams::default();
/// assert_eq!((p.ball_size, p.kmeans_steps), (24, 5));
/// assert!(p.tiled_from_rows < p.max_rows);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub struct PartitionParams {
    /// Rows per cluster, about (k-means clusters vary in size): 24.
    pub ball_size: usize,
    /// Lloyd steps after the principal-direction bisection: 5.
    pub kmeans_steps: usize,
    /// Rows up to which the default clusters are made (k-means with local
    /// Lloyd steps above 512 clusters: ~n·24·d per step; above, the other
    /// strategies): 250,000.
    pub max_rows: usize,
    /// Rows from which clusters are made on CPUs with matrix tiles too
    /// ([`tiles_available`](crate::tiles_available)): the tiles rank every
    /// pair, so their cost grows with the square of the rows, the ball
    /// search's far less: 8192.
    pub tiled_from_rows: usize,
}

impl Default for PartitionParams {
    fn default() -> Self {
        PartitionParams {
            ball_size: BALL_SIZE,
            kmeans_steps: KMEANS_STEPS,
            max_rows: BALLS_MAX_ROWS,
            tiled_from_rows: TILED_BALLS_FROM_ROWS,
        }
    }
}

/// Leading columns of `d` that [`Partition::for_balls`] clusters: half
/// of them, at least 64 (all of them up to 64).
pub(crate) fn cluster_columns(d: usize) -> usize {
    (d / 2).max(d.min(64))
}

impl PartitionParams {
    /// Rows per ball for one search of about `n` queries among `n` rows
    /// without guesses or with weak ones (an initial conversion, the first
    /// full-size search after iterations on samples): about `√(n/5)`, at
    /// least [`ball_size`](Self::ball_size). That balances a query's
    /// comparisons with the n / size centres against the rows of the ~5
    /// balls it opens (docs/tuning.md: on FAUST's 80k pair, 126 rows per
    /// ball make the initial point map and the final search of a sampled
    /// ZoomOut about twice as fast as 24, the same maps). Searches with the
    /// previous iteration's map as guesses open fewer balls and keep
    /// [`ball_size`](Self::ball_size) (larger balls were slower there).
    ///
    /// ```
    /// let p = fmaps_nearest::PartitionParams::default();
    /// assert_eq!(p.coarse_ball_size(80_000), 126);
    /// assert_eq!(p.coarse_ball_size(1000), p.ball_size);
    /// ```
    pub fn coarse_ball_size(&self, n: usize) -> usize {
        ((n as f64 / 5.0).sqrt().round() as usize).max(self.ball_size)
    }
}

/// What [`Partition::for_balls`] builds: the rows from which the ball
/// search pays for the caller, and how the clusters are made. Built with
/// [`BallsRequest::new`] and its modifiers.
///
/// ```
/// use fmaps_nearest::BallsRequest;
/// let r = BallsRequest::new(1024).kmeans_steps(2);
/// assert_eq!((r.min_rows, r.kmeans_steps, r.one_search), (1024, 2, false));
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct BallsRequest {
    /// Fewest rows for which the caller's searches gain from the balls
    /// (below, its other strategies are as fast).
    pub min_rows: usize,
    /// Lloyd steps of the k-means: fewer where the clusters serve few
    /// searches, so that their cost counts (ICP's ten searches at k = 50:
    /// two steps measured ~4% faster in all, five ~5% faster for
    /// ZoomOut's 21; any partition gives the same answers).
    pub kmeans_steps: usize,
    /// The clusters serve one search of about as many queries as rows
    /// without guesses (a single conversion): balls of
    /// [`PartitionParams::coarse_ball_size`] rows instead of
    /// [`PartitionParams::ball_size`].
    pub one_search: bool,
    /// Clusters the caller already has (one label per row, e.g. patches
    /// of neighbouring vertices), used instead of the k-means.
    pub labels: Option<Vec<u32>>,
    /// The caller's other choice is the matrix tiles where the CPU has
    /// them (the default), so [`PartitionParams::tiled_from_rows`] applies;
    /// `false` for a caller whose other choice is brute force without the
    /// tiles ([`NnStrategy::Brute`](crate::NnStrategy::Brute), e.g. Smooth
    /// Shells' searches among a few thousand samples).
    pub against_tiles: bool,
}

impl BallsRequest {
    /// The default clusters for a caller whose searches gain from the
    /// balls from `min_rows` rows on.
    pub fn new(min_rows: usize) -> BallsRequest {
        BallsRequest {
            min_rows,
            kmeans_steps: KMEANS_STEPS,
            one_search: false,
            labels: None,
            against_tiles: true,
        }
    }

    /// With `steps` Lloyd steps.
    pub fn kmeans_steps(mut self, steps: usize) -> BallsRequest {
        self.kmeans_steps = steps;
        self
    }

    /// For one search ([`one_search`](Self::one_search)).
    pub fn one_search(mut self) -> BallsRequest {
        self.one_search = true;
        self
    }

    /// With the caller's clusters ([`labels`](Self::labels)).
    pub fn labels(mut self, labels: Vec<u32>) -> BallsRequest {
        self.labels = Some(labels);
        self
    }

    /// Against brute force without the tiles
    /// ([`against_tiles`](Self::against_tiles) off).
    pub fn over_brute(mut self) -> BallsRequest {
        self.against_tiles = false;
        self
    }
}

impl Partition {
    /// The clusters for searching the rows `rows` (n x d) or any linear
    /// image of them with the ball search, when that is the fastest exact
    /// search: `request.min_rows..=` [`PartitionParams::max_rows`] rows (on
    /// CPUs with matrix tiles, [`tiles_available`](crate::tiles_available),
    /// and [`BallsRequest::against_tiles`], at least
    /// [`PartitionParams::tiled_from_rows`], below which the tiles are),
    /// d > 0, labels (if given) one per row, and `FMAPS_NO_BALLS` unset
    /// (`FMAPS_NO_BALLS=1`: `None`, to compare; the answers are the same).
    /// Without labels: [`Partition::kmeans`] of the leading half of the
    /// columns (at least 64): on a spectral embedding the smoothest
    /// eigenfunctions already decide which rows are neighbours, and the
    /// Lloyd steps cost half as much (FAUST 5k, ZoomOut 50:150:5, one
    /// thread: ~5% faster than clusters of all 150 columns, the same maps;
    /// neutral for 30:200:1, whose clusters serve 171 searches).
    ///
    /// ```
    /// use fmaps_nearest::{BallsRequest, Partition};
    /// let rows = faer::Mat::<f64>::from_fn(3000, 4, |i, j| ((i * (j + 1)) as f64).sin());
    /// if let Some(p) = Partition::for_balls(rows.as_ref(), BallsRequest::new(1024)) {
    ///     assert_eq!(p.len(), 3000);
    /// }
    /// let labels: Vec<u32> = (0..3000).map(|i| i / 20).collect();
    /// let p = Partition::for_balls(rows.as_ref(), BallsRequest::new(1024).labels(labels).over_brute());
    /// if std::env::var_os("FMAPS_NO_BALLS").is_none() {
    ///     assert_eq!(p.expect("3000 rows, from 1024").labels()[45], 2);
    /// }
    /// ```
    pub fn for_balls(rows: MatRef<'_, f64>, request: BallsRequest) -> Option<Arc<Partition>> {
        let tiles = request.against_tiles && crate::tiles_available();
        if !Partition::balls_pay_with(rows.nrows(), rows.ncols(), request.min_rows, tiles) {
            return None;
        }
        if let Some(labels) = request.labels {
            return (labels.len() == rows.nrows()).then(|| Partition::from_labels(labels));
        }
        let size = if request.one_search {
            PartitionParams::default().coarse_ball_size(rows.nrows())
        } else {
            BALL_SIZE
        };
        Some(Partition::kmeans(
            rows.subcols(0, cluster_columns(rows.ncols())),
            size,
            request.kmeans_steps,
        ))
    }

    /// The conditions of [`for_balls`](Self::for_balls), `tiles` saying
    /// whether [`PartitionParams::tiled_from_rows`] applies.
    fn balls_pay_with(n: usize, d: usize, min_rows: usize, tiles: bool) -> bool {
        let off = std::env::var_os("FMAPS_NO_BALLS").is_some_and(|v| !v.is_empty() && v != "0");
        let min_rows = if tiles {
            min_rows.max(TILED_BALLS_FROM_ROWS)
        } else {
            min_rows
        };
        !(off || d == 0 || !(min_rows..=BALLS_MAX_ROWS).contains(&n))
    }

    /// k-means clusters of the rows of `rows` (n x d), about `size` rows
    /// each: the principal-direction bisection of the rows into clusters of
    /// at most `size`, then `steps` Lloyd steps (each row to its nearest
    /// cluster mean: in the first step among all of them, by one f32 GEMM
    /// per block of rows; in the later ones among the means nearest its
    /// own cluster's, sixteen of them). Bisection alone
    /// gives elongated clusters; a few Lloyd steps make them round, which
    /// is what bounding balls need (on FAUST's spectral embeddings, five
    /// steps cut the rows a query visits 3-6x).
    pub fn kmeans(rows: faer::MatRef<'_, f64>, size: usize, steps: usize) -> Arc<Partition> {
        let d = rows.ncols();
        if d == 0 || rows.nrows() == 0 {
            return Arc::new(Partition {
                labels: vec![0; rows.nrows()],
            });
        }
        let r = crate::rows::rows_of(rows);
        Arc::new(Partition::of_rows(&r, d, size.max(1), steps))
    }

    /// A partition given by the cluster of each row (any labels: empty
    /// clusters are skipped; the search is exact with any partition, and
    /// fast with compact clusters of ~[`PartitionParams::ball_size`] rows, e.g. patches of
    /// neighbouring vertices).
    pub fn from_labels(labels: Vec<u32>) -> Arc<Partition> {
        Arc::new(Partition { labels })
    }

    /// The cluster of each row.
    pub fn labels(&self) -> &[u32] {
        &self.labels
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.labels.len()
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    pub(crate) fn of_rows(rows: &[f64], d: usize, size: usize, steps: usize) -> Partition {
        let n = rows.len() / d;
        let mut order: Vec<usize> = (0..n).collect();
        let ranges = split(rows, d, &mut order, 0, size);
        let mut labels = vec![0u32; n];
        for (c, &(start, len)) in ranges.iter().enumerate() {
            for &i in &order[start..start + len] {
                labels[i] = c as u32;
            }
        }
        let m = ranges.len();
        let mut near: Vec<u32> = Vec::new();
        let mut rows32: Vec<f32> = Vec::new();
        for step in 0..steps {
            let mut centers = vec![0.0; m * d];
            let mut count = vec![0usize; m];
            for (row, &l) in rows.chunks_exact(d).zip(&labels) {
                let c = &mut centers[l as usize * d..(l as usize + 1) * d];
                c.iter_mut().zip(row).for_each(|(c, x)| *c += x);
                count[l as usize] += 1;
            }
            // Empty clusters get a mean far from everything (never chosen).
            for (c, &k) in centers.chunks_exact_mut(d).zip(&count) {
                if k == 0 {
                    c.iter_mut().for_each(|v| *v = f64::MAX.sqrt());
                } else {
                    c.iter_mut().for_each(|v| *v /= k as f64);
                }
            }
            let c_norm: Vec<f64> = centers
                .chunks_exact(d)
                .map(|c| c.iter().map(|v| v * v).sum())
                .collect();
            if m > LOCAL_FROM {
                // Many clusters: each row considers only the clusters
                // nearest its own (found once, from the first centres).
                if near.is_empty() {
                    near = nearest_centres(&centers, &c_norm, d, LOCAL_CANDIDATES.min(m));
                }
                let nb = near.len() / m;
                labels
                    .par_chunks_mut(BLOCK)
                    .enumerate()
                    .for_each(|(b, out)| {
                        for (t, o) in out.iter_mut().enumerate() {
                            let row = &rows[(b * BLOCK + t) * d..(b * BLOCK + t + 1) * d];
                            let mut best = (f64::INFINITY, *o);
                            for &j in &near[*o as usize * nb..(*o as usize + 1) * nb] {
                                let c = &centers[j as usize * d..(j as usize + 1) * d];
                                let dot: f64 = row.iter().zip(c).map(|(x, c)| x * c).sum();
                                let s = c_norm[j as usize] - 2.0 * dot;
                                if s < best.0 || (s == best.0 && j < best.1) {
                                    best = (s, j);
                                }
                            }
                            *o = best.1;
                        }
                    });
                continue;
            }
            // The products in f32 (twice the SIMD width of f64): an
            // assignment can only change between near-equidistant means,
            // and any partition gives exact searches.
            if rows32.is_empty() {
                rows32 = rows.iter().map(|&v| v as f32).collect();
            }
            let c32: Vec<f32> = centers.iter().map(|&v| v as f32).collect();
            if step > 0 && m > 2 * STEP_CANDIDATES {
                // After the first step: each row against the clusters
                // nearest its own (found once, from the first step's
                // means), the rows cluster by cluster.
                if near.is_empty() {
                    near = nearest_centres(&centers, &c_norm, d, STEP_CANDIDATES);
                }
                let (order, ranges) = groups_of(&labels);
                let groups: Vec<(usize, usize, u32)> = ranges
                    .iter()
                    .map(|&(start, len)| (start, len, labels[order[start]]))
                    .collect();
                let (rows32, c32, c_norm, near, order) = (&rows32, &c32, &c_norm, &near, &order);
                let parts: Vec<Vec<u32>> = groups
                    .par_chunks(16)
                    .map(|g| local_assign(rows32, c32, d, c_norm, near, order, g))
                    .collect();
                for (&i, l) in order.iter().zip(parts.into_iter().flatten()) {
                    labels[i] = l;
                }
                continue;
            }
            let cm = MatRef::from_row_major_slice(&c32, m, d);
            let rows32 = &rows32;
            labels
                .par_chunks_mut(BLOCK)
                .enumerate()
                .for_each(|(b, out)| {
                    let r0 = b * BLOCK;
                    let xb = MatRef::from_row_major_slice(
                        &rows32[r0 * d..(r0 + out.len()) * d],
                        out.len(),
                        d,
                    );
                    let mut g = Mat::<f32>::zeros(m, out.len());
                    matmul(
                        g.as_mut(),
                        Accum::Replace,
                        cm,
                        xb.transpose(),
                        1.0,
                        Par::Seq,
                    );
                    for (i, o) in out.iter_mut().enumerate() {
                        if let Some(j) = nearest_mean(g.col_as_slice(i), &c_norm) {
                            *o = j;
                        }
                    }
                });
        }
        Partition { labels }
    }

    /// Row indices grouped by cluster (clusters in label order, rows
    /// ascending within each; empty clusters left out) and each
    /// non-empty cluster's (start, len).
    pub(crate) fn groups(&self) -> (Vec<usize>, Vec<(usize, usize)>) {
        groups_of(&self.labels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Half of the columns, at least 64 (all of them up to 64).
    #[test]
    fn clusters_see_half_the_columns_at_least_64() {
        assert_eq!(
            [10, 64, 100, 150, 200].map(cluster_columns),
            [10, 64, 64, 75, 100]
        );
    }

    /// The k-means objective: squared distances of the rows to their
    /// clusters' means.
    fn objective(rows: &[f64], d: usize, labels: &[u32]) -> f64 {
        let m = labels.iter().map(|&l| l as usize + 1).max().unwrap_or(0);
        let mut sums = vec![0.0; m * d];
        let mut count = vec![0.0; m];
        for (row, &l) in rows.chunks_exact(d).zip(labels) {
            let l = l as usize;
            sums[l * d..(l + 1) * d]
                .iter_mut()
                .zip(row)
                .for_each(|(s, x)| *s += x);
            count[l] += 1.0;
        }
        rows.chunks_exact(d)
            .zip(labels)
            .map(|(row, &l)| {
                let l = l as usize;
                row.iter()
                    .zip(&sums[l * d..(l + 1) * d])
                    .map(|(x, s)| (x - s / count[l]).powi(2))
                    .sum::<f64>()
            })
            .sum()
    }

    /// The lane-wise argmin of a Lloyd step is the plain scan's: the
    /// first least score, at every length (8-lane chunks and a tail),
    /// with ties across lanes and chunks, and no answer when every score
    /// is infinite; at every SIMD level this CPU has.
    #[test]
    fn nearest_mean_is_the_first_least_score() {
        let plain = |g: &[f32], c: &[f64]| {
            let mut best = (f64::INFINITY, None);
            for (j, (&gj, &cj)) in g.iter().zip(c).enumerate() {
                let s = cj - 2.0 * f64::from(gj);
                if s < best.0 {
                    best = (s, Some(j as u32));
                }
            }
            best.1
        };
        let mut state = 7u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) % 5
        };
        for level in crate::SimdLevel::ALL {
            crate::set_simd_cap(Some(level));
            for m in [0usize, 1, 7, 8, 9, 17, 40] {
                for _ in 0..50 {
                    // Few distinct values: many ties.
                    let g: Vec<f32> = (0..m).map(|_| next() as f32).collect();
                    let c: Vec<f64> = (0..m).map(|_| next() as f64).collect();
                    assert_eq!(nearest_mean(&g, &c), plain(&g, &c), "m = {m}, {level:?}");
                }
            }
            let inf = vec![f64::INFINITY; 11];
            assert_eq!(nearest_mean(&[0.0; 11], &inf), None);
        }
        crate::set_simd_cap(None);
    }

    /// A local assignment takes, for every row, the first least score
    /// `c_norm[j] − 2 x·c_j` among its cluster's candidates (the products
    /// summed in f64 here, so equal up to the f32 sums' rounding, far
    /// below the gaps of these scores), in the order of the groups' rows;
    /// at every SIMD level this CPU has, with the same labels at each.
    #[test]
    fn local_assign_takes_the_nearest_candidate() {
        const L: usize = STEP_CANDIDATES;
        let (m, d, n) = (40, 13, 300);
        let val = |t: usize| (((t * 2654435761) % 1000) as f32 / 250.0) - 2.0;
        let rows32: Vec<f32> = (0..n * d).map(val).collect();
        let c32: Vec<f32> = (0..m * d).map(|t| val(t + 7919)).collect();
        let c_norm: Vec<f64> = c32
            .chunks_exact(d)
            .map(|c| c.iter().map(|&v| f64::from(v) * f64::from(v)).sum())
            .collect();
        // Candidates of cluster a: a itself, then every other in turn.
        let near: Vec<u32> = (0..m)
            .flat_map(|a| (0..L).map(move |s| ((a + 3 * s) % m) as u32))
            .collect();
        // Rows in an arbitrary order, in three groups of clusters.
        let order: Vec<usize> = (0..n).map(|t| (t * 7) % n).collect();
        let groups = [(0, 100, 5u32), (100, 150, 0), (250, 50, 39)];
        let mut first = None;
        for level in crate::SimdLevel::ALL {
            crate::set_simd_cap(Some(level));
            let got = local_assign(&rows32, &c32, d, &c_norm, &near, &order, &groups);
            assert_eq!(got.len(), n);
            let mut at = 0;
            for &(start, len, a) in &groups {
                let cands = &near[a as usize * L..(a as usize + 1) * L];
                for &r in &order[start..start + len] {
                    let x = &rows32[r * d..(r + 1) * d];
                    let score = |j: u32| {
                        let c = &c32[j as usize * d..(j as usize + 1) * d];
                        let dot: f64 = x
                            .iter()
                            .zip(c)
                            .map(|(&p, &q)| f64::from(p) * f64::from(q))
                            .sum();
                        c_norm[j as usize] - 2.0 * dot
                    };
                    let best = cands
                        .iter()
                        .map(|&j| score(j))
                        .fold(f64::INFINITY, f64::min);
                    assert!(cands.contains(&got[at]), "{level:?}: row {r}");
                    assert!(score(got[at]) <= best + 1e-4, "{level:?}: row {r}");
                    at += 1;
                }
            }
            assert_eq!(*first.get_or_insert_with(|| got.clone()), got, "{level:?}");
        }
        crate::set_simd_cap(None);
    }

    /// Lloyd steps, over all clusters (few clusters: the first step, the
    /// later ones over each row's [`STEP_CANDIDATES`]) or over each row's
    /// nearest ones (more than [`LOCAL_FROM`]), never raise the objective
    /// of the bisection they start from, and lower it on rows near a
    /// curved sheet; every row is labelled.
    #[test]
    fn lloyd_steps_lower_the_objective() {
        let (n, d) = (1800, 12);
        let rows: Vec<f64> = (0..n * d)
            .map(|t| {
                let (i, j) = (t / d, t % d);
                let (u, v) = ((i % 45) as f64 / 45.0, (i / 45) as f64 / 40.0);
                let f = 1.0 + j as f64;
                (f * u * 2.9 + j as f64).sin() * (f * v * 1.7).cos()
            })
            .collect();
        // size 24: ~75 clusters (all compared); size 3: ~600 (local).
        for size in [24, 3] {
            let start = Partition::of_rows(&rows, d, size, 0);
            let after = Partition::of_rows(&rows, d, size, 3);
            let m = start.labels.iter().max().unwrap() + 1;
            assert_eq!(
                (size == 3),
                m as usize > LOCAL_FROM,
                "size {size}: {m} clusters"
            );
            assert_eq!(after.labels.len(), n);
            assert!(after.labels.iter().all(|&l| l < m));
            let (o0, o1) = (
                objective(&rows, d, &start.labels),
                objective(&rows, d, &after.labels),
            );
            assert!(o1 < o0, "size {size}: {o1} >= {o0}");
        }
    }
}
