//! Properties of the cotangent Laplacian over several generated meshes, and
//! closed forms on a flat grid.

use fmaps_laplacian::{LaplaceOperator, LaplacianParams, MassKind, cotan_laplacian};
use fmaps_mesh_io::TriMesh;
use fmaps_shapes::{disjoint_union, grid, icosphere, torus, translated};
use nalgebra::DMatrix;

/// A grid with one extra vertex on an edge's midpoint and a zero-area face.
fn with_zero_area_face() -> TriMesh {
    let g = grid(1.0, 1.0, 3, 3);
    let (mut v, mut f) = g.into_parts();
    // Midpoint of the bottom edge between vertices 0 and 1.
    v.push([1.0 / 6.0, 0.0, 0.0]);
    let m = v.len() - 1;
    f.push([0, m, 1]);
    TriMesh::new(v, f).unwrap()
}

fn meshes() -> Vec<(&'static str, TriMesh)> {
    let s = icosphere(1.0, 2);
    vec![
        ("icosphere", s.clone()),
        ("torus", torus(2.0, 0.7, 14, 9)),
        ("grid (boundary)", grid(2.0, 1.0, 7, 5)),
        (
            "two spheres",
            disjoint_union(&s, &translated(&s, [3.0, 0.0, 0.0]).unwrap()),
        ),
        ("zero-area face", with_zero_area_face()),
    ]
}

fn dense(op: &LaplaceOperator) -> DMatrix<f64> {
    let n = op.n();
    let mut d = DMatrix::zeros(n, n);
    for (v, (i, j)) in op.stiffness.iter() {
        d[(i, j)] += *v;
    }
    d
}

#[test]
fn symmetric_zero_row_sums_psd_and_finite() {
    for (name, mesh) in meshes() {
        for kind in [MassKind::Lumped, MassKind::Voronoi] {
            let op = cotan_laplacian(&mesh, &LaplacianParams::with_mass(kind));
            let l = dense(&op);
            assert!(l.iter().all(|x| x.is_finite()), "{name}");
            assert!(op.mass.iter().all(|x| x.is_finite() && *x >= 0.0), "{name}");
            assert_eq!(l, l.transpose(), "{name}: not exactly symmetric");
            let scale = l.amax();
            for i in 0..op.n() {
                assert!(l.row(i).sum().abs() <= 1e-13 * scale, "{name}: row {i} sum");
            }
            let eig = l.clone().symmetric_eigenvalues();
            assert!(
                eig.min() >= -1e-12 * scale,
                "{name}: min eigenvalue {}",
                eig.min()
            );
            let area = mesh.area();
            let total: f64 = op.mass.iter().sum();
            assert!(
                (total - area).abs() <= 1e-12 * area,
                "{name} {kind:?}: {total} vs {area}"
            );
        }
    }
}

#[test]
fn kernel_dimension_is_the_number_of_components() {
    for (name, mesh, comps) in [
        ("sphere", icosphere(1.0, 2), 1),
        (
            "two spheres",
            disjoint_union(
                &icosphere(1.0, 1),
                &translated(&icosphere(1.0, 1), [3.0, 0.0, 0.0]).unwrap(),
            ),
            2,
        ),
    ] {
        let l = dense(&cotan_laplacian(&mesh, &LaplacianParams::default()));
        let eig = l.symmetric_eigenvalues();
        let zeros = eig.iter().filter(|x| x.abs() < 1e-10).count();
        assert_eq!(zeros, comps, "{name}");
    }
}

/// On a regular grid split along diagonals, the cotan Laplacian is the
/// 5-point finite-difference stencil: weights -hy/hx (horizontal neighbours),
/// -hx/hy (vertical), 0 across diagonals, and interior mass hx*hy.
#[test]
fn flat_grid_closed_form() {
    let (nx, ny, w, h) = (6, 4, 3.0, 1.0);
    let (hx, hy) = (w / nx as f64, h / ny as f64);
    let mesh = grid(w, h, nx, ny);
    let op = cotan_laplacian(&mesh, &LaplacianParams::default());
    let l = dense(&op);
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    for j in 1..ny {
        for i in 1..nx {
            let c = id(i, j);
            assert!((l[(c, id(i + 1, j))] + hy / hx).abs() < 1e-12);
            assert!((l[(c, id(i - 1, j))] + hy / hx).abs() < 1e-12);
            assert!((l[(c, id(i, j + 1))] + hx / hy).abs() < 1e-12);
            assert!((l[(c, id(i, j - 1))] + hx / hy).abs() < 1e-12);
            assert!(l[(c, id(i + 1, j + 1))].abs() < 1e-12);
            assert!((l[(c, c)] - 2.0 * (hx / hy + hy / hx)).abs() < 1e-12);
            assert!((op.mass[c] - hx * hy).abs() < 1e-14);
        }
    }
    // Corner (0,0) touches two triangles (area hx*hy/2 each): lumped mass
    // is a third of their total.
    assert!((op.mass[id(0, 0)] - hx * hy / 3.0).abs() < 1e-14);
}

/// Linear precision: L annihilates linear functions at interior vertices
/// of any flat mesh (here a jittered grid).
#[test]
fn linear_functions_are_harmonic_in_the_interior() {
    let (nx, ny) = (8, 6);
    let g = grid(1.0, 1.0, nx, ny);
    let (mut v, f) = g.into_parts();
    for (k, p) in v.iter_mut().enumerate() {
        let (i, j) = (k % (nx + 1), k / (nx + 1));
        if i > 0 && i < nx && j > 0 && j < ny {
            p[0] += 0.03 * ((k * 7) as f64).sin();
            p[1] += 0.03 * ((k * 13) as f64).cos();
        }
    }
    let mesh = TriMesh::new(v, f).unwrap();
    let l = dense(&cotan_laplacian(&mesh, &LaplacianParams::default()));
    let lin: Vec<f64> = mesh
        .vertices()
        .iter()
        .map(|p| 2.0 * p[0] - 3.0 * p[1] + 0.5)
        .collect();
    let y = &l * nalgebra::DVector::from_vec(lin);
    for k in 0..mesh.n_vertices() {
        let (i, j) = (k % (nx + 1), k / (nx + 1));
        if i > 0 && i < nx && j > 0 && j < ny {
            assert!(y[k].abs() < 1e-12, "vertex {k}: {}", y[k]);
        }
    }
}

/// On an acute triangle the Voronoi areas are the circumcentre regions
/// (closed form for an equilateral triangle: a third each), and on an
/// obtuse one the obtuse vertex gets half.
#[test]
fn voronoi_mass_closed_forms() {
    let s = 3f64.sqrt();
    let eq = TriMesh::new(
        vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, s, 0.0]],
        vec![[0, 1, 2]],
    )
    .unwrap();
    let m = fmaps_laplacian::mass_diagonal(&eq, MassKind::Voronoi);
    for x in &m {
        assert!((x - s / 3.0).abs() < 1e-14);
    }
    let obt = TriMesh::new(
        vec![[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [2.0, 0.5, 0.0]],
        vec![[0, 1, 2]],
    )
    .unwrap();
    let m = fmaps_laplacian::mass_diagonal(&obt, MassKind::Voronoi);
    assert!(
        (m[2] - 0.5).abs() < 1e-14 && (m[0] - 0.25).abs() < 1e-14 && (m[1] - 0.25).abs() < 1e-14
    );
}

#[test]
fn zero_area_face_is_skipped_and_reported() {
    let mesh = with_zero_area_face();
    let op = cotan_laplacian(&mesh, &LaplacianParams::default());
    assert_eq!(op.skipped_faces, vec![mesh.n_faces() - 1]);
    assert_eq!(op.mass[mesh.n_vertices() - 1], 0.0);
    assert!(op.stiffness.data().iter().all(|x| x.is_finite()));
}

/// A boundary edge has one opposite angle: on the grid, the weight of a
/// horizontal boundary edge is half that of an interior one.
#[test]
fn boundary_edges_have_one_cotangent() {
    let (nx, ny) = (4, 4);
    let mesh = grid(1.0, 1.0, nx, ny);
    let l = dense(&cotan_laplacian(&mesh, &LaplacianParams::default()));
    // Bottom edge between vertices 1 and 2 (hx = hy): -cot(45°)/2 = -0.5.
    assert!((l[(1, 2)] + 0.5).abs() < 1e-12);
    // Interior horizontal edge: -1.
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    assert!((l[(id(1, 2), id(2, 2))] + 1.0).abs() < 1e-12);
}

/// A grid whose interior vertices are pushed far enough to create many
/// obtuse, non-Delaunay configurations (negative cotan weights).
fn skewed_grid() -> TriMesh {
    let (nx, ny) = (12, 10);
    let (mut v, f) = grid(1.0, 1.0, nx, ny).into_parts();
    for (k, p) in v.iter_mut().enumerate() {
        let (i, j) = (k % (nx + 1), k / (nx + 1));
        if i > 0 && i < nx && j > 0 && j < ny {
            p[0] += 0.45 / nx as f64 * ((k * 7) as f64).sin();
            p[1] += 0.45 / ny as f64 * ((k * 13) as f64).cos();
            p[2] = 0.05 * ((k * 3) as f64).sin();
        }
    }
    TriMesh::new(v, f).unwrap()
}

#[test]
fn intrinsic_delaunay_equals_cotan_on_delaunay_meshes() {
    for mesh in [icosphere(1.0, 2), grid(2.0, 1.0, 6, 4)] {
        let a = dense(&cotan_laplacian(&mesh, &LaplacianParams::default()));
        let b = dense(&fmaps_laplacian::intrinsic_delaunay_laplacian(
            &mesh,
            &LaplacianParams::default(),
        ));
        assert!((a - b).amax() < 1e-12);
    }
}

#[test]
fn intrinsic_delaunay_has_nonnegative_weights() {
    let mesh = skewed_grid();
    let plain = dense(&cotan_laplacian(&mesh, &LaplacianParams::default()));
    let negative = (0..plain.nrows())
        .flat_map(|i| (0..plain.ncols()).map(move |j| (i, j)))
        .filter(|&(i, j)| i != j && plain[(i, j)] > 1e-12)
        .count();
    assert!(negative > 0, "the test mesh must have non-Delaunay edges");
    for kind in [MassKind::Lumped, MassKind::Voronoi] {
        let op =
            fmaps_laplacian::intrinsic_delaunay_laplacian(&mesh, &LaplacianParams::with_mass(kind));
        let l = dense(&op);
        let scale = l.amax();
        assert_eq!(l, l.transpose());
        for i in 0..op.n() {
            assert!(l.row(i).sum().abs() <= 1e-13 * scale);
            for j in 0..op.n() {
                assert!(
                    i == j || l[(i, j)] <= 1e-12 * scale,
                    "L[{i},{j}] = {}",
                    l[(i, j)]
                );
            }
        }
        assert!(l.clone().symmetric_eigenvalues().min() >= -1e-12 * scale);
        let total: f64 = op.mass.iter().sum();
        assert!((total - mesh.area()).abs() <= 1e-12 * mesh.area());
        // Rippa / Bobenko–Springborn: the (intrinsic) Delaunay triangulation
        // minimizes the Dirichlet energy fᵀLf of the piecewise-linear
        // interpolant of any vertex function.
        for f in [
            nalgebra::DVector::from_iterator(
                op.n(),
                mesh.vertices().iter().map(|p| p[0] + 0.5 * p[1]),
            ),
            nalgebra::DVector::from_iterator(
                op.n(),
                (0..op.n()).map(|i| ((i * 37 % 11) as f64).sin()),
            ),
        ] {
            let (e1, e2) = (
                (f.transpose() * &l * &f)[0],
                (f.transpose() * &plain * &f)[0],
            );
            assert!(e1 <= e2 * (1.0 + 1e-12), "{e1} vs {e2}");
        }
    }
}
