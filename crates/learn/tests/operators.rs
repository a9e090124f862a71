//! DiffusionNet's operators against closed forms: the gradient of a linear
//! function on a flat mesh (exact up to the ridge term), the tangent
//! gradient of a coordinate on a sphere (to discretisation error), and
//! the spectrum and frames of a sphere.

use fmaps_learn::operators::{GRAD_REGULARIZATION, edges, gradient_operators, tangent_frames};
use fmaps_learn::{Error, ShapeOperators};
use fmaps_mesh_io::TriMesh;
use fmaps_shapes::{grid, icosphere};

fn apply(m: &sprs::CsMat<f64>, f: &[f64]) -> Vec<f64> {
    m.outer_iterator()
        .map(|row| row.iter().map(|(j, v)| v * f[j]).sum())
        .collect()
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// On a flat grid tilted in space, `f(x) = a · x` has the tangent gradient
/// `g = (a · X, a · Y)` in every frame, and the least-squares fit of a
/// linear function is exact but for the ridge ε: the fit is
/// `(AᵀA + εI)⁻¹AᵀA g`, off by at most `ε / (λ_min(AᵀA) + ε)` relative.
/// The grid's spacing is h = 0.1 in both directions, and a corner's two
/// edges are orthogonal of length h (`AᵀA = h² I`): the bound
/// `ε / (h² + ε)` is reached there, and no vertex exceeds it.
#[test]
fn a_linear_function_has_its_exact_gradient_on_a_flat_mesh() {
    let (v, f) = grid(1.0, 0.8, 10, 8).into_parts();
    // Tilt the plane: rotate about the x axis by 0.5 and lift it.
    let (c, s) = (0.5f64.cos(), 0.5f64.sin());
    let v: Vec<[f64; 3]> = v
        .iter()
        .map(|p| [p[0], c * p[1] - s * p[2], s * p[1] + c * p[2] + 0.3])
        .collect();
    let mesh = TriMesh::new(v, f).unwrap();
    let normals = fmaps_learn::operators::vertex_normals(&mesh).unwrap();
    let frames = tangent_frames(&normals);
    let (gx, gy) = gradient_operators(mesh.vertices(), &edges(&mesh), &frames);
    let a = [2.0, -3.0, 0.5];
    let values: Vec<f64> = mesh.vertices().iter().map(|&p| dot(a, p)).collect();
    let (x, y) = (apply(&gx, &values), apply(&gy, &values));
    let mut worst = 0.0f64;
    for (i, fr) in frames.iter().enumerate() {
        let want = [dot(a, fr.x), dot(a, fr.y)];
        let scale = want[0].hypot(want[1]);
        worst = worst.max((x[i] - want[0]).hypot(y[i] - want[1]) / scale);
    }
    let eps = GRAD_REGULARIZATION;
    let bound = eps / (0.01 + eps);
    assert!(
        worst <= bound * (1.0 + 1e-9) && worst >= bound * (1.0 - 1e-6),
        "relative error {worst}, closed form {bound}"
    );
}

/// On the unit sphere, `f = z` has the tangent gradient `e_z − (e_z · n) n`
/// (of length `sin θ`). The one-ring fit sees the curvature: the error
/// shrinks with the edge length (about 0.03 on the icosphere of 10242
/// vertices: measured 0.26% in the mean; checked at 1%).
#[test]
fn a_coordinate_has_its_tangent_gradient_on_a_sphere() {
    let mesh = icosphere(1.0, 5);
    let normals = fmaps_learn::operators::vertex_normals(&mesh).unwrap();
    let frames = tangent_frames(&normals);
    let (gx, gy) = gradient_operators(mesh.vertices(), &edges(&mesh), &frames);
    let values: Vec<f64> = mesh.vertices().iter().map(|p| p[2]).collect();
    let (x, y) = (apply(&gx, &values), apply(&gy, &values));
    let (mut err, mut norm) = (0.0, 0.0);
    for (i, fr) in frames.iter().enumerate() {
        let n = fr.normal;
        let g = [-n[2] * n[0], -n[2] * n[1], 1.0 - n[2] * n[2]];
        let want = [dot(g, fr.x), dot(g, fr.y)];
        err += (x[i] - want[0]).hypot(y[i] - want[1]);
        norm += want[0].hypot(want[1]);
    }
    assert!(err / norm < 0.01, "mean relative error {}", err / norm);
}

/// The spectrum is the sphere's (0, then 2 three times), the eigenvectors
/// M-orthonormal, the normals radial, and bad parameters are errors.
#[test]
fn sphere_operators_and_errors() {
    let mesh = icosphere(1.0, 3);
    let ops = ShapeOperators::compute(&mesh, 9).unwrap();
    let ev = &ops.eigenvalues;
    assert!(ev[0].abs() < 1e-9);
    assert!((1..4).all(|i| (ev[i] - 2.0).abs() < 0.01), "{ev:?}");
    let phi = &ops.eigenvectors;
    for a in 0..9 {
        for b in 0..9 {
            let m: f64 = (0..mesh.n_vertices())
                .map(|i| ops.mass[i] * phi[(i, a)] * phi[(i, b)])
                .sum();
            assert!((m - f64::from(u8::from(a == b))).abs() < 1e-8);
        }
    }
    for (p, f) in mesh.vertices().iter().zip(&ops.frames) {
        assert!(dot(*p, f.normal) > 0.999);
    }
    assert!(matches!(
        ShapeOperators::compute(&mesh, 0),
        Err(Error::Parameter(_))
    ));
    assert!(matches!(
        ShapeOperators::compute(&mesh, mesh.n_vertices()),
        Err(Error::Parameter(_))
    ));
    // A vertex in no face has no normal: an error naming it.
    let (mut v, f) = icosphere(1.0, 1).into_parts();
    v.push([5.0, 5.0, 5.0]);
    let lonely = TriMesh::new(v, f).unwrap();
    match ShapeOperators::compute(&lonely, 4) {
        Err(Error::Mesh { vertex, .. }) => assert_eq!(vertex, 42),
        other => panic!("{other:?}"),
    }
}

/// The cache: written on the first call, read back on the second (the
/// same operators, bit for bit), recomputed when damaged or computed for
/// another mesh or k.
#[test]
fn operators_are_cached_and_damaged_files_recomputed() {
    let dir = std::env::temp_dir().join(format!("fmaps-learn-cache-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("sphere.npz");
    let mesh = icosphere(1.0, 2);
    let (first, hit) = ShapeOperators::cached(&mesh, 12, &path).unwrap();
    assert!(!hit);
    let (again, hit) = ShapeOperators::cached(&mesh, 12, &path).unwrap();
    assert!(hit);
    assert_eq!(again.eigenvectors, first.eigenvectors);
    assert_eq!(again.eigenvalues, first.eigenvalues);
    assert_eq!(again.mass, first.mass);
    assert_eq!(again.frames, first.frames);
    assert_eq!(again.grad_x, first.grad_x);
    assert_eq!(again.grad_y, first.grad_y);
    // Another k: recomputed (and the file now holds that one).
    let (_, hit) = ShapeOperators::cached(&mesh, 10, &path).unwrap();
    assert!(!hit);
    // A truncated file: recomputed.
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let (ops, hit) = ShapeOperators::cached(&mesh, 10, &path).unwrap();
    assert!(!hit);
    assert_eq!(ops.eigenvalues.len(), 10);
    std::fs::remove_dir_all(&dir).unwrap();
}
