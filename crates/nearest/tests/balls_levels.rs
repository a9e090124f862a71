//! The ball search with the clusters of a [`Partition`] (ZoomOut's and
//! ICP's path: the data gathered into its clusters' order and scanned in
//! the same pass, the tangent bounds filtered eight balls at a time where
//! the CPU has AVX-512), at every instruction-set level this CPU has,
//! against a naive f64 search, with and without guesses. Partitions are
//! only made where matrix tiles are off, so this binary turns them off
//! (`FMAPS_NO_AMX`) before its first search: one test in its own binary.

use fmaps_eigensolve::conformance::grid_basis;
use fmaps_nearest::{BallsRequest, NnParams, NnStrategy, Partition, view};
use nalgebra::DMatrix;

mod common;
use common::naive_nearest;

#[test]
fn partitioned_balls_give_the_naive_answer_at_every_level() {
    // SAFETY: set before this process's first search, while this test is
    // its only thread (the variable is read once, on the first search).
    unsafe { std::env::set_var("FMAPS_NO_AMX", "1") };
    let b = grid_basis(48, 30, 100);
    let sets: Vec<(DMatrix<f64>, DMatrix<f64>)> = [8, 40, 100]
        .into_iter()
        .map(|k| {
            let x = b.eigenvectors.columns(0, k).into_owned();
            // Queries near the rows, bent by a smooth factor (a functional
            // map's error), and a few far away.
            let q = DMatrix::from_fn(x.nrows(), k, |i, j| {
                let bend = 1.0 + 0.3 * (j as f64 / k as f64) * ((i * 13 + j * 7) as f64).sin();
                x[(i, j)] * bend * if i % 97 == 0 { 3.0 } else { 1.0 }
            });
            (x, q)
        })
        .collect();
    let mut ran = Vec::new();
    fmaps_simd::at_every_level(|level| {
        for (x, q) in &sets {
            let (n, d) = x.shape();
            let want = naive_nearest(x, q);
            let partition = Partition::for_balls(view(x), BallsRequest::new(1))
                .expect("clusters without tiles");
            let params = NnParams::with_strategy(NnStrategy::Balls).with_partition(partition);
            let shifted: Vec<usize> = want.iter().map(|&t| (t + 5) % n).collect();
            for hint in [None, Some(&want), Some(&shifted)] {
                let got = fmaps_nearest::nearest_rows(
                    view(x),
                    view(q),
                    hint.map(|h| h.as_slice()),
                    &params,
                )
                .unwrap();
                assert_eq!(got, want, "{level:?} d = {d}, guesses: {}", hint.is_some());
            }
        }
        ran.push(level.name());
    });
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "note: levels checked: {ran:?}");
    assert!(ran.contains(&"baseline"));
}
