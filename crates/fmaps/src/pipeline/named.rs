//! The refinements by name, as `fmaps match --refine NAME`, `fmaps refine`
//! and the Python package name them, and the policy of what runs without
//! a name: one place, so every front end builds the same refiner from the
//! same options and gets the same map.

use std::sync::Arc;

use super::{MatchError, Refinement, ZOOMOUT_STARTS};
use crate::refine::{self, Icp, ZoomOut};

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
    /// further starts [`ZOOMOUT_STARTS`] by default).
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
}

impl Default for RefineOptions {
    fn default() -> Self {
        RefineOptions {
            k: super::MatchParams::default().k,
            schedule: None,
            icp_iterations: Icp::default().max_iterations,
            samples: None,
            bijective: false,
            adjoint: false,
            sinkhorn: false,
            mirrored: false,
            non_isometric: false,
        }
    }
}

impl RefineOptions {
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
/// let short = RefineOptions { k: 30, ..RefineOptions::default() };
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
        RefinerKind::SmoothShells => Refinement::Custom(Arc::new(refine::SmoothShells {
            reflect: options.mirrored,
            ..if options.non_isometric {
                refine::SmoothShells::non_isometric()
            } else {
                refine::SmoothShells::default()
            }
        })),
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
/// `k_process` eigenpairs: [`ZOOMOUT_STARTS`] (those within the basis)
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

/// Farthest points per shape that ZoomOut's iterations run on when
/// [`default_refine_samples`] samples. On six FAUST pairs subdivided to
/// 80k vertices (the default three-start ZoomOut) 10000 samples gave the
/// mean error of the unsampled run (x100: 1.926 against 1.929), where
/// 5000 gave 1.964, worse on five of the six pairs, and two more
/// iterations on every vertex after the 5000 samples' did not close the
/// gap (docs/benchmarks.md, "Large meshes: sampled refinement").
pub const AUTO_REFINE_SAMPLES: usize = 10_000;

/// Vertices of the larger mesh above which [`default_refine_samples`]
/// samples.
pub const AUTO_SAMPLES_ABOVE: usize = 20_000;

/// The vertices a ZoomOut's iterations run on when the caller does not
/// say, for meshes of `n_a` and `n_b` vertices: every vertex (`None`) up
/// to [`AUTO_SAMPLES_ABOVE`] vertices in the larger mesh, above that
/// [`AUTO_REFINE_SAMPLES`] farthest points per shape (the ZoomOut paper's
/// fast variant: the iterations on samples, the final map on every
/// vertex). `fmaps match`, `fmaps batch` and the Python package follow
/// it and say so. On six FAUST pairs subdivided to 80k vertices the
/// sampled three-start ZoomOut gives the mean error of the unsampled one
/// in about a quarter of the time.
///
/// ```
/// use fmaps::pipeline::{default_refine_samples, AUTO_REFINE_SAMPLES};
/// assert_eq!(default_refine_samples(5000, 6890), None);
/// assert_eq!(default_refine_samples(5000, 80_000), Some(AUTO_REFINE_SAMPLES));
/// ```
pub fn default_refine_samples(n_a: usize, n_b: usize) -> Option<usize> {
    (n_a.max(n_b) > AUTO_SAMPLES_ABOVE).then_some(AUTO_REFINE_SAMPLES)
}

/// Where a multi-start ZoomOut stops its starts by default
/// ([`MatchParams::select_at`](super::MatchParams::select_at)): the
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
