//! How far a map can be trusted, without ground truth: two distortions of
//! the final map and a warning when either is above its threshold,
//! measured on the benchmarks (`cargo xtask confidence`;
//! docs/benchmarks.md, section Confidence):
//!
//! - the metric distortion ([`crate::eval::metric_distortion`]) sees the
//!   global misalignments of a map that is noisy or torn (a head on a
//!   foot, a front on a back): distances between far-apart points change;
//! - the area distortion ([`crate::refine::area_distortion`]) sees those
//!   of a map that is smooth but aligned the wrong way round (Smooth
//!   Shells' failures between different builds: a limb on the wrong limb
//!   keeps distances about as well as the right one, but stretches and
//!   squeezes the surface).

use std::time::Instant;

use fmaps_mesh_io::TriMesh;

use super::{MatchError, PreparedShape};

/// The confidence of a map (see the module's documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Confidence {
    /// Metric distortion of the map: `Σ |d_B(T x, T y) − d_A(x, y)| /
    /// Σ d_A(x, y)` over pairs of [`Confidence::samples_for`] points spread over
    /// the source, edge-path distances at unit area (0: distances kept, as
    /// by an isometry or a symmetry; about 0.1 for a right map between
    /// poses of one body, 0.15-0.3 between different bodies, 0.4-0.6 for an
    /// unrelated map).
    pub distortion: f64,
    /// The same over the samples at least the median distance apart.
    pub long_range: f64,
    /// Area distortion of the map: the area-weighted mean of `|ln(image
    /// area / face area)|`, both shapes at unit area (about 0.3-0.5 for a
    /// right map, 0.5-0.75 for one aligned the wrong way round between
    /// different builds).
    pub area_distortion: f64,
    /// `distortion` is above [`Confidence::WARN_ABOVE`] or
    /// `area_distortion` above [`Confidence::WARN_AREA_ABOVE`]: the map is
    /// likely globally wrong.
    pub likely_wrong: bool,
    /// Seconds to compute it.
    pub seconds: f64,
}

impl Confidence {
    /// Samples of the metric distortion (fewer on large meshes: see
    /// [`Confidence::samples_for`]).
    pub const SAMPLES: usize = 48;
    /// Above this metric distortion a map is reported as likely wrong.
    pub const WARN_ABOVE: f64 = 0.3;
    /// Above this area distortion a map is reported as likely wrong.
    pub const WARN_AREA_ABOVE: f64 = 0.55;

    /// Samples for a source of `n` vertices: [`Confidence::SAMPLES`] up to
    /// 100,000 vertices, then fewer in proportion (at least 16), so that
    /// the `2 samples` Dijkstra runs stay a small part of a match.
    pub fn samples_for(n: usize) -> usize {
        if n <= 100_000 {
            Self::SAMPLES
        } else {
            (Self::SAMPLES * 100_000 / n).max(16)
        }
    }

    /// The confidence of `t_ab` between two prepared shapes.
    pub fn of_map(
        t_ab: &[usize],
        a: &PreparedShape,
        b: &PreparedShape,
    ) -> Result<Confidence, MatchError> {
        let t = Instant::now();
        let mesh = |s: &PreparedShape| {
            TriMesh::new(s.vertices.clone(), s.faces.clone())
                .map_err(|e| MatchError::InvalidParameter(format!("confidence: {e}")))
        };
        let samples = Self::samples_for(a.vertices.len());
        let d = crate::eval::metric_distortion(t_ab, &mesh(a)?, &mesh(b)?, samples)
            .map_err(|e| MatchError::InvalidParameter(format!("confidence: {e}")))?;
        let area =
            crate::refine::area_distortion(t_ab, &a.vertices, &a.faces, &b.vertices, &b.faces)?;
        Ok(Confidence {
            distortion: d.mean,
            long_range: d.long_range,
            area_distortion: area,
            likely_wrong: d.mean > Self::WARN_ABOVE || area > Self::WARN_AREA_ABOVE,
            seconds: t.elapsed().as_secs_f64(),
        })
    }

    /// What to try when the map is likely wrong (`None` otherwise).
    pub fn advice(&self) -> Option<&'static str> {
        self.likely_wrong.then_some(
            "the map distorts distances or areas as a globally misaligned map does; for shapes of different proportions try the second opinion (both Smooth Shells settings), or give 3-5 landmark pairs",
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{MatchParams, prepare};

    /// The true map of the built-in pair (a pose change) keeps distances;
    /// the same map with its halves swapped (the first source vertices sent
    /// where the last ones go) does not, and is reported.
    #[test]
    fn a_true_map_is_trusted_and_a_torn_one_is_not() {
        let pair = fmaps_shapes::creature_pair(3);
        let params = MatchParams::default();
        let a = prepare(&pair.source, &params).unwrap();
        let b = prepare(&pair.target, &params).unwrap();
        let good = Confidence::of_map(&pair.truth, &a, &b).unwrap();
        assert!(good.distortion < 0.1, "{good:?}");
        assert!(!good.likely_wrong && good.advice().is_none());
        let n = pair.truth.len();
        let torn: Vec<usize> = (0..n).map(|i| pair.truth[(i + n / 2) % n]).collect();
        let bad = Confidence::of_map(&torn, &a, &b).unwrap();
        assert!(bad.likely_wrong && bad.advice().is_some(), "{bad:?}");
        // Fewer samples on large meshes, never fewer than 16.
        let ns = [5_000, 100_000, 200_000, 1_000_000].map(Confidence::samples_for);
        assert_eq!(ns, [48, 48, 24, 16]);
        // And the pipeline reports the confidence of its own map.
        let r = crate::pipeline::match_prepared(&a, &b, &params).unwrap();
        let own = r.confidence.unwrap();
        assert_eq!(
            own.distortion,
            Confidence::of_map(&r.t_ab, &a, &b).unwrap().distortion
        );
    }
}
