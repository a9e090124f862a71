//! The regularised functional-map layer of deep functional maps (as in
//! DUO-FMNet, Donati et al. CVPR 2022, and ULRSSM, Cao et al. SIGGRAPH
//! 2023), differentiable.
//!
//! With the features of shapes A and B projected on their bases
//! ([`Spectrum::project`](crate::layers::Spectrum::project)),
//! `A = Φ_Aᵀ M_A F_A` and `B = Φ_Bᵀ M_B F_B` (k x p each), the map `C`
//! (k_B x k_A, A's coefficients to B's) minimises
//!
//! `‖C A − B‖² + λ Σ_ij mask_ij C_ij²`
//!
//! with the resolvent mask of Ren et al. (SGP 2019,
//! [`fmaps_solve::resolvent_mask`], γ = 0.5 by default). The problem
//! separates by rows: row i of C solves the k_A x k_A system
//! `c_i (A Aᵀ + λ diag(mask_i)) = b_i Aᵀ` (`b_i` row i of B), all rows
//! independently.

use faer::linalg::solvers::{Llt, Solve};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::gemm::Op::{N, T};
use crate::gemm::{mul, mul_add};
use crate::{Error, Result};

/// What the forward pass keeps for the backward pass: the factors of the
/// rows' systems and C.
pub struct FmapTape {
    factors: Vec<Llt<f64>>,
    c: DMatrix<f64>,
}

impl std::fmt::Debug for FmapTape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "FmapTape({} factors)", self.factors.len())
    }
}

/// `S⁻¹ v` from the factor of S.
fn solve(f: &Llt<f64>, v: impl ExactSizeIterator<Item = f64>) -> Vec<f64> {
    let n = v.len();
    let mut x = faer::Mat::<f64>::zeros(n, 1);
    for (i, value) in v.enumerate() {
        x[(i, 0)] = value;
    }
    f.solve_in_place(x.as_mut());
    (0..n).map(|i| x[(i, 0)]).collect()
}

/// The layer's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FmapLayer {
    /// Weight λ of the mask term (ULRSSM: 100).
    pub lambda: f64,
    /// Exponent γ of the resolvent mask (0.5).
    pub gamma: f64,
}

impl Default for FmapLayer {
    fn default() -> Self {
        FmapLayer {
            lambda: 100.0,
            gamma: 0.5,
        }
    }
}

impl FmapLayer {
    /// The Cholesky factors of the systems `A Aᵀ + λ diag(mask_i)`, one
    /// per row of C (in parallel over the rows).
    fn factors(&self, a: &DMatrix<f64>, mask: &DMatrix<f64>) -> Result<Vec<Llt<f64>>> {
        let aat = mul(a, N, a, T);
        let k = aat.nrows();
        (0..mask.nrows())
            .into_par_iter()
            .map(|i| {
                let s = faer::Mat::from_fn(k, k, |r, c| {
                    aat[(r, c)]
                        + if r == c {
                            self.lambda * mask[(i, r)]
                        } else {
                            0.0
                        }
                });
                s.llt(faer::Side::Lower).map_err(|_| singular())
            })
            .collect()
    }

    /// `C` (k_B x k_A) from the projected features `a` (k_A x p) and `b`
    /// (k_B x p) and the eigenvalues of both shapes.
    ///
    /// Errors: sizes that do not fit, a singular system (λ = 0 with fewer
    /// features than eigenpairs).
    pub fn forward(
        &self,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        evals_a: &DVector<f64>,
        evals_b: &DVector<f64>,
    ) -> Result<DMatrix<f64>> {
        Ok(self.forward_tape(a, b, evals_a, evals_b)?.0)
    }

    /// [`forward`](Self::forward) keeping the factors for
    /// [`backward_tape`](Self::backward_tape).
    pub fn forward_tape(
        &self,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        evals_a: &DVector<f64>,
        evals_b: &DVector<f64>,
    ) -> Result<(DMatrix<f64>, FmapTape)> {
        self.check(a, b, evals_a, evals_b)?;
        let mask = fmaps_solve::resolvent_mask(evals_a, evals_b, self.gamma);
        let rhs = mul(b, N, a, T);
        let factors = self.factors(a, &mask)?;
        let rows: Vec<Vec<f64>> = factors
            .par_iter()
            .enumerate()
            .map(|(i, f)| solve(f, rhs.row(i).iter().copied()))
            .collect();
        let c = DMatrix::from_fn(b.nrows(), a.nrows(), |i, j| rows[i][j]);
        Ok((c.clone(), FmapTape { factors, c }))
    }

    /// Given `dc` = d loss / d C: d loss / d `a` and d loss / d `b`.
    pub fn backward(
        &self,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        evals_a: &DVector<f64>,
        evals_b: &DVector<f64>,
        dc: &DMatrix<f64>,
    ) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let (_, tape) = self.forward_tape(a, b, evals_a, evals_b)?;
        Ok(self.backward_tape(a, b, &tape, dc))
    }

    /// [`backward`](Self::backward) from the tape of the forward pass on
    /// the same `a` and `b`.
    pub fn backward_tape(
        &self,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        tape: &FmapTape,
        dc: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let ka = a.nrows();
        // c_i = r_i S⁻¹ (S symmetric): with u = S⁻¹ g_iᵀ, dr_i = uᵀ and
        // dS = −(u c_i)ᵀ = −c_iᵀ uᵀ.
        let us: Vec<Vec<f64>> = tape
            .factors
            .par_iter()
            .enumerate()
            .map(|(i, f)| solve(f, dc.row(i).iter().copied()))
            .collect();
        let d_rhs = DMatrix::from_fn(b.nrows(), ka, |i, j| us[i][j]);
        // Σ_i −c_iᵀ u_iᵀ = −Cᵀ U (U = d_rhs).
        let d_s_sum = mul(&tape.c, T, &d_rhs, N) * -1.0;
        // rhs = B Aᵀ; every S contains A Aᵀ.
        let db = mul(&d_rhs, N, a, N);
        let mut da = mul(&d_rhs, T, b, N);
        mul_add(&mut da, 1.0, &(&d_s_sum + d_s_sum.transpose()), N, a, N);
        (da, db)
    }

    fn check(
        &self,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        evals_a: &DVector<f64>,
        evals_b: &DVector<f64>,
    ) -> Result<()> {
        if a.ncols() != b.ncols() || a.nrows() != evals_a.len() || b.nrows() != evals_b.len() {
            return Err(Error::Parameter(format!(
                "projected features {}x{} and {}x{} for {} and {} eigenvalues: expected k_A x p and k_B x p",
                a.nrows(),
                a.ncols(),
                b.nrows(),
                b.ncols(),
                evals_a.len(),
                evals_b.len()
            )));
        }
        if !(self.lambda >= 0.0 && self.lambda.is_finite()) {
            return Err(Error::Parameter(format!(
                "the mask weight λ = {} must be finite and >= 0",
                self.lambda
            )));
        }
        Ok(())
    }
}

fn singular() -> Error {
    Error::Parameter(
        "the functional-map system is singular: fewer independent features than eigenpairs and no mask term (λ = 0)".into(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random;

    fn evals(k: usize, step: f64) -> DVector<f64> {
        DVector::from_fn(k, |i, _| step * i as f64 * (1.0 + 0.1 * i as f64))
    }

    /// Without the mask term and with more features than eigenpairs, C is
    /// the least-squares solution `B Aᵀ (A Aᵀ)⁻¹` (a dense closed form);
    /// with it, every row satisfies its normal equations.
    #[test]
    fn forward_matches_the_closed_forms() {
        let (ka, kb, p) = (6, 5, 20);
        let (a, b) = (random(ka, p, 1), random(kb, p, 2));
        let (ea, eb) = (evals(ka, 1.0), evals(kb, 1.3));
        let plain = FmapLayer {
            lambda: 0.0,
            gamma: 0.5,
        };
        let c = plain.forward(&a, &b, &ea, &eb).unwrap();
        let want = &b * a.transpose() * (&a * a.transpose()).try_inverse().unwrap();
        assert!((&c - want).amax() < 1e-12);
        let layer = FmapLayer::default();
        let c = layer.forward(&a, &b, &ea, &eb).unwrap();
        let mask = fmaps_solve::resolvent_mask(&ea, &eb, 0.5);
        // Gradient of the energy: 2 (C A − B) Aᵀ + 2 λ mask ⊙ C = 0.
        let grad = (&c * &a - &b) * a.transpose() + (mask.component_mul(&c)) * layer.lambda;
        assert!(grad.amax() < 1e-10, "{}", grad.amax());
        // λ = 0 with too few features: singular, an error.
        let thin = random(ka, 3, 3);
        assert!(plain.forward(&thin, &random(kb, 3, 4), &ea, &eb).is_err());
    }

    /// The backward pass against central differences of the forward.
    #[test]
    fn backward_matches_finite_differences() {
        let (ka, kb, p) = (6, 5, 9);
        let (a, b) = (random(ka, p, 5), random(kb, p, 6));
        let (ea, eb) = (evals(ka, 0.8), evals(kb, 1.1));
        let layer = FmapLayer {
            lambda: 3.0,
            gamma: 0.5,
        };
        let g = random(kb, ka, 7);
        let loss = |a: &DMatrix<f64>, b: &DMatrix<f64>| {
            layer
                .forward(a, b, &ea, &eb)
                .unwrap()
                .component_mul(&g)
                .sum()
        };
        let (da, db) = layer.backward(&a, &b, &ea, &eb, &g).unwrap();
        let h = 1e-5;
        let (xa, xb) = (random(ka, p, 8), random(kb, p, 9));
        let num_a = (loss(&(&a + &xa * h), &b) - loss(&(&a - &xa * h), &b)) / (2.0 * h);
        let num_b = (loss(&a, &(&b + &xb * h)) - loss(&a, &(&b - &xb * h))) / (2.0 * h);
        for (analytic, numeric, what) in [
            (da.component_mul(&xa).sum(), num_a, "dA"),
            (db.component_mul(&xb).sum(), num_b, "dB"),
        ] {
            let scale = analytic.abs().max(numeric.abs());
            assert!(
                (analytic - numeric).abs() / scale < 1e-6,
                "{what}: analytic {analytic}, finite difference {numeric}"
            );
        }
    }
}
