//! Every nearest-neighbour strategy against a naive f64 search on random
//! point sets: sizes that do not fill the tiles' blocks, dimensions that
//! do not fill their 32-coordinate steps, offsets and scales where bf16
//! resolves little, duplicated rows, queries on or between rows, and
//! guesses that are right, wrong or out of range; and both directions at
//! once (`nearest_rows_both`).

mod common;
use common::{naive_nearest, nearest_rows_hinted_with, nearest_rows_with};
use faer::MatRef;
use fmaps_nearest::{NnParams, NnStrategy, nearest_rows, nearest_rows_both, view};
use nalgebra::DMatrix;
use proptest::prelude::*;

/// A deterministic stream of uniform values in [0, 1).
fn stream(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed | 1;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn tiles_note() {
    common::note_if_no_tiles("every_strategy_is_exact");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn every_strategy_is_exact(
        nx in 1usize..300,
        nq in 1usize..200,
        d in 1usize..80,
        offset in prop_oneof![Just(0.0), Just(1.0), Just(-37.0), Just(1e4)],
        scale in prop_oneof![Just(1.0), Just(1e-3), Just(1e6)],
        seed in any::<u64>(),
    ) {
        let mut rnd = stream(seed);
        let mut x = DMatrix::from_fn(nx, d, |_, _| offset + scale * (rnd() - 0.5));
        if nx > 3 {
            // A duplicated row: ties go to the smaller index.
            let r = x.row(1).into_owned();
            x.row_mut(nx - 1).copy_from(&r);
        }
        let q = DMatrix::from_fn(nq, d, |i, j| match i % 3 {
            // On a row, near the midpoint of two rows (a hair off, so that
            // the two distances differ by far more than f64 rounding and
            // the naive search's summation order does not matter), or
            // anywhere.
            0 => x[(i % nx, j)],
            1 => 0.5 * (x[(i % nx, j)] + x[((i * 7 + 1) % nx, j)]) + 1e-6 * scale * (rnd() - 0.5),
            _ => offset + scale * (rnd() - 0.5),
        });
        let want = naive_nearest(&x, &q);
        // Both ways at once (the fused kernel up to 32 coordinates).
        let (qx, xq) = nearest_rows_both(view(&q), view(&x)).unwrap();
        prop_assert_eq!(&qx, &want, "both ways: queries to rows");
        prop_assert_eq!(&xq, &naive_nearest(&q, &x), "both ways: rows to queries");
        for strategy in [NnStrategy::Auto, NnStrategy::Brute, NnStrategy::Tree, NnStrategy::Prefix, NnStrategy::Balls, NnStrategy::Tiles] {
            prop_assert_eq!(&nearest_rows_with(&x, &q, strategy), &want, "{:?}", strategy);
        }
        let guesses: Vec<usize> = (0..nq).map(|i| match i % 4 {
            0 => want[i],
            1 => (want[i] + 1) % nx,
            2 => nx + i,
            _ => (i * 13) % nx,
        }).collect();
        for strategy in [NnStrategy::Auto, NnStrategy::Prefix, NnStrategy::Balls, NnStrategy::Tiles] {
            prop_assert_eq!(&nearest_rows_hinted_with(&x, &q, &guesses, strategy), &want, "{:?} with guesses", strategy);
        }
        // Views: column-major, row-major, and the leading columns of a
        // wider row-major matrix (rows read in place).
        let wide = |m: &DMatrix<f64>, extra: usize| {
            let w = m.ncols() + extra;
            let mut v = vec![f64::NAN; m.nrows() * w];
            for i in 0..m.nrows() {
                for j in 0..m.ncols() {
                    v[i * w + j] = m[(i, j)];
                }
            }
            (v, w)
        };
        let ((xw, wx), (qw, wq)) = (wide(&x, 3), wide(&q, 0));
        let xv = MatRef::from_row_major_slice_with_stride(&xw, nx, d, wx);
        let qv = MatRef::from_row_major_slice_with_stride(&qw, nq, d, wq);
        let xc = MatRef::from_column_major_slice(x.as_slice(), nx, d);
        for strategy in [NnStrategy::Auto, NnStrategy::Brute, NnStrategy::Balls, NnStrategy::Tiles] {
            prop_assert_eq!(&nearest_rows(xv, qv, None, &NnParams::with_strategy(strategy)).unwrap(), &want, "{:?} on row views", strategy);
            prop_assert_eq!(&nearest_rows(xc, qv, Some(&guesses), &NnParams::with_strategy(strategy)).unwrap(), &want, "{:?} on mixed views", strategy);
        }
    }
}
