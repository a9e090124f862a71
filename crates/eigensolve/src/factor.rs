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
    /// faer's heuristic (by flop count) in [`ShiftInvert::new`]; the
    /// native eigensolver reads it as `Simplicial` (see
    /// [`NativeParams::factorization`](crate::NativeParams::factorization)).
    #[default]
    Auto,
    /// Column-by-column. Blocks of up to 8 right-hand sides are solved in
    /// one pass over the factor (the fastest solve measured, 5k-80k
    /// vertices); its factorization is slower than the supernodal one on
    /// large meshes.
    Simplicial,
    /// Dense supernodes on BLAS-3 kernels (the fastest factorization of
    /// large meshes). Its parallel kernels sum in an order that depends on
    /// the thread count: the eigenpairs then agree across thread counts to
    /// rounding (1e-12 relative), not bit for bit as with `Simplicial`.
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
        if let Some(st) = Structure::of(&self.symbolic)
            && ncols <= LANES
        {
            solve_rows(&st, &self.values, rhs, ncols);
            return;
        }
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(ncols, Par::Seq));
        let llt = LltRef::new(&self.symbolic, &self.values);
        let x = MatMut::from_column_major_slice_mut(rhs, self.n, ncols);
        llt.solve_in_place_with_conj(Conj::No, x, Par::Seq, MemStack::new(&mut mem));
    }
}

/// Right-hand sides solved together by [`solve_rows`]: one row of the
/// block is one AVX-512 register of f64.
const LANES: usize = 8;

/// The structure of a simplicial Cholesky factor L (column by column, the
/// diagonal entry first: faer's layout) and its fill-reducing permutation
/// (`fwd[i]`: the row of the original matrix that is row i of L's; `None`:
/// the identity), borrowed from faer's symbolic factorization.
struct Structure<'a> {
    col_ptr: &'a [usize],
    row_idx: &'a [usize],
    fwd: Option<&'a [usize]>,
}

impl Structure<'_> {
    /// `None` when the factorization is supernodal.
    fn of(symbolic: &SymbolicCholesky<usize>) -> Option<Structure<'_>> {
        let faer::sparse::linalg::cholesky::SymbolicCholeskyRaw::Simplicial(s) = symbolic.raw()
        else {
            return None;
        };
        Some(Structure {
            col_ptr: s.col_ptr(),
            row_idx: s.row_idx(),
            fwd: symbolic.perm().map(|p| p.arrays().0),
        })
    }

    /// Row `i` of L's in the original matrix.
    #[inline(always)]
    fn original(&self, i: usize) -> usize {
        self.fwd.map_or(i, |f| f[i])
    }
}

fmaps_simd::dispatched! {
    /// `(L Lᵀ)⁻¹` applied to the `ncols` ≤ [`LANES`] columns of `rhs` (n
    /// x ncols, column-major), all of them in one pass over L: the block
    /// is held row-major, one row of 1, 2, 4 or 8 values per vertex
    /// (unused lanes zero), so that each entry of L updates one contiguous
    /// row (faer's solve passes over L once per four columns, each entry
    /// touching four separate columns). Every value gets the same
    /// operations in the same order as in faer's simplicial solve (times
    /// the diagonal's reciprocal; products subtracted column by column; in
    /// the transposed solve the products summed from the last entry of a
    /// column to its first, then subtracted): the same bits.
    fn solve_rows(st: &Structure, values: &[f64], rhs: &mut [f64], ncols: usize) -> () {
        match ncols {
            0 => {}
            1 => solve_rows_of::<1>(st, values, rhs, ncols),
            2 => solve_rows_of::<2>(st, values, rhs, ncols),
            3 | 4 => solve_rows_of::<4>(st, values, rhs, ncols),
            _ => solve_rows_of::<LANES>(st, values, rhs, ncols),
        }
    }
}

/// [`solve_rows`] with rows of `W` ≥ `ncols` lanes.
#[inline(always)]
fn solve_rows_of<const W: usize>(st: &Structure, values: &[f64], rhs: &mut [f64], ncols: usize) {
    let n = st.col_ptr.len() - 1;
    let mut y = vec![[0.0f64; W]; n];
    for (i, row) in y.iter_mut().enumerate() {
        let src = st.original(i);
        for c in 0..ncols {
            row[c] = rhs[c * n + src];
        }
    }
    // L y' = y.
    for j in 0..n {
        let (a, b) = (st.col_ptr[j], st.col_ptr[j + 1]);
        let r = values[a].recip();
        let mut xj = y[j];
        for c in 0..W {
            xj[c] *= r;
        }
        y[j] = xj;
        for p in a + 1..b {
            let (i, l) = (st.row_idx[p], values[p]);
            let yi = &mut y[i];
            for c in 0..W {
                yi[c] -= l * xj[c];
            }
        }
    }
    // Lᵀ x = y'.
    for j in (0..n).rev() {
        let (a, b) = (st.col_ptr[j], st.col_ptr[j + 1]);
        let mut acc = [0.0f64; W];
        for p in (a + 1..b).rev() {
            let (yi, l) = (&y[st.row_idx[p]], values[p]);
            for c in 0..W {
                acc[c] += l * yi[c];
            }
        }
        let r = values[a].recip();
        let yj = &mut y[j];
        for c in 0..W {
            yj[c] = (yj[c] - acc[c]) * r;
        }
    }
    for (i, row) in y.iter().enumerate() {
        let dst = st.original(i);
        for c in 0..ncols {
            rhs[c * n + dst] = row[c];
        }
    }
}

pub(crate) fn par_of(threads: usize) -> Par {
    if threads <= 1 {
        Par::Seq
    } else {
        Par::rayon(threads)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fmaps_simd::SplitMix;

    /// The one-pass solve of up to eight right-hand sides gives faer's
    /// simplicial solve bit for bit (the same operations in the same
    /// order), at every SIMD level the CPU has, for 1..=8 columns, and
    /// solves the system (residual at rounding level).
    #[test]
    fn row_block_solve_is_faers_bit_for_bit() {
        let mesh = fmaps_shapes::torus(2.0, 0.7, 40, 17);
        let op = fmaps_laplacian::cotan_laplacian(&mesh, &Default::default());
        let problem = EigenProblem::new(op.stiffness.view(), &op.mass).unwrap();
        let f = ShiftInvert::new(&problem, -0.01, 1, Factorization::Simplicial).unwrap();
        let st = Structure::of(&f.symbolic).expect("a simplicial factor");
        let n = problem.n();
        let mut rng = SplitMix(7);
        fmaps_simd::at_every_level(|level| {
            for ncols in 1..=LANES {
                let b: Vec<f64> = (0..n * ncols).map(|_| rng.symmetric() - 0.5).collect();
                let mut ours = b.clone();
                solve_rows(&st, &f.values, &mut ours, ncols);
                let mut theirs = b.clone();
                let mut mem =
                    MemBuffer::new(f.symbolic.solve_in_place_scratch::<f64>(ncols, Par::Seq));
                LltRef::new(&f.symbolic, &f.values).solve_in_place_with_conj(
                    Conj::No,
                    MatMut::from_column_major_slice_mut(&mut theirs, n, ncols),
                    Par::Seq,
                    MemStack::new(&mut mem),
                );
                assert!(
                    ours.iter()
                        .zip(&theirs)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{level:?}, {ncols} columns: not faer's bits"
                );
                // (L − σM) x = b, column by column.
                for c in 0..ncols {
                    let x = &ours[c * n..(c + 1) * n];
                    let (mut r2, mut b2) = (0.0, 0.0);
                    for (i, row) in op.stiffness.outer_iterator().enumerate() {
                        let mut ax = 0.01 * op.mass[i] * x[i];
                        for (j, &v) in row.iter() {
                            ax += v * x[j];
                        }
                        r2 += (ax - b[c * n + i]).powi(2);
                        b2 += b[c * n + i].powi(2);
                    }
                    assert!(
                        r2.sqrt() <= 1e-10 * b2.sqrt(),
                        "residual {}",
                        r2.sqrt() / b2.sqrt()
                    );
                }
            }
        });
    }
}
