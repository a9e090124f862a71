//! Exact nearest neighbours of query rows among data rows, in any
//! dimension: `|q − x|² = |x|² − 2 q·x + |q|²`, the cross terms as blocked
//! GEMMs (faer, f64), the minimum per query, and every candidate within a
//! rounding band of it re-checked with a direct distance, so the result is
//! the true nearest row (ties: the smallest index). Memory is bounded by
//! the block size, never n_queries x n_data.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// Queries per block.
const BLOCK: usize = 256;

/// For every row of `queries` (n_q x d), the index of the nearest row of
/// `data` (n_x x d). Panics if the dimensions differ (a programming error
/// of the caller; the public conversions check sizes first).
#[track_caller]
pub fn nearest_rows(data: &DMatrix<f64>, queries: &DMatrix<f64>) -> Vec<usize> {
    assert_eq!(
        data.ncols(),
        queries.ncols(),
        "nearest_rows: dimensions differ"
    );
    let (nx, d) = (data.nrows(), data.ncols());
    if nx == 0 {
        return vec![0; queries.nrows()];
    }
    // Row-major copies: each row contiguous, for the direct re-checks.
    let x_rows: Vec<f64> = (0..nx)
        .flat_map(|i| data.row(i).iter().copied().collect::<Vec<_>>())
        .collect();
    let x_norm: Vec<f64> = x_rows
        .chunks(d.max(1))
        .map(|r| r.iter().map(|v| v * v).sum())
        .collect();
    let x_mat = MatRef::from_column_major_slice(data.as_slice(), nx, d);
    let nq = queries.nrows();
    let starts: Vec<usize> = (0..nq).step_by(BLOCK).collect();
    starts
        .par_iter()
        .flat_map_iter(|&q0| {
            let rows = BLOCK.min(nq - q0);
            let q = Mat::<f64>::from_fn(rows, d, |i, j| queries[(q0 + i, j)]);
            // Sᵀ = X Qᵀ (nx x rows): column i holds query i's cross terms,
            // contiguous for the scans below.
            let mut s = Mat::<f64>::zeros(nx, rows);
            matmul(
                s.as_mut(),
                Accum::Replace,
                x_mat,
                q.transpose(),
                1.0,
                Par::Seq,
            );
            (0..rows)
                .map(|i| {
                    let qi: Vec<f64> = (0..d).map(|j| q[(i, j)]).collect();
                    let q_norm: f64 = qi.iter().map(|v| v * v).sum();
                    let col = s.col_as_slice(i);
                    let score = |k: usize| x_norm[k] - 2.0 * col[k];
                    let mut best = f64::INFINITY;
                    let mut scale = q_norm;
                    for k in 0..nx {
                        best = best.min(score(k));
                        scale = scale.max(x_norm[k]);
                    }
                    // Rounding of the expanded form is ~1e-16 · (|x|² + |q|²);
                    // everything within a generous band is checked directly.
                    let band = 1e-12 * (scale + q_norm);
                    let mut arg = usize::MAX;
                    let mut best_d = f64::INFINITY;
                    for k in 0..nx {
                        if score(k) <= best + band {
                            let xk = &x_rows[k * d..(k + 1) * d];
                            let dist: f64 =
                                xk.iter().zip(&qi).map(|(a, b)| (a - b) * (a - b)).sum();
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
