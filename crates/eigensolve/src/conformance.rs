//! The contract of [`EigenSolver`] as a check any backend can run, ours
//! and third-party ones alike:
//!
//! ```
//! use fmaps_eigensolve::{NativeSolver, conformance};
//!
//! conformance::check(&NativeSolver::default())?;
//! # Ok::<(), conformance::Failure>(())
//! ```
//!
//! The problems are built here, without meshes, with answers that can be
//! defended: the graph Laplacian of a periodic grid has the closed-form
//! spectrum `(4 sin²(π i / n₁) + 4 sin²(π j / n₂)) / h²` (with the uniform
//! mass h²); a grid with varying edge weights and masses is compared with
//! the dense reference ([`DenseSolver`]: faer's dense decomposition of
//! `M^{-1/2} L M^{-1/2}`) on eigenvalues and spanned subspaces; two
//! disconnected grids have two zero eigenvalues. Every basis must meet the
//! contract (ascending, `ΦᵀMΦ = I` to 1e-10, residuals below 1e-6 of the
//! spectrum's scale, signs normalized, report named after the backend),
//! the same call must give the same output, and `k` outside `1..n` must
//! be [`Error::InvalidK`].

use nalgebra::{DMatrix, DVector};
use sprs::{CsMat, TriMat};

use crate::{DenseSolver, EigenProblem, EigenSolver, Error, SpectralBasis};

/// The first broken promise a backend showed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{backend} fails the eigensolver contract ({check}): {message}")]
pub struct Failure {
    /// The backend's name.
    pub backend: String,
    /// Which check failed.
    pub check: &'static str,
    /// What was wrong.
    pub message: String,
}

/// A symmetric problem: stiffness (CSC) and mass.
struct Problem {
    stiffness: CsMat<f64>,
    mass: Vec<f64>,
}

impl Problem {
    fn view(&self) -> EigenProblem<'_> {
        EigenProblem::new(self.stiffness.view(), &self.mass)
            .expect("the conformance problems are valid")
    }
}

/// The weighted graph Laplacian of an `n1 x n2` grid (periodic in both
/// directions when `periodic`), edge weight `w(edge index)`, mass
/// `m(vertex)`.
fn grid(
    n1: usize,
    n2: usize,
    periodic: bool,
    w: impl Fn(usize) -> f64,
    m: impl Fn(usize) -> f64,
) -> Problem {
    let n = n1 * n2;
    let id = |i: usize, j: usize| i * n2 + j;
    let mut t = TriMat::new((n, n));
    let mut diag = vec![0.0; n];
    let mut e = 0;
    let mut edge = |a: usize, b: usize, t: &mut TriMat<f64>| {
        let we = w(e);
        e += 1;
        t.add_triplet(a, b, -we);
        t.add_triplet(b, a, -we);
        diag[a] += we;
        diag[b] += we;
    };
    for i in 0..n1 {
        for j in 0..n2 {
            if j + 1 < n2 || (periodic && n2 > 2) {
                edge(id(i, j), id(i, (j + 1) % n2), &mut t);
            }
            if i + 1 < n1 || (periodic && n1 > 2) {
                edge(id(i, j), id((i + 1) % n1, j), &mut t);
            }
        }
    }
    for (v, d) in diag.iter().enumerate() {
        t.add_triplet(v, v, *d);
    }
    Problem {
        stiffness: t.to_csc(),
        mass: (0..n).map(m).collect(),
    }
}

/// Two copies of `p`, disconnected (block diagonal).
fn twice(p: &Problem) -> Problem {
    let n = p.mass.len();
    let mut t = TriMat::new((2 * n, 2 * n));
    for (&v, (r, c)) in p.stiffness.iter() {
        t.add_triplet(r, c, v);
        t.add_triplet(r + n, c + n, v);
    }
    Problem {
        stiffness: t.to_csc(),
        mass: p.mass.iter().chain(&p.mass).copied().collect(),
    }
}

/// Varying positive edge weights and masses (deterministic).
fn weight(e: usize) -> f64 {
    1.0 + 0.5 * ((e as f64) * 0.7).sin()
}
fn mass(v: usize) -> f64 {
    0.5 + ((v * 37) % 11) as f64 / 11.0
}

/// The first `k` eigenpairs (dense reference) of the weighted `n1 x n2`
/// grid the checks use (varying edge weights and masses, so no symmetry
/// and no repeated eigenvalue): a small basis for the conformance checks
/// of downstream stages (refiners) that must not need a mesh.
///
/// # Panics
/// If `k` is not in `1..n1·n2` (a programming error of the caller).
pub fn grid_basis(n1: usize, n2: usize, k: usize) -> SpectralBasis {
    let p = grid(n1, n2, false, weight, mass);
    DenseSolver::default()
        .solve(&p.view(), k)
        .expect("a valid k for the grid")
}

/// Runs every check on `solver`; the first failure is returned.
pub fn check(solver: &dyn EigenSolver) -> Result<(), Failure> {
    let name = solver.name();
    let fail = |check: &'static str, message: String| Failure {
        backend: name.to_string(),
        check,
        message,
    };
    let solve = |p: &Problem, k: usize, what: &'static str| -> Result<SpectralBasis, Failure> {
        let b = solver
            .solve(&p.view(), k)
            .map_err(|e| fail(what, e.to_string()))?;
        contract(name, &p.view(), &b, k).map_err(|m| fail(what, m))?;
        Ok(b)
    };

    // 1. Closed form: the periodic grid, uniform mass h².
    let (n1, n2, h) = (24usize, 17usize, 0.1f64);
    let torus = grid(n1, n2, true, |_| 1.0, |_| h * h);
    let mut exact: Vec<f64> = (0..n1)
        .flat_map(|i| {
            (0..n2).map(move |j| {
                let s1 = (std::f64::consts::PI * i as f64 / n1 as f64).sin();
                let s2 = (std::f64::consts::PI * j as f64 / n2 as f64).sin();
                4.0 * (s1 * s1 + s2 * s2) / (h * h)
            })
        })
        .collect();
    exact.sort_by(f64::total_cmp);
    let k = 20;
    let b = solve(&torus, k, "closed-form spectrum of a periodic grid")?;
    for (i, (&got, &want)) in b.eigenvalues.iter().zip(&exact).enumerate() {
        if (got - want).abs() > 1e-8 * want.max(exact[1]) {
            return Err(fail(
                "closed-form spectrum of a periodic grid",
                format!("λ_{i} = {got}, exact {want}"),
            ));
        }
    }

    // 2. Varying weights and masses against the dense reference, on
    // eigenvalues and (at a spectral gap) on the spanned subspace.
    let bumpy = grid(20, 15, false, weight, mass);
    let reference = DenseSolver::default()
        .solve(&bumpy.view(), 30)
        .map_err(|e| fail("dense reference", e.to_string()))?;
    let ev = &reference.eigenvalues;
    let k = (2..=24)
        .rev()
        .find(|&k| ev[k] - ev[k - 1] > 1e-4 * ev[k])
        .expect("the weighted grid has gaps");
    let b = solve(&bumpy, k, "agreement with the dense reference")?;
    for i in 0..k {
        let (got, want) = (b.eigenvalues[i], ev[i]);
        if (got - want).abs() > 1e-8 * want.abs().max(ev[1]) {
            return Err(fail(
                "agreement with the dense reference",
                format!("λ_{i} = {got}, dense {want}"),
            ));
        }
    }
    let cos = min_subspace_cosine(&b, &reference.truncate(k));
    if cos < 1.0 - 1e-8 {
        return Err(fail(
            "agreement with the dense reference",
            format!("the spans of the first {k} eigenvectors differ: smallest cosine {cos}"),
        ));
    }

    // 3. Two components: two zero eigenvalues.
    let two = twice(&grid(9, 8, false, weight, mass));
    let b = solve(&two, 6, "two disconnected components")?;
    let scale = b.eigenvalues[5].abs().max(1.0);
    if b.eigenvalues[0].abs() > 1e-9 * scale || b.eigenvalues[1].abs() > 1e-9 * scale {
        return Err(fail(
            "two disconnected components",
            format!(
                "λ_0 = {}, λ_1 = {}: expected two zeros",
                b.eigenvalues[0], b.eigenvalues[1]
            ),
        ));
    }
    if b.eigenvalues[2] <= 1e-6 * scale {
        return Err(fail(
            "two disconnected components",
            format!("λ_2 = {}: expected positive", b.eigenvalues[2]),
        ));
    }

    // 4. Determinism.
    let again = solve(&two, 6, "determinism")?;
    if again.eigenvalues != b.eigenvalues || again.eigenvectors != b.eigenvectors {
        return Err(fail(
            "determinism",
            "the same call gave a different basis".into(),
        ));
    }

    // 5. k outside 1..n is an error naming k and n.
    let small = grid(4, 3, false, weight, mass);
    let n = small.mass.len();
    for k in [0, n, n + 3] {
        match solver.solve(&small.view(), k) {
            Err(Error::InvalidK { k: ek, n: en }) if (ek, en) == (k, n) => {}
            other => {
                return Err(fail(
                    "invalid k",
                    format!(
                        "k = {k} of n = {n}: expected Error::InvalidK, got {}",
                        match other {
                            Ok(b) => format!("a basis of {} pairs", b.k()),
                            Err(e) => e.to_string(),
                        }
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The basis contract: k pairs, ascending, `ΦᵀMΦ = I` (checked directly,
/// not from the report), residuals small against the spectrum's scale,
/// signs normalized, the report naming the backend.
fn contract(name: &str, p: &EigenProblem<'_>, b: &SpectralBasis, k: usize) -> Result<(), String> {
    if b.k() != k || b.n() != p.n() || b.eigenvalues.len() != k || b.mass.len() != p.n() {
        return Err(format!(
            "asked for {k} pairs of a size-{} problem, got {} x {} eigenvectors, {} eigenvalues, mass {}",
            p.n(),
            b.n(),
            b.k(),
            b.eigenvalues.len(),
            b.mass.len()
        ));
    }
    let ev = &b.eigenvalues;
    if let Some(i) = (1..k).find(|&i| ev[i] < ev[i - 1]) {
        return Err(format!("eigenvalues not ascending at {i}"));
    }
    let m = DVector::from_column_slice(p.mass());
    if b.mass != m {
        return Err("the basis carries a different mass".into());
    }
    let mut mphi = b.eigenvectors.clone();
    for mut col in mphi.column_iter_mut() {
        col.component_mul_assign(&m);
    }
    let gram = b.eigenvectors.tr_mul(&mphi);
    let err = (gram - DMatrix::identity(k, k)).amax();
    if !(err <= 1e-10) {
        return Err(format!("max |ΦᵀMΦ − I| = {err:e}"));
    }
    let scale = ev[k - 1]
        .abs()
        .max(ev[1.min(k - 1)].abs())
        .max(f64::MIN_POSITIVE);
    if !(b.report.max_residual() <= 1e-6 * scale.max(1.0)) {
        return Err(format!(
            "max residual {:e} for eigenvalues up to {scale}",
            b.report.max_residual()
        ));
    }
    for (j, col) in b.eigenvectors.column_iter().enumerate() {
        let big = col.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let first = col.iter().find(|v| v.abs() == big).copied().unwrap_or(0.0);
        if first < 0.0 {
            return Err(format!(
                "eigenvector {j}: its first entry of largest magnitude is negative (signs not normalized)"
            ));
        }
    }
    if b.report.backend != name {
        return Err(format!(
            "the report names backend {:?}, the solver is {name:?}",
            b.report.backend
        ));
    }
    Ok(())
}

/// Cosines of the principal angles between two M-orthonormal bases are
/// the singular values of `Φ_aᵀ M Φ_b`; equal spans give all ones.
fn min_subspace_cosine(a: &SpectralBasis, b: &SpectralBasis) -> f64 {
    let mut mb = b.eigenvectors.clone();
    for mut c in mb.column_iter_mut() {
        c.component_mul_assign(&b.mass);
    }
    a.eigenvectors.tr_mul(&mb).singular_values().min()
}
