//! Metric distortion of a point map, without ground truth: how far the map
//! is from preserving distances between points spread over the whole
//! source. A map that puts a head on a foot or a front on a back
//! stretches long distances, however smooth it is locally (area and
//! conformal distortion, [`crate::map_quality`], measure faces only and
//! can stay low for a globally wrong map); an isometry, including a
//! symmetry of the shape, scores 0.
//!
//! The distances are shortest paths along the edges of each mesh (Dijkstra)
//! from samples spread by farthest-point sampling, both shapes at unit
//! area, so the score does not depend on units, and the edge graphs'
//! overestimate of the surface distance (a few percent) largely cancels
//! between the two shapes.

use fmaps_geodesic::{DijkstraSolver, DistanceSolver};
use fmaps_mesh_io::TriMesh;

use crate::Result;

/// The scores of [`metric_distortion`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MetricDistortion {
    /// `Σ |d_B(T x, T y) − d_A(x, y)| / Σ d_A(x, y)` over the pairs of
    /// samples (0: the distances between samples are preserved; an
    /// unreachable image counts its whole source distance).
    pub mean: f64,
    /// The same over the pairs of samples at least the median distance
    /// apart: the global part of the distortion.
    pub long_range: f64,
    /// Samples used.
    pub samples: usize,
}

/// Scores the map `t_ab` (for every vertex of `a`, a vertex of `b`) by the
/// distortion of distances between `samples` points of `a` (farthest-point
/// sampling from vertex 0's farthest vertex; all vertices when `a` has
/// fewer) and their images. Cost: `2 samples` Dijkstra runs.
///
/// Errors: a map of the wrong length or with an index out of range, or
/// fewer than 2 samples.
///
/// ```
/// use fmaps_eval::distortion::metric_distortion;
/// use fmaps_shapes::icosphere;
///
/// let s = icosphere(1.0, 3);
/// let id: Vec<usize> = (0..s.n_vertices()).collect();
/// assert_eq!(metric_distortion(&id, &s, &s, 32)?.mean, 0.0);
/// # Ok::<(), fmaps_eval::Error>(())
/// ```
pub fn metric_distortion(
    t_ab: &[usize],
    a: &TriMesh,
    b: &TriMesh,
    samples: usize,
) -> Result<MetricDistortion> {
    use rayon::prelude::*;
    crate::quality::check_map("T_AB", t_ab, a.n_vertices(), b.n_vertices())?;
    if samples < 2 {
        return Err(crate::Error::Parameter(format!(
            "metric distortion needs at least 2 samples, got {samples}"
        )));
    }
    let (ga, gb) = (DijkstraSolver::new(a), DijkstraSolver::new(b));
    let (sa, sb) = (unit(a), unit(b));
    let m = samples.min(a.n_vertices());
    // Farthest-point sampling; an unreached vertex (another component) is
    // the farthest of all.
    let far = |d: &[f64]| {
        (0..d.len())
            .max_by(|&i, &j| d[i].total_cmp(&d[j]).then(j.cmp(&i)))
            .unwrap_or(0)
    };
    let mut chosen = vec![far(&ga.distances(&[0])?)];
    let mut rows = vec![ga.distances(&chosen)?];
    let mut nearest = rows[0].clone();
    while chosen.len() < m {
        let next = far(&nearest);
        let d = ga.distances(&[next])?;
        nearest.iter_mut().zip(&d).for_each(|(n, x)| *n = n.min(*x));
        chosen.push(next);
        rows.push(d);
    }
    let images: Vec<Vec<f64>> = chosen
        .par_iter()
        .map(|&s| gb.distances(&[t_ab[s]]))
        .collect::<std::result::Result<_, _>>()?;
    let mut pairs = Vec::with_capacity(m * (m - 1) / 2);
    for i in 0..m {
        for j in i + 1..m {
            let da = rows[i][chosen[j]] / sa;
            let db = images[i][t_ab[chosen[j]]] / sb;
            if da.is_finite() {
                let gap = if db.is_finite() { (da - db).abs() } else { da };
                pairs.push((da, gap));
            }
        }
    }
    let ratio = |p: &[(f64, f64)]| {
        let total: f64 = p.iter().map(|x| x.0).sum();
        if total > 0.0 {
            p.iter().map(|x| x.1).sum::<f64>() / total
        } else {
            0.0
        }
    };
    let mean = ratio(&pairs);
    let mut by_distance: Vec<f64> = pairs.iter().map(|p| p.0).collect();
    by_distance.sort_by(f64::total_cmp);
    let median = by_distance
        .get(by_distance.len() / 2)
        .copied()
        .unwrap_or(0.0);
    let long: Vec<(f64, f64)> = pairs.into_iter().filter(|p| p.0 >= median).collect();
    Ok(MetricDistortion {
        mean,
        long_range: ratio(&long),
        samples: m,
    })
}

/// √area, the unit of distances (1 for an empty mesh).
fn unit(m: &TriMesh) -> f64 {
    let a = m.area().sqrt();
    if a > 0.0 { a } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fmaps_shapes::{grid, icosphere};

    #[test]
    fn isometries_score_zero_whatever_the_units() {
        let g = grid(2.0, 1.0, 12, 6);
        let n = g.n_vertices();
        let id: Vec<usize> = (0..n).collect();
        let d = metric_distortion(&id, &g, &g, 20).unwrap();
        assert_eq!((d.mean, d.long_range, d.samples), (0.0, 0.0, 20));
        // The half turn about the grid's centre is an isometry of its edge
        // graph (diagonals go to diagonals): vertex v -> n - 1 - v.
        let turn: Vec<usize> = (0..n).map(|v| n - 1 - v).collect();
        let d = metric_distortion(&turn, &g, &g, 20).unwrap();
        assert!(d.mean < 1e-12 && d.long_range < 1e-12, "{d:?}");
        // A copy a thousand times larger: the same at unit area.
        let (v, f) = g.clone().into_parts();
        let big = TriMesh::new(v.iter().map(|p| p.map(|x| 1e3 * x)).collect(), f).unwrap();
        let d = metric_distortion(&id, &g, &big, 20).unwrap();
        assert!(d.mean < 1e-12, "{d:?}");
    }

    #[test]
    fn a_stretch_scores_its_change_of_distances_and_a_scramble_scores_high() {
        // Stretched x2 along x and rescaled to unit area: distances along x
        // grow by √2, along y shrink by 1/√2, so the distortion lies
        // between the two ratios' gaps (1 − 1/√2 = 0.29 and √2 − 1 = 0.41).
        let g = grid(1.0, 1.0, 10, 10);
        let n = g.n_vertices();
        let (v, f) = g.clone().into_parts();
        let wide = TriMesh::new(v.iter().map(|p| [2.0 * p[0], p[1], p[2]]).collect(), f).unwrap();
        let id: Vec<usize> = (0..n).collect();
        let d = metric_distortion(&id, &g, &wide, 30).unwrap();
        assert!(d.mean > 0.1 && d.mean < 0.42, "{d:?}");
        // A pseudo-random permutation: image distances unrelated to the
        // source's (on a sphere their gap is about half the mean distance).
        let s = icosphere(1.0, 3);
        let n = s.n_vertices();
        let scramble: Vec<usize> = (0..n).map(|i| (i * 7919 + 13) % n).collect();
        let d = metric_distortion(&scramble, &s, &s, 30).unwrap();
        assert!(d.mean > 0.3 && d.long_range > 0.25, "{d:?}");
        // A constant map: every distance vanishes, distortion 1.
        let d = metric_distortion(&vec![5; n], &s, &s, 30).unwrap();
        assert!((d.mean - 1.0).abs() < 1e-12, "{d:?}");
    }

    #[test]
    fn bad_maps_and_too_few_samples_are_errors() {
        let s = icosphere(1.0, 1);
        let n = s.n_vertices();
        assert!(metric_distortion(&vec![0; n - 1], &s, &s, 8).is_err());
        assert!(metric_distortion(&vec![n; n], &s, &s, 8).is_err());
        assert!(metric_distortion(&vec![0; n], &s, &s, 1).is_err());
        // More samples than vertices: every vertex once.
        let id: Vec<usize> = (0..n).collect();
        assert_eq!(metric_distortion(&id, &s, &s, 10 * n).unwrap().samples, n);
    }
}
