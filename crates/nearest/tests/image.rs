//! [`ImageSearch`]: searches of linear images `X Mᵀ` of rows copied into
//! their clusters' order once (ZoomOut's `Φ_A Cᵀ` at every size), by
//! queries checked once ([`CheckedRows`]), against a naive f64 search of
//! the image computed directly; and its errors.

use fmaps_eigensolve::conformance::grid_basis;
use fmaps_nearest::{CheckedRows, Error, ImageSearch, Partition, view};
use nalgebra::DMatrix;

mod common;
use common::naive_nearest;

/// A near-orthogonal k_out x k_in map (a functional map's shape: the
/// identity bent by a smooth perturbation), scaled by `s`.
fn bent_map(k_out: usize, k_in: usize, s: f64) -> DMatrix<f64> {
    DMatrix::from_fn(k_out, k_in, |i, j| {
        let d = if i == j { 1.0 } else { 0.0 };
        s * (d + 0.05 * ((i * 7 + j * 3) as f64).sin() / (1.0 + (i as f64 - j as f64).abs()))
    })
}

/// The rows of `x` (first `m.ncols()` columns) times `mᵀ`, computed the
/// plain way.
fn image(x: &DMatrix<f64>, m: &DMatrix<f64>) -> DMatrix<f64> {
    x.columns(0, m.ncols()) * m.transpose()
}

#[test]
fn images_at_growing_sizes_give_the_naive_answer() {
    let b = grid_basis(48, 30, 100);
    let x = b.eigenvectors.columns(0, 60).into_owned();
    let n = x.nrows();
    let partition = Partition::kmeans(
        view(&x),
        fmaps_nearest::PartitionParams::default().ball_size,
        3,
    );
    let search = ImageSearch::new(view(&x), partition).unwrap();
    assert_eq!(search.len(), n);
    // Queries: the rows themselves, bent (a map's error), a few far off.
    let q = DMatrix::from_fn(n, 60, |i, j| {
        let bend = 1.0 + 0.3 * (j as f64 / 60.0) * ((i * 13 + j * 7) as f64).sin();
        x[(i, j)] * bend * if i % 97 == 0 { 3.0 } else { 1.0 }
    });
    let checked = CheckedRows::new(view(&q)).unwrap();
    // ZoomOut's pattern: square maps of growing size (the buffer grows),
    // then a smaller and a rectangular one (it is reused shorter), with a
    // huge and a tiny scale (the rows are rescaled by a power of two).
    let mut previous: Option<Vec<usize>> = None;
    for (k_out, k_in, s) in [
        (10, 10, 1.0),
        (20, 20, 1.0),
        (40, 40, 1.0),
        (60, 60, 1.0),
        (25, 30, 1.0),
        (30, 30, 1e40),
        (30, 30, 1e-40),
    ] {
        let m = bent_map(k_out, k_in, s);
        let want = naive_nearest(&image(&x, &m), &q.columns(0, k_out).into_owned());
        let qk = checked.leading(k_out);
        let got = search.nearest(view(&m), &qk, None).unwrap();
        assert_eq!(got, want, "{k_out} x {k_in}, scale {s}, no guesses");
        // The previous size's answer as guesses (ZoomOut), and bad ones.
        let shifted: Vec<usize> = want.iter().map(|&t| (t + 5) % n).collect();
        for hint in [previous.as_ref(), Some(&want), Some(&shifted)]
            .into_iter()
            .flatten()
        {
            let got = search.nearest(view(&m), &qk, Some(hint)).unwrap();
            assert_eq!(got, want, "{k_out} x {k_in}, scale {s}, guesses");
        }
        previous = Some(want);
    }
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let x = DMatrix::from_fn(300, 6, |i, j| ((i * (j + 3)) as f64 * 0.01).sin());
    let q = DMatrix::from_fn(20, 6, |i, j| ((i + 2 * j) as f64 * 0.05).cos());
    let p = Partition::kmeans(view(&x), 24, 2);
    // A partition of other rows.
    let short = Partition::kmeans(view(&x.rows(0, 200).into_owned()), 24, 2);
    assert!(matches!(
        ImageSearch::new(view(&x), short),
        Err(Error::SizeMismatch {
            found: 200,
            expected: 300,
            ..
        })
    ));
    // Rows that are not finite: the first one is named.
    let mut bad = x.clone();
    bad[(17, 4)] = f64::NAN;
    assert!(matches!(
        ImageSearch::new(view(&bad), p.clone()),
        Err(Error::NonFinite {
            side: "data",
            row: 17,
            col: 4,
            ..
        })
    ));
    let mut bad_q = q.clone();
    bad_q[(3, 2)] = f64::INFINITY;
    assert!(matches!(
        CheckedRows::new(view(&bad_q)),
        Err(Error::NonFinite {
            side: "query",
            row: 3,
            col: 2,
            ..
        })
    ));
    let search = ImageSearch::new(view(&x), p).unwrap();
    let checked = CheckedRows::new(view(&q)).unwrap();
    // A map wider than the rows.
    assert!(matches!(
        search.nearest(view(&bent_map(6, 7, 1.0)), &checked, None),
        Err(Error::SizeMismatch {
            found: 7,
            expected: 6,
            ..
        })
    ));
    // Queries of another width than the map's rows.
    assert!(matches!(
        search.nearest(view(&bent_map(5, 6, 1.0)), &checked, None),
        Err(Error::DimensionMismatch {
            data: 5,
            queries: 6
        })
    ));
    // Guesses not one per query.
    assert!(matches!(
        search.nearest(view(&bent_map(6, 6, 1.0)), &checked, Some(&[0; 3])),
        Err(Error::HintCount {
            found: 3,
            expected: 20
        })
    ));
    // A map whose image is not finite: the data row is named (in the
    // rows' own order, not the clusters').
    let mut m = bent_map(6, 6, 1.0);
    m[(2, 0)] = f64::NAN;
    // (NaN times any coordinate is NaN: every row's coordinate 2.)
    assert!(matches!(
        search.nearest(view(&m), &checked, None),
        Err(Error::NonFinite {
            side: "data",
            row: 0,
            col: 2,
            ..
        })
    ));
    // An image that overflows: row 123's coordinate 4 (every other row's
    // stays below 1e300), named in the rows' own order.
    let mut big = x.clone();
    big[(123, 1)] = 1e300;
    let big_search = ImageSearch::new(view(&big), Partition::kmeans(view(&x), 24, 2)).unwrap();
    let mut m = bent_map(6, 6, 1.0);
    m[(4, 1)] = 1e300;
    assert!(matches!(
        big_search.nearest(view(&m), &checked, None),
        Err(Error::NonFinite {
            side: "data",
            row: 123,
            col: 4,
            ..
        })
    ));
    // A search still works after an error (the buffer is not lost).
    let m = bent_map(6, 6, 1.0);
    let want = naive_nearest(&image(&x, &m), &q);
    assert_eq!(search.nearest(view(&m), &checked, None).unwrap(), want);
}
