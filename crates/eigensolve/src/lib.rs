//! Laplace–Beltrami spectra: the `k` smallest eigenpairs of the sparse
//! generalized symmetric problem `L φ = λ M φ`, with `L` symmetric positive
//! semi-definite (the cotangent stiffness) and `M` a positive diagonal mass.
//!
//! Every backend implements the small [`EigenSolver`] trait and returns a
//! [`SpectralBasis`]: eigenvalues ascending, eigenvectors `Φ` (n x k) with
//! `Φᵀ M Φ = I`, and a [`SolveReport`] (residuals, orthonormality error,
//! timings, iteration counts). Backends:
//!
//! - [`NativeSolver`] (default, pure Rust): shift-invert with a small
//!   negative shift σ, a sparse Cholesky factorization of `L − σM` (faer,
//!   AMD ordering), and a block Krylov–Schur iteration (thick-restarted block
//!   Lanczos with full reorthogonalization on BLAS-3 kernels, converged
//!   Ritz pairs locked at each restart).
//! - `ArpackSolver` (cargo feature `arpack`): ARPACK's implicitly restarted
//!   Lanczos (`dsaupd`/`dseupd`, mode 3) on the same factorization.
//! - [`DenseSolver`]: a dense symmetric eigendecomposition, a reference for
//!   small problems and tests.
//!
//! No backend falls back silently to another: a failure is an [`Error`].
//! Nothing here knows about meshes; any `(L, M)` pair will do.
//!
//! ```
//! use fmaps_eigensolve::{EigenProblem, EigenSolver, NativeSolver};
//! use sprs::TriMat;
//!
//! // The path graph Laplacian on 50 nodes with unit mass: eigenvalues
//! // 2 - 2 cos(π j / n), j = 0..n.
//! let n = 50;
//! let mut t = TriMat::new((n, n));
//! for i in 0..n - 1 {
//!     t.add_triplet(i, i + 1, -1.0);
//!     t.add_triplet(i + 1, i, -1.0);
//!     t.add_triplet(i, i, 1.0);
//!     t.add_triplet(i + 1, i + 1, 1.0);
//! }
//! let l = t.to_csc();
//! let mass = vec![1.0; n];
//! let problem = EigenProblem::new(l.view(), &mass)?;
//! let basis = NativeSolver::default().solve(&problem, 6)?;
//! for (j, lam) in basis.eigenvalues.iter().enumerate() {
//!     let exact = 2.0 - 2.0 * (std::f64::consts::PI * j as f64 / n as f64).cos();
//!     assert!((lam - exact).abs() < 1e-10);
//! }
//! assert!(basis.report.orthonormality_error < 1e-12);
//! # Ok::<(), fmaps_eigensolve::Error>(())
//! ```
//!
//! # Features
//!
//! - `arpack`: the ARPACK backend, linking the system `arpack-ng`
//!   (Debian: `libarpack2-dev pkg-config libclang-dev`; install
//!   `libopenblas0-pthread` too, or ARPACK runs on the slow reference BLAS).
#![deny(missing_docs)]
#![deny(unsafe_code)]

pub mod conformance;
mod dense;
mod error;
mod factor;
mod gram;
mod native;
mod verify;

#[cfg(feature = "arpack")]
// The ARPACK binding is the one module of this crate that calls C.
#[allow(unsafe_code)]
mod arpack;

use nalgebra::{DMatrix, DVector};
use sprs::CsMatView;

#[cfg(feature = "arpack")]
pub use arpack::{ArpackParams, ArpackSolver};
pub use dense::DenseSolver;
pub use error::{Error, Result};
pub use factor::{Factorization, ShiftInvert};
pub use native::{NativeParams, NativeSolver, default_shift};
pub use verify::SolveStats;

/// A validated generalized eigenproblem `L φ = λ M φ` with a diagonal mass.
#[derive(Debug, Clone, Copy)]
pub struct EigenProblem<'a> {
    stiffness: CsMatView<'a, f64>,
    mass: &'a [f64],
}

impl<'a> EigenProblem<'a> {
    /// Checks and wraps a problem: `stiffness` square (CSC or CSR), finite,
    /// symmetric (to `1e-12` relative to its largest entry); `mass` of the
    /// same size, positive and finite.
    pub fn new(stiffness: CsMatView<'a, f64>, mass: &'a [f64]) -> Result<Self> {
        let (rows, cols) = stiffness.shape();
        if rows != cols {
            return Err(Error::NotSquare { rows, cols });
        }
        if mass.len() != rows {
            return Err(Error::SizeMismatch {
                stiffness: rows,
                mass: mass.len(),
            });
        }
        let mut amax = 0.0f64;
        for (&v, (r, c)) in stiffness.iter() {
            if !v.is_finite() {
                return Err(Error::NonFiniteStiffness {
                    row: r,
                    col: c,
                    value: v,
                });
            }
            amax = amax.max(v.abs());
        }
        for (&v, (r, c)) in stiffness.iter() {
            let t = stiffness.get(c, r).copied().unwrap_or(0.0);
            if (v - t).abs() > 1e-12 * amax {
                return Err(Error::NotSymmetric {
                    row: r,
                    col: c,
                    a_ij: v,
                    a_ji: t,
                });
            }
        }
        if let Some((index, &value)) = mass
            .iter()
            .enumerate()
            .find(|(_, m)| !(m.is_finite() && **m > 0.0))
        {
            return Err(Error::NonPositiveMass { index, value });
        }
        Ok(Self { stiffness, mass })
    }

    /// Problem size n.
    pub fn n(&self) -> usize {
        self.mass.len()
    }

    /// The stiffness matrix `L`.
    pub fn stiffness(&self) -> CsMatView<'a, f64> {
        self.stiffness
    }

    /// The mass diagonal.
    pub fn mass(&self) -> &'a [f64] {
        self.mass
    }

    /// Checks `1 <= k < n`.
    pub fn check_k(&self, k: usize) -> Result<()> {
        if k == 0 || k >= self.n() {
            return Err(Error::InvalidK { k, n: self.n() });
        }
        Ok(())
    }
}

/// A backend computing the `k` smallest eigenpairs of an [`EigenProblem`].
///
/// Contract (checked by [`conformance::check`], which any backend can run,
/// and by the mesh-based suite in `tests/conformance.rs`): eigenvalues ascending; eigenvectors n x k with
/// `Φᵀ M Φ = I` to about `1e-12`; every eigenpair meets the backend's
/// tolerance or the call fails with [`Error::NoConvergence`]; the sign of
/// each eigenvector is fixed (its entry of largest magnitude is positive);
/// same input, same output.
pub trait EigenSolver {
    /// A short name for reports ("native", "arpack", "dense").
    fn name(&self) -> &'static str;

    /// Computes the `k` eigenpairs of smallest eigenvalue.
    fn solve(&self, problem: &EigenProblem<'_>, k: usize) -> Result<SpectralBasis>;
}

/// How a solve went: for the user to check, never needed to use the result.
/// (`Default`: nothing known, e.g. a basis read back from a cache.)
#[derive(Debug, Clone, PartialEq, Default)]
#[non_exhaustive]
pub struct SolveReport {
    /// The backend that produced the basis.
    pub backend: &'static str,
    /// The shift σ of shift-invert (0 for the dense backend).
    pub shift: f64,
    /// Restarts (Krylov–Schur) or ARPACK iterations.
    pub restarts: usize,
    /// Applications of `(L − σM)⁻¹M` to a vector.
    pub operator_applications: usize,
    /// Seconds spent factorizing `L − σM` (0 when not factorized).
    pub factorization_seconds: f64,
    /// Seconds in the iteration, after the factorization.
    pub iteration_seconds: f64,
    /// Residual of each eigenpair: `‖Lφᵢ − λᵢMφᵢ‖_{M⁻¹}` (φᵢ has unit
    /// M-norm, so this is on the scale of λᵢ).
    pub residuals: Vec<f64>,
    /// `max |ΦᵀMΦ − I|` over all entries.
    pub orthonormality_error: f64,
}

impl SolveReport {
    /// The largest residual.
    pub fn max_residual(&self) -> f64 {
        self.residuals.iter().copied().fold(0.0, f64::max)
    }
}

/// The first k eigenpairs of `L φ = λ M φ` and the mass they are
/// orthonormal for.
#[derive(Debug, Clone)]
pub struct SpectralBasis {
    /// Eigenvalues λ, ascending (length k).
    pub eigenvalues: DVector<f64>,
    /// Eigenvectors Φ, n x k, columns M-orthonormal: `ΦᵀMΦ = I`.
    pub eigenvectors: DMatrix<f64>,
    /// The mass diagonal M (length n).
    pub mass: DVector<f64>,
    /// How the solve went.
    pub report: SolveReport,
}

/// `Aᵀ diag(w) B` (A n x k, B n x d, w of length n) by one GEMM (faer,
/// parallel in the current rayon pool when large): the M-weighted inner
/// products of the columns, e.g. the projection `Φᵀ M F` of functions onto
/// a basis.
///
/// # Panics
/// If the row counts differ.
#[track_caller]
pub fn weighted_tr_mul(a: &DMatrix<f64>, w: &DVector<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    use faer::linalg::matmul::matmul;
    let (n, k, d) = (a.nrows(), a.ncols(), b.ncols());
    assert!(
        b.nrows() == n && w.len() == n,
        "weighted_tr_mul: {} rows, {} weights, {} rows",
        n,
        w.len(),
        b.nrows()
    );
    let mut wb = b.clone();
    for mut col in wb.column_iter_mut() {
        col.component_mul_assign(w);
    }
    let mut out = DMatrix::zeros(k, d);
    let par = if n * k * d >= 1 << 20 {
        faer::Par::rayon(0)
    } else {
        faer::Par::Seq
    };
    matmul(
        faer::MatMut::from_column_major_slice_mut(out.as_mut_slice(), k, d),
        faer::Accum::Replace,
        faer::MatRef::from_column_major_slice(a.as_slice(), n, k).transpose(),
        faer::MatRef::from_column_major_slice(wb.as_slice(), n, d),
        1.0,
        par,
    );
    out
}

impl SpectralBasis {
    /// Number of vertices n.
    pub fn n(&self) -> usize {
        self.eigenvectors.nrows()
    }

    /// Number of eigenpairs k.
    pub fn k(&self) -> usize {
        self.eigenvectors.ncols()
    }

    /// Spectral coefficients of functions: `A = Φᵀ M F` (k x d for F n x d).
    ///
    /// # Panics
    /// If `f` does not have n rows.
    #[track_caller]
    pub fn project(&self, f: &DMatrix<f64>) -> DMatrix<f64> {
        assert_eq!(
            f.nrows(),
            self.n(),
            "project: function has {} rows, basis has {}",
            f.nrows(),
            self.n()
        );
        weighted_tr_mul(&self.eigenvectors, &self.mass, f)
    }

    /// Functions from spectral coefficients: `F = Φ A` (n x d for A k x d).
    ///
    /// # Panics
    /// If `a` does not have k rows.
    #[track_caller]
    pub fn reconstruct(&self, a: &DMatrix<f64>) -> DMatrix<f64> {
        assert_eq!(
            a.nrows(),
            self.k(),
            "reconstruct: coefficients have {} rows, basis has k = {}",
            a.nrows(),
            self.k()
        );
        &self.eigenvectors * a
    }

    /// The first `k` eigenpairs (k is clamped to the basis size).
    pub fn truncate(&self, k: usize) -> SpectralBasis {
        let k = k.min(self.k());
        let mut report = self.report.clone();
        report.residuals.truncate(k);
        SpectralBasis {
            eigenvalues: self.eigenvalues.rows(0, k).into_owned(),
            // The leading columns of a column-major matrix are contiguous.
            eigenvectors: DMatrix::from_column_slice(
                self.n(),
                k,
                &self.eigenvectors.as_slice()[..self.n() * k],
            ),
            mass: self.mass.clone(),
            report,
        }
    }
}
