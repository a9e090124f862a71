//! One start of the pipeline from described shapes: fit, point map,
//! refinement, orientation score.

use std::time::Instant;

use super::fit::{Described, fit_described};
use super::{
    MatchError, MatchParams, MatchResult, MatchTimes, PreparedShape, Refinement, orientation_of,
    refine_result, with_refiner,
};
use nalgebra::DMatrix;

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
    };
    if let Some(r) = with_refiner(&params.refine, params.adjoint, a, b, |r| {
        refine_result(&mut out, a, b, r)
    }) {
        r?;
    }
    out.orientation = orientation_of(&out.t_ab, a, b)?;
    Ok((out, c_init))
}

/// The initial point map `T_AB` of the fit `c_ba` (k x k).
/// With a sub-sampled ZoomOut's samples, the search bounds the target's
/// sample cells by balls (free where the default k-means clusters of a
/// large shape's rows take about as long as the search) and starts each
/// vertex from its nearest sample's image under the samples' map (a small
/// search): the same exact nearest neighbours.
pub(super) fn initial_map(
    c_ba: &DMatrix<f64>,
    a: &PreparedShape,
    b: &PreparedShape,
    params: &MatchParams,
) -> Result<Vec<usize>, MatchError> {
    use crate::nearest::{NnParams, NnStrategy};
    use crate::solve::convert::{BasisRows, Conversion, point_map};
    let k = c_ba.ncols();
    if let Refinement::ZoomOut { zoomout, .. } = &params.refine
        && let Some(s) = &zoomout.subsample
        && s.nearest_b.len() == a.basis.n()
    {
        // The refiner's A is the target.
        let rows_b = BasisRows::new(&b.basis, k);
        if let Some(p) = s.cells_of_a(rows_b.view(k)) {
            let conversion = if params.adjoint {
                Conversion::Adjoint
            } else {
                Conversion::Direct
            };
            let (sb, sa) = (
                BasisRows::at_vertices(&b.basis, k, &s.a)?,
                BasisRows::at_vertices(&a.basis, k, &s.b)?,
            );
            let on_samples = point_map(c_ba, &sb, &sa, conversion, None, &NnParams::default())?;
            let rows_a = BasisRows::new(&a.basis, k);
            let nn = NnParams::with_strategy(NnStrategy::Balls).with_partition(p);
            let guesses = s.guesses(&on_samples);
            return Ok(point_map(
                c_ba,
                &rows_b,
                &rows_a,
                conversion,
                guesses.as_deref(),
                &nn,
            )?);
        }
    }
    let (sb, sa) = (b.basis.truncate(k), a.basis.truncate(k));
    Ok(if params.adjoint {
        solve::point_map_from_fmap_adjoint(c_ba, &sb, &sa)?
    } else {
        solve::point_map_from_fmap(c_ba, &sb, &sa)?
    })
}
