//! Exact nearest neighbours of query rows among data rows, in any
//! dimension: `|q − x|² = |x|² − 2 q·x + |q|²`. The cross terms are
//! blocked GEMMs in f32 (faer; twice the f64 throughput), which only
//! *select candidates*: every data row whose f32 score lies within a
//! rigorous rounding band of the best one is re-checked with a direct f64
//! distance, so the result is the true nearest row in f64 (ties: the
//! smallest index). Memory is bounded by the block size, never
//! n_queries x n_data.
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

/// How [`nearest_rows_with`] searches; every strategy returns the same,
/// exact answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NnStrategy {
    /// The tree in dimensions up to 48 when both sets are large enough
    /// for it to pay, else brute force.
    #[default]
    Auto,
    /// Every query against every data row (blocked f32 GEMM).
    Brute,
    /// Both sets split into clusters by principal-direction bisection;
    /// a cluster of queries is compared (f32 GEMM) only with the data
    /// clusters that the triangle inequality cannot rule out.
    Tree,
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
    assert_eq!(
        data.ncols(),
        queries.ncols(),
        "nearest_rows: dimensions differ"
    );
    let (nx, d) = (data.nrows(), data.ncols());
    if nx == 0 {
        return vec![0; queries.nrows()];
    }
    let tree = match strategy {
        // Measured on FAUST spectral embeddings (`cargo xtask bench-refine`):
        // the tree is 3x faster at d = 10, even at d = 50, and slower above
        // (cluster radii grow with the frequencies in the embedding).
        NnStrategy::Auto => {
            (1..=TREE_MAX_DIM).contains(&d)
                && nx >= 4 * LEAF_DATA
                && queries.nrows() >= 2 * LEAF_QUERY
        }
        NnStrategy::Brute => false,
        NnStrategy::Tree => d > 0,
    };
    if tree {
        return tree_search(data, queries);
    }
    // Row-major copies: each row contiguous, for the direct re-checks.
    let x_rows: Vec<f64> = data.transpose().as_slice().to_vec();
    let x_norm: Vec<f64> = x_rows
        .chunks(d.max(1))
        .map(|r| r.iter().map(|v| v * v).sum())
        .collect();
    let x_norm_max = x_norm.iter().fold(0.0f64, |a, &b| a.max(b));
    let x32: Vec<f32> = data.as_slice().iter().map(|&v| v as f32).collect();
    let x_mat = MatRef::from_column_major_slice(&x32, nx, d);
    let q_rows: Vec<f64> = queries.transpose().as_slice().to_vec();
    let nq = queries.nrows();
    let u = f64::from(f32::EPSILON) / 2.0;
    let starts: Vec<usize> = (0..nq).step_by(BLOCK).collect();
    starts
        .par_iter()
        .flat_map_iter(|&q0| {
            let rows = BLOCK.min(nq - q0);
            let q = Mat::<f32>::from_fn(rows, d, |i, j| queries[(q0 + i, j)] as f32);
            // Sᵀ = X Qᵀ (nx x rows): column i holds query i's cross terms,
            // contiguous for the scans below.
            let mut s = Mat::<f32>::zeros(nx, rows);
            matmul(
                s.as_mut(),
                Accum::Replace,
                x_mat,
                q.transpose(),
                1.0f32,
                Par::Seq,
            );
            let (x_rows, x_norm, q_rows) = (&x_rows, &x_norm, &q_rows);
            (0..rows)
                .map(move |i| {
                    let qi = &q_rows[(q0 + i) * d..(q0 + i + 1) * d];
                    let q_norm: f64 = qi.iter().map(|v| v * v).sum();
                    let col = s.col_as_slice(i);
                    let mut best = f64::INFINITY;
                    for k in 0..nx {
                        best = best.min(x_norm[k] - 2.0 * f64::from(col[k]));
                    }
                    let band = 4.0 * (d as f64 + 2.0) * u * (q_norm + x_norm_max) + 1e-300;
                    let mut arg = usize::MAX;
                    let mut best_d = f64::INFINITY;
                    for k in 0..nx {
                        if x_norm[k] - 2.0 * f64::from(col[k]) <= best + band {
                            let xk = &x_rows[k * d..(k + 1) * d];
                            let dist: f64 = xk.iter().zip(qi).map(|(a, b)| (a - b) * (a - b)).sum();
                            if dist < best_d {
                                best_d = dist;
                                arg = k;
                            }
                        }
                    }
                    arg
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

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

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
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
    let x_rows: Vec<f64> = data.transpose().as_slice().to_vec();
    let q_rows: Vec<f64> = queries.transpose().as_slice().to_vec();
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
    let u = f64::from(f32::EPSILON) / 2.0;
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
                .map(|qn| (d as f64 + 2.0) * u * (qn + x_norm_max) + 1e-300)
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
