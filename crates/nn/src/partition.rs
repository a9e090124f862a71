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

impl Partition {
    /// k-means clusters of the rows of `rows` (n x d), about `size` rows
    /// each: the principal-direction bisection of the rows into clusters of
    /// at most `size`, then `steps` Lloyd steps (each row to its nearest
    /// cluster mean, by one f64 GEMM per block of rows). Bisection alone
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
    /// fast with compact clusters of ~[`BALL_SIZE`](crate::BALL_SIZE) rows, e.g. patches of
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
        for _ in 0..steps {
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
            let cm = MatRef::from_row_major_slice(&centers, m, d);
            const BLOCK: usize = 256;
            labels
                .par_chunks_mut(BLOCK)
                .enumerate()
                .for_each(|(b, out)| {
                    let r0 = b * BLOCK;
                    let xb = MatRef::from_row_major_slice(
                        &rows[r0 * d..(r0 + out.len()) * d],
                        out.len(),
                        d,
                    );
                    let mut g = Mat::<f64>::zeros(out.len(), m);
                    matmul(
                        g.as_mut(),
                        Accum::Replace,
                        xb,
                        cm.transpose(),
                        1.0,
                        Par::Seq,
                    );
                    for (i, o) in out.iter_mut().enumerate() {
                        let mut best = (f64::INFINITY, *o);
                        for j in 0..m {
                            let s = c_norm[j] - 2.0 * g[(i, j)];
                            if s < best.0 {
                                best = (s, j as u32);
                            }
                        }
                        *o = best.1;
                    }
                });
        }
        Partition { labels }
    }

    /// Row indices grouped by cluster (clusters in label order, rows
    /// ascending within each; empty clusters left out) and each
    /// non-empty cluster's (start, len).
    pub(crate) fn groups(&self) -> (Vec<usize>, Vec<(usize, usize)>) {
        let m = self
            .labels
            .iter()
            .map(|&l| l as usize + 1)
            .max()
            .unwrap_or(0);
        let mut count = vec![0usize; m + 1];
        for &l in &self.labels {
            count[l as usize + 1] += 1;
        }
        for j in 0..m {
            count[j + 1] += count[j];
        }
        let mut order = vec![0usize; self.labels.len()];
        let mut next = count.clone();
        for (i, &l) in self.labels.iter().enumerate() {
            order[next[l as usize]] = i;
            next[l as usize] += 1;
        }
        let ranges = (0..m)
            .filter(|&j| count[j + 1] > count[j])
            .map(|j| (count[j], count[j + 1] - count[j]))
            .collect();
        (order, ranges)
    }
}
