//! The shift-invert operator `(L − σM)⁻¹`: a sparse Cholesky factorization
//! (faer, AMD fill-reducing ordering) shared by the native and ARPACK
//! backends.

use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::solvers::LltError;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use crate::{EigenProblem, Error, Result};

/// Which Cholesky variant faer uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum Factorization {
    /// faer's heuristic (by flop count).
    #[default]
    Auto,
    /// Column-by-column (best for very sparse factors and single vectors).
    Simplicial,
    /// Dense supernodes on BLAS-3 kernels (best for large meshes and blocks
    /// of right-hand sides).
    Supernodal,
}

/// A factorization of `L − σM` that solves `(L − σM) X = B` for blocks of
/// right-hand sides.
#[derive(Debug)]
pub struct ShiftInvert {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    n: usize,
    shift: f64,
    threads: usize,
    seconds: f64,
}

impl ShiftInvert {
    /// Factorizes `L − σM` for the shift σ = `shift` with `threads` threads
    /// (1 = sequential).
    pub fn new(
        problem: &EigenProblem<'_>,
        shift: f64,
        threads: usize,
        kind: Factorization,
    ) -> Result<Self> {
        if !shift.is_finite() {
            return Err(Error::InvalidParameter(format!(
                "shift must be finite, got {shift}"
            )));
        }
        let t0 = Instant::now();
        let n = problem.n();
        let l = problem.stiffness();
        let mass = problem.mass();
        // Lower triangle of K = L − σM, column by column. A symmetric matrix
        // stored as CSR is its own CSC, so the outer dimension is taken as
        // the column either way.
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::with_capacity(l.nnz() / 2 + n);
        let mut vals = Vec::with_capacity(l.nnz() / 2 + n);
        col_ptr.push(0usize);
        let mut col: Vec<(usize, f64)> = Vec::new();
        for (j, lane) in l.outer_iterator().enumerate() {
            col.clear();
            col.push((j, -shift * mass[j]));
            for (i, &v) in lane.iter() {
                if i >= j {
                    col.push((i, v));
                }
            }
            col.sort_unstable_by_key(|e| e.0);
            for &(i, v) in &col {
                if row_idx.len() > col_ptr[j] && *row_idx.last().unwrap() == i {
                    *vals.last_mut().unwrap() += v;
                } else {
                    row_idx.push(i);
                    vals.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        let par = par_of(threads);
        let sym_mat = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let threshold = match kind {
            Factorization::Auto => SupernodalThreshold::AUTO,
            Factorization::Simplicial => SupernodalThreshold::FORCE_SIMPLICIAL,
            Factorization::Supernodal => SupernodalThreshold::FORCE_SUPERNODAL,
        };
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: threshold,
            ..Default::default()
        };
        let symbolic =
            factorize_symbolic_cholesky(sym_mat, Side::Lower, SymmetricOrdering::Amd, params)
                .map_err(|e| Error::OutOfMemory(format!("symbolic Cholesky: {e:?}")))?;
        let mut values = Vec::new();
        values.try_reserve_exact(symbolic.len_val()).map_err(|_| {
            Error::OutOfMemory(format!("{} Cholesky factor entries", symbolic.len_val()))
        })?;
        values.resize(symbolic.len_val(), 0.0);
        let mut mem = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
        )
        .map_err(|_| Error::OutOfMemory("Cholesky workspace".into()))?;
        let mat = SparseColMatRef::new(sym_mat, &vals);
        let result = symbolic.factorize_numeric_llt::<f64>(
            &mut values,
            mat,
            Side::Lower,
            Default::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        );
        match result {
            Ok(_) => {}
            Err(LltError::NonPositivePivot { index }) => {
                return Err(Error::NotPositiveDefinite {
                    shift,
                    pivot: index,
                });
            }
        }
        Ok(Self {
            symbolic,
            values,
            n,
            shift,
            threads: threads.max(1),
            seconds: t0.elapsed().as_secs_f64(),
        })
    }

    /// The shift σ.
    pub fn shift(&self) -> f64 {
        self.shift
    }

    /// Seconds the factorization took.
    pub fn seconds(&self) -> f64 {
        self.seconds
    }

    /// Number of stored entries of the Cholesky factor.
    pub fn factor_nnz(&self) -> usize {
        self.values.len()
    }

    /// True when faer chose (or was told to use) the supernodal variant.
    pub fn is_supernodal(&self) -> bool {
        matches!(
            self.symbolic.raw(),
            faer::sparse::linalg::cholesky::SymbolicCholeskyRaw::Supernodal(_)
        )
    }

    /// Overwrites the n x `ncols` column-major block `rhs` with
    /// `(L − σM)⁻¹ rhs`. With several threads the columns are split among
    /// them, each solved sequentially: faer's parallel supernodal solve of
    /// one block was much slower than the sequential one on large meshes,
    /// while splitting the right-hand sides scales (docs/tuning.md).
    ///
    /// # Panics
    /// If `rhs.len() != n * ncols`.
    #[track_caller]
    pub fn solve_in_place(&self, rhs: &mut [f64], ncols: usize) {
        assert_eq!(
            rhs.len(),
            self.n * ncols,
            "solve_in_place: wrong block size"
        );
        let parts = self.threads.min(ncols);
        if parts <= 1 {
            self.solve_seq(rhs, ncols);
            return;
        }
        let per = ncols.div_ceil(parts);
        std::thread::scope(|s| {
            for chunk in rhs.chunks_mut(per * self.n) {
                s.spawn(move || self.solve_seq(chunk, chunk.len() / self.n));
            }
        });
    }

    fn solve_seq(&self, rhs: &mut [f64], ncols: usize) {
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(ncols, Par::Seq));
        let llt = LltRef::new(&self.symbolic, &self.values);
        let x = MatMut::from_column_major_slice_mut(rhs, self.n, ncols);
        llt.solve_in_place_with_conj(Conj::No, x, Par::Seq, MemStack::new(&mut mem));
    }
}

pub(crate) fn par_of(threads: usize) -> Par {
    if threads <= 1 {
        Par::Seq
    } else {
        Par::rayon(threads)
    }
}
