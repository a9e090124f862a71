//! The point-map and refinement stages: the initial point map of a fit,
//! the refiner a [`Refinement`] describes for a pair (with its samples),
//! applied to a result, and the orientation score of the final map.

use std::time::Instant;

use nalgebra::DMatrix;

use super::error::MatchError;
use super::params::MatchParams;
use super::prepare::PreparedShape;
use super::refinement::Refinement;
use super::result::MatchResult;
use crate::refine::{self, Refiner};
use crate::solve;

pub(super) fn orientation_of(
    t_ab: &[usize],
    a: &PreparedShape,
    b: &PreparedShape,
) -> Result<f64, MatchError> {
    Ok(refine::orientation_score(
        t_ab,
        &a.vertices,
        &a.faces,
        &b.vertices,
        &b.faces,
    )?)
}

/// Refines a pipeline result in place with any [`Refiner`]: `C_BA` (B's
/// functions to A's) is refined between the bases of `b` and `a`, and the
/// point map `T_AB` is the refiner's output. The unrefined map stays in
/// `t_ab_init`; the time goes to `times.refine` (and `times.total`).
pub fn refine_result(
    out: &mut MatchResult,
    a: &PreparedShape,
    b: &PreparedShape,
    refiner: &dyn Refiner,
) -> Result<(), MatchError> {
    refine_with_landmarks(out, a, b, refiner, &[])
}

/// [`refine_result`] with landmark pairs `(vertex of A, vertex of B)` for
/// refiners that use them ([`refine::RefineInput::landmarks`]).
pub(super) fn refine_with_landmarks(
    out: &mut MatchResult,
    a: &PreparedShape,
    b: &PreparedShape,
    refiner: &dyn Refiner,
    landmarks: &[(usize, usize)],
) -> Result<(), MatchError> {
    let t = Instant::now();
    // The refiner's A is our B.
    let swapped: Vec<(usize, usize)> = landmarks.iter().map(|&(x, y)| (y, x)).collect();
    // A point map A -> B pulls functions back from B to A, so T_AB goes
    // with C_BA: the refiner's (c_ab, basis_a, basis_b) -> t_ba contract
    // is applied to the pair (B, A), and its t_ba is our T_AB.
    // The unrefined point map is the conversion of C_BA that the
    // refiner's first search repeats: its guess.
    let refined = refiner.refine(
        &refine::RefineInput::new(&out.c_ba, &b.basis, &a.basis)
            .with_geometry(b.geometry(), a.geometry())
            .with_guess(&out.t_ab)
            .with_landmarks(&swapped),
    )?;
    out.c_ba = refined.c_ab;
    out.t_ab = refined.t_ba;
    out.refine = Some(refined.report);
    out.times.refine = t.elapsed().as_secs_f64();
    out.times.total += out.times.refine;
    Ok(())
}

/// The last stages of one start: `params.refinement` applied to `out`
/// ([`refine_result`]), then the orientation score of the final map.
pub(super) fn refine_and_orient(
    out: &mut MatchResult,
    a: &PreparedShape,
    b: &PreparedShape,
    params: &MatchParams,
) -> Result<(), MatchError> {
    if let Some(r) = with_refiner(&params.refinement, params.adjoint, a, b, |r| {
        refine_with_landmarks(out, a, b, r, &params.descriptors.landmarks)
    }) {
        r?;
    }
    out.orientation = orientation_of(&out.t_ab, a, b)?;
    Ok(())
}

/// Calls `f` with the refiner `refine` describes for the pair (`a`, `b`)
/// (`adjoint` forces the adjoint conversion); `None` for no refinement.
pub(super) fn with_refiner<R>(
    refine: &Refinement,
    adjoint: bool,
    a: &PreparedShape,
    b: &PreparedShape,
    f: impl FnOnce(&dyn Refiner) -> R,
) -> Option<R> {
    match refine {
        Refinement::None => None,
        Refinement::Icp(icp) => Some(f(&refine::Icp {
            adjoint: icp.adjoint || adjoint,
            ..*icp
        })),
        Refinement::ZoomOut { zoomout, samples } => {
            let mut zo = zoomout.clone();
            zo.adjoint |= adjoint;
            // The refiner's "A" is the target (see `refine_result`).
            if let Some(m) = samples {
                zo = sampled(zo, a, b, *m);
            }
            Some(f(&zo))
        }
        Refinement::Custom(r) => Some(f(r.as_ref())),
    }
}

/// Iterations on every vertex after a sub-sampled ZoomOut's iterations on
/// samples ([`refine::ZoomOut::full_iterations`]) in the pipeline.
const SAMPLED_FULL_ITERATIONS: usize = 1;

/// A sub-sampled ZoomOut's samples, drawn once for every start: `params`
/// with the [`refine::Subsample`] in place of `samples` (the refiner's A
/// is the target), and the seconds it took; `None` for other refinements.
pub(super) fn draw_samples(
    a: &PreparedShape,
    b: &PreparedShape,
    params: &MatchParams,
) -> (Option<MatchParams>, f64) {
    let Refinement::ZoomOut {
        zoomout,
        samples: Some(m),
    } = &params.refinement
    else {
        return (None, 0.0);
    };
    let t = Instant::now();
    let mut p = params.clone();
    p.refinement = Refinement::ZoomOut {
        zoomout: sampled(zoomout.clone(), a, b, *m),
        samples: None,
    };
    (Some(p), t.elapsed().as_secs_f64())
}

/// `zoomout` on `m` farthest points per shape of the pair (`a`, `b`), as
/// the pipeline runs it (the refiner's A is the target; then
/// [`SAMPLED_FULL_ITERATIONS`] on every vertex).
fn sampled(
    zoomout: refine::ZoomOut,
    a: &PreparedShape,
    b: &PreparedShape,
    m: usize,
) -> refine::ZoomOut {
    refine::ZoomOut {
        subsample: Some(refine::Subsample::farthest(&b.vertices, &a.vertices, m)),
        full_iterations: SAMPLED_FULL_ITERATIONS,
        ..zoomout
    }
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
    if let Refinement::ZoomOut { zoomout, .. } = &params.refinement
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
