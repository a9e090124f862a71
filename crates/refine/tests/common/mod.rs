//! Helpers shared by this crate's integration tests.

use fmaps_eigensolve::{EigenProblem, EigenSolver, NativeSolver, SpectralBasis};
use fmaps_laplacian::{LaplacianParams, cotan_laplacian};
use fmaps_mesh_io::TriMesh;

/// The first `k` eigenpairs of `mesh`'s cotangent Laplacian (native
/// solver).
pub fn basis(mesh: &TriMesh, k: usize) -> SpectralBasis {
    let op = cotan_laplacian(mesh, &LaplacianParams::default());
    NativeSolver::default()
        .solve(
            &EigenProblem::new(op.stiffness.view(), &op.mass).unwrap(),
            k,
        )
        .unwrap()
}
