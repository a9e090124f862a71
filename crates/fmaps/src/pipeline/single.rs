//! One start of the pipeline from described shapes: fit, point map,
//! refinement, orientation score.

use std::time::Instant;

use nalgebra::DMatrix;

use super::error::MatchError;
use super::fit::{Described, fit_described};
use super::params::MatchParams;
use super::prepare::PreparedShape;
use super::refining::{initial_map, refine_and_orient};
use super::result::{MatchResult, MatchTimes};

use crate::solve;

/// The pipeline from checked, compressed descriptors on (one start, size
/// `params.k`): fit, point map, refinement, orientation score. The
/// descriptors' time is the caller's to add.
pub(super) fn match_described(
    a: &PreparedShape,
    b: &PreparedShape,
    described: &Described<'_>,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    let (out, _) = match_described_deferred(a, b, described, params, false)?;
    Ok(out)
}

/// [`match_described`]; with `defer_initial_map` (for a refiner that does
/// not start from the initial point map) that map is not computed:
/// `t_ab_init` is left empty and the initial `C_BA` is returned for
/// [`initial_map`], which a multi-start run calls for the kept start only.
pub(super) fn match_described_deferred(
    a: &PreparedShape,
    b: &PreparedShape,
    described: &Described<'_>,
    params: &MatchParams,
    defer_initial_map: bool,
) -> Result<(MatchResult, Option<DMatrix<f64>>), MatchError> {
    let k = params.k;
    let mut times = MatchTimes::default();
    let fit = fit_described(a, b, described, params)?;
    times.descriptors = fit.times.descriptors;
    times.operators = fit.times.operators;
    times.solve = fit.times.solve;
    let (c_ba, energy_terms, energy_value) = (fit.c_ba, fit.energy_terms, fit.energy);
    let (sb, sa) = (b.basis.truncate(k), a.basis.truncate(k));

    let t = Instant::now();
    let (t_ab, c_init) = if defer_initial_map {
        (Vec::new(), Some(c_ba.clone()))
    } else {
        (initial_map(&c_ba, a, b, params)?, None)
    };
    times.point_map = t.elapsed().as_secs_f64();
    times.total = times.descriptors + times.operators + times.solve + times.point_map;
    let metrics = solve::fmap_metrics(&c_ba, &sb.eigenvalues, &sa.eigenvalues)?;
    let mut out = MatchResult {
        t_ab_init: t_ab.clone(),
        t_ab,
        c_ba,
        refine: None,
        orientation: 0.0,
        starts: Vec::new(),
        metrics,
        energy_terms,
        energy: energy_value,
        times,
        confidence: None,
        passed_over: None,
    };
    refine_and_orient(&mut out, a, b, params)?;
    Ok((out, c_init))
}
