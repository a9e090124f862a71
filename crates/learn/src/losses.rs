//! Unsupervised losses on functional maps (no ground truth), with their
//! gradients: for maps `C₁₂` (shape 1's coefficients to shape 2's) and
//! `C₂₁` of the same pair,
//!
//! - bijectivity `‖C₁₂ C₂₁ − I‖² + ‖C₂₁ C₁₂ − I‖²` (the maps invert each
//!   other),
//! - orthogonality `‖C₁₂ᵀ C₁₂ − I‖² + ‖C₂₁ᵀ C₂₁ − I‖²` (area preservation),
//! - Laplacian commutativity `Σ_ij mask_ij C_ij²` of each map (with the
//!   resolvent mask, [`fmaps_solve::resolvent_mask`]: an isometry
//!   commutes with the Laplacian),
//!
//! all squared Frobenius norms, as in the deep-functional-map literature
//! (Roufosse et al. 2019; Cao et al. 2023).

use nalgebra::{DMatrix, DVector};

/// `‖C₁₂ C₂₁ − I‖² + ‖C₂₁ C₁₂ − I‖²` and its gradients with respect to
/// `C₁₂` and `C₂₁`.
pub fn bijectivity(c12: &DMatrix<f64>, c21: &DMatrix<f64>) -> (f64, DMatrix<f64>, DMatrix<f64>) {
    let e1 = c12 * c21 - DMatrix::identity(c12.nrows(), c21.ncols());
    let e2 = c21 * c12 - DMatrix::identity(c21.nrows(), c12.ncols());
    let loss = e1.norm_squared() + e2.norm_squared();
    let d12 = (&e1 * c21.transpose() + c21.transpose() * &e2) * 2.0;
    let d21 = (c12.transpose() * &e1 + &e2 * c12.transpose()) * 2.0;
    (loss, d12, d21)
}

/// `‖Cᵀ C − I‖²` of one map and its gradient `4 C (Cᵀ C − I)`.
pub fn orthogonality(c: &DMatrix<f64>) -> (f64, DMatrix<f64>) {
    let e = c.transpose() * c - DMatrix::identity(c.ncols(), c.ncols());
    (e.norm_squared(), c * &e * 4.0)
}

/// `Σ_ij mask_ij C_ij²` for the map `c` from a shape of eigenvalues
/// `evals_from` to one of `evals_to`, with the resolvent mask of exponent
/// `gamma`, and its gradient `2 mask ⊙ C`.
pub fn laplacian_commutativity(
    c: &DMatrix<f64>,
    evals_from: &DVector<f64>,
    evals_to: &DVector<f64>,
    gamma: f64,
) -> (f64, DMatrix<f64>) {
    let mask = fmaps_solve::resolvent_mask(evals_from, evals_to, gamma);
    let weighted = mask.component_mul(c);
    (weighted.component_mul(c).sum(), weighted * 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random;

    fn close(analytic: f64, numeric: f64, what: &str) {
        let scale = analytic.abs().max(numeric.abs()).max(1e-8);
        assert!(
            (analytic - numeric).abs() / scale < 1e-6,
            "{what}: analytic {analytic}, finite difference {numeric}"
        );
    }

    /// Each gradient against central differences along a random
    /// direction; each loss vanishes where it should (an orthogonal map
    /// and its inverse; a diagonal map between equal spectra).
    #[test]
    fn losses_and_gradients() {
        let k = 5;
        let (c12, c21) = (random(k, k, 1), random(k, k, 2));
        let (e12, e21) = (random(k, k, 3), random(k, k, 4));
        let h = 1e-5;
        let f = |a: &DMatrix<f64>, b: &DMatrix<f64>| bijectivity(a, b).0;
        let (_, d12, d21) = bijectivity(&c12, &c21);
        let num = (f(&(&c12 + &e12 * h), &c21) - f(&(&c12 - &e12 * h), &c21)) / (2.0 * h);
        close(d12.component_mul(&e12).sum(), num, "bijectivity dC12");
        let num = (f(&c12, &(&c21 + &e21 * h)) - f(&c12, &(&c21 - &e21 * h))) / (2.0 * h);
        close(d21.component_mul(&e21).sum(), num, "bijectivity dC21");
        let (_, d) = orthogonality(&c12);
        let g = |c: &DMatrix<f64>| orthogonality(c).0;
        let num = (g(&(&c12 + &e12 * h)) - g(&(&c12 - &e12 * h))) / (2.0 * h);
        close(d.component_mul(&e12).sum(), num, "orthogonality");
        let ev = DVector::from_fn(k, |i, _| (i * i) as f64 + 0.5 * i as f64);
        let ew = DVector::from_fn(k, |i, _| 1.2 * (i * i) as f64);
        let (_, d) = laplacian_commutativity(&c12, &ev, &ew, 0.5);
        let l = |c: &DMatrix<f64>| laplacian_commutativity(c, &ev, &ew, 0.5).0;
        let num = (l(&(&c12 + &e12 * h)) - l(&(&c12 - &e12 * h))) / (2.0 * h);
        close(d.component_mul(&e12).sum(), num, "laplacian");
        // Zeros: a rotation and its transpose; a diagonal map between
        // the same spectrum.
        let (s, c) = (0.3f64.sin(), 0.3f64.cos());
        let rot = DMatrix::from_row_slice(2, 2, &[c, -s, s, c]);
        assert!(bijectivity(&rot, &rot.transpose()).0 < 1e-28);
        assert!(orthogonality(&rot).0 < 1e-28);
        let diag = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, -1.0, 1.0, 1.0, -1.0]));
        assert!(laplacian_commutativity(&diag, &ev, &ev, 0.5).0 < 1e-28);
    }
}
