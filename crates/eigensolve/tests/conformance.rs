//! One conformance suite for every backend of `EigenSolver`.
//!
//! Each backend must: reproduce the sphere spectrum l(l+1)/r² with
//! multiplicity 2l+1 (within discretization error), agree with the dense
//! reference to 1e-8 relative on eigenvalues and on spanned subspaces, give
//! ΦᵀMΦ = I to 1e-10 with small residuals, handle a disconnected mesh (two
//! zero eigenvalues), and turn bad input into errors.

use fmaps_eigensolve::*;
use fmaps_laplacian::{LaplaceOperator, LaplacianParams, cotan_laplacian};
use fmaps_mesh_io::TriMesh;
use fmaps_shapes::{disjoint_union, grid, icosphere, torus, translated};
use nalgebra::DMatrix;

fn backends() -> Vec<Box<dyn EigenSolver>> {
    let mut v: Vec<Box<dyn EigenSolver>> = vec![
        Box::new(NativeSolver::default()),
        // A smaller block and a tight basis: many restarts.
        Box::new(NativeSolver::new(native(|p| {
            p.block_size = 5;
            p.subspace = Some(1);
        }))),
        Box::new(NativeSolver::new(native(|p| {
            p.factorization = fmaps_eigensolve::Factorization::Simplicial;
            p.threads = 2;
        }))),
    ];
    #[cfg(feature = "arpack")]
    v.push(Box::new(ArpackSolver::default()));
    v.push(Box::new(DenseSolver::default()));
    v
}

fn op(mesh: &TriMesh) -> LaplaceOperator {
    cotan_laplacian(mesh, &LaplacianParams::default())
}

fn solve(s: &dyn EigenSolver, op: &LaplaceOperator, k: usize) -> SpectralBasis {
    let problem = EigenProblem::new(op.stiffness.view(), &op.mass).unwrap();
    s.solve(&problem, k)
        .unwrap_or_else(|e| panic!("{}: {e}", s.name()))
}

/// Checks the basis contract: ascending, M-orthonormal, small residuals.
fn check_contract(name: &str, b: &SpectralBasis) {
    let ev = &b.eigenvalues;
    assert!(
        ev.iter().zip(ev.iter().skip(1)).all(|(a, c)| a <= c),
        "{name}: not ascending"
    );
    assert!(
        b.report.orthonormality_error < 1e-10,
        "{name}: orthonormality {}",
        b.report.orthonormality_error
    );
    // Direct check of ΦᵀMΦ = I, independent of the report.
    let mut mphi = b.eigenvectors.clone();
    for mut c in mphi.column_iter_mut() {
        c.component_mul_assign(&b.mass);
    }
    let g = b.eigenvectors.tr_mul(&mphi);
    assert!(
        (g - DMatrix::identity(b.k(), b.k())).amax() < 1e-10,
        "{name}: ΦᵀMΦ ≠ I"
    );
    let scale = ev[ev.len() - 1].abs().max(1.0);
    assert!(
        b.report.max_residual() < 1e-6 * scale,
        "{name}: max residual {}",
        b.report.max_residual()
    );
}

/// Cosines of the principal angles between the spans of two M-orthonormal
/// bases are the singular values of Φ_aᵀ M Φ_b; equal spans give all ones.
fn min_subspace_cosine(a: &SpectralBasis, b: &SpectralBasis) -> f64 {
    let mut mb = b.eigenvectors.clone();
    for mut c in mb.column_iter_mut() {
        c.component_mul_assign(&b.mass);
    }
    let g = a.eigenvectors.tr_mul(&mb);
    g.singular_values().min()
}

/// The first `groups` eigenvalue groups of a sphere of radius `r`: group l
/// holds 2l + 1 eigenvalues within `tol` (relative) of l(l + 1)/r², spread
/// by less than `spread` (relative), each group above the previous one.
fn check_sphere_groups(
    name: &str,
    b: &SpectralBasis,
    r: f64,
    groups: usize,
    tol: f64,
    spread: f64,
) {
    let mut i = 0;
    let mut prev_max = f64::NEG_INFINITY;
    for l in 0..groups {
        let exact = (l * (l + 1)) as f64 / (r * r);
        let group = &b.eigenvalues.as_slice()[i..i + 2 * l + 1];
        for &lam in group {
            assert!(
                (lam - exact).abs() <= tol * exact + 1e-9,
                "{name}: λ = {lam}, l = {l}: {exact}"
            );
        }
        let lo = group.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = group.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!(lo > prev_max, "{name}: group l={l} overlaps the previous");
        assert!(
            hi - lo < spread * exact + 1e-9,
            "{name}: group l={l} spread {}",
            hi - lo
        );
        prev_max = hi;
        i += 2 * l + 1;
    }
}

/// Two bases of the same k pairs: eigenvalues within `tol` (relative,
/// absolute below 1) and the same span (principal cosines above 1 − tol).
fn assert_same_pairs(name: &str, a: &SpectralBasis, b: &SpectralBasis, tol: f64) {
    for i in 0..a.k() {
        let (x, y) = (a.eigenvalues[i], b.eigenvalues[i]);
        assert!(
            (x - y).abs() <= tol * y.abs().max(1.0),
            "{name}: λ_{i} {x} vs {y}"
        );
    }
    let cos = min_subspace_cosine(a, b);
    assert!(
        cos > 1.0 - tol,
        "{name}: subspaces differ, min cosine {cos}"
    );
}

#[test]
fn sphere_spectrum_groups_as_l_l_plus_1() {
    let r = 2.0;
    let mesh = icosphere(r, 3); // 642 vertices
    let o = op(&mesh);
    let k = 25; // l = 0..4: 1 + 3 + 5 + 7 + 9
    for s in backends() {
        let b = solve(s.as_ref(), &o, k);
        check_contract(s.name(), &b);
        // The cotan discretization error grows like (l h)²; at 642
        // vertices it is 2.6% for l = 4 (dense reference agrees).
        check_sphere_groups(s.name(), &b, r, 5, 0.03, 0.05);
    }
}

#[test]
fn backends_agree_with_the_dense_reference() {
    let meshes = [
        ("sphere", icosphere(1.0, 3), 16),
        ("torus", torus(2.0, 0.6, 30, 14), 30),
        ("grid", grid(2.0, 1.0, 24, 13), 40),
    ];
    for (mname, mesh, target) in meshes {
        let o = op(&mesh);
        let reference = solve(&DenseSolver::default(), &o, target + 6);
        // Spans are only defined at a gap: take the largest k <= target
        // with a relative gap above 1e-4 (the torus has double eigenvalues).
        let ev = &reference.eigenvalues;
        let k = (2..=target)
            .rev()
            .find(|&k| ev[k] - ev[k - 1] > 1e-4 * ev[k])
            .unwrap();
        for s in backends() {
            let name = format!("{} on {mname}", s.name());
            let b = solve(s.as_ref(), &o, k);
            check_contract(&name, &b);
            assert_same_pairs(&name, &b, &reference.truncate(k), 1e-8);
        }
    }
}

#[test]
fn two_disjoint_spheres_have_two_zero_eigenvalues() {
    let s = icosphere(1.0, 2);
    let mesh = disjoint_union(&s, &translated(&s, [4.0, 0.0, 0.0]).unwrap());
    let o = op(&mesh);
    for s in backends() {
        let b = solve(s.as_ref(), &o, 8);
        check_contract(s.name(), &b);
        assert!(
            b.eigenvalues[0].abs() < 1e-9 && b.eigenvalues[1].abs() < 1e-9,
            "{}: {}",
            s.name(),
            b.eigenvalues
        );
        assert!(b.eigenvalues[2] > 1.0, "{}", s.name());
    }
}

#[test]
fn deterministic() {
    let o = op(&torus(2.0, 0.6, 20, 10));
    for s in backends() {
        let a = solve(s.as_ref(), &o, 12);
        let b = solve(s.as_ref(), &o, 12);
        assert_eq!(a.eigenvalues, b.eigenvalues, "{}", s.name());
        assert_eq!(a.eigenvectors, b.eigenvectors, "{}", s.name());
    }
}

#[test]
fn bad_input_is_an_error() {
    let mesh = icosphere(1.0, 1);
    let o = op(&mesh);
    let n = o.n();
    let problem = EigenProblem::new(o.stiffness.view(), &o.mass).unwrap();
    for s in backends() {
        assert_eq!(
            s.solve(&problem, n).unwrap_err(),
            Error::InvalidK { k: n, n },
            "{}",
            s.name()
        );
        assert_eq!(
            s.solve(&problem, n + 5).unwrap_err(),
            Error::InvalidK { k: n + 5, n }
        );
        assert_eq!(
            s.solve(&problem, 0).unwrap_err(),
            Error::InvalidK { k: 0, n }
        );
    }
    let mut bad = o.stiffness.clone();
    bad.data_mut()[3] = f64::NAN;
    assert!(matches!(
        EigenProblem::new(bad.view(), &o.mass),
        Err(Error::NonFiniteStiffness { .. })
    ));
    let mut asym = o.stiffness.clone();
    asym.data_mut()[1] += 0.5;
    assert!(matches!(
        EigenProblem::new(asym.view(), &o.mass),
        Err(Error::NotSymmetric { .. })
    ));
    let mut mass = o.mass.clone();
    mass[7] = 0.0;
    assert_eq!(
        EigenProblem::new(o.stiffness.view(), &mass).unwrap_err(),
        Error::NonPositiveMass {
            index: 7,
            value: 0.0
        }
    );
    mass[7] = -1.0;
    assert!(matches!(
        EigenProblem::new(o.stiffness.view(), &mass),
        Err(Error::NonPositiveMass { index: 7, .. })
    ));
    mass[7] = f64::INFINITY;
    assert!(matches!(
        EigenProblem::new(o.stiffness.view(), &mass),
        Err(Error::NonPositiveMass { index: 7, .. })
    ));
    assert!(matches!(
        EigenProblem::new(o.stiffness.view(), &o.mass[1..]),
        Err(Error::SizeMismatch { .. })
    ));
    // A positive shift inside the spectrum makes L − σM indefinite.
    let positive = NativeSolver::new(native(|p| {
        p.shift = Some(5.0);
    }));
    assert!(matches!(
        positive.solve(&problem, 4),
        Err(Error::NotPositiveDefinite { .. })
    ));
    let rect = sprs::CsMat::new_csc((3, 2), vec![0, 1, 2], vec![0, 1], vec![1.0, 1.0]);
    assert_eq!(
        EigenProblem::new(rect.view(), &[1.0, 1.0, 1.0]).unwrap_err(),
        Error::NotSquare { rows: 3, cols: 2 }
    );
    for bad in [
        native(|p| {
            p.tol = 0.0;
        }),
        native(|p| {
            p.tol = 1.5;
        }),
        native(|p| {
            p.block_size = 0;
        }),
        native(|p| {
            p.shift = Some(f64::NAN);
        }),
    ] {
        assert!(
            matches!(
                NativeSolver::new(bad.clone()).solve(&problem, 4),
                Err(Error::InvalidParameter(_))
            ),
            "{bad:?}"
        );
    }
    let dense = DenseSolver { max_n: 10 };
    assert!(matches!(
        dense.solve(&problem, 4),
        Err(Error::TooLargeForDense { .. })
    ));
    // An indefinite "stiffness" is caught by the factorization.
    let mut neg = o.stiffness.clone();
    neg.data_mut().iter_mut().for_each(|v| *v = -*v);
    let p = EigenProblem::new(neg.view(), &o.mass).unwrap();
    assert!(matches!(
        NativeSolver::default().solve(&p, 4),
        Err(Error::NotPositiveDefinite { .. })
    ));
}

#[test]
fn no_convergence_is_reported_not_hidden() {
    let o = op(&icosphere(1.0, 3));
    let problem = EigenProblem::new(o.stiffness.view(), &o.mass).unwrap();
    let s = NativeSolver::new(native(|p| {
        p.max_restarts = 0;
        p.tol = 1e-15;
        p.subspace = Some(30);
    }));
    match s.solve(&problem, 20) {
        Err(Error::NoConvergence {
            wanted: 20,
            converged,
            ..
        }) => assert!(converged < 20),
        other => panic!("expected NoConvergence, got {other:?}"),
    }
}

/// The native backend locks converged Ritz pairs at its restarts (they
/// leave the projected problem). Locking must not lose a copy of a repeated
/// eigenvalue nor loosen convergence: on a 2562-vertex icosphere, k = 100
/// (the groups l = 0..9, multiplicities up to 19, split by the icosahedral
/// symmetry into blocks of at most 5), the default basis (2 restarts) and a
/// tight one (many restarts, pairs locked at many of them) must find every
/// group and agree on eigenvalues and on the spanned space.
#[test]
fn locking_keeps_every_copy_and_the_accuracy() {
    let r = 1.0;
    let o = op(&icosphere(r, 4));
    let k = 100;
    let default = solve(&NativeSolver::default(), &o, k);
    let tight = solve(
        &NativeSolver::new(native(|p| {
            p.subspace = Some(1);
        })),
        &o,
        k,
    );
    assert!(
        tight.report.restarts >= 5 && default.report.restarts >= 1,
        "restarts: tight {}, default {}",
        tight.report.restarts,
        default.report.restarts
    );
    for (name, b) in [("default", &default), ("tight", &tight)] {
        check_contract(name, b);
        let lam_k = b.eigenvalues[k - 1];
        // tol = 1e-12 on θ gives ~1e-11 here; pairs locked before they
        // converged (a broken budget) give ~1e-8.
        assert!(
            b.report.max_residual() < 1e-10 * lam_k,
            "{name}: residual {} (λ_k {lam_k})",
            b.report.max_residual()
        );
        check_sphere_groups(name, b, r, 10, 0.05, 0.1);
    }
    assert_same_pairs("default vs tight", &default, &tight, 1e-10);
}

#[test]
fn small_problems_and_k_close_to_n() {
    let mesh = icosphere(1.0, 0); // 12 vertices
    let o = op(&mesh);
    let reference = solve(&DenseSolver::default(), &o, 11);
    for k in [1, 5, 9, 10, 11] {
        let b = solve(&NativeSolver::default(), &o, k);
        check_contract("native small", &b);
        for i in 0..k {
            assert!(
                (b.eigenvalues[i] - reference.eigenvalues[i]).abs()
                    < 1e-9 * reference.eigenvalues[i].max(1.0),
                "k={k} i={i}"
            );
        }
    }
}

#[test]
fn basis_projection_helpers() {
    let o = op(&icosphere(1.0, 2));
    let b = solve(&NativeSolver::default(), &o, 10);
    let n = b.n();
    // Projecting the eigenvectors themselves gives the identity.
    let a = b.project(&b.eigenvectors);
    assert!((a - DMatrix::identity(10, 10)).amax() < 1e-10);
    // Reconstruct(project(f)) is the M-orthogonal projection: idempotent.
    let f = DMatrix::from_fn(n, 2, |i, j| ((i * (j + 3)) as f64).sin());
    let pf = b.reconstruct(&b.project(&f));
    let ppf = b.reconstruct(&b.project(&pf));
    assert!((pf - ppf).amax() < 1e-10);
    let t = b.truncate(4);
    assert_eq!(
        (t.k(), t.eigenvalues.len(), t.report.residuals.len()),
        (4, 4, 4)
    );
    assert_eq!(t.eigenvectors.column(3), b.eigenvectors.column(3));
}

/// The exported check ([`conformance::check`], mesh-free problems with
/// closed-form or dense-reference answers) passes for every backend here.
#[test]
fn every_backend_passes_the_exported_conformance_check() {
    for s in backends() {
        conformance::check(s.as_ref()).unwrap_or_else(|e| panic!("{e}"));
    }
}

/// A backend that breaks one promise fails the exported check, naming it.
#[test]
fn the_exported_check_catches_broken_backends() {
    /// The dense reference with one defect.
    struct Broken(&'static str);
    impl EigenSolver for Broken {
        fn name(&self) -> &'static str {
            self.0
        }
        fn solve(&self, p: &EigenProblem<'_>, k: usize) -> Result<SpectralBasis> {
            let good = DenseSolver::default().solve(p, k)?;
            let mut stats = SolveStats::new(self.0);
            stats.iteration_seconds = 0.0;
            match self.0 {
                // Eigenvalues off by 1e-6 relative.
                "biased" => SpectralBasis::from_eigenpairs(
                    p,
                    good.eigenvalues.map(|v| v * (1.0 + 1e-6)),
                    good.eigenvectors,
                    stats,
                ),
                // The k-th eigenvector replaced by the (k+1)-th.
                "wrong-span" => {
                    let more = DenseSolver::default().solve(p, (k + 1).min(p.n() - 1))?;
                    let mut phi = good.eigenvectors.clone();
                    if more.k() > k {
                        phi.set_column(k - 1, &more.eigenvectors.column(k));
                    }
                    SpectralBasis::from_eigenpairs(p, good.eigenvalues, phi, stats)
                }
                // Not M-orthonormal: columns scaled by 1.001.
                _ => SpectralBasis::from_eigenpairs(
                    p,
                    good.eigenvalues,
                    good.eigenvectors * 1.001,
                    stats,
                ),
            }
        }
    }
    for (name, check) in [
        ("biased", "closed-form spectrum of a periodic grid"),
        // The periodic grid's 20th and 21st eigenvalues coincide, so the
        // swap is harmless there; the weighted grid has no such luck.
        ("wrong-span", "agreement with the dense reference"),
        ("scaled", "closed-form spectrum of a periodic grid"),
    ] {
        let e = conformance::check(&Broken(name)).unwrap_err();
        assert_eq!((e.backend.as_str(), e.check), (name, check), "{e}");
    }
}

/// The public constructor rejects what is not a basis.
#[test]
fn from_eigenpairs_rejects_malformed_bases() {
    let o = op(&icosphere(1.0, 1));
    let p = EigenProblem::new(o.stiffness.view(), &o.mass).unwrap();
    let good = DenseSolver::default().solve(&p, 4).unwrap();
    let stats = || SolveStats::new("custom");
    let e = |r: Result<SpectralBasis>| matches!(r, Err(Error::InvalidBasis(_)));
    let mut descending = good.eigenvalues.clone();
    descending.swap_rows(1, 3);
    assert!(e(SpectralBasis::from_eigenpairs(
        &p,
        descending,
        good.eigenvectors.clone(),
        stats()
    )));
    let mut nan = good.eigenvectors.clone();
    nan[(5, 2)] = f64::NAN;
    assert!(e(SpectralBasis::from_eigenpairs(
        &p,
        good.eigenvalues.clone(),
        nan,
        stats()
    )));
    assert!(e(SpectralBasis::from_eigenpairs(
        &p,
        good.eigenvalues.rows(0, 3).into_owned(),
        good.eigenvectors.clone(),
        stats()
    )));
    // Signs are normalized: a flipped column comes back as it was.
    let mut flipped = good.eigenvectors.clone();
    flipped.column_mut(2).neg_mut();
    let b = SpectralBasis::from_eigenpairs(&p, good.eigenvalues.clone(), flipped, stats()).unwrap();
    assert_eq!(b.eigenvectors, good.eigenvectors);
    assert_eq!(b.report.backend, "custom");
}

/// The native solver's defaults changed by `set` (the parameters are
/// `#[non_exhaustive]`: built from the default).
fn native(set: impl FnOnce(&mut NativeParams)) -> NativeParams {
    let mut p = NativeParams::default();
    set(&mut p);
    p
}

/// The native solver gives the same eigenpairs, bit for bit, on 1 and 4
/// threads with its default (simplicial) factorization: no reduction's
/// order depends on the thread count. The supernodal factorization's
/// parallel kernels sum in another order: the same to rounding.
#[test]
fn native_results_do_not_depend_on_the_thread_count() {
    let mesh = translated(&torus(1.0, 0.35, 48, 20), [0.1, -0.2, 0.3]).unwrap();
    let o = op(&mesh);
    for factorization in [
        fmaps_eigensolve::Factorization::Auto,
        fmaps_eigensolve::Factorization::Simplicial,
        fmaps_eigensolve::Factorization::Supernodal,
    ] {
        let on = |threads: usize| {
            let s = NativeSolver::new(native(|p| {
                p.threads = threads;
                p.factorization = factorization;
            }));
            solve(&s, &o, 30)
        };
        let (one, four) = (on(1), on(4));
        if factorization == fmaps_eigensolve::Factorization::Supernodal {
            for (a, b) in one.eigenvalues.iter().zip(four.eigenvalues.iter()) {
                assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{a} vs {b}");
            }
            continue;
        }
        assert_eq!(
            one.eigenvalues.as_slice(),
            four.eigenvalues.as_slice(),
            "{factorization:?}"
        );
        assert_eq!(
            one.eigenvectors.as_slice(),
            four.eigenvectors.as_slice(),
            "{factorization:?}"
        );
    }
}
