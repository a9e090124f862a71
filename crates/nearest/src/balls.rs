//! The ball search ([`NnStrategy::Balls`](crate::NnStrategy::Balls)).
//!
//! The data rows are split into small clusters (a [`Partition`]: k-means,
//! ~[`PartitionParams::ball_size`] rows each), each bounded twice: by a ball (its mean `c`
//! and the largest distance `r` from the mean to its rows), and by a
//! *tangent box*: [`TANGENT`] orthonormal directions `U` spanning most of
//! the rows' spread (greedy pivoted Gram–Schmidt), the box of the rows'
//! coordinates `U(x − c)` along them and the largest distance `r⊥` of a row
//! from that affine subspace. For a query `q`, with `v = q − c`,
//! `|q − x|² ≥ dist(Uv, box)² + (|P⊥v| − r⊥)₊²` for every row `x` of the
//! cluster, and each row has the same bound with its own coordinates
//! instead of the box.
//!
//! Why: the rows searched are spectral embeddings of a surface, a
//! 2-dimensional sheet curved through k = 50-200 dimensions, and the
//! queries (the other shape's embedding) sit off that sheet by about the
//! spacing of its rows. A ball of ~24 neighbouring rows is as wide as that
//! offset, so balls alone leave 15-30 clusters per query (7-10% of the
//! rows); the tangent box sees that the offset is across the sheet, not
//! along it, and leaves ~6 clusters and ~3 rows per query (FAUST 5k,
//! k = 100, the previous ZoomOut iteration's map as guesses).
//!
//! A search: the queries sorted by their guesses' clusters and cut into
//! blocks; per ~512 queries one f32 GEMM against the centres gives every
//! (query, cluster) ball bound, with the guess's exact distance as upper
//! bound (a search without guesses first takes for each query the nearest
//! row of the ball whose centre is nearest; a query whose guess is out of
//! range: the nearest cluster's farthest possible row);
//! the queries' f32 products with the directions of the clusters that pass
//! give the tangent bounds (with AVX-512 only each query's own passing
//! clusters', ball by ball; elsewhere one GEMM per block against every
//! cluster that passes for some query); each query visits its
//! surviving clusters nearest bound first, skips rows by their own bound,
//! and measures the rest exactly in f64.
//!
//! Exactness: every bound is a rigorous lower bound on the exact
//! distance, computed from quantities moved the safe way by a relative
//! slack far above their f64 rounding (`(d + 2)·2⁻⁵³` relative to the
//! norms involved; the directions' departure from orthonormality `η` is
//! measured and folded in) and, for the GEMMs' f32 products, by their
//! rounding bound (`(d + 2)·2⁻²⁴` relative, plus f32 underflow: the
//! brute-force search's `score_err`; the rows are rescaled by a power of
//! two into f32's range first), and a cluster or row is skipped only when its
//! bound is *strictly* above the best distance so far, so the answer is
//! the same f64 argmin (ties: the smallest index) as every strategy.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatRef, Par};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::brute::{scale_for, score_err};
use crate::partition::{BALL_SIZE, KMEANS_STEPS};
pub use crate::partition::{Partition, PartitionParams};
use crate::rows::{Rows, dist2, dist2_below, dot8 as dot};

/// Queries per block (one GEMM against the centres each).
const QUERY_BLOCK: usize = 64;
/// Fewest queries per block where the next query's guess lies in another
/// ball.
const MIN_BLOCK: usize = 8;
/// Queries per GEMM against the centres (about: whole blocks).
const SUPER_BLOCK: usize = 512;

/// The ball search's data side: prepared once, searched by any number of
/// query sets.
pub(crate) struct BallData {
    d: usize,
    /// Data rows in ball order, row-major.
    x_ord: Vec<f64>,
    /// Original index of each row in ball order.
    order: Vec<usize>,
    /// Position in ball order of each row (original order).
    pos_of: Vec<u32>,
    /// (start, len) of each ball in ball order.
    ranges: Vec<(usize, usize)>,
    /// The squared norms of the ball centres (means) and their square
    /// roots.
    c_norm: Vec<f64>,
    c_len: Vec<f64>,
    /// The ball of each row (original order).
    ball_of: Vec<u32>,
    /// Each ball's centre, radius and tangent box, each row's distance to
    /// its centre and coordinates.
    geo: Geometry,
    /// The ball centres (row-major, m x d), and per ball [`TANGENT`]
    /// orthonormal directions (row-major, `TANGENT x d`; unused ones zero)
    /// spanning most of its rows' spread, in f32: the GEMMs' operands,
    /// whose products carry the error bound [`score_err`]; each centre's
    /// share of that bound (additive in the two norms: a query's share and
    /// a centre's are summed, the constant part then counted twice).
    centers32: Vec<f32>,
    tangent32: Vec<f32>,
    c_err: Vec<f64>,
}

/// Directions per ball of the tangent bound: the rows of a small ball of
/// a surface's spectral embedding lie close to a 2-dimensional patch,
/// bent by curvature into a few more (three pay best; docs/tuning.md).
pub(crate) const TANGENT: usize = 3;

/// Room past the end of the lists the AVX-512 kernels write: they store
/// whole vectors of compressed indices (a compress into a register and a
/// plain store, not the compressing store to memory: `plain_pass_avx512`),
/// at most sixteen entries past the last one kept.
const PAD: usize = 16;

/// Query `t` of the search order: row `map[t]` of `rows` (row `t` without
/// a map).
#[inline(always)]
fn query_row<'a>(rows: &'a Rows<'_>, map: Option<&[usize]>, t: usize) -> &'a [f64] {
    rows.row(match map {
        Some(o) => o[t],
        None => t,
    })
}

/// `max(a, b)` for numbers that are not NaN (a compare and a select,
/// which vectorize, where `f64::max` also handles NaN).
#[inline(always)]
fn max_finite(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// Relative slack of every bound: well above the f64 rounding of a
/// d-term dot product or squared distance (`(d + 2) 2⁻⁵³` relative to the
/// norms involved).
fn slack(d: usize) -> f64 {
    1e-12 + 4.0 * (d as f64 + 2.0) * f64::EPSILON
}

impl BallData {
    /// The balls of `data`'s rows: the clusters of `partition` when it
    /// labels every row (e.g. a k-means partition of the rows before a
    /// linear map: ZoomOut's `Φ_A Cᵀ`), else a k-means partition of the
    /// data itself.
    pub(crate) fn new(data: &DMatrix<f64>, partition: Option<&Partition>) -> BallData {
        BallData::from_rows(&Rows::of(crate::view(data)), partition, None)
    }

    /// [`BallData::new`] of the rows `data`, each multiplied by `scale`
    /// when given (a power of two, exact: see `power_of_two_scale`).
    pub(crate) fn from_rows(
        data: &Rows<'_>,
        partition: Option<&Partition>,
        scale: Option<f64>,
    ) -> BallData {
        let (nx, d) = data.shape();
        let own;
        let partition = match partition.filter(|p| p.len() == nx) {
            Some(p) => p,
            None => {
                own = Partition::of_rows(&data.gather(None, scale), d, BALL_SIZE, KMEANS_STEPS);
                &own
            }
        };
        let (order, ranges) = partition.groups();
        let x_ord = data.gather(Some(&order), scale);
        BallData::assemble(d, x_ord, order, ranges)
    }

    /// [`BallData::from_rows`] of the clusters of `partition` (which labels
    /// every row), checked and scaled on the way: `None` when a coordinate
    /// is not finite; else the balls and the scale of the data with
    /// queries of largest magnitude `q_max` (`scale_for`). The rows are
    /// read once (the copy in the clusters' order is also the scan).
    pub(crate) fn from_rows_checked(
        data: &Rows<'_>,
        partition: &Partition,
        q_max: f64,
    ) -> Option<(BallData, Option<f64>)> {
        let d = data.shape().1;
        let (order, ranges) = partition.groups();
        let (mut x_ord, x_max) = data.gather_max_abs(&order);
        let scale = scale_for(x_max?.max(q_max));
        if let Some(s) = scale {
            // (A power of two: the same values as scaling on the copy.)
            for v in &mut x_ord {
                *v *= s;
            }
        }
        Some((BallData::assemble(d, x_ord, order, ranges), scale))
    }

    /// The balls of `x_ord` (`d` columns), the data rows in the clusters'
    /// order `order`, cluster `b` at `ranges[b]` (start, length).
    pub(crate) fn assemble(
        d: usize,
        x_ord: Vec<f64>,
        order: Vec<usize>,
        ranges: Vec<(usize, usize)>,
    ) -> BallData {
        let nx = order.len();
        let mut pos_of = vec![0u32; nx];
        for (p, &i) in order.iter().enumerate() {
            pos_of[i] = p as u32;
        }
        let geo = geometry(&x_ord, d, &ranges);
        let mut ball_of = vec![0u32; nx];
        for (b, &(start, len)) in ranges.iter().enumerate() {
            for &i in &order[start..start + len] {
                ball_of[i] = b as u32;
            }
        }
        let c_norm: Vec<f64> = geo
            .centers
            .chunks_exact(d)
            .map(|c| c.iter().map(|v| v * v).sum())
            .collect();
        let c_err = c_norm.iter().map(|&cn| score_err(d, 0.0, cn)).collect();
        let c_len = c_norm.iter().map(|&cn| cn.sqrt()).collect();
        let centers32 = geo.centers.iter().map(|&v| v as f32).collect();
        let tangent32 = geo.tangent.iter().map(|&v| v as f32).collect();
        BallData {
            d,
            x_ord,
            order,
            pos_of,
            ranges,
            c_norm,
            c_len,
            ball_of,
            geo,
            centers32,
            tangent32,
            c_err,
        }
    }

    /// The data rows in ball order (row-major), taken back (e.g. as a
    /// buffer for the next image to search).
    pub(crate) fn into_rows(self) -> Vec<f64> {
        self.x_ord
    }

    /// The nearest data row of every query (same width as the data);
    /// `hint`: one guess per query (out-of-range entries: no guess).
    pub(crate) fn search(&self, queries: &DMatrix<f64>, hint: Option<&[usize]>) -> Vec<usize> {
        self.search_rows(&Rows::of(crate::view(queries)), hint, None)
    }

    /// A guess for every query: the nearest row (in f64, of the query
    /// multiplied by `scale`) among the rows of the ball whose centre
    /// scores nearest in f32 (one GEMM against the centres per
    /// [`SUPER_BLOCK`] queries). Any row is a valid guess: the search only
    /// takes its exact distance as the first upper bound.
    fn seed_guesses(&self, queries: &Rows<'_>, scale: Option<f64>) -> Vec<usize> {
        let (nq, d, m) = (queries.shape().0, self.d, self.ranges.len());
        let centers = MatRef::from_row_major_slice(&self.centers32, m, d);
        let chunks: Vec<usize> = (0..nq).step_by(SUPER_BLOCK).collect();
        let seeds: Vec<Vec<usize>> = chunks
            .par_iter()
            .map(|&q0| {
                let len = SUPER_BLOCK.min(nq - q0);
                let chunk: Vec<usize> = (q0..q0 + len).collect();
                let q64 = queries.gather(Some(&chunk), scale);
                let q32: Vec<f32> = q64.iter().map(|&v| v as f32).collect();
                let mut g = vec![0.0f32; m * len];
                matmul(
                    faer::MatMut::from_column_major_slice_mut(&mut g, m, len),
                    Accum::Replace,
                    centers,
                    MatRef::from_row_major_slice(&q32, len, d).transpose(),
                    1.0,
                    Par::Seq,
                );
                (0..len)
                    .map(|t| {
                        let j =
                            crate::partition::nearest_mean(&g[t * m..(t + 1) * m], &self.c_norm)
                                .map_or(0, |j| j as usize);
                        let (start, l) = self.ranges[j];
                        let q = &q64[t * d..(t + 1) * d];
                        let mut best = (f64::INFINITY, start);
                        for p in start..start + l {
                            let dp = dist2(&self.x_ord[p * d..(p + 1) * d], q);
                            if dp < best.0 {
                                best = (dp, p);
                            }
                        }
                        self.order[best.1]
                    })
                    .collect()
            })
            .collect();
        seeds.into_iter().flatten().collect()
    }

    /// [`BallData::search`] of the rows `queries`, each multiplied by
    /// `scale` when given (the data's scale).
    pub(crate) fn search_rows(
        &self,
        queries: &Rows<'_>,
        hint: Option<&[usize]>,
        scale: Option<f64>,
    ) -> Vec<usize> {
        let nq = queries.shape().0;
        if hint.is_none() && nq > 0 {
            // No guesses: seed each query with the nearest row of the
            // ball whose centre is nearest, an upper bound as tight as a
            // guess (the answer is the same exact argmin with any guess).
            let seeds = self.seed_guesses(queries, scale);
            return self.search_rows(queries, Some(&seeds), scale);
        }
        // Queries grouped by their guess's ball: a block of queries then
        // visits mostly the same balls, which stay in cache.
        let nx = self.order.len();
        // The cluster of each query's guess (u32::MAX: no guess).
        let cluster = |q: usize| match hint.map(|h| h[q]) {
            Some(g) if g < nx => self.ball_of[g],
            _ => u32::MAX,
        };
        let qorder: Vec<usize> = match hint {
            Some(_) => order_by_key(nq, self.ranges.len(), cluster),
            None => (0..nq).collect(),
        };
        // The queries' f64 rows read in place (through `qorder`), or
        // gathered in that order when they must be scaled; in f32 for the
        // GEMMs, in that order.
        let scaled = scale.map(|_| Rows::owned(queries.gather(Some(&qorder), scale), nq, self.d));
        let (q_src, q_map) = match &scaled {
            Some(r) => (r, None),
            None => (queries, Some(qorder.as_slice())),
        };
        let mut q32: Vec<f32> = Vec::with_capacity(nq * self.d);
        for t in 0..nq {
            if t + 4 < nq {
                fmaps_simd::prefetch(query_row(q_src, q_map, t + 4));
            }
            let row = query_row(q_src, q_map, t);
            q32.extend(row.iter().map(|&v| v as f32));
        }
        let hints: Option<Vec<usize>> = hint.map(|h| qorder.iter().map(|&q| h[q]).collect());
        let keys: Vec<u32> = qorder.iter().map(|&q| cluster(q)).collect();
        // Blocks: the queries whose guesses share a ball (they search the
        // same neighbourhood), at most QUERY_BLOCK, runs shorter than
        // MIN_BLOCK merged with the next.
        let mut blocks: Vec<(usize, usize)> = Vec::new();
        let mut q0 = 0;
        for t in 1..=nq {
            let len = t - q0;
            if t == nq || len == QUERY_BLOCK || (len >= MIN_BLOCK && keys[t] != keys[t - 1]) {
                blocks.push((q0, len));
                q0 = t;
            }
        }
        // Super-blocks of about SUPER_BLOCK queries share one GEMM against
        // the centres (the centres are packed once per super-block).
        let mut supers: Vec<std::ops::Range<usize>> = Vec::new();
        let mut b0 = 0;
        for b in 0..blocks.len() {
            if blocks[b].0 + blocks[b].1 - blocks[b0].0 >= SUPER_BLOCK || b + 1 == blocks.len() {
                supers.push(b0..b + 1);
                b0 = b + 1;
            }
        }
        let m = self.ranges.len();
        let d = self.d;
        let centers = MatRef::from_row_major_slice(&self.centers32, m, d);
        let found: Vec<Vec<usize>> = supers
            .par_iter()
            .map(|range| {
                BallWork::with(m, |work| {
                    let s0 = blocks[range.start].0;
                    let last = blocks[range.end - 1];
                    let slen = last.0 + last.1 - s0;
                    let mut g = std::mem::take(&mut work.g);
                    if g.len() < m * slen {
                        g.resize(m * slen, 0.0);
                    }
                    // Centre dot products, one contiguous column per query.
                    matmul(
                        faer::MatMut::from_column_major_slice_mut(&mut g[..m * slen], m, slen),
                        Accum::Replace,
                        centers,
                        MatRef::from_row_major_slice(&q32[s0 * d..(s0 + slen) * d], slen, d)
                            .transpose(),
                        1.0,
                        Par::Seq,
                    );
                    let mut out = Vec::with_capacity(slen);
                    for &(q0, len) in &blocks[range.clone()] {
                        let gb = &g[(q0 - s0) * m..(q0 - s0 + len) * m];
                        out.extend(ball_block(
                            self,
                            (q_src, q_map, &q32),
                            hints.as_deref(),
                            q0,
                            len,
                            gb,
                            work,
                        ));
                    }
                    work.g = g;
                    out
                })
            })
            .collect();
        let mut out = vec![0; nq];
        for (&q, x) in qorder.iter().zip(found.into_iter().flatten()) {
            out[q] = x;
        }
        out
    }
}

/// Per-thread buffers of [`ball_block`].
struct BallWork {
    /// Dot products of the centres with a super-block's queries (m per
    /// query).
    g: Vec<f32>,
    /// Per ball, for the query at hand: the plain bound's margin (≤ 0:
    /// the ball may hold the nearest row).
    pass: Vec<f64>,
    /// The balls that pass, query after query (query i's from
    /// `p_start[i]` to `p_start[i + 1]`).
    p_list: Vec<u32>,
    p_start: Vec<usize>,
    /// The balls one query keeps after the tangent filter.
    keep: Vec<u32>,
    /// Per ball: its slot among the block's candidate balls (or `u32::MAX`),
    /// and the candidates (to reset their slots).
    slot: Vec<u32>,
    cands: Vec<u32>,
    /// The candidate balls' data for the AVX-512 filter.
    #[cfg(target_arch = "x86_64")]
    slots: SlotData,
    /// Their directions' products with the block's queries (`TANGENT`
    /// per slot, query after query; with AVX-512 only those of each
    /// query's plain-test survivors are current).
    tq: Vec<f32>,
    /// The candidates' directions (row-major, `TANGENT` rows each) for
    /// the GEMM off AVX-512.
    ut: Vec<f32>,
    /// Per query: |q|², the best (distance², original index) so far.
    qn: Vec<f64>,
    q_err: Vec<f64>,
    t_err: Vec<f64>,
    best: Vec<(f64, usize)>,
    /// Balls to visit: their tangent data, and (bound², ball, position in
    /// `tangents`) to sort (small entries: cheap to move).
    tangents: Vec<Tangent>,
    visit: Vec<(f64, u32, u32)>,
    /// Per row of a visited ball: its lower bound².
    row_lb: Vec<f64>,
}

thread_local! {
    /// This thread's [`BallWork`], kept from search to search: its
    /// buffers (the centre products of a super-block, ~0.5 MB at 5k rows)
    /// are then allocated and zeroed once, not per super-block.
    static WORK: std::cell::RefCell<Option<BallWork>> = const { std::cell::RefCell::new(None) };
}

impl BallWork {
    /// `f` with this thread's buffers for `m` balls (fresh ones if they
    /// are in use further up this thread's stack).
    fn with<R>(m: usize, f: impl FnOnce(&mut BallWork) -> R) -> R {
        WORK.with(|cell| match cell.try_borrow_mut() {
            Ok(mut kept) => {
                let work = kept.get_or_insert_with(|| BallWork::new(m));
                if work.pass.len() != m {
                    // Per-ball buffers for another partition (every slot
                    // is u32::MAX between blocks).
                    work.pass = vec![0.0; m];
                    work.slot = vec![u32::MAX; m];
                    work.keep = vec![0; m + PAD];
                }
                f(work)
            }
            Err(_) => f(&mut BallWork::new(m)),
        })
    }

    fn new(m: usize) -> BallWork {
        BallWork {
            g: Vec::new(),
            pass: vec![0.0; m],
            p_list: Vec::new(),
            p_start: Vec::with_capacity(QUERY_BLOCK + 1),
            keep: vec![0; m + PAD],
            cands: Vec::new(),
            slot: vec![u32::MAX; m],
            #[cfg(target_arch = "x86_64")]
            slots: SlotData::default(),
            tq: Vec::new(),
            ut: Vec::new(),
            qn: vec![0.0; QUERY_BLOCK],
            q_err: vec![0.0; QUERY_BLOCK],
            t_err: vec![0.0; QUERY_BLOCK],
            best: vec![(0.0, 0); QUERY_BLOCK],
            tangents: Vec::new(),
            visit: Vec::new(),
            row_lb: Vec::new(),
        }
    }
}

crate::cpu::dispatched! {
    /// The nearest rows of queries `q0..q0 + len` (grouped by their
    /// guesses' balls): the plain ball bound for every (query, ball) from
    /// one GEMM against the centres; for the balls that pass it (any
    /// query), the queries' coordinates along their directions from a
    /// second GEMM, hence each pair's tangent bound ([`tangent_bound`]);
    /// the surviving balls visited nearest bound first, their rows
    /// filtered by the same bound per row, the rest measured exactly.
    fn ball_block(
        this: &BallData,
        queries: (&Rows<'_>, Option<&[usize]>, &[f32]),
        hint: Option<&[usize]>,
        q0: usize,
        len: usize,
        gb: &[f32],
        work: &mut BallWork,
    ) -> Vec<usize> {
        let (d, m, nx) = (this.d, this.ranges.len(), this.order.len());
        // The queries in f64 (for the exact distances) and f32 (the GEMMs).
        // (Query t of the block order is row `q_map[t]` of `q_rows`.)
        let (q_rows, q_map, q32) = queries;
        let sl = slack(d);
        // Plain loops, no closures: closures would not be compiled for the
        // instruction set this function is dispatched to.
        // Room for every query's list (grown once per thread: no zeroing
        // per query); the lists follow one another from the start.
        if work.p_list.len() < len * m + PAD {
            work.p_list.resize(len * m + PAD, 0);
        }
        let mut p_len = 0;
        work.p_start.clear();
        #[cfg(target_arch = "x86_64")]
        let v4 = crate::cpu::has_v4();
        for i in 0..len {
            // The rows of a query ahead and of its guess (gathered from
            // anywhere: the hardware prefetcher cannot see them coming).
            if i + 2 < len {
                fmaps_simd::prefetch(query_row(q_rows, q_map, q0 + i + 2));
                if let Some(&h) = hint.and_then(|h| h.get(q0 + i + 2))
                    && h < nx
                {
                    let p = this.pos_of[h] as usize;
                    fmaps_simd::prefetch(&this.x_ord[p * d..(p + 1) * d]);
                }
            }
            let q = query_row(q_rows, q_map, q0 + i);
            let qn = dot(q, q);
            work.qn[i] = qn;
            // The error of the f32 products with this query: its share of
            // 2 q·c's, and each coordinate along a direction.
            work.q_err[i] = score_err(d, qn, 0.0);
            work.t_err[i] = score_err(d, qn, 1.0 + this.geo.eta);
            // (distance², original index): ties go to the smaller index.
            let mut best = (f64::INFINITY, usize::MAX);
            if let Some(&h) = hint.and_then(|h| h.get(q0 + i))
                && h < nx
            {
                let p = this.pos_of[h] as usize;
                best = (dist2(&this.x_ord[p * d..(p + 1) * d], q), h);
            }
            work.best[i] = best;
            // Without a guess: the farthest any row of the nearest-reaching
            // ball can be (every ball holds a row).
            let g = &gb[i * m..(i + 1) * m];
            let mut reach = best.0.sqrt() * (1.0 + sl);
            if !(reach < f64::INFINITY) {
                for j in 0..m {
                    let s = qn + this.c_norm[j];
                    let e2 = work.q_err[i] + this.c_err[j];
                    let hi = (s - 2.0 * f64::from(g[j]) + sl * s + e2).max(0.0).sqrt() * (1.0 + sl);
                    let far = (hi + this.geo.radii[j]) * (1.0 + sl);
                    reach = if far < reach { far } else { reach };
                }
            }
            // The plain bound (|q − c| − r)₊ at most the reach: |q − c|²
            // (from the GEMM, lowered by the slack) at most (reach + r)²;
            // the passing balls listed in order.
            let plain = Plain {
                qn,
                q_err: work.q_err[i],
                reach,
                sl,
            };
            let list = &mut work.p_list[p_len..p_len + m + PAD];
            #[cfg(target_arch = "x86_64")]
            let n = if v4 {
                // SAFETY: the CPU has x86-64-v4 (checked above); `list`
                // holds PAD entries past the m balls.
                unsafe { plain_pass_avx512(this, g, plain, list) }
            } else {
                plain_pass(this, g, plain, &mut work.pass[..m], &mut list[..m])
            };
            #[cfg(not(target_arch = "x86_64"))]
            let n = plain_pass(this, g, plain, &mut work.pass[..m], &mut list[..m]);
            work.p_start.push(p_len);
            p_len += n;
        }
        work.p_start.push(p_len);
        // The candidate balls (those that pass for some query) in slots,
        // and for the AVX-512 filter their data in slot order.
        work.cands.clear();
        for &j in &work.p_list[..p_len] {
            let j = j as usize;
            if work.slot[j] == u32::MAX {
                work.slot[j] = work.cands.len() as u32;
                work.cands.push(j as u32);
            }
        }
        let n_cand = work.cands.len();
        #[cfg(target_arch = "x86_64")]
        if v4 {
            work.slots.fill(this, &work.cands);
        }
        // Each query's products with the candidates' directions (query
        // i's from `i TANGENT n_cand`, `TANGENT` per slot).
        #[cfg(target_arch = "x86_64")]
        let sparse = v4;
        #[cfg(not(target_arch = "x86_64"))]
        let sparse = false;
        let nc3 = n_cand * TANGENT;
        direction_products(this, &q32[q0 * d..(q0 + len) * d], len, work, sparse);
        let mut out = Vec::with_capacity(len);
        for i in 0..len {
            let q = query_row(q_rows, q_map, q0 + i);
            let (qn, mut best) = (work.qn[i], work.best[i]);
            let q_norm = qn.sqrt();
            let g = &gb[i * m..(i + 1) * m];
            // The balls that may pass the tangent bound: all that passed the
            // plain one, or those the AVX-512 filter keeps (a superset of
            // those the bound below keeps; in slot order, which does not
            // matter: the visits are sorted by bound, then ball).
            let passed = work.p_start[i]..work.p_start[i + 1];
            let tcol = &work.tq[i * nc3..(i + 1) * nc3];
            work.visit.clear();
            work.tangents.clear();
            #[cfg(target_arch = "x86_64")]
            let kept = if v4 {
                let q = BoundQuery {
                    i,
                    qn,
                    q_norm,
                    q_err: work.q_err[i],
                    t_err: work.t_err[i],
                    sl,
                };
                let keep = &mut work.keep[..n_cand + PAD];
                // SAFETY: x86-64-v4 (checked above); the candidates are
                // below m (`g`), `slots` holds their data, `tcol` their
                // TANGENT n_cand products.
                let n = unsafe {
                    tangent_filter_avx512(&work.slots, this.geo.eta, &work.cands, tcol, g, q, best.0, keep)
                };
                &work.keep[..n]
            } else {
                &work.p_list[passed]
            };
            #[cfg(not(target_arch = "x86_64"))]
            let kept = &work.p_list[passed];
            for &j in kept {
                let j = j as usize;
                let s = work.slot[j] as usize;
                let mut uq = [0.0; TANGENT];
                for t in 0..TANGENT {
                    uq[t] = f64::from(tcol[s * TANGENT + t]);
                }
                let err = Err32 {
                    qc: work.q_err[i] + this.c_err[j],
                    uq: work.t_err[i],
                };
                if let Some(tb) =
                    tangent_bound(this, j, (qn, q_norm), f64::from(g[j]), &uq, err, sl, best.0)
                    && tb.lb2 <= best.0
                {
                    work.visit.push((tb.lb2, j as u32, work.tangents.len() as u32));
                    work.tangents.push(tb);
                }
            }
            sort_visits(&mut work.visit);
            for v in 0..work.visit.len() {
                let (lb2, j, at) = work.visit[v];
                if lb2 > best.0 {
                    break;
                }
                let tb = work.tangents[at as usize];
                let (start, l) = this.ranges[j as usize];
                let tol = tb.eps + sl * this.geo.radii[j as usize];
                // Each row's own bound, branch-free across the ball: its
                // tangent bound and ||q − c| − |x − c||.
                // (Slices of equal length and `max_finite`: the loop runs
                // across rows in SIMD lanes.)
                work.row_lb.clear();
                work.row_lb.resize(l, 0.0);
                let lb = &mut work.row_lb[..l];
                let (e, rp) = (&this.geo.to_center[start..start + l], &this.geo.row_perp[start..start + l]);
                let rt: [&[f64]; TANGENT] =
                    std::array::from_fn(|t| &this.geo.row_tan[t * nx + start..t * nx + start + l]);
                let (up, down, keep) = (1.0 + sl, 1.0 - sl, 1.0 - 2.0 * sl);
                let flat = 1.0 - this.geo.eta;
                for k in 0..l {
                    let a = max_finite(max_finite(tb.dc_lo - e[k] * up, e[k] * down - tb.dc_hi), 0.0);
                    let mut gap2 = 0.0;
                    for t in 0..TANGENT {
                        let gt = max_finite((tb.t[t] - rt[t][k]).abs() - tol, 0.0);
                        gap2 += gt * gt;
                    }
                    let pb = max_finite(tb.perp - rp[k], 0.0);
                    let lt = gap2 * flat + pb * pb;
                    lb[k] = max_finite(a * a, lt) * keep;
                }
                for k in 0..l {
                    if work.row_lb[k] > best.0 {
                        continue;
                    }
                    let p = start + k;
                    if let Some(dk) = dist2_below(&this.x_ord[p * d..(p + 1) * d], q, best.0) {
                        let idx = this.order[p];
                        if dk < best.0 || (dk == best.0 && idx < best.1) {
                            best = (dk, idx);
                        }
                    }
                }
            }
            out.push(best.1);
        }
        for &j in &work.cands {
            work.slot[j as usize] = u32::MAX;
        }
        out
    }
}

/// `0..n` sorted by `(key(i), i)`, for keys below `m` or `u32::MAX`
/// (last): a counting sort.
fn order_by_key(n: usize, m: usize, key: impl Fn(usize) -> u32) -> Vec<usize> {
    let bucket = |i: usize| (key(i) as usize).min(m);
    let mut start = vec![0usize; m + 2];
    for i in 0..n {
        start[bucket(i) + 1] += 1;
    }
    for b in 0..=m {
        start[b + 1] += start[b];
    }
    let mut order = vec![0usize; n];
    for i in 0..n {
        let b = bucket(i);
        order[start[b]] = i;
        start[b] += 1;
    }
    order
}

/// `visit` by bound, then ball: an insertion sort for the few balls a
/// query usually visits (no call, no comparator), the library's sort for
/// more.
#[inline(always)]
fn sort_visits(visit: &mut [(f64, u32, u32)]) {
    if visit.len() > 16 {
        visit.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        return;
    }
    for i in 1..visit.len() {
        let mut k = i;
        while k > 0 && (visit[k - 1].0, visit[k - 1].1) > (visit[k].0, visit[k].1) {
            visit.swap(k - 1, k);
            k -= 1;
        }
    }
}

mod geometry;
use geometry::{Geometry, geometry};

mod bound;
#[cfg(target_arch = "x86_64")]
use bound::{BoundQuery, SlotData, tangent_filter_avx512};
use bound::{Err32, Tangent, direction_products, tangent_bound};

mod plain;
#[cfg(target_arch = "x86_64")]
use plain::plain_pass_avx512;
use plain::{Plain, plain_pass};

#[cfg(test)]
mod tests;
