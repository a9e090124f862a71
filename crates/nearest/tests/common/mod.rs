//! Shared test helpers: a naive nearest-row search; short forms of
//! [`fmaps_nearest::nearest_rows`] on nalgebra matrices. (Spectral embeddings,
//! the rows this crate is tuned for, come from
//! `fmaps_eigensolve::conformance::grid_basis`: a weighted grid, a surface
//! without symmetry.)

// Each test binary uses some of these helpers.
#![allow(dead_code)]

use fmaps_nearest::{NnParams, NnStrategy, view};
use nalgebra::DMatrix;

/// The nearest row of each query by direct f64 distances (ties: the
/// smaller index).
pub fn naive_nearest(x: &DMatrix<f64>, q: &DMatrix<f64>) -> Vec<usize> {
    (0..q.nrows())
        .map(|i| {
            let dist = |k: usize| (x.row(k) - q.row(i)).norm_squared();
            (0..x.nrows())
                .min_by(|&a, &b| dist(a).total_cmp(&dist(b)).then(a.cmp(&b)))
                .unwrap()
        })
        .collect()
}

/// [`fmaps_nearest::nearest_rows`] with the default strategy.
pub fn nearest_rows(x: &DMatrix<f64>, q: &DMatrix<f64>) -> Vec<usize> {
    nearest_rows_with(x, q, NnStrategy::Auto)
}

/// [`fmaps_nearest::nearest_rows`] with `strategy`.
pub fn nearest_rows_with(x: &DMatrix<f64>, q: &DMatrix<f64>, strategy: NnStrategy) -> Vec<usize> {
    fmaps_nearest::nearest_rows(view(x), view(q), None, &NnParams::with_strategy(strategy)).unwrap()
}

/// [`fmaps_nearest::nearest_rows`] with guesses.
pub fn nearest_rows_hinted(x: &DMatrix<f64>, q: &DMatrix<f64>, hint: &[usize]) -> Vec<usize> {
    nearest_rows_hinted_with(x, q, hint, NnStrategy::Auto)
}

/// [`fmaps_nearest::nearest_rows`] with guesses and `strategy`.
pub fn nearest_rows_hinted_with(
    x: &DMatrix<f64>,
    q: &DMatrix<f64>,
    hint: &[usize],
    strategy: NnStrategy,
) -> Vec<usize> {
    fmaps_nearest::nearest_rows(
        view(x),
        view(q),
        Some(hint),
        &NnParams::with_strategy(strategy),
    )
    .unwrap()
}

/// Says, past the test harness's output capture (so that it shows in a
/// passing run), that a test checks the fallback of the matrix tiles
/// because this CPU (or `FMAPS_NO_AMX`) has none.
pub fn note_if_no_tiles(test: &str) {
    use std::io::Write;
    if !fmaps_nearest::tiles_available() {
        let _ = writeln!(
            std::io::stderr(),
            "note: {test}: no AMX tiles here (or FMAPS_NO_AMX is set); NnStrategy::Tiles is checked through its fallback, the tile kernel is skipped"
        );
    }
}
