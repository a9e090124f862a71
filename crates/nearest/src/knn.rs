//! The `k` nearest data rows of every query row ([`k_nearest_rows`]), for
//! sparse supports such as the kernels of Sinkhorn conversions.
//!
//! Blocked f64 GEMM of the cross terms (`|x|² − 2 q·x`), a partial
//! selection of the `k + KNN_MARGIN` best expanded scores per query, then
//! the direct f64 distance of those candidates, sorted. The expansion's
//! rounding (relative ~1e-16 of `|q| |x|`) can only reorder rows whose
//! scores differ by less than that, so the result is the exact k nearest
//! unless more than `KNN_MARGIN` rows tie within rounding at the k-th
//! place. Memory: one block of 256 queries x n_data scores.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use rayon::prelude::*;

use crate::{Result, check_finite, check_input};

/// Extra candidates re-ranked by direct distance beyond the `k` asked.
pub(crate) const KNN_MARGIN: usize = 8;

/// Queries per block.
const BLOCK: usize = 256;

/// The `k` nearest data rows of each query, nearest first.
#[derive(Debug, Clone, PartialEq)]
pub struct KNearest {
    /// Neighbours per query (`min(k, n_data)`).
    pub k: usize,
    /// Row-major n_queries x k: data row indices, nearest first (ties:
    /// the smaller index first).
    pub index: Vec<usize>,
    /// Row-major n_queries x k: the Euclidean distances (f64, direct).
    pub distance: Vec<f64>,
}

impl KNearest {
    /// The neighbours of query `q`.
    pub fn indices(&self, q: usize) -> &[usize] {
        &self.index[q * self.k..(q + 1) * self.k]
    }

    /// Their distances.
    pub fn distances(&self, q: usize) -> &[f64] {
        &self.distance[q * self.k..(q + 1) * self.k]
    }
}

/// For every row of `queries`, its `k` nearest rows of `data` (Euclidean,
/// nearest first; `k` clamped to the number of data rows). Parallel over
/// blocks of queries.
///
/// ```
/// use faer::Mat;
/// use fmaps_nearest::k_nearest_rows;
///
/// let data = Mat::from_fn(5, 1, |i, _| i as f64); // 0, 1, 2, 3, 4
/// let queries = Mat::from_fn(1, 1, |_, _| 2.8);
/// let knn = k_nearest_rows(data.as_ref(), queries.as_ref(), 3)?;
/// assert_eq!(knn.indices(0), &[3, 2, 4]);
/// assert!((knn.distances(0)[0] - 0.2).abs() < 1e-12);
/// # Ok::<(), fmaps_nearest::Error>(())
/// ```
///
/// Errors: rows of different lengths, queries without data rows, a
/// coordinate that is not finite.
pub fn k_nearest_rows(
    data: MatRef<'_, f64>,
    queries: MatRef<'_, f64>,
    k: usize,
) -> Result<KNearest> {
    let (nx, d) = (data.nrows(), data.ncols());
    let nq = queries.nrows();
    if check_input(nx, d, queries, None)? {
        return Ok(KNearest {
            k: k.min(nx),
            index: Vec::new(),
            distance: Vec::new(),
        });
    }
    check_finite(data, "data")?;
    check_finite(queries, "query")?;
    let k = k.min(nx);
    let keep = (k + KNN_MARGIN).min(nx);
    let data_norms: Vec<f64> = (0..nx)
        .map(|i| (0..d).map(|j| data[(i, j)] * data[(i, j)]).sum())
        .collect();
    let mut index = vec![0usize; nq * k];
    let mut distance = vec![0.0f64; nq * k];
    index
        .par_chunks_mut((BLOCK * k).max(1))
        .zip(distance.par_chunks_mut((BLOCK * k).max(1)))
        .enumerate()
        .for_each(|(b, (idx_block, dist_block))| {
            if k == 0 {
                return;
            }
            let q0 = b * BLOCK;
            let rows = BLOCK.min(nq - q0);
            let q = queries.subrows(q0, rows);
            // rows x nx cross terms.
            let mut cross = Mat::<f64>::zeros(rows, nx);
            matmul(
                cross.as_mut(),
                Accum::Replace,
                q,
                data.transpose(),
                1.0,
                Par::Seq,
            );
            let mut scores: Vec<(f64, usize)> = Vec::with_capacity(nx);
            let mut cand: Vec<(f64, usize)> = Vec::with_capacity(keep);
            for r in 0..rows {
                scores.clear();
                scores.extend((0..nx).map(|j| (data_norms[j] - 2.0 * cross[(r, j)], j)));
                if keep < nx {
                    scores.select_nth_unstable_by(keep - 1, |a, b| a.0.total_cmp(&b.0));
                }
                cand.clear();
                cand.extend(scores[..keep].iter().map(|&(_, j)| {
                    let dist2: f64 = (0..d)
                        .map(|c| {
                            let t = q[(r, c)] - data[(j, c)];
                            t * t
                        })
                        .sum();
                    (dist2, j)
                }));
                cand.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                for (t, &(d2, j)) in cand[..k].iter().enumerate() {
                    idx_block[r * k + t] = j;
                    dist_block[r * k + t] = d2.sqrt();
                }
            }
        });
    Ok(KNearest { k, index, distance })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(data: &Mat<f64>, queries: &Mat<f64>, k: usize) -> Vec<Vec<usize>> {
        (0..queries.nrows())
            .map(|q| {
                let mut all: Vec<(f64, usize)> = (0..data.nrows())
                    .map(|i| {
                        let d2: f64 = (0..data.ncols())
                            .map(|c| (queries[(q, c)] - data[(i, c)]).powi(2))
                            .sum();
                        (d2, i)
                    })
                    .collect();
                all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                all[..k.min(all.len())].iter().map(|x| x.1).collect()
            })
            .collect()
    }

    #[test]
    fn agrees_with_a_naive_search() {
        // Pseudo-random points in 30 dimensions, spectral-like decay.
        let mut s = 12345u64;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let data = Mat::from_fn(700, 30, |_, j| r() / (1.0 + j as f64));
        let queries = Mat::from_fn(300, 30, |_, j| r() / (1.0 + j as f64));
        let knn = k_nearest_rows(data.as_ref(), queries.as_ref(), 12).unwrap();
        let truth = naive(&data, &queries, 12);
        for (q, t) in truth.iter().enumerate() {
            assert_eq!(knn.indices(q), &t[..]);
            let ds = knn.distances(q);
            assert!(ds.windows(2).all(|w| w[0] <= w[1]));
        }
    }

    #[test]
    fn k_is_clamped_and_empty_queries_are_fine() {
        let data = Mat::from_fn(3, 2, |i, j| (i + j) as f64);
        let queries = Mat::from_fn(2, 2, |i, _| i as f64);
        let knn = k_nearest_rows(data.as_ref(), queries.as_ref(), 10).unwrap();
        assert_eq!(knn.k, 3);
        assert_eq!(knn.index.len(), 6);
        let none = Mat::<f64>::zeros(0, 2);
        assert!(
            k_nearest_rows(data.as_ref(), none.as_ref(), 4)
                .unwrap()
                .index
                .is_empty()
        );
        let bad = Mat::from_fn(1, 3, |_, _| 0.0);
        assert!(k_nearest_rows(data.as_ref(), bad.as_ref(), 1).is_err());
        let nan = Mat::from_fn(1, 2, |_, _| f64::NAN);
        assert!(k_nearest_rows(data.as_ref(), nan.as_ref(), 1).is_err());
    }
}
