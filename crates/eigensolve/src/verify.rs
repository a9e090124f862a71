//! Checks shared by all backends: residuals, M-orthonormality, sign
//! normalization, and a small deterministic random generator.

use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::{Accum, MatRef};
use nalgebra::{DMatrix, DVector};

use crate::{EigenProblem, Error, Result, SolveReport, SpectralBasis};

/// What a backend measured while solving, for [`SpectralBasis::from_eigenpairs`]
/// (which adds the residuals and the orthonormality check).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct SolveStats {
    /// The backend's name ([`EigenSolver::name`](crate::EigenSolver::name)).
    pub backend: &'static str,
    /// The shift σ of shift-invert (0 when none).
    pub shift: f64,
    /// Restarts or outer iterations.
    pub restarts: usize,
    /// Applications of the operator to a vector.
    pub operator_applications: usize,
    /// Seconds spent factorizing (0 when not factorized).
    pub factorization_seconds: f64,
    /// Seconds in the iteration.
    pub iteration_seconds: f64,
    /// Threads for the orthonormality check (0 or 1: sequential).
    pub threads: usize,
}

impl SolveStats {
    /// Stats of `backend` with every count and time zero (set the fields
    /// the backend measured).
    pub fn new(backend: &'static str) -> Self {
        SolveStats {
            backend,
            shift: 0.0,
            restarts: 0,
            operator_applications: 0,
            factorization_seconds: 0.0,
            iteration_seconds: 0.0,
            threads: 1,
        }
    }
}

impl SpectralBasis {
    /// The basis a backend computed, with its report: the public way for
    /// any backend (ours use it too) to produce a [`SpectralBasis`].
    /// `eigenvalues` ascending (length k), `eigenvectors` n x k for the n
    /// of `problem`. Each eigenvector's sign is normalized (its entry of
    /// largest magnitude positive), and the residuals and the
    /// M-orthonormality error are computed here, the same way for every
    /// backend (outside any timed iteration).
    ///
    /// Errors ([`Error::InvalidBasis`]): mismatched sizes, non-finite
    /// values, eigenvalues not ascending. The accuracy is not judged here:
    /// the report says it, and [`conformance::check`](crate::conformance::check)
    /// tests a backend against the contract.
    pub fn from_eigenpairs(
        problem: &EigenProblem<'_>,
        eigenvalues: DVector<f64>,
        mut eigenvectors: DMatrix<f64>,
        stats: SolveStats,
    ) -> Result<SpectralBasis> {
        let bad = |why: String| Err(Error::InvalidBasis(why));
        let (n, k) = eigenvectors.shape();
        if n != problem.n() || eigenvalues.len() != k {
            return bad(format!(
                "{} eigenvalues and {n} x {k} eigenvectors for a problem of size {}",
                eigenvalues.len(),
                problem.n()
            ));
        }
        if let Some(i) = eigenvalues.iter().position(|v| !v.is_finite()) {
            return bad(format!("eigenvalue {i} is {}", eigenvalues[i]));
        }
        if let Some(i) = eigenvectors.iter().position(|v| !v.is_finite()) {
            return bad(format!(
                "eigenvector {} has a non-finite entry",
                i / n.max(1)
            ));
        }
        if let Some(i) = (1..k).find(|&i| eigenvalues[i] < eigenvalues[i - 1]) {
            return bad(format!(
                "eigenvalues not ascending: λ_{} = {} > λ_{i} = {}",
                i - 1,
                eigenvalues[i - 1],
                eigenvalues[i]
            ));
        }
        fix_signs(&mut eigenvectors);
        let report = SolveReport {
            backend: stats.backend,
            shift: stats.shift,
            restarts: stats.restarts,
            operator_applications: stats.operator_applications,
            factorization_seconds: stats.factorization_seconds,
            iteration_seconds: stats.iteration_seconds,
            residuals: residuals(problem, &eigenvalues, &eigenvectors),
            orthonormality_error: orthonormality_error(
                problem.mass(),
                &eigenvectors,
                stats.threads,
            ),
        };
        Ok(SpectralBasis {
            eigenvalues,
            eigenvectors,
            mass: DVector::from_column_slice(problem.mass()),
            report,
        })
    }
}

/// `‖Lφᵢ − λᵢMφᵢ‖_{M⁻¹}` for every column.
fn residuals(problem: &EigenProblem<'_>, lambda: &DVector<f64>, phi: &DMatrix<f64>) -> Vec<f64> {
    let (n, k) = phi.shape();
    let l = problem.stiffness();
    let m = problem.mass();
    let mut out = Vec::with_capacity(k);
    // Blocks of RESIDUAL_BLOCK columns copied row-major: every stored
    // entry of L then scales one contiguous row of the block (SIMD across
    // the columns), and each column's sums run in the same order as one
    // column at a time.
    let mut rows = Vec::new();
    for c0 in (0..k).step_by(RESIDUAL_BLOCK) {
        let w = RESIDUAL_BLOCK.min(k - c0);
        rows.clear();
        rows.resize(n * w, 0.0);
        for c in 0..w {
            for (j, &v) in phi.column(c0 + c).iter().enumerate() {
                rows[j * w + c] = v;
            }
        }
        let lam = &lambda.as_slice()[c0..c0 + w];
        out.extend(residual_block(l, m, &rows, w, lam));
    }
    out
}

/// Columns per block of [`residuals`].
const RESIDUAL_BLOCK: usize = 16;

fmaps_simd::dispatched! {
    /// `‖L x − λ M x‖_{M⁻¹}` of the `w` columns of `rows` (row-major, `w`
    /// wide), row `j` of `L x` as the dot product of column `j` of `L`
    /// with `x` (L is symmetric, so CSC and CSR storage give the same
    /// product).
    fn residual_block(
        l: sprs::CsMatView<'_, f64>,
        m: &[f64],
        rows: &[f64],
        w: usize,
        lam: &[f64],
    ) -> Vec<f64> {
        let mut s = vec![0.0; w];
        let mut lp = vec![0.0; w];
        for (j, lane) in l.outer_iterator().enumerate() {
            lp.fill(0.0);
            for (&i, &v) in lane.indices().iter().zip(lane.data()) {
                let x = &rows[i * w..(i + 1) * w];
                for c in 0..w {
                    lp[c] += v * x[c];
                }
            }
            let xj = &rows[j * w..(j + 1) * w];
            for c in 0..w {
                let r = lp[c] - lam[c] * m[j] * xj[c];
                s[c] += r * r / m[j];
            }
        }
        s.into_iter().map(f64::sqrt).collect()
    }
}

/// `max |ΦᵀMΦ − I|`.
fn orthonormality_error(mass: &[f64], phi: &DMatrix<f64>, threads: usize) -> f64 {
    let n = phi.nrows();
    let k = phi.ncols();
    let mut mphi = phi.clone();
    for mut col in mphi.column_iter_mut() {
        for (v, m) in col.iter_mut().zip(mass) {
            *v *= m;
        }
    }
    let a = MatRef::from_column_major_slice(phi.as_slice(), n, k);
    let b = MatRef::from_column_major_slice(mphi.as_slice(), n, k);
    // ΦᵀMΦ is symmetric: its lower triangle only (half the products).
    let mut g = faer::Mat::<f64>::zeros(k, k);
    triangular::matmul(
        &mut g,
        BlockStructure::TriangularLower,
        Accum::Replace,
        a.transpose(),
        BlockStructure::Rectangular,
        b,
        BlockStructure::Rectangular,
        1.0,
        crate::factor::par_of(threads),
    );
    let mut e = 0.0f64;
    for j in 0..k {
        for i in j..k {
            let want = if i == j { 1.0 } else { 0.0 };
            e = e.max((g[(i, j)] - want).abs());
        }
    }
    e
}

/// Flips each column so that its entry of largest magnitude is positive
/// (ties: the first such entry), making outputs comparable and
/// deterministic.
fn fix_signs(phi: &mut DMatrix<f64>) {
    for mut col in phi.column_iter_mut() {
        let mut best = 0.0f64;
        let mut sign = 1.0;
        for &v in col.iter() {
            if v.abs() > best {
                best = v.abs();
                sign = v.signum();
            }
        }
        if sign < 0.0 {
            col.neg_mut();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The residuals agree with the dense product `L x − λ M x` weighted by
    /// `M⁻¹`, for a symmetric L with off-diagonal entries (a weighted path
    /// graph's Laplacian) and vectors that are not eigenvectors.
    #[test]
    fn residuals_equal_the_dense_computation() {
        let n = 7;
        let mut tri = sprs::TriMat::new((n, n));
        for i in 0..n - 1 {
            let w = 1.0 + i as f64 * 0.25;
            tri.add_triplet(i, i + 1, -w);
            tri.add_triplet(i + 1, i, -w);
            tri.add_triplet(i, i, w);
            tri.add_triplet(i + 1, i + 1, w);
        }
        let l: sprs::CsMat<f64> = tri.to_csc();
        let mass: Vec<f64> = (0..n).map(|i| 0.5 + 0.1 * i as f64).collect();
        let problem = EigenProblem::new(l.view(), &mass).unwrap();
        let phi = DMatrix::from_fn(n, 3, |i, c| ((i * 3 + c * 5) % 7) as f64 - 3.0);
        let lambda = DVector::from_vec(vec![0.0, 0.7, 2.5]);
        let mut dense = vec![vec![0.0; n]; n];
        for (&v, (i, j)) in l.iter() {
            dense[i][j] += v;
        }
        for (c, r) in residuals(&problem, &lambda, &phi).into_iter().enumerate() {
            let mut s = 0.0;
            for i in 0..n {
                let lx: f64 = (0..n).map(|j| dense[i][j] * phi[(j, c)]).sum();
                let t = lx - lambda[c] * mass[i] * phi[(i, c)];
                s += t * t / mass[i];
            }
            assert!(
                (r - s.sqrt()).abs() <= 1e-12 * s.sqrt().max(1.0),
                "{r} vs {}",
                s.sqrt()
            );
        }
    }

    /// The orthonormality error is the largest entry of `|ΦᵀMΦ − I|`
    /// (computed from one triangle: the Gram matrix is symmetric), wherever
    /// it is: off the diagonal or on it.
    #[test]
    fn orthonormality_error_finds_the_largest_departure() {
        let mass = [0.25, 1.0, 4.0, 1.0];
        // M-unit columns: e_0 / 0.5, e_1, e_2 / 2, then combinations.
        let unit = |i: usize| [2.0, 1.0, 0.5, 1.0][i];
        let cols = |c: &[(usize, f64)]| {
            let mut v = vec![0.0; 4];
            for &(i, a) in c {
                v[i] += a * unit(i);
            }
            v
        };
        // ⟨c0, c1⟩_M = 0.6 (both of M-norm 1); c2 has M-norm² 1.21.
        let sets = [
            (
                vec![
                    cols(&[(0, 1.0)]),
                    cols(&[(0, 0.6), (1, 0.8)]),
                    cols(&[(2, 1.0)]),
                ],
                0.6,
            ),
            (
                vec![cols(&[(0, 1.0)]), cols(&[(1, 1.0)]), cols(&[(2, 1.1)])],
                0.21,
            ),
            (
                vec![
                    cols(&[(3, 1.0)]),
                    cols(&[(1, 1.0)]),
                    cols(&[(0, -0.3), (2, 1.0)]),
                ],
                0.09,
            ),
        ];
        for (set, want) in sets {
            let phi = DMatrix::from_fn(4, set.len(), |i, c| set[c][i]);
            let e = orthonormality_error(&mass, &phi, 1);
            assert!((e - want).abs() < 1e-14, "{e} vs {want}");
        }
    }
}
