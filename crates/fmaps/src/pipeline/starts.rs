//! Multi-start ([`Starts`](super::Starts)): one run per initial size from
//! the same descriptors, each final map scored without ground truth
//! ([`crate::eval::map_quality`]), one kept
//! ([`crate::refine::starts::best_start`]).

use std::sync::Arc;
use std::time::Instant;

use fmaps_mesh_io::TriMesh;
use nalgebra::DMatrix;
use rayon::prelude::*;

use super::error::MatchError;
use super::fit::Described;
use super::params::MatchParams;
use super::prepare::PreparedShape;
use super::refinement::Refinement;
use super::refining::{initial_map, orientation_of, refine_with_landmarks, with_refiner};
use super::result::{MatchResult, MatchTimes, Start};
use super::single::match_described_deferred;
use crate::refine::starts::{StartScores, best_start, first_start_suffices, start_sizes};

/// One run per initial size from the same descriptors (computed in
/// `descriptor_seconds`), keeping the final map of the best score.
pub(super) fn multi_start(
    a: &PreparedShape,
    b: &PreparedShape,
    described: &Described<'_>,
    descriptor_seconds: f64,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    let sizes = start_sizes(params.k, &params.starts.sizes);
    let reversing = params.energy.orient_reversing;
    // A ZoomOut may stop every start at `select_at`: the kept one then
    // goes on alone.
    let stop = params.starts_stop();
    // A sub-sampled ZoomOut does not start from the initial point map: it
    // is computed for the kept start only (one full-size search instead
    // of one per start).
    let defer = matches!(&params.refinement, Refinement::ZoomOut { zoomout, .. } if zoomout.subsample.is_some());
    let run = |k: usize| -> Result<(MatchResult, Option<DMatrix<f64>>), MatchError> {
        let mut p = params.clone();
        p.k = k;
        p.starts.sizes.clear();
        match &mut p.refinement {
            Refinement::ZoomOut { zoomout, .. } => *zoomout = zoomout.for_start(k, stop),
            Refinement::Custom(r) => {
                if let Some(r) = r.for_initial_size(k) {
                    p.refinement = Refinement::Custom(Arc::from(r));
                }
            }
            _ => {}
        }
        match_described_deferred(a, b, described, &p, defer)
    };
    let wall = Instant::now();
    let mut results = Vec::with_capacity(sizes.len());
    let first = match params.starts.restart_below {
        // The first start alone (it may be enough), then the others.
        Some(t) => {
            let r = run(sizes[0])?;
            let enough = first_start_suffices(r.0.orientation, t, reversing);
            results.push(r);
            if enough { sizes.len() } else { 1 }
        }
        None => 0,
    };
    // In parallel (a start's result does not depend on the threads).
    let rest: Vec<Result<_, MatchError>> = sizes[first..].par_iter().map(|&k| run(k)).collect();
    for r in rest {
        results.push(r?);
    }
    let mut times = MatchTimes {
        descriptors: descriptor_seconds,
        ..MatchTimes::default()
    };
    let mesh = |s: &PreparedShape, shape| {
        TriMesh::new(s.vertices.clone(), s.faces.clone()).map_err(|e| MatchError::InvalidShape {
            shape,
            message: e.to_string(),
        })
    };
    let (mesh_a, mesh_b) = (mesh(a, "source")?, mesh(b, "target")?);
    let mut starts = Vec::with_capacity(results.len());
    let mut scores = Vec::with_capacity(results.len());
    for (k, (r, _)) in sizes.iter().zip(&results) {
        for (acc, x) in [
            (&mut times.descriptors, r.times.descriptors),
            (&mut times.operators, r.times.operators),
            (&mut times.solve, r.times.solve),
            (&mut times.point_map, r.times.point_map),
            (&mut times.refine, r.times.refine),
        ] {
            *acc += x;
        }
        let quality = crate::eval::map_quality(&r.t_ab, &mesh_a, &mesh_b, None)
            .map_err(|e| MatchError::InvalidParameter(format!("map quality: {e}")))?;
        scores.push(StartScores {
            orientation: r.orientation,
            area_distortion: quality.area_distortion,
            conformal_distortion: quality.conformal_distortion,
        });
        starts.push(Start {
            k: *k,
            orientation: r.orientation,
            quality,
            chosen: false,
            seconds: r.times.total,
        });
    }
    let chosen = best_start(&scores, params.starts.select, reversing).expect("at least one start");
    let (mut out, c_init) = results.swap_remove(chosen);
    if let Some(c) = c_init {
        let t = Instant::now();
        out.t_ab_init = initial_map(&c, a, b, params)?;
        let s = t.elapsed().as_secs_f64();
        out.times.point_map += s;
        times.point_map += s;
    }
    if let (Some(s), Refinement::ZoomOut { zoomout, samples }) = (stop, &params.refinement) {
        // The kept start's ZoomOut from `s` on, from its map and its
        // s x s fit.
        let rest = Refinement::ZoomOut {
            zoomout: zoomout.continued_from(s),
            samples: *samples,
        };
        let first = out.refine.take();
        let before = out.times.refine;
        if let Some(r) = with_refiner(&rest, params.adjoint, a, b, |r| {
            refine_with_landmarks(&mut out, a, b, r, &params.descriptors.landmarks)
        }) {
            r?;
        }
        times.refine += out.times.refine;
        out.times.refine += before;
        if let Some(first) = first {
            out.refine = out.refine.take().map(|second| second.continuing(first));
        }
        out.orientation = orientation_of(&out.t_ab, a, b)?;
    }
    // Stages summed over the starts; the total is the wall-clock time.
    times.total = descriptor_seconds + wall.elapsed().as_secs_f64();
    starts[chosen].chosen = true;
    out.starts = starts;
    out.times = times;
    Ok(out)
}
