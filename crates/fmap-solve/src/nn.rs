//! Exact nearest neighbours of query rows among data rows, in any
//! dimension: `|q − x|² = |x|² − 2 q·x + |q|²`. The cross terms are
//! blocked GEMMs in f32 (faer; twice the f64 throughput), which only
//! *select candidates*: every data row whose f32 score lies within a
//! rigorous rounding band of the best one is re-checked with a direct f64
//! distance, so the result is the true nearest row in f64 (ties: the
//! smallest index). Memory is bounded by the block size, never
//! n_queries x n_data.
//!
//! In high dimensions most of that work can be skipped ([`NnStrategy::Prefix`]):
//! spectral embeddings spread mostly along their leading (low-frequency)
//! coordinates, so the distance over a 40-coordinate prefix, which bounds
//! the full distance from below, already exceeds the nearest distance for
//! all but a few percent of the rows. Guesses (the previous iteration's
//! map in ZoomOut and ICP, [`nearest_rows_hinted`]) give the upper bound
//! that makes this cut sharp. The scans and distance kernels are compiled
//! for AVX-512 and AVX2 as well and the widest one the CPU has is run.
//!
//! On CPUs with matrix tiles (Intel AMX; [`NnStrategy::Tiles`], the
//! default from 16 dimensions where [`tiles_available`]) every pair is
//! ranked in bf16 in the full dimension at ~6x the f32 GEMM rate, with a
//! bound on the bf16 error that is tight within 10% in the worst case
//! (see the `tiles` module), and the few rows within it re-checked in f64.
//!
//! The band: with u = 2⁻²⁴, rounding the inputs to f32 and a length-d dot
//! product in f32 change `q·x` by at most `(d + 2) u |q| |x|`, so each score
//! `|x|² − 2 q·x` is off by at most `e = (d + 2) u (|q|² + |x|²)`; the
//! true nearest row scores within `2 e_max` of the f32 minimum. The band
//! used is twice that.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// Queries per block.
const BLOCK: usize = 256;

/// A function compiled three times, for AVX-512, for AVX2 and for baseline
/// x86-64, and the widest one the CPU has run (see [`simd`]).
macro_rules! dispatched {
    ($(#[$m:meta])* fn $name:ident($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty $body:block) => {
        $(#[$m])*
        fn $name($($arg: $ty),*) -> $ret {
            #[inline(always)]
            fn body($($arg: $ty),*) -> $ret $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,bmi1,bmi2,popcnt,lzcnt")]
                fn v4($($arg: $ty),*) -> $ret {
                    body($($arg),*)
                }
                #[target_feature(enable = "avx2,fma,bmi1,bmi2,popcnt,lzcnt")]
                fn v3($($arg: $ty),*) -> $ret {
                    body($($arg),*)
                }
                if simd::has_v4() {
                    // SAFETY: the CPU has the features (runtime check).
                    return unsafe { v4($($arg),*) };
                }
                if simd::has_v3() {
                    // SAFETY: as above.
                    return unsafe { v3($($arg),*) };
                }
            }
            body($($arg),*)
        }
    };
}

/// How [`nearest_rows_with`] searches; every strategy returns the same,
/// exact answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NnStrategy {
    /// The matrix tiles from 16 dimensions where the CPU has them; else
    /// the tree in dimensions up to 48 when both sets are large enough for
    /// it to pay, the prefix search from 64 dimensions with guesses, brute
    /// force otherwise.
    #[default]
    Auto,
    /// Every query against every data row (blocked f32 GEMM).
    Brute,
    /// Both sets split into clusters by principal-direction bisection;
    /// a cluster of queries is compared (f32 GEMM) only with the data
    /// clusters that the triangle inequality cannot rule out.
    Tree,
    /// Every pair is ranked on the leading [`PREFIX_DIM`] coordinates only
    /// (half of them below 64 dimensions)
    /// (f32 GEMM of that width); a query's full f64 distance is computed
    /// only for the rows whose partial distance does not already exceed an
    /// upper bound of its nearest distance (the best-ranked row's, or the
    /// hint's when given). Spectral embeddings concentrate their spread in
    /// the leading (low-frequency) coordinates, so a few percent of the
    /// rows survive.
    Prefix,
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
pub const PREFIX_DIM: usize = 40;

/// Smallest prefix width; the prefix search needs at least twice as many
/// dimensions.
pub const PREFIX_MIN: usize = 8;

/// The prefix width used in dimension `d`.
fn prefix_width(d: usize) -> usize {
    if d >= PREFIX_FROM {
        PREFIX_DIM
    } else {
        (d / 2).max(PREFIX_MIN)
    }
}

/// For every row of `queries` (n_q x d), the index of the nearest row of
/// `data` (n_x x d); [`NnStrategy::Auto`]. Panics if the dimensions differ
/// (a programming error of the caller; the public conversions check sizes
/// first).
#[track_caller]
pub fn nearest_rows(data: &DMatrix<f64>, queries: &DMatrix<f64>) -> Vec<usize> {
    nearest_rows_with(data, queries, NnStrategy::Auto)
}

/// [`nearest_rows`] with a chosen strategy (for benchmarks and tests: the
/// answer does not depend on it).
#[track_caller]
pub fn nearest_rows_with(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    strategy: NnStrategy,
) -> Vec<usize> {
    search(data, queries, strategy, None)
}

/// [`nearest_rows`] with a guess per query (any data row index, e.g. the
/// previous iteration's answer in ZoomOut or ICP). A good guess lets the
/// search discard more rows early; the answer is the same exact nearest
/// row whatever the guesses are (an index out of range counts as no
/// guess). Panics if the dimensions differ or `hint` is not one per query.
#[track_caller]
pub fn nearest_rows_hinted(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    hint: &[usize],
) -> Vec<usize> {
    assert_eq!(
        hint.len(),
        queries.nrows(),
        "nearest_rows_hinted: one hint per query"
    );
    search(data, queries, NnStrategy::Auto, Some(hint))
}

/// [`nearest_rows_hinted`] with a chosen strategy. A caller that knows its
/// guesses are good at every step (ICP, whose map changes little per
/// iteration) can ask for [`NnStrategy::Prefix`] below the dimension where
/// `Auto` starts using it (64): it then ranks on the leading half of the
/// coordinates. Same exact answer whatever the strategy.
#[track_caller]
pub fn nearest_rows_hinted_with(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    hint: &[usize],
    strategy: NnStrategy,
) -> Vec<usize> {
    assert_eq!(
        hint.len(),
        queries.nrows(),
        "nearest_rows_hinted_with: one hint per query"
    );
    search(data, queries, strategy, Some(hint))
}

/// [`nearest_rows_hinted_with`] on faer views of any layout (`hint`
/// optional). Where the search runs on the matrix tiles, views whose rows
/// are contiguous (column stride 1: row-major, or a leading block of a
/// row-major matrix) are read in place; other layouts and strategies copy
/// first. Same exact answer as every other entry point. Panics if the
/// dimensions differ or `hint` is not one per query.
#[track_caller]
pub fn nearest_rows_in(
    data: MatRef<'_, f64>,
    queries: MatRef<'_, f64>,
    hint: Option<&[usize]>,
    strategy: NnStrategy,
) -> Vec<usize> {
    assert_eq!(
        data.ncols(),
        queries.ncols(),
        "nearest_rows_in: dimensions differ"
    );
    if let Some(h) = hint {
        assert_eq!(
            h.len(),
            queries.nrows(),
            "nearest_rows_in: one hint per query"
        );
    }
    let (nx, d) = (data.nrows(), data.ncols());
    let tiles = match strategy {
        NnStrategy::Tiles => true,
        NnStrategy::Auto => d >= TILES_FROM && crate::tiles::available(),
        _ => false,
    };
    if tiles
        && nx > 0
        && let Some(found) = crate::tiles::search_rows(Rows::of(data), Rows::of(queries), hint)
    {
        return found;
    }
    let copy = |m: MatRef<'_, f64>| DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)]);
    let strategy = if strategy == NnStrategy::Tiles {
        NnStrategy::Brute
    } else {
        strategy
    };
    search(&copy(data), &copy(queries), strategy, hint)
}

/// The rows of a matrix, each contiguous: read in place from a view whose
/// column stride is 1, else copied row-major (in parallel).
pub(crate) struct Rows<'a> {
    ptr: *const f64,
    stride: usize,
    n: usize,
    d: usize,
    /// The copy, when one was made (`ptr` points into it).
    _owned: Vec<f64>,
    _view: std::marker::PhantomData<&'a f64>,
}

// SAFETY: `Rows` only reads, through a shared view or its own copy.
unsafe impl Send for Rows<'_> {}
// SAFETY: as above.
unsafe impl Sync for Rows<'_> {}

impl<'a> Rows<'a> {
    pub(crate) fn of(m: MatRef<'a, f64>) -> Rows<'a> {
        let (n, d) = (m.nrows(), m.ncols());
        let rs = m.row_stride();
        if n > 0 && d > 0 && m.col_stride() == 1 && rs >= d as isize {
            return Rows {
                ptr: m.as_ptr(),
                stride: rs as usize,
                n,
                d,
                _owned: Vec::new(),
                _view: std::marker::PhantomData,
            };
        }
        let owned = rows_of(m);
        Rows {
            ptr: owned.as_ptr(),
            stride: d,
            n,
            d,
            _owned: owned,
            _view: std::marker::PhantomData,
        }
    }

    /// Row count and length.
    pub(crate) fn shape(&self) -> (usize, usize) {
        (self.n, self.d)
    }

    /// Row `i`.
    #[inline(always)]
    pub(crate) fn row(&self, i: usize) -> &[f64] {
        assert!(i < self.n, "row {i} of {}", self.n);
        // SAFETY: row i's d elements are elements of the view (column
        // stride 1) or of the copy, both alive for 'a / self.
        unsafe { std::slice::from_raw_parts(self.ptr.add(i * self.stride), self.d) }
    }
}

#[track_caller]
fn search(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    strategy: NnStrategy,
    hint: Option<&[usize]>,
) -> Vec<usize> {
    assert_eq!(
        data.ncols(),
        queries.ncols(),
        "nearest_rows: dimensions differ"
    );
    let (nx, d) = (data.nrows(), data.ncols());
    if nx == 0 {
        return vec![0; queries.nrows()];
    }
    let strategy = match strategy {
        // Measured on FAUST spectral embeddings, one thread
        // (`cargo xtask bench-refine`): the tree is 3x faster than brute
        // force at d = 10 and still ahead at d = 30, slower from d ≈ 50
        // (cluster radii grow with the frequencies in the embedding). The
        // prefix search needs a good upper bound: with the previous
        // iteration's map as guesses it takes 0.048 / 0.063 s at d = 100 /
        // 150 inside ZoomOut 50:150:5 (brute force: 0.063 / 0.086);
        // without guesses, on a noisy initial map, 3x longer than brute
        // force; and at d < 64 (d = 55: 0.080 s against 0.045), where the
        // prefix is most of the work and early ZoomOut maps are noisy.
        NnStrategy::Auto if d >= TILES_FROM && crate::tiles::available() => NnStrategy::Tiles,
        NnStrategy::Auto => {
            let prefix =
                (1024..=PREFIX_MAX_ROWS).contains(&nx) && d >= PREFIX_FROM && hint.is_some();
            if prefix {
                NnStrategy::Prefix
            } else if (1..=TREE_MAX_DIM).contains(&d)
                && nx >= 4 * LEAF_DATA
                && queries.nrows() >= 2 * LEAF_QUERY
            {
                NnStrategy::Tree
            } else {
                NnStrategy::Brute
            }
        }
        s => s,
    };
    if strategy == NnStrategy::Tiles
        && let Some(found) = crate::tiles::search(data, queries, hint)
    {
        return found;
    }
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
        _ => {}
    }
    brute_search(data, queries)
}

/// Every query against every data row: blocked f32 GEMMs select the rows
/// within [`score_err`]'s band of the best score, re-checked in f64.
/// Exact at any scale (the band covers underflow); fast where the
/// coordinates are well inside f32's range.
fn brute_search(data: &DMatrix<f64>, queries: &DMatrix<f64>) -> Vec<usize> {
    let (nx, d) = (data.nrows(), data.ncols());
    // Row-major copies: each row contiguous, for the direct re-checks.
    let x_rows = row_major(data, None);
    let x_norm: Vec<f64> = x_rows
        .chunks(d.max(1))
        .map(|r| r.iter().map(|v| v * v).sum())
        .collect();
    let x_norm_max = x_norm.iter().fold(0.0f64, |a, &b| a.max(b));
    let x32: Vec<f32> = data.as_slice().iter().map(|&v| v as f32).collect();
    let x_mat = MatRef::from_column_major_slice(&x32, nx, d);
    let q_rows = row_major(queries, None);
    let nq = queries.nrows();
    let starts: Vec<usize> = (0..nq).step_by(BLOCK).collect();
    let blocks: Vec<Vec<usize>> = starts
        .par_iter()
        .map_init(
            || Mat::<f32>::zeros(nx, BLOCK),
            |buf, &q0| {
                let rows = BLOCK.min(nq - q0);
                let q = Mat::<f32>::from_fn(rows, d, |i, j| queries[(q0 + i, j)] as f32);
                // Sᵀ = X Qᵀ (nx x rows): column i holds query i's cross
                // terms, contiguous for the scans.
                matmul(
                    buf.as_mut().subcols_mut(0, rows),
                    Accum::Replace,
                    x_mat,
                    q.transpose(),
                    1.0f32,
                    Par::Seq,
                );
                let mut out = Vec::with_capacity(rows);
                for i in 0..rows {
                    let qi = &q_rows[(q0 + i) * d..(q0 + i + 1) * d];
                    let q_norm: f64 = qi.iter().map(|v| v * v).sum();
                    let band = 4.0 * score_err(d, q_norm, x_norm_max);
                    let col = &buf.col_as_slice(i)[..nx];
                    out.push(brute_query(&x_rows, &x_norm, col, qi, band));
                }
                out
            },
        )
        .collect();
    blocks.into_iter().flatten().collect()
}

/// A bound on the error of a score `|x|² − 2 q·x` whose cross term is
/// computed from f32 copies of `q` and `x` by a length-`d` f32 dot product
/// (`q_norm` = |q|², `x_norm_max` ≥ |x|²), with the norms exact:
/// relative rounding, `(d + 2) u |q||x|` for the dot product (u = 2⁻²⁴),
/// twice, folded with `2|q||x| ≤ |q|² + |x|²`; and the absolute errors that
/// relative rounding does not cover, each at most f32's smallest normal λ
/// (flushed to zero or gradually underflowed): coordinates converted below
/// the normal range (`√d λ (|q| + |x|)`), products and partial sums (`2 d
/// λ`), twice, plus a margin.
fn score_err(d: usize, q_norm: f64, x_norm_max: f64) -> f64 {
    let u = f64::from(f32::EPSILON) / 2.0;
    let tiny = f64::from(f32::MIN_POSITIVE);
    let df = d as f64;
    (df + 2.0) * u * (q_norm + x_norm_max)
        + 2.0 * tiny * (df.sqrt() * (q_norm.sqrt() + x_norm_max.sqrt()) + 2.0 * df + 4.0)
}

/// Largest magnitude [`power_of_two_scale`] leaves alone (2³⁰), and its
/// reciprocal the smallest.
const F32_COMFORT: f64 = 1_073_741_824.0;

/// A power of two that brings the largest finite coordinate magnitude of
/// both sets into [1, 2) (at most 2¹⁰⁰⁰: subnormal ones stay below), when it lies outside [2⁻³⁰, 2³⁰] (else `None`:
/// the common case costs one pass over the data). Exact in f64: the
/// scaled distances are the original ones times the square of the scale,
/// wherever neither underflows (coordinates more than 2⁵⁰⁰ below the
/// largest).
fn power_of_two_scale(data: &DMatrix<f64>, queries: &DMatrix<f64>) -> Option<f64> {
    let max = data
        .iter()
        .chain(queries.iter())
        .filter(|v| v.is_finite())
        .fold(0.0f64, |a, &b| a.max(b.abs()));
    if max == 0.0 || (1.0 / F32_COMFORT..=F32_COMFORT).contains(&max) {
        return None;
    }
    // max = m 2^e with m in [1, 2): scale by 2^-e, at most by 2^1000 (a
    // subnormal max then lands near 2^-60, still far inside f32's range).
    let biased = ((max.to_bits() >> 52) & 0x7ff) as i32;
    let e = (biased - 1023).max(-1000);
    Some(2f64.powi(-e))
}

dispatched! {
    /// The nearest row to `qi` given its cross terms `col` (f32) with every
    /// row: every row whose score `|x|² − 2 q·x` is within `band` of the
    /// smallest is re-checked with a direct f64 distance.
    fn brute_query(x_rows: &[f64], x_norm: &[f64], col: &[f32], qi: &[f64], band: f64) -> usize {
        let d = qi.len();
        let mut best = f64::INFINITY;
        for (xn, c) in x_norm.iter().zip(col) {
            best = best.min(xn - 2.0 * f64::from(*c));
        }
        let mut arg = usize::MAX;
        let mut best_d = f64::INFINITY;
        for (k, (xn, c)) in x_norm.iter().zip(col).enumerate() {
            if xn - 2.0 * f64::from(*c) <= best + band
                && let Some(dist) = dist2_below(&x_rows[k * d..(k + 1) * d], qi, best_d)
                && dist < best_d
            {
                best_d = dist;
                arg = k;
            }
        }
        arg
    }
}

/// Smallest dimension [`NnStrategy::Auto`] uses the matrix tiles from
/// (where they are available). Below, the tiles pad every row to 32
/// coordinates and the tree is about as fast (measured on FAUST
/// embeddings, one thread, `cargo xtask bench-refine --nn-only` and the
/// `nn_profile` example: tiles 0.0103 s against the tree's 0.0130 at
/// d = 10, within ±30% either way at d = 4-8; at d = 30, 0.0099 against
/// 0.0364).
const TILES_FROM: usize = 16;

/// Largest dimension [`NnStrategy::Auto`] uses the tree for.
const TREE_MAX_DIM: usize = 48;
/// Data rows per cluster.
const LEAF_DATA: usize = 64;
/// Query rows per cluster.
const LEAF_QUERY: usize = 128;

/// A partition of points (rows) into clusters of at most `leaf` rows by
/// recursive median splits along the principal direction.
struct Clusters {
    /// Point indices, cluster by cluster.
    order: Vec<usize>,
    /// (start, len) of each cluster in `order`.
    ranges: Vec<(usize, usize)>,
    /// Cluster means, row-major (m x d).
    centers: Vec<f64>,
    /// Largest distance from a cluster's mean to its points (rounded up).
    radii: Vec<f64>,
}

fn clusters(rows: &[f64], d: usize, leaf: usize) -> Clusters {
    let n = rows.len() / d;
    let mut order: Vec<usize> = (0..n).collect();
    let ranges = split(rows, d, &mut order, 0, leaf);
    let mut centers = vec![0.0; ranges.len() * d];
    let mut radii = vec![0.0; ranges.len()];
    for (c, &(start, len)) in ranges.iter().enumerate() {
        let mean = &mut centers[c * d..(c + 1) * d];
        for &i in &order[start..start + len] {
            for (m, x) in mean.iter_mut().zip(&rows[i * d..(i + 1) * d]) {
                *m += x;
            }
        }
        mean.iter_mut().for_each(|m| *m /= len as f64);
        let r2 = order[start..start + len]
            .iter()
            .map(|&i| dist2(&rows[i * d..(i + 1) * d], mean))
            .fold(0.0f64, f64::max);
        radii[c] = r2.sqrt() * (1.0 + 1e-12) + 1e-300;
    }
    Clusters {
        order,
        ranges,
        centers,
        radii,
    }
}

/// `|a − b|²` in f64, summed in eight lanes (vectorised). Every strategy
/// decides with this one function, so all return the same row.
#[inline(always)]
fn dist2(a: &[f64], b: &[f64]) -> f64 {
    dist2_below(a, b, f64::INFINITY).unwrap_or(f64::NAN)
}

/// Smallest dimension [`NnStrategy::Auto`] uses the prefix search from
/// (with guesses).
const PREFIX_FROM: usize = 64;
/// Largest data size [`NnStrategy::Auto`] uses the prefix search for: on
/// the 80k-vertex subdivided FAUST pair, 12% of the rows pass the prefix
/// bar at k = 200 (2-5% at 5k) and brute force is twice as fast.
const PREFIX_MAX_ROWS: usize = 20_000;

/// The prefix search ([`NnStrategy::Prefix`]). Per block of queries, one
/// f32 GEMM over the leading `m` coordinates gives every pair's partial
/// score `|x_m|² − 2 q_m·x_m`, within a rigorous rounding bound `e` of its
/// exact value. With `ub` the full f64 distance to the best-ranked row (or
/// to the hint, if smaller), the nearest row x* satisfies
/// `|q_m − x*_m|² ≤ |q − x*|² ≤ ub`, so its computed score is at most
/// `ub − |q_m|² + e`: only rows under that bar get a full distance.
fn prefix_search(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    hint: Option<&[usize]>,
) -> Vec<usize> {
    prefix_search_with(data, queries, hint, UNION_DENSITY)
}

/// [`prefix_search`] with the union-GEMM switch as a parameter (tests
/// force either path).
fn prefix_search_with(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    hint: Option<&[usize]>,
    union_density: usize,
) -> Vec<usize> {
    let (nx, d, nq) = (data.nrows(), data.ncols(), queries.nrows());
    let m = prefix_width(d);
    // Both sets in a spatially coherent order (principal-direction
    // bisection on the prefix): consecutive queries then share most of
    // their surviving rows, which stay in cache, contiguous.
    let prefix_rows = |a: &DMatrix<f64>| -> Vec<f64> {
        let n = a.nrows();
        let mut out = vec![0.0; n * m];
        for j in 0..m {
            for (i, v) in a.column(j).iter().enumerate() {
                out[i * m + j] = *v;
            }
        }
        out
    };
    let (order_x, order_q) = rayon::join(
        || {
            let mut o: Vec<usize> = (0..nx).collect();
            split(&prefix_rows(data), m, &mut o, 0, ORDER_LEAF);
            o
        },
        || {
            let mut o: Vec<usize> = (0..nq).collect();
            split(&prefix_rows(queries), m, &mut o, 0, ORDER_LEAF);
            o
        },
    );
    let mut pos_x = vec![0usize; nx];
    for (p, &i) in order_x.iter().enumerate() {
        pos_x[i] = p;
    }
    let x_rows = row_major(data, Some(&order_x));
    let q_rows = row_major(queries, Some(&order_q));
    let xm_norm: Vec<f64> = x_rows
        .chunks(d)
        .map(|r| r[..m].iter().map(|v| v * v).sum())
        .collect();
    let xm_norm_max = xm_norm.iter().fold(0.0f64, |a, &b| a.max(b));
    let x_norm: Vec<f64> = x_rows
        .chunks(d)
        .map(|r| r.iter().map(|v| v * v).sum())
        .collect();
    let ctx = Prefix {
        d,
        m,
        union_density,
        x_norm_max: x_norm.iter().fold(0.0f64, |a, &b| a.max(b)),
        x_norm,
        xn32: xm_norm.iter().map(|&v| v as f32).collect(),
        // Column by column (each column of `data` stays in cache).
        x32: Mat::<f32>::from_fn(nx, m, |p, j| data[(order_x[p], j)] as f32),
        x_rows,
        xm_norm_max,
        q_rows,
        order_x,
        pos_x,
        hint: hint.map(|h| {
            order_q
                .iter()
                .map(|&i| h.get(i).copied().unwrap_or(usize::MAX))
                .collect()
        }),
    };
    let starts: Vec<usize> = (0..nq).step_by(PREFIX_BLOCK).collect();
    let found: Vec<Vec<usize>> = starts
        .par_iter()
        .map_init(
            || PrefixWork {
                s: Mat::<f32>::zeros(nx, PREFIX_BLOCK),
                slot: vec![u32::MAX; nx],
            },
            |work, &q0| {
                let rows = PREFIX_BLOCK.min(nq - q0);
                let q = Mat::<f32>::from_fn(rows, m, |i, j| ctx.q_rows[(q0 + i) * d + j] as f32);
                matmul(
                    work.s.as_mut().subcols_mut(0, rows),
                    Accum::Replace,
                    ctx.x32.as_ref(),
                    q.transpose(),
                    1.0f32,
                    Par::Seq,
                );
                prefix_block(&ctx, q0, rows, work)
            },
        )
        .collect();
    let mut out = vec![0; nq];
    for (p, x) in found.into_iter().flatten().enumerate() {
        out[order_q[p]] = x;
    }
    out
}

/// The prefix search's data, both sets in their coherent order.
struct Prefix {
    d: usize,
    m: usize,
    /// Data rows (f64, row-major), their prefix in f32 (column-major) and
    /// the squared norms of the prefixes.
    x_rows: Vec<f64>,
    x32: Mat<f32>,
    xn32: Vec<f32>,
    xm_norm_max: f64,
    /// Scores a block's union of candidates by GEMM when it holds at most
    /// this many times the candidate pairs.
    union_density: usize,
    /// Squared norms of the data rows (f64) and their largest value.
    x_norm: Vec<f64>,
    x_norm_max: f64,
    /// Query rows (f64, row-major).
    q_rows: Vec<f64>,
    /// Original index of each data position, and its inverse.
    order_x: Vec<usize>,
    pos_x: Vec<usize>,
    /// Original data index guessed for each query position.
    hint: Option<Vec<usize>>,
}

/// Per-thread buffers of the prefix search.
struct PrefixWork {
    /// Prefix scores of a block (nx x PREFIX_BLOCK).
    s: Mat<f32>,
    /// Position of a data row in the block's union of candidates
    /// (`u32::MAX` when not in it).
    slot: Vec<u32>,
}

dispatched! {
    /// The nearest rows (original indices) of queries `q0..q0 + rows`
    /// given their prefix scores in the first columns of `work.s` (f32,
    /// one column per query).
    ///
    /// Per query: exact distances to the guess (else the best-ranked row),
    /// to the previous query's answer and to the 16 best-ranked rows give
    /// an upper bound `ub`; the candidates are the rows whose prefix score
    /// is under the bar it sets. When the candidates of the block are
    /// dense in their union, the union's full scores are one more f32 GEMM
    /// (then, as in brute force, candidates within the rounding band of a
    /// query's best are re-checked in f64); else each candidate's f64
    /// distance is computed directly.
    fn prefix_block(this: &Prefix, q0: usize, rows: usize, work: &mut PrefixWork) -> Vec<usize> {
        let (d, m, nx) = (this.d, this.m, this.xn32.len());
        let mut last = usize::MAX;
        let mut cand: Vec<(f32, u32)> = Vec::new();
        // Candidates of every query (flat, with offsets) and the best row
        // found so far (distance, original index): ties go to the smaller
        // original index, as in every strategy.
        let mut flat: Vec<u32> = Vec::new();
        let mut offsets = vec![0usize];
        let mut bests = Vec::with_capacity(rows);
        #[inline(always)]
        fn consider(this: &Prefix, qi: &[f64], p: usize, best: &mut (f64, usize)) {
            let d = this.d;
            if let Some(dk) = dist2_below(&this.x_rows[p * d..(p + 1) * d], qi, best.0)
                && (dk < best.0 || this.order_x[p] < best.1)
            {
                *best = (dk, this.order_x[p]);
            }
        }
        for i in 0..rows {
            let qi = &this.q_rows[(q0 + i) * d..(q0 + i + 1) * d];
            let qm_norm: f64 = qi[..m].iter().map(|v| v * v).sum();
            let col = &work.s.col_as_slice(i)[..nx];
            // Rounding of a computed score: the f32 inputs and dot product
            // ([`score_err`]), |x_m|² to f32 and the subtraction (three
            // more roundings, at most one more flush); doubled for safety.
            let err = 2.0 * score_err(m + 3, qm_norm, this.xm_norm_max);
            let bar = |ub: f64| {
                let bar = ub * (1.0 + 1e-12) - qm_norm + err;
                let b32 = bar as f32;
                if f64::from(b32) < bar { b32.next_up() } else { b32 }
            };
            let mut best = (f64::INFINITY, usize::MAX);
            let consider = |p: usize, best: &mut (f64, usize)| consider(this, qi, p, best);
            // Upper bounds: the guess, else the best-ranked row; and the
            // previous query's answer (the queries are in coherent order,
            // so it is usually close).
            match this.hint.as_ref().map(|h| h[q0 + i]) {
                Some(h) if h < nx => consider(this.pos_x[h], &mut best),
                _ => consider(argmin_score(&this.xn32, col), &mut best),
            }
            if last < nx {
                consider(last, &mut best);
            }
            cand.clear();
            for_each_under(&this.xn32, col, bar(best.0), |p, score| {
                cand.push((score, p as u32))
            });
            // The best-ranked few first: their distances lower the bar for
            // all the others.
            if cand.len() > FIRST {
                cand.select_nth_unstable_by(FIRST, |a, b| a.0.total_cmp(&b.0));
                for &(_, p) in &cand[..FIRST] {
                    consider(p as usize, &mut best);
                }
            }
            let b = bar(best.0);
            flat.extend(cand.iter().filter(|c| c.0 <= b).map(|c| c.1));
            offsets.push(flat.len());
            bests.push(best);
            last = this.pos_x.get(best.1).copied().unwrap_or(usize::MAX);
        }
        // The union of the block's candidates.
        let mut union: Vec<u32> = Vec::new();
        for &p in &flat {
            if work.slot[p as usize] == u32::MAX {
                work.slot[p as usize] = 0;
                union.push(p);
            }
        }
        let dense = union.len() * rows <= this.union_density * flat.len();
        if dense {
            union.sort_unstable();
            for (r, &p) in union.iter().enumerate() {
                work.slot[p as usize] = r as u32;
            }
            let nu = union.len();
            // Gathered row by row (contiguous reads).
            let mut xu = vec![0.0f32; nu * d];
            for (dst, &p) in xu.chunks_exact_mut(d).zip(&union) {
                let src = &this.x_rows[p as usize * d..(p as usize + 1) * d];
                dst.iter_mut().zip(src).for_each(|(a, b)| *a = *b as f32);
            }
            let xu = MatRef::from_row_major_slice(&xu, nu, d);
            let q = Mat::<f32>::from_fn(rows, d, |i, j| this.q_rows[(q0 + i) * d + j] as f32);
            let mut full = Mat::<f32>::zeros(nu, rows);
            matmul(full.as_mut(), Accum::Replace, xu, q.transpose(), 1.0f32, Par::Seq);
            for (i, best) in bests.iter_mut().enumerate() {
                let qi = &this.q_rows[(q0 + i) * d..(q0 + i + 1) * d];
                let q_norm: f64 = qi.iter().map(|v| v * v).sum();
                let col = full.col_as_slice(i);
                let cands = &flat[offsets[i]..offsets[i + 1]];
                let score = |p: u32| this.x_norm[p as usize] - 2.0 * f64::from(col[work.slot[p as usize] as usize]);
                let low = cands.iter().map(|&p| score(p)).fold(f64::INFINITY, f64::min);
                let band = 4.0 * score_err(d, q_norm, this.x_norm_max);
                for &p in cands {
                    if score(p) <= low + band {
                        consider(this, qi, p as usize, best);
                    }
                }
            }
        } else {
            for (i, best) in bests.iter_mut().enumerate() {
                let qi = &this.q_rows[(q0 + i) * d..(q0 + i + 1) * d];
                for &p in &flat[offsets[i]..offsets[i + 1]] {
                    consider(this, qi, p as usize, best);
                }
            }
        }
        for &p in &union {
            work.slot[p as usize] = u32::MAX;
        }
        bests.into_iter().map(|b| b.1).collect()
    }
}

/// The prefix search scores a block's union of candidates with a GEMM
/// when it holds at most this many times the candidate pairs.
const UNION_DENSITY: usize = 8;

/// The rows of `m` (in `order` when given), row-major. Tiles of 64 rows
/// keep both the column reads and the row writes in cache.
pub(crate) fn row_major(m: &DMatrix<f64>, order: Option<&[usize]>) -> Vec<f64> {
    let (n, d) = m.shape();
    let t = rows_of(MatRef::from_column_major_slice(m.as_slice(), n, d));
    match order {
        None => t,
        Some(order) => {
            let mut out = vec![0.0; n * d];
            for (dst, &i) in out.chunks_exact_mut(d.max(1)).zip(order) {
                dst.copy_from_slice(&t[i * d..(i + 1) * d]);
            }
            out
        }
    }
}

/// The rows of a view, copied row-major: tiles of 8 rows (one cache line
/// of each column when the columns are contiguous; the tile stays in L1),
/// in parallel over blocks of tiles.
fn rows_of(m: MatRef<'_, f64>) -> Vec<f64> {
    let (n, d) = (m.nrows(), m.ncols());
    let mut out = vec![0.0; n * d];
    if d == 0 {
        return out;
    }
    let cols: Vec<Option<&[f64]>> = (0..d)
        .map(|j| m.col(j).try_as_col_major().map(|c| c.as_slice()))
        .collect();
    out.par_chunks_mut(512 * d)
        .enumerate()
        .for_each(|(b, block)| {
            for (t, tile) in block.chunks_mut(8 * d).enumerate() {
                let i0 = b * 512 + t * 8;
                let rows = tile.len() / d;
                for (j, col) in cols.iter().enumerate() {
                    match col {
                        Some(c) => {
                            for (i, v) in c[i0..i0 + rows].iter().enumerate() {
                                tile[i * d + j] = *v;
                            }
                        }
                        None => {
                            for i in 0..rows {
                                tile[i * d + j] = m[(i0 + i, j)];
                            }
                        }
                    }
                }
            }
        });
    out
}

/// Points per leaf of the bisection that orders both sets.
const ORDER_LEAF: usize = 64;
/// Queries per block of the prefix search.
const PREFIX_BLOCK: usize = 128;

/// Candidates of the prefix search whose distance is computed before the
/// bar is lowered.
const FIRST: usize = 16;

#[inline(always)]
/// [`dist2`] when it is at most `bound`, else `None` (possibly decided
/// early: partial sums only grow, and are rounded no higher than the full
/// sum, so a partial sum above the bound proves the full one is).
pub(crate) fn dist2_below(a: &[f64], b: &[f64], bound: f64) -> Option<f64> {
    let n = a.len().min(b.len());
    let mut lanes = [0.0f64; 8];
    let total = |l: &[f64; 8]| ((l[0] + l[4]) + (l[1] + l[5])) + ((l[2] + l[6]) + (l[3] + l[7]));
    let mut i = 0;
    // 32 coordinates per step (lane j takes j, j + 8, ...: the order of
    // eight-wide chunks), then a check against the bound.
    while i + 32 <= n {
        let (x, y) = (&a[i..i + 32], &b[i..i + 32]);
        for c in 0..4 {
            for j in 0..8 {
                let t = x[c * 8 + j] - y[c * 8 + j];
                lanes[j] += t * t;
            }
        }
        if total(&lanes) > bound {
            return None;
        }
        i += 32;
    }
    while i + 8 <= n {
        let (x, y) = (&a[i..i + 8], &b[i..i + 8]);
        for j in 0..8 {
            let t = x[j] - y[j];
            lanes[j] += t * t;
        }
        i += 8;
    }
    for j in 0..n - i {
        let t = a[i + j] - b[i + j];
        lanes[j] += t * t;
    }
    let d = total(&lanes);
    (d <= bound).then_some(d)
}

/// The index of the smallest score `xn[k] − 2 col[k]` (f32; used only as
/// a candidate, so its own rounding does not matter).
#[inline(always)]
fn argmin_score(xn: &[f32], col: &[f32]) -> usize {
    const L: usize = 16;
    let mut val = [f32::INFINITY; L];
    let mut idx = [0u32; L];
    let (cx, cc) = (xn.chunks_exact(L), col.chunks_exact(L));
    let n = col.len() - cc.remainder().len();
    for (c, (x, v)) in cx.zip(cc).enumerate() {
        let base = (c * L) as u32;
        for j in 0..L {
            let s = x[j] - 2.0 * v[j];
            let better = s < val[j];
            val[j] = if better { s } else { val[j] };
            idx[j] = if better { base + j as u32 } else { idx[j] };
        }
    }
    let mut best = (f32::INFINITY, 0usize);
    for j in 0..L {
        if val[j] < best.0 {
            best = (val[j], idx[j] as usize);
        }
    }
    for k in n..col.len() {
        let s = xn[k] - 2.0 * col[k];
        if s < best.0 {
            best = (s, k);
        }
    }
    best.1
}

/// Calls `f(k, score)` for every k (ascending) with score
/// `xn[k] − 2 col[k] <= bar`, testing 16 rows per step.
#[inline(always)]
fn for_each_under(xn: &[f32], col: &[f32], bar: f32, mut f: impl FnMut(usize, f32)) {
    const L: usize = 16;
    let (cx, cc) = (xn.chunks_exact(L), col.chunks_exact(L));
    let n = col.len() - cc.remainder().len();
    for (c, (x, v)) in cx.zip(cc).enumerate() {
        let mut score = [0.0f32; L];
        let mut mask = 0u32;
        for j in 0..L {
            score[j] = x[j] - 2.0 * v[j];
            mask |= u32::from(score[j] <= bar) << j;
        }
        while mask != 0 {
            let j = mask.trailing_zeros() as usize;
            f(c * L + j, score[j]);
            mask &= mask - 1;
        }
    }
    for k in n..col.len() {
        let score = xn[k] - 2.0 * col[k];
        if score <= bar {
            f(k, score);
        }
    }
}

/// Splits `idx` (points `offset..offset + idx.len()` of the final order)
/// at the median of the projections on the principal direction (two power
/// iterations from the direction of the point farthest from the mean).
fn split(
    rows: &[f64],
    d: usize,
    idx: &mut [usize],
    offset: usize,
    leaf: usize,
) -> Vec<(usize, usize)> {
    let n = idx.len();
    if n <= leaf {
        return vec![(offset, n)];
    }
    let row = |i: usize| &rows[i * d..(i + 1) * d];
    let mut mean = vec![0.0; d];
    for &i in idx.iter() {
        mean.iter_mut().zip(row(i)).for_each(|(m, x)| *m += x);
    }
    mean.iter_mut().for_each(|m| *m /= n as f64);
    let far = idx
        .iter()
        .map(|&i| (dist2(row(i), &mean), i))
        .fold((-1.0, 0), |a, b| if b.0 > a.0 { b } else { a })
        .1;
    let mut v: Vec<f64> = row(far).iter().zip(&mean).map(|(x, m)| x - m).collect();
    for _ in 0..2 {
        let mut w = vec![0.0; d];
        for &i in idx.iter() {
            let t: f64 = row(i)
                .iter()
                .zip(&mean)
                .zip(&v)
                .map(|((x, m), v)| (x - m) * v)
                .sum();
            w.iter_mut()
                .zip(row(i))
                .zip(&mean)
                .for_each(|((w, x), m)| *w += t * (x - m));
        }
        let norm = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm == 0.0 {
            break;
        }
        v = w.into_iter().map(|x| x / norm).collect();
    }
    let mut keyed: Vec<(f64, usize)> = idx
        .iter()
        .map(|&i| (row(i).iter().zip(&v).map(|(x, v)| x * v).sum(), i))
        .collect();
    let mid = n / 2;
    keyed.select_nth_unstable_by(mid, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    for (slot, (_, i)) in idx.iter_mut().zip(keyed) {
        *slot = i;
    }
    let (left, right) = idx.split_at_mut(mid);
    let (mut l, r) = if n > 8192 {
        rayon::join(
            || split(rows, d, left, offset, leaf),
            || split(rows, d, right, offset + mid, leaf),
        )
    } else {
        (
            split(rows, d, left, offset, leaf),
            split(rows, d, right, offset + mid, leaf),
        )
    };
    l.extend(r);
    l
}

/// The clustered exact search. Per query cluster: lower bounds
/// `(|q − c_j| − r_j)₊` for every data cluster j (one f64 GEMM against the
/// centres), data clusters visited in increasing order of their smallest
/// bound, each one skipped when no query of the block can have its
/// nearest point there (bound² above the query's current upper bound) and
/// the loop left once the smallest remaining bound exceeds every upper
/// bound. Visited clusters are scored with one f32 GEMM; candidates within
/// the rounding band are re-checked in f64 as in the brute-force search.
fn tree_search(data: &DMatrix<f64>, queries: &DMatrix<f64>) -> Vec<usize> {
    let (nx, d, nq) = (data.nrows(), data.ncols(), queries.nrows());
    let x_rows = row_major(data, None);
    let q_rows = row_major(queries, None);
    let (cx, cq) = rayon::join(
        || clusters(&x_rows, d, LEAF_DATA),
        || clusters(&q_rows, d, LEAF_QUERY),
    );
    let x_norm: Vec<f64> = cx
        .order
        .iter()
        .map(|&i| x_rows[i * d..(i + 1) * d].iter().map(|v| v * v).sum())
        .collect();
    let x_norm_max = x_norm.iter().fold(0.0f64, |a, &b| a.max(b));
    let x32 = Mat::<f32>::from_fn(nx, d, |i, j| x_rows[cx.order[i] * d + j] as f32);
    let m = cx.ranges.len();
    let centers = MatRef::from_row_major_slice(&cx.centers, m, d);
    let c_norm: Vec<f64> = cx
        .centers
        .chunks(d)
        .map(|c| c.iter().map(|v| v * v).sum())
        .collect();
    let per_block: Vec<Vec<(usize, usize)>> = cq
        .ranges
        .par_iter()
        .map(|&(start, len)| {
            let qi: &[usize] = &cq.order[start..start + len];
            let q64 = Mat::<f64>::from_fn(len, d, |i, j| q_rows[qi[i] * d + j]);
            let q32 = Mat::<f32>::from_fn(len, d, |i, j| q64[(i, j)] as f32);
            let q_norm: Vec<f64> = (0..len)
                .map(|i| (0..d).map(|j| q64[(i, j)] * q64[(i, j)]).sum())
                .collect();
            // Lower bounds to every data cluster (len x m).
            let mut g = Mat::<f64>::zeros(len, m);
            matmul(
                g.as_mut(),
                Accum::Replace,
                q64.as_ref(),
                centers.transpose(),
                1.0,
                Par::Seq,
            );
            let lb = Mat::<f64>::from_fn(len, m, |i, j| {
                let s = q_norm[i] + c_norm[j];
                let d2 = (s - 2.0 * g[(i, j)] - 1e-12 * s).max(0.0);
                (d2.sqrt() - cx.radii[j]).max(0.0).powi(2)
            });
            let mut visit: Vec<(f64, usize)> = (0..m)
                .map(|j| {
                    (
                        (0..len).map(|i| lb[(i, j)]).fold(f64::INFINITY, f64::min),
                        j,
                    )
                })
                .collect();
            visit.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            // Rounding error of a score, and the band kept for re-checks.
            let err: Vec<f64> = q_norm
                .iter()
                .map(|&qn| score_err(d, qn, x_norm_max))
                .collect();
            let mut best = vec![f64::INFINITY; len];
            let mut upper = vec![f64::INFINITY; len];
            let mut cand: Vec<Vec<(usize, f64)>> = vec![Vec::new(); len];
            let mut s = Mat::<f32>::zeros(LEAF_DATA, len);
            for &(lb_min, j) in &visit {
                let worst = upper.iter().fold(0.0f64, |a, &b| a.max(b));
                if lb_min > worst {
                    break;
                }
                if !(0..len).any(|i| lb[(i, j)] <= upper[i]) {
                    continue;
                }
                let (x0, lx) = cx.ranges[j];
                matmul(
                    s.as_mut().submatrix_mut(0, 0, lx, len),
                    Accum::Replace,
                    x32.as_ref().subrows(x0, lx),
                    q32.transpose(),
                    1.0f32,
                    Par::Seq,
                );
                for i in 0..len {
                    let col = &s.col_as_slice(i)[..lx];
                    let band = 4.0 * err[i];
                    for t in 0..lx {
                        let score = x_norm[x0 + t] - 2.0 * f64::from(col[t]);
                        if score <= best[i] + band {
                            cand[i].push((x0 + t, score));
                            if score < best[i] {
                                best[i] = score;
                            }
                        }
                    }
                    upper[i] = best[i] + q_norm[i] + 2.0 * err[i];
                }
            }
            (0..len)
                .map(|i| {
                    let q = &q_rows[qi[i] * d..(qi[i] + 1) * d];
                    let band = 4.0 * err[i];
                    let mut arg = (f64::INFINITY, usize::MAX);
                    for &(pos, score) in &cand[i] {
                        if score <= best[i] + band {
                            let x = cx.order[pos];
                            let dist = dist2(&x_rows[x * d..(x + 1) * d], q);
                            if dist < arg.0 || (dist == arg.0 && x < arg.1) {
                                arg = (dist, x);
                            }
                        }
                    }
                    (qi[i], arg.1)
                })
                .collect()
        })
        .collect();
    let mut out = vec![0; nq];
    for (q, x) in per_block.into_iter().flatten() {
        out[q] = x;
    }
    out
}

/// Runtime detection of the vector instructions the kernels are compiled
/// for (the build targets baseline x86-64; faer's GEMMs dispatch on their
/// own). Every level runs the same code, so computes the same values: no
/// FMA contraction, the same summation order.
#[cfg(target_arch = "x86_64")]
mod simd {
    use std::sync::OnceLock;

    /// AVX-512 (F, BW, VL) with AVX2 and FMA.
    pub fn has_v4() -> bool {
        static V4: OnceLock<bool> = OnceLock::new();
        *V4.get_or_init(|| {
            std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512bw")
                && std::arch::is_x86_feature_detected!("avx512vl")
                && has_v3()
        })
    }

    /// AVX2 with FMA, BMI and the bit-count instructions.
    pub fn has_v3() -> bool {
        static V3: OnceLock<bool> = OnceLock::new();
        *V3.get_or_init(|| {
            std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
                && std::arch::is_x86_feature_detected!("bmi1")
                && std::arch::is_x86_feature_detected!("bmi2")
                && std::arch::is_x86_feature_detected!("popcnt")
                && std::arch::is_x86_feature_detected!("lzcnt")
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both ways of scoring the prefix search's candidates (per candidate,
    /// and one GEMM over the block's union) return the brute-force answer,
    /// with and without guesses, on points near a curved 2-manifold in
    /// R^70 (as spectral embeddings are) whose spread decays with the
    /// coordinate.
    #[test]
    fn prefix_search_paths_equal_brute_force() {
        let (n, d) = (1500, 70);
        let x = DMatrix::from_fn(n, d, |i, j| {
            let (u, v) = ((i % 50) as f64 / 50.0, (i / 50) as f64 / 30.0);
            let f = 1.0 + j as f64;
            (f * u * 3.1 + (j as f64) * 0.7).sin() * (f * v * 2.3).cos() / f.sqrt()
        });
        let q = DMatrix::from_fn(700, d, |i, j| {
            let r = (i * 7 + 3) % n;
            x[(r, j)] + 0.03 * ((i * 13 + j * 5) as f64).sin() / (1.0 + j as f64).sqrt()
        });
        let brute = nearest_rows_with(&x, &q, NnStrategy::Brute);
        let guess: Vec<usize> = brute.iter().map(|&t| (t + 1) % n).collect();
        for density in [0, 1 << 20] {
            assert_eq!(
                prefix_search_with(&x, &q, None, density),
                brute,
                "{density}"
            );
            assert_eq!(
                prefix_search_with(&x, &q, Some(&guess), density),
                brute,
                "{density}"
            );
        }
    }

    /// Naive f64 search with the strategies' own f64 distance (the same
    /// summation order, so that near-ties break alike; ties: the smallest
    /// index).
    fn naive(x: &DMatrix<f64>, q: &DMatrix<f64>) -> Vec<usize> {
        let (xr, qr, d) = (row_major(x, None), row_major(q, None), x.ncols());
        (0..q.nrows())
            .map(|i| {
                let mut best = (f64::INFINITY, 0);
                for r in 0..x.nrows() {
                    let dist = dist2(&xr[r * d..(r + 1) * d], &qr[i * d..(i + 1) * d]);
                    if dist < best.0 {
                        best = (dist, r);
                    }
                }
                best.1
            })
            .collect()
    }

    /// The f32 strategies are exact on their own, without the power-of-two
    /// scaling of [`search`], where the cross terms underflow (coordinates
    /// ~1e-29, products ~1e-57: all flush to zero, so only the band's
    /// absolute terms keep the nearest row) or where tiny coordinates sit
    /// next to ordinary ones. A band without [`score_err`]'s absolute
    /// terms returns wrong rows in the first case.
    #[test]
    fn f32_bands_cover_underflow() {
        let (nx, d) = (300, 40);
        for (offset, spread) in [(0.0, 1e-30), (0.0, 1e-42), (1.0, 1e-40)] {
            let x = DMatrix::from_fn(nx, d, |i, j| {
                offset + spread * (((i * 37 + j * 11) % 101) as f64 - 50.0)
            });
            let q = DMatrix::from_fn(120, d, |i, j| {
                offset + spread * (((i * 53 + j * 7) % 97) as f64 - 48.5)
            });
            let want = naive(&x, &q);
            assert_eq!(brute_search(&x, &q), want, "brute {offset} {spread}");
            assert_eq!(tree_search(&x, &q), want, "tree {offset} {spread}");
            assert_eq!(
                prefix_search(&x, &q, None),
                want,
                "prefix {offset} {spread}"
            );
        }
    }

    /// Far outside f32's range (coordinates 1e±30 and 1e±150: underflow
    /// and overflow of the f32 products and inputs) every strategy agrees with the naive
    /// search, through the power-of-two scaling.
    #[test]
    fn every_strategy_exact_at_extreme_scales() {
        let (nx, d) = (500, 24);
        for scale in [1e-30, 1e30, 1e-150, 1e150] {
            let x = DMatrix::from_fn(nx, d, |i, j| {
                scale * ((i * 37 + j * 11) % 101) as f64 / 101.0
            });
            let q = DMatrix::from_fn(300, d, |i, j| scale * ((i * 53 + j * 7) % 97) as f64 / 97.0);
            let want = naive(&x, &q);
            for strategy in [
                NnStrategy::Auto,
                NnStrategy::Brute,
                NnStrategy::Tree,
                NnStrategy::Prefix,
                NnStrategy::Tiles,
            ] {
                assert_eq!(
                    nearest_rows_with(&x, &q, strategy),
                    want,
                    "{strategy:?} at {scale:e}"
                );
            }
        }
        let zero = DMatrix::zeros(1, 2);
        assert_eq!(
            power_of_two_scale(&DMatrix::from_element(2, 2, 3.0), &zero),
            None
        );
        for v in [3e-300, 7e300, f64::MAX] {
            let s = power_of_two_scale(&DMatrix::from_element(2, 2, v), &zero).unwrap();
            assert!((1.0..2.0).contains(&(v * s)), "{v:e}: {}", v * s);
        }
        let s = power_of_two_scale(&DMatrix::from_element(2, 2, 5e-320), &zero).unwrap();
        assert!((1e-20..1e-15).contains(&(5e-320 * s)), "{}", 5e-320 * s);
    }
}
