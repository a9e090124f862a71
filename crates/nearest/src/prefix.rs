//! The prefix search ([`NnStrategy::Prefix`](crate::NnStrategy::Prefix)).

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::brute::score_err;
use crate::prefix_width;
use crate::rows::{dist2_below, row_major};
use crate::tree::split;

/// Smallest dimension [`NnStrategy::Auto`] uses the prefix search from
/// (with guesses).
pub(crate) const PREFIX_FROM: usize = 64;
/// Largest data size [`NnStrategy::Auto`] uses the prefix search for:
/// on large meshes too many rows pass the prefix bar and brute force is
/// faster (the crate README, "Choosing a strategy").
pub(crate) const PREFIX_MAX_ROWS: usize = 20_000;

/// The prefix search ([`NnStrategy::Prefix`]). Per block of queries, one
/// f32 GEMM over the leading `m` coordinates gives every pair's partial
/// score `|x_m|² − 2 q_m·x_m`, within a rigorous rounding bound `e` of its
/// exact value. With `ub` the full f64 distance to the best-ranked row (or
/// to the hint, if smaller), the nearest row x* satisfies
/// `|q_m − x*_m|² ≤ |q − x*|² ≤ ub`, so its computed score is at most
/// `ub − |q_m|² + e`: only rows under that bar get a full distance.
pub(crate) fn prefix_search(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    hint: Option<&[usize]>,
) -> Vec<usize> {
    prefix_search_with(data, queries, hint, UNION_DENSITY)
}

/// [`prefix_search`] with the union-GEMM switch as a parameter (tests
/// force either path).
pub(crate) fn prefix_search_with(
    data: &DMatrix<f64>,
    queries: &DMatrix<f64>,
    hint: Option<&[usize]>,
    union_density: usize,
) -> Vec<usize> {
    // Both sides ordered side by side.
    let (prefix, order_q) = rayon::join(
        || PrefixData::new(data),
        || query_order(queries, prefix_width(data.ncols())),
    );
    prefix.search_ordered(queries, &order_q, hint, union_density)
}

/// The queries in a spatially coherent order (bisection on the prefix of
/// width `m`): consecutive queries then share most of their surviving
/// rows, which stay in cache, contiguous.
fn query_order(queries: &DMatrix<f64>, m: usize) -> Vec<usize> {
    let mut order_q: Vec<usize> = (0..queries.nrows()).collect();
    split(&prefix_rows(queries, m), m, &mut order_q, 0, ORDER_LEAF);
    order_q
}

/// The rows' leading `m` coordinates, row-major.
fn prefix_rows(a: &DMatrix<f64>, m: usize) -> Vec<f64> {
    let n = a.nrows();
    let mut out = vec![0.0; n * m];
    for j in 0..m {
        for (i, v) in a.column(j).iter().enumerate() {
            out[i * m + j] = *v;
        }
    }
    out
}

/// The prefix search's data side, in a spatially coherent order
/// (principal-direction bisection on the prefix): prepared once, searched
/// by any number of query sets.
pub(crate) struct PrefixData {
    d: usize,
    m: usize,
    /// Data rows (f64, row-major), their prefix in f32 (column-major) and
    /// the squared norms of the prefixes.
    x_rows: Vec<f64>,
    x32: Mat<f32>,
    xn32: Vec<f32>,
    xm_norm_max: f64,
    /// Squared norms of the data rows (f64) and their largest value.
    x_norm: Vec<f64>,
    x_norm_max: f64,
    /// Original index of each data position, and its inverse.
    order_x: Vec<usize>,
    pos_x: Vec<usize>,
}

impl PrefixData {
    pub(crate) fn new(data: &DMatrix<f64>) -> PrefixData {
        let (nx, d) = (data.nrows(), data.ncols());
        let m = prefix_width(d);
        let mut order_x: Vec<usize> = (0..nx).collect();
        split(&prefix_rows(data, m), m, &mut order_x, 0, ORDER_LEAF);
        let mut pos_x = vec![0usize; nx];
        for (p, &i) in order_x.iter().enumerate() {
            pos_x[i] = p;
        }
        let x_rows = row_major(data, Some(&order_x));
        let xm_norm: Vec<f64> = x_rows
            .chunks(d)
            .map(|r| r[..m].iter().map(|v| v * v).sum())
            .collect();
        let xm_norm_max = xm_norm.iter().fold(0.0f64, |a, &b| a.max(b));
        let x_norm: Vec<f64> = x_rows
            .chunks(d)
            .map(|r| r.iter().map(|v| v * v).sum())
            .collect();
        PrefixData {
            d,
            m,
            x_norm_max: x_norm.iter().fold(0.0f64, |a, &b| a.max(b)),
            x_norm,
            xn32: xm_norm.iter().map(|&v| v as f32).collect(),
            // Column by column (each column of `data` stays in cache).
            x32: Mat::<f32>::from_fn(nx, m, |p, j| data[(order_x[p], j)] as f32),
            x_rows,
            xm_norm_max,
            order_x,
            pos_x,
        }
    }

    /// The nearest data row of every query (same width as the data).
    pub(crate) fn search(&self, queries: &DMatrix<f64>, hint: Option<&[usize]>) -> Vec<usize> {
        let order_q = query_order(queries, self.m);
        self.search_ordered(queries, &order_q, hint, UNION_DENSITY)
    }

    /// [`search`](Self::search) with the queries' order given.
    fn search_ordered(
        &self,
        queries: &DMatrix<f64>,
        order_q: &[usize],
        hint: Option<&[usize]>,
        union_density: usize,
    ) -> Vec<usize> {
        let (nx, d, m, nq) = (self.order_x.len(), self.d, self.m, queries.nrows());
        let ctx = Prefix {
            data: self,
            union_density,
            q_rows: row_major(queries, Some(order_q)),
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
                    let q =
                        Mat::<f32>::from_fn(rows, m, |i, j| ctx.q_rows[(q0 + i) * d + j] as f32);
                    matmul(
                        work.s.as_mut().subcols_mut(0, rows),
                        Accum::Replace,
                        self.x32.as_ref(),
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
}

/// One prefix search: the prepared data and the queries in their
/// coherent order.
pub(crate) struct Prefix<'a> {
    data: &'a PrefixData,
    /// Scores a block's union of candidates by GEMM when it holds at most
    /// this many times the candidate pairs.
    union_density: usize,
    /// Query rows (f64, row-major).
    q_rows: Vec<f64>,
    /// Original data index guessed for each query position.
    hint: Option<Vec<usize>>,
}

/// Per-thread buffers of the prefix search.
pub(crate) struct PrefixWork {
    /// Prefix scores of a block (nx x PREFIX_BLOCK).
    s: Mat<f32>,
    /// Position of a data row in the block's union of candidates
    /// (`u32::MAX` when not in it).
    slot: Vec<u32>,
}

crate::cpu::dispatched! {
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
    fn prefix_block(search: &Prefix<'_>, q0: usize, rows: usize, work: &mut PrefixWork) -> Vec<usize> {
        // The query side, then the data side read directly in the loops.
        let (q_rows, hint, union_density) =
            (&search.q_rows[..], search.hint.as_deref(), search.union_density);
        let this: &PrefixData = search.data;
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
        fn consider(this: &PrefixData, qi: &[f64], p: usize, best: &mut (f64, usize)) {
            let d = this.d;
            if let Some(dk) = dist2_below(&this.x_rows[p * d..(p + 1) * d], qi, best.0)
                && (dk < best.0 || this.order_x[p] < best.1)
            {
                *best = (dk, this.order_x[p]);
            }
        }
        for i in 0..rows {
            let qi = &q_rows[(q0 + i) * d..(q0 + i + 1) * d];
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
            match hint.map(|h| h[q0 + i]) {
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
        let dense = union.len() * rows <= union_density * flat.len();
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
            let q = Mat::<f32>::from_fn(rows, d, |i, j| q_rows[(q0 + i) * d + j] as f32);
            let mut full = Mat::<f32>::zeros(nu, rows);
            matmul(full.as_mut(), Accum::Replace, xu, q.transpose(), 1.0f32, Par::Seq);
            for (i, best) in bests.iter_mut().enumerate() {
                let qi = &q_rows[(q0 + i) * d..(q0 + i + 1) * d];
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
                let qi = &q_rows[(q0 + i) * d..(q0 + i + 1) * d];
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
pub(crate) const UNION_DENSITY: usize = 8;

/// Points per leaf of the bisection that orders both sets.
pub(crate) const ORDER_LEAF: usize = 64;
/// Queries per block of the prefix search.
pub(crate) const PREFIX_BLOCK: usize = 128;

/// Candidates of the prefix search whose distance is computed before the
/// bar is lowered.
pub(crate) const FIRST: usize = 16;

/// The index of the smallest score `xn[k] − 2 col[k]` (f32; used only as
/// a candidate, so its own rounding does not matter).
#[inline(always)]
pub(crate) fn argmin_score(xn: &[f32], col: &[f32]) -> usize {
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
pub(crate) fn for_each_under(xn: &[f32], col: &[f32], bar: f32, mut f: impl FnMut(usize, f32)) {
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
