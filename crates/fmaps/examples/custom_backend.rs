//! A third-party eigensolver backend written against the public API
//! alone: block subspace iteration with shift-invert and Rayleigh–Ritz
//! (Bathe & Wilson 1973; Saad, "Numerical methods for large eigenvalue
//! problems", §5.1), on the crate's public sparse factorization
//! [`ShiftInvert`]. It passes the exported conformance check, then runs
//! the whole matching pipeline through [`fmaps::match_shapes`]:
//! `cargo run --release -p fmaps --example custom_backend`.

use std::sync::Arc;
use std::time::Instant;

use fmaps::eigensolve::{
    EigenProblem, EigenSolver, Factorization, Result, ShiftInvert, SolveStats, SpectralBasis,
    conformance, default_shift,
};
use fmaps::pipeline::{MatchParams, Refinement, match_shapes};
use fmaps::shapes::creature_pair;
use fmaps::{Backend, SpectrumParams};
use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// Block subspace iteration: `X ← (L − σM)⁻¹ M X`, M-orthonormalized,
/// then the Ritz pairs of `Xᵀ L X`, until the k wanted pairs' residuals
/// are below `tol` of the spectrum's scale.
struct SubspaceIteration {
    /// Extra vectors in the block beyond k (speed of convergence:
    /// `(λ_k − σ) / (λ_{p+1} − σ)` per iteration for a block of p).
    extra: usize,
    /// Iteration limit.
    max_iterations: usize,
    /// Residual tolerance, relative to max(λ_k, 1).
    tol: f64,
}

/// `L X` for a symmetric sparse L (CSC or CSR: the outer index is used as
/// the column, the same for a symmetric matrix).
fn stiffness_times(problem: &EigenProblem<'_>, x: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(x.nrows(), x.ncols());
    for (j, lane) in problem.stiffness().outer_iterator().enumerate() {
        for (i, &v) in lane.iter() {
            for c in 0..x.ncols() {
                out[(i, c)] += v * x[(j, c)];
            }
        }
    }
    out
}

/// Modified Gram–Schmidt in the M inner product, twice ("twice is
/// enough"); columns that vanish are replaced by a fresh direction.
fn m_orthonormalize(x: &mut DMatrix<f64>, mass: &[f64]) {
    let dot = |a: &[f64], b: &[f64]| -> f64 {
        a.iter().zip(b).zip(mass).map(|((p, q), m)| p * q * m).sum()
    };
    let (n, p) = x.shape();
    for _ in 0..2 {
        for j in 0..p {
            for i in 0..j {
                let (left, right) = x.as_mut_slice().split_at_mut(j * n);
                let (qi, qj) = (&left[i * n..(i + 1) * n], &mut right[..n]);
                let r = dot(qi, qj);
                qj.iter_mut().zip(qi).for_each(|(v, q)| *v -= r * q);
            }
            let col = &mut x.as_mut_slice()[j * n..(j + 1) * n];
            let norm = dot(col, col).sqrt();
            if norm > 1e-300 {
                col.iter_mut().for_each(|v| *v /= norm);
            } else {
                col.iter_mut()
                    .enumerate()
                    .for_each(|(i, v)| *v = ((i * (j + 7)) % 13) as f64);
            }
        }
    }
}

impl EigenSolver for SubspaceIteration {
    fn name(&self) -> &'static str {
        "subspace-iteration"
    }

    fn solve(&self, problem: &EigenProblem<'_>, k: usize) -> Result<SpectralBasis> {
        problem.check_k(k)?;
        let t0 = Instant::now();
        let (n, mass) = (problem.n(), problem.mass());
        let p = (k + self.extra.max(k)).min(n);
        // L is PSD, so a small negative shift makes L − σM definite.
        let sigma = default_shift(mass);
        let op = ShiftInvert::new(problem, sigma, 1, Factorization::Auto)?;
        let mut x = DMatrix::from_fn(n, p, |i, j| {
            (((i * 2654435761 + j * 40503) % 1000) as f64 / 500.0) - 1.0
        });
        m_orthonormalize(&mut x, mass);
        let mut stats = SolveStats::new(self.name());
        stats.shift = sigma;
        stats.factorization_seconds = op.seconds();
        let mut ritz: (DVector<f64>, DMatrix<f64>) = (DVector::zeros(p), x.clone());
        for it in 0..self.max_iterations {
            // X ← (L − σM)⁻¹ M X.
            for mut col in x.column_iter_mut() {
                col.iter_mut().zip(mass).for_each(|(v, m)| *v *= m);
            }
            op.solve_in_place(x.as_mut_slice(), p);
            stats.operator_applications += p;
            m_orthonormalize(&mut x, mass);
            // Rayleigh–Ritz on span(X) (XᵀMX = I).
            let lx = stiffness_times(problem, &x);
            let a = x.tr_mul(&lx);
            let a = (&a + a.transpose()) * 0.5;
            let eig = SymmetricEigen::new(a);
            let mut order: Vec<usize> = (0..p).collect();
            order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
            let theta = DVector::from_fn(p, |i, _| eig.eigenvalues[order[i]]);
            let w = DMatrix::from_fn(p, p, |r, c| eig.eigenvectors[(r, order[c])]);
            x = &x * &w;
            let lx = &lx * &w;
            // Residuals of the wanted pairs: ‖Lx − θMx‖_{M⁻¹}.
            let scale = theta[k - 1].abs().max(1.0);
            let worst = (0..k)
                .map(|c| {
                    (0..n)
                        .map(|i| {
                            let r = lx[(i, c)] - theta[c] * mass[i] * x[(i, c)];
                            r * r / mass[i]
                        })
                        .sum::<f64>()
                        .sqrt()
                })
                .fold(0.0, f64::max);
            stats.restarts = it + 1;
            ritz = (theta, x.clone());
            if worst <= self.tol * scale || p == n {
                break;
            }
        }
        stats.iteration_seconds = t0.elapsed().as_secs_f64() - stats.factorization_seconds;
        let (theta, x) = ritz;
        SpectralBasis::from_eigenpairs(
            problem,
            theta.rows(0, k).into_owned(),
            x.columns(0, k).into_owned(),
            stats,
        )
    }
}

/// Checks the conformance, then matches the built-in pair with it (also
/// called by the workspace test `tests/extension_points.rs`).
pub fn main() -> std::result::Result<(), Box<dyn std::error::Error>> {
    let backend = SubspaceIteration {
        extra: 16,
        max_iterations: 500,
        tol: 1e-11,
    };
    conformance::check(&backend)?;
    println!(
        "{}: passes fmaps_eigensolve::conformance::check",
        backend.name()
    );

    // The whole pipeline with it, on the built-in pair (known truth).
    let pair = creature_pair(3);
    let mut params = MatchParams::default();
    params.k_process = 80;
    params.descriptors.eigenpairs = 60;
    params.k = 30;
    params.refinement = Refinement::zoomout(30, 80, 5);
    params.spectrum.backend = Backend::Custom(Arc::new(backend));
    let t = Instant::now();
    let r = match_shapes(&pair.source, &pair.target, &params)?;
    let seconds = t.elapsed().as_secs_f64();
    // The same pipeline with the built-in backend: two independent
    // eigensolvers must give the same map (up to near-ties).
    let mut native = params.clone();
    native.spectrum = SpectrumParams::default();
    let r_native = match_shapes(&pair.source, &pair.target, &native)?;
    let exact = r
        .t_ab
        .iter()
        .zip(&pair.truth)
        .filter(|(a, b)| a == b)
        .count();
    let same = r
        .t_ab
        .iter()
        .zip(&r_native.t_ab)
        .filter(|(a, b)| a == b)
        .count();
    println!(
        "match_shapes with the custom backend: {exact} of {} vertices on their true image, {seconds:.2} s; same map as the native backend on {same} vertices",
        pair.truth.len(),
    );
    if same * 100 < 99 * r.t_ab.len() {
        return Err(format!("custom and native backends agree on only {same} vertices").into());
    }
    Ok(())
}
