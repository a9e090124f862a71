//! Functional maps (M. Ovsjanikov et al., "Functional maps: a flexible
//! representation of maps between shapes", SIGGRAPH 2012) between two
//! shapes A and B with Laplace–Beltrami bases Φ_A (n_A x k_A) and Φ_B
//! (n_B x k_B), M-orthonormal.
//!
//! Conventions (names carry direction): `c_ab` is k_B x k_A and maps the
//! coefficients of a function on A to those of its transfer on B
//! (`b = C_AB a`); `t_ba` has length n_B and gives, for each vertex of B, a
//! vertex of A. A point map induces `C_AB = Φ_Bᵀ M_B Π_BA Φ_A` with `Π_BA`
//! the n_B x n_A selection matrix of `t_ba`; conversely
//! `T_BA(y) = argmin_x ‖C_AB Φ_A(x)ᵀ − Φ_B(y)ᵀ‖` (exact nearest neighbours
//! in the spectral embedding), or with the adjoint, `argmin_x ‖Φ_A(x)ᵀ −
//! C_ABᵀ Φ_B(y)ᵀ‖`.
//!
//! ```
//! use fmaps_solve::{fmap_from_point_map, point_map_from_fmap};
//! # use fmaps_eigensolve::{EigenProblem, EigenSolver, NativeSolver};
//! # use fmaps_laplacian::{cotan_laplacian, LaplacianParams};
//! # let mesh = fmaps_shapes::torus(2.0, 0.7, 20, 9);
//! # let op = cotan_laplacian(&mesh, &LaplacianParams::default());
//! # let basis = NativeSolver::default().solve(&EigenProblem::new(op.stiffness.view(), &op.mass)?, 20)?;
//! // The identity map of a shape to itself is the identity functional map,
//! // and back.
//! let n = basis.n();
//! let identity: Vec<usize> = (0..n).collect();
//! let c = fmap_from_point_map(&identity, &basis, &basis)?;
//! assert!((c.clone() - nalgebra::DMatrix::identity(20, 20)).amax() < 1e-10);
//! assert_eq!(point_map_from_fmap(&c, &basis, &basis)?, identity);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

mod assemble;
mod chol;
pub mod convert;
mod energy;
mod normal;
mod operators;
pub mod sinkhorn;
mod types;
mod weights;

use fmaps_eigensolve::SpectralBasis;
use nalgebra::DMatrix;

pub use assemble::{EnergyParams, ShapeData, build_energy};
pub use convert::{BasisRows, Conversion};
pub use energy::{
    FmapEnergy, OperatorPairs, PerTerm, SolveMethod, SolveReport, laplacian_mask,
    multiplication_operator, resolvent_mask,
};
pub use operators::{multiplication_operators, orientation_operators};
pub use types::{FunctionalMap, PointMap};
pub use weights::{
    compress_descriptors, effective_descriptor_count, normalize_weights, term_scales,
};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A size does not match.
    #[error("{what}: got {found}, expected {expected}")]
    SizeMismatch {
        /// What was compared.
        what: &'static str,
        /// Found.
        found: usize,
        /// Expected.
        expected: usize,
    },
    /// The energy's normal equations are not positive definite (all
    /// weights zero, or descriptors that do not constrain C).
    #[error(
        "the functional-map energy has no unique minimum (normal equations not positive definite); add descriptors or a positive Laplacian weight"
    )]
    NotPositiveDefinite,
    /// The nearest-neighbour search refused its input (empty shapes).
    #[error("nearest-neighbour search: {0}")]
    Search(fmaps_nearest::Error),
    /// A parameter is out of its range.
    #[error("{0}")]
    InvalidParameter(String),
    /// A point map refers to a vertex that does not exist.
    #[error("point map entry {at} is {index}, but the target shape has {n} vertices")]
    IndexOutOfRange {
        /// Position in the map.
        at: usize,
        /// The index.
        index: usize,
        /// Vertices of the shape indexed.
        n: usize,
    },
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// `C_AB = Φ_Bᵀ M_B Π_BA Φ_A` (k_B x k_A, all the eigenpairs of both bases)
/// from the point map `t_ba` (length n_B, values < n_A).
pub fn fmap_from_point_map(
    t_ba: &[usize],
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
) -> Result<DMatrix<f64>> {
    convert::pullback(
        t_ba,
        &BasisRows::new(basis_a, basis_a.k()),
        basis_a.k(),
        &BasisRows::new(basis_b, basis_b.k()),
        basis_b.k(),
        basis_b.mass.as_slice(),
    )
}

/// `T_BA(y) = argmin_x ‖C_AB Φ_A(x)ᵀ − Φ_B(y)ᵀ‖`: the point map B → A of a
/// functional map A → B (uses the first k_A and k_B eigenvectors, as `c_ab`
/// is sized). Exact nearest neighbours; from 20,000 vertices
/// of A (and without matrix tiles) they are searched in k-means clusters of
/// A's rows, built for this one search.
pub fn point_map_from_fmap(
    c_ab: &DMatrix<f64>,
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
) -> Result<Vec<usize>> {
    convert_once(c_ab, basis_a, basis_b, Conversion::Direct)
}

/// The adjoint conversion: `T_BA(y) = argmin_x ‖Φ_A(x)ᵀ − C_ABᵀ Φ_B(y)ᵀ‖`,
/// better when `C_AB` is far from square-orthonormal.
pub fn point_map_from_fmap_adjoint(
    c_ab: &DMatrix<f64>,
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
) -> Result<Vec<usize>> {
    convert_once(c_ab, basis_a, basis_b, Conversion::Adjoint)
}

/// One conversion on fresh row-major copies of the bases (the refiners
/// keep theirs across iterations).
fn convert_once(
    c_ab: &DMatrix<f64>,
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
    conversion: Conversion,
) -> Result<Vec<usize>> {
    let (kb, ka) = check_fmap(c_ab, basis_a, basis_b)?;
    let (rows_a, rows_b) = (BasisRows::new(basis_a, ka), BasisRows::new(basis_b, kb));
    // On large shapes without matrix tiles, the ball search (exact) over
    // k-means clusters of A's rows, sized for one search without guesses
    // (`PartitionParams::coarse_ball_size`): the searched rows (`Φ_A Cᵀ` or `Φ_A`) are a
    // linear image of them, and a search without guesses otherwise
    // compares most pairs (docs/tuning.md: the 80k initial point map).
    let params = match fmaps_nearest::Partition::for_balls(
        rows_a.view(ka),
        fmaps_nearest::BallsRequest::new(BALLS_FROM_ROWS).one_search(),
    ) {
        Some(p) => fmaps_nearest::NnParams::with_strategy(fmaps_nearest::NnStrategy::Balls)
            .with_partition(p),
        None => fmaps_nearest::NnParams::default(),
    };
    convert::point_map(c_ab, &rows_a, &rows_b, conversion, None, &params)
}

/// Rows of A from which [`point_map_from_fmap`] searches k-means clusters
/// (below, the default strategies are as fast).
pub(crate) const BALLS_FROM_ROWS: usize = 20_000;

/// Transfers functions on A (n_A x d) to B through `c_ab`:
/// `Φ_B C_AB Φ_Aᵀ M_A f` (n_B x d).
pub fn transfer_functions(
    c_ab: &DMatrix<f64>,
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
    f_a: &DMatrix<f64>,
) -> Result<DMatrix<f64>> {
    let (kb, ka) = check_fmap(c_ab, basis_a, basis_b)?;
    if f_a.nrows() != basis_a.n() {
        return Err(Error::SizeMismatch {
            what: "function rows vs vertices of A",
            found: f_a.nrows(),
            expected: basis_a.n(),
        });
    }
    let coeffs = basis_a.truncate(ka).project(f_a);
    Ok(basis_b.eigenvectors.columns(0, kb) * (c_ab * coeffs))
}

fn check_fmap(
    c_ab: &DMatrix<f64>,
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
) -> Result<(usize, usize)> {
    let (kb, ka) = c_ab.shape();
    if ka > basis_a.k() {
        return Err(Error::SizeMismatch {
            what: "C_AB columns vs eigenpairs of A",
            found: ka,
            expected: basis_a.k(),
        });
    }
    if kb > basis_b.k() {
        return Err(Error::SizeMismatch {
            what: "C_AB rows vs eigenpairs of B",
            found: kb,
            expected: basis_b.k(),
        });
    }
    Ok((kb, ka))
}

/// Structural measures of a functional map `c_ab` (k_B x k_A).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FmapMetrics {
    /// `‖C_ABᵀ C_AB − I‖_F`: 0 for an isometry (area-preserving map
    /// between bases of equal size).
    pub orthonormality: f64,
    /// `‖C_AB Λ_A − Λ_B C_AB‖_F / ‖Λ_B C_AB‖_F`: 0 when C commutes with the
    /// Laplacians (isometries).
    pub laplacian_commutativity: f64,
    /// Fraction of entries with `|C_ij| < 0.1` (the seed paper reports
    /// over 94% for near-isometric shapes at k = 100 ... 200).
    pub sparsity: f64,
}

/// [`FmapMetrics`] of `c_ab` with the first k_A and k_B eigenvalues.
pub fn fmap_metrics(
    c_ab: &DMatrix<f64>,
    evals_a: &nalgebra::DVector<f64>,
    evals_b: &nalgebra::DVector<f64>,
) -> Result<FmapMetrics> {
    let (kb, ka) = c_ab.shape();
    if evals_a.len() < ka || evals_b.len() < kb {
        return Err(Error::SizeMismatch {
            what: "eigenvalues vs the size of C_AB",
            found: evals_a.len().min(evals_b.len()),
            expected: ka.max(kb),
        });
    }
    let ctc = c_ab.tr_mul(c_ab);
    let orthonormality = (ctc - DMatrix::identity(ka, ka)).norm();
    let cl = DMatrix::from_fn(kb, ka, |i, j| c_ab[(i, j)] * evals_a[j]);
    let lc = DMatrix::from_fn(kb, ka, |i, j| evals_b[i] * c_ab[(i, j)]);
    let denom = lc.norm();
    let laplacian_commutativity = if denom > 0.0 {
        (cl - &lc).norm() / denom
    } else {
        0.0
    };
    let small = c_ab.iter().filter(|v| v.abs() < 0.1).count();
    Ok(FmapMetrics {
        orthonormality,
        laplacian_commutativity,
        sparsity: small as f64 / (ka * kb).max(1) as f64,
    })
}

/// Rows `rows_b` of the soft point map `Φ_B C_AB Φ_Aᵀ M_A` (the seed
/// paper's first perspective: row y is the image of the delta at y pulled
/// back to A, a function on A). Returns `rows_b.len()` x n_A; only the
/// asked rows are formed, never n_B x n_A.
pub fn soft_map_rows(
    c_ab: &DMatrix<f64>,
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
    rows_b: &[usize],
) -> Result<DMatrix<f64>> {
    let (kb, ka) = check_fmap(c_ab, basis_a, basis_b)?;
    if let Some((at, &index)) = rows_b.iter().enumerate().find(|(_, y)| **y >= basis_b.n()) {
        return Err(Error::IndexOutOfRange {
            at,
            index,
            n: basis_b.n(),
        });
    }
    let phib = DMatrix::from_fn(rows_b.len(), kb, |r, j| {
        basis_b.eigenvectors[(rows_b[r], j)]
    });
    let coeffs = phib * c_ab; // rows x k_A
    let mut out = coeffs * basis_a.eigenvectors.columns(0, ka).transpose();
    for (x, mut col) in out.column_iter_mut().enumerate() {
        col *= basis_a.mass[x];
    }
    Ok(out)
}
