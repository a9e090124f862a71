//! The best of several refinements of one input: each refiner runs, and
//! the map that distorts the surface least ([`area_distortion`] of its
//! point map, both shapes at unit area) is kept. A map aligned the wrong
//! way round (a limb on the wrong limb, a body facing backwards) stretches
//! and squeezes the surface far more than the right one; two refiners that
//! fail on different pairs (Smooth Shells' two orientations and its
//! eight-orientation screen) make together a refiner that fails on fewer.

use std::sync::Arc;

use crate::{RefineInput, Refined, Refiner, Result, area_distortion};

/// Runs every refiner and keeps the result of least area distortion (the
/// first on a tie). Needs the shapes' geometry.
///
/// ```
/// use std::sync::Arc;
/// use fmaps_refine::{BestOf, Refiner, ZoomOut};
///
/// let best = BestOf::new(vec![Arc::new(ZoomOut::default()), Arc::new(ZoomOut::with_schedule("50:100:10")?)])?;
/// assert_eq!(best.k_needed(), 150);
/// assert!(best.name().starts_with("best of (zoomout"));
/// # Ok::<(), fmaps_refine::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct BestOf {
    refiners: Vec<Arc<dyn Refiner>>,
}

impl BestOf {
    /// The refiners, in order of preference on a tie.
    ///
    /// Errors: no refiner.
    pub fn new(refiners: Vec<Arc<dyn Refiner>>) -> Result<BestOf> {
        if refiners.is_empty() {
            return Err(crate::Error::InvalidParameter(
                "best of: at least one refiner".into(),
            ));
        }
        Ok(BestOf { refiners })
    }

    /// The refiners.
    pub fn refiners(&self) -> &[Arc<dyn Refiner>] {
        &self.refiners
    }
}

impl Refiner for BestOf {
    fn name(&self) -> String {
        let names: Vec<String> = self.refiners.iter().map(|r| r.name()).collect();
        format!("best of ({}) by area distortion", names.join(" | "))
    }

    fn k_needed(&self) -> usize {
        self.refiners
            .iter()
            .map(|r| r.k_needed())
            .max()
            .unwrap_or(0)
    }

    fn refine(&self, input: &RefineInput<'_>) -> Result<Refined> {
        let t = std::time::Instant::now();
        let (geo_a, geo_b) = input.geometry_for("best of")?;
        let mut best: Option<(f64, usize, Refined)> = None;
        let (mut searches, mut nn_seconds) = (0, 0.0);
        for (i, r) in self.refiners.iter().enumerate() {
            let out = r.refine(input)?;
            searches += out.report.nn_searches;
            nn_seconds += out.report.nn_seconds;
            // The refined map goes from B's vertices to A's.
            let score = area_distortion(
                &out.t_ba,
                geo_b.vertices,
                geo_b.faces,
                geo_a.vertices,
                geo_a.faces,
            )?;
            if best.as_ref().is_none_or(|b| score < b.0) {
                best = Some((score, i, out));
            }
        }
        let (score, i, mut out) = best.expect("BestOf::new checked there is a refiner");
        out.report.method = format!(
            "{}: kept {} (area distortion {score:.3})",
            self.name(),
            self.refiners[i].name()
        );
        out.report.nn_searches = searches;
        out.report.nn_seconds = nn_seconds;
        out.report.seconds = t.elapsed().as_secs_f64();
        Ok(out)
    }
}
