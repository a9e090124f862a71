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
