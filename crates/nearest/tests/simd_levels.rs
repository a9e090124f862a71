//! Every instruction-set level this CPU has, forced in turn with
//! [`fmaps_nearest::set_simd_cap`], against a naive f64 search: brute force
//! (the fused kernel up to 32 dimensions, the GEMM path above), the tree,
//! the prefix search with and without guesses, and the k nearest rows.
//! One test in its own binary: the cap is process-wide. Levels the CPU
//! lacks are reported as skipped.

use fmaps_eigensolve::conformance::grid_basis;
use fmaps_nearest::{NnStrategy, SimdLevel, k_nearest_rows, set_simd_cap, simd_level, view};
use nalgebra::DMatrix;

mod common;
use common::{naive_nearest, nearest_rows_hinted_with, nearest_rows_with};

#[test]
fn every_simd_level_gives_the_naive_answer() {
    use std::io::Write;
    let mut s = 777u64;
    let mut rnd = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let random: Vec<(DMatrix<f64>, DMatrix<f64>)> = [3, 20, 32, 40, 70]
        .into_iter()
        .map(|d| {
            (
                DMatrix::from_fn(600, d, |_, _| rnd()),
                DMatrix::from_fn(250, d, |_, _| rnd()),
            )
        })
        .collect();
    let b = grid_basis(40, 20, 96);
    let spectral: Vec<(DMatrix<f64>, DMatrix<f64>)> = [24, 96]
        .into_iter()
        .map(|k| {
            let x = b.eigenvectors.columns(0, k).into_owned();
            let q = DMatrix::from_fn(x.nrows(), k, |i, j| {
                x[(i, j)] * (1.0 + 0.3 * (j as f64 / k as f64) * ((i * 13 + j * 7) as f64).sin())
            });
            (x, q)
        })
        .collect();
    let want: Vec<Vec<usize>> = random
        .iter()
        .chain(&spectral)
        .map(|(x, q)| naive_nearest(x, q))
        .collect();
    let mut ran = Vec::new();
    for level in SimdLevel::ALL {
        if !level.detected() {
            let _ = writeln!(
                std::io::stderr(),
                "note: {}: skipped, this CPU does not have it",
                level.name()
            );
            continue;
        }
        set_simd_cap(Some(level));
        assert_eq!(simd_level(), level);
        for ((x, q), want) in random.iter().chain(&spectral).zip(&want) {
            let d = x.ncols();
            for strategy in [
                NnStrategy::Brute,
                NnStrategy::Tree,
                NnStrategy::Prefix,
                NnStrategy::Balls,
            ] {
                let got = nearest_rows_with(x, q, strategy);
                assert_eq!(&got, want, "{level:?} {strategy:?} d = {d}");
            }
            let shifted: Vec<usize> = want.iter().map(|&t| (t + 5) % x.nrows()).collect();
            for hint in [want, &shifted] {
                let got = nearest_rows_hinted_with(x, q, hint, NnStrategy::Prefix);
                assert_eq!(&got, want, "{level:?} prefix with guesses, d = {d}");
                let got = nearest_rows_hinted_with(x, q, hint, NnStrategy::Balls);
                assert_eq!(&got, want, "{level:?} balls with guesses, d = {d}");
            }
            let knn = k_nearest_rows(view(x), view(q), 3).unwrap();
            let first: Vec<usize> = knn.index.chunks(knn.k).map(|r| r[0]).collect();
            assert_eq!(&first, want, "{level:?} k nearest, d = {d}");
        }
        ran.push(level.name());
    }
    set_simd_cap(None);
    let _ = writeln!(std::io::stderr(), "note: levels checked: {ran:?}");
    assert!(ran.contains(&"baseline"));
}
