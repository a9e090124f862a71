//! The dense reference backend.

use std::time::Instant;

use faer::{Mat, Side};
use nalgebra::{DMatrix, DVector};

use crate::{EigenProblem, EigenSolver, Error, Result, SolveStats, SpectralBasis};

/// A dense symmetric eigendecomposition of `M^{-1/2} L M^{-1/2}` (faer's
/// self-adjoint divide and conquer): exact to rounding, O(n³) time and
/// O(n²) memory. A reference for tests and small problems.
#[derive(Debug, Clone)]
pub struct DenseSolver {
    /// Largest problem size accepted (default 8000: a 512 MB matrix, about
    /// a minute of work; a 5k-vertex mesh takes ~10 s).
    pub max_n: usize,
}

impl Default for DenseSolver {
    fn default() -> Self {
        Self { max_n: 8000 }
    }
}

/// The k smallest eigenpairs by a dense decomposition of
/// `M^{-1/2} L M^{-1/2}`, eigenvectors M-orthonormal with fixed signs.
pub(crate) fn dense_pairs(
    problem: &EigenProblem<'_>,
    k: usize,
    backend: &'static str,
) -> Result<(DVector<f64>, DMatrix<f64>)> {
    let n = problem.n();
    let d: Vec<f64> = problem.mass().iter().map(|m| 1.0 / m.sqrt()).collect();
    let mut a = Mat::<f64>::zeros(n, n);
    for (j, lane) in problem.stiffness().outer_iterator().enumerate() {
        for (i, &v) in lane.iter() {
            a[(i, j)] += d[i] * v * d[j];
        }
    }
    let evd = a
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| Error::Backend {
            backend,
            message: format!("dense eigensolver: {e:?}"),
        })?;
    let s = evd.S().column_vector();
    let u = evd.U();
    let eigenvalues = DVector::from_iterator(k, (0..k).map(|i| s[i]));
    let eigenvectors = DMatrix::from_fn(n, k, |i, j| u[(i, j)] * d[i]);
    Ok((eigenvalues, eigenvectors))
}

impl EigenSolver for DenseSolver {
    fn name(&self) -> &'static str {
        "dense"
    }

    fn solve(&self, problem: &EigenProblem<'_>, k: usize) -> Result<SpectralBasis> {
        problem.check_k(k)?;
        let n = problem.n();
        if n > self.max_n {
            return Err(Error::TooLargeForDense { n, max: self.max_n });
        }
        let t0 = Instant::now();
        let (eigenvalues, eigenvectors) = dense_pairs(problem, k, "dense")?;
        let stats = SolveStats {
            backend: "dense",
            shift: 0.0,
            restarts: 0,
            operator_applications: 0,
            factorization_seconds: 0.0,
            iteration_seconds: t0.elapsed().as_secs_f64(),
            threads: 1,
        };
        SpectralBasis::from_eigenpairs(problem, eigenvalues, eigenvectors, stats)
    }
}
