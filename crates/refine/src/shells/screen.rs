//! The screening of rigid orientations ([`SmoothShells::screen`]): each
//! orientation's best proposal runs a short alignment, and those whose
//! maps distort area least go on to the whole alignment.

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::level::{Alignment, Samples, Shell};
use super::{SmoothShells, as_start, merge};
use crate::{RefineReport, Result};

impl SmoothShells {
    /// The `orientations` of `xs` whose best proposal, aligned by a short
    /// schedule (12 levels on the samples `ix`, `iy`), gives the map that
    /// distorts area least, with their proposals (see
    /// [`SmoothShells::screen`]).
    #[allow(clippy::type_complexity)]
    pub(super) fn screened<'s>(
        &self,
        xs: Vec<Shell<'s>>,
        y: &Shell<'_>,
        ranked: Vec<Vec<Alignment>>,
        (ix, iy): (&Samples, &Samples),
        gram: &DMatrix<f64>,
        report: &mut RefineReport,
    ) -> Result<(Vec<Shell<'s>>, Vec<Vec<Alignment>>)> {
        let scores = self.quick_scores(&xs, y, &ranked, (ix, iy), gram, report)?;
        // Least area distortion first (a lower is better: negated).
        let mut order: Vec<(f64, usize)> =
            scores.iter().enumerate().map(|(o, a)| (-a, o)).collect();
        // Best first; ties (and NaN) keep the surrogate's order.
        order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let keep: Vec<usize> = order
            .iter()
            .take(self.orientations.max(1))
            .map(|&(_, o)| o)
            .collect();
        let mut xs: Vec<Option<Shell<'s>>> = xs.into_iter().map(Some).collect();
        let mut ranked: Vec<Option<Vec<Alignment>>> = ranked.into_iter().map(Some).collect();
        Ok(keep
            .into_iter()
            .map(|o| {
                (
                    xs[o].take().expect("kept once"),
                    ranked[o].take().expect("kept once"),
                )
            })
            .unzip())
    }

    /// Per orientation, the area distortion of the map
    /// its best proposal gives after a short alignment (12 levels on the
    /// samples `ix`, `iy`); ∞ for an orientation without proposals.
    fn quick_scores(
        &self,
        xs: &[Shell<'_>],
        y: &Shell<'_>,
        ranked: &[Vec<Alignment>],
        (ix, iy): (&Samples, &Samples),
        gram: &DMatrix<f64>,
        report: &mut RefineReport,
    ) -> Result<Vec<f64>> {
        let quick = SmoothShells {
            levels: 12,
            ..self.clone()
        };
        let scores: Vec<Result<(f64, RefineReport)>> = xs
            .par_iter()
            .zip(ranked)
            .map(|(x, states)| {
                let mut rep = RefineReport::start(String::new());
                let Some(best) = states.first() else {
                    return Ok((f64::INFINITY, rep));
                };
                let (_, state) = quick.align(
                    x,
                    y,
                    (ix, iy),
                    (ix, iy),
                    gram,
                    as_start(best.clone()),
                    &mut rep,
                )?;
                rep.iterations.clear();
                let map = Self::point_map(x, y, &state, self.k_max, &mut rep)?;
                let a = crate::area_distortion(&map, &y.verts, y.faces, &x.verts, x.faces)?;
                Ok((a, rep))
            })
            .collect();
        let mut out = Vec::with_capacity(scores.len());
        for r in scores {
            let (score, rep) = r?;
            merge(report, &rep);
            out.push(score);
        }
        Ok(out)
    }
}
