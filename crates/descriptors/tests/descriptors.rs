//! Invariances of HKS/WKS through the whole pipeline (mesh -> Laplacian ->
//! eigenbasis -> descriptors), on an irregular mesh without repeated
//! eigenvalues, and error paths.

use fmaps_descriptors::*;
use fmaps_eigensolve::{EigenProblem, EigenSolver, NativeSolver, SpectralBasis};
use fmaps_laplacian::{LaplacianParams, cotan_laplacian};
use fmaps_mesh_io::TriMesh;
use fmaps_shapes::torus;
use nalgebra::{DMatrix, DVector};

const K: usize = 30;

/// A bumpy torus: no symmetry, so no repeated eigenvalues.
fn bumpy() -> TriMesh {
    let (mut v, f) = torus(2.0, 0.8, 24, 14).into_parts();
    for (k, p) in v.iter_mut().enumerate() {
        let s = 1.0 + 0.08 * ((k * 31 % 17) as f64 / 17.0 - 0.5);
        *p = [p[0] * s, p[1] * s * 1.1, p[2] * (2.0 - s)];
    }
    TriMesh::new(v, f).unwrap()
}

/// The first K eigenpairs; K must end at a gap of the spectrum for the
/// truncated basis (and so the descriptors) to be well defined.
fn basis(mesh: &TriMesh) -> SpectralBasis {
    let op = cotan_laplacian(mesh, &LaplacianParams::default());
    let p = EigenProblem::new(op.stiffness.view(), &op.mass).unwrap();
    let b = NativeSolver::default().solve(&p, K + 1).unwrap();
    let ev = &b.eigenvalues;
    assert!(
        ev[K] - ev[K - 1] > 1e-3 * ev[K],
        "no spectral gap after {K}: {} {}",
        ev[K - 1],
        ev[K]
    );
    b.truncate(K)
}

fn max_rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax()
}

fn all(b: &SpectralBasis) -> Vec<DMatrix<f64>> {
    vec![
        hks(&b.eigenvalues, &b.eigenvectors, &HksParams::default()).unwrap(),
        wks(&b.eigenvalues, &b.eigenvectors, &WksParams::default()).unwrap(),
        landmark_wks(&b.eigenvalues, &b.eigenvectors, &[3, 50], &wks_params(10)).unwrap(),
    ]
}

#[test]
fn permuting_vertices_permutes_descriptors() {
    let mesh = bumpy();
    let n = mesh.n_vertices();
    let b = basis(&mesh);
    // perm[new] = old.
    let perm: Vec<usize> = (0..n).map(|i| (i * 97 + 13) % n).collect();
    let mut inv = vec![0; n];
    for (new, &old) in perm.iter().enumerate() {
        inv[old] = new;
    }
    let (v, f) = mesh.clone().into_parts();
    let pv = perm.iter().map(|&old| v[old]).collect();
    let pf = f.iter().map(|t| t.map(|old| inv[old])).collect();
    let pb = basis(&TriMesh::new(pv, pf).unwrap());
    let (a, mut c) = (all(&b), all(&pb));
    // Landmarks move with the permutation.
    c[2] = landmark_wks(
        &pb.eigenvalues,
        &pb.eigenvectors,
        &[inv[3], inv[50]],
        &wks_params(10),
    )
    .unwrap();
    for (x, y) in a.iter().zip(&c) {
        let yp = DMatrix::from_fn(n, y.ncols(), |i, j| y[(inv[i], j)]);
        assert!(max_rel(&yp, x) < 1e-8, "{}", max_rel(&yp, x));
    }
}

#[test]
fn rigid_motions_do_not_change_descriptors() {
    let mesh = bumpy();
    let (c, s) = (0.3f64.cos(), 0.3f64.sin());
    let (v, f) = mesh.clone().into_parts();
    let moved: Vec<[f64; 3]> = v
        .iter()
        .map(|p| {
            [
                c * p[0] - s * p[2] + 5.0,
                p[1] - 2.0,
                s * p[0] + c * p[2] + 1.0,
            ]
        })
        .collect();
    let a = all(&basis(&mesh));
    let b = all(&basis(&TriMesh::new(moved, f).unwrap()));
    for (x, y) in a.iter().zip(&b) {
        assert!(max_rel(y, x) < 1e-8);
    }
}

/// The heat kernel is symmetric: the landmark HKS of x at landmark l equals
/// that of l at landmark x.
#[test]
fn landmark_hks_is_symmetric() {
    let b = basis(&bumpy());
    let mut p = HksParams::default();
    p.n_times = 5;
    p.scaled = false;
    let d = landmark_hks(&b.eigenvalues, &b.eigenvectors, &[7, 120], &p).unwrap();
    for t in 0..5 {
        let (x_at_l, l_at_x) = (d[(120, t)], d[(7, 5 + t)]);
        assert!((x_at_l - l_at_x).abs() <= 1e-12 * x_at_l.abs().max(1e-300));
    }
    // At the landmark itself it is the plain HKS.
    let plain = hks(&b.eigenvalues, &b.eigenvectors, &p).unwrap();
    for t in 0..5 {
        assert!((d[(7, t)] - plain[(7, t)]).abs() < 1e-14 * plain[(7, t)]);
    }
}

#[test]
fn normalization_and_sampling() {
    let b = basis(&bumpy());
    let mut d = wks(&b.eigenvalues, &b.eigenvectors, &WksParams::default()).unwrap();
    normalize_columns(&mut d, &b.mass);
    for col in d.column_iter() {
        let n2: f64 = col.iter().zip(b.mass.iter()).map(|(x, m)| m * x * x).sum();
        assert!((n2 - 1.0).abs() < 1e-12);
    }
    let t = hks_times(&b.eigenvalues, 3).unwrap();
    let ln10 = 10f64.ln();
    assert!((t[0] - 4.0 * ln10 / b.eigenvalues[K - 1]).abs() < 1e-12 * t[0]);
    assert!((t[2] - 4.0 * ln10 / b.eigenvalues[1]).abs() < 1e-12 * t[2]);
    assert!((t[1] - (t[0] * t[2]).sqrt()).abs() < 1e-12 * t[1]);
    let (e, sigma) = wks_energies(&b.eigenvalues, 10).unwrap();
    assert!(
        (sigma - 7.0 * (b.eigenvalues[K - 1].ln() - b.eigenvalues[1].ln()) / 10.0).abs() < 1e-12
    );
    assert!((e[0] - (b.eigenvalues[1].ln() + 2.0 * sigma)).abs() < 1e-12);
}

#[test]
fn errors() {
    let evals = DVector::from_vec(vec![0.0, 1.0, 2.0]);
    let evecs = DMatrix::from_element(4, 2, 0.5);
    assert!(matches!(
        hks(&evals, &evecs, &HksParams::default()),
        Err(Error::SizeMismatch { .. })
    ));
    let evecs = DMatrix::from_element(4, 3, 0.5);
    assert!(matches!(
        landmark_hks(&evals, &evecs, &[9], &HksParams::default()),
        Err(Error::LandmarkOutOfRange { index: 9, n: 4 })
    ));
    let flat = DVector::from_vec(vec![0.0, 0.0, 0.0]);
    assert!(matches!(
        wks(&flat, &evecs, &WksParams::default()),
        Err(Error::TooFewEigenvalues(0))
    ));
    assert!(matches!(
        wks(&evals, &evecs, &wks_params(0)),
        Err(Error::InvalidParameter(_))
    ));
}

/// The pipeline's descriptor matrix is the family and its landmark
/// variant side by side, every `subsample`-th column, each of unit L²
/// norm; the HKS variant likewise.
#[test]
fn descriptor_matrix_stacks_subsamples_and_normalizes() {
    let b = basis(&bumpy());
    let (ev, phi, m) = (&b.eigenvalues, &b.eigenvectors, &b.mass);
    let landmarks = [3, 40];
    let mut p = DescriptorParams::default();
    p.kind = DescriptorKind::Wks;
    p.n = 12;
    p.subsample = 2;
    let got = descriptor_matrix(ev, phi, m, &landmarks, &p).unwrap();
    let w = wks_params(12);
    let (a, l) = (
        wks(ev, phi, &w).unwrap(),
        landmark_wks(ev, phi, &landmarks, &w).unwrap(),
    );
    let all: Vec<_> = (0..a.ncols())
        .map(|j| a.column(j).into_owned())
        .chain((0..l.ncols()).map(|j| l.column(j).into_owned()))
        .step_by(2)
        .collect();
    assert_eq!(got.ncols(), all.len());
    for (j, col) in all.iter().enumerate() {
        let norm = |c: &DVector<f64>| {
            c.iter()
                .zip(m.iter())
                .map(|(d, w)| w * d * d)
                .sum::<f64>()
                .sqrt()
        };
        let want = col / norm(col);
        assert!((got.column(j) - &want).amax() < 1e-12, "column {j}");
        assert!((norm(&got.column(j).into_owned()) - 1.0).abs() < 1e-12);
    }
    let mut h = p;
    h.kind = DescriptorKind::Hks;
    assert_eq!(descriptor_matrix(ev, phi, m, &[], &h).unwrap().ncols(), 6);
    let mut bad = p;
    bad.subsample = 0;
    assert!(matches!(
        descriptor_matrix(ev, phi, m, &[], &bad),
        Err(Error::InvalidParameter(_))
    ));
}

/// Scaled WKS with `n` energies (the parameters are `#[non_exhaustive]`:
/// built from the default).
fn wks_params(n: usize) -> WksParams {
    let mut p = WksParams::default();
    p.n_energies = n;
    p
}

/// Closed forms on the unit sphere. Its eigenfunctions of degree l (eigenvalue
/// l(l+1), 2l+1 of them) satisfy the addition theorem
/// `Σ_m Y_lm(x)² = (2l+1)/(4π)` at every point, whatever basis the
/// eigensolver picks inside each degree. So with the degrees 0..=4 (25
/// eigenpairs):
/// - the HKS is `Σ_l (2l+1)/(4π) e^{−t l(l+1)}`, the same at every vertex;
/// - the scaled HKS and the scaled WKS (each sample divided by its total
///   weight `Σ_k c_k`) are `1/(4π)` exactly, for every time or energy.
///
/// The mesh's deviation from the sphere bounds the error: on the
/// icosphere of 10242 vertices the largest eigenvalue is 19.97 (20 on the
/// sphere) and the vertex values are within 0.11% (HKS), 0.16% (scaled
/// HKS) and 0.24% (scaled WKS) of the closed forms; checked at 1%.
#[test]
fn sphere_descriptors_match_the_addition_theorem() {
    use std::f64::consts::PI;
    let mesh = fmaps_shapes::icosphere(1.0, 5);
    let op = cotan_laplacian(&mesh, &LaplacianParams::default());
    let p = EigenProblem::new(op.stiffness.view(), &op.mass).unwrap();
    let b = NativeSolver::default().solve(&p, 25).unwrap();
    let (ev, phi) = (&b.eigenvalues, &b.eigenvectors);
    // The degrees end at a gap: 25 eigenpairs are degrees 0..=4.
    assert!((ev[24] - 20.0).abs() < 0.1, "{}", ev[24]);
    let times = [0.05, 0.2, 1.0];
    let h = hks_at(ev, phi, &times, false).unwrap();
    let mut worst = 0.0f64;
    for (j, &t) in times.iter().enumerate() {
        let exact: f64 = (0..=4)
            .map(|l| (2 * l + 1) as f64 / (4.0 * PI) * (-t * (l * (l + 1)) as f64).exp())
            .sum();
        for x in 0..h.nrows() {
            worst = worst.max((h[(x, j)] - exact).abs() / exact);
        }
    }
    assert!(worst < 0.01, "HKS: relative error {worst}");
    let one_over = 1.0 / (4.0 * PI);
    let scaled_hks = hks_at(ev, phi, &times, true).unwrap();
    let scaled_wks = wks(ev, phi, &wks_params(20)).unwrap();
    for (name, d) in [("scaled HKS", &scaled_hks), ("scaled WKS", &scaled_wks)] {
        let worst = d
            .iter()
            .map(|v| (v - one_over).abs() / one_over)
            .fold(0.0f64, f64::max);
        assert!(worst < 0.01, "{name}: relative error {worst}");
    }
}
