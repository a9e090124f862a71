//! Multi-start ([`MatchParams::starts`]): one pipeline run per initial
//! size, one final map kept by a score without ground truth.

use std::sync::Arc;
use std::time::Instant;

use fmaps_mesh_io::TriMesh;
use nalgebra::DMatrix;
use rayon::prelude::*;

use super::fit::Described;
use super::single::{initial_map, match_described_deferred};
use super::{
    MatchError, MatchParams, MatchResult, MatchTimes, PreparedShape, Refinement, Start,
    StartSelection, orientation_of, refine_result, with_refiner,
};
use crate::refine;

impl MatchParams {
    /// The size at which a multi-start run stops its starts
    /// ([`select_at`](Self::select_at)): `Some` only with starts, a
    /// ZoomOut refinement and a stop below its final size.
    pub fn starts_stop(&self) -> Option<usize> {
        match (&self.refine, self.select_at) {
            (Refinement::ZoomOut { zoomout, .. }, Some(s))
                if !self.starts.is_empty() && s < zoomout.k_final =>
            {
                Some(s)
            }
            _ => None,
        }
    }
}

/// [`MatchParams::starts`]: one run per initial size from the same
/// descriptors (computed in `descriptor_seconds`), keep the final map of
/// the best score.
pub(super) fn multi_start(
    a: &PreparedShape,
    b: &PreparedShape,
    described: &Described<'_>,
    descriptor_seconds: f64,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    let mut sizes = vec![params.k];
    for &s in &params.starts {
        if !sizes.contains(&s) {
            sizes.push(s);
        }
    }
    let sign = if params.orient_reversing { -1.0 } else { 1.0 };
    // A ZoomOut may stop every start at `select_at`: the kept one then
    // goes on alone.
    let stop = params.starts_stop();
    // A sub-sampled ZoomOut does not start from the initial point map: it
    // is computed for the kept start only (one full-size search instead
    // of one per start).
    let defer = matches!(&params.refine, Refinement::ZoomOut { zoomout, .. } if zoomout.subsample.is_some());
    let run = |k: usize| -> Result<(MatchResult, Option<DMatrix<f64>>), MatchError> {
        let mut p = MatchParams {
            k,
            starts: Vec::new(),
            ..params.clone()
        };
        match &mut p.refine {
            Refinement::ZoomOut { zoomout, .. } => {
                zoomout.k_start = zoomout.k_start.min(k);
                if let Some(s) = stop {
                    zoomout.k_final = s;
                    zoomout.k_start = zoomout.k_start.min(s);
                    // The starts' maps at the stop are only scored.
                    zoomout.full_iterations = 0;
                }
            }
            Refinement::Custom(r) => {
                if let Some(r) = r.for_initial_size(k) {
                    p.refine = Refinement::Custom(Arc::from(r));
                }
            }
            _ => {}
        }
        match_described_deferred(a, b, described, &p, defer)
    };
    let wall = Instant::now();
    let mut results = Vec::with_capacity(sizes.len());
    let first = match params.restart_below {
        // The first start alone (it may be enough), then the others.
        Some(t) => {
            let r = run(sizes[0])?;
            let enough = sign * r.0.orientation >= t;
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
    let mut starts = Vec::with_capacity(results.len());
    type Best = (usize, f64, MatchResult, Option<DMatrix<f64>>);
    let mut best: Option<Best> = None;
    let mesh = |s: &PreparedShape| TriMesh::new(s.vertices.clone(), s.faces.clone());
    let (mesh_a, mesh_b) = (
        mesh(a).map_err(|e| MatchError::InvalidShape {
            shape: "source",
            message: e.to_string(),
        })?,
        mesh(b).map_err(|e| MatchError::InvalidShape {
            shape: "target",
            message: e.to_string(),
        })?,
    );
    for (k, (r, c_init)) in sizes.iter().zip(results) {
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
        starts.push(Start {
            k: *k,
            orientation: r.orientation,
            quality,
            chosen: false,
            seconds: r.times.total,
        });
        // Lower is better.
        let score = match params.select {
            StartSelection::Orientation => -sign * r.orientation,
            StartSelection::Conformal => quality.conformal_distortion,
            StartSelection::Area => quality.area_distortion,
        };
        if best.as_ref().is_none_or(|(_, b, _, _)| score < *b) {
            best = Some((starts.len() - 1, score, r, c_init));
        }
    }
    let (chosen, _, mut out, c_init) = best.expect("at least one start");
    if let Some(c) = c_init {
        let t = Instant::now();
        out.t_ab_init = initial_map(&c, a, b, params)?;
        let s = t.elapsed().as_secs_f64();
        out.times.point_map += s;
        times.point_map += s;
    }
    if let (Some(s), Refinement::ZoomOut { zoomout, samples }) = (stop, &params.refine) {
        // The kept start's ZoomOut from `s` on, from its map and its
        // s x s fit: the rest of the schedule (the same iterations as
        // without the stop when the start's sizes pass through s).
        let rest = Refinement::ZoomOut {
            zoomout: refine::ZoomOut {
                k_start: s,
                ..zoomout.clone()
            },
            samples: *samples,
        };
        let first = out.refine.take();
        let before = out.times.refine;
        if let Some(r) = with_refiner(&rest, params.adjoint, a, b, |r| {
            refine_result(&mut out, a, b, r)
        }) {
            r?;
        }
        times.refine += out.times.refine;
        out.times.refine += before;
        if let (Some(first), Some(second)) = (first, out.refine.as_mut()) {
            second.method = format!("{}, kept start continued {}", first.method, second.method);
            let mut its = first.iterations;
            its.append(&mut second.iterations);
            second.iterations = its;
            second.nn_searches += first.nn_searches;
            second.nn_seconds += first.nn_seconds;
            second.seconds += first.seconds;
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
