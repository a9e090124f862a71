//! Deep functional maps for fmaps: the learned side of shape matching
//! (Litany et al. 2017 onwards). A network learns per-vertex features, a
//! differentiable layer solves the functional map from them, and losses on
//! the map train the network without labels.
//!
//! This crate holds what DiffusionNet (Sharp, Attaiki, Crane, Ovsjanikov,
//! ToG 2022), the feature extractor of the field's current methods, needs
//! of each shape, computed once per mesh from the workspace's Laplacian
//! and eigensolver ([`ShapeOperators`]): the lumped mass and the first k
//! eigenpairs for the learned spectral diffusion, a tangent frame per
//! vertex and the sparse gradient operators for the spatial gradient
//! features; [`layers`] holds its layers with their backward passes,
//! [`network`] the whole network, [`fmap_layer`] the differentiable
//! functional-map solve, [`losses`] and [`coupling`] the unsupervised
//! losses, [`optim`] Adam and gradient clipping, [`train`] the training
//! loop and its checkpoints, [`model`] a trained network and its file.
//!
//! ```
//! use fmaps_learn::ShapeOperators;
//!
//! let mesh = fmaps_shapes::icosphere(1.0, 2);
//! let ops = ShapeOperators::compute(&mesh, 16)?;
//! // The frames are orthonormal; the normals of a sphere point outwards.
//! let f = ops.frames[0];
//! let p = mesh.vertices()[0];
//! let outward: f64 = (0..3).map(|c| f.normal[c] * p[c]).sum();
//! assert!(outward > 0.99);
//! # Ok::<(), fmaps_learn::Error>(())
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod adapt;
pub mod augment;
pub mod coupling;
pub mod dirichlet;
pub mod fmap_layer;
mod gemm;
pub mod layers;
pub mod losses;
pub mod model;
pub mod network;
pub mod operators;
pub mod optim;
pub mod train;

pub use operators::{Frame, ShapeOperators};

/// Helpers of the unit tests.
#[cfg(test)]
mod testing {
    use nalgebra::DMatrix;

    /// A reproducible `r` x `c` matrix of values in [−1, 1).
    pub(crate) fn random(r: usize, c: usize, seed: u64) -> DMatrix<f64> {
        let mut rng = fmaps_simd::SplitMix(seed);
        DMatrix::from_fn(r, c, |_, _| rng.symmetric())
    }
}

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A parameter is out of range.
    #[error("invalid parameter: {0}")]
    Parameter(String),
    /// The mesh has a vertex the operators cannot be built at.
    #[error("vertex {vertex}: {problem}")]
    Mesh {
        /// The vertex (0-based).
        vertex: usize,
        /// What is wrong.
        problem: String,
    },
    /// The eigensolver failed.
    #[error("eigenbasis: {0}")]
    Eigen(#[from] fmaps_eigensolve::Error),
    /// A mesh or cache file could not be read or written.
    #[error("{0}")]
    File(#[from] fmaps_mesh_io::Error),
    /// The input descriptors could not be computed.
    #[error("input features: {0}")]
    Descriptors(#[from] fmaps_descriptors::Error),
    /// A model or checkpoint file is not one this crate reads.
    #[error("{}: {problem}", path.display())]
    ModelFile {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A file could not be written.
    #[error("{}: cannot write: {source}", path.display())]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// Training produced a loss or gradient that is not finite.
    #[error("step {step}: the loss is not finite ({what}); the last checkpoint is kept")]
    NonFinite {
        /// The step (1-based).
        step: u64,
        /// Which value and pair.
        what: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
