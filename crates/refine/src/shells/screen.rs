//! The screening of rigid orientations ([`SmoothShells::screen`]): each
//! orientation's best proposal runs a short alignment, and those whose
//! maps score best go on to the whole alignment.

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::level::{Alignment, Samples};
use super::shell::Shell;
use super::{Select, SmoothShells, as_start, merge};
use crate::{RefineReport, Result};

impl SmoothShells {
    /// The setting for shapes that are not near-isometric (different
    /// people, different animals): all eight rigid orientations screened
    /// by a short alignment, the two whose short maps score best by area
    /// distortion and orientation together aligned in full, and the final
    /// map chosen by the same score ([`Select::AreaAndOrientation`]).
    /// Screening eight orientations instead of two costs initialisation
    /// time; this setting wins it back with 500 initialisation samples
    /// instead of 1000 and 30 random proposals per aligned orientation
    /// instead of 60 (60 dealt among the eight), so it takes about the
    /// default's time (the accuracy table of docs/benchmarks.md). On the 30 generated
    /// non-isometric pairs (docs/benchmarks.md, exact geodesics) it lowers the mean
    /// geodesic error from the default's 15.8 x100 to 10.5 (10.7 with
    /// 1000 samples and 60 proposals, 10.4 with 500 and 60: the
    /// difference is a few pairs' orientation choices, within the
    /// spread of the proposals' draws).
    ///
    /// ```
    /// let s = fmaps_refine::SmoothShells::non_isometric();
    /// assert_eq!((s.screen, s.orientations), (8, 2));
    /// assert_eq!((s.init_samples, s.proposals), (500, 30));
    /// ```
    pub fn non_isometric() -> SmoothShells {
        SmoothShells {
            screen: 8,
            select: Select::AreaAndOrientation,
            init_samples: 500,
            proposals: 30,
            ..SmoothShells::default()
        }
    }

    /// The `orientations` of `xs` whose best proposal, aligned by a short
    /// schedule (12 levels on the samples `ix`, `iy`), gives the best map
    /// (see [`SmoothShells::screen`]), with their proposals.
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
        let mut order: Vec<(f64, usize)> = scores
            .iter()
            .enumerate()
            .map(|(o, &score)| (score, o))
            .collect();
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

    /// Per orientation, the score (higher is better) of the map its best
    /// proposal gives after a short alignment (12 levels on the samples
    /// `ix`, `iy`): [`SmoothShells::selection_score`] with
    /// [`Select::AreaAndOrientation`], else minus the area distortion;
    /// −∞ for an orientation without proposals.
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
                    return Ok((f64::NEG_INFINITY, rep));
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
                let score = match self.select {
                    // The final choice's own score: an orientation whose
                    // quick map folds over (a mirror image of the right
                    // map distorts area as little) is not kept.
                    Select::AreaAndOrientation => self.selection_score(&map, x, y)?,
                    // Least area distortion first.
                    Select::Orientation => {
                        -crate::area_distortion(&map, &y.verts, y.faces, &x.verts, x.faces)?
                    }
                };
                Ok((score, rep))
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

    /// The score by which [`SmoothShells::select`] compares the point map
    /// `map` of Y onto X with those of other orientations (higher is
    /// better): the orientation score, minus the area distortion with
    /// [`Select::AreaAndOrientation`].
    pub(super) fn selection_score(
        &self,
        map: &[usize],
        x: &Shell<'_>,
        y: &Shell<'_>,
    ) -> Result<f64> {
        // A reflected X keeps its faces: its orientation is reversed.
        let sign = if self.reflect { -1.0 } else { 1.0 };
        let o = sign * crate::orientation_score(map, &y.verts, y.faces, &x.verts, x.faces)?;
        Ok(match self.select {
            Select::Orientation => o,
            Select::AreaAndOrientation => {
                o - crate::area_distortion(map, &y.verts, y.faces, &x.verts, x.faces)?
            }
        })
    }
}
