//! Multi-start refinement: the same refiner run from initial maps of
//! several sizes, one final map kept by a score that needs no ground
//! truth. Small initial maps have fewer degrees of freedom for swapping
//! parts (a left and a right limb), large ones resolve more detail; the
//! distortion (or orientation) of each refined map tells which start
//! converged to the right branch.
//!
//! ```
//! use fmaps_refine::starts::{StartScores, StartSelection, best_start, start_sizes};
//!
//! assert_eq!(start_sizes(50, &[8, 20, 50]), vec![50, 8, 20]);
//! let scores = [
//!     StartScores { orientation: 0.9, area_distortion: 0.40, conformal_distortion: 2.1 },
//!     StartScores { orientation: 0.7, area_distortion: 0.25, conformal_distortion: 2.5 },
//! ];
//! assert_eq!(best_start(&scores, StartSelection::Area, false), Some(1));
//! assert_eq!(best_start(&scores, StartSelection::Orientation, false), Some(0));
//! assert_eq!(best_start(&scores, StartSelection::Conformal, false), Some(0));
//! ```

use crate::{RefineReport, ZoomOut};

/// How a multi-start run picks its final map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StartSelection {
    /// The highest [orientation score](crate::orientation_score) (lowest
    /// when looking for orientation-reversing maps).
    Orientation,
    /// The lowest conformal distortion (area-weighted MIPS energy of the
    /// map's affine maps between triangles): a map that swaps or folds
    /// parts shears the triangles at every seam.
    Conformal,
    /// The lowest area distortion (area-weighted `|ln(image area / area)|`
    /// over the triangles, both shapes at unit area): a map that sends a
    /// part to the wrong one stretches or shrinks it. The default: closest
    /// to the best start on every collection measured.
    #[default]
    Area,
}

/// The scores of one start's map, none of which needs ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartScores {
    /// [`crate::orientation_score`]: near 1 preserved, near −1 mirrored.
    pub orientation: f64,
    /// Area-weighted `|ln(image area / area)|` over the triangles.
    pub area_distortion: f64,
    /// Area-weighted MIPS energy of the map's affine maps.
    pub conformal_distortion: f64,
}

impl StartSelection {
    /// The cost of a start under this selection (lower is better);
    /// `reversing`: the maps sought reverse orientation.
    pub fn cost(self, scores: &StartScores, reversing: bool) -> f64 {
        let sign = if reversing { -1.0 } else { 1.0 };
        match self {
            StartSelection::Orientation => -sign * scores.orientation,
            StartSelection::Conformal => scores.conformal_distortion,
            StartSelection::Area => scores.area_distortion,
        }
    }
}

/// The start of lowest [`StartSelection::cost`] (the first of equal
/// ones); `None` for no starts.
pub fn best_start(
    scores: &[StartScores],
    selection: StartSelection,
    reversing: bool,
) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, s) in scores.iter().enumerate() {
        let c = selection.cost(s, reversing);
        if best.is_none_or(|(_, b)| c < b) {
            best = Some((i, c));
        }
    }
    best.map(|(i, _)| i)
}

/// The sizes a multi-start run tries: `k` first, then the further sizes
/// in their order, each once.
pub fn start_sizes(k: usize, further: &[usize]) -> Vec<usize> {
    let mut sizes = vec![k];
    for &s in further {
        if !sizes.contains(&s) {
            sizes.push(s);
        }
    }
    sizes
}

/// Whether a first start whose map has orientation score `orientation`
/// is good enough to skip the further starts (`threshold`: the score it
/// must reach, its negative when `reversing`).
pub fn first_start_suffices(orientation: f64, threshold: f64, reversing: bool) -> bool {
    let sign = if reversing { -1.0 } else { 1.0 };
    sign * orientation >= threshold
}

impl ZoomOut {
    /// This ZoomOut for a start of size `k`: from `min(k_start, k)`; with
    /// `stop`, ending there (its map only scored: no iterations on every
    /// vertex), for [`continued_from`](Self::continued_from) to finish
    /// the kept start.
    pub fn for_start(&self, k: usize, stop: Option<usize>) -> ZoomOut {
        let mut z = ZoomOut {
            k_start: self.k_start.min(k),
            ..self.clone()
        };
        if let Some(s) = stop {
            z.k_final = s;
            z.k_start = z.k_start.min(s);
            z.full_iterations = 0;
        }
        z
    }

    /// The rest of this ZoomOut's schedule from size `s` on (after a
    /// start stopped there by [`for_start`](Self::for_start)): the same
    /// iterations as without the stop when the start's sizes pass through
    /// `s`.
    pub fn continued_from(&self, s: usize) -> ZoomOut {
        ZoomOut {
            k_start: s,
            ..self.clone()
        }
    }
}

impl RefineReport {
    /// One report for a refinement run in two parts, `first` then `self`
    /// (a kept start continued): the iterations, searches and seconds of
    /// both.
    pub fn continuing(mut self, first: RefineReport) -> RefineReport {
        self.method = format!("{}, kept start continued {}", first.method, self.method);
        let mut its = first.iterations;
        its.append(&mut self.iterations);
        self.iterations = its;
        self.nn_searches += first.nn_searches;
        self.nn_seconds += first.nn_seconds;
        self.seconds += first.seconds;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(orientation: f64, area: f64, conformal: f64) -> StartScores {
        StartScores {
            orientation,
            area_distortion: area,
            conformal_distortion: conformal,
        }
    }

    /// Each selection minimises its own score; orientation flips its sign
    /// for reversing maps; ties keep the first start.
    #[test]
    fn each_selection_picks_its_best_start() {
        let scores = [s(0.2, 0.5, 3.0), s(-0.8, 0.3, 4.0), s(0.6, 0.3, 2.0)];
        assert_eq!(best_start(&scores, StartSelection::Area, false), Some(1));
        assert_eq!(
            best_start(&scores, StartSelection::Conformal, false),
            Some(2)
        );
        assert_eq!(
            best_start(&scores, StartSelection::Orientation, false),
            Some(2)
        );
        assert_eq!(
            best_start(&scores, StartSelection::Orientation, true),
            Some(1)
        );
        assert_eq!(best_start(&[], StartSelection::Area, false), None);
        assert!(first_start_suffices(0.6, 0.5, false));
        assert!(!first_start_suffices(0.6, 0.5, true));
        assert!(first_start_suffices(-0.6, 0.5, true));
    }

    /// A start stopped at `s` and continued from `s` runs the sizes of
    /// the full schedule when they pass through `s`.
    #[test]
    fn a_stopped_start_continues_on_the_same_schedule() {
        let z = ZoomOut::default();
        let first = z.for_start(20, Some(100));
        assert_eq!((first.k_start, first.k_final), (20, 100));
        assert_eq!(first.full_iterations, 0);
        let mut both = first.schedule();
        both.extend(z.continued_from(100).schedule());
        assert_eq!(both, z.for_start(20, None).schedule());
        assert_eq!(z.for_start(8, None).k_start, 8);
        assert_eq!(z.for_start(80, None).k_start, z.k_start);
    }
}
