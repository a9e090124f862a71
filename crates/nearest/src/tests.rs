//! Unit tests of the internal strategies and bounds.

use nalgebra::DMatrix;

use crate::brute::{
    BruteData, GROUP, PANEL, brute_search, fused_err, fused_scores_body, power_of_two_scale,
};
#[cfg(target_arch = "x86_64")]
use crate::brute::{WIDE_GROUP, fused_scores_avx512};
use crate::prefix::{prefix_search, prefix_search_with};
use crate::rows::{dist2, row_major};
use crate::tree::tree_search;
use crate::{NnParams, NnStrategy, nearest_rows, view};

/// Both ways of scoring the prefix search's candidates (per candidate,
/// and one GEMM over the block's union) return the brute-force answer,
/// with and without guesses, on points near a curved 2-manifold in
/// R^70 (as spectral embeddings are) whose spread decays with the
/// coordinate.
#[test]
fn prefix_search_paths_equal_brute_force() {
    let (n, d) = (1500, 70);
    let x = DMatrix::from_fn(n, d, |i, j| {
        let (u, v) = ((i % 50) as f64 / 50.0, (i / 50) as f64 / 30.0);
        let f = 1.0 + j as f64;
        (f * u * 3.1 + (j as f64) * 0.7).sin() * (f * v * 2.3).cos() / f.sqrt()
    });
    let q = DMatrix::from_fn(700, d, |i, j| {
        let r = (i * 7 + 3) % n;
        x[(r, j)] + 0.03 * ((i * 13 + j * 5) as f64).sin() / (1.0 + j as f64).sqrt()
    });
    let brute = brute_search(&x, &q);
    let guess: Vec<usize> = brute.iter().map(|&t| (t + 1) % n).collect();
    for density in [0, 1 << 20] {
        assert_eq!(
            prefix_search_with(&x, &q, None, density),
            brute,
            "{density}"
        );
        assert_eq!(
            prefix_search_with(&x, &q, Some(&guess), density),
            brute,
            "{density}"
        );
    }
}

/// Naive f64 search with the strategies' own f64 distance (the same
/// summation order, so that near-ties break alike; ties: the smallest
/// index).
fn naive(x: &DMatrix<f64>, q: &DMatrix<f64>) -> Vec<usize> {
    let (xr, qr, d) = (row_major(x, None), row_major(q, None), x.ncols());
    (0..q.nrows())
        .map(|i| {
            let mut best = (f64::INFINITY, 0);
            for r in 0..x.nrows() {
                let dist = dist2(&xr[r * d..(r + 1) * d], &qr[i * d..(i + 1) * d]);
                if dist < best.0 {
                    best = (dist, r);
                }
            }
            best.1
        })
        .collect()
}

/// The f32 strategies are exact on their own, without the power-of-two
/// scaling of [`search`], where the cross terms underflow (coordinates
/// ~1e-29, products ~1e-57: all flush to zero, so only the band's
/// absolute terms keep the nearest row) or where tiny coordinates sit
/// next to ordinary ones. A band without [`score_err`]'s absolute
/// terms returns wrong rows in the first case.
#[test]
fn f32_bands_cover_underflow() {
    // d = 20: brute force runs the fused kernel; d = 40: the GEMMs.
    for (nx, d, offset, spread) in [20, 40]
        .into_iter()
        .flat_map(|d| [(0.0, 1e-30), (0.0, 1e-42), (1.0, 1e-40)].map(|(o, s)| (300, d, o, s)))
    {
        let x = DMatrix::from_fn(nx, d, |i, j| {
            offset + spread * (((i * 37 + j * 11) % 101) as f64 - 50.0)
        });
        let q = DMatrix::from_fn(120, d, |i, j| {
            offset + spread * (((i * 53 + j * 7) % 97) as f64 - 48.5)
        });
        let want = naive(&x, &q);
        assert_eq!(brute_search(&x, &q), want, "brute {d} {offset} {spread}");
        assert_eq!(tree_search(&x, &q), want, "tree {d} {offset} {spread}");
        assert_eq!(
            prefix_search(&x, &q, None),
            want,
            "prefix {d} {offset} {spread}"
        );
    }
}

/// Rows repeated all over the data (each of seven rows 171 or 172 times):
/// every panel of the fused search holds a copy of each query's nearest
/// row, so all 75 panels are within the band and every copy is
/// re-checked; the tie still goes to the first copy.
#[test]
fn fused_search_keeps_the_first_of_many_tied_rows() {
    let (nx, d) = (1200, 8);
    let x = DMatrix::from_fn(nx, d, |i, j| (((i % 7) * 13 + j * 5) % 17) as f64 / 17.0);
    let q = DMatrix::from_fn(50, d, |i, j| ((i * 3 + j * 7) % 19) as f64 / 19.0);
    let want = naive(&x, &q);
    assert!(want.iter().all(|&w| w < 7), "the first copies win ties");
    let got = brute_search(&x, &q);
    assert_eq!(got, want);
    assert_eq!(BruteData::new(&x).panels.len() / (d * PANEL), 75);
}

/// Both directions at once answer as two naive searches: odd sizes (not
/// whole blocks or panels), widths from 1 to past the fused kernel's,
/// rows repeated (ties to the first), far outside f32's range, where the
/// f32 products underflow, and clusters far from the origin whose
/// distances f32 cannot tell apart (there a band of zero returns other
/// rows: the re-check in f64 decides).
#[test]
fn both_directions_at_once_agree_with_two_naive_searches() {
    let cases = [
        (130, 97, 1, 0.0, 1.0, 7),
        (200, 331, 5, 0.0, 1.0, 7),
        (517, 260, 20, 0.0, 1.0, 7),
        (300, 300, 32, 0.0, 1.0, 7),
        (150, 170, 33, 0.0, 1.0, 7),
        (260, 140, 12, 0.0, 1e-30, 7),
        (260, 140, 12, 1.0, 1e-40, 7),
        (260, 140, 12, 0.0, 1e30, 7),
        (64, 1, 7, 0.0, 1.0, 7),
        (400, 300, 12, 30.0, 1e-4, 389),
        (333, 250, 24, 10.0, 1e-5, 331),
    ];
    for (na, nb, d, offset, spread, distinct) in cases {
        // `distinct` rows of `a`, repeated; `b` spread out.
        let a = DMatrix::from_fn(na, d, |i, j| {
            offset
                + spread * ((((i % distinct) * 13 + j * 5) % 17) as f64 - 8.0)
                + spread * (((i % distinct) * 31 + j * 3) % 29) as f64 / 29.0
        });
        let b = DMatrix::from_fn(nb, d, |i, j| {
            offset + spread * (((i * 53 + j * 7) % 97) as f64 / 6.0 - 8.0)
        });
        let (ab, ba) = crate::nearest_rows_both(view(&a), view(&b)).unwrap();
        assert_eq!(
            ab,
            naive(&b, &a),
            "a -> b: {na} x {nb}, {d} columns, {spread:e}"
        );
        assert_eq!(
            ba,
            naive(&a, &b),
            "b -> a: {na} x {nb}, {d} columns, {spread:e}"
        );
        assert!(
            ba.iter().all(|&i| i < distinct),
            "ties go to the first copy"
        );
    }
    let (a, b) = (DMatrix::zeros(3, 4), DMatrix::zeros(2, 5));
    assert!(crate::nearest_rows_both(view(&a), view(&b)).is_err());
}

/// Far outside f32's range (coordinates 1e±30 and 1e±150: underflow
/// and overflow of the f32 products and inputs) every strategy agrees with the naive
/// search, through the power-of-two scaling.
#[test]
fn every_strategy_exact_at_extreme_scales() {
    let (nx, d) = (500, 24);
    for scale in [1e-30, 1e30, 1e-150, 1e150] {
        let x = DMatrix::from_fn(nx, d, |i, j| {
            scale * ((i * 37 + j * 11) % 101) as f64 / 101.0
        });
        let q = DMatrix::from_fn(300, d, |i, j| scale * ((i * 53 + j * 7) % 97) as f64 / 97.0);
        let want = naive(&x, &q);
        for strategy in [
            NnStrategy::Auto,
            NnStrategy::Brute,
            NnStrategy::Tree,
            NnStrategy::Prefix,
            NnStrategy::Tiles,
        ] {
            assert_eq!(
                nearest_rows(view(&x), view(&q), None, &NnParams::with_strategy(strategy)).unwrap(),
                want,
                "{strategy:?} at {scale:e}"
            );
        }
    }
    let zero = DMatrix::zeros(1, 2);
    assert_eq!(
        power_of_two_scale(&DMatrix::from_element(2, 2, 3.0), &zero),
        None
    );
    for v in [3e-300, 7e300, f64::MAX] {
        let s = power_of_two_scale(&DMatrix::from_element(2, 2, v), &zero).unwrap();
        assert!((1.0..2.0).contains(&(v * s)), "{v:e}: {}", v * s);
    }
    let s = power_of_two_scale(&DMatrix::from_element(2, 2, 5e-320), &zero).unwrap();
    assert!((1e-20..1e-15).contains(&(5e-320 * s)), "{}", 5e-320 * s);
}

/// Every score of the fused kernel, with and without fused multiply-adds
/// (whatever the CPU: the variant with them is called here without the
/// target features, through the library's exact `mul_add`), is within
/// the bound [`fused_err`] derives (without its doubling) of the exact
/// score `|x|² − 2 q·x`, at ordinary scales and where coordinates and
/// products fall below f32's normal range.
#[test]
fn fused_scores_are_within_their_bound() {
    for (d, scale) in [
        (1, 1.0),
        (3, 1.0),
        (17, 1.0),
        (32, 3e5),
        (32, 1e-21),
        (9, 1e-40),
    ] {
        let (nx, nq) = (37, 4);
        let x = DMatrix::from_fn(nx, d, |i, j| {
            scale * (((i * 37 + j * 11) % 101) as f64 / 50.0 - 1.0 + (i as f64).sin() * 1e-3)
        });
        let q = DMatrix::from_fn(nq, d, |i, j| {
            scale * (((i * 53 + j * 7) % 97) as f64 / 48.0 - 1.0 + (j as f64).cos() * 1e-3)
        });
        let data = BruteData::new(&x);
        let x_norm_max = (0..nx).map(|r| x.row(r).norm_squared()).fold(0.0, f64::max);
        let four = check_fused::<GROUP>(&x, &q, x_norm_max, scale, &|fma, c, out| {
            let best = if fma {
                fused_scores_body::<true>(&data.panels, &data.panel_norms, d, c, out)
            } else {
                fused_scores_body::<false>(&data.panels, &data.panel_norms, d, c, out)
            };
            best.to_vec()
        });
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::SimdLevel::Avx512.detected() {
            // The AVX-512 kernel (fused multiply-adds only) gives the same
            // scores as the portable one with them, bit for bit.
            let eight = check_fused::<WIDE_GROUP>(&x, &q, x_norm_max, scale, &|_, c, out| {
                // SAFETY: the CPU has AVX-512 (checked above).
                unsafe { fused_scores_avx512(&data.panels, &data.panel_norms, d, c, out) }.to_vec()
            });
            assert_eq!(four, eight, "d {d} scale {scale:e}");
        } else {
            use std::io::Write as _;
            let _ = writeln!(
                std::io::stderr(),
                "note: skipped the AVX-512 fused kernel (this CPU has no AVX-512)"
            );
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = four;
            use std::io::Write as _;
            let _ = writeln!(
                std::io::stderr(),
                "note: skipped the AVX-512 fused kernel (not an x86-64 CPU)"
            );
        }
    }
}

/// A fused kernel: `(fma, c, scores) -> best`.
type Kernel<'a> = dyn Fn(bool, &[f32], &mut [f32]) -> Vec<f32> + 'a;

/// [`fused_scores_are_within_their_bound`] for a kernel of `G` queries
/// (`q` has at most `G` rows; the rest of the group is zeros); returns
/// the queries' scores with fused multiply-adds.
fn check_fused<const G: usize>(
    x: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x_norm_max: f64,
    scale: f64,
    kernel: &Kernel<'_>,
) -> Vec<f32> {
    let (nx, d, nq) = (x.nrows(), x.ncols(), q.nrows());
    let np = nx.div_ceil(PANEL);
    let mut c = vec![0.0f32; G * d];
    for g in 0..nq {
        for j in 0..d {
            c[j * G + g] = -2.0 * (q[(g, j)] as f32);
        }
    }
    let mut fused = Vec::new();
    for fma in [false, true] {
        let mut scores = vec![0.0f32; G * np * PANEL];
        let best = kernel(fma, &c, &mut scores);
        for g in 0..nq {
            let q_norm = q.row(g).norm_squared();
            let bound = fused_err(d, q_norm, x_norm_max) / 2.0;
            let col = &scores[g * np * PANEL..(g + 1) * np * PANEL];
            for r in 0..nx {
                let exact = x.row(r).norm_squared() - 2.0 * x.row(r).dot(&q.row(g));
                let err = (f64::from(col[r]) - exact).abs();
                assert!(
                    err <= bound,
                    "d {d} scale {scale:e} fma {fma}: {err:e} > {bound:e}"
                );
            }
            // The padding never scores, and the best is the smallest.
            assert!(col[nx..].iter().all(|s| *s == f32::INFINITY));
            let min = col.iter().fold(f32::INFINITY, |a, &b| a.min(b));
            assert_eq!(best[g], min);
        }
        if fma {
            fused = scores[..nq * np * PANEL].to_vec();
        }
    }
    fused
}
