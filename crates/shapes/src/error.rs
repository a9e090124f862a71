//! The error type of the shape generators.

/// What can go wrong when generating a shape.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The shape cannot be built with the parameters given (a grid with too
    /// few cells, a pose the collection does not have, a surface the grid
    /// misses); the message names the parameter.
    #[error("{0}")]
    Parameter(String),
    /// The generated vertices or faces do not form a valid mesh (for example
    /// a translation to non-finite coordinates).
    #[error(transparent)]
    Mesh(#[from] fmaps_mesh_io::Error),
}

/// `Result` with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
