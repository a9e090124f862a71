//! The brute-force search: every query against every data row.

use faer::linalg::matmul::matmul;
use std::cell::RefCell;

use faer::{Accum, Mat, MatMut, MatRef, Par};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::rows::{dist2_below, row_major};

/// Queries per block.
const BLOCK: usize = 256;

/// Data rows per panel of the fused search (sixteen f32 lanes: one
/// AVX-512 vector, two AVX2 ones).
pub(crate) const PANEL: usize = 16;
/// Queries scored together by the fused search: each panel's coordinates
/// are loaded once for all of them, and their scores (`GROUP` x rows f32)
/// stay in the first-level cache for the second scan.
pub(crate) const GROUP: usize = 4;
/// The group with AVX-512: eight accumulators of one register each keep
/// both FMA units busy (four leave them waiting on the previous sum);
/// AVX2 needs two registers per accumulator, so four fill its sixteen.
pub(crate) const WIDE_GROUP: usize = 8;
/// Queries per parallel task of the fused search.
const FUSED_BLOCK: usize = 64;
/// Widest data the fused search takes. Up to here, writing every score of
/// a 256-query block to memory and reading it back twice costs more than
/// the products; from 32 to 48 both paths measured the same, and wider
/// the GEMM's register blocking wins (crate README, "Choosing a
/// strategy").
pub(crate) const FUSED_MAX_DIM: usize = 32;

thread_local! {
    /// Per thread, the scores of one block (kept between searches: many
    /// small searches would otherwise spend their time zeroing it).
    static SCORES: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// Every query against every data row: f32 scores (by blocked GEMMs, or
/// by the fused kernel up to [`FUSED_MAX_DIM`] coordinates) select the
/// rows within a rigorous band of the best score, re-checked in f64.
/// Exact at any scale (the band covers underflow); fast where the
/// coordinates are well inside f32's range.
pub(crate) fn brute_search(data: &DMatrix<f64>, queries: &DMatrix<f64>) -> Vec<usize> {
    BruteData::new(data).search(queries)
}

/// The brute-force search's data side: prepared once, searched by any
/// number of query sets.
pub(crate) struct BruteData {
    d: usize,
    /// Rows (row-major), for the direct re-checks.
    x_rows: Vec<f64>,
    /// Squared row norms (f64 and rounded to f32) and their largest value.
    x_norm: Vec<f64>,
    x_norm32: Vec<f32>,
    x_norm_max: f64,
    /// The data in f32, column-major (n x d) (empty where the fused
    /// search runs).
    x32: Vec<f32>,
    /// For the fused search (d ≤ [`FUSED_MAX_DIM`]; else empty): the data
    /// in f32 by panels of [`PANEL`] rows, coordinate by coordinate
    /// (`[panel][coordinate][row]`), and the squared norms in f32 by
    /// panels, the last panel padded with rows of zeros whose norm is
    /// `+∞` (their score is `+∞`: never in a band).
    pub(crate) panels: Vec<f32>,
    pub(crate) panel_norms: Vec<f32>,
}

impl BruteData {
    pub(crate) fn new(data: &DMatrix<f64>) -> BruteData {
        BruteData::build(row_major(data, None), data.ncols(), Some(data.as_slice()))
    }

    /// [`BruteData::new`] of the rows `x_rows` (row-major, `d` wide).
    pub(crate) fn from_rows(x_rows: Vec<f64>, d: usize) -> BruteData {
        BruteData::build(x_rows, d, None)
    }

    /// The data side of the rows `x_rows` (row-major, `d` wide), given
    /// them column-major too where the caller has them (`col_major`).
    fn build(x_rows: Vec<f64>, d: usize, col_major: Option<&[f64]>) -> BruteData {
        let x_norm: Vec<f64> = x_rows
            .chunks(d.max(1))
            .map(|r| r.iter().map(|v| v * v).sum())
            .collect();
        let n = x_norm.len();
        let fused = n > 0 && (1..=FUSED_MAX_DIM).contains(&d);
        let (mut panels, mut panel_norms) = (Vec::new(), Vec::new());
        if fused {
            let np = n.div_ceil(PANEL);
            panels = vec![0.0f32; np * d * PANEL];
            panel_norms = vec![f32::INFINITY; np * PANEL];
            for (i, row) in x_rows.chunks_exact(d.max(1)).enumerate().take(n) {
                let (p, l) = (i / PANEL, i % PANEL);
                for (j, &v) in row.iter().enumerate() {
                    panels[(p * d + j) * PANEL + l] = v as f32;
                }
                panel_norms[i] = x_norm[i] as f32;
            }
        }
        BruteData {
            d,
            x_norm_max: x_norm.iter().fold(0.0f64, |a, &b| a.max(b)),
            x_norm32: x_norm.iter().map(|&v| v as f32).collect(),
            x_norm,
            x32: if fused {
                Vec::new()
            } else {
                // Column-major.
                match col_major {
                    Some(c) => c.iter().map(|&v| v as f32).collect(),
                    None => {
                        let mut x32 = vec![0.0f32; n * d];
                        for (i, row) in x_rows.chunks_exact(d.max(1)).enumerate().take(n) {
                            for (j, &v) in row.iter().enumerate() {
                                x32[j * n + i] = v as f32;
                            }
                        }
                        x32
                    }
                }
            },
            x_rows,
            panels,
            panel_norms,
        }
    }

    /// The fused search: per group of [`GROUP`] queries ([`WIDE_GROUP`]
    /// with AVX-512), every score `|x|² − 2 q·x` in f32 panel by panel
    /// (the products and their lane minima in registers, the scores kept
    /// for the second scan), then each query's rows within [`fused_err`]'s
    /// band of its best score re-checked in f64.
    fn search_fused(&self, queries: &DMatrix<f64>) -> Vec<usize> {
        let q_rows = row_major(queries, None);
        let blocks = self.fused_blocks(&q_rows, false);
        blocks.into_iter().flat_map(|b| b.0).collect()
    }

    /// The queries `q_rows` (row-major) by blocks of [`FUSED_BLOCK`] in
    /// parallel: each block's answers and, with `reverse`, its groups'
    /// smallest approximate squared distances to every data row (see
    /// [`BruteData::search_both`]; else empty).
    fn fused_blocks(&self, q_rows: &[f64], reverse: bool) -> Vec<(Vec<usize>, Vec<f32>)> {
        let nq = q_rows.len() / self.d;
        let np = self.x_norm.len().div_ceil(PANEL);
        let wide = wide_kernel();
        let group = if wide { WIDE_GROUP } else { GROUP };
        let starts: Vec<usize> = (0..nq).step_by(FUSED_BLOCK).collect();
        starts
            .par_iter()
            .map(|&q0| {
                let rows = q0..(q0 + FUSED_BLOCK).min(nq);
                let mut col_min = if reverse {
                    vec![f32::INFINITY; rows.len().div_ceil(group) * np * PANEL]
                } else {
                    Vec::new()
                };
                let cm = reverse.then_some(col_min.as_mut_slice());
                let found = if wide {
                    self.fused_block::<WIDE_GROUP>(q_rows, rows, cm)
                } else {
                    self.fused_block::<GROUP>(q_rows, rows, cm)
                };
                (found, col_min)
            })
            .collect()
    }

    /// [`BruteData::search_fused`] for the queries `rows` (of the
    /// row-major `q_rows`), `G` at a time.
    fn fused_block<const G: usize>(
        &self,
        q_rows: &[f64],
        rows: std::ops::Range<usize>,
        mut col_min: Option<&mut [f32]>,
    ) -> Vec<usize> {
        let (nx, d) = (self.x_norm.len(), self.d);
        let np = nx.div_ceil(PANEL);
        let mut out = Vec::with_capacity(rows.len());
        SCORES.with_borrow_mut(|buf| {
            if buf.len() < G * np * PANEL {
                buf.resize(G * np * PANEL, 0.0);
            }
            let scores = &mut buf[..G * np * PANEL];
            let mut c = [0.0f32; WIDE_GROUP * FUSED_MAX_DIM];
            let c = &mut c[..G * d];
            for g0 in rows.clone().step_by(G) {
                let gn = G.min(rows.end - g0);
                // −2q in f32 (exact doubling), coordinate by coordinate;
                // missing queries of the last group are zeros.
                c.fill(0.0);
                for g in 0..gn {
                    let qi = &q_rows[(g0 + g) * d..(g0 + g + 1) * d];
                    for (j, &v) in qi.iter().enumerate() {
                        c[j * G + g] = -2.0 * (v as f32);
                    }
                }
                let best = fused_scores::<G>(&self.panels, &self.panel_norms, d, c, scores);
                let q_norms: [f64; G] = std::array::from_fn(|g| {
                    q_rows[(g0 + g.min(gn - 1)) * d..(g0 + g.min(gn - 1) + 1) * d]
                        .iter()
                        .map(|v| v * v)
                        .sum()
                });
                if let Some(cm) = col_min.as_deref_mut() {
                    let gi = (g0 - rows.start) / G;
                    let cm = &mut cm[gi * np * PANEL..(gi + 1) * np * PANEL];
                    for (g, &qn) in q_norms.iter().enumerate().take(gn) {
                        col_min_update(
                            &scores[g * np * PANEL..(g + 1) * np * PANEL],
                            qn as f32,
                            cm,
                        );
                    }
                }
                for (g, &b) in best.iter().enumerate().take(gn) {
                    let qi = &q_rows[(g0 + g) * d..(g0 + g + 1) * d];
                    let q_norm = q_norms[g];
                    let band = 2.0 * fused_err(d, q_norm, self.x_norm_max);
                    let col = &scores[g * np * PANEL..(g + 1) * np * PANEL];
                    out.push(fused_pick(&self.x_rows, col, nx, b, qi, band));
                }
            }
        });
        out
    }

    /// [`BruteData::search`] and at once the reverse search: for each
    /// data row its nearest query row (ties to the smallest index), from
    /// the same f32 products. Each group of queries scored together
    /// ([`WIDE_GROUP`] or [`GROUP`]) keeps, per data row, the smallest of
    /// its approximate squared distances `|x|² − 2 q·x + |q|²` to the
    /// group's queries ([`col_min_update`], on the scores while they are
    /// in the first-level cache); a data row's groups within
    /// [`both_err`]'s band of its smallest are re-checked in f64, query by
    /// query ([`reverse_panel`]). `None` outside the fused search's widths
    /// or without queries.
    pub(crate) fn search_both(&self, q_rows: &[f64]) -> Option<(Vec<usize>, Vec<usize>)> {
        if self.panels.is_empty() || q_rows.is_empty() {
            return None;
        }
        let (nx, d) = (self.x_norm.len(), self.d);
        let np = nx.div_ceil(PANEL);
        let group = if wide_kernel() { WIDE_GROUP } else { GROUP };
        let blocks = self.fused_blocks(q_rows, true);
        let q_norm_max = q_rows
            .chunks_exact(d)
            .map(|r| r.iter().map(|v| v * v).sum::<f64>())
            .fold(0.0f64, f64::max);
        // Every group's smallest distances (`np * PANEL` each), group
        // after group: group `gi` holds queries `gi * group..` (the blocks
        // are whole groups but the last).
        let mins: Vec<&[f32]> = blocks
            .iter()
            .flat_map(|b| b.1.chunks_exact(np * PANEL))
            .collect();
        let ctx = Reverse {
            mins: &mins,
            group,
            x_rows: &self.x_rows,
            x_norm: &self.x_norm,
            q_rows,
            q_norm_max,
            d,
        };
        let reverse: Vec<usize> = (0..np)
            .into_par_iter()
            .flat_map_iter(|p| {
                let mut out = [usize::MAX; PANEL];
                let rows = p * PANEL..((p + 1) * PANEL).min(nx);
                reverse_panel(&ctx, p, &mut out[..rows.len()]);
                out.into_iter().take(rows.len())
            })
            .collect();
        Some((blocks.into_iter().flat_map(|b| b.0).collect(), reverse))
    }

    /// The nearest data row of every query (same width as the data).
    pub(crate) fn search(&self, queries: &DMatrix<f64>) -> Vec<usize> {
        if !self.panels.is_empty() {
            return self.search_fused(queries);
        }
        let (nx, d) = (self.x_norm.len(), self.d);
        let (x_rows, x_norm32, x_norm_max) = (&self.x_rows, &self.x_norm32, self.x_norm_max);
        let x_mat = MatRef::from_column_major_slice(&self.x32, nx, d);
        let q_rows = row_major(queries, None);
        let nq = queries.nrows();
        let starts: Vec<usize> = (0..nq).step_by(BLOCK).collect();
        let blocks: Vec<Vec<usize>> = starts
            .par_iter()
            .map(|&q0| {
                let rows = BLOCK.min(nq - q0);
                let q = Mat::<f32>::from_fn(rows, d, |i, j| queries[(q0 + i, j)] as f32);
                SCORES.with_borrow_mut(|buf| {
                    // Grown, never cleared: the product overwrites it.
                    if buf.len() < nx * rows {
                        buf.resize(nx * rows, 0.0);
                    }
                    let s = MatMut::from_column_major_slice_mut(&mut buf[..nx * rows], nx, rows);
                    // Sᵀ = X Qᵀ (nx x rows): column i holds query i's cross
                    // terms, contiguous for the scans.
                    matmul(s, Accum::Replace, x_mat, q.transpose(), 1.0f32, Par::Seq);
                    (0..rows)
                        .map(|i| {
                            let qi = &q_rows[(q0 + i) * d..(q0 + i + 1) * d];
                            let q_norm: f64 = qi.iter().map(|v| v * v).sum();
                            let band = 4.0 * score_err(d, q_norm, x_norm_max)
                                + 2.0 * scan_err(q_norm, x_norm_max);
                            let col = &buf[i * nx..(i + 1) * nx];
                            brute_query(x_rows, x_norm32, col, qi, band)
                        })
                        .collect()
                })
            })
            .collect();
        blocks.into_iter().flatten().collect()
    }
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
pub(crate) fn score_err(d: usize, q_norm: f64, x_norm_max: f64) -> f64 {
    let u = f64::from(f32::EPSILON) / 2.0;
    let tiny = f64::from(f32::MIN_POSITIVE);
    let df = d as f64;
    (df + 2.0) * u * (q_norm + x_norm_max)
        + 2.0 * tiny * (df.sqrt() * (q_norm.sqrt() + x_norm_max.sqrt()) + 2.0 * df + 4.0)
}

/// Largest magnitude [`power_of_two_scale`] leaves alone (2³⁰), and its
/// reciprocal the smallest.
pub(crate) const F32_COMFORT: f64 = 1_073_741_824.0;

/// A power of two that brings the largest finite coordinate magnitude of
/// both sets into [1, 2) (at most 2¹⁰⁰⁰: subnormal ones stay below), when
/// it lies outside [2⁻³⁰, 2³⁰] (else `None`: the common case costs one
/// pass over the data). Exact in f64: the
/// scaled distances are the original ones times the square of the scale,
/// wherever neither underflows (coordinates more than 2⁵⁰⁰ below the
/// largest).
pub(crate) fn power_of_two_scale(data: &DMatrix<f64>, queries: &DMatrix<f64>) -> Option<f64> {
    scale_for(max_abs(data).max(max_abs(queries)))
}

/// The largest finite magnitude of `m` (0 when none).
pub(crate) fn max_abs(m: &DMatrix<f64>) -> f64 {
    // Eight lanes of `v > lane ? v : lane` (vectorizes to max instructions;
    // NaN never wins); a filtered pass only when an infinity won.
    let s = m.as_slice();
    let mut lanes = [0.0f64; 8];
    let mut chunks = s.chunks_exact(8);
    for c in &mut chunks {
        for (l, v) in lanes.iter_mut().zip(c) {
            let a = v.abs();
            *l = if a > *l { a } else { *l };
        }
    }
    let mut max = chunks
        .remainder()
        .iter()
        .fold(0.0f64, |l, v| if v.abs() > l { v.abs() } else { l });
    for l in lanes {
        max = if l > max { l } else { max };
    }
    if max.is_finite() {
        max
    } else {
        s.iter()
            .filter(|v| v.is_finite())
            .fold(0.0f64, |a, &b| a.max(b.abs()))
    }
}

/// [`power_of_two_scale`] given the largest magnitude.
pub(crate) fn scale_for(max: f64) -> Option<f64> {
    if max == 0.0 || (1.0 / F32_COMFORT..=F32_COMFORT).contains(&max) {
        return None;
    }
    // max = m 2^e with m in [1, 2): scale by 2^-e, at most by 2^1000 (a
    // subnormal max then lands near 2^-60, still far inside f32's range).
    let biased = ((max.to_bits() >> 52) & 0x7ff) as i32;
    let e = (biased - 1023).max(-1000);
    Some(2f64.powi(-e))
}

crate::cpu::dispatched! {
    /// The nearest row to `qi` given its cross terms `col` (f32) with every
    /// row: every row whose score `|x|² − 2 q·x`, computed in f32 from the
    /// norms `x_norm32` rounded to f32, is within `band` of the smallest is
    /// re-checked with a direct f64 distance. `band` covers the cross
    /// terms' error ([`score_err`]) and twice the f32 scan's own
    /// ([`scan_err`]): a row within the cross terms' band of the best exact
    /// score is within `band` of the best f32 score.
    fn brute_query(x_rows: &[f64], x_norm32: &[f32], col: &[f32], qi: &[f64], band: f64) -> usize {
        // Both scans run over sixteen f32 lanes at a time (`s < l ? s : l`
        // vectorizes to min instructions; a NaN score never wins), the
        // second one looking inside a chunk only when a lane is in the band.
        const L: usize = 16;
        let d = qi.len();
        let score = |xn: f32, c: f32| xn - 2.0 * c;
        let full = x_norm32.len() / L * L;
        let mut lanes = [f32::INFINITY; L];
        for (xs, cs) in x_norm32[..full].chunks_exact(L).zip(col[..full].chunks_exact(L)) {
            for ((l, &xn), &c) in lanes.iter_mut().zip(xs).zip(cs) {
                let s = score(xn, c);
                *l = if s < *l { s } else { *l };
            }
        }
        let mut best = f32::INFINITY;
        for s in lanes
            .into_iter()
            .chain(x_norm32[full..].iter().zip(&col[full..]).map(|(&xn, &c)| score(xn, c)))
        {
            best = if s < best { s } else { best };
        }
        // The limit rounded up to the next f32 (infinite when `best` is).
        let limit = (f64::from(best) + band) as f32;
        let limit = if limit.is_finite() { limit.next_up() } else { limit };
        let mut arg = usize::MAX;
        let mut best_d = f64::INFINITY;
        let mut check = |k: usize, best_d: &mut f64| {
            if score(x_norm32[k], col[k]) <= limit
                && let Some(dist) = dist2_below(&x_rows[k * d..(k + 1) * d], qi, *best_d)
                && dist < *best_d
            {
                *best_d = dist;
                arg = k;
            }
        };
        for (chunk, (xs, cs)) in x_norm32[..full]
            .chunks_exact(L)
            .zip(col[..full].chunks_exact(L))
            .enumerate()
        {
            let mut any = false;
            for (&xn, &c) in xs.iter().zip(cs) {
                any |= score(xn, c) <= limit;
            }
            if any {
                for k in chunk * L..(chunk + 1) * L {
                    check(k, &mut best_d);
                }
            }
        }
        for k in full..x_norm32.len() {
            check(k, &mut best_d);
        }
        arg
    }
}

/// A bound on the error of a score `|x|² − 2c` computed in f32 from `|x|²`
/// rounded to f32 and an f32 cross term `c` (|c| ≤ |q||x|), against the
/// same expression in f64: the rounding of the norm (`u |x|²`) and of the
/// difference (`u (|x|² + 2|c|)`), with `2|q||x| ≤ |q|² + |x|²`, plus f32's
/// smallest normal for a norm that underflows; doubled as a margin.
pub(crate) fn scan_err(q_norm: f64, x_norm_max: f64) -> f64 {
    let u = f64::from(f32::EPSILON) / 2.0;
    2.0 * (u * (3.0 * x_norm_max + q_norm) + 2.0 * f64::from(f32::MIN_POSITIVE))
}

/// A bound on the error of a score `|x|² − 2 q·x` as the fused search
/// computes it in f32 (`q_norm` = |q|², `x_norm_max` ≥ |x|²): `|x|²`
/// rounded to f32, then the d products `(−2q_j) x_j` of the f32 copies
/// added one by one, each product and each sum rounded. Relative
/// rounding (u = 2⁻²⁴): the norm `u|x|²`, the conversions `(2u + u²)`
/// and the products `u` of each `2|q_j x_j|` (at most `(3u + u²) 2|q||x|`
/// in all), the d sums `u` of partial sums at most `(1 + u)|x|² + (1 +
/// 3u)2|q||x|`; with `2|q||x| ≤ |q|² + |x|²` all of it is below
/// `(2d + 4) u (|q|² + |x|²)` (for d < 2²⁰). Absolute errors that relative
/// rounding does not cover, each at most f32's smallest normal λ:
/// conversions of coordinates below the normal range (`2 √d λ (|q| +
/// |x|)`), the norm, the products and the sums (`2d + 1`). Doubled as a
/// margin.
pub(crate) fn fused_err(d: usize, q_norm: f64, x_norm_max: f64) -> f64 {
    let u = f64::from(f32::EPSILON) / 2.0;
    let tiny = f64::from(f32::MIN_POSITIVE);
    let df = d as f64;
    2.0 * ((2.0 * df + 4.0) * u * (q_norm + x_norm_max)
        + tiny * (2.0 * df.sqrt() * (q_norm.sqrt() + x_norm_max.sqrt()) + 2.0 * df + 1.0))
}

/// Whether the fused search runs its AVX-512 kernel ([`WIDE_GROUP`]
/// queries at a time).
fn wide_kernel() -> bool {
    #[cfg(target_arch = "x86_64")]
    return crate::cpu::has_v4();
    #[cfg(not(target_arch = "x86_64"))]
    return false;
}

/// What [`reverse_panel`] reads: every group's smallest approximate
/// squared distances to the data rows (`mins`, one slice of whole panels
/// per group of `group` queries), the data rows and their squared norms,
/// the queries (row-major) and their largest squared norm.
#[derive(Clone, Copy)]
struct Reverse<'a> {
    mins: &'a [&'a [f32]],
    group: usize,
    x_rows: &'a [f64],
    x_norm: &'a [f64],
    q_rows: &'a [f64],
    q_norm_max: f64,
    d: usize,
}

/// The band [`BruteData::search_both`] re-checks for a data row of
/// squared norm `x_norm` against queries of squared norms at most
/// `q_norm_max`: twice a bound on the error of each approximate squared
/// distance `(|x|² − 2 q·x) + |q|²` in f32. The fused score's error is
/// half of [`fused_err`] (its bound is symmetric in the two norms); `|q|²`
/// rounded to f32 adds `u |q|²`, the sum's rounding `u (|q| + |x|)² ≤
/// 2u (|q|² + |x|²)`, and f32's smallest normal covers what falls below
/// the normal range. Doubled here with a margin: the band also holds
/// the smallest value's own error.
pub(crate) fn both_err(d: usize, x_norm: f64, q_norm_max: f64) -> f64 {
    let u = f64::from(f32::EPSILON) / 2.0;
    let tiny = f64::from(f32::MIN_POSITIVE);
    2.0 * fused_err(d, x_norm, q_norm_max) + 8.0 * u * (x_norm + q_norm_max) + 8.0 * tiny
}

/// The fused search's products: the scores of `G` queries (`c`: their
/// coordinates times −2, coordinate by coordinate: `c[j * G + g]` is
/// coordinate `j` of query `g`) against every panel, written to `scores`
/// (query by query, `norms.len()` each), and each query's smallest score.
/// Sums run in coordinate order from the norm; with AVX2 or AVX-512 each
/// product and sum is one fused multiply-add (one rounding instead of two:
/// [`fused_err`] covers both). `G` is [`WIDE_GROUP`] with AVX-512 (its
/// kernel), else [`GROUP`]; the group size only changes how many queries
/// share a load of the panel, never a score.
fn fused_scores<const G: usize>(
    panels: &[f32],
    norms: &[f32],
    d: usize,
    c: &[f32],
    scores: &mut [f32],
) -> [f32; G] {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2,fma,bmi1,bmi2,popcnt,lzcnt")]
        fn v3(panels: &[f32], norms: &[f32], d: usize, c: &[f32], scores: &mut [f32]) -> [f32; 4] {
            fused_scores_body::<true>(panels, norms, d, c, scores)
        }
        let mut best = [f32::INFINITY; G];
        if G == WIDE_GROUP && crate::cpu::has_v4() {
            // SAFETY: the CPU has the features (runtime check).
            let b = unsafe { fused_scores_avx512(panels, norms, d, c, scores) };
            best.copy_from_slice(&b);
            return best;
        }
        if G == GROUP && crate::cpu::has_v3() {
            // SAFETY: as above.
            best.copy_from_slice(&unsafe { v3(panels, norms, d, c, scores) });
            return best;
        }
    }
    assert_eq!(
        G, GROUP,
        "the portable kernel scores {GROUP} queries at a time"
    );
    let mut best = [f32::INFINITY; G];
    best.copy_from_slice(&fused_scores_body::<false>(panels, norms, d, c, scores));
    best
}

/// [`fused_scores`] for [`GROUP`] queries, with (`FMA`) or without fused
/// multiply-adds.
#[inline(always)]
pub(crate) fn fused_scores_body<const FMA: bool>(
    panels: &[f32],
    norms: &[f32],
    d: usize,
    c: &[f32],
    scores: &mut [f32],
) -> [f32; GROUP] {
    const { assert!(GROUP == 4) };
    let n = norms.len();
    let mut lanes = [[f32::INFINITY; PANEL]; GROUP];
    let madd = |a: f32, b: f32, acc: f32| if FMA { a.mul_add(b, acc) } else { acc + a * b };
    for (p, (xp, np)) in panels
        .chunks_exact(d * PANEL)
        .zip(norms.chunks_exact(PANEL))
        .enumerate()
    {
        let np: &[f32; PANEL] = np.try_into().expect("panel");
        let (mut a0, mut a1, mut a2, mut a3) = (*np, *np, *np, *np);
        for (x, k) in xp.chunks_exact(PANEL).zip(c.chunks_exact(GROUP)) {
            let x: &[f32; PANEL] = x.try_into().expect("panel");
            let (k0, k1, k2, k3) = (k[0], k[1], k[2], k[3]);
            for l in 0..PANEL {
                a0[l] = madd(k0, x[l], a0[l]);
                a1[l] = madd(k1, x[l], a1[l]);
                a2[l] = madd(k2, x[l], a2[l]);
                a3[l] = madd(k3, x[l], a3[l]);
            }
        }
        for (g, (a, l)) in [a0, a1, a2, a3].iter().zip(lanes.iter_mut()).enumerate() {
            scores[g * n + p * PANEL..g * n + (p + 1) * PANEL].copy_from_slice(a);
            for (lv, &av) in l.iter_mut().zip(a) {
                *lv = if av < *lv { av } else { *lv };
            }
        }
    }
    let mut best = [f32::INFINITY; GROUP];
    for (b, l) in best.iter_mut().zip(&lanes) {
        for &v in l {
            *b = if v < *b { v } else { *b };
        }
    }
    best
}

/// [`fused_scores`] for [`WIDE_GROUP`] queries with AVX-512: one register
/// per query (eight independent sums keep both FMA units busy), the same
/// fused multiply-adds in the same order as [`fused_scores_body`] (so
/// the same scores, bit for bit).
///
/// # Safety
///
/// The CPU must have AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
pub(crate) unsafe fn fused_scores_avx512(
    panels: &[f32],
    norms: &[f32],
    d: usize,
    c: &[f32],
    scores: &mut [f32],
) -> [f32; WIDE_GROUP] {
    use std::arch::x86_64::*;
    const { assert!(PANEL == 16) };
    let n = norms.len();
    let np = n / PANEL;
    assert!(panels.len() >= np * d * PANEL && c.len() >= d * WIDE_GROUP);
    assert!(scores.len() >= WIDE_GROUP * n);
    let mut lanes = [_mm512_set1_ps(f32::INFINITY); WIDE_GROUP];
    for p in 0..np {
        // SAFETY (all loads and stores): in bounds by the asserts above.
        let mut a = [unsafe { _mm512_loadu_ps(norms.as_ptr().add(p * PANEL)) }; WIDE_GROUP];
        let xp = unsafe { panels.as_ptr().add(p * d * PANEL) };
        for j in 0..d {
            let x = unsafe { _mm512_loadu_ps(xp.add(j * PANEL)) };
            let k = &c[j * WIDE_GROUP..(j + 1) * WIDE_GROUP];
            for (ag, &kg) in a.iter_mut().zip(k) {
                *ag = _mm512_fmadd_ps(_mm512_set1_ps(kg), x, *ag);
            }
        }
        for (g, (ag, lg)) in a.iter().zip(lanes.iter_mut()).enumerate() {
            unsafe { _mm512_storeu_ps(scores.as_mut_ptr().add(g * n + p * PANEL), *ag) };
            *lg = _mm512_min_ps(*ag, *lg);
        }
    }
    lanes.map(|l| _mm512_reduce_min_ps(l))
}

crate::cpu::dispatched! {
    /// [`BruteData::search_both`]'s reverse answers for the data rows of
    /// panel `p` (`out`: one per row): the smallest of each row's group
    /// minima, then the queries of the groups within [`both_err`]'s band
    /// of it, in order, by their f64 distances.
    fn reverse_panel(r: &Reverse<'_>, p: usize, out: &mut [usize]) -> () {
        let Reverse { mins, group, x_rows, x_norm, q_rows, q_norm_max, d } = *r;
        let nq = q_rows.len() / d;
        let mut smallest = [f32::INFINITY; PANEL];
        for m in mins {
            let m: &[f32; PANEL] = m[p * PANEL..(p + 1) * PANEL].try_into().expect("panel");
            for (s, &v) in smallest.iter_mut().zip(m) {
                *s = if v < *s { v } else { *s };
            }
        }
        // Each row's limit (rows past the data: none pass).
        let mut limit = [f32::NEG_INFINITY; PANEL];
        for (l, lim) in limit.iter_mut().enumerate().take(out.len()) {
            let k = p * PANEL + l;
            let v = (f64::from(smallest[l]) + both_err(d, x_norm[k], q_norm_max)) as f32;
            *lim = if v.is_finite() { v.next_up() } else { v };
        }
        // The groups in order; in each, the rows it passes (one compare
        // for the panel's sixteen), their queries in order by f64 distance.
        let mut best = [(f64::INFINITY, usize::MAX); PANEL];
        for (gi, m) in mins.iter().enumerate() {
            let m: &[f32; PANEL] = m[p * PANEL..(p + 1) * PANEL].try_into().expect("panel");
            let mut mask = 0u32;
            for l in 0..PANEL {
                mask |= u32::from(m[l] <= limit[l]) << l;
            }
            while mask != 0 {
                let l = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let k = p * PANEL + l;
                let xk = &x_rows[k * d..(k + 1) * d];
                for i in gi * group..((gi + 1) * group).min(nq) {
                    if let Some(dist) = dist2_below(&q_rows[i * d..(i + 1) * d], xk, best[l].0)
                        && dist < best[l].0
                    {
                        best[l] = (dist, i);
                    }
                }
            }
        }
        for (o, b) in out.iter_mut().zip(best) {
            *o = b.1;
        }
    }
}

crate::cpu::dispatched! {
    /// Each data row's smallest approximate squared distance so far:
    /// `col_min[k]` lowered to `col[k] + q_norm` (`col`: one query's fused
    /// scores, `q_norm`: its squared norm in f32).
    fn col_min_update(col: &[f32], q_norm: f32, col_min: &mut [f32]) -> () {
        for (m, &s) in col_min.iter_mut().zip(col) {
            let v = s + q_norm;
            *m = if v < *m { v } else { *m };
        }
    }
}

crate::cpu::dispatched! {
    /// The nearest of the `nx` rows to `qi` given its fused scores `col`
    /// (padded to whole panels) and the smallest of them: every row whose
    /// score is within `band` of it is re-checked with a direct f64
    /// distance (ties to the smallest index).
    fn fused_pick(x_rows: &[f64], col: &[f32], nx: usize, best: f32, qi: &[f64], band: f64) -> usize {
        let d = qi.len();
        let limit = (f64::from(best) + band) as f32;
        let limit = if limit.is_finite() { limit.next_up() } else { limit };
        let mut arg = usize::MAX;
        let mut best_d = f64::INFINITY;
        for (p, cs) in col.chunks_exact(PANEL).enumerate() {
            let mut any = false;
            for &s in cs {
                any |= s <= limit;
            }
            if any {
                for (l, &s) in cs.iter().enumerate() {
                    let k = p * PANEL + l;
                    if k < nx
                        && s <= limit
                        && let Some(dist) = dist2_below(&x_rows[k * d..(k + 1) * d], qi, best_d)
                        && dist < best_d
                    {
                        best_d = dist;
                        arg = k;
                    }
                }
            }
        }
        arg
    }
}
