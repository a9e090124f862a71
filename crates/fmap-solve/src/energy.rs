//! The functional-map energy and its exact minimizer.
//!
//! For descriptor coefficients `A` (k_A x p) on A and `B` (k_B x p) on B,
//! eigenvalues of both shapes, and pairs of descriptor multiplication
//! operators `X_q = Φ_Aᵀ M_A diag(d_q) Φ_A`, `Y_q` likewise on B:
//!
//! ```text
//! E(C) = w_descr ‖C A − B‖²                       descriptor preservation
//!      + w_lap   Σ_ij mask_ij C_ij²               Laplacian commutativity
//!      + w_dcomm Σ_q ‖C X_q − Y_q C‖²             descriptor commutativity
//! ```
//!
//! with `mask_ij = (λ_A,j − λ_B,i)²` (the commutativity of Ovsjanikov et
//! al. 2012) or the bounded resolvent mask of Ren et al. 2019. E is a
//! convex quadratic in C: its minimum solves linear normal equations, so it
//! is computed exactly (no iterative optimizer). Without the descriptor
//! commutativity term the rows of C decouple into k_B systems of size k_A.

use faer::Side;
use nalgebra::{DMatrix, DVector};

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
    pub ops: Vec<(DMatrix<f64>, DMatrix<f64>)>,
    /// Weight of descriptor preservation.
    pub w_descr: f64,
    /// Weight of Laplacian commutativity.
    pub w_lap: f64,
    /// Weight of descriptor commutativity.
    pub w_dcomm: f64,
}

impl FmapEnergy {
    fn dims(&self) -> Result<(usize, usize)> {
        let (ka, kb) = (self.descr_a.nrows(), self.descr_b.nrows());
        if self.descr_a.ncols() != self.descr_b.ncols() {
            return Err(Error::SizeMismatch {
                what: "descriptor counts of A and B",
                found: self.descr_b.ncols(),
                expected: self.descr_a.ncols(),
            });
        }
        if self.lap_mask.shape() != (kb, ka) {
            return Err(Error::SizeMismatch {
                what: "Laplacian mask rows (k_B)",
                found: self.lap_mask.nrows(),
                expected: kb,
            });
        }
        for (x, y) in &self.ops {
            if x.shape() != (ka, ka) || y.shape() != (kb, kb) {
                return Err(Error::SizeMismatch {
                    what: "multiplication operator size",
                    found: x.nrows(),
                    expected: ka,
                });
            }
        }
        Ok((ka, kb))
    }

    /// The energy of `c` (k_B x k_A).
    pub fn value(&self, c: &DMatrix<f64>) -> f64 {
        let mut e = self.w_descr * (c * &self.descr_a - &self.descr_b).norm_squared();
        e += self.w_lap * self.lap_mask.component_mul(&c.component_mul(c)).sum();
        for (x, y) in &self.ops {
            e += self.w_dcomm * (c * x - y * c).norm_squared();
        }
        e
    }

    /// The gradient of [`FmapEnergy::value`] at `c`.
    pub fn gradient(&self, c: &DMatrix<f64>) -> DMatrix<f64> {
        let mut g =
            2.0 * self.w_descr * (c * &self.descr_a - &self.descr_b) * self.descr_a.transpose();
        g += 2.0 * self.w_lap * self.lap_mask.component_mul(c);
        for (x, y) in &self.ops {
            let r = c * x - y * c;
            g += 2.0 * self.w_dcomm * (&r * x.transpose() - y.transpose() * &r);
        }
        g
    }

    /// The exact minimizer of the energy. With `w_dcomm = 0` (or no
    /// operators) each row is an independent k_A x k_A system; otherwise the
    /// normal equations in vec(C) (size k_A·k_B) are assembled from
    /// Kronecker products and solved by Cholesky.
    pub fn minimize(&self) -> Result<DMatrix<f64>> {
        let (ka, kb) = self.dims()?;
        let aat = &self.descr_a * self.descr_a.transpose();
        let bat = &self.descr_b * self.descr_a.transpose();
        if self.w_dcomm == 0.0 || self.ops.is_empty() {
            let mut c = DMatrix::zeros(kb, ka);
            for i in 0..kb {
                let mut h = self.w_descr * &aat;
                for j in 0..ka {
                    h[(j, j)] += self.w_lap * self.lap_mask[(i, j)];
                }
                let rhs = self.w_descr * bat.row(i).transpose();
                let row = solve_spd(h, rhs)?;
                c.row_mut(i).copy_from(&row.transpose());
            }
            return Ok(c);
        }
        // vec(C) is column-major: index (i, j) -> i + kb * j.
        let m = ka * kb;
        let mut h = DMatrix::<f64>::zeros(m, m);
        // w_descr (A Aᵀ ⊗ I) + w_lap diag(vec mask).
        for j in 0..ka {
            for l in 0..ka {
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
        // w_dcomm Σ_q (Xᵀ ⊗ I − I ⊗ Y)ᵀ (Xᵀ ⊗ I − I ⊗ Y), entry by entry:
        // row (i, j), column (r, l) gets
        // δ_ir (X Xᵀ)_jl + δ_jl (YᵀY)_ir − X_jl Y_ir − X_lj Y_ri.
        for (x, y) in &self.ops {
            let xxt = x * x.transpose();
            let yty = y.transpose() * y;
            for l in 0..ka {
                for r in 0..kb {
                    let col = r + kb * l;
                    for j in 0..ka {
                        let (xlj, xjl) = (x[(l, j)], x[(j, l)]);
                        for i in 0..kb {
                            let mut v = -xjl * y[(i, r)] - xlj * y[(r, i)];
                            if i == r {
                                v += xxt[(j, l)];
                            }
                            if j == l {
                                v += yty[(i, r)];
                            }
                            h[(i + kb * j, col)] += self.w_dcomm * v;
                        }
                    }
                }
            }
        }
        let rhs = DVector::from_iterator(m, (0..m).map(|t| self.w_descr * bat[(t % kb, t / kb)]));
        let x = solve_spd(h, rhs)?;
        Ok(DMatrix::from_column_slice(kb, ka, x.as_slice()))
    }
}

/// Solves H x = b for symmetric positive definite H (faer Cholesky).
fn solve_spd(h: DMatrix<f64>, b: DVector<f64>) -> Result<DVector<f64>> {
    let n = h.nrows();
    let hm = faer::MatRef::from_column_major_slice(h.as_slice(), n, n);
    let llt = hm
        .llt(Side::Lower)
        .map_err(|_| Error::NotPositiveDefinite)?;
    let mut x = b.clone();
    let xm = faer::MatMut::from_column_major_slice_mut(x.as_mut_slice(), n, 1);
    use faer::linalg::solvers::SolveCore;
    llt.solve_in_place_with_conj(faer::Conj::No, xm);
    Ok(x)
}
