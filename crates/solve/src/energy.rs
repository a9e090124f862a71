//! The functional-map energy and its exact minimizer.
//!
//! For descriptor coefficients `A` (k_A x p) on A and `B` (k_B x p) on B,
//! eigenvalues of both shapes, pairs of descriptor multiplication operators
//! `X_q = Φ_Aᵀ M_A diag(d_q) Φ_A`, `Y_q` likewise on B, and pairs of
//! orientation operators `(U_q, V_q)` (see [`orientation_operators`](crate::orientation_operators)):
//!
//! ```text
//! E(C) = w_descr  ‖C A − B‖²                      descriptor preservation
//!      + w_lap    Σ_ij mask_ij C_ij²              Laplacian commutativity
//!      + w_dcomm  Σ_q ‖C X_q − Y_q C‖²            descriptor commutativity
//!      + w_orient Σ_q ‖C U_q − V_q C‖²            orientation preservation
//! ```
//!
//! with `mask_ij = (λ_A,j − λ_B,i)²` (the commutativity of Ovsjanikov et
//! al. 2012) or the bounded resolvent mask of Ren et al. 2019. E is a
//! convex quadratic in C: its minimum solves linear normal equations, so it
//! is computed exactly (no iterative optimizer). Without operator terms the
//! rows of C decouple into k_B systems of size k_A. With them, the normal
//! equations in vec(C) are assembled from Kronecker structure: the
//! `Σ_q X_q X_qᵀ ⊗ I` and `I ⊗ Σ_q Y_qᵀ Y_q` parts are two small GEMMs and
//! all the cross terms `Σ_q X_q ⊗ Y_q` one GEMM of the stacked operators,
//! then one dense Cholesky factorization.
//!
//! Optionally the first column of C (the image of the constant function)
//! is held fixed, as pyFM does: C maps constants to constants, with the
//! scale `sqrt(area_B / area_A)` and the sign of the two first
//! eigenvectors. The minimum is then over the remaining columns.

use faer::linalg::matmul::matmul;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatRef, Par};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::{Error, Result};

/// The Laplacian commutativity weights `mask_ij` (k_B x k_A).
pub fn laplacian_mask(evals_a: &DVector<f64>, evals_b: &DVector<f64>) -> DMatrix<f64> {
    DMatrix::from_fn(evals_b.len(), evals_a.len(), |i, j| {
        (evals_a[j] - evals_b[i]).powi(2)
    })
}

/// The resolvent mask of Ren et al. (SGP 2019), bounded in k: with both
/// spectra divided by their common largest value and raised to `gamma`,
/// `mask_ij = |1/(λ_j^γ − i) − 1/(μ_i^γ − i)|²` (i the imaginary unit).
pub fn resolvent_mask(evals_a: &DVector<f64>, evals_b: &DVector<f64>, gamma: f64) -> DMatrix<f64> {
    let scale = evals_a
        .iter()
        .chain(evals_b.iter())
        .fold(0.0f64, |m, x| m.max(x.abs()));
    let s = if scale > 0.0 { scale } else { 1.0 };
    // 1/(x − i) = (x + i)/(x² + 1).
    let res = |x: f64| {
        let xg = (x.abs() / s).powf(gamma);
        let d = xg * xg + 1.0;
        (xg / d, 1.0 / d)
    };
    DMatrix::from_fn(evals_b.len(), evals_a.len(), |i, j| {
        let (ra, ia) = res(evals_a[j]);
        let (rb, ib) = res(evals_b[i]);
        (ra - rb).powi(2) + (ia - ib).powi(2)
    })
}

/// The descriptor multiplication operator `Φᵀ M diag(d) Φ` (k x k) of a
/// vertex function d, for a basis with eigenvectors `phi` (n x k) and mass.
pub fn multiplication_operator(phi: &DMatrix<f64>, mass: &DVector<f64>, d: &[f64]) -> DMatrix<f64> {
    let mut w = phi.clone();
    for (i, mut row) in w.row_iter_mut().enumerate() {
        row *= mass[i] * d[i];
    }
    phi.tr_mul(&w)
}

/// How [`FmapEnergy::minimize_with_report`] found the minimum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum SolveMethod {
    /// No operator terms: one small system per row of C.
    Rows,
    /// Conjugate gradients in f64 preconditioned by an f32 Cholesky factor
    /// of the normal matrix.
    Iterative,
    /// Dense f64 Cholesky of the normal matrix (the fallback when the
    /// iterative method does not converge).
    Dense,
}

/// How the minimum of an energy was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveReport {
    /// The method.
    pub method: SolveMethod,
    /// Conjugate-gradient iterations (0 for the direct methods).
    pub iterations: usize,
    /// For the iterative method, the final relative residual
    /// `‖b − H x‖ / ‖b‖` of the normal equations over the free entries of
    /// C (recomputed from x).
    pub residual: Option<f64>,
}

impl SolveReport {
    fn direct(method: SolveMethod) -> SolveReport {
        SolveReport {
            method,
            iterations: 0,
            residual: None,
        }
    }
}

/// Pairs of operators (on A: k_A x k_A, on B: k_B x k_B).
pub type OperatorPairs = Vec<(DMatrix<f64>, DMatrix<f64>)>;

/// One value per term of the energy (the terms' values at a map, their
/// weights, or their reference scales), by name.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PerTerm {
    /// Descriptor preservation `‖C A − B‖²`.
    pub descr: f64,
    /// Laplacian commutativity (masked).
    pub lap: f64,
    /// Descriptor commutativity (multiplication operators).
    pub dcomm: f64,
    /// Orientation preservation (orientation operators).
    pub orient: f64,
}

impl PerTerm {
    /// `[descr, lap, dcomm, orient]`.
    pub fn as_array(&self) -> [f64; 4] {
        [self.descr, self.lap, self.dcomm, self.orient]
    }
}

/// The terms and weights of the energy (see the module docs).
#[derive(Debug, Clone)]
pub struct FmapEnergy {
    /// Descriptor coefficients on A (k_A x p).
    pub descr_a: DMatrix<f64>,
    /// Descriptor coefficients on B (k_B x p).
    pub descr_b: DMatrix<f64>,
    /// Laplacian commutativity weights (k_B x k_A).
    pub lap_mask: DMatrix<f64>,
    /// Pairs of multiplication operators (k_A x k_A, k_B x k_B).
    pub ops: OperatorPairs,
    /// Pairs of orientation operators (k_A x k_A, k_B x k_B).
    pub orient_ops: OperatorPairs,
    /// Weight of descriptor preservation.
    pub w_descr: f64,
    /// Weight of Laplacian commutativity.
    pub w_lap: f64,
    /// Weight of descriptor commutativity.
    pub w_dcomm: f64,
    /// Weight of orientation preservation.
    pub w_orient: f64,
    /// When set, the first column of C (length k_B) is fixed to this value
    /// and only the other columns are optimized.
    pub fixed_first_column: Option<DVector<f64>>,
}

impl FmapEnergy {
    /// Descriptor preservation alone (weight 1), with the given Laplacian
    /// mask at weight 0 and no operators; set the other fields as needed.
    pub fn new(descr_a: DMatrix<f64>, descr_b: DMatrix<f64>, lap_mask: DMatrix<f64>) -> Self {
        FmapEnergy {
            descr_a,
            descr_b,
            lap_mask,
            ops: Vec::new(),
            orient_ops: Vec::new(),
            w_descr: 1.0,
            w_lap: 0.0,
            w_dcomm: 0.0,
            w_orient: 0.0,
            fixed_first_column: None,
        }
    }

    /// (k_A, k_B) after checking every size.
    pub fn dims(&self) -> Result<(usize, usize)> {
        let (ka, kb) = (self.descr_a.nrows(), self.descr_b.nrows());
        if self.descr_a.ncols() != self.descr_b.ncols() {
            return Err(Error::SizeMismatch {
                what: "descriptor counts of A and B",
                found: self.descr_b.ncols(),
                expected: self.descr_a.ncols(),
            });
        }
        if self.lap_mask.nrows() != kb {
            return Err(Error::SizeMismatch {
                what: "Laplacian mask rows (k_B)",
                found: self.lap_mask.nrows(),
                expected: kb,
            });
        }
        if self.lap_mask.ncols() != ka {
            return Err(Error::SizeMismatch {
                what: "Laplacian mask columns (k_A)",
                found: self.lap_mask.ncols(),
                expected: ka,
            });
        }
        for (x, y) in self.ops.iter().chain(&self.orient_ops) {
            if x.shape() != (ka, ka) {
                return Err(Error::SizeMismatch {
                    what: "operator on A (k_A x k_A)",
                    found: x.nrows(),
                    expected: ka,
                });
            }
            if y.shape() != (kb, kb) {
                return Err(Error::SizeMismatch {
                    what: "operator on B (k_B x k_B)",
                    found: y.nrows(),
                    expected: kb,
                });
            }
        }
        if let Some(c0) = &self.fixed_first_column
            && c0.len() != kb
        {
            return Err(Error::SizeMismatch {
                what: "fixed first column length (k_B)",
                found: c0.len(),
                expected: kb,
            });
        }
        Ok((ka, kb))
    }

    pub(crate) fn op_terms(&self) -> impl Iterator<Item = (f64, &(DMatrix<f64>, DMatrix<f64>))> {
        let d = self.ops.iter().map(|p| (self.w_dcomm, p));
        let o = self.orient_ops.iter().map(|p| (self.w_orient, p));
        d.chain(o).filter(|(w, _)| *w != 0.0)
    }

    /// The energy of `c` (k_B x k_A).
    pub fn value(&self, c: &DMatrix<f64>) -> f64 {
        self.weighted_sum(&self.terms(c))
    }

    /// The four weights.
    pub fn weights(&self) -> PerTerm {
        PerTerm {
            descr: self.w_descr,
            lap: self.w_lap,
            dcomm: self.w_dcomm,
            orient: self.w_orient,
        }
    }

    /// `Σ w_t terms_t` over the terms with nonzero weight: the energy,
    /// given the unweighted [`terms`](Self::terms) of a map.
    pub fn weighted_sum(&self, terms: &PerTerm) -> f64 {
        self.weights()
            .as_array()
            .iter()
            .zip(terms.as_array())
            .filter(|(w, _)| **w != 0.0)
            .map(|(w, t)| w * t)
            .sum()
    }

    /// The values of the four terms at `c`, unweighted. The operator terms
    /// are two small GEMMs per pair, pairs in parallel, summed in a fixed
    /// order.
    pub fn terms(&self, c: &DMatrix<f64>) -> PerTerm {
        let (kb, ka) = c.shape();
        let cf = MatRef::from_column_major_slice(c.as_slice(), kb, ka);
        let op_sum = |ops: &OperatorPairs| -> f64 {
            let norms: Vec<f64> = ops
                .par_iter()
                .map_init(
                    || Mat::<f64>::zeros(kb, ka),
                    |r, (x, y)| {
                        let x = MatRef::from_column_major_slice(x.as_slice(), x.nrows(), x.ncols());
                        let y = MatRef::from_column_major_slice(y.as_slice(), y.nrows(), y.ncols());
                        matmul(r.as_mut(), Accum::Replace, cf, x, 1.0, Par::Seq);
                        matmul(r.as_mut(), Accum::Add, y, cf, -1.0, Par::Seq);
                        r.squared_norm_l2()
                    },
                )
                .collect();
            norms.iter().sum()
        };
        PerTerm {
            descr: (c * &self.descr_a - &self.descr_b).norm_squared(),
            lap: self.lap_mask.component_mul(&c.component_mul(c)).sum(),
            dcomm: op_sum(&self.ops),
            orient: op_sum(&self.orient_ops),
        }
    }

    /// The gradient of [`FmapEnergy::value`] at `c` (all entries, also the
    /// first column when it is fixed).
    pub fn gradient(&self, c: &DMatrix<f64>) -> DMatrix<f64> {
        let mut g =
            2.0 * self.w_descr * (c * &self.descr_a - &self.descr_b) * self.descr_a.transpose();
        g += 2.0 * self.w_lap * self.lap_mask.component_mul(c);
        for (w, (x, y)) in self.op_terms() {
            let r = c * x - y * c;
            g += 2.0 * w * (&r * x.transpose() - y.transpose() * &r);
        }
        g
    }

    /// The exact minimizer of the energy (k_B x k_A). Without operator
    /// terms each row is an independent k_A x k_A system; otherwise the
    /// normal equations in vec(C) (size k_A·k_B) are solved by conjugate
    /// gradients in f64, preconditioned by a Cholesky factor of the normal
    /// matrix computed in f32, to a residual at rounding level (1e-14 of
    /// the right-hand side), and if that fails (a singular or very badly
    /// conditioned problem) as [`minimize_dense`](Self::minimize_dense)
    /// does.
    pub fn minimize(&self) -> Result<DMatrix<f64>> {
        self.minimize_with_report().map(|(c, _)| c)
    }

    /// [`minimize`](Self::minimize), with how the minimum was found.
    pub fn minimize_with_report(&self) -> Result<(DMatrix<f64>, SolveReport)> {
        let (ka, kb) = self.dims()?;
        let j0 = usize::from(self.fixed_first_column.is_some());
        if self.op_terms().next().is_none() || ka == j0 {
            let c = self.minimize_dense()?;
            return Ok((c, SolveReport::direct(SolveMethod::Rows)));
        }
        let normal = crate::normal::Normal::new(self, ka, kb, j0);
        let b = normal.rhs(self, self.fixed_first_column.as_ref().map(|c| c.as_slice()));
        if let Some((x, iterations, residual)) = normal.solve(&b) {
            let mut out = DMatrix::zeros(kb, ka);
            if let Some(c0) = &self.fixed_first_column {
                out.column_mut(0).copy_from(c0);
            }
            out.as_mut_slice()[j0 * kb..].copy_from_slice(&x);
            let report = SolveReport {
                method: SolveMethod::Iterative,
                iterations,
                residual: Some(residual),
            };
            return Ok((out, report));
        }
        let c = self.minimize_dense()?;
        Ok((c, SolveReport::direct(SolveMethod::Dense)))
    }

    /// The exact minimizer by a direct solve in f64: without operator
    /// terms each row is an independent k_A x k_A system; otherwise the
    /// normal equations in vec(C) (size k_A·k_B) are assembled with GEMMs
    /// and solved by Cholesky (with a growing ridge on singular problems,
    /// see the crate docs). Slower than [`minimize`](Self::minimize) with
    /// operator terms (twice the factorization time and memory); the
    /// reference it is tested against.
    pub fn minimize_dense(&self) -> Result<DMatrix<f64>> {
        let (ka, kb) = self.dims()?;
        let aat = &self.descr_a * self.descr_a.transpose();
        let bat = &self.descr_b * self.descr_a.transpose();
        let j0 = usize::from(self.fixed_first_column.is_some());
        if j0 == 1 && ka == 0 {
            return Err(Error::SizeMismatch {
                what: "columns of C with a fixed first column",
                found: 0,
                expected: 1,
            });
        }
        if self.op_terms().next().is_none() {
            return self.minimize_rows(ka, kb, &aat, &bat);
        }
        // vec(C) is column-major: index (i, j) -> i + kb * j. Only the
        // lower triangle of H is formed (the factorization reads no more).
        let m = ka * kb;
        let build = |h: &mut Mat<f64>| self.fill_normal_matrix(h, &aat, ka, kb);
        let mut h = Mat::<f64>::zeros(m, m);
        build(&mut h);
        let mut rhs: Vec<f64> = (0..m)
            .map(|t| self.w_descr * bat[(t % kb, t / kb)])
            .collect();
        let free = j0 * kb;
        if let Some(c0) = &self.fixed_first_column {
            for t in free..m {
                let s: f64 = (0..kb).map(|i| h[(t, i)] * c0[i]).sum();
                rhs[t] -= s;
            }
        }
        let x = solve_spd(&mut h, free, &rhs[free..], build)?;
        let mut c = DMatrix::zeros(kb, ka);
        if let Some(c0) = &self.fixed_first_column {
            c.column_mut(0).copy_from(c0);
        }
        c.as_mut_slice()[free..].copy_from_slice(&x);
        Ok(c)
    }

    /// The lower triangle of the normal matrix H (k_A·k_B square, vec(C)
    /// column-major) into `h`, with `aat = A Aᵀ`; the strict upper
    /// triangle is left zero.
    pub(crate) fn fill_normal_matrix(
        &self,
        h: &mut Mat<f64>,
        aat: &DMatrix<f64>,
        ka: usize,
        kb: usize,
    ) {
        h.fill(0.0);
        // w_descr (A Aᵀ ⊗ I) + w_lap diag(vec mask).
        for l in 0..ka {
            for j in l..ka {
                let v = self.w_descr * aat[(j, l)];
                for i in 0..kb {
                    h[(i + kb * j, i + kb * l)] += v;
                }
            }
        }
        for j in 0..ka {
            for i in 0..kb {
                h[(i + kb * j, i + kb * j)] += self.w_lap * self.lap_mask[(i, j)];
            }
        }
        self.add_operator_hessian(h, ka, kb);
    }

    fn minimize_rows(
        &self,
        ka: usize,
        kb: usize,
        aat: &DMatrix<f64>,
        bat: &DMatrix<f64>,
    ) -> Result<DMatrix<f64>> {
        let j0 = usize::from(self.fixed_first_column.is_some());
        let nf = ka - j0;
        let mut c = DMatrix::zeros(kb, ka);
        for i in 0..kb {
            let build = |h: &mut Mat<f64>| {
                *h = Mat::<f64>::from_fn(nf, nf, |r, s| self.w_descr * aat[(r + j0, s + j0)]);
                for j in 0..nf {
                    h[(j, j)] += self.w_lap * self.lap_mask[(i, j + j0)];
                }
            };
            let mut h = Mat::<f64>::zeros(nf, nf);
            build(&mut h);
            let mut rhs: Vec<f64> = (0..nf).map(|j| self.w_descr * bat[(i, j + j0)]).collect();
            if let Some(c0) = &self.fixed_first_column {
                c[(i, 0)] = c0[i];
                for (j, r) in rhs.iter_mut().enumerate() {
                    *r -= self.w_descr * aat[(j + j0, 0)] * c0[i];
                }
            }
            let row = solve_spd(&mut h, 0, &rhs, build)?;
            for (j, v) in row.into_iter().enumerate() {
                c[(i, j + j0)] = v;
            }
        }
        Ok(c)
    }

    /// Adds `Σ_q w_q (Xᵀ ⊗ I − I ⊗ Y)ᵀ (Xᵀ ⊗ I − I ⊗ Y)` over all operator
    /// terms: entry (row (i, j), column (r, l)) is
    /// `δ_ir (X Xᵀ)_jl + δ_jl (YᵀY)_ir − X_jl Y_ir − X_lj Y_ri`.
    fn add_operator_hessian(&self, h: &mut Mat<f64>, ka: usize, kb: usize) {
        let terms: Vec<_> = self.op_terms().collect();
        let p = terms.len();
        // Stacked, weight-scaled copies: xs = [√w X_1 … √w X_p] (ka x ka·p),
        // yts = [√w Y_1ᵀ … √w Y_pᵀ] (kb x kb·p), ys = [√w Y_1 … √w Y_p].
        let mut xs = vec![0.0; ka * ka * p];
        let mut ys = vec![0.0; kb * kb * p];
        let mut yts = vec![0.0; kb * kb * p];
        for (q, (w, (x, y))) in terms.iter().enumerate() {
            let s = w.sqrt();
            for l in 0..ka {
                for j in 0..ka {
                    xs[q * ka * ka + l * ka + j] = s * x[(j, l)];
                }
            }
            for r in 0..kb {
                for i in 0..kb {
                    ys[q * kb * kb + r * kb + i] = s * y[(i, r)];
                    yts[q * kb * kb + i * kb + r] = s * y[(i, r)];
                }
            }
        }
        let xs_h = MatRef::from_column_major_slice(&xs, ka, ka * p);
        let yts_h = MatRef::from_column_major_slice(&yts, kb, kb * p);
        let par = Par::rayon(0);
        let mut xxt = Mat::<f64>::zeros(ka, ka);
        matmul(
            xxt.as_mut(),
            Accum::Replace,
            xs_h,
            xs_h.transpose(),
            1.0,
            par,
        );
        let mut yty = Mat::<f64>::zeros(kb, kb);
        matmul(
            yty.as_mut(),
            Accum::Replace,
            yts_h,
            yts_h.transpose(),
            1.0,
            par,
        );
        // R[(j, l), (i, r)] = Σ_q w_q X_q[j, l] Y_q[i, r]: the stacked
        // operators viewed as (ka² x p) and (kb² x p) column-major matrices.
        let xv = MatRef::from_column_major_slice(&xs, ka * ka, p);
        let yv = MatRef::from_column_major_slice(&ys, kb * kb, p);
        // Stored transposed, rt[(i, r), (j, l)], so the loops below read
        // along columns.
        let mut rt = Mat::<f64>::zeros(kb * kb, ka * ka);
        matmul(rt.as_mut(), Accum::Replace, yv, xv.transpose(), 1.0, par);
        // Columns are independent: add them to H in parallel, rows on and
        // below the diagonal only.
        h.par_col_iter_mut().enumerate().for_each(|(col, mut out)| {
            let (r, l) = (col % kb, col / kb);
            for j in l..ka {
                let (jl, lj) = (j + ka * l, l + ka * j);
                let (c_jl, c_lj) = (rt.col_as_slice(jl), rt.col_as_slice(lj));
                let i0 = if j == l { r } else { 0 };
                for i in i0..kb {
                    out[i + kb * j] -= c_jl[i + kb * r] + c_lj[r + kb * i];
                }
                out[r + kb * j] += xxt[(j, l)];
                if j == l {
                    for i in i0..kb {
                        out[i + kb * j] += yty[(i, r)];
                    }
                }
            }
        });
    }
}

/// Solves `H[s.., s..] x = b` for symmetric positive semidefinite H, of
/// which only the lower triangle is read; factors in place (faer's blocked
/// Cholesky, no copy), so `rebuild` must restore H for a retry.
///
/// Symmetric shapes (repeated eigenvalues with descriptors invariant
/// under the symmetry) make the energy flat along some directions: every
/// point of that flat set is an exact minimum. A ridge of 1e-13 of the
/// largest diagonal entry picks one (the nearly minimum-norm one) at no
/// measurable cost in energy; if the factorization still fails the ridge
/// grows by 100x, up to 1e-5. An all-zero H is an error.
fn solve_spd(
    h: &mut Mat<f64>,
    s: usize,
    b: &[f64],
    rebuild: impl Fn(&mut Mat<f64>),
) -> Result<Vec<f64>> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::cholesky::llt::factor;
    use faer::linalg::triangular_solve;
    let n = h.nrows() - s;
    if n == 0 {
        return Ok(Vec::new());
    }
    let max_diag = (s..s + n).fold(0.0f64, |m, i| m.max(h[(i, i)]));
    if !(max_diag > 0.0 && max_diag.is_finite()) {
        return Err(Error::NotPositiveDefinite);
    }
    let par = faer::get_global_parallelism();
    let mut mem = MemBuffer::new(factor::cholesky_in_place_scratch::<f64>(
        n,
        par,
        Default::default(),
    ));
    let mut ridge = 1e-13;
    let mut first = true;
    while ridge <= 1e-5 {
        if !first {
            rebuild(h);
        }
        first = false;
        let mut a = h.as_mut().submatrix_mut(s, s, n, n);
        for i in 0..n {
            a[(i, i)] += ridge * max_diag;
        }
        let ok = factor::cholesky_in_place(
            a.rb_mut(),
            Default::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .is_ok();
        if ok {
            // L Lᵀ x = b.
            let mut x = b.to_vec();
            let mut xm = faer::MatMut::from_column_major_slice_mut(&mut x, n, 1);
            let l = a.rb();
            triangular_solve::solve_lower_triangular_in_place(l, xm.rb_mut(), par);
            triangular_solve::solve_upper_triangular_in_place(l.transpose(), xm.rb_mut(), par);
            if x.iter().all(|v| v.is_finite()) {
                return Ok(x);
            }
        }
        ridge *= 100.0;
    }
    Err(Error::NotPositiveDefinite)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A PSD matrix made slightly indefinite by rounding-level noise: the
    /// first ridge (1e-13 of the largest diagonal) cannot factor it, so
    /// the in-place factorization fails, H is rebuilt and the next ridge
    /// (1e-11) solves the regularized system; the lower triangle alone is
    /// read (the upper one holds garbage).
    #[test]
    fn solve_spd_retries_on_a_rebuilt_matrix() {
        let n = 6;
        let v: Vec<f64> = (0..n).map(|i| 1.0 + i as f64).collect();
        let build = |h: &mut Mat<f64>| {
            for j in 0..n {
                for i in 0..n {
                    h[(i, j)] = if i >= j {
                        v[i] * v[j] - if i == j { 1e-12 * 36.0 } else { 0.0 }
                    } else {
                        f64::NAN
                    };
                }
            }
        };
        let mut h = Mat::<f64>::zeros(n, n);
        build(&mut h);
        let rebuilt = std::cell::Cell::new(0);
        let b: Vec<f64> = (0..n).map(|i| (i as f64).sin()).collect();
        let x = solve_spd(&mut h, 0, &b, |h| {
            rebuilt.set(rebuilt.get() + 1);
            build(h)
        })
        .unwrap();
        assert_eq!(rebuilt.get(), 1);
        // (v vᵀ − 1e-12·36 I + 1e-11·36 I) x = b, to backward-stable
        // accuracy (the system has condition ~1e11).
        let vx: f64 = v.iter().zip(&x).map(|(a, b)| a * b).sum();
        let x_max = x.iter().fold(0.0f64, |m, y| m.max(y.abs()));
        for i in 0..n {
            let hx = v[i] * vx + (1e-11 - 1e-12) * 36.0 * x[i];
            assert!(
                (hx - b[i]).abs() <= 1e-12 * (91.0 * x_max + 1.0),
                "{hx} vs {}",
                b[i]
            );
        }
        // A block below the fixed part: only H[s.., s..] is factored.
        let mut g = Mat::<f64>::identity(4, 4);
        g[(0, 0)] = f64::NAN;
        let y = solve_spd(&mut g, 1, &[1.0, 2.0, 3.0], |_| unreachable!()).unwrap();
        for (a, e) in y.iter().zip([1.0, 2.0, 3.0]) {
            assert!((a - e).abs() < 1e-9);
        }
    }
}
