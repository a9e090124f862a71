//! The refinement stage's choices: the [`Refinement`] the pipeline runs,
//! the refinements by name (as `fmaps match --refine NAME`, `fmaps
//! refine` and the Python package name them) and the policy of what runs
//! without a name: one place, so every front end builds the same refiner
//! from the same options and gets the same map.

use std::sync::Arc;

use super::error::MatchError;
use crate::refine::{self, Icp, Refiner, ZoomOut};

/// The refinement stage of the pipeline.
#[derive(Clone, Default)]
pub enum Refinement {
    /// The initial map as solved.
    #[default]
    None,
    /// Spectral ICP at the map's size.
    Icp(refine::Icp),
    /// ZoomOut, its iterations optionally on farthest-point samples.
    ZoomOut {
        /// Schedule and variants (its `subsample` must stay `None`: the
        /// pipeline samples the shapes itself, see `samples`).
        zoomout: refine::ZoomOut,
        /// Run the iterations on this many farthest points per shape
        /// (Euclidean farthest point sampling from vertex 0); `None`: all
        /// vertices.
        samples: Option<usize>,
    },
    /// Any [`Refiner`], given `C_BA` between the bases of the target and
    /// the source (the pipeline's map is `T_AB`, so its refiner's "A" is
    /// the target shape: see [`refine_result`](super::refine_result)).
    Custom(Arc<dyn Refiner>),
}

impl std::fmt::Debug for Refinement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refinement::None => f.write_str("None"),
            Refinement::Icp(icp) => f.debug_tuple("Icp").field(icp).finish(),
            Refinement::ZoomOut { zoomout, samples } => f
                .debug_struct("ZoomOut")
                .field("zoomout", zoomout)
                .field("samples", samples)
                .finish(),
            Refinement::Custom(r) => f.debug_tuple("Custom").field(r).finish(),
        }
    }
}

impl Refinement {
    /// ZoomOut with a schedule and no sub-sampling.
    pub fn zoomout(k_start: usize, k_final: usize, step: usize) -> Self {
        Refinement::ZoomOut {
            zoomout: refine::ZoomOut {
                k_start,
                k_final,
                step,
                ..refine::ZoomOut::default()
            },
            samples: None,
        }
    }

    /// The refinement `fmaps match` runs when no refinement is asked for:
    /// Smooth Shells ([`refine::SmoothShells::default`]), chosen by
    /// measurement as the most accurate on every collection (near-isometric
    /// and non-isometric; docs/benchmarks.md has the errors and times). It
    /// needs 200 eigenpairs per shape, so meshes of more than 200
    /// vertices ([`RefinerKind::default_for`] keeps the initial map on
    /// smaller ones).
    pub fn recommended() -> Self {
        Refinement::Custom(Arc::new(refine::SmoothShells::default()))
    }

    /// ZoomOut with [`refine::ZoomOut::default`]'s schedule (50 → 150 in
    /// steps of 5, as pyFM users run it), no sub-sampling.
    pub fn default_zoomout() -> Self {
        Refinement::ZoomOut {
            zoomout: refine::ZoomOut::default(),
            samples: None,
        }
    }

    /// The largest basis size the refinement needs.
    pub fn k_needed(&self) -> usize {
        match self {
            Refinement::None => 0,
            Refinement::Icp(icp) => icp.k_needed(),
            Refinement::ZoomOut { zoomout, .. } => zoomout.k_needed(),
            Refinement::Custom(r) => r.k_needed(),
        }
    }
}

/// The further initial sizes a refinement on a ZoomOut schedule runs
/// from by default ([`default_starts`]): ZoomOut from initial maps of
/// sizes 50, 8 and 20, keeping the result of lowest area distortion
/// ([`StartSelection::Area`](crate::refine::starts::StartSelection::Area)).
/// Measured with exact geodesics against the previous default (starts 50,
/// 20, 30, best orientation kept), mean error x100 on the first test
/// pairs: TOSCA_Isometric 4.11 -> 2.65, FAUST 5.89 -> 3.60, generated-iso
/// 2.46 -> 2.43, generated-noniso 39.2 -> 37.4, at the same number of runs.
const ZOOMOUT_STARTS: [usize; 2] = [8, 20];

/// The size of the initial map (`k`) of the literature's automatic
/// pipeline: 50 x 50.
pub(super) const DEFAULT_K: usize = 50;

/// A refinement by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefinerKind {
    /// No refinement: the descriptor map as solved.
    None,
    /// Spectral ICP (orthogonal Procrustes) at the map's size.
    Icp,
    /// ZoomOut spectral upsampling (Melzi et al. 2019).
    Zoomout,
    /// Bijective ZoomOut, a preset of the discrete solver (Ren et al.,
    /// "Discrete Optimization for Shape Matching", SGP 2021).
    BijectiveZoomout,
    /// The discrete solver of the same paper with all its energy terms.
    Discrete,
    /// A repair of the BCICP class (Ren et al., SIGGRAPH Asia 2018).
    Bcicp,
    /// Smooth Shells (Eisenberger et al., CVPR 2020) with its own
    /// initialisation.
    SmoothShells,
}

impl RefinerKind {
    /// Every kind, in the order the documentation lists them.
    pub const ALL: [RefinerKind; 7] = [
        RefinerKind::None,
        RefinerKind::Icp,
        RefinerKind::Zoomout,
        RefinerKind::BijectiveZoomout,
        RefinerKind::Discrete,
        RefinerKind::Bcicp,
        RefinerKind::SmoothShells,
    ];

    /// The name (`fmaps match --refine NAME`).
    pub fn name(self) -> &'static str {
        match self {
            RefinerKind::None => "none",
            RefinerKind::Icp => "icp",
            RefinerKind::Zoomout => "zoomout",
            RefinerKind::BijectiveZoomout => "bijective-zoomout",
            RefinerKind::Discrete => "discrete",
            RefinerKind::Bcicp => "bcicp",
            RefinerKind::SmoothShells => "smooth-shells",
        }
    }

    /// One line for a user choosing among the kinds: what it does and its
    /// paper (the command line's `--refine` help, the Python docs).
    pub fn summary(self) -> &'static str {
        match self {
            RefinerKind::None => "no refinement: the descriptor map",
            RefinerKind::Icp => {
                "spectral ICP (orthogonal Procrustes) at the map's size (Ovsjanikov et al. 2012)"
            }
            RefinerKind::Zoomout => {
                "ZoomOut spectral upsampling (Melzi et al., SIGGRAPH Asia 2019)"
            }
            RefinerKind::BijectiveZoomout => {
                "bijective ZoomOut: both point maps updated together, each pulled towards the other's inverse (Ren et al., SGP 2021)"
            }
            RefinerKind::Discrete => {
                "the discrete solver on orthogonality, bijectivity, properness and Laplacian commutativity (Ren et al., SGP 2021)"
            }
            RefinerKind::Bcicp => {
                "a repair of the BCICP class: bijective ICP with coverage, continuity and smoothness repairs on the meshes (Ren et al., SIGGRAPH Asia 2018)"
            }
            RefinerKind::SmoothShells => {
                "Smooth Shells: A's shells deformed onto B's coarse to fine, with its own initialisation (Eisenberger et al., CVPR 2020)"
            }
        }
    }

    /// What runs when no refinement is named, for meshes whose smaller one
    /// has `smallest` vertices: [`Refinement::recommended`] (Smooth
    /// Shells) where both meshes have more vertices than its basis needs,
    /// else none.
    pub fn default_for(smallest: usize) -> RefinerKind {
        if smallest > Refinement::recommended().k_needed() {
            RefinerKind::SmoothShells
        } else {
            RefinerKind::None
        }
    }

    /// The discrete-optimisation preset of this kind, if it is one.
    pub fn discrete_preset(self) -> Option<&'static str> {
        match self {
            RefinerKind::BijectiveZoomout => Some("bijective-zoomout"),
            RefinerKind::Discrete => Some("discrete"),
            _ => None,
        }
    }

    /// Whether the kind runs on a ZoomOut schedule (and so from the
    /// further starts [`default_starts`] by default).
    pub fn has_schedule(self) -> bool {
        matches!(
            self,
            RefinerKind::Zoomout | RefinerKind::BijectiveZoomout | RefinerKind::Discrete
        )
    }
}

impl std::fmt::Display for RefinerKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for RefinerKind {
    type Err = MatchError;
    fn from_str(s: &str) -> Result<Self, MatchError> {
        RefinerKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = RefinerKind::ALL.iter().map(|k| k.name()).collect();
                MatchError::InvalidParameter(format!(
                    "unknown refinement '{s}' (expected one of: {})",
                    names.join(", ")
                ))
            })
    }
}

/// The options a named refinement is built from (`fmaps match`'s flags).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct RefineOptions {
    /// Size of the initial map (a schedule must start at or below it).
    pub k: usize,
    /// ZoomOut schedule `START:FINAL:STEP` (`None`: the default 50:150:5);
    /// also the discrete presets' schedule.
    pub schedule: Option<String>,
    /// ICP iterations.
    pub icp_iterations: usize,
    /// ZoomOut on this many farthest points per shape.
    pub samples: Option<usize>,
    /// ZoomOut updates both directions together.
    pub bijective: bool,
    /// Convert with the adjoint of C.
    pub adjoint: bool,
    /// Convert with the Fast Sinkhorn Filter instead of nearest neighbours.
    pub sinkhorn: bool,
    /// The target is a mirror image of the source (Smooth Shells aligns
    /// the source's reflection).
    pub mirrored: bool,
    /// The shapes are not near-isometric (different people, different
    /// animals): Smooth Shells screens all eight rigid orientations
    /// ([`crate::refine::SmoothShells::non_isometric`], about the
    /// default's time). Other refinements ignore it.
    pub non_isometric: bool,
    /// Smooth Shells runs both settings (the default's two orientations and
    /// the non-isometric eight-orientation screen) and keeps the map of
    /// least area distortion ([`crate::refine::BestOf`]; twice the time).
    /// Other refinements ignore it.
    pub second_opinion: bool,
}

impl Default for RefineOptions {
    fn default() -> Self {
        RefineOptions {
            k: DEFAULT_K,
            schedule: None,
            icp_iterations: Icp::default().max_iterations,
            samples: None,
            bijective: false,
            adjoint: false,
            sinkhorn: false,
            mirrored: false,
            non_isometric: false,
            second_opinion: false,
        }
    }
}

impl RefineOptions {
    /// The default options for an initial map of size `k`.
    pub fn for_map_size(k: usize) -> RefineOptions {
        RefineOptions {
            k,
            ..RefineOptions::default()
        }
    }

    /// The ZoomOut schedule asked for, checked against the map's size.
    fn zoomout(&self) -> Result<ZoomOut, MatchError> {
        let z = match &self.schedule {
            None => ZoomOut::default(),
            Some(text) => ZoomOut::with_schedule(text)
                .map_err(|e| MatchError::InvalidParameter(format!("the schedule '{text}': {e}")))?,
        };
        if z.k_start > self.k {
            return Err(MatchError::InvalidParameter(format!(
                "the schedule starts at {}, but the initial map is only {k} x {k} (k = {k})",
                z.k_start,
                k = self.k
            )));
        }
        Ok(z)
    }

    fn sinkhorn(&self) -> Option<crate::solve::sinkhorn::Sinkhorn> {
        self.sinkhorn
            .then(crate::solve::sinkhorn::Sinkhorn::default)
    }
}

/// The refinement `kind` with `options`.
///
/// Errors: a schedule that does not parse or starts above `options.k`.
///
/// ```
/// use fmaps::pipeline::{named_refinement, RefineOptions, RefinerKind};
///
/// let r = named_refinement("zoomout".parse()?, &RefineOptions::default())?;
/// assert_eq!(r.k_needed(), 150);
/// let short = RefineOptions::for_map_size(30);
/// assert!(named_refinement(RefinerKind::Zoomout, &short).is_err());
/// # Ok::<(), fmaps::pipeline::MatchError>(())
/// ```
pub fn named_refinement(
    kind: RefinerKind,
    options: &RefineOptions,
) -> Result<Refinement, MatchError> {
    if let Some(preset) = kind.discrete_preset() {
        let z = options.zoomout()?;
        let mut d = refine::DiscreteOp::preset(preset)?;
        d.sinkhorn = options.sinkhorn();
        (d.k_start, d.k_final, d.step) = (z.k_start, z.k_final, z.step);
        return Ok(Refinement::Custom(Arc::new(d)));
    }
    Ok(match kind {
        RefinerKind::None => Refinement::None,
        RefinerKind::Bcicp => Refinement::Custom(Arc::new(refine::Repair::default())),
        RefinerKind::SmoothShells => {
            let shells = |non_isometric: bool| refine::SmoothShells {
                reflect: options.mirrored,
                ..if non_isometric {
                    refine::SmoothShells::non_isometric()
                } else {
                    refine::SmoothShells::default()
                }
            };
            if options.second_opinion {
                Refinement::Custom(Arc::new(refine::BestOf::new(vec![
                    Arc::new(shells(false)),
                    Arc::new(shells(true)),
                ])?))
            } else {
                Refinement::Custom(Arc::new(shells(options.non_isometric)))
            }
        }
        RefinerKind::Icp => Refinement::Icp(Icp {
            max_iterations: options.icp_iterations,
            adjoint: options.adjoint,
            sinkhorn: options.sinkhorn(),
        }),
        RefinerKind::Zoomout | RefinerKind::BijectiveZoomout | RefinerKind::Discrete => {
            let z = options.zoomout()?;
            Refinement::ZoomOut {
                zoomout: ZoomOut {
                    adjoint: options.adjoint,
                    bijective: options.bijective,
                    sinkhorn: options.sinkhorn(),
                    subsample: None,
                    ..z
                },
                samples: options.samples,
            }
        }
    })
}

/// The further starts `kind` runs from by default when the shapes hold
/// `k_process` eigenpairs: 8 and 20 (those within the basis)
/// for the kinds on a ZoomOut schedule, none otherwise.
pub fn default_starts(kind: RefinerKind, k_process: usize) -> Vec<usize> {
    if kind.has_schedule() {
        ZOOMOUT_STARTS
            .into_iter()
            .filter(|&s| s <= k_process)
            .collect()
    } else {
        Vec::new()
    }
}

/// When a ZoomOut's iterations run on farthest-point samples instead of
/// every vertex (the ZoomOut paper's fast variant: the iterations on
/// samples, the final map on every vertex), for callers that do not say.
/// `fmaps match`, `fmaps batch` and the Python package follow
/// [`RefineSampling::default`] and say so.
///
/// ```
/// use fmaps::pipeline::RefineSampling;
/// let policy = RefineSampling::default();
/// assert_eq!(policy.samples_for(5000, 6890), None);
/// assert_eq!(policy.samples_for(5000, 80_000), Some(policy.samples));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub struct RefineSampling {
    /// Vertices of the larger mesh above which the iterations run on
    /// samples (20000).
    pub above: usize,
    /// Farthest points per shape (10000). On six FAUST pairs subdivided to
    /// 80k vertices (the default three-start ZoomOut) 10000 samples gave
    /// the mean error of the unsampled run (x100: 1.926 against 1.929) in
    /// about a quarter of the time, where 5000 gave 1.964, worse on five
    /// of the six pairs, and two more iterations on every vertex after the
    /// 5000 samples' did not close the gap (docs/benchmarks.md, "Large
    /// meshes: sampled refinement").
    pub samples: usize,
}

impl Default for RefineSampling {
    fn default() -> Self {
        RefineSampling {
            above: 20_000,
            samples: 10_000,
        }
    }
}

impl RefineSampling {
    /// The samples per shape for meshes of `n_a` and `n_b` vertices:
    /// `None` (every vertex) up to [`above`](Self::above) vertices in the
    /// larger mesh, [`samples`](Self::samples) beyond.
    pub fn samples_for(&self, n_a: usize, n_b: usize) -> Option<usize> {
        (n_a.max(n_b) > self.above).then_some(self.samples)
    }
}

/// Where a multi-start ZoomOut stops its starts by default
/// ([`Starts::select_at`](super::Starts::select_at)): the
/// middle of the schedule, `(k_start + k_final) / 2` (100 for 50:150:5),
/// when that is strictly between its ends; `None` for other refinements.
/// The starts' maps at that size already tell which one converges to the
/// right branch (measured: the same errors on FAUST and TOSCA, a third less
/// time than running every start to the end).
pub fn default_select_at(refine: &Refinement) -> Option<usize> {
    match refine {
        Refinement::ZoomOut { zoomout, .. } => {
            let mid = (zoomout.k_start + zoomout.k_final) / 2;
            (mid > zoomout.k_start && mid < zoomout.k_final).then_some(mid)
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A second opinion runs both Smooth Shells settings, the default's
    /// first (kept on a tie), and needs the eigenpairs of either; other
    /// refinements ignore it.
    #[test]
    fn a_second_opinion_is_both_smooth_shells_settings() {
        let options = RefineOptions {
            second_opinion: true,
            ..RefineOptions::default()
        };
        let r = named_refinement(RefinerKind::SmoothShells, &options).unwrap();
        let Refinement::Custom(best) = &r else {
            panic!("{r:?}")
        };
        let default = refine::SmoothShells::default().name();
        let screen = refine::SmoothShells::non_isometric().name();
        assert_eq!(
            best.name(),
            format!("best of ({default} | {screen}) by area distortion")
        );
        assert_eq!(r.k_needed(), refine::SmoothShells::default().k_needed());
        let z = named_refinement(RefinerKind::Zoomout, &options).unwrap();
        let plain = named_refinement(RefinerKind::Zoomout, &RefineOptions::default()).unwrap();
        assert_eq!(format!("{z:?}"), format!("{plain:?}"));
    }
}
