//! Tests of the ball search's bounds (internal: they read its clusters).
use super::*;
use crate::rows::row_major;

/// Cluster `j`'s bound for the query `qi`, from f32 dot products of f32
/// copies as the search's GEMMs compute them (in another summation
/// order: the error bounds hold for any).
fn bound(b: &BallData, j: usize, qi: &[f64]) -> Tangent {
    let d = b.d;
    let q32: Vec<f32> = qi.iter().map(|&v| v as f32).collect();
    let dot32 = |v: &[f32]| -> f64 {
        f64::from(q32.iter().zip(v).fold(0.0f32, |s, (a, b)| a.mul_add(*b, s)))
    };
    let qn: f64 = qi.iter().map(|v| v * v).sum();
    let qc = dot32(&b.centers32[j * d..(j + 1) * d]);
    let uq: Vec<f64> = (0..TANGENT)
        .map(|t| dot32(&b.tangent32[(j * TANGENT + t) * d..(j * TANGENT + t + 1) * d]))
        .collect();
    let err = Err32 {
        qc: score_err(d, qn, 0.0) + b.c_err[j],
        uq: score_err(d, qn, 1.0 + b.geo.eta),
    };
    tangent_bound(b, j, (qn, qn.sqrt()), qc, &uq, err, slack(d), f64::INFINITY).expect("no cutoff")
}

/// Every bound the search uses is below the distance it bounds: per
/// (query, cluster) the cluster's bound (from the GEMMs' quantities,
/// as the search computes them) against every row of the cluster, and
/// each row's own bound against its distance, on points near a curved
/// 2-manifold in R^d (as spectral embeddings are), queries on rows, near
/// and far, in dimensions below and above the number of directions.
#[test]
fn bounds_are_below_the_distances() {
    for d in [1, 3, 5, 40, 97] {
        let n = 600;
        let x = DMatrix::from_fn(n, d, |i, j| {
            let (u, v) = ((i % 30) as f64 / 30.0, (i / 30) as f64 / 20.0);
            let f = 1.0 + j as f64;
            (f * u * 3.1 + j as f64 * 0.7).sin() * (f * v * 2.3).cos() / f.sqrt()
        });
        let q = DMatrix::from_fn(200, d, |i, j| {
            let base = x[((i * 7) % n, j)];
            if i % 10 == 0 {
                3.0 + base
            } else if i % 10 == 5 {
                // On a row: every bound must reach 0 despite the f32
                // products' rounding.
                base
            } else {
                base + 0.05 * ((i * 13 + j * 5) as f64).sin()
            }
        });
        let b = BallData::new(&x, None);
        let sl = slack(d);
        let qr = row_major(&q, None);
        let mut checked = 0usize;
        for qi in qr.chunks_exact(d) {
            for (j, &(start, len)) in b.ranges.iter().enumerate() {
                let tb = bound(&b, j, qi);
                let tol = tb.eps + sl * b.geo.radii[j];
                for p in start..start + len {
                    let dist = dist2(&b.x_ord[p * d..(p + 1) * d], qi);
                    assert!(tb.lb2 <= dist, "d {d} cluster {j}: {} > {dist}", tb.lb2);
                    let mut gap2 = 0.0;
                    for t in 0..TANGENT {
                        let g = ((tb.t[t] - b.geo.row_tan[t * n + p]).abs() - tol).max(0.0);
                        gap2 += g * g;
                    }
                    let pb = (tb.perp - b.geo.row_perp[p]).max(0.0);
                    let row = (gap2 * (1.0 - b.geo.eta) + pb * pb) * (1.0 - 2.0 * sl);
                    assert!(row <= dist, "d {d} row {p}: {row} > {dist}");
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 200 * n);
        // The directions are orthonormal to rounding.
        assert!(b.geo.eta < 1e-12, "eta {}", b.geo.eta);
    }
}

/// The tangent bound prunes: on the same manifold, a query near it
/// rules out most clusters the ball bound alone keeps.
#[test]
fn tangent_bound_is_tighter_than_the_ball() {
    let (n, d) = (2400, 60);
    let x = DMatrix::from_fn(n, d, |i, j| {
        let (u, v) = ((i % 60) as f64 / 60.0, (i / 60) as f64 / 40.0);
        let f = 1.0 + j as f64;
        (f * u * 3.1 + j as f64 * 0.7).sin() * (f * v * 2.3).cos() / f.sqrt()
    });
    let b = BallData::new(&x, None);
    let (mut ball, mut tangent) = (0usize, 0usize);
    for i in (0..n).step_by(37) {
        // A query off the sheet by a fraction of the spacing.
        let qi: Vec<f64> = (0..d)
            .map(|j| x[(i, j)] + 0.02 * ((i + 3 * j) as f64).cos())
            .collect();
        let best = (0..n)
            .map(|p| dist2(&b.x_ord[p * d..(p + 1) * d], &qi))
            .fold(f64::INFINITY, f64::min);
        for j in 0..b.ranges.len() {
            let tb = bound(&b, j, &qi);
            let plain = (tb.dc_lo - b.geo.radii[j]).max(0.0);
            ball += usize::from(plain * plain <= best);
            tangent += usize::from(tb.lb2 <= best);
        }
    }
    assert!(tangent * 2 < ball, "tangent {tangent}, ball {ball}");
}

/// The queries' order by their guesses' balls (a counting sort) is the
/// order of a sort by (key, index), `u32::MAX` (no guess) last.
#[test]
fn order_by_key_is_the_sorted_order() {
    for (n, m) in [(0, 3), (1, 1), (50, 1), (200, 7), (1000, 40)] {
        let key = |i: usize| -> u32 {
            let h = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
            if h.is_multiple_of(5) {
                u32::MAX
            } else {
                (h % m as u64) as u32
            }
        };
        let mut want: Vec<usize> = (0..n).collect();
        want.sort_by_key(|&i| (key(i), i));
        assert_eq!(order_by_key(n, m, key), want, "n = {n}, m = {m}");
    }
}
