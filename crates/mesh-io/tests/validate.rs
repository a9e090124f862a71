//! The validation report on meshes with known combinatorics.

use fmaps_mesh_io::TriMesh;
use fmaps_shapes::{disjoint_union, grid, icosphere, torus, translated};

#[test]
fn icosphere_is_a_clean_sphere() {
    for s in 0..3 {
        let m = icosphere(1.0, s);
        let r = m.validate();
        assert_eq!(r.n_vertices, 10 * 4usize.pow(s) + 2);
        assert_eq!(r.n_edges, 30 * 4usize.pow(s));
        assert_eq!(r.euler_characteristic, 2);
        assert_eq!(r.genus, Some(0));
        assert!(r.is_clean() && r.is_closed_manifold(), "{r:?}");
        // The inscribed polyhedron has less area than the sphere, and
        // converges to it.
        assert!(r.area < 4.0 * std::f64::consts::PI);
    }
    let a = icosphere(1.0, 4).area();
    assert!((a - 4.0 * std::f64::consts::PI).abs() < 0.01 * a);
}

#[test]
fn icosphere_faces_point_outwards() {
    let m = icosphere(1.0, 2);
    // Signed volume by the divergence theorem is positive for outward faces.
    let vol: f64 = m
        .faces()
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| m.vertices()[i]);
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
                / 6.0
        })
        .sum();
    assert!(vol > 0.0);
}

#[test]
fn torus_has_genus_one() {
    let r = torus(3.0, 1.0, 12, 8).validate();
    assert_eq!(r.euler_characteristic, 0);
    assert_eq!(r.genus, Some(1));
    assert!(r.is_clean());
}

#[test]
fn grid_is_a_disk_with_one_boundary_loop() {
    let r = grid(2.0, 1.0, 4, 3).validate();
    assert_eq!(r.boundary_loops, 1);
    assert_eq!(r.boundary_edges, 2 * (4 + 3));
    assert_eq!(r.euler_characteristic, 1);
    assert_eq!(r.genus, Some(0));
    assert!((r.area - 2.0).abs() < 1e-12);
    assert_eq!(r.bounding_box, [[0.0, 0.0, 0.0], [2.0, 1.0, 0.0]]);
}

#[test]
fn two_spheres_are_two_components() {
    let a = icosphere(1.0, 1);
    let b = translated(&a, [5.0, 0.0, 0.0]).unwrap();
    let r = disjoint_union(&a, &b).validate();
    assert_eq!(r.connected_components, 2);
    assert_eq!(r.euler_characteristic, 4);
    assert_eq!(r.genus, Some(0));
    assert!(!r.is_clean());
}

#[test]
fn defects_are_reported() {
    let v = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [2.0, 0.0, 0.0],
        [-1.0, -1.0, 0.0],
        [-1.0, 0.0, -1.0],
        [9.0, 9.0, 9.0],
    ];
    let f = vec![
        [0, 1, 2],
        [0, 1, 3], // edge 0-1 now has two faces
        [1, 0, 4], // third face on edge 0-1: non-manifold edge
        [0, 5, 6], // touches the rest only at vertex 0: bow-tie
        [2, 1, 0], // duplicate of face 0 (reversed)
        [1, 4, 4], // repeated index: degenerate
        [0, 1, 4], // collinear points: degenerate (and duplicate of 2)
    ];
    let r = TriMesh::new(v, f).unwrap().validate();
    // Edge 1-4 is shared by faces 2, 5 and 6 as well.
    assert_eq!(r.non_manifold_edges, vec![[0, 1], [1, 4]]);
    assert!(r.non_manifold_vertices.contains(&0), "{r:?}");
    assert_eq!(r.duplicate_faces, vec![4, 6]);
    assert_eq!(r.degenerate_faces, vec![2, 5, 6]);
    assert_eq!(r.unreferenced_vertices, vec![7]);
    assert_eq!(r.genus, None);
}

#[test]
fn flipped_face_is_an_orientation_defect() {
    let m = icosphere(1.0, 1);
    let (v, mut f) = m.into_parts();
    f[3].swap(0, 1);
    let r = TriMesh::new(v, f).unwrap().validate();
    assert_eq!(r.inconsistently_oriented_edges, 3);
    assert!(r.is_manifold());
}

#[test]
fn subdivision_keeps_the_surface() {
    use fmaps_shapes::subdivide;
    for m in [torus(3.0, 1.0, 9, 7), grid(2.0, 1.0, 3, 2)] {
        let r = m.validate();
        let s = subdivide(&m);
        let rs = s.validate();
        assert_eq!(rs.n_vertices, r.n_vertices + r.n_edges);
        assert_eq!(rs.n_faces, 4 * r.n_faces);
        assert_eq!(rs.euler_characteristic, r.euler_characteristic);
        assert_eq!(rs.boundary_loops, r.boundary_loops);
        assert!((rs.area - r.area).abs() < 1e-12 * r.area);
        assert!(rs.is_clean());
        assert_eq!(rs.inconsistently_oriented_edges, 0);
    }
}

#[test]
fn face_adjacency_is_mutual_and_none_on_the_boundary() {
    let t = torus(3.0, 1.0, 8, 6);
    let a = t.face_adjacency();
    for (f, row) in a.across.iter().enumerate() {
        for (k, nb) in row.iter().enumerate() {
            let (g, j) = nb.expect("a closed torus has no boundary");
            assert_eq!(a.across[g][j], Some((f, k)));
            // The shared edge has the same two vertices.
            let (ff, gg) = (t.faces()[f], t.faces()[g]);
            let mut e1 = [ff[(k + 1) % 3], ff[(k + 2) % 3]];
            let mut e2 = [gg[(j + 1) % 3], gg[(j + 2) % 3]];
            e1.sort_unstable();
            e2.sort_unstable();
            assert_eq!(e1, e2);
        }
    }
    let g = grid(1.0, 1.0, 3, 2);
    let boundary = g
        .face_adjacency()
        .across
        .iter()
        .flatten()
        .filter(|x| x.is_none())
        .count();
    assert_eq!(boundary, g.validate().boundary_edges);
    assert!(g.face_adjacency().non_manifold_edges.is_empty());
}

/// The generators never panic on extreme input: a
/// translation out of the finite range is an error, and subdivision of a
/// mesh with coordinates near f64::MAX keeps every midpoint finite.
#[test]
fn translation_and_subdivision_at_the_edge_of_f64() {
    use fmaps_shapes::{subdivide, translated};
    let g = grid(1.0, 1.0, 2, 2);
    assert!(translated(&g, [f64::MAX, 0.0, 0.0]).is_ok());
    assert!(translated(&g, [f64::INFINITY, 0.0, 0.0]).is_err());
    let huge = translated(&g, [f64::MAX, 0.0, 0.0]).unwrap();
    assert!(translated(&huge, [f64::MAX, 0.0, 0.0]).is_err());
    let s = subdivide(&huge.scaled(1.0).unwrap());
    assert!(s.vertices().iter().flatten().all(|c| c.is_finite()));
}
