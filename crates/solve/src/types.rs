//! Direction-carrying wrappers of the plain conversions.
//!
//! A [`PointMap`] from S to T gives a T vertex for every S vertex; a
//! [`FunctionalMap`] from S to T maps coefficients of functions on S to
//! coefficients on T. The two go opposite ways: a point map T → S pulls
//! functions on S back to T, so it induces the functional map S → T.

use fmaps_eigensolve::SpectralBasis;
use nalgebra::DMatrix;

use crate::{Error, Result};

/// A vertex-to-vertex map from a source shape to a target shape.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointMap {
    targets: Vec<usize>,
    n_target: usize,
}

impl PointMap {
    /// `targets[x]` is the target vertex of source vertex x; every entry
    /// must be below `n_target`.
    pub fn new(targets: Vec<usize>, n_target: usize) -> Result<Self> {
        if let Some((at, &index)) = targets.iter().enumerate().find(|(_, t)| **t >= n_target) {
            return Err(Error::IndexOutOfRange {
                at,
                index,
                n: n_target,
            });
        }
        Ok(PointMap { targets, n_target })
    }

    /// The target vertex of every source vertex.
    pub fn targets(&self) -> &[usize] {
        &self.targets
    }

    /// Vertices of the source shape.
    pub fn n_source(&self) -> usize {
        self.targets.len()
    }

    /// Vertices of the target shape.
    pub fn n_target(&self) -> usize {
        self.n_target
    }

    /// The plain vector.
    pub fn into_targets(self) -> Vec<usize> {
        self.targets
    }
}

/// A functional map from a source shape to a target shape: the
/// k_target x k_source matrix C with `b = C a` for the coefficients `a` of a
/// function on the source and `b` of its transfer on the target.
#[derive(Debug, Clone, PartialEq)]
pub struct FunctionalMap {
    matrix: DMatrix<f64>,
}

impl FunctionalMap {
    /// Wraps C (k_target x k_source).
    pub fn new(matrix: DMatrix<f64>) -> Self {
        FunctionalMap { matrix }
    }

    /// The functional map S → T induced by a point map T → S
    /// (`C = Φ_Tᵀ M_T Π Φ_S`), with all eigenpairs of both bases.
    pub fn from_point_map(
        target_to_source: &PointMap,
        source: &SpectralBasis,
        target: &SpectralBasis,
    ) -> Result<Self> {
        if target_to_source.n_target() != source.n() {
            return Err(Error::SizeMismatch {
                what: "point map's target vertices vs the source basis",
                found: target_to_source.n_target(),
                expected: source.n(),
            });
        }
        crate::fmap_from_point_map(target_to_source.targets(), source, target).map(Self::new)
    }

    /// The point map T → S it encodes (nearest neighbours in the spectral
    /// embedding; `adjoint` selects the adjoint conversion).
    pub fn to_point_map(
        &self,
        source: &SpectralBasis,
        target: &SpectralBasis,
        adjoint: bool,
    ) -> Result<PointMap> {
        let t = if adjoint {
            crate::point_map_from_fmap_adjoint(&self.matrix, source, target)?
        } else {
            crate::point_map_from_fmap(&self.matrix, source, target)?
        };
        PointMap::new(t, source.n())
    }

    /// Transfers coefficients (k_source x d) to the target (k_target x d).
    pub fn transfer_coefficients(&self, a: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        if a.nrows() != self.k_source() {
            return Err(Error::SizeMismatch {
                what: "coefficient rows vs k_source",
                found: a.nrows(),
                expected: self.k_source(),
            });
        }
        Ok(&self.matrix * a)
    }

    /// The matrix C.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.matrix
    }

    /// Basis size on the source (columns of C).
    pub fn k_source(&self) -> usize {
        self.matrix.ncols()
    }

    /// Basis size on the target (rows of C).
    pub fn k_target(&self) -> usize {
        self.matrix.nrows()
    }
}
