//! The ARPACK backend (cargo feature `arpack`): implicitly restarted
//! Lanczos, `dsaupd`/`dseupd` in mode 3 (generalized shift-invert,
//! `OP = (L − σM)⁻¹M`, `B = M`), the way SciPy's `eigsh(L, k, M, sigma)`
//! calls it, on the same faer factorization as the native backend.

use std::sync::Mutex;
use std::time::Instant;

use arpack_ng_sys::{dsaupd_c, dseupd_c};

/// ARPACK's integer (`a_int`, a C `int` in the Debian build).
#[allow(non_camel_case_types)]
type a_int = std::os::raw::c_int;
use nalgebra::{DMatrix, DVector};

use crate::factor::{Factorization, ShiftInvert};
use crate::native::default_shift;
use crate::{EigenProblem, EigenSolver, Error, Result, SolveStats, SpectralBasis};
use fmaps_simd::SplitMix;

/// ARPACK keeps state in Fortran common blocks (timers, debug levels):
/// calls from several threads at once are not safe, so they are serialized.
static ARPACK_LOCK: Mutex<()> = Mutex::new(());

/// Options of the ARPACK backend.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct ArpackParams {
    /// The shift σ; `None` as in [`crate::NativeParams::shift`].
    pub shift: Option<f64>,
    /// ARPACK's relative tolerance on Ritz values; 0 means machine
    /// precision (ARPACK's and SciPy's default).
    pub tol: f64,
    /// Number of Lanczos vectors; `None` is SciPy's `max(2k + 1, 20)`.
    pub ncv: Option<usize>,
    /// Maximum number of implicit restarts.
    pub max_iterations: usize,
    /// Seed of the start vector (ARPACK's own random start is not
    /// reproducible across calls in one process).
    pub seed: u64,
}

impl Default for ArpackParams {
    fn default() -> Self {
        Self {
            shift: None,
            tol: 0.0,
            ncv: None,
            max_iterations: 1000,
            seed: 0x5eed_f00d,
        }
    }
}

/// The ARPACK eigensolver.
#[derive(Debug, Clone, Default)]
pub struct ArpackSolver {
    /// Its options.
    pub params: ArpackParams,
}

impl EigenSolver for ArpackSolver {
    fn name(&self) -> &'static str {
        "arpack"
    }

    fn solve(&self, problem: &EigenProblem<'_>, k: usize) -> Result<SpectralBasis> {
        problem.check_k(k)?;
        let p = &self.params;
        let n = problem.n();
        let shift = p.shift.unwrap_or_else(|| default_shift(problem.mass()));
        let ncv = p.ncv.unwrap_or((2 * k + 1).max(20)).min(n);
        if ncv <= k {
            return Err(Error::InvalidParameter(format!(
                "ARPACK needs k < ncv <= n; with n = {n} at most k = {} eigenpairs",
                n - 1
            )));
        }
        let to_int = |x: usize| {
            a_int::try_from(x).map_err(|_| {
                Error::InvalidParameter(format!("{x} does not fit ARPACK's integer type"))
            })
        };
        let (n_i, k_i, ncv_i) = (to_int(n)?, to_int(k)?, to_int(ncv)?);
        let lworkl = ncv * (ncv + 8);
        let lworkl_i = to_int(lworkl)?;
        let factor = ShiftInvert::new(problem, shift, 1, Factorization::Auto)?;
        let mass = problem.mass();

        let _guard = ARPACK_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let t0 = Instant::now();
        let mut rng = SplitMix(p.seed);
        let mut resid: Vec<f64> = (0..n).map(|_| rng.symmetric()).collect();
        let mut v = vec![0.0; n * ncv];
        let mut workd = vec![0.0; 3 * n];
        let mut workl = vec![0.0; lworkl];
        let mut iparam: [a_int; 11] = [0; 11];
        let mut ipntr: [a_int; 14] = [0; 14];
        iparam[0] = 1; // exact shifts
        iparam[2] = to_int(p.max_iterations)?;
        iparam[6] = 3; // shift-invert mode
        let mut ido: a_int = 0;
        let mut info: a_int = 1; // use `resid` as the start vector
        let bmat = c"G";
        let which = c"LM";
        let mut applies = 0usize;
        loop {
            // SAFETY: every buffer has the length ARPACK's documentation
            // requires for (n, nev = k, ncv, lworkl), and lives across calls.
            unsafe {
                dsaupd_c(
                    &mut ido,
                    bmat.as_ptr(),
                    n_i,
                    which.as_ptr(),
                    k_i,
                    p.tol,
                    resid.as_mut_ptr(),
                    ncv_i,
                    v.as_mut_ptr(),
                    n_i,
                    iparam.as_mut_ptr(),
                    ipntr.as_mut_ptr(),
                    workd.as_mut_ptr(),
                    workl.as_mut_ptr(),
                    lworkl_i,
                    &mut info,
                );
            }
            let x0 = ipntr[0] as usize - 1;
            let y0 = ipntr[1] as usize - 1;
            match ido {
                -1 => {
                    // y = (L − σM)⁻¹ M x
                    for i in 0..n {
                        workd[y0 + i] = mass[i] * workd[x0 + i];
                    }
                    factor.solve_in_place(&mut workd[y0..y0 + n], 1);
                    applies += 1;
                }
                1 => {
                    // y = (L − σM)⁻¹ (M x), with M x already at ipntr[2].
                    let b0 = ipntr[2] as usize - 1;
                    workd.copy_within(b0..b0 + n, y0);
                    factor.solve_in_place(&mut workd[y0..y0 + n], 1);
                    applies += 1;
                }
                2 => {
                    for i in 0..n {
                        workd[y0 + i] = mass[i] * workd[x0 + i];
                    }
                }
                _ => break,
            }
        }
        let restarts = iparam[2].max(0) as usize;
        if info == 1 {
            return Err(Error::NoConvergence {
                converged: iparam[4].max(0) as usize,
                wanted: k,
                restarts,
                operator_applications: applies,
            });
        }
        if info != 0 {
            return Err(Error::Backend {
                backend: "arpack",
                message: format!("dsaupd info = {info}"),
            });
        }
        let select: Vec<a_int> = vec![0; ncv];
        let mut d = vec![0.0; k];
        let mut z = vec![0.0; n * k];
        let mut info2: a_int = 0;
        // SAFETY: as above; `z` is n x k, `d` has k entries.
        unsafe {
            dseupd_c(
                1,
                c"A".as_ptr(),
                select.as_ptr(),
                d.as_mut_ptr(),
                z.as_mut_ptr(),
                n_i,
                shift,
                bmat.as_ptr(),
                n_i,
                which.as_ptr(),
                k_i,
                p.tol,
                resid.as_mut_ptr(),
                ncv_i,
                v.as_mut_ptr(),
                n_i,
                iparam.as_mut_ptr(),
                ipntr.as_mut_ptr(),
                workd.as_mut_ptr(),
                workl.as_mut_ptr(),
                lworkl_i,
                &mut info2,
            );
        }
        if info2 != 0 {
            return Err(Error::Backend {
                backend: "arpack",
                message: format!("dseupd info = {info2}"),
            });
        }
        drop(_guard);
        let mut order: Vec<usize> = (0..k).collect();
        order.sort_by(|&a, &b| d[a].total_cmp(&d[b]));
        let eigenvalues = DVector::from_iterator(k, order.iter().map(|&i| d[i]));
        let eigenvectors = DMatrix::from_fn(n, k, |r, c| z[order[c] * n + r]);
        let stats = SolveStats {
            backend: "arpack",
            shift,
            restarts,
            operator_applications: applies,
            factorization_seconds: factor.seconds(),
            iteration_seconds: t0.elapsed().as_secs_f64(),
            threads: 1,
        };
        SpectralBasis::from_eigenpairs(problem, eigenvalues, eigenvectors, stats)
    }
}
