//! The evaluation protocol of shape-correspondence benchmarks (Kim et al.
//! 2011, as used by the functional-maps literature):
//!
//! For a point map `T: A → B` (a target vertex of B for every vertex of A)
//! and ground-truth pairs `(a_i, b_i)`, the error of point i is
//! `d_B(T(a_i), b_i) / sqrt(area(B))` with `d_B` the geodesic distance on
//! B. Reported: the mean, the symmetry-aware mean (per point, the minimum
//! against the left-right mirrored truth), the cumulative curve (fraction of
//! points with error ≤ t for t in [0, 0.25]) and its normalized area,
//! coverage (fraction of B's vertices hit by T) and, given the reverse map
//! as well, bijectivity.
//!
//! Distances are computed only where needed: one early-stopped propagation
//! from each distinct predicted vertex to its true target(s), in parallel —
//! never an n x n matrix. The report names the geodesic method.
//!
//! ```
//! use fmaps_eval::{evaluate, EvalParams, GroundTruth};
//! use fmaps_geodesic::ExactSolver;
//! use fmaps_shapes::grid;
//!
//! let b = grid(1.0, 1.0, 4, 4); // area 1
//! let solver = ExactSolver::new(&b)?;
//! // A map from a copy of B to B that moves every vertex one step right
//! // (the last column stays): error 0.25 on 20 of 25 points.
//! let t_ab: Vec<usize> = (0..25).map(|v| if v % 5 < 4 { v + 1 } else { v }).collect();
//! let gt = GroundTruth::new((0..25).collect(), (0..25).collect(), None)?;
//! let r = evaluate(&b, &solver, &t_ab, &gt, None, &EvalParams::default())?;
//! assert!((r.mean_error - 0.25 * 20.0 / 25.0).abs() < 1e-12);
//! assert_eq!(r.coverage, 20.0 / 25.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Features
//!
//! - `serde`: `Serialize` for the reports.
//! - `published-maps`: the benchmark's published maps read from their zip
//!   archives ([`Collection::published_maps`]; the `zip` dependency).
#![deny(missing_docs)]
#![forbid(unsafe_code)]

mod dataset;
pub mod distortion;
#[cfg(feature = "published-maps")]
mod published;
pub mod quality;

use std::collections::HashMap;
use std::time::Instant;

use fmaps_geodesic::DistanceSolver;
use fmaps_mesh_io::TriMesh;
use rayon::prelude::*;

pub use dataset::Collection;
pub use distortion::{MetricDistortion, metric_distortion};
#[cfg(feature = "published-maps")]
pub use published::PublishedMaps;
pub use quality::{MapQuality, map_quality};

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading a mesh or correspondence file failed.
    #[error(transparent)]
    Mesh(#[from] fmaps_mesh_io::Error),
    /// A geodesic computation failed.
    #[error(transparent)]
    Geodesic(#[from] fmaps_geodesic::Error),
    /// Sizes that must agree do not.
    #[error("{what}: {found} entries, expected {expected}")]
    SizeMismatch {
        /// What was compared.
        what: String,
        /// Entries found.
        found: usize,
        /// Entries expected.
        expected: usize,
    },
    /// An index is out of range.
    #[error("{what}: index {index} is out of range (size {size})")]
    OutOfRange {
        /// What was indexed.
        what: String,
        /// The index (0-based).
        index: usize,
        /// The size.
        size: usize,
    },
    /// A parameter is out of its range.
    #[error("{0}")]
    Parameter(String),
    /// The ground truth has no point: there is nothing to measure.
    #[error("the ground truth is empty: no point to measure the map at")]
    EmptyGroundTruth,
    /// A dataset file or directory is missing or malformed.
    #[error("{0}")]
    Dataset(String),
    /// A zip archive of published maps could not be read.
    #[error("{path}: {message}")]
    Zip {
        /// The archive.
        path: std::path::PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Ground-truth correspondences of a pair (A, B): point i is vertex
/// `source[i]` of A and vertex `target[i]` of B (and `target_sym[i]` for
/// the mirrored truth), all 0-based.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundTruth {
    source: Vec<usize>,
    target: Vec<usize>,
    target_sym: Option<Vec<usize>>,
}

impl GroundTruth {
    /// Checks that the lists have the same length.
    pub fn new(
        source: Vec<usize>,
        target: Vec<usize>,
        target_sym: Option<Vec<usize>>,
    ) -> Result<Self> {
        if source.is_empty() {
            return Err(Error::EmptyGroundTruth);
        }
        if source.len() != target.len() {
            return Err(Error::SizeMismatch {
                what: "ground truth target list".into(),
                found: target.len(),
                expected: source.len(),
            });
        }
        if let Some(s) = &target_sym
            && s.len() != source.len()
        {
            return Err(Error::SizeMismatch {
                what: "symmetric ground truth list".into(),
                found: s.len(),
                expected: source.len(),
            });
        }
        Ok(Self {
            source,
            target,
            target_sym,
        })
    }

    /// The points on A (0-based vertices).
    pub fn source(&self) -> &[usize] {
        &self.source
    }

    /// The points on B, line-aligned with [`GroundTruth::source`].
    pub fn target(&self) -> &[usize] {
        &self.target
    }

    /// Number of ground-truth points.
    pub fn len(&self) -> usize {
        self.source.len()
    }

    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.source.is_empty()
    }
}

/// Options of [`evaluate`].
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct EvalParams {
    /// Largest threshold of the cumulative curve (normalized error).
    pub max_threshold: f64,
    /// Number of thresholds, evenly spaced in [0, max_threshold].
    pub n_thresholds: usize,
}

impl Default for EvalParams {
    fn default() -> Self {
        Self {
            max_threshold: 0.25,
            n_thresholds: 101,
        }
    }
}

/// The evaluation of one map.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[non_exhaustive]
pub struct MapReport {
    /// Per ground-truth point, `d_B(T(a_i), b_i) / sqrt(area(B))`.
    pub errors: Vec<f64>,
    /// Per point, the minimum of the error against the truth and against
    /// the mirrored truth (when given).
    pub sym_errors: Option<Vec<f64>>,
    /// Mean of `errors` (normalized, not x100).
    pub mean_error: f64,
    /// Mean of `sym_errors`.
    pub sym_mean_error: Option<f64>,
    /// Thresholds of the cumulative curve.
    pub thresholds: Vec<f64>,
    /// Fraction of points with error ≤ each threshold.
    pub curve: Vec<f64>,
    /// Area under the curve divided by the largest threshold (in [0, 1]).
    pub auc: f64,
    /// Fraction of B's vertices that are the image of some vertex of A.
    pub coverage: f64,
    /// Fraction of A's vertices a with `T_BA(T_AB(a)) = a` (given T_BA).
    pub bijectivity: Option<f64>,
    /// The geodesic method ("exact", "dijkstra").
    pub geodesic: &'static str,
    /// Seconds spent.
    pub seconds: f64,
}

/// Evaluates the point map `t_ab` (length n_A, values < n_B) against the
/// ground truth, with distances on `target` (B) from `solver` (built on the
/// same mesh). `t_ba`, when given, adds bijectivity.
pub fn evaluate(
    target: &TriMesh,
    solver: &dyn DistanceSolver,
    t_ab: &[usize],
    gt: &GroundTruth,
    t_ba: Option<&[usize]>,
    params: &EvalParams,
) -> Result<MapReport> {
    let t0 = Instant::now();
    let n_b = target.n_vertices();
    if solver.n_vertices() != n_b {
        return Err(Error::SizeMismatch {
            what: "geodesic solver mesh".into(),
            found: solver.n_vertices(),
            expected: n_b,
        });
    }
    check_range("map T_AB", t_ab, n_b)?;
    check_range("ground truth source", &gt.source, t_ab.len())?;
    check_range("ground truth target", &gt.target, n_b)?;
    if let Some(s) = &gt.target_sym {
        check_range("symmetric ground truth target", s, n_b)?;
    }
    // Group the points by predicted vertex: one propagation from each
    // predicted vertex to all the true targets that need it.
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for i in 0..gt.len() {
        groups.entry(t_ab[gt.source[i]]).or_default().push(i);
    }
    let mut group_list: Vec<(usize, Vec<usize>)> = groups.into_iter().collect();
    group_list.sort_unstable_by_key(|g| g.0);
    let results: Vec<Vec<(usize, f64, Option<f64>)>> = group_list
        .par_iter()
        .map(|(p, idx)| {
            // Propagate until the true targets are final. A mirrored target
            // that is not final yet is farther than all of them, so its
            // tentative distance still gives the right minimum.
            let targets: Vec<usize> = idx.iter().map(|&i| gt.target[i]).collect();
            let d = solver.distances_until(&[*p], &targets)?;
            Ok(idx
                .iter()
                .map(|&i| {
                    let db = d[gt.target[i]];
                    (i, db, gt.target_sym.as_ref().map(|s| db.min(d[s[i]])))
                })
                .collect())
        })
        .collect::<Result<_>>()?;
    let scale = target.area().sqrt();
    let mut errors = vec![0.0; gt.len()];
    let mut sym_errors = gt.target_sym.as_ref().map(|_| vec![0.0; gt.len()]);
    for group in results {
        for (i, d, dmin) in group {
            errors[i] = d / scale;
            if let (Some(se), Some(dmin)) = (sym_errors.as_mut(), dmin) {
                se[i] = dmin / scale;
            }
        }
    }
    let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len().max(1) as f64;
    let thresholds: Vec<f64> = (0..params.n_thresholds)
        .map(|j| params.max_threshold * j as f64 / (params.n_thresholds.max(2) - 1) as f64)
        .collect();
    let curve = cumulative_curve(&errors, &thresholds);
    let auc = area_under(&thresholds, &curve);
    let mut hit = vec![false; n_b];
    t_ab.iter().for_each(|&v| hit[v] = true);
    let coverage = hit.iter().filter(|&&h| h).count() as f64 / n_b as f64;
    let bijectivity = match t_ba {
        Some(t_ba) => {
            if t_ba.len() != n_b {
                return Err(Error::SizeMismatch {
                    what: "map T_BA".into(),
                    found: t_ba.len(),
                    expected: n_b,
                });
            }
            check_range("map T_BA", t_ba, t_ab.len())?;
            Some(
                t_ab.iter()
                    .enumerate()
                    .filter(|&(a, &b)| t_ba[b] == a)
                    .count() as f64
                    / t_ab.len() as f64,
            )
        }
        None => None,
    };
    Ok(MapReport {
        mean_error: mean(&errors),
        sym_mean_error: sym_errors.as_deref().map(mean),
        errors,
        sym_errors,
        thresholds,
        curve,
        auc,
        coverage,
        bijectivity,
        geodesic: solver.name(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Fraction of errors at or below each threshold.
pub fn cumulative_curve(errors: &[f64], thresholds: &[f64]) -> Vec<f64> {
    let mut sorted = errors.to_vec();
    sorted.sort_by(f64::total_cmp);
    thresholds
        .iter()
        .map(|t| sorted.partition_point(|e| e <= t) as f64 / sorted.len().max(1) as f64)
        .collect()
}

/// Trapezoidal area under a curve, divided by the threshold range.
pub fn area_under(thresholds: &[f64], curve: &[f64]) -> f64 {
    let range =
        thresholds.last().copied().unwrap_or(0.0) - thresholds.first().copied().unwrap_or(0.0);
    if range <= 0.0 {
        return 0.0;
    }
    let area: f64 = thresholds
        .windows(2)
        .zip(curve.windows(2))
        .map(|(t, c)| (t[1] - t[0]) * (c[0] + c[1]) / 2.0)
        .sum();
    area / range
}

fn check_range(what: &str, v: &[usize], size: usize) -> Result<()> {
    match v.iter().find(|&&i| i >= size) {
        Some(&index) => Err(Error::OutOfRange {
            what: what.into(),
            index,
            size,
        }),
        None => Ok(()),
    }
}
