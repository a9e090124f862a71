//! The pipeline's error type.

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
    Descriptors(#[from] fmaps_descriptors::Error),
    /// The solve or the conversion failed.
    #[error("functional map: {0}")]
    Solve(#[from] fmaps_solve::Error),
    /// The refinement failed.
    #[error("refinement: {0}")]
    Refine(#[from] fmaps_refine::Error),
    /// The learned features failed (a model the shapes do not fit, an
    /// adaptation that diverged).
    #[error("learned features: {0}")]
    Learned(fmaps_learn::Error),
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
