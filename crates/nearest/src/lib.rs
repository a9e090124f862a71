//! Exact nearest neighbours of query rows among data rows, in any
//! dimension: `|q − x|² = |x|² − 2 q·x + |q|²`. The cross terms are
//! blocked GEMMs in f32 (faer; twice the f64 throughput), which only
//! *select candidates*: every data row whose f32 score lies within a
//! rigorous rounding band of the best one is re-checked with a direct f64
//! distance, so the result is the true nearest row in f64 (ties: the
//! smallest index). Memory is bounded by the block size, never
//! n_queries x n_data. In up to 32 dimensions brute force scores in one
//! fused kernel instead (four queries, eight with AVX-512, against sixteen rows in registers,
//! one multiply-add per coordinate, its own band: `fused_err`).
//!
//! In high dimensions most of that work can be skipped ([`NnStrategy::Prefix`]):
//! spectral embeddings spread mostly along their leading (low-frequency)
//! coordinates, so the distance over a 40-coordinate prefix, which bounds
//! the full distance from below, already exceeds the nearest distance for
//! all but a few percent of the rows. Guesses (the previous iteration's
//! map in ZoomOut and ICP, the `hint` of [`nearest_rows`]) give the upper bound
//! that makes this cut sharp. The scans and distance kernels are compiled
//! for AVX-512 and AVX2 as well and the widest one the CPU has is run.
//!
//! Without matrix tiles (with them, from [`PartitionParams::tiled_from_rows`] rows),
//! where a search is repeated on linear images of
//! the same rows (ZoomOut's `Φ_A Cᵀ`) with guesses, clusters of the rows
//! computed once ([`Partition`]) prune nearly everything
//! ([`NnStrategy::Balls`]): each cluster is bounded by a ball and by a box
//! along its principal directions, and a query measures only the few rows
//! those bounds cannot rule out, in f64.
//!
//! On CPUs with matrix tiles (Intel AMX; [`NnStrategy::Tiles`], the
//! default from 16 dimensions where [`tiles_available`]) every pair is
//! ranked in bf16 in the full dimension at ~6x the f32 GEMM rate, with a
//! bound on the bf16 error that is tight within 10% in the worst case
//! (see the `tiles` module), and the few rows within it re-checked in f64.
//!
//! The band: with u = 2⁻²⁴, rounding the inputs to f32 and a length-d dot
//! product in f32 change `q·x` by at most `(d + 2) u |q| |x|`, plus the
//! absolute error of values that underflow f32's normal range, so each
//! score `|x|² − 2 q·x` is off by at most some `e` (`score_err` in the
//! `brute` module); the true nearest row scores within `2 e_max` of the
//! f32 minimum. The band used is twice that. Coordinates far outside f32's
//! range are first scaled by one power of two (exact in f64).
//!
//! The main entry point is [`nearest_rows`]: faer views of any layout in,
//! optional guesses, knobs in [`NnParams`] ([`nearest_rows_both`] answers
//! both ways between two point sets from one pass of products, up to 32
//! coordinates):
//!
//! ```
//! use faer::Mat;
//! use fmaps_nearest::{NnParams, nearest_rows};
//!
//! // Four points on a line and two queries.
//! let data = Mat::from_fn(4, 3, |i, j| (i * 10 + j) as f64);
//! let queries = Mat::from_fn(2, 3, |i, j| (i * 29 + j) as f64 + 0.4);
//! let nearest = nearest_rows(data.as_ref(), queries.as_ref(), None, &NnParams::default())?;
//! assert_eq!(nearest, vec![0, 3]);
//! # Ok::<(), fmaps_nearest::Error>(())
//! ```
//!
//! The kernels run at the widest instruction set the CPU has
//! ([`simd_level`]); [`set_simd_cap`] or the environment variable
//! `FMAPS_SIMD=baseline|avx2|avx512` caps it (to test or time the
//! narrower kernels; the answers are the same), and `FMAPS_NO_AMX` turns
//! the tiles off.
//!
//! This crate reports the CPU's features ([`cpu_features`], detected by
//! `fmaps-simd`) and holds the `unsafe` code of the search (the AMX tiles,
//! the strided row view, the `#[target_feature]` kernels).
#![deny(missing_docs)]

mod balls;
mod brute;
mod cpu;
mod image;
mod knn;
mod partition;
mod prefix;
mod rows;
mod tiles;
mod tree;

#[cfg(test)]
mod tests;

use faer::MatRef;
use nalgebra::DMatrix;

use std::sync::OnceLock;

use balls::BallData;
pub use balls::{Partition, PartitionParams};
use brute::{BruteData, FUSED_MAX_DIM, brute_search, max_abs, power_of_two_scale, scale_for};
pub use partition::BallsRequest;
use partition::TILED_BALLS_FROM_ROWS;
use prefix::{PREFIX_FROM, PREFIX_MAX_ROWS, PrefixData, prefix_search};
use rows::Rows;
use std::sync::Arc;
use tree::{LEAF_DATA, LEAF_QUERY, TREE_MAX_DIM, TreeData, tree_search};

/// Rows of both sets from which [`NnStrategy::Auto`] uses the tree (in
/// `FUSED_MAX_DIM + 1..=TREE_MAX_DIM` dimensions): on spectral embeddings
/// of FAUST subdivided to 80k vertices, d = 30-48, one thread without
/// AMX, it beat brute force by 10-25%; at 20k rows brute force was
/// 1.5-2x faster (the `strategies` example).
const TREE_MIN_ROWS: usize = 50_000;

pub use cpu::{CpuFeatures, SimdLevel, cpu_features, set_simd_cap, simd_level};
pub use image::{CheckedRows, ImageSearch};
pub use knn::{KNearest, k_nearest_rows};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Data and query rows have different lengths.
    #[error("data rows have {data} coordinates but query rows have {queries}")]
    DimensionMismatch {
        /// Coordinates per data row.
        data: usize,
        /// Coordinates per query row.
        queries: usize,
    },
    /// The guesses are not one per query.
    #[error("{found} guesses for {expected} queries (one per query)")]
    HintCount {
        /// Guesses given.
        found: usize,
        /// Queries.
        expected: usize,
    },
    /// There are queries but no data rows to find.
    #[error("{queries} queries but no data rows")]
    NoData {
        /// Queries.
        queries: usize,
    },
    /// Two sizes that must agree do not.
    #[error("{what}: {found}, expected {expected}")]
    SizeMismatch {
        /// What was compared.
        what: &'static str,
        /// The size found.
        found: usize,
        /// The size expected.
        expected: usize,
    },
    /// A coordinate is NaN or infinite (no nearest row is defined).
    #[error("{side} row {row}, coordinate {col} is {value}: coordinates must be finite")]
    NonFinite {
        /// "data" or "query".
        side: &'static str,
        /// The row.
        row: usize,
        /// The coordinate.
        col: usize,
        /// Its value.
        value: f64,
    },
}

/// The sum of `s` in eight independent lanes (a plain running sum waits on
/// each addition; this one vectorizes). Not finite when an entry is not
/// (or the sum overflows).
fn lane_sum(s: &[f64]) -> f64 {
    let mut lanes = [0.0f64; 8];
    let mut chunks = s.chunks_exact(8);
    for c in &mut chunks {
        for (l, v) in lanes.iter_mut().zip(c) {
            *l += v;
        }
    }
    lanes.iter().sum::<f64>() + chunks.remainder().iter().sum::<f64>()
}

/// The first non-finite entry of `m` (line by line), as an error of
/// `side`. A sum per column (per row for a row-major view: along the
/// contiguous direction) catches NaN and infinities cheaply; only a line
/// whose sum is not finite (or overflowed) is scanned entry by entry.
fn check_finite(m: MatRef<'_, f64>, side: &'static str) -> Result<()> {
    let by_rows = m.col_stride() == 1 && m.ncols() > 1;
    // Lines along the contiguous direction: (row, column) of entry t of
    // line l.
    let (lines, len) = if by_rows {
        (m.nrows(), m.ncols())
    } else {
        (m.ncols(), m.nrows())
    };
    let at = |l: usize, t: usize| if by_rows { (l, t) } else { (t, l) };
    for l in 0..lines {
        let contiguous = if by_rows {
            m.row(l).try_as_row_major().map(|r| r.as_slice())
        } else {
            m.col(l).try_as_col_major().map(|c| c.as_slice())
        };
        let sum: f64 = match contiguous {
            Some(s) => lane_sum(s),
            None => (0..len).map(|t| m[at(l, t)]).sum(),
        };
        if !sum.is_finite()
            && let Some(t) = (0..len).find(|&t| !m[at(l, t)].is_finite())
        {
            let (row, col) = at(l, t);
            return Err(Error::NonFinite {
                side,
                row,
                col,
                value: m[(row, col)],
            });
        }
    }
    Ok(())
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Knobs of [`nearest_rows`]; the answer never depends on them.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[non_exhaustive]
pub struct NnParams {
    /// How the search runs ([`NnStrategy::Auto`] by default).
    pub strategy: NnStrategy,
    /// Clusters of the data rows for [`NnStrategy::Balls`] (ignored when
    /// it does not label every data row): computed once, e.g. for a
    /// shape's spectral embedding, and reused for every linear image of it
    /// that is searched (ZoomOut's `Φ_A Cᵀ`). With a partition,
    /// [`NnStrategy::Auto`] runs the balls in more than 32 dimensions
    /// where the CPU has no matrix tiles, or from [`PartitionParams::tiled_from_rows`]
    /// data rows where it has them (with or without guesses: without, each
    /// query is first seeded from its nearest centre's ball).
    pub partition: Option<Arc<Partition>>,
}

impl NnParams {
    /// The default knobs with `strategy`.
    pub fn with_strategy(strategy: NnStrategy) -> Self {
        NnParams {
            strategy,
            partition: None,
        }
    }

    /// These knobs with the data rows' clusters `partition`.
    pub fn with_partition(self, partition: Arc<Partition>) -> Self {
        NnParams {
            partition: Some(partition),
            ..self
        }
    }
}

/// How [`nearest_rows`] searches; every strategy returns the same,
/// exact answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NnStrategy {
    /// With a [`Partition`] in more than 32 dimensions the ball search
    /// (where the CPU has matrix tiles, from [`PartitionParams::tiled_from_rows`] data
    /// rows); else the matrix tiles from 16 dimensions where the CPU has
    /// them; else the prefix search from 64 dimensions with guesses, the
    /// tree in 33 to 48 dimensions when both sets have 50,000 rows or
    /// more, brute force otherwise.
    #[default]
    Auto,
    /// Every query against every data row (blocked f32 GEMM; up to 32
    /// dimensions a fused f32 kernel).
    Brute,
    /// Both sets split into clusters by principal-direction bisection;
    /// a cluster of queries is compared (f32 GEMM) only with the data
    /// clusters that the triangle inequality cannot rule out.
    Tree,
    /// Every pair is ranked on the leading 40 coordinates only
    /// (half of them below 64 dimensions)
    /// (f32 GEMM of that width); a query's full f64 distance is computed
    /// only for the rows whose partial distance does not already exceed an
    /// upper bound of its nearest distance (the best-ranked row's, or the
    /// hint's when given). Spectral embeddings concentrate their spread in
    /// the leading (low-frequency) coordinates, so a few percent of the
    /// rows survive.
    Prefix,
    /// The data rows in small clusters (a [`Partition`], given in
    /// [`NnParams::partition`] or computed), each bounded by a ball and by
    /// a *tangent box* (its spread along a few principal directions, and
    /// its distance from their span); each query bounds its distance to
    /// every cluster (two f32 GEMMs per block of queries, their rounding
    /// bounded) and visits, nearest bound first, only the clusters, then
    /// the rows, that can be nearer than its best so far (its guess, when
    /// given), with exact f64 distances. No matrix units: on spectral
    /// embeddings with the previous iteration's map as guesses a query
    /// measures ~3 rows (FAUST, 5k vertices, k = 100).
    Balls,
    /// Every pair ranked in the full dimension on the CPU's matrix tiles
    /// (Intel AMX: bf16 products, f32 sums, ~6x the f32 GEMM rate); the
    /// rows within a rigorous bound of the best are re-checked in f64.
    /// Brute force where the CPU or the OS does not offer the tiles
    /// ([`tiles_available`]).
    Tiles,
}

/// Whether [`NnStrategy::Tiles`] runs on matrix tiles here (x86-64 Linux
/// with AMX-BF16, and `FMAPS_NO_AMX` unset); detected once.
pub fn tiles_available() -> bool {
    crate::tiles::available()
}

/// Leading coordinates on which [`NnStrategy::Prefix`] ranks every pair
/// from 64 dimensions on (below, half of the coordinates, at least
/// [`PREFIX_MIN`]).
pub(crate) const PREFIX_DIM: usize = 40;

/// Smallest prefix width; the prefix search needs at least twice as many
/// dimensions.
pub(crate) const PREFIX_MIN: usize = 8;

/// The prefix width used in dimension `d`.
pub(crate) fn prefix_width(d: usize) -> usize {
    if d >= PREFIX_FROM {
        PREFIX_DIM
    } else {
        (d / 2).max(PREFIX_MIN)
    }
}

/// For every row of `queries` (n_q x d), the index of the nearest row of
/// `data` (n_x x d) in f64 (ties: the smallest index), whatever the
/// strategy. `hint`, when given, holds one guess per query (any data row
/// index, e.g. the previous iteration's answer in ZoomOut or ICP; an index
/// out of range counts as no guess): a good guess lets the search discard
/// more rows early, never changes the answer.
///
/// Views of any layout are accepted. Where the search runs on the matrix
/// tiles, views whose rows are contiguous (column stride 1: row-major, or
/// a leading block of a row-major matrix) are read in place; other
/// layouts and strategies copy first (`O(n d)`, small next to the search).
///
/// Errors: rows of different lengths, a hint count other than one per
/// query, queries without data rows, a coordinate that is not finite.
/// Rows of no coordinates are all at distance 0: every query gets row 0.
pub fn nearest_rows(
    data: MatRef<'_, f64>,
    queries: MatRef<'_, f64>,
    hint: Option<&[usize]>,
    params: &NnParams,
) -> Result<Vec<usize>> {
    let (nx, d) = (data.nrows(), data.ncols());
    if check_input(nx, d, queries, hint)? {
        return Ok(Vec::new());
    }
    if d == 0 {
        // Every row is at distance 0: ties go to the smallest index.
        return Ok(vec![0; queries.nrows()]);
    }
    let partition = params.partition.as_deref().filter(|p| p.len() == nx);
    let mut strategy = resolve(
        params.strategy,
        nx,
        queries.nrows(),
        d,
        hint.is_some(),
        partition.is_some(),
    );
    if strategy == NnStrategy::Balls {
        // Row by row from the views (no column-major copies): the data in
        // its clusters' order, the queries in their guesses' order. The
        // finiteness check and the scale in one pass per side (on the
        // data, the same pass as its copy in the clusters' order).
        // (Otherwise the checks below name the first entry that is not.)
        let (x, q) = (Rows::of(data), Rows::of(queries));
        if let Some(mq) = q.max_abs_finite() {
            match partition {
                Some(p) => {
                    if let Some((balls, scale)) = BallData::from_rows_checked(&x, p, mq) {
                        return Ok(balls.search_rows(&q, hint, scale));
                    }
                }
                None => {
                    if let Some(mx) = x.max_abs_finite() {
                        let scale = scale_for(mx.max(mq));
                        return Ok(
                            BallData::from_rows(&x, None, scale).search_rows(&q, hint, scale)
                        );
                    }
                }
            }
        }
    }
    check_finite(data, "data")?;
    check_finite(queries, "query")?;
    if strategy == NnStrategy::Tiles {
        if let Some(found) = tiles::search_rows(Rows::of(data), Rows::of(queries), hint) {
            return Ok(found);
        }
        // No tiles here, or rows out of their range.
        strategy = NnStrategy::Brute;
    }
    Ok(search(
        &owned(data),
        &owned(queries),
        strategy,
        hint,
        partition,
    ))
}

/// Nearest rows both ways by brute force: for each row of `a` its
/// nearest row of `b`, and for each row of `b` its nearest row of `a`
/// (ties to the smallest index) — what `nearest_rows(b, a, ..)` and
/// `nearest_rows(a, b, ..)` with [`NnStrategy::Brute`] return, and with
/// the same errors. Up to the fused kernel's width (32 coordinates) one
/// pass of f32 products serves both directions (the reverse one keeps
/// each row's smallest approximate distance per group of queries scored
/// together and re-checks, in f64, the groups within a rigorous band of
/// it); wider, two searches.
///
/// ```
/// use fmaps_nearest::{nearest_rows_both, view};
/// use nalgebra::DMatrix;
/// let a = DMatrix::from_row_slice(3, 2, &[0.0, 0.0, 1.0, 0.0, 5.0, 5.0]);
/// let b = DMatrix::from_row_slice(2, 2, &[0.9, 0.1, 4.0, 4.0]);
/// let (ab, ba) = nearest_rows_both(view(&a), view(&b)).unwrap();
/// assert_eq!(ab, vec![0, 0, 1]);
/// assert_eq!(ba, vec![1, 2]);
/// ```
pub fn nearest_rows_both(
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let d = b.ncols();
    if a.ncols() == d && a.nrows() > 0 && b.nrows() > 0 && (1..=FUSED_MAX_DIM).contains(&d) {
        // Row by row from the views (read in place where rows are
        // contiguous): the finiteness check and the scale in one pass per
        // side, then one row-major copy each (rescaled when needed).
        let (xr, qr) = (Rows::of(b), Rows::of(a));
        if let (Some(mx), Some(mq)) = (xr.max_abs_finite(), qr.max_abs_finite()) {
            let scale = scale_for(mx.max(mq));
            let q_rows = qr.gather(None, scale);
            if let Some(found) =
                BruteData::from_rows(xr.gather(None, scale), d).search_both(&q_rows)
            {
                return Ok(found);
            }
        }
    }
    // Other widths, empty sides, or a coordinate that is not finite (the
    // searches name it): two searches.
    let brute = NnParams::with_strategy(NnStrategy::Brute);
    let (ab, ba) = rayon::join(
        || nearest_rows(b, a, None, &brute),
        || nearest_rows(a, b, None, &brute),
    );
    Ok((ab?, ba?))
}

/// Checks the queries and guesses against `nx` data rows of `d`
/// coordinates; `true` when there is nothing to search (no queries).
fn check_input(
    nx: usize,
    d: usize,
    queries: MatRef<'_, f64>,
    hint: Option<&[usize]>,
) -> Result<bool> {
    if queries.ncols() != d {
        return Err(Error::DimensionMismatch {
            data: d,
            queries: queries.ncols(),
        });
    }
    if let Some(h) = hint
        && h.len() != queries.nrows()
    {
        return Err(Error::HintCount {
            found: h.len(),
            expected: queries.nrows(),
        });
    }
    if queries.nrows() == 0 {
        return Ok(true);
    }
    if nx == 0 {
        return Err(Error::NoData {
            queries: queries.nrows(),
        });
    }
    Ok(false)
}

/// A data set searched repeatedly: [`nearest_rows`] with the data-side
/// work of each f32 strategy (row-major and f32 copies, norms, clusters,
/// the prefix order) done the first time that strategy runs and kept for
/// every later query set. Same answers as [`nearest_rows`]. (The tiles
/// pack their data per search; their data side is not kept.)
///
/// ```
/// use faer::Mat;
/// use fmaps_nearest::{NnParams, Searcher, nearest_rows};
///
/// let data = Mat::from_fn(500, 20, |i, j| ((i * 7 + j * 3) % 101) as f64);
/// let searcher = Searcher::new(data.as_ref(), &NnParams::default())?;
/// for shift in [0.25, 0.5] {
///     let queries = Mat::from_fn(50, 20, |i, j| ((i * 13 + j) % 97) as f64 + shift);
///     let once = nearest_rows(data.as_ref(), queries.as_ref(), None, &NnParams::default())?;
///     assert_eq!(searcher.search(queries.as_ref(), None)?, once);
/// }
/// # Ok::<(), fmaps_nearest::Error>(())
/// ```
pub struct Searcher {
    /// The data as given (column-major copy).
    data: DMatrix<f64>,
    /// Its largest finite magnitude, and the power of two the prepared
    /// strategies work in (see [`nearest_rows`]).
    max: f64,
    scale: Option<f64>,
    params: NnParams,
    brute: OnceLock<BruteData>,
    tree: OnceLock<TreeData>,
    prefix: OnceLock<PrefixData>,
    balls: OnceLock<BallData>,
}

impl Searcher {
    /// A searcher of the rows of `data` (n x d, any layout; copied).
    /// Errors: a non-finite coordinate.
    pub fn new(data: MatRef<'_, f64>, params: &NnParams) -> Result<Searcher> {
        check_finite(data, "data")?;
        let data = owned(data);
        let max = max_abs(&data);
        Ok(Searcher {
            scale: scale_for(max),
            max,
            data,
            params: params.clone(),
            brute: OnceLock::new(),
            tree: OnceLock::new(),
            prefix: OnceLock::new(),
            balls: OnceLock::new(),
        })
    }

    /// Data rows n.
    pub fn n(&self) -> usize {
        self.data.nrows()
    }

    /// Coordinates per row d.
    pub fn dim(&self) -> usize {
        self.data.ncols()
    }

    /// For every row of `queries` (n_q x d), the index of the nearest data
    /// row, as [`nearest_rows`] (same errors).
    pub fn search(&self, queries: MatRef<'_, f64>, hint: Option<&[usize]>) -> Result<Vec<usize>> {
        let (nx, d) = self.data.shape();
        if check_input(nx, d, queries, hint)? {
            return Ok(Vec::new());
        }
        check_finite(queries, "query")?;
        if d == 0 {
            return Ok(vec![0; queries.nrows()]);
        }
        let nq = queries.nrows();
        let partition = self.params.partition.as_deref().filter(|p| p.len() == nx);
        let mut strategy = resolve(
            self.params.strategy,
            nx,
            nq,
            d,
            hint.is_some(),
            partition.is_some(),
        );
        if strategy == NnStrategy::Tiles {
            if let Some(found) =
                tiles::search_rows(Rows::of(view(&self.data)), Rows::of(queries), hint)
            {
                return Ok(found);
            }
            strategy = NnStrategy::Brute;
        }
        let queries = owned(queries);
        // The prepared data works in the data's scale: queries that need
        // another one (far larger or smaller than the data) take the
        // one-off path.
        if scale_for(self.max.max(max_abs(&queries))) != self.scale {
            return Ok(search(&self.data, &queries, strategy, hint, partition));
        }
        let scaled = |m: &DMatrix<f64>| self.scale.map(|s| m * s);
        let q_scaled = scaled(&queries);
        let q = q_scaled.as_ref().unwrap_or(&queries);
        let data = || scaled(&self.data).unwrap_or_else(|| self.data.clone());
        Ok(match strategy {
            NnStrategy::Tree if d > 0 => self.tree.get_or_init(|| TreeData::new(&data())).search(q),
            NnStrategy::Prefix if d >= 2 * PREFIX_MIN => self
                .prefix
                .get_or_init(|| PrefixData::new(&data()))
                .search(q, hint),
            NnStrategy::Balls => self
                .balls
                .get_or_init(|| BallData::new(&data(), partition))
                .search(q, hint),
            _ => self.brute.get_or_init(|| BruteData::new(&data())).search(q),
        })
    }
}

/// The strategy [`NnStrategy::Auto`] stands for with `nx` data rows, `nq`
/// queries of `d` coordinates (others stand for themselves). The choice
/// follows measurements on FAUST spectral embeddings (README, "Choosing a
/// strategy"): the clusters where a partition is given, with or without
/// guesses (more than 32 coordinates: below, the fused kernel; with
/// matrix tiles from [`PartitionParams::tiled_from_rows`] data rows), else the tiles
/// wherever they exist, the prefix search with guesses in high
/// dimensions, the tree
/// only for very large sets in 33-48 dimensions (below 33 the fused
/// brute-force kernel is faster at every size measured, up to 80k x 80k
/// rows).
fn resolve(
    strategy: NnStrategy,
    nx: usize,
    nq: usize,
    d: usize,
    hinted: bool,
    partitioned: bool,
) -> NnStrategy {
    if strategy != NnStrategy::Auto {
        return strategy;
    }
    let tiles = d >= TILES_FROM && tiles::available();
    if partitioned && d > FUSED_MAX_DIM && (!tiles || nx >= TILED_BALLS_FROM_ROWS) {
        NnStrategy::Balls
    } else if tiles {
        NnStrategy::Tiles
    } else if (1024..=PREFIX_MAX_ROWS).contains(&nx) && d >= PREFIX_FROM && hinted {
        NnStrategy::Prefix
    } else if (FUSED_MAX_DIM + 1..=TREE_MAX_DIM).contains(&d)
        && nx >= TREE_MIN_ROWS.max(4 * LEAF_DATA)
        && nq >= TREE_MIN_ROWS.max(2 * LEAF_QUERY)
    {
        NnStrategy::Tree
    } else {
        NnStrategy::Brute
    }
}

/// A column-major copy of a view (one `memcpy` per column when the
/// columns are contiguous).
fn owned(m: MatRef<'_, f64>) -> DMatrix<f64> {
    let (n, d) = (m.nrows(), m.ncols());
    let mut out = DMatrix::zeros(n, d);
    for (j, col) in out.as_mut_slice().chunks_exact_mut(n.max(1)).enumerate() {
        match m.col(j).try_as_col_major() {
            Some(c) => col.copy_from_slice(c.as_slice()),
            None => {
                for (i, o) in col.iter_mut().enumerate() {
                    *o = m[(i, j)];
                }
            }
        }
    }
    out
}

/// A faer view of a column-major nalgebra matrix (no copy), for
/// [`nearest_rows`].
pub fn view(m: &DMatrix<f64>) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(m.as_slice(), m.nrows(), m.ncols())
}

/// The f32 strategies behind [`nearest_rows`] (`strategy` resolved, not
/// `Tiles`) on column-major matrices of equal width.
fn search(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    strategy: NnStrategy,
    hint: Option<&[usize]>,
    partition: Option<&Partition>,
) -> Vec<usize> {
    let d = data.ncols();
    // The f32 strategies need coordinates well inside f32's range: far
    // below it the cross terms underflow (the band then covers every row),
    // far above it they overflow. Nearest rows do not change when both
    // sets are scaled by one power of two, which is exact in f64.
    let scaled = power_of_two_scale(data, queries).map(|s| (data * s, queries * s));
    let (data, queries) = match &scaled {
        Some((x, q)) => (x, q),
        None => (data, queries),
    };
    match strategy {
        NnStrategy::Tree if d > 0 => return tree_search(data, queries),
        NnStrategy::Prefix if d >= 2 * PREFIX_MIN => return prefix_search(data, queries, hint),
        NnStrategy::Balls => return BallData::new(data, partition).search(queries, hint),
        _ => {}
    }
    brute_search(data, queries)
}

/// Smallest dimension [`NnStrategy::Auto`] uses the matrix tiles from
/// (where they are available). Below, the tiles pad every row to 32
/// coordinates and the tree is about as fast (README, "Choosing a
/// strategy").
const TILES_FROM: usize = 16;
