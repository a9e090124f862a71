//! Refinement of functional maps, part of fmaps.
//!
//! A functional map `C_AB` (k_B x k_A, coefficients on A to coefficients
//! on B) computed from descriptors is noisy; the refiners here alternate
//! between the point map it induces and the functional map that point map
//! induces:
//!
//! - [`Icp`]: ICP in the spectral domain (Ovsjanikov et al. 2012, §6.1):
//!   `T_BA = NN(C)`, `C ← Φ_Bᵀ M_B Π_BA Φ_A`, then the nearest orthonormal
//!   matrix `U Vᵀ` (orthogonal Procrustes). It stops early, with the same
//!   result, once the point map repeats (a fixed point).
//! - [`ZoomOut`] (Melzi et al., "ZoomOut: spectral upsampling for efficient
//!   shape correspondence", SIGGRAPH Asia 2019): the same alternation while
//!   the basis grows from k_start to k_final by `step`; with the common
//!   options (adjoint conversion, sub-sampled iterations as in the paper's
//!   fast variant, a variant that averages both directions' maps).
//! - [`DiscreteOp`] (Ren, Melzi, Wonka, Ovsjanikov, "Discrete Optimization
//!   for Shape Matching", SGP 2021): functional-map energies (properness,
//!   bijectivity, orthogonality, Laplacian commutativity) minimised over
//!   pairs of point maps by nearest-neighbour searches in concatenated
//!   embeddings; its presets include the paper's bijective ZoomOut.
//!
//! - [`Repair`]: a repair of the BCICP class (Ren, Poulenard, Wonka,
//!   Ovsjanikov, SIGGRAPH Asia 2018): bijective ICP in the spectral
//!   domain alternated with coverage, continuity and smoothness repairs of
//!   both point maps on the meshes ([`RefineInput::with_geometry`]).
//! - [`SmoothShells`] (Eisenberger, Lähner, Cremers, CVPR 2020): the
//!   shapes' smooth shells aligned coarse to fine by a deformation field
//!   and a functional map in a product space, after its own
//!   descriptor-free initialisation (rigid alignment and deformation
//!   proposals); the strongest refiner here on non-isometric pairs, and
//!   stronger still with [`SmoothShells::non_isometric`] (all eight rigid
//!   orientations screened).
//! - Map scores without ground truth: [`orientation_score`] (folds) and
//!   [`area_distortion`] (stretching), used to choose among hypotheses.
//!
//! All implement [`Refiner`], so a pipeline swaps one for the other (or
//! for its own) through a trait object. Every nearest-neighbour search is
//! exact ([`fmaps_nearest::nearest_rows`]), so the results are deterministic
//! and independent of the thread count.
//!
//! ```
//! use fmaps_refine::{RefineInput, Refiner, ZoomOut};
//! # use fmaps_eigensolve::{EigenProblem, EigenSolver, NativeSolver};
//! # use fmaps_laplacian::{cotan_laplacian, LaplacianParams};
//! # let mesh = fmaps_shapes::torus(2.0, 0.7, 24, 11);
//! # let op = cotan_laplacian(&mesh, &LaplacianParams::default());
//! # let basis = NativeSolver::default().solve(&EigenProblem::new(op.stiffness.view(), &op.mass)?, 40)?;
//! // Refine the identity functional map of a shape to itself, from a 10 x 10
//! // block up to 40 x 40: the map stays the identity.
//! let c = nalgebra::DMatrix::<f64>::identity(10, 10);
//! let zo = ZoomOut { k_start: 10, k_final: 40, step: 5, ..ZoomOut::default() };
//! let out = zo.refine(&RefineInput::new(&c, &basis, &basis))?;
//! assert_eq!(out.c_ab.shape(), (40, 40));
//! assert!(out.t_ba.iter().enumerate().all(|(y, &x)| x == y));
//! println!("{}", out.report);
//!
//! // Bijective ZoomOut on the same schedule: also the identity.
//! let bij = fmaps_refine::DiscreteOp {
//!     k_start: 10,
//!     k_final: 40,
//!     step: 5,
//!     ..fmaps_refine::DiscreteOp::preset("bijective-zoomout")?
//! };
//! let out = bij.refine(&RefineInput::new(&c, &basis, &basis))?;
//! assert!(out.t_ba.iter().enumerate().all(|(y, &x)| x == y));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

mod best_of;
pub mod conformance;
mod discrete;
mod icp;
mod orientation;
mod repair;
mod sampling;
mod shells;
pub mod starts;
mod zoomout;

use std::fmt;

use fmaps_eigensolve::SpectralBasis;
use nalgebra::DMatrix;

pub use best_of::BestOf;
pub use discrete::{DiscreteOp, DiscreteWeights};
pub use icp::Icp;
pub use orientation::{area_distortion, orientation_score};
pub use repair::Repair;
pub use sampling::{farthest_point_sampling, farthest_point_sampling_with_nearest};
pub use shells::{Select, SmoothShells};
pub(crate) use zoomout::search_cells;
pub use zoomout::{Subsample, ZoomOut};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A basis has fewer eigenpairs than the refinement needs.
    #[error("shape {shape}: the refinement needs {needed} eigenpairs, the basis has {available}")]
    NotEnoughEigenpairs {
        /// "A" or "B".
        shape: &'static str,
        /// Eigenpairs needed.
        needed: usize,
        /// Eigenpairs available.
        available: usize,
    },
    /// A parameter is out of range.
    #[error("invalid refinement parameter: {0}")]
    InvalidParameter(String),
    /// A sub-sample index is out of range.
    #[error(
        "sub-sample of shape {shape}: entry {at} is vertex {index}, but the shape has {n} vertices"
    )]
    SampleOutOfRange {
        /// "A" or "B".
        shape: &'static str,
        /// Position in the sample list.
        at: usize,
        /// The index.
        index: usize,
        /// Vertices of the shape.
        n: usize,
    },
    /// The least-squares fit on a sub-sample is singular (too few or
    /// degenerate samples for the basis size).
    #[error(
        "the sub-sampled basis of shape B ({samples} rows, {k} columns) is rank deficient; use more samples"
    )]
    SingularSample {
        /// Sample rows.
        samples: usize,
        /// Basis columns.
        k: usize,
    },
    /// A conversion failed (sizes).
    #[error(transparent)]
    Solve(#[from] fmaps_solve::Error),
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A refined functional map and the point map it induces.
#[derive(Debug, Clone)]
pub struct Refined {
    /// The refined `C_AB` (k_B x k_A at the final sizes).
    pub c_ab: DMatrix<f64>,
    /// The point map B → A induced by `c_ab` (one A vertex per B vertex,
    /// all vertices of B, with the refiner's conversion).
    pub t_ba: Vec<usize>,
    /// What happened.
    pub report: RefineReport,
}

/// One iteration of a refinement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Iteration {
    /// Basis sizes of the functional map this iteration produced (k_A, k_B).
    pub k: (usize, usize),
    /// Query points (vertices of B, or the samples of B) whose image under
    /// the point map this iteration computed differs from the point map
    /// before it (for the first ZoomOut iteration: all of them).
    pub changed: usize,
    /// Wall-clock seconds of the iteration.
    pub seconds: f64,
}

/// The convergence and iteration report of a refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct RefineReport {
    /// The refiner's name with its parameters, e.g. `zoomout 50:150:5`.
    pub method: String,
    /// Per iteration.
    pub iterations: Vec<Iteration>,
    /// For ICP: the point map reached a fixed point before the iteration
    /// limit. For ZoomOut: the final size was reached.
    pub converged: bool,
    /// Nearest-neighbour searches performed (the dominant cost).
    pub nn_searches: usize,
    /// Seconds spent in nearest-neighbour searches.
    pub nn_seconds: f64,
    /// Total wall-clock seconds.
    pub seconds: f64,
}

impl RefineReport {
    /// The report of a refinement that is starting: no iterations yet.
    pub(crate) fn start(method: String) -> RefineReport {
        RefineReport {
            method,
            iterations: Vec::new(),
            converged: false,
            nn_searches: 0,
            nn_seconds: 0.0,
            seconds: 0.0,
        }
    }
}

impl fmt::Display for RefineReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let last = self.iterations.last();
        write!(
            f,
            "{}: {} iterations{}, {} NN searches ({:.3} s), {:.3} s",
            self.method,
            self.iterations.len(),
            if self.converged {
                ""
            } else {
                " (not converged)"
            },
            self.nn_searches,
            self.nn_seconds,
            self.seconds
        )?;
        if let Some(it) = last {
            write!(
                f,
                "; final k = {}x{}, last change {} points",
                it.k.1, it.k.0, it.changed
            )?;
        }
        Ok(())
    }
}

/// A shape's vertices and triangles, for [`RefineInput::with_geometry`].
#[derive(Debug, Clone, Copy)]
pub struct ShapeGeometry<'a> {
    /// Vertex positions (the rows of the shape's basis, in order).
    pub vertices: &'a [[f64; 3]],
    /// Triangles (0-based vertex indices).
    pub faces: &'a [[usize; 3]],
}

/// What a refinement starts from: the functional map and both bases, and,
/// where the caller has them, the shapes' geometry and a guess of the
/// point map. Build it with [`RefineInput::new`] and add the optional parts
/// with [`with_geometry`](Self::with_geometry) and
/// [`with_guess`](Self::with_guess).
#[derive(Clone, Copy)]
#[non_exhaustive]
pub struct RefineInput<'a> {
    /// The functional map A → B, k_B x k_A (its sizes select the leading
    /// eigenpairs of each basis).
    pub c_ab: &'a DMatrix<f64>,
    /// Shape A's eigenbasis.
    pub basis_a: &'a SpectralBasis,
    /// Shape B's eigenbasis.
    pub basis_b: &'a SpectralBasis,
    /// Both shapes' vertex positions and triangles (rows in the order of
    /// the bases), for refiners that work on the surfaces as well
    /// ([`Repair`], [`SmoothShells`]: an error without them).
    pub geometry: Option<(ShapeGeometry<'a>, ShapeGeometry<'a>)>,
    /// A guess of the point map `T_BA` (one vertex of A per vertex of B),
    /// e.g. the conversion of `c_ab` a pipeline has already made: refiners
    /// whose first step converts `c_ab` by an exact nearest-neighbour
    /// search (ZoomOut, ICP) start that search from it, which only makes
    /// it faster: the result is the same for any guess. A guess of the
    /// wrong length is ignored.
    pub t_ba_guess: Option<&'a [usize]>,
    /// Corresponding vertices the user knows, `(vertex of A, vertex of
    /// B)`: refiners that align the shapes in space ([`SmoothShells`])
    /// take their rigid alignment from them (at least three); the others
    /// ignore them.
    pub landmarks: &'a [(usize, usize)],
}

impl<'a> RefineInput<'a> {
    /// The functional map and the bases, without geometry or guess.
    pub fn new(
        c_ab: &'a DMatrix<f64>,
        basis_a: &'a SpectralBasis,
        basis_b: &'a SpectralBasis,
    ) -> Self {
        RefineInput {
            c_ab,
            basis_a,
            basis_b,
            geometry: None,
            t_ba_guess: None,
            landmarks: &[],
        }
    }

    /// With both shapes' geometry.
    pub fn with_geometry(self, a: ShapeGeometry<'a>, b: ShapeGeometry<'a>) -> Self {
        RefineInput {
            geometry: Some((a, b)),
            ..self
        }
    }

    /// With landmark pairs `(vertex of A, vertex of B)`.
    pub fn with_landmarks(self, landmarks: &'a [(usize, usize)]) -> Self {
        RefineInput { landmarks, ..self }
    }

    /// With a guess of the point map B → A.
    pub fn with_guess(self, t_ba: &'a [usize]) -> Self {
        RefineInput {
            t_ba_guess: Some(t_ba),
            ..self
        }
    }

    /// The geometry, or the error saying that `what` needs it.
    pub(crate) fn geometry_for(
        &self,
        what: &str,
    ) -> Result<(ShapeGeometry<'a>, ShapeGeometry<'a>)> {
        self.geometry.ok_or_else(|| {
            Error::InvalidParameter(format!(
                "{what} works on the shapes as well as their bases: give their geometry (RefineInput::with_geometry)"
            ))
        })
    }
}

/// A refinement of a functional map between two shapes.
///
/// The input's `c_ab` is k_B x k_A (its sizes select the leading
/// eigenpairs of each basis); the result holds the refined map and the
/// point map B → A it induces. `Debug` shows its parameters (a
/// pipeline's parameters print the refiner they hold).
pub trait Refiner: Send + Sync + std::fmt::Debug {
    /// A short name with the parameters (for reports and tables).
    fn name(&self) -> String;

    /// Refines `input.c_ab` (with the geometry and the guess where the
    /// refiner uses them).
    fn refine(&self, input: &RefineInput<'_>) -> Result<Refined>;

    /// Eigenpairs per shape the refinement needs beyond the size of the
    /// map it is given (ZoomOut: its final size); a pipeline computes at
    /// least this many. Default 0.
    fn k_needed(&self) -> usize {
        0
    }

    /// The same refiner for an initial map of size `k` when it reads a
    /// leading block of its input (ZoomOut and discrete optimisation start
    /// from `min(k_start, k)`), so that a pipeline can run it from initial
    /// maps of several sizes. Default `None`: the refiner takes any size
    /// as it is.
    fn for_initial_size(&self, k: usize) -> Option<Box<dyn Refiner>> {
        let _ = k;
        None
    }
}

/// The sizes a growing map takes after `k_start`: `k_start + step, ...,
/// k_final` (the last step clamped; a step of 0 counts as 1).
pub(crate) fn growth_schedule(k_start: usize, k_final: usize, step: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut k = k_start;
    while k < k_final {
        k = k.saturating_add(step.max(1)).min(k_final);
        out.push(k);
    }
    out
}

/// Errors unless each geometry has one vertex per basis row and its
/// faces index those vertices.
fn check_geometry(
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
    geo_a: &ShapeGeometry<'_>,
    geo_b: &ShapeGeometry<'_>,
) -> Result<()> {
    for (name, g, basis) in [("A", geo_a, basis_a), ("B", geo_b, basis_b)] {
        if g.vertices.len() != basis.eigenvectors.nrows()
            || g.faces.iter().flatten().any(|&v| v >= g.vertices.len())
        {
            return Err(Error::InvalidParameter(format!(
                "shape {name}: {} vertices (faces in range?) for a basis of {} rows",
                g.vertices.len(),
                basis.eigenvectors.nrows()
            )));
        }
    }
    Ok(())
}

fn check_k(basis: &SpectralBasis, shape: &'static str, needed: usize) -> Result<()> {
    if basis.k() < needed {
        return Err(Error::NotEnoughEigenpairs {
            shape,
            needed,
            available: basis.k(),
        });
    }
    Ok(())
}

fn count_changed(prev: Option<&[usize]>, next: &[usize]) -> usize {
    match prev {
        Some(p) => p.iter().zip(next).filter(|(a, b)| a != b).count(),
        None => next.len(),
    }
}
