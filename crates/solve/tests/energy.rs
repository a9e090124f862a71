//! The functional-map energy: closed forms, gradient, exact minimality.

use fmaps_solve::*;
use nalgebra::{DMatrix, DVector};

fn rnd_matrix(r: usize, c: usize, seed: u64) -> DMatrix<f64> {
    let mut s = seed;
    DMatrix::from_fn(r, c, |_, _| {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    })
}

fn sym(m: DMatrix<f64>) -> DMatrix<f64> {
    (&m + m.transpose()) * 0.5
}

fn energy(ka: usize, kb: usize, p: usize, w_dcomm: f64) -> FmapEnergy {
    let ea = DVector::from_fn(ka, |i, _| i as f64 * 0.7);
    let eb = DVector::from_fn(kb, |i, _| i as f64 * 0.75);
    FmapEnergy {
        descr_a: rnd_matrix(ka, p, 1),
        descr_b: rnd_matrix(kb, p, 2),
        lap_mask: laplacian_mask(&ea, &eb),
        // General (non-symmetric) operators, so index mix-ups cannot hide.
        ops: (0..3)
            .map(|q| (rnd_matrix(ka, ka, 10 + q), rnd_matrix(kb, kb, 20 + q)))
            .collect(),
        w_descr: 1.0,
        w_lap: 1e-2,
        w_dcomm,
        orient_ops: (0..2)
            .map(|q| (rnd_matrix(ka, ka, 30 + q), rnd_matrix(kb, kb, 40 + q)))
            .collect(),
        w_orient: 0.3 * w_dcomm,
        fixed_first_column: None,
    }
}

#[test]
fn descriptor_term_alone_has_the_least_squares_solution() {
    // Square, invertible A: C = B A⁻¹ exactly.
    let a = rnd_matrix(6, 6, 3);
    let b = rnd_matrix(5, 6, 4);
    let e = FmapEnergy {
        descr_a: a.clone(),
        descr_b: b.clone(),
        lap_mask: DMatrix::zeros(5, 6),
        ops: vec![],
        w_descr: 1.0,
        w_lap: 0.0,
        w_dcomm: 0.0,
        orient_ops: vec![],
        w_orient: 0.0,
        fixed_first_column: None,
    };
    let c = e.minimize().unwrap();
    let want = &b * a.try_inverse().unwrap();
    assert!((c - want).amax() < 1e-10);
}

#[test]
fn gradient_matches_finite_differences() {
    let e = energy(5, 4, 7, 0.5);
    let c = rnd_matrix(4, 5, 9);
    let g = e.gradient(&c);
    let h = 1e-6;
    for i in 0..4 {
        for j in 0..5 {
            let (mut cp, mut cm) = (c.clone(), c.clone());
            cp[(i, j)] += h;
            cm[(i, j)] -= h;
            let fd = (e.value(&cp) - e.value(&cm)) / (2.0 * h);
            assert!(
                (fd - g[(i, j)]).abs() < 1e-6 * (1.0 + fd.abs()),
                "({i},{j}): {fd} vs {}",
                g[(i, j)]
            );
        }
    }
}

#[test]
fn minimizer_is_exact_for_both_paths() {
    for w in [0.0, 0.5] {
        let e = energy(6, 5, 8, w);
        let c = e.minimize().unwrap();
        let g = e.gradient(&c);
        assert!(g.amax() < 1e-9, "w_dcomm {w}: gradient {}", g.amax());
        // A convex quadratic: any perturbation raises the energy.
        let e0 = e.value(&c);
        for s in 0..5 {
            let d = rnd_matrix(5, 6, 100 + s) * 1e-3;
            assert!(e.value(&(&c + d)) > e0);
        }
    }
}

/// A shape matched to itself: identical descriptors and operators give the
/// identity functional map (with the commutativity masks zero on it).
#[test]
fn self_map_is_the_identity() {
    let k = 6;
    let evals = DVector::from_fn(k, |i, _| i as f64 + 0.5);
    let a = rnd_matrix(k, 10, 5);
    let x = sym(rnd_matrix(k, k, 6));
    let e = FmapEnergy {
        descr_a: a.clone(),
        descr_b: a,
        lap_mask: resolvent_mask(&evals, &evals, 0.5),
        ops: vec![(x.clone(), x)],
        w_descr: 1.0,
        w_lap: 1.0,
        w_dcomm: 1.0,
        orient_ops: vec![],
        w_orient: 0.0,
        fixed_first_column: None,
    };
    let c = e.minimize().unwrap();
    assert!((c - DMatrix::identity(k, k)).amax() < 1e-9);
    // Masks vanish exactly on equal eigenvalues and are positive elsewhere.
    let m = laplacian_mask(&evals, &evals);
    let r = resolvent_mask(&evals, &evals, 0.5);
    for i in 0..k {
        assert_eq!(m[(i, i)], 0.0);
        assert_eq!(r[(i, i)], 0.0);
        for j in 0..k {
            assert!(i == j || (m[(i, j)] > 0.0 && r[(i, j)] > 0.0));
        }
    }
}

#[test]
fn degenerate_energy_is_an_error() {
    let e = FmapEnergy {
        descr_a: DMatrix::zeros(3, 2),
        descr_b: DMatrix::zeros(3, 2),
        lap_mask: DMatrix::zeros(3, 3),
        ops: vec![],
        w_descr: 1.0,
        w_lap: 0.0,
        w_dcomm: 0.0,
        orient_ops: vec![],
        w_orient: 0.0,
        fixed_first_column: None,
    };
    assert_eq!(e.minimize().unwrap_err(), Error::NotPositiveDefinite);
    let mut bad = e.clone();
    bad.lap_mask = DMatrix::zeros(2, 2);
    assert!(matches!(bad.minimize(), Err(Error::SizeMismatch { .. })));
}

#[test]
fn multiplication_operator_of_a_constant_is_its_value() {
    // With M-orthonormal Φ, Φᵀ M diag(c) Φ = c I.
    let n = 4;
    let mass: DVector<f64> = DVector::from_vec(vec![0.5, 0.25, 0.125, 0.125]);
    // Columns orthonormal in the M inner product: scaled unit vectors.
    let phi = DMatrix::from_fn(
        n,
        2,
        |i, j| if i == j { 1.0 / mass[i].sqrt() } else { 0.0f64 },
    );
    let op = multiplication_operator(&phi, &mass, &[3.0; 4]);
    assert!((op - DMatrix::identity(2, 2) * 3.0).amax() < 1e-14);
}

#[test]
fn fixed_first_column_is_kept_and_the_rest_is_optimal() {
    for w in [0.0, 0.5] {
        let mut e = energy(6, 5, 8, w);
        let c0 = DVector::from_fn(5, |i, _| if i == 0 { 1.3 } else { 0.1 * i as f64 });
        e.fixed_first_column = Some(c0.clone());
        let c = e.minimize().unwrap();
        assert_eq!(c.column(0), c0.column(0));
        let g = e.gradient(&c);
        // Stationary in the free columns only.
        assert!(
            g.columns(1, 5).amax() < 1e-9,
            "w {w}: {}",
            g.columns(1, 5).amax()
        );
        assert!(g.column(0).amax() > 1e-6);
        let e0 = e.value(&c);
        for s in 0..5 {
            let mut d = rnd_matrix(5, 6, 200 + s) * 1e-3;
            d.column_mut(0).fill(0.0);
            assert!(e.value(&(&c + d)) > e0);
        }
    }
}

#[test]
fn normalized_weights_do_not_depend_on_descriptor_scale() {
    let base = energy(6, 5, 8, 1.0);
    let solve = |s: f64| {
        let mut e = base.clone();
        e.descr_a *= s;
        e.descr_b *= s;
        for (x, y) in e.ops.iter_mut() {
            *x *= s;
            *y *= s;
        }
        for (x, y) in e.orient_ops.iter_mut() {
            *x *= s;
            *y *= s;
        }
        normalize_weights(
            &mut e,
            PerTerm {
                descr: 0.1,
                lap: 1e-3,
                dcomm: 1.0,
                orient: 1.0,
            },
        );
        e.minimize().unwrap()
    };
    let (c1, c7) = (solve(1.0), solve(7.0));
    assert!((&c1 - &c7).amax() < 1e-9 * c1.amax());
}

#[test]
fn effective_descriptor_count_closed_forms() {
    // p copies of one descriptor: one independent descriptor.
    let col = rnd_matrix(7, 1, 3);
    let copies = DMatrix::from_fn(7, 5, |i, _| col[(i, 0)]);
    assert!((effective_descriptor_count(&copies) - 1.0).abs() < 1e-12);
    // p orthogonal descriptors of equal norm (below the constant row): p.
    let ortho = DMatrix::from_fn(7, 4, |i, j| if i == j + 1 { 2.0 } else { 0.0 });
    assert!((effective_descriptor_count(&ortho) - 4.0).abs() < 1e-12);
    // The constant row is ignored.
    let mut with_const = ortho.clone();
    with_const.row_mut(0).fill(100.0);
    assert!((effective_descriptor_count(&with_const) - 4.0).abs() < 1e-12);
}
