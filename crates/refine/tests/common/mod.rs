//! Helpers shared by this crate's integration tests.

use fmaps_eigensolve::{EigenProblem, EigenSolver, NativeSolver, SpectralBasis};
use fmaps_laplacian::{LaplacianParams, cotan_laplacian};
use fmaps_mesh_io::TriMesh;
use fmaps_shapes::torus;

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

/// A torus of 1800 vertices (above the 1024 rows from which ZoomOut
/// clusters its rows for the ball search), bumped by `amp`.
#[allow(dead_code)]
pub fn bumpy(amp: f64) -> TriMesh {
    let (mut v, f) = torus(2.0, 0.8, 60, 30).into_parts();
    for (i, p) in v.iter_mut().enumerate() {
        let s = 1.0 + amp * ((i * 31 % 17) as f64 / 17.0 - 0.5);
        *p = [p[0] * s, p[1] * s * 1.1, p[2] * (2.0 - s)];
    }
    TriMesh::new(v, f).unwrap()
}
