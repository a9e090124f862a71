//! What the pipeline returns: the maps, their scores and the time of
//! each stage.

use nalgebra::DMatrix;

use crate::refine::RefineReport;
use crate::solve;

/// Seconds per stage of [`match_prepared`](super::match_prepared).
#[derive(Debug, Clone, Copy, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MatchTimes {
    /// Laplacians and eigenbases of both shapes (0 when prepared earlier).
    pub spectra: f64,
    /// Descriptors, their projection and normalization.
    pub descriptors: f64,
    /// Multiplication and orientation operators.
    pub operators: f64,
    /// Weights, assembly and exact solve of the energy.
    pub solve: f64,
    /// Conversion to the point map.
    pub point_map: f64,
    /// Refinement (0 without).
    pub refine: f64,
    /// Sum of all stages.
    pub total: f64,
}

/// The result of the pipeline.
#[derive(Debug, Clone)]
pub struct MatchResult {
    /// `T_AB`: for every source vertex, a target vertex (0-based); refined
    /// when a refinement ran.
    pub t_ab: Vec<usize>,
    /// `C_BA`: coefficients on B to coefficients on A (k x k, or the
    /// refinement's final size).
    pub c_ba: DMatrix<f64>,
    /// The initial point map, before refinement.
    pub t_ab_init: Vec<usize>,
    /// The refinement report, when one ran.
    pub refine: Option<RefineReport>,
    /// [`crate::refine::orientation_score`] of `t_ab` (near 1: orientation
    /// preserved, near −1: mirrored, near 0: noise or swapped parts).
    pub orientation: f64,
    /// Every start of a multi-start run ([`MatchParams::starts`](super::MatchParams::starts)); empty
    /// for a single start.
    pub starts: Vec<Start>,
    /// Structural measures of the initial `C_BA`.
    pub metrics: solve::FmapMetrics,
    /// Energy terms at the solution, unweighted.
    pub energy_terms: solve::PerTerm,
    /// The weighted energy at the solution.
    pub energy: f64,
    /// Timings.
    pub times: MatchTimes,
    /// How far the final map can be trusted (computed by
    /// [`match_prepared`](super::match_prepared) and the functions built on
    /// it; `None` from a bare refinement).
    pub confidence: Option<super::Confidence>,
    /// With a second opinion ([`MatchParams::second_opinion`](super::MatchParams::second_opinion)):
    /// the map that was not kept.
    pub passed_over: Option<PassedOver>,
}

/// The map a second opinion did not keep: which pipeline made it and its
/// area distortion (above the kept map's).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct PassedOver {
    /// `learned` or `descriptors`.
    pub features: &'static str,
    /// Its refiner's name (`None`: no refinement).
    pub refiner: Option<String>,
    /// Its area distortion.
    pub area_distortion: f64,
    /// Its orientation score ([`MatchResult::orientation`]).
    pub orientation: f64,
}

/// One start of a multi-start run.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Start {
    /// Size of the initial map.
    pub k: usize,
    /// Orientation score of its final map (of its map at
    /// [`Starts::select_at`](super::Starts::select_at) when the starts stopped there).
    pub orientation: f64,
    /// Scores of that map without ground truth (unit-area shapes).
    pub quality: crate::eval::MapQuality,
    /// Its map was kept.
    pub chosen: bool,
    /// Seconds for this start (descriptors to refined map).
    pub seconds: f64,
}
