//! Assembling the energy of a pair from bases, faces and descriptors:
//! coefficients, Laplacian mask, multiplication and orientation operators
//! for the terms in use, and the fixed first column.

use fmaps_eigensolve::weighted_tr_mul;
use nalgebra::{DMatrix, DVector};

use crate::{
    Error, FmapEnergy, PerTerm, Result, laplacian_mask, multiplication_operators,
    orientation_operators, resolvent_mask,
};

/// What the energy needs of one shape, as plain arrays (so bases and
/// descriptors from elsewhere, e.g. pyFM's, can be used as they are).
#[derive(Debug, Clone, Copy)]
pub struct ShapeData<'a> {
    /// Oriented triangles.
    pub faces: &'a [[usize; 3]],
    /// The first k eigenvectors (n x k), M-orthonormal.
    pub phi: &'a DMatrix<f64>,
    /// The first k eigenvalues.
    pub evals: &'a DVector<f64>,
    /// The lumped mass.
    pub mass: &'a DVector<f64>,
    /// Total area.
    pub area: f64,
}

/// The terms of [`build_energy`] and their relative weights.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct EnergyParams {
    /// Relative weights (the operators of a term are built only when its
    /// weight is positive).
    pub weights: PerTerm,
    /// Resolvent Laplacian mask with this γ; `None`: plain `(λ − μ)²`.
    pub resolvent_gamma: Option<f64>,
    /// Look for orientation-reversing maps instead.
    pub orient_reversing: bool,
}

impl Default for EnergyParams {
    /// The literature's automatic pipeline (pyFM's): `w_descr = 0.1`,
    /// `w_lap = 1e-3` with the resolvent mask (γ = 0.5), `w_dcomm = 1`,
    /// `w_orient = 1`.
    fn default() -> Self {
        EnergyParams {
            weights: PerTerm {
                descr: 0.1,
                lap: 1e-3,
                dcomm: 1.0,
                orient: 1.0,
            },
            resolvent_gamma: Some(0.5),
            orient_reversing: false,
        }
    }
}

/// The energy of the functional map from `src` to `tgt` (k_tgt x k_src)
/// for descriptors `d_src` (n_src x p) and `d_tgt`: coefficients, Laplacian
/// mask, multiplication and orientation operators for the terms with a
/// positive weight, and the fixed first column (constants to constants).
/// The weights are left at the raw relative values; call
/// [`normalize_weights`](crate::normalize_weights) to scale them.
pub fn build_energy(
    src: &ShapeData<'_>,
    tgt: &ShapeData<'_>,
    d_src: &DMatrix<f64>,
    d_tgt: &DMatrix<f64>,
    params: &EnergyParams,
) -> Result<FmapEnergy> {
    let project = |s: &ShapeData<'_>,
                   d: &DMatrix<f64>,
                   what: (&'static str, &'static str)|
     -> Result<DMatrix<f64>> {
        for (found, name) in [(d.nrows(), "descriptor rows"), (s.mass.len(), "mass")] {
            if found != s.phi.nrows() {
                return Err(Error::SizeMismatch {
                    what: if name == "mass" { what.1 } else { what.0 },
                    found,
                    expected: s.phi.nrows(),
                });
            }
        }
        Ok(weighted_tr_mul(s.phi, s.mass, d))
    };
    let w = params.weights;
    let mut energy = FmapEnergy::new(
        project(
            src,
            d_src,
            (
                "source descriptor rows vs basis rows",
                "source mass vs basis rows",
            ),
        )?,
        project(
            tgt,
            d_tgt,
            (
                "target descriptor rows vs basis rows",
                "target mass vs basis rows",
            ),
        )?,
        match params.resolvent_gamma {
            Some(g) => resolvent_mask(src.evals, tgt.evals, g),
            None => laplacian_mask(src.evals, tgt.evals),
        },
    );
    energy.w_descr = w.descr;
    energy.w_lap = w.lap;
    energy.w_dcomm = w.dcomm;
    energy.w_orient = w.orient;
    if w.dcomm > 0.0 {
        let (xs, xt) = rayon::join(
            || multiplication_operators(src.phi, src.mass, d_src),
            || multiplication_operators(tgt.phi, tgt.mass, d_tgt),
        );
        energy.ops = xs?.into_iter().zip(xt?).collect();
    }
    if w.orient > 0.0 {
        let (os, ot) = rayon::join(
            || orientation_operators(src.faces, src.phi, d_src, false),
            || orientation_operators(tgt.faces, tgt.phi, d_tgt, params.orient_reversing),
        );
        energy.orient_ops = os?.into_iter().zip(ot?).collect();
    }
    // Constants map to constants: φ_0 = ±1/sqrt(area) on both shapes.
    let k_tgt = tgt.phi.ncols();
    let mut c0 = DVector::zeros(k_tgt);
    if k_tgt > 0 && src.phi.ncols() > 0 {
        let sign = (src.phi[(0, 0)] * tgt.phi[(0, 0)]).signum();
        c0[0] = sign * (tgt.area / src.area).sqrt();
    }
    energy.fixed_first_column = Some(c0);
    Ok(energy)
}
