//! The error type of `fmaps-eigensolve`.

/// Everything that can go wrong setting up or solving an eigenproblem.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The stiffness matrix is not square.
    #[error("the stiffness matrix is {rows} x {cols}; it must be square")]
    NotSquare {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
    },
    /// Stiffness and mass sizes differ.
    #[error("the stiffness matrix is {stiffness} x {stiffness} but the mass has {mass} entries")]
    SizeMismatch {
        /// Size of the stiffness matrix.
        stiffness: usize,
        /// Length of the mass diagonal.
        mass: usize,
    },
    /// A stiffness entry is NaN or infinite.
    #[error("stiffness entry ({row}, {col}) is not finite ({value})")]
    NonFiniteStiffness {
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The value.
        value: f64,
    },
    /// The stiffness matrix is not symmetric.
    #[error(
        "the stiffness matrix is not symmetric: entry ({row}, {col}) = {a_ij} but ({col}, {row}) = {a_ji}"
    )]
    NotSymmetric {
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// `L[row, col]`.
        a_ij: f64,
        /// `L[col, row]`.
        a_ji: f64,
    },
    /// A mass entry is zero, negative or not finite.
    #[error(
        "mass entry {index} is {value}; the mass must be positive and finite (is vertex {index} unreferenced or only in degenerate faces?)"
    )]
    NonPositiveMass {
        /// The vertex.
        index: usize,
        /// The value.
        value: f64,
    },
    /// `k` is zero or not smaller than the problem size.
    #[error("cannot compute {k} eigenpairs of a problem of size {n}: need 1 <= k < n")]
    InvalidK {
        /// Requested number of eigenpairs.
        k: usize,
        /// Problem size.
        n: usize,
    },
    /// A parameter is out of its valid range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// `L - σM` could not be factorized (it must be positive definite:
    /// `L` PSD and a negative shift σ).
    #[error(
        "the shifted matrix L - ({shift})M is not positive definite (pivot {pivot}); the stiffness must be positive semi-definite and the shift negative"
    )]
    NotPositiveDefinite {
        /// The shift σ.
        shift: f64,
        /// The failing pivot (in the permuted order).
        pivot: usize,
    },
    /// The problem is too large for the dense reference backend.
    #[error("the dense backend handles at most {max} unknowns, the problem has {n}")]
    TooLargeForDense {
        /// Problem size.
        n: usize,
        /// The limit.
        max: usize,
    },
    /// The iteration stopped before `wanted` eigenpairs met the tolerance.
    #[error(
        "no convergence: {converged} of {wanted} eigenpairs converged after {restarts} restarts ({operator_applications} operator applications); raise max_restarts or the subspace size"
    )]
    NoConvergence {
        /// Eigenpairs that met the tolerance.
        converged: usize,
        /// Eigenpairs requested.
        wanted: usize,
        /// Restarts performed.
        restarts: usize,
        /// Operator applications performed.
        operator_applications: usize,
    },
    /// Memory for the factorization or the Krylov basis could not be
    /// allocated.
    #[error("out of memory: {0}")]
    OutOfMemory(String),
    /// A backend's eigenpairs do not form a basis
    /// ([`SpectralBasis::from_eigenpairs`](crate::SpectralBasis::from_eigenpairs)).
    #[error("invalid eigenbasis: {0}")]
    InvalidBasis(String),
    /// An error reported by an external backend (ARPACK's info code).
    #[error("{backend} failed: {message}")]
    Backend {
        /// The backend.
        backend: &'static str,
        /// Its message.
        message: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
