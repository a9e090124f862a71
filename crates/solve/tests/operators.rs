//! Descriptor multiplication and orientation operators on real meshes.

use fmaps_mesh_io::TriMesh;
use fmaps_mesh_io::vec3::{cross, dot, sub};
use fmaps_shapes::grid;
use fmaps_solve::*;
use nalgebra::DMatrix;

mod common;
use common::basis;

fn bumpy() -> TriMesh {
    common::bumpy(20, 11)
}

/// Smooth, non-symmetric test functions of the coordinates.
fn functions(mesh: &TriMesh, p: usize) -> DMatrix<f64> {
    DMatrix::from_fn(mesh.n_vertices(), p, |v, q| {
        let [x, y, z] = mesh.vertices()[v];
        let t = q as f64 + 1.0;
        (0.3 * t * x + 0.2 * y).sin() + 0.1 * t * z * z + 0.05 * x * y
    })
}

/// The geometric definition, face by face: `Σ_F ∫_F φ_i ⟨n × ∇f, ∇φ_j⟩`
/// with normals, areas and gradients from the coordinates.
fn orientation_geometric(mesh: &TriMesh, phi: &DMatrix<f64>, f: &[f64]) -> DMatrix<f64> {
    let k = phi.ncols();
    let mut out = DMatrix::zeros(k, k);
    for &[a, b, c] in mesh.faces() {
        let p = [mesh.vertices()[a], mesh.vertices()[b], mesh.vertices()[c]];
        let nn = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        let len = dot(nn, nn).sqrt();
        let area = 0.5 * len;
        let n = [nn[0] / len, nn[1] / len, nn[2] / len];
        // ∇ψ_u = n × e_u / (2 area), e_u the edge opposite u.
        let g = [
            cross(n, sub(p[2], p[1])),
            cross(n, sub(p[0], p[2])),
            cross(n, sub(p[1], p[0])),
        ]
        .map(|v| v.map(|x| x / (2.0 * area)));
        let idx = [a, b, c];
        let grad = |vals: [f64; 3]| -> [f64; 3] {
            let mut r = [0.0; 3];
            for u in 0..3 {
                for d in 0..3 {
                    r[d] += vals[u] * g[u][d];
                }
            }
            r
        };
        let rot = cross(n, grad(idx.map(|v| f[v])));
        for j in 0..k {
            let gj = grad(idx.map(|v| phi[(v, j)]));
            let s = dot(rot, gj) * area / 3.0;
            for i in 0..k {
                out[(i, j)] += s * (phi[(a, i)] + phi[(b, i)] + phi[(c, i)]);
            }
        }
    }
    out
}

#[test]
fn orientation_operator_matches_the_geometric_definition_and_is_antisymmetric() {
    let mesh = bumpy();
    let b = basis(&mesh, 12);
    let f = functions(&mesh, 3);
    let ops = orientation_operators(mesh.faces(), &b.eigenvectors, &f, false).unwrap();
    for (q, op) in ops.iter().enumerate() {
        let col: Vec<f64> = f.column(q).iter().copied().collect();
        let want = orientation_geometric(&mesh, &b.eigenvectors, &col);
        assert!(
            (op - &want).amax() < 1e-10 * want.amax(),
            "{q}: {}",
            (op - &want).amax()
        );
        // Closed mesh: exactly antisymmetric (rounding only).
        assert!((op + op.transpose()).amax() < 1e-12 * op.amax());
        assert!(op.amax() > 1e-3);
    }
}

#[test]
fn flipped_orientation_negates_and_reversing_flag_too() {
    let mesh = bumpy();
    let b = basis(&mesh, 10);
    let f = functions(&mesh, 2);
    let flipped: Vec<[usize; 3]> = mesh.faces().iter().map(|&[a, b, c]| [a, c, b]).collect();
    let ops = orientation_operators(mesh.faces(), &b.eigenvectors, &f, false).unwrap();
    let neg = orientation_operators(&flipped, &b.eigenvectors, &f, false).unwrap();
    let rev = orientation_operators(mesh.faces(), &b.eigenvectors, &f, true).unwrap();
    for q in 0..2 {
        assert!((&ops[q] + &neg[q]).amax() < 1e-13 * ops[q].amax());
        assert_eq!(rev[q], -&ops[q]);
    }
}

#[test]
fn orientation_of_a_constant_vanishes_and_boundary_meshes_work() {
    // On a grid with boundary the operator is no longer antisymmetric but
    // still matches the geometric definition; a constant has no gradient.
    let mesh = grid(1.0, 0.8, 9, 7);
    let b = basis(&mesh, 8);
    let mut f = functions(&mesh, 2);
    f.column_mut(1).fill(2.5);
    let ops = orientation_operators(mesh.faces(), &b.eigenvectors, &f, false).unwrap();
    let col: Vec<f64> = f.column(0).iter().copied().collect();
    let want = orientation_geometric(&mesh, &b.eigenvectors, &col);
    assert!((&ops[0] - &want).amax() < 1e-10 * want.amax());
    assert!(ops[1].amax() < 1e-14);
}

#[test]
fn batched_multiplication_operators_equal_the_single_ones() {
    let mesh = bumpy();
    let b = basis(&mesh, 9);
    let f = functions(&mesh, 4);
    let ops = multiplication_operators(&b.eigenvectors, &b.mass, &f).unwrap();
    for q in 0..4 {
        let col: Vec<f64> = f.column(q).iter().copied().collect();
        let want = multiplication_operator(&b.eigenvectors, &b.mass, &col);
        assert!((&ops[q] - &want).amax() < 1e-13 * want.amax());
        assert!((&ops[q] - ops[q].transpose()).amax() < 1e-13 * want.amax());
    }
}

#[test]
fn operator_inputs_are_checked() {
    let mesh = bumpy();
    let b = basis(&mesh, 4);
    let short = DMatrix::zeros(3, 1);
    assert!(matches!(
        orientation_operators(mesh.faces(), &b.eigenvectors, &short, false),
        Err(Error::SizeMismatch { .. })
    ));
    let f = functions(&mesh, 1);
    let bad = vec![[0, 1, mesh.n_vertices()]];
    assert!(matches!(
        orientation_operators(&bad, &b.eigenvectors, &f, false),
        Err(Error::IndexOutOfRange { .. })
    ));
    assert!(matches!(
        multiplication_operators(&b.eigenvectors, &b.mass, &short),
        Err(Error::SizeMismatch { .. })
    ));
}
