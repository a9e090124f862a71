//! The pure-Rust backend: shift-invert block Krylov–Schur.
//!
//! With `D = M^{1/2}` the problem `Lφ = λMφ` becomes the standard symmetric
//! problem for `A = D (L − σM)⁻¹ D`, whose eigenvalues `θ = 1/(λ − σ)` are
//! largest for the wanted λ and whose eigenvectors are `ψ = Dφ`; ψ's
//! Euclidean orthonormality is φ's M-orthonormality. A block Lanczos process
//! with full reorthogonalization (two classical Gram–Schmidt passes as
//! GEMMs) builds an orthonormal basis `V` of the block Krylov space and the
//! projected matrix `H = VᵀAV`; when the basis is full, the Ritz pairs of
//! `H` are computed, converged ones are checked, and the basis is
//! compressed to the leading Ritz vectors plus the residual block
//! (the Krylov–Schur restart of G. W. Stewart, SIAM J. Matrix Anal. Appl.
//! 23(3), 2001; for the symmetric case it is the thick-restart Lanczos of
//! K. Wu and H. Simon, SIAM J. Matrix Anal. Appl. 22(2), 2000). At each
//! restart, converged Ritz pairs are locked (deflated, which the
//! Krylov–Schur form makes simple, as Stewart notes): they leave the projected
//! problem, so the dense eigendecompositions, the restarts and the final
//! basis product only involve the unlocked part. The block
//! size lets the sparse solves and the reorthogonalization run as BLAS-3
//! kernels and makes clusters of close eigenvalues converge together.

use std::time::Instant;

use faer::linalg::matmul::matmul;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef};
use fmaps_simd::dot8 as dot;
use nalgebra::{DMatrix, DVector};

use crate::factor::{Factorization, ShiftInvert, par_of};
use crate::{EigenProblem, EigenSolver, Error, Result, SolveStats, SpectralBasis};
use fmaps_simd::SplitMix;

/// Options of the native backend. `Default` converges every eigenpair to
/// near machine precision (eigenvalues agree with ARPACK's to ~1e-12).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct NativeParams {
    /// The shift σ (negative, so that `L − σM` is positive definite).
    /// `None` picks `−0.01 · 4π / area` with `area = Σ M`, i.e. −0.01 at the
    /// scale of the unit sphere, as pyFM's `sigma=-0.01` on unit-area shapes.
    pub shift: Option<f64>,
    /// Convergence tolerance: a Ritz pair (θ, y) of the shift-inverted
    /// operator is accepted when `‖A y − θ y‖ ≤ tol · θ`.
    pub tol: f64,
    /// Number of vectors per Lanczos block. Blocks of several vectors run
    /// the solves and the reorthogonalization as BLAS-3 kernels and find
    /// every copy of an eigenvalue of multiplicity up to the block size
    /// (exactly symmetric meshes such as an icosphere have 4- and 5-fold
    /// eigenvalues). `1` is plain thick-restart Lanczos: it can miss copies
    /// of exactly repeated eigenvalues, as any single-vector Krylov method.
    /// The default, 5, is the largest multiplicity a symmetry of a mesh
    /// can force (the largest irreducible representation of a finite
    /// subgroup of O(3), the icosahedral group's, has dimension 5); larger
    /// blocks cost more operator applications for the same basis size
    /// (FAUST at 5k, k = 200: 688 with blocks of 8, 600 with 5).
    pub block_size: usize,
    /// Size of the Krylov basis before a restart. `None` picks
    /// `max(min(2k, max(k + 100, 1.5k)), k + 4·block)`: 2k up to k = 100,
    /// then 1.5k (for k = 150 and 200, about 10% faster than 2k on 5k-vertex
    /// meshes at one thread, as many operator applications; no difference
    /// measured at 20k and 80k, where the solves dominate). Any value is
    /// raised to at least `k + 2·block`, rounded up to whole blocks and
    /// capped by n.
    pub subspace: Option<usize>,
    /// Restarts before giving up with [`Error::NoConvergence`].
    pub max_restarts: usize,
    /// Threads for the factorization and the dense kernels (1 = sequential).
    pub threads: usize,
    /// Sparse Cholesky variant. `Auto` is the simplicial one here: the
    /// hundreds of block solves of an iteration outweigh the
    /// factorization, and the simplicial factor's one-pass block solve
    /// was the faster at every size measured (one thread, k = 200: 5k, 20k
    /// and 80k vertices, 12% less at 80k than the supernodal one with its
    /// faster factorization included).
    pub factorization: Factorization,
    /// Seed of the random start block.
    pub seed: u64,
}

impl Default for NativeParams {
    fn default() -> Self {
        Self {
            shift: None,
            tol: 1e-12,
            block_size: 5,
            subspace: None,
            max_restarts: 300,
            threads: 1,
            factorization: Factorization::Auto,
            seed: 0x5eed_f00d,
        }
    }
}

/// The default, pure-Rust eigensolver (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct NativeSolver {
    /// Its options.
    pub params: NativeParams,
}

impl NativeSolver {
    /// A solver with the given options.
    pub fn new(params: NativeParams) -> Self {
        Self { params }
    }
}

/// The shift used when none is given: −0.01 at the scale of a unit sphere.
pub fn default_shift(mass: &[f64]) -> f64 {
    let area: f64 = mass.iter().sum();
    -0.01 * 4.0 * std::f64::consts::PI / area
}

impl EigenSolver for NativeSolver {
    fn name(&self) -> &'static str {
        "native"
    }

    fn solve(&self, problem: &EigenProblem<'_>, k: usize) -> Result<SpectralBasis> {
        problem.check_k(k)?;
        let p = &self.params;
        if !(p.tol > 0.0 && p.tol < 1.0) {
            return Err(Error::InvalidParameter(format!(
                "tol must be in (0, 1), got {}",
                p.tol
            )));
        }
        if p.block_size == 0 {
            return Err(Error::InvalidParameter(
                "block_size must be at least 1".into(),
            ));
        }
        let shift = p.shift.unwrap_or_else(|| default_shift(problem.mass()));
        let n = problem.n();
        if n < k + 2 * p.block_size.min(n) + 2 {
            // The Krylov basis plus its residual block would span the whole
            // space: the Rayleigh–Ritz projection onto everything is the
            // dense eigendecomposition, which is then the cheaper and exact
            // way to do the same computation.
            let t0 = Instant::now();
            let (eigenvalues, eigenvectors) = crate::dense::dense_pairs(problem, k, "native")?;
            let stats = SolveStats {
                backend: "native",
                shift,
                restarts: 0,
                operator_applications: 0,
                factorization_seconds: 0.0,
                iteration_seconds: t0.elapsed().as_secs_f64(),
                threads: p.threads,
            };
            return SpectralBasis::from_eigenpairs(problem, eigenvalues, eigenvectors, stats);
        }
        let kind = match p.factorization {
            Factorization::Auto => Factorization::Simplicial,
            kind => kind,
        };
        let factor = ShiftInvert::new(problem, shift, p.threads, kind)?;
        let t0 = Instant::now();
        let (theta, psi, restarts, applies) = krylov_schur(problem, &factor, k, p)?;
        let d: Vec<f64> = problem.mass().iter().map(|m| m.sqrt()).collect();
        // θ descending is λ ascending.
        let eigenvalues = DVector::from_iterator(k, theta.iter().map(|t| shift + 1.0 / t));
        let mut eigenvectors = DMatrix::from_column_slice(n, k, &psi);
        for mut col in eigenvectors.column_iter_mut() {
            for (v, di) in col.iter_mut().zip(&d) {
                *v /= di;
            }
        }
        let stats = SolveStats {
            backend: "native",
            shift,
            restarts,
            operator_applications: applies,
            factorization_seconds: factor.seconds(),
            iteration_seconds: t0.elapsed().as_secs_f64(),
            threads: p.threads,
        };
        SpectralBasis::from_eigenpairs(problem, eigenvalues, eigenvectors, stats)
    }
}

/// Returns the k largest θ (descending), the n x k column-major Ritz
/// vectors ψ, the restart count and the number of operator applications.
fn krylov_schur(
    problem: &EigenProblem<'_>,
    factor: &ShiftInvert,
    k: usize,
    p: &NativeParams,
) -> Result<(Vec<f64>, Vec<f64>, usize, usize)> {
    let n = problem.n();
    let par = par_of(p.threads);
    let d: Vec<f64> = problem.mass().iter().map(|m| m.sqrt()).collect();
    // Block size and basis size must leave room for the residual block:
    // m + b <= n, m > k, m a multiple of b.
    // The caller guarantees n >= k + 2b + 2, so m = k + b rounded up to
    // whole blocks always fits.
    let b = p.block_size;
    let default_m = (2 * k).min((k + 100).max(3 * k / 2)).max(k + 4 * b);
    let want_m = p.subspace.unwrap_or(default_m).max(k + 2 * b);
    let mut m = want_m.div_ceil(b) * b;
    while m + b > n {
        m -= b;
    }
    debug_assert!(m >= k + b);
    let cols = m + b;
    let mut v = Vec::new();
    v.try_reserve_exact(n * cols)
        .map_err(|_| Error::OutOfMemory(format!("Krylov basis of {n} x {cols}")))?;
    v.resize(n * cols, 0.0);
    let mut h = Mat::<f64>::zeros(m + b, m + b);
    let mut w = vec![0.0; n * b];
    let mut coef = Mat::<f64>::zeros(m + b, b);
    let mut rng = SplitMix(p.seed);

    // Random start block, orthonormalized.
    for x in &mut v[..n * b] {
        *x = rng.symmetric();
    }
    let mut r = Mat::<f64>::zeros(b, b);
    orthonormalize_block(&mut v, n, 0, b, &mut r, &mut rng);

    let apply = |x: &[f64], out: &mut [f64]| {
        for (c, chunk) in out.chunks_mut(n).enumerate() {
            for i in 0..n {
                chunk[i] = d[i] * x[c * n + i];
            }
        }
        factor.solve_in_place(out, out.len() / n);
        for chunk in out.chunks_mut(n) {
            for i in 0..n {
                chunk[i] *= d[i];
            }
        }
    };

    let mut c = 0; // first column of the block whose image is next
    let mut block_start = 0; // first block of this cycle (couples to all before it)
    let mut restarts = 0;
    let mut applies = 0;
    let mut last_r = Mat::<f64>::zeros(b, b);
    // Columns 0..locked of V are converged Ritz vectors taken out of the
    // projected problem (see the restart); locked_theta their values.
    let mut locked = 0;
    let mut locked_theta: Vec<f64> = Vec::with_capacity(k);
    let mut lock_spent = 0.0; // Σ‖s_i‖² of the locked pairs' dropped couplings
    loop {
        // Expand the basis block by block up to m columns.
        while c < m {
            let cb = c + b;
            apply(&v[c * n..cb * n], &mut w);
            applies += b;
            // In exact arithmetic A·V_c only has components along the
            // previous block, itself, and (for the first block after a
            // restart) the kept Ritz vectors. Remove those first, cheaply;
            // then one full classical Gram–Schmidt pass removes the
            // rounding-level rest, and a second full pass runs only when a
            // column lost more than half its norm in the first (the DGKS
            // criterion), which is when that is not enough.
            let lo = if c == block_start { 0 } else { c - b };
            coef.fill(0.0);
            project_out(&v, n, lo, cb, &mut w, b, &mut coef, p.threads);
            let before: Vec<f64> = w.chunks(n).map(norm).collect();
            project_out(&v, n, 0, cb, &mut w, b, &mut coef, p.threads);
            let after: Vec<f64> = w.chunks(n).map(norm).collect();
            if before.iter().zip(&after).any(|(x, y)| *y < 0.5 * x) {
                project_out(&v, n, 0, cb, &mut w, b, &mut coef, p.threads);
            }
            let pre_norms = before;
            for j in 0..b {
                for i in 0..cb {
                    let x = coef[(i, j)];
                    h[(i, c + j)] = x;
                    if i < c {
                        h[(c + j, i)] = x;
                    }
                }
            }
            // Symmetrize the diagonal block.
            for i in 0..b {
                for j in 0..i {
                    let s = 0.5 * (h[(c + i, c + j)] + h[(c + j, c + i)]);
                    h[(c + i, c + j)] = s;
                    h[(c + j, c + i)] = s;
                }
            }
            // The next block and its coupling R: W = Q R.
            v[cb * n..(cb + b) * n].copy_from_slice(&w);
            orthonormalize_against(&mut v, n, cb, b, &pre_norms, &mut r, &mut rng);
            for i in 0..b {
                for j in 0..b {
                    h[(cb + i, c + j)] = r[(i, j)];
                    h[(c + j, cb + i)] = r[(i, j)];
                }
            }
            last_r.copy_from(&r);
            c = cb;
        }

        // Ritz pairs of the active part of the projected matrix (columns
        // locked..m), θ descending.
        // One thread, explicitly: faer's default (its global parallelism)
        // splits the tridiagonalization by the pool's size, and the basis
        // then differs in the last digits between thread counts.
        let ma = m - locked;
        let ka = k - locked;
        let (mut u, mut s) = (
            Mat::<f64>::zeros(ma, ma),
            faer::diag::Diag::<f64>::zeros(ma),
        );
        {
            use faer::dyn_stack::{MemBuffer, MemStack};
            use faer::linalg::evd;
            let seq = faer::Par::Seq;
            let mut mem = MemBuffer::new(evd::self_adjoint_evd_scratch::<f64>(
                ma,
                evd::ComputeEigenvectors::Yes,
                seq,
                Default::default(),
            ));
            evd::self_adjoint_evd(
                h.as_ref().submatrix(locked, locked, ma, ma),
                s.as_mut(),
                Some(u.as_mut()),
                seq,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| Error::Backend {
                backend: "native",
                message: format!("dense eigensolver: {e:?}"),
            })?;
        }
        let (s, u) = (s.column_vector(), u.as_ref());
        let order: Vec<usize> = (0..ma).rev().collect();
        let theta: Vec<f64> = order.iter().map(|&i| s[i]).collect();
        // Residual of Ritz pair i: ‖R · y_i[ma−b..ma]‖.
        let resid: Vec<f64> = order
            .iter()
            .map(|&i| {
                let mut acc = 0.0;
                for a in 0..b {
                    let mut x = 0.0;
                    for t in 0..b {
                        x += last_r[(a, t)] * u[(ma - b + t, i)];
                    }
                    acc += x * x;
                }
                acc.sqrt()
            })
            .collect();
        let converged = (0..ka)
            .filter(|&i| resid[i] <= p.tol * theta[i].abs())
            .count();
        if converged == ka || restarts >= p.max_restarts {
            if converged < ka {
                return Err(Error::NoConvergence {
                    converged: locked + converged,
                    wanted: k,
                    restarts,
                    operator_applications: applies,
                });
            }
            let y = gather_columns(u, &order[..ka]);
            let mut psi = vec![0.0; n * k];
            psi[..locked * n].copy_from_slice(&v[..locked * n]);
            basis_times(
                &v[locked * n..m * n],
                n,
                y.as_ref(),
                MatMut::from_column_major_slice_mut(&mut psi[locked * n..], n, ka),
                par,
            );
            let mut all_theta = locked_theta;
            all_theta.extend_from_slice(&theta[..ka]);
            return Ok(sort_descending(all_theta, psi, n, restarts, applies));
        }

        // Lock (deflate) converged active Ritz pairs: they leave the
        // projected problem, the restarts and the final basis product (only
        // the Gram–Schmidt passes still see them). A locked pair's coupling
        // s_i to the residual block is dropped from H; since A is
        // symmetric, that changes the residual of any later Ritz pair (and
        // of a pair locked later) by at most ‖[s_1 … s_L]‖_F. Pairs are
        // locked, smallest coupling first, while Σ‖s_i‖² stays within
        // (tol · θ_k)², θ_k the smallest wanted Ritz value: every wanted
        // pair then keeps its residual within √2 · tol · θ.
        let budget = (p.tol * theta[ka - 1].abs()).powi(2);
        let mut candidates: Vec<usize> = (0..ka)
            .filter(|&i| resid[i] <= p.tol * theta[i].abs())
            .collect();
        candidates.sort_by(|&x, &y| resid[x].total_cmp(&resid[y]));
        let mut is_new_lock = vec![false; ka];
        for &i in &candidates {
            let r2 = resid[i] * resid[i];
            if lock_spent + r2 > budget {
                break;
            }
            lock_spent += r2;
            is_new_lock[i] = true;
        }
        // The new locks first (θ descending), then the other active
        // pairs in θ order.
        let sel: Vec<usize> = (0..ka)
            .filter(|&i| is_new_lock[i])
            .chain((0..ma).filter(|&i| i >= ka || !is_new_lock[i]))
            .collect();
        let new_locks = ka - sel[..ka].iter().filter(|&&i| !is_new_lock[i]).count();

        // Thick restart: keep the leading keep Ritz vectors (locked
        // included) and the residual block; m − keep must be a positive
        // multiple of b.
        let target = k + (m - k) / 2;
        let keep = m - ((m - target) / b).max(1) * b;
        debug_assert!(keep >= k && (m - keep).is_multiple_of(b));
        let kept: Vec<usize> = sel[..keep - locked].iter().map(|&i| order[i]).collect();
        let y = gather_columns(u, &kept);
        restart_in_place(&mut v[locked * n..], n, ma, y.as_ref(), par);
        v.copy_within(m * n..(m + b) * n, keep * n);
        h.fill(0.0);
        for i in locked..keep {
            h[(i, i)] = theta[sel[i - locked]];
        }
        // Coupling of the residual block to the kept active Ritz vectors:
        // S = R · Y[ma−b..ma, ..].
        for a in 0..b {
            for i in locked..keep {
                let mut x = 0.0;
                for t in 0..b {
                    x += last_r[(a, t)] * y[(ma - b + t, i - locked)];
                }
                h[(keep + a, i)] = x;
                h[(i, keep + a)] = x;
            }
        }
        locked_theta.extend(sel[..new_locks].iter().map(|&i| theta[i]));
        locked += new_locks;
        c = keep;
        block_start = keep;
        restarts += 1;
    }
}

/// The locked and active Ritz pairs in one θ-descending order (a pair
/// found after others were locked may exceed them).
fn sort_descending(
    theta: Vec<f64>,
    psi: Vec<f64>,
    n: usize,
    restarts: usize,
    applies: usize,
) -> (Vec<f64>, Vec<f64>, usize, usize) {
    let k = theta.len();
    let mut idx: Vec<usize> = (0..k).collect();
    idx.sort_by(|&a, &b| theta[b].total_cmp(&theta[a]));
    if idx.iter().enumerate().all(|(i, &j)| i == j) {
        return (theta, psi, restarts, applies);
    }
    let mut out = vec![0.0; n * k];
    for (dst, &src) in idx.iter().enumerate() {
        out[dst * n..(dst + 1) * n].copy_from_slice(&psi[src * n..(src + 1) * n]);
    }
    let sorted = idx.iter().map(|&i| theta[i]).collect();
    (sorted, out, restarts, applies)
}

/// Rows of `V · Y` (V: the n x m column-major `v`, Y: m x cols) into `out`
/// (n x cols), a chunk of rows at a time. Each chunk of V is first copied
/// to a contiguous block: faer's GEMM then reads it without the stride n
/// between columns.
fn basis_times(v: &[f64], n: usize, y: MatRef<'_, f64>, mut out: MatMut<'_, f64>, par: faer::Par) {
    let m = y.nrows();
    let vm = MatRef::from_column_major_slice(v, n, m);
    let mut a = Mat::<f64>::zeros(CHUNK.min(n), m);
    let mut r0 = 0;
    while r0 < n {
        let rows = CHUNK.min(n - r0);
        let mut ar = a.as_mut().subrows_mut(0, rows);
        ar.copy_from(vm.submatrix(r0, 0, rows, m));
        matmul(
            out.rb_mut().subrows_mut(r0, rows),
            Accum::Replace,
            ar.rb(),
            y,
            1.0,
            par,
        );
        r0 += rows;
    }
}

/// Rows per chunk of [`basis_times`] and [`restart_in_place`].
const CHUNK: usize = 256;

/// Overwrites the first `keep` columns of the basis with `V[:, 0..m] · Y`
/// (Y is m x keep), a row chunk at a time: rows are independent, so a small
/// temporary suffices instead of an n x keep copy of the basis.
fn restart_in_place(v: &mut [f64], n: usize, m: usize, y: MatRef<'_, f64>, par: faer::Par) {
    let keep = y.ncols();
    let mut tmp = Mat::<f64>::zeros(CHUNK.min(n), keep);
    let mut block = Mat::<f64>::zeros(CHUNK.min(n), m);
    let mut r0 = 0;
    while r0 < n {
        let rows = CHUNK.min(n - r0);
        // The chunk's rows of every column, contiguous (see basis_times);
        // a copy anyway, since V's rows are then overwritten in place.
        let mut b = block.as_mut().subrows_mut(0, rows);
        b.copy_from(MatRef::from_column_major_slice(&v[..m * n], n, m).submatrix(r0, 0, rows, m));
        let mut t = tmp.as_mut().subrows_mut(0, rows);
        matmul(t.rb_mut(), Accum::Replace, b.rb(), y, 1.0, par);
        MatMut::from_column_major_slice_mut(&mut v[..m * n], n, m)
            .submatrix_mut(r0, 0, rows, keep)
            .copy_from(t.rb());
        r0 += rows;
    }
}

/// Projects columns `lo..hi` of the orthonormal basis `v` out of the n x b
/// block `w` (one classical Gram–Schmidt pass, `C = Vᵀ W` and `W −= V C`),
/// adding the coefficients to rows `lo..hi` of `coef`. With AVX-512 the
/// kernels of `gram` run (they read V in contiguous runs); elsewhere
/// faer's GEMM, which was faster there (the kernels' accumulators do not
/// fit in 16 AVX2 registers; two-column variants that do fit only tied
/// with faer on an AVX2-only AMD EPYC, where both reach ~60% of the FMA
/// peak).
#[allow(clippy::too_many_arguments)]
fn project_out(
    v: &[f64],
    n: usize,
    lo: usize,
    hi: usize,
    w: &mut [f64],
    b: usize,
    coef: &mut Mat<f64>,
    threads: usize,
) {
    let cols = hi - lo;
    let vb = &v[lo * n..hi * n];
    if fmaps_simd::simd_level() == fmaps_simd::SimdLevel::Avx512 {
        let mut ct = vec![0.0; b * cols];
        crate::gram::project(vb, n, w, b, &mut ct, threads);
        for j in 0..b {
            for i in 0..cols {
                coef[(lo + i, j)] += ct[j * cols + i];
            }
        }
    } else {
        let vm = MatRef::from_column_major_slice(vb, n, cols);
        let mut wm = MatMut::from_column_major_slice_mut(w, n, b);
        let mut ctm = Mat::<f64>::zeros(b, cols);
        // Transposed, `Cᵀ = Wᵀ V` and `Wᵀ −= Cᵀ Vᵀ`: the same sums as
        // `C = Vᵀ W`, `W −= V C`, but with the wide V on the right faer's
        // GEMM skips repacking it (1.4–1.7x faster for these shapes).
        let par = par_of(threads);
        matmul(
            ctm.as_mut(),
            Accum::Replace,
            wm.rb().transpose(),
            vm,
            1.0,
            par,
        );
        matmul(
            wm.rb_mut().transpose_mut(),
            Accum::Add,
            ctm.as_ref(),
            vm.transpose(),
            -1.0,
            par,
        );
        for j in 0..b {
            for i in 0..cols {
                coef[(lo + i, j)] += ctm[(j, i)];
            }
        }
    }
}

fn gather_columns(u: MatRef<'_, f64>, idx: &[usize]) -> Mat<f64> {
    Mat::from_fn(u.nrows(), idx.len(), |i, j| u[(i, idx[j])])
}

#[inline(always)]
fn norm(x: &[f64]) -> f64 {
    dot(x, x).sqrt()
}

/// Orthonormalizes columns `start..start+b` of the column-major `v` (n
/// rows) among themselves (twice-iterated modified Gram–Schmidt), writing
/// the upper-triangular R with `old = Q R`. Used for the start block.
fn orthonormalize_block(
    v: &mut [f64],
    n: usize,
    start: usize,
    b: usize,
    r: &mut Mat<f64>,
    rng: &mut SplitMix,
) {
    let pre: Vec<f64> = (0..b)
        .map(|j| norm(&v[(start + j) * n..(start + j + 1) * n]))
        .collect();
    orthonormalize_against(v, n, start, b, &pre, r, rng);
}

fmaps_simd::dispatched! {
    /// Makes columns `start..start+b` orthonormal and orthogonal to columns
    /// `0..start` (which are orthonormal), writing R (b x b) with
    /// `W = Q R` for the part of W orthogonal to the earlier columns.
    ///
    /// A column whose norm collapses below `1e-13` of `pre_norms[j]` (the norm
    /// of W before any orthogonalization) is dependent: it is replaced by a
    /// random unit vector orthogonal to everything, with a zero row in R —
    /// the Krylov space has an invariant subspace there, and the new direction
    /// continues the iteration.
    fn orthonormalize_against(v: &mut [f64], n: usize, start: usize, b: usize, pre_norms: &[f64], r: &mut Mat<f64>, rng: &mut SplitMix) -> () {
        r.fill(0.0);
        for j in 0..b {
            let cj = start + j;
            let (before, rest) = v.split_at_mut(cj * n);
            let x = &mut rest[..n];
            for _pass in 0..2 {
                for i in 0..j {
                    let q = &before[(start + i) * n..(start + i + 1) * n];
                    let a = dot(q, x);
                    r[(i, j)] += a;
                    for t in 0..n {
                        x[t] -= a * q[t];
                    }
                }
            }
            let nrm = norm(x);
            if nrm > 1e-13 * pre_norms[j] && nrm > 0.0 {
                r[(j, j)] = nrm;
                for t in x.iter_mut() {
                    *t /= nrm;
                }
                continue;
            }
            // Dependent column: a random direction orthogonal to columns 0..cj.
            loop {
                for t in x.iter_mut() {
                    *t = rng.symmetric();
                }
                for _pass in 0..2 {
                    for i in 0..cj {
                        let q = &before[i * n..(i + 1) * n];
                        let a = dot(q, x);
                        for t in 0..n {
                            x[t] -= a * q[t];
                        }
                    }
                }
                let nrm = norm(x);
                if nrm > 1e-8 {
                    for t in x.iter_mut() {
                        *t /= nrm;
                    }
                    break;
                }
            }
        }
    }
}
