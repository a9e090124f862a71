//! The clustered search ([`NnStrategy::Tree`](crate::NnStrategy::Tree)).

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::brute::score_err;
use crate::rows::{dist2, dot8, row_major};

/// Largest dimension [`NnStrategy::Auto`] uses the tree for.
pub(crate) const TREE_MAX_DIM: usize = 48;
/// Data rows per cluster.
pub(crate) const LEAF_DATA: usize = 64;
/// Query rows per cluster.
pub(crate) const LEAF_QUERY: usize = 128;

/// A partition of points (rows) into clusters of at most `leaf` rows by
/// recursive median splits along the principal direction.
pub(crate) struct Clusters {
    /// Point indices, cluster by cluster.
    order: Vec<usize>,
    /// (start, len) of each cluster in `order`.
    ranges: Vec<(usize, usize)>,
    /// Cluster means, row-major (m x d).
    centers: Vec<f64>,
    /// Largest distance from a cluster's mean to its points (rounded up).
    radii: Vec<f64>,
}

pub(crate) fn clusters(rows: &[f64], d: usize, leaf: usize) -> Clusters {
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

crate::cpu::dispatched! {
    /// Splits `idx` (points `offset..offset + idx.len()` of the final order)
    /// at the median of the projections on the principal direction (two power
    /// iterations from the direction of the point farthest from the mean).
    pub(crate) fn split(rows: &[f64], d: usize, idx: &mut [usize], offset: usize, leaf: usize) -> Vec<(usize, usize)> {
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
        let mut centred = vec![0.0; d];
        for _ in 0..2 {
            let mut w = vec![0.0; d];
            for &i in idx.iter() {
                centred
                    .iter_mut()
                    .zip(row(i))
                    .zip(&mean)
                    .for_each(|((c, x), m)| *c = x - m);
                let t = dot8(&centred, &v);
                w.iter_mut().zip(&centred).for_each(|(w, c)| *w += t * c);
            }
            let norm = dot8(&w, &w).sqrt();
            if norm == 0.0 {
                break;
            }
            v = w.into_iter().map(|x| x / norm).collect();
        }
        let mut keyed: Vec<(f64, usize)> = idx.iter().map(|&i| (dot8(row(i), &v), i)).collect();
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
}

/// The clustered exact search. Per query cluster: lower bounds
/// `(|q − c_j| − r_j)₊` for every data cluster j (one f64 GEMM against the
/// centres), data clusters visited in increasing order of their smallest
/// bound, each one skipped when no query of the block can have its
/// nearest point there (bound² above the query's current upper bound) and
/// the loop left once the smallest remaining bound exceeds every upper
/// bound. Visited clusters are scored with one f32 GEMM; candidates within
/// the rounding band are re-checked in f64 as in the brute-force search.
pub(crate) fn tree_search(data: &DMatrix<f64>, queries: &DMatrix<f64>) -> Vec<usize> {
    // Both sides prepared side by side.
    let (tree, (q_rows, cq)) = rayon::join(|| TreeData::new(data), || query_clusters(queries));
    tree.search_clustered(&q_rows, &cq)
}

/// The query rows (row-major) and their clusters.
fn query_clusters(queries: &DMatrix<f64>) -> (Vec<f64>, Clusters) {
    let q_rows = row_major(queries, None);
    let cq = clusters(&q_rows, queries.ncols(), LEAF_QUERY);
    (q_rows, cq)
}

/// The clustered search's data side: prepared once, searched by any
/// number of query sets.
pub(crate) struct TreeData {
    d: usize,
    /// Data rows, row-major, in their original order.
    x_rows: Vec<f64>,
    /// The data clusters.
    cx: Clusters,
    /// Squared norms of the rows in cluster order, and their largest.
    x_norm: Vec<f64>,
    x_norm_max: f64,
    /// The rows in cluster order, f32.
    x32: Mat<f32>,
    /// Squared norms of the cluster centres.
    c_norm: Vec<f64>,
}

impl TreeData {
    pub(crate) fn new(data: &DMatrix<f64>) -> TreeData {
        let (nx, d) = (data.nrows(), data.ncols());
        let x_rows = row_major(data, None);
        let cx = clusters(&x_rows, d, LEAF_DATA);
        let x_norm: Vec<f64> = cx
            .order
            .iter()
            .map(|&i| x_rows[i * d..(i + 1) * d].iter().map(|v| v * v).sum())
            .collect();
        let x_norm_max = x_norm.iter().fold(0.0f64, |a, &b| a.max(b));
        let x32 = Mat::<f32>::from_fn(nx, d, |i, j| x_rows[cx.order[i] * d + j] as f32);
        let c_norm: Vec<f64> = cx
            .centers
            .chunks(d)
            .map(|c| c.iter().map(|v| v * v).sum())
            .collect();
        TreeData {
            d,
            x_rows,
            cx,
            x_norm,
            x_norm_max,
            x32,
            c_norm,
        }
    }

    /// The nearest data row of every query (same width as the data).
    pub(crate) fn search(&self, queries: &DMatrix<f64>) -> Vec<usize> {
        let (q_rows, cq) = query_clusters(queries);
        self.search_clustered(&q_rows, &cq)
    }

    /// [`search`](Self::search) on clustered query rows.
    fn search_clustered(&self, q_rows: &[f64], cq: &Clusters) -> Vec<usize> {
        let TreeData {
            d,
            x_rows,
            cx,
            x_norm,
            x_norm_max,
            x32,
            c_norm,
        } = self;
        let (d, x_norm_max) = (*d, *x_norm_max);
        let nq = cq.order.len();
        let m = cx.ranges.len();
        let centers = MatRef::from_row_major_slice(&cx.centers, m, d);
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
}
