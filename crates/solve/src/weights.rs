//! Scale-free weights for the energy terms.
//!
//! The four terms of [`FmapEnergy`] have very different magnitudes (they
//! grow with k, with the number of descriptors and with their norms), so
//! raw weights do not transfer between problems. [`normalize_weights`]
//! divides each term by a reference scale, the expected size of the term
//! for a generic map (the normalization of pyFM 1.3, so that its published
//! weights `w_descr = 0.1, w_lap = 1e-3, w_dcomm = 1, w_orient` mean the
//! same thing here), and divides the weights by their sum:
//!
//! ```text
//! p_eff   = mean over A, B of (tr G)² / ‖G‖²_F,  G = Fᵀ F, F the descriptor
//!           coefficients without the constant mode (the effective count
//!           of independent descriptors)
//! τ_descr = m ‖F_A‖² / k_A / p_eff
//! τ_lap   = m Σ_ij mask_ij / (k_A k_B)
//! τ_dcomm = m (k_B Σ‖X_q‖² + k_A Σ‖Y_q‖² − 2 Σ tr X_q tr Y_q) / (k_A k_B) / p_eff
//! τ_orient= m (k_B Σ‖U_q‖² + k_A Σ‖V_q‖²) / (k_A k_B) / p_eff
//! ```
//!
//! with m = min(k_A, k_B); a degenerate scale (zero) counts as 1.

use nalgebra::DMatrix;

use crate::{FmapEnergy, PerTerm};

/// The effective number of independent descriptors of one shape's
/// coefficients `f` (k x p): `(tr G)² / ‖G‖²_F` with `G = Fᵀ F`, F without
/// its first row (the constant mode). 1 when F vanishes.
pub fn effective_descriptor_count(f: &DMatrix<f64>) -> f64 {
    if f.nrows() < 2 {
        return 1.0;
    }
    let g = f.rows(1, f.nrows() - 1);
    // ‖FᵀF‖_F = ‖FFᵀ‖_F: use the smaller Gram matrix.
    let small = g * g.transpose();
    let denom = small.norm_squared();
    if denom > 0.0 {
        small.trace().powi(2) / denom
    } else {
        1.0
    }
}

/// The reference scales τ of the terms of `energy` (see the module docs).
pub fn term_scales(energy: &FmapEnergy) -> PerTerm {
    let (ka, kb) = (energy.descr_a.nrows(), energy.descr_b.nrows());
    let m = ka.min(kb) as f64;
    let kk = (ka * kb) as f64;
    let p_eff = (0.5
        * (effective_descriptor_count(&energy.descr_a)
            + effective_descriptor_count(&energy.descr_b)))
    .max(1e-12);
    let guard = |v: f64| if v > 0.0 && v.is_finite() { v } else { 1.0 };
    let descr = if ka > 1 {
        energy.descr_a.rows(1, ka - 1).norm_squared()
    } else {
        0.0
    };
    let ops_scale = |ops: &crate::OperatorPairs, skew: bool| -> f64 {
        let (mut total, mut positive) = (0.0, 0.0);
        for (x, y) in ops {
            let pos = kb as f64 * x.norm_squared() + ka as f64 * y.norm_squared();
            positive += pos;
            total += if skew {
                pos
            } else {
                pos - 2.0 * x.trace() * y.trace()
            };
        }
        let total = total.max(0.0);
        if total <= 1e-12 * positive || ops.is_empty() {
            1.0
        } else {
            total * m / kk / p_eff
        }
    };
    PerTerm {
        descr: guard(m * descr / ka as f64 / p_eff),
        lap: guard(m * energy.lap_mask.sum() / kk),
        dcomm: ops_scale(&energy.ops, false),
        orient: ops_scale(&energy.orient_ops, true),
    }
}

/// Sets the weights of `energy` from relative weights: each divided by
/// the sum of all four and by its term's scale ([`term_scales`]). Only
/// the ratios of the relative weights matter.
pub fn normalize_weights(energy: &mut FmapEnergy, relative: PerTerm) {
    let total: f64 = relative.as_array().iter().sum();
    let total = if total > 0.0 { total } else { 1.0 };
    let tau = term_scales(energy);
    energy.w_descr = relative.descr / total / tau.descr;
    energy.w_lap = relative.lap / total / tau.lap;
    energy.w_dcomm = relative.dcomm / total / tau.dcomm;
    energy.w_orient = relative.orient / total / tau.orient;
}

/// Re-expresses paired descriptors (`da`: n_A x p, `db`: n_B x p, column q
/// of both is descriptor q) in an orthonormal basis of descriptor space
/// ordered by importance, dropping the directions that carry nothing.
///
/// Every term of the energy, and every scale of [`term_scales`], is
/// invariant under one orthogonal change of basis `Q` applied to the
/// descriptor index of both shapes (`D_A Q`, `D_B Q`; multiplication and
/// orientation operators are linear in the descriptor, so they transform
/// alike). With `Q` the eigenvectors of the Gram matrix
/// `G = D_Aᵀ M_A D_A + D_Bᵀ M_B D_B`, a direction with eigenvalue `g`
/// contributes `O(g)` to every term; directions with
/// `g ≤ rel_tol · g_max` are dropped. With `rel_tol` at rounding level
/// (1e-15) the energy is unchanged to rounding while far fewer operators
/// are needed: 100 WKS descriptors of a FAUST pair keep ~35 directions.
///
/// Returns the new descriptors (n_A x r, n_B x r).
pub fn compress_descriptors(
    da: &DMatrix<f64>,
    mass_a: &nalgebra::DVector<f64>,
    db: &DMatrix<f64>,
    mass_b: &nalgebra::DVector<f64>,
    rel_tol: f64,
) -> crate::Result<(DMatrix<f64>, DMatrix<f64>)> {
    if da.ncols() != db.ncols() {
        return Err(crate::Error::SizeMismatch {
            what: "descriptor counts of A and B",
            found: db.ncols(),
            expected: da.ncols(),
        });
    }
    for (d, m, what) in [
        (da, mass_a, "descriptor rows vs mass of A"),
        (db, mass_b, "descriptor rows vs mass of B"),
    ] {
        if d.nrows() != m.len() {
            return Err(crate::Error::SizeMismatch {
                what,
                found: d.nrows(),
                expected: m.len(),
            });
        }
    }
    let gram =
        |d: &DMatrix<f64>, m: &nalgebra::DVector<f64>| fmaps_eigensolve::weighted_tr_mul(d, m, d);
    let g = gram(da, mass_a) + gram(db, mass_b);
    let eig = nalgebra::SymmetricEigen::new(g);
    let gmax = eig.eigenvalues.iter().fold(0.0f64, |a, &x| a.max(x));
    let mut order: Vec<usize> = (0..eig.eigenvalues.len())
        .filter(|&i| eig.eigenvalues[i] > rel_tol * gmax)
        .collect();
    order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
    let q = DMatrix::from_fn(da.ncols(), order.len(), |r, c| {
        eig.eigenvectors[(r, order[c])]
    });
    Ok((da * &q, db * &q))
}
