//! The functional-map solve on given descriptors: the pipeline's own
//! (from [`shape_descriptors`](super::shape_descriptors)) or any per-vertex
//! features with corresponding columns.

use std::borrow::Cow;
use std::time::Instant;

use fmaps_solve::build_energy;
use nalgebra::DMatrix;

use super::error::MatchError;
use super::params::MatchParams;
use super::prepare::{PreparedShape, shape_data};
use super::result::MatchTimes;
use crate::solve;

/// The functional map the descriptors determine, from [`fit_descriptors`].
#[derive(Debug, Clone)]
pub struct Fit {
    /// `C_BA` (`params.k` x `params.k`): B's coefficients to A's.
    pub c_ba: DMatrix<f64>,
    /// Energy terms at the solution, unweighted.
    pub energy_terms: solve::PerTerm,
    /// The weighted energy at the solution.
    pub energy: f64,
    /// Seconds: `descriptors` (their compression), `operators`, `solve`.
    pub times: MatchTimes,
}

/// The pipeline's functional-map solve on given descriptors: `da` (n_A x
/// p) on `a`, `db` (n_B x p) on `b`, column j of one corresponding to
/// column j of the other (from [`shape_descriptors`](super::shape_descriptors), or any per-vertex
/// features, e.g. learned ones). The energy of `params` (descriptor
/// preservation, commutativity with the descriptors' multiplication
/// operators, Laplacian commutativity, orientation) is minimised exactly
/// for `C_BA` of size `params.k`. Descriptors are compressed to their span
/// first when `params.descriptors.compress` (exact to rounding).
///
/// Errors: sizes that do not match the shapes or each other, non-finite
/// descriptors, too few eigenpairs, and an energy without a unique
/// minimum.
pub fn fit_descriptors(
    a: &PreparedShape,
    b: &PreparedShape,
    da: &DMatrix<f64>,
    db: &DMatrix<f64>,
    params: &MatchParams,
) -> Result<Fit, MatchError> {
    let d = Described::new(a, b, da, db, params)?;
    let mut fit = fit_described(a, b, &d, params)?;
    fit.times.descriptors += d.seconds;
    Ok(fit)
}

/// Descriptors checked against the shapes and compressed to their span
/// (with `params.descriptors.compress`): what [`fit_described`] fits, once per pair
/// whatever the number of map sizes tried (a multi-start run).
pub(super) struct Described<'a> {
    da: Cow<'a, DMatrix<f64>>,
    db: Cow<'a, DMatrix<f64>>,
    /// Seconds of the compression.
    pub(super) seconds: f64,
}

impl<'a> Described<'a> {
    /// [`fit_descriptors`]'s checks and compression (without it, the
    /// descriptors as given, borrowed).
    pub(super) fn new(
        a: &PreparedShape,
        b: &PreparedShape,
        da: &'a DMatrix<f64>,
        db: &'a DMatrix<f64>,
        params: &MatchParams,
    ) -> Result<Described<'a>, MatchError> {
        check_descriptors(a, b, da, db, params.k)?;
        let t = Instant::now();
        // The energy only sees the span of the descriptors: drop the
        // directions below rounding level (exact to rounding, ~3x fewer
        // operators).
        let (da, db) = if params.descriptors.compress {
            let (ca, cb) =
                solve::compress_descriptors(da, &a.basis.mass, db, &b.basis.mass, 1e-15)?;
            (Cow::Owned(ca), Cow::Owned(cb))
        } else {
            (Cow::Borrowed(da), Cow::Borrowed(db))
        };
        Ok(Described {
            da,
            db,
            seconds: t.elapsed().as_secs_f64(),
        })
    }
}

fn check_descriptors(
    a: &PreparedShape,
    b: &PreparedShape,
    da: &DMatrix<f64>,
    db: &DMatrix<f64>,
    k: usize,
) -> Result<(), MatchError> {
    for (shape, s, d) in [("source", a, da), ("target", b, db)] {
        if d.nrows() != s.basis.n() {
            return Err(MatchError::InvalidParameter(format!(
                "the {shape} descriptors have {} rows, but the {shape} has {} vertices",
                d.nrows(),
                s.basis.n()
            )));
        }
        if let Some(i) = d.iter().position(|x| !x.is_finite()) {
            return Err(MatchError::InvalidParameter(format!(
                "the {shape} descriptors are not finite at vertex {}, column {}",
                i % d.nrows(),
                i / d.nrows()
            )));
        }
        if s.basis.k() < k {
            return Err(MatchError::InvalidParameter(format!(
                "the {shape} shape was prepared with {} eigenpairs, fewer than k = {k}",
                s.basis.k()
            )));
        }
    }
    if da.ncols() != db.ncols() || da.ncols() == 0 {
        return Err(MatchError::InvalidParameter(format!(
            "the source has {} descriptor columns and the target {}: expected the same number, at least one",
            da.ncols(),
            db.ncols()
        )));
    }
    Ok(())
}

/// The energy of `params` on described shapes, minimised for `C_BA` of
/// size `params.k` (the compression's time is not counted).
pub(super) fn fit_described(
    a: &PreparedShape,
    b: &PreparedShape,
    described: &Described<'_>,
    params: &MatchParams,
) -> Result<Fit, MatchError> {
    let k = params.k;
    let (da, db) = (described.da.as_ref(), described.db.as_ref());
    let mut times = MatchTimes::default();
    // The map solved for is C_BA: source of C is B, target A.
    let (sb, sa) = (b.basis.truncate(k), a.basis.truncate(k));

    let t = Instant::now();
    let mut energy = build_energy(
        &shape_data(b, &sb),
        &shape_data(a, &sa),
        db,
        da,
        &params.energy,
    )?;
    times.operators = t.elapsed().as_secs_f64();
    let t = Instant::now();
    solve::normalize_weights(&mut energy, params.energy.weights);
    let c_ba = energy.minimize()?;
    check_determined(&c_ba, a.area, b.area)?;
    let energy_terms = energy.terms(&c_ba);
    let energy_value = energy.weighted_sum(&energy_terms);
    times.solve = t.elapsed().as_secs_f64();
    Ok(Fit {
        c_ba,
        energy_terms,
        energy: energy_value,
        times,
    })
}

/// Largest `|C_ij|`, relative to the area scale, accepted from the solve.
/// C_BA pulls functions on B back to A: for a map that spreads A's area
/// over B (ratio `r`) its columns have norm about `√r` between
/// L²-orthonormal bases (≤ 1 entries for an isometry). A thousand times
/// that is not a map; an undetermined solve gives 1e10 and more.
const MAX_C_ENTRY: f64 = 1e3;

/// Errors with [`MatchError::Undetermined`] when `c_ba` cannot be the
/// pull-back of a map between shapes of areas `area_a` and `area_b`: far
/// larger than one can be, or of numerical rank below half its size (the
/// pull-back of a map that reaches most of B has singular values of order
/// 1; a solve whose descriptors span only the constants on one shape gives
/// rank 1).
fn check_determined(c_ba: &DMatrix<f64>, area_a: f64, area_b: f64) -> Result<(), MatchError> {
    let ratio = (area_a / area_b).max(area_b / area_a);
    let scale = if ratio.is_finite() { ratio.sqrt() } else { 1.0 };
    let max_entry = c_ba.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let k = c_ba.nrows().min(c_ba.ncols());
    let sv = c_ba.singular_values();
    let top = sv.iter().fold(0.0f64, |m, &x| m.max(x));
    let rank = sv.iter().filter(|&&x| x > 1e-8 * top).count();
    if max_entry <= MAX_C_ENTRY * scale && 2 * rank >= k {
        return Ok(());
    }
    let ctc = c_ba.transpose() * c_ba;
    let orthonormality = (ctc - DMatrix::identity(c_ba.ncols(), c_ba.ncols())).norm();
    Err(MatchError::Undetermined {
        max_entry,
        rank,
        k,
        orthonormality,
    })
}
