//! The contract of [`Refiner`] as a check any refiner can run, ours and
//! third-party ones alike:
//!
//! ```
//! use fmaps_refine::{ZoomOut, conformance};
//!
//! conformance::check(&ZoomOut { k_start: 10, k_final: 30, step: 5, ..ZoomOut::default() })?;
//! # Ok::<(), conformance::Failure>(())
//! ```
//!
//! On the eigenbasis of a weighted grid (no symmetry, no repeated
//! eigenvalue; [`fmaps_eigensolve::conformance::grid_basis`]) and a copy
//! of it with its vertices renumbered (so the true map is the
//! permutation, and the true functional map the identity), a refiner
//! must: keep the identity map of a shape to itself; recover the
//! permutation exactly from a functional map perturbed by small noise;
//! return maps of the right length and range with a named report; give
//! the same output for the same input; and turn a functional map larger
//! than the bases into an error, not a panic.

use fmaps_eigensolve::SpectralBasis;
use fmaps_eigensolve::conformance::grid_basis;
use nalgebra::DMatrix;

use crate::Refiner;

/// The first broken promise a refiner showed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{refiner} fails the refiner contract ({check}): {message}")]
pub struct Failure {
    /// The refiner's name.
    pub refiner: String,
    /// Which check failed.
    pub check: &'static str,
    /// What was wrong.
    pub message: String,
}

/// Eigenpairs of the test bases: enough for a ZoomOut up to 60.
const K: usize = 60;

/// `basis` with its vertices renumbered: row `y` of the copy is row
/// `perm[y]` of `basis` (so `t_ba = perm`).
fn renumbered(basis: &SpectralBasis, perm: &[usize]) -> SpectralBasis {
    let mut b = basis.clone();
    b.eigenvectors = DMatrix::from_fn(perm.len(), basis.k(), |y, j| {
        basis.eigenvectors[(perm[y], j)]
    });
    b.mass = nalgebra::DVector::from_fn(perm.len(), |y, _| basis.mass[perm[y]]);
    b
}

/// Runs every check on `refiner`, starting from 20 x 20 maps between
/// bases of 60 eigenpairs (so [`Refiner::k_needed`] must be at most 60);
/// the first failure is returned.
pub fn check(refiner: &dyn Refiner) -> Result<(), Failure> {
    let name = refiner.name();
    let fail = |check: &'static str, message: String| Failure {
        refiner: name.clone(),
        check,
        message,
    };
    if refiner.k_needed() > K {
        return Err(fail(
            "basis size",
            format!(
                "needs {} eigenpairs; the check offers {K} (configure it smaller)",
                refiner.k_needed()
            ),
        ));
    }
    let a = grid_basis(30, 24, K);
    let n = a.n();
    // A renumbering with no fixed structure: y -> (7y + 3) mod n (7 and
    // n = 720 are coprime).
    let perm: Vec<usize> = (0..n).map(|y| (7 * y + 3) % n).collect();
    let b = renumbered(&a, &perm);
    let k0 = 20;

    let run = |c: &DMatrix<f64>,
               basis_a: &SpectralBasis,
               basis_b: &SpectralBasis,
               what: &'static str|
     -> Result<Vec<usize>, Failure> {
        let r = refiner
            .refine(&crate::RefineInput::new(c, basis_a, basis_b))
            .map_err(|e| fail(what, e.to_string()))?;
        if r.t_ba.len() != basis_b.n() {
            return Err(fail(
                what,
                format!(
                    "t_ba has {} entries for {} vertices of B",
                    r.t_ba.len(),
                    basis_b.n()
                ),
            ));
        }
        if let Some((y, &x)) = r.t_ba.iter().enumerate().find(|(_, x)| **x >= basis_a.n()) {
            return Err(fail(
                what,
                format!("t_ba[{y}] = {x}, but A has {} vertices", basis_a.n()),
            ));
        }
        let (kb, ka) = r.c_ab.shape();
        if ka > basis_a.k() || kb > basis_b.k() || r.c_ab.iter().any(|v| !v.is_finite()) {
            return Err(fail(
                what,
                format!(
                    "c_ab is {kb} x {ka} (bases of {} and {}) or not finite",
                    basis_b.k(),
                    basis_a.k()
                ),
            ));
        }
        if r.report.method.is_empty() {
            return Err(fail(what, "the report has no method name".into()));
        }
        Ok(r.t_ba)
    };

    // 1. The identity is kept.
    let identity = DMatrix::identity(k0, k0);
    let t = run(&identity, &a, &a, "identity self-map")?;
    if let Some(y) = (0..n).find(|&y| t[y] != y) {
        return Err(fail(
            "identity self-map",
            format!("vertex {y} maps to {} instead of itself", t[y]),
        ));
    }

    // 2. The permutation is recovered from a perturbed identity (noise of
    // 0.02 per entry, deterministic).
    let noisy = DMatrix::from_fn(k0, k0, |i, j| {
        let e = (((i * 31 + j * 17) % 23) as f64 / 23.0 - 0.5) * 0.04;
        if i == j { 1.0 + e } else { e }
    });
    let t = run(&noisy, &a, &b, "renumbered copy")?;
    let wrong = (0..n).filter(|&y| t[y] != perm[y]).count();
    if wrong > 0 {
        return Err(fail(
            "renumbered copy",
            format!("{wrong} of {n} vertices off the true map"),
        ));
    }

    // 3. Determinism.
    if run(&noisy, &a, &b, "determinism")? != t {
        return Err(fail(
            "determinism",
            "the same call gave a different map".into(),
        ));
    }

    // 4. A map larger than the bases is an error.
    let big = DMatrix::identity(K + 1, K + 1);
    if refiner
        .refine(&crate::RefineInput::new(&big, &a, &b))
        .is_ok()
    {
        return Err(fail(
            "oversized map",
            format!(
                "a {0} x {0} map between bases of {K} pairs was accepted",
                K + 1
            ),
        ));
    }
    Ok(())
}
