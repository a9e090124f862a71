//! Refining a point map that came from elsewhere (another tool, a learned
//! method, landmarks, a published benchmark map): the map's functional map
//! is its pull-back between the two eigenbases, and any refiner takes it
//! from there. This separates the quality of an initial map from the
//! quality of a refiner.

use std::time::Instant;

use crate::refine::RefineReport;
use fmaps_solve::convert::{BasisRows, pullback};
use nalgebra::DMatrix;

use super::error::MatchError;
use super::params::MatchParams;
use super::prepare::PreparedShape;
use super::refining::{orientation_of, with_refiner};
use crate::solve;

/// The result of [`refine_point_map`].
#[derive(Debug, Clone)]
pub struct RefinedMap {
    /// The refined map `T_AB` (the given one when no refinement is asked).
    pub t_ab: Vec<usize>,
    /// `C_BA` after refinement.
    pub c_ba: DMatrix<f64>,
    /// The given map.
    pub t_ab_init: Vec<usize>,
    /// The given map's `C_BA` (`k` x `k`): its pull-back.
    pub c_ba_init: DMatrix<f64>,
    /// Structural measures of `c_ba_init`.
    pub metrics_init: solve::FmapMetrics,
    /// The refinement report, when one ran.
    pub refine: Option<RefineReport>,
    /// Orientation scores of the given and the refined map.
    pub orientation_init: f64,
    /// See [`MatchResult::orientation`](super::MatchResult::orientation).
    pub orientation: f64,
    /// Seconds for the pull-back and the refinement.
    pub seconds: f64,
}

/// Refines the point map `t_ab` (for every vertex of `a`, a vertex of `b`)
/// with `params.refinement`, starting from its pull-back
/// `C_BA = Φ_Aᵀ M_A Π_AB Φ_B` of size `params.k` (ZoomOut starts from its
/// top-left `k_start` block). The shapes must be prepared with at least
/// `params.k` and the refinement's eigenpairs.
///
/// Errors: a map of the wrong length or with an index out of range, too
/// few eigenpairs, and the refiner's errors.
pub fn refine_point_map(
    a: &PreparedShape,
    b: &PreparedShape,
    t_ab: &[usize],
    params: &MatchParams,
) -> Result<RefinedMap, MatchError> {
    let t = Instant::now();
    if t_ab.len() != a.basis.n() {
        return Err(MatchError::InvalidParameter(format!(
            "the initial map has {} entries, but the source has {} vertices (one target per source vertex)",
            t_ab.len(),
            a.basis.n()
        )));
    }
    let k = params.k;
    for (shape, s) in [("source", a), ("target", b)] {
        let needed = k.max(params.refinement.k_needed());
        if s.basis.k() < needed {
            return Err(MatchError::InvalidParameter(format!(
                "the {shape} was prepared with {} eigenpairs; the refinement needs {needed}",
                s.basis.k()
            )));
        }
    }
    // C_BA pulls B's functions back to A along T_AB.
    let c_ba_init = pullback(
        t_ab,
        &BasisRows::new(&b.basis, k),
        k,
        &BasisRows::new(&a.basis, k),
        k,
        a.basis.mass.as_slice(),
    )?;
    let (sb, sa) = (b.basis.truncate(k), a.basis.truncate(k));
    let metrics_init = solve::fmap_metrics(&c_ba_init, &sb.eigenvalues, &sa.eigenvalues)?;
    let orientation_init = orientation_of(t_ab, a, b)?;
    let refined = with_refiner(&params.refinement, params.adjoint, a, b, |r| {
        r.refine(
            &crate::refine::RefineInput::new(&c_ba_init, &b.basis, &a.basis)
                .with_geometry(b.geometry(), a.geometry()),
        )
    })
    .transpose()?;
    let (t_ab_out, c_ba, report) = match refined {
        Some(r) => (r.t_ba, r.c_ab, Some(r.report)),
        None => (t_ab.to_vec(), c_ba_init.clone(), None),
    };
    let orientation = orientation_of(&t_ab_out, a, b)?;
    Ok(RefinedMap {
        t_ab: t_ab_out,
        c_ba,
        t_ab_init: t_ab.to_vec(),
        c_ba_init,
        metrics_init,
        refine: report,
        orientation_init,
        orientation,
        seconds: t.elapsed().as_secs_f64(),
    })
}
