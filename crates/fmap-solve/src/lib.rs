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
//! # let mesh = fmaps_mesh_io::generate::torus(2.0, 0.7, 20, 9);
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

mod energy;
mod nn;

use fmaps_eigensolve::SpectralBasis;
use nalgebra::DMatrix;

pub use energy::{FmapEnergy, laplacian_mask, multiplication_operator, resolvent_mask};
pub use nn::nearest_rows;

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
    let (na, nb) = (basis_a.n(), basis_b.n());
    if t_ba.len() != nb {
        return Err(Error::SizeMismatch {
            what: "point map T_BA length vs vertices of B",
            found: t_ba.len(),
            expected: nb,
        });
    }
    if let Some((at, &index)) = t_ba.iter().enumerate().find(|(_, x)| **x >= na) {
        return Err(Error::IndexOutOfRange { at, index, n: na });
    }
    let ka = basis_a.k();
    // Π_BA Φ_A: row y is row t_ba[y] of Φ_A; then weight rows by M_B.
    let pulled = DMatrix::from_fn(nb, ka, |y, j| {
        basis_b.mass[y] * basis_a.eigenvectors[(t_ba[y], j)]
    });
    Ok(basis_b.eigenvectors.tr_mul(&pulled))
}

/// `T_BA(y) = argmin_x ‖C_AB Φ_A(x)ᵀ − Φ_B(y)ᵀ‖`: the point map B → A of a
/// functional map A → B (uses the first k_A and k_B eigenvectors, as `c_ab`
/// is sized).
pub fn point_map_from_fmap(
    c_ab: &DMatrix<f64>,
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
) -> Result<Vec<usize>> {
    let (kb, ka) = check_fmap(c_ab, basis_a, basis_b)?;
    let emb_a = basis_a.eigenvectors.columns(0, ka) * c_ab.transpose(); // n_A x k_B
    let emb_b = basis_b.eigenvectors.columns(0, kb).into_owned();
    Ok(nearest_rows(&emb_a, &emb_b))
}

/// The adjoint conversion: `T_BA(y) = argmin_x ‖Φ_A(x)ᵀ − C_ABᵀ Φ_B(y)ᵀ‖`,
/// better when `C_AB` is far from square-orthonormal.
pub fn point_map_from_fmap_adjoint(
    c_ab: &DMatrix<f64>,
    basis_a: &SpectralBasis,
    basis_b: &SpectralBasis,
) -> Result<Vec<usize>> {
    let (kb, ka) = check_fmap(c_ab, basis_a, basis_b)?;
    let emb_a = basis_a.eigenvectors.columns(0, ka).into_owned();
    let emb_b = basis_b.eigenvectors.columns(0, kb) * c_ab; // n_B x k_A
    Ok(nearest_rows(&emb_a, &emb_b))
}

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
