//! Shared test shapes: a torus with per-vertex pseudo-random scaling (no
//! symmetry left) and its eigenbasis.

// Each test binary uses some of these helpers.
#![allow(dead_code)]

use fmaps_eigensolve::{EigenProblem, EigenSolver, NativeSolver, SpectralBasis};
use fmaps_laplacian::{LaplacianParams, cotan_laplacian};
use fmaps_mesh_io::TriMesh;
use fmaps_shapes::torus;

/// The bumpy torus with `nu x nv` vertices.
pub fn bumpy(nu: usize, nv: usize) -> TriMesh {
    let (mut v, f) = torus(2.0, 0.8, nu, nv).into_parts();
    for (k, p) in v.iter_mut().enumerate() {
        let s = 1.0 + 0.08 * ((k * 31 % 17) as f64 / 17.0 - 0.5);
        *p = [p[0] * s, p[1] * s * 1.1, p[2] * (2.0 - s)];
    }
    TriMesh::new(v, f).unwrap()
}

/// The first k eigenpairs (native solver, lumped mass).
pub fn basis(mesh: &TriMesh, k: usize) -> SpectralBasis {
    let op = cotan_laplacian(mesh, &LaplacianParams::default());
    NativeSolver::default()
        .solve(
            &EigenProblem::new(op.stiffness.view(), &op.mass).unwrap(),
            k,
        )
        .unwrap()
}
