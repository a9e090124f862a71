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

use nalgebra::{DMatrix, DVector};

use crate::{Error, Result};

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
    /// The systems `A Aᵀ + λ diag(mask_i)`, one per row of C.
    fn systems(&self, a: &DMatrix<f64>, mask: &DMatrix<f64>) -> Vec<DMatrix<f64>> {
        let aat = a * a.transpose();
        (0..mask.nrows())
            .map(|i| {
                let mut s = aat.clone();
                for j in 0..mask.ncols() {
                    s[(j, j)] += self.lambda * mask[(i, j)];
                }
                s
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
        self.check(a, b, evals_a, evals_b)?;
        let mask = fmaps_solve::resolvent_mask(evals_a, evals_b, self.gamma);
        let rhs = b * a.transpose();
        let mut c = DMatrix::zeros(b.nrows(), a.nrows());
        for (i, s) in self.systems(a, &mask).into_iter().enumerate() {
            let chol = s.cholesky().ok_or_else(singular)?;
            let row = chol.solve(&rhs.row(i).transpose());
            c.row_mut(i).copy_from(&row.transpose());
        }
        Ok(c)
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
        self.check(a, b, evals_a, evals_b)?;
        let mask = fmaps_solve::resolvent_mask(evals_a, evals_b, self.gamma);
        let rhs = b * a.transpose();
        let (ka, p) = a.shape();
        let mut d_rhs = DMatrix::zeros(b.nrows(), ka);
        let mut d_s_sum = DMatrix::zeros(ka, ka);
        for (i, s) in self.systems(a, &mask).into_iter().enumerate() {
            let chol = s.cholesky().ok_or_else(singular)?;
            // c_i = r_i S⁻¹ (S symmetric): with u = S⁻¹ g_iᵀ, dr_i = uᵀ
            // and dS = −(u c_i)ᵀ = −c_iᵀ uᵀ.
            let c_i = chol.solve(&rhs.row(i).transpose());
            let u = chol.solve(&dc.row(i).transpose());
            d_rhs.row_mut(i).copy_from(&u.transpose());
            d_s_sum -= &c_i * u.transpose();
        }
        // rhs = B Aᵀ; every S contains A Aᵀ.
        let db = &d_rhs * a;
        let da = d_rhs.transpose() * b + (&d_s_sum + d_s_sum.transpose()) * a;
        debug_assert_eq!(da.shape(), (ka, p));
        Ok((da, db))
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
