//! The basic functional-map pipeline: two meshes in, a point map out.
//!
//! For shapes A (source) and B (target) it computes
//!
//! 1. the Laplace–Beltrami eigenbases of both ([`crate::spectrum`]),
//! 2. spectral descriptors (WKS or HKS from the first `k_descr` eigenpairs,
//!    optionally landmark descriptors), every column normalized to unit
//!    L² norm,
//! 3. the functional map `C_BA` (k x k, functions on B to functions on A)
//!    minimizing the energy of [`fmaps_solve::FmapEnergy`]: descriptor
//!    preservation, Laplacian commutativity (resolvent mask), descriptor
//!    commutativity and orientation preservation, with the first column
//!    fixed (constants to constants), solved exactly,
//! 4. the point map `T_AB` (a vertex of B for every vertex of A) by exact
//!    nearest neighbours in the spectral embedding,
//! 5. optionally a refinement of `C_BA` and `T_AB` ([`Refinement`]: ICP or
//!    ZoomOut from `fmaps-refine`, or any [`fmaps_refine::Refiner`] through
//!    [`refine_result`]).
//!
//! The direction follows the dataset convention: the map file `A_B.map`
//! lists a B vertex per A vertex, and `T_AB` is read off `C_BA` (pull-back
//! of B's functions).
//!
//! [`MatchParams::default`] is the setting of the literature's standard
//! automatic pipeline, as pyFM ships it: k = 200 eigenpairs computed, 100
//! WKS descriptors from 128 eigenpairs, a 50 x 50 map, weights
//! `w_descr = 0.1, w_lap = 1e-3, w_dcomm = 1` with the resolvent mask
//! (γ = 0.5) and pyFM's term normalization, and the orientation term on
//! (`w_orient = 1`; without it, maps of left-right symmetric shapes flip).

use std::sync::Arc;
use std::time::Instant;

use fmaps_descriptors as descriptors;
pub use fmaps_descriptors::DescriptorKind;
use fmaps_eigensolve::SpectralBasis;
use fmaps_mesh_io::TriMesh;
use fmaps_refine::{self as refine, RefineReport, Refiner};
use fmaps_solve::{self as solve, EnergyParams, ShapeData};
use nalgebra::DMatrix;

use crate::{SpectrumParams, spectrum};

mod fit;
mod from_map;
mod guards;
mod named;
mod single;
mod starts;
use fit::Described;
pub use fit::{Fit, fit_descriptors};
pub use from_map::{RefinedMap, SAMPLED_FULL_ITERATIONS, refine_point_map};
use from_map::{draw_samples, with_refiner};
pub use guards::parse_starts;
use guards::unit_area;
pub use named::{
    AUTO_REFINE_SAMPLES, AUTO_SAMPLES_ABOVE, RefineOptions, RefinerKind, default_refine_samples,
    default_select_at, default_starts, named_refinement,
};
use single::match_described;
use starts::multi_start;

/// Errors of the pipeline, naming the stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MatchError {
    /// The eigensolver failed.
    #[error("eigenbasis of the {shape} shape: {source}")]
    Spectrum {
        /// "source" or "target".
        shape: &'static str,
        /// The cause.
        source: fmaps_eigensolve::Error,
    },
    /// Descriptors could not be computed.
    #[error("descriptors: {0}")]
    Descriptors(#[from] descriptors::Error),
    /// The solve or the conversion failed.
    #[error("functional map: {0}")]
    Solve(#[from] solve::Error),
    /// The refinement failed.
    #[error("refinement: {0}")]
    Refine(#[from] refine::Error),
    /// A parameter is out of range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// The descriptors and operators do not determine the functional map:
    /// the solve's C is orders of magnitude larger than any map between
    /// the shapes can be.
    #[error(
        "the functional map is undetermined: max |C_ij| = {max_entry:.3e}, numerical rank {rank} of {k}, ||C^T C - I|| = {orthonormality:.3e}, where a map between the shapes has entries of order 1 and full rank; the descriptors do not tell the points of a shape apart (a sphere, a highly symmetric or featureless shape?). Try landmarks, another descriptor (HKS/WKS) or a smaller k"
    )]
    Undetermined {
        /// The largest entry of C in magnitude.
        max_entry: f64,
        /// Singular values of C above 1e-8 of the largest.
        rank: usize,
        /// The size of C (columns).
        k: usize,
        /// ‖CᵀC − I‖_F.
        orthonormality: f64,
    },
    /// A shape the pipeline cannot work on (zero or overflowing area, a
    /// degenerate functional-map problem).
    #[error("{shape} shape: {message}")]
    InvalidShape {
        /// Which shape ("source", "target", or "input" for one alone).
        shape: &'static str,
        /// What is wrong and what to try.
        message: String,
    },
}

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
    /// the target shape: see [`refine_result`]).
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
            Refinement::Custom(r) => write!(f, "Custom({:?})", r.name()),
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
    /// vertices. [`MatchParams::default`] keeps the initial map
    /// ([`Refinement::None`]): the building block the refiners start from.
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

/// The further initial sizes the `fmaps match --refine zoomout` command
/// and the `fmaps-zoomout` evaluation method use by default
/// ([`MatchParams::starts`]): ZoomOut from initial maps of sizes 50, 8
/// and 20, keeping the result of lowest area distortion
/// ([`StartSelection::Area`]). Measured with exact geodesics against the
/// previous default (starts 50, 20, 30, best orientation kept), mean
/// error x100 on the first test pairs: TOSCA_Isometric 4.11 ->
/// 2.65, FAUST 5.89 -> 3.60, generated-iso 2.46 -> 2.43,
/// generated-noniso 39.2 -> 37.4, at the same number of runs.
/// [`MatchParams::default`] stays the literature's single start.
pub const ZOOMOUT_STARTS: [usize; 2] = [8, 20];

/// Options of the pipeline (see the module docs for the defaults).
#[derive(Debug, Clone)]
pub struct MatchParams {
    /// Eigenpairs computed per shape.
    pub k_process: usize,
    /// Eigenpairs the descriptors are built from.
    pub k_descr: usize,
    /// Descriptor samples (energies or times) per family.
    pub n_descr: usize,
    /// Descriptor family.
    pub descriptor: DescriptorKind,
    /// Keep every `subsample`-th descriptor column (1 = all).
    pub subsample: usize,
    /// Size of the functional map (k x k).
    pub k: usize,
    /// Relative weight of descriptor preservation.
    pub w_descr: f64,
    /// Relative weight of Laplacian commutativity.
    pub w_lap: f64,
    /// Relative weight of descriptor commutativity.
    pub w_dcomm: f64,
    /// Relative weight of orientation preservation (0 = off).
    pub w_orient: f64,
    /// Look for orientation-reversing maps instead.
    pub orient_reversing: bool,
    /// Resolvent Laplacian mask with this γ; `None`: plain `(λ − μ)²`.
    pub resolvent_gamma: Option<f64>,
    /// Landmark pairs (source vertex, target vertex), 0-based: adds
    /// landmark descriptors.
    pub landmarks: Vec<(usize, usize)>,
    /// Convert with the adjoint (`T_AB(x) = argmin_y ‖Φ_B(y) − C_BAᵀ Φ_A(x)‖`).
    pub adjoint: bool,
    /// Eigensolver options.
    pub spectrum: SpectrumParams,
    /// Refinement of the initial map (none by default).
    pub refine: Refinement,
    /// Rotate the descriptors of both shapes to an orthonormal basis of
    /// their span and drop directions below rounding level
    /// ([`fmaps_solve::compress_descriptors`]); the energy is unchanged to
    /// rounding. On by default.
    pub compress: bool,
    /// Scale each shape to unit area before anything else (on by
    /// default): the eigenvalues, the descriptors' energies, the Laplacian
    /// mask and every refiner then see the same numbers whatever the
    /// mesh's units (millimetres, metres), and the two shapes of a pair
    /// may come in different units. `C_BA` is then between the bases of
    /// the unit-area shapes. Off: the shapes as given (only for shapes
    /// known to share units and a comparable size).
    pub area_normalize: bool,
    /// Multi-start: further sizes of the initial map. The pipeline is run
    /// once per size from the same descriptors (all sizes in parallel, or
    /// with [`restart_below`](Self::restart_below) `k` first; a ZoomOut
    /// starts from the smaller of the size and its `k_start`), and one
    /// final map is kept by
    /// [`select`](Self::select) (default: the lowest area distortion). Small initial maps have fewer degrees of freedom for
    /// swapping parts (a left and a right limb) and large ones resolve
    /// more detail; the distortion (or orientation) of the refined map
    /// tells which start converged to the right branch, without any
    /// ground truth. Empty: a single start at `k`.
    pub starts: Vec<usize>,
    /// With [`starts`](Self::starts): which final map is kept.
    pub select: StartSelection,
    /// With [`starts`](Self::starts): try the further starts only when the
    /// first start's (size `k`) orientation score is below this value
    /// (above its negative with `orient_reversing`), so well-oriented
    /// pairs cost one start. `None`: always run every start.
    pub restart_below: Option<f64>,
    /// With [`starts`](Self::starts) and a ZoomOut refinement: every
    /// start's ZoomOut stops at this size (when below its final size),
    /// the start is chosen there by [`select`](Self::select), and only
    /// the kept one goes on to the final size (the rest of its schedule,
    /// the same iterations as without the stop when its sizes pass
    /// through the stop). `None`: every start runs to the end;
    /// [`pipeline::default_select_at`](crate::pipeline::default_select_at):
    /// what `fmaps match` uses.
    pub select_at: Option<usize>,
}

impl Default for MatchParams {
    fn default() -> Self {
        let energy = EnergyParams::default();
        Self {
            k_process: 200,
            k_descr: 128,
            n_descr: 100,
            descriptor: DescriptorKind::Wks,
            subsample: 1,
            k: 50,
            w_descr: energy.weights.descr,
            w_lap: energy.weights.lap,
            w_dcomm: energy.weights.dcomm,
            w_orient: energy.weights.orient,
            orient_reversing: energy.orient_reversing,
            resolvent_gamma: energy.resolvent_gamma,
            landmarks: Vec::new(),
            adjoint: false,
            spectrum: SpectrumParams::default(),
            compress: true,
            refine: Refinement::None,
            area_normalize: true,
            starts: Vec::new(),
            select: StartSelection::default(),
            restart_below: None,
            select_at: None,
        }
    }
}

/// How a multi-start run ([`MatchParams::starts`]) picks its final map,
/// by a score that needs no ground truth ([`crate::eval::map_quality`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum StartSelection {
    /// The highest [orientation score](refine::orientation_score) (lowest
    /// with `orient_reversing`).
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

impl MatchParams {
    /// The eigenpairs this pipeline uses: the largest of `k_descr`, `k`,
    /// the starts and the refinement's need
    /// ([`Refinement::k_needed`]). `fmaps match` computes this many when
    /// `--k-process` is not given (200 for the default Smooth Shells, 150
    /// for ZoomOut 50 → 150, 128 without refinement): eigenpairs beyond it
    /// would never be read. On every 10th FAUST and TOSCA test pair the
    /// three-start ZoomOut gives the same mean errors from 150 eigenpairs
    /// as from 200.
    pub fn k_process_needed(&self) -> usize {
        let starts = self.starts.iter().copied().max().unwrap_or(0);
        self.k_descr
            .max(self.k)
            .max(starts)
            .max(self.refine.k_needed())
    }

    /// The relative weights of the four terms.
    pub fn weights(&self) -> solve::PerTerm {
        solve::PerTerm {
            descr: self.w_descr,
            lap: self.w_lap,
            dcomm: self.w_dcomm,
            orient: self.w_orient,
        }
    }

    fn check(&self) -> Result<(), MatchError> {
        let bad = |m: String| Err(MatchError::InvalidParameter(m));
        if self.k == 0 || self.k > self.k_process {
            return bad(format!(
                "the map size k = {} must be in 1..=k_process ({})",
                self.k, self.k_process
            ));
        }
        if self.k_descr < 2 || self.k_descr > self.k_process {
            return bad(format!(
                "k_descr = {} must be in 2..=k_process ({})",
                self.k_descr, self.k_process
            ));
        }
        if let Some(&s) = self.starts.iter().find(|&&s| s == 0 || s > self.k_process) {
            return bad(format!(
                "the start size {s} must be in 1..=k_process ({})",
                self.k_process
            ));
        }
        if self.n_descr == 0 || self.subsample == 0 {
            return bad("n_descr and subsample must be positive".into());
        }
        // WKS and HKS samples are combinations of the k_descr functions
        // φ_i²: far more samples than that only repeat them.
        let most = MAX_DESCR_PER_EIGENPAIR
            .saturating_mul(self.k_descr)
            .max(MAX_DESCR_ANY);
        if self.n_descr > most {
            return bad(format!(
                "n_descr = {} is more than {most} (the larger of {MAX_DESCR_ANY} and {MAX_DESCR_PER_EIGENPAIR} x k_descr = {}): the descriptors are combinations of the {} functions φ_i², more samples only repeat them",
                self.n_descr,
                MAX_DESCR_PER_EIGENPAIR.saturating_mul(self.k_descr),
                self.k_descr
            ));
        }
        if let Refinement::ZoomOut { zoomout, .. } = &self.refine
            && zoomout.subsample.is_some()
        {
            return bad(
                "Refinement::ZoomOut samples the shapes itself: set `samples`, not `zoomout.subsample`"
                    .into(),
            );
        }
        if self.refine.k_needed() > self.k_process {
            return bad(format!(
                "the refinement needs {} eigenpairs, more than k_process = {}",
                self.refine.k_needed(),
                self.k_process
            ));
        }
        let w = self.weights().as_array();
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
pub const MAX_DESCR_PER_EIGENPAIR: usize = 4;

/// Descriptor samples always allowed, whatever the number of eigenpairs.
pub const MAX_DESCR_ANY: usize = 1000;

/// Memory the descriptor matrices of one shape may take (2 GiB).
pub const MAX_DESCRIPTOR_BYTES: usize = 1 << 31;

/// One shape after the per-shape stages: reusable across pairs.
#[derive(Debug, Clone)]
pub struct PreparedShape {
    /// Vertex positions (for sub-sampled refinement and the orientation
    /// score), after the area normalization when it is on.
    pub vertices: Vec<[f64; 3]>,
    /// Oriented triangles (for the orientation operators).
    pub faces: Vec<[usize; 3]>,
    /// The eigenbasis (`k_process` pairs) of the (normalized) shape.
    pub basis: SpectralBasis,
    /// Total area of the (normalized) shape: the sum of the lumped mass,
    /// 1 to rounding with [`MatchParams::area_normalize`].
    pub area: f64,
    /// The input mesh's area, in its own units squared.
    pub input_area: f64,
    /// The factor every coordinate was multiplied by (`1/√input_area`
    /// with the area normalization, else 1).
    pub scale: f64,
    /// Seconds for the Laplacian and the eigenbasis.
    pub seconds: f64,
}

/// Laplacian and eigenbasis of one shape, after scaling it to unit area
/// when [`MatchParams::area_normalize`] is on (the default), so that
/// nothing downstream depends on the mesh's units.
pub fn prepare(mesh: &TriMesh, params: &MatchParams) -> Result<PreparedShape, MatchError> {
    prepare_with_basis(mesh, params, None)
}

/// [`prepare`], with the eigenbasis taken from `cached` when given (a
/// basis [`prepare`] computed earlier for the same mesh and parameters,
/// e.g. from `fmaps batch`'s cache): the same normalization, no
/// eigensolve. A cached basis with another vertex count or fewer than
/// `k_process` pairs is an error.
pub fn prepare_with_basis(
    mesh: &TriMesh,
    params: &MatchParams,
    cached: Option<SpectralBasis>,
) -> Result<PreparedShape, MatchError> {
    params.check()?;
    let t = Instant::now();
    let input_area = mesh.area();
    let (normalized, scale) = if params.area_normalize {
        let (m, scale) = unit_area(mesh).map_err(|message| MatchError::InvalidShape {
            shape: "input",
            message,
        })?;
        (Some(m), scale)
    } else {
        (None, 1.0)
    };
    let mesh = normalized.as_ref().unwrap_or(mesh);
    let basis = match cached {
        Some(b) => {
            if b.eigenvectors.nrows() != mesh.n_vertices() || b.eigenvalues.len() < params.k_process
            {
                return Err(MatchError::InvalidShape {
                    shape: "input",
                    message: format!(
                        "the cached eigenbasis has {} rows and {} pairs, the mesh {} vertices and k_process = {}",
                        b.eigenvectors.nrows(),
                        b.eigenvalues.len(),
                        mesh.n_vertices(),
                        params.k_process
                    ),
                });
            }
            b
        }
        None => {
            spectrum(mesh, params.k_process, &params.spectrum)
                .map_err(|source| MatchError::Spectrum {
                    shape: "input",
                    source,
                })?
                .basis
        }
    };
    let area = basis.mass.iter().sum();
    Ok(PreparedShape {
        vertices: mesh.vertices().to_vec(),
        faces: mesh.faces().to_vec(),
        basis,
        area,
        input_area,
        scale,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// Seconds per stage of [`match_prepared`].
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
    /// [`refine::orientation_score`] of `t_ab` (near 1: orientation
    /// preserved, near −1: mirrored, near 0: noise or swapped parts).
    pub orientation: f64,
    /// Every start of a multi-start run ([`MatchParams::starts`]); empty
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
}

/// One start of a multi-start run.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Start {
    /// Size of the initial map.
    pub k: usize,
    /// Orientation score of its final map (of its map at
    /// [`MatchParams::select_at`] when the starts stopped there).
    pub orientation: f64,
    /// Scores of that map without ground truth (unit-area shapes).
    pub quality: crate::eval::MapQuality,
    /// Its map was kept.
    pub chosen: bool,
    /// Seconds for this start (descriptors to refined map).
    pub seconds: f64,
}

/// Runs the whole pipeline from source `a` to target `b`.
pub fn match_shapes(
    a: &TriMesh,
    b: &TriMesh,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    match_shapes_with_progress(a, b, params, &|_| {})
}

/// [`match_shapes`], calling `stage` with a short description as each
/// stage starts (for progress displays).
pub fn match_shapes_with_progress(
    a: &TriMesh,
    b: &TriMesh,
    params: &MatchParams,
    stage: &dyn Fn(&str),
) -> Result<MatchResult, MatchError> {
    params.check()?;
    stage("Laplacians and eigenbases of both shapes");
    let mut single = params.clone();
    single.spectrum.threads = 1;
    // The two shapes side by side, one thread each.
    let t = Instant::now();
    let (pa, pb) = rayon::join(|| prepare(a, &single), || prepare(b, &single));
    let spectra = t.elapsed().as_secs_f64();
    let name = |shape, e| match e {
        MatchError::Spectrum { source, .. } => MatchError::Spectrum { shape, source },
        MatchError::InvalidShape { message, .. } => MatchError::InvalidShape { shape, message },
        e => e,
    };
    let pa = pa.map_err(|e| name("source", e))?;
    let pb = pb.map_err(|e| name("target", e))?;
    stage(match params.refine {
        Refinement::None => "descriptors, functional map, point map",
        _ => "descriptors, functional map, point map, refinement",
    });
    let mut out = match_prepared(&pa, &pb, params)?;
    out.times.spectra = spectra;
    out.times.total += spectra;
    Ok(out)
}

/// The descriptors (n x p, unit L² columns) of a prepared shape
/// ([`descriptors::descriptor_matrix`] on its first `k_descr` eigenpairs).
pub fn shape_descriptors(
    shape: &PreparedShape,
    landmarks: &[usize],
    params: &MatchParams,
) -> Result<DMatrix<f64>, MatchError> {
    let basis = shape.basis.truncate(params.k_descr);
    let mut p = descriptors::DescriptorParams::default();
    p.kind = params.descriptor;
    p.n = params.n_descr;
    p.subsample = params.subsample;
    Ok(descriptors::descriptor_matrix(
        &basis.eigenvalues,
        &basis.eigenvectors,
        &basis.mass,
        landmarks,
        &p,
    )?)
}

/// The pipeline on two prepared shapes (source `a`, target `b`).
pub fn match_prepared(
    a: &PreparedShape,
    b: &PreparedShape,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    params.check()?;
    let k = params.k;
    for (shape, s) in [("source", a), ("target", b)] {
        if s.basis.k() < params.k_process.max(k) {
            return Err(MatchError::InvalidParameter(format!(
                "the {shape} shape was prepared with {} eigenpairs, fewer than k_process = {}",
                s.basis.k(),
                params.k_process
            )));
        }
    }
    for &(x, y) in &params.landmarks {
        if x >= a.basis.n() || y >= b.basis.n() {
            return Err(MatchError::InvalidParameter(format!(
                "landmark ({x}, {y}) is outside the shapes ({} and {} vertices)",
                a.basis.n(),
                b.basis.n()
            )));
        }
    }
    // The descriptor matrices (n x columns) of the larger shape, and the
    // columns x columns Gram matrix of their compression, must fit.
    let columns = params.n_descr.saturating_mul(1 + params.landmarks.len()) / params.subsample;
    let bytes = columns
        .saturating_mul(a.basis.n().max(b.basis.n()).max(columns))
        .saturating_mul(8);
    if bytes > MAX_DESCRIPTOR_BYTES {
        return Err(MatchError::InvalidParameter(format!(
            "{} descriptors ({} samples x (1 + {} landmarks) / subsample {}) on {} vertices need {:.1} GB (with their Gram matrix), more than {} GB: use fewer landmarks or samples",
            columns,
            params.n_descr,
            params.landmarks.len(),
            params.subsample,
            a.basis.n().max(b.basis.n()),
            bytes as f64 / 1e9,
            MAX_DESCRIPTOR_BYTES as f64 / 1e9
        )));
    }
    let t = Instant::now();
    let lm_a: Vec<usize> = params.landmarks.iter().map(|p| p.0).collect();
    let lm_b: Vec<usize> = params.landmarks.iter().map(|p| p.1).collect();
    let (da, db) = rayon::join(
        || shape_descriptors(a, &lm_a, params),
        || shape_descriptors(b, &lm_b, params),
    );
    let (da, db) = (da?, db?);
    // Checked and compressed once for every start.
    let described = Described::new(a, b, &da, &db, params)?;
    let seconds = t.elapsed().as_secs_f64();
    let (sampled, sampling_seconds) = draw_samples(a, b, params);
    let params = sampled.as_ref().unwrap_or(params);
    let mut out = if params.starts.is_empty() {
        let mut out = match_described(a, b, &described, params)?;
        out.times.descriptors += seconds;
        out.times.total += seconds;
        out
    } else {
        multi_start(a, b, &described, seconds, params)?
    };
    out.times.refine += sampling_seconds;
    out.times.total += sampling_seconds;
    Ok(out)
}

fn orientation_of(t_ab: &[usize], a: &PreparedShape, b: &PreparedShape) -> Result<f64, MatchError> {
    Ok(refine::orientation_score(
        t_ab,
        &a.vertices,
        &a.faces,
        &b.vertices,
        &b.faces,
    )?)
}

/// Refines a pipeline result in place with any [`Refiner`]: `C_BA` (B's
/// functions to A's) is refined between the bases of `b` and `a`, and the
/// point map `T_AB` is the refiner's output. The unrefined map stays in
/// `t_ab_init`; the time goes to `times.refine` (and `times.total`).
pub fn refine_result(
    out: &mut MatchResult,
    a: &PreparedShape,
    b: &PreparedShape,
    refiner: &dyn Refiner,
) -> Result<(), MatchError> {
    let t = Instant::now();
    // A point map A -> B pulls functions back from B to A, so T_AB goes
    // with C_BA: the refiner's (c_ab, basis_a, basis_b) -> t_ba contract
    // is applied to the pair (B, A), and its t_ba is our T_AB.
    // The unrefined point map is the conversion of C_BA that the
    // refiner's first search repeats: its guess.
    let refined = refiner.refine(
        &refine::RefineInput::new(&out.c_ba, &b.basis, &a.basis)
            .with_geometry(b.geometry(), a.geometry())
            .with_guess(&out.t_ab),
    )?;
    out.c_ba = refined.c_ab;
    out.t_ab = refined.t_ba;
    out.refine = Some(refined.report);
    out.times.refine = t.elapsed().as_secs_f64();
    out.times.total += out.times.refine;
    Ok(())
}

impl PreparedShape {
    /// Its vertices and triangles, for refiners that work on the meshes.
    pub fn geometry(&self) -> refine::ShapeGeometry<'_> {
        refine::ShapeGeometry {
            vertices: &self.vertices,
            faces: &self.faces,
        }
    }
}

/// The arrays of a prepared shape the energy needs (its basis truncated
/// to the map's size).
fn shape_data<'a>(shape: &'a PreparedShape, truncated: &'a SpectralBasis) -> ShapeData<'a> {
    ShapeData {
        faces: &shape.faces,
        phi: &truncated.eigenvectors,
        evals: &truncated.eigenvalues,
        mass: &truncated.mass,
        area: shape.area,
    }
}

/// The energy parameters of `params`.
pub fn energy_params(params: &MatchParams) -> EnergyParams {
    let mut p = EnergyParams::default();
    p.weights = params.weights();
    p.resolvent_gamma = params.resolvent_gamma;
    p.orient_reversing = params.orient_reversing;
    p
}
