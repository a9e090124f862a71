//! fmaps: non-rigid 3D shape matching with functional maps, in Rust.
//!
//! This facade re-exports the crates of the pipeline, each usable alone:
//!
//! | module | crate | what |
//! | --- | --- | --- |
//! | [`mesh_io`] | `fmaps-mesh-io` | `TriMesh`, OFF/OBJ/PLY, `.vts`/`.map`, validation |
//! | [`laplacian`] | `fmaps-laplacian` | cotangent stiffness, lumped/Voronoi mass |
//! | [`eigensolve`] | `fmaps-eigensolve` | `EigenSolver` trait, native/ARPACK/dense backends, `SpectralBasis` |
//! | [`geodesic`] | `fmaps-geodesic` | exact polyhedral geodesics, Dijkstra |
//! | [`eval`] | `fmaps-eval` | benchmark protocol: geodesic errors, curves, dataset loader |
//! | [`descriptors`] | `fmaps-descriptors` | HKS, WKS, landmark descriptors |
//! | [`solve`] | `fmaps-solve` | functional-map energy and exact solve, map conversions |
//! | [`nearest`] | `fmaps-nearest` | exact nearest rows in spectral embeddings |
//! | [`refine`] | `fmaps-refine` | Smooth Shells, ZoomOut, ICP, discrete optimisation, orientation score |
//! | [`shapes`] | `fmaps-shapes` | shapes generated in code with exact ground truth |
//! | `viz` | `fmaps-viz` | software rendering to PNG, colour maps, plots (feature `viz`) |
//!
//! and provides [`spectrum`], the mesh-to-eigenbasis stage with per-stage
//! timings, [`pipeline`] ([`match_shapes`]: two meshes to a point map),
//! [`demo`] (the built-in pairs) and `pictures` of a map (feature `viz`;
//! NumPy files: [`mesh_io::npy`]).
//!
//! ```
//! use fmaps::{spectrum, SpectrumParams};
//! use fmaps::shapes::icosphere;
//!
//! // The first nine eigenvalues of a unit sphere: 0, then 2 (x3), then 6 (x5).
//! let out = spectrum(&icosphere(1.0, 3), 9, &SpectrumParams::default())?;
//! let ev = &out.basis.eigenvalues;
//! assert!(ev[0].abs() < 1e-9);
//! assert!((1..4).all(|i| (ev[i] - 2.0).abs() < 0.01));
//! assert!((4..9).all(|i| (ev[i] - 6.0).abs() < 0.05));
//! # Ok::<(), fmaps::eigensolve::Error>(())
//! ```
//!
//! # Features
//!
//! - `viz` (default): `fmaps::viz` and `fmaps::pictures`, pictures of maps
//!   without a GPU.
//! - `published-maps` (default): the benchmark's published maps read from
//!   their zip archives (`fmaps::eval::PublishedMaps`).
//! - `serde`: `Serialize` for the reports.
//! - `arpack`: the ARPACK eigensolver backend (needs system libraries).
//!
//! A library that only matches shapes can turn the defaults off:
//! `fmaps = { version = "0.1", default-features = false }`.
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod demo;
#[cfg(feature = "viz")]
pub mod pictures;
pub mod pipeline;

use std::sync::Arc;
use std::time::Instant;

pub use fmaps_descriptors as descriptors;
pub use fmaps_eigensolve as eigensolve;
pub use fmaps_eval as eval;
pub use fmaps_geodesic as geodesic;
pub use fmaps_laplacian as laplacian;
pub use fmaps_learn as learn;
pub use fmaps_mesh_io as mesh_io;
pub use fmaps_nearest as nearest;
pub use fmaps_refine as refine;
pub use fmaps_shapes as shapes;
pub use fmaps_solve as solve;
#[cfg(feature = "viz")]
pub use fmaps_viz as viz;
pub use pipeline::{MatchParams, MatchResult, match_shapes};

use eigensolve::{EigenProblem, EigenSolver, NativeParams, NativeSolver, SpectralBasis};
use laplacian::{LaplacianParams, MassKind};
use mesh_io::TriMesh;

/// An eigensolver shared between threads (the pipeline solves both
/// shapes side by side).
pub type SharedSolver = Arc<dyn EigenSolver + Send + Sync>;

/// The eigensolver of [`spectrum`]: a built-in backend by name, or any
/// [`EigenSolver`] (`Backend::Custom`), e.g. a third-party backend that
/// passes [`eigensolve::conformance::check`].
#[derive(Clone, Default)]
#[non_exhaustive]
pub enum Backend {
    /// Pure-Rust shift-invert block Krylov–Schur (default).
    #[default]
    Native,
    /// ARPACK (needs the `arpack` feature).
    Arpack,
    /// Dense reference (small meshes only).
    Dense,
    /// Any backend, used as it is (the thread and block-size knobs of
    /// [`SpectrumParams`] do not reach it).
    Custom(SharedSolver),
}

impl std::fmt::Debug for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Backend::Native => f.write_str("Native"),
            Backend::Arpack => f.write_str("Arpack"),
            Backend::Dense => f.write_str("Dense"),
            Backend::Custom(s) => write!(f, "Custom({:?})", s.name()),
        }
    }
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "native" => Ok(Backend::Native),
            "arpack" => Ok(Backend::Arpack),
            "dense" => Ok(Backend::Dense),
            _ => Err(format!("unknown backend '{s}' (native, arpack, dense)")),
        }
    }
}

impl Backend {
    /// Builds the solver, or explains why it is not available.
    pub fn solver(
        &self,
        threads: usize,
        block_size: Option<usize>,
    ) -> Result<SharedSolver, eigensolve::Error> {
        match self {
            Backend::Native => {
                let mut p = NativeParams::default();
                p.threads = threads;
                p.block_size = block_size.unwrap_or(p.block_size);
                Ok(Arc::new(NativeSolver::new(p)))
            }
            Backend::Dense => Ok(Arc::new(eigensolve::DenseSolver::default())),
            #[cfg(feature = "arpack")]
            Backend::Arpack => Ok(Arc::new(eigensolve::ArpackSolver::default())),
            #[cfg(not(feature = "arpack"))]
            Backend::Arpack => Err(eigensolve::Error::InvalidParameter(
                "this fmaps was built without the ARPACK backend; rebuild with `--features arpack`"
                    .into(),
            )),
            Backend::Custom(s) => Ok(Arc::clone(s)),
        }
    }
}

/// Options of [`spectrum`].
#[derive(Debug, Clone, Default)]
#[non_exhaustive]
pub struct SpectrumParams {
    /// Mass matrix kind.
    pub mass: MassKind,
    /// Eigensolver backend.
    pub backend: Backend,
    /// Threads for the eigensolver (0 or 1 = sequential).
    pub threads: usize,
    /// Block size of the native backend (`None`: its default).
    pub block_size: Option<usize>,
}

/// Seconds spent in each stage of [`spectrum`].
#[derive(Debug, Clone, Copy, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct StageTimes {
    /// Cotangent Laplacian assembly.
    pub laplacian: f64,
    /// Factorization of `L − σM` (0 for backends that do not factorize).
    pub factorization: f64,
    /// Eigensolver iteration after the factorization.
    pub eigensolve: f64,
}

/// The result of [`spectrum`].
#[derive(Debug, Clone)]
pub struct Spectrum {
    /// The eigenbasis.
    pub basis: SpectralBasis,
    /// Degenerate faces the Laplacian skipped.
    pub skipped_faces: Vec<usize>,
    /// Stage timings.
    pub times: StageTimes,
}

/// The first `k` Laplace–Beltrami eigenpairs of a mesh: cotangent
/// Laplacian, then the chosen eigensolver.
pub fn spectrum(
    mesh: &TriMesh,
    k: usize,
    params: &SpectrumParams,
) -> Result<Spectrum, eigensolve::Error> {
    let t = Instant::now();
    let op = laplacian::cotan_laplacian(mesh, &LaplacianParams::with_mass(params.mass));
    let lap = t.elapsed().as_secs_f64();
    let problem = EigenProblem::new(op.stiffness.view(), &op.mass)?;
    let solver = params
        .backend
        .solver(params.threads.max(1), params.block_size)?;
    let basis = solver.solve(&problem, k)?;
    let times = StageTimes {
        laplacian: lap,
        factorization: basis.report.factorization_seconds,
        eigensolve: basis.report.iteration_seconds,
    };
    Ok(Spectrum {
        basis,
        skipped_faces: op.skipped_faces,
        times,
    })
}

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
