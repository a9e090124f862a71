//! The pipeline's parameters, one group per stage: descriptors, energy,
//! refinement, starts.

use fmaps_solve::EnergyParams;

use super::error::MatchError;
use super::features::LearnedFeatures;
use super::refinement::{
    DEFAULT_K, RefineOptions, Refinement, RefinerKind, default_select_at, default_starts,
    named_refinement,
};
pub use crate::descriptors::DescriptorKind;
use crate::refine::starts::StartSelection;
use crate::{SpectrumParams, descriptors};

/// Options of the pipeline. [`MatchParams::default`] is what `fmaps
/// match` runs without flags on meshes of more than 200 vertices (Smooth
/// Shells after the literature's standard descriptor map);
/// [`MatchParams::for_meshes`] is what it runs on meshes of any size.
///
/// ```
/// use fmaps::pipeline::{MatchParams, RefineOptions, RefinerKind};
///
/// let mut params = MatchParams::default();
/// params.descriptors.n = 60;
/// params.energy.weights.orient = 0.0;
/// params.set_refinement(RefinerKind::Zoomout, &RefineOptions::default())?;
/// assert_eq!(params.starts.sizes, [8, 20]);
/// assert_eq!(params.k_process_needed(), 150);
/// # Ok::<(), fmaps::pipeline::MatchError>(())
/// ```
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct MatchParams {
    /// Eigenpairs computed per shape.
    pub k_process: usize,
    /// Size of the functional map (k x k).
    pub k: usize,
    /// Eigensolver options.
    pub spectrum: SpectrumParams,
    /// Scale each shape to unit area before anything else (on by
    /// default): the eigenvalues, the descriptors' energies, the Laplacian
    /// mask and every refiner then see the same numbers whatever the
    /// mesh's units (millimetres, metres), and the two shapes of a pair
    /// may come in different units. `C_BA` is then between the bases of
    /// the unit-area shapes. Off: the shapes as given (only for shapes
    /// known to share units and a comparable size).
    pub area_normalize: bool,
    /// The descriptors the map is solved from.
    pub descriptors: DescriptorOptions,
    /// Where the per-vertex features come from: the descriptors (default)
    /// or a learned feature extractor, which replaces the descriptor
    /// solve (see [`Features::Learned`]).
    pub features: Features,
    /// The energy's terms and weights (descriptor preservation, Laplacian
    /// commutativity, descriptor commutativity, orientation).
    pub energy: EnergyParams,
    /// Convert with the adjoint (`T_AB(x) = argmin_y ‖Φ_B(y) − C_BAᵀ Φ_A(x)‖`).
    pub adjoint: bool,
    /// Refinement of the initial map.
    pub refinement: Refinement,
    /// Multi-start: further initial sizes and how one final map is kept.
    pub starts: Starts,
    /// A second pipeline run on the same pair (the descriptor pipeline
    /// beside learned features: [`MatchParams::with_axiomatic_opinion`]);
    /// the map of least area distortion of the two is kept
    /// ([`MatchResult::passed_over`](super::MatchResult::passed_over) says
    /// which). The shapes must be prepared for both (`k_process` and
    /// features: prepare with `self`, whose `k_process` covers both).
    pub second_opinion: Option<Box<MatchParams>>,
}

/// The features a map is computed from.
#[derive(Debug, Clone, Default)]
#[non_exhaustive]
// Parameters are built once per run: the learned variant's size (its
// recipe) costs nothing worth a box in every user's match.
#[allow(clippy::large_enum_variant)]
pub enum Features {
    /// Spectral descriptors ([`MatchParams::descriptors`]) and the
    /// functional-map energy ([`MatchParams::energy`]), from several
    /// starts when [`MatchParams::starts`] asks.
    #[default]
    Descriptors,
    /// A learned feature extractor ([`LearnedFeatures`]): the initial map
    /// comes from its features (the descriptors, the energy and the
    /// starts are not used), then the refinement runs as usual. Needs the
    /// area normalisation (the networks see unit-area shapes).
    Learned(LearnedFeatures),
}

/// The descriptors stage: WKS or HKS from the first eigenpairs, landmark
/// descriptors, every column at unit L² norm.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct DescriptorOptions {
    /// Eigenpairs the descriptors are built from (128).
    pub eigenpairs: usize,
    /// Descriptor family (WKS).
    pub kind: DescriptorKind,
    /// Samples (energies or times) per family (100).
    pub n: usize,
    /// Keep every `subsample`-th descriptor column (1 = all).
    pub subsample: usize,
    /// Landmark pairs (source vertex, target vertex), 0-based: adds
    /// landmark descriptors.
    pub landmarks: Vec<(usize, usize)>,
    /// Rotate the descriptors of both shapes to an orthonormal basis of
    /// their span and drop directions below rounding level
    /// ([`fmaps_solve::compress_descriptors`]); the energy is unchanged to
    /// rounding. On by default.
    pub compress: bool,
    /// The user's own per-vertex descriptors of A and B (n_A x p and
    /// n_B x p, column q of both the same descriptor), used instead of
    /// the spectral ones (the family, samples and landmarks then do not
    /// apply). `None`: the pipeline computes them.
    pub given: Option<std::sync::Arc<(nalgebra::DMatrix<f64>, nalgebra::DMatrix<f64>)>>,
}

impl Default for DescriptorOptions {
    fn default() -> Self {
        let d = descriptors::DescriptorParams::default();
        DescriptorOptions {
            eigenpairs: 128,
            kind: d.kind,
            n: d.n,
            subsample: d.subsample,
            landmarks: Vec::new(),
            compress: true,
            given: None,
        }
    }
}

impl DescriptorOptions {
    /// The descriptor crate's parameters (family, samples, sub-sampling).
    pub fn params(&self) -> descriptors::DescriptorParams {
        let mut p = descriptors::DescriptorParams::default();
        p.kind = self.kind;
        p.n = self.n;
        p.subsample = self.subsample;
        p
    }
}

/// Multi-start: the pipeline is run once per initial size from the same
/// descriptors (all sizes in parallel, or with
/// [`restart_below`](Self::restart_below) `k` first; a ZoomOut starts
/// from the smaller of the size and its `k_start`), and one final map is
/// kept by [`select`](Self::select) ([`crate::refine::starts`]).
#[derive(Debug, Clone, PartialEq, Default)]
#[non_exhaustive]
pub struct Starts {
    /// Further sizes of the initial map. Empty: a single start at `k`.
    pub sizes: Vec<usize>,
    /// Which final map is kept.
    pub select: StartSelection,
    /// Try the further starts only when the first start's (size `k`)
    /// orientation score is below this value (above its negative for
    /// orientation-reversing maps), so well-oriented pairs cost one start.
    /// `None`: always run every start.
    pub restart_below: Option<f64>,
    /// With a ZoomOut refinement: every start's ZoomOut stops at this
    /// size (when below its final size), the start is chosen there, and
    /// only the kept one goes on to the final size (the rest of its
    /// schedule). `None`: every start runs to the end.
    pub select_at: Option<usize>,
}

impl Default for MatchParams {
    fn default() -> Self {
        let mut p = MatchParams {
            k_process: 0,
            k: DEFAULT_K,
            spectrum: SpectrumParams::default(),
            area_normalize: true,
            descriptors: DescriptorOptions::default(),
            features: Features::Descriptors,
            energy: EnergyParams::default(),
            adjoint: false,
            refinement: Refinement::recommended(),
            starts: Starts::default(),
            second_opinion: None,
        };
        p.k_process = p.k_process_needed();
        p
    }
}

impl MatchParams {
    /// [`MatchParams::default`] without refinement: the literature's
    /// standard automatic pipeline (pyFM's initial map) on 200 eigenpairs,
    /// the building block the refiners start from.
    pub fn unrefined() -> MatchParams {
        MatchParams {
            refinement: Refinement::None,
            ..MatchParams::default()
        }
    }

    /// What `fmaps match` runs without flags on meshes of `n_a` and `n_b`
    /// vertices: [`MatchParams::default`] with the refinement
    /// [`RefinerKind::default_for`] the smaller mesh (none on meshes too
    /// small for Smooth Shells' basis) and the eigenpairs it needs.
    pub fn for_meshes(n_a: usize, n_b: usize) -> MatchParams {
        let mut p = MatchParams::default();
        if RefinerKind::default_for(n_a.min(n_b)) == RefinerKind::None {
            p.refinement = Refinement::None;
            p.k_process = p.k_process_needed();
        }
        p
    }

    /// What `fmaps match --features learned` runs on meshes of `n_a` and
    /// `n_b` vertices: `learned`'s point map pulled back at size
    /// [`LearnedFeatures::DEFAULT_K`] and refined by ZoomOut on
    /// [`LearnedFeatures::default_schedule`] (no refinement on meshes too
    /// small for one, as [`MatchParams::for_meshes`]); one start.
    pub fn learned(
        n_a: usize,
        n_b: usize,
        learned: LearnedFeatures,
    ) -> Result<MatchParams, MatchError> {
        let mut p = MatchParams::for_meshes(n_a, n_b);
        if RefinerKind::default_for(n_a.min(n_b)) != RefinerKind::None {
            p.k = LearnedFeatures::DEFAULT_K;
            let options = RefineOptions {
                schedule: Some(LearnedFeatures::default_schedule(p.k)),
                ..RefineOptions::for_map_size(p.k)
            };
            p.set_refinement(RefinerKind::Zoomout, &options)?;
        }
        p.starts.sizes.clear();
        p.features = Features::Learned(learned);
        p.k_process = p.k_process.max(p.k_process_needed());
        Ok(p)
    }

    /// With the default descriptor pipeline on meshes of `n_a` and `n_b`
    /// vertices as a second opinion (Smooth Shells, itself with both its
    /// settings: [`RefineOptions::second_opinion`]): the map of least area
    /// distortion of this pipeline's and that one's is kept. `k_process`
    /// grows to what both need.
    pub fn with_axiomatic_opinion(mut self, n_a: usize, n_b: usize) -> Result<Self, MatchError> {
        let mut other = MatchParams::for_meshes(n_a, n_b);
        let kind = RefinerKind::default_for(n_a.min(n_b));
        if kind != RefinerKind::None {
            let options = RefineOptions {
                second_opinion: true,
                ..RefineOptions::for_map_size(other.k)
            };
            other.set_refinement(kind, &options)?;
        }
        other.k_process = other.k_process.max(other.k_process_needed());
        self.k_process = self.k_process.max(other.k_process);
        other.k_process = self.k_process;
        other.spectrum = self.spectrum.clone();
        other.area_normalize = self.area_normalize;
        self.second_opinion = Some(Box::new(other));
        Ok(self)
    }

    /// Sets the refinement `kind` built from `options`
    /// ([`named_refinement`]) with the starts `fmaps match` runs it from:
    /// [`default_starts`] within `k_process` (or the refinement's need,
    /// when larger), kept by area distortion, and for ZoomOut schedules
    /// the selection at [`default_select_at`].
    ///
    /// Errors: a schedule that does not parse or starts above `options.k`.
    pub fn set_refinement(
        &mut self,
        kind: RefinerKind,
        options: &RefineOptions,
    ) -> Result<(), MatchError> {
        self.refinement = named_refinement(kind, options)?;
        self.starts.sizes = default_starts(kind, self.k_process.max(self.refinement.k_needed()));
        self.starts.select_at = default_select_at(&self.refinement);
        Ok(())
    }

    /// The eigenpairs this pipeline uses: the largest of the descriptors'
    /// eigenpairs (the learned features' with [`Features::Learned`]), `k`, the starts and the refinement's need
    /// ([`Refinement::k_needed`]). `fmaps match` computes this many when
    /// `--k-process` is not given (200 for the default Smooth Shells, 150
    /// for ZoomOut 50 → 150, 128 without refinement): eigenpairs beyond it
    /// would never be read. On every 10th FAUST and TOSCA test pair the
    /// three-start ZoomOut gives the same mean errors from 150 eigenpairs
    /// as from 200.
    pub fn k_process_needed(&self) -> usize {
        let starts = self.starts.sizes.iter().copied().max().unwrap_or(0);
        let features = match &self.features {
            Features::Descriptors => self.descriptors.eigenpairs,
            Features::Learned(l) => l.eigenpairs(),
        };
        features
            .max(self.k)
            .max(starts)
            .max(self.refinement.k_needed())
    }

    /// The size at which a multi-start run stops its starts
    /// ([`Starts::select_at`]): `Some` only with starts, a ZoomOut
    /// refinement and a stop below its final size.
    pub fn starts_stop(&self) -> Option<usize> {
        match (&self.refinement, self.starts.select_at) {
            (Refinement::ZoomOut { zoomout, .. }, Some(s))
                if !self.starts.sizes.is_empty() && s < zoomout.k_final =>
            {
                Some(s)
            }
            _ => None,
        }
    }

    pub(super) fn check(&self) -> Result<(), MatchError> {
        let bad = |m: String| Err(MatchError::InvalidParameter(m));
        if let Some(other) = &self.second_opinion {
            if other.k_process != self.k_process || other.area_normalize != self.area_normalize {
                return bad(format!(
                    "the second opinion's k_process ({}) and area normalisation ({}) must be this pipeline's ({}, {}): both run on the same prepared shapes",
                    other.k_process, other.area_normalize, self.k_process, self.area_normalize
                ));
            }
            other.check()?;
        }
        let d = &self.descriptors;
        if self.k == 0 || self.k > self.k_process {
            return bad(format!(
                "the map size k = {} must be in 1..=k_process ({})",
                self.k, self.k_process
            ));
        }
        let descriptors = matches!(self.features, Features::Descriptors);
        if descriptors && (d.eigenpairs < 2 || d.eigenpairs > self.k_process) {
            return bad(format!(
                "the descriptors' eigenpairs ({}) must be in 2..=k_process ({})",
                d.eigenpairs, self.k_process
            ));
        }
        if let Some(&s) = self
            .starts
            .sizes
            .iter()
            .find(|&&s| s == 0 || s > self.k_process)
        {
            return bad(format!(
                "the start size {s} must be in 1..=k_process ({})",
                self.k_process
            ));
        }
        if d.n == 0 || d.subsample == 0 {
            return bad("the descriptor samples and subsample must be positive".into());
        }
        // WKS and HKS samples are combinations of the eigenpairs'
        // functions φ_i²: far more samples than that only repeat them.
        let most = MAX_DESCR_PER_EIGENPAIR
            .saturating_mul(d.eigenpairs)
            .max(MAX_DESCR_ANY);
        if d.n > most {
            return bad(format!(
                "{} descriptor samples is more than {most} (the larger of {MAX_DESCR_ANY} and {MAX_DESCR_PER_EIGENPAIR} x {} eigenpairs): the descriptors are combinations of the {} functions φ_i², more samples only repeat them",
                d.n, d.eigenpairs, d.eigenpairs
            ));
        }
        if let Refinement::ZoomOut { zoomout, .. } = &self.refinement
            && zoomout.subsample.is_some()
        {
            return bad(
                "Refinement::ZoomOut samples the shapes itself: set `samples`, not `zoomout.subsample`"
                    .into(),
            );
        }
        if self.refinement.k_needed() > self.k_process {
            return bad(format!(
                "the refinement needs {} eigenpairs, more than k_process = {}",
                self.refinement.k_needed(),
                self.k_process
            ));
        }
        if let Features::Learned(l) = &self.features {
            if !self.area_normalize {
                return bad(
                    "learned features need the area normalisation: the networks are trained on unit-area shapes"
                        .into(),
                );
            }
            if !d.landmarks.is_empty() {
                return bad(
                    "landmarks are descriptors: the learned features take none (match with descriptors, or refine the learned map)"
                        .into(),
                );
            }
            let needed = l.eigenpairs();
            if needed > self.k_process {
                return bad(format!(
                    "the learned features need {needed} eigenpairs (the model's and the adaptation's), more than k_process = {}",
                    self.k_process
                ));
            }
        }
        let w = self.energy.weights.as_array();
        if w.iter().any(|x| !x.is_finite() || *x < 0.0) || w.iter().sum::<f64>() <= 0.0 {
            return bad(format!(
                "weights must be >= 0 with a positive sum, got {w:?}"
            ));
        }
        Ok(())
    }
}

/// Descriptor samples allowed per eigenpair they are built from, beyond
/// [`MAX_DESCR_ANY`].
const MAX_DESCR_PER_EIGENPAIR: usize = 4;

/// Descriptor samples always allowed, whatever the number of eigenpairs.
const MAX_DESCR_ANY: usize = 1000;
