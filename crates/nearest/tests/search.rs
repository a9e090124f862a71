//! The exact search against naive f64 searches: random data with
//! duplicates and near ties, spectral embeddings of a surface (the case the
//! strategies are tuned for), guesses right and wrong, gaps below f32's
//! resolution, and the worst case of the bf16 bound of the tiles.

use fmaps_eigensolve::conformance::grid_basis;
use fmaps_nearest::NnStrategy;

/// The prefix search's widths as `NnStrategy::Prefix` documents them: 40
/// leading coordinates from 64 dimensions on, half of them below, at least
/// 8.
const PREFIX_DIM: usize = 40;
const PREFIX_MIN: usize = 8;
use nalgebra::DMatrix;

mod common;
use common::{
    naive_nearest, nearest_rows, nearest_rows_hinted, nearest_rows_hinted_with, nearest_rows_with,
};

#[test]
fn nearest_rows_matches_a_naive_search() {
    // Deterministic pseudo-random data with exact duplicates and near ties.
    let mut s = 12345u64;
    let mut rnd = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    for d in [1, 3, 17, 33, 64, 150, 257] {
        let nx = 700;
        let mut x = DMatrix::from_fn(nx, d, |_, _| rnd());
        // Row 5 duplicates row 2: a tie resolved to the smaller index.
        let r2 = x.row(2).into_owned();
        x.row_mut(5).copy_from(&r2);
        let mut q = DMatrix::from_fn(300, d, |_, _| rnd());
        q.row_mut(0).copy_from(&r2);
        // A query 1e-13 away from row 9: far below the expanded-form rounding
        // of the other candidates, resolved by the direct re-check.
        let r9 = x.row(9).map(|v| v + 1e-13);
        q.row_mut(1).copy_from(&r9);
        for strategy in [
            NnStrategy::Auto,
            NnStrategy::Brute,
            NnStrategy::Tree,
            NnStrategy::Prefix,
            NnStrategy::Balls,
            NnStrategy::Tiles,
        ] {
            let got = nearest_rows_with(&x, &q, strategy);
            for (i, &g) in got.iter().enumerate() {
                let dist = |k: usize| (x.row(k) - q.row(i)).norm_squared();
                let best = (0..nx)
                    .min_by(|&a, &b| dist(a).total_cmp(&dist(b)).then(a.cmp(&b)))
                    .unwrap();
                assert_eq!(g, best, "{strategy:?} d={d} query {i}");
            }
            assert_eq!(got[0], 2);
            assert_eq!(got[1], 9);
        }
    }
}

/// Spectral embeddings of a surface (the case the tree is for: points on a
/// 2-manifold in R^k, queries near it) and queries far from the data: the
/// tree and brute force agree exactly, for every query.
#[test]
fn tree_search_equals_brute_force_on_spectral_embeddings() {
    let b = grid_basis(48, 20, 40);
    let n = b.n();
    for k in [3, 12, 40] {
        let x = b.eigenvectors.columns(0, k).into_owned();
        // Queries: every row moved by a smooth perturbation, plus far points.
        let mut q = DMatrix::from_fn(n, k, |i, j| {
            x[(i, j)] + 0.02 * ((i * 7 + j * 3) as f64).sin() * x.column(j).amax()
        });
        for i in 0..10 {
            q.row_mut(i).iter_mut().for_each(|v| *v = 3.0 + i as f64);
        }
        let brute = nearest_rows_with(&x, &q, NnStrategy::Brute);
        let tree = nearest_rows_with(&x, &q, NnStrategy::Tree);
        assert_eq!(brute, tree, "k = {k}");
        let tiles = nearest_rows_with(&x, &q, NnStrategy::Tiles);
        assert_eq!(brute, tiles, "k = {k}, tiles");
        // The unperturbed embedding maps every vertex to itself.
        let own = nearest_rows_with(&x, &x, NnStrategy::Tree);
        assert!(own.iter().enumerate().all(|(i, &j)| i == j), "k = {k}");
    }
}

/// The prefix search on spectral embeddings (from its narrowest prefix to
/// the full one): equal to brute force for every query, with no guess,
/// with exact guesses, with wrong and out-of-range guesses (on ~1100 rows,
/// where `nearest_rows_hinted` picks it from d = 64).
#[test]
fn prefix_search_equals_brute_force_whatever_the_guesses() {
    let b = grid_basis(48, 24, 80);
    let n = b.n();
    // 16: the narrowest prefix (8 coordinates); 30, 41, 48: half of the
    // coordinates; 80: PREFIX_DIM of them.
    for k in [2 * PREFIX_MIN, 30, PREFIX_DIM + 1, 48, 80] {
        let x = b.eigenvectors.columns(0, k).into_owned();
        // Queries: rows moved by a perturbation that grows with the
        // frequency (as a noisy functional map does), plus far points.
        let mut q = DMatrix::from_fn(n, k, |i, j| {
            x[(i, j)] * (1.0 + 0.3 * (j as f64 / k as f64) * ((i * 13 + j * 7) as f64).sin())
        });
        for i in 0..10 {
            q.row_mut(i).iter_mut().for_each(|v| *v = 3.0 + i as f64);
        }
        let brute = nearest_rows_with(&x, &q, NnStrategy::Brute);
        assert_eq!(
            nearest_rows_with(&x, &q, NnStrategy::Prefix),
            brute,
            "k = {k}"
        );
        assert_eq!(nearest_rows(&x, &q), brute, "k = {k}, auto");
        let shifted: Vec<usize> = brute.iter().map(|&t| (t + 17) % n).collect();
        let wild: Vec<usize> = (0..n)
            .map(|i| if i % 3 == 0 { n + i } else { (i * 31) % n })
            .collect();
        assert_eq!(
            nearest_rows_with(&x, &q, NnStrategy::Tiles),
            brute,
            "k = {k}, tiles"
        );
        for hint in [&brute, &shifted, &wild] {
            assert_eq!(nearest_rows_hinted(&x, &q, hint), brute, "k = {k}");
            assert_eq!(
                nearest_rows_hinted_with(&x, &q, hint, NnStrategy::Tiles),
                brute,
                "k = {k}, tiles with guesses"
            );
            assert_eq!(
                nearest_rows_hinted_with(&x, &q, hint, NnStrategy::Prefix),
                brute,
                "k = {k}, prefix with guesses"
            );
        }
        // Every row is its own nearest (no two vertices share an embedding).
        let own = nearest_rows_with(&x, &x, NnStrategy::Prefix);
        assert!(own.iter().enumerate().all(|(i, &j)| i == j), "k = {k}");
    }
}

/// The default clusters of the ball search ([`fmaps_nearest::Partition::for_balls`]):
/// none below the caller's row count, for zero columns, where matrix tiles
/// exist below `PartitionParams::tiled_from_rows` rows, or with `FMAPS_NO_BALLS` set
/// (not set in this test); otherwise a k-means partition of every row, the
/// same as `Partition::kmeans` with the default sizes on the leading half
/// of the columns (at least 64; 75 of 150 here).
#[test]
fn default_ball_clusters_follow_the_policy() {
    use fmaps_nearest::{BallsRequest, Partition, PartitionParams, tiles_available, view};
    let PartitionParams {
        ball_size,
        kmeans_steps,
        tiled_from_rows,
        ..
    } = PartitionParams::default();
    if std::env::var_os("FMAPS_NO_BALLS").is_some() {
        use std::io::Write as _;
        let _ = writeln!(
            std::io::stderr(),
            "note: default_ball_clusters_follow_the_policy: skipped, FMAPS_NO_BALLS is set"
        );
        return;
    }
    let b = grid_basis(48, 24, 150);
    let rows = b.eigenvectors.columns(0, 150).into_owned();
    let n = rows.nrows();
    assert!(Partition::for_balls(view(&rows), BallsRequest::new(n + 1)).is_none());
    assert!(Partition::for_balls(view(&rows).subcols(0, 0), BallsRequest::new(1)).is_none());
    let got = Partition::for_balls(view(&rows), BallsRequest::new(n));
    if tiles_available() {
        eprintln!(
            "note: default_ball_clusters_follow_the_policy: AMX tiles here, so no clusters (the tile search is used); the clustering is checked without tiles"
        );
        assert!(got.is_none());
    } else {
        let got = got.expect("clusters without tiles");
        assert_eq!(got.len(), n);
        assert_eq!(
            got,
            Partition::kmeans(view(&rows).subcols(0, 75), ball_size, kmeans_steps)
        );
        assert_ne!(
            got,
            Partition::kmeans(view(&rows), ball_size, kmeans_steps),
            "the clusters of all columns differ here, so the test sees the column count"
        );
    }
    // From `tiled_from_rows` rows clusters on every CPU; one row fewer
    // only without tiles (rows of any smooth map: the policy looks at the
    // counts only).
    let big = |n: usize| {
        faer::Mat::<f64>::from_fn(n, 3, |i, j| ((i as f64) * 0.001 * (j + 1) as f64).sin())
    };
    let at = big(tiled_from_rows);
    let got = Partition::for_balls(at.as_ref(), BallsRequest::new(1))
        .expect("clusters from tiled_from_rows rows");
    assert_eq!(got.len(), tiled_from_rows);
    let below = big(tiled_from_rows - 1);
    assert_eq!(
        Partition::for_balls(below.as_ref(), BallsRequest::new(1)).is_some(),
        !tiles_available()
    );
}

/// The ball search on spectral embeddings, as ZoomOut runs it: the
/// clusters computed once on the embedding and reused for linear images
/// of it (`Φ Cᵀ` for near-isometric and rough maps `C`), and clusters
/// that fit the rows badly (stripes of every 7th row, one cluster of
/// everything, singletons): equal to brute force for every query, with no
/// guess, exact, shifted and out-of-range guesses.
#[test]
fn ball_search_equals_brute_force_with_any_partition() {
    use fmaps_nearest::{NnParams, Partition, PartitionParams, view};
    let defaults = PartitionParams::default();
    let b = grid_basis(48, 24, 80);
    let n = b.n();
    let own = Partition::kmeans(
        view(&b.eigenvectors.columns(0, 80).into_owned()),
        defaults.ball_size,
        defaults.kmeans_steps,
    );
    let partitions = [
        own,
        Partition::from_labels((0..n as u32).map(|i| i % 7).collect()),
        Partition::from_labels(vec![0; n]),
        Partition::from_labels((0..n as u32).collect()),
    ];
    for k in [3, 12, 40, 80] {
        let phi = b.eigenvectors.columns(0, k).into_owned();
        // A near-identity map with sign flips and mixing, and a rough one.
        for (m, c) in [(0, 0.05), (1, 0.6)] {
            let cmat = DMatrix::from_fn(k, k, |i, j| {
                let sign = if (i + m) % 3 == 0 { -1.0 } else { 1.0 };
                (if i == j { sign } else { 0.0 })
                    + c * (((i * 7 + j * 3 + m) as f64).sin()) / k as f64
            });
            let x = &phi * cmat.transpose();
            let mut q = DMatrix::from_fn(n, k, |i, j| {
                phi[(i, j)] * (1.0 + 0.2 * ((i * 13 + j * 7) as f64).sin())
            });
            for i in 0..10 {
                q.row_mut(i).iter_mut().for_each(|v| *v = 3.0 + i as f64);
            }
            let brute = nearest_rows_with(&x, &q, NnStrategy::Brute);
            let shifted: Vec<usize> = brute.iter().map(|&t| (t + 17) % n).collect();
            let wild: Vec<usize> = (0..n)
                .map(|i| if i % 3 == 0 { n + i } else { (i * 31) % n })
                .collect();
            for (pi, p) in partitions.iter().enumerate() {
                let params = NnParams::with_strategy(NnStrategy::Balls).with_partition(p.clone());
                let run = |hint: Option<&[usize]>| {
                    fmaps_nearest::nearest_rows(view(&x), view(&q), hint, &params).unwrap()
                };
                assert_eq!(run(None), brute, "k = {k}, map {m}, partition {pi}");
                for hint in [&brute, &shifted, &wild] {
                    assert_eq!(
                        run(Some(hint)),
                        brute,
                        "k = {k}, map {m}, partition {pi}, guesses"
                    );
                }
                // Auto takes the clusters with guesses and > 32 coordinates.
                let auto = fmaps_nearest::nearest_rows(
                    view(&x),
                    view(&q),
                    Some(&shifted),
                    &NnParams::default().with_partition(p.clone()),
                )
                .unwrap();
                assert_eq!(auto, brute, "k = {k}, map {m}, partition {pi}, auto");
            }
            // Row-major views (read in place), and magnitudes far outside
            // f32's comfort range (the search works on exactly rescaled
            // copies).
            for scale in [1.0, 1e-200, 1e200] {
                let (xs, qs) = (&x * scale, &q * scale);
                let want = nearest_rows_with(&xs, &qs, NnStrategy::Brute);
                let (xt, qt) = (xs.transpose(), qs.transpose());
                let params = NnParams::with_strategy(NnStrategy::Balls)
                    .with_partition(partitions[0].clone());
                // With guesses, and without (each query then seeded from
                // its nearest centre's ball, in the rescaled copy).
                for hint in [Some(shifted.as_slice()), None] {
                    let found = fmaps_nearest::nearest_rows(
                        faer::MatRef::from_row_major_slice(xt.as_slice(), n, k),
                        faer::MatRef::from_row_major_slice(qt.as_slice(), n, k),
                        hint,
                        &params,
                    )
                    .unwrap();
                    let how = if hint.is_some() { "guesses" } else { "seeds" };
                    assert_eq!(
                        found, want,
                        "k = {k}, map {m}, row-major, x{scale:e}, {how}"
                    );
                }
            }
        }
    }
}

/// The tile search where bf16 resolves nothing (rows 1e-3 apart on a
/// common offset of 1e3: the bf16 step there is 4) and where its products
/// could overflow (1e16, handed to brute force): the exact answer.
#[test]
fn tiles_exact_where_bf16_is_coarse_or_out_of_range() {
    common::note_if_no_tiles("tiles_exact_where_bf16_is_coarse_or_out_of_range");
    for (offset, spread) in [(1e3, 1e-3), (1.0, 3e-3), (1e16, 1e13), (0.0, 1e-30)] {
        let (nx, d) = (300, 40);
        let x = DMatrix::from_fn(nx, d, |i, j| {
            offset + spread * (((i * 37 + j * 11) % 101) as f64 - 50.0)
        });
        let q = DMatrix::from_fn(120, d, |i, j| {
            offset + spread * (((i * 53 + j * 7) % 97) as f64 - 48.5)
        });
        let got = nearest_rows_with(&x, &q, NnStrategy::Tiles);
        assert_eq!(got, naive_nearest(&x, &q), "offset {offset}");
    }
    // Near ties: each query a hair off the midpoint of two random rows in
    // [0.5, 1.5]^d (bf16 steps of 2⁻⁸..2⁻⁷ there), so that the two
    // distances differ far below the bf16 rounding of the scores.
    let mut st = 99u64;
    let mut rnd = || {
        st = st
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (st >> 11) as f64 / (1u64 << 53) as f64
    };
    let (nx, d) = (400, 64);
    let x = DMatrix::from_fn(nx, d, |_, _| 0.5 + rnd());
    let q = DMatrix::from_fn(400, d, |i, j| {
        let (a, b) = ((i * 7) % nx, (i * 13 + 1) % nx);
        0.5 * (x[(a, j)] + x[(b, j)]) + 1e-7 * (rnd() - 0.5)
    });
    let got = nearest_rows_with(&x, &q, NnStrategy::Tiles);
    assert_eq!(got, naive_nearest(&x, &q), "near ties");
    // The worst case of the bound: every coordinate of the query (1 +
    // 0.99·2⁻⁸) and of row 5 (1 + 0.98·2⁻⁸) rounds down to 1, so row 5's
    // score is computed too high by nearly the whole bound; row 9 (1 −
    // 0.4·2⁻⁸, also 1 in bf16, smaller norm) ranks first and is farther.
    // A bound 0.9 times as large misses row 5.
    let h = 2f64.powi(-8);
    let mut x = DMatrix::from_fn(64, d, |_, _| 2.0 + rnd());
    x.row_mut(5).fill(1.0 + 0.98 * h);
    x.row_mut(9).fill(1.0 - 0.4 * h);
    let q = DMatrix::from_element(3, d, 1.0 + 0.99 * h);
    assert_eq!(nearest_rows_with(&x, &q, NnStrategy::Tiles), vec![5; 3]);
    assert_eq!(
        nearest_rows_hinted_with(&x, &q, &[9, 9, 0], NnStrategy::Tiles),
        vec![5; 3]
    );
}

/// Rows closer than f32 can resolve: the f32 GEMM only selects candidates,
/// the f64 re-check must still return the true nearest row.
#[test]
fn nearest_rows_resolves_below_f32_precision() {
    let d = 30;
    let base: Vec<f64> = (0..d).map(|j| 1.0 + 0.37 * j as f64).collect();
    // 50 rows equal to `base` up to 1e-9 offsets (f32 rounds them alike).
    let x = DMatrix::from_fn(50, d, |i, j| {
        base[j] + if j == 3 { 1e-9 * i as f64 } else { 0.0 }
    });
    for target in [0usize, 17, 49] {
        let q = DMatrix::from_fn(1, d, |_, j| {
            base[j]
                + if j == 3 {
                    1e-9 * target as f64 + 2e-10
                } else {
                    0.0
                }
        });
        assert_eq!(nearest_rows(&x, &q), vec![target]);
        assert_eq!(nearest_rows_with(&x, &q, NnStrategy::Tree), vec![target]);
    }
    // The same in a dimension where the prefix search applies: the near
    // ties differ only beyond the prefix.
    let d = PREFIX_DIM + 8;
    let base: Vec<f64> = (0..d).map(|j| 1.0 + 0.37 * j as f64).collect();
    let off = PREFIX_DIM + 3;
    let x = DMatrix::from_fn(50, d, |i, j| {
        base[j] + if j == off { 1e-9 * i as f64 } else { 0.0 }
    });
    for target in [0usize, 17, 49] {
        let q = DMatrix::from_fn(1, d, |_, j| {
            base[j]
                + if j == off {
                    1e-9 * target as f64 + 2e-10
                } else {
                    0.0
                }
        });
        assert_eq!(nearest_rows_with(&x, &q, NnStrategy::Prefix), vec![target]);
        assert_eq!(nearest_rows_hinted(&x, &q, &[3]), vec![target]);
    }
}

/// A `Searcher` answers every query set as the one-off search (and the
/// naive one) does, whatever the strategy, after its data side is kept:
/// several query sets in a row, with and without guesses, data far
/// outside f32's range (kept in its power-of-two scale), and queries in
/// another scale than the data (the one-off path).
#[test]
fn a_searcher_answers_every_query_set_like_the_one_off_search() {
    use fmaps_nearest::{NnParams, Searcher, view};
    let b = grid_basis(30, 24, 70);
    for data_scale in [1.0, 1e-30] {
        let x = b.eigenvectors.columns(0, 70).map(|v| v * data_scale);
        // Query sets and their naive answers, the same for every strategy.
        let rounds: Vec<(DMatrix<f64>, Vec<usize>)> = [1.0, 1.0, 1e20, 1.0]
            .into_iter()
            .enumerate()
            .map(|(round, query_scale)| {
                let q = DMatrix::from_fn(300 + 50 * round, 70, |i, j| {
                    let r = (i * 7 + round) % 720;
                    x[(r, j)] * query_scale
                        + 0.05 * data_scale * ((i * 13 + j * 5 + round) as f64).sin()
                            / (1.0 + j as f64).sqrt()
                });
                let want = naive_nearest(&x, &q);
                (q, want)
            })
            .collect();
        for strategy in [
            NnStrategy::Auto,
            NnStrategy::Brute,
            NnStrategy::Tree,
            NnStrategy::Prefix,
            NnStrategy::Tiles,
        ] {
            let searcher = Searcher::new(view(&x), &NnParams::with_strategy(strategy)).unwrap();
            assert_eq!((searcher.n(), searcher.dim()), (720, 70));
            for (round, (q, want)) in rounds.iter().enumerate() {
                let guess: Vec<usize> = want.iter().map(|&t| (t + round) % 720).collect();
                for hint in [None, Some(guess.as_slice())] {
                    assert_eq!(
                        &searcher.search(view(q), hint).unwrap(),
                        want,
                        "{strategy:?}, data x{data_scale:e}, round {round}, hint {}",
                        hint.is_some()
                    );
                }
            }
            assert!(searcher.search(view(&DMatrix::zeros(3, 5)), None).is_err());
        }
    }
}

/// Bad input is an error naming the row, never an out-of-range index.
#[test]
fn bad_input_is_an_error() {
    use faer::MatRef;
    use fmaps_nearest::{Error, NnParams, Searcher, nearest_rows, view};
    let p = NnParams::default();
    let x = DMatrix::from_fn(40, 6, |i, j| (i * 3 + j) as f64);
    let mut q = DMatrix::from_fn(10, 6, |i, j| (i + j) as f64);
    assert_eq!(
        nearest_rows(view(&x), view(&DMatrix::zeros(0, 6)), None, &p).unwrap(),
        Vec::<usize>::new()
    );
    assert_eq!(
        nearest_rows(view(&DMatrix::zeros(0, 6)), view(&q), None, &p).unwrap_err(),
        Error::NoData { queries: 10 }
    );
    assert!(matches!(
        nearest_rows(view(&x), view(&DMatrix::zeros(3, 5)), None, &p),
        Err(Error::DimensionMismatch {
            data: 6,
            queries: 5
        })
    ));
    assert!(matches!(
        nearest_rows(view(&x), view(&q), Some(&[0, 1]), &p),
        Err(Error::HintCount {
            found: 2,
            expected: 10
        })
    ));
    q[(7, 4)] = f64::NAN;
    assert!(matches!(
        nearest_rows(view(&x), view(&q), None, &p),
        Err(Error::NonFinite {
            side: "query",
            row: 7,
            col: 4,
            ..
        })
    ));
    // The same through a row-major view (checked row by row).
    let qt = q.transpose();
    assert!(matches!(
        nearest_rows(
            view(&x),
            MatRef::from_row_major_slice(qt.as_slice(), 10, 6),
            None,
            &p
        ),
        Err(Error::NonFinite {
            side: "query",
            row: 7,
            col: 4,
            ..
        })
    ));
    let mut bad = x.clone();
    bad[(12, 1)] = f64::INFINITY;
    assert!(matches!(
        nearest_rows(view(&bad), view(&x), None, &p),
        Err(Error::NonFinite {
            side: "data",
            row: 12,
            col: 1,
            ..
        })
    ));
    assert!(matches!(
        Searcher::new(view(&bad), &p),
        Err(Error::NonFinite { row: 12, .. })
    ));
    // The ball search checks finiteness in its own pass (with the scale):
    // the same errors, data first.
    let balls = NnParams::with_strategy(fmaps_nearest::NnStrategy::Balls)
        .with_partition(fmaps_nearest::Partition::kmeans(view(&x), 8, 2));
    assert!(matches!(
        nearest_rows(view(&x), view(&q), None, &balls),
        Err(Error::NonFinite {
            side: "query",
            row: 7,
            col: 4,
            ..
        })
    ));
    assert!(matches!(
        nearest_rows(view(&bad), view(&q), None, &balls),
        Err(Error::NonFinite {
            side: "data",
            row: 12,
            col: 1,
            ..
        })
    ));
    q[(7, 4)] = 0.5;
    assert_eq!(
        nearest_rows(view(&x), view(&q), None, &balls).unwrap(),
        nearest_rows(view(&x), view(&q), None, &p).unwrap()
    );
    // Huge finite values whose column sums overflow are not an error.
    let big = DMatrix::from_fn(4, 2, |i, _| 1e308 * (1.0 - i as f64 * 0.1));
    assert_eq!(
        nearest_rows(view(&big), view(&big), None, &p).unwrap(),
        vec![0, 1, 2, 3]
    );
    // No coordinates: every row at distance 0, the smallest index wins.
    let empty = DMatrix::<f64>::zeros(5, 0);
    assert_eq!(
        nearest_rows(view(&empty), view(&DMatrix::zeros(3, 0)), None, &p).unwrap(),
        vec![0; 3]
    );
}
