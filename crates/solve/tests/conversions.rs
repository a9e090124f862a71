//! Point maps <-> functional maps on shapes with known correspondence.

use fmaps_mesh_io::TriMesh;
use fmaps_solve::*;
use nalgebra::DMatrix;

mod common;
use common::basis;

fn bumpy() -> TriMesh {
    common::bumpy(24, 14)
}

/// B is A with its vertices permuted; the bases are computed independently
/// (eigenvector signs differ). The ground-truth map gives a C that is
/// diagonal with ±1 entries, and converting back recovers the permutation.
#[test]
fn permuted_copy_round_trip() {
    let a = bumpy();
    let n = a.n_vertices();
    let perm: Vec<usize> = (0..n).map(|i| (i * 97 + 13) % n).collect(); // perm[new] = old
    let mut inv = vec![0; n];
    for (new, &old) in perm.iter().enumerate() {
        inv[old] = new;
    }
    let (v, f) = a.clone().into_parts();
    let b = TriMesh::new(
        perm.iter().map(|&o| v[o]).collect(),
        f.iter().map(|t| t.map(|o| inv[o])).collect(),
    )
    .unwrap();
    let k = 30;
    let (ba, bb) = (basis(&a, k), basis(&b, k));
    // T_BA: vertex y of B is vertex perm[y] of A.
    let t_ba = perm.clone();
    let c = fmap_from_point_map(&t_ba, &ba, &bb).unwrap();
    for i in 0..k {
        for j in 0..k {
            let want = if i == j { 1.0 } else { 0.0 };
            assert!(
                (c[(i, j)].abs() - want).abs() < 1e-8,
                "C[{i},{j}] = {}",
                c[(i, j)]
            );
        }
    }
    assert_eq!(point_map_from_fmap(&c, &ba, &bb).unwrap(), t_ba);
    assert_eq!(point_map_from_fmap_adjoint(&c, &ba, &bb).unwrap(), t_ba);
    // Transfer of the coordinate functions: exact up to the basis truncation,
    // and the same as transporting through the permutation and projecting.
    let f_a = DMatrix::from_fn(n, 3, |i, j| a.vertices()[i][j]);
    let on_b = transfer_functions(&c, &ba, &bb, &f_a).unwrap();
    let f_b = DMatrix::from_fn(n, 3, |y, j| f_a[(t_ba[y], j)]);
    let projected = bb.reconstruct(&bb.project(&f_b));
    assert!((on_b - projected).amax() < 1e-8);
}

#[test]
fn bad_sizes_are_errors() {
    let b = basis(&bumpy(), 10);
    let n = b.n();
    // A functional map that is not finite has no point map: an error, not
    // an out-of-range index.
    let mut nan = DMatrix::identity(10, 10);
    nan[(3, 4)] = f64::NAN;
    assert!(matches!(
        point_map_from_fmap(&nan, &b, &b),
        Err(Error::Search(fmaps_nearest::Error::NonFinite { .. }))
    ));
    assert!(matches!(
        fmap_from_point_map(&[0, 1], &b, &b),
        Err(Error::SizeMismatch { .. })
    ));
    let mut bad: Vec<usize> = (0..n).collect();
    bad[4] = n + 3;
    assert_eq!(
        fmap_from_point_map(&bad, &b, &b).unwrap_err(),
        Error::IndexOutOfRange {
            at: 4,
            index: n + 3,
            n
        }
    );
    let big = DMatrix::zeros(12, 10);
    assert!(matches!(
        point_map_from_fmap(&big, &b, &b),
        Err(Error::SizeMismatch { .. })
    ));
    let c = DMatrix::identity(10, 10);
    assert!(matches!(
        transfer_functions(&c, &b, &b, &DMatrix::zeros(3, 1)),
        Err(Error::SizeMismatch { .. })
    ));
}

/// The typed wrappers carry direction: a permutation B -> A induces the
/// functional map A -> B, which converts back to the same point map.
#[test]
fn typed_maps_round_trip_and_check_sizes() {
    let a = bumpy();
    let n = a.n_vertices();
    let ba = basis(&a, 12);
    let identity = PointMap::new((0..n).collect(), n).unwrap();
    let c = FunctionalMap::from_point_map(&identity, &ba, &ba).unwrap();
    assert_eq!((c.k_source(), c.k_target()), (12, 12));
    assert!((c.matrix() - DMatrix::identity(12, 12)).amax() < 1e-10);
    assert_eq!(c.to_point_map(&ba, &ba, false).unwrap(), identity);
    assert_eq!(c.to_point_map(&ba, &ba, true).unwrap(), identity);
    let coeffs = DMatrix::from_fn(12, 2, |i, j| (i + j) as f64);
    assert!((c.transfer_coefficients(&coeffs).unwrap() - &coeffs).amax() < 1e-9);
    assert!(matches!(
        c.transfer_coefficients(&DMatrix::zeros(5, 1)),
        Err(Error::SizeMismatch { .. })
    ));
    assert!(matches!(
        PointMap::new(vec![0, n], n),
        Err(Error::IndexOutOfRange { at: 1, .. })
    ));
    let short = PointMap::new(vec![0; n], n - 1).unwrap();
    assert!(matches!(
        FunctionalMap::from_point_map(&short, &ba, &ba),
        Err(Error::SizeMismatch { .. })
    ));
}

/// The pull-back of the conversion module (row-major copies, chunked
/// GEMMs) equals the formula `Φ_Bᵀ M_B Π_BA Φ_A` evaluated directly with
/// nalgebra, on the full and a sampled set of rows, and its inputs are
/// checked.
#[test]
fn pullback_equals_the_dense_formula_and_checks_its_input() {
    use fmaps_solve::convert::{gram, pullback, pullback_unweighted};
    let b = basis(&bumpy(), 16);
    let n = b.n();
    let t: Vec<usize> = (0..n).map(|y| (y * 5 + 2) % n).collect();
    let (ra, rb) = (BasisRows::new(&b, 12), BasisRows::new(&b, 10));
    let got = pullback(&t, &ra, 12, &rb, 10, b.mass.as_slice()).unwrap();
    let pulled = DMatrix::from_fn(n, 12, |y, j| b.mass[y] * b.eigenvectors[(t[y], j)]);
    let want = b.eigenvectors.columns(0, 10).transpose() * pulled;
    assert!((&got - &want).amax() < 1e-12, "{}", (&got - &want).amax());
    // On samples, without the mass, and the Gram matrix of the samples.
    let samples: Vec<usize> = (0..n).step_by(3).collect();
    let rs = BasisRows::at_vertices(&b, 10, &samples).unwrap();
    let ts: Vec<usize> = samples.iter().map(|&y| t[y]).collect();
    let got = pullback_unweighted(&ts, &ra, 12, &rs, 10).unwrap();
    let phis = DMatrix::from_fn(samples.len(), 10, |r, j| b.eigenvectors[(samples[r], j)]);
    let want = phis.transpose() * DMatrix::from_fn(ts.len(), 12, |r, j| b.eigenvectors[(ts[r], j)]);
    assert!((&got - &want).amax() < 1e-12);
    assert!((gram(&rs, 10) - phis.transpose() * &phis).amax() < 1e-12);
    // Bad input is an error.
    assert!(matches!(
        pullback(&t[1..], &ra, 12, &rb, 10, b.mass.as_slice()),
        Err(Error::SizeMismatch { .. })
    ));
    assert!(matches!(
        pullback(&t, &ra, 13, &rb, 10, b.mass.as_slice()),
        Err(Error::SizeMismatch { .. })
    ));
    assert!(matches!(
        pullback(&t, &ra, 12, &rb, 10, &b.mass.as_slice()[1..]),
        Err(Error::SizeMismatch { .. })
    ));
    assert!(matches!(
        BasisRows::at_vertices(&b, 10, &[0, n]),
        Err(Error::IndexOutOfRange { at: 1, .. })
    ));
}

/// The incremental pull-back (ZoomOut's fit: a map that changed at some
/// rows, a size grown by some columns) equals the direct one for every
/// mix: few or all rows changed, grown rows and/or columns, an empty start;
/// and its extra inputs are checked.
#[test]
fn pullback_update_equals_the_direct_pullback() {
    use fmaps_solve::convert::{pullback, pullback_update};
    let b = basis(&bumpy(), 16);
    let n = b.n();
    let m = b.mass.as_slice();
    let ra = BasisRows::new(&b, 16);
    let rb = BasisRows::new(&b, 14);
    let t_prev: Vec<usize> = (0..n).map(|y| (y * 5 + 2) % n).collect();
    for (every, (kbp, kap), (kb, ka)) in [
        (3, (10, 8), (14, 12)),
        (3, (10, 8), (10, 8)),
        (7, (10, 8), (14, 8)),
        (7, (10, 8), (10, 16)),
        (1, (10, 8), (14, 12)),
        (1000, (0, 0), (6, 9)),
        (1000, (5, 5), (5, 5)),
    ] {
        let t: Vec<usize> = (0..n)
            .map(|y| {
                if y % every == 0 {
                    (y * 11 + 1) % n
                } else {
                    t_prev[y]
                }
            })
            .collect();
        let c_prev = pullback(&t_prev, &ra, kap, &rb, kbp, m).unwrap();
        let got = pullback_update(&c_prev, &t_prev, &t, &ra, ka, &rb, kb, m).unwrap();
        let want = pullback(&t, &ra, ka, &rb, kb, m).unwrap();
        assert_eq!(got.shape(), (kb, ka));
        let err = (&got - &want).amax();
        assert!(
            err < 1e-13,
            "every {every}, {kbp}x{kap} -> {kb}x{ka}: {err}"
        );
    }
    let c_prev = pullback(&t_prev, &ra, 8, &rb, 10, m).unwrap();
    assert!(matches!(
        pullback_update(&c_prev, &t_prev, &t_prev, &ra, 7, &rb, 10, m),
        Err(Error::InvalidParameter(_))
    ));
    assert!(matches!(
        pullback_update(&c_prev, &t_prev[1..], &t_prev, &ra, 8, &rb, 10, m),
        Err(Error::SizeMismatch { .. })
    ));
    let mut bad = t_prev.clone();
    bad[3] = n;
    assert!(matches!(
        pullback_update(&c_prev, &t_prev, &bad, &ra, 8, &rb, 10, m),
        Err(Error::IndexOutOfRange { at: 3, .. })
    ));
}

/// On shapes of more than 20,000 vertices (the threshold
/// `point_map_from_fmap` documents) the one-off conversion
/// searches k-means clusters (without tiles); the map must be the exact
/// nearest neighbours all the same: the brute-force search of the same
/// embeddings, both directions of conversion.
#[test]
fn large_conversions_equal_the_brute_force_search() {
    use fmaps_nearest::{NnParams, NnStrategy, nearest_rows};
    if fmaps_nearest::tiles_available() {
        eprintln!(
            "skipped in part: this CPU has matrix tiles, so the conversion searched with them, not with the clusters"
        );
    }
    let (a, b) = (common::bumpy(150, 140), common::bumpy(141, 150));
    assert!(a.n_vertices() > 20_000 && b.n_vertices() > 20_000);
    let (ba, bb) = (basis(&a, 12), basis(&b, 12));
    // A map that is not diagonal: signs and a rotation of a 2-block.
    let mut c = DMatrix::<f64>::identity(12, 12);
    for i in 0..12 {
        c[(i, i)] = if i % 3 == 1 { -1.0 } else { 1.0 };
    }
    let (cs, sn) = (0.8f64, 0.6f64);
    c[(4, 4)] = cs;
    c[(4, 5)] = -sn;
    c[(5, 4)] = sn;
    c[(5, 5)] = cs;
    let brute = NnParams::with_strategy(NnStrategy::Brute);
    let rows_a = ba.eigenvectors.clone();
    let rows_b = bb.eigenvectors.clone();
    // Direct: data Φ_A Cᵀ, queries Φ_B.
    let data = &rows_a * c.transpose();
    let want = nearest_rows(
        fmaps_nearest::view(&data),
        fmaps_nearest::view(&rows_b),
        None,
        &brute,
    )
    .unwrap();
    assert_eq!(point_map_from_fmap(&c, &ba, &bb).unwrap(), want);
    // Adjoint: data Φ_A, queries Φ_B C.
    let queries = &rows_b * &c;
    let want = nearest_rows(
        fmaps_nearest::view(&rows_a),
        fmaps_nearest::view(&queries),
        None,
        &brute,
    )
    .unwrap();
    assert_eq!(point_map_from_fmap_adjoint(&c, &ba, &bb).unwrap(), want);
}
